//! Shared pieces of the front end: progress bars and PNG output.

use crate::error::{Error, Result};
use crate::viz::Rgb8;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::Path;

/// A progress bar on stderr with ETA; hidden when stderr is not a terminal.
pub fn progress(len: u64, what: &str) -> ProgressBar {
    let pb = ProgressBar::new(len);
    pb.set_style(
        ProgressStyle::with_template("{prefix:>10} [{bar:30}] {pos}/{len} {msg} ({elapsed} < {eta})")
            .expect("static template")
            .progress_chars("=> "),
    );
    pb.set_prefix(what.to_string());
    pb
}

/// Write a picture as an 8-bit RGB PNG, atomically.
pub fn save_png(path: &Path, img: &Rgb8) -> Result<()> {
    write_png(path, std::slice::from_ref(img), None)
}

/// Write pictures of one size as an animated PNG (APNG, looping forever), `fps` frames per
/// second, atomically. Viewers without APNG support show the first frame.
pub fn save_apng(path: &Path, frames: &[Rgb8], fps: u16) -> Result<()> {
    if fps == 0 {
        return Err(Error::config("APNG: frame rate must be positive"));
    }
    write_png(path, frames, Some(fps))
}

/// The PNG encoder behind [`save_png`] (one frame, `fps` None) and [`save_apng`].
fn write_png(path: &Path, frames: &[Rgb8], fps: Option<u16>) -> Result<()> {
    let Some(first) = frames.first() else {
        return Err(Error::format(path, "cannot write PNG: no pictures"));
    };
    for f in frames {
        assert_eq!(f.data.len(), f.w * f.h * 3);
        if (f.w, f.h) != (first.w, first.h) {
            return Err(Error::shape(format!(
                "animated PNG {}: frames of {}x{} and {}x{}",
                path.display(),
                first.w,
                first.h,
                f.w,
                f.h
            )));
        }
    }
    crate::io::write_atomic(path, |out| {
        let mut enc = png::Encoder::new(out, first.w as u32, first.h as u32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        if let Some(fps) = fps {
            enc.set_animated(frames.len() as u32, 0).map_err(std::io::Error::other)?;
            enc.set_frame_delay(1, fps).map_err(std::io::Error::other)?;
        }
        let mut wr = enc.write_header().map_err(std::io::Error::other)?;
        for f in frames {
            wr.write_image_data(&f.data).map_err(std::io::Error::other)?;
        }
        wr.finish().map_err(std::io::Error::other)
    })
    .map_err(|e| match e {
        Error::Io { path, source } => Error::format(path, format!("cannot write PNG: {source}")),
        e => e,
    })
}
