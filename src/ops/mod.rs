//! The closed list of ops. Each op has a plain scalar reference `*_ref` (the spec) and a fast
//! path (SIMD via `wide` + threads via `rayon`) with the same signature; tests compare them.
//! Backward functions sit next to their forwards and ADD into gradient buffers (`+=`).

pub mod conv2d;

pub use conv2d::Padding;
