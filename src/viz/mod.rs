//! Pictures: every PNG the tool writes is drawn here, as a plain 8-bit RGB buffer
//! ([`image::Rgb8`]); the CLI writes it with `app::ui::save_png(path, &img)`.
//!
//! - [`image`]: the raster picture, geometry images and maps to pixels, nearest resampling,
//!   tiling (`hstack`, `vstack`, `pad`), text labels.
//! - [`font`]: the built-in 5×7 bitmap font.
//! - [`render`]: the software rasterizer for grid cloth meshes (camera, shading, props) and
//!   comparison rows of tiles sharing one camera.
//! - [`heat`]: the heat colour scale, per-vertex scalar colours, the colour bar, and a heat
//!   row with its colour bar.
//! - [`closeup`]: close-ups where the truth's folds are (LR | Catmull-Rom | anisocb | HR in
//!   normal shading), stills and flip-book frames.
//! - [`plot`]: the line plot (loss curves, per-frame errors).
//! - [`sheet`]: contact sheets (rows of tiles) and the strip of a few frames of a sequence.
//!
//! A comparison row with an error heat map:
//!
//! ```
//! use anisocb::eval::metrics;
//! use anisocb::geom::GridMesh;
//! use anisocb::viz::{heat, render};
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
//!         colors: Some(heat::ScalarColors { values: &err, lo: 0.0, hi: 0.02 }),
//!     },
//! ];
//! let row = render::render_row(&tiles, &render::View::default(), &render::Shading::default(), 128, 128, 4)?;
//! assert_eq!(row.w, 3 * 128 + 2 * 4);
//! # Ok::<(), anisocb::Error>(())
//! ```

pub mod closeup;
pub mod font;
pub mod heat;
pub mod image;
pub mod plot;
pub mod render;
pub mod sheet;

pub use image::Rgb8;
