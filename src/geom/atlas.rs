//! Geometry images of any mesh (issue 45, deliverable 2): each piece of the cloth is flattened
//! to the plane — the file's own UVs where they are a usable layout, else ARAP (Liu et al.
//! 2008) — scaled so one pixel is one LR edge, packed into one image with gaps, and resampled:
//! a pixel inside a chart takes the barycentric blend of its triangle's vertices, a pixel
//! outside is extrapolated from the chart so the convolutions see the cloth continued, not a
//! cliff. The image is a fixed linear function of the frame's vertices, built once per shot.
//!
//! Pixel coordinates: `[x, y]` = (column, row) of the LR image, pixel (row r, col c) centred at
//! `[c, r]` — the convention of the align-corners resampling the nets use.

use crate::error::{Error, Result};

/// A fixed-topology mesh to lay out.
pub struct AtlasInput<'a> {
    /// Faces of 3 or 4 vertex indices into `rest`, manifold (an edge in at most two faces, no
    /// repeated vertex in a face, no face twice): checked by the caller.
    pub faces: &'a [Vec<u32>],
    /// The positions the layout is made from (the first frame, or a point cache's rest mesh),
    /// metres.
    pub rest: &'a [[f32; 3]],
    /// The file's UVs, if it has them: coordinates and, per face (parallel to `faces`), the
    /// coordinate index of each corner.
    pub uv: Option<(&'a [[f32; 2]], &'a [Vec<u32>])>,
}

/// Where the charts came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ChartSource {
    /// The file's UV islands.
    Uv,
    /// ARAP flattening of each piece (cut to a disk where it is not one).
    Arap,
}

/// The layout of one topology (see the module docs).
pub struct Atlas {
    /// LR image rows and columns.
    pub h: usize,
    pub w: usize,
    /// Per face, per corner: the corner's chart position in LR pixel units (`[col, row]`).
    pub corner_px: Vec<Vec<[f32; 2]>>,
    /// Metres per pixel on the rest mesh.
    pub texel: f32,
    /// Charts in the image.
    pub charts: usize,
    pub source: ChartSource,
}

impl Atlas {
    /// Lay out `input`.
    pub fn build(input: &AtlasInput) -> Result<Atlas> {
        let _ = input;
        Err(Error::shape("any-mesh layout: not built yet"))
    }

    /// The (3, h, w) geometry image (planar x, y, z) of `pos` (a frame of the same topology as
    /// the rest mesh) into `out` (3·h·w floats).
    pub fn image_into(&self, pos: &[[f32; 3]], out: &mut [f32]) {
        let _ = (pos, out);
    }

    /// Per pixel (row-major, h·w), whether it lies inside a chart.
    pub fn mask(&self) -> Vec<bool> {
        vec![false; self.h * self.w]
    }
}
