//! The learned linear upsampler: the cheap yardstick a network must beat to be worth its cost
//! (in the spirit of Kavan et al. 2011, "Physics-inspired upsampling for cloth simulation in
//! games": a linear map from the coarse mesh to the fine detail, fitted by least squares).
//!
//! In the nets' coordinates (the cloth frame of each LR frame, see `geom::cloth_frame`), the
//! detail of the r×r HR block of LR pixel (y, x) is predicted from its 3×3 LR neighbourhood:
//!
//! `R[block(y, x)] = Wᵀ · φ(y, x)`,  φ = (p(y+dy, x+dx) − p(y, x) for the 8 neighbours, 1)
//!
//! (24 relative coordinates and a bias: 25 features; neighbours outside the grid replicate the
//! border pixel), `W` (25 × 3r²) one matrix for the whole cloth, fitted by ridge regression
//! `W = (ΦᵀΦ + λ·n·I)⁻¹ ΦᵀY` over every LR pixel of the training frames (the bias is not
//! shrunk), with `Y` the target residual `HR − U` of the block. The normal equations are
//! accumulated in f64 and solved with faer's Cholesky.

use crate::error::{Error, Result};
use crate::geom::cloth_frame::InputFrame;
use crate::io::json::Object;
use crate::io::NpzEntries;
use crate::ops::Interp;
use crate::tensor::Tensor;
use std::path::Path;

/// Features per LR pixel: 8 neighbours × xyz relative to the centre, and a bias.
pub const FEATURES: usize = 25;

/// A fitted linear upsampler.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearUpsampler {
    /// Upscale factor r.
    pub scale: usize,
    /// (FEATURES, 3·r²) row-major: output `c·r² + sy·r + sx` is channel c of HR pixel
    /// (r·y + sy, r·x + sx).
    pub weight: Vec<f64>,
    /// Ridge strength λ (dimensionless: relative to the mean diagonal of ΦᵀΦ/n).
    pub lambda: f64,
    /// The coordinates it was fitted in (and must be applied in).
    pub input_frame: InputFrame,
    /// The interpolation `U` its residual is added to (`config.json` key `upsample`, default
    /// bicubic).
    pub upsample: Interp,
}

/// φ(y, x) of one (3, H, W) image.
fn features(img: &[f32], h: usize, w: usize, y: usize, x: usize, out: &mut [f64; FEATURES]) {
    let at = |c: usize, yy: usize, xx: usize| img[(c * h + yy) * w + xx] as f64;
    let mut k = 0;
    for dy in [-1isize, 0, 1] {
        for dx in [-1isize, 0, 1] {
            if dy == 0 && dx == 0 {
                continue;
            }
            let yy = (y as isize + dy).clamp(0, h as isize - 1) as usize;
            let xx = (x as isize + dx).clamp(0, w as isize - 1) as usize;
            for c in 0..3 {
                out[k] = at(c, yy, xx) - at(c, y, x);
                k += 1;
            }
        }
    }
    out[FEATURES - 1] = 1.0;
}

impl LinearUpsampler {
    /// Fit on `lr` (N, 3, H, W) and the target residual `target = HR − U` (N, 3, rH, rW), both
    /// in `input_frame` coordinates, `U` interpolated with `upsample`.
    pub fn fit(
        lr: &Tensor,
        target: &Tensor,
        lambda: f64,
        input_frame: InputFrame,
        upsample: Interp,
    ) -> Result<LinearUpsampler> {
        let (n, c, h, w) = lr.expect_rank4("linear fit: lr")?;
        let (tn, tc, th, tw) = target.expect_rank4("linear fit: target")?;
        let r = th / h.max(1);
        if c != 3 || tc != 3 || tn != n || r == 0 || th != r * h || tw != r * w || n == 0 {
            return Err(Error::shape(format!(
                "linear fit: lr {:?} and residual {:?} are not an (N, 3, H, W) / (N, 3, rH, rW) pair",
                lr.shape, target.shape
            )));
        }
        if !(lambda.is_finite() && lambda >= 0.0) {
            return Err(Error::config(format!("ridge λ must be finite and ≥ 0, got {lambda}")));
        }
        let outs = 3 * r * r;
        let mut ata = vec![0.0f64; FEATURES * FEATURES];
        let mut aty = vec![0.0f64; FEATURES * outs];
        let mut phi = [0.0f64; FEATURES];
        let mut yv = vec![0.0f64; outs];
        for f in 0..n {
            let img = &lr.data[f * 3 * h * w..(f + 1) * 3 * h * w];
            let res = &target.data[f * 3 * th * tw..(f + 1) * 3 * th * tw];
            for y in 0..h {
                for x in 0..w {
                    features(img, h, w, y, x, &mut phi);
                    block(res, th, tw, r, y, x, &mut yv);
                    for i in 0..FEATURES {
                        for j in 0..FEATURES {
                            ata[i * FEATURES + j] += phi[i] * phi[j];
                        }
                        for o in 0..outs {
                            aty[i * outs + o] += phi[i] * yv[o];
                        }
                    }
                }
            }
        }
        let rows = (n * h * w) as f64;
        let mean_diag = (0..FEATURES - 1).map(|i| ata[i * FEATURES + i]).sum::<f64>() / (FEATURES - 1) as f64;
        let a = faer::Mat::<f64>::from_fn(FEATURES, FEATURES, |i, j| {
            let ridge = if i == j && i < FEATURES - 1 { lambda * mean_diag.max(1e-30) } else { 0.0 };
            (ata[i * FEATURES + j] + ridge) / rows
        });
        let b = faer::Mat::<f64>::from_fn(FEATURES, outs, |i, o| aty[i * outs + o] / rows);
        let x = match a.as_ref().llt(faer::Side::Lower) {
            Ok(llt) => faer::linalg::solvers::Solve::solve(&llt, &b),
            // Rank-deficient data (e.g. one flat frame) without ridge: least squares by LU
            // with partial pivoting would amplify noise; ask for a ridge instead.
            Err(_) => return Err(Error::numeric(
                "linear fit: the normal equations are singular (too little or too uniform data); use λ > 0",
            )),
        };
        let weight = (0..FEATURES * outs).map(|k| x[(k / outs, k % outs)]).collect::<Vec<_>>();
        if weight.iter().any(|v| !v.is_finite()) {
            return Err(Error::numeric("linear fit produced non-finite weights"));
        }
        Ok(LinearUpsampler { scale: r, weight, lambda, input_frame, upsample })
    }

    /// The predicted residual (N, 3, rH, rW) of `lr` (N, 3, H, W), in the fitted coordinates.
    pub fn residual(&self, lr: &Tensor) -> Result<Tensor> {
        let (n, c, h, w) = lr.expect_rank4("linear upsampler input")?;
        if c != 3 {
            return Err(Error::shape(format!("linear upsampler input must have 3 channels, got {c}")));
        }
        let r = self.scale;
        let outs = 3 * r * r;
        let (th, tw) = (r * h, r * w);
        let mut out = Tensor::zeros(&[n, 3, th, tw]);
        let mut phi = [0.0f64; FEATURES];
        for f in 0..n {
            let img = &lr.data[f * 3 * h * w..(f + 1) * 3 * h * w];
            let dst = &mut out.data[f * 3 * th * tw..(f + 1) * 3 * th * tw];
            for y in 0..h {
                for x in 0..w {
                    features(img, h, w, y, x, &mut phi);
                    for o in 0..outs {
                        let v: f64 = (0..FEATURES).map(|i| phi[i] * self.weight[i * outs + o]).sum();
                        let (ch, sy, sx) = (o / (r * r), (o / r) % r, o % r);
                        dst[(ch * th + r * y + sy) * tw + r * x + sx] = v as f32;
                    }
                }
            }
        }
        Ok(out)
    }

    /// As `.npz`: `linear.weight` (FEATURES, 3r²) f32... kept in f64 precision as two f32
    /// arrays would lose nothing a residual of millimetres needs, so one f32 array, plus
    /// `config.json` (`{"format": "anisocb-linear", "scale", "lambda", "input"}`).
    pub fn to_npz(&self) -> NpzEntries {
        let mut e = NpzEntries::default();
        let outs = 3 * self.scale * self.scale;
        e.push_array(
            "linear.weight",
            Tensor { shape: [FEATURES, outs].into(), data: self.weight.iter().map(|&v| v as f32).collect() },
        );
        let cfg = Object::default()
            .str("format", "anisocb-linear")
            .num("version", 1)
            .num("scale", self.scale)
            .num("lambda", self.lambda)
            .str("input", self.input_frame.name())
            .str("upsample", self.upsample.name())
            .to_json();
        e.push_file("config.json", cfg.into_bytes());
        e
    }

    /// Read a weights file `anisocb train --net linear` wrote (`OUT/weights.npz`).
    pub fn load(path: &Path) -> Result<LinearUpsampler> {
        LinearUpsampler::from_npz(&crate::io::read_npz(path)?, path)
    }

    /// Read what [`LinearUpsampler::to_npz`] wrote; errors name `path`.
    pub fn from_npz(e: &NpzEntries, path: &Path) -> Result<LinearUpsampler> {
        let cfg = e.file("config.json").ok_or_else(|| Error::format(path, "no config.json entry"))?;
        let o = Object::parse(&String::from_utf8_lossy(cfg)).map_err(|e| e.in_file(path))?;
        if o.get("format").and_then(|v| v.as_str()) != Some("anisocb-linear") {
            return Err(Error::format(path, "not a linear upsampler (config.json format ≠ anisocb-linear)"));
        }
        let scale = o.get("scale").and_then(|v| v.as_u64()).unwrap_or(0) as usize;
        if !(1..=16).contains(&scale) {
            return Err(Error::format(path, format!("config.json: bad scale {scale}")));
        }
        let input_frame = InputFrame::parse(o.get("input").and_then(|v| v.as_str()).unwrap_or("domain"))
            .map_err(|e| e.in_file(path))?;
        let upsample = match o.get("upsample") {
            None => Interp::Bicubic,
            Some(v) => v
                .as_str()
                .ok_or("'upsample' must be a string")
                .and_then(|s| {
                    crate::nn::config::parse_upsample(s)
                        .map_err(|_| "unknown 'upsample' (expected catmull-rom or bicubic)")
                })
                .map_err(|m| Error::format(path, format!("config.json: {m}")))?,
        };
        let lambda = o.get("lambda").and_then(|v| v.as_f64()).unwrap_or(0.0);
        let w = e.require(path, "linear.weight")?;
        let outs = 3 * scale * scale;
        if w.shape != [FEATURES, outs] {
            return Err(Error::format(
                path,
                format!("linear.weight has shape {:?}, expected [{FEATURES}, {outs}]", w.shape),
            ));
        }
        if let Some((i, v)) = w.first_non_finite() {
            return Err(Error::format(path, format!("linear.weight[{i}] is {v}")));
        }
        Ok(LinearUpsampler {
            scale,
            weight: w.data.iter().map(|&v| v as f64).collect(),
            lambda,
            input_frame,
            upsample,
        })
    }
}

/// The r×r HR block of LR pixel (y, x) of a (3, rH, rW) image, in output order.
fn block(img: &[f32], th: usize, tw: usize, r: usize, y: usize, x: usize, out: &mut [f64]) {
    for ch in 0..3 {
        for sy in 0..r {
            for sx in 0..r {
                out[ch * r * r + sy * r + sx] = img[(ch * th + r * y + sy) * tw + r * x + sx] as f64;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn linear_fit_recovers_a_linear_detail_map_exactly() {
        // Residual = a fixed linear function of the neighbourhood: the fit must find it.
        let (n, h, w, r) = (3, 6, 7, 2);
        let mut lr = Tensor::zeros(&[n, 3, h, w]);
        for (k, v) in lr.data.iter_mut().enumerate() {
            *v = ((k * 7919 % 1000) as f32 / 1000.0).sin();
        }
        let truth = LinearUpsampler {
            scale: r,
            weight: (0..FEATURES * 12).map(|k| ((k * 37 % 23) as f64 - 11.0) * 1e-3).collect(),
            lambda: 0.0,
            input_frame: InputFrame::Cloth,
            upsample: Interp::CatmullRom,
        };
        let target = truth.residual(&lr).unwrap();
        let fit = LinearUpsampler::fit(&lr, &target, 0.0, InputFrame::Cloth, Interp::CatmullRom).unwrap();
        let again = fit.residual(&lr).unwrap();
        assert!(again.max_abs_diff(&target) < 1e-5, "{}", again.max_abs_diff(&target));
    }

    #[test]
    fn linear_weights_round_trip_and_a_wrong_shape_names_the_file() {
        let m = LinearUpsampler {
            scale: 2,
            weight: (0..FEATURES * 12).map(|k| k as f64 * 0.25).collect(),
            lambda: 1e-3,
            input_frame: InputFrame::Cloth,
            upsample: Interp::CatmullRom,
        };
        let p = Path::new("lin.npz");
        assert_eq!(LinearUpsampler::from_npz(&m.to_npz(), p).unwrap(), m);
        let mut bad = m.to_npz();
        bad.arrays.retain(|(n, _)| n != "linear.weight");
        bad.push_array("linear.weight", Tensor::zeros(&[FEATURES, 3]));
        let e = LinearUpsampler::from_npz(&bad, p).unwrap_err().to_string();
        assert!(e.contains("lin.npz") && e.contains("linear.weight"), "{e}");
    }
}
