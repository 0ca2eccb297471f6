//! XPBD constraints of a grid cloth and their graph colouring.
//!
//! - Stretch: distance constraints on row and column edges. Shear: distance constraints on both
//!   diagonals of every quad (symmetric, so the sheet has no preferred diagonal).
//! - Bending: **isometric bending** (Bergou, Wardetzky, Harmon, Zorin, Grinspun 2006) on every
//!   interior edge of the triangulation ([`GridMesh::triangles`]). For an edge (a, b) with
//!   opposite vertices c, d the discrete mean-curvature vector `v = Σ K_k x_k` is linear in the
//!   positions (the weights `K` are cotangents of the flat rest state), and the energy is
//!   `E = kb · 3 / (2 (A0 + A1)) · |v|²`. We solve it as the linear vector constraint `v = 0`
//!   with compliance `α = (A0 + A1) / (3 kb)`, so its gradient is constant and well behaved at
//!   the flat state (unlike a dihedral-angle constraint). It assumes a flat rest shape, which
//!   every scenario has.
//!
//! Constraints are sorted by colour (no two constraints of a colour share a vertex), so a
//! colour can be projected in any order or in parallel with the same result.

use crate::geom::mesh::{dist, GridMesh};
use crate::geom::vec3::{cross, dot, norm, sub};

/// Distance constraint `|x_a − x_b| = rest` with compliance `alpha` (m/N).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Distance {
    pub a: u32,
    pub b: u32,
    pub rest: f32,
    pub alpha: f32,
}

/// Isometric bending stencil: vertices (edge a, edge b, opposite c, opposite d), weights `k`
/// (Σ k = 0), compliance `alpha` (m/N).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bend {
    pub v: [u32; 4],
    pub k: [f32; 4],
    pub alpha: f32,
}

/// A constraint set sorted by colour; `ranges[c]` is the index range of colour `c`.
#[derive(Clone, Debug, Default)]
pub struct Coloured<T> {
    pub items: Vec<T>,
    pub ranges: Vec<std::ops::Range<usize>>,
}

/// Greedy colouring in input order (deterministic): each constraint gets the smallest colour
/// not yet used by any of its vertices; then a stable sort by colour.
pub fn colour<T: Copy>(n_vertices: usize, items: Vec<T>, verts: impl Fn(&T) -> Vec<u32>) -> Coloured<T> {
    let mut used = vec![0u128; n_vertices];
    let mut col = Vec::with_capacity(items.len());
    for it in &items {
        let vs = verts(it);
        let mask = vs.iter().fold(0u128, |m, &v| m | used[v as usize]);
        let c = (!mask).trailing_zeros().min(127);
        for &v in &vs {
            used[v as usize] |= 1u128 << c;
        }
        col.push(c as usize);
    }
    let n_col = col.iter().copied().max().map_or(0, |c| c + 1);
    let mut order: Vec<usize> = (0..items.len()).collect();
    order.sort_by_key(|&k| col[k]);
    let mut ranges = Vec::with_capacity(n_col);
    let mut start = 0;
    for c in 0..n_col {
        let n = col.iter().filter(|&&x| x == c).count();
        ranges.push(start..start + n);
        start += n;
    }
    Coloured { items: order.into_iter().map(|k| items[k]).collect(), ranges }
}

/// Per-vertex compliance lookup: the constraint's compliance is the mean of its vertices'
/// (lets a scenario give bands of the cloth different materials).
pub type MaterialOf<'a> = &'a dyn Fn(usize) -> super::Material;

/// Stretch and shear constraints of a grid at its rest positions.
pub fn distance_constraints(rest: &GridMesh, mat: MaterialOf) -> Coloured<Distance> {
    let (w, h) = (rest.w, rest.h);
    let mut items = Vec::new();
    let mut push = |a: usize, b: usize, shear: bool| {
        let (ma, mb) = (mat(a), mat(b));
        let alpha = if shear {
            0.5 * (ma.shear_compliance + mb.shear_compliance)
        } else {
            0.5 * (ma.stretch_compliance + mb.stretch_compliance)
        };
        items.push(Distance { a: a as u32, b: b as u32, rest: dist(rest.pos[a], rest.pos[b]), alpha });
    };
    for j in 0..h {
        for i in 0..w {
            let v = j * w + i;
            if i + 1 < w {
                push(v, v + 1, false);
            }
            if j + 1 < h {
                push(v, v + w, false);
            }
            if i + 1 < w && j + 1 < h {
                push(v, v + w + 1, true);
                push(v + 1, v + w, true);
            }
        }
    }
    colour(w * h, items, |d| vec![d.a, d.b])
}

fn cot(a: [f32; 3], b: [f32; 3]) -> f32 {
    let d = dot(a, b) as f64;
    let c = cross(a, b);
    let s = (dot(c, c) as f64).sqrt().max(1e-20);
    (d / s) as f32
}

/// Isometric bending constraints on every interior edge of the triangulation.
pub fn bend_constraints(rest: &GridMesh, mat: MaterialOf) -> Coloured<Bend> {
    bend_constraints_of(&rest.pos, &rest.triangles(), mat)
}

/// Stretch constraints on every edge of a mesh of triangles and quads at its rest positions
/// `pos`, and shear constraints on both diagonals of each quad (as on a grid's cells); a
/// triangle's shear is held by its own edges.
pub fn mesh_distance_constraints(
    pos: &[[f32; 3]],
    faces: &[Vec<u32>],
    mat: MaterialOf,
) -> Coloured<Distance> {
    let mut seen = std::collections::HashSet::new();
    let mut items = Vec::new();
    let push = |a: u32, b: u32, shear: bool, items: &mut Vec<Distance>| {
        let (ma, mb) = (mat(a as usize), mat(b as usize));
        let alpha = if shear {
            0.5 * (ma.shear_compliance + mb.shear_compliance)
        } else {
            0.5 * (ma.stretch_compliance + mb.stretch_compliance)
        };
        items.push(Distance { a, b, rest: dist(pos[a as usize], pos[b as usize]), alpha });
    };
    for f in faces {
        for i in 0..f.len() {
            let (a, b) = (f[i], f[(i + 1) % f.len()]);
            if seen.insert((a.min(b), a.max(b))) {
                push(a, b, false, &mut items);
            }
        }
        if f.len() == 4 {
            push(f[0], f[2], true, &mut items);
            push(f[1], f[3], true, &mut items);
        }
    }
    colour(pos.len(), items, |d| vec![d.a, d.b])
}

/// [`bend_constraints`] on the triangles `tris` over the rest positions `pos`.
pub fn bend_constraints_of(pos: &[[f32; 3]], tris: &[[usize; 3]], mat: MaterialOf) -> Coloured<Bend> {
    // Edge → (triangle, opposite vertex); a sorted list instead of a map keeps it deterministic.
    let mut half: Vec<(u32, u32, u32)> = Vec::with_capacity(tris.len() * 3);
    for t in tris {
        for k in 0..3 {
            let (a, b, c) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
            half.push((a.min(b) as u32, a.max(b) as u32, c as u32));
        }
    }
    half.sort_unstable();
    let p = pos;
    let mut items = Vec::new();
    let mut k = 0;
    while k < half.len() {
        if k + 1 < half.len() && half[k].0 == half[k + 1].0 && half[k].1 == half[k + 1].1 {
            let (a, b, c, d) = (half[k].0, half[k].1, half[k].2, half[k + 1].2);
            let (xa, xb, xc, xd) = (p[a as usize], p[b as usize], p[c as usize], p[d as usize]);
            let e0 = sub(xb, xa);
            let e1 = sub(xc, xa);
            let e2 = sub(xd, xa);
            let e3 = sub(xc, xb);
            let e4 = sub(xd, xb);
            let c01 = cot(e0, e1);
            let c02 = cot(e0, e2);
            let c03 = cot([-e0[0], -e0[1], -e0[2]], e3);
            let c04 = cot([-e0[0], -e0[1], -e0[2]], e4);
            let area = 0.5 * norm(cross(e0, e1)) + 0.5 * norm(cross(e0, e2));
            let kb = [a, b, c, d].iter().map(|&v| mat(v as usize).bend_stiffness).sum::<f32>() / 4.0;
            let alpha = if kb > 0.0 { area / (3.0 * kb) } else { f32::INFINITY };
            if alpha.is_finite() && area > 0.0 {
                items.push(Bend {
                    v: [a, b, c, d],
                    k: [c03 + c04, c01 + c02, -c01 - c03, -c02 - c04],
                    alpha,
                });
            }
            k += 2;
        } else {
            k += 1;
        }
    }
    colour(pos.len(), items, |b| b.v.to_vec())
}
