//! What the compute commands (`upscale`, `demo`, `eval`) set up first: the thread pool and the
//! model (the bundle, or a GeometryNet alone).

use crate::error::{Error, Result};
use crate::nn::bundle::AnisoCb;
use crate::nn::geometry_net::GeometryNet;
use crate::nn::weights::embedded_model;
use crate::nn::weights::{load_any, Weights};
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

/// Largest `--threads N` accepted: far more workers than any machine has cores only costs
/// memory and start-up time (100 000 threads take minutes to spawn).
pub const MAX_THREADS: usize = 1024;

/// What is wrong with `--threads N`, if anything.
fn threads_problem(n: usize) -> Option<String> {
    match n {
        0 => Some("--threads must be ≥ 1".into()),
        n if n > MAX_THREADS => {
            Some(format!("--threads {n} is more than {MAX_THREADS}; leave it out to use one thread per core"))
        }
        _ => None,
    }
}

/// Clap value parser of `--threads N` (1 to [`MAX_THREADS`]): the process builds its worker
/// pool from it before a command runs, so it is checked while parsing.
pub fn parse_threads(s: &str) -> std::result::Result<usize, String> {
    let n: usize = s.trim().parse().map_err(|_| format!("expected a whole number of threads, got {s:?}"))?;
    threads_problem(n).map_or(Ok(n), Err)
}

/// `--threads N`: the size of the global worker pool (default: all cores).
pub fn set_threads(threads: Option<usize>) -> Result<()> {
    if let Some(n) = threads {
        if let Some(why) = threads_problem(n) {
            return Err(Error::config(why));
        }
        // Fails if a pool was already set up in this process (the `anisocb` binary builds it
        // with this count in `app::process_main`); the first setting wins.
        let _ = rayon::ThreadPoolBuilder::new().num_threads(n).build_global();
    }
    Ok(())
}
