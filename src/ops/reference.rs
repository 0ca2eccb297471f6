//! [`RefOps`]: the op table filled with the scalar `*_ref` functions, the specs of the ops.
//!
//! One table for everything that runs a net, a loss or a training step on the specs: the
//! audits against the JAX fixtures (`tests/ops_audit.rs`, `tests/losses_audit.rs`) check it
//! beside [`Cpu`](super::Cpu), and `tests/ops_audit.rs` checks that the two tables agree on
//! every op at random odd shapes. Slow (plain loops, one thread): not for production.

use super::{activation, adam, conv2d, loss, pixel_shuffle, resample};
use super::{AdamParams, Interp, Ops, Padding};
use crate::tensor::Tensor;

/// The op table of the scalar references. `conv2d_packed` keeps the trait's default (the
/// packed weights unused, the epilogue as separate ops), `enter` runs in place.
#[derive(Clone, Copy, Debug, Default)]
pub struct RefOps;

impl Ops for RefOps {
    fn name(&self) -> &'static str {
        "ref"
    }
    fn conv2d(&self, x: &Tensor, w: &Tensor, b: Option<&Tensor>, pad: Padding) -> Tensor {
        conv2d::conv2d_ref(x, w, b, pad)
    }
    fn conv2d_backward(
        &self,
        x: &Tensor,
        w: &Tensor,
        dy: &Tensor,
        pad: Padding,
        dx: Option<&mut Tensor>,
        dw: &mut Tensor,
        db: Option<&mut Tensor>,
    ) {
        conv2d::conv2d_backward_ref(x, w, dy, pad, dx, dw, db)
    }
    fn relu(&self, x: &Tensor) -> Tensor {
        activation::relu_ref(x)
    }
    fn relu_backward(&self, x: &Tensor, dy: &Tensor, dx: &mut Tensor) {
        activation::relu_backward_ref(x, dy, dx)
    }
    fn add_assign(&self, a: &mut Tensor, b: &Tensor) {
        activation::add_assign_ref(a, b)
    }
    fn pixel_shuffle(&self, x: &Tensor, r: usize) -> Tensor {
        pixel_shuffle::pixel_shuffle_ref(x, r)
    }
    fn pixel_unshuffle(&self, x: &Tensor, r: usize) -> Tensor {
        pixel_shuffle::pixel_unshuffle_ref(x, r)
    }
    fn resize(&self, x: &Tensor, out_h: usize, out_w: usize, mode: Interp) -> Tensor {
        resample::resize_ref(x, out_h, out_w, mode)
    }
    fn resize_backward(&self, dy: &Tensor, mode: Interp, dx: &mut Tensor) {
        resample::resize_backward_ref(dy, mode, dx)
    }
    fn sigmoid(&self, x: &Tensor) -> Tensor {
        activation::sigmoid_ref(x)
    }
    fn mse(&self, pred: &Tensor, target: &Tensor) -> (f32, Tensor) {
        loss::mse_ref(pred, target)
    }
    fn bce_with_logits(&self, logits: &Tensor, target: &Tensor, pos_weight: f32) -> (f32, Tensor) {
        loss::bce_with_logits_ref(logits, target, pos_weight)
    }
    fn edge_mse(&self, pred: &Tensor, target: &Tensor) -> (f32, Tensor) {
        loss::edge_mse_ref(pred, target)
    }
    fn edge_length_mse(&self, pred: &Tensor, target: &Tensor) -> (f32, Tensor) {
        loss::edge_length_mse_ref(pred, target)
    }
    fn laplacian_mse(&self, pred: &Tensor, target: &Tensor) -> (f32, Tensor) {
        loss::laplacian_mse_ref(pred, target)
    }
    fn detail_energy_mse(
        &self,
        pred: &Tensor,
        target: &Tensor,
        lr_h: usize,
        lr_w: usize,
        p: loss::DetailEnergy,
    ) -> (f32, Tensor) {
        loss::detail_energy_mse_ref(pred, target, lr_h, lr_w, p)
    }
    fn adam_update(
        &self,
        p: &mut [f32],
        g: &[f32],
        m: &mut [f32],
        v: &mut [f32],
        step: u64,
        hp: &AdamParams,
    ) {
        adam::adam_update_ref(p, g, m, v, step, hp)
    }
}
