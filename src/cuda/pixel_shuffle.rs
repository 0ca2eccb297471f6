//! `kernels/pixel_shuffle.cu` on device buffers: sub-pixel upscaling and its inverse.

use cudarc::driver::PushKernelArg;

use super::device::{dims4, grid1, i32_of, Cuda, DResult, DevBuf};

impl Cuda {
    /// (N, C·r², H, W) → (N, C, H·r, W·r)
    pub fn pixel_shuffle_dev(&self, x: &DevBuf, r: usize) -> DResult<DevBuf> {
        let [n, cr2, h, w] = dims4(&x.shape, "pixel_shuffle x");
        assert!(r >= 1 && cr2 % (r * r) == 0, "pixel_shuffle: {cr2} channels not divisible by r²={}", r * r);
        let c = cr2 / (r * r);
        let mut y = self.zeros(&[n, c, h * r, w * r])?;
        if y.is_empty() {
            return Ok(y);
        }
        let _ = i32_of(cr2 * h * r * w * r, "pixel_shuffle plane size");
        let (ni, ci, hi, wi, ri) = (n as i32, c as i32, h as i32, w as i32, r as i32);
        let cfg = grid1(y.len());
        let mut l = self.stream.launch_builder(&self.k.pixel_shuffle);
        l.arg(&x.buf).arg(&mut y.buf).arg(&ni).arg(&ci).arg(&hi).arg(&wi).arg(&ri);
        // SAFETY: matches pixel_shuffle (C = output channels).
        unsafe { l.launch(cfg) }?;
        self.mark(|| "pixel (un)shuffle".into());
        Ok(y)
    }

    /// (N, C, H·r, W·r) → (N, C·r², H, W)
    pub fn pixel_unshuffle_dev(&self, x: &DevBuf, r: usize) -> DResult<DevBuf> {
        let [n, c, hr, wr] = dims4(&x.shape, "pixel_unshuffle x");
        assert!(r >= 1 && hr % r == 0 && wr % r == 0, "pixel_unshuffle: {hr}x{wr} not divisible by r={r}");
        let (h, w) = (hr / r, wr / r);
        let mut y = self.zeros(&[n, c * r * r, h, w])?;
        if y.is_empty() {
            return Ok(y);
        }
        let _ = i32_of(c * r * r * hr * wr, "pixel_unshuffle plane size");
        let (ni, ci, hi, wi, ri) = (n as i32, c as i32, h as i32, w as i32, r as i32);
        let cfg = grid1(y.len());
        let mut l = self.stream.launch_builder(&self.k.pixel_unshuffle);
        l.arg(&x.buf).arg(&mut y.buf).arg(&ni).arg(&ci).arg(&hi).arg(&wi).arg(&ri);
        // SAFETY: matches pixel_unshuffle (C = input channels, H, W = output size).
        unsafe { l.launch(cfg) }?;
        self.mark(|| "pixel (un)shuffle".into());
        Ok(y)
    }
}
