//! `kernels/loss.cu` on device buffers: MSE and BCE-with-logits, each the mean loss (f64
//! partial sums per block, summed in order on the host) and its gradient.

use cudarc::driver::{CudaFunction, PushKernelArg};

use super::device::{grid1, Cuda, DResult, DevBuf};

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
}
