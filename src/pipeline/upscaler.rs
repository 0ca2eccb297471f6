//! [`Upscaler`]: the model, its parameters and an engine, upscaling one frame at a time for a
//! host that has its frames in memory (a game engine, a DCC plug-in, the C ABI). It keeps the
//! temporal context itself: with `temporal` = k (cloth-frame models), frame `f`'s result needs
//! the nets' outputs of frames `f − k … f + k`, so it comes out k frames after `f` went in, and
//! [`Upscaler::flush`] hands out the last k at the end of the shot. Each frame gives the same
//! bits as `anisocb upscale` gives it in the whole shot ([`crate::sr::stream`]).

use crate::error::{Error, Result};
use crate::geom::cloth_frame::InputFrame;
use crate::geom::geometry_image::{image_to_mesh, mesh_to_image};
use crate::geom::{Domain, GridMesh};
use crate::nn::bundle::AnisoCb;
use crate::ops::{Cpu, Ops};
use crate::sr::upscale::{embedded_model, finish, run_nets, Predictions, UpscaleParams};

/// A model ready to upscale a shot frame by frame (see the module docs).
pub struct Upscaler {
    model: AnisoCb,
    params: UpscaleParams,
    ops: Box<dyn Ops>,
    /// Worker threads of its own (`None`: the global pool).
    pool: Option<rayon::ThreadPool>,
    /// The box geometry images are encoded with (Eq 1): the unit box for a cloth-frame model,
    /// for which each frame depends on itself alone.
    domain: Domain,
    /// The shot's LR grid (columns, rows), fixed by its first frame.
    grid: Option<(usize, usize)>,
    /// The nets' outputs for frames `raw_lo .. pushed` of the shot.
    raw: Option<Predictions>,
    raw_lo: usize,
    /// Frames given to [`Upscaler::push`] and handed out so far.
    pushed: usize,
    emitted: usize,
}

impl Upscaler {
    /// `model` with `params` on the CPU, on the global worker pool.
    pub fn new(model: AnisoCb, params: UpscaleParams) -> Result<Upscaler> {
        params.validate()?;
        Ok(Upscaler {
            model,
            params,
            ops: Box::new(Cpu),
            pool: None,
            domain: Domain::UNIT,
            grid: None,
            raw: None,
            raw_lo: 0,
            pushed: 0,
            emitted: 0,
        })
    }

    /// The embedded ×2 model with the default parameters (what `anisocb upscale` runs).
    pub fn embedded() -> Result<Upscaler> {
        Upscaler::new(embedded_model()?, UpscaleParams::default())
    }

    /// Run on `threads` worker threads of its own (1 to 1024) instead of the global pool.
    pub fn with_threads(mut self, threads: usize) -> Result<Upscaler> {
        if !(1..=1024).contains(&threads) {
            return Err(Error::config(format!("threads must be 1 to 1024, got {threads}")));
        }
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .map_err(|e| Error::config(format!("cannot start {threads} worker threads: {e}")))?;
        self.pool = Some(pool);
        Ok(self)
    }

    /// Run on another op table (`crate::cuda::ops_for_device("cuda")`).
    pub fn with_ops(mut self, ops: Box<dyn Ops>) -> Upscaler {
        self.ops = ops;
        self
    }

    /// Encode frames with `domain` (a box around the whole shot, metres): needed only by models
    /// that work in the sequence's frame ([`InputFrame::Domain`]); cloth-frame models give the
    /// same result in any domain up to rounding, and use the unit box.
    pub fn with_domain(mut self, domain: Domain) -> Result<Upscaler> {
        domain.validate()?;
        self.domain = domain;
        Ok(self)
    }

    /// The model's scale (2: an LR grid of W × H vertices becomes 2W × 2H).
    pub fn scale(&self) -> usize {
        self.model.scale()
    }

    /// Frames a result comes out after its input went in.
    pub fn latency(&self) -> usize {
        if self.model.input_frame() == InputFrame::Cloth {
            self.params.temporal
        } else {
            0
        }
    }

    /// Give the next LR frame of the shot; returns the next HR frame once its temporal context
    /// is in (at once when [`Upscaler::latency`] is 0). Every frame of a shot must have the
    /// first frame's grid size.
    pub fn push(&mut self, lr: &GridMesh) -> Result<Option<GridMesh>> {
        let (w, h) = *self.grid.get_or_insert((lr.w, lr.h));
        if (lr.w, lr.h) != (w, h) {
            return Err(Error::shape(format!(
                "frame {} is a {}×{} grid, the shot's first frame {w}×{h}: every frame of a shot \
                 must have the same grid (call flush to start a new shot)",
                self.pushed, lr.w, lr.h
            )));
        }
        if w < 2 || h < 2 {
            return Err(Error::shape(format!("a grid of {w}×{h} vertices is too small: at least 2×2")));
        }
        let img = mesh_to_image(lr, &self.domain).reshape(&[1, 3, h, w])?;
        let (ops, model, domain, params) = (self.ops.as_ref(), &self.model, &self.domain, &self.params);
        let frame = self.pushed;
        let new = in_pool(&self.pool, || run_nets(ops, model, &img, domain, params, &mut |_| {}))
            .map_err(|e| at_frame(e, frame))?;
        match self.raw.as_mut() {
            Some(r) => r.append(&new),
            None => {
                self.raw = Some(new);
                self.raw_lo = self.pushed;
            }
        }
        self.pushed += 1;
        if self.pushed - self.emitted > self.latency() {
            return self.emit().map(Some);
        }
        Ok(None)
    }

    /// The HR frames still held back at the end of the shot (the last [`Upscaler::latency`]);
    /// the next [`Upscaler::push`] starts a new shot.
    pub fn flush(&mut self) -> Result<Vec<GridMesh>> {
        let mut out = Vec::new();
        while let Some(m) = self.flush_one()? {
            out.push(m);
        }
        Ok(out)
    }

    /// [`Upscaler::flush`] one frame at a time: the next held-back frame, or `None` (and the
    /// next push starts a new shot).
    pub fn flush_one(&mut self) -> Result<Option<GridMesh>> {
        if self.emitted < self.pushed {
            return self.emit().map(Some);
        }
        self.grid = None;
        self.raw = None;
        (self.pushed, self.emitted, self.raw_lo) = (0, 0, 0);
        Ok(None)
    }

    /// Finish frame `emitted` over its window `emitted − k … pushed` and drop what no later
    /// frame reads.
    fn emit(&mut self) -> Result<GridMesh> {
        let (e, k) = (self.emitted, self.latency());
        let lo = e.saturating_sub(k);
        let raw = self.raw.as_mut().expect("frames were pushed");
        let window = raw.slice_frames(lo - self.raw_lo..self.pushed - self.raw_lo);
        let (model, params) = (&self.model, &self.params);
        let up = in_pool(&self.pool, || finish(window, model, params)).map_err(|err| at_frame(err, lo))?;
        let mesh = image_to_mesh(&up.hr, e - lo, &self.domain);
        let keep_from = (e + 1).saturating_sub(k);
        raw.drop_front(keep_from - self.raw_lo);
        self.raw_lo = keep_from;
        self.emitted += 1;
        Ok(mesh)
    }
}

/// Run `f` on `pool` if there is one.
fn in_pool<T: Send>(pool: &Option<rayon::ThreadPool>, f: impl FnOnce() -> T + Send) -> T {
    match pool {
        Some(p) => p.install(f),
        None => f(),
    }
}

/// A numeric error's frame numbers counted from frame `first` of the shot.
fn at_frame(e: Error, first: usize) -> Error {
    match e {
        Error::Numeric(m) => Error::numeric(format!("{m} (counting from frame {first} of the shot)")),
        e => e,
    }
}
