//! `kernels/adam.cu` on device buffers: one Adam step with bias correction, on one buffer
//! ([`Cuda::adam_update_dev`], the op table's) or on every tensor of a trunk in one launch
//! ([`Cuda::adam_update_all_dev`], device-resident training).

use cudarc::driver::{CudaSlice, DevicePtr, LaunchConfig, PushKernelArg};

use super::device::{grid1, Cuda, DResult, DevBuf, THREADS};
use crate::ops::adam::corrections;
use crate::ops::AdamParams;

/// The device addresses of a trunk's (parameter, gradient, m, v) tensors and their lengths, one
/// row of five `u64` each, uploaded once for [`Cuda::adam_update_all_dev`].
pub(super) struct AdamTable {
    rows: CudaSlice<u64>,
    tensors: usize,
    longest: usize,
}

impl Cuda {
    /// One Adam step on device buffers of `n` values each. `step` counts from 1.
    #[allow(clippy::too_many_arguments)]
    pub fn adam_update_dev(
        &self,
        p: &mut CudaSlice<f32>,
        g: &CudaSlice<f32>,
        m: &mut CudaSlice<f32>,
        v: &mut CudaSlice<f32>,
        n: usize,
        step: u64,
        hp: &AdamParams,
    ) -> DResult<()> {
        let (c1, c2) = corrections(step, hp);
        assert!(
            p.len() >= n && g.len() >= n && m.len() >= n && v.len() >= n,
            "adam_update: buffers shorter than {n}"
        );
        if n == 0 {
            return Ok(());
        }
        let nn = n as i64;
        let mut l = self.stream.launch_builder(&self.k.adam_step);
        l.arg(p).arg(g).arg(m).arg(v).arg(&nn);
        l.arg(&hp.lr).arg(&hp.beta1).arg(&hp.beta2).arg(&hp.eps).arg(&c1).arg(&c2);
        // SAFETY: matches adam_step; all buffers hold ≥ n values.
        unsafe { l.launch(grid1(n)) }?;
        Ok(())
    }

    /// The table of `params` with their gradients and moments (each at least the parameter's
    /// length). The table holds raw addresses: its owner keeps these buffers, unmoved and
    /// unfreed, for as long as it launches [`Cuda::adam_update_all_dev`] on it.
    pub(super) fn adam_table(
        &self,
        params: &[DevBuf],
        grads: &[DevBuf],
        m: &[CudaSlice<f32>],
        v: &[CudaSlice<f32>],
    ) -> DResult<AdamTable> {
        let count = params.len();
        assert!(
            grads.len() == count && m.len() == count && v.len() == count,
            "adam_table: list lengths differ"
        );
        let mut rows = Vec::with_capacity(5 * count);
        for i in 0..count {
            let n = params[i].len();
            assert!(
                grads[i].buf.len() >= n && m[i].len() >= n && v[i].len() >= n,
                "adam_table: tensor {i} has buffers shorter than its {n} parameters"
            );
            let (p, _s0) = params[i].buf.device_ptr(&self.stream);
            let (g, _s1) = grads[i].buf.device_ptr(&self.stream);
            let (mm, _s2) = m[i].device_ptr(&self.stream);
            let (vv, _s3) = v[i].device_ptr(&self.stream);
            rows.extend([p, g, mm, vv, n as u64]);
        }
        let longest = params.iter().map(DevBuf::len).max().unwrap_or(0);
        Ok(AdamTable { rows: self.up(&rows)?, tensors: count, longest })
    }

    /// One Adam step on every tensor of `table` in one launch; each gradient is zeroed once
    /// read (the next backward adds into zeros without a memset). Per element the bits of
    /// [`Cuda::adam_update_dev`].
    pub(super) fn adam_update_all_dev(&self, table: &AdamTable, step: u64, hp: &AdamParams) -> DResult<()> {
        let (c1, c2) = corrections(step, hp);
        if table.tensors == 0 || table.longest == 0 {
            return Ok(());
        }
        let cfg = LaunchConfig {
            grid_dim: (grid1(table.longest).grid_dim.0, table.tensors as u32, 1),
            block_dim: (THREADS, 1, 1),
            shared_mem_bytes: 0,
        };
        let mut l = self.stream.launch_builder(&self.k.adam_step_all);
        l.arg(&table.rows);
        l.arg(&hp.lr).arg(&hp.beta1).arg(&hp.beta2).arg(&hp.eps).arg(&c1).arg(&c2);
        // SAFETY: matches adam_step_all; the table's rows address live buffers of at least
        // their n values (adam_table's contract), one row per blockIdx.y.
        unsafe { l.launch(cfg) }?;
        self.mark(|| "adam".into());
        Ok(())
    }
}
