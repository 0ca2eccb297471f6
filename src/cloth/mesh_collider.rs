//! Triangle-mesh colliders of the physics pass (`upscale --physics --collider PATH`): the body
//! an artist's cloth lies on, as a mesh of triangles and quads, static (one OBJ file) or
//! animated (a folder of OBJ frames, one per shot frame, blended linearly over the substeps).
//!
//! Contact, per substep after the constraints ([`MeshCollider::substep`]), for every free
//! vertex (inv_mass > 0), in two steps:
//! 1. **No tunnelling.** If the vertex's motion over the substep, taken relative to the
//!    collider (each triangle's start point carried by the triangle's own mean displacement,
//!    exact for a translating body), enters a triangle from its front, the vertex is put back
//!    in front of it, `thickness` off its plane. A vertex fast enough to pass a thin plate in
//!    one substep is stopped where a closest-point test alone would see it on the far side.
//!    Leaving through the back (out of the inside) is free.
//! 2. **Closest point.** The closest point on the surface within `REACH × thickness`, found
//!    through a uniform hash grid of the triangles (cell ≈ the mean edge length, rebuilt each
//!    substep while the collider moves). Inside or outside by the closest feature's
//!    angle-weighted pseudo-normal (Bærentzen & Aanæs 2005, "Signed distance computation
//!    using the angle weighted pseudonormal") on a closed mesh, outward-oriented (a closed
//!    mesh wound inward, by its volume's sign, is turned outward); an open mesh is one-sided:
//!    behind a face (or an interior edge or vertex, by its pseudo-normal) is inside, and its
//!    rim is a rounded edge with no inside. A vertex inside, or outside closer than
//!    `thickness`, moves to `thickness` outside along the normal, with the primitives'
//!    position-based friction ([`super::collision::resolve`]) on its motion relative to the
//!    surface.
//!
//! A closed mesh's inside is known at any depth ([`MeshCollider::push_out`] searches as far
//! as it must): the pass runs it on its cloth once a frame, and on the frames it writes.
//!
//! Determinism: the grid is only looked up, never iterated in hash order; among equally
//! close triangles the lowest index wins; each vertex's result depends on that vertex alone,
//! so the rayon split over vertices gives the same bits on any number of threads.

use super::collision::{resolve, Cuboid, Sphere};
use crate::error::{Error, Result};
use crate::geom::obj::{list_obj_files, parse_obj, read_obj_text};
use crate::geom::vec3::{add, cross, dot, norm, normalize_or, scale, sub};
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Default gap (m) the cloth keeps from a mesh collider (`--collider-thickness`): 5 mm, a
/// skin thick enough that a vertex resting on the surface stays clear of its facets'
/// rounding and thin enough not to show between cloth and body at shot scale.
pub const COLLIDER_THICKNESS: f32 = 0.005;

/// Largest `--collider-thickness` (m) accepted: 10 cm is no longer a skin but another body;
/// a larger number is most likely millimetres given as metres (`5` for 5 mm).
pub const MAX_COLLIDER_THICKNESS: f32 = 0.1;

/// The per-substep closest-point search looks this many thicknesses from a vertex. A vertex
/// the crossing test kept outside touches the surface within one thickness; the second
/// catches one that slipped in by rounding where the crossing test met an edge.
const REACH: f32 = 2.0;

/// Slack on the barycentric coordinates of the segment–triangle test: a segment through a
/// shared edge or vertex is seen by the triangles on both sides, not missed by both.
const EDGE_SLACK: f32 = 1e-5;

/// Below this fraction of the thickness a vertex's offset from its closest point has no
/// reliable direction (f32 positions of metres round at ~0.1 µm); the feature's normal is
/// used instead.
const DIRECTION_FLOOR: f32 = 1e-3;

/// The grid's budget of (cell, triangle) entries per triangle: a mesh of mixed sizes (a
/// floor of two triangles beside a detailed body) doubles its cell until it fits, instead of
/// listing the large triangles in millions of small cells.
const ENTRIES_PER_TRIANGLE: usize = 16;

/// Most cells along the grid's longest side: cell indices stay small integers whatever the
/// triangles' sizes.
const MAX_CELLS_PER_AXIS: f32 = 1024.0;

/// Projections of [`MeshCollider::push_out`] per vertex: pushed out of one face at a concave
/// crease, a vertex may land inside the other; each pass takes it out of the closest one.
const PUSH_OUT_PASSES: usize = 4;

/// Vertices per parallel task.
const CHUNK: usize = 256;

/// Below this many vertices the contacts run on the calling thread: handing each substep to
/// the pool costs more than it saves (as the solver's `parallel_min_colour`).
const PARALLEL_MIN_VERTICES: usize = 4096;

/// Run `f(v, &mut x[v])` for every vertex, in parallel chunks when there are enough of them
/// (each vertex's result depends on that vertex alone: the same bits either way).
fn for_vertices(x: &mut [[f32; 3]], f: impl Fn(usize, &mut [f32; 3]) + Sync) {
    if x.len() < PARALLEL_MIN_VERTICES {
        x.iter_mut().enumerate().for_each(|(v, xv)| f(v, xv));
        return;
    }
    x.par_chunks_mut(CHUNK).enumerate().for_each(|(c, xs)| {
        for (i, xv) in xs.iter_mut().enumerate() {
            f(c * CHUNK + i, xv);
        }
    });
}

/// No triangle across an edge (a rim).
const NONE: u32 = u32::MAX;

/// A collider's geometry: its triangles (quads split) and its vertices in each frame (one
/// frame: static). Shared between runs behind an `Arc`; compared by content checksum.
#[derive(Clone, Debug)]
pub struct ColliderMesh {
    /// The file or folder it was read from (messages and the run's record).
    source: PathBuf,
    tris: Vec<[u32; 3]>,
    frames: Vec<Vec<[f32; 3]>>,
    /// Per triangle and edge k (corner k to corner k+1), the triangle across it; [`NONE`] on a
    /// rim (an edge of one face, or of more than two, or two that disagree on orientation).
    across: Vec<[u32; 3]>,
    /// Vertices on a rim edge: their pseudo-normal says nothing of an inside.
    rim_vertex: Vec<bool>,
    closed: bool,
    /// The grid cell (m): the mean edge length of the first frame.
    cell: f32,
    /// Bounding box over every frame (m).
    bounds: ([f32; 3], [f32; 3]),
    checksum: u64,
}

impl PartialEq for ColliderMesh {
    /// Same source and same content (FNV-1a over triangles and positions): O(1).
    fn eq(&self, o: &ColliderMesh) -> bool {
        self.checksum == o.checksum && self.source == o.source
    }
}

impl ColliderMesh {
    /// A collider from `faces` (3 or more corners each; an n-gon is fanned; 0-based into each frame's vertices) and
    /// one vertex list per frame (one: static). Vertices at exactly the same place in every
    /// frame are welded (an export that splits vertices along seams is still closed); each
    /// quad is split along its shorter diagonal in the first frame. `source` names it in
    /// errors and records.
    pub fn new(source: impl Into<PathBuf>, faces: &[Vec<u32>], frames: Vec<Vec<[f32; 3]>>) -> Result<Self> {
        let source = source.into();
        let bad = |msg: String| Error::format(&source, msg);
        let n = frames.first().map_or(0, Vec::len);
        if n == 0 {
            return Err(bad("has no vertices: a collider is a mesh of triangles or quads".into()));
        }
        if let Some(k) = frames.iter().position(|f| f.len() != n) {
            return Err(bad(format!(
                "frame {k} has {} vertices, the first frame {n}: every frame of an animated \
                 collider is the same mesh moved",
                frames[k].len()
            )));
        }
        if let Some(k) = frames.iter().position(|f| f.iter().flatten().any(|c| !c.is_finite())) {
            return Err(bad(format!("frame {k} has a non-finite vertex coordinate")));
        }
        if faces.is_empty() {
            return Err(bad("has no faces: a collider is a mesh of triangles or quads".into()));
        }
        let rep = weld(&frames);
        let p0 = &frames[0];
        let mut tris = Vec::with_capacity(faces.len() * 2);
        for (i, f) in faces.iter().enumerate() {
            if let Some(&v) = f.iter().find(|&&v| v as usize >= n) {
                return Err(bad(format!("face {} references vertex {}, but it has {n}", i + 1, v + 1)));
            }
            let f: Vec<u32> = f.iter().map(|&v| rep[v as usize]).collect();
            match f[..] {
                [a, b, c] => tris.push([a, b, c]),
                [a, b, c, d] => {
                    let d2 = |u: u32, v: u32| {
                        let e = sub(p0[u as usize], p0[v as usize]);
                        dot(e, e)
                    };
                    if d2(a, c) <= d2(b, d) {
                        tris.extend([[a, b, c], [a, c, d]]);
                    } else {
                        tris.extend([[a, b, d], [b, c, d]]);
                    }
                }
                // An n-gon (a cylinder's cap, as modelling tools export it): a fan from its
                // first corner, right for the convex faces colliders have.
                _ if f.len() > 4 => tris.extend((1..f.len() - 1).map(|k| [f[0], f[k], f[k + 1]])),
                _ => {
                    return Err(bad(format!(
                        "face {} has {} corners: a face needs at least 3",
                        i + 1,
                        f.len()
                    )))
                }
            }
        }
        // Faces collapsed by the weld (two corners at one place) have no surface.
        tris.retain(|t| t[0] != t[1] && t[1] != t[2] && t[2] != t[0]);
        if tris.is_empty() {
            return Err(bad("has no face of non-zero size".into()));
        }
        let (mut across, mut rim_vertex, closed) = adjacency(&tris, n);
        if closed && signed_volume(p0, &tris) < 0.0 {
            tris.iter_mut().for_each(|t| t.swap(1, 2));
            (across, rim_vertex, _) = adjacency(&tris, n);
        }
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in frames.iter().flatten() {
            for c in 0..3 {
                lo[c] = lo[c].min(p[c]);
                hi[c] = hi[c].max(p[c]);
            }
        }
        let edges: f64 = tris
            .iter()
            .map(|t| {
                (0..3).map(|k| norm(sub(p0[t[k] as usize], p0[t[(k + 1) % 3] as usize])) as f64).sum::<f64>()
            })
            .sum();
        let cell = (edges / (3 * tris.len()) as f64) as f32;
        let mut h = Fnv::new();
        tris.iter().flatten().for_each(|v| h.eat(&v.to_le_bytes()));
        frames.iter().flatten().flatten().for_each(|c| h.eat(&c.to_bits().to_le_bytes()));
        Ok(ColliderMesh {
            source,
            tris,
            frames,
            across,
            rim_vertex,
            closed,
            cell,
            bounds: (lo, hi),
            checksum: h.0,
        })
    }

    /// Read a collider: an OBJ file (static) or a folder of OBJ frames in natural order
    /// (animated; every frame the first frame's mesh moved). Errors name the file at fault.
    pub fn read(path: &Path) -> Result<ColliderMesh> {
        if path.is_dir() {
            let files = list_obj_files(path)?;
            let first = parse_obj(&read_obj_text(&files[0])?, &files[0])?;
            let n = first.pos.len();
            let mut frames = vec![first.pos];
            for f in &files[1..] {
                let m = parse_obj(&read_obj_text(f)?, f)?;
                let name = files[0].file_name().unwrap_or_default().to_string_lossy();
                if m.pos.len() != n {
                    return Err(Error::format(
                        f,
                        format!(
                            "has {} vertices, the collider's first frame {name} has {n}: every frame \
                             of an animated collider is the same mesh moved",
                            m.pos.len()
                        ),
                    ));
                }
                if m.faces != first.faces {
                    return Err(Error::format(
                        f,
                        format!(
                            "has other faces than the collider's first frame {name}: every frame of \
                             an animated collider is the same mesh moved"
                        ),
                    ));
                }
                frames.push(m.pos);
            }
            let mut m = ColliderMesh::new(&files[0], &first.faces, frames)?;
            m.source = path.to_path_buf();
            Ok(m)
        } else if !path.exists() {
            Err(Error::format(
                path,
                "no such file or directory: a collider is an OBJ file or a folder of OBJ frames",
            ))
        } else if !path.extension().is_some_and(|e| e.eq_ignore_ascii_case("obj")) {
            Err(Error::format(path, "not an OBJ file: a collider is an OBJ file or a folder of OBJ frames"))
        } else {
            let m = parse_obj(&read_obj_text(path)?, path)?;
            ColliderMesh::new(path, &m.faces, vec![m.pos])
        }
    }

    /// The file or folder it came from.
    pub fn source(&self) -> &Path {
        &self.source
    }
    /// Frames: 1 for a static collider.
    pub fn frames(&self) -> usize {
        self.frames.len()
    }
    pub fn is_animated(&self) -> bool {
        self.frames.len() > 1
    }
    /// Triangles after quads are split.
    pub fn triangles(&self) -> usize {
        self.tris.len()
    }
    /// Closed (every edge between two faces that agree on orientation): an inside at any depth.
    pub fn is_closed(&self) -> bool {
        self.closed
    }
    /// FNV-1a of its triangles and positions: two colliders of one checksum are the same.
    pub fn checksum(&self) -> u64 {
        self.checksum
    }
    /// Bounding box over every frame (m).
    pub fn bounds(&self) -> ([f32; 3], [f32; 3]) {
        self.bounds
    }

    /// The vertices between frames `span` at `t` (0: `span.0`, 1: `span.1`).
    fn blend(&self, span: (usize, usize), t: f32) -> Vec<[f32; 3]> {
        let (a, b) = (&self.frames[span.0], &self.frames[span.1]);
        if span.0 == span.1 {
            return a.clone();
        }
        a.iter().zip(b).map(|(p, q)| std::array::from_fn(|c| p[c] + t * (q[c] - p[c]))).collect()
    }

    /// Signed distance (m) of each of `pts` from the surface in frame `frame` (negative
    /// inside; an open mesh's rim has no inside), through the same closest-point search and
    /// inside test as the contacts (frames past the last are the last). For tests and reports.
    pub fn signed_distances(&self, frame: usize, pts: &[[f32; 3]]) -> Vec<f32> {
        let pose = Pose::new(self, self.frames[frame.min(self.frames.len() - 1)].clone());
        pts.iter()
            .map(|&p| {
                let h = self.closest_anywhere(&pose, p);
                let d = h.d2.sqrt();
                match self.side_normal(&pose, &h) {
                    Some(n) if dot(sub(p, h.point), n) < 0.0 => -d,
                    _ => d,
                }
            })
            .collect()
    }
}

/// FNV-1a, 64 bits.
struct Fnv(u64);
impl Fnv {
    fn new() -> Fnv {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
    fn eat(&mut self, bytes: &[u8]) {
        bytes.iter().for_each(|&b| self.0 = (self.0 ^ b as u64).wrapping_mul(0x0100_0000_01b3));
    }
}

/// For each vertex, the lowest-numbered vertex at exactly its place in every frame.
fn weld(frames: &[Vec<[f32; 3]>]) -> Vec<u32> {
    let n = frames[0].len();
    // `+ 0.0` makes −0 and 0 one key.
    let key = |v: usize| frames[0][v].map(|c| (c + 0.0).to_bits());
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_unstable_by_key(|&v| (key(v), v));
    let mut rep: Vec<u32> = (0..n as u32).collect();
    let mut run = 0;
    while run < n {
        let end = (run..n).find(|&i| key(order[i]) != key(order[run])).unwrap_or(n);
        for i in run + 1..end {
            let v = order[i];
            if let Some(&u) = order[run..i].iter().find(|&&u| frames.iter().all(|f| f[u] == f[v])) {
                rep[v] = rep[u];
            }
        }
        run = end;
    }
    rep
}

/// Edge adjacency of `tris` over `n` vertices: the triangle across each edge, the rim
/// vertices, and whether the mesh is closed and consistently oriented.
fn adjacency(tris: &[[u32; 3]], n: usize) -> (Vec<[u32; 3]>, Vec<bool>, bool) {
    // (low vertex, high vertex, triangle, edge, runs low → high).
    let mut half: Vec<(u32, u32, u32, u8, bool)> = Vec::with_capacity(3 * tris.len());
    for (t, tri) in tris.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            half.push((a.min(b), a.max(b), t as u32, k as u8, a < b));
        }
    }
    half.sort_unstable();
    let mut across = vec![[NONE; 3]; tris.len()];
    let mut rim_vertex = vec![false; n];
    let mut closed = true;
    for g in half.chunk_by(|x, y| (x.0, x.1) == (y.0, y.1)) {
        if let [e, f] = g {
            if e.4 != f.4 {
                across[e.2 as usize][e.3 as usize] = f.2;
                across[f.2 as usize][f.3 as usize] = e.2;
                continue;
            }
        }
        closed = false;
        rim_vertex[g[0].0 as usize] = true;
        rim_vertex[g[0].1 as usize] = true;
    }
    (across, rim_vertex, closed)
}

/// Six times the volume enclosed by `tris` (positive when wound outward), in f64.
fn signed_volume(p: &[[f32; 3]], tris: &[[u32; 3]]) -> f64 {
    let f = |v: u32| p[v as usize].map(f64::from);
    tris.iter().map(|t| dot(f(t[0]), cross(f(t[1]), f(t[2])))).sum()
}

/// Where on a triangle the closest point lies: a corner, an edge (corner k to k+1), the face.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Feature {
    Vertex(u8),
    Edge(u8),
    Face,
}

/// The closest point of a query on the surface.
#[derive(Clone, Copy, Debug)]
struct Hit {
    point: [f32; 3],
    /// Squared distance (m²).
    d2: f32,
    tri: u32,
    /// Barycentric coordinates of `point` on `tri`.
    bary: [f32; 3],
    feature: Feature,
}

impl Hit {
    /// Closer, or as close and of a lower triangle: the order does not depend on the search's.
    fn beats(&self, o: &Option<Hit>) -> bool {
        o.is_none_or(|o| self.d2 < o.d2 || (self.d2 == o.d2 && self.tri < o.tri))
    }
}

/// `n / d`, 0 where `d` is not positive (a degenerate triangle).
#[inline]
fn ratio(n: f32, d: f32) -> f32 {
    if d > 0.0 {
        n / d
    } else {
        0.0
    }
}

/// The closest point to `p` on triangle `(a, b, c)` (Ericson 2005, "Real-Time Collision
/// Detection", 5.1.5): point, barycentrics, feature.
fn closest_on_triangle(p: [f32; 3], a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> ([f32; 3], [f32; 3], Feature) {
    let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(p, a));
    let (d1, d2) = (dot(ab, ap), dot(ac, ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return (a, [1.0, 0.0, 0.0], Feature::Vertex(0));
    }
    let bp = sub(p, b);
    let (d3, d4) = (dot(ab, bp), dot(ac, bp));
    if d3 >= 0.0 && d4 <= d3 {
        return (b, [0.0, 1.0, 0.0], Feature::Vertex(1));
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = ratio(d1, d1 - d3);
        return (add(a, scale(ab, v)), [1.0 - v, v, 0.0], Feature::Edge(0));
    }
    let cp = sub(p, c);
    let (d5, d6) = (dot(ab, cp), dot(ac, cp));
    if d6 >= 0.0 && d5 <= d6 {
        return (c, [0.0, 0.0, 1.0], Feature::Vertex(2));
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = ratio(d2, d2 - d6);
        return (add(a, scale(ac, w)), [1.0 - w, 0.0, w], Feature::Edge(2));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        let w = ratio(d4 - d3, (d4 - d3) + (d5 - d6));
        return (add(b, scale(sub(c, b), w)), [0.0, 1.0 - w, w], Feature::Edge(1));
    }
    let s = va + vb + vc;
    let (v, w) = (ratio(vb, s), ratio(vc, s));
    (add(a, add(scale(ab, v), scale(ac, w))), [1.0 - v - w, v, w], Feature::Face)
}

/// One pose of a collider: vertices, unit face normals, angle-weighted vertex pseudo-normals
/// and the grid over its triangles.
struct Pose {
    pos: Vec<[f32; 3]>,
    face_n: Vec<[f32; 3]>,
    /// Per triangle, a sphere around it (centroid, radius; m): most triangles of a cell are
    /// rejected by it before the closest-point test.
    ball: Vec<([f32; 3], f32)>,
    vert_n: Vec<[f32; 3]>,
    grid: Grid,
}

impl Pose {
    fn new(mesh: &ColliderMesh, pos: Vec<[f32; 3]>) -> Pose {
        let mut face_n = Vec::with_capacity(mesh.tris.len());
        let mut ball = Vec::with_capacity(mesh.tris.len());
        let mut vert_n = vec![[0.0f32; 3]; pos.len()];
        for t in &mesh.tris {
            let p = t.map(|v| pos[v as usize]);
            let n = normalize_or(cross(sub(p[1], p[0]), sub(p[2], p[0])), [0.0; 3]);
            face_n.push(n);
            let c = scale(add(add(p[0], p[1]), p[2]), 1.0 / 3.0);
            ball.push((c, p.iter().map(|q| norm(sub(*q, c))).fold(0.0f32, f32::max)));
            for k in 0..3 {
                let (u, w) = (sub(p[(k + 1) % 3], p[k]), sub(p[(k + 2) % 3], p[k]));
                let angle = norm(cross(u, w)).atan2(dot(u, w));
                let vn = &mut vert_n[t[k] as usize];
                *vn = add(*vn, scale(n, angle));
            }
        }
        vert_n.iter_mut().for_each(|n| *n = normalize_or(*n, [0.0; 3]));
        let grid = Grid::new(&pos, &mesh.tris, mesh.cell);
        Pose { pos, face_n, ball, vert_n, grid }
    }

    fn corners(&self, tris: &[[u32; 3]], t: u32) -> [[f32; 3]; 3] {
        tris[t as usize].map(|v| self.pos[v as usize])
    }
}

/// A uniform grid of cells of side `cell` (m) from `origin`, hashed: each occupied cell lists
/// the triangles whose bounding boxes overlap it, in triangle order.
struct Grid {
    origin: [f32; 3],
    cell: f32,
    /// Cells along each axis over the triangles' bounding box.
    dims: [i64; 3],
    /// Open addressing (linear probing), a power of two long; `len == 0`: empty.
    slots: Vec<Slot>,
    items: Vec<u32>,
    tris: usize,
}

#[derive(Clone, Copy, Default)]
struct Slot {
    cell: u64,
    start: u32,
    len: u32,
}

impl Grid {
    fn new(pos: &[[f32; 3]], tris: &[[u32; 3]], mean_edge: f32) -> Grid {
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for t in tris {
            for &v in t {
                for c in 0..3 {
                    lo[c] = lo[c].min(pos[v as usize][c]);
                    hi[c] = hi[c].max(pos[v as usize][c]);
                }
            }
        }
        let extent = (0..3).map(|c| hi[c] - lo[c]).fold(0.0f32, f32::max);
        let mut cell = mean_edge.max(extent / MAX_CELLS_PER_AXIS).max(f32::MIN_POSITIVE.sqrt());
        let range = |t: &[u32; 3], cell: f32| -> ([i64; 3], [i64; 3]) {
            let p = t.map(|v| pos[v as usize]);
            let k = |x: f32, c: usize| ((x - lo[c]) / cell).floor() as i64;
            (
                std::array::from_fn(|c| k(p[0][c].min(p[1][c]).min(p[2][c]), c)),
                std::array::from_fn(|c| k(p[0][c].max(p[1][c]).max(p[2][c]), c)),
            )
        };
        let budget = ENTRIES_PER_TRIANGLE * tris.len() + 4096;
        loop {
            let entries: usize = tris
                .iter()
                .map(|t| {
                    let (a, b) = range(t, cell);
                    (0..3).map(|c| (b[c] - a[c] + 1) as usize).product::<usize>()
                })
                .sum();
            if entries <= budget {
                break;
            }
            cell *= 2.0;
        }
        let dims: [i64; 3] = std::array::from_fn(|c| ((hi[c] - lo[c]) / cell).floor() as i64 + 1);
        let lin = |k: [i64; 3]| (k[0] + dims[0] * (k[1] + dims[1] * k[2])) as u64;
        let mut entries: Vec<(u64, u32)> = Vec::new();
        for (t, tri) in tris.iter().enumerate() {
            let (a, b) = range(tri, cell);
            for z in a[2]..=b[2] {
                for y in a[1]..=b[1] {
                    for x in a[0]..=b[0] {
                        entries.push((lin([x, y, z]), t as u32));
                    }
                }
            }
        }
        entries.sort_unstable();
        let cells = entries.chunk_by(|a, b| a.0 == b.0).count();
        let size = (2 * cells).next_power_of_two().max(16);
        let mut slots = vec![Slot::default(); size];
        let items: Vec<u32> = entries.iter().map(|e| e.1).collect();
        let mut start = 0;
        for g in entries.chunk_by(|a, b| a.0 == b.0) {
            let mut i = slot_of(g[0].0, size);
            while slots[i].len != 0 {
                i = (i + 1) & (size - 1);
            }
            slots[i] = Slot { cell: g[0].0, start: start as u32, len: g.len() as u32 };
            start += g.len();
        }
        Grid { origin: lo, cell, dims, slots, items, tris: tris.len() }
    }

    /// The cells (inclusive index ranges) that the box `lo..hi` overlaps, clipped to the grid;
    /// `None` when it misses the grid.
    fn cells(&self, lo: [f32; 3], hi: [f32; 3]) -> Option<([i64; 3], [i64; 3])> {
        let mut a = [0i64; 3];
        let mut b = [0i64; 3];
        for c in 0..3 {
            let d = self.dims[c] as f32;
            let k0 = ((lo[c] - self.origin[c]) / self.cell).floor();
            let k1 = ((hi[c] - self.origin[c]) / self.cell).floor();
            // NaN fails both tests: no cells.
            if !(k1 >= 0.0 && k0 < d) {
                return None;
            }
            a[c] = k0.max(0.0) as i64;
            b[c] = k1.min(d - 1.0) as i64;
        }
        Some((a, b))
    }

    /// The triangles listed in cell `k` (in triangle order).
    fn cell(&self, k: [i64; 3]) -> &[u32] {
        let lin = (k[0] + self.dims[0] * (k[1] + self.dims[1] * k[2])) as u64;
        let size = self.slots.len();
        let mut i = slot_of(lin, size);
        loop {
            let s = self.slots[i];
            if s.len == 0 {
                return &[];
            }
            if s.cell == lin {
                return &self.items[s.start as usize..(s.start + s.len) as usize];
            }
            i = (i + 1) & (size - 1);
        }
    }

    /// Call `f` on every triangle whose cells overlap `lo..hi` (a triangle in several cells
    /// once per cell), or on every triangle when that is fewer visits.
    fn visit(&self, lo: [f32; 3], hi: [f32; 3], mut f: impl FnMut(u32)) {
        let Some((a, b)) = self.cells(lo, hi) else { return };
        let cells: i64 = (0..3).map(|c| b[c] - a[c] + 1).product();
        if cells as usize > self.tris {
            (0..self.tris as u32).for_each(f);
            return;
        }
        for z in a[2]..=b[2] {
            for y in a[1]..=b[1] {
                for x in a[0]..=b[0] {
                    self.cell([x, y, z]).iter().for_each(|&t| f(t));
                }
            }
        }
    }
}

/// The slot a cell's linear index hashes to (Fibonacci hashing) in a table of `size` (a power
/// of two) slots.
#[inline]
fn slot_of(cell: u64, size: usize) -> usize {
    (cell.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> (64 - size.trailing_zeros())) as usize
}

/// Where a vertex's motion enters a triangle from its front.
#[derive(Clone, Copy, Debug)]
struct Entry {
    tri: u32,
    /// Where on the triangle (m).
    point: [f32; 3],
    /// The motion's start, carried with the triangle (m).
    start: [f32; 3],
}

impl ColliderMesh {
    /// The closest point of `pose`'s surface to `p` within `r` (m), if any.
    fn closest_within(&self, pose: &Pose, p: [f32; 3], r: f32) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let r2 = r * r;
        pose.grid.visit(sub(p, [r; 3]), add(p, [r; 3]), |t| {
            let (centre, radius) = pose.ball[t as usize];
            let e = sub(p, centre);
            if dot(e, e) > (r + radius) * (r + radius) {
                return;
            }
            let h = self.hit(pose, p, t);
            if h.d2 <= r2 && h.beats(&best) {
                best = Some(h);
            }
        });
        best
    }

    /// The closest point of `pose`'s surface to `p`, however far: the search box doubles
    /// until it holds one, and past the grid's far corner every triangle is tested.
    fn closest_anywhere(&self, pose: &Pose, p: [f32; 3]) -> Hit {
        let g = &pose.grid;
        let far_corner: [f32; 3] = std::array::from_fn(|c| {
            let (lo, hi) = (g.origin[c], g.origin[c] + g.dims[c] as f32 * g.cell);
            (p[c] - lo).abs().max((p[c] - hi).abs())
        });
        // NaN (a cloth that blew up) skips the loop.
        let r_max = norm(far_corner);
        let mut r = g.cell;
        while r < r_max {
            if let Some(h) = self.closest_within(pose, p, r) {
                return h;
            }
            r *= 2.0;
        }
        // A collider has at least one triangle ([`ColliderMesh::new`]).
        let mut best = self.hit(pose, p, 0);
        for t in 1..self.tris.len() as u32 {
            let h = self.hit(pose, p, t);
            if h.beats(&Some(best)) {
                best = h;
            }
        }
        best
    }

    /// The closest point to `p` on triangle `t` of `pose`.
    fn hit(&self, pose: &Pose, p: [f32; 3], t: u32) -> Hit {
        let [a, b, c] = pose.corners(&self.tris, t);
        let (point, bary, feature) = closest_on_triangle(p, a, b, c);
        let d = sub(p, point);
        Hit { point, d2: dot(d, d), tri: t, bary, feature }
    }

    /// The normal that says which side of the closest feature `h` is outside: the face's, an
    /// edge's or a vertex's pseudo-normal; `None` on an open mesh's rim (no inside there).
    fn side_normal(&self, pose: &Pose, h: &Hit) -> Option<[f32; 3]> {
        let t = h.tri as usize;
        match h.feature {
            Feature::Face => Some(pose.face_n[t]),
            Feature::Edge(k) => {
                let u = self.across[t][k as usize];
                (u != NONE)
                    .then(|| normalize_or(add(pose.face_n[t], pose.face_n[u as usize]), pose.face_n[t]))
            }
            Feature::Vertex(k) => {
                let v = self.tris[t][k as usize] as usize;
                (!self.rim_vertex[v]).then(|| pose.vert_n[v])
            }
        }
    }

    /// Where the motion `p0 → p1` first enters a triangle of `pose` from its front, each
    /// triangle's start point carried by its mean displacement from `before` (the pose at the
    /// motion's start; `None`: static), which is at most `moved` (m).
    fn first_entry(
        &self,
        pose: &Pose,
        before: Option<&[[f32; 3]]>,
        moved: f32,
        p0: [f32; 3],
        p1: [f32; 3],
    ) -> Option<Entry> {
        let lo: [f32; 3] = std::array::from_fn(|c| p0[c].min(p1[c]) - moved);
        let hi: [f32; 3] = std::array::from_fn(|c| p0[c].max(p1[c]) + moved);
        let mut best: Option<(f32, Entry)> = None;
        pose.grid.visit(lo, hi, |t| {
            let tri = self.tris[t as usize];
            let [a, b, c] = pose.corners(&self.tris, t);
            let start = match before {
                Some(q) => {
                    let d: [f32; 3] = std::array::from_fn(|k| {
                        tri.iter().map(|&v| pose.pos[v as usize][k] - q[v as usize][k]).sum::<f32>() / 3.0
                    });
                    add(p0, d)
                }
                None => p0,
            };
            // Only from the front of the triangle's plane to its back.
            let n = pose.face_n[t as usize];
            if !(dot(sub(start, a), n) >= 0.0 && dot(sub(p1, a), n) < 0.0) {
                return;
            }
            // Möller & Trumbore 1997; det > 0: the motion runs against the face normal.
            let dir = sub(p1, start);
            let (e1, e2) = (sub(b, a), sub(c, a));
            let pv = cross(dir, e2);
            let det = dot(e1, pv);
            if det <= 0.0 {
                return;
            }
            let tv = sub(start, a);
            let u = dot(tv, pv) / det;
            if !(-EDGE_SLACK..=1.0 + EDGE_SLACK).contains(&u) {
                return;
            }
            let qv = cross(tv, e1);
            let v = dot(dir, qv) / det;
            if v < -EDGE_SLACK || u + v > 1.0 + EDGE_SLACK {
                return;
            }
            let s = dot(e2, qv) / det;
            if !(0.0..=1.0).contains(&s) {
                return;
            }
            if best.is_none_or(|(bs, be)| s < bs || (s == bs && t < be.tri)) {
                best = Some((s, Entry { tri: t, point: add(start, scale(dir, s)), start }));
            }
        });
        best.map(|b| b.1)
    }

    /// The direction (unit) and distance (m) that take `x`, whose closest point is `h`, to
    /// `thickness` outside; `None` when it is outside already.
    fn push(&self, pose: &Pose, h: &Hit, x: [f32; 3], thickness: f32) -> Option<([f32; 3], f32)> {
        let d = sub(x, h.point);
        let dist = h.d2.sqrt();
        let side = self.side_normal(pose, h);
        let sure = dist > DIRECTION_FLOOR * thickness;
        match side {
            Some(n) if dot(d, n) < 0.0 => {
                Some((if sure { scale(d, -1.0 / dist) } else { n }, dist + thickness))
            }
            _ if dist < thickness => {
                let n = side.unwrap_or(pose.face_n[h.tri as usize]);
                Some((if sure { scale(d, 1.0 / dist) } else { n }, thickness - dist))
            }
            _ => None,
        }
    }
}

/// A mesh collider in a scene: its geometry, its thickness, and the frames the next step
/// blends between.
#[derive(Clone)]
pub struct MeshCollider {
    mesh: Arc<ColliderMesh>,
    /// Gap (m) the cloth keeps from the surface.
    thickness: f32,
    /// Shot frames the step runs from and to (equal: still).
    span: (usize, usize),
    /// The pose at `span.1`.
    end: Arc<Pose>,
}

impl std::fmt::Debug for MeshCollider {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MeshCollider")
            .field("source", &self.mesh.source)
            .field("triangles", &self.mesh.tris.len())
            .field("frames", &self.mesh.frames.len())
            .field("thickness", &self.thickness)
            .field("span", &self.span)
            .finish()
    }
}

impl MeshCollider {
    /// `mesh` keeping the cloth `thickness` (m) away, posed at its first frame.
    pub fn new(mesh: Arc<ColliderMesh>, thickness: f32) -> MeshCollider {
        let end = Arc::new(Pose::new(&mesh, mesh.frames[0].clone()));
        MeshCollider { mesh, thickness, span: (0, 0), end }
    }

    pub fn mesh(&self) -> &ColliderMesh {
        &self.mesh
    }

    /// The next step runs from frame `from` to frame `to` of the collider (a static one stays
    /// at its frame): the substeps blend linearly between them. Frames past its last are an
    /// error naming it.
    pub fn set_span(&mut self, from: usize, to: usize) -> Result<()> {
        let n = self.mesh.frames.len();
        let span = if n == 1 { (0, 0) } else { (from, to) };
        if span.0 >= n || span.1 >= n {
            return Err(Error::format(
                &self.mesh.source,
                format!(
                    "the animated collider has {n} frames and the shot reached frame {}: it needs \
                     one frame per frame of the shot",
                    span.0.max(span.1)
                ),
            ));
        }
        if span.1 != self.span.1 {
            self.end = Arc::new(Pose::new(&self.mesh, self.mesh.frames[span.1].clone()));
        }
        self.span = span;
        Ok(())
    }

    /// Contacts of one substep (see the module docs): the collider moves from its pose at
    /// `blends.0` of the span to its pose at `blends.1`; `x` are the positions after the
    /// constraints, `prev` at the substep's start, `mu` the friction coefficient.
    pub fn substep(
        &self,
        x: &mut [[f32; 3]],
        prev: &[[f32; 3]],
        inv_mass: &[f32],
        blends: (f32, f32),
        mu: f32,
    ) {
        let moving = self.span.0 != self.span.1;
        let owned;
        let (pose, before) = if moving {
            let p0 = self.mesh.blend(self.span, blends.0);
            let p1 = Pose::new(&self.mesh, self.mesh.blend(self.span, blends.1));
            owned = (p0, p1);
            (&owned.1, Some(owned.0.as_slice()))
        } else {
            (&*self.end, None)
        };
        let moved = before
            .map_or(0.0, |b| pose.pos.iter().zip(b).map(|(p, q)| norm(sub(*p, *q))).fold(0.0, f32::max));
        let reach = REACH * self.thickness;
        let m = &*self.mesh;
        for_vertices(x, |v, xv| {
            if inv_mass[v] <= 0.0 {
                return;
            }
            // The motion's start (carried by any triangle) lies within `way` of `x`: it
            // can cross no surface when the closest one is farther.
            let mut near = m.closest_within(pose, *xv, reach);
            let way = norm(sub(*xv, prev[v])) + moved;
            if way >= near.map_or(reach, |h| h.d2.sqrt()) {
                if let Some(e) = m.first_entry(pose, before, moved, prev[v], *xv) {
                    let n = pose.face_n[e.tri as usize];
                    let pen = self.thickness - dot(sub(*xv, e.point), n);
                    resolve(xv, e.start, n, pen, mu);
                    near = m.closest_within(pose, *xv, reach);
                }
            }
            if let Some(h) = near {
                if let Some((n, pen)) = m.push(pose, &h, *xv, self.thickness) {
                    // The start carried with the surface: friction on the relative motion.
                    let start = match before {
                        Some(b) => {
                            let t = m.tris[h.tri as usize];
                            let was: [f32; 3] = std::array::from_fn(|k| {
                                (0..3).map(|j| h.bary[j] * b[t[j] as usize][k]).sum::<f32>()
                            });
                            add(prev[v], sub(h.point, was))
                        }
                        None => prev[v],
                    };
                    resolve(xv, start, n, pen, mu);
                }
            }
        });
    }

    /// Take every vertex of `x` (those with `free[v] > 0`, or all) out of the collider at the
    /// span's end pose, to `thickness` outside, without friction: first back across any
    /// surface its way from `from[v]` (where it was known to be outside) enters, then out of
    /// the inside (a closed mesh's at any depth) and of the thickness.
    pub fn push_out(&self, x: &mut [[f32; 3]], from: Option<&[[f32; 3]]>, free: Option<&[f32]>) {
        let (pose, m, t) = (&*self.end, &*self.mesh, self.thickness);
        let reach = REACH * t;
        let (lo, hi) = (sub(m.bounds.0, [reach; 3]), add(m.bounds.1, [reach; 3]));
        for_vertices(x, |v, xv| {
            if free.is_some_and(|f| f[v] <= 0.0) || !xv.iter().all(|c| c.is_finite()) {
                return;
            }
            if let Some(f) = from {
                if let Some(e) = m.first_entry(pose, None, 0.0, f[v], *xv) {
                    let n = pose.face_n[e.tri as usize];
                    let pen = t - dot(sub(*xv, e.point), n);
                    *xv = add(*xv, scale(n, pen));
                }
            }
            for _ in 0..PUSH_OUT_PASSES {
                if (0..3).any(|k| xv[k] < lo[k] || xv[k] > hi[k]) {
                    break;
                }
                let h = if m.closed {
                    Some(m.closest_anywhere(pose, *xv))
                } else {
                    m.closest_within(pose, *xv, reach)
                };
                match h.and_then(|h| m.push(pose, &h, *xv, t)) {
                    Some((n, pen)) => *xv = add(*xv, scale(n, pen)),
                    None => break,
                }
            }
        });
    }

    /// Take the faces `tris` of `x` out of the collider at the span's end pose: a triangle whose
    /// centroid lies inside it, or nearer than half the thickness, moves its corners (those with
    /// `free[v] > 0`, or all) along the surface's normal there until its centroid is that far
    /// outside. Over a curved body thinner than a few faces (an arm in a sleeve) a face sags
    /// into it between corners that each keep the thickness: the body showed through the cloth.
    /// Two sweeps in triangle order (deterministic).
    pub fn push_faces_out(&self, x: &mut [[f32; 3]], tris: &[[usize; 3]], free: Option<&[f32]>) {
        let (pose, m) = (&*self.end, &*self.mesh);
        let gap = 0.5 * self.thickness;
        let reach = REACH * self.thickness;
        let (lo, hi) = (sub(m.bounds.0, [reach; 3]), add(m.bounds.1, [reach; 3]));
        for _ in 0..2 {
            for tr in tris {
                let c: [f32; 3] = std::array::from_fn(|k| (x[tr[0]][k] + x[tr[1]][k] + x[tr[2]][k]) / 3.0);
                if (0..3).any(|k| !(c[k] >= lo[k] && c[k] <= hi[k])) {
                    continue;
                }
                let h = if m.closed {
                    Some(m.closest_anywhere(pose, c))
                } else {
                    m.closest_within(pose, c, reach)
                };
                if let Some((n, pen)) = h.and_then(|h| m.push(pose, &h, c, gap)) {
                    for &v in tr {
                        if free.is_none_or(|f| f[v] > 0.0) {
                            x[v] = add(x[v], scale(n, pen));
                        }
                    }
                }
            }
        }
    }
}

/// The mesh of an axis-aligned box: 8 corners and 6 quads wound outward (counter-clockwise
/// seen from outside), corner `i` at `center ± half` by the bits of `i` (x, y, z).
pub fn cuboid(b: Cuboid) -> (Vec<[f32; 3]>, Vec<Vec<u32>>) {
    let pos = (0..8)
        .map(|i| std::array::from_fn(|c| b.center[c] + (((i >> c) & 1) as f32 * 2.0 - 1.0) * b.half[c]))
        .collect();
    let faces = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
    (pos, faces.iter().map(|f| f.to_vec()).collect())
}

/// The mesh of a UV sphere inscribed in `s`: `segments` around its y axis, `rings` from pole to
/// pole (a triangle fan at each pole, quads between), wound outward. Its facets lie inside
/// the sphere by at most `r·(1 − cos(π/rings)·cos(π/segments))`.
pub fn uv_sphere(s: Sphere, segments: usize, rings: usize) -> (Vec<[f32; 3]>, Vec<Vec<u32>>) {
    let (c, r) = (s.center, s.radius);
    let mut pos = vec![[c[0], c[1] + r, c[2]]];
    for j in 1..rings {
        let th = std::f32::consts::PI * j as f32 / rings as f32;
        for i in 0..segments {
            let ph = 2.0 * std::f32::consts::PI * i as f32 / segments as f32;
            pos.push([c[0] + r * th.sin() * ph.cos(), c[1] + r * th.cos(), c[2] - r * th.sin() * ph.sin()]);
        }
    }
    pos.push([c[0], c[1] - r, c[2]]);
    let ring = |j: usize, i: usize| (1 + (j - 1) * segments + i % segments) as u32;
    let last = pos.len() as u32 - 1;
    let mut faces = Vec::new();
    for i in 0..segments {
        faces.push(vec![0, ring(1, i), ring(1, i + 1)]);
        for j in 1..rings - 1 {
            faces.push(vec![ring(j, i), ring(j + 1, i), ring(j + 1, i + 1), ring(j, i + 1)]);
        }
        faces.push(vec![ring(rings - 1, i), last, ring(rings - 1, i + 1)]);
    }
    (pos, faces)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn box_mesh(center: [f32; 3], half: [f32; 3], inward: bool) -> ColliderMesh {
        let (pos, mut faces) = cuboid(Cuboid { center, half });
        if inward {
            faces.iter_mut().for_each(|f| f.reverse());
        }
        ColliderMesh::new("box", &faces, vec![pos]).unwrap()
    }

    fn uv_sphere(center: [f32; 3], radius: f32, segments: usize, rings: usize) -> ColliderMesh {
        let (pos, faces) = super::uv_sphere(Sphere { center, radius }, segments, rings);
        ColliderMesh::new("sphere", &faces, vec![pos]).unwrap()
    }

    fn rng_points(n: usize, lo: f32, hi: f32, seed: u64) -> Vec<[f32; 3]> {
        let mut r = crate::rng::Rng::new(seed);
        (0..n).map(|_| std::array::from_fn(|_| r.uniform_in(lo, hi))).collect()
    }

    #[test]
    fn a_face_sagging_into_a_thin_body_between_corners_outside_is_pushed_out() {
        // A ball of 4 cm and a triangle 6 cm across lying on its top: every corner is more
        // than the thickness away, the centroid 1 cm inside.
        let mesh = Arc::new(uv_sphere([0.0, 0.0, 0.0], 0.04, 32, 16));
        let col = MeshCollider::new(mesh.clone(), 0.005);
        let y = 0.03;
        let mut x = vec![[-0.05, y, -0.03], [0.05, y, -0.03], [0.0, y, 0.06], [0.3, 0.3, 0.3]];
        let tris = [[0usize, 1, 2]];
        let before = mesh.signed_distances(0, &x[..3]);
        assert!(before.iter().all(|d| *d > 0.005), "{before:?}");
        let centroid =
            |x: &[[f32; 3]]| -> [f32; 3] { std::array::from_fn(|k| (x[0][k] + x[1][k] + x[2][k]) / 3.0) };
        assert!(mesh.signed_distances(0, &[centroid(&x)])[0] < 0.0);
        // A held corner stays; with none held the face comes out.
        let mut held = x.clone();
        col.push_faces_out(&mut held, &tris, Some(&[0.0, 0.0, 0.0, 1.0]));
        assert_eq!(held, x);
        col.push_faces_out(&mut x, &tris, None);
        let after = mesh.signed_distances(0, &[centroid(&x)])[0];
        assert!(after >= 0.5 * 0.005 - 1e-5, "centroid {after} m from the surface");
        assert_eq!(x[3], [0.3, 0.3, 0.3], "a vertex of no face moved");
    }

    #[test]
    fn box_mesh_distances_and_insides_match_the_analytic_box() {
        let (c, h) = ([0.1, 0.5, -0.2], [0.3, 0.2, 0.4]);
        for inward in [false, true] {
            let m = box_mesh(c, h, inward);
            assert!(m.is_closed() && m.triangles() == 12);
            let pts = rng_points(2000, -0.8, 1.2, 3);
            let sd = m.signed_distances(0, &pts);
            for (p, s) in pts.iter().zip(&sd) {
                let q: [f32; 3] = std::array::from_fn(|k| (p[k] - c[k]).abs() - h[k]);
                let out = norm(q.map(|v| v.max(0.0)));
                let exact = out + q[0].max(q[1]).max(q[2]).min(0.0);
                assert!((s - exact).abs() < 1e-5, "inward {inward}: {p:?}: {s} vs {exact}");
            }
        }
    }

    #[test]
    fn uv_sphere_mesh_distances_are_the_spheres_within_its_facets() {
        let (c, r) = ([0.2, 0.4, 0.0], 0.3);
        let m = uv_sphere(c, r, 32, 16);
        assert!(m.is_closed(), "a UV sphere is closed");
        assert!((900..1100).contains(&m.triangles()), "{}", m.triangles());
        // The facets lie inside the sphere by at most r(1 − cos(π/16)·cos(π/32)) (a quad's
        // centre): 2.3 mm here.
        let sag = r * (1.0 - (std::f32::consts::PI / 16.0).cos() * (std::f32::consts::PI / 32.0).cos());
        let pts = rng_points(3000, -0.3, 0.8, 5);
        for (p, s) in pts.iter().zip(m.signed_distances(0, &pts)) {
            let exact = norm(sub(*p, c)) - r;
            assert!(s >= exact - 1e-5 && s <= exact + sag + 1e-5, "{p:?}: {s} vs sphere {exact}");
            if exact.abs() > sag {
                assert_eq!(s < 0.0, exact < 0.0, "{p:?}: inside test");
            }
        }
    }

    #[test]
    fn grid_search_finds_what_testing_every_triangle_finds() {
        let m = uv_sphere([0.0, 0.0, 0.0], 0.5, 24, 12);
        let pose = Pose::new(&m, m.frames[0].clone());
        for p in rng_points(2000, -0.9, 0.9, 9) {
            let mut best: Option<Hit> = None;
            for t in 0..m.tris.len() as u32 {
                let h = m.hit(&pose, p, t);
                if h.beats(&best) {
                    best = Some(h);
                }
            }
            let (b, g) = (best.unwrap(), m.closest_anywhere(&pose, p));
            assert_eq!((b.tri, b.d2), (g.tri, g.d2), "{p:?}");
            let near = m.closest_within(&pose, p, 0.05);
            assert_eq!(near.map(|h| h.tri), (b.d2 <= 0.05 * 0.05).then_some(b.tri), "{p:?}");
        }
    }

    #[test]
    fn a_fast_vertex_does_not_pass_through_a_thin_plate() {
        // A 2 mm plate (a closed box) and a one-sided quad, each crossed in one substep by a
        // vertex at 30 m/s (5 cm in a 600 Hz substep): it ends in front, a thickness off.
        let plate = box_mesh([0.0, 1.0, 0.0], [0.5, 0.001, 0.5], false);
        let quad = ColliderMesh::new(
            "quad",
            &[vec![0, 1, 2, 3]],
            vec![vec![[-0.5, 1.0, -0.5], [-0.5, 1.0, 0.5], [0.5, 1.0, 0.5], [0.5, 1.0, -0.5]]],
        )
        .unwrap();
        assert!(!quad.is_closed());
        for m in [plate, quad] {
            let top = m.bounds().1[1];
            let col = MeshCollider::new(Arc::new(m), COLLIDER_THICKNESS);
            let prev = vec![[0.1, 1.02, 0.05], [0.3, 1.03, -0.2]];
            let mut x = vec![[0.1, 0.97, 0.05], [0.32, 0.98, -0.2]];
            col.substep(&mut x, &prev, &[1.0, 1.0], (0.0, 1.0), 0.0);
            for p in &x {
                assert!(
                    (p[1] - (top + COLLIDER_THICKNESS)).abs() < 1e-5,
                    "{:?} ended at {p:?}",
                    col.mesh().source()
                );
            }
            // Without the crossing test the closest point alone leaves it below.
            let h = col.mesh.closest_within(&col.end, [0.1, 0.97, 0.05], REACH * COLLIDER_THICKNESS);
            assert!(h.is_none());
            // From behind the one-sided quad (out of the inside) it passes.
            let mut x = vec![[0.1, 1.05, 0.05]];
            col.substep(&mut x, &[[0.1, 0.95, 0.05]], &[1.0], (0.0, 1.0), 0.0);
            if !col.mesh.is_closed() {
                assert_eq!(x[0], [0.1, 1.05, 0.05]);
            }
        }
    }

    #[test]
    fn a_plate_moving_up_into_a_vertex_lifts_it() {
        // An animated quad rises 3 cm through a still vertex in one substep.
        let quad = |y: f32| vec![[-0.5, y, -0.5], [-0.5, y, 0.5], [0.5, y, 0.5], [0.5, y, -0.5]];
        let m = ColliderMesh::new("rising", &[vec![0, 1, 2, 3]], vec![quad(0.98), quad(1.01)]).unwrap();
        let mut col = MeshCollider::new(Arc::new(m), COLLIDER_THICKNESS);
        col.set_span(0, 1).unwrap();
        let mut x = vec![[0.0, 1.0, 0.0]];
        col.substep(&mut x, &[[0.0, 1.0, 0.0]], &[1.0], (0.0, 1.0), 0.5);
        assert!((x[0][1] - (1.01 + COLLIDER_THICKNESS)).abs() < 1e-5, "{:?}", x[0]);
        assert!(col.set_span(1, 2).unwrap_err().to_string().contains("rising"));
    }

    #[test]
    fn an_open_mesh_is_one_sided_and_its_rim_has_no_inside() {
        let floor = ColliderMesh::new(
            "floor",
            &[vec![0, 1, 2, 3]],
            vec![vec![[-1.0, 0.0, -1.0], [-1.0, 0.0, 1.0], [1.0, 0.0, 1.0], [1.0, 0.0, -1.0]]],
        )
        .unwrap();
        let sd = floor.signed_distances(0, &[[0.2, -0.05, 0.3], [0.2, 0.05, 0.3], [1.5, -0.05, 0.0]]);
        assert!((sd[0] + 0.05).abs() < 1e-6 && (sd[1] - 0.05).abs() < 1e-6, "{sd:?}");
        assert!((sd[2] - 0.5f32.hypot(0.05)).abs() < 1e-5, "beyond the rim: {sd:?}");
    }

    #[test]
    fn unwelded_closed_meshes_read_as_closed_and_bad_faces_are_refused() {
        // A cube with every face's corners its own (24 vertices): welded, it is closed.
        let b = box_mesh([0.0; 3], [0.5; 3], false);
        let tri_pos: Vec<[f32; 3]> = b.tris.iter().flatten().map(|&v| b.frames[0][v as usize]).collect();
        let faces: Vec<Vec<u32>> =
            (0..b.tris.len() as u32).map(|t| vec![3 * t, 3 * t + 1, 3 * t + 2]).collect();
        let m = ColliderMesh::new("split", &faces, vec![tri_pos]).unwrap();
        assert!(m.is_closed());
        // A pentagon (an n-gon cap) is fanned into three triangles; one collapsed to a point
        // has no surface.
        let pent: Vec<[f32; 3]> =
            (0..5).map(|k| [(k as f32 * 1.2566).cos(), (k as f32 * 1.2566).sin(), 0.0]).collect();
        assert_eq!(ColliderMesh::new("pent.obj", &[vec![0, 1, 2, 3, 4]], vec![pent]).unwrap().triangles(), 3);
        let e = ColliderMesh::new("dot.obj", &[vec![0, 1, 2, 3, 4]], vec![vec![[0.0; 3]; 5]]).unwrap_err();
        assert!(
            e.to_string().contains("dot.obj") && e.to_string().contains("no face of non-zero size"),
            "{e}"
        );
        let e = ColliderMesh::new("none.obj", &[], vec![vec![[0.0; 3]; 3]]).unwrap_err();
        assert!(e.to_string().contains("none.obj") && e.to_string().contains("no faces"), "{e}");
    }

    #[test]
    fn contacts_give_the_same_bits_on_one_thread_and_many() {
        let m = Arc::new(uv_sphere([0.0, 0.0, 0.0], 0.3, 32, 16));
        let col = MeshCollider::new(m, COLLIDER_THICKNESS);
        let prev = rng_points(5000, -0.35, 0.35, 11);
        let x0: Vec<[f32; 3]> = prev.iter().map(|p| [p[0] * 0.9, p[1] - 0.01, p[2] * 0.9]).collect();
        let w = vec![1.0; x0.len()];
        let mut a = x0.clone();
        col.substep(&mut a, &prev, &w, (0.0, 1.0), 0.4);
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        let mut b = x0.clone();
        one.install(|| col.substep(&mut b, &prev, &w, (0.0, 1.0), 0.4));
        assert!(a == b);
        assert!(a != x0, "nothing touched the sphere");
    }
}
