//! The paper's scenarios (figures 8–13) and a free sheet dropped on a sphere (`drop`) as named
//! presets, and the functions that run them at one resolution ([`run_single`]) or as a
//! low/high-resolution pair ([`paired_run`]).
//!
//! The rest rectangle of a scenario is fixed by the spec's (low) resolution: width from the
//! scenario, height = width · (h − 1)/(w − 1) so LR cells are square. The HR run uses the same
//! rectangle with `scale·w × scale·h` vertices (corners aligned).

use super::collision::{Colliders, Cuboid, Sphere};
use super::follow::PinnedEdges;
use super::kinematics::{Kinematics, Pin};
use super::params::{Material, SimParams};
use super::solver::{Cloth, Scene};
use super::tracking::{bilinear_targets, CoarseTrack, Restriction, TrackTargets, TrackingMode};
use super::wind::Wind;
use crate::error::{Error, Result};
use crate::geom::mesh::{rest_uv, GridMesh};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Scenario {
    Flag,
    FlagSphere,
    Drape,
    Twist,
    TwistMaterials,
    TwistZeroG,
    Drop,
    DropTable,
}

/// `--help` text listing the scenarios.
pub const SCENARIO_HELP: &str = "Scenarios (paper figures):
  flag             flag, top edge pinned and flapping back and forth in gusty wind (Fig 8)
  flag-sphere      the same flag swinging into a sphere behind it (Fig 9)
  drape            square sheet held at 4 corners, lowered and pulled in over a sphere (Fig 10)
  twist            horizontal strip twisted from both ends in opposite directions (Fig 11)
  twist-materials  the same strip made of three bands: silk, rubber, denim (Fig 12)
  twist-zero-g     the twist without gravity (Fig 13)
  drop             free square sheet dropped flat on a sphere; its hem falls into folds (not in the paper)
  drop-table       free square sheet dropped on a table (a box); its hem hangs down the sides and folds at the corners (not in the paper)";

impl Scenario {
    pub const ALL: [Scenario; 8] = [
        Scenario::Flag,
        Scenario::FlagSphere,
        Scenario::Drape,
        Scenario::Twist,
        Scenario::TwistMaterials,
        Scenario::TwistZeroG,
        Scenario::Drop,
        Scenario::DropTable,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Scenario::Flag => "flag",
            Scenario::FlagSphere => "flag-sphere",
            Scenario::Drape => "drape",
            Scenario::Twist => "twist",
            Scenario::TwistMaterials => "twist-materials",
            Scenario::TwistZeroG => "twist-zero-g",
            Scenario::Drop => "drop",
            Scenario::DropTable => "drop-table",
        }
    }

    pub fn from_name(name: &str) -> Result<Scenario> {
        Scenario::ALL.iter().copied().find(|s| s.name() == name).ok_or_else(|| {
            let names: Vec<&str> = Scenario::ALL
                .iter()
                .map(|s| s.name())
                .chain(super::garments::Garment::ALL.iter().map(|g| g.name()))
                .collect();
            Error::config(format!("unknown scenario '{name}'; choose one of: {}", names.join(", ")))
        })
    }

    /// The edges of the grid the scenario holds its cloth by, as an artist names them to
    /// `upscale --physics-pin` (the vertices [`ScenarioSpec::setup`] pins; a test checks it).
    pub fn held_edges(self) -> PinnedEdges {
        let mut e = PinnedEdges::default();
        match self {
            Scenario::Flag | Scenario::FlagSphere => e.top = true,
            Scenario::Drape => e.corners = true,
            Scenario::Twist | Scenario::TwistMaterials | Scenario::TwistZeroG => {
                (e.left, e.right) = (true, true)
            }
            Scenario::Drop | Scenario::DropTable => {}
        }
        e
    }

    pub fn description(self) -> &'static str {
        SCENARIO_HELP
            .lines()
            .find(|l| l.split_whitespace().next() == Some(self.name()))
            .map(|l| l.trim_start()[self.name().len()..].trim())
            .unwrap_or("")
    }

    /// Default LR resolution (vertices, columns × rows), as in the paper.
    pub fn default_resolution(self) -> (usize, usize) {
        match self {
            Scenario::Flag
            | Scenario::FlagSphere
            | Scenario::Drape
            | Scenario::Drop
            | Scenario::DropTable => (32, 32),
            _ => (32, 10),
        }
    }

    /// Width of the rest rectangle (m).
    fn width(self) -> f32 {
        match self {
            Scenario::Flag | Scenario::FlagSphere => 1.0,
            Scenario::Drape | Scenario::Drop | Scenario::DropTable => 1.4,
            _ => 2.0,
        }
    }
}

impl std::fmt::Display for Scenario {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// One run (or pair of runs) to simulate.
#[derive(Clone, Debug, PartialEq)]
pub struct ScenarioSpec {
    pub scenario: Scenario,
    /// Low-resolution grid (vertices: columns × rows).
    pub w: usize,
    pub h: usize,
    /// Number of output frames; frame 0 is the rest state, frame k is at time k·dt.
    pub frames: usize,
    /// Seeds the wind gusts.
    pub seed: u64,
    /// Cloth material (`twist-materials` ignores it and uses its bands).
    pub material: Material,
    /// HR → LR attachment strength (1/s²) in paired runs; 0 = off.
    pub tracking: f32,
    /// What the attachment holds: the LR-scale averages (default) or every HR vertex.
    pub tracking_mode: TrackingMode,
    /// Upscale factor of the HR run (vertices per side).
    pub scale: usize,
    /// Seed of a randomised variant of the scene ([`Variation`]); 0 = the scenario as given.
    pub vary: u64,
    /// Metres of seeded noise (uniform in ±`hr_jitter` per coordinate, seed `seed`) added to
    /// the tracked HR run's free vertices at rest; 0 = none. Two runs that differ only in it
    /// are twins of one HR truth under the same LR run: how far their detail agrees is how much
    /// of it the LR run fixes (docs/research/wrinkles.md, "How much of the detail the LR run fixes").
    pub hr_jitter: f32,
    /// Frame at which the tracked HR run forgets its own history: its free vertices are put on
    /// the LR run's bilinear surface, moving with the LR run's velocity, and the folds form
    /// again from there; 0 = never. Compared with the run that kept its history, it says how
    /// long a window of LR frames fixes the HR detail (docs/research/wrinkles.md).
    pub hr_restart: usize,
    /// The tracked HR run knows only its LR run, as a physics upscaler of someone else's cloth
    /// would: no colliders, no wind, started on the LR run's surface (a restart at frame 1);
    /// gravity, material and pins stay the scenario's. A study of what such an upscaler could
    /// reach (docs/research/wrinkles.md), not training data.
    pub hr_blind: bool,
    pub params: SimParams,
}

/// A seeded variant of a scenario, so a model learns cloth rather than six clips: cloth size,
/// material, wind, flapping, obstacle size and place, drape and twist speeds. Seed 0 is the
/// identity (every factor 1, every offset 0, the spec's material).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Variation {
    /// Cloth width factor (rest rectangle; the LR cells stay square).
    pub width: f32,
    /// Mean wind and gust strength factor.
    pub wind: f32,
    /// Flap amplitude factor (flag scenarios) and frequency factor.
    pub flap: f32,
    pub flap_freq: f32,
    /// Obstacle size factor (sphere radius; table top side, `drop-table`) and centre offset
    /// (metres, x and z; halved for the table).
    pub sphere_radius: f32,
    pub sphere_offset: [f32; 2],
    /// Drape: inward squeeze (fraction, default 0.3) and drop factor.
    pub squeeze: f32,
    pub drop: f32,
    /// Twist: angular speed factor.
    pub twist: f32,
    /// Material (None = the spec's).
    pub material: Option<Material>,
}

impl Variation {
    pub const NONE: Variation = Variation {
        width: 1.0,
        wind: 1.0,
        flap: 1.0,
        flap_freq: 1.0,
        sphere_radius: 1.0,
        sphere_offset: [0.0; 2],
        squeeze: 0.3,
        drop: 1.0,
        twist: 1.0,
        material: None,
    };

    pub fn from_seed(seed: u64) -> Variation {
        if seed == 0 {
            return Variation::NONE;
        }
        let mut r = crate::rng::Rng::new(crate::rng::mix_seed(&[0x5CE7E, seed]));
        Variation {
            width: r.uniform_in(0.7, 1.4),
            wind: r.uniform_in(0.4, 1.6),
            flap: r.uniform_in(0.4, 1.6),
            flap_freq: r.uniform_in(0.6, 1.5),
            sphere_radius: r.uniform_in(0.7, 1.4),
            sphere_offset: [r.uniform_in(-0.15, 0.15), r.uniform_in(-0.1, 0.1)],
            squeeze: r.uniform_in(0.1, 0.4),
            drop: r.uniform_in(0.6, 1.2),
            twist: r.uniform_in(0.5, 1.5),
            material: Some(Material::ALL[r.below(Material::ALL.len())]),
        }
    }
}

/// Default tracking strength (1/s²): attachment natural frequency ≈ 5 Hz, soft enough for
/// wrinkles to form, strong enough to keep the HR run on its LR twin. Measured
/// (docs/research/results-notebook.md, "What there is to learn"): at 100 1/s² most of HR − U on a held-out flag is the HR run drifting
/// away (3.6 mm), at 1000 it is 2.1 mm and at 10 000 2.0 mm, so 1000 keeps the wrinkles and
/// drops the drift no upscaler could predict. The shipped model is trained at this strength.
pub const DEFAULT_TRACKING: f32 = 1000.0;

impl ScenarioSpec {
    /// The scenario's defaults: paper resolution, 200 frames, seed 0, cotton, default tracking.
    pub fn new(scenario: Scenario) -> ScenarioSpec {
        let (w, h) = scenario.default_resolution();
        let mut params = SimParams::default();
        if scenario == Scenario::TwistZeroG {
            params.gravity = [0.0; 3];
        }
        ScenarioSpec {
            scenario,
            w,
            h,
            frames: 200,
            seed: 0,
            material: Material::COTTON,
            tracking: DEFAULT_TRACKING,
            tracking_mode: TrackingMode::Coarse,
            scale: 2,
            vary: 0,
            hr_jitter: 0.0,
            hr_restart: 0,
            hr_blind: false,
            params,
        }
    }

    pub fn validate(&self) -> Result<()> {
        self.params.validate()?;
        if self.w < 2 || self.h < 2 || self.w > 4096 || self.h > 4096 {
            return Err(Error::config(format!(
                "resolution must be between 2x2 and 4096x4096, got {}x{}",
                self.w, self.h
            )));
        }
        if self.frames == 0 {
            return Err(Error::config("frames must be at least 1"));
        }
        if self.scale == 0 || self.scale > 8 {
            return Err(Error::config(format!("scale must be in 1..=8, got {}", self.scale)));
        }
        if !(self.hr_jitter.is_finite() && (0.0..=0.01).contains(&self.hr_jitter)) {
            return Err(Error::config(format!(
                "hr jitter must be between 0 and 0.01 m, got {}",
                self.hr_jitter
            )));
        }
        if !(self.tracking.is_finite() && self.tracking >= 0.0) {
            return Err(Error::config(format!(
                "tracking must be finite and ≥ 0 (1/s²), got {}",
                self.tracking
            )));
        }
        Ok(())
    }

    /// The spec an HR run at `scale`× the resolution uses: `scale`× the substeps, because a
    /// Gauss–Seidel sweep carries a correction about one cell per substep, so a finer grid
    /// needs proportionally more substeps to be as stiff as the coarse one.
    pub fn for_scale(&self, scale: usize) -> ScenarioSpec {
        let mut s = self.clone();
        s.params.substeps = self.params.substeps * scale.max(1);
        s
    }

    /// Rest rectangle (width, height) in metres, fixed by the LR resolution.
    pub fn size(&self) -> (f32, f32) {
        let wd = self.scenario.width() * Variation::from_seed(self.vary).width;
        (wd, wd * (self.h - 1) as f32 / (self.w - 1) as f32)
    }

    /// Build the cloth and its scene at a `w × h` resolution over this spec's rest rectangle.
    pub fn setup(&self, w: usize, h: usize) -> (Cloth, Scene) {
        let (sx, sy) = self.size();
        let var = Variation::from_seed(self.vary);
        let uv: Vec<(f32, f32)> = (0..h).flat_map(|j| (0..w).map(move |i| rest_uv(i, j, w, h))).collect();
        let corner = |i: usize, j: usize| (i == 0 || i + 1 == w) && (j == 0 || j + 1 == h);
        let calm = Wind::none();
        let (pos, pins_of, kinematics, wind, colliders): (Vec<[f32; 3]>, Vec<(usize, f32)>, _, _, _) =
            match self.scenario {
                Scenario::Flag | Scenario::FlagSphere => {
                    // Vertical in the xy plane, top row pinned at y = 1.5 m; wind blows +z.
                    let pos = uv.iter().map(|&(u, v)| [(u - 0.5) * sx, 1.5 - v * sy, 0.0]).collect();
                    let pins = (0..w).map(|i| (i, 0.0)).collect();
                    let kin = Kinematics::Flap {
                        amplitude: 0.25 * var.flap,
                        freq: 0.6 * var.flap_freq,
                        dir: [0.0, 0.0, 1.0],
                    };
                    let wind =
                        Wind::gusty([0.5 * var.wind, 0.0, 1.8 * var.wind], 1.2 * var.wind, 4, self.seed);
                    let col = if self.scenario == Scenario::FlagSphere {
                        let [ox, oz] = var.sphere_offset;
                        Colliders {
                            sphere: Some(Sphere {
                                center: [0.1 + ox, 1.5 - 0.75 * sy, 0.45 + oz],
                                radius: 0.25 * var.sphere_radius,
                            }),
                            ..Default::default()
                        }
                    } else {
                        Colliders::default()
                    };
                    (pos, pins, kin, wind, col)
                }
                Scenario::Drape => {
                    // Horizontal (xz) at y = 1.0 m, centred over a sphere; corners lowered and
                    // pulled in over the first 2 s.
                    let pos = uv.iter().map(|&(u, v)| [(u - 0.5) * sx, 1.0, (v - 0.5) * sy]).collect();
                    let pins =
                        (0..h).flat_map(|j| (0..w).map(move |i| (i, j))).filter(|&(i, j)| corner(i, j));
                    let pins = pins.map(|(i, j)| (j * w + i, 0.0)).collect();
                    let kin = Kinematics::Drape { squeeze: var.squeeze, drop: 0.45 * var.drop, ramp: 2.0 };
                    let [ox, oz] = var.sphere_offset;
                    let radius = 0.3 * var.sphere_radius;
                    let col = Colliders {
                        sphere: Some(Sphere { center: [ox, 0.75 - radius, oz], radius }),
                        ground: Some(0.0),
                        ..Default::default()
                    };
                    (pos, pins, kin, calm, col)
                }
                Scenario::Drop | Scenario::DropTable => {
                    // Horizontal (xz), nothing pinned, 5 cm above the obstacle it falls onto; the
                    // free hem hangs and folds, unlike the drape's sheet held at its corners
                    // (cloth from other tools is mostly such free hems). `drop`: a sphere.
                    // `drop-table`: a table 0.75 m high whose top is 0.6 × the sheet's side × the
                    // obstacle size factor (0.7–1.4; at most 0.8 ×, to leave a hem): the hem hangs
                    // down the sides, clear of the ground, and folds at the corners.
                    let (y0, col) = if self.scenario == Scenario::Drop {
                        let [ox, oz] = var.sphere_offset;
                        let radius = 0.35 * var.sphere_radius;
                        let center = [ox, 0.05 + radius, oz];
                        let sphere = Sphere { center, radius };
                        (center[1] + radius + 0.05, Colliders { sphere: Some(sphere), ..Default::default() })
                    } else {
                        let [ox, oz] = var.sphere_offset.map(|o| 0.5 * o);
                        let top = 0.75;
                        let half = |side: f32| (0.3 * var.sphere_radius).min(0.4) * side;
                        let cuboid =
                            Cuboid { center: [ox, 0.5 * top, oz], half: [half(sx), 0.5 * top, half(sy)] };
                        (top + 0.05, Colliders { cuboid: Some(cuboid), ..Default::default() })
                    };
                    let pos = uv.iter().map(|&(u, v)| [(u - 0.5) * sx, y0, (v - 0.5) * sy]).collect();
                    // A breeze with gusts keeps the hem swaying once the sheet has landed.
                    let wind =
                        Wind::gusty([0.6 * var.wind, 0.0, 0.6 * var.wind], 1.0 * var.wind, 4, self.seed);
                    (pos, Vec::new(), Kinematics::Static, wind, Colliders { ground: Some(0.0), ..col })
                }
                Scenario::Twist | Scenario::TwistMaterials | Scenario::TwistZeroG => {
                    // Horizontal strip along x at y = 1.0 m; both end columns pinned and turned
                    // about the strip's axis in opposite directions, moving slowly inward.
                    let pos = uv.iter().map(|&(u, v)| [(u - 0.5) * sx, 1.0, (v - 0.5) * sy]).collect();
                    let pins = (0..h).flat_map(|j| [(j * w, -1.0), (j * w + w - 1, 1.0)]).collect();
                    let kin = Kinematics::Twist {
                        center_y: 1.0,
                        center_z: 0.0,
                        omega: 0.5 * var.twist,
                        inward_speed: 0.03,
                        max_inward: 0.06 * sx,
                    };
                    (pos, pins, kin, calm, Colliders::default())
                }
            };
        let rest = GridMesh::new(w, h, pos);
        let pins: Vec<Pin> =
            pins_of.iter().map(|&(v, side)| Pin { vertex: v, anchor: rest.pos[v], side }).collect();
        let base = var.material.unwrap_or(self.material);
        let banded = self.scenario == Scenario::TwistMaterials;
        let material = move |v: usize| {
            if banded {
                // Three bands along the strip: silk | rubber | denim.
                let u = rest_uv(v % w, v / w, w, h).0;
                if u < 1.0 / 3.0 {
                    Material::SILK
                } else if u < 2.0 / 3.0 {
                    Material::RUBBER
                } else {
                    Material::DENIM
                }
            } else {
                base
            }
        };
        let cloth = Cloth::new(&rest, &material, pins);
        (cloth, Scene { kinematics, wind, colliders, meshes: Vec::new() })
    }
}

fn check_finite(frame: &GridMesh, k: usize) -> Result<()> {
    if frame.pos.iter().any(|p| p.iter().any(|c| !c.is_finite())) {
        return Err(Error::numeric(format!(
            "the simulation blew up (non-finite position) at frame {k}; try more substeps"
        )));
    }
    Ok(())
}

/// Simulate `spec` at a `w × h` resolution; with `track = Some(lr_frames)` (and
/// `spec.tracking > 0`) the run is attached to the LR run as `spec.tracking_mode` says (see
/// [`super::tracking`]). `progress(k)` is called after frame k.
pub fn run_at(
    spec: &ScenarioSpec,
    w: usize,
    h: usize,
    track: Option<&[GridMesh]>,
    progress: &mut dyn FnMut(usize),
) -> Result<Vec<GridMesh>> {
    spec.validate()?;
    let track = track.filter(|_| spec.tracking > 0.0);
    if let Some(lr) = track {
        if lr.len() < spec.frames {
            return Err(Error::shape(format!("tracking needs {} LR frames, got {}", spec.frames, lr.len())));
        }
    }
    let (mut cloth, mut scene) = spec.setup(w, h);
    let restart = match track {
        Some(_) if spec.hr_blind => {
            scene.colliders = Default::default();
            scene.wind = crate::cloth::wind::Wind::none();
            1
        }
        Some(_) => spec.hr_restart,
        None => 0,
    };
    if track.is_some() && spec.hr_jitter > 0.0 {
        cloth.jitter_free(spec.seed, spec.hr_jitter);
    }
    let coarse = match (track, spec.tracking_mode) {
        (Some(lr), TrackingMode::Coarse) => {
            Some(CoarseTrack::new(Restriction::new(lr[0].w, lr[0].h, w, h), &cloth.inv_mass))
        }
        _ => None,
    };
    let targets_of = |lr: &GridMesh| match &coarse {
        Some(ct) => ct.restriction.targets(lr),
        None => bilinear_targets(lr, w, h),
    };
    let mut out = Vec::with_capacity(spec.frames);
    out.push(cloth.mesh());
    progress(0);
    let mut from = track.map(|lr| targets_of(&lr[0]));
    for k in 1..spec.frames {
        if let Some(lr) = track.filter(|_| restart > 0 && restart + 1 == k) {
            let (now, before) =
                (bilinear_targets(&lr[k - 1], w, h), bilinear_targets(&lr[k.max(2) - 2], w, h));
            let inv_dt = 1.0 / spec.params.dt;
            for v in 0..cloth.x.len() {
                if cloth.inv_mass[v] > 0.0 {
                    cloth.x[v] = now[v];
                    cloth.v[v] = std::array::from_fn(|c| (now[v][c] - before[v][c]) * inv_dt);
                }
            }
        }
        match (track, &from) {
            (Some(lr), Some(f)) => {
                let to = targets_of(&lr[k]);
                let tt = TrackTargets {
                    from: f,
                    to: &to,
                    strength: spec.tracking,
                    damping: 0.0,
                    coarse: coarse.as_ref(),
                    pins: None,
                };
                cloth.step(&spec.params, &scene, Some(&tt));
                from = Some(to);
            }
            _ => cloth.step(&spec.params, &scene, None),
        }
        let m = cloth.mesh();
        check_finite(&m, k)?;
        out.push(m);
        progress(k);
    }
    Ok(out)
}

/// Simulate `spec` at its own (LR) resolution.
pub fn run_single(spec: &ScenarioSpec) -> Result<Vec<GridMesh>> {
    run_at(spec, spec.w, spec.h, None, &mut |_| {})
}

/// The same scenario at `w × h` (LR) and `scale·w × scale·h` (HR), the HR run tracking the LR
/// one with `spec.tracking` and `spec.tracking_mode` (strength 0 = independent runs).
pub fn paired_run(spec: &ScenarioSpec) -> Result<(Vec<GridMesh>, Vec<GridMesh>)> {
    paired_run_with_progress(spec, &mut |_| {})
}

/// [`paired_run`] with a progress callback counting frames over both runs (0 .. 2·frames).
pub fn paired_run_with_progress(
    spec: &ScenarioSpec,
    progress: &mut dyn FnMut(usize),
) -> Result<(Vec<GridMesh>, Vec<GridMesh>)> {
    let lr = run_at(spec, spec.w, spec.h, None, &mut |k| progress(k))?;
    let (hw, hh) = (spec.scale * spec.w, spec.scale * spec.h);
    let hr_spec = spec.for_scale(spec.scale);
    let hr = run_at(&hr_spec, hw, hh, Some(&lr), &mut |k| progress(spec.frames + k))?;
    Ok((lr, hr))
}
