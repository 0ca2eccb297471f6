//! Device-resident training of one trunk ([`DeviceTrainer`]): its parameters, gradients and
//! Adam moments live on the GPU for the whole run; a step uploads the batch (LR patches, U and
//! the target) and downloads the loss. The forward with its tape and the backward mirror
//! [`Trunk::forward_train`] and [`Trunk::backward`] op for op on the `*_dev` kernels of this
//! module (the same kernels as the op table, in the same order: `tests/cuda_parity.rs`).
//! GeometryNet's loss runs on the device with its edge-vector and edge-length terms
//! ([`Cuda::geometry_loss_dev`], the CPU's gradient to the bit); the Laplacian and
//! wrinkle-energy terms have no kernels: with a weight other than 0 for either, the estimate is
//! downloaded, the CPU computes the loss and its gradient, and the gradient is uploaded
//! ([`estimate_loss`]).
//!
//! Fewer launches than op for op, with the same bits: the ReLUs, the residual skips and U + R
//! are done in the conv stores ([`Epilogue`]), the ReLUs' backward in the input gradients'
//! stores (the ReLU's output is the mask: relu(t) > 0 exactly where t > 0), a skip's gradient
//! by accumulating the conv's input gradient into it, and Adam is one launch for every tensor
//! that also zeroes the gradients for the next step (`kernels/emu/check_kernels.py` checks
//! each fusion against the kernels it replaces, bit for bit).

use cudarc::driver::{CudaSlice, PinnedHostSlice};

use super::adam::AdamTable;
use super::conv2d::Epilogue;
use super::device::{Cuda, DResult, DevBuf};
use super::StepLoss;
use crate::nn::config::{NetConfig, NetKind};
use crate::nn::geometry_net::estimate_loss;
use crate::nn::layers::{layout, Layer, Trunk};
use crate::ops::{AdamParams, Cpu};
use crate::tensor::Tensor;
use crate::train::adam::Adam;

/// One trunk in training on the GPU (see the module docs).
pub struct DeviceTrainer<'a> {
    cuda: &'a Cuda,
    kind: NetKind,
    config: NetConfig,
    /// In [`Trunk::params`] order: conv i's weight at 2i, its bias at 2i + 1.
    params: Vec<DevBuf>,
    grads: Vec<DevBuf>,
    m: Vec<CudaSlice<f32>>,
    v: Vec<CudaSlice<f32>>,
    /// The addresses of `params`, `grads`, `m`, `v` (which never move while `self` lives).
    adam_table: AdamTable,
    /// Page-locked copies of a step's lr, u and target ([`Cuda::upload_staged`]): a step's
    /// uploads queue behind the previous step's backward instead of waiting for it.
    staging: [Option<PinnedHostSlice<f32>>; 3],
    step: u64,
    adam: AdamParams,
}

impl Drop for DeviceTrainer<'_> {
    fn drop(&mut self) {
        self.cuda.report_profile(&format!("training the {} net, {} steps", self.kind.name(), self.step));
    }
}

/// Activations a training forward keeps for its backward (as [`crate::nn::Tape`], without the
/// ReLUs' inputs: their outputs mask the gradients).
struct DevTape {
    input: DevBuf,
    /// Per block: its input a and relu(conv1(a)).
    blocks: Vec<[DevBuf; 2]>,
    upscale_in: DevBuf,
    /// Each tail conv's input: the pixel shuffle's output, then ReLU outputs.
    tail_in: Vec<DevBuf>,
}

impl<'a> DeviceTrainer<'a> {
    /// `trunk` and `adam` (its state for `trunk.params()`, e.g. from a checkpoint) uploaded.
    pub fn new(cuda: &'a Cuda, trunk: &Trunk, adam: &Adam) -> crate::Result<DeviceTrainer<'a>> {
        let up = || -> DResult<DeviceTrainer<'a>> {
            let params =
                trunk.params().into_iter().map(|(_, t)| cuda.upload(t)).collect::<DResult<Vec<_>>>()?;
            let grads = params.iter().map(|p| cuda.zeros(&p.shape)).collect::<DResult<Vec<_>>>()?;
            let m = adam.m.iter().map(|m| cuda.up(m)).collect::<DResult<Vec<_>>>()?;
            let v = adam.v.iter().map(|v| cuda.up(v)).collect::<DResult<Vec<_>>>()?;
            let adam_table = cuda.adam_table(&params, &grads, &m, &v)?;
            Ok(DeviceTrainer {
                cuda,
                kind: trunk.kind,
                config: trunk.config,
                params,
                grads,
                m,
                v,
                adam_table,
                staging: [None, None, None],
                step: adam.step,
                adam: adam.params,
            })
        };
        up().map_err(|e| {
            crate::Error::device(format!("CUDA: uploading the trunk for training failed: {e:?}"))
        })
    }

    /// One step on a batch: lr (N, 3, h, w), u and target (N, C, rh, rw) (u unused for a map
    /// net); the gradients, then Adam. Returns the loss (NaN after a driver failure, which the
    /// table records: [`crate::ops::Ops::take_error`]).
    pub fn step(&mut self, lr: &Tensor, u: &Tensor, target: &Tensor, loss: StepLoss) -> f32 {
        self.cuda.run("train step", || f32::NAN, || self.step_dev(lr, u, target, loss))
    }

    /// The loss of the current weights on a batch, without a step (validation).
    pub fn loss(&self, lr: &Tensor, u: &Tensor, target: &Tensor, loss: StepLoss) -> f32 {
        self.cuda.run(
            "validation loss",
            || f32::NAN,
            || {
                let c = self.cuda;
                let skip = skip_of(loss, || c.upload(u))?;
                let (y, _) = self.forward_train(c.upload(lr)?, skip.as_ref())?;
                Ok(self.loss_and_grad(y, lr, target, &c.upload(target)?, loss)?.0)
            },
        )
    }

    /// The loss of the output `y` (U + R for GeometryNet, logits for a map net) against the
    /// target (on the host and on the device) and its gradient.
    fn loss_and_grad(
        &self,
        y: DevBuf,
        lr: &Tensor,
        target: &Tensor,
        target_dev: &DevBuf,
        loss: StepLoss,
    ) -> DResult<(f32, DevBuf)> {
        let c = self.cuda;
        Ok(match loss {
            StepLoss::Geometry(w) => match c.geometry_loss_dev(&y, target_dev, w)? {
                Some(lg) => lg,
                None => {
                    let (_, _, h, wd) = lr.dims4();
                    let (l, g) = estimate_loss(&Cpu, &c.download(&y)?, target, (h, wd), w);
                    (l, c.upload(&g)?)
                }
            },
            StepLoss::Map { pos_weight } => c.bce_with_logits_dev(&y, target_dev, pos_weight)?,
        })
    }

    fn step_dev(&mut self, lr: &Tensor, u: &Tensor, target: &Tensor, loss: StepLoss) -> DResult<f32> {
        let c = self.cuda;
        c.mark(|| "host: the batch, the loop".into());
        let [s_lr, s_u, s_target] = &mut self.staging;
        let x = c.upload_staged(lr, s_lr)?;
        let skip = skip_of(loss, || c.upload_staged(u, s_u))?;
        let t = c.upload_staged(target, s_target)?;
        c.mark(|| "upload lr, u, target".into());
        let (y, tape) = self.forward_train(x, skip.as_ref())?;
        drop(skip);
        let (l, dy) = self.loss_and_grad(y, lr, target, &t, loss)?;
        c.mark(|| "loss (download the loss)".into());
        // The gradients are zero here: at the start, and after every Adam step.
        self.backward(&tape, &dy)?;
        self.step += 1;
        c.adam_update_all_dev(&self.adam_table, self.step, &self.adam)?;
        Ok(l)
    }

    /// Conv `l`'s (weight, bias) on the device.
    fn conv(&self, l: Layer) -> (&DevBuf, &DevBuf) {
        let i = l.index(self.config.blocks);
        (&self.params[2 * i], &self.params[2 * i + 1])
    }

    fn conv_fwd(&self, l: Layer, x: &DevBuf, epi: Epilogue) -> DResult<DevBuf> {
        let (w, b) = self.conv(l);
        self.cuda.conv2d_epi_dev(x, w, Some(b), self.config.padding, epi)
    }

    /// Adds conv `l`'s gradients for input `x` and output gradient `dy`; into `dx` if given,
    /// masked where `x` is a ReLU's output (`relu_out`).
    fn conv_bwd(
        &mut self,
        l: Layer,
        x: &DevBuf,
        dy: &DevBuf,
        dx: Option<&mut DevBuf>,
        relu_out: bool,
    ) -> DResult<()> {
        let i = l.index(self.config.blocks);
        let (dw, db) = self.grads[2 * i..2 * i + 2].split_at_mut(1);
        self.cuda.conv2d_backward_dev(
            x,
            &self.params[2 * i],
            dy,
            self.config.padding,
            dx,
            relu_out.then_some(x),
            &mut dw[0],
            Some(&mut db[0]),
        )
    }

    /// [`Trunk::forward_train`] on the device; `skip` (the output's shape) is added to the
    /// last conv's output.
    fn forward_train(&self, x: DevBuf, skip: Option<&DevBuf>) -> DResult<(DevBuf, DevTape)> {
        let c = self.cuda;
        let mut a = self.conv_fwd(Layer::ConvIn, &x, Epilogue::None)?;
        let mut blocks = Vec::with_capacity(self.config.blocks);
        for k in 0..self.config.blocks {
            let r1 = self.conv_fwd(Layer::Conv1(k), &a, Epilogue::Relu)?;
            let epi = if self.kind.residual() { Epilogue::Add(&a) } else { Epilogue::None };
            let out = self.conv_fwd(Layer::Conv2(k), &r1, epi)?;
            blocks.push([std::mem::replace(&mut a, out), r1]);
        }
        let u = self.conv_fwd(Layer::Upscale, &a, Epilogue::None)?;
        let mut z = c.pixel_shuffle_dev(&u, self.config.scale)?;
        drop(u);
        let tails = layout(self.kind, self.config).len() - Layer::Upscale.index(self.config.blocks) - 1;
        let mut tail_in = Vec::with_capacity(tails);
        for i in 0..tails {
            if i + 1 == tails {
                let y = self.conv_fwd(Layer::Tail(i), &z, skip.map_or(Epilogue::None, Epilogue::Add))?;
                tail_in.push(z);
                return Ok((y, DevTape { input: x, blocks, upscale_in: a, tail_in }));
            }
            let r = self.conv_fwd(Layer::Tail(i), &z, Epilogue::Relu)?;
            tail_in.push(std::mem::replace(&mut z, r));
        }
        unreachable!("a trunk has tail convs")
    }

    /// [`Trunk::backward`] on the device: adds every parameter's gradient into `self.grads`.
    fn backward(&mut self, tape: &DevTape, dy: &DevBuf) -> DResult<()> {
        let c = self.cuda;
        // The gradient of each tail conv's output, from the last back; tail_in[i > 0] is a
        // ReLU's output, so its gradient comes masked (the ReLU's input's gradient).
        let mut dz: Option<DevBuf> = None;
        for i in (0..tape.tail_in.len()).rev() {
            let mut dzin = c.zeros(&tape.tail_in[i].shape)?;
            self.conv_bwd(
                Layer::Tail(i),
                &tape.tail_in[i],
                dz.as_ref().unwrap_or(dy),
                Some(&mut dzin),
                i > 0,
            )?;
            dz = Some(dzin);
        }
        let dz = dz.expect("a trunk has tail convs");
        let du = c.pixel_unshuffle_dev(&dz, self.config.scale)?;
        drop(dz);
        let mut da = c.zeros(&tape.upscale_in.shape)?;
        self.conv_bwd(Layer::Upscale, &tape.upscale_in, &du, Some(&mut da), false)?;
        drop(du);
        for k in (0..self.config.blocks).rev() {
            let [a_in, r1] = &tape.blocks[k];
            let mut dt1 = c.zeros(&r1.shape)?;
            self.conv_bwd(Layer::Conv2(k), r1, &da, Some(&mut dt1), true)?;
            // The skip's gradient is da itself: conv1's input gradient is added into it.
            let mut da_in = if self.kind.residual() { da } else { c.zeros(&a_in.shape)? };
            self.conv_bwd(Layer::Conv1(k), a_in, &dt1, Some(&mut da_in), false)?;
            da = da_in;
        }
        self.conv_bwd(Layer::ConvIn, &tape.input, &da, None, false)
    }

    /// The parameters and Adam's state back into `trunk` and `adam` (for a checkpoint, a
    /// validation pass, the weights file).
    pub fn store(&self, trunk: &mut Trunk, adam: &mut Adam) -> crate::Result<()> {
        let c = self.cuda;
        let mut down = || -> DResult<()> {
            for (t, d) in trunk.params_mut().into_iter().zip(&self.params) {
                t.data.copy_from_slice(&c.down(&d.buf, d.len())?);
            }
            for (h, d) in adam.m.iter_mut().zip(&self.m).chain(adam.v.iter_mut().zip(&self.v)) {
                let n = h.len();
                h.copy_from_slice(&c.down(d, n)?);
            }
            Ok(())
        };
        c.run("train store", || Err(()), || down().map(Ok)).map_err(|_| {
            c.take_failure().unwrap_or_else(|| crate::Error::device("CUDA: downloading the trunk failed"))
        })?;
        adam.step = self.step;
        Ok(())
    }
}

/// What the last conv adds to its output: U for GeometryNet (its estimate is U + R), uploaded
/// by `up`; nothing for a map net.
fn skip_of(loss: StepLoss, up: impl FnOnce() -> DResult<DevBuf>) -> DResult<Option<DevBuf>> {
    match loss {
        StepLoss::Geometry(_) => up().map(Some),
        StepLoss::Map { .. } => Ok(None),
    }
}
