//! Losses, each returning (mean loss, gradient w.r.t. the prediction). Any shape.
//!
//! Loss sums are accumulated in f64. The fast paths thread over fixed chunks (partial sums
//! added in chunk order, so the result does not depend on the thread count); their per-element
//! gradients are the reference's expressions (bitwise equal), their loss agrees to rounding.

use super::activation::{CHUNK, PAR_MIN};
use crate::tensor::Tensor;
use rayon::prelude::*;

pub mod detail;
pub mod geometry;

pub use detail::{
    detail_amplitude, detail_energy_mse, detail_energy_mse_ref, detail_high_pass, image_normals, DetailEnergy,
};
pub use geometry::{
    edge_length_mse, edge_length_mse_ref, edge_mse, edge_mse_ref, laplacian_mse, laplacian_mse_ref,
};

/// One element of BCE-with-logits: (loss, d loss / d z), not yet divided by the count.
/// loss = −[w·t·log σ(z) + (1−t)·log(1−σ(z))] = w·t·softplus(−z) + (1−t)·softplus(z)
/// d/dz = w·t·(σ(z) − 1) + (1−t)·σ(z)
/// Stable for any |z|: with e = exp(−|z|) ∈ (0, 1], softplus(±z) = max(±z, 0) + ln(1 + e) and
/// σ(z) = 1/(1 + e) for z ≥ 0, e/(1 + e) otherwise (one exp and one log per element).
#[inline(always)]
fn bce1(z: f32, t: f32, pos_weight: f32) -> (f32, f32) {
    let e = (-z.abs()).exp();
    let l1p = e.ln_1p();
    let sp_pos = z.max(0.0) + l1p; // softplus(z)
    let sp_neg = (-z).max(0.0) + l1p; // softplus(−z)
    let s = if z >= 0.0 { 1.0 / (1.0 + e) } else { e / (1.0 + e) };
    let wt = pos_weight * t;
    (wt * sp_neg + (1.0 - t) * sp_pos, wt * (s - 1.0) + (1.0 - t) * s)
}

pub(super) fn check(pred: &Tensor, target: &Tensor, what: &str) {
    assert_eq!(pred.shape, target.shape, "{what}: prediction {:?} vs target {:?}", pred.shape, target.shape);
}

/// mean((pred − target)²) and its gradient 2·(pred − target)/count.
pub fn mse_ref(pred: &Tensor, target: &Tensor) -> (f32, Tensor) {
    check(pred, target, "mse");
    let n = pred.len().max(1) as f32;
    let mut sum = 0.0f64;
    let mut g = Tensor::zeros(&pred.shape);
    for i in 0..pred.len() {
        let d = pred.data[i] - target.data[i];
        sum += (d as f64) * (d as f64);
        g.data[i] = 2.0 * d / n;
    }
    ((sum / n as f64) as f32, g)
}

/// Fast [`mse_ref`].
pub fn mse(pred: &Tensor, target: &Tensor) -> (f32, Tensor) {
    check(pred, target, "mse");
    let n = pred.len().max(1) as f32;
    let mut g = Tensor::zeros(&pred.shape);
    let body = |g: &mut [f32], p: &[f32], t: &[f32]| -> f64 {
        let mut s = 0.0f64;
        for ((g, &p), &t) in g.iter_mut().zip(p).zip(t) {
            let d = p - t;
            s += (d as f64) * (d as f64);
            *g = 2.0 * d / n;
        }
        s
    };
    let sum: f64 = if pred.len() < PAR_MIN {
        body(&mut g.data, &pred.data, &target.data)
    } else {
        let parts: Vec<f64> = g
            .data
            .par_chunks_mut(CHUNK)
            .zip(pred.data.par_chunks(CHUNK))
            .zip(target.data.par_chunks(CHUNK))
            .map(|((g, p), t)| body(g, p, t))
            .collect();
        parts.iter().sum()
    };
    ((sum / n as f64) as f32, g)
}

/// Mean binary cross-entropy on logits with positive-class weight `pos_weight` (1 = none),
/// stable for any |z|, and its gradient w.r.t. the logits. target values in [0, 1].
pub fn bce_with_logits_ref(logits: &Tensor, target: &Tensor, pos_weight: f32) -> (f32, Tensor) {
    check(logits, target, "bce_with_logits");
    let n = logits.len().max(1) as f32;
    let mut sum = 0.0f64;
    let mut g = Tensor::zeros(&logits.shape);
    for i in 0..logits.len() {
        let (l, d) = bce1(logits.data[i], target.data[i], pos_weight);
        sum += l as f64;
        g.data[i] = d / n;
    }
    ((sum / n as f64) as f32, g)
}

/// Fast [`bce_with_logits_ref`].
pub fn bce_with_logits(logits: &Tensor, target: &Tensor, pos_weight: f32) -> (f32, Tensor) {
    check(logits, target, "bce_with_logits");
    let n = logits.len().max(1) as f32;
    let mut g = Tensor::zeros(&logits.shape);
    let body = |g: &mut [f32], z: &[f32], t: &[f32]| -> f64 {
        let mut s = 0.0f64;
        for ((g, &z), &t) in g.iter_mut().zip(z).zip(t) {
            let (l, d) = bce1(z, t, pos_weight);
            s += l as f64;
            *g = d / n;
        }
        s
    };
    let sum: f64 = if logits.len() < PAR_MIN {
        body(&mut g.data, &logits.data, &target.data)
    } else {
        let parts: Vec<f64> = g
            .data
            .par_chunks_mut(CHUNK)
            .zip(logits.data.par_chunks(CHUNK))
            .zip(target.data.par_chunks(CHUNK))
            .map(|((g, z), t)| body(g, z, t))
            .collect();
        parts.iter().sum()
    };
    ((sum / n as f64) as f32, g)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::testing::TestRng;

    #[test]
    fn fast_losses_match_ref() {
        let mut rng = TestRng::new(6);
        for n in [1, 3, 17, 1001, PAR_MIN - 1, PAR_MIN + 3, 3 * CHUNK + 11] {
            let p = rng.tensor(&[n], -2.0, 2.0);
            let t = rng.tensor(&[n], 0.0, 1.0);
            let (la, ga) = mse(&p, &t);
            let (lb, gb) = mse_ref(&p, &t);
            assert!((la - lb).abs() <= 1e-6 * lb.abs(), "mse n={n}: {la} vs {lb}");
            assert_eq!(ga, gb, "mse grad n={n}");
            for w in [1.0, 4.5] {
                let (la, ga) = bce_with_logits(&p, &t, w);
                let (lb, gb) = bce_with_logits_ref(&p, &t, w);
                assert!((la - lb).abs() <= 1e-6 * lb.abs(), "bce n={n} w={w}: {la} vs {lb}");
                assert_eq!(ga, gb, "bce grad n={n} w={w}");
            }
        }
    }

    /// Largest |a − b| over the largest |b| (0 for two zero tensors).
    fn rel_diff(a: &Tensor, b: &Tensor) -> f32 {
        assert_eq!(a.shape, b.shape);
        let top = b.data.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let d = a.data.iter().zip(&b.data).fold(0.0f32, |m, (x, y)| m.max((x - y).abs()));
        if top > 0.0 {
            d / top
        } else {
            d
        }
    }

    #[test]
    fn geometry_losses_match_their_refs_on_odd_shapes() {
        // 1-pixel rows and columns, grids under 3×3 (no Laplacian interior), odd channel counts;
        // the same edge lengths in pred and target somewhere (e = 0) and a zero-length edge.
        let mut rng = TestRng::new(8);
        for case in 0..40 {
            let (n, c) = (rng.range(1, 2), rng.range(1, 5));
            let (h, w) = if case < 4 {
                [(1, 1), (1, 7), (6, 1), (2, 2)][case]
            } else {
                (rng.range(1, 13), rng.range(1, 13))
            };
            let p = rng.tensor(&[n, c, h, w], -1.0, 1.0);
            let mut t = rng.tensor(&[n, c, h, w], -1.0, 1.0);
            if case % 5 == 0 {
                t = p.clone();
            }
            let mut p = p;
            if case % 7 == 1 && w > 1 {
                for ch in 0..c {
                    p.data[ch * h * w + 1] = p.data[ch * h * w];
                }
            }
            let tag = format!("{:?}", p.shape);
            type Loss = fn(&Tensor, &Tensor) -> (f32, Tensor);
            for (name, fast, spec) in [
                ("edge_mse", edge_mse as Loss, edge_mse_ref as Loss),
                ("edge_length_mse", edge_length_mse, edge_length_mse_ref),
                ("laplacian_mse", laplacian_mse, laplacian_mse_ref),
            ] {
                let ((la, ga), (lb, gb)) = (fast(&p, &t), spec(&p, &t));
                assert!((la - lb).abs() <= 1e-6 * lb.abs(), "{name} {tag}: {la} vs {lb}");
                let d = rel_diff(&ga, &gb);
                assert!(d <= 1e-6, "{name} grad {tag}: off by {d:e} of its largest entry");
            }
        }
    }

    #[test]
    fn detail_energy_mse_matches_its_ref_on_odd_shapes() {
        // Odd HR and LR sizes (LR 1×k included), radius 0 (one pixel) to wider than the image,
        // all three channels along the normals or not, 2 channels (no normals), flat
        // regions where the amplitude floor ε holds.
        let mut rng = TestRng::new(9);
        for case in 0..24 {
            let normal_only = case % 2 == 0;
            let c = if normal_only { 3 } else { [1, 2, 3][case % 3] };
            let (n, h, w) = (rng.range(1, 2), rng.range(2, 13), rng.range(2, 13));
            let (lr_h, lr_w) = (rng.range(1, h), rng.range(1, w));
            let p = DetailEnergy { radius: rng.range(0, 4), eps: [1e-5, 1e-3][case % 4 / 2], normal_only };
            // A smooth sheet (so its normals are defined) plus detail of either sign.
            let mut t = rng.tensor(&[n, c, h, w], -0.05, 0.05);
            for img in 0..n {
                for y in 0..h {
                    for x in 0..w {
                        let i = t.idx4(img, 0, y, x);
                        t.data[i] += x as f32 / w as f32;
                        if c > 1 {
                            let i = t.idx4(img, 1, y, x);
                            t.data[i] += y as f32 / h as f32;
                        }
                    }
                }
            }
            let mut pr = t.clone();
            for v in pr.data.iter_mut() {
                *v += rng.uniform(-0.03, 0.03);
            }
            if case == 5 {
                pr.data.iter_mut().for_each(|v| *v = 0.25); // no detail at all: a = ε
            }
            let tag = format!("{:?} lr {lr_h}×{lr_w} {p:?}", pr.shape);
            let ((la, ga), (lb, gb)) =
                (detail_energy_mse(&pr, &t, lr_h, lr_w, p), detail_energy_mse_ref(&pr, &t, lr_h, lr_w, p));
            assert!((la - lb).abs() <= 1e-5 * lb.abs(), "detail_energy_mse {tag}: {la} vs {lb}");
            let d = rel_diff(&ga, &gb);
            assert!(d <= 1e-5, "detail_energy_mse grad {tag}: off by {d:e} of its largest entry");
        }
    }

    #[test]
    fn bce_is_finite_and_exact_at_extreme_logits() {
        let z = Tensor { shape: [4].into(), data: vec![-100.0, 100.0, -100.0, 100.0] };
        let t = Tensor { shape: [4].into(), data: vec![1.0, 0.0, 0.0, 1.0] };
        let (l, g) = bce_with_logits(&z, &t, 2.0);
        // two confidently wrong samples (w=2 for the positive one): (2·100 + 100)/4
        assert!((l - 75.0).abs() < 1e-4, "{l}");
        for (gi, want) in g.data.iter().zip([-0.5, 0.25, 0.0, 0.0]) {
            assert!((gi - want).abs() < 1e-30, "{:?}", g.data);
        }
    }

    #[test]
    fn loss_gradients_match_finite_differences() {
        let mut rng = TestRng::new(7);
        let p = rng.tensor(&[2, 3, 4, 5], -2.0, 2.0);
        let t = rng.tensor(&[2, 3, 4, 5], 0.0, 1.0);
        for which in 0..2 {
            let f = |p: &Tensor| if which == 0 { mse(p, &t) } else { bce_with_logits(p, &t, 3.0) };
            let (_, g) = f(&p);
            for i in [0, 17, 119] {
                let h = 1e-2;
                let mut a = p.clone();
                a.data[i] += h;
                let mut b = p.clone();
                b.data[i] -= h;
                let fd = (f(&a).0 as f64 - f(&b).0 as f64) / (2.0 * h as f64);
                assert!((fd - g.data[i] as f64).abs() < 2e-4, "loss {which} i={i}: fd {fd} vs {}", g.data[i]);
            }
        }
    }
}
