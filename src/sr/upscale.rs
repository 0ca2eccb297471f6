//! The upscale pipeline: LR geometry images → the nets' input frame → the three nets → Eq 12
//! → back to the geometry image's domain → HR meshes (Eq 2, with the input's domain).
//!
//! lr: (T, 3, H, W) → hr: (T, 3, rH, rW), maps (T, 1, rH, rW). Inputs and outputs are geometry
//! images in the sequence's domain (Eq 1, the format on disk); a model trained in the cloth
//! frame ([`InputFrame::Cloth`]) gets each frame re-expressed in its own frame first, and its
//! output mapped back, so the result moves, turns and scales with the input frame by frame.

use super::compose::compose;
use crate::error::{Error, Result};
use crate::geom::cloth_frame::{Affine, InputFrame};
use crate::geom::geometry_image::{images_to_sequence, sequence_to_images};
use crate::geom::{Domain, GridMesh};
use crate::io::npz::npz_from_bytes;
use crate::nn::bundle::AnisoCb;
use crate::nn::weights::bundle_from_npz;
use crate::ops::Ops;
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

/// Options of the pipeline.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UpscaleParams {
    /// Enhancement factor η of Eq 12 (dimensionless, ≥ 0); see [`super::compose::DEFAULT_ETA`].
    pub eta: f32,
    /// Frames per network forward (memory ≈ batch · 2·C·r²·H·W floats at the widest layer).
    pub batch: usize,
    /// Set Γb = 1 on the grid's border pixels: the topological border is known exactly (it is
    /// always in the ground-truth map, Eq 4–9), so the border keeps the interpolated input
    /// whatever BoundaryNet says there — no shrinkage of the cloth's outline by construction.
    pub pin_border: bool,
}

impl Default for UpscaleParams {
    fn default() -> Self {
        UpscaleParams { eta: super::compose::DEFAULT_ETA, batch: 8, pin_border: true }
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
    /// Γe (T, 1, rH, rW).
    pub enhance: Tensor,
}

impl Upscaled {
    /// Γfinal for another enhancement factor `eta`, from the same network outputs (Eq 12).
    pub fn with_eta(&self, eta: f32) -> Result<Tensor> {
        compose(&self.interpolated, &self.residual, Some(&self.boundary), Some(&self.enhance), eta)
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
    if params.batch == 0 {
        return Err(Error::config("batch must be ≥ 1"));
    }
    domain.validate()?;
    let r = model.scale();
    let (hh, hw) = (r * h, r * w);
    let mut out = Upscaled {
        hr: Tensor::zeros(&[t, 3, hh, hw]),
        interpolated: Tensor::zeros(&[t, 3, hh, hw]),
        residual: Tensor::zeros(&[t, 3, hh, hw]),
        boundary: Tensor::zeros(&[t, 1, hh, hw]),
        enhance: Tensor::zeros(&[t, 1, hh, hw]),
    };
    let (px3, px1) = (3 * hh * hw, hh * hw);
    let mut done = 0;
    while done < t {
        let n = params.batch.min(t - done);
        let maps: Vec<(Affine, Affine)> =
            (done..done + n).map(|f| model.input_frame().image_maps(lr, f, domain)).collect();
        let mut x = lr.slice_batch(done, n);
        for (img, m) in x.data.chunks_exact_mut(3 * h * w).zip(&maps) {
            m.0.apply_image(img, true);
        }
        let mut o = model.forward(ops, &x)?;
        if params.pin_border {
            set_border(&mut o.boundary, 1.0);
        }
        let mut g = compose(&o.u, &o.r, Some(&o.boundary), Some(&o.enhance), params.eta)?;
        if model.input_frame() != InputFrame::Domain {
            for (k, m) in maps.iter().enumerate() {
                let at = k * px3..(k + 1) * px3;
                m.1.apply_image(&mut g.data[at.clone()], true);
                m.1.apply_image(&mut o.u.data[at.clone()], true);
                m.1.apply_image(&mut o.r.data[at], false);
            }
        }
        out.hr.data[done * px3..(done + n) * px3].copy_from_slice(&g.data);
        out.interpolated.data[done * px3..(done + n) * px3].copy_from_slice(&o.u.data);
        out.residual.data[done * px3..(done + n) * px3].copy_from_slice(&o.r.data);
        out.boundary.data[done * px1..(done + n) * px1].copy_from_slice(&o.boundary.data);
        out.enhance.data[done * px1..(done + n) * px1].copy_from_slice(&o.enhance.data);
        done += n;
        on_frames(done);
    }
    if let Some((i, v)) = out.hr.first_non_finite() {
        return Err(Error::numeric(format!(
            "the network produced a non-finite value {v} in frame {} (bad weights file?)",
            i / px3
        )));
    }
    Ok(out)
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
