//! `kernels/adam.cu` on device buffers: one Adam step with bias correction.

use cudarc::driver::{CudaSlice, PushKernelArg};

use super::device::{grid1, Cuda, DResult};
use crate::ops::AdamParams;

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
        assert!(step >= 1, "adam_update: step counts from 1");
        assert!(
            p.len() >= n && g.len() >= n && m.len() >= n && v.len() >= n,
            "adam_update: buffers shorter than {n}"
        );
        if n == 0 {
            return Ok(());
        }
        // Bias corrections as the CPU path computes them: f64, rounded once.
        let t = step.min(i32::MAX as u64) as i32;
        let c1 = (1.0 - (hp.beta1 as f64).powi(t)) as f32;
        let c2 = (1.0 - (hp.beta2 as f64).powi(t)) as f32;
        let nn = n as i64;
        let mut l = self.stream.launch_builder(&self.k.adam_step);
        l.arg(p).arg(g).arg(m).arg(v).arg(&nn);
        l.arg(&hp.lr).arg(&hp.beta1).arg(&hp.beta2).arg(&hp.eps).arg(&c1).arg(&c2);
        // SAFETY: matches adam_step; all buffers hold ≥ n values.
        unsafe { l.launch(grid1(n)) }?;
        Ok(())
    }
}
