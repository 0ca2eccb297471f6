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

use cudarc::driver::CudaSlice;

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
    step: u64,
    adam: AdamParams,
}

impl Drop for DeviceTrainer<'_> {
    fn drop(&mut self) {
        self.cuda.report_profile(&format!("training the {} net, {} steps", self.kind.name(), self.step));
    }
}

/// Activations a training forward keeps for its backward (as [`crate::nn::Tape`]).
struct DevTape {
    input: DevBuf,
    blocks: Vec<[DevBuf; 3]>,
    upscale_in: DevBuf,
    tail_in: Vec<DevBuf>,
    tail_pre: Vec<DevBuf>,
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
            Ok(DeviceTrainer {
                cuda,
                kind: trunk.kind,
                config: trunk.config,
                params,
                grads,
                m,
                v,
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
                let (y, _) = self.forward_train(self.cuda.upload(lr)?)?;
                Ok(self.loss_and_grad(y, lr, u, target, loss)?.0)
            },
        )
    }

    /// The loss of the output `y` (R for GeometryNet, logits for a map net) and its gradient.
    fn loss_and_grad(
        &self,
        mut y: DevBuf,
        lr: &Tensor,
        u: &Tensor,
        target: &Tensor,
        loss: StepLoss,
    ) -> DResult<(f32, DevBuf)> {
        let c = self.cuda;
        Ok(match loss {
            StepLoss::Geometry(w) => {
                c.add_assign_dev(&mut y, &c.upload(u)?)?;
                match c.geometry_loss_dev(&y, &c.upload(target)?, w)? {
                    Some(lg) => lg,
                    None => {
                        let (_, _, h, wd) = lr.dims4();
                        let (l, g) = estimate_loss(&Cpu, &c.download(&y)?, target, (h, wd), w);
                        (l, c.upload(&g)?)
                    }
                }
            }
            StepLoss::Map { pos_weight } => c.bce_with_logits_dev(&y, &c.upload(target)?, pos_weight)?,
        })
    }

    fn step_dev(&mut self, lr: &Tensor, u: &Tensor, target: &Tensor, loss: StepLoss) -> DResult<f32> {
        let c = self.cuda;
        c.mark(|| "host: the batch, the loop".into());
        for g in &mut self.grads {
            c.stream.memset_zeros(&mut g.buf)?;
        }
        c.mark(|| "zero the gradients".into());
        let x = c.upload(lr)?;
        c.mark(|| "upload lr".into());
        let (y, tape) = self.forward_train(x)?;
        let (l, dy) = self.loss_and_grad(y, lr, u, target, loss)?;
        c.mark(|| "loss (upload u, target; download the loss)".into());
        self.backward(&tape, &dy)?;
        self.step += 1;
        for i in 0..self.params.len() {
            let n = self.params[i].len();
            c.adam_update_dev(
                &mut self.params[i].buf,
                &self.grads[i].buf,
                &mut self.m[i],
                &mut self.v[i],
                n,
                self.step,
                &self.adam,
            )?;
        }
        c.mark(|| "adam".into());
        Ok(l)
    }

    /// Conv `l`'s (weight, bias) on the device.
    fn conv(&self, l: Layer) -> (&DevBuf, &DevBuf) {
        let i = l.index(self.config.blocks);
        (&self.params[2 * i], &self.params[2 * i + 1])
    }

    fn conv_fwd(&self, l: Layer, x: &DevBuf) -> DResult<DevBuf> {
        let (w, b) = self.conv(l);
        self.cuda.conv2d_dev(x, w, Some(b), self.config.padding)
    }

    /// Adds conv `l`'s gradients for input `x` and output gradient `dy`; into `dx` if given.
    fn conv_bwd(&mut self, l: Layer, x: &DevBuf, dy: &DevBuf, dx: Option<&mut DevBuf>) -> DResult<()> {
        let i = l.index(self.config.blocks);
        let (dw, db) = self.grads[2 * i..2 * i + 2].split_at_mut(1);
        self.cuda.conv2d_backward_dev(
            x,
            &self.params[2 * i],
            dy,
            self.config.padding,
            dx,
            &mut dw[0],
            Some(&mut db[0]),
        )
    }

    /// [`Trunk::forward_train`] on the device.
    fn forward_train(&self, x: DevBuf) -> DResult<(DevBuf, DevTape)> {
        let c = self.cuda;
        let mut a = self.conv_fwd(Layer::ConvIn, &x)?;
        let mut blocks = Vec::with_capacity(self.config.blocks);
        for k in 0..self.config.blocks {
            let t1 = self.conv_fwd(Layer::Conv1(k), &a)?;
            let r1 = c.relu_dev(&t1)?;
            let mut out = self.conv_fwd(Layer::Conv2(k), &r1)?;
            if self.kind.residual() {
                c.add_assign_dev(&mut out, &a)?;
            }
            blocks.push([std::mem::replace(&mut a, out), t1, r1]);
        }
        let u = self.conv_fwd(Layer::Upscale, &a)?;
        let mut z = c.pixel_shuffle_dev(&u, self.config.scale)?;
        drop(u);
        let tails = layout(self.kind, self.config).len() - Layer::Upscale.index(self.config.blocks) - 1;
        let (mut tail_in, mut tail_pre) = (Vec::with_capacity(tails), Vec::with_capacity(tails));
        for i in 0..tails {
            let y = self.conv_fwd(Layer::Tail(i), &z)?;
            if i + 1 == tails {
                tail_in.push(z);
                return Ok((y, DevTape { input: x, blocks, upscale_in: a, tail_in, tail_pre }));
            }
            let r = c.relu_dev(&y)?;
            tail_in.push(std::mem::replace(&mut z, r));
            tail_pre.push(y);
        }
        unreachable!("a trunk has tail convs")
    }

    /// [`Trunk::backward`] on the device: adds every parameter's gradient into `self.grads`.
    fn backward(&mut self, tape: &DevTape, dy: &DevBuf) -> DResult<()> {
        let c = self.cuda;
        let last = tape.tail_in.len() - 1;
        let mut dz = c.zeros(&tape.tail_in[last].shape)?;
        self.conv_bwd(Layer::Tail(last), &tape.tail_in[last], dy, Some(&mut dz))?;
        for i in (0..last).rev() {
            let mut dpre = c.zeros(&dz.shape)?;
            c.relu_backward_dev(&tape.tail_pre[i], &dz, &mut dpre)?;
            let mut dzin = c.zeros(&tape.tail_in[i].shape)?;
            self.conv_bwd(Layer::Tail(i), &tape.tail_in[i], &dpre, Some(&mut dzin))?;
            dz = dzin;
        }
        let du = c.pixel_unshuffle_dev(&dz, self.config.scale)?;
        drop(dz);
        let mut da = c.zeros(&tape.upscale_in.shape)?;
        self.conv_bwd(Layer::Upscale, &tape.upscale_in, &du, Some(&mut da))?;
        drop(du);
        for k in (0..self.config.blocks).rev() {
            let [a_in, t1, r1] = &tape.blocks[k];
            let mut dr1 = c.zeros(&r1.shape)?;
            self.conv_bwd(Layer::Conv2(k), r1, &da, Some(&mut dr1))?;
            let mut dt1 = c.zeros(&t1.shape)?;
            c.relu_backward_dev(t1, &dr1, &mut dt1)?;
            drop(dr1);
            let mut da_in = c.zeros(&a_in.shape)?;
            self.conv_bwd(Layer::Conv1(k), a_in, &dt1, Some(&mut da_in))?;
            if self.kind.residual() {
                c.add_assign_dev(&mut da_in, &da)?;
            }
            da = da_in;
        }
        self.conv_bwd(Layer::ConvIn, &tape.input, &da, None)
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
