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

use super::atlas::{Atlas, AtlasInput, MARGIN};
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
    /// The HR mesh's border: its edges in one face only.
    border: Vec<(u32, u32)>,
    /// The HR vertices on the border and one edge in from it: what the outline floor blends.
    outer: Vec<u32>,
    /// The faces the LR normals are taken on: the welded cloth's where it welds (so the
    /// copies of a vertex on a seam get one normal), with each LR vertex's representative.
    normal_faces: Vec<Vec<u32>>,
    lr_rep: Vec<u32>,
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
        // The border on the welded cloth: the seams of an unwelded export are no border.
        let rep: Vec<u32> = match &welded {
            Some(_) => {
                let mut first = std::collections::HashMap::new();
                let hr_rest = sub.apply(rest);
                hr_rest
                    .iter()
                    .enumerate()
                    .map(|(v, p)| *first.entry(p.map(|x| (x + 0.0).to_bits())).or_insert(v as u32))
                    .collect()
            }
            None => (0..sub.hr_vertices() as u32).collect(),
        };
        let (border, outer) = border_and_outer(&sub.faces, &rep);
        let mut lr_rep: Vec<u32> = (0..surface.vertices as u32).collect();
        for (f, w) in surface.faces.iter().zip(faces) {
            f.iter().zip(w).for_each(|(&v, &r)| lr_rep[v as usize] = r);
        }
        let normal_faces = faces.clone();
        Ok(MeshLayout { surface, sub, atlas, at, start, border, outer, normal_faces, lr_rep })
    }

    /// Unit normals of the LR frame `pos` per vertex (area-weighted over its faces; a quad's
    /// from its diagonals), one per point of the welded cloth; 0 for a vertex in no face.
    fn normals(&self, pos: &[[f32; 3]]) -> Vec<[f32; 3]> {
        let mut n = vec![[0.0f32; 3]; pos.len()];
        let sub = |a: [f32; 3], b: [f32; 3]| -> [f32; 3] { std::array::from_fn(|k| a[k] - b[k]) };
        for f in &self.normal_faces {
            let p = |i: usize| pos[f[i] as usize];
            let (u, v) = if f.len() == 4 {
                (sub(p(2), p(0)), sub(p(3), p(1)))
            } else {
                (sub(p(1), p(0)), sub(p(2), p(0)))
            };
            let c = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
            for &i in f {
                (0..3).for_each(|k| n[i as usize][k] += c[k]);
            }
        }
        let unit = |m: [f32; 3]| {
            let len = (m[0] * m[0] + m[1] * m[1] + m[2] * m[2]).sqrt();
            if len > 0.0 {
                m.map(|c| c / len)
            } else {
                [0.0; 3]
            }
        };
        (0..pos.len()).map(|v| unit(n[self.lr_rep[v] as usize])).collect()
    }

    /// What the nets' detail is added to on a mesh: the curved subdivision of the LR frame
    /// `lr` ([`Subdivision::apply_curved`] on the welded cloth's normals), the counterpart of
    /// the grid's Catmull-Rom U.
    pub fn base(&self, lr: &[[f32; 3]]) -> Vec<[f32; 3]> {
        self.sub.apply_curved(lr, &self.normals(lr))
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

    /// The HR frame: the LR frame `lr`'s curved subdivision ([`MeshLayout::base`]) plus, at
    /// each HR vertex's chart position, the detail `hr − base` of frame `frame` of the HR images
    /// (both (T, 3, rH, rW) in `domain`; `base` is the interpolation U the nets refined),
    /// bilinearly sampled. With
    /// `keep_outline` ([`crate::sr::params::UpscaleParams::keep_outline`]), the outline floor
    /// of a mesh ([`MeshLayout::floor_outline`]).
    pub fn hr_frame(
        &self,
        hr: &Tensor,
        base: &Tensor,
        frame: usize,
        domain: &Domain,
        lr: &[[f32; 3]],
        keep_outline: bool,
    ) -> Vec<[f32; 3]> {
        let (_, _, hh, hw) = hr.dims4();
        let (h, w) = self.image_size();
        let px = hh * hw;
        let plane = (frame * 3) * px;
        // Align-corners: LR pixel x is HR pixel x·(rW − 1)/(W − 1).
        let (sx, sy) = ((hw - 1) as f32 / (w - 1).max(1) as f32, (hh - 1) as f32 / (h - 1).max(1) as f32);
        let mut out = self.base(lr);
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
        if keep_outline {
            self.floor_outline(&self.sub.apply(lr), &mut out);
        }
        out
    }

    /// The outline floor on a mesh: the HR border never shorter than the linear subdivision's
    /// `s` (which is the LR border polyline's length). Where the detail added to `s` in `out`
    /// shortens it (the nets pulling a hem in), the detail of the border vertices and of those
    /// one edge in is scaled by the largest α ∈ [0, 1] (to 2⁻²⁰, by bisection) that keeps the
    /// border at least that long; α = 0 is `s` itself. The rest of the cloth is left as it is.
    pub fn floor_outline(&self, s: &[[f32; 3]], out: &mut [[f32; 3]]) {
        let length = |a: f64| -> f64 {
            let at = |v: u32| -> [f64; 3] {
                let (p, q) = (s[v as usize], out[v as usize]);
                std::array::from_fn(|c| p[c] as f64 + a * (q[c] as f64 - p[c] as f64))
            };
            self.border
                .iter()
                .map(|&(u, v)| {
                    let (p, q) = (at(u), at(v));
                    ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
                })
                .sum()
        };
        let floor = length(0.0);
        if length(1.0) >= floor {
            return;
        }
        let (mut lo, mut hi) = (0.0f64, 1.0f64);
        for _ in 0..20 {
            let mid = 0.5 * (lo + hi);
            if length(mid) >= floor {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        for &v in &self.outer {
            let (p, q) = (s[v as usize], &mut out[v as usize]);
            for c in 0..3 {
                q[c] = p[c] + (lo as f32) * (q[c] - p[c]);
            }
        }
    }
}

/// Training windows of a mesh's geometry images (issue 45, step 5): the LR atlas over an
/// `n` × `n` window of its image and the HR subdivision's atlas over the matching `r·n` × `r·n`
/// window, so that a garment's frames become (LR, HR) image pairs of the sheets' size.
pub struct TrainingWindow {
    /// Top-left LR pixel of the window (negative, or past the image: filled as the image is).
    pub origin: [i64; 2],
    /// (3, n, n) images of an LR frame.
    pub lr: Atlas,
    /// (3, r·n, r·n) images of the HR frame (the LR mesh subdivided once, in
    /// [`Subdivision`]'s numbering), aligned with `lr` by align-corners as the nets' U is: HR
    /// pixel X is LR pixel x = X·(n − 1)/(r·n − 1) of the window.
    pub hr: Atlas,
    /// Per HR pixel, whether it lies inside a chart.
    hr_mask: Vec<bool>,
}

impl TrainingWindow {
    /// (3, n, n) image of the LR frame `pos` in the window.
    pub fn lr_image(&self, pos: &[[f32; 3]], out: &mut [f32]) {
        self.lr.image_into(pos, out);
    }

    /// (3, rn, rn) image of a per-HR-vertex field (the HR run's detail: its frame minus the LR
    /// frame's linear subdivision) in the window: rasterised inside the charts, 0 outside them.
    /// `upscale` adds the nets' `Γfinal − U` at each HR vertex's chart position to the linear
    /// subdivision ([`MeshLayout::hr_frame`]), so a garment's HR target is `U + this`: the
    /// residual the nets learn is the detail `hr_frame` adds, and none where it never reads.
    pub fn hr_detail(&self, detail: &[[f32; 3]], out: &mut [f32]) {
        self.hr.image_into(detail, out);
        let m = self.hr_mask.len();
        for plane in out.chunks_exact_mut(m).take(3) {
            plane.iter_mut().zip(&self.hr_mask).filter(|(_, inside)| !**inside).for_each(|(v, _)| *v = 0.0);
        }
    }
}

impl MeshLayout {
    /// The windows of `n` LR pixels that cover the image (one, centred, where the image is
    /// smaller; overlapping ones where it is larger), for the HR scale `r`. `rest`: the
    /// positions the layout was made from.
    pub fn training_windows(&self, rest: &[[f32; 3]], n: usize, r: usize) -> Vec<TrainingWindow> {
        let faces = &self.surface.faces;
        let hr_rest = self.sub.apply(rest);
        // Each HR face's corners at their places in the LR charts (the HR faces of LR face f are
        // 4f..4f + 4; a corner is the mean of the LR corners it is made from).
        let sources = self.sub.sources(faces);
        let hr_corners: Vec<Vec<[f32; 2]>> = self
            .sub
            .faces
            .iter()
            .enumerate()
            .map(|(j, hf)| {
                let f = j / 4;
                let c = &self.atlas.corner_px[f];
                hf.iter()
                    .map(|&v| {
                        let (_, ks) = sources[v as usize]
                            .iter()
                            .find(|(g, _)| *g as usize == f)
                            .expect("a corner of f");
                        let m = ks.len() as f32;
                        std::array::from_fn(|k| ks.iter().map(|&i| c[i as usize][k]).sum::<f32>() / m)
                    })
                    .collect()
            })
            .collect();
        let (h, w) = self.image_size();
        let mut out = Vec::new();
        for oy in window_origins(h, n) {
            for ox in window_origins(w, n) {
                let o = [ox as f32, oy as f32];
                let s = (r * n - 1) as f64 / (n - 1).max(1) as f64;
                let lr = self.atlas.resampled(
                    faces,
                    rest,
                    &self.atlas.corner_px,
                    |p| [(p[0] - o[0]) as f64, (p[1] - o[1]) as f64],
                    (n, n),
                );
                let hr = self.atlas.resampled(
                    &self.sub.faces,
                    &hr_rest,
                    &hr_corners,
                    |p| [(p[0] - o[0]) as f64 * s, (p[1] - o[1]) as f64 * s],
                    (r * n, r * n),
                );
                let hr_mask = hr.mask();
                out.push(TrainingWindow { origin: [ox, oy], lr, hr, hr_mask });
            }
        }
        out
    }
}

/// Origins of windows of `n` pixels over `d` pixels: one centred window where the charts fit
/// (the image less its [`MARGIN`] of fill on each side), else the fewest that cover `d` with
/// each overlapping the next by at least a quarter window.
fn window_origins(d: usize, n: usize) -> Vec<i64> {
    if d <= n + 2 * MARGIN {
        return vec![(d as i64 - n as i64).div_euclid(2)];
    }
    let step = (3 * n / 4).max(1);
    let count = (d - n).div_ceil(step) + 1;
    (0..count).map(|i| ((i * (d - n)) as f64 / (count - 1) as f64).round() as i64).collect()
}

/// The border of a mesh (its edges in one face only) and the vertices on it or one edge in,
/// with the vertices of `faces` taken as their representatives `rep` (one per place: copies of
/// a vertex are one vertex of the cloth). Border edges are given by representatives; the outer
/// vertices are every copy.
fn border_and_outer(faces: &[Vec<u32>], rep: &[u32]) -> (Vec<(u32, u32)>, Vec<u32>) {
    let mut edges: Vec<(u32, u32)> = faces
        .iter()
        .flat_map(|f| {
            (0..f.len()).map(move |k| {
                super::surface::edge_key(rep[f[k] as usize], rep[f[(k + 1) % f.len()] as usize])
            })
        })
        .collect();
    edges.sort_unstable();
    let mut border = Vec::new();
    let mut i = 0;
    while i < edges.len() {
        let j = edges[i..].iter().take_while(|e| **e == edges[i]).count();
        if j == 1 {
            border.push(edges[i]);
        }
        i += j;
    }
    let mut on = vec![false; rep.len()];
    border.iter().for_each(|&(a, b)| (on[a as usize], on[b as usize]) = (true, true));
    let mut near = on.clone();
    for &(a, b) in &edges {
        if on[a as usize] || on[b as usize] {
            (near[a as usize], near[b as usize]) = (true, true);
        }
    }
    (border, (0..rep.len() as u32).filter(|&v| near[rep[v as usize] as usize]).collect())
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

    /// A flat, tilted 11×8 sheet of triangles (any-mesh path): positions are an affine
    /// function of the chart coordinates, so every image of it is one too.
    fn tilted_triangles() -> (MeshLayout, Vec<[f32; 3]>) {
        let (nx, ny) = (11usize, 8usize);
        let rest: Vec<[f32; 3]> = (0..nx * ny)
            .map(|v| {
                let (i, j) = ((v % nx) as f32, (v / nx) as f32);
                [0.03 * i, 0.02 * j, 0.5 + 0.012 * i - 0.006 * j]
            })
            .collect();
        let mut faces = Vec::new();
        for j in 0..ny - 1 {
            for i in 0..nx - 1 {
                let a = (j * nx + i) as u32;
                let (b, c, d) = (a + 1, a + 1 + nx as u32, a + nx as u32);
                faces.extend([vec![a, b, c], vec![a, c, d]]);
            }
        }
        let surface = Surface::new(rest.len(), faces, std::path::Path::new("t.obj")).unwrap();
        (MeshLayout::new(surface, &rest, None).unwrap(), rest)
    }

    #[test]
    fn training_windows_cover_the_lr_image_and_align_the_hr_window_by_align_corners() {
        let (layout, rest) = tilted_triangles();
        let (h, w) = layout.image_size();
        let n = 8;
        let windows = layout.training_windows(&rest, n, 2);
        assert!(windows.len() >= 2, "an image of {h}×{w} in windows of {n}: {}", windows.len());
        let mut full = vec![0.0f32; 3 * h * w];
        layout.atlas.image_into(&rest, &mut full);
        let hr_frame = layout.sub.apply(&rest);
        let mask = layout.atlas.mask();
        let mut seen = vec![false; h * w];
        for win in &windows {
            let (mut lr, mut hr) = (vec![0.0f32; 3 * n * n], vec![0.0f32; 3 * 4 * n * n]);
            win.lr_image(&rest, &mut lr);
            win.hr.image_into(&hr_frame, &mut hr);
            // The detail image is 0 outside the charts and the field inside.
            let mut d = vec![0.0f32; 3 * 4 * n * n];
            win.hr_detail(&hr_frame, &mut d);
            for (p, inside) in win.hr_mask.iter().enumerate() {
                assert_eq!(d[p], if *inside { hr[p] } else { 0.0 });
            }
            // The LR window is the image itself where the image has charts.
            for y in 0..n {
                for x in 0..n {
                    let (fy, fx) = (y as i64 + win.origin[1], x as i64 + win.origin[0]);
                    if fy < 0 || fx < 0 || fy >= h as i64 || fx >= w as i64 {
                        continue;
                    }
                    let p = fy as usize * w + fx as usize;
                    if !mask[p] {
                        continue;
                    }
                    seen[p] = true;
                    for c in 0..3 {
                        let (a, b) = (lr[c * n * n + y * n + x], full[c * h * w + p]);
                        assert!(
                            (a - b).abs() < 1e-5,
                            "window {:?} px ({x},{y}) ch {c}: {a} vs {b}",
                            win.origin
                        );
                    }
                }
            }
            // HR pixel X is LR pixel X·(n − 1)/(2n − 1): on a flat cloth the HR image there is
            // the LR image's bilinear sample (a window off by half a pixel is off by 15 mm).
            let lr_mask = win.lr.mask();
            let hr_mask = win.hr.mask();
            let s = (n - 1) as f32 / (2 * n - 1) as f32;
            let mut checked = 0;
            for yy in 0..2 * n {
                for xx in 0..2 * n {
                    let (x, y) = (xx as f32 * s, yy as f32 * s);
                    let (x0, y0) = ((x as usize).min(n - 2), (y as usize).min(n - 2));
                    let around = [(y0, x0), (y0, x0 + 1), (y0 + 1, x0), (y0 + 1, x0 + 1)];
                    if !hr_mask[yy * 2 * n + xx] || !around.iter().all(|&(r, c)| lr_mask[r * n + c]) {
                        continue;
                    }
                    checked += 1;
                    for c in 0..3 {
                        let want = bilinear(&lr[c * n * n..(c + 1) * n * n], n, n, x, y);
                        let got = hr[c * 4 * n * n + yy * 2 * n + xx];
                        assert!((got - want).abs() < 1e-5, "HR px ({xx},{yy}) ch {c}: {got} vs {want}");
                    }
                }
            }
            assert!(checked > n * n / 2, "window {:?}: only {checked} HR pixels checked", win.origin);
        }
        assert!(mask.iter().zip(&seen).all(|(m, s)| !m || *s), "a chart pixel in no window");
        assert_eq!(window_origins(5, 8), vec![-2]);
        assert_eq!(window_origins(8, 8), vec![0]);
        assert_eq!(window_origins(33, 32), vec![0]);
        assert_eq!(window_origins(38, 32), vec![3]);
        assert_eq!(window_origins(39, 32), vec![0, 7]);
        assert_eq!(window_origins(80, 32), vec![0, 24, 48]);
    }

    #[test]
    fn the_mesh_outline_floor_keeps_the_border_as_long_as_the_subdivisions_and_only_there() {
        let (layout, rest) = tilted_triangles();
        let s = layout.sub.apply(&rest);
        let border = |p: &[[f32; 3]]| -> f64 {
            layout
                .border
                .iter()
                .map(|&(a, b)| {
                    crate::geom::vec3::norm(crate::geom::vec3::sub(p[a as usize], p[b as usize])) as f64
                })
                .sum()
        };
        // An 11×8 sheet has 2·(10 + 7) = 34 border edges, each split in two.
        assert_eq!(layout.border.len(), 68);
        // Detail that pulls every vertex toward the centre (a hem drawn in) and lifts it.
        let c = [0.15f32, 0.07, 0.5];
        let pulled: Vec<[f32; 3]> = s
            .iter()
            .map(|p| [p[0] + 0.1 * (c[0] - p[0]), p[1] + 0.1 * (c[1] - p[1]), p[2] + 0.003])
            .collect();
        assert!(border(&pulled) < 0.95 * border(&s));
        let mut out = pulled.clone();
        layout.floor_outline(&s, &mut out);
        let (got, floor) = (border(&out), border(&s));
        assert!(
            got >= floor * (1.0 - 1e-6) && got <= floor * (1.0 + 1e-4),
            "border {got} for a floor of {floor}"
        );
        for v in 0..s.len() {
            if layout.outer.binary_search(&(v as u32)).is_err() {
                assert_eq!(out[v], pulled[v], "vertex {v} away from the border moved");
            }
        }
        // Detail that lengthens the border is left alone.
        let pushed: Vec<[f32; 3]> = s.iter().map(|p| [p[0] - 0.1 * (c[0] - p[0]), p[1], p[2]]).collect();
        let mut out = pushed.clone();
        layout.floor_outline(&s, &mut out);
        assert_eq!(out, pushed);
    }

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
