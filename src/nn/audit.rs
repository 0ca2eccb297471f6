//! Layer-by-layer dump of a network's activations as `.npy`, named after the layers
//! (`conv_in.npy`, `blocks.0.conv1.npy`, `blocks.0.relu.npy`, `blocks.0.conv2.npy`, `blocks.0.npy`
//! (after the skip, GeometryNet only), `upscale.npy`, `pixel_shuffle.npy`, `tail.0.npy`,
//! `tail.0.relu.npy`, …, `tail.3.npy`), so a user can compare with their own framework.
//! GeometryNet adds `interp.npy` (U) and `estimate.npy` (U + R); the map nets `sigmoid.npy`.

use super::config::NetKind;
use super::geometry_net::{check_input, interpolate};
use super::layers::Trunk;
use super::weights::Weights;
use crate::error::Result;
use crate::io::{atomic::ensure_dir, write_npy};
use crate::ops::Ops;
use crate::tensor::Tensor;
use std::path::{Path, PathBuf};

/// Write every activation of `trunk` on `x` (N, 3, H, W) into `dir`; returns the files in order.
pub fn audit_trunk(ops: &dyn Ops, trunk: &Trunk, x: &Tensor, dir: &Path) -> Result<Vec<PathBuf>> {
    check_input(x, "audit input")?;
    ensure_dir(dir)?;
    let mut files = Vec::new();
    let mut first_err = None;
    let mut save = |name: &str, t: &Tensor| {
        let p = dir.join(format!("{name}.npy"));
        match write_npy(&p, t) {
            Ok(()) => files.push(p),
            Err(e) => {
                first_err.get_or_insert(e);
            }
        }
    };
    save("input", x);
    let y = trunk.forward_observed(ops, x, &mut |n, t| save(n, t));
    if trunk.kind == NetKind::Geometry {
        let mut est = interpolate(ops, x, trunk.config.scale, trunk.config.upsample);
        save("interp", &est);
        ops.add_assign(&mut est, &y);
        save("estimate", &est);
    } else {
        save("sigmoid", &ops.sigmoid(&y));
    }
    match first_err {
        Some(e) => Err(e),
        None => Ok(files),
    }
}

/// [`audit_trunk`] for a weights file of either layout: a bundle writes `dir/<net>/…`
/// (`geometry1/` … for an ensemble's further GeometryNets).
pub fn audit(ops: &dyn Ops, weights: &Weights, x: &Tensor, dir: &Path) -> Result<Vec<PathBuf>> {
    match weights {
        Weights::Net(t) => audit_trunk(ops, t, x, dir),
        Weights::Bundle(b) => {
            let mut all = Vec::new();
            for (name, t) in b.named_trunks() {
                all.extend(audit_trunk(ops, t, x, &dir.join(name))?);
            }
            Ok(all)
        }
    }
}
