//! What the compute commands (`upscale`, `demo`, `eval`) set up first: the thread pool and the
//! model (the bundle, or a GeometryNet alone).

use crate::error::{Error, Result};
use crate::nn::bundle::AnisoCb;
use crate::nn::geometry_net::GeometryNet;
use crate::nn::weights::{load_any, Weights};
use crate::sr::upscale::embedded_model;
use std::path::Path;

/// The model to use: `--weights FILE` or the embedded one.
pub fn load_model(weights: Option<&Path>) -> Result<AnisoCb> {
    match weights {
        Some(p) => AnisoCb::load(p),
        None => embedded_model(),
    }
}

/// A GeometryNet from a single-net weights file or from a bundle (its geometry net).
pub fn load_geometry_net(path: &Path) -> Result<GeometryNet> {
    match load_any(path)? {
        Weights::Net(t) if t.kind == crate::nn::NetKind::Geometry => Ok(GeometryNet { trunk: *t }),
        Weights::Net(t) => {
            Err(Error::format(path, format!("expected a geometry net, got a {} net", t.kind.name())))
        }
        Weights::Bundle(b) => Ok(b.geometry),
    }
}

/// `--threads N`: the size of the global worker pool (default: all cores).
pub fn set_threads(threads: Option<usize>) -> Result<()> {
    if let Some(n) = threads {
        if n == 0 {
            return Err(Error::config("--threads must be ≥ 1"));
        }
        // Fails if a pool was already set up in this process (the `anisocb` binary builds it
        // with this count in `app::process_main`); the first setting wins.
        let _ = rayon::ThreadPoolBuilder::new().num_threads(n).build_global();
    }
    Ok(())
}
