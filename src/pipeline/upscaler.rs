//! [`Upscaler`]: the model, its parameters and an engine, upscaling one frame at a time for a
//! host that has its frames in memory (a game engine, a DCC plug-in, the C ABI). It keeps the
//! temporal context itself: with `temporal` = k (cloth-frame models), frame `f`'s result needs
//! the nets' outputs of frames `f − k … f + k`, so it comes out k frames after `f` went in, and
//! [`Upscaler::flush`] hands out the last k at the end of the shot. It drives the same
//! [`FrameWindow`] as the file pipeline, so each frame gives the same bits as `anisocb upscale`
//! gives it in the whole shot ([`super::stream`]).

use super::physics::{MeshPhysicsPass, PhysicsPass};
use super::stream::{at_frame, temporal_radius, FrameWindow};
use super::worker::Worker;
use crate::cloth::follow::FollowParams;
use crate::error::{Error, Result};
use crate::geom::layout::{GridLayout, Layout, MeshLayout};
use crate::geom::surface::{FaceUvs, Surface};
use crate::geom::{Domain, GridMesh};
use crate::nn::bundle::AnisoCb;
use crate::nn::weights::embedded_model;
use crate::ops::conv2d::PackedConv;
use crate::ops::{Cpu, Ops};
use crate::sr::params::UpscaleParams;
use crate::sr::upscale::{finish, run_nets_into, Predictions};
use crate::tensor::Tensor;

/// A model ready to upscale a shot frame by frame (see the module docs).
///
/// After the first few frames of a shot (the pools and its buffers warmed up), a frame through
/// [`Upscaler::push_into`] (the C ABI's `anisocb_push`) on its own threads
/// ([`Upscaler::with_threads`]) allocates nothing on the heap; [`Upscaler::push`] allocates the
/// mesh it returns (tests/upscaler_allocations.rs). On rayon's global pool, handing the frame's
/// work to the pool allocates about once every 16 frames (rayon's job queue). The physics pass
/// ([`Upscaler::with_physics`]) allocates its simulation's buffers every frame.
pub struct Upscaler {
    model: AnisoCb,
    /// Every conv's weights packed once ([`AnisoCb::pack_all`] of `model`, which never changes).
    packed: Vec<Vec<PackedConv>>,
    /// `model`'s checksum, computed when a device first asks ([`PackedAnisoCb::checksum`]).
    checksum: std::sync::OnceLock<u64>,
    params: UpscaleParams,
    ops: Box<dyn Ops>,
    /// Worker threads of its own (`None`: the global pool).
    pool: Option<Worker>,
    /// The physics pass the HR frames go through, in shot order (`None`: off): on grids.
    physics: Option<PhysicsPass>,
    /// The same on a mesh ([`Upscaler::with_mesh`]).
    mesh_physics: Option<MeshPhysicsPass>,
    /// The box geometry images are encoded with (Eq 1): the unit box for a cloth-frame model,
    /// for which each frame depends on itself alone.
    domain: Domain,
    /// The shot's LR grid, fixed by its first frame.
    grid: Option<GridLayout>,
    /// A mesh that is not a grid ([`Upscaler::with_mesh`]), fixed for every shot, and the LR
    /// frames pushed whose HR frames are not handed out yet (their subdivision is the base).
    mesh: Option<Box<MeshLayout>>,
    lr_held: std::collections::VecDeque<Vec<[f32; 3]>>,
    /// The nets' outputs for the frames of the shot that a frame still to come out reads.
    window: FrameWindow,
    /// Frames given to [`Upscaler::push`] and handed out so far.
    pushed: usize,
    emitted: usize,
    scratch: Scratch,
    /// The most bytes a shot's first frame may ask for ([`Upscaler::with_memory_limit`]).
    memory_limit: Option<usize>,
}

/// Buffers an [`Upscaler`] reuses from frame to frame, so that a frame allocates nothing.
#[derive(Default)]
struct Scratch {
    /// The nets' outputs for the frame just pushed, before they join `raw`.
    fresh: Option<Predictions>,
    /// The frames [`finish`] reads for the frame handed out (they come back in its result).
    context: Option<Predictions>,
}

impl Upscaler {
    /// `model` with `params` on the CPU, on the global worker pool.
    pub fn new(model: AnisoCb, params: UpscaleParams) -> Result<Upscaler> {
        params.validate()?;
        Ok(Upscaler {
            window: FrameWindow::new(temporal_radius(&model, &params)),
            packed: model.pack_all(params.precision),
            checksum: std::sync::OnceLock::new(),
            model,
            params,
            ops: Box::new(Cpu),
            pool: None,
            physics: None,
            mesh_physics: None,
            domain: Domain::UNIT,
            grid: None,
            mesh: None,
            lr_held: Default::default(),
            pushed: 0,
            emitted: 0,
            scratch: Scratch::default(),
            memory_limit: None,
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
        let pool = Worker::new(threads)
            .map_err(|e| Error::config(format!("cannot start {threads} worker threads: {e}")))?;
        self.pool = Some(pool);
        Ok(self)
    }

    /// Refuse a shot whose frames need more than `bytes` of memory ([`Upscaler::frame_bytes`])
    /// with [`Error::OutOfMemory`], as when the allocator cannot give it: a host that shares
    /// the machine caps what the upscaler takes.
    pub fn with_memory_limit(mut self, bytes: usize) -> Upscaler {
        self.memory_limit = Some(bytes);
        self
    }

    /// About the most bytes upscaling a frame of `w` × `h` geometry-image pixels allocates:
    /// the nets' activations (C channels at the HR size, [`WORKING_COPIES`] of them) and the
    /// temporal window's predictions. Measured: a 256 × 256 shot through `anisocb upscale`
    /// peaks at 7.2 KB per LR vertex; this says 8.2 KB.
    pub fn frame_bytes(&self, w: usize, h: usize) -> usize {
        let r = self.scale();
        let c = self.model.geometry.trunk.config.channels;
        let window = 2 * self.latency() + 1;
        let per_hr_pixel = 4 * (WORKING_COPIES * c + PREDICTION_CHANNELS * window);
        w.saturating_mul(h).saturating_mul(r * r).saturating_mul(per_hr_pixel)
    }

    /// Before a shot's first frame allocates its buffers: ask the allocator for
    /// [`Upscaler::frame_bytes`] fallibly (Rust's allocations abort the process when memory
    /// runs out, which would take a host application down), and hold to the caller's limit.
    fn check_memory(&self, w: usize, h: usize) -> Result<()> {
        let need = self.frame_bytes(w, h);
        let fail = |why: &str| {
            Error::OutOfMemory(format!(
                "a {w}×{h} frame needs about {} MiB to upscale, {why}; upscale a coarser grid or \
                 free memory",
                need >> 20
            ))
        };
        if let Some(limit) = self.memory_limit.filter(|&l| need > l) {
            return Err(fail(&format!("more than the limit of {} MiB set for this upscaler", limit >> 20)));
        }
        reserve_probe(need).map_err(|()| fail("more than the allocator can give"))
    }

    /// Send every HR frame through the physics pass (`anisocb upscale --physics`,
    /// docs/research/wrinkles.md): an HR cloth held to the frames at the LR grid's scale, so folds finer
    /// than the LR grid form. The shot must start at its first frame; [`Upscaler::flush`] ends
    /// it. Frames are read as metres.
    pub fn with_physics(mut self, params: FollowParams) -> Result<Upscaler> {
        params.validate()?;
        match &self.mesh {
            Some(m) => self.mesh_physics = Some(MeshPhysicsPass::new(params, m.sub.clone(), m.lr_vertices())),
            None => self.physics = Some(PhysicsPass::new(params)),
        }
        Ok(self)
    }

    /// Upscale a mesh that is not a regular grid (any triangles and quads: a garment, a round
    /// tablecloth; docs/options.md, "Any mesh") instead of grids: `faces` (3 or 4 vertex
    /// indices each) over the vertices of `rest` (metres: the first frame, or the rest pose),
    /// laid out by `uv` (the mesh's texture coordinates and each face's indices into them) when
    /// they are a usable layout, else by ARAP. Frames then go in through
    /// [`Upscaler::push_mesh`] and come out as the vertices of the mesh's subdivision, whose
    /// faces [`Upscaler::hr_faces`] gives; the same vertices `anisocb upscale` writes for them
    /// (with [`Upscaler::with_physics`], before or after this, through the pass on the mesh).
    pub fn with_mesh(
        mut self,
        faces: Vec<Vec<u32>>,
        rest: &[[f32; 3]],
        uv: Option<FaceUvs>,
    ) -> Result<Upscaler> {
        self.set_mesh(faces, rest, uv)?;
        Ok(self)
    }

    /// [`Upscaler::with_mesh`] on a live upscaler, between shots (before a shot's first frame,
    /// or after its flush); on an error the upscaler is unchanged. A physics pass set for grids
    /// or for another mesh moves to this one.
    pub fn set_mesh(&mut self, faces: Vec<Vec<u32>>, rest: &[[f32; 3]], uv: Option<FaceUvs>) -> Result<()> {
        if self.pushed > 0 {
            return Err(Error::config(
                "the mesh can change only between shots: flush the shot's last frames first",
            ));
        }
        let surface = Surface::new(rest.len(), faces, std::path::Path::new("the mesh"))?;
        let m = MeshLayout::new(surface, rest, uv)?;
        let params = match (self.physics.take(), self.mesh_physics.take()) {
            (Some(p), _) => Some(p.params),
            (None, Some(p)) => Some(p.params),
            (None, None) => None,
        };
        if let Some(params) = params {
            self.mesh_physics = Some(MeshPhysicsPass::new(params, m.sub.clone(), m.lr_vertices()));
        }
        self.mesh = Some(Box::new(m));
        Ok(())
    }

    /// The vertices of a mesh's LR and HR frames after [`Upscaler::with_mesh`]; `None` for grids.
    pub fn mesh_vertices(&self) -> Option<(usize, usize)> {
        self.mesh.as_ref().map(|m| (m.lr_vertices(), m.sub.hr_vertices()))
    }

    /// The faces of the HR mesh (four per face of the mesh, in its order) after
    /// [`Upscaler::with_mesh`]; `None` for grids.
    pub fn hr_faces(&self) -> Option<&[Vec<u32>]> {
        self.mesh.as_ref().map(|m| m.sub.faces.as_slice())
    }

    /// [`Upscaler::push`] for a mesh set by [`Upscaler::with_mesh`]: the next LR frame's
    /// vertices (metres, the mesh's order) in; the next HR frame's vertices out once its
    /// temporal context is in.
    pub fn push_mesh(&mut self, lr: &[[f32; 3]]) -> Result<Option<Vec<[f32; 3]>>> {
        let Some(m) = self.mesh.as_ref() else {
            return Err(Error::config("push_mesh needs a mesh: call with_mesh first (push takes grids)"));
        };
        let img = m.to_image(lr, &self.domain).map_err(|e| at_frame(e, self.pushed))?;
        self.lr_held.push_back(lr.to_vec());
        if !self.take_image(&img)? {
            return Ok(None);
        }
        self.emit_mesh_vertices().map(Some)
    }

    /// [`Upscaler::flush`] for a mesh: the HR frames still held back at the end of the shot;
    /// the next [`Upscaler::push_mesh`] starts a new shot.
    pub fn flush_mesh(&mut self) -> Result<Vec<Vec<[f32; 3]>>> {
        let mut out = Vec::new();
        while let Some(v) = self.flush_mesh_one()? {
            out.push(v);
        }
        Ok(out)
    }

    /// [`Upscaler::flush_mesh`] one frame at a time: the next held-back frame's HR vertices, or
    /// `None` (and the next [`Upscaler::push_mesh`] starts a new shot).
    pub fn flush_mesh_one(&mut self) -> Result<Option<Vec<[f32; 3]>>> {
        if self.emitted < self.pushed {
            return self.emit_mesh_vertices().map(Some);
        }
        self.flush_one()?;
        self.lr_held.clear();
        Ok(None)
    }

    /// [`Upscaler::emit`] of a mesh frame into a new list of HR vertices (through the physics
    /// pass, when there is one).
    fn emit_mesh_vertices(&mut self) -> Result<Vec<[f32; 3]>> {
        let n = self.mesh.as_ref().map_or(0, |m| m.sub.hr_vertices());
        let (k, mut out) = (self.emitted, vec![[0.0; 3]; n]);
        self.emit(&mut out)?;
        match self.mesh_physics.as_mut() {
            Some(p) => p.apply(out, k),
            None => Ok(out),
        }
    }

    /// Run on another op table (`crate::cuda::ops_for_device("cuda")`).
    pub fn with_ops(mut self, ops: Box<dyn Ops>) -> Upscaler {
        self.ops = ops;
        self.packed = self.model.pack_all(self.params.precision.for_ops(self.ops.as_ref()));
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

    /// The shot's LR grid (columns, rows), fixed by its first frame; `None` before it.
    pub fn grid(&self) -> Option<(usize, usize)> {
        self.grid.map(|g| (g.w, g.h))
    }

    /// Frames pushed whose results are not handed out yet (what [`Upscaler::flush`] gives).
    pub fn held_back(&self) -> usize {
        self.pushed - self.emitted
    }

    /// Frames a result comes out after its input went in.
    pub fn latency(&self) -> usize {
        temporal_radius(&self.model, &self.params)
    }

    /// Give the next LR frame of the shot; returns the next HR frame once its temporal context
    /// is in (at once when [`Upscaler::latency`] is 0). Every frame of a shot must have the
    /// first frame's grid size.
    pub fn push(&mut self, lr: &GridMesh) -> Result<Option<GridMesh>> {
        if !self.take_frame(lr.w, lr.h, &lr.pos)? {
            return Ok(None);
        }
        self.emit_mesh().map(Some)
    }

    /// [`Upscaler::push`] of the `w` × `h` grid of positions `lr` (row-major) that writes the
    /// HR frame into `hr` (at least rW·rH positions; the first rW·rH are written) and returns
    /// whether it did: without allocating, after the first frames of a shot.
    pub fn push_into(&mut self, w: usize, h: usize, lr: &[[f32; 3]], hr: &mut [[f32; 3]]) -> Result<bool> {
        let n = self.hr_vertices(w, h, hr.len())?;
        if !self.take_frame(w, h, lr)? {
            return Ok(false);
        }
        self.emit(&mut hr[..n]).map(|_| true)
    }

    /// The HR vertices of a `w` × `h` frame, or an error if `room` (positions) cannot hold them.
    fn hr_vertices(&self, w: usize, h: usize, room: usize) -> Result<usize> {
        let r = self.scale();
        let n = GridLayout { w, h }.hr_vertices(r);
        if room < n {
            return Err(Error::shape(format!(
                "room for {room} HR positions; a {w}×{h} frame upscales to {} × {} = {n}",
                r * w,
                r * h
            )));
        }
        Ok(n)
    }

    /// Run the nets on the next LR frame (`w` × `h` positions `lr`) and keep their outputs;
    /// whether a frame is then ready to hand out.
    fn take_frame(&mut self, w0: usize, h0: usize, lr: &[[f32; 3]]) -> Result<bool> {
        if self.mesh.is_some() {
            return Err(Error::config(
                "this Upscaler is set for a mesh (with_mesh): give its frames to push_mesh",
            ));
        }
        let g = *self.grid.get_or_insert(GridLayout { w: w0, h: h0 });
        if (w0, h0) != (g.w, g.h) {
            return Err(Error::shape(format!(
                "frame {} is a {w0}×{h0} grid, the shot's first frame {}×{}: every frame of a shot \
                 must have the same grid (call flush to start a new shot)",
                self.pushed, g.w, g.h
            )));
        }
        GridLayout::new(g.w, g.h)?;
        let img = g.to_image(lr, &self.domain)?;
        self.take_image(&img)
    }

    /// Run the nets on the next LR frame's geometry image `img` (1, 3, H, W) and keep their
    /// outputs; whether a frame is then ready to hand out.
    fn take_image(&mut self, img: &Tensor) -> Result<bool> {
        if self.pushed == 0 {
            if let Err(e) = self.check_memory(img.shape[3], img.shape[2]) {
                // Refused before it began: the next frame may start the shot with another grid.
                self.grid = None;
                return Err(e);
            }
        }
        let (ops, domain, params) = (self.ops.as_ref(), &self.domain, &self.params);
        let nets = self.model.packed_with(&self.packed, &self.checksum);
        let new = self.scratch.fresh.get_or_insert_with(Predictions::none);
        let frame = self.pushed;
        in_pool(&self.pool, || run_nets_into(ops, &nets, img, domain, params, &mut |_| {}, new))
            .map_err(|e| at_frame(e, frame))?;
        self.window.append(frame, new);
        self.pushed += 1;
        Ok(self.pushed - self.emitted > self.latency())
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
            return self.emit_mesh().map(Some);
        }
        self.grid = None;
        self.window.reset();
        if let Some(p) = self.physics.as_mut() {
            p.reset();
        }
        if let Some(p) = self.mesh_physics.as_mut() {
            p.reset();
        }
        (self.pushed, self.emitted) = (0, 0);
        Ok(None)
    }

    /// [`Upscaler::flush_one`] into `hr` (as [`Upscaler::push_into`]): whether a frame was
    /// left to write.
    pub fn flush_into(&mut self, hr: &mut [[f32; 3]]) -> Result<bool> {
        if self.emitted < self.pushed {
            let g = self.grid.expect("frames were pushed");
            let n = self.hr_vertices(g.w, g.h, hr.len())?;
            return self.emit(&mut hr[..n]).map(|_| true);
        }
        self.flush_one().map(|_| false)
    }

    /// [`Upscaler::emit`] into a new HR mesh.
    fn emit_mesh(&mut self) -> Result<GridMesh> {
        let g = self.grid.expect("frames were pushed");
        let r = self.scale();
        let mut hr = GridMesh::new(r * g.w, r * g.h, vec![[0.0; 3]; g.hr_vertices(r)]);
        self.emit(&mut hr.pos)?;
        Ok(hr)
    }

    /// Finish frame `emitted` over its context `emitted − k … pushed`, write its HR vertices
    /// into `out` and release what no later frame reads.
    fn emit(&mut self, out: &mut [[f32; 3]]) -> Result<()> {
        let e = self.emitted;
        let g = self.grid.unwrap_or(GridLayout { w: 0, h: 0 });
        let context = self.window.context(e..e + 1, self.pushed);
        let mut window = self.scratch.context.take().unwrap_or_else(Predictions::none);
        self.window.copy_into(context.clone(), &mut window);
        let (model, params) = (&self.model, &self.params);
        let mut up = in_pool(&self.pool, || finish(window, model, params))
            .map_err(|err| at_frame(err, context.start))?;
        let f = e - context.start;
        // A frame the physics pass fails on is used up like any other (the error says which).
        let physics = match self.physics.as_mut() {
            Some(p) => p.apply(&mut up.hr, f, e, &self.domain, (g.w, g.h)),
            None => Ok(()),
        };
        let done = physics.map(|()| match (&self.mesh, self.lr_held.pop_front()) {
            (Some(m), Some(lr)) => {
                let hr = m.hr_frame(&up.hr, &up.interpolated(), f, &self.domain, &lr, up.keeps_outline());
                out.copy_from_slice(&hr);
            }
            _ => g.to_vertices(&up.hr, f, &self.domain, out),
        });
        self.scratch.context = Some(up.into_nets());
        self.window.release_before((e + 1).saturating_sub(self.latency()));
        self.emitted += 1;
        done
    }
}

/// Copies of a frame's activations at the HR size, C channels each, that the nets hold at once
/// at most ([`Upscaler::frame_bytes`]).
const WORKING_COPIES: usize = 16;
/// Channels of a frame's predictions kept in the temporal window (the HR geometry image, the
/// maps, the residual and the interpolation), rounded up.
const PREDICTION_CHANNELS: usize = 8;

/// Whether `bytes` can be had from the allocator now, asked without aborting on failure (the
/// memory is given back at once; on Linux it is never touched, so it costs no page).
pub(crate) fn reserve_probe(bytes: usize) -> std::result::Result<(), ()> {
    let mut probe: Vec<u8> = Vec::new();
    probe.try_reserve_exact(bytes).map_err(|_| ())
}

/// Run `f` on `pool` if there is one.
fn in_pool<T: Send>(pool: &Option<Worker>, f: impl FnOnce() -> T + Send) -> T {
    match pool {
        Some(p) => p.run(f),
        None => f(),
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_reservation_no_allocator_can_give_is_an_error_not_an_abort() {
        assert!(super::reserve_probe(usize::MAX / 2 + 1).is_err());
        assert!(super::reserve_probe(1 << 20).is_ok());
    }
}
