//! Canny edge detector on f32 images with scikit-image's `feature.canny` semantics
//! (`mode='constant'`, `cval=0`, no mask, `use_quantiles=False`):
//! 1. Gaussian smoothing (σ) with zero padding, divided by the smoothed all-ones image
//!    ([`super::gaussian::gaussian_blur_normalized`]);
//! 2. Sobel gradients, border mode `reflect` ([`super::sobel::sobel`]), magnitude `√(g0² + g1²)`;
//! 3. non-maximum suppression along the gradient with bilinear interpolation between the two
//!    neighbours it points between; pixels on the image border are never edges;
//! 4. hysteresis: pixels kept by (3) with magnitude ≥ `low` form 8-connected components; a
//!    component is an edge if it holds a pixel with magnitude ≥ `high`.
//!
//! The ground-truth enhance map (docs/architecture.md, "Ground-truth enhance map") is the OR of the per-channel Canny edges of the HR
//! geometry image ([`enhance_map`]).

use super::gaussian::gaussian_blur_normalized;
use super::sobel::sobel;
use crate::error::{Error, Result};
use crate::tensor::Tensor;

/// Canny parameters. Thresholds are absolute values of the Sobel gradient magnitude of the
/// smoothed image (skimage's `use_quantiles=False`; a ramp rising by `s` per pixel has
/// magnitude `8s`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CannyParams {
    /// Standard deviation of the Gaussian (pixels). Default 1.0.
    pub sigma: f32,
    /// Hysteresis low threshold (gradient magnitude). Default 0.15.
    pub low: f32,
    /// Hysteresis high threshold (gradient magnitude). Default 0.3.
    pub high: f32,
}

impl Default for CannyParams {
    /// Tuned for geometry images with values in [0, 1] at HR sizes 64–256 pixels: the
    /// parametrisation ramp of a sheet spanning its domain has magnitude ≈ 8/W (0.125 at
    /// W = 64), so `low` sits above it and a flat sheet gives no edges; a wrinkle of a few
    /// percent of the domain over a few pixels exceeds `high`.
    fn default() -> Self {
        CannyParams { sigma: 1.0, low: 0.15, high: 0.3 }
    }
}

/// Largest Gaussian σ (pixels) [`CannyParams::validate`] accepts: the kernel is truncated at
/// 4σ, so σ = 50 is 401 taps, already wider than any geometry image it smooths (a few hundred
/// pixels); a larger σ only blurs the image flat, and an absurd one could not be allocated.
pub const MAX_SIGMA: f32 = 50.0;

impl CannyParams {
    pub fn validate(&self) -> Result<()> {
        if !(self.sigma.is_finite() && (0.0..=MAX_SIGMA).contains(&self.sigma)) {
            return Err(Error::invalid(
                "canny_sigma",
                format!(
                    "the Canny Gaussian σ must be 0 to {MAX_SIGMA} pixels, got {}; the default 1 \
                     suits geometry images of 64 to 256 pixels, 0 = no smoothing",
                    self.sigma
                ),
            ));
        }
        if !(self.low.is_finite() && self.high.is_finite() && self.low >= 0.0 && self.high >= self.low) {
            return Err(Error::config(format!(
                "canny thresholds need 0 ≤ low ≤ high, got low {} high {}",
                self.low, self.high
            )));
        }
        Ok(())
    }
}

/// Gradient magnitude after non-maximum suppression and the low threshold (0 where
/// suppressed). `g0`, `g1`: Sobel derivatives along axis 0 and 1; `mag`: their norm.
// g0, g1, mag: (h, w) → (h, w)
pub fn non_maximum_suppression(
    g0: &[f32],
    g1: &[f32],
    mag: &[f32],
    h: usize,
    w: usize,
    low: f32,
) -> Vec<f32> {
    let low = if low == 0.0 { 1e-14 } else { low };
    let mut out = vec![0.0f32; h * w];
    let m_at = |r: usize, c: usize| mag[r * w + c];
    // Keep if both interpolated neighbours are ≤ m; the mixed f32/f64 arithmetic follows
    // skimage's Cython kernel so ties resolve the same way.
    let keep = |m: f32, wt: f32, a1: f32, a2: f32, b1: f32, b2: f32| -> bool {
        let wd = 1.0f64 - wt as f64;
        let plus = (a2 * wt) as f64 + a1 as f64 * wd;
        let minus = (b2 * wt) as f64 + b1 as f64 * wd;
        plus <= m as f64 && minus <= m as f64
    };
    for r in 1..h.saturating_sub(1) {
        for c in 1..w.saturating_sub(1) {
            let i = r * w + c;
            let m = mag[i];
            if m < low {
                continue;
            }
            let (gr, gc) = (g0[i], g1[i]);
            let (ar, ac) = (gr.abs(), gc.abs());
            let down = gr <= 0.0;
            let left = gc <= 0.0;
            let kept = if down == left {
                // Gradient in the first/third quadrant: neighbours towards (+1, +1) and (−1, −1).
                if ar > ac {
                    let wt = ac / ar;
                    keep(m, wt, m_at(r + 1, c), m_at(r + 1, c + 1), m_at(r - 1, c), m_at(r - 1, c - 1))
                } else {
                    let wt = ar / ac;
                    keep(m, wt, m_at(r, c + 1), m_at(r + 1, c + 1), m_at(r, c - 1), m_at(r - 1, c - 1))
                }
            } else if ar < ac {
                // Second/fourth quadrant: neighbours towards (−1, +1) and (+1, −1).
                let wt = ar / ac;
                keep(m, wt, m_at(r, c + 1), m_at(r - 1, c + 1), m_at(r, c - 1), m_at(r + 1, c - 1))
            } else {
                let wt = ac / ar;
                keep(m, wt, m_at(r - 1, c), m_at(r - 1, c + 1), m_at(r + 1, c), m_at(r + 1, c - 1))
            };
            if kept {
                out[i] = m;
            }
        }
    }
    out
}

/// Hysteresis with 8-connectivity: components of `nms > 0` that contain a value ≥ `high`.
pub fn hysteresis(nms: &[f32], h: usize, w: usize, high: f32) -> Vec<u8> {
    let mut out = vec![0u8; h * w];
    let mut stack = Vec::new();
    for seed in 0..h * w {
        if nms[seed] <= 0.0 || nms[seed] < high || out[seed] != 0 {
            continue;
        }
        out[seed] = 1;
        stack.push(seed);
        while let Some(v) = stack.pop() {
            let (r, c) = ((v / w) as i64, (v % w) as i64);
            for dr in -1..=1i64 {
                for dc in -1..=1i64 {
                    let (rr, cc) = (r + dr, c + dc);
                    if rr < 0 || cc < 0 || rr >= h as i64 || cc >= w as i64 {
                        continue;
                    }
                    let u = rr as usize * w + cc as usize;
                    if out[u] == 0 && nms[u] > 0.0 {
                        out[u] = 1;
                        stack.push(u);
                    }
                }
            }
        }
    }
    out
}

/// Canny edges of one channel `img` (h × w, row-major) as {0, 1}.
// img: (h, w) → (h, w)
pub fn canny(img: &[f32], h: usize, w: usize, p: &CannyParams) -> Vec<u8> {
    assert_eq!(img.len(), h * w);
    let s = gaussian_blur_normalized(img, h, w, p.sigma);
    let (g0, g1) = sobel(&s, h, w);
    let mag: Vec<f32> = g0.iter().zip(&g1).map(|(a, b)| (a * a + b * b).sqrt()).collect();
    let nms = non_maximum_suppression(&g0, &g1, &mag, h, w, p.low);
    hysteresis(&nms, h, w, p.high)
}

/// Enhance map: per-channel Canny of a (C, H, W) image, OR-combined → (1, H, W) in {0, 1}.
pub fn enhance_map(img: &Tensor, p: &CannyParams) -> Result<Tensor> {
    p.validate()?;
    if img.rank() != 3 {
        return Err(Error::shape(format!("enhance map needs a (C, H, W) image, got {:?}", img.shape)));
    }
    let (c, h, w) = (img.shape[0], img.shape[1], img.shape[2]);
    let mut out = vec![0.0f32; h * w];
    for ch in 0..c {
        let e = canny(&img.data[ch * h * w..(ch + 1) * h * w], h, w, p);
        for (o, &v) in out.iter_mut().zip(&e) {
            if v != 0 {
                *o = 1.0;
            }
        }
    }
    Ok(Tensor { shape: [1, h, w].into(), data: out })
}
