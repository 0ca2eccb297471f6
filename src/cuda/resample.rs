//! `kernels/resample.cu` on device buffers: align-corners resize and its backward. The GPU
//! only gathers; the taps (indices and weights per output index, and their transpose for the
//! backward) are the CPU path's own ([`crate::ops::resample::axis_taps`]), so both paths
//! interpolate with identical weights.

use cudarc::driver::PushKernelArg;

use super::device::{dims4, grid1, i32_of, Cuda, DResult, DevBuf};
use crate::ops::resample::{axis_taps, transpose};
use crate::ops::Interp;

/// Tap indices as the kernels' `int` (the callers check sizes against the 32-bit range).
fn ints(v: &[usize]) -> Vec<i32> {
    v.iter().map(|&i| i as i32).collect()
}

impl Cuda {
    /// (N, C, H, W) → (N, C, out_h, out_w), align corners.
    pub fn resize_dev(&self, x: &DevBuf, out_h: usize, out_w: usize, mode: Interp) -> DResult<DevBuf> {
        let [n, c, h, w] = dims4(&x.shape, "resize x");
        assert!(h > 0 && w > 0, "resize: empty input {:?}", x.shape);
        let mut y = self.zeros(&[n, c, out_h, out_w])?;
        if y.is_empty() {
            return Ok(y);
        }
        let _ = i32_of(h.max(out_h) * w.max(out_w), "resize plane size");
        let (ty, tx) = (axis_taps(h, out_h, mode), axis_taps(w, out_w, mode));
        let (ty_i, ty_w, tx_i, tx_w) =
            (self.up(&ints(&ty.idx))?, self.up(&ty.w)?, self.up(&ints(&tx.idx))?, self.up(&tx.w)?);
        let (nc, hi, wi, ohi, owi) = ((n * c) as i64, h as i32, w as i32, out_h as i32, out_w as i32);
        let (ky, kx) = (ty.k as i32, tx.k as i32);
        let cfg = grid1(y.len());
        let mut l = self.stream.launch_builder(&self.k.resize_fwd);
        l.arg(&x.buf).arg(&mut y.buf).arg(&nc).arg(&hi).arg(&wi).arg(&ohi).arg(&owi);
        l.arg(&ty_i).arg(&ty_w).arg(&ky).arg(&tx_i).arg(&tx_w).arg(&kx);
        // SAFETY: matches resize_fwd; taps hold out·k entries with indices < in.
        unsafe { l.launch(cfg) }?;
        Ok(y)
    }

    /// dx (N, C, H, W) += resizeᵀ(dy (N, C, out_h, out_w)).
    pub fn resize_backward_dev(&self, dy: &DevBuf, mode: Interp, dx: &mut DevBuf) -> DResult<()> {
        let [n, c, out_h, out_w] = dims4(&dy.shape, "resize_backward dy");
        let [n2, c2, h, w] = dims4(&dx.shape, "resize_backward dx");
        assert_eq!((n, c), (n2, c2), "resize_backward: dy {:?} vs dx {:?}", dy.shape, dx.shape);
        if dy.is_empty() || dx.is_empty() {
            return Ok(());
        }
        let _ = i32_of(h.max(out_h) * w.max(out_w) * 4, "resize plane size");
        let cy = transpose(&axis_taps(h, out_h, mode), h);
        let cx = transpose(&axis_taps(w, out_w, mode), w);
        let (cy_p, cy_o, cy_w) = (self.up(&ints(&cy.ptr))?, self.up(&ints(&cy.o))?, self.up(&cy.w)?);
        let (cx_p, cx_o, cx_w) = (self.up(&ints(&cx.ptr))?, self.up(&ints(&cx.o))?, self.up(&cx.w)?);
        let (nc, hi, wi, ohi, owi) = ((n * c) as i64, h as i32, w as i32, out_h as i32, out_w as i32);
        let cfg = grid1(dx.len());
        let mut l = self.stream.launch_builder(&self.k.resize_bwd);
        l.arg(&dy.buf).arg(&mut dx.buf).arg(&nc).arg(&hi).arg(&wi).arg(&ohi).arg(&owi);
        l.arg(&cy_p).arg(&cy_o).arg(&cy_w).arg(&cx_p).arg(&cx_o).arg(&cx_w);
        // SAFETY: matches resize_bwd; CSR pointers hold in + 1 entries, outputs < out.
        unsafe { l.launch(cfg) }?;
        Ok(())
    }
}
