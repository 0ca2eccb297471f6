//! The line plot, into an RGB picture: axes, ticks with numbers (built-in font), several
//! series in distinct colours (or each its own), a legend, optional logarithmic y axis. Used
//! for loss curves ([`loss_plot`], drawn by `anisocb train` from the trainer's checkpoint
//! events) and per-frame error plots (eval). Non-finite points (and y ≤ 0 on a log axis) break
//! the line instead of failing.

use super::font::{text_width, GLYPH_H};
use super::image::{Rgb8, BLACK, WHITE};
use crate::error::{Error, Result};
use crate::train::trainer::LogRow;

/// Distinct series colours (Tableau 10).
pub const PALETTE: [[u8; 3]; 8] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [214, 39, 40],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [127, 127, 127],
];

/// One named line: (x, y) points drawn in the given order.
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    pub name: String,
    pub points: Vec<(f32, f32)>,
    /// Its colour; `None` = the next [`PALETTE`] colour (by the series' position).
    pub color: Option<[u8; 3]>,
}

#[derive(Clone, Debug, Default, PartialEq)]
pub struct LinePlot {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub log_y: bool,
    pub series: Vec<Series>,
}

/// Short text for an axis number: up to 4 significant digits, scientific when very large/small.
pub fn format_number(v: f32) -> String {
    if !v.is_finite() {
        return format!("{v}");
    }
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    if !(1e-3..1e5).contains(&a) {
        let s = format!("{v:.1e}");
        return s.replace(".0e", "e");
    }
    let decimals = (3 - a.log10().floor() as i32).clamp(0, 4) as usize;
    let s = format!("{v:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// Ticks for a linear axis over [lo, hi]: steps of 1, 2 or 5 × 10^k, about `n` of them.
fn nice_ticks(lo: f32, hi: f32, n: usize) -> Vec<f32> {
    let raw = (hi - lo) / n.max(1) as f32;
    let mag = 10f32.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0].iter().map(|m| m * mag).find(|s| *s >= raw).unwrap_or(10.0 * mag);
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    (first..=last).map(|k| k as f32 * step).collect()
}

impl LinePlot {
    pub fn new(title: &str) -> LinePlot {
        LinePlot { title: title.into(), ..Default::default() }
    }

    pub fn labels(mut self, x_label: &str, y_label: &str) -> LinePlot {
        self.x_label = x_label.into();
        self.y_label = y_label.into();
        self
    }

    pub fn log_y(mut self, on: bool) -> LinePlot {
        self.log_y = on;
        self
    }

    pub fn series(mut self, name: &str, points: Vec<(f32, f32)>) -> LinePlot {
        self.series.push(Series { name: name.into(), points, color: None });
        self
    }

    /// A series drawn in `color` instead of the palette's.
    pub fn series_colored(mut self, name: &str, points: Vec<(f32, f32)>, color: [u8; 3]) -> LinePlot {
        self.series.push(Series { name: name.into(), points, color: Some(color) });
        self
    }

    /// Convenience: y values at x = 0, 1, 2, … (e.g. per-frame errors, per-step losses).
    pub fn series_y(self, name: &str, ys: &[f32]) -> LinePlot {
        let pts = ys.iter().enumerate().map(|(i, &y)| (i as f32, y)).collect();
        self.series(name, pts)
    }

    fn usable(&self, p: (f32, f32)) -> bool {
        p.0.is_finite() && p.1.is_finite() && (!self.log_y || p.1 > 0.0)
    }

    /// Draws the plot into a `w × h` picture (at least 160 × 120).
    pub fn render(&self, w: usize, h: usize) -> Result<Rgb8> {
        if w < 160 || h < 120 {
            return Err(Error::config(format!("plot size {w}x{h} too small (min 160x120)")));
        }
        let mut img = Rgb8::new(w, h, WHITE);
        let pts = self.series.iter().flat_map(|s| s.points.iter().copied()).filter(|&p| self.usable(p));
        let (mut x0, mut x1, mut y0, mut y1) = (f32::MAX, f32::MIN, f32::MAX, f32::MIN);
        for (x, y) in pts {
            let y = if self.log_y { y.log10() } else { y };
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
        if x0 > x1 {
            (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
        }
        if x1 - x0 <= 0.0 {
            (x0, x1) = (x0 - 0.5, x1 + 0.5);
        }
        if y1 - y0 <= 0.0 {
            let d = if self.log_y { 0.5 } else { (y0.abs() * 0.1).max(1e-6) };
            (y0, y1) = (y0 - d, y1 + d);
        }
        let (yt, ylabels): (Vec<f32>, Vec<String>) = if self.log_y {
            (y0, y1) = (y0.floor(), y1.ceil());
            let step = ((y1 - y0) / 6.0).ceil().max(1.0);
            let ks: Vec<f32> = (0..).map(|k| y0 + k as f32 * step).take_while(|&v| v <= y1 + 1e-3).collect();
            let labels = ks.iter().map(|&k| format_number(10f32.powf(k))).collect();
            (ks, labels)
        } else {
            let pad = 0.05 * (y1 - y0);
            (y0, y1) = (y0 - pad, y1 + pad);
            let t = nice_ticks(y0, y1, 5);
            let labels = t.iter().map(|&v| format_number(v)).collect();
            (t, labels)
        };
        let xt = nice_ticks(x0, x1, 6);
        let title_scale = if w >= 400 { 2 } else { 1 };
        let left = 10 + ylabels.iter().map(|s| text_width(s, 1)).max().unwrap_or(0);
        let top = 8 + GLYPH_H * title_scale + 6 + if self.y_label.is_empty() { 0 } else { GLYPH_H + 4 };
        let bottom = 8 + GLYPH_H + 6 + if self.x_label.is_empty() { 0 } else { GLYPH_H + 6 };
        let right = 16;
        let (pw, ph) = (w - left - right, h - top - bottom);
        let sx = |x: f32| left as f32 + (x - x0) / (x1 - x0) * pw as f32;
        let sy = |y: f32| (top + ph) as f32 - (y - y0) / (y1 - y0) * ph as f32;
        let grid = [232, 232, 232];
        let tick_col = [90, 90, 90];
        for (v, s) in yt.iter().zip(&ylabels) {
            let y = sy(*v);
            img.line(left as f32, y, (left + pw) as f32, y, 1, grid);
            img.line(left as f32 - 4.0, y, left as f32, y, 1, tick_col);
            img.text((left - 6 - text_width(s, 1)) as i64, y as i64 - 3, s, 1, BLACK);
        }
        for v in &xt {
            let x = sx(*v);
            let s = format_number(*v);
            img.line(x, top as f32, x, (top + ph) as f32, 1, grid);
            img.line(x, (top + ph) as f32, x, (top + ph) as f32 + 4.0, 1, tick_col);
            img.text(x as i64 - text_width(&s, 1) as i64 / 2, (top + ph + 7) as i64, &s, 1, BLACK);
        }
        img.line(left as f32, top as f32, left as f32, (top + ph) as f32, 1, BLACK);
        img.line(left as f32, (top + ph) as f32, (left + pw) as f32, (top + ph) as f32, 1, BLACK);
        img.text(
            (w / 2) as i64 - text_width(&self.title, title_scale) as i64 / 2,
            6,
            &self.title,
            title_scale,
            BLACK,
        );
        if !self.y_label.is_empty() {
            let s = if self.log_y { format!("{} (log)", self.y_label) } else { self.y_label.clone() };
            img.text(6, (top - GLYPH_H - 4) as i64, &s, 1, BLACK);
        }
        if !self.x_label.is_empty() {
            let x = left + pw / 2 - text_width(&self.x_label, 1) / 2;
            img.text(x as i64, (h - GLYPH_H - 4) as i64, &self.x_label, 1, BLACK);
        }
        let mut drawn: Vec<(f32, f32)> = Vec::new();
        for (k, s) in self.series.iter().enumerate() {
            let c = s.color.unwrap_or(PALETTE[k % PALETTE.len()]);
            let mut prev: Option<(f32, f32)> = None;
            for &p in &s.points {
                if !self.usable(p) {
                    prev = None;
                    continue;
                }
                let q = (sx(p.0), sy(if self.log_y { p.1.log10() } else { p.1 }));
                if let Some(a) = prev {
                    for k in 1..8 {
                        let t = k as f32 / 8.0;
                        drawn.push((a.0 + t * (q.0 - a.0), a.1 + t * (q.1 - a.1)));
                    }
                }
                drawn.push(q);
                match prev {
                    Some(a) => img.line(a.0, a.1, q.0, q.1, 2, c),
                    None => img.fill_rect(q.0 as i64 - 1, q.1 as i64 - 1, 2, 2, c),
                }
                prev = Some(q);
            }
        }
        // Legend, top-right inside the plot area.
        if !self.series.is_empty() {
            let tw = self.series.iter().map(|s| text_width(&s.name, 1)).max().unwrap_or(0);
            let (lw, lh) = (tw + 28, self.series.len() * 11 + 6);
            // The corner of the plot area that hides the fewest data points.
            let corners = [
                ((left + pw).saturating_sub(lw + 6), top + 6),
                (left + 6, top + 6),
                ((left + pw).saturating_sub(lw + 6), (top + ph).saturating_sub(lh + 6)),
                (left + 6, (top + ph).saturating_sub(lh + 6)),
            ];
            let hidden = |(cx, cy): (usize, usize)| {
                drawn
                    .iter()
                    .filter(|&&(x, y)| {
                        x >= cx as f32 && x <= (cx + lw) as f32 && y >= cy as f32 && y <= (cy + lh) as f32
                    })
                    .count()
            };
            let best = corners.iter().copied().min_by_key(|&c| hidden(c)).unwrap_or(corners[0]);
            let (lx, ly) = (best.0 as i64, best.1 as i64);
            img.fill_rect(lx - 1, ly - 1, lw + 2, lh + 2, [160, 160, 160]);
            img.fill_rect(lx, ly, lw, lh, WHITE);
            for (k, s) in self.series.iter().enumerate() {
                let y = ly + 4 + 11 * k as i64;
                let c = s.color.unwrap_or(PALETTE[k % PALETTE.len()]);
                img.fill_rect(lx + 4, y + 2, 16, 3, c);
                img.text(lx + 24, y, &s.name, 1, BLACK);
            }
        }
        Ok(img)
    }
}

/// The loss curve of `net`: per-step training loss (light blue) and its exponential moving
/// average over ~2% of the run (dark blue), validation loss (orange); log y, x = step.
/// Non-positive and non-finite losses are left out.
pub fn loss_plot(net: &str, history: &[LogRow]) -> LinePlot {
    let ok = |v: f32| v.is_finite() && v > 0.0;
    let train: Vec<(f32, f32)> =
        history.iter().filter(|r| ok(r.train)).map(|r| (r.step as f32, r.train)).collect();
    let alpha = 2.0 / (history.len() as f32 / 50.0 + 2.0);
    let mut ema: Option<f32> = None;
    let smooth = train
        .iter()
        .map(|&(s, v)| {
            let e = ema.map_or(v, |e| e + alpha * (v - e));
            ema = Some(e);
            (s, e)
        })
        .collect();
    let val = history.iter().filter(|r| ok(r.val)).map(|r| (r.step as f32, r.val)).collect();
    LinePlot::new(&format!("{net} net: loss"))
        .labels("step", "loss")
        .log_y(true)
        .series_colored("train", train, [175, 200, 240])
        .series_colored("train, moving average", smooth, [30, 70, 190])
        .series_colored("validation", val, [230, 120, 20])
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
        let img = loss_plot("geometry", &h).render(320, 180).unwrap();
        assert_eq!(img.data.len(), 320 * 180 * 3);
        let has = |c: [u8; 3]| img.data.chunks_exact(3).any(|p| p == c);
        assert!(has([30, 70, 190]) && has([230, 120, 20]));
        assert!(loss_plot("geometry", &[]).series.iter().all(|s| s.points.is_empty()));
    }
}
