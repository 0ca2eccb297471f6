//! # anisocb — geometry-image super-resolution of cloth (AnisoCBConvNet)
//!
//! ```text
//!  PBD cloth sim ──► LR mesh sequence ──► geometry image (Eq 1) ──► each frame in its own
//!   (cloth/)          (geom/)               3×H×W, on disk           cloth frame (geom/cloth_frame)
//!                                                                    U = cubic ×2 (align corners)
//!                                               │                    │
//!                                               ├─► GeometryNet ─► R (residual)      (nn/)
//!                                               ├─► BoundaryNet ─► Γb (prob. map)
//!                                               └─► EnhanceNet  ─► Γe (prob. map)
//!        Γfinal = U + (1 − Γb) ⊙ (1 + η Γe) ⊙ R        (our Eq 12, sr/; R smoothed over time
//!                                                        in the cloth frame)
//!           back to the sequence's frame ──► HR geometry image ──► HR mesh (Eq 2) ──► OBJ / .npy
//! ```
//!
//! Module map (one folder per stage):
//! - [`tensor`]: dense f32 tensors. Activations NCHW, conv weights OIHW (PyTorch layout).
//! - [`ops`]: the closed op list; each op has a scalar `*_ref` and a fast path, forward + backward.
//! - [`nn`]: layers, GeometryNet / BoundaryNet / EnhanceNet, weights (`.npz`) in and out.
//! - [`train`]: Adam, dataset, trainer.
//! - [`cloth`]: XPBD cloth simulator and the paper's scenarios.
//! - [`geom`]: grid meshes, OBJ, geometry images, the cloth frame the nets see, Laplacian,
//!   anisotropic boundary maps, 3-vectors.
//! - [`imgproc`]: Gaussian, Sobel, Canny.
//! - [`sr`]: the nets on a shot's frames, composition (Eq 12), outline floor, strain limit,
//!   temporal smoothing, streaming.
//! - [`pipeline`]: the upscale job on files (OBJ sequences, point caches, `.npy`) and the
//!   frame-by-frame [`pipeline::Upscaler`]: the library the CLI and the C ABI sit on.
//! - [`eval`]: metrics (incl. STED), the interpolation and learned-linear baselines, tables.
//! - `viz` (feature `viz`, on with `cli`): every picture (raster image, font, renderer, plots,
//!   heat tiles, sheets).
//! - [`io`]: `.npy`/`.npz`, JSON, PC2/MDD point caches, atomic writes.
//! - [`rng`]: the seeded random number generator everything shares.
//! - [`perf`]: speed measurement for benchmarks (FMA peak, timers, the conv table).
//! - [`cuda`]: the GPU backend (feature `cuda`); a stub with the same API otherwise.
//! - `capi` (feature `capi`): the C ABI, `include/anisocb.h`.
//! - `app` (feature `cli`): the command-line front end.
//!
//! The pipeline, one frame's path and our reading of each equation: `docs/architecture.md`.

#[cfg(feature = "capi")]
pub mod capi;
pub mod cloth;
pub mod cuda;
pub mod error;
pub mod eval;
pub mod geom;
pub mod imgproc;
pub mod io;
pub mod nn;
pub mod ops;
pub mod perf;
pub mod pipeline;
pub mod pool;
pub mod rng;
pub mod sr;
pub mod tensor;
pub mod train;
#[cfg(feature = "viz")]
pub mod viz;

#[cfg(feature = "cli")]
pub mod app;

pub use error::{Error, Result};
pub use tensor::{Shape, Tensor};
