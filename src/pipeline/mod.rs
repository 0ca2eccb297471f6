//! The upscale pipeline as a library, without the command line (`default-features = false`):
//!
//! - [`upscale_files`]: a whole job on files — an OBJ sequence, a point cache with its rest
//!   mesh, or a geometry.npy in; OBJ, a point cache or `.npy` out — exactly as
//!   `anisocb upscale` runs it (the command line calls it), with a [`Report`] for progress.
//! - [`Upscaler`]: frames in memory, one at a time (the temporal context kept inside); what the
//!   C ABI (`include/anisocb.h`) wraps.
//! - [`input`] and [`output`]: the frame sources and sinks the job streams between.
//!
//! ```no_run
//! use anisocb::pipeline::{upscale_files, Quiet, UpscaleJob};
//! use anisocb::nn::weights::embedded_model;
//!
//! let model = embedded_model()?;
//! let job = UpscaleJob::new(vec!["frames/".into()], "hr/").check()?;
//! let done = upscale_files(&anisocb::ops::Cpu, &model, &job, &mut Quiet)?;
//! println!("{} frames, {:?} -> {:?}", done.frames, done.lr, done.hr);
//! # Ok::<(), anisocb::Error>(())
//! ```

pub mod folder;
pub mod input;
pub mod job;
pub mod output;
pub mod physics;
pub mod stream;
pub mod upscaler;
mod worker;

pub use job::{upscale_files, OutputFormat, Quiet, Report, Summary, UpscaleJob};
pub use upscaler::Upscaler;
