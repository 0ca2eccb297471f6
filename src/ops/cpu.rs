//! [`Cpu`]: the op table filled with this module's fast CPU kernels.

use super::{activation, adam, conv2d, loss, pixel_shuffle, resample};
use super::{AdamParams, Cpu, Interp, Ops, Padding};
use crate::tensor::Tensor;

/// Builds rayon's global pool with the calling thread as its worker 0 and `threads` threads in
/// all (0: one per core), as ONNX Runtime runs its intra-op work on the caller plus N − 1
/// threads. Ops called from that thread then split their loops across the pool without handing
/// the call to another thread and sleeping until it returns: a 32→32 3×3 conv on one 32×32
/// image went 40 → 36 µs per call (`ops::entered` already on a worker; 71 → 36 µs without it),
/// 2-core machine. Call it once, first thing, from a thread that lives as long as the process
/// (the `anisocb` binary's main thread; not a test thread, which ends before its process).
/// Fails if the global pool was already built.
pub fn join_global_pool(threads: usize) -> Result<(), rayon::ThreadPoolBuildError> {
    rayon::ThreadPoolBuilder::new().num_threads(threads).use_current_thread().build_global()
}

impl Ops for Cpu {
    fn name(&self) -> &'static str {
        "cpu"
    }
    fn runs_chains(&self) -> bool {
        true
    }
    fn conv2d(&self, x: &Tensor, w: &Tensor, b: Option<&Tensor>, pad: Padding) -> Tensor {
        conv2d::conv2d(x, w, b, pad)
    }
    fn conv2d_packed(
        &self,
        x: &Tensor,
        w: &Tensor,
        packed: &conv2d::PackedConv,
        b: Option<&Tensor>,
        pad: Padding,
        epi: conv2d::Epilogue,
    ) -> Tensor {
        assert_eq!(packed.shape().as_slice(), &w.shape[..], "conv2d: weights packed from another shape");
        conv2d::conv2d_packed(x, packed, b, pad, epi)
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
        conv2d::conv2d_backward(x, w, dy, pad, dx, dw, db)
    }
    fn relu(&self, x: &Tensor) -> Tensor {
        activation::relu(x)
    }
    fn relu_backward(&self, x: &Tensor, dy: &Tensor, dx: &mut Tensor) {
        activation::relu_backward(x, dy, dx)
    }
    fn add_assign(&self, a: &mut Tensor, b: &Tensor) {
        activation::add_assign(a, b)
    }
    fn pixel_shuffle(&self, x: &Tensor, r: usize) -> Tensor {
        pixel_shuffle::pixel_shuffle(x, r)
    }
    fn pixel_unshuffle(&self, x: &Tensor, r: usize) -> Tensor {
        pixel_shuffle::pixel_unshuffle(x, r)
    }
    fn resize(&self, x: &Tensor, out_h: usize, out_w: usize, mode: Interp) -> Tensor {
        resample::resize(x, out_h, out_w, mode)
    }
    fn resize_backward(&self, dy: &Tensor, mode: Interp, dx: &mut Tensor) {
        resample::resize_backward(dy, mode, dx)
    }
    fn sigmoid(&self, x: &Tensor) -> Tensor {
        activation::sigmoid(x)
    }
    fn mse(&self, pred: &Tensor, target: &Tensor) -> (f32, Tensor) {
        loss::mse(pred, target)
    }
    fn bce_with_logits(&self, logits: &Tensor, target: &Tensor, pos_weight: f32) -> (f32, Tensor) {
        loss::bce_with_logits(logits, target, pos_weight)
    }
    fn edge_mse(&self, pred: &Tensor, target: &Tensor) -> (f32, Tensor) {
        loss::edge_mse(pred, target)
    }
    fn edge_length_mse(&self, pred: &Tensor, target: &Tensor) -> (f32, Tensor) {
        loss::edge_length_mse(pred, target)
    }
    fn laplacian_mse(&self, pred: &Tensor, target: &Tensor) -> (f32, Tensor) {
        loss::laplacian_mse(pred, target)
    }
    fn detail_energy_mse(
        &self,
        pred: &Tensor,
        target: &Tensor,
        lr_h: usize,
        lr_w: usize,
        p: loss::DetailEnergy,
    ) -> (f32, Tensor) {
        loss::detail_energy_mse(pred, target, lr_h, lr_w, p)
    }
    fn enter(&self, f: &mut (dyn FnMut() + Send)) {
        // From a non-worker thread, rayon::scope hands the closure to the pool and blocks.
        rayon::scope(|_| f())
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
        adam::adam_update(p, g, m, v, step, hp)
    }
}
