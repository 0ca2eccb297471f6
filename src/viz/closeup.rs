//! Close-ups where the folds are: the window of the HR truth with the most wrinkle detail
//! ([`wrinkle_detail`]), cut from LR, Catmull-Rom, anisocb and the truth, rendered with one
//! camera looking along the patch's mean normal in normal shading
//! ([`super::render::Look::Normals`]) with the folds' share of the normals exaggerated
//! ([`exaggerated_normals`]), so millimetre folds show. Stills (a few frames as rows) and the
//! frames of a flip-book.
use super::image::{hstack, vstack, Rgb8, WHITE};
use super::render::{render_mesh_with_normals, Camera, Shading, View};
use crate::error::{Error, Result};
use crate::eval::metrics::{lr_round_trip, wrinkle_detail, WRINKLE_RING};
use crate::geom::mesh::vertex_normals;
use crate::geom::vec3::{dot, normalize_or, V3};
use crate::geom::GridMesh;

/// Tilt gain of the close-ups' normal shading (colour per radian of tilt away from the view).
pub const CLOSEUP_NORMAL_GAIN: f32 = 1.5;

/// Exaggeration of the fold detail in the close-ups' normals ([`exaggerated_normals`]): a
/// 1 mm fold over a 5 cm wavelength tilts the surface by ~0.1 rad, a tenth of the patch's
/// large-scale bending, and would read as a faint tint.
pub const CLOSEUP_DETAIL_GAIN: f32 = 4.0;

/// LR vertices per side of a close-up window (≈ 2× that on a ×2 HR grid).
pub const CLOSEUP_LR_SIZE: usize = 12;

/// A rectangular sub-grid of vertices: columns `i0..i0 + w`, rows `j0..j0 + h`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Patch {
    pub i0: usize,
    pub j0: usize,
    pub w: usize,
    pub h: usize,
}

impl Patch {
    /// The patch's vertices of `mesh` as a grid of their own.
    pub fn cut(&self, mesh: &GridMesh) -> Result<GridMesh> {
        Ok(GridMesh::new(self.w, self.h, self.cut_values(&mesh.pos, mesh.w, mesh.h)?))
    }

    /// The patch's entries of per-vertex `values` of a `w × h` grid, row by row.
    pub fn cut_values<T: Copy>(&self, values: &[T], w: usize, h: usize) -> Result<Vec<T>> {
        if self.w < 2 || self.h < 2 || self.i0 + self.w > w || self.j0 + self.h > h || values.len() != w * h {
            return Err(Error::shape(format!("patch {self:?} does not fit a {w}x{h} grid")));
        }
        Ok((self.j0..self.j0 + self.h)
            .flat_map(|j| (self.i0..self.i0 + self.w).map(move |i| values[j * w + i]))
            .collect())
    }
}

/// The same piece of cloth on the LR grid and on the HR grid (rest coordinates `u = i/(w−1)`):
/// the HR patch holds the HR vertices inside the LR patch's span.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Window {
    pub lr: Patch,
    pub hr: Patch,
}

/// HR indices `k0..k0 + n` whose rest coordinate lies in that of LR indices `a..=b`.
fn hr_span(a: usize, b: usize, lr_n: usize, hr_n: usize) -> (usize, usize) {
    let (l, h) = (lr_n - 1, hr_n - 1);
    let k0 = (a * h).div_ceil(l);
    let k1 = b * h / l;
    (k0, k1 + 1 - k0)
}

/// The window of `lr_size × lr_size` LR vertices (fewer where the LR grid is smaller) whose HR
/// patch holds the most wrinkle detail of `truth`, `Σ D²` with D = [`wrinkle_detail`] against
/// the `lr_w × lr_h` grid (0 on the outer rings it leaves out). The first of equal windows.
pub fn wrinkle_window(truth: &GridMesh, lr_w: usize, lr_h: usize, lr_size: usize) -> Result<Window> {
    if lr_w > truth.w || lr_h > truth.h || lr_size < 2 {
        return Err(Error::shape(format!(
            "close-up: LR grid {lr_w}x{lr_h} and window {lr_size} do not fit an HR grid {}x{}",
            truth.w, truth.h
        )));
    }
    let d = wrinkle_detail(truth, lr_w, lr_h)?;
    let (w, h, r) = (truth.w, truth.h, WRINKLE_RING);
    // Summed-area table of D² over the HR grid: sat[(j)(w+1) + i] = Σ over rows < j, cols < i.
    let mut sat = vec![0.0f64; (w + 1) * (h + 1)];
    for j in 0..h {
        let mut row = 0.0f64;
        for i in 0..w {
            if (r..h - r).contains(&j) && (r..w - r).contains(&i) {
                row += (d[(j - r) * (w - 2 * r) + i - r] as f64).powi(2);
            }
            sat[(j + 1) * (w + 1) + i + 1] = sat[j * (w + 1) + i + 1] + row;
        }
    }
    let sum = |p: &Patch| {
        let at = |i: usize, j: usize| sat[j * (w + 1) + i];
        at(p.i0 + p.w, p.j0 + p.h) - at(p.i0, p.j0 + p.h) - at(p.i0 + p.w, p.j0) + at(p.i0, p.j0)
    };
    let (nw, nh) = (lr_size.min(lr_w), lr_size.min(lr_h));
    let mut best: Option<(f64, Window)> = None;
    for b in 0..=lr_h - nh {
        for a in 0..=lr_w - nw {
            let (i0, pw) = hr_span(a, a + nw - 1, lr_w, w);
            let (j0, ph) = hr_span(b, b + nh - 1, lr_h, h);
            let win = Window { lr: Patch { i0: a, j0: b, w: nw, h: nh }, hr: Patch { i0, j0, w: pw, h: ph } };
            let s = sum(&win.hr);
            if best.is_none_or(|(m, _)| s > m) {
                best = Some((s, win));
            }
        }
    }
    Ok(best.expect("at least one window").1)
}

/// Unit vertex normals of `mesh` with its detail beyond the `lr_w × lr_h` grid exaggerated
/// `gain` times: `n_s + gain·(n − n_s)`, normalised, where n are the vertex normals and n_s
/// those of the mesh's LR-scale shape ([`lr_round_trip`], the S(X) of [`wrinkle_detail`]).
/// `gain` = 1 gives the plain normals; a mesh on the LR grid itself has no detail to
/// exaggerate. Exaggerated shading in the spirit of Rusinkiewicz, Burns & DeCarlo 2006:
/// the large-scale shape keeps its shading and the folds are drawn stronger. The round trip
/// also damps bends near the LR grid's limit, so an interpolated mesh (Catmull-Rom) shows
/// those as faint bands, stronger than on the LR tile, which keeps its plain normals.
pub fn exaggerated_normals(mesh: &GridMesh, lr_w: usize, lr_h: usize, gain: f32) -> Vec<V3> {
    let n = vertex_normals(mesh);
    if (mesh.w, mesh.h) == (lr_w, lr_h) {
        return n;
    }
    let ns = vertex_normals(&lr_round_trip(mesh, lr_w, lr_h));
    n.iter()
        .zip(&ns)
        .map(|(a, s)| normalize_or(std::array::from_fn(|k| s[k] + gain * (a[k] - s[k])), *a))
        .collect()
}

/// Mean of the unit vertex normals of a mesh, normalised (+z for a degenerate one).
fn mean_normal(mesh: &GridMesh) -> V3 {
    let n = vertex_normals(mesh).iter().fold([0.0f32; 3], |a, n| [a[0] + n[0], a[1] + n[1], a[2] + n[2]]);
    normalize_or(n, [0.0, 0.0, 1.0])
}

/// An orthographic view looking along `-n` (camera on the side `n` points to), 4 % margin.
fn view_along(n: V3) -> View {
    let el = n[1].clamp(-1.0, 1.0).asin().to_degrees();
    let az = n[0].atan2(n[2]).to_degrees();
    View { azimuth_deg: az, elevation_deg: el, fov_deg: 0.0, margin: 0.04 }
}

/// The four meshes of one frame, whole: the LR input, Catmull-Rom, anisocb and the HR truth.
#[derive(Clone, Copy, Debug)]
pub struct Frame<'a> {
    pub lr: &'a GridMesh,
    pub catmull_rom: &'a GridMesh,
    pub ours: &'a GridMesh,
    /// The label of `ours` ("anisocb", "anisocb --physics").
    pub ours_label: &'a str,
    pub truth: &'a GridMesh,
}

/// Tiles of [`render_patches`] in order, each with its label.
pub const CLOSEUP_LABELS: [&str; 4] = ["LR", "Catmull-Rom", "anisocb", "HR (truth)"];

/// `win` of each mesh of `f` rendered side by side, `tile × tile` px each, 6 px apart, with
/// ONE orthographic camera looking along the truth patch's mean normal (turned towards the
/// default 3/4 view's side) in normal shading with [`CLOSEUP_DETAIL_GAIN`]-times
/// [`exaggerated_normals`] (the same for every tile). `first_label` replaces "LR" (e.g. with the
/// frame number).
pub fn render_patches(f: &Frame<'_>, win: &Window, tile: usize, first_label: &str) -> Result<Rgb8> {
    let (lw, lh) = (f.lr.w, f.lr.h);
    let whole = [(f.lr, &win.lr), (f.catmull_rom, &win.hr), (f.ours, &win.hr), (f.truth, &win.hr)];
    let mut meshes = Vec::with_capacity(4);
    let mut normals = Vec::with_capacity(4);
    for (m, p) in whole {
        meshes.push(p.cut(m)?);
        normals.push(p.cut_values(&exaggerated_normals(m, lw, lh, CLOSEUP_DETAIL_GAIN), m.w, m.h)?);
    }
    let mut n = mean_normal(&meshes[3]);
    if dot(n, View::default().toward_camera()) < 0.0 {
        n = n.map(|c| -c);
    }
    let refs: Vec<&GridMesh> = meshes.iter().collect();
    let cam = Camera::fit_meshes(&view_along(n), &refs, tile, tile)?;
    let shade = Shading::normals(CLOSEUP_NORMAL_GAIN);
    let scale = if tile >= 256 { 2 } else { 1 };
    let mut pics = Vec::with_capacity(4);
    for (k, m) in meshes.iter().enumerate() {
        let mut p = render_mesh_with_normals(m, &normals[k], &cam, &shade)?;
        let label = match k {
            0 => first_label,
            2 => f.ours_label,
            _ => CLOSEUP_LABELS[k],
        };
        p.label(label, scale);
        pics.push(p);
    }
    Ok(hstack(&pics, 6, WHITE))
}

/// Close-ups of a few frames as rows, 6 px apart: each frame's own [`wrinkle_window`] of
/// `lr_size` LR vertices per side, [`render_patches`] `tile` px per tile; `frames[k].0` is
/// the frame number shown in the first label.
pub fn closeup_rows(frames: &[(usize, Frame<'_>)], lr_size: usize, tile: usize) -> Result<Rgb8> {
    let mut rows = Vec::with_capacity(frames.len());
    for (k, f) in frames {
        let win = wrinkle_window(f.truth, f.lr.w, f.lr.h, lr_size)?;
        rows.push(render_patches(f, &win, tile, &format!("LR  frame {k}"))?);
    }
    Ok(vstack(&rows, 6, WHITE))
}

/// Frames of a close-up flip-book of a sequence: the window is the [`wrinkle_window`] of the
/// middle frame, fixed; every frame, or every 2nd where there are more than 60, each one
/// [`render_patches`] row labelled with its frame number.
pub fn flipbook_frames(seq: &[Frame<'_>], lr_size: usize, tile: usize) -> Result<Vec<Rgb8>> {
    if seq.is_empty() {
        return Err(Error::shape("close-up flip-book: no frames"));
    }
    let mid = &seq[seq.len() / 2];
    let win = wrinkle_window(mid.truth, mid.lr.w, mid.lr.h, lr_size)?;
    let step = if seq.len() > 60 { 2 } else { 1 };
    (0..seq.len())
        .step_by(step)
        .map(|k| render_patches(&seq[k], &win, tile, &format!("LR  frame {k}")))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hr_span_covers_the_lr_span_on_a_x2_grid() {
        // LR 32 → HR 64 (align corners): LR 0..=11 spans u ∈ [0, 11/31], HR 0..=22.
        assert_eq!(hr_span(0, 11, 32, 64), (0, 23));
        assert_eq!(hr_span(20, 31, 32, 64), (41, 23));
        // Equal grids: the same indices.
        assert_eq!(hr_span(3, 7, 16, 16), (3, 5));
    }
}
