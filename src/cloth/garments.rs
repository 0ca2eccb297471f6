//! Garments (issue 45): cloth of any mesh — tubes, T-shaped panels sewn together, disks of
//! triangles, sheets with holes, seams in the UVs — on a body of closed meshes that moves, as
//! named presets beside the sheet scenarios, simulated as an LR/HR pair the way the sheets are.
//!
//! - The cloth is cut from a pattern: its rest mesh is the garment as sewn, its UVs the flat
//!   pattern (a tube has a seam where the pattern's two edges meet).
//! - The body is a set of closed meshes (torso, limbs), each rigid, moved by a hierarchy of
//!   joints ([`Body`]); parts never overlap (limbs taper toward their joints and leave a gap),
//!   so the union is one collider whose inside the closest surface tells. A pinned vertex rides
//!   on the part it is sewn to (a waistband, a collar, a shoulder).
//! - The HR run is the LR mesh subdivided once ([`Subdivision`]), simulated with twice the
//!   substeps and held to the LR run only at the LR vertices (coarse tracking, as the sheets'
//!   training truth), so its folds are its own.
//!
//! The output is the layout `eval --meshes` reads: `lr/`, `hr/` (OBJ frames with the pattern's
//! UVs), `collider/` (the body, frame by frame) and `scene.json`.

use super::collision::Colliders;
use super::kinematics::{Kinematics, Pin};
use super::mesh_collider::{ColliderMesh, MeshCollider};
use super::params::{Material, SimParams};
use super::scenarios::DEFAULT_TRACKING;
use super::solver::{Cloth, Scene};
use super::tracking::{CoarseTrack, PinPath, Restriction, TrackTargets};
use super::wind::Wind;
use crate::error::{Error, Result};
use crate::geom::surface::{Subdivision, Surface};
use std::f32::consts::{PI, TAU};
use std::path::Path;
use std::sync::Arc;

/// `--help` text listing the garments.
pub const GARMENT_HELP: &str = "Garments (meshes that are not grids; --pair writes lr/, hr/, collider/, scene.json):
  skirt            flared skirt (a tube of quads, UV seam at the back), waistband on the hips of a body that turns and walks
  sleeve           sleeve (a tube of quads) sewn at the shoulder, on an arm that bends at the elbow and lifts
  cape             cape (rounded panel of triangles) fastened around the neck of a torso that turns and sways
  tablecloth       round tablecloth (a disk of triangles) dropped on a round table, in a breeze
  tshirt           T-shirt (front and back T panels of quads sewn at sides, shoulders and sleeves) on a torso with moving arms
  holed-sheet      square sheet of triangles with a round hole, dropped on a ball, in a breeze";

/// A garment preset.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Garment {
    Skirt,
    Sleeve,
    Cape,
    Tablecloth,
    Tshirt,
    HoledSheet,
}

impl Garment {
    pub const ALL: [Garment; 6] = [
        Garment::Skirt,
        Garment::Sleeve,
        Garment::Cape,
        Garment::Tablecloth,
        Garment::Tshirt,
        Garment::HoledSheet,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Garment::Skirt => "skirt",
            Garment::Sleeve => "sleeve",
            Garment::Cape => "cape",
            Garment::Tablecloth => "tablecloth",
            Garment::Tshirt => "tshirt",
            Garment::HoledSheet => "holed-sheet",
        }
    }

    /// The garment called `name`, or None (a sheet scenario, or nothing).
    pub fn from_name(name: &str) -> Option<Garment> {
        Garment::ALL.iter().copied().find(|g| g.name() == name)
    }
}

impl std::fmt::Display for Garment {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A seeded variant of a garment scene (seed 0: as given): garment and body size, how far and
/// how fast the body moves, the breeze, the material.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GarmentVariation {
    /// Size factor of garment and body together.
    pub size: f32,
    /// Amplitude and frequency factors of every joint's motion.
    pub motion: f32,
    pub speed: f32,
    /// Breeze strength factor.
    pub wind: f32,
    /// Garment fullness factor (a skirt's flare, a cape's width, a tablecloth's overhang).
    pub fullness: f32,
    /// Material (None = the spec's).
    pub material: Option<Material>,
}

impl GarmentVariation {
    pub const NONE: GarmentVariation =
        GarmentVariation { size: 1.0, motion: 1.0, speed: 1.0, wind: 1.0, fullness: 1.0, material: None };

    pub fn from_seed(seed: u64) -> GarmentVariation {
        if seed == 0 {
            return GarmentVariation::NONE;
        }
        let mut r = crate::rng::Rng::new(crate::rng::mix_seed(&[0x6A2E, seed]));
        GarmentVariation {
            size: r.uniform_in(0.85, 1.15),
            motion: r.uniform_in(0.6, 1.4),
            speed: r.uniform_in(0.7, 1.3),
            wind: r.uniform_in(0.4, 1.6),
            fullness: r.uniform_in(0.8, 1.2),
            material: Some(Material::ALL[r.below(Material::ALL.len())]),
        }
    }
}

/// One garment run (or pair) to simulate.
#[derive(Clone, Debug, PartialEq)]
pub struct GarmentSpec {
    pub garment: Garment,
    /// Output frames; frame 0 is the rest state, frame k at time k·dt.
    pub frames: usize,
    /// Seeds the breeze.
    pub seed: u64,
    /// Seed of the randomised variant ([`GarmentVariation`]); 0 = the garment as given.
    pub vary: u64,
    pub material: Material,
    /// HR → LR attachment strength (1/s², coarse: one constraint per LR vertex); 0 = off.
    pub tracking: f32,
    /// Metres of seeded noise (uniform in ±`hr_jitter` per coordinate, seed `seed`) added to
    /// the HR run's free start positions: a twin of the HR truth under the same LR run, for
    /// measuring how much of the truth the LR run fixes. 0 = the truth itself.
    pub hr_jitter: f32,
    /// The gap the cloth keeps from the body (m).
    pub thickness: f32,
    pub params: SimParams,
}

impl GarmentSpec {
    pub fn new(garment: Garment) -> GarmentSpec {
        GarmentSpec {
            garment,
            frames: 150,
            seed: 0,
            vary: 0,
            material: Material::COTTON,
            tracking: DEFAULT_TRACKING,
            hr_jitter: 0.0,
            thickness: 0.006,
            params: SimParams::default(),
        }
    }

    pub fn validate(&self) -> Result<()> {
        self.params.validate()?;
        if self.frames == 0 || self.frames > 100_000 {
            return Err(Error::config(format!("frames must be 1 to 100000, got {}", self.frames)));
        }
        if !(self.tracking.is_finite() && self.tracking >= 0.0) {
            return Err(Error::config(format!(
                "tracking must be finite and ≥ 0 (1/s²), got {}",
                self.tracking
            )));
        }
        if !(self.hr_jitter.is_finite() && (0.0..=0.01).contains(&self.hr_jitter)) {
            return Err(Error::config(format!("hr-jitter must be 0 to 0.01 m, got {}", self.hr_jitter)));
        }
        if !(self.thickness.is_finite() && (0.0005..=0.05).contains(&self.thickness)) {
            return Err(Error::config(format!("thickness must be 0.5 to 50 mm, got {} m", self.thickness)));
        }
        Ok(())
    }
}

/// A rigid motion `x ↦ r·x + t`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rigid {
    pub r: [[f32; 3]; 3],
    pub t: [f32; 3],
}

impl Rigid {
    pub const IDENTITY: Rigid = Rigid { r: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], t: [0.0; 3] };

    pub fn apply(&self, p: [f32; 3]) -> [f32; 3] {
        std::array::from_fn(|i| (0..3).map(|j| self.r[i][j] * p[j]).sum::<f32>() + self.t[i])
    }

    /// `self ∘ o` (first `o`, then `self`).
    pub fn then(&self, o: &Rigid) -> Rigid {
        let r =
            std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| self.r[i][k] * o.r[k][j]).sum()));
        Rigid { r, t: self.apply(o.t) }
    }

    /// The turn by `angle` (rad) about the unit `axis` through `pivot` (Rodrigues).
    pub fn about(pivot: [f32; 3], axis: [f32; 3], angle: f32) -> Rigid {
        let (s, c) = angle.sin_cos();
        let [x, y, z] = axis;
        let r = [
            [c + x * x * (1.0 - c), x * y * (1.0 - c) - z * s, x * z * (1.0 - c) + y * s],
            [y * x * (1.0 - c) + z * s, c + y * y * (1.0 - c), y * z * (1.0 - c) - x * s],
            [z * x * (1.0 - c) - y * s, z * y * (1.0 - c) + x * s, c + z * z * (1.0 - c)],
        ];
        let rot = Rigid { r, t: [0.0; 3] };
        let q = rot.apply(pivot);
        Rigid { r, t: std::array::from_fn(|k| pivot[k] - q[k]) }
    }
}

/// A joint's angle (rad) or an offset (m) over time `t` (s), eased in over the first second:
/// `ease(t) · (offset + amp · sin(2π · freq · t + phase))`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Wave {
    pub offset: f32,
    pub amp: f32,
    pub freq: f32,
    pub phase: f32,
}

impl Wave {
    pub const ZERO: Wave = Wave { offset: 0.0, amp: 0.0, freq: 0.0, phase: 0.0 };

    pub fn at(&self, t: f32) -> f32 {
        let e = t.clamp(0.0, 1.0);
        let ease = e * e * (3.0 - 2.0 * e);
        ease * (self.offset + self.amp * (TAU * self.freq * t + self.phase).sin())
    }

    fn scaled(self, amp: f32, speed: f32) -> Wave {
        Wave { offset: self.offset * amp, amp: self.amp * amp, freq: self.freq * speed, phase: self.phase }
    }
}

/// One rigid part of a body: a closed mesh at rest (m), turned about its joint (`pivot`, unit
/// `axis`, angle `angle(t)`) after its parent's motion.
#[derive(Clone, Debug)]
pub struct Part {
    pub pos: Vec<[f32; 3]>,
    pub faces: Vec<Vec<u32>>,
    pub parent: Option<usize>,
    pub pivot: [f32; 3],
    pub axis: [f32; 3],
    pub angle: Wave,
}

/// A moving body: parts (a parent before its children) and the root's motion — a turn about
/// the vertical through the origin (`yaw`, rad), a sway along x and a bob along y (m).
#[derive(Clone, Debug)]
pub struct Body {
    pub parts: Vec<Part>,
    pub yaw: Wave,
    pub sway: Wave,
    pub bob: Wave,
}

impl Body {
    /// Every part's motion at time `t` (s).
    pub fn poses(&self, t: f32) -> Vec<Rigid> {
        let root = Rigid::about([0.0; 3], [0.0, 1.0, 0.0], self.yaw.at(t));
        let root = Rigid { t: [self.sway.at(t), self.bob.at(t), 0.0], ..root };
        let mut out: Vec<Rigid> = Vec::with_capacity(self.parts.len());
        for p in &self.parts {
            let base = p.parent.map_or(root, |q| out[q]);
            out.push(base.then(&Rigid::about(p.pivot, p.axis, p.angle.at(t))));
        }
        out
    }

    /// The body as one mesh: its faces and its vertices at each of `frames` frames `dt` apart.
    pub fn frames(&self, frames: usize, dt: f32) -> (Vec<Vec<u32>>, Vec<Vec<[f32; 3]>>) {
        let mut faces = Vec::new();
        let mut base = 0u32;
        for p in &self.parts {
            faces.extend(p.faces.iter().map(|f| f.iter().map(|v| v + base).collect::<Vec<u32>>()));
            base += p.pos.len() as u32;
        }
        let posed = (0..frames)
            .map(|k| {
                let poses = self.poses(k as f32 * dt);
                self.parts.iter().zip(&poses).flat_map(|(p, m)| p.pos.iter().map(|x| m.apply(*x))).collect()
            })
            .collect();
        (faces, posed)
    }
}

/// A closed tube along the unit `axis` from `a`: `radius(s)` = (half-widths across) at `s` m
/// along it, for `s` in `0..=len`, `rings` rings of `seg` vertices, capped by a fan at each end;
/// wound outward. `across` is a unit vector perpendicular to `axis` (the first half-width's
/// direction).
#[allow(clippy::too_many_arguments)]
fn tube(
    a: [f32; 3],
    axis: [f32; 3],
    across: [f32; 3],
    len: f32,
    rings: usize,
    seg: usize,
    radius: impl Fn(f32) -> (f32, f32),
) -> (Vec<[f32; 3]>, Vec<Vec<u32>>) {
    let b = crate::geom::vec3::cross(axis, across);
    let mut pos = Vec::new();
    for j in 0..rings {
        let s = len * j as f32 / (rings - 1) as f32;
        let (r1, r2) = radius(s);
        for i in 0..seg {
            let ph = TAU * i as f32 / seg as f32;
            let (c, sn) = (ph.cos(), ph.sin());
            pos.push(std::array::from_fn(|k| a[k] + s * axis[k] + r1 * c * across[k] + r2 * sn * b[k]));
        }
    }
    let ring = |j: usize, i: usize| (j * seg + i % seg) as u32;
    let mut faces = Vec::new();
    for j in 0..rings - 1 {
        for i in 0..seg {
            faces.push(vec![ring(j, i), ring(j, i + 1), ring(j + 1, i + 1), ring(j + 1, i)]);
        }
    }
    let (c0, c1) = (pos.len() as u32, pos.len() as u32 + 1);
    pos.push(a);
    pos.push(std::array::from_fn(|k| a[k] + len * axis[k]));
    for i in 0..seg {
        faces.push(vec![c0, ring(0, i + 1), ring(0, i)]);
        faces.push(vec![c1, ring(rings - 1, i), ring(rings - 1, i + 1)]);
    }
    // Wound so that the normals point away from the axis: flip if the first quad's faces in.
    let f = &faces[0];
    let (p0, p1, p3) = (pos[f[0] as usize], pos[f[1] as usize], pos[f[3] as usize]);
    let n = crate::geom::vec3::cross(crate::geom::vec3::sub(p1, p0), crate::geom::vec3::sub(p3, p0));
    let out = crate::geom::vec3::sub(p0, a);
    if crate::geom::vec3::dot(n, out) - crate::geom::vec3::dot(n, axis) * crate::geom::vec3::dot(out, axis)
        < 0.0
    {
        faces.iter_mut().for_each(|f| f.reverse());
    }
    (pos, faces)
}

/// A limb: a round tube of `radius` from `a` along `axis` for `len` m, tapered to a third of
/// its radius over its last 4 cm at each joint end (`taper_start`, `taper_end`), so that two
/// limbs turning about the joint between them never overlap.
fn limb(
    a: [f32; 3],
    axis: [f32; 3],
    len: f32,
    radius: f32,
    taper: (bool, bool),
) -> (Vec<[f32; 3]>, Vec<Vec<u32>>) {
    let across = if axis[1].abs() > 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
    let across = crate::geom::vec3::normalize_or(
        crate::geom::vec3::sub(across, axis.map(|c| c * crate::geom::vec3::dot(across, axis))),
        [0.0, 0.0, 1.0],
    );
    let r = move |s: f32| {
        let end = |d: f32| if d < 0.04 { radius * (0.33 + 0.67 * d / 0.04) } else { radius };
        let mut v = radius;
        if taper.0 {
            v = v.min(end(s));
        }
        if taper.1 {
            v = v.min(end(len - s));
        }
        (v, v)
    };
    tube(a, axis, across, len, (len / 0.02).ceil().max(3.0) as usize + 1, 16, r)
}

/// A cloth mesh as cut: rest positions (m), faces (triangles and quads), the pattern's UVs
/// with each face's UV indices, and the vertices sewn to a body part (vertex, part).
#[derive(Clone, Debug, Default)]
pub struct GarmentMesh {
    pub pos: Vec<[f32; 3]>,
    pub faces: Vec<Vec<u32>>,
    pub uv: Vec<[f32; 2]>,
    pub face_uv: Vec<Vec<u32>>,
    pub pins: Vec<(u32, usize)>,
}

/// A flat pattern of `nx × ny` cells over `[0, sx] × [0, sy]` (m), the cells `keep(i, j)`
/// keeps, placed by `place(x, y)`; quads, or each quad in two triangles (diagonals alternating,
/// so the mesh has no preferred direction). Vertices no kept cell uses are dropped; the UVs are
/// the pattern's `(x/sx, y/sy)`. Returns the mesh and, per kept vertex, its grid `(i, j)`.
fn pattern(
    (nx, ny): (usize, usize),
    (sx, sy): (f32, f32),
    keep: impl Fn(usize, usize) -> bool,
    place: impl Fn(f32, f32) -> [f32; 3],
    triangles: bool,
) -> (GarmentMesh, Vec<(usize, usize)>) {
    let mut id = vec![u32::MAX; (nx + 1) * (ny + 1)];
    let mut m = GarmentMesh::default();
    let mut ij = Vec::new();
    let mut vertex = |m: &mut GarmentMesh, i: usize, j: usize| -> u32 {
        let k = j * (nx + 1) + i;
        if id[k] == u32::MAX {
            id[k] = m.pos.len() as u32;
            let (x, y) = (sx * i as f32 / nx as f32, sy * j as f32 / ny as f32);
            m.pos.push(place(x, y));
            m.uv.push([x / sx, y / sy]);
            ij.push((i, j));
        }
        id[k]
    };
    for j in 0..ny {
        for i in 0..nx {
            if !keep(i, j) {
                continue;
            }
            let [a, b, c, d] =
                [(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)].map(|(i, j)| vertex(&mut m, i, j));
            let faces: Vec<Vec<u32>> = if !triangles {
                vec![vec![a, b, c, d]]
            } else if (i + j) % 2 == 0 {
                vec![vec![a, b, c], vec![a, c, d]]
            } else {
                vec![vec![a, b, d], vec![b, c, d]]
            };
            m.face_uv.extend(faces.iter().cloned());
            m.faces.extend(faces);
        }
    }
    (m, ij)
}

/// A breeze of mean velocity `mean` (m/s); its gusts are added, seeded, by [`GarmentSpec::scene`].
fn breeze(mean: [f32; 3]) -> Wind {
    Wind { mean, gusts: Vec::new() }
}

/// A garment scene: the cloth, the body it is on, the breeze, and a floor (height, m) if any.
pub struct GarmentScene {
    pub mesh: GarmentMesh,
    pub body: Body,
    pub wind: Wind,
    pub ground: Option<f32>,
    /// Tether free vertices to their nearest pin (off where the straight distance is far
    /// shorter than the way along the cloth: panels sewn around a body).
    pub tethers: bool,
}

/// A skirt: a tube of quads from the waist (radius of the hips) flaring to the hem, its UVs a
/// pattern cut open at the back; the waistband pinned to the hips.
fn skirt(v: &GarmentVariation) -> GarmentScene {
    let (s, full) = (v.size, v.fullness);
    let (seg, rings) = (28, 12);
    let (top, hem) = (1.04 * s, (1.04 - 0.5) * s);
    let (rx, rz) = (0.175 * s, 0.135 * s);
    let flare = 1.0 + 1.0 * full;
    let mut m = GarmentMesh::default();
    for j in 0..rings {
        let f = j as f32 / (rings - 1) as f32;
        let y = top + f * (hem - top);
        let k = 1.0 + f * (flare - 1.0);
        for i in 0..seg {
            // Angle 0 at the back (−z): the pattern's seam.
            let ph = TAU * i as f32 / seg as f32;
            m.pos.push([k * rx * ph.sin(), y, -k * rz * ph.cos()]);
        }
        for i in 0..=seg {
            m.uv.push([i as f32 / seg as f32, 1.0 - f]);
        }
    }
    for j in 0..rings - 1 {
        for i in 0..seg {
            let v = |j: usize, i: usize| (j * seg + i % seg) as u32;
            let t = |j: usize, i: usize| (j * (seg + 1) + i) as u32;
            m.faces.push(vec![v(j, i), v(j + 1, i), v(j + 1, i + 1), v(j, i + 1)]);
            m.face_uv.push(vec![t(j, i), t(j + 1, i), t(j + 1, i + 1), t(j, i + 1)]);
        }
    }
    m.pins = (0..seg as u32).map(|i| (i, 0)).collect();
    // Hips (an elliptic drum) and two legs hanging from hip joints below it, tapered at the top.
    let (hips_p, hips_f) =
        tube([0.0, 0.86 * s, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0], 0.26 * s, 6, 24, |_| {
            (0.16 * s, 0.12 * s)
        });
    let leg = |x: f32, phase: f32| {
        let (p, f) = limb([x * s, 0.82 * s, 0.0], [0.0, -1.0, 0.0], 0.8 * s, 0.065 * s, (true, false));
        Part {
            pos: p,
            faces: f,
            parent: Some(0),
            pivot: [x * s, 0.84 * s, 0.0],
            axis: [1.0, 0.0, 0.0],
            angle: Wave { offset: 0.0, amp: 0.42, freq: 0.9, phase }.scaled(v.motion, v.speed),
        }
    };
    let hips = Part {
        pos: hips_p,
        faces: hips_f,
        parent: None,
        pivot: [0.0; 3],
        axis: [0.0, 1.0, 0.0],
        angle: Wave::ZERO,
    };
    let body = Body {
        parts: vec![hips, leg(0.08, 0.0), leg(-0.08, PI)],
        yaw: Wave { offset: 0.0, amp: 1.0, freq: 0.3, phase: 0.0 }.scaled(v.motion, v.speed),
        sway: Wave { offset: 0.0, amp: 0.03, freq: 0.45, phase: 0.5 }.scaled(v.motion, v.speed),
        bob: Wave { offset: 0.0, amp: 0.012, freq: 1.8, phase: 0.0 }.scaled(v.motion, v.speed),
    };
    GarmentScene { mesh: m, body, wind: Wind::none(), ground: None, tethers: true }
}

/// A sleeve: a tube of quads around an arm held out along +x, sewn at the shoulder; the arm
/// lifts at the shoulder and bends at the elbow.
fn sleeve(v: &GarmentVariation) -> GarmentScene {
    let s = v.size;
    let (seg, rings) = (16, 16);
    let (len, r0, r1) = (0.5 * s, 0.08 * s * v.fullness, 0.065 * s * v.fullness);
    let y0 = 1.4 * s;
    let mut m = GarmentMesh::default();
    for j in 0..rings {
        let f = j as f32 / (rings - 1) as f32;
        let r = r0 + f * (r1 - r0);
        for i in 0..seg {
            // Angle 0 under the arm: the pattern's seam.
            let ph = TAU * i as f32 / seg as f32;
            m.pos.push([0.02 * s + f * len, y0 - r * ph.cos(), r * ph.sin()]);
        }
        for i in 0..=seg {
            m.uv.push([f, i as f32 / seg as f32]);
        }
    }
    for j in 0..rings - 1 {
        for i in 0..seg {
            let v = |j: usize, i: usize| (j * seg + i % seg) as u32;
            let t = |j: usize, i: usize| (j * (seg + 1) + i) as u32;
            m.faces.push(vec![v(j, i), v(j, i + 1), v(j + 1, i + 1), v(j + 1, i)]);
            m.face_uv.push(vec![t(j, i), t(j, i + 1), t(j + 1, i + 1), t(j + 1, i)]);
        }
    }
    m.pins = (0..seg as u32).map(|i| (i, 0)).collect();
    let r = 0.045 * s;
    let elbow = [0.3 * s, y0, 0.0];
    let (up_p, up_f) = limb([0.0, y0, 0.0], [1.0, 0.0, 0.0], 0.28 * s, r, (false, true));
    let (fo_p, fo_f) = limb([0.32 * s, y0, 0.0], [1.0, 0.0, 0.0], 0.3 * s, 0.9 * r, (true, false));
    let upper = Part {
        pos: up_p,
        faces: up_f,
        parent: None,
        pivot: [0.0, y0, 0.0],
        axis: [0.0, 0.0, 1.0],
        angle: Wave { offset: -0.25, amp: 0.35, freq: 0.35, phase: 0.0 }.scaled(v.motion, v.speed),
    };
    let fore = Part {
        pos: fo_p,
        faces: fo_f,
        parent: Some(0),
        pivot: elbow,
        axis: [0.0, 1.0, 0.0],
        angle: Wave { offset: 0.75, amp: 0.7, freq: 0.5, phase: -1.2 }.scaled(v.motion.min(1.15), v.speed),
    };
    let body = Body { parts: vec![upper, fore], yaw: Wave::ZERO, sway: Wave::ZERO, bob: Wave::ZERO };
    GarmentScene { mesh: m, body, wind: Wind::none(), ground: None, tethers: true }
}

/// The torso of the cape and the T-shirt: an elliptic drum from the hips to the shoulders.
fn torso(s: f32) -> Part {
    let (p, f) = tube([0.0, 0.85 * s, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0], 0.57 * s, 8, 24, |h| {
        // Narrower toward the neck.
        let k = if h > 0.45 * s { 1.0 - 0.35 * (h - 0.45 * s) / (0.12 * s) } else { 1.0 };
        (0.16 * s * k, 0.105 * s * k.max(0.8))
    });
    Part { pos: p, faces: f, parent: None, pivot: [0.0; 3], axis: [0.0, 1.0, 0.0], angle: Wave::ZERO }
}

/// A cape: a panel of triangles, narrow at the collar, wide and rounded at the hem, hanging
/// down the back from a collar that wraps the back of the neck; the torso turns and sways.
fn cape(v: &GarmentVariation) -> GarmentScene {
    let s = v.size;
    let (nx, ny) = (16, 18);
    let (sx, sy) = (0.9 * s * v.fullness, 0.75 * s);
    let top = 1.42 * s;
    // The pattern's rectangle bent into the cape: each row's width grows from 45 % at the
    // collar to 100 % at the hem, whose sides curve up; the collar curves forward around the
    // sides of the neck, and lower down the cape falls straight down the back.
    let place = |x: f32, y: f32| {
        let (w, f) = (2.0 * x / sx - 1.0, y / sy);
        let half = 0.5 * sx * (0.45 + 0.55 * f);
        let collar = (1.0 - f).powi(3);
        let lift = 0.12 * sy * w * w * f.powi(4);
        [w * half, top - f * sy + lift, -0.12 * s - 0.06 * s * f + 0.09 * s * collar * w * w]
    };
    // The hem's two corners cut off: no garment is a W×H grid.
    let keep = |i: usize, j: usize| !(j + 1 == ny && (i == 0 || i + 1 == nx));
    let (mut m, ij) = pattern((nx, ny), (sx, sy), keep, place, true);
    m.pins = ij.iter().enumerate().filter(|(_, (_, j))| *j == 0).map(|(k, _)| (k as u32, 0)).collect();
    let body = Body {
        parts: vec![torso(s)],
        yaw: Wave { offset: 0.0, amp: 0.8, freq: 0.35, phase: 0.0 }.scaled(v.motion, v.speed),
        sway: Wave { offset: 0.0, amp: 0.08, freq: 0.5, phase: 1.0 }.scaled(v.motion, v.speed),
        bob: Wave { offset: 0.0, amp: 0.015, freq: 1.6, phase: 0.0 }.scaled(v.motion, v.speed),
    };
    GarmentScene { mesh: m, body, wind: breeze([0.0, 0.0, -0.4 * v.wind]), ground: None, tethers: true }
}

/// A round tablecloth: a disk of triangles (rings of 6k vertices) dropped on a round table.
fn tablecloth(v: &GarmentVariation) -> GarmentScene {
    let s = v.size;
    let rings = 15;
    let radius = 0.8 * s;
    let table_r = 0.5 * s / v.fullness.max(0.5);
    let h = 0.75;
    let mut m = GarmentMesh::default();
    m.pos.push([0.0, h + 0.04, 0.0]);
    for k in 1..=rings {
        for i in 0..6 * k {
            let a = TAU * i as f32 / (6 * k) as f32;
            let r = radius * k as f32 / rings as f32;
            m.pos.push([r * a.cos(), h + 0.04, -r * a.sin()]);
        }
    }
    let start = |k: usize| if k == 0 { 0 } else { 1 + 3 * k * (k - 1) };
    let at = |k: usize, i: usize| (start(k) + if k == 0 { 0 } else { i % (6 * k) }) as u32;
    for k in 0..rings {
        // Ring k to ring k+1: each of the 6 sides has k inner and k+1 outer vertices.
        for side in 0..6 {
            for q in 0..=k {
                let (o, o1) = (at(k + 1, side * (k + 1) + q), at(k + 1, side * (k + 1) + q + 1));
                let i0 = at(k, side * k + q);
                m.faces.push(vec![i0, o, o1]);
                if q < k {
                    m.faces.push(vec![i0, o1, at(k, side * k + q + 1)]);
                }
            }
        }
    }
    m.uv = m.pos.iter().map(|p| [0.5 + 0.5 * p[0] / radius, 0.5 - 0.5 * p[2] / radius]).collect();
    m.face_uv = m.faces.clone();
    let (tp, tf) = tube([0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0], h, 2, 48, |_| (table_r, table_r));
    let table =
        Part { pos: tp, faces: tf, parent: None, pivot: [0.0; 3], axis: [0.0, 1.0, 0.0], angle: Wave::ZERO };
    let body = Body { parts: vec![table], yaw: Wave::ZERO, sway: Wave::ZERO, bob: Wave::ZERO };
    GarmentScene {
        mesh: m,
        body,
        wind: breeze([0.5 * v.wind, 0.0, 0.4 * v.wind]),
        ground: Some(0.0),
        tethers: false,
    }
}

/// A T-shirt: front and back T-shaped panels of quads, sewn along the sides, under the
/// sleeves, over the shoulders and the sleeve tops (the neck, the hem and the cuffs open), on
/// a torso whose arms (held out) lift and fall; the collar is pinned to the torso.
fn tshirt(v: &GarmentVariation) -> GarmentScene {
    let s = v.size;
    let (nx, ny) = (26, 16);
    let (sx, sy) = (1.04 * s, 0.64 * s);
    let (body_half, sleeve_h, neck) = (0.22 * s * v.fullness, 0.18 * s, 0.09 * s);
    let bottom = 0.84 * s;
    let cell = (sx / nx as f32, sy / ny as f32);
    let keep = |i: usize, j: usize| {
        let x = (i as f32 + 0.5) * cell.0 - 0.5 * sx;
        let y = (j as f32 + 0.5) * cell.1;
        x.abs() < body_half || y > sy - sleeve_h
    };
    let flat = |x: f32, y: f32| [x - 0.5 * sx, bottom + y, 0.0];
    let (panel, ij) = pattern((nx, ny), (sx, sy), keep, flat, false);
    // Which outline vertices are sewn: every border vertex but the neck, the hem and the cuffs.
    let on = |i: usize, j: usize| {
        let cells =
            [(i.wrapping_sub(1), j.wrapping_sub(1)), (i, j.wrapping_sub(1)), (i.wrapping_sub(1), j), (i, j)];
        cells.iter().filter(|&&(a, b)| a < nx && b < ny && keep(a, b)).count()
    };
    let open = |i: usize, j: usize| {
        let x = i as f32 * cell.0 - 0.5 * sx;
        (j == ny && x.abs() < neck) || j == 0 || i == 0 || i == nx
    };
    let n = panel.pos.len();
    let sewn: Vec<bool> = ij.iter().map(|&(i, j)| on(i, j) < 4 && !open(i, j)).collect();
    // Depth of each panel vertex off the seam plane: the distance to the nearest seam, capped at
    // the torso's half depth plus a gap (a pillow, round in the sleeves).
    let seams: Vec<[f32; 3]> = (0..n).filter(|&k| sewn[k]).map(|k| panel.pos[k]).collect();
    let depth: Vec<f32> = panel
        .pos
        .iter()
        .map(|p| {
            let d = seams.iter().map(|q| crate::geom::mesh::dist(*p, *q)).fold(f32::INFINITY, f32::min);
            (1.2 * d).min(0.13 * s)
        })
        .collect();
    let mut m = GarmentMesh::default();
    // Front: as cut; back: its own vertices except the sewn ones, faces wound the other way.
    let mut back = vec![0u32; n];
    for (k, p) in panel.pos.iter().enumerate() {
        m.pos.push([p[0], p[1], depth[k]]);
    }
    for k in 0..n {
        back[k] = if sewn[k] {
            k as u32
        } else {
            m.pos.push([panel.pos[k][0], panel.pos[k][1], -depth[k]]);
            (m.pos.len() - 1) as u32
        };
    }
    m.uv = panel.uv.iter().map(|t| [0.5 * t[0], t[1]]).collect();
    m.uv.extend(panel.uv.iter().map(|t| [0.5 + 0.5 * t[0], t[1]]));
    for f in &panel.faces {
        m.faces.push(f.clone());
        m.face_uv.push(f.clone());
    }
    for f in &panel.faces {
        m.faces.push(f.iter().rev().map(|&v| back[v as usize]).collect());
        m.face_uv.push(f.iter().rev().map(|&v| v + n as u32).collect());
    }
    // The collar: the neck opening's vertices, front and back.
    m.pins = (0..n)
        .filter(|&k| ij[k].1 == ny && open(ij[k].0, ij[k].1))
        .flat_map(|k| [(k as u32, 0), (back[k], 0)])
        .collect();
    m.pins.sort_unstable();
    m.pins.dedup();
    let arm = |side: f32| {
        let a = [side * 0.2 * s, bottom + sy - 0.5 * sleeve_h, 0.0];
        let (p, f) = limb(a, [side, 0.0, 0.0], 0.5 * s, 0.045 * s, (true, false));
        Part {
            pos: p,
            faces: f,
            parent: Some(0),
            pivot: [side * 0.18 * s, a[1], 0.0],
            axis: [0.0, 0.0, side],
            angle: Wave { offset: -0.25, amp: 0.3, freq: 0.4, phase: 0.5 * side }.scaled(v.motion, v.speed),
        }
    };
    let body = Body {
        parts: vec![torso(s), arm(1.0), arm(-1.0)],
        yaw: Wave { offset: 0.0, amp: 0.5, freq: 0.3, phase: 0.0 }.scaled(v.motion, v.speed),
        sway: Wave::ZERO,
        bob: Wave { offset: 0.0, amp: 0.01, freq: 1.5, phase: 0.0 }.scaled(v.motion, v.speed),
    };
    GarmentScene { mesh: m, body, wind: Wind::none(), ground: None, tethers: false }
}

/// A square sheet of triangles with a round hole off its centre, dropped flat on a ball.
fn holed_sheet(v: &GarmentVariation) -> GarmentScene {
    let s = v.size;
    let n = 24;
    let side = 1.2 * s;
    let (hx, hz, hr) = (0.62, 0.55, 0.13 * v.fullness);
    let keep = |i: usize, j: usize| {
        let (x, y) = ((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32);
        (x - hx).hypot(y - hz) > hr
    };
    let ball = 0.3 * s;
    let y0 = 2.0 * ball + 0.1 + 0.05;
    let (mut m, ij) = pattern((n, n), (side, side), keep, |x, y| [x - 0.5 * side, y0, 0.5 * side - y], true);
    // The hole's rim (inner vertices of fewer than four kept cells) moved out onto the circle,
    // so the hole is round, not a staircase of cells.
    for (k, &(i, j)) in ij.iter().enumerate() {
        let cells =
            [(i.wrapping_sub(1), j.wrapping_sub(1)), (i, j.wrapping_sub(1)), (i.wrapping_sub(1), j), (i, j)];
        let inner = i > 0 && j > 0 && i < n && j < n;
        if inner && cells.iter().filter(|&&(a, b)| keep(a, b)).count() < 4 {
            let (u, w) = (i as f32 / n as f32 - hx, j as f32 / n as f32 - hz);
            let r = u.hypot(w).max(1e-6);
            let (u, w) = (u * hr / r, w * hr / r);
            m.pos[k] = [(hx + u - 0.5) * side, y0, (0.5 - hz - w) * side];
            m.uv[k] = [hx + u, hz + w];
        }
    }
    let (bp, bf) = crate::cloth::mesh_collider::uv_sphere(
        crate::cloth::collision::Sphere { center: [0.0, 0.1 + ball, 0.0], radius: ball },
        32,
        16,
    );
    let ballp =
        Part { pos: bp, faces: bf, parent: None, pivot: [0.0; 3], axis: [0.0, 1.0, 0.0], angle: Wave::ZERO };
    let body = Body { parts: vec![ballp], yaw: Wave::ZERO, sway: Wave::ZERO, bob: Wave::ZERO };
    GarmentScene {
        mesh: m,
        body,
        wind: breeze([0.6 * v.wind, 0.0, 0.5 * v.wind]),
        ground: Some(0.0),
        tethers: false,
    }
}

impl GarmentSpec {
    /// The garment, its body and its breeze (seeded by `seed`) for this spec's variation.
    pub fn scene(&self) -> GarmentScene {
        let v = GarmentVariation::from_seed(self.vary);
        let mut g = match self.garment {
            Garment::Skirt => skirt(&v),
            Garment::Sleeve => sleeve(&v),
            Garment::Cape => cape(&v),
            Garment::Tablecloth => tablecloth(&v),
            Garment::Tshirt => tshirt(&v),
            Garment::HoledSheet => holed_sheet(&v),
        };
        // The breeze's gusts seeded by the spec's seed.
        if !g.wind.is_calm() {
            g.wind =
                Wind::gusty(g.wind.mean, 0.8 * crate::geom::vec3::norm(g.wind.mean).max(0.1), 4, self.seed);
        }
        g
    }

    fn material(&self) -> Material {
        GarmentVariation::from_seed(self.vary).material.unwrap_or(self.material)
    }
}

/// A simulated garment pair (or the LR run alone: `hr` empty).
pub struct GarmentRun {
    pub mesh: GarmentMesh,
    /// The HR mesh: the LR mesh subdivided once.
    pub sub: Subdivision,
    pub lr: Vec<Vec<[f32; 3]>>,
    pub hr: Vec<Vec<[f32; 3]>>,
    /// The body: its faces and its vertices frame by frame.
    pub body_faces: Vec<Vec<u32>>,
    pub body: Vec<Vec<[f32; 3]>>,
    pub material: Material,
}

/// The HR vertices of `sub` made of pinned LR vertices only, each with the part of its first.
fn hr_pins(sub: &Subdivision, pins: &[(u32, usize)], lr: usize) -> Vec<(u32, usize)> {
    let mut part = vec![usize::MAX; lr];
    pins.iter().for_each(|&(v, p)| part[v as usize] = p);
    sub.weights()
        .iter()
        .enumerate()
        .filter(|(_, w)| w.iter().all(|(v, _)| part[*v as usize] != usize::MAX))
        .map(|(k, w)| (k as u32, part[w[0].0 as usize]))
        .collect()
}

/// One run of `cloth` (rest `rest`, pins `pins` riding on the body's parts) over the spec's
/// frames; with `track`, held to those coarse targets (one per LR vertex) frame by frame.
#[allow(clippy::too_many_arguments)]
fn run_cloth(
    spec: &GarmentSpec,
    params: &SimParams,
    scene_of: &GarmentScene,
    rest: &[[f32; 3]],
    faces: &[Vec<u32>],
    pins: &[(u32, usize)],
    collider: &Arc<ColliderMesh>,
    track: Option<(&CoarseTrackOf, &[Vec<[f32; 3]>])>,
    progress: &mut dyn FnMut(usize),
) -> Result<Vec<Vec<[f32; 3]>>> {
    let material = spec.material();
    let pin_list: Vec<Pin> =
        pins.iter().map(|&(v, _)| Pin { vertex: v as usize, anchor: rest[v as usize], side: 0.0 }).collect();
    let mut cloth = Cloth::from_mesh(rest, faces, &|_| material, pin_list);
    if track.is_some() && spec.hr_jitter > 0.0 {
        cloth.jitter_free(spec.seed, spec.hr_jitter);
    }
    let mut p = params.clone();
    p.tethers = p.tethers && scene_of.tethers;
    let colliders = Colliders { ground: scene_of.ground, ..Default::default() };
    let mut scene = Scene {
        kinematics: Kinematics::Static,
        wind: scene_of.wind.clone(),
        colliders,
        meshes: vec![MeshCollider::new(collider.clone(), spec.thickness)],
    };
    let pin_at = |k: usize| -> Vec<[f32; 3]> {
        let poses = scene_of.body.poses(k as f32 * p.dt);
        pins.iter().map(|&(v, part)| poses[part].apply(rest[v as usize])).collect()
    };
    let coarse = track.map(|(ct, _)| CoarseTrack::new(ct.restriction.clone(), &cloth.inv_mass));
    let targets = |k: usize| -> Vec<[f32; 3]> {
        let (ct, lr) = track.expect("targets only when tracking");
        ct.restriction.apply(&ct.sub.apply(&lr[k]))
    };
    let mut out = vec![cloth.x.clone()];
    progress(0);
    let mut pin_from = pin_at(0);
    let mut from = track.map(|_| targets(0));
    for k in 1..spec.frames {
        for m in &mut scene.meshes {
            m.set_span(k - 1, k)?;
        }
        let pin_to = pin_at(k);
        let to = track.map(|_| targets(k));
        let tt = TrackTargets {
            from: from.as_deref().unwrap_or(&[]),
            to: to.as_deref().unwrap_or(&[]),
            strength: if track.is_some() { spec.tracking } else { 0.0 },
            damping: 0.0,
            coarse: coarse.as_ref(),
            pins: Some(PinPath { from: &pin_from, to: &pin_to }),
        };
        cloth.step(&p, &scene, Some(&tt));
        if cloth.x.iter().any(|x| x.iter().any(|c| !c.is_finite())) {
            return Err(Error::numeric(format!(
                "the {} simulation blew up (non-finite position) at frame {k}; try more substeps",
                spec.garment
            )));
        }
        out.push(cloth.x.clone());
        pin_from = pin_to;
        from = to;
        progress(k);
    }
    Ok(out)
}

/// What the HR run is held to: the restriction to the LR vertices of the subdivision.
struct CoarseTrackOf {
    sub: Subdivision,
    restriction: Restriction,
}

/// Simulate `spec`: the LR run, and with `pair` the HR run (the LR mesh subdivided once, twice
/// the substeps, held to the LR run at its vertices). `progress(k)` counts frames over both
/// runs (0 .. 2·frames with `pair`).
pub fn garment_run(spec: &GarmentSpec, pair: bool, progress: &mut dyn FnMut(usize)) -> Result<GarmentRun> {
    spec.validate()?;
    let scene = spec.scene();
    let m = &scene.mesh;
    let n = m.pos.len();
    // The garment must be a surface anisocb takes (a test of the presets, kept at run time).
    Surface::new(n, m.faces.clone(), Path::new(spec.garment.name()))?;
    let (body_faces, body) = scene.body.frames(spec.frames, spec.params.dt);
    let collider = Arc::new(ColliderMesh::new(format!("{} body", spec.garment), &body_faces, body.clone())?);
    let lr = run_cloth(spec, &spec.params, &scene, &m.pos, &m.faces, &m.pins, &collider, None, progress)?;
    let sub = Subdivision::of(n, &m.faces);
    let hr = if pair {
        let rest = sub.apply(&m.pos);
        let pins = hr_pins(&sub, &m.pins, n);
        let mut p = spec.params.clone();
        p.substeps *= 2;
        let ct = CoarseTrackOf { restriction: Restriction::of_subdivision(&sub, n), sub: sub.clone() };
        let frames = spec.frames;
        run_cloth(spec, &p, &scene, &rest, &sub.faces, &pins, &collider, Some((&ct, &lr)), &mut |k| {
            progress(frames + k)
        })?
    } else {
        Vec::new()
    };
    Ok(GarmentRun { mesh: scene.mesh, sub, lr, hr, body_faces, body, material: spec.material() })
}
