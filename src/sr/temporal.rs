//! Temporal smoothing ([`super::params::UpscaleParams::temporal`]) of the nets' outputs along frames.

use super::params::MAX_TEMPORAL;
use crate::tensor::Tensor;

/// `x` (T, C, H, W) averaged over time per pixel with binomial weights of radius `k` (row 2k of
/// Pascal's triangle), the weights renormalised where the window leaves the sequence. Each
/// row is halved as it is built (row n sums to 1), so no radius overflows; callers bound `k`
/// ([`super::params::MAX_TEMPORAL`]) because the cost is O(k²) + O(k) per frame.
pub fn smooth_in_time(x: &Tensor, k: usize) -> Tensor {
    let t = x.shape[0];
    let per = x.len() / t.max(1);
    // Row 2k, built in place (on the stack up to the largest radius the callers allow): entry
    // i of row n + 1 is ½·row[i − 1] + ½·row[i], the same sums as adding both halves of each
    // entry of row n into a fresh row.
    let (mut stack, mut heap) = ([0.0f64; 2 * MAX_TEMPORAL + 1], Vec::new());
    let w: &mut [f64] = if k <= MAX_TEMPORAL {
        &mut stack[..2 * k + 1]
    } else {
        heap.resize(2 * k + 1, 0.0);
        &mut heap
    };
    w[0] = 1.0;
    for n in 1..=2 * k {
        w[n] = 0.5 * w[n - 1];
        for i in (1..n).rev() {
            w[i] = 0.5 * w[i - 1] + 0.5 * w[i];
        }
        w[0] *= 0.5;
    }
    let w = &*w;
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temporal_smoothing_keeps_constant_detail_and_averages_flicker() {
        // Frame f holds the value c + (−1)^f·a in every pixel.
        let (t, per) = (7, 5);
        let x = Tensor {
            shape: [t, 1, 1, per].into(),
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
        let c = Tensor { shape: [4, 1, 1, 3].into(), data: vec![0.3; 12] };
        assert!(smooth_in_time(&c, 2).max_abs_diff(&c) < 1e-7);
        assert_eq!(smooth_in_time(&x, 0).data, x.data);
    }
}
