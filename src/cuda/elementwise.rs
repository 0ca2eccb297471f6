//! `kernels/elementwise.cu` on device buffers: ReLU and its backward, sigmoid, residual add.

use cudarc::driver::{CudaFunction, CudaSlice, PushKernelArg};

use super::device::{grid1, Cuda, DResult, DevBuf};

impl Cuda {
    /// Launch a flat kernel `f(a, b, n)` (element-wise, `n` > 0 elements).
    fn flat2(&self, f: &CudaFunction, a: &CudaSlice<f32>, b: &mut CudaSlice<f32>, n: usize) -> DResult<()> {
        let nn = n as i64;
        let mut l = self.stream.launch_builder(f);
        l.arg(a).arg(b).arg(&nn);
        // SAFETY: (const float*, float*, long long) kernels; both buffers hold ≥ n values.
        unsafe { l.launch(grid1(n)) }?;
        self.mark(|| "element-wise".into());
        Ok(())
    }

    pub fn relu_dev(&self, x: &DevBuf) -> DResult<DevBuf> {
        let mut y = self.zeros(&x.shape)?;
        if !x.is_empty() {
            self.flat2(&self.k.relu_fwd, &x.buf, &mut y.buf, x.len())?;
        }
        Ok(y)
    }

    pub fn sigmoid_dev(&self, x: &DevBuf) -> DResult<DevBuf> {
        let mut y = self.zeros(&x.shape)?;
        if !x.is_empty() {
            self.flat2(&self.k.sigmoid_fwd, &x.buf, &mut y.buf, x.len())?;
        }
        Ok(y)
    }

    /// dx += dy ⊙ [x > 0]
    pub fn relu_backward_dev(&self, x: &DevBuf, dy: &DevBuf, dx: &mut DevBuf) -> DResult<()> {
        assert_eq!(x.shape, dy.shape, "relu_backward: x and dy shapes differ");
        assert_eq!(x.shape, dx.shape, "relu_backward: x and dx shapes differ");
        let n = x.len();
        if n == 0 {
            return Ok(());
        }
        let nn = n as i64;
        let mut l = self.stream.launch_builder(&self.k.relu_bwd);
        l.arg(&x.buf).arg(&dy.buf).arg(&mut dx.buf).arg(&nn);
        // SAFETY: matches relu_bwd; all three buffers hold n values.
        unsafe { l.launch(grid1(n)) }?;
        self.mark(|| "element-wise".into());
        Ok(())
    }

    /// a += b
    pub fn add_assign_dev(&self, a: &mut DevBuf, b: &DevBuf) -> DResult<()> {
        assert_eq!(a.shape, b.shape, "add_assign: shapes differ");
        let n = a.len();
        if n == 0 {
            return Ok(());
        }
        let nn = n as i64;
        let mut l = self.stream.launch_builder(&self.k.add_assign);
        l.arg(&mut a.buf).arg(&b.buf).arg(&nn);
        // SAFETY: matches add_assign; both buffers hold n values.
        unsafe { l.launch(grid1(n)) }?;
        self.mark(|| "element-wise".into());
        Ok(())
    }
}
