//! Cotangent Laplacian on the triangulated grid and Laplacian smoothing (paper Eq 5, 7, 8).
//!
//! For an edge (i, j) the weight is `w_ij = cot α_ij + cot β_ij`, the cotangents of the two
//! angles opposite the edge (Meyer et al. 2003); a border edge has one adjacent triangle and
//! keeps its single term, so border vertices use their one-sided ring. We normalise by the
//! weight sum,
//!
//! ```text
//!   L(p_i) = Σ_j w_ij (p_j − p_i) / Σ_j w_ij ,     p̄_i = p_i + λ L(p_i)
//! ```
//!
//! (Yu & Turk 2013's smoothing step with cotangent instead of isotropic weights), so `λ` is
//! dimensionless: 0 keeps `p`, 1 moves each vertex to the weighted centroid of its ring.
//! Negative cotangents (obtuse angles in a sheared cloth) are clamped to 0 so `p̄_i` stays a
//! convex combination of its ring for `λ ≤ 1`; on a regular grid no angle is obtuse and the
//! clamp never acts. Computed in f64.

use super::mesh::GridMesh;
use super::vec3::{cross, dot, norm, sub};

/// Cotangent of the angle at `a` in triangle (a, b, c): (u·v)/|u×v|, u = b−a, v = c−a.
/// Degenerate triangles (|u×v| = 0) contribute 0.
#[inline]
pub fn cot_at(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> f64 {
    let u = sub(b, a);
    let v = sub(c, a);
    let n = norm(cross(u, v));
    if n > 0.0 {
        dot(u, v) / n
    } else {
        0.0
    }
}

/// Positions of a grid mesh in f64.
pub fn positions_f64(mesh: &GridMesh) -> Vec<[f64; 3]> {
    mesh.pos.iter().map(|p| [p[0] as f64, p[1] as f64, p[2] as f64]).collect()
}

/// `L(p_i)` for every vertex (metres), cotangent weights clamped at 0, normalised by the
/// weight sum; 0 for a vertex whose weights all vanish.
pub fn cotan_laplacian(mesh: &GridMesh) -> Vec<[f64; 3]> {
    let p = positions_f64(mesh);
    let n = p.len();
    let mut acc = vec![[0.0f64; 3]; n];
    let mut wsum = vec![0.0f64; n];
    // Each triangle adds cot(angle at corner k) to the opposite edge; interior edges receive
    // both of their triangles' terms, border edges one.
    for t in mesh.triangles() {
        for k in 0..3 {
            let (a, b, c) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
            let w = cot_at(p[a], p[b], p[c]).max(0.0);
            let d = sub(p[c], p[b]);
            for q in 0..3 {
                acc[b][q] += w * d[q];
                acc[c][q] -= w * d[q];
            }
            wsum[b] += w;
            wsum[c] += w;
        }
    }
    acc.iter()
        .zip(&wsum)
        .map(|(a, &s)| if s > 0.0 { [a[0] / s, a[1] / s, a[2] / s] } else { [0.0; 3] })
        .collect()
}

/// Laplacian-smoothed positions `p̄ = p + λ L(p)` (Eq 5), metres, f64.
pub fn smooth(mesh: &GridMesh, lambda: f64) -> Vec<[f64; 3]> {
    let l = cotan_laplacian(mesh);
    mesh.pos.iter().zip(&l).map(|(p, l)| std::array::from_fn(|q| p[q] as f64 + lambda * l[q])).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interior_vertices_of_a_flat_regular_grid_do_not_move() {
        let m = GridMesh::flat(6, 5, 1.0, 0.8);
        let l = cotan_laplacian(&m);
        for j in 1..4 {
            for i in 1..5 {
                let v = l[m.idx(i, j)];
                assert!(v.iter().all(|x| x.abs() < 1e-6), "({i},{j}) {v:?}");
            }
        }
    }

    #[test]
    fn border_vertices_move_inward_along_their_one_sided_ring() {
        let m = GridMesh::flat(5, 5, 1.0, 1.0);
        let l = cotan_laplacian(&m);
        // Left border (i = 0, x = 0): pulled towards +x, not along y or z.
        let v = l[m.idx(0, 2)];
        assert!(v[0] > 0.0 && v[1].abs() < 1e-6 && v[2] == 0.0, "{v:?}");
    }
}
