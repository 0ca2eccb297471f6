//! The XPBD substep loop (Macklin, Müller, Chentanez 2016; "small steps", Macklin et al. 2019).
//!
//! Per frame: external forces (gravity, wind drag on vertex normals) are evaluated once; then
//! for each of `substeps` substeps of length h:
//! predict `x ← x + h·v` (free) or move pins to their kinematic positions; project stretch,
//! shear, bending and tracking constraints (Gauss–Seidel by colour, λ reset per substep);
//! project contacts with friction (primitives, then mesh colliders posed at the substep's end);
//! `v ← (x − x_prev)/h`.

use super::collision::Colliders;
use super::constraints::{
    bend_constraints, bend_constraints_of, distance_constraints, mesh_distance_constraints, Bend, Coloured,
    Distance,
};
use super::kinematics::{Kinematics, Pin};
use super::mesh_collider::MeshCollider;
use super::params::{Material, SimParams};
use super::tracking::{CoarseTrack, TrackTargets};
use super::wind::Wind;
use crate::geom::mesh::GridMesh;
use crate::geom::vec3::{cross, norm, sub};

/// Everything outside the cloth: how pins move, the wind, the colliders.
#[derive(Clone, Debug)]
pub struct Scene {
    pub kinematics: Kinematics,
    pub wind: Wind,
    pub colliders: Colliders,
    /// Triangle-mesh colliders, projected after the primitives, in order.
    pub meshes: Vec<MeshCollider>,
}

/// A grid cloth and its simulation state.
#[derive(Clone, Debug)]
pub struct Cloth {
    pub w: usize,
    pub h: usize,
    /// Positions (m) and velocities (m/s), vertex (i, j) at `j*w + i`.
    pub x: Vec<[f32; 3]>,
    pub v: Vec<[f32; 3]>,
    prev: Vec<[f32; 3]>,
    /// Inverse vertex masses (1/kg); 0 for pinned vertices.
    pub inv_mass: Vec<f32>,
    /// Lumped vertex area (m²), a third of the adjacent rest triangle areas.
    pub area: Vec<f32>,
    pub dist: Coloured<Distance>,
    pub bend: Coloured<Bend>,
    pub pins: Vec<Pin>,
    /// Simulated time (s).
    pub time: f32,
    lambda_d: Vec<f32>,
    lambda_b: Vec<[f32; 3]>,
    /// Multipliers of the coarse tracking constraints (one 3-vector per LR node).
    lambda_t: Vec<[f32; 3]>,
    /// Long-range attachments: (free vertex, pin index, rest distance m).
    tethers: Vec<(u32, u32, f32)>,
    /// Bending constraints with `w_j·k_j` and `Σ w_j k_j²` (masses are fixed, so precomputed).
    bend_w: Coloured<BendW>,
    accel: Vec<[f32; 3]>,
    /// A mesh cloth's triangles ([`Cloth::from_mesh`]), for its normals; empty for a grid.
    mesh_tris: Vec<[usize; 3]>,
}

impl Cloth {
    /// A cloth at rest in `rest` (flat), with per-vertex material and pinned vertices.
    pub fn new(rest: &GridMesh, material: &dyn Fn(usize) -> Material, pins: Vec<Pin>) -> Cloth {
        let dist = distance_constraints(rest, material);
        let bend = bend_constraints(rest, material);
        Cloth::assemble((rest.w, rest.h), &rest.pos, &rest.triangles(), dist, bend, material, pins)
    }

    /// Move every free vertex by up to `j` metres per coordinate (uniform, seeded by `seed`): the
    /// start of an HR twin under the same LR run (`simulate --hr-jitter`, on sheets and garments).
    pub fn jitter_free(&mut self, seed: u64, j: f32) {
        let mut rng = crate::rng::Rng::new(crate::rng::mix_seed(&[seed, 0x6a17]));
        for (x, &im) in self.x.iter_mut().zip(&self.inv_mass) {
            if im > 0.0 {
                x.iter_mut().for_each(|c| *c += rng.uniform_in(-j, j));
            }
        }
    }

    /// A cloth of any mesh of triangles and quads (`faces` over the rest positions `rest`, m):
    /// stretch on every edge, shear on each quad's diagonals, isometric bending on every
    /// interior edge of its triangles (a quad split along its 0–2 diagonal: bending needs no
    /// grid, and a flat rest is the flat fabric a garment is cut from). Its `w × h` is
    /// `vertices × 1` (a mesh is not a grid: [`Cloth::mesh`] and [`Cloth::normals`] are for
    /// grids).
    pub fn from_mesh(
        rest: &[[f32; 3]],
        faces: &[Vec<u32>],
        material: &dyn Fn(usize) -> Material,
        pins: Vec<Pin>,
    ) -> Cloth {
        let tris: Vec<[usize; 3]> = faces
            .iter()
            .flat_map(|f| (1..f.len() - 1).map(move |k| [f[0] as usize, f[k] as usize, f[k + 1] as usize]))
            .collect();
        let dist = mesh_distance_constraints(rest, faces, material);
        let bend = bend_constraints_of(rest, &tris, material);
        let mut c = Cloth::assemble((rest.len(), 1), rest, &tris, dist, bend, material, pins);
        c.mesh_tris = tris;
        c
    }

    /// A cloth at rest at `pos` (its triangles `tris`, constraints `dist` and `bend`).
    fn assemble(
        (w, h): (usize, usize),
        pos: &[[f32; 3]],
        tris: &[[usize; 3]],
        dist: Coloured<Distance>,
        bend: Coloured<Bend>,
        material: &dyn Fn(usize) -> Material,
        pins: Vec<Pin>,
    ) -> Cloth {
        let n = pos.len();
        let mut area = vec![0.0f32; n];
        for t in tris {
            let a = 0.5 * norm(cross(sub(pos[t[1]], pos[t[0]]), sub(pos[t[2]], pos[t[0]])));
            for &v in t {
                area[v] += a / 3.0;
            }
        }
        let mut inv_mass: Vec<f32> = (0..n)
            .map(|v| {
                let m = material(v).density * area[v];
                if m > 0.0 {
                    1.0 / m
                } else {
                    0.0
                }
            })
            .collect();
        for p in &pins {
            inv_mass[p.vertex] = 0.0;
        }
        let bend_w = Coloured {
            items: bend
                .items
                .iter()
                .map(|b| {
                    let wk: [f32; 4] = std::array::from_fn(|j| inv_mass[b.v[j] as usize] * b.k[j]);
                    BendW { c: *b, wk, ws: (0..4).map(|j| wk[j] * b.k[j]).sum() }
                })
                .collect(),
            ranges: bend.ranges.clone(),
        };
        // Each free vertex tethers to its nearest pin at rest (the sheet is flat, so the rest
        // distance is the geodesic one). Ties go to the lower pin index: deterministic.
        let mut tethers = Vec::new();
        if !pins.is_empty() {
            for (v, &w) in inv_mass.iter().enumerate() {
                if w == 0.0 {
                    continue;
                }
                let (mut best, mut bd) = (0usize, f32::INFINITY);
                for (k, p) in pins.iter().enumerate() {
                    let d = crate::geom::mesh::dist(pos[v], p.anchor);
                    if d < bd {
                        (best, bd) = (k, d);
                    }
                }
                tethers.push((v as u32, best as u32, bd));
            }
        }
        Cloth {
            tethers,
            bend_w,
            w,
            h,
            x: pos.to_vec(),
            v: vec![[0.0; 3]; n],
            prev: pos.to_vec(),
            inv_mass,
            area,
            lambda_d: vec![0.0; dist.items.len()],
            lambda_b: vec![[0.0; 3]; bend.items.len()],
            lambda_t: Vec::new(),
            dist,
            bend,
            pins,
            time: 0.0,
            accel: vec![[0.0; 3]; n],
            mesh_tris: Vec::new(),
        }
    }

    /// The cloth's triangles: a mesh cloth's ([`Cloth::from_mesh`]), or the grid's.
    pub fn triangles(&self) -> Vec<[usize; 3]> {
        if self.mesh_tris.is_empty() {
            self.mesh().triangles()
        } else {
            self.mesh_tris.clone()
        }
    }

    pub fn mesh(&self) -> GridMesh {
        GridMesh::new(self.w, self.h, self.x.clone())
    }

    /// Area-weighted vertex normals (unit; zero for degenerate neighbourhoods): of the grid's
    /// quads, or of a mesh cloth's triangles.
    pub fn normals(&self) -> Vec<[f32; 3]> {
        let (w, h) = (self.w, self.h);
        let mut nrm = vec![[0.0f32; 3]; w * h];
        for t in &self.mesh_tris {
            let n = cross(sub(self.x[t[1]], self.x[t[0]]), sub(self.x[t[2]], self.x[t[0]]));
            for &v in t {
                for k in 0..3 {
                    nrm[v][k] += n[k];
                }
            }
        }
        for j in 0..h.saturating_sub(1) {
            for i in 0..w.saturating_sub(1) {
                let a = j * w + i;
                let (b, c, d) = (a + 1, a + w + 1, a + w);
                let n = cross(sub(self.x[c], self.x[a]), sub(self.x[d], self.x[b]));
                for v in [a, b, c, d] {
                    for k in 0..3 {
                        nrm[v][k] += n[k];
                    }
                }
            }
        }
        for n in &mut nrm {
            let l = norm(*n);
            if l > 0.0 {
                *n = [n[0] / l, n[1] / l, n[2] / l];
            }
        }
        nrm
    }

    /// Advance one frame of `p.dt` seconds.
    pub fn step(&mut self, p: &SimParams, scene: &Scene, track: Option<&TrackTargets>) {
        let n = self.x.len();
        let h = p.h();
        // External accelerations, constant over the frame.
        if scene.wind.is_calm() || p.drag == 0.0 {
            self.accel.iter_mut().for_each(|a| *a = p.gravity);
        } else {
            let nrm = self.normals();
            for (v, nv) in nrm.iter().enumerate() {
                let wv = scene.wind.velocity(self.time, self.x[v]);
                let rel = sub(wv, self.v[v]);
                let rn = rel[0] * nv[0] + rel[1] * nv[1] + rel[2] * nv[2];
                let f = p.drag * self.area[v] * rn * self.inv_mass[v];
                self.accel[v] = std::array::from_fn(|k| p.gravity[k] + f * nv[k]);
            }
        }
        let damp = (1.0 - p.damping * h).max(0.0);
        let track_frac = track.filter(|t| t.strength > 0.0).map(|t| {
            let s = t.strength * h * h;
            s / (1.0 + s)
        });
        for s in 0..p.substeps {
            let t = self.time + h * (s + 1) as f32;
            self.prev.copy_from_slice(&self.x);
            for v in 0..n {
                if self.inv_mass[v] > 0.0 {
                    let (x, vel, a) = (&mut self.x[v], &mut self.v[v], self.accel[v]);
                    for k in 0..3 {
                        vel[k] = (vel[k] + h * a[k]) * damp;
                        x[k] += h * vel[k];
                    }
                }
            }
            let blend = (s + 1) as f32 / p.substeps as f32;
            for (k, pin) in self.pins.iter().enumerate() {
                self.x[pin.vertex] = match track.and_then(|tt| tt.pins) {
                    Some(path) => {
                        std::array::from_fn(|c| path.from[k][c] + blend * (path.to[k][c] - path.from[k][c]))
                    }
                    None => scene.kinematics.position(pin.anchor, pin.side, t),
                };
            }
            self.lambda_d.iter_mut().for_each(|l| *l = 0.0);
            self.lambda_b.iter_mut().for_each(|l| *l = [0.0; 3]);
            if let Some(TrackTargets { coarse: Some(ct), .. }) = track {
                self.lambda_t.clear();
                self.lambda_t.resize(ct.restriction.nodes(), [0.0; 3]);
            }
            let inv_h2 = 1.0 / (h * h);
            for _ in 0..p.iterations {
                let par = p.parallel_min_colour;
                solve_distance(&mut self.x, &self.inv_mass, &self.dist, &mut self.lambda_d, inv_h2, par);
                solve_bend(&mut self.x, &self.bend_w, &mut self.lambda_b, inv_h2, par);
                match (track_frac, track) {
                    (Some(_), Some(tt @ TrackTargets { coarse: Some(ct), .. })) => {
                        let blends = (s as f32 / p.substeps as f32, blend);
                        let (x, prev) = (&mut self.x, &self.prev);
                        solve_coarse_track(x, prev, &self.inv_mass, ct, tt, blends, &mut self.lambda_t, h);
                    }
                    (Some(frac), Some(tt)) => {
                        for v in 0..n {
                            if self.inv_mass[v] > 0.0 {
                                for k in 0..3 {
                                    let target = tt.from[v][k] + blend * (tt.to[v][k] - tt.from[v][k]);
                                    self.x[v][k] += frac * (target - self.x[v][k]);
                                }
                            }
                        }
                    }
                    _ => {}
                }
            }
            if p.tethers {
                let slack = 1.0 + p.tether_slack;
                for &(v, k, rest) in &self.tethers {
                    let a = self.x[self.pins[k as usize].vertex];
                    let xv = &mut self.x[v as usize];
                    let d = sub(*xv, a);
                    let l = norm(d);
                    let max = rest * slack;
                    if l > max {
                        let f = max / l;
                        *xv = std::array::from_fn(|c| a[c] + d[c] * f);
                    }
                }
            }
            scene.colliders.project(&mut self.x, &self.prev, &self.inv_mass, p.collision_margin, p.friction);
            let blends = (s as f32 / p.substeps as f32, blend);
            for m in &scene.meshes {
                m.substep(&mut self.x, &self.prev, &self.inv_mass, blends, p.friction);
            }
            let inv_h = 1.0 / h;
            for v in 0..n {
                self.v[v] = std::array::from_fn(|k| (self.x[v][k] - self.prev[v][k]) * inv_h);
            }
        }
        self.time += p.dt;
    }
}

/// Positions shared by the threads projecting one colour. Constraints of a colour touch
/// disjoint vertices, so no two threads read or write the same element.
#[derive(Clone, Copy)]
struct XPtr(*mut [f32; 3]);
// SAFETY: only used inside one colour (disjoint vertex sets) while the owning `&mut` slice is
// borrowed by `for_colours`.
unsafe impl Send for XPtr {}
unsafe impl Sync for XPtr {}

impl XPtr {
    #[inline(always)]
    fn get(self, i: usize) -> [f32; 3] {
        // SAFETY: `i` is a vertex of the grid (constraints are built from it); see `XPtr`.
        unsafe { self.0.add(i).read() }
    }
    #[inline(always)]
    fn set(self, i: usize, v: [f32; 3]) {
        // SAFETY: as in `get`; no other thread touches vertex `i` in this colour.
        unsafe { self.0.add(i).write(v) }
    }
}

/// The overflow colour of [`super::constraints::colour`] may hold conflicting constraints.
const OVERFLOW_COLOUR: usize = 127;

/// Run `f` over each colour's constraints in colour order: serially, or for colours with at
/// least `par_min` members in parallel chunks (same bits either way).
fn for_colours<T: Sync, L: Send>(
    x: &mut [[f32; 3]],
    cs: &Coloured<T>,
    lambda: &mut [L],
    par_min: usize,
    f: impl Fn(XPtr, &T, &mut L) + Sync,
) {
    let xp = XPtr(x.as_mut_ptr());
    for (c, r) in cs.ranges.iter().enumerate() {
        let (items, ls) = (&cs.items[r.clone()], &mut lambda[r.clone()]);
        if r.len() >= par_min && c < OVERFLOW_COLOUR {
            use rayon::prelude::*;
            items.par_chunks(1024).zip(ls.par_chunks_mut(1024)).for_each(|(ic, lc)| {
                for (it, l) in ic.iter().zip(lc.iter_mut()) {
                    f(xp, it, l);
                }
            });
        } else {
            for (it, l) in items.iter().zip(ls.iter_mut()) {
                f(xp, it, l);
            }
        }
    }
}

/// Gauss–Seidel projection of distance constraints (in colour order).
fn solve_distance(
    x: &mut [[f32; 3]],
    w: &[f32],
    cs: &Coloured<Distance>,
    lambda: &mut [f32],
    inv_h2: f32,
    par: usize,
) {
    for_colours(x, cs, lambda, par, |x, c, l| {
        let (a, b) = (c.a as usize, c.b as usize);
        let (wa, wb) = (w[a], w[b]);
        let ws = wa + wb;
        if ws == 0.0 {
            return;
        }
        let (xa, xb) = (x.get(a), x.get(b));
        let d = sub(xa, xb);
        let len = norm(d);
        if len < 1e-12 {
            return;
        }
        let at = c.alpha * inv_h2;
        let dl = (-(len - c.rest) - at * *l) / (ws + at);
        *l += dl;
        let s = dl / len;
        x.set(a, std::array::from_fn(|k| xa[k] + wa * s * d[k]));
        x.set(b, std::array::from_fn(|k| xb[k] - wb * s * d[k]));
    });
}

/// A bending constraint with its mass-weighted coefficients.
#[derive(Clone, Copy, Debug)]
struct BendW {
    c: Bend,
    /// `w_j · k_j` (1/kg).
    wk: [f32; 4],
    /// `Σ w_j k_j²` (1/kg).
    ws: f32,
}

/// Projection of the linear isometric-bending constraints `Σ k_j x_j = 0` (3 components).
fn solve_bend(x: &mut [[f32; 3]], cs: &Coloured<BendW>, lambda: &mut [[f32; 3]], inv_h2: f32, par: usize) {
    for_colours(x, cs, lambda, par, |x, b, l| {
        let (c, wk, ws) = (&b.c, b.wk, b.ws);
        if ws == 0.0 {
            return;
        }
        let vi = c.v.map(|v| v as usize);
        let at = c.alpha * inv_h2;
        let p = vi.map(|v| x.get(v));
        let cv: [f32; 3] = std::array::from_fn(|k| {
            c.k[0] * p[0][k] + c.k[1] * p[1][k] + c.k[2] * p[2][k] + c.k[3] * p[3][k]
        });
        let denom = 1.0 / (ws + at);
        let dl: [f32; 3] = std::array::from_fn(|k| (-cv[k] - at * l[k]) * denom);
        for k in 0..3 {
            l[k] += dl[k];
        }
        for j in 0..4 {
            x.set(vi[j], std::array::from_fn(|k| p[j][k] + wk[j] * dl[k]));
        }
    });
}

/// Gauss–Seidel XPBD projection of the coarse tracking constraints
/// `C_I = Σ_k w_Ik x_k − t_I` (3 components, `t_I` blended between the frame's targets at
/// `blends.1` of the frame, `blends.0` at the substep's start), each a zero-length spring of
/// stiffness `m_I · strength` (compliance `α = 1/(m_I · strength)`, `α̃ = α/h²`), damped with
/// `β = 2·damping/√strength` (critical at `damping` = 1; `γ = α β / h`) on the change of C over
/// the substep, `δC = Σ_k w_Ik (x_k − x_prev,k) − (t_I(end) − t_I(start))`:
/// `Δλ = (−C − α̃ λ − γ δC) / ((1 + γ) Σ_k w_k²/m_k + α̃)`, `x_k += w_k/m_k · Δλ`
/// (Macklin et al. 2016, Eq 26). Serial, in node order.
#[allow(clippy::too_many_arguments)]
fn solve_coarse_track(
    x: &mut [[f32; 3]],
    prev: &[[f32; 3]],
    inv_mass: &[f32],
    ct: &CoarseTrack,
    tt: &TrackTargets,
    blends: (f32, f32),
    lambda: &mut [[f32; 3]],
    h: f32,
) {
    let inv_h2 = 1.0 / (h * h);
    let target = |n: usize, b: f32| -> [f32; 3] {
        std::array::from_fn(|k| tt.from[n][k] + b * (tt.to[n][k] - tt.from[n][k]))
    };
    for (n, l) in lambda.iter_mut().enumerate() {
        let (ws, m) = (ct.w2_inv_mass[n], ct.node_mass[n]);
        if ws == 0.0 || m == 0.0 {
            continue;
        }
        let at = inv_h2 / (m * tt.strength);
        let t1 = target(n, blends.1);
        let mut c: [f32; 3] = std::array::from_fn(|k| -t1[k]);
        for (v, wv) in ct.restriction.node(n) {
            for k in 0..3 {
                c[k] += wv * x[v][k];
            }
        }
        let dl: [f32; 3] = if tt.damping > 0.0 {
            let gamma = 2.0 * tt.damping / tt.strength.sqrt() / (m * tt.strength * h);
            let t0 = target(n, blends.0);
            let mut dc: [f32; 3] = std::array::from_fn(|k| t0[k] - t1[k]);
            for (v, wv) in ct.restriction.node(n) {
                for k in 0..3 {
                    dc[k] += wv * (x[v][k] - prev[v][k]);
                }
            }
            let denom = 1.0 / ((1.0 + gamma) * ws + at);
            std::array::from_fn(|k| (-c[k] - at * l[k] - gamma * dc[k]) * denom)
        } else {
            let denom = 1.0 / (ws + at);
            std::array::from_fn(|k| (-c[k] - at * l[k]) * denom)
        };
        for k in 0..3 {
            l[k] += dl[k];
        }
        for (v, wv) in ct.restriction.node(n) {
            let f = wv * inv_mass[v];
            for k in 0..3 {
                x[v][k] += f * dl[k];
            }
        }
    }
}
