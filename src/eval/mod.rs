//! Evaluation: metrics against the HR ground truth, the interpolation baseline, and the
//! pictures of the reports (software renders, tiles with labels, line plots).
//!
//! Pictures are plain 8-bit RGB buffers ([`image::Rgb8`]); the CLI writes them with
//! `app::ui::save_png_rgb(path, img.w, img.h, &img.data)`.
//!
//! A comparison row with an error heat map, and the metrics of a sequence:
//!
//! ```
//! use anisocb::eval::{metrics, render};
//! use anisocb::geom::GridMesh;
//!
//! let hr = GridMesh::flat(16, 16, 1.0, 1.0);
//! let pred = GridMesh::new(16, 16, hr.pos.iter().map(|p| [p[0], p[1], p[2] + 0.01]).collect());
//! let err = metrics::vertex_errors(&pred, &hr)?;
//! let tiles = [
//!     render::Tile { mesh: &pred, label: "anisocb", colors: None },
//!     render::Tile { mesh: &hr, label: "HR", colors: None },
//!     render::Tile {
//!         mesh: &pred,
//!         label: "error",
//!         colors: Some(render::ScalarColors { values: &err, lo: 0.0, hi: 0.02 }),
//!     },
//! ];
//! let row = render::render_row(&tiles, &render::View::default(), &render::Shading::default(), 128, 128, 4)?;
//! assert_eq!(row.w, 3 * 128 + 2 * 4);
//! let m = metrics::sequence_metrics(&[pred], &[hr], None)?;
//! assert!((m.mean.rmse - 0.01).abs() < 1e-6);
//! # Ok::<(), anisocb::Error>(())
//! ```

pub mod baseline;
pub mod font;
pub mod image;
pub mod metrics;
pub mod plot;
pub mod render;

pub use image::Rgb8;
