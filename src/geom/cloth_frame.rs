//! The frame the nets see a cloth frame in.
//!
//! Eq 1 normalises positions by the *sequence's* bounding box, so the same wrinkle is a
//! different residual when the animation travels or turns, and a net trained on it learns
//! where the cloth is in the world instead of what it looks like. [`InputFrame::Cloth`] gives
//! each frame its own similarity transform, estimated from the LR frame alone:
//!
//! - origin `o` = centroid of the LR vertices (translation removed);
//! - unit `L` = mean LR edge length × (max(W, H) − 1): the cloth's nominal extent along its
//!   longer side, measured along the cloth (intrinsic: it does not change when the cloth
//!   folds, only when it stretches);
//! - rotation `Rot = [e1 e2 e3]`: the rotation that best maps the grid's parameter plane onto
//!   the frame (shape matching, Müller et al. 2005): with `M = Σ (pᵢ − o)(qᵢ − q̄)ᵀ` (3×2,
//!   `qᵢ = (column, row)` of vertex i), `[e1 e2] = M (MᵀM)^(−1/2)` (the polar factor) and
//!   `e3 = e1 × e2`.
//!
//! The nets see `n = Rotᵀ (p − o) / L + ½` (a flat square sheet fills [0, 1]² × {½}, the range
//! Eq 1 gives), and their output goes back with `p = o + L·Rot·(n − ½)`. Moving, turning or
//! uniformly scaling a frame moves, turns or scales `o`, `Rot` and `L` with it, so the nets'
//! input is unchanged and the output moves with the cloth: equivariance by construction, per
//! frame, whatever each frame's transform is. Bicubic interpolation commutes with any affine
//! map (its weights sum to 1), so `U` is the same either way.
//!
//! Why a canonical frame rather than residuals in local tangent frames or rotation
//! augmentation: it is exact (not learned), costs one 3×2 reduction per frame, keeps the
//! nets, their audit and the CUDA path unchanged, and leaves every direction of the detail
//! (normal and tangential) to the net. Its weak spot is a frame whose grid is folded onto
//! itself so that `M` loses rank (`[e1 e2]` then falls back to Gram–Schmidt of the stronger
//! column); the transform stays equivariant there, only less smooth in time.

use super::geometry_image::{image_vertices, Domain};
use super::mesh::GridMesh;
use super::vec3::{add as add3, cross, dot, norm, normalize_or, scale, sub};
use crate::error::{Error, Result};
use crate::tensor::Tensor;

/// Which coordinates the nets take their input in (and give their residual in).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum InputFrame {
    /// The paper's Eq 1: the sequence's bounding box (the geometry image as stored).
    #[default]
    Domain,
    /// A per-frame similarity transform that moves with the cloth ([`ClothFrame`]).
    Cloth,
}

impl InputFrame {
    pub fn name(self) -> &'static str {
        match self {
            InputFrame::Domain => "domain",
            InputFrame::Cloth => "cloth-frame",
        }
    }

    /// The maps between frame `frame` of `images` (T, 3, H, W) in `domain` (Eq 1) and the nets'
    /// coordinates: `(to_net, from_net)`. Identity for [`InputFrame::Domain`]; for
    /// [`InputFrame::Cloth`], the frame's [`ClothFrame`] composed with Eq 2 / Eq 1.
    pub fn image_maps(self, images: &Tensor, frame: usize, domain: &Domain) -> (Affine, Affine) {
        match self {
            InputFrame::Domain => (Affine::IDENTITY, Affine::IDENTITY),
            InputFrame::Cloth => {
                let (w, h, at) = image_vertices(images, frame, domain);
                let cf = ClothFrame::of_grid(w, h, at);
                let ext: [f64; 3] = std::array::from_fn(|k| (domain.bmax[k] - domain.bmin[k]) as f64);
                let diag = |d: [f64; 3]| {
                    std::array::from_fn(|r| std::array::from_fn(|c| if r == c { d[r] } else { 0.0 }))
                };
                let decode = Affine { m: diag(ext), t: domain.bmin.map(|v| v as f64) };
                let encode = Affine {
                    m: diag(ext.map(|e| 1.0 / e)),
                    t: std::array::from_fn(|k| -(domain.bmin[k] as f64) / ext[k]),
                };
                (cf.to_net().after(&decode), encode.after(&cf.from_net()))
            }
        }
    }

    pub fn parse(s: &str) -> Result<InputFrame> {
        match s {
            "domain" => Ok(InputFrame::Domain),
            "cloth-frame" | "cloth" => Ok(InputFrame::Cloth),
            _ => Err(Error::config(format!("unknown input frame '{s}' (expected cloth-frame or domain)"))),
        }
    }
}

/// Every frame of `images` (T, 3, H, W: geometry images in `domain`, Eq 1) in the nets'
/// coordinates of `frame`, and the per-frame maps `(to_net, from_net)` that took it there,
/// each estimated from its own frame ([`InputFrame::image_maps`]): (T, 3, H, W), T maps.
///
/// The one home of the round trip domain → nets' frame → domain: other images of the same
/// frames (the HR truth, at any resolution) follow with [`map_frames`] and the maps' `to_net`,
/// and what the nets give back returns with [`from_cloth_frames`] ([`into_cloth_frames`]: the
/// first step in place). The maps are identities
/// for [`InputFrame::Domain`] (applied all the same, so both frames take one path).
pub fn to_cloth_frames(
    frame: InputFrame,
    images: &Tensor,
    domain: &Domain,
) -> (Tensor, Vec<(Affine, Affine)>) {
    let (mut net, mut maps) = (images.clone(), Vec::with_capacity(images.shape[0]));
    into_cloth_frames(frame, &mut net, domain, &mut maps);
    (net, maps)
}

/// [`to_cloth_frames`] in place, the maps appended to `maps`: for a caller that keeps its
/// buffers from frame to frame (the frame-by-frame upscaler allocates nothing per frame once
/// `maps` has room).
pub fn into_cloth_frames(
    frame: InputFrame,
    images: &mut Tensor,
    domain: &Domain,
    maps: &mut Vec<(Affine, Affine)>,
) {
    let first = maps.len();
    maps.extend((0..images.shape[0]).map(|k| frame.image_maps(images, k, domain)));
    map_frames(images, maps[first..].iter().map(|m| &m.0), true);
}

/// Images in the nets' coordinates (T, 3, ·, ·) back into the domain, in place: frame k by
/// `maps[k].1` (the maps of [`to_cloth_frames`]), as points (positions) or as vectors (a
/// residual).
pub fn from_cloth_frames(images: &mut Tensor, maps: &[(Affine, Affine)], as_points: bool) {
    map_frames(images, maps.iter().map(|m| &m.1), as_points);
}

/// Frame k of `images` (T, 3, H, W, any H × W: the maps act on coordinates, not pixels) mapped
/// in place by the k-th of `maps`, as points or as vectors; frames past the last map are left
/// as they are.
pub fn map_frames<'a>(images: &mut Tensor, maps: impl IntoIterator<Item = &'a Affine>, as_points: bool) {
    let per = images.len() / images.shape[0].max(1);
    if per == 0 {
        return;
    }
    for (img, m) in images.data.chunks_exact_mut(per).zip(maps) {
        m.apply_image(img, as_points);
    }
}

/// An affine map of 3-vectors, `y = m·x + t` (`m` row-major), applied per pixel to a geometry
/// image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Affine {
    pub m: [[f64; 3]; 3],
    pub t: [f64; 3],
}

impl Affine {
    pub const IDENTITY: Affine =
        Affine { m: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], t: [0.0; 3] };

    /// `m·x + t`
    #[inline]
    pub fn point(&self, x: [f64; 3]) -> [f64; 3] {
        let v = self.vector(x);
        [v[0] + self.t[0], v[1] + self.t[1], v[2] + self.t[2]]
    }

    /// `m·x` (for displacements such as a residual).
    #[inline]
    pub fn vector(&self, x: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|r| self.m[r][0] * x[0] + self.m[r][1] * x[1] + self.m[r][2] * x[2])
    }

    /// `self ∘ first`: apply `first`, then `self`.
    pub fn after(&self, first: &Affine) -> Affine {
        let m = std::array::from_fn(|r| {
            std::array::from_fn(|c| (0..3).map(|k| self.m[r][k] * first.m[k][c]).sum::<f64>())
        });
        Affine { m, t: self.point(first.t) }
    }

    /// Apply in place to one (3, H, W) image (`img.len() = 3·H·W`), as points or as vectors.
    pub fn apply_image(&self, img: &mut [f32], as_points: bool) {
        let hw = img.len() / 3;
        let (x, rest) = img.split_at_mut(hw);
        let (y, z) = rest.split_at_mut(hw);
        for ((a, b), c) in x.iter_mut().zip(y.iter_mut()).zip(z.iter_mut()) {
            let p = [*a as f64, *b as f64, *c as f64];
            let q = if as_points { self.point(p) } else { self.vector(p) };
            (*a, *b, *c) = (q[0] as f32, q[1] as f32, q[2] as f32);
        }
    }
}

/// The per-frame similarity transform of the module docs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClothFrame {
    /// Centroid of the LR vertices (metres).
    pub origin: [f64; 3],
    /// Columns e1, e2, e3 (`rot[r][c]` = component r of e_c): a proper rotation.
    pub rot: [[f64; 3]; 3],
    /// Cloth-intrinsic length unit L (metres): mean edge length × (max(W, H) − 1).
    pub unit: f64,
}

impl ClothFrame {
    /// Estimate the frame of one LR mesh (positions in metres). A degenerate mesh (all
    /// vertices in one point, or not finite) gets the identity rotation and unit 1.
    pub fn of_mesh(mesh: &GridMesh) -> ClothFrame {
        ClothFrame::of_grid(mesh.w, mesh.h, |v| mesh.pos[v])
    }

    /// [`ClothFrame::of_mesh`] of the `w` × `h` grid whose vertex v (row-major) is at `at(v)`.
    pub fn of_grid(w: usize, h: usize, at: impl Fn(usize) -> [f32; 3]) -> ClothFrame {
        let p = |i: usize, j: usize| at(j * w + i).map(|v| v as f64);
        let n = (w * h) as f64;
        let mut o = [0.0f64; 3];
        for q in (0..w * h).map(&at) {
            for k in 0..3 {
                o[k] += q[k] as f64 / n;
            }
        }
        // Mean edge length over the grid's row and column edges.
        let (mut len, mut cnt) = (0.0f64, 0usize);
        for j in 0..h {
            for i in 0..w {
                if i + 1 < w {
                    len += norm(sub(p(i + 1, j), p(i, j)));
                    cnt += 1;
                }
                if j + 1 < h {
                    len += norm(sub(p(i, j + 1), p(i, j)));
                    cnt += 1;
                }
            }
        }
        let mut unit = len / cnt.max(1) as f64 * (w.max(h) - 1).max(1) as f64;
        // Shape matching: M = Σ (p − o)(q − q̄)ᵀ with q = (column, row).
        let (ci, cj) = ((w - 1) as f64 / 2.0, (h - 1) as f64 / 2.0);
        let (mut a, mut b) = ([0.0f64; 3], [0.0f64; 3]);
        for j in 0..h {
            for i in 0..w {
                let d = sub(p(i, j), o);
                a = add3(a, scale(d, i as f64 - ci));
                b = add3(b, scale(d, j as f64 - cj));
            }
        }
        let (mut e1, mut e2) = polar_3x2(a, b);
        if !(unit.is_finite() && unit > 0.0 && e1.iter().chain(&e2).all(|v| v.is_finite())) {
            unit = 1.0;
            (e1, e2) = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        }
        if !o.iter().all(|v| v.is_finite()) {
            o = [0.0; 3];
        }
        let e3 = cross(e1, e2);
        let rot = std::array::from_fn(|r| [e1[r], e2[r], e3[r]]);
        ClothFrame { origin: o, rot, unit }
    }

    /// World (metres) → net coordinates: `Rotᵀ (p − o) / L + ½`.
    pub fn to_net(&self) -> Affine {
        let m: [[f64; 3]; 3] = std::array::from_fn(|r| std::array::from_fn(|c| self.rot[c][r] / self.unit));
        let mo = Affine { m, t: [0.0; 3] }.vector(self.origin);
        Affine { m, t: std::array::from_fn(|k| 0.5 - mo[k]) }
    }

    /// Net coordinates → world: `o + L·Rot·(n − ½)`.
    pub fn from_net(&self) -> Affine {
        let m: [[f64; 3]; 3] = std::array::from_fn(|r| std::array::from_fn(|c| self.rot[r][c] * self.unit));
        let half = Affine { m, t: [0.0; 3] }.vector([0.5; 3]);
        Affine { m, t: std::array::from_fn(|k| self.origin[k] - half[k]) }
    }
}

/// The grid's four mirror images, as (flip rows, flip columns): the grid as given, flipped
/// left-right, top-bottom, both. Each is the same surface with another parametrisation.
pub const GRID_MIRRORS: [(bool, bool); 4] = [(false, false), (false, true), (true, false), (true, true)];

/// Which net coordinates a grid mirror reverses (`n ↦ 1 − n`), given the frame the mirrored
/// grid gets from [`ClothFrame::of_mesh`]: flipping the columns turns q = (column, row) into
/// (−column, row) about the centre, so M's first column, e1 and e3 = e1 × e2 change sign and
/// the mirrored frame is the original turned 180° about e2 (origin and unit unchanged);
/// flipping the rows does the same to e2 and e3. Exact wherever M has full rank.
pub fn mirrored_axes(flip_rows: bool, flip_cols: bool) -> [bool; 3] {
    [flip_cols, flip_rows, flip_rows ^ flip_cols]
}

/// The net coordinates the grid mirror (`rows`, `cols`) reverses in `frame`: the
/// [`mirrored_axes`] in the cloth's frame, none in the paper's domain frame.
pub fn net_axes(rows: bool, cols: bool, frame: InputFrame) -> [bool; 3] {
    match frame {
        InputFrame::Cloth => mirrored_axes(rows, cols),
        InputFrame::Domain => [false; 3],
    }
}

/// Net-frame images (N, 3, H, W) mirrored by the grid mirror (`rows`, `cols`) and re-expressed
/// in the frame the mirrored grid gets: positions (`as_points`) `n ↦ 1 − n` and vectors (a
/// residual) `v ↦ −v` on the [`mirrored_axes`]. In the paper's domain frame (`frame` =
/// [`InputFrame::Domain`]) the coordinates do not depend on the grid: pixels only. Its own
/// inverse.
pub fn mirror_net_images(t: &Tensor, rows: bool, cols: bool, frame: InputFrame, as_points: bool) -> Tensor {
    let mut m = t.flipped(rows, cols);
    let axes = net_axes(rows, cols, frame);
    let (_, c, h, w) = m.dims4();
    debug_assert_eq!(c, 3, "mirror_net_images: xyz images");
    for (plane, _) in m.data.chunks_exact_mut(h * w).zip(axes.iter().cycle()).filter(|(_, a)| **a) {
        plane.iter_mut().for_each(|v| *v = if as_points { 1.0 - *v } else { -*v });
    }
    m
}

/// Orthonormal polar factor `[a b]·(SᵀS)^(−1/2)` of the 3×2 matrix with columns a, b; when the
/// matrix has (nearly) lost rank, Gram–Schmidt starting from the longer column.
fn polar_3x2(a: [f64; 3], b: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let (saa, sab, sbb) = (dot(a, a), dot(a, b), dot(b, b));
    let det = saa * sbb - sab * sab;
    let tr = saa + sbb;
    if tr > 0.0 && det > 1e-10 * tr * tr {
        // √S = (S + √det·I) / √(tr + 2√det) for a 2×2 SPD S; (√S)⁻¹ by the 2×2 inverse.
        let sd = det.sqrt();
        let t = (tr + 2.0 * sd).sqrt();
        let (p, q, r) = ((saa + sd) / t, sab / t, (sbb + sd) / t); // √S = [[p, q], [q, r]]
        let dd = p * r - q * q;
        let (ip, iq, ir) = (r / dd, -q / dd, p / dd); // (√S)⁻¹
        let e1 = add3(scale(a, ip), scale(b, iq));
        let e2 = add3(scale(a, iq), scale(b, ir));
        return (normalize_or(e1, [1.0, 0.0, 0.0]), normalize_or(e2, [0.0, 1.0, 0.0]));
    }
    // Rank ≤ 1: keep the longer column's direction, any perpendicular for the other.
    let swap = sbb > saa;
    let (long, short) = if swap { (b, a) } else { (a, b) };
    let u = normalize_or(long, [1.0, 0.0, 0.0]);
    let mut v = sub(short, scale(u, dot(short, u)));
    if dot(v, v) < 1e-20 * (1.0 + tr) {
        let helper = if u[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
        v = sub(helper, scale(u, dot(helper, u)));
    }
    let v = normalize_or(v, [0.0, 0.0, 1.0]);
    if swap {
        (v, u)
    } else {
        (u, v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wavy(w: usize, h: usize) -> GridMesh {
        let mut m = GridMesh::flat(w, h, 1.2, 0.8);
        for (k, p) in m.pos.iter_mut().enumerate() {
            p[2] = 0.05 * (k as f32 * 0.7).sin();
        }
        m
    }

    fn rotation(axis: [f64; 3], angle: f64) -> [[f64; 3]; 3] {
        let a = normalize_or(axis, [0.0, 0.0, 1.0]);
        let (s, c) = angle.sin_cos();
        let k = [[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]];
        std::array::from_fn(|r| {
            std::array::from_fn(|q| {
                let kk: f64 = (0..3).map(|i| k[r][i] * k[i][q]).sum();
                (r == q) as u8 as f64 + s * k[r][q] + (1.0 - c) * kk
            })
        })
    }

    #[test]
    fn net_coordinates_do_not_change_when_the_frame_is_moved_turned_or_scaled() {
        let m = wavy(9, 7);
        let f = ClothFrame::of_mesh(&m);
        let moved =
            Affine { m: rotation([0.3, -1.0, 0.5], 2.1).map(|r| r.map(|v| 1.7 * v)), t: [3.0, -4.0, 9.0] };
        let m2 = GridMesh::new(
            9,
            7,
            m.pos.iter().map(|p| moved.point(p.map(|v| v as f64)).map(|v| v as f32)).collect(),
        );
        let f2 = ClothFrame::of_mesh(&m2);
        for (p, q) in m.pos.iter().zip(&m2.pos) {
            let a = f.to_net().point(p.map(|v| v as f64));
            let b = f2.to_net().point(q.map(|v| v as f64));
            for k in 0..3 {
                assert!((a[k] - b[k]).abs() < 1e-5, "{a:?} vs {b:?}");
            }
        }
        assert!((f2.unit / f.unit - 1.7).abs() < 1e-5);
    }

    #[test]
    fn to_net_and_from_net_are_inverse_and_a_flat_square_fills_the_unit_square() {
        let m = GridMesh::flat(5, 5, 2.0, 2.0);
        let f = ClothFrame::of_mesh(&m);
        let back = f.from_net().after(&f.to_net());
        for p in &m.pos {
            let q = back.point(p.map(|v| v as f64));
            for k in 0..3 {
                assert!((q[k] - p[k] as f64).abs() < 1e-12);
            }
            let n = f.to_net().point(p.map(|v| v as f64));
            assert!(n.iter().all(|v| (-1e-9..=1.0 + 1e-9).contains(v)), "{n:?}");
            assert!((n[2] - 0.5).abs() < 1e-9);
        }
        let det = {
            let r = f.rot;
            r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1])
                - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
                + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0])
        };
        assert!((det - 1.0).abs() < 1e-12, "a proper rotation, det {det}");
    }

    #[test]
    fn a_mirrored_grid_sees_the_cloth_turned_180_degrees_as_mirrored_axes_says() {
        let (w, h) = (9, 7);
        let m = wavy(w, h);
        let f = ClothFrame::of_mesh(&m);
        for (rows, cols) in GRID_MIRRORS {
            let at = |i: usize, j: usize| {
                let (si, sj) = (if cols { w - 1 - i } else { i }, if rows { h - 1 - j } else { j });
                m.pos[sj * w + si]
            };
            let mirrored = GridMesh::new(w, h, (0..w * h).map(|k| at(k % w, k / w)).collect());
            let fm = ClothFrame::of_mesh(&mirrored);
            let axes = mirrored_axes(rows, cols);
            for (k, p) in mirrored.pos.iter().enumerate() {
                let a = fm.to_net().point(p.map(|v| v as f64));
                let b = f.to_net().point(p.map(|v| v as f64));
                for c in 0..3 {
                    let want = if axes[c] { 1.0 - b[c] } else { b[c] };
                    assert!((a[c] - want).abs() < 1e-9, "mirror {rows} {cols}, vertex {k}, axis {c}");
                }
            }
        }
    }

    #[test]
    fn the_cloth_frame_round_trip_gives_each_frame_back_and_takes_the_hr_frames_along() {
        use crate::geom::geometry_image::sequence_to_images;
        let m = wavy(9, 7);
        let turned =
            Affine { m: rotation([1.0, 0.2, -0.4], 0.8).map(|r| r.map(|v| 0.6 * v)), t: [0.5, 2.0, -1.0] };
        let seq = [
            m.clone(),
            GridMesh::new(
                9,
                7,
                m.pos.iter().map(|p| turned.point(p.map(|v| v as f64)).map(|v| v as f32)).collect(),
            ),
        ];
        let domain = Domain::enclosing(&seq, 0.05);
        let images = sequence_to_images(&seq, &domain);
        for frame in [InputFrame::Domain, InputFrame::Cloth] {
            let (mut net, maps) = to_cloth_frames(frame, &images, &domain);
            assert_eq!((net.shape, maps.len()), (images.shape, 2));
            // Both frames are the same cloth, moved: the same net coordinates in the cloth frame.
            if frame == InputFrame::Cloth {
                let per = net.len() / 2;
                let worst = (0..per).map(|i| (net.data[i] - net.data[per + i]).abs()).fold(0.0, f32::max);
                assert!(worst < 1e-5, "{worst}");
            }
            // The HR images of the same frames (here: the LR ones again) follow with `to_net`.
            let mut other = images.clone();
            map_frames(&mut other, maps.iter().map(|m| &m.0), true);
            assert_eq!(other.data, net.data);
            // In place, after the maps already there: the same images and maps.
            let (mut inplace, mut more) = (images.clone(), vec![(Affine::IDENTITY, Affine::IDENTITY)]);
            into_cloth_frames(frame, &mut inplace, &domain, &mut more);
            assert_eq!((inplace.data.as_slice(), &more[1..]), (net.data.as_slice(), maps.as_slice()));
            from_cloth_frames(&mut net, &maps, true);
            let back = net.data.iter().zip(&images.data).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max);
            assert!(back < 1e-5, "{} round trip: {back}", frame.name());
        }
    }

    #[test]
    fn a_collapsed_or_folded_frame_still_gives_a_rotation() {
        let point = GridMesh::new(3, 3, vec![[1.0, 2.0, 3.0]; 9]);
        let f = ClothFrame::of_mesh(&point);
        assert_eq!(f.unit, 1.0);
        // Folded in half along the columns: column sums cancel.
        let mut m = GridMesh::flat(4, 4, 1.0, 1.0);
        for p in m.pos.iter_mut() {
            p[0] = (p[0] - 0.5).abs();
        }
        let f = ClothFrame::of_mesh(&m);
        for c in 0..3 {
            let col = [f.rot[0][c], f.rot[1][c], f.rot[2][c]];
            assert!((dot(col, col) - 1.0).abs() < 1e-9);
        }
    }
}
