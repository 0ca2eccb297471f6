//! BoundaryNet and EnhanceNet: the plain trunk (no residual skips) ending in one channel of
//! logits `z`; the map is `Γ = σ(z)` and the loss the mean sigmoid binary cross-entropy
//!
//! `ℓ = −mean[ w·t·log σ(z) + (1 − t)·log(1 − σ(z)) ]`  (paper Eq 10, 11),
//!
//! where `w` (`pos_weight`, PyTorch's `BCEWithLogitsLoss(pos_weight=…)`) up-weights the rare
//! positive pixels. `w = 1` (the default) keeps `Γ` a calibrated probability, which the
//! composition `(1 − Γb)(1 + ηΓe)R` expects; `w > 1` trades calibration for recall.

use super::config::{NetConfig, NetKind};
use super::geometry_net::{check_input, check_target};
use super::layers::Trunk;
use crate::error::{Error, Result};
use crate::ops::conv2d::PackedConv;
use crate::ops::Ops;
use crate::tensor::Tensor;

#[derive(Clone, Debug, PartialEq)]
pub struct MapNet {
    pub trunk: Trunk,
}

impl MapNet {
    /// `kind` is [`NetKind::Boundary`] or [`NetKind::Enhance`].
    pub fn new(kind: NetKind, config: NetConfig, seed: u64) -> Result<Self> {
        if kind == NetKind::Geometry {
            return Err(Error::config("MapNet is BoundaryNet or EnhanceNet, not GeometryNet"));
        }
        Ok(MapNet { trunk: Trunk::init(kind, config, seed) })
    }

    pub fn kind(&self) -> NetKind {
        self.trunk.kind
    }

    /// A map net that marks nothing: every weight and bias zero but the last conv's bias,
    /// `logit` (Γ = σ(logit) everywhere). `bundle --boundary none` writes one beside a
    /// GeometryNet distilled from a whole bundle, whose residual is already gated; it is never
    /// run ([`MapNet::constant_logit`]).
    pub fn constant(kind: NetKind, config: NetConfig, logit: f32) -> Result<Self> {
        let mut net = MapNet::new(kind, config, 0)?;
        net.trunk.params_mut().into_iter().for_each(|t| t.data.iter_mut().for_each(|v| *v = 0.0));
        net.trunk.tail.last_mut().expect("a trunk ends in a tail conv").bias.data[0] = logit;
        Ok(net)
    }

    /// The last conv's bias where that conv's weights are all zero: the logits are then that
    /// value at every pixel whatever the input (finite, as [`check_input`] requires), and the
    /// trunk need not run to know them.
    pub fn constant_logit(&self) -> Option<f32> {
        let last = self.trunk.tail.last()?;
        last.weight.data.iter().all(|&w| w == 0.0).then(|| last.bias.data[0])
    }

    /// lr (N, 3, H, W) → logits (N, 1, rH, rW).
    pub fn logits(&self, ops: &dyn Ops, lr: &Tensor) -> Result<Tensor> {
        check_input(lr, "map net input")?;
        if let Some(z) = self.constant_logit() {
            let (n, _, h, w) = lr.dims4();
            let r = self.trunk.config.scale;
            return Ok(Tensor::full(&[n, 1, r * h, r * w], z));
        }
        Ok(self.trunk.forward(ops, lr))
    }

    /// lr (N, 3, H, W) → Γ = σ(logits) (N, 1, rH, rW), probabilities in [0, 1].
    pub fn probabilities(&self, ops: &dyn Ops, lr: &Tensor) -> Result<Tensor> {
        Ok(ops.sigmoid(&self.logits(ops, lr)?))
    }

    /// [`MapNet::probabilities`] with the trunk's weights packed in advance if given
    /// ([`Trunk::pack`]).
    pub fn probabilities_packed(
        &self,
        ops: &dyn Ops,
        lr: &Tensor,
        packed: Option<&[PackedConv]>,
    ) -> Result<Tensor> {
        match packed {
            Some(_) if self.constant_logit().is_some() => self.probabilities(ops, lr),
            Some(p) => {
                check_input(lr, "map net input")?;
                Ok(ops.sigmoid(&self.trunk.forward_packed(ops, lr, p)))
            }
            None => self.probabilities(ops, lr),
        }
    }

    /// Mean BCE against `target` (N, 1, rH, rW) in [0, 1]; adds gradients into `grads` if given.
    pub fn loss(
        &self,
        ops: &dyn Ops,
        lr: &Tensor,
        target: &Tensor,
        pos_weight: f32,
        grads: Option<&mut Trunk>,
    ) -> Result<f32> {
        map_loss(ops, &self.trunk, lr, target, pos_weight, grads)
    }
}

/// [`MapNet::loss`] on a bare trunk (of kind Boundary or Enhance).
pub fn map_loss(
    ops: &dyn Ops,
    trunk: &Trunk,
    lr: &Tensor,
    target: &Tensor,
    pos_weight: f32,
    grads: Option<&mut Trunk>,
) -> Result<f32> {
    check_target(lr, target, 1, trunk.config.scale, "map target")?;
    if !(pos_weight.is_finite() && pos_weight > 0.0) {
        return Err(Error::config(format!("pos_weight must be > 0, got {pos_weight}")));
    }
    Ok(match grads {
        None => ops.bce_with_logits(&trunk.forward(ops, lr), target, pos_weight).0,
        Some(g) => {
            let (z, tape) = trunk.forward_train(ops, lr);
            let (loss, dz) = ops.bce_with_logits(&z, target, pos_weight);
            drop(z);
            trunk.backward(ops, &tape, &dz, g);
            loss
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ops::Cpu;

    /// A map net whose last conv has zero weights is not run, and gives the bits running it
    /// would: σ(bias) at every pixel, packed or not.
    #[test]
    fn a_constant_map_net_is_skipped_with_the_bits_of_running_it() {
        let config = NetConfig::tiny();
        let lr =
            Tensor { shape: [2, 3, 5, 7].into(), data: (0..210).map(|i| (i as f32 * 0.61).cos()).collect() };
        let net = MapNet::constant(NetKind::Boundary, config, -2.5).unwrap();
        assert_eq!(net.constant_logit(), Some(-2.5));
        let ran = Cpu.sigmoid(&net.trunk.forward(&Cpu, &lr));
        let packed = net.trunk.pack(crate::ops::Precision::Fp32);
        for got in [
            net.probabilities(&Cpu, &lr).unwrap(),
            net.probabilities_packed(&Cpu, &lr, Some(&packed)).unwrap(),
        ] {
            assert_eq!(got.shape, ran.shape);
            assert!(got.data.iter().zip(&ran.data).all(|(a, b)| a.to_bits() == b.to_bits()));
        }
        // A trained net (random weights here) is run.
        assert_eq!(MapNet::new(NetKind::Boundary, config, 1).unwrap().constant_logit(), None);
    }
}
