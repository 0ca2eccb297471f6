//! Contact sheets: tiles in rows on a background, and the strip of a few frames of a
//! geometry-image sequence (the `simulate` preview).

use super::image::{hstack, image_rgb8, pad, upscale_nearest, vstack, Rgb8};
use crate::error::Result;
use crate::tensor::Tensor;

/// `count` (≥ 1) indices spread evenly over `0..total` (> 0), first and last included.
pub fn evenly_spaced(count: usize, total: usize) -> Vec<usize> {
    (0..count).map(|k| if count == 1 { 0 } else { k * (total - 1) / (count - 1) }).collect()
}

/// Rows of tiles, `gap` px apart both ways, inside a `margin` px border, all on `bg`. Tiles
/// are top-left aligned in their row, rows left-aligned.
pub fn sheet(rows: &[Vec<Rgb8>], gap: usize, margin: usize, bg: [u8; 3]) -> Rgb8 {
    let rows: Vec<Rgb8> = rows.iter().map(|r| hstack(r, gap, bg)).collect();
    pad(&vstack(&rows, gap, bg), margin, bg)
}

/// `n` evenly spaced frames of (T, 3, H, W) geometry images side by side, each upscaled by
/// nearest neighbour so it is at least `min_height` pixels tall, 4 grey columns apart.
pub fn frame_strip(images: &Tensor, n: usize, min_height: usize) -> Result<Rgb8> {
    let (t, _, h, _) = images.expect_rank4("frame strip")?;
    let s = min_height.div_ceil(h.max(1)).max(1);
    let tiles = evenly_spaced(n.clamp(1, t.max(1)), t)
        .into_iter()
        .map(|k| Ok(upscale_nearest(&image_rgb8(&images.slice_batch(k, 1))?, s)))
        .collect::<Result<Vec<_>>>()?;
    Ok(sheet(&[tiles], 4, 0, [96; 3]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sheet_lays_out_rows_with_gaps_and_margin() {
        let a = Rgb8::new(3, 2, [255, 0, 0]);
        let s = sheet(&[vec![a.clone(), a.clone()], vec![a.clone()]], 1, 2, [0; 3]);
        assert_eq!((s.w, s.h), (2 + 3 + 1 + 3 + 2, 2 + 2 + 1 + 2 + 2));
        assert_eq!(s.get(2, 2), [255, 0, 0]);
        assert_eq!(s.get(5, 2), [0; 3]);
        assert_eq!(s.get(4, 5), [255, 0, 0]);
        assert_eq!(s.get(6, 5), [0; 3]);
        assert_eq!(evenly_spaced(4, 10), vec![0, 3, 6, 9]);
        assert_eq!(evenly_spaced(1, 10), vec![0]);
    }
}
