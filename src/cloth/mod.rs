//! XPBD cloth simulator and the paper's scenarios (figures 8–13).
//!
//! A cloth is a regular `w × h` vertex grid ([`crate::geom::GridMesh`], vertex (i, j) at
//! `j*w + i`, rest parameter `(u, v) = rest_uv(i, j)`), y up, metres and seconds.
//!
//! - [`params`]: [`SimParams`] (time step, substeps, gravity, damping, contacts) and
//!   [`Material`] presets, with units.
//! - [`constraints`]: stretch/shear distance constraints and isometric bending (Bergou et al.
//!   2006, as a linear vector constraint), graph-coloured for Gauss–Seidel sweeps.
//! - [`kinematics`]: pinned and driven vertices (flapping edge, twisting ends, lowered corners).
//! - [`collision`]: sphere, box (table) and ground with a margin and Coulomb-style position
//!   friction.
//! - [`mesh_collider`]: triangle-mesh colliders (static or animated OBJ), contacts through a
//!   hash grid with pseudo-normal inside tests and a no-tunnelling crossing test.
//! - [`wind`]: a time-varying wind field, deterministic from the seed.
//! - [`solver`]: the XPBD substep loop ([`solver::Cloth::step`]).
//! - [`tracking`]: soft attachment of a high-resolution run to a low-resolution one.
//! - [`follow`]: the physics pass of `upscale --physics`, an HR cloth coarse-tracked to a shot;
//!   [`held_edges`]: the grid edges it pins.
//! - [`scenarios`]: named presets ([`Scenario`]), [`ScenarioSpec`], [`run_single`], [`paired_run`].
//! - [`run_io`]: the run directory (`geometry.npy`, `domain.npy`, `meta.json`, `obj/`).
//!
//! Everything is serial or partitioned so that each vertex's result does not depend on thread
//! scheduling: the same seed gives the same bits.

pub mod collision;
pub mod constraints;
pub mod follow;
pub mod garments;
pub mod held_edges;
pub mod kinematics;
pub mod mesh_collider;
pub mod params;
pub mod run_io;
pub mod scenarios;
pub mod solver;
pub mod tracking;
pub mod wind;

pub use params::{Material, SimParams};
pub use scenarios::{paired_run, run_single, Scenario, ScenarioSpec};
