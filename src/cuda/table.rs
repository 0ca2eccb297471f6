//! The [`Ops`] table of the GPU backend over host tensors.

use super::device::{store, Cuda};
use crate::ops::loss::DetailEnergy;
use crate::ops::{AdamParams, Cpu, Interp, Ops, Padding};
use crate::tensor::Tensor;

/// The [`Ops`] table over host tensors: each call uploads its inputs, runs the kernels and
/// downloads its outputs (see the module docs for the transfer cost).
impl Ops for Cuda {
    fn name(&self) -> &'static str {
        "cuda"
    }

    fn take_error(&self) -> Option<crate::Error> {
        self.take_failure()
    }

    fn as_cuda(&self) -> Option<&Cuda> {
        Some(self)
    }

    fn conv2d(&self, x: &Tensor, w: &Tensor, b: Option<&Tensor>, pad: Padding) -> Tensor {
        self.run(
            "conv2d",
            || Tensor::full(&[x.shape[0], w.shape[0], x.shape[2], x.shape[3]], f32::NAN),
            || {
                let (xd, wd) = (self.upload(x)?, self.upload(w)?);
                let bd = b.map(|b| self.upload(b)).transpose()?;
                let y = self.conv2d_dev(&xd, &wd, bd.as_ref(), pad)?;
                self.download(&y)
            },
        )
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
        self.run(
            "conv2d_backward",
            || (),
            || {
                let (xd, wd, dyd) = (self.upload(x)?, self.upload(w)?, self.upload(dy)?);
                let mut dwd = self.upload(dw)?;
                let mut dxd = dx.as_deref().map(|t| self.upload(t)).transpose()?;
                let mut dbd = db.as_deref().map(|t| self.upload(t)).transpose()?;
                self.conv2d_backward_dev(&xd, &wd, &dyd, pad, dxd.as_mut(), None, &mut dwd, dbd.as_mut())?;
                store(dw, self.download(&dwd)?);
                if let (Some(dx), Some(d)) = (dx, dxd) {
                    store(dx, self.download(&d)?);
                }
                if let (Some(db), Some(d)) = (db, dbd) {
                    store(db, self.download(&d)?);
                }
                Ok(())
            },
        )
    }

    fn relu(&self, x: &Tensor) -> Tensor {
        self.run(
            "relu",
            || Tensor::full(&x.shape, f32::NAN),
            || self.download(&self.relu_dev(&self.upload(x)?)?),
        )
    }

    fn relu_backward(&self, x: &Tensor, dy: &Tensor, dx: &mut Tensor) {
        self.run(
            "relu_backward",
            || (),
            || {
                let (xd, dyd, mut dxd) = (self.upload(x)?, self.upload(dy)?, self.upload(dx)?);
                self.relu_backward_dev(&xd, &dyd, &mut dxd)?;
                store(dx, self.download(&dxd)?);
                Ok(())
            },
        )
    }

    fn add_assign(&self, a: &mut Tensor, b: &Tensor) {
        self.run(
            "add_assign",
            || (),
            || {
                let (mut ad, bd) = (self.upload(a)?, self.upload(b)?);
                self.add_assign_dev(&mut ad, &bd)?;
                store(a, self.download(&ad)?);
                Ok(())
            },
        )
    }

    fn pixel_shuffle(&self, x: &Tensor, r: usize) -> Tensor {
        self.run(
            "pixel_shuffle",
            || Tensor::full(&[x.shape[0], x.shape[1] / (r * r), x.shape[2] * r, x.shape[3] * r], f32::NAN),
            || self.download(&self.pixel_shuffle_dev(&self.upload(x)?, r)?),
        )
    }

    fn pixel_unshuffle(&self, x: &Tensor, r: usize) -> Tensor {
        self.run(
            "pixel_unshuffle",
            || Tensor::full(&[x.shape[0], x.shape[1] * r * r, x.shape[2] / r, x.shape[3] / r], f32::NAN),
            || self.download(&self.pixel_unshuffle_dev(&self.upload(x)?, r)?),
        )
    }

    fn resize(&self, x: &Tensor, out_h: usize, out_w: usize, mode: Interp) -> Tensor {
        self.run(
            "resize",
            || Tensor::full(&[x.shape[0], x.shape[1], out_h, out_w], f32::NAN),
            || self.download(&self.resize_dev(&self.upload(x)?, out_h, out_w, mode)?),
        )
    }

    fn resize_backward(&self, dy: &Tensor, mode: Interp, dx: &mut Tensor) {
        self.run(
            "resize_backward",
            || (),
            || {
                let (dyd, mut dxd) = (self.upload(dy)?, self.upload(dx)?);
                self.resize_backward_dev(&dyd, mode, &mut dxd)?;
                store(dx, self.download(&dxd)?);
                Ok(())
            },
        )
    }

    fn sigmoid(&self, x: &Tensor) -> Tensor {
        self.run(
            "sigmoid",
            || Tensor::full(&x.shape, f32::NAN),
            || self.download(&self.sigmoid_dev(&self.upload(x)?)?),
        )
    }

    fn mse(&self, pred: &Tensor, target: &Tensor) -> (f32, Tensor) {
        self.run(
            "mse",
            || (f32::NAN, Tensor::full(&pred.shape, f32::NAN)),
            || {
                let (l, g) = self.mse_dev(&self.upload(pred)?, &self.upload(target)?)?;
                Ok((l, self.download(&g)?))
            },
        )
    }

    fn bce_with_logits(&self, logits: &Tensor, target: &Tensor, pos_weight: f32) -> (f32, Tensor) {
        self.run(
            "bce_with_logits",
            || (f32::NAN, Tensor::full(&logits.shape, f32::NAN)),
            || {
                let (l, g) =
                    self.bce_with_logits_dev(&self.upload(logits)?, &self.upload(target)?, pos_weight)?;
                Ok((l, self.download(&g)?))
            },
        )
    }

    // The geometry losses have no kernels in the table: the CPU table computes them on the
    // host (their inputs are host tensors already). Device-resident training does not come
    // here: its `Cuda::geometry_loss_dev` fuses the MSE, edge and length terms on the GPU.

    fn edge_mse(&self, pred: &Tensor, target: &Tensor) -> (f32, Tensor) {
        Cpu.edge_mse(pred, target)
    }

    fn edge_length_mse(&self, pred: &Tensor, target: &Tensor) -> (f32, Tensor) {
        Cpu.edge_length_mse(pred, target)
    }

    fn laplacian_mse(&self, pred: &Tensor, target: &Tensor) -> (f32, Tensor) {
        Cpu.laplacian_mse(pred, target)
    }

    fn detail_energy_mse(
        &self,
        pred: &Tensor,
        target: &Tensor,
        lr_h: usize,
        lr_w: usize,
        p: DetailEnergy,
    ) -> (f32, Tensor) {
        Cpu.detail_energy_mse(pred, target, lr_h, lr_w, p)
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
        assert!(
            p.len() == g.len() && p.len() == m.len() && p.len() == v.len(),
            "adam_update: lengths p {} g {} m {} v {}",
            p.len(),
            g.len(),
            m.len(),
            v.len()
        );
        self.run(
            "adam_update",
            || (),
            || {
                let n = p.len();
                let (mut pd, gd, mut md, mut vd) = (self.up(p)?, self.up(g)?, self.up(m)?, self.up(v)?);
                self.adam_update_dev(&mut pd, &gd, &mut md, &mut vd, n, step, hp)?;
                p.copy_from_slice(&self.down(&pd, n)?);
                m.copy_from_slice(&self.down(&md, n)?);
                v.copy_from_slice(&self.down(&vd, n)?);
                Ok(())
            },
        )
    }
}
