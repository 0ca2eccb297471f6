//! The upscale pipeline: LR geometry images → the nets' input frame → the three nets (on the
//! grid's four mirror images, averaged: [`UpscaleParams::mirrors`]) → optional temporal
//! smoothing → back to the geometry image's domain → Eq 12 → HR meshes (Eq 2, with the input's
//! domain).
//!
//! lr: (T, 3, H, W) → hr: (T, 3, rH, rW), maps (T, 1, rH, rW). Inputs and outputs are geometry
//! images in the sequence's domain (Eq 1, the format on disk); a model trained in the cloth
//! frame ([`InputFrame::Cloth`]) gets each frame re-expressed in its own frame first, and its
//! output mapped back, so the result moves, turns and scales with the input frame by frame.

use super::compose::compose;
use super::outline::{blend_outer_rings, loop_length, outline_base, outline_weight, set_border};
use super::params::UpscaleParams;
use super::strain::{hr_edge_targets, limit_strain};
use super::temporal::smooth_in_time;
use crate::cuda::MirrorView;
use crate::error::{Error, Result};
use crate::geom::cloth_frame::{
    from_cloth_frames, into_cloth_frames, mirror_net_images, net_axes, Affine, InputFrame, GRID_MIRRORS,
};
use crate::geom::geometry_image::{images_to_sequence, sequence_to_images};
use crate::geom::mesh::ring_vertices;
use crate::geom::{Domain, GridMesh};
use crate::nn::bundle::{AnisoCb, NetsOutput, PackedAnisoCb};
use crate::ops::{Interp, Ops};
use crate::pool;
use crate::tensor::Tensor;

/// How the nets were run, for the composition: fixed for a shot.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Composition {
    /// Whether EnhanceNet ran (it does not at η = 0, where Eq 12 ignores Γe).
    enhance_ran: bool,
    strain_iters: usize,
    keep_outline: bool,
    gate_coarse_only: bool,
}

/// Step 1's result ([`run_nets`]): the nets' outputs for consecutive frames, in the nets' frame.
/// It can be cut and joined along frames, which the streaming pipeline does so that every
/// frame runs through the nets once; [`finish`] turns it into an [`Upscaled`].
#[derive(Clone, Debug)]
pub struct Predictions {
    /// Catmull-Rom interpolation U (T, 3, rH, rW), in the nets' frame.
    pub interpolated: Tensor,
    /// GeometryNet's residual R (T, 3, rH, rW), in the nets' frame.
    pub residual: Tensor,
    /// Γb (T, 1, rH, rW).
    pub boundary: Tensor,
    /// Γe (T, 1, rH, rW); all 0 where EnhanceNet was not run.
    pub enhance: Tensor,
    /// Per frame: (domain → nets' frame, back).
    net_frames: Vec<(Affine, Affine)>,
    /// The LR frames in the nets' frame (T, 3, H, W), for the strain limit and outline floor.
    lr_net: Tensor,
    how: Composition,
}

/// What the pipeline produces for a sequence ([`finish`]): the composed HR frames, in the
/// sequence's domain, and the nets' outputs they were composed from, kept in the nets' frame.
/// Eq 12, the outline floor and the strain limit all run in the nets' frame, and the result
/// is mapped back to the domain once.
#[derive(Clone, Debug)]
pub struct Upscaled {
    /// Γfinal, the HR geometry images (T, 3, rH, rW), in the domain.
    pub hr: Tensor,
    /// What `hr` was composed from (after temporal smoothing).
    nets: Predictions,
    /// Whether the nets' frame is the domain itself (a model in the sequence's frame).
    in_domain: bool,
}

impl Predictions {
    /// Frames in it.
    pub fn frames(&self) -> usize {
        self.interpolated.shape[0]
    }

    /// A copy of frames `r`.
    pub fn slice_frames(&self, r: std::ops::Range<usize>) -> Predictions {
        let mut out = Predictions::none();
        self.copy_frames_into(r, &mut out);
        out
    }

    /// No frames, no buffers: what [`run_nets_into`] and [`Predictions::copy_frames_into`]
    /// fill.
    pub(crate) fn none() -> Predictions {
        let empty = || Tensor::zeros(&[0]);
        Predictions {
            interpolated: empty(),
            residual: empty(),
            boundary: empty(),
            enhance: empty(),
            net_frames: Vec::new(),
            lr_net: empty(),
            how: Composition::default(),
        }
    }

    /// [`Predictions::slice_frames`] into `out`, replacing its frames and reusing its buffers
    /// where they have room (a frame-by-frame caller then allocates nothing).
    pub(crate) fn copy_frames_into(&self, r: std::ops::Range<usize>, out: &mut Predictions) {
        let (n0, n) = (r.start, r.len());
        out.interpolated.assign_batch(&self.interpolated, n0, n);
        out.residual.assign_batch(&self.residual, n0, n);
        out.boundary.assign_batch(&self.boundary, n0, n);
        out.enhance.assign_batch(&self.enhance, n0, n);
        out.lr_net.assign_batch(&self.lr_net, n0, n);
        out.net_frames.clear();
        out.net_frames.extend_from_slice(&self.net_frames[r]);
        out.how = self.how;
    }

    /// `frames` frames of zeros at an HR size of `hh` × `hw` (an LR size of half that), in
    /// the domain's frame: for tests of what cuts and joins them.
    #[cfg(test)]
    pub(crate) fn blank(frames: usize, hh: usize, hw: usize) -> Predictions {
        let z = |c: usize, h: usize, w: usize| Tensor::zeros(&[frames, c, h, w]);
        Predictions {
            interpolated: z(3, hh, hw),
            residual: z(3, hh, hw),
            boundary: z(1, hh, hw),
            enhance: z(1, hh, hw),
            net_frames: vec![(Affine::IDENTITY, Affine::IDENTITY); frames],
            lr_net: z(3, hh / 2, hw / 2),
            how: Composition::default(),
        }
    }

    /// Drop the first `n` frames.
    pub fn drop_front(&mut self, n: usize) {
        for t in [
            &mut self.interpolated,
            &mut self.residual,
            &mut self.boundary,
            &mut self.enhance,
            &mut self.lr_net,
        ] {
            t.drop_batch_front(n);
        }
        self.net_frames.drain(..n);
    }

    /// Append `other`'s frames (the same sizes).
    pub fn append(&mut self, other: &Predictions) {
        self.interpolated.append_batch(&other.interpolated);
        self.residual.append_batch(&other.residual);
        self.boundary.append_batch(&other.boundary);
        self.enhance.append_batch(&other.enhance);
        self.lr_net.append_batch(&other.lr_net);
        self.net_frames.extend_from_slice(&other.net_frames);
    }
}

impl Upscaled {
    /// Frames in it.
    pub fn frames(&self) -> usize {
        self.nets.frames()
    }

    /// Γb (T, 1, rH, rW).
    pub fn boundary(&self) -> &Tensor {
        &self.nets.boundary
    }

    /// Γe (T, 1, rH, rW); all 0 where EnhanceNet was not run.
    pub fn enhance(&self) -> &Tensor {
        &self.nets.enhance
    }

    /// The interpolation U (T, 3, rH, rW) in the domain: the baseline.
    pub fn interpolated(&self) -> Tensor {
        self.to_domain(self.nets.interpolated.clone(), true)
    }

    /// GeometryNet's residual R (T, 3, rH, rW) in the domain, before composition.
    pub fn residual(&self) -> Tensor {
        self.to_domain(self.nets.residual.clone(), false)
    }

    /// The nets' outputs it was composed from (for a caller that reuses their buffers).
    pub(crate) fn into_nets(self) -> Predictions {
        self.nets
    }

    /// Whether [`Upscaled::with_eta`] applies the outline floor ([`UpscaleParams::keep_outline`]).
    pub fn keeps_outline(&self) -> bool {
        self.nets.how.keep_outline
    }

    /// Compose with or without the outline floor from now on (`eval`'s comparison).
    pub fn set_keep_outline(&mut self, on: bool) {
        self.nets.how.keep_outline = on;
    }

    /// Γfinal for another enhancement factor `eta`, from the same network outputs (Eq 12, the
    /// same outline floor and strain limit as [`Upscaled::hr`]), in the domain.
    pub fn with_eta(&self, eta: f32) -> Result<Tensor> {
        if eta != 0.0 && !self.nets.how.enhance_ran {
            return Err(Error::config(format!(
                "η = {eta} needs EnhanceNet's map, which was not computed (upscaled with η = 0)"
            )));
        }
        let n = &self.nets;
        let mut g = if n.how.gate_coarse_only {
            // U + (1 − Γb)·S(R) + (1 + ηΓe)·(R − S(R)): BoundaryNet gates the coarse part,
            // η deepens the fine part (the folds) where EnhanceNet expects them.
            let (_, _, h, w) = n.lr_net.dims4();
            let (_, _, hh, hw) = n.residual.dims4();
            // The CPU table's resize: the composition has no ops handle (it runs after the nets).
            let up = |x: &Tensor, oh, ow| crate::ops::Cpu.resize(x, oh, ow, Interp::CatmullRom);
            let coarse = up(&up(&n.residual, h, w), hh, hw);
            let mut fine = n.residual.clone();
            for (f, c) in fine.data.iter_mut().zip(&coarse.data) {
                *f -= c;
            }
            let base = compose(&n.interpolated, &coarse, Some(&n.boundary), None, 0.0)?;
            compose(&base, &fine, None, Some(&n.enhance), eta)?
        } else {
            compose(&n.interpolated, &n.residual, Some(&n.boundary), Some(&n.enhance), eta)?
        };
        self.keep_outline_net(&mut g);
        self.limit_strain_net(&mut g);
        Ok(self.to_domain(g, true))
    }

    /// Eq 12 without BoundaryNet's gate (Γb = 0), with the outline floor, in the domain:
    /// `eval`'s ablation.
    pub fn without_boundary(&self, eta: f32) -> Result<Tensor> {
        let n = &self.nets;
        let mut g = compose(&n.interpolated, &n.residual, None, Some(&n.enhance), eta)?;
        self.keep_outline_net(&mut g);
        Ok(self.to_domain(g, true))
    }

    /// Images in the nets' frame (T, 3, ·, ·) into the domain: `points` (positions) or vectors.
    fn to_domain(&self, mut x: Tensor, points: bool) -> Tensor {
        if !self.in_domain {
            from_cloth_frames(&mut x, &self.nets.net_frames, points);
        }
        x
    }

    /// The outline floor ([`UpscaleParams::keep_outline`]) on every frame of `hr` (T, 3, rH,
    /// rW, composed over U, in the nets' frame).
    fn keep_outline_net(&self, hr: &mut Tensor) {
        let n = &self.nets;
        if !n.how.keep_outline {
            return;
        }
        let (_, _, h, w) = n.lr_net.dims4();
        let (_, _, hh, hw) = hr.dims4();
        let (lr_ring, hr_ring, px3) = (ring_vertices(w, h, 0), ring_vertices(hw, hh, 0), 3 * hh * hw);
        for (k, img) in hr.data.chunks_exact_mut(px3).enumerate() {
            let floor = loop_length(&n.lr_net.data[k * 3 * h * w..(k + 1) * 3 * h * w], lr_ring.clone());
            // Long enough already (α = 1): nothing to scale, no normals to compute.
            if loop_length(img, hr_ring.clone()) >= floor {
                continue;
            }
            let base = outline_base(img, &n.interpolated.data[k * px3..(k + 1) * px3], hh, hw);
            let a = outline_weight(img, &base, hr_ring.clone(), floor);
            if a < 1.0 {
                blend_outer_rings(img, &base, hh, hw, a);
            }
            pool::give(base);
        }
    }

    /// [`limit_strain`] on every frame of `hr` (T, 3, rH, rW, in the nets' frame), toward the
    /// HR edge lengths implied by the LR frame's own edges.
    fn limit_strain_net(&self, hr: &mut Tensor) {
        let n = &self.nets;
        if n.how.strain_iters == 0 {
            return;
        }
        let (_, _, h, w) = n.lr_net.dims4();
        let (_, _, hh, hw) = hr.dims4();
        for (k, img) in hr.data.chunks_exact_mut(3 * hh * hw).enumerate() {
            let lr = &n.lr_net.data[k * 3 * h * w..(k + 1) * 3 * h * w];
            let (lx, ly) = hr_edge_targets(lr, h, w, hh, hw);
            limit_strain(img, hh, hw, &lx, &ly, n.how.strain_iters);
            pool::give(lx);
            pool::give(ly);
        }
    }
}

/// Upscale LR geometry images in `domain` (the box they were encoded with, Eq 1). `on_frames(k)`
/// is called after each batch with the number of frames done so far.
pub fn upscale_images(
    ops: &dyn Ops,
    model: &AnisoCb,
    lr: &Tensor,
    domain: &Domain,
    params: &UpscaleParams,
    on_frames: &mut dyn FnMut(usize),
) -> Result<Upscaled> {
    let raw = run_nets(ops, model, lr, domain, params, on_frames)?;
    finish(raw, model, params)
}

/// Step 1 of [`upscale_images`], per frame: each LR frame in the nets' frame and the three
/// nets, batch by batch, into [`Predictions`] (U and R in the nets' frame until [`finish`]),
/// which can be cut and joined along frames ([`Predictions::drop_front`],
/// [`Predictions::append`]): the streaming pipeline does so that every frame runs once.
pub fn run_nets(
    ops: &dyn Ops,
    model: &AnisoCb,
    lr: &Tensor,
    domain: &Domain,
    params: &UpscaleParams,
    on_frames: &mut dyn FnMut(usize),
) -> Result<Predictions> {
    params.validate()?;
    // Every conv's weights packed once for all batches and mirror views.
    let mut out = Predictions::none();
    run_nets_into(
        ops,
        &model.packed_as(params.precision.for_ops(ops)),
        lr,
        domain,
        params,
        on_frames,
        &mut out,
    )?;
    Ok(out)
}

/// [`run_nets`] with the weights packed in advance, into `out`: its frames are replaced, its
/// buffers reused where they have room (a caller that keeps `out` from frame to frame
/// allocates nothing). On an error `out` holds no meaningful frames.
pub(crate) fn run_nets_into(
    ops: &dyn Ops,
    nets: &PackedAnisoCb,
    lr: &Tensor,
    domain: &Domain,
    params: &UpscaleParams,
    on_frames: &mut dyn FnMut(usize),
    out: &mut Predictions,
) -> Result<()> {
    let model = nets.model();
    let (t, c, h, w) = lr.expect_rank4("upscale input")?;
    if c != 3 {
        return Err(Error::shape(format!("upscale input must have 3 channels (xyz), got {c}")));
    }
    if t == 0 {
        return Err(Error::shape("upscale input has no frames"));
    }
    if let Some((i, v)) = lr.first_non_finite() {
        let frame = i / (c * h * w);
        return Err(Error::numeric(format!("input frame {frame} holds a non-finite value {v}")));
    }
    domain.validate()?;
    check_extent(lr, domain)?;
    let r = model.scale();
    let (hh, hw) = (r * h, r * w);
    let cloth = model.input_frame() == InputFrame::Cloth;
    out.interpolated.reset_zeros(&[t, 3, hh, hw]);
    out.residual.reset_zeros(&[t, 3, hh, hw]);
    out.boundary.reset_zeros(&[t, 1, hh, hw]);
    out.enhance.reset_zeros(&[t, 1, hh, hw]);
    out.net_frames.clear();
    out.lr_net.reset_zeros(&[t, 3, h, w]);
    out.how = Composition {
        enhance_ran: params.eta != 0.0 || params.enhance_map,
        strain_iters: if cloth { params.strain_iters } else { 0 },
        keep_outline: params.keep_outline && !params.pin_border && cloth,
        gate_coarse_only: params.gate_coarse_only,
    };
    let (px3, px1) = (3 * hh * hw, hh * hw);
    let mut done = 0;
    while done < t {
        let n = params.batch.min(t - done);
        let mut x = lr.slice_batch(done, n);
        into_cloth_frames(model.input_frame(), &mut x, domain, &mut out.net_frames);
        out.lr_net.data[done * 3 * h * w..(done + n) * 3 * h * w].copy_from_slice(&x.data);
        let (r_at, m_at) = (done * px3..(done + n) * px3, done * px1..(done + n) * px1);
        let o = views_averaged(ops, nets, &x, params.mirrors, out.how.enhance_ran)?;
        out.interpolated.data[r_at.clone()].copy_from_slice(&o.interpolated.data);
        out.residual.data[r_at.clone()].copy_from_slice(&o.residual.data);
        out.boundary.data[m_at.clone()].copy_from_slice(&o.boundary.data);
        out.enhance.data[m_at.clone()].copy_from_slice(&o.enhance.data);
        if params.pin_border {
            let mut b = out.boundary.slice_batch(done, n);
            set_border(&mut b, 1.0);
            out.boundary.data[m_at].copy_from_slice(&b.data);
        }
        // A GPU table's driver failure surfaces here, not as NaN frames.
        crate::ops::check_device(ops)?;
        done += n;
        on_frames(done);
    }
    Ok(())
}

/// The nets on `x` (N, 3, H, W), frames already in the nets' frame: U, R, Γb, Γe, with
/// `mirrors` the mean over the grid's four mirror images (each in its own frame, its outputs
/// mirrored back onto `x`'s grid). `enhance`: run EnhanceNet (else Γe = 0).
pub fn views_averaged(
    ops: &dyn Ops,
    nets: &PackedAnisoCb,
    x: &Tensor,
    mirrors: bool,
    enhance: bool,
) -> Result<NetsOutput> {
    let mirrors = if mirrors { &GRID_MIRRORS[1..] } else { &[] };
    let frame = nets.model().input_frame();
    let views: Vec<MirrorView> = GRID_MIRRORS[..1 + mirrors.len()]
        .iter()
        .map(|&(rows, cols)| MirrorView { rows, cols, axes: net_axes(rows, cols, frame) })
        .collect();
    // A GPU with tensor cores runs every view and net at once and averages them there.
    if let Some(o) = crate::cuda::nets_views(ops, nets, x, &views, enhance) {
        return Ok(o);
    }
    let mut o = nets.forward_with(ops, x, enhance)?;
    if !mirrors.is_empty() {
        let add = |acc: &mut [f32], t: &Tensor| acc.iter_mut().zip(&t.data).for_each(|(a, b)| *a += b);
        for &(rows, cols) in mirrors {
            let m = nets.forward_with(ops, &mirror_net_images(x, rows, cols, frame, true), enhance)?;
            add(&mut o.residual.data, &mirror_net_images(&m.residual, rows, cols, frame, false));
            add(&mut o.boundary.data, &m.boundary.flipped(rows, cols));
            add(&mut o.enhance.data, &m.enhance.flipped(rows, cols));
        }
        let s = 1.0 / (1 + mirrors.len()) as f32;
        for t in [&mut o.residual, &mut o.enhance, &mut o.boundary] {
            t.data.iter_mut().for_each(|v| *v *= s);
        }
    }
    Ok(o)
}

/// Refuse a frame of `lr` (T, 3, H, W, geometry images in `domain`) whose vertices all lie at
/// one point: it has no size, no orientation and no wrinkles, and the nets' frame of it (and
/// every check of the result against its size) would divide by zero.
fn check_extent(lr: &Tensor, domain: &Domain) -> Result<()> {
    let (_, _, h, w) = lr.dims4();
    for (f, img) in lr.data.chunks_exact(3 * h * w).enumerate() {
        let flat = img.chunks_exact(h * w).all(|c| c.iter().all(|&v| v == c[0]));
        if flat {
            let at = domain.decode([img[0], img[h * w], img[2 * h * w]]);
            return Err(Error::numeric(format!(
                "input frame {f} is collapsed to a point: all its {} vertices are at {at:?}, so it \
                 has no extent to upscale (a frame exported before the cloth existed, or a broken \
                 export); re-export it or leave it out of the frames upscaled",
                h * w
            )));
        }
    }
    Ok(())
}

/// Steps 2–3 of [`upscale_images`] on [`run_nets`]'s output for consecutive frames: temporal
/// smoothing (the window renormalised at `raw`'s ends), back to the sequence's domain, Eq 12
/// and the strain limit.
pub fn finish(mut out: Predictions, model: &AnisoCb, params: &UpscaleParams) -> Result<Upscaled> {
    let px3 = out.interpolated.len() / out.interpolated.shape[0].max(1);
    // 2. Temporal smoothing of R where it is comparable across frames: in the cloth frame a
    //    wrinkle that stays on the cloth has the same residual whatever the cloth does. The
    //    maps that gate R in Eq 12 get the same window: a gate that flickers makes the detail
    //    flicker however smooth R is.
    if params.temporal > 0 && model.input_frame() == InputFrame::Cloth {
        out.residual = smooth_in_time(&out.residual, params.temporal);
        out.boundary = smooth_in_time(&out.boundary, params.temporal);
        if out.how.enhance_ran {
            out.enhance = smooth_in_time(&out.enhance, params.temporal);
        }
    }
    // 3. Eq 12, the outline floor and the strain limit in the nets' frame, then back to the
    //    sequence's domain (`with_eta`).
    let (_, _, hh, hw) = out.interpolated.dims4();
    let in_domain = model.input_frame() == InputFrame::Domain;
    let mut out = Upscaled { hr: Tensor::zeros(&[0, 3, hh, hw]), nets: out, in_domain };
    out.hr = out.with_eta(params.eta)?;
    if let Some((i, v)) = out.hr.first_non_finite() {
        return Err(Error::numeric(format!(
            "the network produced a non-finite value {v} in frame {} (bad weights file?)",
            i / px3
        )));
    }
    check_detail_size(&out.hr, &out.interpolated())?;
    Ok(out)
}

/// Largest distance, as a fraction of the frame's extent, by which an upscaled frame may move
/// from its interpolated input: the nets add folds of millimetres to centimetres on cloth of
/// metres (a few percent even at the largest η); half the cloth's size is a broken model.
pub const MAX_DETAIL_FRACTION: f32 = 0.5;

/// Refuse frames of `hr` that lie further than [`MAX_DETAIL_FRACTION`] of their extent from
/// `interpolated` (both (T, 3, H, W), same coordinates): finite but corrupt weights, or weights
/// for other data, would otherwise write a cloth kilometres wide with exit status 0.
pub fn check_detail_size(hr: &Tensor, interpolated: &Tensor) -> Result<()> {
    let (t, _, h, w) = interpolated.dims4();
    let px = h * w;
    for f in 0..t {
        let (mut extent, mut moved) = (0.0f32, 0.0f32);
        for c in 0..3 {
            let at = (f * 3 + c) * px..(f * 3 + c + 1) * px;
            let u = &interpolated.data[at.clone()];
            let (lo, hi) =
                u.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), &v| (l.min(v), h.max(v)));
            extent = extent.max(hi - lo);
            moved = hr.data[at].iter().zip(u).fold(moved, |m, (a, b)| m.max((a - b).abs()));
        }
        if moved > MAX_DETAIL_FRACTION * extent {
            return Err(Error::numeric(format!(
                "frame {f}: the upscaled cloth moves up to {:.1}× the frame's size away from the \
                 interpolated input (the nets add detail of a few percent of it): the weights file \
                 is corrupt or was trained for other data",
                moved / extent.max(f32::MIN_POSITIVE)
            )));
        }
    }
    Ok(())
}

/// Upscale a mesh sequence with `domain` (the box its geometry images are normalised by):
/// returns the HR meshes and the raw pipeline outputs.
pub fn upscale_meshes(
    ops: &dyn Ops,
    model: &AnisoCb,
    frames: &[GridMesh],
    domain: &Domain,
    params: &UpscaleParams,
    on_frames: &mut dyn FnMut(usize),
) -> Result<(Vec<GridMesh>, Upscaled)> {
    domain.validate()?;
    if frames.is_empty() {
        return Err(Error::shape("no frames to upscale"));
    }
    let lr = sequence_to_images(frames, domain);
    let up = upscale_images(ops, model, &lr, domain, params, on_frames)?;
    let meshes = images_to_sequence(&up.hr, domain);
    Ok((meshes, up))
}

/// Upscale the frames of a mesh that is not a grid (`layout`, positions in metres) in memory:
/// each frame's atlas image through the pipeline, and each HR frame its subdivision plus the
/// composed detail ([`MeshLayout::hr_frame`]), in the layout's HR numbering.
pub fn upscale_mesh_frames(
    ops: &dyn Ops,
    model: &AnisoCb,
    layout: &crate::geom::layout::MeshLayout,
    frames: &[Vec<[f32; 3]>],
    params: &UpscaleParams,
) -> Result<Vec<Vec<[f32; 3]>>> {
    if frames.is_empty() {
        return Err(Error::shape("no frames to upscale"));
    }
    // A domain-frame model needs the shot's box; a cloth-frame one works in any.
    let domain = if model.input_frame() == InputFrame::Cloth {
        Domain::UNIT
    } else {
        let all: Vec<[f32; 3]> = frames.iter().flatten().copied().collect();
        Domain::enclosing(&[GridMesh::new(all.len(), 1, all)], 0.05)
    };
    let (h, w) = layout.image_size();
    let mut lr = Tensor::zeros(&[frames.len(), 3, h, w]);
    for (k, f) in frames.iter().enumerate() {
        let img = layout.to_image(f, &domain)?;
        lr.data[k * img.len()..(k + 1) * img.len()].copy_from_slice(&img.data);
    }
    let up = upscale_images(ops, model, &lr, &domain, params, &mut |_| {})?;
    let base = up.interpolated();
    Ok(frames
        .iter()
        .enumerate()
        .map(|(k, f)| layout.hr_frame(&up.hr, &base, k, &domain, f, up.keeps_outline()))
        .collect())
}
