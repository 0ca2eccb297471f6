//! Our Eq 12: Γfinal = U + (1 − Γb) ⊙ (1 + η·Γe) ⊙ R.

use anisocb::rng::Rng;
#[path = "common/random.rs"]
mod random;
use anisocb::sr::compose;
use anisocb::Tensor;
use random::TestData;

#[test]
fn composition_matches_scalar_formula_with_broadcast_maps() {
    let mut rng = Rng::new(0x9E3779B97F4A7C15);
    let (n, h, w) = (2, 5, 7);
    let u = rng.tensor(&[n, 3, h, w], 0.0, 1.0);
    let r = rng.tensor(&[n, 3, h, w], 0.0, 1.0);
    let gb = rng.tensor(&[n, 1, h, w], 0.0, 1.0);
    let ge = rng.tensor(&[n, 1, h, w], 0.0, 1.0);
    let eta = 0.75;
    let out = compose(&u, &r, Some(&gb), Some(&ge), eta).unwrap();
    let mut worst = 0.0f32;
    for b in 0..n {
        for c in 0..3 {
            for y in 0..h {
                for x in 0..w {
                    let i = u.idx4(b, c, y, x);
                    let m = gb.idx4(b, 0, y, x);
                    let want = u.data[i] + (1.0 - gb.data[m]) * (1.0 + eta * ge.data[m]) * r.data[i];
                    worst = worst.max((out.data[i] - want).abs());
                }
            }
        }
    }
    assert!(worst <= 1e-6, "largest difference {worst}");
}

#[test]
fn composition_known_values() {
    // U = 0.5, R = 0.1, Γb = 0.25, Γe = 1, η = 2  →  0.5 + 0.75 · 3 · 0.1 = 0.725
    let u = Tensor::full(&[1, 3, 1, 1], 0.5);
    let r = Tensor::full(&[1, 3, 1, 1], 0.1);
    let gb = Tensor::full(&[1, 1, 1, 1], 0.25);
    let ge = Tensor::full(&[1, 1, 1, 1], 1.0);
    let out = compose(&u, &r, Some(&gb), Some(&ge), 2.0).unwrap();
    for v in &out.data {
        assert!((v - 0.725).abs() < 1e-6, "{v}");
    }
}

#[test]
fn boundary_pixels_keep_interpolated_input_and_eta_zero_is_plain_residual() {
    let mut rng = Rng::new(7);
    let u = rng.tensor(&[1, 3, 4, 4], 0.0, 1.0);
    let r = rng.tensor(&[1, 3, 4, 4], 0.0, 1.0);
    let ones = Tensor::full(&[1, 1, 4, 4], 1.0);
    let out = compose(&u, &r, Some(&ones), Some(&ones), 3.0).unwrap();
    assert_eq!(out, u);
    let out = compose(&u, &r, None, Some(&ones), 0.0).unwrap();
    for i in 0..u.len() {
        assert_eq!(out.data[i], u.data[i] + r.data[i]);
    }
}

#[test]
fn composition_rejects_eta_below_minus_one_and_bad_shapes() {
    let u = Tensor::zeros(&[1, 3, 2, 2]);
    assert!(compose(&u, &u, None, None, -1.1).is_err());
    assert!(compose(&u, &u, None, None, f32::NAN).is_err());
    let bad = Tensor::zeros(&[1, 3, 2, 2]);
    assert!(compose(&u, &u, Some(&bad), None, 0.5).is_err());
    assert!(compose(&u, &Tensor::zeros(&[1, 3, 2, 3]), None, None, 0.5).is_err());
}

/// Negative η softens the detail on wrinkle edges: −0.5 halves it where Γe = 1, −1 removes it;
/// off the edges (Γe = 0) nothing changes.
#[test]
fn negative_eta_softens_detail_on_wrinkle_edges_only() {
    let u = Tensor::from_vec(&[1, 3, 1, 2], vec![0.0; 6]).unwrap();
    let r = Tensor::from_vec(&[1, 3, 1, 2], vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap();
    let ge = Tensor::from_vec(&[1, 1, 1, 2], vec![1.0, 0.0]).unwrap();
    for (eta, gain) in [(-0.5f32, 0.5f32), (-1.0, 0.0)] {
        let out = compose(&u, &r, None, Some(&ge), eta).unwrap();
        for ch in 0..3 {
            assert_eq!(out.data[ch * 2], gain * r.data[ch * 2], "η {eta}, on the edge");
            assert_eq!(out.data[ch * 2 + 1], r.data[ch * 2 + 1], "η {eta}, off the edge");
        }
    }
}
