//! Streaming upscale: a shot of any length read, upscaled and written a chunk of frames at a
//! time, so memory is bounded by the chunk, not the shot; and any frame range of a shot
//! upscales to exactly the bits the whole shot gives for those frames (farm slices).
//!
//! Each chunk of frames `a..b` is finished ([`finish`]: temporal smoothing, Eq 12, strain
//! limit) together with the `temporal` = k frames on either side of it (clipped to the shot),
//! which the smoothing of frames `a..b` reads; the context frames' own results are discarded,
//! their nets' outputs kept for the next chunk, so every frame runs through the nets once.
//! Every other step is per frame, so frame `f`'s result depends only on frames `f − k … f + k`
//! of the shot, as in [`super::upscale::upscale_images`].

use super::upscale::{finish, run_nets, Predictions, UpscaleParams, Upscaled};
use crate::error::{Error, Result};
use crate::geom::cloth_frame::InputFrame;
use crate::geom::Domain;
use crate::nn::bundle::AnisoCb;
use crate::ops::Ops;
use crate::tensor::Tensor;
use std::ops::Range;

/// Where LR frames come from.
pub trait LrSource {
    /// Frames in the whole shot.
    fn frames(&self) -> usize;
    /// Frames `range` of the shot as geometry images (n, 3, H, W) in the shot's domain.
    fn read(&mut self, range: Range<usize>) -> Result<Tensor>;
}

/// Where HR frames go, in order.
pub trait HrSink {
    /// Write frames `first..first + keep.len()` of the shot: entries `keep` of `up`.
    fn write(&mut self, first: usize, up: &Upscaled, keep: Range<usize>) -> Result<()>;
}

/// An in-memory shot.
impl LrSource for Tensor {
    fn frames(&self) -> usize {
        self.shape[0]
    }
    fn read(&mut self, range: Range<usize>) -> Result<Tensor> {
        Ok(self.slice_batch(range.start, range.len()))
    }
}

/// Default frames per chunk: the 64² → 128² working set of a chunk is ≈ 6 copies × 64 frames
/// × 3·128² floats ≈ 75 MB, plus the nets' activations of one batch.
pub const DEFAULT_CHUNK: usize = 64;

/// Upscale frames `range` of `src` (geometry images in `domain`) chunk by chunk into `sink`.
/// `on_frames(k)` gets the number of frames of `range` written so far.
#[allow(clippy::too_many_arguments)]
pub fn upscale_stream(
    ops: &dyn Ops,
    model: &AnisoCb,
    src: &mut dyn LrSource,
    domain: &Domain,
    range: Range<usize>,
    params: &UpscaleParams,
    chunk: usize,
    sink: &mut dyn HrSink,
    on_frames: &mut dyn FnMut(usize),
) -> Result<()> {
    params.validate()?;
    let t = src.frames();
    if range.start >= range.end || range.end > t {
        return Err(Error::config(format!(
            "frames {}:{} are not a non-empty range of the shot's {t} frames (0:{t})",
            range.start, range.end
        )));
    }
    if chunk == 0 {
        return Err(Error::config("chunk must be ≥ 1 frame"));
    }
    // Only a cloth-frame model smooths in time (see `UpscaleParams::temporal`).
    let k = if model.input_frame() == InputFrame::Cloth { params.temporal } else { 0 };
    // Its frame numbers count from the window's first frame.
    let from_frame = |lo: usize| {
        move |e: Error| match e {
            Error::Numeric(m) => Error::numeric(format!("{m} (counting from frame {lo} of the shot)")),
            e => e,
        }
    };
    // The nets' outputs for frames buf_lo..buf_lo + raw.frames(): each chunk's window, whose
    // overlap with the next window is kept so that every frame runs through the nets once.
    let mut raw: Option<Predictions> = None;
    let mut buf_lo = 0;
    let mut a = range.start;
    while a < range.end {
        let b = (a + chunk).min(range.end);
        let (lo, hi) = (a.saturating_sub(k), (b + k).min(t));
        let have = raw.as_ref().map_or(0, Predictions::frames);
        if buf_lo + have <= lo {
            raw = None;
            buf_lo = lo;
        } else if let Some(r) = raw.as_mut() {
            r.drop_front(lo - buf_lo);
            buf_lo = lo;
        }
        let from = buf_lo + raw.as_ref().map_or(0, Predictions::frames);
        if from < hi {
            let lr = src.read(from..hi)?;
            let new = run_nets(ops, model, &lr, domain, params, &mut |_| {}).map_err(from_frame(from))?;
            match raw.as_mut() {
                Some(r) => r.append(&new),
                None => raw = Some(new),
            }
        }
        // Keep only what the next window shares with this one (≤ 2k frames from b − k).
        let next_lo = b.saturating_sub(k).max(lo);
        let window = raw.take().expect("the window holds frames lo..hi");
        raw = Some(window.slice_frames(next_lo - lo..hi - lo));
        buf_lo = next_lo;
        let up = finish(window, model, params).map_err(from_frame(lo))?;
        sink.write(a, &up, a - lo..b - lo)?;
        a = b;
        on_frames(a - range.start);
    }
    Ok(())
}
