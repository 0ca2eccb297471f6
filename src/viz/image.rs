//! Plain 8-bit RGB pictures (row-major, `w·h·3` bytes, the layout `app::ui::save_png` writes)
//! and the small helpers every picture needs: geometry images and maps to pixels,
//! nearest-neighbour resampling, tiling side by side and top to bottom, text labels with the
//! built-in font.

use super::font::{glyph, text_width, ADVANCE, GLYPH_H, GLYPH_W};
use crate::error::{Error, Result};
use crate::tensor::Tensor;

/// An 8-bit RGB picture; pixel (x, y) starts at byte `3·(y·w + x)`.
#[derive(Clone, Debug, PartialEq)]
pub struct Rgb8 {
    pub w: usize,
    pub h: usize,
    pub data: Vec<u8>,
}

pub const WHITE: [u8; 3] = [255, 255, 255];
pub const BLACK: [u8; 3] = [0, 0, 0];

impl Rgb8 {
    /// A `w × h` picture filled with `bg`.
    pub fn new(w: usize, h: usize, bg: [u8; 3]) -> Rgb8 {
        let mut data = Vec::with_capacity(w * h * 3);
        for _ in 0..w * h {
            data.extend_from_slice(&bg);
        }
        Rgb8 { w, h, data }
    }

    #[inline]
    pub fn get(&self, x: usize, y: usize) -> [u8; 3] {
        let i = 3 * (y * self.w + x);
        [self.data[i], self.data[i + 1], self.data[i + 2]]
    }

    #[inline]
    pub fn set(&mut self, x: usize, y: usize, c: [u8; 3]) {
        let i = 3 * (y * self.w + x);
        self.data[i..i + 3].copy_from_slice(&c);
    }

    /// Sets (x, y) if it lies inside the picture (signed coordinates, clipped).
    #[inline]
    pub fn put(&mut self, x: i64, y: i64, c: [u8; 3]) {
        if x >= 0 && y >= 0 && (x as usize) < self.w && (y as usize) < self.h {
            self.set(x as usize, y as usize, c);
        }
    }

    /// Filled axis-aligned rectangle, clipped.
    pub fn fill_rect(&mut self, x0: i64, y0: i64, w: usize, h: usize, c: [u8; 3]) {
        for y in y0..y0 + h as i64 {
            for x in x0..x0 + w as i64 {
                self.put(x, y, c);
            }
        }
    }

    /// Copies `src` with its top-left corner at (x0, y0), clipped.
    pub fn blit(&mut self, src: &Rgb8, x0: i64, y0: i64) {
        for y in 0..src.h {
            for x in 0..src.w {
                self.put(x0 + x as i64, y0 + y as i64, src.get(x, y));
            }
        }
    }

    /// Line from (x0, y0) to (x1, y1) (pixels), `thick` px wide, clipped.
    pub fn line(&mut self, x0: f32, y0: f32, x1: f32, y1: f32, thick: usize, c: [u8; 3]) {
        let n = ((x1 - x0).abs().max((y1 - y0).abs()).ceil() as usize).max(1);
        let off = (thick as i64 - 1) / 2;
        for s in 0..=n {
            let t = s as f32 / n as f32;
            let x = (x0 + t * (x1 - x0)).round() as i64 - off;
            let y = (y0 + t * (y1 - y0)).round() as i64 - off;
            self.fill_rect(x, y, thick, thick, c);
        }
    }

    /// Draws `text` with its top-left corner at (x, y), each font pixel `scale × scale`.
    pub fn text(&mut self, x: i64, y: i64, text: &str, scale: usize, c: [u8; 3]) {
        let scale = scale.max(1);
        for (k, ch) in text.chars().enumerate() {
            let g = glyph(ch);
            let gx = x + (k * ADVANCE * scale) as i64;
            for (row, bits) in g.iter().enumerate() {
                for col in 0..GLYPH_W {
                    if bits >> (GLYPH_W - 1 - col) & 1 == 1 {
                        self.fill_rect(gx + (col * scale) as i64, y + (row * scale) as i64, scale, scale, c);
                    }
                }
            }
        }
    }

    /// A label in the top-left corner: `text` in black on a white box with a 2·scale px pad.
    pub fn label(&mut self, text: &str, scale: usize) {
        let scale = scale.max(1);
        let pad = 2 * scale;
        self.fill_rect(0, 0, text_width(text, scale) + 2 * pad, GLYPH_H * scale + 2 * pad, WHITE);
        self.text(pad as i64, pad as i64, text, scale, BLACK);
    }
}

/// A value in [0, 1] (clamped) as an 8-bit channel, rounded to nearest.
#[inline]
pub fn to_u8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// A geometry image (3, H, W) or (1, 3, H, W) → RGB (x→R, y→G, z→B, values clamped to [0,1]),
/// or a map (1, H, W) / (1, 1, H, W) / (H, W) → grey. Image row j = geometry image row j.
pub fn image_rgb8(img: &Tensor) -> Result<Rgb8> {
    let s = &img.shape;
    let (c, h, w) = match s.len() {
        2 => (1, s[0], s[1]),
        3 => (s[0], s[1], s[2]),
        4 if s[0] == 1 => (s[1], s[2], s[3]),
        _ => (0, 0, 0),
    };
    if c != 1 && c != 3 {
        return Err(Error::shape(format!(
            "image_rgb8: expected a (3, H, W) geometry image or a 1-channel map, got {s:?}"
        )));
    }
    let mut out = Rgb8::new(w, h, BLACK);
    for p in 0..h * w {
        let px = if c == 3 {
            [to_u8(img.data[p]), to_u8(img.data[h * w + p]), to_u8(img.data[2 * h * w + p])]
        } else {
            let g = to_u8(img.data[p]);
            [g, g, g]
        };
        out.data[3 * p..3 * p + 3].copy_from_slice(&px);
    }
    Ok(out)
}

/// Nearest-neighbour upscaling by an integer factor (pixel art stays crisp).
pub fn upscale_nearest(img: &Rgb8, factor: usize) -> Rgb8 {
    let f = factor.max(1);
    let mut out = Rgb8::new(img.w * f, img.h * f, BLACK);
    for y in 0..out.h {
        for x in 0..out.w {
            out.set(x, y, img.get(x / f, y / f));
        }
    }
    out
}

/// Nearest-neighbour resampling to exactly `w × h` (e.g. to bring maps of different grid
/// sizes to one tile size).
pub fn resize_nearest(img: &Rgb8, w: usize, h: usize) -> Rgb8 {
    let mut out = Rgb8::new(w, h, BLACK);
    if img.w == 0 || img.h == 0 {
        return out;
    }
    for y in 0..h {
        for x in 0..w {
            out.set(x, y, img.get(x * img.w / w, y * img.h / h));
        }
    }
    out
}

/// Tiles side by side, top-aligned, separated by `gap` px of `bg`.
pub fn hstack(tiles: &[Rgb8], gap: usize, bg: [u8; 3]) -> Rgb8 {
    let w = tiles.iter().map(|t| t.w).sum::<usize>() + gap * tiles.len().saturating_sub(1);
    let h = tiles.iter().map(|t| t.h).max().unwrap_or(0);
    let mut out = Rgb8::new(w, h, bg);
    let mut x = 0;
    for t in tiles {
        out.blit(t, x as i64, 0);
        x += t.w + gap;
    }
    out
}

/// Rows stacked top to bottom, left-aligned, separated by `gap` px of `bg`.
pub fn vstack(rows: &[Rgb8], gap: usize, bg: [u8; 3]) -> Rgb8 {
    let w = rows.iter().map(|t| t.w).max().unwrap_or(0);
    let h = rows.iter().map(|t| t.h).sum::<usize>() + gap * rows.len().saturating_sub(1);
    let mut out = Rgb8::new(w, h, bg);
    let mut y = 0;
    for t in rows {
        out.blit(t, 0, y as i64);
        y += t.h + gap;
    }
    out
}

/// `img` with a border of `margin` px of `bg` on every side.
pub fn pad(img: &Rgb8, margin: usize, bg: [u8; 3]) -> Rgb8 {
    let mut out = Rgb8::new(img.w + 2 * margin, img.h + 2 * margin, bg);
    out.blit(img, margin as i64, margin as i64);
    out
}
