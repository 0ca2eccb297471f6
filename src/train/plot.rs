//! A loss curve as an RGB picture (no font, no plotting crate): log-scale y with a grey line
//! at every power of ten, training loss in light blue (its moving average dark blue),
//! validation loss in orange, x = step.

use super::trainer::LogRow;

/// Draw `history` into a `w × h` RGB buffer (row-major, 3 bytes per pixel).
pub fn loss_curve_rgb(history: &[LogRow], w: usize, h: usize) -> Vec<u8> {
    let mut img = vec![255u8; w * h * 3];
    let (m, w_in, h_in) = (8usize, w.saturating_sub(16).max(1), h.saturating_sub(16).max(1));
    let vals = history.iter().flat_map(|r| [r.train, r.val]).filter(|v| v.is_finite() && *v > 0.0);
    let (lo, hi) = vals.fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
    if history.is_empty() || !lo.is_finite() {
        return img;
    }
    let (llo, mut lhi) = (lo.log10().floor(), hi.log10().ceil());
    if lhi <= llo {
        lhi = llo + 1.0;
    }
    let max_step = history.last().map_or(1, |r| r.step.max(1)) as f32;
    let to_px = |step: u64, v: f32| -> (i64, i64) {
        let x = m as f32 + step as f32 / max_step * (w_in - 1) as f32;
        let y = m as f32 + (lhi - v.log10()) / (lhi - llo) * (h_in - 1) as f32;
        (x.round() as i64, y.round() as i64)
    };
    let mut put = |x: i64, y: i64, c: [u8; 3]| {
        if x >= 0 && y >= 0 && (x as usize) < w && (y as usize) < h {
            let i = (y as usize * w + x as usize) * 3;
            img[i..i + 3].copy_from_slice(&c);
        }
    };
    for d in 0..=(lhi - llo) as i32 {
        let (_, y) = to_px(0, 10f32.powf(llo + d as f32));
        for x in m..m + w_in {
            put(x as i64, y, [210, 210, 210]);
        }
    }
    for y in m..m + h_in {
        put(m as i64 - 1, y as i64, [0, 0, 0]);
    }
    for x in m..m + w_in {
        put(x as i64, (m + h_in) as i64, [0, 0, 0]);
    }
    let mut line = |pts: &mut dyn Iterator<Item = (u64, f32)>, c: [u8; 3]| {
        let mut prev: Option<(i64, i64)> = None;
        for (s, v) in pts {
            let p = to_px(s, v);
            let (x0, y0) = prev.unwrap_or(p);
            let n = (p.0 - x0).abs().max((p.1 - y0).abs()).max(1);
            for k in 0..=n {
                put(x0 + (p.0 - x0) * k / n, y0 + (p.1 - y0) * k / n, c);
            }
            prev = Some(p);
        }
    };
    let ok = |v: f32| v.is_finite() && v > 0.0;
    line(&mut history.iter().filter(|r| ok(r.train)).map(|r| (r.step, r.train)), [175, 200, 240]);
    // Exponential moving average of the (noisy, per-batch) training loss, over ~2% of the run.
    let alpha = 2.0 / (history.len() as f32 / 50.0 + 2.0);
    let mut ema: Option<f32> = None;
    let smooth: Vec<(u64, f32)> = history
        .iter()
        .filter(|r| ok(r.train))
        .map(|r| {
            let e = ema.map_or(r.train, |e| e + alpha * (r.train - e));
            ema = Some(e);
            (r.step, e)
        })
        .collect();
    line(&mut smooth.into_iter(), [30, 70, 190]);
    line(&mut history.iter().filter(|r| ok(r.val)).map(|r| (r.step, r.val)), [230, 120, 20]);
    img
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn curve_draws_both_series_inside_the_picture() {
        let h: Vec<LogRow> = (1..=200)
            .map(|s| LogRow {
                step: s,
                train: 1.0 / s as f32,
                val: if s % 50 == 0 { 2.0 / s as f32 } else { f32::NAN },
            })
            .collect();
        let img = loss_curve_rgb(&h, 160, 90);
        assert_eq!(img.len(), 160 * 90 * 3);
        let has = |c: [u8; 3]| img.chunks_exact(3).any(|p| p == c);
        assert!(has([30, 70, 190]) && has([230, 120, 20]));
        assert!(loss_curve_rgb(&[], 10, 10).iter().all(|&b| b == 255));
    }
}
