//! The one tolerance comparator of the tests: |got − want| ≤ atol + rtol·|want| at every
//! element, NaN-safe (a NaN or infinity on either side fails: the test is `!(d <= tol)`, not
//! `d > tol`, which a NaN passes). Fails with the first mismatches and the largest difference;
//! prints the largest difference when it passes. Include with
//! `#[path = "common/close.rs"] mod close;`.

use anisocb::Tensor;

/// [`assert_close_slice`] on tensors of the same shape.
#[allow(dead_code)]
pub fn assert_close(what: &str, got: &Tensor, want: &Tensor, atol: f32, rtol: f32) {
    assert_eq!(got.shape, want.shape, "{what}: shapes differ");
    assert_close_slice(what, &got.data, &want.data, atol, rtol);
}

/// |got − want| ≤ atol + rtol·|want| at every element (see the module docs).
pub fn assert_close_slice(what: &str, got: &[f32], want: &[f32], atol: f32, rtol: f32) {
    assert_eq!(got.len(), want.len(), "{what}: lengths differ");
    let (mut worst, mut at) = (0.0f32, 0usize);
    let mut bad = Vec::new();
    let mut n_bad = 0;
    for (i, (&g, &w)) in got.iter().zip(want).enumerate() {
        let d = (g - w).abs();
        if d > worst || (d.is_nan() && !worst.is_nan()) {
            (worst, at) = (d, i);
        }
        let within = d <= atol + rtol * w.abs();
        if !within {
            n_bad += 1;
            if bad.len() < 5 {
                bad.push(format!("[{i}] got {g} want {w}"));
            }
        }
    }
    assert!(
        n_bad == 0,
        "{what}: {n_bad} values out of tolerance (atol {atol}, rtol {rtol}): {}; largest difference {worst:.3e} at {at}",
        bad.join(", ")
    );
    println!("{what}: largest difference {worst:.3e} at {at}");
}

/// One value.
#[allow(dead_code)]
pub fn assert_close_f32(what: &str, got: f32, want: f32, atol: f32, rtol: f32) {
    assert_close_slice(what, &[got], &[want], atol, rtol);
}
