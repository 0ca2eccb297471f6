//! The closed list of ops. Each op has a plain scalar reference `*_ref` (the spec) and a fast
//! path (SIMD via `wide` + threads via `rayon`) with the same signature; tests compare them.
//! Backward functions sit next to their forwards and ADD into gradient buffers (`+=`).
//!
//! [`Ops`] is the op table the networks and the trainer are written against: [`Cpu`] fills it
//! with the fast CPU kernels, [`RefOps`] with the scalar references (the tests, the audits),
//! `cuda::Cuda` (feature `cuda`) with GPU kernels. Shapes: NCHW activations, OIHW conv weights.

pub mod activation;
pub mod adam;
pub mod conv2d;
pub mod cpu;
pub mod loss;
pub mod pixel_shuffle;
pub mod precision;
pub mod reference;
pub mod resample;

pub use conv2d::Padding;
pub use precision::Precision;
pub use reference::RefOps;

use crate::tensor::Tensor;

/// Resampling kernels (all with align-corners semantics).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interp {
    Bilinear,
    /// Keys cubic convolution, a = −0.75 (PyTorch's), border samples clamped.
    Bicubic,
    /// Keys cubic convolution, a = −0.5 (Catmull-Rom), border samples clamped: reproduces
    /// evenly spaced samples exactly (away from the border), which a = −0.75 does not.
    CatmullRom,
}

impl Interp {
    /// Name in configs and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Interp::Bilinear => "bilinear",
            Interp::Bicubic => "bicubic",
            Interp::CatmullRom => "catmull-rom",
        }
    }

    pub fn parse(s: &str) -> Option<Interp> {
        [Interp::Bilinear, Interp::Bicubic, Interp::CatmullRom].into_iter().find(|m| m.name() == s)
    }
}

/// Adam hyper-parameters (paper: lr 1e-4).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdamParams {
    /// Learning rate (step size in parameter units).
    pub lr: f32,
    pub beta1: f32,
    pub beta2: f32,
    pub eps: f32,
}

impl Default for AdamParams {
    fn default() -> Self {
        AdamParams { lr: 1e-4, beta1: 0.9, beta2: 0.999, eps: 1e-8 }
    }
}

/// The op table. Every method has the contract of the CPU function of the same name.
pub trait Ops: Sync {
    fn name(&self) -> &'static str;
    /// x: (N, C, H, W), w: (O, C, KH, KW), b: (O) → y: (N, O, H, W); stride 1, "same" padding.
    fn conv2d(&self, x: &Tensor, w: &Tensor, b: Option<&Tensor>, pad: Padding) -> Tensor;
    /// [`Ops::conv2d`] with `packed` = [`conv2d::PackedConv::new`] of `w`, made once for many
    /// calls (inference), then the epilogue (`add_assign` of its skip, `relu`), fused where the
    /// table can. Default: `packed` is not used and the epilogue runs as the separate ops.
    fn conv2d_packed(
        &self,
        x: &Tensor,
        w: &Tensor,
        packed: &conv2d::PackedConv,
        b: Option<&Tensor>,
        pad: Padding,
        epi: conv2d::Epilogue,
    ) -> Tensor {
        let _ = packed;
        let mut y = self.conv2d(x, w, b, pad);
        if let Some(s) = epi.skip {
            self.add_assign(&mut y, s);
        }
        if epi.relu {
            y = self.relu(&y);
        }
        y
    }
    /// Adds into dx (if given), dw, db (if given).
    #[allow(clippy::too_many_arguments)]
    fn conv2d_backward(
        &self,
        x: &Tensor,
        w: &Tensor,
        dy: &Tensor,
        pad: Padding,
        dx: Option<&mut Tensor>,
        dw: &mut Tensor,
        db: Option<&mut Tensor>,
    );
    fn relu(&self, x: &Tensor) -> Tensor;
    /// dx += dy ⊙ [x > 0]
    fn relu_backward(&self, x: &Tensor, dy: &Tensor, dx: &mut Tensor);
    /// a += b (residual add; its backward is the identity on both inputs).
    fn add_assign(&self, a: &mut Tensor, b: &Tensor);
    /// (N, C·r², H, W) → (N, C, H·r, W·r), PyTorch's channel order.
    fn pixel_shuffle(&self, x: &Tensor, r: usize) -> Tensor;
    /// Inverse of pixel_shuffle (and its backward).
    fn pixel_unshuffle(&self, x: &Tensor, r: usize) -> Tensor;
    /// (N, C, H, W) → (N, C, out_h, out_w), align corners.
    fn resize(&self, x: &Tensor, out_h: usize, out_w: usize, mode: Interp) -> Tensor;
    /// Adds the gradient w.r.t. the input of `resize` into dx (N, C, in_h, in_w).
    fn resize_backward(&self, dy: &Tensor, mode: Interp, dx: &mut Tensor);
    fn sigmoid(&self, x: &Tensor) -> Tensor;
    /// Mean squared error and its gradient w.r.t. pred.
    fn mse(&self, pred: &Tensor, target: &Tensor) -> (f32, Tensor);
    /// Mean of −[w·t·log σ(z) + (1−t)·log(1−σ(z))] (stable form) and its gradient w.r.t. z.
    fn bce_with_logits(&self, logits: &Tensor, target: &Tensor, pos_weight: f32) -> (f32, Tensor);
    /// Edge-vector error of geometry images (GeometryNet's loss term) and its gradient w.r.t.
    /// pred: [`loss::edge_mse`]. pred, target: (N, C, H, W).
    fn edge_mse(&self, pred: &Tensor, target: &Tensor) -> (f32, Tensor);
    /// Edge-length error of geometry images (each pixel's C channels a point) and its gradient
    /// w.r.t. pred: [`loss::edge_length_mse`]. pred, target: (N, C, H, W).
    fn edge_length_mse(&self, pred: &Tensor, target: &Tensor) -> (f32, Tensor);
    /// Curvature (5-point Laplacian) error of geometry images and its gradient w.r.t. pred:
    /// [`loss::laplacian_mse`]. pred, target: (N, C, H, W).
    fn laplacian_mse(&self, pred: &Tensor, target: &Tensor) -> (f32, Tensor);
    /// Wrinkle-energy error beyond the (lr_h, lr_w) grid and its gradient w.r.t. pred:
    /// [`loss::detail_energy_mse`]. pred, target: (N, C, H, W) (C = 3 with `p.normal_only`).
    fn detail_energy_mse(
        &self,
        pred: &Tensor,
        target: &Tensor,
        lr_h: usize,
        lr_w: usize,
        p: loss::DetailEnergy,
    ) -> (f32, Tensor);
    /// One Adam step with bias correction; `step` counts from 1.
    #[allow(clippy::too_many_arguments)]
    fn adam_update(&self, p: &mut [f32], g: &[f32], m: &mut [f32], v: &mut [f32], step: u64, hp: &AdamParams);
    /// Runs `f`, a sequence of calls to this table, where they start cheapest. Default: here.
    /// [`Cpu`] runs it on a rayon worker thread: the serial parts of each op then run on a
    /// worker and the calling thread sleeps, instead of competing for the cores with workers
    /// that spin between parallel loops (≈ 10–20 % of a 32×32 frame's three nets on 2 cores).
    /// On a thread that is a worker already (the `anisocb` binary's main thread, see
    /// [`cpu::join_global_pool`]) it runs `f` in place.
    fn enter(&self, f: &mut (dyn FnMut() + Send)) {
        f()
    }
    /// The first failure of a device behind this table since the last call, if any (the
    /// methods have no error channel: a GPU table records a driver failure, returns NaN
    /// results from then on, and reports it here). Callers check it at batch boundaries
    /// ([`check_device`]). Default: none (the CPU cannot fail this way).
    fn take_error(&self) -> Option<crate::Error> {
        None
    }
    /// The CUDA table this is, if it is one: the device-resident paths that take a whole
    /// bundle at once ([`crate::cuda::nets_views`]) ask. Default: none.
    fn as_cuda(&self) -> Option<&crate::cuda::Cuda> {
        None
    }
    /// Whether nets run through this table may take the CPU kernels' chains, which run the
    /// trunks' inner convs themselves instead of through the table, activations kept in the
    /// kernels' own layout between convs: the bf16 tiles' ([`Precision::Bf16`]) and the fp32
    /// one ([`conv2d::chain`]). Only [`Cpu`]: another table (a GPU, a wrapper that counts or
    /// fails convs) gets every conv. Default: no.
    fn runs_chains(&self) -> bool {
        false
    }
}

/// `Err` with the device's failure if `ops` recorded one ([`Ops::take_error`]).
pub fn check_device(ops: &dyn Ops) -> crate::Result<()> {
    ops.take_error().map_or(Ok(()), Err)
}

/// `f()` through [`Ops::enter`], with its result.
pub fn entered<R: Send>(ops: &dyn Ops, f: impl FnOnce() -> R + Send) -> R {
    let (mut f, mut out) = (Some(f), None);
    ops.enter(&mut || out = f.take().map(|f| f()));
    out.expect("Ops::enter runs its closure once")
}

/// The CPU op table: the fast kernels of this module.
#[derive(Clone, Copy, Debug, Default)]
pub struct Cpu;
