//! GeometryNet: the residual trunk predicting the detail `R` over the cubic interpolation `U`
//! (align corners, ×r) of the LR geometry image; the estimate is `U + R`, the loss
//! `MSE(U + R, HR)` (paper Eq 3).

use super::config::{NetConfig, NetKind, IN_CHANNELS};
use super::layers::Trunk;
use crate::error::{Error, Result};
use crate::ops::conv2d::PackedConv;
use crate::ops::loss::DetailEnergy;
use crate::ops::{Interp, Ops};
use crate::tensor::Tensor;

#[derive(Clone, Debug, PartialEq)]
pub struct GeometryNet {
    pub trunk: Trunk,
}

/// Check that `x` is a batch of 3-channel geometry images; returns (N, H, W).
pub fn check_input(x: &Tensor, what: &str) -> Result<(usize, usize, usize)> {
    let (n, c, h, w) = x.expect_rank4(what)?;
    if c != IN_CHANNELS || n == 0 || h == 0 || w == 0 {
        return Err(Error::shape(format!(
            "{what}: expected (N, 3, H, W) with N, H, W > 0, got {:?}",
            x.shape
        )));
    }
    Ok((n, h, w))
}

/// `target` must be (N, channels, r·H, r·W) for an input (N, 3, H, W).
pub fn check_target(x: &Tensor, target: &Tensor, channels: usize, scale: usize, what: &str) -> Result<()> {
    let (n, h, w) = check_input(x, "input")?;
    let want = [n, channels, h * scale, w * scale];
    if target.shape != want {
        return Err(Error::shape(format!(
            "{what}: expected {want:?} for input {:?}, got {:?}",
            x.shape, target.shape
        )));
    }
    Ok(())
}

/// `U`: the LR batch (N, C, H, W) resized to (N, C, r·H, r·W) with `mode` (the net's
/// `config.upsample`), aligned corners.
pub fn interpolate(ops: &dyn Ops, lr: &Tensor, scale: usize, mode: Interp) -> Tensor {
    let (_, _, h, w) = lr.dims4();
    ops.resize(lr, h * scale, w * scale, mode)
}

impl GeometryNet {
    pub fn new(config: NetConfig, seed: u64) -> Self {
        GeometryNet { trunk: Trunk::init(NetKind::Geometry, config, seed) }
    }

    pub fn config(&self) -> NetConfig {
        self.trunk.config
    }

    /// lr (N, 3, H, W) → (U, R), both (N, 3, rH, rW). Inference: keeps no activations.
    pub fn forward(&self, ops: &dyn Ops, lr: &Tensor) -> Result<(Tensor, Tensor)> {
        self.forward_packed(ops, lr, None)
    }

    /// [`GeometryNet::forward`] with the trunk's weights packed in advance if given ([`Trunk::pack`]).
    pub fn forward_packed(
        &self,
        ops: &dyn Ops,
        lr: &Tensor,
        packed: Option<&[PackedConv]>,
    ) -> Result<(Tensor, Tensor)> {
        check_input(lr, "GeometryNet input")?;
        let u = interpolate(ops, lr, self.trunk.config.scale, self.trunk.config.upsample);
        let r = match packed {
            Some(p) => self.trunk.forward_packed(ops, lr, p),
            None => self.trunk.forward(ops, lr),
        };
        Ok((u, r))
    }

    /// `MSE(U + R, HR)` for a batch, with `U` given (e.g. cropped from a whole-frame
    /// interpolation, see `train::patches`); adds the parameter gradients into `grads` if given.
    pub fn loss(
        &self,
        ops: &dyn Ops,
        lr: &Tensor,
        u: &Tensor,
        hr: &Tensor,
        grads: Option<&mut Trunk>,
    ) -> Result<f32> {
        geometry_loss(ops, &self.trunk, lr, u, hr, GeometryLoss::default(), grads)
    }
}

/// Weights (dimensionless) of the terms GeometryNet's loss adds to the position MSE (Eq 3);
/// all 0 = Eq 3 alone. The terms are ops of the table (the CUDA table computes them on the
/// host).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GeometryLoss {
    /// Edge-vector term [`Ops::edge_mse`]: swimming edge lengths, noisy normals.
    pub edge: f32,
    /// Curvature term [`Ops::laplacian_mse`]: bumps and dents that show in shading.
    pub laplacian: f32,
    /// Edge-length term [`Ops::edge_length_mse`]: the in-plane shrinking of an averaged surface.
    pub length: f32,
    /// Wrinkle-energy term [`Ops::detail_energy_mse`]: the fold amplitude an averaged surface
    /// lacks, priced without asking for the folds' phase.
    pub detail: f32,
    /// Window and amplitude floor of the wrinkle-energy term.
    pub detail_params: DetailEnergy,
}

/// The loss of an HR estimate `est = U + R` against `hr`, and its gradient w.r.t. `est` (= the
/// gradient w.r.t. R): `mse + w.edge · edge_mse + w.laplacian · laplacian_mse
/// + w.length · edge_length_mse + w.detail · detail_energy_mse`. `lr_hw`: the (H, W) of the
/// LR input `est` was upsampled from (the wrinkle-energy term's high-pass).
pub fn estimate_loss(
    ops: &dyn Ops,
    est: &Tensor,
    hr: &Tensor,
    lr_hw: (usize, usize),
    w: GeometryLoss,
) -> (f32, Tensor) {
    let (mut loss, mut grad) = ops.mse(est, hr);
    // A term: its weight and the op computing it, called only for a weight other than 0.
    type Term<'a> = (f32, &'a dyn Fn() -> (f32, Tensor));
    let terms: [Term; 4] = [
        (w.edge, &|| ops.edge_mse(est, hr)),
        (w.laplacian, &|| ops.laplacian_mse(est, hr)),
        (w.length, &|| ops.edge_length_mse(est, hr)),
        (w.detail, &|| ops.detail_energy_mse(est, hr, lr_hw.0, lr_hw.1, w.detail_params)),
    ];
    for (weight, term) in terms {
        if weight != 0.0 {
            let (l, g) = term();
            loss += weight * l;
            for (d, e) in grad.data.iter_mut().zip(&g.data) {
                *d += weight * e;
            }
        }
    }
    (loss, grad)
}

/// [`GeometryNet::loss`] on a bare trunk (of kind Geometry).
///
/// `weights` adds the [`GeometryLoss`] terms of `U + R` against HR to the paper's MSE (Eq 3).
pub fn geometry_loss(
    ops: &dyn Ops,
    trunk: &Trunk,
    lr: &Tensor,
    u: &Tensor,
    hr: &Tensor,
    weights: GeometryLoss,
    grads: Option<&mut Trunk>,
) -> Result<f32> {
    let r = trunk.config.scale;
    check_target(lr, u, 3, r, "U")?;
    check_target(lr, hr, 3, r, "HR target")?;
    let (_, _, lr_h, lr_w) = lr.dims4();
    Ok(match grads {
        None => {
            let mut est = trunk.forward(ops, lr);
            ops.add_assign(&mut est, u);
            estimate_loss(ops, &est, hr, (lr_h, lr_w), weights).0
        }
        Some(g) => {
            let (mut est, tape) = trunk.forward_train(ops, lr);
            ops.add_assign(&mut est, u);
            let (loss, d_est) = estimate_loss(ops, &est, hr, (lr_h, lr_w), weights);
            drop(est);
            // d(U + R)/dR = identity; U is not trained.
            trunk.backward(ops, &tape, &d_est, g);
            loss
        }
    })
}
