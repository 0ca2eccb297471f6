//! Super-resolution: the composition of the three networks' outputs (our Eq 12) and the
//! upscale pipeline around it.

pub mod compose;
pub mod stream;
pub mod upscale;

pub use compose::{compose, DEFAULT_ETA};
