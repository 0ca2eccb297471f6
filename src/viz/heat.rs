//! Heat maps: the colour scale, per-vertex scalars on a rendered mesh, the colour bar, and a
//! comparison row of heat-coloured tiles with its colour bar (the error pictures of `demo`
//! and `eval`).

use super::font::ADVANCE;
use super::image::{hstack, to_u8, Rgb8, BLACK, WHITE};
use super::plot::format_number;
use super::render::{render_row, Shading, Tile, View};
use crate::error::Result;
use crate::geom::vec3::V3;

/// Per-vertex scalars shown with [`heat_color`]: `lo` maps to blue, `hi` to red.
#[derive(Clone, Copy, Debug)]
pub struct ScalarColors<'a> {
    pub values: &'a [f32],
    pub lo: f32,
    pub hi: f32,
}

/// Heat-map colour scale (sRGB, blue → cyan → green → yellow → red) for t ∈ [0,1] (clamped).
pub fn heat_color(t: f32) -> V3 {
    const STOPS: [V3; 5] =
        [[0.10, 0.20, 0.70], [0.10, 0.65, 0.90], [0.35, 0.80, 0.35], [1.00, 0.85, 0.15], [0.85, 0.12, 0.08]];
    let t = if t.is_finite() { t.clamp(0.0, 1.0) } else { 0.0 };
    let x = t * (STOPS.len() - 1) as f32;
    let i = (x as usize).min(STOPS.len() - 2);
    let f = x - i as f32;
    std::array::from_fn(|k| STOPS[i][k] + f * (STOPS[i + 1][k] - STOPS[i][k]))
}

/// The top of a heat scale starting at 0 that shows every value: their maximum, at least
/// `floor` (so an all-zero set still has a scale).
pub fn scale_max<'a>(values: impl IntoIterator<Item = &'a f32>, floor: f32) -> f32 {
    values.into_iter().fold(floor, |m, &v| m.max(v))
}

/// A vertical colour bar for [`heat_color`], `h` px tall, with `lo`, middle and `hi` values
/// written beside it (and an optional `title` above, e.g. "err mm").
pub fn colorbar(h: usize, lo: f32, hi: f32, title: &str) -> Rgb8 {
    let labels = [format_number(hi), format_number(0.5 * (lo + hi)), format_number(lo)];
    let text_w = labels
        .iter()
        .chain(std::iter::once(&title.to_string()))
        .map(|s| s.len() * ADVANCE)
        .max()
        .unwrap_or(0);
    let (bar_w, top) = (14usize, if title.is_empty() { 4 } else { 14 });
    let w = bar_w + 6 + text_w + 4;
    let mut img = Rgb8::new(w, h, WHITE);
    let bar_h = h.saturating_sub(top + 4).max(2);
    for y in 0..bar_h {
        let t = 1.0 - y as f32 / (bar_h - 1) as f32;
        let c = heat_color(t).map(to_u8);
        img.fill_rect(2, (top + y) as i64, bar_w, 1, c);
    }
    img.text(2, 2, title, 1, BLACK);
    let tx = (bar_w + 6) as i64;
    img.text(tx, top as i64, &labels[0], 1, BLACK);
    img.text(tx, (top + bar_h / 2) as i64 - 3, &labels[1], 1, BLACK);
    img.text(tx, (top + bar_h) as i64 - 7, &labels[2], 1, BLACK);
    img
}

/// [`render_row`] of heat-coloured tiles (their [`ScalarColors`] on the scale `lo..hi`) with a
/// [`colorbar`] titled `bar_title` on the right, `gap` px apart.
pub fn render_heat_row(
    tiles: &[Tile<'_>],
    view: &View,
    shade: &Shading,
    (tile_w, tile_h): (usize, usize),
    gap: usize,
    (lo, hi): (f32, f32),
    bar_title: &str,
) -> Result<Rgb8> {
    let row = render_row(tiles, view, shade, tile_w, tile_h, gap)?;
    let bar = colorbar(row.h, lo, hi, bar_title);
    Ok(hstack(&[row, bar], gap, WHITE))
}
