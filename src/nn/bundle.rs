//! The three networks together, as the upscale pipeline uses them.

use super::config::{NetConfig, NetKind};
use super::geometry_net::{check_input, GeometryNet};
use super::layers::Trunk;
use super::map_net::MapNet;
use crate::error::{Error, Result};
use crate::geom::cloth_frame::InputFrame;
use crate::ops::Ops;
use crate::tensor::Tensor;

/// GeometryNet, BoundaryNet and EnhanceNet. All three must share the upscale factor.
#[derive(Clone, Debug, PartialEq)]
pub struct AnisoCb {
    pub geometry: GeometryNet,
    pub boundary: MapNet,
    pub enhance: MapNet,
}

/// What the nets say about one batch; every map is (N, ·, r·H, r·W).
#[derive(Clone, Debug)]
pub struct SrOutputs {
    /// Cubic (align-corners) interpolation U of the input (`config.upsample`), (N, 3, rH, rW).
    pub u: Tensor,
    /// GeometryNet's residual, (N, 3, rH, rW).
    pub r: Tensor,
    /// Γb = σ(BoundaryNet logits), (N, 1, rH, rW), in [0, 1].
    pub boundary: Tensor,
    /// Γe = σ(EnhanceNet logits), (N, 1, rH, rW), in [0, 1].
    pub enhance: Tensor,
}

impl AnisoCb {
    /// Fresh nets, all with `config`, initialised from `seed` (each net gets its own stream).
    pub fn new(config: NetConfig, seed: u64) -> Self {
        AnisoCb {
            geometry: GeometryNet::new(config, seed),
            boundary: MapNet { trunk: Trunk::init(NetKind::Boundary, config, seed) },
            enhance: MapNet { trunk: Trunk::init(NetKind::Enhance, config, seed) },
        }
    }

    /// Assemble from three trunks (checks kinds and scales).
    pub fn from_trunks(geometry: Trunk, boundary: Trunk, enhance: Trunk) -> Result<Self> {
        for (t, k) in
            [(&geometry, NetKind::Geometry), (&boundary, NetKind::Boundary), (&enhance, NetKind::Enhance)]
        {
            if t.kind != k {
                return Err(Error::config(format!("expected a {} net, got {}", k.name(), t.kind.name())));
            }
        }
        if geometry.config.scale != boundary.config.scale || geometry.config.scale != enhance.config.scale {
            return Err(Error::config("the three nets have different upscale factors"));
        }
        let frames = [&geometry, &boundary, &enhance].map(|t| t.config.input_frame.name());
        if frames[1..].iter().any(|f| *f != frames[0]) {
            return Err(Error::config(format!(
                "the three nets were trained in different input frames (geometry, boundary, enhance: {})",
                frames.join(", ")
            )));
        }
        Ok(AnisoCb {
            geometry: GeometryNet { trunk: geometry },
            boundary: MapNet { trunk: boundary },
            enhance: MapNet { trunk: enhance },
        })
    }

    pub fn scale(&self) -> usize {
        self.geometry.trunk.config.scale
    }

    /// The coordinates the nets expect their input in (shared by all three).
    pub fn input_frame(&self) -> InputFrame {
        self.geometry.trunk.config.input_frame
    }

    pub fn trunks(&self) -> [&Trunk; 3] {
        [&self.geometry.trunk, &self.boundary.trunk, &self.enhance.trunk]
    }

    /// lr (N, 3, H, W) → (U, R, Γb, Γe). Inference only: no activations are kept; run it in
    /// batches that fit memory (≈ 2·C·r²·H·W floats per sample at the widest layer).
    pub fn forward(&self, ops: &dyn Ops, lr: &Tensor) -> Result<SrOutputs> {
        self.forward_with(ops, lr, true)
    }

    /// [`AnisoCb::forward`], with EnhanceNet run only if `enhance` (else Γe = 0, which is all
    /// Eq 12 reads of it at η = 0): a third less work for the default η.
    pub fn forward_with(&self, ops: &dyn Ops, lr: &Tensor, enhance: bool) -> Result<SrOutputs> {
        check_input(lr, "AnisoCb input")?;
        crate::ops::entered(ops, || {
            let (u, r) = self.geometry.forward(ops, lr)?;
            let boundary = self.boundary.probabilities(ops, lr)?;
            let enhance =
                if enhance { self.enhance.probabilities(ops, lr)? } else { Tensor::zeros(&boundary.shape) };
            Ok(SrOutputs { u, r, boundary, enhance })
        })
    }
}
