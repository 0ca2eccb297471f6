//! A cloth is a regular grid of `w × h` vertices (columns × rows). Vertex (i, j) — column i,
//! row j — is stored at `j * w + i`; in a geometry image it is pixel (row j, col i).

use super::vec3::{cross, norm, normalize_or, sub};
use std::borrow::Borrow;

/// Positions in metres.
#[derive(Clone, Debug, PartialEq)]
pub struct GridMesh {
    pub w: usize,
    pub h: usize,
    pub pos: Vec<[f32; 3]>,
}

impl GridMesh {
    pub fn new(w: usize, h: usize, pos: Vec<[f32; 3]>) -> Self {
        assert_eq!(pos.len(), w * h, "grid {w}x{h} needs {} vertices", w * h);
        GridMesh { w, h, pos }
    }

    /// Flat sheet in the z = 0 plane spanning `size_x × size_y` metres, row 0 at y = size_y.
    pub fn flat(w: usize, h: usize, size_x: f32, size_y: f32) -> Self {
        let mut pos = Vec::with_capacity(w * h);
        for j in 0..h {
            for i in 0..w {
                let (u, v) = rest_uv(i, j, w, h);
                pos.push([u * size_x, (1.0 - v) * size_y, 0.0]);
            }
        }
        GridMesh { w, h, pos }
    }

    #[inline]
    pub fn idx(&self, i: usize, j: usize) -> usize {
        j * self.w + i
    }

    /// Triangles of the grid: each quad (i,j)-(i+1,j+1) split along its (i,j)–(i+1,j+1)
    /// diagonal, counter-clockwise seen from +z for a flat sheet with rows going down in y.
    pub fn triangles(&self) -> Vec<[usize; 3]> {
        let mut t = Vec::with_capacity(2 * (self.w - 1) * (self.h - 1));
        for j in 0..self.h.saturating_sub(1) {
            for i in 0..self.w.saturating_sub(1) {
                let a = self.idx(i, j);
                let b = self.idx(i + 1, j);
                let c = self.idx(i + 1, j + 1);
                let d = self.idx(i, j + 1);
                t.push([a, c, b]);
                t.push([a, d, c]);
            }
        }
        t
    }

    /// Quads (a, b, c, d) in the same winding as [`GridMesh::triangles`].
    pub fn quads(&self) -> Vec<[usize; 4]> {
        let mut q = Vec::with_capacity((self.w - 1) * (self.h - 1));
        for j in 0..self.h.saturating_sub(1) {
            for i in 0..self.w.saturating_sub(1) {
                q.push([self.idx(i, j), self.idx(i, j + 1), self.idx(i + 1, j + 1), self.idx(i + 1, j)]);
            }
        }
        q
    }

    /// True for vertices on the grid's border (the topological boundary of the sheet).
    pub fn is_border(&self, i: usize, j: usize) -> bool {
        i == 0 || j == 0 || i + 1 == self.w || j + 1 == self.h
    }

    /// Longest edge length (metres) over the grid's structural edges and quad diagonals used by
    /// the triangulation.
    pub fn longest_edge(&self) -> f32 {
        let mut m = 0.0f32;
        for t in self.triangles() {
            for k in 0..3 {
                m = m.max(dist(self.pos[t[k]], self.pos[t[(k + 1) % 3]]));
            }
        }
        m
    }

    /// Lengths (metres) of the grid's row edges, then its column edges.
    pub fn edge_lengths(&self) -> Vec<f32> {
        let mut v = Vec::with_capacity(2 * self.w * self.h);
        for j in 0..self.h {
            for i in 0..self.w.saturating_sub(1) {
                v.push(dist(self.pos[self.idx(i, j)], self.pos[self.idx(i + 1, j)]));
            }
        }
        for j in 0..self.h.saturating_sub(1) {
            for i in 0..self.w {
                v.push(dist(self.pos[self.idx(i, j)], self.pos[self.idx(i, j + 1)]));
            }
        }
        v
    }

    pub fn bounds(&self) -> ([f32; 3], [f32; 3]) {
        bounds(&self.pos)
    }
}

/// One of the 8 symmetries of a grid's vertex numbering: the same sheet numbered with its
/// columns reversed (`mirror_i`), rows reversed (`mirror_j`), and/or rows and columns swapped
/// (`transpose`, applied first). Exporters renumber a grid this way after an edit; aligning a
/// frame to another means finding the symmetry that maps one numbering onto the other.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GridSymmetry {
    pub transpose: bool,
    pub mirror_i: bool,
    pub mirror_j: bool,
}

impl GridSymmetry {
    pub const IDENTITY: GridSymmetry = GridSymmetry { transpose: false, mirror_i: false, mirror_j: false };

    /// All 8, the identity first.
    pub fn all() -> [GridSymmetry; 8] {
        std::array::from_fn(|k| GridSymmetry {
            transpose: k & 4 != 0,
            mirror_i: k & 1 != 0,
            mirror_j: k & 2 != 0,
        })
    }

    /// (columns, rows) of a `w × h` grid renumbered by `self`.
    pub fn dims(self, w: usize, h: usize) -> (usize, usize) {
        if self.transpose {
            (h, w)
        } else {
            (w, h)
        }
    }

    /// For each vertex of the renumbered grid (`j'·w' + i'`, dims from [`Self::dims`]), the
    /// index of the same vertex in the `w × h` grid it is taken from.
    pub fn source_index(self, w: usize, h: usize) -> Vec<usize> {
        let (w2, h2) = self.dims(w, h);
        let mut idx = Vec::with_capacity(w * h);
        for j2 in 0..h2 {
            for i2 in 0..w2 {
                let (a, b) = if self.transpose { (j2, i2) } else { (i2, j2) };
                let i = if self.mirror_i { w - 1 - a } else { a };
                let j = if self.mirror_j { h - 1 - b } else { b };
                idx.push(j * w + i);
            }
        }
        idx
    }

    /// `mesh` renumbered by `self`.
    pub fn apply(self, mesh: &GridMesh) -> GridMesh {
        let (w2, h2) = self.dims(mesh.w, mesh.h);
        GridMesh::new(w2, h2, self.source_index(mesh.w, mesh.h).into_iter().map(|k| mesh.pos[k]).collect())
    }

    /// How a grid numbered by `self` looks next to one numbered the identity's way, in words.
    pub fn describe(self) -> &'static str {
        match (self.transpose, self.mirror_i, self.mirror_j) {
            (false, false, false) => "the same order",
            (false, true, false) => "each row reversed",
            (false, false, true) => "rows in reverse order",
            (false, true, true) => "turned 180 degrees",
            (true, false, false) => "rows and columns swapped",
            (true, true, false) | (true, false, true) => "turned 90 degrees",
            (true, true, true) => "swapped along the other diagonal",
        }
    }
}

/// Rest parameter (u, v) ∈ [0,1]² of vertex (i, j) on a `w × h` grid (corners aligned).
#[inline]
pub fn rest_uv(i: usize, j: usize, w: usize, h: usize) -> (f32, f32) {
    let u = if w > 1 { i as f32 / (w - 1) as f32 } else { 0.0 };
    let v = if h > 1 { j as f32 / (h - 1) as f32 } else { 0.0 };
    (u, v)
}

/// Vertices of the grid border in order, as a closed loop: row 0 left→right, last column
/// top→bottom, last row right→left, column 0 bottom→top.
pub fn border_loop(w: usize, h: usize) -> Vec<usize> {
    ring_loop(w, h, 0)
}

/// Vertices of ring `r` of a `w × h` grid (r = 0: the border, 1: the ring inside it, …) in
/// order, as a closed loop: the border loop of the sub-grid `r` vertices in from each side,
/// [`border_loop`]'s order. Empty when the grid has no such ring.
pub fn ring_loop(w: usize, h: usize, r: usize) -> Vec<usize> {
    ring_vertices(w, h, r).collect()
}

/// [`ring_loop`] as an iterator (no list is made: the pipeline walks rings on every frame).
pub fn ring_vertices(w: usize, h: usize, r: usize) -> impl Iterator<Item = usize> + Clone {
    let live = w > 2 * r && h > 2 * r;
    // No ring: every range below is empty (the top row's is emptied by `live`).
    let (x0, y0, x1, y1) = if live { (r, r, w - 1 - r, h - 1 - r) } else { (r, r, r, r) };
    let top = (x0..=x1).filter(move |_| live).map(move |i| y0 * w + i);
    let right = (y0 + 1..=y1).map(move |j| j * w + x1);
    let bottom = (x0..x1).rev().filter(move |_| y1 > y0).map(move |i| y1 * w + i);
    let left = (y0 + 1..y1).rev().filter(move |_| x1 > x0).map(move |j| j * w + x0);
    top.chain(right).chain(bottom).chain(left)
}

/// Length of the closed polyline through `at(ring[0]), at(ring[1]), …` and back to the first
/// (in f64; `ring` as from [`ring_loop`] or [`ring_vertices`]).
pub fn closed_loop_length<I>(ring: I, at: impl Fn(usize) -> [f64; 3]) -> f64
where
    I: IntoIterator,
    I::Item: Borrow<usize>,
{
    let mut ring = ring.into_iter().map(|v| *v.borrow());
    let Some(first) = ring.next() else { return 0.0 };
    let (mut sum, mut prev) = (0.0f64, first);
    // Σ_k |p_k − p_{k+1}| in the ring's order, the last edge back to the first vertex.
    for v in ring.chain(std::iter::once(first)) {
        sum += norm(sub(at(prev), at(v)));
        prev = v;
    }
    sum
}

/// Area-weighted vertex normals of the grid's triangulation (unit length; (0,0,1) if isolated).
pub fn vertex_normals(mesh: &GridMesh) -> Vec<[f32; 3]> {
    let mut n = vec![[0.0f32; 3]; mesh.pos.len()];
    for t in mesh.triangles() {
        let (a, b, c) = (mesh.pos[t[0]], mesh.pos[t[1]], mesh.pos[t[2]]);
        let f = cross(sub(b, a), sub(c, a));
        for &v in &t {
            for k in 0..3 {
                n[v][k] += f[k];
            }
        }
    }
    n.into_iter().map(|v| normalize_or(v, [0.0, 0.0, 1.0])).collect()
}

#[inline]
pub fn dist(a: [f32; 3], b: [f32; 3]) -> f32 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

pub fn bounds(pts: &[[f32; 3]]) -> ([f32; 3], [f32; 3]) {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in pts {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}
