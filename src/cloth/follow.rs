//! The physics pass of `anisocb upscale --physics` (docs/research/wrinkles.md, "The physics pass"): an
//! HR cloth simulated alongside a shot it did not make, coarse-tracked to the nets' HR frames,
//! so the folds finer than the LR grid form as they would in an HR run of the same cloth.
//!
//! Why a simulation: the LR run does fix where the HR run's folds go — one frame after the HR
//! run is put back on the bare LR surface its folds are back (correlation 0.53–0.66 with the
//! original's, docs/research/wrinkles.md, "How much of the detail the LR run fixes") — but the nets do
//! not learn that map, even on their training runs (≤ 0.13). An HR cloth held to the LR
//! surface's coarse shape buckles where the real one did.
//!
//! What it knows: only the frames. The coarse constraint ([`super::tracking::Restriction`],
//! one XPBD constraint per LR node on the average of the HR vertices under its tent) holds
//! the shape the LR grid carries, frame by frame, blending linearly over the substeps; gravity,
//! the material, the frame rate and which edges the artist holds ([`PinnedEdges`]: those HR
//! vertices follow the shot's frames exactly) come from [`FollowParams`], and so do the
//! colliders the artist names (a floor, a sphere, a box, triangle meshes static or animated:
//! the output stays out of them); there is no wind, and a collider not named is not seen (the tracking and the drift correction keep
//! the cloth where the shot's cloth is; its folds may dip into it).
//!
//! Any mesh (issue 45, [`Follower::new_mesh`]): the same pass on the HR mesh of a mesh's linear
//! subdivision ([`Cloth::from_mesh`]), one coarse constraint per LR vertex on the HR vertices
//! its subdivision reaches ([`Restriction::of_subdivision`]), and `S` (the part of a frame the
//! LR shape holds) the linear subdivision of the frame's LR vertices instead of the round trip
//! through the LR grid.

use super::collision::{Colliders, Cuboid, Sphere};
pub use super::held_edges::PinnedEdges;
use super::kinematics::{Kinematics, Pin};
use super::mesh_collider::{ColliderMesh, MeshCollider, COLLIDER_THICKNESS, MAX_COLLIDER_THICKNESS};
use super::params::{Material, SimParams};
use super::scenarios::{Scenario, ScenarioSpec};
use super::solver::{Cloth, Scene};
use super::tracking::{CoarseTrack, PinPath, Restriction, TrackTargets};
use super::wind::Wind;
use crate::error::{Error, Result};
use crate::geom::geometry_image::{image_to_mesh, lr_round_trip, sequence_to_images};
use crate::geom::surface::{edge_key, Subdivision};
use crate::geom::Domain;
use crate::geom::GridMesh;
use crate::io::json::Value;
use crate::ops::resample::resize;
use crate::ops::Interp;
use std::sync::Arc;

/// What the physics pass simulates with; units are the shot's, taken as metres.
#[derive(Clone, Debug, PartialEq)]
pub struct FollowParams {
    /// Gravity in the shot's axes (m/s²): y-up OBJ `0,-9.81,0` (the default), a z-up scene
    /// `0,0,-9.81`.
    pub gravity: [f32; 3],
    /// Frames per second of the shot (the time between frames is `1/fps` s).
    pub fps: f32,
    /// The cloth's material: its bending stiffness sets the fold wavelength.
    pub material: Material,
    /// Coarse tracking strength (1/s²): the square of the attachment's angular frequency.
    pub strength: f32,
    /// XPBD substeps per second of shot time (at least 1 per frame). With one solver
    /// iteration per substep the cloth is stiffer against stretching the more substeps it
    /// takes: 600 (the default, what the training truth's HR runs take: 20 per 30 fps frame)
    /// was chosen on the seed-6 validation runs over 300 and 1200 (docs/research/wrinkles.md, "The
    /// physics pass").
    pub substeps_per_second: f32,
    /// Damping of the tracking as a fraction of critical. The default is none, as the
    /// training truth's HR runs track their LR runs: the cloth's coarse shape then swings
    /// about the shot as the truth's swings about its LR run, and the folds form where the
    /// truth's do (at 2000 1/s² on the seed-6 validation runs, mean correlation 0.369 at 0.1
    /// of critical, 0.380 at 0.3, 0.447 undamped; docs/research/wrinkles.md, "The physics pass"). An
    /// undamped attachment rings at √strength rad/s (7.1 Hz at 2000 1/s²) after a jolt, which
    /// a more damped solver's cloth does not: on the Blender sheet landing on a sphere, STED
    /// temporal 1.01× Catmull-Rom's undamped, 0.78× at 1 (critical; 0.81× in silk), the
    /// value for Blender shots chosen on the five Blender validation scenes (docs/research/wrinkles.md,
    /// "Blender shots").
    pub damping: f32,
    /// What the pass hands on.
    pub output: FollowOutput,
    /// `cloth` output only: the time constant (s) of the drift correction, an exponential
    /// moving average of how far the cloth's coarse shape (its Catmull-Rom round trip through
    /// the LR grid) lies from the shot's, added back to the cloth. It takes out the slow part
    /// of the lag (wind or a collider the pass does not know push the shot's cloth where the
    /// springs alone would not) and leaves out the frame-to-frame jitter of the nets' coarse
    /// shape, which the simulated cloth filters. `f32::INFINITY` turns it off, 0 corrects
    /// every frame in full. 3 s was chosen on the seed-6 validation runs (docs/research/wrinkles.md,
    /// "The physics pass", Output).
    pub drift_seconds: f32,
    /// The edges of the grid that follow the shot's frames exactly (the artist's pins).
    pub pins: PinnedEdges,
    /// A floor under the cloth (`--physics-ground`): its height (m) along −gravity, so
    /// `y = ground` in a y-up shot. No output vertex goes below it (the pass's cloth does not
    /// see the shot's colliders; without a floor its folds dipped up to 22 mm into the
    /// seed-6 drop's). `None`: no floor.
    pub ground: Option<f32>,
    /// A static sphere and an axis-aligned box in the shot (`--physics-sphere`,
    /// `--physics-box`; m, the shot's axes): the pass's cloth collides with them, and no output
    /// vertex is left inside them.
    pub sphere: Option<Sphere>,
    pub cuboid: Option<Cuboid>,
    /// Triangle-mesh colliders (`--collider`, [`super::mesh_collider`]): bodies the cloth lies
    /// on, static or animated (one frame per shot frame). The pass's cloth collides with them
    /// and no output vertex is left inside them. Loaded once and shared: cloning the
    /// parameters copies pointers, comparing them compares checksums.
    pub colliders: Vec<Arc<ColliderMesh>>,
    /// The gap (m) the cloth keeps from the mesh colliders (`--collider-thickness`).
    pub collider_thickness: f32,
    /// The LR vertices the shot's cloth is held by, of a mesh that is not a grid (0-based, in
    /// the mesh's order; `--physics-pin-vertices`): they and the HR vertices between them
    /// (edge midpoints and quad centres of pinned vertices only) follow the shot exactly. A
    /// grid names its held edges instead ([`FollowParams::pins`]).
    pub pin_vertices: Vec<u32>,
}

/// What [`Follower::step`] returns.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FollowOutput {
    /// The shot's frame plus the simulated cloth's detail finer than the LR grid,
    /// `target + (x − S(x))` with `S` the Catmull-Rom round trip through the LR grid
    /// ([`lr_round_trip`]): the shape stays the nets', the folds are the simulation's, and
    /// so does the nets' frame-to-frame jitter of their coarse shape (STED temporal up to
    /// 1.7× Catmull-Rom's on the validation twists).
    Detail,
    /// The simulated cloth itself, its slow coarse drift from the shot taken out
    /// ([`FollowParams::drift_seconds`]). The default: chosen over `Detail` on the seed-6
    /// validation runs (mean correlation 0.306 → 0.316, STED temporal below Catmull-Rom's on
    /// all six instead of four; docs/research/wrinkles.md, "The physics pass", Output).
    Cloth,
}

impl Default for FollowParams {
    fn default() -> Self {
        FollowParams {
            gravity: [0.0, -9.81, 0.0],
            fps: 30.0,
            material: Material::COTTON,
            strength: FOLLOW_STRENGTH,
            substeps_per_second: 600.0,
            damping: 0.0,
            output: FollowOutput::Cloth,
            drift_seconds: DRIFT_SECONDS,
            pins: PinnedEdges::default(),
            ground: None,
            sphere: None,
            cuboid: None,
            colliders: Vec::new(),
            collider_thickness: COLLIDER_THICKNESS,
            pin_vertices: Vec::new(),
        }
    }
}

/// Largest distance from the shot's origin, and largest size, in metres, that
/// [`FollowParams::validate`] accepts for a collider (the floor's height, the sphere's centre
/// and radius, the box's centre and half extents): 10 km is far beyond any cloth's scene; a
/// larger number is a slip or another unit, and would make the pass's arithmetic overflow.
pub const MAX_COLLIDER_METRES: f32 = 1e4;

impl FollowParams {
    /// The setting for cloth simulated by Blender (`upscale --preset blender`): silk, damped
    /// at critical, the rest the defaults. Chosen on the five Blender validation scenes
    /// (research/wrinkles/blender_setting.sh): damping 1 gave the lowest flicker against
    /// Catmull-Rom's (mean STED 0.895×, undamped 1.083×), silk at it the wrinkle ratio closest
    /// to 1 (0.51) with flicker below interpolation's (0.952×).
    pub fn blender_shot() -> FollowParams {
        FollowParams { material: Material::SILK, damping: 1.0, ..FollowParams::default() }
    }

    pub fn validate(&self) -> Result<()> {
        if !self.gravity.iter().all(|g| g.is_finite() && g.abs() <= 1000.0) {
            return Err(Error::invalid(
                "gravity",
                format!("must be three finite numbers of at most 1000 m/s² each, got {:?}", self.gravity),
            ));
        }
        if !(self.fps.is_finite() && (1.0..=1000.0).contains(&self.fps)) {
            return Err(Error::invalid(
                "fps",
                format!("must be 1 to 1000 frames per second, got {}", self.fps),
            ));
        }
        if !(self.strength.is_finite() && (1.0..=1e6).contains(&self.strength)) {
            return Err(Error::invalid(
                "strength",
                format!("the physics pass's tracking strength must be 1 to 1e6 1/s², got {}", self.strength),
            ));
        }
        if !(self.damping.is_finite() && (0.0..=100.0).contains(&self.damping)) {
            return Err(Error::invalid(
                "damping",
                format!("the physics pass's damping must be 0 to 100 (× critical), got {}", self.damping),
            ));
        }
        if let Some(g) = self.ground {
            if g.is_finite() && g.abs() > MAX_COLLIDER_METRES {
                return Err(Error::invalid(
                    "ground",
                    format!(
                        "the floor's height must be within ±{MAX_COLLIDER_METRES} m of the shot's \
                         origin, got {g}; give it in the shot's units (metres)"
                    ),
                ));
            }
            if !g.is_finite() || self.gravity.iter().all(|&c| c == 0.0) {
                return Err(Error::invalid(
                    "ground",
                    format!(
                        "the floor must be a finite height in metres and needs a gravity to say \
                     which way is down, got {g} with gravity {:?}",
                        self.gravity
                    ),
                ));
            }
        }
        let sphere_ok =
            |s: &Sphere| s.center.iter().all(|c| c.is_finite()) && s.radius.is_finite() && s.radius > 0.0;
        if !self.sphere.as_ref().is_none_or(sphere_ok) {
            return Err(Error::invalid(
                "sphere",
                format!(
                    "the sphere must be X,Y,Z,R in metres with a finite centre and R > 0, got {:?}",
                    self.sphere
                ),
            ));
        }
        let far = |v: &[f32]| v.iter().any(|x| x.is_finite() && x.abs() > MAX_COLLIDER_METRES);
        if let Some(s) = self.sphere.filter(|s| far(&s.center) || far(&[s.radius])) {
            return Err(Error::invalid(
                "sphere",
                format!(
                    "the sphere's centre and radius must be within ±{MAX_COLLIDER_METRES} m, got \
                     centre {:?} radius {}; give them in the shot's units (metres)",
                    s.center, s.radius
                ),
            ));
        }
        let box_ok = self.cuboid.is_none_or(|b| {
            b.center.iter().all(|c| c.is_finite()) && b.half.iter().all(|h| h.is_finite() && *h > 0.0)
        });
        if let Some(b) = self.cuboid.filter(|b| box_ok && (far(&b.center) || far(&b.half))) {
            return Err(Error::invalid(
                "cuboid",
                format!(
                    "the box's centre and half extents must be within ±{MAX_COLLIDER_METRES} m, got \
                     centre {:?} half extents {:?}; give them in the shot's units (metres)",
                    b.center, b.half
                ),
            ));
        }
        if !box_ok {
            return Err(Error::invalid(
                "cuboid",
                format!(
                    "the box must be X,Y,Z,HX,HY,HZ in metres (centre, half extents > 0), got {:?}",
                    self.cuboid
                ),
            ));
        }
        let t = self.collider_thickness;
        if !(t.is_finite() && t > 0.0 && t <= MAX_COLLIDER_THICKNESS) {
            return Err(Error::invalid(
                "collider_thickness",
                format!(
                    "the gap kept from mesh colliders must be above 0 and at most \
                     {MAX_COLLIDER_THICKNESS} m, got {t}; give it in metres (5 mm is 0.005)"
                ),
            ));
        }
        for m in &self.colliders {
            let (lo, hi) = m.bounds();
            if lo.iter().chain(&hi).any(|c| c.abs() > MAX_COLLIDER_METRES) {
                return Err(Error::invalid(
                    "colliders",
                    format!(
                        "{} reaches {lo:?} to {hi:?}, beyond ±{MAX_COLLIDER_METRES} m of the shot's \
                         origin; give it in the shot's units (metres)",
                        m.source().display()
                    ),
                ));
            }
        }
        if self.drift_seconds.is_nan() || self.drift_seconds < 0.0 {
            return Err(Error::invalid("drift_seconds", format!(
                "the drift correction's time constant must be a time in seconds ≥ 0 (inf turns the correction off), got {}",
                self.drift_seconds
            )));
        }
        if !(self.substeps_per_second.is_finite() && (1.0..=1e5).contains(&self.substeps_per_second)) {
            return Err(Error::invalid(
                "substeps_per_second",
                format!(
                    "the physics pass's substeps must be 1 to 1e5 per second, got {}",
                    self.substeps_per_second
                ),
            ));
        }
        Ok(())
    }

    /// Refuse an animated collider whose frame count is not the shot's `frames`, naming its
    /// folder and both counts.
    pub fn check_shot_frames(&self, frames: usize) -> Result<()> {
        if let Some(m) = self.colliders.iter().find(|m| m.is_animated() && m.frames() != frames) {
            return Err(Error::format(
                m.source(),
                format!(
                    "holds {} collider frames and the shot {frames}: an animated collider needs \
                     one OBJ frame per frame of the shot (a static one is a single OBJ file)",
                    m.frames()
                ),
            ));
        }
        Ok(())
    }

    /// What an artist knows of one of our simulator's runs (its `meta.json`): gravity, frame
    /// rate, the material (cotton where the run mixes materials) and the scenario's held
    /// edges; the rest the defaults. `eval --physics` and the physics study run with these.
    pub fn for_run(meta: &Value) -> FollowParams {
        let d = FollowParams::default();
        let num = |v: &Value| v.as_f64().map(|x| x as f32);
        let gravity = meta.get("gravity_m_per_s2").and_then(Value::as_array).and_then(|g| match g {
            [x, y, z] => Some([num(x)?, num(y)?, num(z)?]),
            _ => None,
        });
        let material = meta.get("material").and_then(|m| m.get("name")).and_then(Value::as_str);
        let scenario = meta.get("scenario").and_then(Value::as_str).and_then(|s| Scenario::from_name(s).ok());
        // The scene's colliders, rebuilt from the run's scenario, LR grid and variation seed
        // (the artist of the shot knows them; our scenes are y-up, so their ground is a floor).
        let lr = meta.get("lr_resolution").and_then(Value::as_array).and_then(|r| match r {
            [w, h] => Some((w.as_u64()? as usize, h.as_u64()? as usize)),
            _ => None,
        });
        let vary = meta.get("vary").and_then(Value::as_u64).unwrap_or(0);
        let obstacles = scenario.zip(lr).filter(|(_, (w, h))| *w >= 2 && *h >= 2).map(|(sc, (w, h))| {
            let mut spec = ScenarioSpec::new(sc);
            (spec.w, spec.h, spec.vary) = (w, h, vary);
            spec.setup(w, h).1.colliders
        });
        FollowParams {
            gravity: gravity.unwrap_or(d.gravity),
            // 1/dt to a thousandth of a frame: 1/0.033333335 s is the 30 fps it was.
            fps: meta
                .get("dt_s")
                .and_then(num)
                .filter(|dt| *dt > 0.0)
                .map_or(d.fps, |dt| (1e3 / dt).round() / 1e3),
            material: material.and_then(|m| Material::from_name(m).ok()).unwrap_or(d.material),
            pins: scenario.map_or(d.pins, Scenario::held_edges),
            ground: obstacles.and_then(|c| c.ground),
            sphere: obstacles.and_then(|c| c.sphere),
            cuboid: obstacles.and_then(|c| c.cuboid),
            ..d
        }
    }

    /// The solver's parameters: one frame of the shot per step; tethers only with pins (each
    /// free vertex no farther from its nearest pin than in the first frame, plus the slack: the
    /// first frame should be the cloth laid out or hanging, not crumpled). Tethers with the pins
    /// raised the mean correlation on the seed-6 validation runs with held edges from 0.253 to
    /// 0.290 (pins alone 0.255; docs/research/wrinkles.md, "The physics pass", Pins).
    pub fn sim_params(&self) -> SimParams {
        let substeps = ((self.substeps_per_second / self.fps).ceil() as usize).clamp(1, 1000);
        SimParams {
            dt: 1.0 / self.fps,
            substeps,
            gravity: self.gravity,
            tethers: !self.pins.is_empty(),
            ..SimParams::default()
        }
    }
}

/// Default tracking strength of the pass (1/s²), twice the training runs': chosen on the
/// seed-6 validation runs by the rule written before the runs (the highest mean correlation
/// of D with the truth's, vertex RMSE ≤ 1.1× Catmull-Rom's and, since the undamped pass,
/// STED temporal ≤ Catmull-Rom's on every run). Undamped, targets from the frame's LR-grid
/// resampling, the targets not raised: 1500 0.431 (the drop's STED 1.39× Catmull-Rom's: not
/// eligible), **2000 0.447**, 3000 0.392. Earlier, critically damped with raised targets:
/// 0.220 at 30 000, 0.269 at 10 000, 0.306 at 3000, 0.291 at 1000 (docs/research/wrinkles.md, "The
/// physics pass").
pub const FOLLOW_STRENGTH: f32 = 2_000.0;

/// Default time constant (s) of the `cloth` output's drift correction
/// ([`FollowParams::drift_seconds`]): on the seed-6 validation runs a longer one kept more of
/// the cloth's own coarse motion (mean correlation 0.311 at 0.3 s, 0.313 at 0.65 s, 0.314 at
/// 1.1 s, 0.317 at 3.3 s; 0.318 with none, but then the flag's vertex RMSE is 1.13×
/// Catmull-Rom's, over the rule's 1.1×).
pub const DRIFT_SECONDS: f32 = 3.0;

/// Shot time (s) the pass holds the first frame still before the shot starts. With the
/// attachment undamped, 1 s left the hem's slow sway in the start: a still sheet gained
/// 0.79 mm RMS of detail, 0.45 mm with the settle critically damped, 0.18 mm over 2 s
/// (`tests/physics_pass.rs`). The validation runs' mean correlation was 0.447 at 1 s and is
/// 0.423 at 2 s, the difference the chaotic drops' (drop 0.24 → 0.15, drop-table 0.45 →
/// 0.33; the other four 2.00 → 2.06 in sum): the still sheet decided.
pub const SETTLE_SECONDS: f32 = 2.0;

/// The LR shape a cloth is tracked at: a grid, or any mesh (issue 45). It says what `S` (the
/// part of an HR frame the LR shape can hold) and the coarse targets are.
enum Coarse {
    /// An LR grid of (columns, rows) under an HR grid of (columns, rows): `S` is the
    /// Catmull-Rom round trip through the LR grid ([`lr_round_trip`]).
    Grid { lr: (usize, usize), hr: (usize, usize) },
    /// A mesh's linear subdivision ([`Restriction::of_subdivision`]'s tents): `S(x)` is the
    /// subdivision of `x`'s LR vertices (HR vertices `0..lr`), and `taper` is each HR
    /// vertex's share of the detail in `detail` output (0 on the mesh's border, ½ one edge in).
    Mesh { sub: Subdivision, lr: usize, taper: Vec<f32> },
}

impl Coarse {
    /// `S(x)`: the part of the HR positions `x` the LR shape holds.
    fn smooth(&self, x: &[[f32; 3]]) -> Vec<[f32; 3]> {
        match self {
            Coarse::Grid { lr, hr } => lr_round_trip(&GridMesh::new(hr.0, hr.1, x.to_vec()), lr.0, lr.1).pos,
            Coarse::Mesh { sub, lr, .. } => sub.apply(&x[..*lr]),
        }
    }

    /// How much of the simulated detail HR vertex `v` takes in `detail` output.
    fn taper(&self, v: usize) -> f32 {
        match self {
            Coarse::Grid { hr: (w, h), .. } => border_taper(v % w, v / w, *w, *h),
            Coarse::Mesh { taper, .. } => taper[v],
        }
    }
}
/// The physics pass's state over one shot: the HR cloth and the last frame's coarse targets.
pub struct Follower {
    cloth: Cloth,
    scene: Scene,
    sim: SimParams,
    strength: f32,
    damping: f32,
    track: CoarseTrack,
    /// Coarse targets (one per LR node, m) of the last frame given.
    from: Vec<[f32; 3]>,
    /// The part finer than the LR grid of each vertex's offset from the first frame at the end
    /// of [`Follower::settle`] (m).
    rest_sag: Vec<[f32; 3]>,
    /// Where the pins were at the end of the last frame (m), in the cloth's pin order.
    pin_from: Vec<[f32; 3]>,
    /// What "the part the LR shape holds" is for this cloth.
    shape: Coarse,
    /// The cloth's triangles, for the faces' contacts with mesh colliders.
    tris: Vec<[usize; 3]>,
    /// The floor ([`FollowParams::ground`]) as (unit up, height).
    floor: Option<([f32; 3], f32)>,
    /// The shot frame the cloth is at (the mesh colliders' pose).
    frame: usize,
    output: FollowOutput,
    /// `cloth` output: the weight of the last frame in the drift correction's moving average,
    /// `exp(−1/(fps·drift_seconds))` (1 = off).
    drift_keep: f32,
    /// The moving average of `S(shot) − S(cloth)` (m, one per HR vertex; empty before the
    /// first frame).
    drift: Vec<[f32; 3]>,
}

impl Follower {
    /// A cloth whose rest shape is `first` (the shot's first HR frame: flat or relaxed cloth,
    /// `scale·w × scale·h` vertices for an LR grid of `lr` = (w, h)), at rest there.
    pub fn new(first: &GridMesh, lr: (usize, usize), p: &FollowParams) -> Result<Follower> {
        p.validate()?;
        if lr.0 < 2 || lr.1 < 2 || first.w < lr.0 || first.h < lr.1 {
            return Err(Error::shape(format!(
                "the physics pass needs an HR grid at least as large as the LR grid (≥ 2×2), got HR \
                 {}×{} for LR {}×{}",
                first.w, first.h, lr.0, lr.1
            )));
        }
        if !p.pin_vertices.is_empty() {
            return Err(Error::invalid(
                "pin_vertices",
                "a grid is held by its edges (top, left, …), not by a vertex list; a vertex list is \
                 for a mesh that is not a grid",
            ));
        }
        check_frame(&first.pos, 0)?;
        let material = p.material;
        let pins = p.pins.vertices(first.w, first.h);
        let pin_from: Vec<[f32; 3]> = pins.iter().map(|&v| first.pos[v]).collect();
        let pins = pins.iter().map(|&v| Pin { vertex: v, anchor: first.pos[v], side: 0.0 }).collect();
        let cloth = Cloth::new(first, &|_| material, pins);
        let track = CoarseTrack::new(Restriction::new(lr.0, lr.1, first.w, first.h), &cloth.inv_mass);
        let shape = Coarse::Grid { lr, hr: (first.w, first.h) };
        Follower::start(cloth, track, shape, pin_from, &first.pos, p)
    }

    /// A cloth of any mesh (issue 45): the HR mesh of `sub` (the linear subdivision of an LR
    /// mesh of `lr` vertices) whose rest shape is `first` (the shot's first HR frame), at rest
    /// there; coarse-tracked with one constraint per LR vertex ([`Restriction::of_subdivision`]),
    /// `S` the linear subdivision of a frame's LR vertices. Its pins are
    /// [`FollowParams::pin_vertices`]; held grid edges are refused (a mesh has no sides to name).
    pub fn new_mesh(first: &[[f32; 3]], sub: Subdivision, lr: usize, p: &FollowParams) -> Result<Follower> {
        p.validate()?;
        if !p.pins.is_empty() {
            return Err(Error::invalid(
                "pins",
                "held grid edges (top, left, …) name a grid's sides; a mesh that is not a grid has \
                 none: leave them out",
            ));
        }
        if first.len() != sub.hr_vertices() || lr > first.len() {
            return Err(Error::shape(format!(
                "the physics pass's mesh has {} HR vertices, the frame {}",
                sub.hr_vertices(),
                first.len()
            )));
        }
        check_frame(first, 0)?;
        if let Some(&v) = p.pin_vertices.iter().find(|&&v| v as usize >= lr) {
            return Err(Error::invalid(
                "pin_vertices",
                format!("vertex {} is held, but the mesh has {lr} vertices (numbered from 1)", v + 1),
            ));
        }
        // The held LR vertices and every HR vertex made of held ones only.
        let mut held = vec![false; lr];
        p.pin_vertices.iter().for_each(|&v| held[v as usize] = true);
        let pins: Vec<usize> = sub
            .weights()
            .iter()
            .enumerate()
            .filter(|(_, w)| !p.pin_vertices.is_empty() && w.iter().all(|(v, _)| held[*v as usize]))
            .map(|(k, _)| k)
            .collect();
        let pin_from: Vec<[f32; 3]> = pins.iter().map(|&v| first[v]).collect();
        let pins = pins.iter().map(|&v| Pin { vertex: v, anchor: first[v], side: 0.0 }).collect();
        let material = p.material;
        let cloth = Cloth::from_mesh(first, &sub.faces, &|_| material, pins);
        let track = CoarseTrack::new(Restriction::of_subdivision(&sub, lr), &cloth.inv_mass);
        let taper = mesh_border_taper(&sub.faces, first.len());
        Follower::start(cloth, track, Coarse::Mesh { sub, lr, taper }, pin_from, first, p)
    }

    /// The pass on `cloth` (tracked by `track` at `shape`), settled on the first frame `first`.
    fn start(
        cloth: Cloth,
        track: CoarseTrack,
        shape: Coarse,
        pin_from: Vec<[f32; 3]>,
        first: &[[f32; 3]],
        p: &FollowParams,
    ) -> Result<Follower> {
        let colliders = Colliders { sphere: p.sphere, cuboid: p.cuboid, ground: None };
        let meshes = p.colliders.iter().map(|m| MeshCollider::new(m.clone(), p.collider_thickness)).collect();
        let scene = Scene { kinematics: Kinematics::Static, wind: Wind::none(), colliders, meshes };
        let tris = cloth.triangles();
        let mut f = Follower {
            cloth,
            scene,
            sim: p.sim_params(),
            strength: p.strength,
            damping: p.damping,
            track,
            from: Vec::new(),
            rest_sag: Vec::new(),
            pin_from,
            tris,
            shape,
            output: p.output,
            drift_keep: (-1.0 / (p.fps * p.drift_seconds)).exp(),
            floor: p.ground.map(|h| {
                let n = p.gravity.iter().map(|g| g * g).sum::<f32>().sqrt();
                (p.gravity.map(|g| -g / n), h)
            }),
            drift: Vec::new(),
            frame: 0,
        };
        // A first frame that dips into a mesh collider starts outside it.
        f.push_cloth_out();
        f.settle(first);
        f.push_cloth_out();
        f.from = f.targets(first);
        Ok(f)
    }

    /// Settle the cloth on the shot's first frame: the pass holds that frame still for
    /// [`SETTLE_SECONDS`], the attachment at least critically damped, and the shot starts from
    /// the cloth's mean shape over the second half, at rest. Started from the first frame
    /// itself, the hem's fine modes, which nothing but the material damps, swung for seconds
    /// (a still sheet gained 1.2 mm RMS of detail).
    /// It also keeps where each vertex hangs then on average (`rest_sag`, its part finer than
    /// the LR grid): the scallops of a border carried by springs instead of by whatever holds
    /// the shot's cloth, which [`Follower::step`] takes off its output.
    ///
    /// The cloth hangs below its targets on its springs (≈ half of g/strength: the
    /// overlapping tents make them stiffer than one node's alone), as the training truth's HR
    /// runs hang below their LR runs; the targets are not raised to carry that weight. At the
    /// earlier defaults (3000 1/s², critically damped) not raising them took the seed-6
    /// validation runs' mean correlation from 0.356 to 0.386 (drop-table 0.37 → 0.42, drape
    /// 0.50 → 0.55), but on its own it put the held-out flag's vertex error at 1.30×
    /// Catmull-Rom's; with the attachment undamped and the LR-grid targets it is 0.94×
    /// (docs/research/wrinkles.md, "The physics pass"). `cloth` output's drift correction takes the sag
    /// out of the output from the first frame.
    fn settle(&mut self, first: &[[f32; 3]]) {
        let (time, t) = (self.cloth.time, self.targets(first));
        let frames = (SETTLE_SECONDS * self.sim.dt.recip()).ceil().max(2.0) as usize;
        let n = (frames - frames.div_ceil(2)) as f32;
        let mut mean = vec![[0.0f32; 3]; first.len()];
        for k in 0..frames {
            let tt = TrackTargets {
                from: &t,
                to: &t,
                strength: self.strength,
                damping: self.damping.max(1.0),
                coarse: Some(&self.track),
                pins: None,
            };
            self.cloth.step(&self.sim, &self.scene, Some(&tt));
            if 2 * k >= frames {
                for (m, x) in mean.iter_mut().zip(&self.cloth.x) {
                    (0..3).for_each(|i| m[i] += x[i] / n);
                }
            }
        }
        // The part finer than the LR shape: the coarse sag stays in the cloth.
        let d: Vec<[f32; 3]> =
            mean.iter().zip(first).map(|(x, f)| std::array::from_fn(|c| x[c] - f[c])).collect();
        let coarse = self.shape.smooth(&d);
        self.rest_sag = d.iter().zip(&coarse).map(|(a, b)| std::array::from_fn(|c| a[c] - b[c])).collect();
        let c = &mut self.cloth;
        for (v, (x, m)) in c.x.iter_mut().zip(&mean).enumerate() {
            if c.inv_mass[v] > 0.0 {
                *x = *m;
            }
        }
        c.v.iter_mut().for_each(|v| *v = [0.0; 3]);
        c.time = time;
    }

    /// The coarse targets of an HR frame (one per LR node, m), made as the training truth's
    /// HR runs make theirs from their LR frames ([`Restriction::targets`]: the tent averages of
    /// the LR grid's bilinear surface): the frame resampled to the LR grid (Catmull-Rom, the
    /// metric's `S` halfway) stands for the LR frame. The tent averages of the frame itself,
    /// a smooth surface where the truth's targets come from a faceted one, lie a curvature's
    /// worth apart from those, and the folds form elsewhere: on the seed-6 validation runs
    /// the mean correlation was 0.427 that way, 0.447 this way (drape 0.61 → 0.69; with the
    /// true LR frames 0.456; docs/research/wrinkles.md, "The physics pass").
    /// On a mesh, the tent averages of its LR vertices' subdivision.
    fn targets(&self, frame: &[[f32; 3]]) -> Vec<[f32; 3]> {
        match &self.shape {
            Coarse::Grid { lr, hr } => {
                let frame = GridMesh::new(hr.0, hr.1, frame.to_vec());
                let img = sequence_to_images(std::slice::from_ref(&frame), &Domain::UNIT);
                // The simulator's own resampling, not a net op: the CPU function, not the op table.
                let lr = resize(&img, lr.1, lr.0, Interp::CatmullRom);
                self.track.restriction.targets(&image_to_mesh(&lr, 0, &Domain::UNIT))
            }
            Coarse::Mesh { .. } => self.track.restriction.apply(&self.shape.smooth(frame)),
        }
    }

    /// The pass over a whole shot in memory (HR frames in shot order, LR grid `lr`): the first
    /// frame as it is, then [`Follower::step`] toward each later one.
    pub fn run(frames: &[GridMesh], lr: (usize, usize), p: &FollowParams) -> Result<Vec<GridMesh>> {
        let Some(first) = frames.first() else { return Ok(Vec::new()) };
        let mut f = Follower::new(first, lr, p)?;
        let mut out = vec![first.clone()];
        for (k, t) in frames.iter().enumerate().skip(1) {
            out.push(f.step(t, k)?);
        }
        Ok(out)
    }

    /// Simulate one frame toward `target` (the next HR frame of the shot, same grid as the
    /// first) and return the cloth there; `k` is the frame's number in the shot: animated mesh
    /// colliders move from their frame of the last step to their frame `k` over its substeps
    /// (an error naming the collider when it has no frame `k`), and errors name it.
    pub fn step(&mut self, target: &GridMesh, k: usize) -> Result<GridMesh> {
        if (target.w, target.h) != (self.cloth.w, self.cloth.h) {
            return Err(Error::shape(format!(
                "frame {k} is a {}×{} grid, the physics pass's cloth {}×{}",
                target.w, target.h, self.cloth.w, self.cloth.h
            )));
        }
        Ok(GridMesh::new(target.w, target.h, self.step_to(&target.pos, k)?))
    }

    /// [`Follower::step`] for a cloth of any mesh ([`Follower::new_mesh`]): `target` holds the
    /// next HR frame's vertices.
    pub fn step_mesh(&mut self, target: &[[f32; 3]], k: usize) -> Result<Vec<[f32; 3]>> {
        if target.len() != self.cloth.x.len() {
            return Err(Error::shape(format!(
                "frame {k} has {} HR vertices, the physics pass's cloth {}",
                target.len(),
                self.cloth.x.len()
            )));
        }
        self.step_to(target, k)
    }

    /// One frame toward `target` (as many positions as the cloth), the output positions.
    fn step_to(&mut self, target: &[[f32; 3]], k: usize) -> Result<Vec<[f32; 3]>> {
        check_frame(target, k)?;
        for m in &mut self.scene.meshes {
            m.set_span(self.frame, k)?;
        }
        let to = self.targets(target);
        let pin_to: Vec<[f32; 3]> = self.cloth.pins.iter().map(|p| target[p.vertex]).collect();
        let tt = TrackTargets {
            from: &self.from,
            to: &to,
            strength: self.strength,
            damping: self.damping,
            coarse: Some(&self.track),
            pins: Some(PinPath { from: &self.pin_from, to: &pin_to }),
        };
        self.cloth.step(&self.sim, &self.scene, Some(&tt));
        self.frame = k;
        self.push_cloth_out();
        self.from = to;
        self.pin_from = pin_to;
        let mut out: Vec<[f32; 3]> = self
            .cloth
            .x
            .iter()
            .zip(&self.rest_sag)
            .map(|(x, s)| std::array::from_fn(|c| x[c] - s[c]))
            .collect();
        match self.output {
            FollowOutput::Detail => {
                let s = self.shape.smooth(&out);
                for (v, ((o, t), s)) in out.iter_mut().zip(target).zip(&s).enumerate() {
                    let k = self.shape.taper(v);
                    *o = std::array::from_fn(|c| t[c] + k * (o[c] - s[c]));
                }
            }
            FollowOutput::Cloth if self.drift_keep < 1.0 => self.correct_drift(&mut out, target),
            FollowOutput::Cloth => {}
        }
        // Out of the colliders (the drift correction and the rest sag may carry it in), onto
        // their surfaces: `prev = out` leaves friction nothing to do.
        let c = &self.scene.colliders;
        if c.sphere.is_some() || c.cuboid.is_some() {
            let (before, free) = (out.clone(), vec![1.0; out.len()]);
            c.project(&mut out, &before, &free, 0.0, 0.0);
        }
        // Back across any mesh surface the way from the cloth (outside) enters, and out.
        for m in &self.scene.meshes {
            m.push_out(&mut out, Some(&self.cloth.x), None);
            m.push_faces_out(&mut out, &self.tris, None);
        }
        if let Some((up, h)) = self.floor {
            for o in &mut out {
                let below = h - (0..3).map(|c| o[c] * up[c]).sum::<f32>();
                if below > 0.0 {
                    (0..3).for_each(|c| o[c] += below * up[c]);
                }
            }
        }
        // Pinned vertices are the shot's (the rest sag and the detail are the free cloth's).
        for pin in &self.cloth.pins {
            out[pin.vertex] = target[pin.vertex];
        }
        if out.iter().flatten().any(|c| !c.is_finite()) {
            return Err(Error::numeric(format!(
                "the physics pass blew up at frame {k} (non-finite position): is the shot in metres \
                 and --fps its frame rate?"
            )));
        }
        Ok(out)
    }
}

impl Follower {
    /// Take the cloth's free vertices out of the mesh colliders at the current frame (a closed
    /// one's inside at any depth), once a frame: the substeps' contacts look only a few
    /// thicknesses from each vertex.
    fn push_cloth_out(&mut self) {
        let c = &mut self.cloth;
        for m in &self.scene.meshes {
            m.push_out(&mut c.x, None, Some(&c.inv_mass));
            m.push_faces_out(&mut c.x, &self.tris, Some(&c.inv_mass));
        }
    }

    /// `cloth` output: move `out` (the cloth) by the moving average of how far its coarse shape
    /// lies from the shot's, `drift ← keep·drift + (1 − keep)·(S(target) − S(out))`, the
    /// first frame's offset taken as it is.
    fn correct_drift(&mut self, out: &mut [[f32; 3]], target: &[[f32; 3]]) {
        let (st, so) = (self.shape.smooth(target), self.shape.smooth(out));
        let now = st.iter().zip(&so).map(|(t, o)| std::array::from_fn(|c| t[c] - o[c]));
        if self.drift.is_empty() {
            self.drift = now.collect();
        } else {
            let k = self.drift_keep;
            for (d, n) in self.drift.iter_mut().zip(now) {
                *d = std::array::from_fn(|c| k * d[c] + (1.0 - k) * n[c]);
            }
        }
        for (o, d) in out.iter_mut().zip(&self.drift) {
            (0..3).for_each(|c| o[c] += d[c]);
        }
    }
}

/// How much of the simulated detail vertex (i, j) of a `w × h` grid takes in `detail` output:
/// none on the border ring, half on the next, all inside. The simulated hem, held by fewer
/// coarse constraints than the inside, crumples in its own plane: with all of it the border
/// came out 2.5–6 % longer than the truth's on the seed-6 drops and twists (the nets' within
/// 2 %); the shot's border is the nets' (docs/research/wrinkles.md, "The physics pass").
fn border_taper(i: usize, j: usize, w: usize, h: usize) -> f32 {
    match i.min(j).min(w - 1 - i).min(h - 1 - j) {
        0 => 0.0,
        1 => 0.5,
        _ => 1.0,
    }
}

fn check_frame(x: &[[f32; 3]], k: usize) -> Result<()> {
    if x.iter().flatten().any(|c| !c.is_finite()) {
        return Err(Error::numeric(format!(
            "frame {k} has a non-finite position; the physics pass needs finite frames"
        )));
    }
    Ok(())
}

/// Per vertex of the mesh `faces` (`n` vertices): 0 on its border (a vertex of an edge in one
/// face), ½ one edge in, 1 further in: [`border_taper`] on any mesh.
fn mesh_border_taper(faces: &[Vec<u32>], n: usize) -> Vec<f32> {
    let mut count: std::collections::HashMap<(u32, u32), u32> = std::collections::HashMap::new();
    for f in faces {
        for i in 0..f.len() {
            *count.entry(edge_key(f[i], f[(i + 1) % f.len()])).or_default() += 1;
        }
    }
    let mut ring = vec![2u8; n];
    for (&(a, b), &c) in &count {
        if c == 1 {
            ring[a as usize] = 0;
            ring[b as usize] = 0;
        }
    }
    // One edge in from the border (the border is final before this pass: order-free).
    for &(a, b) in count.keys() {
        let (ra, rb) = (ring[a as usize], ring[b as usize]);
        if ra == 0 && rb != 0 {
            ring[b as usize] = 1;
        }
        if rb == 0 && ra != 0 {
            ring[a as usize] = 1;
        }
    }
    ring.into_iter().map(|r| [0.0, 0.5, 1.0][r as usize]).collect()
}
