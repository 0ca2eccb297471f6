//! The wrinkle-detail metric (issue 30, docs/research/wrinkles.md): D(X) = (X − S(X))·n, the part of
//! an HR frame its Catmull-Rom round trip through the LR grid does not hold, along the normals
//! of that round trip; its RMS, correlation with the truth's and frame-to-frame change.

use super::metrics::same_grid;
use crate::error::{Error, Result};
pub use crate::geom::geometry_image::lr_round_trip;
use crate::geom::vec3::{cross, dot, sub};
use crate::geom::GridMesh;
use crate::io::json::{Object, Value};
use rayon::prelude::*;

/// Unit normals of a grid from its grid derivatives, `n = ∂p/∂i × ∂p/∂j` normalised (i the
/// column, j the row; central differences inside, one-sided at the border). This sign points
/// to −z for [`GridMesh::flat`] (rows going down in y), the opposite of
/// [`crate::geom::mesh::vertex_normals`]; where the cross product vanishes the normal is 0. In f64, stored f32.
pub fn grid_normals(mesh: &GridMesh) -> Vec<[f32; 3]> {
    let (w, h) = (mesh.w, mesh.h);
    let p = |i: usize, j: usize| mesh.pos[j * w + i].map(f64::from);
    // Central difference along one axis of `n` samples at k, one-sided at the ends.
    let diff = |k: usize, n: usize, at: &dyn Fn(usize) -> [f64; 3]| -> [f64; 3] {
        let (a, b) = (k.saturating_sub(1), (k + 1).min(n - 1));
        let span = (b - a).max(1) as f64;
        sub(at(b), at(a)).map(|c| c / span)
    };
    let mut out = Vec::with_capacity(w * h);
    for j in 0..h {
        for i in 0..w {
            let di = diff(i, w, &|k| p(k, j));
            let dj = diff(j, h, &|k| p(i, k));
            out.push(crate::geom::vec3::normalize_or(cross(di, dj), [0.0; 3]).map(|c| c as f32));
        }
    }
    out
}

/// Rings of vertices the wrinkle detail leaves out on every side (the clamped border of the
/// resampling and the one-sided normals live there).
pub const WRINKLE_RING: usize = 2;

/// Wrinkle detail of one frame: the detail the LR grid cannot hold, measured along the
/// surface, `D = (X − S(X)) · n` with `S` = [`lr_round_trip`] to the `lr_w × lr_h` grid (the
/// size of the LR input the method upscaled) and `n` = [`grid_normals`] of S(X), in metres.
/// Over the interior only: rows `2..h−2` outer, columns `2..w−2` inner, `(h−4)·(w−4)` values.
/// Invariant under rigid motions (the resampling's weights sum to 1).
pub fn wrinkle_detail(frame: &GridMesh, lr_w: usize, lr_h: usize) -> Result<Vec<f32>> {
    let r = WRINKLE_RING;
    if frame.w < 2 * r + 1 || frame.h < 2 * r + 1 || frame.pos.len() != frame.w * frame.h {
        return Err(Error::shape(format!("wrinkle detail: grid {}x{} has no interior", frame.w, frame.h)));
    }
    if lr_w < 2 || lr_h < 2 {
        return Err(Error::shape(format!("wrinkle detail: LR grid {lr_w}x{lr_h} is smaller than 2x2")));
    }
    let s = lr_round_trip(frame, lr_w, lr_h);
    let n = grid_normals(&s);
    let mut d = Vec::with_capacity((frame.h - 2 * r) * (frame.w - 2 * r));
    for j in r..frame.h - r {
        for i in r..frame.w - r {
            let v = j * frame.w + i;
            let off = sub(frame.pos[v].map(f64::from), s.pos[v].map(f64::from));
            d.push(dot(off, n[v].map(f64::from)) as f32);
        }
    }
    Ok(d)
}

/// Wrinkle detail of a predicted sequence against the truth's ([`wrinkle_detail`], `D` and
/// `D_g`); sums over all frames and interior vertices, in f64.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WrinkleStats {
    /// RMS(D) of the prediction, mm.
    pub rms_mm: f32,
    /// RMS(D_g) of the truth, mm (the same for every method on a run).
    pub truth_rms_mm: f32,
    /// RMS(D) / RMS(D_g): 0 = no detail beyond the LR grid (an interpolation), 1 = as much as
    /// the truth.
    pub ratio: f32,
    /// `Σ D·D_g / √(Σ D² Σ D_g²)`: 1 = the truth's wrinkles in the truth's places.
    pub corr: f32,
    /// RMS(D(t+1) − D(t)) / the truth's: > 1 = wrinkles that change faster than the truth's
    /// (NaN for fewer than 2 frames).
    pub change_ratio: f32,
}

impl WrinkleStats {
    /// Field names in the order of [`WrinkleStats::values`] (JSON keys).
    pub const NAMES: [&'static str; 5] = ["rms_mm", "truth_rms_mm", "ratio", "corr", "change_ratio"];

    pub fn values(&self) -> [f32; 5] {
        [self.rms_mm, self.truth_rms_mm, self.ratio, self.corr, self.change_ratio]
    }

    /// A JSON object with the [`WrinkleStats::NAMES`] keys (non-finite values as `null`).
    pub fn to_value(&self) -> Value {
        let o =
            Self::NAMES.iter().zip(self.values()).fold(Object::new(), |o, (k, v)| o.val(k, Value::finite(v)));
        o.into()
    }
}

/// [`WrinkleStats`] of `pred` against `truth` (same grids, same frame count), the wrinkle
/// detail taken against the `lr_w × lr_h` grid the methods upscaled.
pub fn wrinkle_stats(
    pred: &[GridMesh],
    truth: &[GridMesh],
    lr_w: usize,
    lr_h: usize,
) -> Result<WrinkleStats> {
    if pred.is_empty() || pred.len() != truth.len() {
        return Err(Error::shape(format!(
            "wrinkle stats: {} predicted frames vs {} ground truth",
            pred.len(),
            truth.len()
        )));
    }
    for (p, g) in pred.iter().zip(truth) {
        same_grid(p, g)?;
    }
    let detail = |seq: &[GridMesh]| -> Result<Vec<Vec<f32>>> {
        seq.par_iter().map(|m| wrinkle_detail(m, lr_w, lr_h)).collect()
    };
    let (dp, dg) = (detail(pred)?, detail(truth)?);
    // Σ over frames and vertices of f(a, b), in f64.
    let sum = |a: &[Vec<f32>], b: &[Vec<f32>], f: &dyn Fn(f64, f64) -> f64| -> f64 {
        a.iter().flatten().zip(b.iter().flatten()).map(|(&x, &y)| f(x as f64, y as f64)).sum()
    };
    let count = (dp.len() * dp[0].len()) as f64;
    let (spp, sgg, spg) =
        (sum(&dp, &dp, &|x, _| x * x), sum(&dg, &dg, &|_, y| y * y), sum(&dp, &dg, &|x, y| x * y));
    // Mean square of D(t+1) − D(t) over the T − 1 steps.
    let change = |d: &[Vec<f32>]| -> f64 {
        let s = sum(&d[1..], &d[..d.len() - 1], &|x, y| (x - y) * (x - y));
        s / ((d.len() - 1) * d[0].len()) as f64
    };
    let (rp, rg) = ((spp / count).sqrt(), (sgg / count).sqrt());
    Ok(WrinkleStats {
        rms_mm: (1e3 * rp) as f32,
        truth_rms_mm: (1e3 * rg) as f32,
        ratio: (rp / rg) as f32,
        corr: (spg / (spp * sgg).sqrt()) as f32,
        change_ratio: (change(&dp) / change(&dg)).sqrt() as f32,
    })
}
