//! Super-resolution: the composition of the three networks' outputs (our Eq 12) and the
//! upscale pipeline around it.

pub mod compose;
pub mod outline;
pub mod params;
pub mod strain;
pub mod temporal;
pub mod upscale;
pub mod uv;

pub use compose::{compose, DEFAULT_ETA};
