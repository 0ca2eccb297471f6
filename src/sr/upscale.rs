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
use crate::error::{Error, Result};
use crate::geom::cloth_frame::{mirror_net_images, Affine, InputFrame, GRID_MIRRORS};
use crate::geom::geometry_image::{images_to_sequence, sequence_to_images};
use crate::geom::mesh::{border_loop, closed_loop_length, ring_loop};
use crate::geom::vec3::{cross, dot, norm, sub};
use crate::geom::{Domain, GridMesh};
use crate::io::npz::npz_from_bytes;
use crate::nn::bundle::AnisoCb;
use crate::nn::weights::bundle_from_npz;
use crate::ops::resample::resize;
use crate::ops::{Interp, Ops};
use crate::tensor::Tensor;
use std::path::Path;

/// The shipped ×2 model (see weights/README.md), embedded so the binary needs no files.
pub static EMBEDDED_WEIGHTS: &[u8] = include_bytes!("../../weights/anisocb-x2.npz");

/// Decode [`EMBEDDED_WEIGHTS`].
pub fn embedded_model() -> Result<AnisoCb> {
    let what = Path::new("<embedded weights/anisocb-x2.npz>");
    let e = npz_from_bytes(EMBEDDED_WEIGHTS).map_err(|m| Error::format(what, m))?;
    bundle_from_npz(&e, what)
}

/// Default [`UpscaleParams::strain_iters`]: off. Measured on validation runs (seed 6), 10
/// iterations lower vertex RMSE by 6 % on a drape and a flag and put their temporal
/// edge-length error well below bicubic's, but on a strongly twisted strip with a rubber band
/// (LR edges strained up to 35 %) they cost 26 % — the LR frame's edge lengths are then not
/// the HR cloth's. Opt in with `upscale --strain-iters 10` for cloth that does not stretch much.
pub const DEFAULT_STRAIN_ITERS: usize = 0;
/// The strain-limit iterations `eval` reports as its own row.
pub const EVAL_STRAIN_ITERS: usize = 10;

/// Default temporal smoothing radius (frames), [`UpscaleParams::temporal`]: off. With one pass
/// of the nets, radius 2 was chosen on the validation runs (seed 6 = `--vary 6`: neither
/// training nor held out; STED temporal 1.044 → 1.019 % on the drape, 2.192 → 2.125 % on the
/// flag with radius 1, a little more with 2). With mirror averaging ([`DEFAULT_MIRRORS`]) the
/// residual no longer carries the frame-to-frame noise the window removed, and on the same
/// runs radius 0 against 2 was better or equal on every run and metric: STED temporal −0.0 to
/// −14 % (twist-6 0.918 → 0.791× bicubic: averaging the detail of a strip that keeps turning
/// moves it off its place), the flicker metric −0.3 to −0.8 %, vertex RMSE −0.1 to −0.4 %,
/// normal angle equal or lower. Radius 1 and 3 sat between.
pub const DEFAULT_TEMPORAL: usize = 0;

/// Largest temporal smoothing radius (frames) [`UpscaleParams::validate`] accepts: a window of
/// 129 frames (±2 s at 30 fps) is already far wider than any detail worth keeping, and the
/// cost grows with the radius.
pub const MAX_TEMPORAL: usize = 64;

/// Largest enhancement factor η [`UpscaleParams::validate`] accepts: η multiplies the detail
/// on wrinkle edges by up to 1 + η (Eq 12); at 10 the folds are already 11× deeper than the
/// nets predict, and larger values only blow the mesh up.
pub const MAX_ETA: f32 = 10.0;

/// Smallest η [`UpscaleParams::validate`] accepts: −1 removes the detail where EnhanceNet is
/// sure of a wrinkle (gain 1 + ηΓe = 0); below it the gain would turn the folds inside out.
pub const MIN_ETA: f32 = -1.0;

/// Largest strain-limit iteration count [`UpscaleParams::validate`] accepts: the default 10
/// already removes the swimming; each iteration is a pass over every edge of every frame, so
/// a count in the millions would run for days.
pub const MAX_STRAIN_ITERS: usize = 1000;

/// Largest network batch [`UpscaleParams::validate`] accepts (frames per pass): beyond a few
/// dozen frames a pass is no faster, only larger in memory.
pub const MAX_BATCH: usize = 1024;

/// Default [`UpscaleParams::mirrors`]: on. Measured on the validation runs (seed 6: neither
/// training nor held out) with the shipped model, against one pass: the smooth flag's
/// normal-angle error 1.06 → 0.98× bicubic's and its STED temporal 1.015 → 0.981× (the only
/// per-run targets the single pass missed there), its mean-curvature error 0.347 → 0.271 1/m,
/// STED temporal lower on all five runs (−0.6 to −4.2 %); vertex RMSE −0.9 % (flag), −3.2 %
/// (smooth flag), but +0.9 % (drape), +4.0 % (twist) and +2.8 % (twist-materials), whose
/// training clips twist one way, so a mirrored view is less familiar to the nets. Training
/// with mirrored samples (`train --mirror-augment`) raised GeometryNet's validation loss by
/// 59 % and did not beat this (weights/README.md).
pub const DEFAULT_MIRRORS: bool = true;

/// Default [`UpscaleParams::pin_border`]: off. Measured on the validation runs (seed 6) with
/// the shipped model (trained on whole frames, BoundaryNet's target judging the border like
/// any pixel): pinning the outermost ring to U costs 0–6 % vertex RMSE (twists 5–6 %) and
/// 0–35 % border-band RMSE (drape 11 %, twists 30–35 %), and raises the normal-angle error on
/// the drape and twists. The border length stays within 0.5 % of the truth's unpinned.
pub const DEFAULT_PIN_BORDER: bool = false;

/// Default [`UpscaleParams::keep_outline`]: on (since 2026-11-24; off before). The nets were
/// trained on our simulator's cloth, whose hems rarely fold; on draped sheets from Blender
/// they flatten the hanging hem's folds and the outline comes out shorter than the LR frame's
/// own. Chosen by a rule written down before the three draped Blender validation scenes
/// stool-drape, oval-table and bench-drape were simulated (weights/README.md): over the five
/// Blender validation scenes the border's distance from the truth's length falls from 0.27 %
/// to 0.11 % on average (stool-drape 0.9951 → 0.9984 of the truth's, oval-table 0.9957 →
/// 0.9992), vertex RMSE +0.00 to +0.05 %. The cost is on our simulator's twisted strips, whose
/// true outline is itself shorter than the LR polyline: on the seed-6 validation runs vertex
/// RMSE +0.6 % (drape), +1.0 % (twist), +0.9 % (twist-materials), the flags unchanged, and
/// border-band RMSE +4 to +6 % on those three; every run stays below bicubic's error, normal
/// angle and flicker. Scaling the whole correction toward U instead of its normal part (tried
/// first) cost up to 2.8 % vertex RMSE, 17 % border-band RMSE and +6.8 % STED temporal.
pub const DEFAULT_KEEP_OUTLINE: bool = true;

/// Options of the pipeline.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UpscaleParams {
    /// Enhancement factor η of Eq 12 (dimensionless, ≥ 0); see [`super::compose::DEFAULT_ETA`].
    /// At η = 0 EnhanceNet is not run (Γe = 0) unless `enhance_map`.
    pub eta: f32,
    /// Run EnhanceNet even at η = 0: for its map Γe, or to compose other η later
    /// ([`Upscaled::with_eta`]).
    pub enhance_map: bool,
    /// Frames per network forward (memory ≈ batch · 2·C·r²·H·W floats at the widest layer).
    pub batch: usize,
    /// Set Γb = 1 on the grid's border pixels, so the border keeps the interpolated input
    /// whatever BoundaryNet says there (the outline is U's by construction). Off by default
    /// ([`DEFAULT_PIN_BORDER`]): the nets are trained on whole frames, so they see real borders
    /// and correct U's one-sided extrapolation there.
    pub pin_border: bool,
    /// Temporal smoothing radius (frames) of the residual and of the maps Γb, Γe that gate it,
    /// in the cloth frame: binomial weights over frames t − k … t + k (k = 1: ¼ ½ ¼),
    /// renormalised at the ends of the sequence; 0 = off, and off for models in the paper's
    /// domain frame (their residuals are not comparable across frames). Detail that stays on
    /// the cloth is kept; detail that flips from frame to frame (what shows as shading flicker
    /// and swimming edges) is averaged out. With one pass of the nets, smoothing Γb as well as
    /// R lowered STED temporal on every seed-6 validation run (twist-materials 2.35 → 2.31 %);
    /// with mirror averaging it is off by default ([`DEFAULT_TEMPORAL`]).
    pub temporal: usize,
    /// Strain limit: Jacobi iterations pulling the HR grid's edge lengths toward those implied
    /// by the LR frame's own edges ([`hr_edge_targets`], [`limit_strain`]), in the cloth frame;
    /// 0 = off ([`DEFAULT_STRAIN_ITERS`]). Border vertices stay put.
    pub strain_iters: usize,
    /// Average the nets' outputs over the grid's four mirror images (the LR grid as given,
    /// flipped along its rows, its columns, both): each mirror is upscaled in its own cloth
    /// frame, its R, Γb and Γe mapped back onto the original grid and frame, and the four
    /// averaged before Eq 12 ([`DEFAULT_MIRRORS`]). Every mirror is the same surface, so the
    /// result keeps the invariances; detail the nets agree on stays, and what one
    /// parametrisation of the grid invents and the others do not is averaged down. 4× the
    /// network time.
    pub mirrors: bool,
    /// Outline floor: each frame's HR border loop is never shorter than the LR frame's own
    /// border polyline (a curve through the LR border vertices is not shorter than the
    /// polyline through them). Where the composed result's would be, the part of its
    /// correction Γfinal − U along U's surface normal ([`outline_base`]: what flattens a
    /// hem's folds) is scaled down near the border, by α on the border ring and (1 + α)/2 on
    /// the ring inside it, α ∈ [0, 1] the largest that keeps the length ([`outline_weight`];
    /// α = 0 if even that is not enough). Measured in each frame's cloth frame, so the
    /// invariances hold; off for models in the paper's domain frame and with `pin_border`
    /// ([`DEFAULT_KEEP_OUTLINE`]).
    pub keep_outline: bool,
    /// BoundaryNet gates only the coarse part of the residual, S(R) (R through the LR grid
    /// and back, Catmull-Rom), and leaves its fine part R − S(R) — folds finer than the LR
    /// grid — as the net predicts it: `(1 − Γb)` then cannot flatten wrinkles where the
    /// BoundaryNet says "interpolate", only their coarse shift; η's gain `1 + ηΓe` applies to
    /// the fine part: Γ = U + (1 − Γb)·S(R) + (1 + ηΓe)·(R − S(R)). Off by default.
    pub gate_coarse_only: bool,
}

impl UpscaleParams {
    /// Refuse values that make no sense or could not finish: η not in [[`MIN_ETA`], [`MAX_ETA`]],
    /// `temporal` above [`MAX_TEMPORAL`], `batch` not in 1..=[`MAX_BATCH`], `strain_iters`
    /// above [`MAX_STRAIN_ITERS`]. Checked before any network runs.
    pub fn validate(&self) -> Result<()> {
        if !(self.eta.is_finite() && (MIN_ETA..=MAX_ETA).contains(&self.eta)) {
            return Err(Error::config(format!(
                "enhancement factor η (--eta) must be a number from {MIN_ETA} to {MAX_ETA}, got {}; \
                 0 = the nets' detail as predicted, 1 = up to twice as deep on wrinkle edges, \
                 -0.5 = half as deep",
                self.eta
            )));
        }
        if self.temporal > MAX_TEMPORAL {
            return Err(Error::config(format!(
                "temporal smoothing radius (--temporal) must be at most {MAX_TEMPORAL} frames, got {}; \
                 1 or 2 calm flicker, 0 = off",
                self.temporal
            )));
        }
        if self.batch == 0 || self.batch > MAX_BATCH {
            return Err(Error::config(format!(
                "batch (--batch) must be 1 to {MAX_BATCH} frames per network pass, got {}",
                self.batch
            )));
        }
        if self.strain_iters > MAX_STRAIN_ITERS {
            return Err(Error::config(format!(
                "strain-limit iterations (--strain-iters) must be at most {MAX_STRAIN_ITERS}, got {}; \
                 about 10 removes swimming, 0 = off",
                self.strain_iters
            )));
        }
        Ok(())
    }
}

impl Default for UpscaleParams {
    fn default() -> Self {
        UpscaleParams {
            eta: super::compose::DEFAULT_ETA,
            enhance_map: false,
            batch: 8,
            pin_border: DEFAULT_PIN_BORDER,
            temporal: DEFAULT_TEMPORAL,
            strain_iters: DEFAULT_STRAIN_ITERS,
            mirrors: DEFAULT_MIRRORS,
            keep_outline: DEFAULT_KEEP_OUTLINE,
            gate_coarse_only: false,
        }
    }
}

/// What the pipeline produces for a sequence.
#[derive(Clone, Debug)]
pub struct Upscaled {
    /// Γfinal, the HR geometry images (T, 3, rH, rW).
    pub hr: Tensor,
    /// Bicubic interpolation U (T, 3, rH, rW): the baseline.
    pub interpolated: Tensor,
    /// GeometryNet's residual R (T, 3, rH, rW), before composition.
    pub residual: Tensor,
    /// Γb (T, 1, rH, rW).
    pub boundary: Tensor,
    /// Γe (T, 1, rH, rW); all 0 where EnhanceNet was not run (`enhance_ran`).
    pub enhance: Tensor,
    /// Whether EnhanceNet ran (it does not at η = 0, where Eq 12 ignores Γe).
    enhance_ran: bool,
    /// Per frame: (domain → nets' frame, back) and the LR frame in the nets' frame (for the
    /// strain limit and the outline floor); `strain_iters` and `keep_outline` as run.
    maps: Vec<(Affine, Affine)>,
    lr_net: Tensor,
    strain_iters: usize,
    pub(crate) keep_outline: bool,
    gate_coarse_only: bool,
}

impl Upscaled {
    /// Frames in it.
    pub fn frames(&self) -> usize {
        self.interpolated.shape[0]
    }

    /// A copy of frames `r` (`hr` is not carried: run [`finish`] after).
    pub fn slice_frames(&self, r: std::ops::Range<usize>) -> Upscaled {
        let cut = |t: &Tensor| t.slice_batch(r.start, r.len());
        Upscaled {
            hr: Tensor::zeros(&[0, 3, self.interpolated.shape[2], self.interpolated.shape[3]]),
            interpolated: cut(&self.interpolated),
            residual: cut(&self.residual),
            boundary: cut(&self.boundary),
            enhance: cut(&self.enhance),
            enhance_ran: self.enhance_ran,
            maps: self.maps[r.clone()].to_vec(),
            lr_net: cut(&self.lr_net),
            strain_iters: self.strain_iters,
            keep_outline: self.keep_outline,
            gate_coarse_only: self.gate_coarse_only,
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
        if self.hr.shape[0] >= n {
            self.hr.drop_batch_front(n);
        }
        self.maps.drain(..n);
    }

    /// Append `other`'s frames (the same sizes; `hr` is not carried: run [`finish`] after).
    pub fn append(&mut self, other: &Upscaled) {
        self.interpolated.append_batch(&other.interpolated);
        self.residual.append_batch(&other.residual);
        self.boundary.append_batch(&other.boundary);
        self.enhance.append_batch(&other.enhance);
        self.lr_net.append_batch(&other.lr_net);
        self.maps.extend_from_slice(&other.maps);
        self.hr = Tensor::zeros(&[0, 3, self.interpolated.shape[2], self.interpolated.shape[3]]);
    }

    /// Γfinal for another enhancement factor `eta`, from the same network outputs (Eq 12, the
    /// same outline floor and strain limit as [`Upscaled::hr`]).
    pub fn with_eta(&self, eta: f32) -> Result<Tensor> {
        if eta != 0.0 && !self.enhance_ran {
            return Err(Error::config(format!(
                "η = {eta} needs EnhanceNet's map, which was not computed (upscaled with η = 0)"
            )));
        }
        let mut g = if self.gate_coarse_only {
            // U + (1 − Γb)·S(R) + (1 + ηΓe)·(R − S(R)): BoundaryNet gates the coarse part,
            // η deepens the fine part (the folds) where EnhanceNet expects them.
            let (_, _, h, w) = self.lr_net.dims4();
            let (_, _, hh, hw) = self.residual.dims4();
            let coarse =
                resize(&resize(&self.residual, h, w, Interp::CatmullRom), hh, hw, Interp::CatmullRom);
            let mut fine = self.residual.clone();
            for (f, c) in fine.data.iter_mut().zip(&coarse.data) {
                *f -= c;
            }
            let base = compose(&self.interpolated, &coarse, Some(&self.boundary), None, 0.0)?;
            compose(&base, &fine, None, Some(&self.enhance), eta)?
        } else {
            compose(&self.interpolated, &self.residual, Some(&self.boundary), Some(&self.enhance), eta)?
        };
        self.keep_outline_all(&mut g);
        self.limit_strain_all(&mut g);
        Ok(g)
    }

    /// The outline floor ([`UpscaleParams::keep_outline`]) on every frame of `hr` (T, 3, rH,
    /// rW, in the domain, composed over [`Upscaled::interpolated`]): normals and lengths in
    /// each frame's cloth frame, the blend ([`blend_outer_rings`]) in the domain (a blend
    /// commutes with the affine map between them).
    pub(crate) fn keep_outline_all(&self, hr: &mut Tensor) {
        if !self.keep_outline {
            return;
        }
        let (_, _, h, w) = self.lr_net.dims4();
        let (_, _, hh, hw) = hr.dims4();
        let (lr_ring, hr_ring, px3) = (border_loop(w, h), border_loop(hw, hh), 3 * hh * hw);
        for (k, img) in hr.data.chunks_exact_mut(px3).enumerate() {
            let floor = loop_length(&self.lr_net.data[k * 3 * h * w..(k + 1) * 3 * h * w], &lr_ring);
            let mut hr_net = img.to_vec();
            self.maps[k].0.apply_image(&mut hr_net, true);
            // Long enough already (α = 1): nothing to scale, no normals to compute.
            if loop_length(&hr_net, &hr_ring) >= floor {
                continue;
            }
            let mut u_net = self.interpolated.data[k * px3..(k + 1) * px3].to_vec();
            self.maps[k].0.apply_image(&mut u_net, true);
            let base_net = outline_base(&hr_net, &u_net, hh, hw);
            let a = outline_weight(&hr_net, &base_net, &hr_ring, floor);
            if a < 1.0 {
                let mut base = base_net;
                self.maps[k].1.apply_image(&mut base, true);
                blend_outer_rings(img, &base, hh, hw, a);
            }
        }
    }

    /// [`limit_strain`] on every frame of `hr` (T, 3, rH, rW, in the domain), in each frame's
    /// cloth frame, toward the HR edge lengths implied by the LR frame's own edges.
    fn limit_strain_all(&self, hr: &mut Tensor) {
        if self.strain_iters == 0 {
            return;
        }
        let (_, _, h, w) = self.lr_net.dims4();
        let (_, _, hh, hw) = hr.dims4();
        for (k, img) in hr.data.chunks_exact_mut(3 * hh * hw).enumerate() {
            let lr = &self.lr_net.data[k * 3 * h * w..(k + 1) * 3 * h * w];
            let (lx, ly) = hr_edge_targets(lr, h, w, hh, hw);
            self.maps[k].0.apply_image(img, true);
            limit_strain(img, hh, hw, &lx, &ly, self.strain_iters);
            self.maps[k].1.apply_image(img, true);
        }
    }
}

/// Target lengths of the HR grid's row edges (rH × (rW − 1)) and column edges ((rH − 1) × rW):
/// the nearest LR edge's length (LR image `lr`, 3 × H × W) times the spacing ratio
/// (W − 1)/(rW − 1) (resp. rows): the HR surface keeps the LR frame's local stretch, so
/// stretchy bands stay stretched and nothing the nets add swims along the cloth.
pub fn hr_edge_targets(lr: &[f32], h: usize, w: usize, hh: usize, hw: usize) -> (Vec<f32>, Vec<f32>) {
    let px = h * w;
    let len =
        |a: usize, b: usize| (0..3).map(|c| (lr[c * px + b] - lr[c * px + a]).powi(2)).sum::<f32>().sqrt();
    let (sx, sy) = ((w - 1) as f32 / (hw - 1).max(1) as f32, (h - 1) as f32 / (hh - 1).max(1) as f32);
    let near = |v: f32, n: usize| (v.round().max(0.0) as usize).min(n.saturating_sub(1));
    let mut lx = Vec::with_capacity(hh * hw);
    for y in 0..hh {
        let j = near(y as f32 * sy, h);
        for x in 0..hw.saturating_sub(1) {
            let i = near((x as f32 + 0.5) * sx - 0.5, w - 1);
            lx.push(len(j * w + i, j * w + i + 1) * sx);
        }
    }
    let mut ly = Vec::with_capacity(hh * hw);
    for y in 0..hh.saturating_sub(1) {
        let j = near((y as f32 + 0.5) * sy - 0.5, h - 1);
        for x in 0..hw {
            let i = near(x as f32 * sx, w);
            ly.push(len(j * w + i, (j + 1) * w + i) * sy);
        }
    }
    (lx, ly)
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
/// nets, batch by batch. U, R and the per-frame maps stay in the nets' frame (`hr` is empty)
/// until [`finish`]; the result can be cut and joined along frames ([`Upscaled::drop_front`],
/// [`Upscaled::append`]), which the streaming pipeline does so every frame runs once.
pub fn run_nets(
    ops: &dyn Ops,
    model: &AnisoCb,
    lr: &Tensor,
    domain: &Domain,
    params: &UpscaleParams,
    on_frames: &mut dyn FnMut(usize),
) -> Result<Upscaled> {
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
    params.validate()?;
    domain.validate()?;
    let r = model.scale();
    let (hh, hw) = (r * h, r * w);
    let mut out = Upscaled {
        hr: Tensor::zeros(&[0, 3, hh, hw]),
        interpolated: Tensor::zeros(&[t, 3, hh, hw]),
        residual: Tensor::zeros(&[t, 3, hh, hw]),
        boundary: Tensor::zeros(&[t, 1, hh, hw]),
        enhance: Tensor::zeros(&[t, 1, hh, hw]),
        enhance_ran: params.eta != 0.0 || params.enhance_map,
        maps: Vec::with_capacity(t),
        lr_net: Tensor::zeros(&[t, 3, h, w]),
        strain_iters: if model.input_frame() == InputFrame::Cloth { params.strain_iters } else { 0 },
        keep_outline: params.keep_outline && !params.pin_border && model.input_frame() == InputFrame::Cloth,
        gate_coarse_only: params.gate_coarse_only,
    };
    let (px3, px1) = (3 * hh * hw, hh * hw);
    // Every conv's weights packed once for all batches and mirror views.
    let nets = model.packed();
    let mut done = 0;
    while done < t {
        let n = params.batch.min(t - done);
        out.maps.extend((done..done + n).map(|f| model.input_frame().image_maps(lr, f, domain)));
        let mut x = lr.slice_batch(done, n);
        for (img, m) in x.data.chunks_exact_mut(3 * h * w).zip(&out.maps[done..]) {
            m.0.apply_image(img, true);
        }
        out.lr_net.data[done * 3 * h * w..(done + n) * 3 * h * w].copy_from_slice(&x.data);
        let o = nets.forward_with(ops, &x, out.enhance_ran)?;
        let (r_at, m_at) = (done * px3..(done + n) * px3, done * px1..(done + n) * px1);
        out.interpolated.data[r_at.clone()].copy_from_slice(&o.u.data);
        out.residual.data[r_at.clone()].copy_from_slice(&o.r.data);
        out.boundary.data[m_at.clone()].copy_from_slice(&o.boundary.data);
        out.enhance.data[m_at.clone()].copy_from_slice(&o.enhance.data);
        // The other mirrors of the grid, each in its own frame; their outputs back onto this one.
        let mirrors = if params.mirrors { &GRID_MIRRORS[1..] } else { &[] };
        let frame = model.input_frame();
        let add = |acc: &mut [f32], t: &Tensor| acc.iter_mut().zip(&t.data).for_each(|(a, b)| *a += b);
        for &(rows, cols) in mirrors {
            let o =
                nets.forward_with(ops, &mirror_net_images(&x, rows, cols, frame, true), out.enhance_ran)?;
            add(&mut out.residual.data[r_at.clone()], &mirror_net_images(&o.r, rows, cols, frame, false));
            add(&mut out.boundary.data[m_at.clone()], &o.boundary.flipped(rows, cols));
            add(&mut out.enhance.data[m_at.clone()], &o.enhance.flipped(rows, cols));
        }
        if !mirrors.is_empty() {
            let s = 1.0 / (1 + mirrors.len()) as f32;
            out.residual.data[r_at].iter_mut().for_each(|v| *v *= s);
            out.enhance.data[m_at.clone()].iter_mut().for_each(|v| *v *= s);
            out.boundary.data[m_at.clone()].iter_mut().for_each(|v| *v *= s);
        }
        if params.pin_border {
            let mut b = out.boundary.slice_batch(done, n);
            set_border(&mut b, 1.0);
            out.boundary.data[m_at].copy_from_slice(&b.data);
        }
        done += n;
        on_frames(done);
    }
    Ok(out)
}

/// Steps 2–3 of [`upscale_images`] on [`run_nets`]'s output for consecutive frames: temporal
/// smoothing (the window renormalised at `raw`'s ends), back to the sequence's domain, Eq 12
/// and the strain limit.
pub fn finish(mut out: Upscaled, model: &AnisoCb, params: &UpscaleParams) -> Result<Upscaled> {
    let px3 = out.interpolated.len() / out.interpolated.shape[0].max(1);
    // 2. Temporal smoothing of R where it is comparable across frames: in the cloth frame a
    //    wrinkle that stays on the cloth has the same residual whatever the cloth does. The
    //    maps that gate R in Eq 12 get the same window: a gate that flickers makes the detail
    //    flicker however smooth R is.
    if params.temporal > 0 && model.input_frame() == InputFrame::Cloth {
        out.residual = smooth_in_time(&out.residual, params.temporal);
        out.boundary = smooth_in_time(&out.boundary, params.temporal);
        if out.enhance_ran {
            out.enhance = smooth_in_time(&out.enhance, params.temporal);
        }
    }
    // 3. Back to the sequence's domain, then Eq 12 and the strain limit (`with_eta`).
    if model.input_frame() != InputFrame::Domain {
        for (k, m) in out.maps.iter().enumerate() {
            let at = k * px3..(k + 1) * px3;
            m.1.apply_image(&mut out.interpolated.data[at.clone()], true);
            m.1.apply_image(&mut out.residual.data[at], false);
        }
    }
    out.hr = out.with_eta(params.eta)?;
    if let Some((i, v)) = out.hr.first_non_finite() {
        return Err(Error::numeric(format!(
            "the network produced a non-finite value {v} in frame {} (bad weights file?)",
            i / px3
        )));
    }
    check_detail_size(&out.hr, &out.interpolated)?;
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

/// Texture coordinates of the HR grid (`r·w × r·h`, row-major) from the LR grid's `uv`
/// (`w × h`): bilinear with corners aligned, so the border, the corners and every LR vertex's
/// UV stay exactly where they were (no seam or texture edge moves), and a uniformly unwrapped
/// sheet gets the uniform UVs its HR truth has. Not a cubic: Keys' bicubic (a = −0.75) does
/// not reproduce a linear function (12 → 24 vertices puts u = 0.4825 where the uniform layout
/// has 0.4783, 0.4 % of the texture's width), and Catmull-Rom does only away from the clamped
/// border; either would squeeze and stretch the texture in a pattern tied to the grid.
pub fn upscale_uv(uv: &[[f32; 2]], w: usize, h: usize, r: usize) -> Vec<[f32; 2]> {
    let mut t = Tensor::zeros(&[1, 2, h, w]);
    for (v, p) in uv.iter().enumerate() {
        t.data[v] = p[0];
        t.data[h * w + v] = p[1];
    }
    let up = crate::ops::resample::resize_ref(&t, r * h, r * w, crate::ops::Interp::Bilinear);
    let px = r * r * h * w;
    (0..px).map(|v| [up.data[v], up.data[px + v]]).collect()
}

/// Pull the row edges (H × (W − 1), lengths `lx`) and column edges ((H − 1) × W, `ly`) of one
/// (3, H, W) geometry image toward their target lengths: `iters` Jacobi sweeps, each moving
/// both ends of every edge by half its length error along the edge (averaged over a vertex's
/// edges); the border does not move, so the outline stays the interpolated input's.
pub fn limit_strain(img: &mut [f32], h: usize, w: usize, lx: &[f32], ly: &[f32], iters: usize) {
    let px = h * w;
    let mut delta = vec![0.0f32; 3 * px];
    let mut count = vec![0u32; px];
    for _ in 0..iters {
        delta.iter_mut().for_each(|d| *d = 0.0);
        count.iter_mut().for_each(|c| *c = 0);
        for y in 0..h {
            for x in 0..w {
                let a = y * w + x;
                let row = (x + 1 < w).then(|| (a + 1, lx[y * (w - 1) + x]));
                let col = (y + 1 < h).then(|| (a + w, ly[a]));
                for (b, rest) in [row, col].into_iter().flatten() {
                    let d: [f32; 3] = std::array::from_fn(|c| img[c * px + b] - img[c * px + a]);
                    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                    if len <= 0.0 {
                        continue;
                    }
                    let k = 0.5 * (len - rest) / len;
                    for c in 0..3 {
                        delta[c * px + a] += k * d[c];
                        delta[c * px + b] -= k * d[c];
                    }
                    count[a] += 1;
                    count[b] += 1;
                }
            }
        }
        for y in 1..h.saturating_sub(1) {
            for x in 1..w.saturating_sub(1) {
                let a = y * w + x;
                if count[a] > 0 {
                    for c in 0..3 {
                        img[c * px + a] += delta[c * px + a] / count[a] as f32;
                    }
                }
            }
        }
    }
}

/// `x` (T, C, H, W) averaged over time per pixel with binomial weights of radius `k` (row 2k of
/// Pascal's triangle), the weights renormalised where the window leaves the sequence. Each
/// row is halved as it is built (row n sums to 1), so no radius overflows; callers bound `k`
/// ([`MAX_TEMPORAL`]) because the cost is O(k²) + O(k) per frame.
pub fn smooth_in_time(x: &Tensor, k: usize) -> Tensor {
    let t = x.shape[0];
    let per = x.len() / t.max(1);
    let mut w = vec![1.0f64];
    for _ in 0..2 * k {
        let mut next = vec![0.0f64; w.len() + 1];
        for (i, wi) in w.iter().enumerate() {
            next[i] += 0.5 * wi;
            next[i + 1] += 0.5 * wi;
        }
        w = next;
    }
    let mut out = Tensor::zeros(&x.shape);
    for f in 0..t {
        let lo = f.saturating_sub(k);
        let hi = (f + k).min(t - 1);
        let norm: f64 = (lo..=hi).map(|g| w[g + k - f]).sum();
        let dst = &mut out.data[f * per..(f + 1) * per];
        for g in lo..=hi {
            let wg = (w[g + k - f] / norm) as f32;
            for (d, s) in dst.iter_mut().zip(&x.data[g * per..(g + 1) * per]) {
                *d += wg * s;
            }
        }
    }
    out
}

/// Length of the closed loop through pixels `ring` of one planar image `img` (3 × px):
/// `Σ_k |p_{k+1} − p_k|`, the last back to the first.
pub fn loop_length(img: &[f32], ring: &[usize]) -> f32 {
    loop_length_blend(img, img, 1.0, ring)
}

/// [`loop_length`] of `base + a (hr − base)` (planar 3 × px images), accumulated in f64.
fn loop_length_blend(hr: &[f32], base: &[f32], a: f32, ring: &[usize]) -> f32 {
    let px = hr.len() / 3;
    let at = |v: usize| -> [f64; 3] {
        std::array::from_fn(|c| (base[c * px + v] + a * (hr[c * px + v] - base[c * px + v])) as f64)
    };
    closed_loop_length(ring, at) as f32
}

/// What the outline floor scales toward: `hr` (planar 3 × rH × rW, composed over the
/// interpolation `u`) with, on the two outermost rings, the component of the correction
/// hr − u along U's surface normal removed. U's normal at a pixel is the cross product of its
/// grid derivatives (central differences, one-sided at the border); where it is degenerate
/// nothing is removed. The normal component is what flattens a hem's folds; the in-plane
/// part of the correction, which places the border, is kept.
pub fn outline_base(hr: &[f32], u: &[f32], hh: usize, hw: usize) -> Vec<f32> {
    let px = hh * hw;
    let at = |img: &[f32], v: usize| -> [f32; 3] { std::array::from_fn(|c| img[c * px + v]) };
    let mut base = hr.to_vec();
    for r in 0..2 {
        for v in ring_loop(hw, hh, r) {
            let (x, y) = (v % hw, v / hw);
            let (x0, x1) = (y * hw + x.saturating_sub(1), y * hw + (x + 1).min(hw - 1));
            let (y0, y1) = (y.saturating_sub(1) * hw + x, (y + 1).min(hh - 1) * hw + x);
            let n = cross(sub(at(u, x1), at(u, x0)), sub(at(u, y1), at(u, y0)));
            let len = norm(n);
            if len.is_nan() || len <= 1e-12 {
                continue;
            }
            let n = n.map(|c| c / len);
            let d = dot(sub(at(hr, v), at(u, v)), n);
            for c in 0..3 {
                base[c * px + v] -= d * n[c];
            }
        }
    }
    base
}

/// The outline floor's weight for one frame: the largest α ∈ [0, 1] (to 2⁻²⁰, by bisection)
/// whose border loop `ring` ([`border_loop`] of the rW × rH grid) of `base + α (hr − base)`
/// (planar 3 × rH × rW images; `base` from [`outline_base`]) is at least `floor` long; 1 if `hr`'s already is, 0 if not even `base`'s.
pub fn outline_weight(hr: &[f32], base: &[f32], ring: &[usize], floor: f32) -> f32 {
    let len = |a: f32| loop_length_blend(hr, base, a, ring);
    if len(1.0) >= floor {
        return 1.0;
    }
    if len(0.0) < floor {
        return 0.0;
    }
    // len(lo) ≥ floor > len(hi) throughout.
    let (mut lo, mut hi) = (0.0f32, 1.0f32);
    for _ in 0..20 {
        let mid = 0.5 * (lo + hi);
        if len(mid) >= floor {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

/// `hr ← base + w (hr − base)` with w = α on the border ring of the planar 3 × rH × rW images
/// and (1 + α)/2 on the ring inside it (no step between the two rings and the interior's full
/// weight).
pub fn blend_outer_rings(hr: &mut [f32], base: &[f32], hh: usize, hw: usize, a: f32) {
    let px = hh * hw;
    for (r, w) in [(0, a), (1, 0.5 * (1.0 + a))] {
        for v in ring_loop(hw, hh, r) {
            for c in 0..3 {
                let i = c * px + v;
                hr[i] = base[i] + w * (hr[i] - base[i]);
            }
        }
    }
}

/// Set the border pixels of every (N, 1, H, W) map to `v`.
pub fn set_border(map: &mut Tensor, v: f32) {
    let (n, c, h, w) = map.dims4();
    for plane in map.data.chunks_exact_mut(h * w).take(n * c) {
        for x in 0..w {
            plane[x] = v;
            plane[(h - 1) * w + x] = v;
        }
        for y in 0..h {
            plane[y * w] = v;
            plane[y * w + w - 1] = v;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flat `w × h` grid (planar 3 × h × w image) with spacing 1, its border ring pulled
    /// toward the centre by `pull` (a shorter outline).
    fn flat_with_border_pulled(w: usize, h: usize, pull: f32) -> Vec<f32> {
        let px = w * h;
        let mut img = vec![0.0f32; 3 * px];
        let (cx, cy) = ((w - 1) as f32 / 2.0, (h - 1) as f32 / 2.0);
        for j in 0..h {
            for i in 0..w {
                let border = i == 0 || j == 0 || i == w - 1 || j == h - 1;
                let s = if border { 1.0 - pull } else { 1.0 };
                img[j * w + i] = cx + s * (i as f32 - cx);
                img[px + j * w + i] = cy + s * (j as f32 - cy);
            }
        }
        img
    }

    #[test]
    fn outline_weight_is_the_largest_blend_whose_border_reaches_the_floor() {
        let (w, h) = (9, 7);
        let ring = border_loop(w, h);
        let u = flat_with_border_pulled(w, h, 0.0);
        let hr = flat_with_border_pulled(w, h, 0.1); // 10 % shorter outline
        let (lu, lh) = (loop_length(&u, &ring), loop_length(&hr, &ring));
        assert!((lu - 2.0 * (8.0 + 6.0)).abs() < 1e-5 && (lh - 0.9 * lu).abs() < 1e-4, "{lu} {lh}");
        // Long enough already: 1; not even U: 0; in between: where the length crosses the floor.
        assert_eq!(outline_weight(&hr, &u, &ring, lh), 1.0);
        assert_eq!(outline_weight(&hr, &u, &ring, 1.01 * lu), 0.0);
        let floor = 0.95 * lu;
        let a = outline_weight(&hr, &u, &ring, floor);
        let len = |a: f32| loop_length_blend(&hr, &u, a, &ring);
        assert!(len(a) >= floor && len(a + 1e-5) < floor, "α = {a}: {} vs floor {floor}", len(a));
        assert!((a - 0.5).abs() < 1e-4, "the outline shrinks linearly with α here: α = {a}");
    }

    #[test]
    fn outline_base_removes_only_the_normal_part_of_the_correction_on_two_rings() {
        // U: the flat grid z = 0 (normal ±z everywhere); hr: U moved in x, y and z everywhere.
        let (w, h) = (9, 8);
        let px = w * h;
        let u = flat_with_border_pulled(w, h, 0.0);
        let mut hr = u.clone();
        for v in 0..px {
            hr[v] += 0.1 + 0.01 * v as f32;
            hr[px + v] -= 0.2;
            hr[2 * px + v] += 0.3 + 0.02 * (v % 5) as f32;
        }
        let base = outline_base(&hr, &u, h, w);
        for v in 0..px {
            let (i, j) = (v % w, v / w);
            let outer = i.min(j).min(w - 1 - i).min(h - 1 - j) < 2;
            assert_eq!([base[v], base[px + v]], [hr[v], hr[px + v]], "in-plane part kept at ({i}, {j})");
            let want_z = if outer { u[2 * px + v] } else { hr[2 * px + v] };
            assert!(
                (base[2 * px + v] - want_z).abs() < 1e-6,
                "({i}, {j}): z {} vs {want_z}",
                base[2 * px + v]
            );
        }
    }

    #[test]
    fn blend_outer_rings_scales_the_correction_on_two_rings_only() {
        let (w, h, a) = (8, 6, 0.25f32);
        let u = vec![1.0f32; 3 * w * h];
        let mut hr: Vec<f32> = (0..3 * w * h).map(|k| 1.0 + (k % 7) as f32).collect();
        let before = hr.clone();
        blend_outer_rings(&mut hr, &u, h, w, a);
        for c in 0..3 {
            for j in 0..h {
                for i in 0..w {
                    let k = c * w * h + j * w + i;
                    let want = match i.min(j).min(w - 1 - i).min(h - 1 - j) {
                        0 => 1.0 + a * (before[k] - 1.0),
                        1 => 1.0 + 0.5 * (1.0 + a) * (before[k] - 1.0),
                        _ => before[k],
                    };
                    assert!((hr[k] - want).abs() < 1e-6, "({c}, {j}, {i}): {} vs {want}", hr[k]);
                }
            }
        }
    }

    /// A flat (3, h, w) grid with spacing `d`, plus `noise`·(pseudo-random) on every channel.
    fn grid(h: usize, w: usize, d: f32, noise: f32) -> Vec<f32> {
        let px = h * w;
        let mut img = vec![0.0f32; 3 * px];
        for p in 0..px {
            let jitter = |c: usize| noise * (((p * 7 + c * 13) % 11) as f32 / 5.0 - 1.0);
            img[p] = (p % w) as f32 * d + jitter(0);
            img[px + p] = (p / w) as f32 * d + jitter(1);
            img[2 * px + p] = jitter(2);
        }
        img
    }

    #[test]
    fn strain_limit_pulls_edges_to_the_lr_lengths_and_keeps_the_border() {
        let (h, w) = (5, 6);
        let lr = grid(h, w, 0.2, 0.0);
        let (hh, hw) = (2 * h, 2 * w);
        let (lx, ly) = hr_edge_targets(&lr, h, w, hh, hw);
        // A flat LR grid of spacing 0.2 over (w − 1) cells → HR spacing 0.2·(w − 1)/(2w − 1).
        assert!(lx.iter().all(|&l| (l - 0.2 * 5.0 / 11.0).abs() < 1e-6));
        assert!(ly.iter().all(|&l| (l - 0.2 * 4.0 / 9.0).abs() < 1e-6));
        let mut img = grid(hh, hw, 0.2 * 5.0 / 11.0, 0.01);
        let before = img.clone();
        let err = |img: &[f32]| {
            let px = hh * hw;
            let mut e = 0.0f32;
            for y in 0..hh {
                for x in 0..hw - 1 {
                    let a = y * hw + x;
                    let l =
                        (0..3).map(|c| (img[c * px + a + 1] - img[c * px + a]).powi(2)).sum::<f32>().sqrt();
                    e += (l - lx[y * (hw - 1) + x]).abs();
                }
            }
            e
        };
        limit_strain(&mut img, hh, hw, &lx, &ly, 20);
        assert!(err(&img) < 0.5 * err(&before), "{} → {}", err(&before), err(&img));
        for p in 0..hh * hw {
            let (y, x) = (p / hw, p % hw);
            if y == 0 || x == 0 || y + 1 == hh || x + 1 == hw {
                for c in 0..3 {
                    assert_eq!(img[c * hh * hw + p], before[c * hh * hw + p], "border vertex {p} moved");
                }
            }
        }
    }

    #[test]
    fn temporal_smoothing_keeps_constant_detail_and_averages_flicker() {
        // Frame f holds the value c + (−1)^f·a in every pixel.
        let (t, per) = (7, 5);
        let x = Tensor {
            shape: vec![t, 1, 1, per],
            data: (0..t * per).map(|i| 2.0 + if (i / per) % 2 == 0 { 0.5 } else { -0.5 }).collect(),
        };
        let y = smooth_in_time(&x, 1);
        // Interior frames: ¼(c ∓ a) + ½(c ± a) + ¼(c ∓ a) = c: flicker at the frame rate is
        // removed entirely.
        for f in 1..t - 1 {
            assert!((y.data[f * per] - 2.0).abs() < 1e-6, "frame {f}: {}", y.data[f * per]);
        }
        // Ends renormalised: frame 0 = (½·2.5 + ¼·1.5)/¾.
        assert!((y.data[0] - (0.5 * 2.5 + 0.25 * 1.5) / 0.75).abs() < 1e-6);
        // A constant sequence is unchanged, and radius 0 is the identity.
        let c = Tensor { shape: vec![4, 1, 1, 3], data: vec![0.3; 12] };
        assert!(smooth_in_time(&c, 2).max_abs_diff(&c) < 1e-7);
        assert_eq!(smooth_in_time(&x, 0).data, x.data);
    }
}
