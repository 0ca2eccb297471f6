//! # anisocb — geometry-image super-resolution of cloth (AnisoCBConvNet)
//!
//! ```text
//!  PBD cloth sim ──► LR mesh sequence ──► geometry image (Eq 1) ──► U = bicubic ×2 (align corners)
//!   (cloth/)          (geom/)               3×H×W in [0,1]            │
//!                                               ├─► GeometryNet ─► R (residual)      (nn/)
//!                                               ├─► BoundaryNet ─► Γb (prob. map)
//!                                               └─► EnhanceNet  ─► Γe (prob. map)
//!        Γfinal = U + (1 − Γb) ⊙ (1 + η Γe) ⊙ R        (our Eq 12, sr/)
//!                                  HR geometry image ──► HR mesh (Eq 2) ──► OBJ / .npy
//! ```
//!
//! Module map (one folder per stage):
//! - [`tensor`]: dense f32 tensors. Activations NCHW, conv weights OIHW (PyTorch layout).
//! - [`ops`]: the closed op list; each op has a scalar `*_ref` and a fast path, forward + backward.
//! - [`nn`]: layers, GeometryNet / BoundaryNet / EnhanceNet, weights (`.npz`) in and out.
//! - [`train`]: Adam, dataset, trainer.
//! - [`cloth`]: XPBD cloth simulator and the paper's scenarios.
//! - [`geom`]: grid meshes, OBJ, geometry images, Laplacian, anisotropic boundary maps.
//! - [`imgproc`]: Gaussian, Sobel, Canny.
//! - [`sr`]: composition (Eq 12) and the upscale pipeline.
//! - [`eval`]: metrics, baselines, renders.
//! - [`io`]: `.npy`/`.npz`, atomic writes.
//! - [`cuda`]: the GPU backend (feature `cuda`); a stub with the same API otherwise.
//! - `app` (feature `cli`): the command-line front end.

pub mod cloth;
pub mod cuda;
pub mod error;
pub mod eval;
pub mod geom;
pub mod imgproc;
pub mod io;
pub mod nn;
pub mod ops;
pub mod rng;
pub mod sr;
pub mod tensor;
pub mod train;
pub mod viz;

#[cfg(feature = "cli")]
pub mod app;

pub use error::{Error, Result};
pub use tensor::Tensor;
