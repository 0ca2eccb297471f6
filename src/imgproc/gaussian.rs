//! Separable Gaussian smoothing with SciPy's `ndimage.gaussian_filter` conventions: kernel
//! radius `⌊4σ + 0.5⌋`, weights `exp(−x²/2σ²)` normalised to sum 1, axis 0 (rows) first then
//! axis 1, f64 accumulation, f32 storage between passes.

/// 1-D Gaussian weights for standard deviation `sigma` (pixels), truncated at 4σ.
/// `sigma ≤ 0` gives the identity kernel `[1]`.
pub fn gaussian_kernel(sigma: f32) -> Vec<f64> {
    if sigma <= 0.0 {
        return vec![1.0];
    }
    let sd = sigma as f64;
    let radius = (4.0 * sd + 0.5) as i64;
    let k: Vec<f64> = (-radius..=radius).map(|x| (-0.5 / (sd * sd) * (x * x) as f64).exp()).collect();
    let s: f64 = k.iter().sum();
    k.into_iter().map(|v| v / s).collect()
}

/// Gaussian blur of `img` (h × w), zero outside the image (SciPy mode `constant`, cval 0),
/// then divided by the blurred all-ones image (+ f32 ε) so the border is not darkened —
/// exactly scikit-image's `canny` preprocessing without a mask.
// img: (h, w) → (h, w)
pub fn gaussian_blur_normalized(img: &[f32], h: usize, w: usize, sigma: f32) -> Vec<f32> {
    assert_eq!(img.len(), h * w);
    let k = gaussian_kernel(sigma);
    let r = (k.len() / 2) as i64;
    // Pass 1: along rows' axis (axis 0).
    let mut tmp = vec![0.0f32; h * w];
    for y in 0..h as i64 {
        for x in 0..w {
            let mut s = 0.0f64;
            for (t, kv) in k.iter().enumerate() {
                let yy = y + t as i64 - r;
                if yy >= 0 && yy < h as i64 {
                    s += kv * img[yy as usize * w + x] as f64;
                }
            }
            tmp[y as usize * w + x] = s as f32;
        }
    }
    // The blurred all-ones image is separable: a(y) (f32 after pass 1) times Σ valid k along x.
    let valid_sum = |c: i64, n: usize| -> f64 {
        k.iter()
            .enumerate()
            .filter(|(t, _)| (0..n as i64).contains(&(c + *t as i64 - r)))
            .map(|(_, v)| v)
            .sum()
    };
    let ay: Vec<f32> = (0..h as i64).map(|y| valid_sum(y, h) as f32).collect();
    let sx: Vec<f64> = (0..w as i64).map(|x| valid_sum(x, w)).collect();
    // Pass 2: along axis 1, then the bleed-over correction.
    let mut out = vec![0.0f32; h * w];
    for y in 0..h {
        let row = &tmp[y * w..(y + 1) * w];
        for x in 0..w as i64 {
            let mut s = 0.0f64;
            for (t, kv) in k.iter().enumerate() {
                let xx = x + t as i64 - r;
                if xx >= 0 && xx < w as i64 {
                    s += kv * row[xx as usize] as f64;
                }
            }
            let bleed = (ay[y] as f64 * sx[x as usize]) as f32 + f32::EPSILON;
            out[y * w + x as usize] = s as f32 / bleed;
        }
    }
    out
}
