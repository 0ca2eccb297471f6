//! Contact sheets: tiles in rows on a background, the strip of a few frames of a
//! geometry-image sequence (the `simulate` preview), the training set's maps by eye (the
//! `dataset` preview), and which frames of a run the pictures show.

use super::image::{hstack, image_rgb8, pad, resize_nearest, upscale_nearest, vstack, Rgb8};
use crate::error::{Error, Result};
use crate::tensor::Tensor;
use crate::train::dataset::Dataset;

/// `count` (≥ 1) indices spread evenly over `0..total` (> 0), first and last included.
pub fn evenly_spaced(count: usize, total: usize) -> Vec<usize> {
    (0..count).map(|k| if count == 1 { 0 } else { k * (total - 1) / (count - 1) }).collect()
}

/// `n` frames of a `t`-frame run spread over its second half (the first frames are near the
/// rest state): the frames `demo` and `eval` show.
pub fn pick_frames(t: usize, n: usize) -> Vec<usize> {
    (0..n).map(|k| (t / 2 + (k + 1) * (t / 2) / (n + 1)).min(t - 1)).collect()
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

/// Rows of (LR, HR, boundary map, edge map) for up to `count` evenly spaced frames of `ds`, to
/// check the maps by eye: geometry images as RGB clamped to `[0, 1]`, maps white on black, nearest
/// upscaling (LR to the HR size, then all to about 128 px).
pub fn contact_sheet(ds: &Dataset, count: usize) -> Result<Rgb8> {
    if ds.is_empty() || count == 0 {
        return Err(Error::config("contact sheet needs at least one frame"));
    }
    let (hh, wh) = (ds.hr.shape[2], ds.hr.shape[3]);
    let zoom = (128 / wh.max(hh)).max(1);
    let rows = evenly_spaced(count.min(ds.len()), ds.len())
        .into_iter()
        .map(|f| {
            let lr = resize_nearest(&image_rgb8(&ds.lr.slice_batch(f, 1))?, wh, hh);
            let hr = image_rgb8(&ds.hr.slice_batch(f, 1))?;
            let b = image_rgb8(&ds.boundary.slice_batch(f, 1))?;
            let e = image_rgb8(&ds.edges.slice_batch(f, 1))?;
            Ok([lr, hr, b, e].iter().map(|t| upscale_nearest(t, zoom)).collect())
        })
        .collect::<Result<Vec<Vec<Rgb8>>>>()?;
    Ok(sheet(&rows, 4, 4, [40; 3]))
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
        assert_eq!(pick_frames(120, 3), vec![75, 90, 105]);
        assert_eq!(pick_frames(2, 3), vec![1, 1, 1]);
    }
}
