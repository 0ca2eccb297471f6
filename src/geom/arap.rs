//! Charts for the atlas ([`super::atlas`]): the faces of a mesh triangulated, split into pieces,
//! each piece cut to a disk where it is not one (a tube, a piece with holes, a closed piece) and
//! flattened — Tutte's embedding, relaxed by ARAP (Liu et al. 2008, "A local/global approach to
//! mesh parameterization") so the chart keeps the cloth's edge lengths.
//!
//! A chart vertex is a copy of a mesh vertex: a vertex on a cut, a seam or a bowtie (two fans of
//! faces meeting at one vertex) has one copy per side. Every ordering here follows face,
//! triangle and vertex indices (sorted vectors, B-trees), so a layout is the same on every run.

use super::vec3::{cross, dot, norm, sub};
use crate::error::{Error, Result};
use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::Llt;
use faer::sparse::{SparseColMat, Triplet};
use faer::{Mat, Side};
use std::cmp::Reverse;
use std::collections::{BTreeMap, BinaryHeap, VecDeque};

/// Largest cotangent weight of an ARAP edge: a sliver's near-zero angle would otherwise weigh
/// its edge without bound and make the global solve ill-conditioned.
const COT_MAX: f64 = 1e3;
/// Added to every (clamped, non-negative) cotangent weight: keeps the system positive definite
/// where a degenerate triangle's cotangents are all zero. Developable cloth still flattens
/// exactly: an isometry zeroes every term whatever the weights.
const WEIGHT_FLOOR: f64 = 1e-3;
/// Local/global iterations ARAP always makes (Liu et al. find 10 enough for most meshes).
const ARAP_MIN_ITERS: usize = 10;
/// Most ARAP iterations: a chart that starts far from isometric (a long tube unrolled from
/// Tutte's circle) needs more than the paper's 10 to straighten out.
const ARAP_MAX_ITERS: usize = 300;
/// ARAP stops once an iteration lowers the energy by less than this fraction of it.
const ARAP_REL_TOL: f64 = 1e-7;
/// Most flipped triangles an ARAP chart may have (fraction of its triangles): a few flips in a
/// strongly curved piece only blur the image there; more means the flattening failed.
pub(crate) const FLIP_MAX_FRACTION: f64 = 0.01;
/// A triangle whose area is under this fraction of the piece's mean triangle area is
/// degenerate: it is not counted as flipped, and it is weighed as a sliver.
pub(crate) const DEGENERATE_REL: f64 = 1e-6;

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
fn triangulate<K: Ord>(faces: &[Vec<u32>], rest: &[[f32; 3]], key: impl Fn(usize, usize) -> K) -> Chart {
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
fn split(chart: &Chart, edges: &[Edge], cut: &[(u32, u32)]) -> Chart {
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
            let fs: Vec<u32> = e[i..i + n].iter().map(|x| whole.origin[x.t as usize].face).collect();
            return Err(Error::shape(format!(
                "the edge between vertices {} and {} is in {n} triangles (of faces {fs:?}, counting from 0): \
                 a quad's diagonal that is also an edge of another face; split that quad into triangles",
                whole.vert[e[i].a as usize], whole.vert[e[i].b as usize]
            )));
        }
    }
    let split = split(&whole, &e, &[]);
    let e = edges(&split.tris);
    Ok(components(&split, &e))
}

/// The boundary loops of `chart` (its edges `edges`), each a cycle of chart vertices, in the
/// order of their least vertex.
fn boundary_loops(chart: &Chart, edges: &[Edge]) -> Result<Vec<Vec<u32>>> {
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

/// Shortest paths over the chart's edges, lengths on the rest mesh (m), from `sources` until
/// `stop(v)` holds for a settled vertex: that vertex and the path to it (source first), or the
/// farthest vertex when `stop` never holds.
fn shortest_path(
    chart: &Chart,
    edges: &[Edge],
    rest: &[[f32; 3]],
    sources: &[u32],
    stop: impl Fn(u32) -> bool,
) -> Vec<u32> {
    let n = chart.vert.len();
    let mut adj: Vec<Vec<(u32, f64)>> = vec![Vec::new(); n];
    for (i, _) in edge_runs(edges) {
        let (a, b) = (edges[i].a, edges[i].b);
        let l = norm(sub(p3(rest, chart.vert[a as usize]), p3(rest, chart.vert[b as usize])));
        adj[a as usize].push((b, l));
        adj[b as usize].push((a, l));
    }
    let mut dist = vec![f64::INFINITY; n];
    let mut pred = vec![u32::MAX; n];
    let mut done = vec![false; n];
    // Non-negative f64s order as their bits; ties go to the lower vertex.
    let mut heap = BinaryHeap::new();
    for &s in sources {
        dist[s as usize] = 0.0;
        heap.push(Reverse((0u64, s)));
    }
    let mut last = sources[0];
    while let Some(Reverse((_, v))) = heap.pop() {
        if done[v as usize] {
            continue;
        }
        done[v as usize] = true;
        last = v;
        if stop(v) {
            break;
        }
        for &(u, l) in &adj[v as usize] {
            let d = dist[v as usize] + l;
            if d < dist[u as usize] {
                dist[u as usize] = d;
                pred[u as usize] = v;
                heap.push(Reverse((d.to_bits(), u)));
            }
        }
    }
    let mut path = vec![last];
    let mut v = last;
    while pred[v as usize] != u32::MAX {
        v = pred[v as usize];
        path.push(v);
    }
    path.reverse();
    path
}

/// `chart` cut to a disk: boundary loops joined by shortest paths, a closed piece opened along
/// a shortest path between two far vertices. `name` names the piece in errors.
fn cut_to_disk(mut chart: Chart, rest: &[[f32; 3]], name: &str) -> Result<Chart> {
    let loops_at_start = boundary_loops(&chart, &edges(&chart.tris))?.len();
    loop {
        let e = edges(&chart.tris);
        let loops = boundary_loops(&chart, &e)?;
        if loops.len() == 1 {
            let (v, f) = (chart.vert.len() as i64, chart.tris.len() as i64);
            let chi = v - edge_runs(&e).count() as i64 + f;
            if chi != 1 {
                return Err(Error::shape(format!(
                    "{name} is not a disk after its {loops_at_start} boundary loop(s) were cut together \
                     (Euler characteristic {chi}, not 1): it has {} handle(s) or is not orientable. Give the \
                     mesh UVs whose islands are disks, or cut the piece along a seam in the modelling tool",
                    ((1 - chi) / 2).max(1)
                )));
            }
            return Ok(chart);
        }
        let path = if loops.is_empty() {
            let far = shortest_path(&chart, &e, rest, &[0], |_| false);
            let a = *far.last().unwrap_or(&0);
            shortest_path(&chart, &e, rest, &[a], |_| false)
        } else {
            let mut on_loop = vec![usize::MAX; chart.vert.len()];
            for (l, lp) in loops.iter().enumerate() {
                for &v in lp {
                    on_loop[v as usize] = l;
                }
            }
            shortest_path(&chart, &e, rest, &loops[0], |v| on_loop[v as usize] > 0 && on_loop[v as usize] != usize::MAX)
        };
        if path.len() < 2 {
            return Err(Error::shape(format!("{name}: found no path to cut it to a disk along")));
        }
        let mut cut: Vec<(u32, u32)> = path.windows(2).map(|w| (w[0].min(w[1]), w[0].max(w[1]))).collect();
        cut.sort_unstable();
        chart = split(&chart, &e, &cut);
    }
}

/// Turns triangles so that neighbours agree (each shared edge runs opposite ways in its two
/// triangles), the winding most of the piece's faces (by area) have.
fn orient(chart: &mut Chart, edges: &[Edge], rest: &[[f32; 3]], name: &str) -> Result<()> {
    let nt = chart.tris.len();
    let runs_forward = |t: u32, a: u32, b: u32| {
        let tri = chart.tris[t as usize];
        (0..3).any(|k| tri[k] == a && tri[(k + 1) % 3] == b)
    };
    let mut nbr: Vec<Vec<(u32, bool)>> = vec![Vec::new(); nt];
    for (i, n) in edge_runs(edges) {
        if n == 2 {
            let (e, f) = (edges[i], edges[i + 1]);
            let same = runs_forward(e.t, e.a, e.b) == runs_forward(f.t, e.a, e.b);
            nbr[e.t as usize].push((f.t, same));
            nbr[f.t as usize].push((e.t, same));
        }
    }
    let mut flip: Vec<Option<bool>> = vec![None; nt];
    for start in 0..nt {
        if flip[start].is_some() {
            continue;
        }
        flip[start] = Some(false);
        let mut queue = VecDeque::from([start as u32]);
        while let Some(t) = queue.pop_front() {
            let ft = flip[t as usize].unwrap_or(false);
            for &(u, same) in &nbr[t as usize] {
                let want = ft ^ same;
                match flip[u as usize] {
                    None => {
                        flip[u as usize] = Some(want);
                        queue.push_back(u);
                    }
                    Some(got) if got != want => {
                        return Err(Error::shape(format!(
                            "{name} is not orientable (a Möbius band?): it cannot be flattened"
                        )));
                    }
                    _ => {}
                }
            }
        }
    }
    let mut balance = 0.0;
    for (t, tri) in chart.tris.iter().enumerate() {
        let p = tri.map(|v| p3(rest, chart.vert[v as usize]));
        let a = area3(p[0], p[1], p[2]);
        balance += if flip[t] == Some(true) { -a } else { a };
    }
    let invert = balance < 0.0;
    for t in 0..nt {
        if flip[t].unwrap_or(false) != invert {
            chart.tris[t].swap(1, 2);
            chart.origin[t].corner.swap(1, 2);
        }
    }
    Ok(())
}

/// Factors the symmetric positive definite `n × n` matrix given by `trip` (duplicates summed).
fn factor(n: usize, trip: &[Triplet<usize, usize, f64>], name: &str) -> Result<Llt<usize, f64>> {
    let m = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, trip)
        .map_err(|e| Error::numeric(format!("{name}: sparse matrix: {e:?}")))?;
    m.sp_cholesky(Side::Lower)
        .map_err(|e| Error::numeric(format!("{name}: the flattening system is not positive definite: {e:?}")))
}

/// Tutte's embedding of the disk `chart` (its edges `edges`, boundary `boundary`): the boundary
/// on a circle by arc length (radius so its perimeter is the rest perimeter, m), every interior
/// vertex the mean of its neighbours.
fn tutte(chart: &mut Chart, edges: &[Edge], boundary: &[u32], rest: &[[f32; 3]], name: &str) -> Result<()> {
    let n = chart.vert.len();
    let at = |v: u32| p3(rest, chart.vert[v as usize]);
    let lens: Vec<f64> = (0..boundary.len())
        .map(|i| norm(sub(at(boundary[i]), at(boundary[(i + 1) % boundary.len()]))))
        .collect();
    let perimeter: f64 = lens.iter().sum();
    let radius = if perimeter > 0.0 { perimeter / std::f64::consts::TAU } else { 1.0 };
    let mut row = vec![usize::MAX; n];
    let mut pos = vec![[0.0f64; 2]; n];
    let mut arc = 0.0;
    for (i, &v) in boundary.iter().enumerate() {
        let frac = if perimeter > 0.0 { arc / perimeter } else { i as f64 / boundary.len() as f64 };
        let ang = std::f64::consts::TAU * frac;
        pos[v as usize] = [radius * ang.cos(), radius * ang.sin()];
        row[v as usize] = usize::MAX - 1;
        arc += lens[i];
    }
    let mut m = 0;
    for r in row.iter_mut().filter(|r| **r == usize::MAX) {
        *r = m;
        m += 1;
    }
    if m > 0 {
        let mut trip = Vec::new();
        let mut rhs = Mat::<f64>::zeros(m, 2);
        for (i, _) in edge_runs(edges) {
            let (a, b) = (edges[i].a as usize, edges[i].b as usize);
            for (p, q) in [(a, b), (b, a)] {
                if row[p] >= m {
                    continue;
                }
                trip.push(Triplet::new(row[p], row[p], 1.0));
                if row[q] < m {
                    trip.push(Triplet::new(row[p], row[q], -1.0));
                } else {
                    rhs[(row[p], 0)] += pos[q][0];
                    rhs[(row[p], 1)] += pos[q][1];
                }
            }
        }
        factor(m, &trip, name)?.solve_in_place(rhs.as_mut());
        for v in 0..n {
            if row[v] < m {
                pos[v] = [rhs[(row[v], 0)], rhs[(row[v], 1)]];
            }
        }
    }
    let signed: f64 = chart.tris.iter().map(|t| orient2(pos[t[0] as usize], pos[t[1] as usize], pos[t[2] as usize])).sum();
    if signed < 0.0 {
        pos.iter_mut().for_each(|p| p[1] = -p[1]);
    }
    chart.pos = pos;
    Ok(())
}

/// ARAP (Liu et al. 2008) from the chart's current positions (Tutte's, counter-clockwise):
/// local step — each triangle's best rotation of its rest shape; global step — the positions
/// closest to the rotated triangles, a cotangent-Laplacian solve factored once, vertex 0 pinned.
/// Returns the iterations made.
fn arap(chart: &mut Chart, rest: &[[f32; 3]], name: &str) -> Result<usize> {
    let n = chart.vert.len();
    let nt = chart.tris.len();
    // Per triangle: its rest shape in its own plane, counter-clockwise ((T, 3) 2D points, m),
    // and the weight of the edge opposite each corner.
    let mut xref = Vec::with_capacity(nt);
    let mut wts = Vec::with_capacity(nt);
    for tri in &chart.tris {
        let p = tri.map(|v| p3(rest, chart.vert[v as usize]));
        let (e1, e2) = (sub(p[1], p[0]), sub(p[2], p[0]));
        let l1 = norm(e1);
        let x2 = if l1 > 0.0 { [dot(e1, e2) / l1, norm(cross(e1, e2)) / l1] } else { [norm(e2), 0.0] };
        xref.push([[0.0, 0.0], [l1, 0.0], x2]);
        wts.push(std::array::from_fn::<f64, 3, _>(|k| {
            let (a, b) = (sub(p[(k + 1) % 3], p[k]), sub(p[(k + 2) % 3], p[k]));
            let s = norm(cross(a, b));
            let cot = if s > 0.0 { dot(a, b) / s } else if dot(a, b) > 0.0 { COT_MAX } else { 0.0 };
            cot.clamp(0.0, COT_MAX) + WEIGHT_FLOOR
        }));
    }
    // Global matrix: the cotangent Laplacian without the pinned vertex 0 (row v − 1).
    let mut trip = Vec::with_capacity(12 * nt);
    for (tri, w) in chart.tris.iter().zip(&wts) {
        for k in 0..3 {
            let (i, j) = (tri[(k + 1) % 3] as usize, tri[(k + 2) % 3] as usize);
            for (p, q) in [(i, j), (j, i)] {
                if p > 0 {
                    trip.push(Triplet::new(p - 1, p - 1, w[k]));
                    if q > 0 {
                        trip.push(Triplet::new(p - 1, q - 1, -w[k]));
                    }
                }
            }
        }
    }
    let llt = factor(n - 1, &trip, name)?;
    let mut rot = vec![[1.0f64, 0.0]; nt];
    let mut prev = f64::INFINITY;
    let mut rhs = Mat::<f64>::zeros(n - 1, 2);
    let mut iters = 0;
    while iters < ARAP_MAX_ITERS {
        // Local: rotation (cos, sin) maximising Σ w (u_i − u_j)·R(x_i − x_j).
        let mut energy = 0.0;
        for t in 0..nt {
            let (tri, x, w) = (chart.tris[t], &xref[t], &wts[t]);
            let mut s = [[0.0f64; 2]; 2];
            for k in 0..3 {
                let (i, j) = ((k + 1) % 3, (k + 2) % 3);
                let du = [chart.pos[tri[i] as usize][0] - chart.pos[tri[j] as usize][0], chart.pos[tri[i] as usize][1] - chart.pos[tri[j] as usize][1]];
                let dx = [x[i][0] - x[j][0], x[i][1] - x[j][1]];
                for (r, dur) in du.iter().enumerate() {
                    for (c, dxc) in dx.iter().enumerate() {
                        s[r][c] += w[k] * dur * dxc;
                    }
                }
            }
            let th = (s[1][0] - s[0][1]).atan2(s[0][0] + s[1][1]);
            rot[t] = [th.cos(), th.sin()];
            for k in 0..3 {
                let (i, j) = ((k + 1) % 3, (k + 2) % 3);
                let d = rotate(rot[t], [x[i][0] - x[j][0], x[i][1] - x[j][1]]);
                let (pi, pj) = (chart.pos[tri[i] as usize], chart.pos[tri[j] as usize]);
                let r = [pi[0] - pj[0] - d[0], pi[1] - pj[1] - d[1]];
                energy += w[k] * (r[0] * r[0] + r[1] * r[1]);
            }
        }
        if iters >= ARAP_MIN_ITERS && prev - energy <= ARAP_REL_TOL * prev {
            break;
        }
        prev = energy;
        iters += 1;
        // Global: L u = Σ w R (x_i − x_j), the pinned vertex moved to the right-hand side.
        rhs.fill(0.0);
        let pin = chart.pos[0];
        for t in 0..nt {
            let (tri, x, w) = (chart.tris[t], &xref[t], &wts[t]);
            for k in 0..3 {
                let (i, j) = ((k + 1) % 3, (k + 2) % 3);
                let d = rotate(rot[t], [x[i][0] - x[j][0], x[i][1] - x[j][1]]);
                for (p, q, sgn) in [(tri[i] as usize, tri[j] as usize, 1.0), (tri[j] as usize, tri[i] as usize, -1.0)] {
                    if p == 0 {
                        continue;
                    }
                    rhs[(p - 1, 0)] += sgn * w[k] * d[0];
                    rhs[(p - 1, 1)] += sgn * w[k] * d[1];
                    if q == 0 {
                        rhs[(p - 1, 0)] += w[k] * pin[0];
                        rhs[(p - 1, 1)] += w[k] * pin[1];
                    }
                }
            }
        }
        llt.solve_in_place(rhs.as_mut());
        for v in 1..n {
            chart.pos[v] = [rhs[(v - 1, 0)], rhs[(v - 1, 1)]];
        }
    }
    Ok(iters)
}

/// `x` turned by the rotation `(cos, sin)`.
#[inline]
fn rotate(r: [f64; 2], x: [f64; 2]) -> [f64; 2] {
    [r[0] * x[0] - r[1] * x[1], r[1] * x[0] + r[0] * x[1]]
}

/// Flattens one piece (a chart straight from [`pieces`]) in metres: cut to a disk, oriented,
/// Tutte then ARAP. Triangles keep the winding most of the piece's faces have, and that winding
/// has the sign `winding_sign` of [`orient2`] in the chart's (column, row) axes. `name` names
/// the piece in errors.
pub(crate) fn flatten(chart: Chart, rest: &[[f32; 3]], winding_sign: f64, name: &str) -> Result<Chart> {
    let mut chart = cut_to_disk(chart, rest, name)?;
    let e = edges(&chart.tris);
    orient(&mut chart, &e, rest, name)?;
    let boundary = boundary_loops(&chart, &e)?.swap_remove(0);
    tutte(&mut chart, &e, &boundary, rest, name)?;
    arap(&mut chart, rest, name)?;
    let areas: Vec<f64> = chart.tris.iter().map(|t| {
        let p = t.map(|v| p3(rest, chart.vert[v as usize]));
        area3(p[0], p[1], p[2])
    }).collect();
    let mean = areas.iter().sum::<f64>() / areas.len().max(1) as f64;
    let flipped = chart
        .tris
        .iter()
        .zip(&areas)
        .filter(|(t, a)| **a > DEGENERATE_REL * mean && orient2(chart.pos[t[0] as usize], chart.pos[t[1] as usize], chart.pos[t[2] as usize]) <= 0.0)
        .count();
    if flipped as f64 > FLIP_MAX_FRACTION * chart.tris.len() as f64 {
        return Err(Error::numeric(format!(
            "{name}: flattening it folded {flipped} of its {} triangles over (more than {}%): the piece is \
             too far from developable for one chart; give the mesh UVs that cut it into flatter islands",
            chart.tris.len(),
            FLIP_MAX_FRACTION * 100.0
        )));
    }
    if winding_sign < 0.0 {
        // ARAP's triangles have orient2 > 0; mirroring the rows turns that sign.
        chart.pos.iter_mut().for_each(|p| p[1] = -p[1]);
    }
    Ok(chart)
}
