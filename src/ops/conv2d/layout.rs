//! Scratch buffers (a per-thread pool) and layout moves at the op boundary: NCHW tensors
//! into padded channels-last (NHWC) buffers, padding materialised once.

use super::*;
/// Raw pointer that rayon tasks may share; every task writes a disjoint set of elements.
#[derive(Clone, Copy)]
pub(super) struct SyncPtr(pub(super) *mut f32);
unsafe impl Send for SyncPtr {}
unsafe impl Sync for SyncPtr {}
impl SyncPtr {
    /// The pointer (a method, so closures capture the whole Sync wrapper).
    #[inline]
    pub(super) fn get(self) -> *mut f32 {
        self.0
    }
}

/// An f32 buffer taken from a small per-thread pool and returned to it on drop, so repeated
/// calls do not pay for fresh pages (page faults cost about as much as the arithmetic on small
/// images). The per-task buffers of the kernels come from here too: with the tensors pooled
/// ([`crate::pool`]) glibc no longer sees large frees, keeps its mmap threshold at 128 KiB and
/// would map and unmap every per-task buffer above it (a 1×64×128×128 conv took 190 000 page
/// faults and 1.4× the time until they were pooled).
///
/// The vector's own length is the most it has ever held (every float of it initialised); the
/// buffer is its first `len` floats. So a pooled buffer used by turns for a small and a large
/// layer is zeroed where it grows only once, not on every turn ([`Scratch::overwritten`]).
pub(super) struct Scratch {
    v: Vec<f32>,
    len: usize,
}

thread_local! {
    static POOL: std::cell::RefCell<Vec<Vec<f32>>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// Buffers kept per thread, and the largest one kept (floats).
pub(super) const POOL_KEEP: usize = 8;
pub(super) const POOL_MAX_LEN: usize = 1 << 24;

impl Scratch {
    /// A pooled vector with room for `len` floats, as it was left (stale values), at least
    /// `len` long (grown with zeros where it was shorter).
    fn take(len: usize) -> Vec<f32> {
        let mut v = POOL
            .with(|p| {
                let mut p = p.borrow_mut();
                // Prefer the smallest pooled buffer that fits, else the largest one (grown).
                let best = (0..p.len()).filter(|&i| p[i].capacity() >= len).min_by_key(|&i| p[i].capacity());
                let pick = best.or_else(|| (0..p.len()).max_by_key(|&i| p[i].capacity()));
                pick.map(|i| p.swap_remove(i))
            })
            .unwrap_or_default();
        if v.len() < len {
            v.resize(len, 0.0);
        }
        v
    }

    pub(super) fn zeroed(len: usize) -> Scratch {
        let mut v = Scratch::take(len);
        v[..len].fill(0.0);
        Scratch { v, len }
    }

    /// `len` floats with unspecified values (stale ones from the pool, zeros where it grew):
    /// for callers that write every element before reading it, and skip the zeroing pass.
    pub(super) fn overwritten(len: usize) -> Scratch {
        Scratch { v: Scratch::take(len), len }
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let v = std::mem::take(&mut self.v);
        if v.capacity() <= POOL_MAX_LEN {
            POOL.with(|p| {
                let mut p = p.borrow_mut();
                if p.len() < POOL_KEEP {
                    p.push(v);
                }
            });
        }
    }
}

impl std::ops::Deref for Scratch {
    type Target = [f32];
    fn deref(&self) -> &[f32] {
        &self.v[..self.len]
    }
}

impl std::ops::DerefMut for Scratch {
    fn deref_mut(&mut self) -> &mut [f32] {
        &mut self.v[..self.len]
    }
}

/// Padded channels-last copy of `x` (N, C, H, W): returns (N·Hp·Wp + extra) pixels × C floats,
/// pixel (n, Y, X) at ((n·Hp + Y)·Wp + X)·C, holding x[n, :, Y−ph, X−pw] with `pad` applied.
/// The `extra` trailing pixels are zero (slack for strided views that run past the end).
pub(super) fn pad_nhwc(
    x: &Tensor,
    ph: usize,
    pw: usize,
    pad: Padding,
    extra: usize,
) -> (Scratch, usize, usize) {
    let (_, _, h, w) = x.dims4();
    pad_nhwc_to(x, ph, pw, pad, h + 2 * ph, w + 2 * pw, extra)
}

/// [`pad_nhwc`] onto a grid of `hp` × `wp` ≥ (H + 2ph) × (W + 2pw) pixels per image; the rows
/// and columns beyond H + 2ph, W + 2pw are zero.
pub(super) fn pad_nhwc_to(
    x: &Tensor,
    ph: usize,
    pw: usize,
    pad: Padding,
    hp: usize,
    wp: usize,
    extra: usize,
) -> (Scratch, usize, usize) {
    let (n, c, h, w) = x.dims4();
    assert!(hp >= h + 2 * ph && wp >= w + 2 * pw);
    let mut out = Scratch::overwritten((n * hp * wp + extra) * c);
    let row_len = wp * c;
    let (body, tail) = out.split_at_mut(n * hp * row_len);
    tail.fill(0.0);
    // Rows per rayon task: ≥ 2¹⁴ floats, so small images are copied on one thread.
    let min_rows = ((1 << 14) / row_len.max(1)).max(1);
    body.par_chunks_mut(row_len)
        .with_min_len(min_rows)
        .enumerate()
        .for_each(|(r, dst)| pad_row_nhwc(x, r / hp, r % hp, ph, pw, pad, dst));
    (out, hp, wp)
}

/// Row `yy` of image `ni` of [`pad_nhwc_to`]'s layout into `dst` (wp pixels × C floats, wp ≥
/// W + 2pw): x[ni, :, yy − ph, ·] with `pad` applied, zeros beyond W + 2pw, and a zero row
/// where yy − ph is outside the image under zero padding or yy ≥ H + 2ph.
pub(super) fn pad_row_nhwc(
    x: &Tensor,
    ni: usize,
    yy: usize,
    ph: usize,
    pw: usize,
    pad: Padding,
    dst: &mut [f32],
) {
    let (_, c, h, w) = x.dims4();
    assert!(dst.len() >= (w + 2 * pw) * c);
    let sy = if yy < h + 2 * ph { pad_index(yy as isize - ph as isize, h, pad) } else { None };
    let Some(sy) = sy else {
        dst.fill(0.0);
        return;
    };
    dst[(w + 2 * pw) * c..].fill(0.0);
    // Interior columns: row sy of the c planes, transposed; then the pw border columns.
    let src = &x.data[(ni * c * h + sy) * w..];
    assert!(src.len() >= c.saturating_sub(1) * h * w + w);
    // SAFETY: the c source rows (plane stride h·w) and the w destination pixels are in bounds
    // (asserted).
    unsafe { transpose(src.as_ptr(), h * w, c, w, dst.as_mut_ptr().add(pw * c), c) };
    for xx in (0..pw).chain(pw + w..w + 2 * pw) {
        let px = &mut dst[xx * c..(xx + 1) * c];
        match pad_index(xx as isize - pw as isize, w, pad) {
            None => px.fill(0.0),
            Some(sx) => px.iter_mut().enumerate().for_each(|(ci, v)| *v = src[ci * h * w + sx]),
        }
    }
}

/// dst[j·ds + i] = src[i·ss + j] for i < rows, j < cols: a strided transpose, in 8×8 blocks
/// through registers (`f32x8::transpose`: AVX shuffles), element by element at the ragged
/// edges. Moves activations between NCHW planes and the kernels' channels-last rows.
///
/// # Safety
/// Source rows i < rows hold cols floats at i·ss; destination rows j < cols hold rows floats
/// at j·ds; the two do not overlap.
pub(super) unsafe fn transpose(
    src: *const f32,
    ss: usize,
    rows: usize,
    cols: usize,
    dst: *mut f32,
    ds: usize,
) {
    transpose_map(src, ss, rows, cols, dst, ds, |v, _| v, |v, _| v)
}

/// [`transpose`] storing `f(v, at)` (8 floats) or `g(v, at)` (one, at the edges) instead of
/// the value read, where `at` is the destination offset (j·ds + i).
///
/// # Safety
/// As [`transpose`].
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) unsafe fn transpose_map(
    src: *const f32,
    ss: usize,
    rows: usize,
    cols: usize,
    dst: *mut f32,
    ds: usize,
    f: impl Fn(f32x8, usize) -> f32x8,
    g: impl Fn(f32, usize) -> f32,
) {
    let (r8, c8) = (rows / 8 * 8, cols / 8 * 8);
    let block = |i0: usize, j0: usize| {
        let m: [f32x8; 8] =
            std::array::from_fn(|k| (src.add((i0 + k) * ss + j0) as *const f32x8).read_unaligned());
        for (k, v) in f32x8::transpose(m).into_iter().enumerate() {
            let at = (j0 + k) * ds + i0;
            (dst.add(at) as *mut f32x8).write_unaligned(f(v, at));
        }
    };
    // The side with the long stride (NCHW planes, often 4 KiB apart or a multiple) in the outer
    // loop: then only 8 of its rows are in flight at a time, where walking all of them at once
    // would put more streams on the same L1 sets than it has ways.
    if ss >= ds {
        for i0 in (0..r8).step_by(8) {
            for j0 in (0..c8).step_by(8) {
                block(i0, j0);
            }
        }
    } else {
        for j0 in (0..c8).step_by(8) {
            for i0 in (0..r8).step_by(8) {
                block(i0, j0);
            }
        }
    }
    for i in 0..rows {
        for j in if i < r8 { c8 } else { 0 }..cols {
            *dst.add(j * ds + i) = g(*src.add(i * ss + j), j * ds + i);
        }
    }
}
