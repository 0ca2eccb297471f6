//! Sobel gradients with SciPy's `ndimage.sobel` conventions: correlation with `[−1, 0, 1]`
//! along the derivative axis, then `[1, 2, 1]` along the other, border mode `reflect`
//! (`d c b a | a b c d`), f64 accumulation and f32 storage between passes.

#[inline]
fn reflect(i: i64, n: usize) -> usize {
    let n = n as i64;
    let i = if i < 0 {
        -i - 1
    } else if i >= n {
        2 * n - i - 1
    } else {
        i
    };
    i.clamp(0, n - 1) as usize
}

/// Returns `(g_row, g_col)`: the derivative along axis 0 (down the rows, skimage's `isobel`)
/// and along axis 1 (across the columns, `jsobel`), unnormalised (a unit-slope ramp gives 8).
// img: (h, w) → 2 × (h, w)
pub fn sobel(img: &[f32], h: usize, w: usize) -> (Vec<f32>, Vec<f32>) {
    assert_eq!(img.len(), h * w);
    let at = |buf: &[f32], y: i64, x: i64| buf[reflect(y, h) * w + reflect(x, w)] as f64;
    // Axis 0 derivative, then smoothing along axis 1.
    let mut d0 = vec![0.0f32; h * w];
    let mut d1 = vec![0.0f32; h * w];
    for y in 0..h as i64 {
        for x in 0..w as i64 {
            d0[y as usize * w + x as usize] = (at(img, y + 1, x) - at(img, y - 1, x)) as f32;
            d1[y as usize * w + x as usize] = (at(img, y, x + 1) - at(img, y, x - 1)) as f32;
        }
    }
    let mut g0 = vec![0.0f32; h * w];
    let mut g1 = vec![0.0f32; h * w];
    for y in 0..h as i64 {
        for x in 0..w as i64 {
            g0[y as usize * w + x as usize] =
                (at(&d0, y, x - 1) + 2.0 * at(&d0, y, x) + at(&d0, y, x + 1)) as f32;
            g1[y as usize * w + x as usize] =
                (at(&d1, y - 1, x) + 2.0 * at(&d1, y, x) + at(&d1, y + 1, x)) as f32;
        }
    }
    (g0, g1)
}
