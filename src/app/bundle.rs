//! `anisocb bundle`: assemble the three nets into one weights file, from separately trained
//! nets or other bundles (e.g. a GeometryNet from one run with a BoundaryNet trained on
//! benefit maps of it).

use crate::error::{Error, Result};
use crate::nn::bundle::AnisoCb;
use crate::nn::map_net::MapNet;
use crate::nn::weights::{load_any, Weights};
use crate::nn::{NetKind, Trunk};
use crate::pipeline::folder;
use crate::pipeline::input::same_file;
use std::path::{Path, PathBuf};

#[derive(clap::Args, Debug)]
#[command(after_help = "Example:
  anisocb bundle --geometry run/geometry/weights.npz --boundary benefit/boundary/weights.npz \\
                 --enhance run/enhance/weights.npz --out weights.npz
An ensemble: --geometry seed1/geometry/weights.npz --geometry seed2/geometry/weights.npz ...")]
pub struct Args {
    /// GeometryNet: a single-net weights file or a bundle (its first geometry net is taken).
    /// Given more than once: an ensemble whose residuals are averaged (same configuration).
    #[arg(long, value_name = "WEIGHTS", required = true)]
    pub geometry: Vec<PathBuf>,
    /// BoundaryNet: a single-net weights file or a bundle; `none` for a map that gates nothing
    /// (Γb = 0, never run), beside a GeometryNet distilled from a whole bundle (`dataset
    /// --distil`), whose residual is already gated.
    #[arg(long, value_name = "WEIGHTS")]
    pub boundary: PathBuf,
    /// EnhanceNet: a single-net weights file or a bundle.
    #[arg(long, value_name = "WEIGHTS")]
    pub enhance: PathBuf,
    /// The bundle to write (atomically): new, or a weights file replaced; never one of the
    /// inputs (in any spelling), and any other file there is refused (see --overwrite). One
    /// run at a time writes it (a lock).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Replace --out even where it is not a weights file.
    #[arg(long)]
    pub overwrite: bool,
}

/// `--boundary none`.
const NO_BOUNDARY: &str = "none";

/// Γb of `--boundary none`: σ(−40) ≈ 4·10⁻¹⁸, so that 1 − Γb is 1 in f32 and Eq 12 is U + R.
const NO_BOUNDARY_LOGIT: f32 = -40.0;

/// The net of `kind` in `path` (a single net of that kind, or a bundle).
fn net_of(path: &Path, kind: NetKind) -> Result<Trunk> {
    match load_any(path)? {
        Weights::Net(t) if t.kind == kind => Ok(*t),
        Weights::Net(t) => {
            Err(Error::format(path, format!("expected a {} net, got a {} net", kind.name(), t.kind.name())))
        }
        Weights::Bundle(b) => Ok(match kind {
            NetKind::Geometry => b.geometry.trunk,
            NetKind::Boundary => b.boundary.trunk,
            NetKind::Enhance => b.enhance.trunk,
        }),
    }
}

pub fn run(a: Args) -> Result<()> {
    // The bundle is written over nothing it is made from (a shipped bundle given as both).
    let none = a.boundary.as_os_str() == NO_BOUNDARY;
    let boundary = (!none).then_some(&a.boundary);
    let inputs = a.geometry.iter().chain(boundary).chain([&a.enhance]);
    if let Some(p) = inputs.into_iter().find(|p| same_file(p, &a.out)) {
        return Err(Error::config(format!(
            "--out {} is the input {}: writing it would replace a net it is made from; choose \
             another file for the bundle",
            a.out.display(),
            p.display()
        )));
    }
    let is_weights = |p: &Path| load_any(p).is_ok();
    let claim = folder::claim_file(&a.out, "a weights file (.npz of nets)", is_weights, a.overwrite)?;
    let more = a.geometry[1..].iter().map(|p| net_of(p, NetKind::Geometry)).collect::<Result<Vec<_>>>()?;
    let geometry = net_of(&a.geometry[0], NetKind::Geometry)?;
    let boundary = match boundary {
        Some(p) => net_of(p, NetKind::Boundary)?,
        None => MapNet::constant(NetKind::Boundary, geometry.config, NO_BOUNDARY_LOGIT)?.trunk,
    };
    let b = AnisoCb::from_trunks(geometry, boundary, net_of(&a.enhance, NetKind::Enhance)?)?
        .with_more_geometry(more)?;
    b.save(&a.out)?;
    drop(claim);
    let nets =
        if a.geometry.len() > 1 { format!(", {} GeometryNets", a.geometry.len()) } else { String::new() };
    eprintln!("bundle ({}{nets}) → {}", b.geometry.trunk.config, a.out.display());
    Ok(())
}
