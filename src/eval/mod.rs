//! Evaluation: metrics against the HR ground truth, the interpolation baseline, and the
//! markdown tables of the reports (the pictures are drawn by [`crate::viz`]).
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
pub mod metrics;
pub mod report;
pub mod wrinkle;
