//! How a frame's vertices become the geometry image the nets see, and how the HR image becomes
//! the HR frame's vertices: a [`Layout`]. The streaming engine ([`crate::pipeline::stream`])
//! and [`crate::pipeline::Upscaler`] move only images between the nets and the composition; a
//! layout is the one place that knows the mesh.
//!
//! Today the one layout is the regular grid ([`GridLayout`]: vertex (i, j) is pixel (j, i),
//! Eq 1 and Eq 2). A mesh of another outline would be a layout of its own (pieces flattened
//! to charts and resampled), with the same two maps.

use super::geometry_image::{grid_to_image, image_to_grid, Domain};
use crate::error::{Error, Result};
use crate::tensor::Tensor;

/// A frame's vertices ↔ a (3, H, W) geometry image (Eq 1, Eq 2), for one topology fixed over
/// a shot.
pub trait Layout {
    /// Vertices of an LR frame.
    fn lr_vertices(&self) -> usize;
    /// The LR geometry image's (H, W).
    fn image_size(&self) -> (usize, usize);
    /// Vertices of an HR frame at scale `r`.
    fn hr_vertices(&self, r: usize) -> usize;
    /// Eq 1: the LR frame's `pos` (metres) → (3, H, W), encoded with `domain`.
    fn to_image(&self, pos: &[[f32; 3]], domain: &Domain) -> Result<Tensor>;
    /// Eq 2: frame `frame` of the HR images `hr` (T, 3, rH, rW) → its vertices in `out`
    /// (exactly [`Layout::hr_vertices`] positions, metres).
    fn to_vertices(&self, hr: &Tensor, frame: usize, domain: &Domain, out: &mut [[f32; 3]]);
}

/// Most vertices of an LR frame (2048 × 2048): the nets' widest activation holds ≈ 2 KB per LR
/// vertex at the paper's 64 channels, so this is ≈ 8 GB per frame already; a larger mesh is
/// refused before anything is allocated for it.
pub const MAX_LR_VERTICES: usize = 1 << 22;

/// A regular grid of `w` × `h` vertices, row-major: the image is the grid itself.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GridLayout {
    /// Columns.
    pub w: usize,
    /// Rows.
    pub h: usize,
}

impl GridLayout {
    /// A `w` × `h` grid; at least 2 × 2 (a border all round needs two rows and columns).
    pub fn new(w: usize, h: usize) -> Result<GridLayout> {
        if w < 2 || h < 2 {
            return Err(Error::shape(format!("a grid of {w}×{h} vertices is too small: at least 2×2")));
        }
        if w.checked_mul(h).is_none_or(|n| n > MAX_LR_VERTICES) {
            return Err(Error::shape(format!(
                "a grid of {w}×{h} vertices is larger than the {MAX_LR_VERTICES} an LR frame may have: \
                 upscale the cloth in pieces"
            )));
        }
        Ok(GridLayout { w, h })
    }
}

impl Layout for GridLayout {
    fn lr_vertices(&self) -> usize {
        self.w * self.h
    }

    fn image_size(&self) -> (usize, usize) {
        (self.h, self.w)
    }

    fn hr_vertices(&self, r: usize) -> usize {
        (r * self.w).saturating_mul(r * self.h)
    }

    fn to_image(&self, pos: &[[f32; 3]], domain: &Domain) -> Result<Tensor> {
        if pos.len() != self.lr_vertices() {
            return Err(Error::shape(format!(
                "a {}×{} grid has {} vertices, got {}",
                self.w,
                self.h,
                self.lr_vertices(),
                pos.len()
            )));
        }
        grid_to_image(self.w, self.h, pos, domain).reshape(&[1, 3, self.h, self.w])
    }

    fn to_vertices(&self, hr: &Tensor, frame: usize, domain: &Domain, out: &mut [[f32; 3]]) {
        image_to_grid(hr, frame, domain, out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_layout_round_trips_a_frame_through_its_image() {
        let g = GridLayout::new(3, 2).unwrap();
        let pos: Vec<[f32; 3]> = (0..6).map(|v| [v as f32 * 0.1, 1.0 - v as f32 * 0.05, 0.25]).collect();
        let d = Domain { bmin: [-1.0; 3], bmax: [2.0; 3] };
        let img = g.to_image(&pos, &d).unwrap();
        assert_eq!(img.shape, [1, 3, 2, 3]);
        let mut back = vec![[0.0; 3]; 6];
        g.to_vertices(&img, 0, &d, &mut back);
        for (a, b) in pos.iter().zip(&back) {
            for k in 0..3 {
                assert!((a[k] - b[k]).abs() < 1e-6, "{a:?} vs {b:?}");
            }
        }
        assert!(g.to_image(&pos[..5], &d).is_err());
        assert!(GridLayout::new(1, 5).is_err());
        assert!(GridLayout::new(usize::MAX, 3).is_err());
        assert!(GridLayout::new(2049, 2048).is_err());
        assert!(GridLayout::new(2048, 2048).is_ok());
    }
}
