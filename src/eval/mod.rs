//! Evaluation: metrics against the HR ground truth, the interpolation baseline, the methods
//! `anisocb eval` compares and how each is run on a held-out run ([`methods`]), the speed
//! study ([`speed`]), and the markdown and JSON tables of the reports ([`report`]); the CLI
//! parses, prints and draws (the pictures with `crate::viz`).
//!
//! The metrics of a sequence:
//!
//! ```
//! use anisocb::eval::metrics;
//! use anisocb::geom::GridMesh;
//!
//! let hr = GridMesh::flat(16, 16, 1.0, 1.0);
//! let pred = GridMesh::new(16, 16, hr.pos.iter().map(|p| [p[0], p[1], p[2] + 0.01]).collect());
//! let m = metrics::sequence_metrics(&[pred], &[hr], None)?;
//! assert!((m.mean.rmse - 0.01).abs() < 1e-6);
//! # Ok::<(), anisocb::Error>(())
//! ```

pub mod baseline;
pub mod invariance;
pub mod linear;
pub mod mesh;
pub mod methods;
pub mod metrics;
pub mod report;
pub mod speed;
pub mod wrinkle;
