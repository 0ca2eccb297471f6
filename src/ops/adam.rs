//! The Adam update on flat slices, with bias correction (Kingma & Ba, Alg. 1; optax.adam's
//! form, ε outside the square root):
//!   m ← β1·m + (1−β1)·g,  v ← β2·v + (1−β2)·g²,
//!   p ← p − lr · (m / (1−β1^t)) / (√(v / (1−β2^t)) + ε),   t = step ≥ 1.
//!
//! The fast path threads over fixed chunks; its per-element body is the reference's scalar
//! expression (the compiler vectorizes it; `sqrt` and `/` are IEEE-exact in SIMD too), so the
//! two agree bit for bit.

use super::activation::{CHUNK, PAR_MIN};
use super::AdamParams;
use rayon::prelude::*;

/// Bias corrections (1 − β1^t, 1 − β2^t), computed in f64 and rounded once.
pub(crate) fn corrections(step: u64, hp: &AdamParams) -> (f32, f32) {
    assert!(step >= 1, "adam_update: step counts from 1");
    let t = step.min(i32::MAX as u64) as i32;
    ((1.0 - (hp.beta1 as f64).powi(t)) as f32, (1.0 - (hp.beta2 as f64).powi(t)) as f32)
}

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn update(p: &mut [f32], g: &[f32], m: &mut [f32], v: &mut [f32], c1: f32, c2: f32, hp: &AdamParams) {
    let (b1, b2, lr, eps) = (hp.beta1, hp.beta2, hp.lr, hp.eps);
    for (((p, &g), m), v) in p.iter_mut().zip(g).zip(m.iter_mut()).zip(v.iter_mut()) {
        let mi = (1.0 - b1) * g + b1 * *m;
        let vi = (1.0 - b2) * (g * g) + b2 * *v;
        *m = mi;
        *v = vi;
        *p -= lr * ((mi / c1) / ((vi / c2).sqrt() + eps));
    }
}

fn check(p: &[f32], g: &[f32], m: &[f32], v: &[f32]) {
    assert!(
        p.len() == g.len() && p.len() == m.len() && p.len() == v.len(),
        "adam_update: lengths p {} g {} m {} v {}",
        p.len(),
        g.len(),
        m.len(),
        v.len()
    );
}

/// Reference Adam step on one flat parameter buffer. `step` counts from 1.
pub fn adam_update_ref(p: &mut [f32], g: &[f32], m: &mut [f32], v: &mut [f32], step: u64, hp: &AdamParams) {
    check(p, g, m, v);
    let (c1, c2) = corrections(step, hp);
    update(p, g, m, v, c1, c2, hp);
}

/// Fast [`adam_update_ref`] (bitwise equal).
pub fn adam_update(p: &mut [f32], g: &[f32], m: &mut [f32], v: &mut [f32], step: u64, hp: &AdamParams) {
    check(p, g, m, v);
    let (c1, c2) = corrections(step, hp);
    if p.len() < PAR_MIN {
        update(p, g, m, v, c1, c2, hp);
    } else {
        p.par_chunks_mut(CHUNK)
            .zip(g.par_chunks(CHUNK))
            .zip(m.par_chunks_mut(CHUNK))
            .zip(v.par_chunks_mut(CHUNK))
            .for_each(|(((p, g), m), v)| update(p, g, m, v, c1, c2, hp));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::testing::TestRng;

    #[test]
    fn fast_adam_matches_ref_bitwise() {
        let mut rng = TestRng::new(8);
        let hp = AdamParams { lr: 1e-3, ..Default::default() };
        for n in [1, 5, 16, 33, PAR_MIN + 7, 2 * CHUNK + 1] {
            let mut pa = rng.tensor(&[n], -1.0, 1.0).into_data();
            let mut pb = pa.clone();
            let (mut ma, mut va) = (vec![0.0; n], vec![0.0; n]);
            let (mut mb, mut vb) = (vec![0.0; n], vec![0.0; n]);
            for step in 1..=3 {
                let g = rng.tensor(&[n], -1.0, 1.0).into_data();
                adam_update(&mut pa, &g, &mut ma, &mut va, step, &hp);
                adam_update_ref(&mut pb, &g, &mut mb, &mut vb, step, &hp);
            }
            assert_eq!((pa, ma, va), (pb, mb, vb), "n={n}");
        }
    }

    #[test]
    fn first_adam_step_moves_each_parameter_by_about_lr() {
        // With bias correction, step 1 gives m̂ = g, v̂ = g², so Δp = −lr·sign(g) (up to ε).
        let hp = AdamParams { lr: 0.01, ..Default::default() };
        let mut p = vec![1.0, 1.0, 1.0];
        let (mut m, mut v) = (vec![0.0; 3], vec![0.0; 3]);
        adam_update(&mut p, &[0.5, -3.0, 1e-3], &mut m, &mut v, 1, &hp);
        for (pi, want) in p.iter().zip([0.99, 1.01, 0.99]) {
            assert!((pi - want).abs() < 1e-5, "{pi} vs {want}");
        }
    }
}
