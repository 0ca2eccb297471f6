//! `kernels/loss.cu` on device buffers: MSE, BCE-with-logits and GeometryNet's loss, each the
//! mean loss (f64 partial sums per block, summed in order on the host) and its gradient.

use cudarc::driver::{CudaFunction, PushKernelArg};

use super::device::{dims4, grid1, Cuda, DResult, DevBuf};
use crate::nn::geometry_net::GeometryLoss;
use crate::tensor::Tensor;

impl Cuda {
    /// A loss kernel `(pred, target, grad, part, n, nf, [pos_weight])`: (mean loss, gradient).
    fn loss_dev(
        &self,
        f: &CudaFunction,
        p: &DevBuf,
        t: &DevBuf,
        pos_weight: Option<f32>,
    ) -> DResult<(f32, DevBuf)> {
        let n = p.len();
        let mut g = self.zeros(&p.shape)?;
        if n == 0 {
            return Ok((0.0, g));
        }
        let cfg = grid1(n);
        let blocks = cfg.grid_dim.0 as usize;
        let mut part = self.stream.alloc_zeros::<f64>(blocks)?;
        let (nn, nf) = (n as i64, n as f32);
        let pw = pos_weight.unwrap_or(1.0);
        let mut l = self.stream.launch_builder(f);
        l.arg(&p.buf).arg(&t.buf).arg(&mut g.buf).arg(&mut part).arg(&nn).arg(&nf);
        if pos_weight.is_some() {
            l.arg(&pw);
        }
        // SAFETY: matches mse_loss / bce_logits_loss; part holds one double per block, 256 threads.
        unsafe { l.launch(cfg) }?;
        let sum: f64 = self.down(&part, blocks)?.iter().sum();
        Ok(((sum / n as f64) as f32, g))
    }

    pub fn mse_dev(&self, pred: &DevBuf, target: &DevBuf) -> DResult<(f32, DevBuf)> {
        assert_eq!(pred.shape, target.shape, "mse: prediction {:?} vs target {:?}", pred.shape, target.shape);
        self.loss_dev(&self.k.mse_loss, pred, target, None)
    }

    pub fn bce_with_logits_dev(
        &self,
        z: &DevBuf,
        target: &DevBuf,
        pos_weight: f32,
    ) -> DResult<(f32, DevBuf)> {
        assert_eq!(
            z.shape, target.shape,
            "bce_with_logits: prediction {:?} vs target {:?}",
            z.shape, target.shape
        );
        self.loss_dev(&self.k.bce_logits_loss, z, target, Some(pos_weight))
    }

    /// GeometryNet's loss of the estimate `est` = U + R (N, C, H, W) against `target` and its
    /// gradient, as [`crate::nn::geometry_net::estimate_loss`] computes them (the gradient to
    /// the bit: the kernel gathers each term in the order the CPU scatters it); `None` where
    /// `w` has a term without a kernel (the Laplacian, the wrinkle energy).
    pub fn geometry_loss_dev(
        &self,
        est: &DevBuf,
        target: &DevBuf,
        w: GeometryLoss,
    ) -> DResult<Option<(f32, DevBuf)>> {
        if w.laplacian != 0.0 || w.detail != 0.0 {
            return Ok(None);
        }
        assert_eq!(
            est.shape, target.shape,
            "geometry loss: estimate {:?} vs target {:?}",
            est.shape, target.shape
        );
        let [n, c, h, wd] = dims4(&est.shape, "geometry loss estimate");
        let mut g = self.zeros(&est.shape)?;
        let pixels = n * h * wd;
        // The counts of `ops::loss`: elements, edges per channel, edges.
        let edges = n * (h * wd.saturating_sub(1) + h.saturating_sub(1) * wd);
        let (elements, edge_count, len_count) = (est.len().max(1), (c * edges).max(1), edges.max(1));
        if pixels == 0 || c == 0 {
            return Ok(Some((0.0, g)));
        }
        let cfg = grid1(pixels);
        let blocks = cfg.grid_dim.0 as usize;
        let mut part = self.stream.alloc_zeros::<f64>(3 * blocks)?;
        let (ni, ci, hi, wi) = (n as i32, c as i32, h as i32, wd as i32);
        let (nf, ef, ls) = (elements as f32, edge_count as f32, 2.0 / len_count as f32);
        let _ = super::device::i32_of(est.len(), "geometry loss size");
        let mut l = self.stream.launch_builder(&self.k.geometry_loss);
        l.arg(&est.buf).arg(&target.buf).arg(&mut g.buf).arg(&mut part);
        l.arg(&ni).arg(&ci).arg(&hi).arg(&wi).arg(&nf).arg(&ef).arg(&ls).arg(&w.edge).arg(&w.length);
        // SAFETY: matches geometry_loss; part holds three doubles per block, 256 threads.
        unsafe { l.launch(cfg) }?;
        let sums = self.down(&part, 3 * blocks)?;
        let sum = |t: usize| -> f64 { sums[t * blocks..(t + 1) * blocks].iter().sum() };
        // The terms as estimate_loss adds them (f32, in this order, each only where weighted).
        let mut loss = (sum(0) / nf as f64) as f32;
        if w.edge != 0.0 {
            loss += w.edge * (sum(1) / edge_count as f64) as f32;
        }
        if w.length != 0.0 {
            loss += w.length * (sum(2) / len_count as f64) as f32;
        }
        self.mark(|| "geometry loss".into());
        Ok(Some((loss, g)))
    }

    /// [`Cuda::geometry_loss_dev`] on host tensors (both uploaded, the gradient downloaded), for
    /// the parity tests; `None` where `w` has a term without a kernel. A driver failure gives
    /// NaN, recorded as the table's ops record it ([`crate::ops::Ops::take_error`]).
    pub fn geometry_loss(&self, est: &Tensor, target: &Tensor, w: GeometryLoss) -> Option<(f32, Tensor)> {
        if w.laplacian != 0.0 || w.detail != 0.0 {
            return None;
        }
        Some(self.run(
            "geometry loss",
            || (f32::NAN, Tensor::full(&est.shape, f32::NAN)),
            || {
                let (e, t) = (self.upload(est)?, self.upload(target)?);
                let (l, g) = self.geometry_loss_dev(&e, &t, w)?.expect("terms with kernels");
                Ok((l, self.download(&g)?))
            },
        ))
    }
}
