//! Simulation parameters and material presets. Units: metres, seconds, kilograms, newtons.

use crate::error::{Error, Result};

/// Integration and contact parameters (one set per run; LR and HR runs of a pair share it).
#[derive(Clone, Debug, PartialEq)]
pub struct SimParams {
    /// Time between output frames (s).
    pub dt: f32,
    /// XPBD substeps per frame ("small steps", Macklin et al. 2019); substep `h = dt / substeps`.
    pub substeps: usize,
    /// Constraint sweeps per substep (1 is the small-steps default).
    pub iterations: usize,
    /// Gravity acceleration (m/s²); y is up.
    pub gravity: [f32; 3],
    /// Velocity damping rate (1/s): `v ← v · max(0, 1 − damping·h)` every substep.
    pub damping: f32,
    /// Vertices are kept at least this far (m) outside the sphere and above the ground.
    pub collision_margin: f32,
    /// Friction coefficient (dimensionless): tangential motion during a contact substep is
    /// removed up to `friction × penetration depth` (position-based Coulomb friction).
    pub friction: f32,
    /// Linear aerodynamic drag (kg/(m²·s)): force on a vertex = `drag · area · ((wind − v)·n) n`.
    pub drag: f32,
    /// Long-range attachments (Kim, Chentanez, Müller 2012): every free vertex may not get
    /// farther from its nearest pinned vertex than their rest distance × (1 + `tether_slack`).
    /// Stops pinned cloth from stretching under its own weight at any resolution.
    pub tethers: bool,
    /// Allowed extra length of a tether (fraction of its rest length).
    pub tether_slack: f32,
    /// A colour of constraints with at least this many members is projected on the rayon
    /// pool (members of a colour share no vertex, so the result is the same bits as serial).
    pub parallel_min_colour: usize,
}

impl Default for SimParams {
    fn default() -> Self {
        SimParams {
            dt: 1.0 / 30.0,
            substeps: 10,
            iterations: 1,
            gravity: [0.0, -9.81, 0.0],
            damping: 0.2,
            collision_margin: 0.01,
            friction: 0.3,
            drag: 0.3,
            tethers: true,
            tether_slack: 0.02,
            parallel_min_colour: 4096,
        }
    }
}

impl SimParams {
    pub fn validate(&self) -> Result<()> {
        if !(self.dt.is_finite() && self.dt > 0.0 && self.dt <= 1.0) {
            return Err(Error::config(format!("dt must be in (0, 1] seconds, got {}", self.dt)));
        }
        if self.substeps == 0 || self.substeps > 1000 {
            return Err(Error::config(format!("substeps must be in 1..=1000, got {}", self.substeps)));
        }
        if self.iterations == 0 || self.iterations > 100 {
            return Err(Error::config(format!("iterations must be in 1..=100, got {}", self.iterations)));
        }
        for (name, v) in [
            ("damping", self.damping),
            ("collision_margin", self.collision_margin),
            ("friction", self.friction),
            ("drag", self.drag),
            ("tether_slack", self.tether_slack),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::config(format!("{name} must be finite and ≥ 0, got {v}")));
            }
        }
        Ok(())
    }

    /// Substep length (s).
    pub fn h(&self) -> f32 {
        self.dt / self.substeps as f32
    }
}

/// A cloth material. Compliances are XPBD compliances (inverse stiffness); they are
/// resolution independent: a distance constraint on a square cell edge with compliance `α`
/// behaves like a membrane of 2D Young's modulus `1/α` (N/m).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    pub name: &'static str,
    /// Areal density (kg/m²).
    pub density: f32,
    /// Compliance of structural (row and column) edges (m/N); 0 = inextensible.
    pub stretch_compliance: f32,
    /// Compliance of the quad diagonals that resist shear (m/N).
    pub shear_compliance: f32,
    /// Bending stiffness of the isometric bending energy (N·m = J).
    pub bend_stiffness: f32,
}

impl Material {
    /// Light, soft-bending, fine wrinkles.
    pub const SILK: Material = Material {
        name: "silk",
        density: 0.08,
        stretch_compliance: 2e-5,
        shear_compliance: 2e-4,
        bend_stiffness: 2e-6,
    };
    /// The default: medium weight, medium bending.
    pub const COTTON: Material = Material {
        name: "cotton",
        density: 0.2,
        stretch_compliance: 1e-5,
        shear_compliance: 1e-4,
        bend_stiffness: 2e-5,
    };
    /// Heavy, stiff-bending, broad folds.
    pub const DENIM: Material = Material {
        name: "denim",
        density: 0.4,
        stretch_compliance: 2e-6,
        shear_compliance: 2e-5,
        bend_stiffness: 2e-4,
    };
    /// Visibly elastic (2D Young's modulus about 500 N/m).
    pub const RUBBER: Material = Material {
        name: "rubber",
        density: 0.5,
        stretch_compliance: 2e-3,
        shear_compliance: 2e-3,
        bend_stiffness: 3e-5,
    };

    pub const ALL: [Material; 4] = [Material::SILK, Material::COTTON, Material::DENIM, Material::RUBBER];

    pub fn from_name(name: &str) -> Result<Material> {
        Material::ALL.iter().find(|m| m.name == name).copied().ok_or_else(|| {
            let names: Vec<&str> = Material::ALL.iter().map(|m| m.name).collect();
            Error::config(format!("unknown material '{name}'; choose one of: {}", names.join(", ")))
        })
    }
}
