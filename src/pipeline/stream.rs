//! The streaming engine: one explicit frame window ([`FrameWindow`]) that both drivers of the
//! nets use — the file pipeline a chunk of frames at a time ([`upscale_stream`]) and
//! [`super::Upscaler`] one frame at a time — so any frame gets the same bits whichever drives
//! it, and memory is bounded by the chunk, not the shot.
//!
//! The nets ([`run_nets_into`]) are per frame. The finish ([`finish`]: temporal smoothing,
//! Eq 12, strain limit) of frames `a..b` reads the nets' outputs of frames `a − k .. b + k`
//! (k = the temporal radius, clipped to the shot). The window holds the nets' outputs of a run
//! of consecutive frames: a driver asks which frames a finish needs ([`FrameWindow::prepare`]),
//! runs the nets on the ones it lacks, appends them, copies the context out and releases
//! what no later frame reads. Every frame runs through the nets once; frame `f`'s result
//! depends only on frames `f − k … f + k` of the shot, so any frame range of a shot (a farm
//! slice) gives exactly the bits the whole shot gives for those frames.
//!
//! The engine sees only geometry images; a [`crate::geom::layout::Layout`] turns a frame's
//! vertices into them and back.

use crate::error::{Error, Result};
use crate::geom::cloth_frame::InputFrame;
use crate::geom::Domain;
use crate::nn::bundle::AnisoCb;
use crate::ops::Ops;
use crate::sr::params::UpscaleParams;
use crate::sr::upscale::{finish, run_nets_into, Predictions, Upscaled};
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

/// The temporal radius `model` smooths with under `params`: only a cloth-frame model smooths
/// in time ([`UpscaleParams::temporal`]).
pub fn temporal_radius(model: &AnisoCb, params: &UpscaleParams) -> usize {
    if model.input_frame() == InputFrame::Cloth {
        params.temporal
    } else {
        0
    }
}

/// The nets' outputs for the consecutive frames `first .. first + held.frames()` of a shot,
/// and the temporal radius that decides which of them a finish reads (see the module docs).
pub struct FrameWindow {
    /// Temporal radius k (frames).
    radius: usize,
    held: Predictions,
    /// The shot frame of `held`'s first entry.
    first: usize,
}

impl FrameWindow {
    /// An empty window for radius `radius` (frames).
    pub fn new(radius: usize) -> FrameWindow {
        FrameWindow { radius, held: Predictions::none(), first: 0 }
    }

    /// One past the last frame held.
    pub fn end(&self) -> usize {
        self.first + self.held.frames()
    }

    /// The frames whose nets' outputs the finish of frames `out` reads, in a shot whose
    /// frames known so far end at `shot_end`: `out` widened by the radius, clipped to the shot.
    pub fn context(&self, out: Range<usize>, shot_end: usize) -> Range<usize> {
        out.start.saturating_sub(self.radius)..(out.end + self.radius).min(shot_end)
    }

    /// Make ready for `context`: forget held frames before it and return the frames of it
    /// still to run through the nets (then [`FrameWindow::append`] them).
    pub fn prepare(&mut self, context: Range<usize>) -> Range<usize> {
        if self.end() <= context.start {
            self.held.drop_front(self.held.frames());
            self.first = context.start;
        } else {
            self.release_before(context.start);
        }
        self.end().max(context.start)..context.end
    }

    /// Append the nets' outputs `new` of frames `from .. from + new.frames()`: the frames right
    /// after those held, or any frames when none are held. Reuses the window's buffers.
    pub fn append(&mut self, from: usize, new: &Predictions) {
        if self.held.frames() == 0 {
            new.copy_frames_into(0..new.frames(), &mut self.held);
            self.first = from;
        } else {
            assert_eq!(from, self.end(), "FrameWindow::append: frames must follow those held");
            self.held.append(new);
        }
    }

    /// Copy the held frames `context` into `out` (its buffers reused), for [`finish`].
    pub fn copy_into(&self, context: Range<usize>, out: &mut Predictions) {
        assert!(
            self.first <= context.start && context.end <= self.end(),
            "FrameWindow: frames {context:?} are not all held ({}..{})",
            self.first,
            self.end()
        );
        self.held.copy_frames_into(context.start - self.first..context.end - self.first, out);
    }

    /// Forget the frames before `frame` (none that a later finish reads).
    pub fn release_before(&mut self, frame: usize) {
        let n = frame.saturating_sub(self.first).min(self.held.frames());
        self.held.drop_front(n);
        self.first += n;
    }

    /// Forget every frame: a new shot starts at frame 0.
    pub fn reset(&mut self) {
        self.held.drop_front(self.held.frames());
        self.first = 0;
    }
}

/// A numeric error's frame numbers, counted from the start of a window, counted from frame
/// `first` of the shot.
pub fn at_frame(e: Error, first: usize) -> Error {
    match e {
        Error::Numeric(m) => Error::numeric(format!("{m} (counting from frame {first} of the shot)")),
        e => e,
    }
}

/// Upscale frames `range` of `src` (geometry images in `domain`) chunk by chunk into `sink`.
/// `on_frames(k)` gets the number of frames of `range` written so far. `params` are checked by
/// the caller ([`UpscaleParams::validate`]).
#[allow(clippy::too_many_arguments)]
pub(crate) fn upscale_stream(
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
    let nets = model.packed_as(params.precision.for_ops(ops));
    let mut win = FrameWindow::new(temporal_radius(model, params));
    let (mut fresh, mut window) = (Predictions::none(), Predictions::none());
    let mut a = range.start;
    while a < range.end {
        let b = a.saturating_add(chunk).min(range.end);
        let context = win.context(a..b, t);
        let need = win.prepare(context.clone());
        if !need.is_empty() {
            let lr = src.read(need.clone())?;
            run_nets_into(ops, &nets, &lr, domain, params, &mut |_| {}, &mut fresh)
                .map_err(|e| at_frame(e, need.start))?;
            win.append(need.start, &fresh);
        }
        win.copy_into(context.clone(), &mut window);
        // The next chunk's context starts at b − k at the earliest.
        win.release_before(b.saturating_sub(win.radius));
        let up = finish(window, model, params).map_err(|e| at_frame(e, context.start))?;
        sink.write(a, &up, a - context.start..b - context.start)?;
        window = up.into_nets();
        a = b;
        on_frames(a - range.start);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn window_runs_each_frame_once_and_keeps_only_what_the_next_finish_reads() {
        // Radius 2, a shot of 10 frames in chunks of 3: the nets run on 0..5, 5..8, 8..10.
        let mut w = FrameWindow::new(2);
        let mut ran = Vec::new();
        let mut a = 0;
        while a < 10 {
            let b = (a + 3).min(10);
            let ctx = w.context(a..b, 10);
            let need = w.prepare(ctx.clone());
            if !need.is_empty() {
                ran.push(need.clone());
                let p = Predictions::blank(need.len(), 4, 4);
                w.append(need.start, &p);
            }
            assert!(w.first <= ctx.start && ctx.end <= w.end(), "{ctx:?} held");
            w.release_before(b.saturating_sub(2));
            a = b;
        }
        assert_eq!(ran, vec![0..5, 5..8, 8..10]);
    }
}
