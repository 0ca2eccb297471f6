//! Evaluation: metrics against the HR ground truth, the interpolation baseline, and the
//! pictures of the reports (software renders, tiles with labels, line plots).
//!
//! Pictures are plain 8-bit RGB buffers ([`image::Rgb8`]); the CLI writes them with
//! `app::ui::save_png_rgb(path, img.w, img.h, &img.data)`.

pub mod baseline;
pub mod font;
pub mod image;
pub mod metrics;
pub mod plot;
pub mod render;

pub use image::Rgb8;
