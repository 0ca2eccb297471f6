//! How a frame's vertices become the geometry image the nets see, and how the HR image becomes
//! the HR frame's vertices: a [`Layout`]. The streaming engine ([`crate::pipeline::stream`])
//! and [`crate::pipeline::Upscaler`] move only images between the nets and the composition; a
//! layout is the one place that knows the mesh.
//!
//! Two layouts: the regular grid ([`GridLayout`]: vertex (i, j) is pixel (j, i), Eq 1 and
//! Eq 2, exactly the paper's), and any other mesh ([`MeshLayout`], issue 45): its pieces
//! flattened to charts and resampled into one image ([`super::atlas`]); its HR vertices are
//! the mesh's own linear subdivision plus the detail the nets composed (HR image − U) read at
//! each vertex's chart position.

use super::atlas::{Atlas, AtlasInput};
use super::geometry_image::{grid_to_image, image_to_grid, Domain};
use super::surface::{FaceUvs, Subdivision, Surface};
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

/// Any mesh (see the module docs): its surface, the HR topology, the atlas, and where each HR
/// vertex reads its detail.
pub struct MeshLayout {
    pub surface: Surface,
    pub sub: Subdivision,
    pub atlas: Atlas,
    /// Per HR vertex `v`, its chart positions (LR pixel units) `at[start[v]..start[v + 1]]`:
    /// one for a vertex inside a chart, one per chart for a vertex on a seam or a cut (its
    /// detail is their mean, so it gets one position), none for a vertex in no face.
    at: Vec<[f32; 2]>,
    start: Vec<u32>,
}

impl MeshLayout {
    /// Lay out `surface` from its positions `rest` (metres) and the file's UVs if any.
    pub fn new(surface: Surface, rest: &[[f32; 3]], uv: Option<FaceUvs>) -> Result<MeshLayout> {
        if surface.vertices > MAX_LR_VERTICES {
            return Err(Error::shape(format!(
                "a mesh of {} vertices is larger than the {MAX_LR_VERTICES} an LR frame may have: \
                 upscale the cloth in pieces",
                surface.vertices
            )));
        }
        // Vertices at one place (a mesh exported unwelded, split at its UV seams or hard
        // edges) are one point of the cloth: laid out together, so the pieces' charts join
        // and the copies read the same detail. Where joining them would not make a surface
        // (an edge in three faces), each copy keeps its own place.
        let welded = weld(&surface.faces, rest);
        let faces = match &welded {
            Some(w) if Surface::new(surface.vertices, w.clone(), std::path::Path::new("")).is_ok() => w,
            _ => &surface.faces,
        };
        let atlas = Atlas::build(&AtlasInput { faces, rest, uv })?;
        let sub = Subdivision::of(surface.vertices, &surface.faces);
        let (mut at, mut start) = (Vec::new(), vec![0u32]);
        for from in sub.sources(&surface.faces) {
            let first = at.len();
            for (f, corners) in from {
                let c = &atlas.corner_px[f as usize];
                let n = corners.len() as f32;
                let p: [f32; 2] =
                    std::array::from_fn(|k| corners.iter().map(|&i| c[i as usize][k]).sum::<f32>() / n);
                // The same chart position from two faces is one copy.
                if !at[first..].contains(&p) {
                    at.push(p);
                }
            }
            start.push(at.len() as u32);
        }
        Ok(MeshLayout { surface, sub, atlas, at, start })
    }

    pub fn lr_vertices(&self) -> usize {
        self.surface.vertices
    }

    /// The LR geometry image's (H, W).
    pub fn image_size(&self) -> (usize, usize) {
        (self.atlas.h, self.atlas.w)
    }

    /// Eq 1 on the atlas: the LR frame `pos` → (1, 3, H, W), encoded with `domain`.
    pub fn to_image(&self, pos: &[[f32; 3]], domain: &Domain) -> Result<Tensor> {
        if pos.len() != self.lr_vertices() {
            return Err(Error::shape(format!(
                "the mesh has {} vertices, the frame {}",
                self.lr_vertices(),
                pos.len()
            )));
        }
        let (h, w) = self.image_size();
        let mut t = Tensor::zeros(&[1, 3, h, w]);
        self.atlas.image_into(pos, &mut t.data);
        let px = h * w;
        for c in 0..3 {
            let (lo, ext) = (domain.bmin[c], domain.bmax[c] - domain.bmin[c]);
            t.data[c * px..(c + 1) * px].iter_mut().for_each(|v| *v = (*v - lo) / ext);
        }
        Ok(t)
    }

    /// The HR frame: the LR frame `lr`'s subdivision plus, at each HR vertex's chart position,
    /// the detail `hr − base` of frame `frame` of the HR images (both (T, 3, rH, rW) in
    /// `domain`; `base` is the interpolation U the nets refined), bilinearly sampled.
    pub fn hr_frame(
        &self,
        hr: &Tensor,
        base: &Tensor,
        frame: usize,
        domain: &Domain,
        lr: &[[f32; 3]],
    ) -> Vec<[f32; 3]> {
        let (_, _, hh, hw) = hr.dims4();
        let (h, w) = self.image_size();
        let px = hh * hw;
        let plane = (frame * 3) * px;
        // Align-corners: LR pixel x is HR pixel x·(rW − 1)/(W − 1).
        let (sx, sy) = ((hw - 1) as f32 / (w - 1).max(1) as f32, (hh - 1) as f32 / (h - 1).max(1) as f32);
        let mut out = self.sub.apply(lr);
        for (v, p) in out.iter_mut().enumerate() {
            let copies = &self.at[self.start[v] as usize..self.start[v + 1] as usize];
            if copies.is_empty() {
                continue;
            }
            for (c, pc) in p.iter_mut().enumerate() {
                let at = plane + c * px..plane + (c + 1) * px;
                let (a, b) = (&hr.data[at.clone()], &base.data[at]);
                let d: f32 = copies
                    .iter()
                    .map(|q| {
                        bilinear(a, hh, hw, q[0] * sx, q[1] * sy) - bilinear(b, hh, hw, q[0] * sx, q[1] * sy)
                    })
                    .sum::<f32>()
                    / copies.len() as f32;
                *pc += d * (domain.bmax[c] - domain.bmin[c]);
            }
        }
        out
    }
}

/// `faces` with every vertex replaced by the first vertex at exactly the same place in `rest`;
/// `None` when no two vertices share a place.
fn weld(faces: &[Vec<u32>], rest: &[[f32; 3]]) -> Option<Vec<Vec<u32>>> {
    let mut first: std::collections::HashMap<[u32; 3], u32> = std::collections::HashMap::new();
    let rep: Vec<u32> = rest
        .iter()
        .enumerate()
        .map(|(v, p)| *first.entry(p.map(|x| (x + 0.0).to_bits())).or_insert(v as u32))
        .collect();
    if first.len() == rest.len() {
        return None;
    }
    Some(faces.iter().map(|f| f.iter().map(|&v| rep[v as usize]).collect()).collect())
}

/// Bilinear sample of the `h` × `w` plane `img` at column `x`, row `y` (pixel centres at
/// integers), clamped to the image.
fn bilinear(img: &[f32], h: usize, w: usize, x: f32, y: f32) -> f32 {
    let x = x.clamp(0.0, (w - 1) as f32);
    let y = y.clamp(0.0, (h - 1) as f32);
    let (x0, y0) = ((x as usize).min(w.saturating_sub(2)), (y as usize).min(h.saturating_sub(2)));
    let (fx, fy) = (x - x0 as f32, y - y0 as f32);
    let at = |r: usize, c: usize| img[r.min(h - 1) * w + c.min(w - 1)];
    let top = at(y0, x0) * (1.0 - fx) + at(y0, x0 + 1) * fx;
    let bottom = at(y0 + 1, x0) * (1.0 - fx) + at(y0 + 1, x0 + 1) * fx;
    top * (1.0 - fy) + bottom * fy
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
