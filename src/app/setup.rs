//! What the compute commands (`upscale`, `demo`, `eval`) set up first: the thread pool and the
//! model.

use crate::error::{Error, Result};
use crate::nn::bundle::AnisoCb;
use crate::sr::upscale::embedded_model;
use std::path::Path;

/// The model to use: `--weights FILE` or the embedded one.
pub fn load_model(weights: Option<&Path>) -> Result<AnisoCb> {
    match weights {
        Some(p) => AnisoCb::load(p),
        None => embedded_model(),
    }
}

/// `--threads N`: the size of the global worker pool (default: all cores).
pub fn set_threads(threads: Option<usize>) -> Result<()> {
    if let Some(n) = threads {
        if n == 0 {
            return Err(Error::config("--threads must be ≥ 1"));
        }
        // Fails only if a pool was already set up in this process; the first setting wins.
        let _ = rayon::ThreadPoolBuilder::new().num_threads(n).build_global();
    }
    Ok(())
}
