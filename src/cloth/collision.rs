//! Sphere, box and ground contacts, projected after the constraints of every substep, with a
//! margin and position-based Coulomb friction (Macklin et al. 2014, "Unified particle physics").

use crate::geom::vec3::{dot, norm, sub};

/// A static sphere: centre (m), radius (m).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sphere {
    pub center: [f32; 3],
    pub radius: f32,
}

/// A static axis-aligned box (a table): centre (m), half extents along x, y, z (m).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cuboid {
    pub center: [f32; 3],
    pub half: [f32; 3],
}

/// Colliders of a scene.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Colliders {
    pub sphere: Option<Sphere>,
    pub cuboid: Option<Cuboid>,
    /// Height (m) of a horizontal ground plane y = ground.
    pub ground: Option<f32>,
}

/// Push `x` out along unit normal `n` by `pen` (m) and remove tangential motion since `prev`
/// up to `mu · pen` (static friction below that, kinetic above). A moving collider
/// ([`super::mesh_collider`]) passes `prev` carried along with its surface, so the friction
/// acts on the motion relative to it.
#[inline]
pub(super) fn resolve(x: &mut [f32; 3], prev: [f32; 3], n: [f32; 3], pen: f32, mu: f32) {
    for k in 0..3 {
        x[k] += n[k] * pen;
    }
    let dx = sub(*x, prev);
    let dn = dot(dx, n);
    let t = [dx[0] - dn * n[0], dx[1] - dn * n[1], dx[2] - dn * n[2]];
    let lt = norm(t);
    if lt <= 0.0 {
        return;
    }
    let f = if lt < mu * pen { 1.0 } else { mu * pen / lt };
    for k in 0..3 {
        x[k] -= f * t[k];
    }
}

impl Colliders {
    /// Project every free vertex (inv_mass > 0) out of the colliders, `margin` (m) away.
    pub fn project(&self, x: &mut [[f32; 3]], prev: &[[f32; 3]], inv_mass: &[f32], margin: f32, mu: f32) {
        if let Some(s) = self.sphere {
            let r = s.radius + margin;
            for v in 0..x.len() {
                if inv_mass[v] == 0.0 {
                    continue;
                }
                let d = sub(x[v], s.center);
                let l2 = dot(d, d);
                if l2 < r * r {
                    let l = l2.sqrt();
                    let n = if l > 1e-9 { [d[0] / l, d[1] / l, d[2] / l] } else { [0.0, 1.0, 0.0] };
                    resolve(&mut x[v], prev[v], n, r - l, mu);
                }
            }
        }
        if let Some(b) = self.cuboid {
            // A vertex inside the box grown by the margin leaves through the nearest face.
            for v in 0..x.len() {
                if inv_mass[v] == 0.0 {
                    continue;
                }
                let d = sub(x[v], b.center);
                let pen: [f32; 3] = std::array::from_fn(|k| b.half[k] + margin - d[k].abs());
                if pen.iter().all(|&p| p > 0.0) {
                    let k = (0..3).min_by(|&i, &j| pen[i].total_cmp(&pen[j])).unwrap_or(1);
                    let mut n = [0.0; 3];
                    n[k] = if d[k] < 0.0 { -1.0 } else { 1.0 };
                    resolve(&mut x[v], prev[v], n, pen[k], mu);
                }
            }
        }
        if let Some(g) = self.ground {
            let y0 = g + margin;
            for v in 0..x.len() {
                if inv_mass[v] != 0.0 && x[v][1] < y0 {
                    let pen = y0 - x[v][1];
                    resolve(&mut x[v], prev[v], [0.0, 1.0, 0.0], pen, mu);
                }
            }
        }
    }
}
