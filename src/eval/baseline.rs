//! The interpolation baseline: an LR mesh sequence upscaled through its geometry images
//! (Eq 1), resized with align corners from (3, H, W) to (3, f·H, f·W), and read back (Eq 2).
//! With the `upsample` of a model's config this is exactly the `U` its networks refine.

use crate::error::{Error, Result};
use crate::geom::geometry_image::{images_to_sequence, sequence_to_images};
use crate::geom::{Domain, GridMesh};
use crate::ops::{Interp, Ops};

/// Upscales every frame of `lr` (all `w × h`) to `factor·w × factor·h` vertices by
/// interpolating the geometry images over `domain` (metres; the sequence's domain).
pub fn interpolate_sequence(
    ops: &dyn Ops,
    lr: &[GridMesh],
    domain: &Domain,
    factor: usize,
    mode: Interp,
) -> Result<Vec<GridMesh>> {
    domain.validate()?;
    if factor == 0 {
        return Err(Error::config("upscale factor must be ≥ 1"));
    }
    let Some(first) = lr.first() else {
        return Ok(Vec::new());
    };
    if let Some(bad) = lr.iter().find(|m| m.w != first.w || m.h != first.h) {
        return Err(Error::shape(format!(
            "all frames must share one grid: {}x{} vs {}x{}",
            first.w, first.h, bad.w, bad.h
        )));
    }
    let imgs = sequence_to_images(lr, domain);
    let up = ops.resize(&imgs, factor * first.h, factor * first.w, mode);
    Ok(images_to_sequence(&up, domain))
}

/// The bicubic baseline of one frame (factor 2 = the paper's ×2).
pub fn bicubic_upscale(ops: &dyn Ops, lr: &GridMesh, domain: &Domain, factor: usize) -> Result<GridMesh> {
    Ok(interpolate_sequence(ops, std::slice::from_ref(lr), domain, factor, Interp::Bicubic)?.remove(0))
}
