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
    assert_eq!(img.data.len(), img.w * img.h * 3);
    crate::io::write_atomic(path, |out| {
        let mut enc = png::Encoder::new(out, img.w as u32, img.h as u32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut wr = enc.write_header().map_err(std::io::Error::other)?;
        wr.write_image_data(&img.data).map_err(std::io::Error::other)?;
        wr.finish().map_err(std::io::Error::other)
    })
    .map_err(|e| match e {
        Error::Io { path, source } => Error::format(path, format!("cannot write PNG: {source}")),
        e => e,
    })
}
