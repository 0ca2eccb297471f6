//! Flattening one piece of cloth for the atlas ([`super::atlas`]): cut to a disk where it is
//! not one (a tube, a piece with holes, a closed piece), Tutte's embedding, relaxed by ARAP
//! (Liu et al. 2008, "A local/global approach to mesh parameterization") so the chart keeps the
//! cloth's edge lengths.

use super::charts::{
    area3, boundary_loops, edge_runs, edges, orient2, p3, split, turn, Chart, Edge, DEGENERATE_REL,
};
use super::vec3::{cross, dot, norm, sub};
use crate::error::{Error, Result};
use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::Llt;
use faer::sparse::{SparseColMat, Triplet};
use faer::{Mat, Side};
use std::cmp::Reverse;
use std::collections::{BinaryHeap, VecDeque};

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

/// ARAP stops once an iteration lowers the energy by less than this fraction of it ...
const ARAP_REL_TOL: f64 = 1e-5;

/// ... or once the energy is under this fraction of the rest shape's own (Σ w·|x_i − x_j|²):
/// edges right to ≈ 1e-5 of their length, a developable piece flattened.
const ARAP_ABS_TOL: f64 = 1e-10;

/// Most flipped triangles an ARAP chart may have (fraction of its triangles): a few flips in a
/// strongly curved piece only blur the image there; more means the flattening failed.
const FLIP_MAX_FRACTION: f64 = 0.01;

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
            shortest_path(&chart, &e, rest, &loops[0], |v| {
                on_loop[v as usize] > 0 && on_loop[v as usize] != usize::MAX
            })
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
    for (t, f) in flip.iter().enumerate() {
        if f.unwrap_or(false) != invert {
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
    let mut pos = vec![[0.0f64; 2]; n];
    let mut on_boundary = vec![false; n];
    let mut arc = 0.0;
    for (i, &v) in boundary.iter().enumerate() {
        let frac = if perimeter > 0.0 { arc / perimeter } else { i as f64 / boundary.len() as f64 };
        let ang = std::f64::consts::TAU * frac;
        pos[v as usize] = [radius * ang.cos(), radius * ang.sin()];
        on_boundary[v as usize] = true;
        arc += lens[i];
    }
    // Interior vertices, numbered in order: the rows of the uniform Laplacian.
    let mut row: Vec<Option<usize>> = vec![None; n];
    let mut m = 0;
    for (r, _) in row.iter_mut().zip(&on_boundary).filter(|(_, b)| !**b) {
        *r = Some(m);
        m += 1;
    }
    if m > 0 {
        let mut trip = Vec::new();
        let mut rhs = Mat::<f64>::zeros(m, 2);
        for (i, _) in edge_runs(edges) {
            let (a, b) = (edges[i].a as usize, edges[i].b as usize);
            for (p, q) in [(a, b), (b, a)] {
                let Some(rp) = row[p] else { continue };
                trip.push(Triplet::new(rp, rp, 1.0));
                match row[q] {
                    Some(rq) => trip.push(Triplet::new(rp, rq, -1.0)),
                    None => {
                        rhs[(rp, 0)] += pos[q][0];
                        rhs[(rp, 1)] += pos[q][1];
                    }
                }
            }
        }
        factor(m, &trip, name)?.solve_in_place(rhs.as_mut());
        for (p, r) in pos.iter_mut().zip(&row) {
            if let Some(r) = *r {
                *p = [rhs[(r, 0)], rhs[(r, 1)]];
            }
        }
    }
    let signed: f64 =
        chart.tris.iter().map(|t| orient2(pos[t[0] as usize], pos[t[1] as usize], pos[t[2] as usize])).sum();
    if signed < 0.0 {
        pos.iter_mut().for_each(|p| p[1] = -p[1]);
    }
    chart.pos = pos;
    Ok(())
}

/// One triangle's part in ARAP.
struct ArapTri {
    /// Its chart vertices.
    v: [u32; 3],
    /// Per edge k (corner k + 1 → corner k + 2, opposite corner k): the rest edge in the
    /// triangle's own plane, counter-clockwise (m), and its weight (the cotangent at corner k).
    dx: [[f64; 2]; 3],
    w: [f64; 3],
}

impl ArapTri {
    fn new(v: [u32; 3], p: [[f64; 3]; 3]) -> ArapTri {
        let (e1, e2) = (sub(p[1], p[0]), sub(p[2], p[0]));
        let l1 = norm(e1);
        let x2 = if l1 > 0.0 { [dot(e1, e2) / l1, norm(cross(e1, e2)) / l1] } else { [norm(e2), 0.0] };
        let x = [[0.0, 0.0], [l1, 0.0], x2];
        let w = std::array::from_fn(|k| {
            let (a, b) = (sub(p[(k + 1) % 3], p[k]), sub(p[(k + 2) % 3], p[k]));
            let (c, s) = (dot(a, b), norm(cross(a, b)));
            let cot = if s > 0.0 {
                c / s
            } else if c > 0.0 {
                COT_MAX
            } else {
                0.0
            };
            cot.clamp(0.0, COT_MAX) + WEIGHT_FLOOR
        });
        ArapTri { v, dx: std::array::from_fn(|k| diff(x[(k + 1) % 3], x[(k + 2) % 3])), w }
    }

    /// Its edges: (from, to, rest edge, weight).
    fn edges(&self) -> impl Iterator<Item = (usize, usize, [f64; 2], f64)> + '_ {
        (0..3).map(|k| (self.v[(k + 1) % 3] as usize, self.v[(k + 2) % 3] as usize, self.dx[k], self.w[k]))
    }
}

/// `a − b`
#[inline]
fn diff(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

/// ARAP (Liu et al. 2008) from the chart's current positions (Tutte's, counter-clockwise):
/// local step — each triangle's best rotation of its rest shape; global step — the positions
/// closest to the rotated triangles, a cotangent-Laplacian solve factored once, vertex 0 pinned.
/// Returns the iterations made.
fn arap(chart: &mut Chart, rest: &[[f32; 3]], name: &str) -> Result<usize> {
    let n = chart.vert.len();
    let tris: Vec<ArapTri> =
        chart.tris.iter().map(|&v| ArapTri::new(v, v.map(|v| p3(rest, chart.vert[v as usize])))).collect();
    // The cotangent Laplacian without the pinned vertex 0 (vertex v is row v − 1).
    let mut trip = Vec::with_capacity(12 * tris.len());
    for (i, j, _, w) in tris.iter().flat_map(ArapTri::edges) {
        for (p, q) in [(i, j), (j, i)] {
            if p > 0 {
                trip.push(Triplet::new(p - 1, p - 1, w));
                if q > 0 {
                    trip.push(Triplet::new(p - 1, q - 1, -w));
                }
            }
        }
    }
    let llt = factor(n - 1, &trip, name)?;
    let own: f64 =
        tris.iter().flat_map(ArapTri::edges).map(|(_, _, d, w)| w * (d[0] * d[0] + d[1] * d[1])).sum();
    let mut rot = vec![[1.0f64, 0.0]; tris.len()];
    let (mut prev, mut iters) = (f64::INFINITY, 0);
    let mut rhs = Mat::<f64>::zeros(n - 1, 2);
    while iters < ARAP_MAX_ITERS {
        // Local: the rotation R maximising Σ w (u_i − u_j)·R(x_i − x_j), and the energy
        // Σ w |(u_i − u_j) − R(x_i − x_j)|² it leaves.
        let mut energy = 0.0;
        for (t, r) in tris.iter().zip(rot.iter_mut()) {
            let (mut c, mut s) = (0.0, 0.0);
            for (i, j, dx, w) in t.edges() {
                let du = diff(chart.pos[i], chart.pos[j]);
                c += w * (du[0] * dx[0] + du[1] * dx[1]);
                s += w * (dx[0] * du[1] - dx[1] * du[0]);
            }
            let th = s.atan2(c);
            *r = [th.cos(), th.sin()];
            for (i, j, dx, w) in t.edges() {
                let e = diff(diff(chart.pos[i], chart.pos[j]), turn(*r, dx));
                energy += w * (e[0] * e[0] + e[1] * e[1]);
            }
        }
        if iters >= ARAP_MIN_ITERS && (prev - energy <= ARAP_REL_TOL * prev || energy <= ARAP_ABS_TOL * own) {
            break;
        }
        prev = energy;
        iters += 1;
        // Global: L u = Σ w R (x_i − x_j), the pinned vertex's terms on the right-hand side.
        rhs.fill(0.0);
        let pin = chart.pos[0];
        for (t, r) in tris.iter().zip(&rot) {
            for (i, j, dx, w) in t.edges() {
                let d = turn(*r, dx);
                for (p, q, sgn) in [(i, j, 1.0), (j, i, -1.0)] {
                    if p == 0 {
                        continue;
                    }
                    let extra = if q == 0 { pin } else { [0.0; 2] };
                    rhs[(p - 1, 0)] += w * (sgn * d[0] + extra[0]);
                    rhs[(p - 1, 1)] += w * (sgn * d[1] + extra[1]);
                }
            }
        }
        llt.solve_in_place(rhs.as_mut());
        for (v, p) in chart.pos.iter_mut().enumerate().skip(1) {
            *p = [rhs[(v - 1, 0)], rhs[(v - 1, 1)]];
        }
    }
    Ok(iters)
}

/// Flattens one piece (a chart straight from [`super::charts::pieces`]) in metres: cut to a disk, oriented,
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
    if let Some(v) = chart.pos.iter().position(|p| !(p[0].is_finite() && p[1].is_finite())) {
        return Err(Error::numeric(format!(
            "{name}: flattening it sent mesh vertex {} to {:?}",
            chart.vert[v], chart.pos[v]
        )));
    }
    let areas: Vec<f64> = chart
        .tris
        .iter()
        .map(|t| {
            let p = t.map(|v| p3(rest, chart.vert[v as usize]));
            area3(p[0], p[1], p[2])
        })
        .collect();
    let mean = areas.iter().sum::<f64>() / areas.len().max(1) as f64;
    let flipped = chart
        .tris
        .iter()
        .zip(&areas)
        .filter(|(t, a)| {
            **a > DEGENERATE_REL * mean
                && orient2(chart.pos[t[0] as usize], chart.pos[t[1] as usize], chart.pos[t[2] as usize])
                    <= 0.0
        })
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
