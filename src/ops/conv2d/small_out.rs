//! Few output channels (the nets' last convs: C → 3, C → 1).
//!
//! The channel-vector kernel above would fill 3 or 1 of 16 lanes. Here the lanes run along the
//! output row instead: the input is padded planar (NCHW, each row widened to whole vectors plus
//! the kernel's overhang), the weights are broadcast, and one register tile holds O output
//! channels × P vectors of 16 pixels. Per (c_in, tap): P unaligned loads, O broadcasts, O·P FMAs.

use super::*;

/// Output channels up to which [`conv2d`] takes the pixel-vector path.
pub const SMALL_OUT_MAX: usize = 4;
/// Vectors of 16 pixels per register tile of the pixel-vector path: O·P accumulators and P
/// input vectors, in 32 zmm registers with AVX-512; without it each f32x16 takes two of 16 ymm
/// registers, and 2 keeps the tile (nearly) out of the stack. Same bits either way.
pub(super) const SMALL_P: usize = if cfg!(target_feature = "avx512f") { 4 } else { 2 };

/// Row length of the padded planar input for rows of `w` outputs under a `kw`-wide kernel:
/// whole vectors of 16 pixels plus the kernel's overhang.
pub(super) fn planar_width(w: usize, kw: usize) -> usize {
    w.div_ceil(L) * L + kw - 1
}

/// Padded planar copy of `x` (N, C, H, W): plane (n, c) at (n·C + c)·hp·wq, rows of `wq` ≥ W + 2pw
/// floats, pixel (Y, X) holding x[n, c, Y−ph, X−pw] with `pad` applied (0 beyond W + 2pw).
pub(super) fn pad_planar(x: &Tensor, ph: usize, pw: usize, pad: Padding, wq: usize) -> (Scratch, usize) {
    let (n, c, h, w) = x.dims4();
    let border = PlanarBorder { h, w, ph, pw, wq, pad };
    // Every element is written below (no pass of zeros first: on the HR tail's 128² planes
    // that pass cost as much as the copy).
    let mut out = Scratch::overwritten(n * c * border.plane());
    out.par_chunks_mut(border.plane()).enumerate().for_each(|(plane, dst)| {
        let src = &x.data[plane * h * w..][..h * w];
        for y in 0..h {
            dst[(y + ph) * wq + pw..][..w].copy_from_slice(&src[y * w..][..w]);
            // SAFETY: dst is this task's whole plane, and its row y is written.
            unsafe { border.fill_row(dst.as_mut_ptr(), y) };
        }
    });
    (out, h + 2 * ph)
}

/// The border of [`pad_planar`]'s layout: planes of hp × wq floats (hp = h + 2ph, wq ≥ w + 2pw)
/// whose interior, rows ph..ph+h × columns pw..pw+w, holds the image.
#[derive(Clone, Copy)]
pub(super) struct PlanarBorder {
    pub h: usize,
    pub w: usize,
    pub ph: usize,
    pub pw: usize,
    pub wq: usize,
    pub pad: Padding,
}

impl PlanarBorder {
    /// Floats a plane.
    pub fn plane(&self) -> usize {
        (self.h + 2 * self.ph) * self.wq
    }

    /// With image row `y` of a plane written: the columns around it as `pad` says (0 beyond
    /// w + 2pw), and, for the first and the last row, the pad rows above or below (copies of
    /// it, or 0). Row by row, so a store can fill the border while the row is in cache.
    ///
    /// # Safety
    /// `plane` points at a whole plane ([`PlanarBorder::plane`] floats); nothing else touches
    /// row ph + y, nor the pad rows above (y = 0) or below (y = h − 1), while this runs.
    pub unsafe fn fill_row(&self, plane: *mut f32, y: usize) {
        let Self { h, w, ph, pw, wq, pad } = *self;
        assert!(y < h && wq >= w + 2 * pw);
        // SAFETY: row ph + y and the pad rows are inside the plane and this call's alone (the
        // caller's contract); the slices made here do not overlap one another.
        unsafe {
            let row = std::slice::from_raw_parts_mut(plane.add((ph + y) * wq), wq);
            for xx in (0..pw).chain(pw + w..w + 2 * pw) {
                row[xx] = pad_index(xx as isize - pw as isize, w, pad).map_or(0.0, |sx| row[pw + sx]);
            }
            row[w + 2 * pw..].fill(0.0);
            let outside = match (y == 0, y + 1 == h) {
                (true, true) => (0..ph).chain(ph + h..h + 2 * ph),
                (true, false) => (0..ph).chain(0..0),
                (false, true) => (0..0).chain(ph + h..h + 2 * ph),
                (false, false) => (0..0).chain(0..0),
            };
            for yy in outside {
                let dst = std::slice::from_raw_parts_mut(plane.add(yy * wq), wq);
                match pad_index(yy as isize - ph as isize, h, pad) {
                    Some(sy) => {
                        debug_assert_eq!(sy, y);
                        dst.copy_from_slice(row)
                    }
                    None => dst.fill(0.0),
                }
            }
        }
    }
}

/// Pixel-vector micro-kernel: O output channels × P vectors (16 pixels each) of one output row.
/// `xp` points at (channel 0, row y, column x0) of the padded planar input (row stride `wq`,
/// plane stride `plane`), `wk` at the packed weights [c_in][ky][kx][O], `out` at the row's
/// scratch for output channel 0 (channel stride `ostride`), already holding the initial value.
///
/// # Safety
/// Rows y..y+kh, columns x0..x0+16P+kw−1 of all `c` planes and the O×16P outputs in bounds.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) unsafe fn micro_px<const O: usize, const P: usize>(
    xp: *const f32,
    wq: usize,
    plane: usize,
    c: usize,
    kh: usize,
    kw: usize,
    wk: *const f32,
    out: *mut f32,
    ostride: usize,
) {
    // The nets' last convs are 3×3: with the kernel's size a constant, the tap loops unroll
    // and the accumulators stay in registers. With a size known only at run time, the compiler
    // unrolled the kx loop by 8, so a 3-tap row ran in its remainder loop, which kept the
    // accumulators on the stack without AVX-512 (5 % of `upscale`). Same sums, same order.
    if (kh, kw) == (3, 3) {
        micro_px_k::<O, P, 3, 3>(xp, wq, plane, c, wk, out, ostride, [3, 3])
    } else {
        micro_px_k::<O, P, 0, 0>(xp, wq, plane, c, wk, out, ostride, [kh, kw])
    }
}

/// [`micro_px`] for a KH × KW kernel, or for the `k` = [kh, kw] given when KH = 0.
#[inline(always)]
#[allow(clippy::too_many_arguments, clippy::needless_range_loop)]
unsafe fn micro_px_k<const O: usize, const P: usize, const KH: usize, const KW: usize>(
    xp: *const f32,
    wq: usize,
    plane: usize,
    c: usize,
    wk: *const f32,
    out: *mut f32,
    ostride: usize,
    k: [usize; 2],
) {
    let [kh, kw] = if KH > 0 { [KH, KW] } else { k };
    let mut acc = [[f32x16::ZERO; P]; O];
    for j in 0..O {
        for p in 0..P {
            acc[j][p] = (out.add(j * ostride + p * L) as *const f32x16).read_unaligned();
        }
    }
    for ci in 0..c {
        for ky in 0..kh {
            let xr = xp.add(ci * plane + ky * wq);
            let wr = wk.add((ci * kh + ky) * kw * O);
            for kx in 0..kw {
                let mut xv = [f32x16::ZERO; P];
                for p in 0..P {
                    xv[p] = (xr.add(kx + p * L) as *const f32x16).read_unaligned();
                }
                for j in 0..O {
                    let wv = f32x16::splat(*wr.add(kx * O + j));
                    for p in 0..P {
                        acc[j][p] = wv.mul_add(xv[p], acc[j][p]);
                    }
                }
            }
        }
    }
    for j in 0..O {
        for p in 0..P {
            (out.add(j * ostride + p * L) as *mut f32x16).write_unaligned(acc[j][p]);
        }
    }
}

/// Weights (O, C, KH, KW) as [`conv2d_small_out`] reads them: [c_in][ky][kx][o].
pub(super) fn pack_small_out(w: &Tensor) -> Vec<f32> {
    let (o, c, kh, kw) = w.dims4();
    let mut wk = vec![0.0f32; c * kh * kw * o];
    for (i, v) in wk.iter_mut().enumerate() {
        let (oi, t) = (i % o, i / o);
        *v = w.data[oi * c * kh * kw + t];
    }
    wk
}

/// Forward for o ≤ [`SMALL_OUT_MAX`] output channels (same contract as [`conv2d_ref`]), with
/// the weights from [`pack_small_out`] of an (o, C, kh, kw) kernel.
pub(super) fn conv2d_small_out(
    x: &Tensor,
    wk: &[f32],
    [o, kh, kw]: [usize; 3],
    b: Option<&Tensor>,
    pad: Padding,
) -> Tensor {
    let (n, c, h, wd) = x.dims4();
    let wq = planar_width(wd, kw);
    let (xp, _) = pad_planar(x, kh / 2, kw / 2, pad, wq);
    small_out_planar(&xp, [n, c, h, wd], wq, wk, [o, kh, kw], b)
}

/// [`conv2d_small_out`] on its input already padded: `xp` in [`pad_planar`]'s layout of an
/// (N, C, H, W) input, rows of `wq` = [`planar_width`] floats.
pub(super) fn small_out_planar(
    xp: &[f32],
    [n, c, h, wd]: [usize; 4],
    wq: usize,
    wk: &[f32],
    [o, kh, kw]: [usize; 3],
    b: Option<&Tensor>,
) -> Tensor {
    assert!((1..=SMALL_OUT_MAX).contains(&o) && wk.len() == c * kh * kw * o);
    let hp = h + 2 * (kh / 2);
    assert!(wq == planar_width(wd, kw) && xp.len() >= n * c * hp * wq);
    let nv = wd.div_ceil(L); // vectors per output row
    let mut y = Tensor::for_overwrite(&[n, o, h, wd]);
    let yp = SyncPtr(y.data.as_mut_ptr());
    let row_len = nv * L;
    // Rows per task: ≈ 2¹⁸ multiply-adds or more, so rayon's overhead stays small on small images.
    let rows_per_task = ((1 << 18) / (o * c * kh * kw * row_len).max(1)).clamp(1, h);
    let tasks = h.div_ceil(rows_per_task);
    let fresh = || Scratch::overwritten(o * row_len);
    (0..n * tasks).into_par_iter().for_each_init(fresh, |buf: &mut Scratch, task| {
        let (ni, ti) = (task / tasks, task % tasks);
        for yy in ti * rows_per_task..((ti + 1) * rows_per_task).min(h) {
            for (oi, dst) in buf.chunks_exact_mut(row_len).enumerate() {
                dst.fill(b.map_or(0.0, |b| b.data[oi]));
            }
            for v0 in (0..nv).step_by(SMALL_P) {
                let np = (nv - v0).min(SMALL_P);
                // SAFETY: rows yy..yy+kh < hp and columns v0·16..(v0+np)·16+kw−1 ≤ wq of every
                // plane of image ni; the buffer holds o rows of nv·16 floats.
                unsafe {
                    let xptr = xp.as_ptr().add(ni * c * hp * wq + yy * wq + v0 * L);
                    let optr = buf.as_mut_ptr().add(v0 * L);
                    let (plane, wptr) = (hp * wq, wk.as_ptr());
                    match o {
                        1 => dispatch_px!(1, np, xptr, wq, plane, c, kh, kw, wptr, optr, row_len),
                        2 => dispatch_px!(2, np, xptr, wq, plane, c, kh, kw, wptr, optr, row_len),
                        3 => dispatch_px!(3, np, xptr, wq, plane, c, kh, kw, wptr, optr, row_len),
                        _ => dispatch_px!(4, np, xptr, wq, plane, c, kh, kw, wptr, optr, row_len),
                    }
                }
            }
            for (oi, src) in buf.chunks_exact(row_len).enumerate() {
                // SAFETY: row (ni, oi, yy) is written by this task only.
                let dst = unsafe {
                    std::slice::from_raw_parts_mut(yp.get().add(((ni * o + oi) * h + yy) * wd), wd)
                };
                dst.copy_from_slice(&src[..wd]);
            }
        }
    });
    y
}
