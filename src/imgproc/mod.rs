//! Image processing on single-channel f32 images (row-major `h × w`): Gaussian smoothing,
//! Sobel gradients and the Canny edge detector (the ground-truth enhance map), with
//! scikit-image's `feature.canny` semantics.

pub mod canny;
pub mod gaussian;
pub mod sobel;

pub use canny::{canny, enhance_map, CannyParams};
