//! The strain limit ([`super::params::UpscaleParams::strain_iters`]): the HR surface's edges pulled
//! toward the lengths the LR frame's own edges imply, in the nets' (cloth) frame.

use crate::pool;

/// Target lengths of the HR grid's row edges (rH × (rW − 1)) and column edges ((rH − 1) × rW):
/// the nearest LR edge's length (LR image `lr`, 3 × H × W) times the spacing ratio
/// (W − 1)/(rW − 1) (resp. rows): the HR surface keeps the LR frame's local stretch, so
/// stretchy bands stay stretched and nothing the nets add swims along the cloth.
pub fn hr_edge_targets(lr: &[f32], h: usize, w: usize, hh: usize, hw: usize) -> (Vec<f32>, Vec<f32>) {
    let px = h * w;
    let len =
        |a: usize, b: usize| (0..3).map(|c| (lr[c * px + b] - lr[c * px + a]).powi(2)).sum::<f32>().sqrt();
    let (sx, sy) = ((w - 1) as f32 / (hw - 1).max(1) as f32, (h - 1) as f32 / (hh - 1).max(1) as f32);
    let near = |v: f32, n: usize| (v.round().max(0.0) as usize).min(n.saturating_sub(1));
    // Pooled buffers (callers give them back: this runs on every frame).
    let mut lx = pool::take(hh * hw);
    lx.clear();
    for y in 0..hh {
        let j = near(y as f32 * sy, h);
        for x in 0..hw.saturating_sub(1) {
            let i = near((x as f32 + 0.5) * sx - 0.5, w - 1);
            lx.push(len(j * w + i, j * w + i + 1) * sx);
        }
    }
    let mut ly = pool::take(hh * hw);
    ly.clear();
    for y in 0..hh.saturating_sub(1) {
        let j = near((y as f32 + 0.5) * sy - 0.5, h - 1);
        for x in 0..hw {
            let i = near(x as f32 * sx, w);
            ly.push(len(j * w + i, (j + 1) * w + i) * sy);
        }
    }
    (lx, ly)
}

/// Pull the row edges (H × (W − 1), lengths `lx`) and column edges ((H − 1) × W, `ly`) of one
/// (3, H, W) geometry image toward their target lengths: `iters` Jacobi sweeps, each moving
/// both ends of every edge by half its length error along the edge (averaged over a vertex's
/// edges); the border does not move, so the outline stays the interpolated input's.
pub fn limit_strain(img: &mut [f32], h: usize, w: usize, lx: &[f32], ly: &[f32], iters: usize) {
    let px = h * w;
    // delta (3 × px) and each vertex's edge count (px; small integers, exact in f32).
    let mut scratch = pool::zeroed(4 * px);
    let (delta, count) = scratch.split_at_mut(3 * px);
    for _ in 0..iters {
        delta.iter_mut().for_each(|d| *d = 0.0);
        count.iter_mut().for_each(|c| *c = 0.0);
        for y in 0..h {
            for x in 0..w {
                let a = y * w + x;
                let row = (x + 1 < w).then(|| (a + 1, lx[y * (w - 1) + x]));
                let col = (y + 1 < h).then(|| (a + w, ly[a]));
                for (b, rest) in [row, col].into_iter().flatten() {
                    let d: [f32; 3] = std::array::from_fn(|c| img[c * px + b] - img[c * px + a]);
                    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                    if len <= 0.0 {
                        continue;
                    }
                    let k = 0.5 * (len - rest) / len;
                    for c in 0..3 {
                        delta[c * px + a] += k * d[c];
                        delta[c * px + b] -= k * d[c];
                    }
                    count[a] += 1.0;
                    count[b] += 1.0;
                }
            }
        }
        for y in 1..h.saturating_sub(1) {
            for x in 1..w.saturating_sub(1) {
                let a = y * w + x;
                if count[a] > 0.0 {
                    for c in 0..3 {
                        img[c * px + a] += delta[c * px + a] / count[a];
                    }
                }
            }
        }
    }
    pool::give(scratch);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flat (3, h, w) grid with spacing `d`, plus `noise`·(pseudo-random) on every channel.
    fn grid(h: usize, w: usize, d: f32, noise: f32) -> Vec<f32> {
        let px = h * w;
        let mut img = vec![0.0f32; 3 * px];
        for p in 0..px {
            let jitter = |c: usize| noise * (((p * 7 + c * 13) % 11) as f32 / 5.0 - 1.0);
            img[p] = (p % w) as f32 * d + jitter(0);
            img[px + p] = (p / w) as f32 * d + jitter(1);
            img[2 * px + p] = jitter(2);
        }
        img
    }

    #[test]
    fn strain_limit_pulls_edges_to_the_lr_lengths_and_keeps_the_border() {
        let (h, w) = (5, 6);
        let lr = grid(h, w, 0.2, 0.0);
        let (hh, hw) = (2 * h, 2 * w);
        let (lx, ly) = hr_edge_targets(&lr, h, w, hh, hw);
        // A flat LR grid of spacing 0.2 over (w − 1) cells → HR spacing 0.2·(w − 1)/(2w − 1).
        assert!(lx.iter().all(|&l| (l - 0.2 * 5.0 / 11.0).abs() < 1e-6));
        assert!(ly.iter().all(|&l| (l - 0.2 * 4.0 / 9.0).abs() < 1e-6));
        let mut img = grid(hh, hw, 0.2 * 5.0 / 11.0, 0.01);
        let before = img.clone();
        let err = |img: &[f32]| {
            let px = hh * hw;
            let mut e = 0.0f32;
            for y in 0..hh {
                for x in 0..hw - 1 {
                    let a = y * hw + x;
                    let l =
                        (0..3).map(|c| (img[c * px + a + 1] - img[c * px + a]).powi(2)).sum::<f32>().sqrt();
                    e += (l - lx[y * (hw - 1) + x]).abs();
                }
            }
            e
        };
        limit_strain(&mut img, hh, hw, &lx, &ly, 20);
        assert!(err(&img) < 0.5 * err(&before), "{} → {}", err(&before), err(&img));
        for p in 0..hh * hw {
            let (y, x) = (p / hw, p % hw);
            if y == 0 || x == 0 || y + 1 == hh || x + 1 == hw {
                for c in 0..3 {
                    assert_eq!(img[c * hh * hw + p], before[c * hh * hw + p], "border vertex {p} moved");
                }
            }
        }
    }
}
