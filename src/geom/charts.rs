//! Charts for the atlas ([`super::atlas`]): the faces of a mesh triangulated and split into
//! pieces (edge-connected parts) or UV islands, and the file's UV islands checked for use as
//! charts. [`super::arap`] flattens a piece that has no usable UVs.
//!
//! A chart vertex is a copy of a mesh vertex: a vertex on a cut, a seam or a bowtie (two fans of
//! faces meeting at one vertex) has one copy per side. Every ordering here follows face,
//! triangle and vertex indices (sorted vectors, B-trees), so a layout is the same on every run.

use super::vec3::{cross, dot, norm, sub};
use crate::error::{Error, Result};
use std::collections::BTreeMap;

/// A triangle whose area is under this fraction of the piece's mean triangle area is
/// degenerate: it is not counted as flipped, and it is weighed as a sliver.
pub(crate) const DEGENERATE_REL: f64 = 1e-6;

/// A UV triangle is stretched where either singular value of its map from 3D, after the
/// island's own best linear correction ([`uv_metric`]), is beyond this factor or under its
/// inverse ...
const UV_STRETCH_MAX: f64 = 2.0;

/// ... and the file's UVs are used only where under this fraction of each island's 3D area is
/// stretched.
const UV_STRETCHED_AREA_MAX: f64 = 0.05;

/// UVs whose islands average fewer faces than this are too fragmented to lay out (each island
/// costs a GAP-wide frame of empty pixels): ARAP makes one chart per piece instead.
const UV_MIN_MEAN_ISLAND_FACES: usize = 8;

/// Cells of the grid the UV islands are drawn on to test them for overlap, per triangle.
const OVERLAP_CELLS_PER_TRIANGLE: f64 = 4.0;

/// Most cells of that grid.
const OVERLAP_MAX_CELLS: f64 = (1u64 << 22) as f64;

/// A cell centre must be this deep inside a triangle (barycentric units) to count for the
/// overlap test: islands that only touch along an edge do not overlap.
const INSIDE_EPS: f64 = 1e-4;

/// Where a chart triangle came from: its mesh face, and which corner of the face each of its
/// three corners is (a quad gives two triangles).
#[derive(Clone, Copy, Debug)]
pub(crate) struct TriOrigin {
    pub face: u32,
    pub corner: [u8; 3],
}

/// A triangulated chart.
pub(crate) struct Chart {
    /// Chart vertex → mesh vertex.
    pub vert: Vec<u32>,
    /// (T, 3) chart-vertex indices of the triangles.
    pub tris: Vec<[u32; 3]>,
    /// Per triangle, its face and corners (parallel to `tris`).
    pub origin: Vec<TriOrigin>,
    /// Per chart vertex, its 2D position (metres while flattening, LR pixels once laid out).
    pub pos: Vec<[f64; 2]>,
}

/// An edge of a triangle: `a < b` chart vertices, `t` the triangle. Sorted, the triangles of one
/// edge are consecutive.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) struct Edge {
    pub a: u32,
    pub b: u32,
    pub t: u32,
}

/// Union-find over `0..n` with path halving.
pub(crate) struct UnionFind(Vec<u32>);

impl UnionFind {
    pub fn new(n: usize) -> UnionFind {
        UnionFind((0..n as u32).collect())
    }
    pub fn find(&mut self, mut x: u32) -> u32 {
        while self.0[x as usize] != x {
            let up = self.0[self.0[x as usize] as usize];
            self.0[x as usize] = up;
            x = up;
        }
        x
    }
    /// Joins the sets of `a` and `b`; the smaller root stays the root (so roots are the least
    /// member, whatever the order of the unions).
    pub fn union(&mut self, a: u32, b: u32) {
        let (ra, rb) = (self.find(a), self.find(b));
        let (lo, hi) = if ra < rb { (ra, rb) } else { (rb, ra) };
        self.0[hi as usize] = lo;
    }
}

/// A rest position in f64 (metres).
#[inline]
pub(crate) fn p3(rest: &[[f32; 3]], v: u32) -> [f64; 3] {
    let p = rest[v as usize];
    [p[0] as f64, p[1] as f64, p[2] as f64]
}

/// Area of the 3D triangle `a b c` (m²).
#[inline]
pub(crate) fn area3(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> f64 {
    0.5 * norm(cross(sub(b, a), sub(c, a)))
}

/// Twice the signed area of the 2D triangle `a b c` (positive counter-clockwise in x-right,
/// y-up axes).
#[inline]
pub(crate) fn orient2(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

/// Twice the signed area of a 2D triangle.
pub(crate) fn orient2_of(t: &[[f64; 2]; 3]) -> f64 {
    orient2(t[0], t[1], t[2])
}

/// `p` turned by the rotation `(cos, sin)`.
pub(crate) fn turn(r: [f64; 2], p: [f64; 2]) -> [f64; 2] {
    [r[0] * p[0] - r[1] * p[1], r[1] * p[0] + r[0] * p[1]]
}

/// `[min, max]` of points.
pub(crate) fn bbox(pts: &[[f64; 2]]) -> [[f64; 2]; 2] {
    let mut b = [[f64::INFINITY; 2], [f64::NEG_INFINITY; 2]];
    for p in pts {
        for k in 0..2 {
            b[0][k] = b[0][k].min(p[k]);
            b[1][k] = b[1][k].max(p[k]);
        }
    }
    b
}

/// Barycentric coordinates of `p` in triangle `t`, or `None` for a degenerate triangle.
pub(crate) fn bary(p: [f64; 2], t: [[f64; 2]; 3]) -> Option<[f64; 3]> {
    let d = orient2(t[0], t[1], t[2]);
    if d == 0.0 || !d.is_finite() {
        return None;
    }
    let (w0, w1) = (orient2(p, t[1], t[2]) / d, orient2(t[0], p, t[2]) / d);
    Some([w0, w1, 1.0 - w0 - w1])
}

/// A chart triangle's 2D corners.
pub(crate) fn corners(c: &Chart, t: usize) -> [[f64; 2]; 3] {
    c.tris[t].map(|v| c.pos[v as usize])
}

/// The corners of the triangles of a face of 3 or 4 vertices, in the face's winding: a quad is
/// split along its shorter diagonal on the rest mesh (the flatter, better-shaped pair).
pub(crate) fn face_triangles(face: &[u32], rest: &[[f32; 3]]) -> &'static [[u8; 3]] {
    if face.len() == 3 {
        return &[[0, 1, 2]];
    }
    let d02 = norm(sub(p3(rest, face[0]), p3(rest, face[2])));
    let d13 = norm(sub(p3(rest, face[1]), p3(rest, face[3])));
    if d02 <= d13 {
        &[[0, 1, 2], [0, 2, 3]]
    } else {
        &[[0, 1, 3], [1, 2, 3]]
    }
}

/// Triangulates all `faces`; two corners become one chart vertex when `key(face, corner)` is
/// equal (the mesh vertex, or the mesh vertex and its UV).
pub(crate) fn triangulate<K: Ord>(
    faces: &[Vec<u32>],
    rest: &[[f32; 3]],
    key: impl Fn(usize, usize) -> K,
) -> Chart {
    let mut ids: BTreeMap<K, u32> = BTreeMap::new();
    let mut c = Chart { vert: Vec::new(), tris: Vec::new(), origin: Vec::new(), pos: Vec::new() };
    for (f, face) in faces.iter().enumerate() {
        let corner_ids: Vec<u32> = (0..face.len())
            .map(|k| {
                let next = ids.len() as u32;
                let id = *ids.entry(key(f, k)).or_insert(next);
                if id == next {
                    c.vert.push(face[k]);
                }
                id
            })
            .collect();
        for tri in face_triangles(face, rest) {
            c.tris.push(tri.map(|k| corner_ids[k as usize]));
            c.origin.push(TriOrigin { face: f as u32, corner: *tri });
        }
    }
    c.pos = vec![[0.0; 2]; c.vert.len()];
    c
}

/// The edges of `tris`, sorted.
pub(crate) fn edges(tris: &[[u32; 3]]) -> Vec<Edge> {
    let mut e = Vec::with_capacity(3 * tris.len());
    for (t, tri) in tris.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            e.push(Edge { a: a.min(b), b: a.max(b), t: t as u32 });
        }
    }
    e.sort_unstable();
    e
}

/// The runs of `edges` that share one edge: `(first index, count)`.
pub(crate) fn edge_runs(edges: &[Edge]) -> impl Iterator<Item = (usize, usize)> + '_ {
    let mut i = 0;
    std::iter::from_fn(move || {
        if i >= edges.len() {
            return None;
        }
        let start = i;
        while i < edges.len() && (edges[i].a, edges[i].b) == (edges[start].a, edges[start].b) {
            i += 1;
        }
        Some((start, i - start))
    })
}

/// Triangle `t`'s corner that is chart vertex `v`.
fn corner_of(tris: &[[u32; 3]], t: u32, v: u32) -> u32 {
    let k = tris[t as usize].iter().position(|&x| x == v).unwrap_or(0);
    3 * t + k as u32
}

/// `chart` with its vertices split wherever the triangles around a vertex are not joined through
/// edges: corners are one vertex only when connected through edges shared by two triangles and
/// not in `cut` (sorted `(a, b)`, `a < b`). Splits bowties, and opens a cut.
pub(crate) fn split(chart: &Chart, edges: &[Edge], cut: &[(u32, u32)]) -> Chart {
    let mut uf = UnionFind::new(3 * chart.tris.len());
    for (i, n) in edge_runs(edges) {
        let (e, f) = (edges[i], edges[i + n - 1]);
        if n != 2 || cut.binary_search(&(e.a, e.b)).is_ok() {
            continue;
        }
        for v in [e.a, e.b] {
            uf.union(corner_of(&chart.tris, e.t, v), corner_of(&chart.tris, f.t, v));
        }
    }
    let mut id = vec![u32::MAX; 3 * chart.tris.len()];
    let mut out = Chart { vert: Vec::new(), tris: Vec::new(), origin: chart.origin.clone(), pos: Vec::new() };
    for (t, tri) in chart.tris.iter().enumerate() {
        let mut nt = [0u32; 3];
        for k in 0..3 {
            let root = uf.find((3 * t + k) as u32) as usize;
            if id[root] == u32::MAX {
                id[root] = out.vert.len() as u32;
                out.vert.push(chart.vert[tri[k] as usize]);
                out.pos.push(chart.pos[tri[k] as usize]);
            }
            nt[k] = id[root];
        }
        out.tris.push(nt);
    }
    out
}

/// The edge-connected components of `chart` (its edges `edges`), each a chart of its own, in
/// the order of their first triangle.
fn components(chart: &Chart, edges: &[Edge]) -> Vec<Chart> {
    let mut uf = UnionFind::new(chart.tris.len());
    for (i, n) in edge_runs(edges) {
        if n == 2 {
            uf.union(edges[i].t, edges[i + 1].t);
        }
    }
    let mut comp_of_root: BTreeMap<u32, usize> = BTreeMap::new();
    let mut out: Vec<Chart> = Vec::new();
    let mut local = vec![u32::MAX; chart.vert.len()];
    let mut owner = vec![usize::MAX; chart.vert.len()];
    for (t, tri) in chart.tris.iter().enumerate() {
        let root = uf.find(t as u32);
        let ci = *comp_of_root.entry(root).or_insert_with(|| {
            out.push(Chart { vert: Vec::new(), tris: Vec::new(), origin: Vec::new(), pos: Vec::new() });
            out.len() - 1
        });
        let c = &mut out[ci];
        let nt = tri.map(|v| {
            if owner[v as usize] != ci {
                owner[v as usize] = ci;
                local[v as usize] = c.vert.len() as u32;
                c.vert.push(chart.vert[v as usize]);
                c.pos.push(chart.pos[v as usize]);
            }
            local[v as usize]
        });
        c.tris.push(nt);
        c.origin.push(chart.origin[t]);
    }
    out
}

/// The pieces of a mesh: `faces` triangulated with corners joined by `key`, split at bowties,
/// and cut into edge-connected components. Errors on an edge of three or more triangles (a quad
/// whose diagonal is also another face's edge).
pub(crate) fn pieces<K: Ord>(
    faces: &[Vec<u32>],
    rest: &[[f32; 3]],
    key: impl Fn(usize, usize) -> K,
) -> Result<Vec<Chart>> {
    let whole = triangulate(faces, rest, key);
    let e = edges(&whole.tris);
    for (i, n) in edge_runs(&e) {
        if n > 2 {
            let fs: Vec<u32> = e[i..i + n].iter().map(|x| whole.origin[x.t as usize].face + 1).collect();
            return Err(Error::shape(format!(
                "the edge between vertices {} and {} is in {n} triangles (of faces {fs:?}): \
                 a quad's diagonal that is also an edge of another face; split that quad into triangles",
                whole.vert[e[i].a as usize] + 1,
                whole.vert[e[i].b as usize] + 1
            )));
        }
    }
    let split = split(&whole, &e, &[]);
    let e = edges(&split.tris);
    Ok(components(&split, &e))
}

/// The boundary loops of `chart` (its edges `edges`), each a cycle of chart vertices, in the
/// order of their least vertex.
pub(crate) fn boundary_loops(chart: &Chart, edges: &[Edge]) -> Result<Vec<Vec<u32>>> {
    let mut nb: Vec<Vec<u32>> = vec![Vec::new(); chart.vert.len()];
    for (i, n) in edge_runs(edges) {
        if n == 1 {
            nb[edges[i].a as usize].push(edges[i].b);
            nb[edges[i].b as usize].push(edges[i].a);
        }
    }
    if let Some(v) = nb.iter().position(|x| !x.is_empty() && x.len() != 2) {
        return Err(Error::shape(format!(
            "mesh vertex {} has {} boundary edges after its fans were split (expected 2)",
            chart.vert[v],
            nb[v].len()
        )));
    }
    let mut seen = vec![false; chart.vert.len()];
    let mut loops = Vec::new();
    for start in 0..chart.vert.len() {
        if nb[start].is_empty() || seen[start] {
            continue;
        }
        let mut lp = vec![start as u32];
        seen[start] = true;
        let (mut prev, mut cur) = (start as u32, nb[start][0]);
        while cur as usize != start {
            seen[cur as usize] = true;
            lp.push(cur);
            let n = &nb[cur as usize];
            let next = if n[0] == prev { n[1] } else { n[0] };
            (prev, cur) = (cur, next);
        }
        loops.push(lp);
    }
    Ok(loops)
}

/// Singular values (largest first) of the map from the 3D triangle `p` (m) to the 2D triangle
/// `q`, or `None` when `p` is degenerate.
fn stretch(p: [[f64; 3]; 3], q: [[f64; 2]; 3]) -> Option<[f64; 2]> {
    let (e1, e2) = (sub(p[1], p[0]), sub(p[2], p[0]));
    let l1 = norm(e1);
    let h = norm(cross(e1, e2)) / l1;
    if !(l1 > 0.0 && h > 0.0) {
        return None;
    }
    let x2 = dot(e1, e2) / l1;
    // J = U X⁻¹, X = [[l1, x2], [0, h]] (columns: the rest edges in the triangle's plane).
    let u = [[q[1][0] - q[0][0], q[2][0] - q[0][0]], [q[1][1] - q[0][1], q[2][1] - q[0][1]]];
    let j = [
        [u[0][0] / l1, (u[0][1] - u[0][0] * x2 / l1) / h],
        [u[1][0] / l1, (u[1][1] - u[1][0] * x2 / l1) / h],
    ];
    let (e, f) = ((j[0][0] + j[1][1]) / 2.0, (j[0][0] - j[1][1]) / 2.0);
    let (g, hh) = ((j[1][0] + j[0][1]) / 2.0, (j[1][0] - j[0][1]) / 2.0);
    let (qq, r) = ((e * e + hh * hh).sqrt(), (f * f + g * g).sqrt());
    Some([qq + r, (qq - r).abs()])
}

/// The file's UV islands (`faces` with `coords` at the corners `uvf`) as charts in LR pixels of
/// `texel` metres, a face's winding turned to the sign `winding` of [`orient2`]; or why they are
/// not a usable layout: a face without UVs, a flipped or degenerate UV triangle, an island
/// stretched against the rest mesh, islands overlapping, or too many islands.
pub(crate) fn uv_charts(
    faces: &[Vec<u32>],
    rest: &[[f32; 3]],
    (coords, uvf): (&[[f32; 2]], &[Vec<u32>]),
    texel: f64,
    winding: f64,
) -> std::result::Result<Vec<Chart>, String> {
    if uvf.len() != faces.len() {
        return Err(format!("UVs for {} faces of {}", uvf.len(), faces.len()));
    }
    for (f, (face, uvs)) in faces.iter().zip(uvf).enumerate() {
        if uvs.len() != face.len() {
            return Err(format!("face {} has {} corners but {} UVs", f + 1, face.len(), uvs.len()));
        }
        if let Some(&i) =
            uvs.iter().find(|&&i| coords.get(i as usize).is_none_or(|c| !c.iter().all(|x| x.is_finite())))
        {
            return Err(format!("face {}'s UV {} is missing or not finite", f + 1, i + 1));
        }
    }
    // UV indices with the same coordinates are one UV (exporters that write one per corner).
    let mut first: BTreeMap<[u32; 2], u32> = BTreeMap::new();
    let canon: Vec<u32> = coords
        .iter()
        .enumerate()
        .map(|(i, c)| *first.entry(c.map(|x| (x + 0.0).to_bits())).or_insert(i as u32))
        .collect();
    let mut islands =
        pieces(faces, rest, |f, k| (canon[uvf[f][k] as usize], faces[f][k])).map_err(|e| e.to_string())?;
    if islands.len() > 1 && islands.len() * UV_MIN_MEAN_ISLAND_FACES > faces.len() {
        return Err(format!("{} UV islands for {} faces: too fragmented", islands.len(), faces.len()));
    }
    let mut maps = Vec::with_capacity(islands.len());
    for (ii, c) in islands.iter_mut().enumerate() {
        for (tri, o) in c.tris.iter().zip(&c.origin) {
            for k in 0..3 {
                let uv = coords[uvf[o.face as usize][o.corner[k] as usize] as usize];
                c.pos[tri[k] as usize] = [uv[0] as f64, uv[1] as f64];
            }
        }
        let name = format!("UV island {} (with face {})", ii + 1, c.origin[0].face + 1);
        let p3s: Vec<[[f64; 3]; 3]> =
            c.tris.iter().map(|t| t.map(|v| p3(rest, c.vert[v as usize]))).collect();
        let a3: Vec<f64> = p3s.iter().map(|p| area3(p[0], p[1], p[2])).collect();
        let auv: Vec<f64> = (0..c.tris.len()).map(|t| 0.5 * orient2_of(&corners(c, t))).collect();
        let (a3_sum, auv_sum) = (a3.iter().sum::<f64>(), auv.iter().sum::<f64>());
        if !(a3_sum > 0.0 && auv_sum != 0.0) {
            return Err(format!("{name} has no area in 3D or in UV"));
        }
        let sign = auv_sum.signum();
        let (m3, muv) = (a3_sum / a3.len() as f64, auv_sum.abs() / auv.len() as f64);
        let bad = |t: usize| a3[t] > DEGENERATE_REL * m3 && sign * auv[t] <= DEGENERATE_REL * muv;
        if let Some(t) = (0..a3.len()).find(|&t| bad(t)) {
            return Err(format!("{name}: face {}'s UVs are flipped or degenerate", c.origin[t].face + 1));
        }
        let a = uv_metric(c, rest).ok_or_else(|| format!("{name}: its UVs have no consistent metric"))?;
        let stretched: f64 = (0..a3.len())
            .filter(|&t| {
                let q = corners(c, t).map(|p| apply(a, p));
                stretch(p3s[t], q).is_some_and(|[hi, lo]| hi > UV_STRETCH_MAX || lo < 1.0 / UV_STRETCH_MAX)
            })
            .map(|t| a3[t])
            .sum();
        if stretched > UV_STRETCHED_AREA_MAX * a3_sum {
            return Err(format!(
                "{name}: {:.0}% of its area is stretched more than {UV_STRETCH_MAX}× in UV",
                100.0 * stretched / a3_sum
            ));
        }
        // To pixels; rows mirrored where the island winds against a grid's faces.
        let my = if sign == winding { 1.0 } else { -1.0 };
        maps.push([[a[0][0] / texel, a[0][1] / texel], [my * a[1][0] / texel, my * a[1][1] / texel]]);
    }
    if let Some((a, b)) = uv_overlap(&islands) {
        return Err(format!("UV islands {} and {} overlap", a + 1, b + 1));
    }
    for (c, m) in islands.iter_mut().zip(&maps) {
        c.pos.iter_mut().for_each(|p| *p = apply(*m, *p));
    }
    Ok(islands)
}

/// `m · p` for a 2×2 matrix `m` (rows).
fn apply(m: [[f64; 2]; 2], p: [f64; 2]) -> [f64; 2] {
    [m[0][0] * p[0] + m[0][1] * p[1], m[1][0] * p[0] + m[1][1] * p[1]]
}

/// The linear map (2×2 rows, metres per UV unit) that best turns the island's UVs into lengths
/// on the rest mesh: the square root of the metric G (2×2 symmetric) whose lengths dᵀ·G·d of
/// the UV edges d best match the squared rest lengths L², in relative least squares (a sliver
/// UV triangle weighs no more than its three edges). A layout squeezed into the unit square (a
/// 11 × 8 sheet at u = i/11, v = j/8) is made isometric again; `None` when G is not positive
/// definite.
fn uv_metric(c: &Chart, rest: &[[f32; 3]]) -> Option<[[f64; 2]; 2]> {
    // Normal equations of rows [d0², 2·d0·d1, d1²] / L² · (g00, g01, g11) = 1.
    let (mut m, mut b) = ([[0.0f64; 3]; 3], [0.0f64; 3]);
    let e = edges(&c.tris);
    for (i, _) in edge_runs(&e) {
        let (va, vb) = (e[i].a as usize, e[i].b as usize);
        let l2 = {
            let l = norm(sub(p3(rest, c.vert[va]), p3(rest, c.vert[vb])));
            l * l
        };
        if l2 <= 0.0 {
            continue;
        }
        let d = [c.pos[va][0] - c.pos[vb][0], c.pos[va][1] - c.pos[vb][1]];
        let row = [d[0] * d[0] / l2, 2.0 * d[0] * d[1] / l2, d[1] * d[1] / l2];
        for (mr, rr) in m.iter_mut().zip(row) {
            for (mrc, rc) in mr.iter_mut().zip(row) {
                *mrc += rr * rc;
            }
        }
        b.iter_mut().zip(row).for_each(|(bk, rk)| *bk += rk);
    }
    let [g00, g01, g11] = solve3(m, b)?;
    let det = g00 * g11 - g01 * g01;
    if !(det > 0.0 && g00 > 0.0 && det.is_finite()) {
        return None;
    }
    // The symmetric square root of a 2×2 SPD matrix: (G + √det·I) / √(tr G + 2√det).
    let sd = det.sqrt();
    let k = 1.0 / (g00 + g11 + 2.0 * sd).sqrt();
    Some([[(g00 + sd) * k, g01 * k], [g01 * k, (g11 + sd) * k]])
}

/// `m⁻¹ · b` for a 3×3 matrix (Cramer's rule), or `None` when `m` is singular.
fn solve3(m: [[f64; 3]; 3], b: [f64; 3]) -> Option<[f64; 3]> {
    let det3 = |a: [[f64; 3]; 3]| {
        a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
            + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
    };
    let d = det3(m);
    if d == 0.0 || !d.is_finite() {
        return None;
    }
    Some(std::array::from_fn(|k| {
        let mut mk = m;
        (0..3).for_each(|r| mk[r][k] = b[r]);
        det3(mk) / d
    }))
}

/// Two UV islands that overlap, if any: where the boxes of islands meet, the islands are drawn
/// on a grid of cell centres, and a centre strictly inside triangles of two islands is an
/// overlap.
fn uv_overlap(islands: &[Chart]) -> Option<(usize, usize)> {
    let boxes: Vec<[[f64; 2]; 2]> = islands.iter().map(|c| bbox(&c.pos)).collect();
    let meet = |a: &[[f64; 2]; 2], b: &[[f64; 2]; 2]| (0..2).all(|k| a[0][k] < b[1][k] && b[0][k] < a[1][k]);
    if !(0..boxes.len()).any(|i| (i + 1..boxes.len()).any(|j| meet(&boxes[i], &boxes[j]))) {
        return None;
    }
    let all = bbox(&boxes.iter().flatten().copied().collect::<Vec<_>>());
    let (lo, span) = (all[0], [all[1][0] - all[0][0], all[1][1] - all[0][1]]);
    let tris: usize = islands.iter().map(|c| c.tris.len()).sum();
    let cells = (OVERLAP_CELLS_PER_TRIANGLE * tris as f64).min(OVERLAP_MAX_CELLS);
    let cell = (span[0] * span[1] / cells).sqrt().max(span[0].max(span[1]) / cells).max(f64::MIN_POSITIVE);
    let (nx, ny) = ((span[0] / cell) as usize + 1, (span[1] / cell) as usize + 1);
    let mut owner = vec![u32::MAX; nx * ny];
    for (ii, c) in islands.iter().enumerate() {
        for t in 0..c.tris.len() {
            let q = corners(c, t);
            let b = bbox(&q);
            let (c0, r0) = (((b[0][0] - lo[0]) / cell) as usize, ((b[0][1] - lo[1]) / cell) as usize);
            let (c1, r1) = (((b[1][0] - lo[0]) / cell) as usize, ((b[1][1] - lo[1]) / cell) as usize);
            for r in r0..=r1.min(ny - 1) {
                for col in c0..=c1.min(nx - 1) {
                    let p = [lo[0] + (col as f64 + 0.5) * cell, lo[1] + (r as f64 + 0.5) * cell];
                    if !bary(p, q).is_some_and(|w| w.iter().all(|&x| x > INSIDE_EPS)) {
                        continue;
                    }
                    match owner[r * nx + col] {
                        u32::MAX => owner[r * nx + col] = ii as u32,
                        o if o as usize != ii => return Some((o as usize, ii)),
                        _ => {}
                    }
                }
            }
        }
    }
    None
}
