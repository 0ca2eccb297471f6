//! Ground-truth boundary map by anisotropic kernels (paper Eq 4–9, Yu & Turk 2013).
//!
//! For every vertex `i` of a cloth mesh:
//! 1. `p̄_i = p_i + λ L(p_i)` with the cotangent Laplacian ([`super::laplacian`]).
//! 2. Neighbours `j` with `|p_i − p_j| < r`, `r = radius_factor · d`, `d` = longest edge of the
//!    rest (initial) mesh, found with a spatial hash of cell size `r` (the vertex itself is a
//!    neighbour). Weights `w_ij = 1 − (|p_i − p_j| / r)³`.
//! 3. `C_i = Σ_j w_ij (p_j − p̄_i)(p_j − p̄_i)ᵀ / Σ_j w_ij` (f64).
//! 4. Eigenvalues `σ1 ≥ σ2 ≥ σ3` of the symmetric `C_i` by cyclic Jacobi (= its singular
//!    values, `C_i` being positive semi-definite).
//! 5. Boundary if `i` lies on the grid border (a border edge has one adjacent triangle) or
//!    `σ3 ≥ γ σ1`: the neighbourhood is folded or sticks out of the surface.
//!
//! The spatial lookup is deterministic: buckets hold vertices in index order, the 27 cells are
//! visited in a fixed order, so the same mesh gives the same bits.

use super::laplacian::smooth;
use super::mesh::GridMesh;
use crate::error::{Error, Result};
use crate::tensor::Tensor;
use rayon::prelude::*;

/// Parameters of the boundary detector.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoundaryParams {
    /// Threshold on `σ3/σ1` (dimensionless). A vertex whose neighbourhood has
    /// `σ3 ≥ γ σ1` is a boundary vertex. Default 0.05 (docs/architecture.md, "Ground-truth boundary map"): a flat or gently curved
    /// sheet stays well below (σ3/σ1 ≈ 0 flat, < 0.01 for bends of radius ≥ 2r), a crease
    /// sharper than ~60° or a sheet folded back onto itself is well above (≈ 0.1–0.5).
    pub gamma: f64,
    /// Laplacian smoothing step `λ` (dimensionless, 0..=1). Default 0.5.
    pub lambda: f64,
    /// Neighbourhood radius in units of the rest mesh's longest edge `d` (`r = radius_factor·d`).
    /// Default 2 (paper).
    pub radius_factor: f64,
}

impl Default for BoundaryParams {
    fn default() -> Self {
        BoundaryParams { gamma: 0.05, lambda: 0.5, radius_factor: 2.0 }
    }
}

impl BoundaryParams {
    pub fn validate(&self) -> Result<()> {
        if !(self.gamma.is_finite() && self.gamma > 0.0) {
            return Err(Error::config(format!("boundary gamma must be > 0, got {}", self.gamma)));
        }
        if !(self.lambda.is_finite() && (0.0..=1.0).contains(&self.lambda)) {
            return Err(Error::config(format!("boundary lambda must be in [0, 1], got {}", self.lambda)));
        }
        if !(self.radius_factor.is_finite() && self.radius_factor > 0.0) {
            return Err(Error::config(format!("radius factor must be > 0, got {}", self.radius_factor)));
        }
        Ok(())
    }
}

/// A symmetric 3×3 matrix stored as its upper triangle `[xx, xy, xz, yy, yz, zz]`.
pub type Sym3 = [f64; 6];

/// The detector's output for one mesh (vertex order `j * w + i`).
#[derive(Clone, Debug, PartialEq)]
pub struct BoundaryMap {
    pub w: usize,
    pub h: usize,
    /// 1 for boundary vertices, 0 otherwise.
    pub mask: Vec<u8>,
    /// Eigenvalues `[σ1, σ2, σ3]`, descending (m²).
    pub sigma: Vec<[f64; 3]>,
    /// `σ3 / σ1` (0 where σ1 = 0); the quantity `γ` thresholds.
    pub ratio: Vec<f64>,
}

impl BoundaryMap {
    /// The mask as a (1, H, W) image in {0, 1}.
    pub fn to_image(&self) -> Tensor {
        Tensor { shape: [1, self.h, self.w].into(), data: self.mask.iter().map(|&m| m as f32).collect() }
    }
}

/// Eigenvalues of a symmetric 3×3 matrix, descending, by cyclic Jacobi rotations in f64.
/// Accurate to about `ε·‖C‖_F` absolutely (the smallest eigenvalue of a near-planar
/// neighbourhood keeps its sign and magnitude, unlike the closed-form trigonometric solver).
#[allow(clippy::needless_range_loop)] // rotations read clearest with explicit indices
pub fn sym3_eigenvalues(c: &Sym3) -> [f64; 3] {
    let mut a = [[c[0], c[1], c[2]], [c[1], c[3], c[4]], [c[2], c[4], c[5]]];
    for _sweep in 0..32 {
        let off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
        let diag = a[0][0] * a[0][0] + a[1][1] * a[1][1] + a[2][2] * a[2][2];
        if off <= 1e-36 * diag || off == 0.0 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            let apq = a[p][q];
            if apq == 0.0 {
                continue;
            }
            // Rotation zeroing a[p][q] (Rutishauser's stable form).
            let theta = (a[q][q] - a[p][p]) / (2.0 * apq);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let cs = 1.0 / (t * t + 1.0).sqrt();
            let sn = t * cs;
            for row in a.iter_mut() {
                let (kp, kq) = (row[p], row[q]);
                row[p] = cs * kp - sn * kq;
                row[q] = sn * kp + cs * kq;
            }
            for k in 0..3 {
                let (pk, qk) = (a[p][k], a[q][k]);
                a[p][k] = cs * pk - sn * qk;
                a[q][k] = sn * pk + cs * qk;
            }
        }
    }
    let mut e = [a[0][0], a[1][1], a[2][2]];
    e.sort_by(|x, y| y.total_cmp(x));
    e
}

/// A spatial hash of points with cubic cells of side `cell` (metres): buckets in a
/// counting-sorted array, vertices inside a bucket in increasing index order.
pub struct SpatialHash {
    cell: f64,
    origin: [f64; 3],
    coords: Vec<[i64; 3]>,
    starts: Vec<u32>,
    items: Vec<u32>,
    mask: usize,
}

impl SpatialHash {
    pub fn new(pts: &[[f64; 3]], cell: f64) -> SpatialHash {
        let mut origin = [f64::INFINITY; 3];
        for p in pts {
            for k in 0..3 {
                origin[k] = origin[k].min(p[k]);
            }
        }
        if pts.is_empty() {
            origin = [0.0; 3];
        }
        let coords: Vec<[i64; 3]> =
            pts.iter().map(|p| std::array::from_fn(|k| ((p[k] - origin[k]) / cell).floor() as i64)).collect();
        let buckets = (2 * pts.len()).next_power_of_two().max(16);
        let mask = buckets - 1;
        let mut starts = vec![0u32; buckets + 1];
        for c in &coords {
            starts[hash_cell(*c) & mask] += 1;
        }
        let mut sum = 0u32;
        for s in starts.iter_mut() {
            let c = *s;
            *s = sum;
            sum += c;
        }
        let mut fill = starts.clone();
        let mut items = vec![0u32; pts.len()];
        for (v, c) in coords.iter().enumerate() {
            let b = hash_cell(*c) & mask;
            items[fill[b] as usize] = v as u32;
            fill[b] += 1;
        }
        SpatialHash { cell, origin, coords, starts, items, mask }
    }

    /// Calls `f(j)` for every point `j` in the 27 cells around `q` (a superset of the points
    /// within one cell side of `q`), each point at most once, in a fixed order.
    #[inline]
    pub fn for_each_near(&self, q: [f64; 3], mut f: impl FnMut(usize)) {
        let c: [i64; 3] = std::array::from_fn(|k| ((q[k] - self.origin[k]) / self.cell).floor() as i64);
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let cc = [c[0] + dx, c[1] + dy, c[2] + dz];
                    let b = hash_cell(cc) & self.mask;
                    for &v in &self.items[self.starts[b] as usize..self.starts[b + 1] as usize] {
                        // Buckets mix cells that collide in the hash: keep this cell's points only.
                        if self.coords[v as usize] == cc {
                            f(v as usize);
                        }
                    }
                }
            }
        }
    }
}

#[inline]
fn hash_cell(c: [i64; 3]) -> usize {
    let h =
        (c[0].wrapping_mul(73_856_093)) ^ (c[1].wrapping_mul(19_349_663)) ^ (c[2].wrapping_mul(83_492_791));
    h as u64 as usize
}

#[inline]
fn accumulate(acc: &mut Sym3, wsum: &mut f64, pi: [f64; 3], pj: [f64; 3], pbar: [f64; 3], r: f64) {
    let d2 = (pj[0] - pi[0]).powi(2) + (pj[1] - pi[1]).powi(2) + (pj[2] - pi[2]).powi(2);
    if d2 >= r * r {
        return;
    }
    let s = d2.sqrt() / r;
    let w = 1.0 - s * s * s;
    let e = [pj[0] - pbar[0], pj[1] - pbar[1], pj[2] - pbar[2]];
    acc[0] += w * e[0] * e[0];
    acc[1] += w * e[0] * e[1];
    acc[2] += w * e[0] * e[2];
    acc[3] += w * e[1] * e[1];
    acc[4] += w * e[1] * e[2];
    acc[5] += w * e[2] * e[2];
    *wsum += w;
}

#[inline]
fn normalise(mut acc: Sym3, wsum: f64) -> Sym3 {
    if wsum > 0.0 {
        for a in acc.iter_mut() {
            *a /= wsum;
        }
    }
    acc
}

/// Weighted covariances `C_i` (Eq 4) of points `p` around centres `pbar`, radius `r` (metres),
/// neighbours from a spatial hash; parallel over vertices, deterministic.
pub fn covariances(p: &[[f64; 3]], pbar: &[[f64; 3]], r: f64) -> Vec<Sym3> {
    let hash = SpatialHash::new(p, r);
    (0..p.len())
        .into_par_iter()
        .with_min_len(256)
        .map(|i| {
            let mut acc = [0.0; 6];
            let mut wsum = 0.0;
            hash.for_each_near(p[i], |j| accumulate(&mut acc, &mut wsum, p[i], p[j], pbar[i], r));
            normalise(acc, wsum)
        })
        .collect()
}

/// Reference for [`covariances`]: all pairs, O(n²), sequential.
pub fn covariances_ref(p: &[[f64; 3]], pbar: &[[f64; 3]], r: f64) -> Vec<Sym3> {
    (0..p.len())
        .map(|i| {
            let mut acc = [0.0; 6];
            let mut wsum = 0.0;
            for &pj in p {
                accumulate(&mut acc, &mut wsum, p[i], pj, pbar[i], r);
            }
            normalise(acc, wsum)
        })
        .collect()
}

/// The boundary map of `mesh` (Eq 4–9). `rest_edge` is `d`, the longest edge of the rest
/// (initial) mesh in metres ([`GridMesh::longest_edge`] of frame 0).
pub fn boundary_map(mesh: &GridMesh, rest_edge: f32, params: &BoundaryParams) -> Result<BoundaryMap> {
    params.validate()?;
    if !(rest_edge.is_finite() && rest_edge > 0.0) {
        return Err(Error::config(format!("rest edge length d must be > 0, got {rest_edge}")));
    }
    if let Some(v) = mesh.pos.iter().position(|p| !p.iter().all(|x| x.is_finite())) {
        return Err(Error::numeric(format!("vertex {v} of the mesh is not finite: {:?}", mesh.pos[v])));
    }
    let r = params.radius_factor * rest_edge as f64;
    let p = super::laplacian::positions_f64(mesh);
    let pbar = smooth(mesh, params.lambda);
    let cov = covariances(&p, &pbar, r);
    let sigma: Vec<[f64; 3]> = cov.par_iter().with_min_len(256).map(sym3_eigenvalues).collect();
    let ratio: Vec<f64> = sigma.iter().map(|s| if s[0] > 0.0 { s[2] / s[0] } else { 0.0 }).collect();
    let mask = (0..mesh.w * mesh.h)
        .map(|v| {
            let (i, j) = (v % mesh.w, v / mesh.w);
            let folded = sigma[v][0] > 0.0 && sigma[v][2] >= params.gamma * sigma[v][0];
            u8::from(mesh.is_border(i, j) || folded)
        })
        .collect();
    Ok(BoundaryMap { w: mesh.w, h: mesh.h, mask, sigma, ratio })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jacobi_eigenvalues_of_a_diagonal_and_a_rotated_matrix() {
        assert_eq!(sym3_eigenvalues(&[1.0, 0.0, 0.0, 3.0, 0.0, 2.0]), [3.0, 2.0, 1.0]);
        // [[2,1,0],[1,2,0],[0,0,5]] has eigenvalues 5, 3, 1.
        let e = sym3_eigenvalues(&[2.0, 1.0, 0.0, 2.0, 0.0, 5.0]);
        for (a, b) in e.iter().zip([5.0, 3.0, 1.0]) {
            assert!((a - b).abs() < 1e-14, "{e:?}");
        }
    }
}
