//! 2-D convolution, stride 1, odd square-or-rectangular kernels, "same" output size
//! (padding kh/2, kw/2), zero or replicate padding, optional bias.
//!
//! x: (N, C, H, W), w: (O, C, KH, KW) (OIHW), b: (O), y: (N, O, H, W).

use crate::tensor::Tensor;

/// How pixels outside the image are read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Padding {
    /// Outside pixels are 0 (PyTorch `padding_mode="zeros"`).
    Zero,
    /// Outside pixels repeat the nearest border pixel (PyTorch `padding_mode="replicate"`).
    Replicate,
}

/// Source index for a padded coordinate, or None where zero padding reads a 0.
#[inline]
pub fn pad_index(p: isize, n: usize, pad: Padding) -> Option<usize> {
    if p >= 0 && (p as usize) < n {
        Some(p as usize)
    } else {
        match pad {
            Padding::Zero => None,
            Padding::Replicate => Some(p.clamp(0, n as isize - 1) as usize),
        }
    }
}

/// Reference forward: the spec. y = b + Σ_c Σ_taps w · x(shifted).
pub fn conv2d_ref(x: &Tensor, w: &Tensor, b: Option<&Tensor>, pad: Padding) -> Tensor {
    let (n, c, h, wd) = x.dims4();
    let (o, c2, kh, kw) = w.dims4();
    assert_eq!(c, c2, "conv2d: x has {c} channels, weight expects {c2}");
    assert!(kh % 2 == 1 && kw % 2 == 1, "conv2d: odd kernels only, got {kh}x{kw}");
    let (ph, pw) = ((kh / 2) as isize, (kw / 2) as isize);
    let mut y = Tensor::zeros(&[n, o, h, wd]);
    for ni in 0..n {
        for oi in 0..o {
            for yy in 0..h {
                for xx in 0..wd {
                    let mut acc = b.map_or(0.0, |b| b.data[oi]);
                    for ci in 0..c {
                        for ky in 0..kh {
                            let Some(sy) = pad_index(yy as isize + ky as isize - ph, h, pad) else {
                                continue;
                            };
                            for kx in 0..kw {
                                let Some(sx) = pad_index(xx as isize + kx as isize - pw, wd, pad) else {
                                    continue;
                                };
                                acc += w.data[w.idx4(oi, ci, ky, kx)] * x.data[x.idx4(ni, ci, sy, sx)];
                            }
                        }
                    }
                    let i = y.idx4(ni, oi, yy, xx);
                    y.data[i] = acc;
                }
            }
        }
    }
    y
}

/// Reference backward. Adds into `dx` (if given), `dw` and `db` (if given).
/// dy: (N, O, H, W); dx like x; dw like w; db: (O).
pub fn conv2d_backward_ref(
    x: &Tensor,
    w: &Tensor,
    dy: &Tensor,
    pad: Padding,
    dx: Option<&mut Tensor>,
    dw: &mut Tensor,
    db: Option<&mut Tensor>,
) {
    let (n, c, h, wd) = x.dims4();
    let (o, _, kh, kw) = w.dims4();
    let (ph, pw) = ((kh / 2) as isize, (kw / 2) as isize);
    let mut dx = dx;
    for ni in 0..n {
        for oi in 0..o {
            for yy in 0..h {
                for xx in 0..wd {
                    let g = dy.data[dy.idx4(ni, oi, yy, xx)];
                    for ci in 0..c {
                        for ky in 0..kh {
                            let Some(sy) = pad_index(yy as isize + ky as isize - ph, h, pad) else {
                                continue;
                            };
                            for kx in 0..kw {
                                let Some(sx) = pad_index(xx as isize + kx as isize - pw, wd, pad) else {
                                    continue;
                                };
                                let xi = x.idx4(ni, ci, sy, sx);
                                let wi = w.idx4(oi, ci, ky, kx);
                                dw.data[wi] += g * x.data[xi];
                                if let Some(dx) = dx.as_deref_mut() {
                                    dx.data[xi] += g * w.data[wi];
                                }
                            }
                        }
                    }
                }
            }
        }
    }
    if let Some(db) = db {
        for ni in 0..n {
            for oi in 0..o {
                let s: f32 = (0..h * wd).map(|k| dy.data[(ni * o + oi) * h * wd + k]).sum();
                db.data[oi] += s;
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Fast path. Three kernels, chosen by shape (each checked against `conv2d_ref` and
// `conv2d_backward_ref` in tests/conv_fast_vs_ref.rs):
//   - C_out ≤ 4 (the nets' last convs): the pixel-vector kernel below (lanes along the row);
//   - 3×3 with C_in a multiple of 16 (the trunks): Winograd F(2×2, 3×3), `winograd.rs`; its
//     weight gradient also needs C_out a multiple of 16, and its input gradient zero padding;
//   - everything else (the 3 → C first conv, odd channel counts, 1×1 / 5×5 / 3×5 kernels): the
//     direct channel-vector kernel described here.
//
// Layout: activations are repacked at the op boundary into a padded, channels-last ("NHWC")
// buffer, so one input pixel's channels are contiguous and the padding (zero or replicate) is
// materialised once. Weights are packed per block of up to 64 output channels as
// [tap][c_in][64]. The micro-kernel keeps P pixels × OV·16 output channels of one output row in
// f32x16 accumulators (P·OV ≤ 24 registers), and for every (tap, c_in) loads OV weight vectors
// and broadcasts P input values: P·OV FMAs per P+OV loads. Each output row is one rayon task;
// the row is accumulated in a small NHWC scratch and scattered to NCHW at the end (no extra
// pass over memory). The input gradient is the same kernel with flipped, transposed weights on
// the padded dy ("full" correlation + fold of the border for replicate padding). The weight
// gradient accumulates dW_tap += dY · X_shift per tap with the `micro_dw` kernel (P input
// channels × OV·16 output channels in registers, summed over pixels), on the padded pixel grid
// so that X_shift is a plain strided view; the pixels are cut into fixed chunks (independent
// of the thread count) whose partial sums are added in a fixed order, so results are
// deterministic.
// ---------------------------------------------------------------------------------------------

use super::activation::relu1;
use rayon::prelude::*;
use wide::{f32x16, f32x8};

const L: usize = 16; // f32 lanes per vector
const OB: usize = 64; // output channels per weight block (4 vectors)
const PMAX: usize = 6; // pixels per micro-tile at OV = 4

/// Raw pointer that rayon tasks may share; every task writes a disjoint set of elements.
#[derive(Clone, Copy)]
struct SyncPtr(*mut f32);
unsafe impl Send for SyncPtr {}
unsafe impl Sync for SyncPtr {}
impl SyncPtr {
    /// The pointer (a method, so closures capture the whole Sync wrapper).
    #[inline]
    fn get(self) -> *mut f32 {
        self.0
    }
}

/// A zero-filled f32 buffer taken from a small per-thread pool and returned to it on drop, so
/// repeated calls do not pay for fresh pages (page faults cost about as much as the
/// arithmetic on small images). The per-task buffers of the kernels come from here too: with
/// the tensors pooled ([`crate::pool`]) glibc no longer sees large frees, keeps its mmap
/// threshold at 128 KiB and would map and unmap every per-task buffer above it (a
/// 1×64×128×128 conv took 190 000 page faults and 1.4× the time until they were pooled).
struct Scratch(Vec<f32>);

thread_local! {
    static POOL: std::cell::RefCell<Vec<Vec<f32>>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// Buffers kept per thread, and the largest one kept (floats).
const POOL_KEEP: usize = 8;
const POOL_MAX_LEN: usize = 1 << 24;

impl Scratch {
    /// A pooled buffer for `len` floats, as it was left (its length and values are stale).
    fn take(len: usize) -> Vec<f32> {
        let v = POOL.with(|p| {
            let mut p = p.borrow_mut();
            // Prefer the smallest pooled buffer that fits, else the largest one (grown).
            let best = (0..p.len()).filter(|&i| p[i].capacity() >= len).min_by_key(|&i| p[i].capacity());
            let pick = best.or_else(|| (0..p.len()).max_by_key(|&i| p[i].capacity()));
            pick.map(|i| p.swap_remove(i))
        });
        v.unwrap_or_default()
    }

    fn zeroed(len: usize) -> Scratch {
        let mut v = Scratch::take(len);
        v.clear();
        v.resize(len, 0.0);
        Scratch(v)
    }

    /// `len` floats with unspecified values (stale ones from the pool, zeros where it grew):
    /// for callers that write every element before reading it, and skip the zeroing pass.
    fn overwritten(len: usize) -> Scratch {
        let mut v = Scratch::take(len);
        v.resize(len, 0.0);
        Scratch(v)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let v = std::mem::take(&mut self.0);
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
        &self.0
    }
}

impl std::ops::DerefMut for Scratch {
    fn deref_mut(&mut self) -> &mut [f32] {
        &mut self.0
    }
}

/// Padded channels-last copy of `x` (N, C, H, W): returns (N·Hp·Wp + extra) pixels × C floats,
/// pixel (n, Y, X) at ((n·Hp + Y)·Wp + X)·C, holding x[n, :, Y−ph, X−pw] with `pad` applied.
/// The `extra` trailing pixels are zero (slack for strided views that run past the end).
fn pad_nhwc(x: &Tensor, ph: usize, pw: usize, pad: Padding, extra: usize) -> (Scratch, usize, usize) {
    let (_, _, h, w) = x.dims4();
    pad_nhwc_to(x, ph, pw, pad, h + 2 * ph, w + 2 * pw, extra)
}

/// [`pad_nhwc`] onto a grid of `hp` × `wp` ≥ (H + 2ph) × (W + 2pw) pixels per image; the rows
/// and columns beyond H + 2ph, W + 2pw are zero.
fn pad_nhwc_to(
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
fn pad_row_nhwc(x: &Tensor, ni: usize, yy: usize, ph: usize, pw: usize, pad: Padding, dst: &mut [f32]) {
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
unsafe fn transpose(src: *const f32, ss: usize, rows: usize, cols: usize, dst: *mut f32, ds: usize) {
    transpose_map(src, ss, rows, cols, dst, ds, |v, _| v, |v, _| v)
}

/// [`transpose`] storing `f(v, at)` (8 floats) or `g(v, at)` (one, at the edges) instead of
/// the value read, where `at` is the destination offset (j·ds + i).
///
/// # Safety
/// As [`transpose`].
#[inline(always)]
#[allow(clippy::too_many_arguments)]
unsafe fn transpose_map(
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

/// What the forward does to conv(x) + b as it stores it, fused into the store instead of a
/// pass of its own over the activations: add `skip` (a tensor of the output's shape: the
/// residual connection), then ReLU (`relu1`: negative values to 0, −0 and NaN kept). Same bits
/// as the separate ops.
#[derive(Clone, Copy, Debug, Default)]
pub struct Epilogue<'a> {
    pub skip: Option<&'a Tensor>,
    pub relu: bool,
}

impl Epilogue<'_> {
    pub const NONE: Epilogue<'static> = Epilogue { skip: None, relu: false };
    pub const RELU: Epilogue<'static> = Epilogue { skip: None, relu: true };

    /// The epilogue on a stored tensor (the paths that do not fuse it).
    fn apply(&self, y: &mut Tensor) {
        if let Some(s) = self.skip {
            super::activation::add_assign(y, s);
        }
        if self.relu {
            y.data.iter_mut().for_each(|v| *v = relu1(*v));
        }
    }
}

/// Weights packed for the micro-kernel: for each block of ≤ 64 output channels (rounded up to
/// whole vectors, zero-filled), [ky][kx][c_in][ov·16]. `get(o, c, ky, kx)` reads the logical
/// weight of output channel o, input channel c.
struct Packed {
    data: Scratch,
    /// (offset, vectors) per block.
    blocks: Vec<(usize, usize)>,
    /// Output channels rounded up to a multiple of 16.
    opad: usize,
}

fn pack_weights(
    o: usize,
    c: usize,
    kh: usize,
    kw: usize,
    get: impl Fn(usize, usize, usize, usize) -> f32 + Sync,
) -> Packed {
    let opad = o.div_ceil(L) * L;
    let mut data = Scratch::zeroed(opad * c * kh * kw);
    let mut blocks = Vec::new();
    let mut off = 0;
    for ob in (0..opad).step_by(OB) {
        let ov = ((opad - ob) / L).min(OB / L);
        let wdt = ov * L;
        let jmax = wdt.min(o - ob);
        // Rayon tasks of whole taps (the block is [tap][c_in][wdt]), ≥ 2¹⁵ floats each: small
        // layers are packed on one thread, where a task would cost more than the copy.
        let min_taps = ((1 << 15) / (c * wdt)).max(1);
        data[off..off + kh * kw * c * wdt]
            .par_chunks_mut(c * wdt)
            .with_min_len(min_taps)
            .enumerate()
            .for_each(|(t, dst)| {
                let (ky, kx) = (t / kw, t % kw);
                for (ci, row) in dst.chunks_exact_mut(wdt).enumerate() {
                    for (j, d) in row[..jmax].iter_mut().enumerate() {
                        *d = get(ob + j, ci, ky, kx);
                    }
                }
            });
        blocks.push((off, ov));
        off += kh * kw * c * wdt;
    }
    Packed { data, blocks, opad }
}

/// Micro-kernel: P pixels × OV vectors of output channels of one output row.
/// `xp` points at input pixel (Y = y, X = x0) of the padded NHWC buffer (row stride `wp`
/// pixels, `c` channels); `wk` at the block's packed weights; `acc_out` at the row scratch
/// (pixel stride `opad`) and receives the sum, added to what it holds if `accumulate` (else
/// the tile is overwritten: the caller need not zero it).
///
/// # Safety
/// All reads/writes must be in bounds: rows y..y+kh, columns x0..x0+P+kw−1 of `xp`.
#[inline(always)]
#[allow(clippy::too_many_arguments, clippy::needless_range_loop)]
unsafe fn micro<const OV: usize, const P: usize>(
    xp: *const f32,
    wp: usize,
    c: usize,
    kh: usize,
    kw: usize,
    wk: *const f32,
    acc_out: *mut f32,
    opad: usize,
    accumulate: bool,
) {
    let mut acc = [[f32x16::ZERO; OV]; P];
    if accumulate {
        for p in 0..P {
            for j in 0..OV {
                acc[p][j] = (acc_out.add(p * opad + j * L) as *const f32x16).read_unaligned();
            }
        }
    }
    let wstride = OV * L;
    for ky in 0..kh {
        for kx in 0..kw {
            let xb = xp.add((ky * wp + kx) * c);
            let wb = wk.add((ky * kw + kx) * c * wstride);
            for ci in 0..c {
                let mut wv = [f32x16::ZERO; OV];
                for j in 0..OV {
                    wv[j] = (wb.add(ci * wstride + j * L) as *const f32x16).read_unaligned();
                }
                for p in 0..P {
                    let xv = f32x16::splat(*xb.add(p * c + ci));
                    for j in 0..OV {
                        acc[p][j] = xv.mul_add(wv[j], acc[p][j]);
                    }
                }
            }
        }
    }
    for p in 0..P {
        for j in 0..OV {
            (acc_out.add(p * opad + j * L) as *mut f32x16).write_unaligned(acc[p][j]);
        }
    }
}

macro_rules! dispatch_p {
    ($f:ident, $ov:literal, $np:expr, $($args:expr),*) => {
        match $np {
            1 => $f::<$ov, 1>($($args),*),
            2 => $f::<$ov, 2>($($args),*),
            3 => $f::<$ov, 3>($($args),*),
            4 => $f::<$ov, 4>($($args),*),
            5 => $f::<$ov, 5>($($args),*),
            6 => $f::<$ov, 6>($($args),*),
            7 => $f::<$ov, 7>($($args),*),
            8 => $f::<$ov, 8>($($args),*),
            9 => $f::<$ov, 9>($($args),*),
            10 => $f::<$ov, 10>($($args),*),
            11 => $f::<$ov, 11>($($args),*),
            12 => $f::<$ov, 12>($($args),*),
            _ => unreachable!(),
        }
    };
}

/// Weight-gradient micro-kernel: P input channels × OV vectors of output channels of one tap,
/// summed over `npix` pixels: acc[p][j] += Σ_i x[i·xs + p] · dy[i·ds + j·16 ..].
/// `x` points at (pixel 0 shifted by the tap, channel c0) of the padded NHWC input (pixel
/// stride `xs`), `dy` at (pixel 0, output channel ob) of the NHWC dy on the padded grid (pixel
/// stride `ds`), `acc_out` at the partial dW[tap][c0][ob] (channel stride `opad`).
///
/// # Safety
/// All `npix` pixels of both buffers and the P×OV·16 accumulator block must be in bounds.
#[inline(always)]
#[allow(clippy::too_many_arguments, clippy::needless_range_loop)]
unsafe fn micro_dw<const OV: usize, const P: usize>(
    x: *const f32,
    xs: usize,
    dy: *const f32,
    ds: usize,
    npix: usize,
    acc_out: *mut f32,
    opad: usize,
) {
    let mut acc = [[f32x16::ZERO; OV]; P];
    for p in 0..P {
        for j in 0..OV {
            acc[p][j] = (acc_out.add(p * opad + j * L) as *const f32x16).read_unaligned();
        }
    }
    for i in 0..npix {
        let mut wv = [f32x16::ZERO; OV];
        for j in 0..OV {
            wv[j] = (dy.add(i * ds + j * L) as *const f32x16).read_unaligned();
        }
        let xb = x.add(i * xs);
        for p in 0..P {
            let xv = f32x16::splat(*xb.add(p));
            for j in 0..OV {
                acc[p][j] = xv.mul_add(wv[j], acc[p][j]);
            }
        }
    }
    for p in 0..P {
        for j in 0..OV {
            (acc_out.add(p * opad + j * L) as *mut f32x16).write_unaligned(acc[p][j]);
        }
    }
}

/// Split `total` into `ceil(total / max)` near-equal tiles of ≤ `max`: (start, len) pairs.
fn tiles(total: usize, max: usize) -> impl Iterator<Item = (usize, usize)> {
    let count = total.div_ceil(max).max(1);
    (0..count).map(move |t| {
        let start = total * t / count;
        (start, total * (t + 1) / count - start)
    })
}

/// Max pixels per tile for OV vectors (keeps P·OV + OV + 1 ≤ 32 registers).
fn pmax(ov: usize) -> usize {
    match ov {
        4 => PMAX,
        3 => 7,
        2 => 10,
        _ => 12,
    }
}

/// Correlate a padded NHWC input (n images of hp×wp pixels, c channels) with packed weights
/// into out_h × out_w outputs per image: out[y][x] = init + Σ_taps,c w · xp[y+ky][x+kx].
/// The output rows of each image are produced in `groups` of (first row, row count), one rayon
/// task per (image, group); `sink(n, group index, rows)` then gets the group's rows as NHWC
/// scratch (rows × out_w × opad floats).
#[allow(clippy::too_many_arguments)]
fn correlate_rows(
    xp: &[f32],
    n: usize,
    hp: usize,
    wp: usize,
    c: usize,
    kh: usize,
    kw: usize,
    pk: &Packed,
    init: Option<&[f32]>,
    out_h: usize,
    out_w: usize,
    groups: &[(usize, usize)],
    sink: &(dyn Fn(usize, usize, &[f32]) + Sync),
) {
    assert!(out_h + kh - 1 <= hp && out_w + kw - 1 <= wp);
    assert!(xp.len() >= n * hp * wp * c);
    assert!(groups.iter().all(|&(y0, r)| y0 + r <= out_h));
    let opad = pk.opad;
    let row_len = out_w * opad;
    let most = groups.iter().map(|g| g.1).max().unwrap_or(0);
    let fresh = || Scratch::overwritten(most * row_len);
    (0..n * groups.len()).into_par_iter().for_each_init(fresh, |buf: &mut Scratch, task| {
        let (ni, gi) = (task / groups.len(), task % groups.len());
        let (y0, rows) = groups[gi];
        let buf = &mut buf[..rows * row_len];
        for (ri, row) in buf.chunks_exact_mut(row_len).enumerate() {
            let y = y0 + ri;
            for dst in row.chunks_exact_mut(opad) {
                match init {
                    Some(b) => dst.copy_from_slice(b),
                    None => dst.fill(0.0),
                }
            }
            let xrow = ((ni * hp + y) * wp) * c;
            for (bi, &(off, ov)) in pk.blocks.iter().enumerate() {
                for (x0, np) in tiles(out_w, pmax(ov)) {
                    // SAFETY: rows y..y+kh ≤ hp and columns x0..x0+np+kw−1 ≤ wp of image ni
                    // (asserted above); the row scratch has out_w × opad floats.
                    unsafe {
                        let xptr = xp.as_ptr().add(xrow + x0 * c);
                        let wptr = pk.data.as_ptr().add(off);
                        let aptr = row.as_mut_ptr().add(x0 * opad + bi * OB);
                        match ov {
                            4 => dispatch_p!(micro, 4, np, xptr, wp, c, kh, kw, wptr, aptr, opad, true),
                            3 => dispatch_p!(micro, 3, np, xptr, wp, c, kh, kw, wptr, aptr, opad, true),
                            2 => dispatch_p!(micro, 2, np, xptr, wp, c, kh, kw, wptr, aptr, opad, true),
                            _ => dispatch_p!(micro, 1, np, xptr, wp, c, kh, kw, wptr, aptr, opad, true),
                        }
                    }
                }
            }
        }
        sink(ni, gi, buf);
    });
}

/// One group per output row.
fn single_rows(out_h: usize) -> Vec<(usize, usize)> {
    (0..out_h).map(|y| (y, 1)).collect()
}

// ---------------------------------------------------------------------------------------------
// Few output channels (the nets' last convs: C → 3, C → 1).
//
// The channel-vector kernel above would fill 3 or 1 of 16 lanes. Here the lanes run along the
// output row instead: the input is padded planar (NCHW, each row widened to whole vectors plus
// the kernel's overhang), the weights are broadcast, and one register tile holds O output
// channels × P vectors of 16 pixels. Per (c_in, tap): P unaligned loads, O broadcasts, O·P FMAs.
// ---------------------------------------------------------------------------------------------

/// Output channels up to which [`conv2d`] takes the pixel-vector path.
pub const SMALL_OUT_MAX: usize = 4;
/// Vectors of 16 pixels per register tile of the pixel-vector path.
const SMALL_P: usize = 4;

/// Padded planar copy of `x` (N, C, H, W): plane (n, c) at (n·C + c)·hp·wq, rows of `wq` ≥ W + 2pw
/// floats, pixel (Y, X) holding x[n, c, Y−ph, X−pw] with `pad` applied (0 beyond W + 2pw).
fn pad_planar(x: &Tensor, ph: usize, pw: usize, pad: Padding, wq: usize) -> (Scratch, usize) {
    let (n, c, h, w) = x.dims4();
    let hp = h + 2 * ph;
    let mut out = Scratch::zeroed(n * c * hp * wq);
    out.par_chunks_mut(hp * wq).enumerate().for_each(|(plane, dst)| {
        let src = &x.data[plane * h * w..][..h * w];
        for (yy, drow) in dst.chunks_exact_mut(wq).enumerate() {
            let Some(sy) = pad_index(yy as isize - ph as isize, h, pad) else {
                continue;
            };
            let srow = &src[sy * w..][..w];
            drow[pw..pw + w].copy_from_slice(srow);
            for xx in (0..pw).chain(pw + w..w + 2 * pw) {
                if let Some(sx) = pad_index(xx as isize - pw as isize, w, pad) {
                    drow[xx] = srow[sx];
                }
            }
        }
    });
    (out, hp)
}

/// Pixel-vector micro-kernel: O output channels × P vectors (16 pixels each) of one output row.
/// `xp` points at (channel 0, row y, column x0) of the padded planar input (row stride `wq`,
/// plane stride `plane`), `wk` at the packed weights [c_in][ky][kx][O], `out` at the row's
/// scratch for output channel 0 (channel stride `ostride`), already holding the initial value.
///
/// # Safety
/// Rows y..y+kh, columns x0..x0+16P+kw−1 of all `c` planes and the O×16P outputs in bounds.
#[inline(always)]
#[allow(clippy::too_many_arguments, clippy::needless_range_loop)]
unsafe fn micro_px<const O: usize, const P: usize>(
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

macro_rules! dispatch_px {
    ($o:literal, $np:expr, $($args:expr),*) => {
        match $np {
            1 => micro_px::<$o, 1>($($args),*),
            2 => micro_px::<$o, 2>($($args),*),
            3 => micro_px::<$o, 3>($($args),*),
            _ => micro_px::<$o, SMALL_P>($($args),*),
        }
    };
}

/// Weights (O, C, KH, KW) as [`conv2d_small_out`] reads them: [c_in][ky][kx][o].
fn pack_small_out(w: &Tensor) -> Vec<f32> {
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
fn conv2d_small_out(
    x: &Tensor,
    wk: &[f32],
    [o, kh, kw]: [usize; 3],
    b: Option<&Tensor>,
    pad: Padding,
) -> Tensor {
    let (n, c, h, wd) = x.dims4();
    assert!((1..=SMALL_OUT_MAX).contains(&o) && wk.len() == c * kh * kw * o);
    let (ph, pw) = (kh / 2, kw / 2);
    let nv = wd.div_ceil(L); // vectors per output row
    let wq = nv * L + kw - 1;
    let (xp, hp) = pad_planar(x, ph, pw, pad, wq);
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

/// A convolution's weights packed for the fast forward, once: inference runs the same weights
/// on every frame and mirror view, and packing them (the Winograd kernel transform) costs about
/// a fifth of a 1×64×32×32 forward. [`conv2d`] packs on every call; [`conv2d_packed`] takes
/// them packed.
pub struct PackedConv {
    /// (O, C, KH, KW) of the weights packed.
    shape: [usize; 4],
    kind: PackedKind,
}

enum PackedKind {
    /// O ≤ [`SMALL_OUT_MAX`]: [`pack_small_out`].
    SmallOut(Vec<f32>),
    /// 3×3 with C a multiple of 16: [`winograd::pack`].
    Winograd(Packed),
    /// Everything else: [`pack_weights`].
    Direct(Packed),
}

impl PackedConv {
    /// Pack weights (O, C, KH, KW), odd kernels, for the kernel [`conv2d`] would pick.
    pub fn new(w: &Tensor) -> PackedConv {
        let (o, c, kh, kw) = w.dims4();
        assert!(kh % 2 == 1 && kw % 2 == 1, "conv2d: odd kernels only, got {kh}x{kw}");
        let get = |oi: usize, ci: usize, ky: usize, kx: usize| w.data[((oi * c + ci) * kh + ky) * kw + kx];
        let kind = if o <= SMALL_OUT_MAX {
            PackedKind::SmallOut(pack_small_out(w))
        } else if winograd::eligible(c, o, kh, kw) {
            PackedKind::Winograd(winograd::pack(o, c, get))
        } else {
            PackedKind::Direct(pack_weights(o, c, kh, kw, get))
        };
        PackedConv { shape: [o, c, kh, kw], kind }
    }

    /// (O, C, KH, KW) of the weights packed.
    pub fn shape(&self) -> [usize; 4] {
        self.shape
    }
}

/// Fast forward (same contract as [`conv2d_ref`]).
pub fn conv2d(x: &Tensor, w: &Tensor, b: Option<&Tensor>, pad: Padding) -> Tensor {
    conv2d_packed(x, &PackedConv::new(w), b, pad, Epilogue::NONE)
}

/// [`conv2d`] with the weights packed in advance, then `epi`: the same bits as [`conv2d`]
/// followed by `add_assign(y, skip)` and `relu`.
pub fn conv2d_packed(
    x: &Tensor,
    packed: &PackedConv,
    b: Option<&Tensor>,
    pad: Padding,
    epi: Epilogue,
) -> Tensor {
    let (n, c, h, wd) = x.dims4();
    let [o, c2, kh, kw] = packed.shape;
    assert_eq!(c, c2, "conv2d: x has {c} channels, weight expects {c2}");
    if let Some(s) = epi.skip {
        assert_eq!(s.shape, [n, o, h, wd], "conv2d: the skip tensor is not the output's shape");
    }
    let (pk, wino) = match &packed.kind {
        PackedKind::SmallOut(wk) => {
            let mut y = conv2d_small_out(x, wk, [o, kh, kw], b, pad);
            epi.apply(&mut y);
            return y;
        }
        PackedKind::Winograd(pk) => (pk, true),
        PackedKind::Direct(pk) => (pk, false),
    };
    let (ph, pw) = (kh / 2, kw / 2);
    // The padded channels-last input, except for small Winograd convs, whose tasks pad their own rows.
    let padded = if !wino {
        Some(pad_nhwc(x, ph, pw, pad, 0))
    } else if x.len() > winograd::FUSE_PAD_MAX {
        Some(winograd::pad_input(x, pad))
    } else {
        None
    };
    let bias: Option<Vec<f32>> = b.map(|b| {
        let mut v = vec![0.0; pk.opad];
        v[..o].copy_from_slice(&b.data[..o]);
        v
    });
    let mut y = Tensor::for_overwrite(&[n, o, h, wd]);
    let yp = SyncPtr(y.data.as_mut_ptr());
    let opad = pk.opad;
    let skip = epi.skip.map(|s| s.data.as_ptr() as usize);
    let relu = epi.relu;
    let sink = move |ni: usize, yy: usize, row: &[f32]| {
        assert!(row.len() >= wd * opad);
        let base = (ni * o * h + yy) * wd;
        // SAFETY: row (ni, yy) of every plane is written by this task only; the row holds wd
        // pixels of opad ≥ o floats (asserted); the skip tensor has y's shape (asserted), so
        // the offsets of y's row are in it too.
        unsafe {
            let sp = skip.map(|p| (p as *const f32).add(base));
            let f = |mut v: f32x8, at: usize| {
                if let Some(sp) = sp {
                    v += (sp.add(at) as *const f32x8).read_unaligned();
                }
                if relu {
                    v = f32x8::from(v.to_array().map(relu1));
                }
                v
            };
            let g = |mut v: f32, at: usize| {
                if let Some(sp) = sp {
                    v += *sp.add(at);
                }
                if relu {
                    v = relu1(v);
                }
                v
            };
            transpose_map(row.as_ptr(), opad, wd, o, yp.get().add(base), h * wd, f, g)
        };
    };
    match (&padded, wino) {
        (Some((xp, hp, wp)), false) => {
            correlate_rows(xp, n, *hp, *wp, c, kh, kw, pk, bias.as_deref(), h, wd, &single_rows(h), &sink)
        }
        (Some((xp, hp, wp)), true) => {
            let input = winograd::Input::Padded { xp, hp: *hp, wp: *wp };
            winograd::correlate(&input, n, c, pk, bias.as_deref(), h, wd, &sink)
        }
        (None, _) => {
            winograd::correlate(&winograd::Input::Nchw { x, pad }, n, c, pk, bias.as_deref(), h, wd, &sink)
        }
    }
    y
}

/// Fast backward (same contract as [`conv2d_backward_ref`]).
pub fn conv2d_backward(
    x: &Tensor,
    w: &Tensor,
    dy: &Tensor,
    pad: Padding,
    dx: Option<&mut Tensor>,
    dw: &mut Tensor,
    db: Option<&mut Tensor>,
) {
    let (n, c, h, wd) = x.dims4();
    let (o, c2, _, _) = w.dims4();
    assert_eq!(c, c2, "conv2d_backward: x has {c} channels, weight expects {c2}");
    assert_eq!(dy.shape, [n, o, h, wd], "conv2d_backward: dy shape");
    assert_eq!(dw.shape, w.shape, "conv2d_backward: dw shape");
    if let Some(dx) = dx {
        assert_eq!(dx.shape, x.shape, "conv2d_backward: dx shape");
        conv2d_input_grad(w, dy, pad, dx);
    }
    conv2d_weight_grad(x, dy, pad, dw);
    if let Some(db) = db {
        let hw = h * wd;
        let sums: Vec<f32> = (0..o)
            .into_par_iter()
            .map(|oi| (0..n).map(|ni| dy.data[(ni * o + oi) * hw..][..hw].iter().sum::<f32>()).sum())
            .collect();
        for (d, s) in db.data.iter_mut().zip(sums) {
            *d += s;
        }
    }
}

/// dx += ∂L/∂x. dy: (N, O, H, W), w: (O, C, KH, KW), dx: (N, C, H, W).
pub fn conv2d_input_grad(w: &Tensor, dy: &Tensor, pad: Padding, dx: &mut Tensor) {
    let (n, o, h, wd) = dy.dims4();
    let (_, c, kh, kw) = w.dims4();
    let (ph, pw) = (kh / 2, kw / 2);
    // Transposed, flipped weights: w'[c][o][ky][kx] = w[o][c][kh−1−ky][kw−1−kx].
    let flipped = |ci: usize, oi: usize, ky: usize, kx: usize| {
        w.data[((oi * c + ci) * kh + kh - 1 - ky) * kw + kw - 1 - kx]
    };
    let wino = winograd::eligible(o, c, kh, kw);
    if pad == Padding::Replicate && wino {
        // The gradient w.r.t. the padded input ((H+2ph) × (W+2pw)) is the zero-padding "same"
        // gradient of dy framed by (ph, pw) zeros, which the Winograd path takes; the frame's
        // pixels are then folded onto the border pixels they replicate.
        let (hp, wp) = (h + 2 * ph, wd + 2 * pw);
        let mut dye = Tensor::zeros(&[n, o, hp, wp]);
        dye.data.par_chunks_mut(hp * wp).zip(dy.data.par_chunks(h * wd)).for_each(|(dst, src)| {
            for (y, row) in src.chunks_exact(wd).enumerate() {
                dst[(y + ph) * wp + pw..][..wd].copy_from_slice(row);
            }
        });
        let mut dxe = Tensor::zeros(&[n, c, hp, wp]);
        conv2d_input_grad(w, &dye, Padding::Zero, &mut dxe);
        dx.data.par_chunks_mut(h * wd).zip(dxe.data.par_chunks(hp * wp)).for_each(|(dst, src)| {
            for (y, row) in src.chunks_exact(wp).enumerate() {
                let dr = &mut dst[(y.saturating_sub(ph)).min(h - 1) * wd..][..wd];
                for (x, v) in row.iter().enumerate() {
                    dr[x.saturating_sub(pw).min(wd - 1)] += v;
                }
            }
        });
        return;
    }
    // Zero padding: the gradient is a "same" correlation of dy, which the Winograd path takes.
    let wino = wino && pad == Padding::Zero;
    let pk = if wino { winograd::pack(c, o, flipped) } else { pack_weights(c, o, kh, kw, flipped) };
    let opad = pk.opad;
    match pad {
        Padding::Zero => {
            let (dyp, hp, wp) = if wino {
                winograd::pad_input(dy, Padding::Zero)
            } else {
                pad_nhwc(dy, ph, pw, Padding::Zero, 0)
            };
            let dxp = SyncPtr(dx.data.as_mut_ptr());
            let sink = move |ni: usize, yy: usize, row: &[f32]| {
                assert!(row.len() >= wd * opad);
                // dx[ni, ·, yy, ·] += the row, moved from channels-last to the planes.
                // SAFETY: row (ni, yy) of every plane is written by this task only; the row
                // holds wd pixels of opad ≥ c floats (asserted), and `at` < c·h·wd − base.
                unsafe {
                    let d = dxp.get().add((ni * c * h + yy) * wd);
                    let f = |v: f32x8, at: usize| v + (d.add(at) as *const f32x8).read_unaligned();
                    let g = |v: f32, at: usize| v + *d.add(at);
                    transpose_map(row.as_ptr(), opad, wd, c, d, h * wd, f, g)
                };
            };
            if wino {
                let input = winograd::Input::Padded { xp: &dyp, hp, wp };
                winograd::correlate(&input, n, o, &pk, None, h, wd, &sink);
            } else {
                correlate_rows(&dyp, n, hp, wp, o, kh, kw, &pk, None, h, wd, &single_rows(h), &sink);
            }
        }
        Padding::Replicate => {
            // Gradient w.r.t. the padded input ((H+2ph) × (W+2pw)): a "full" correlation of dy
            // zero-padded by (kh−1, kw−1), folded onto the clamped pixels. One task per dx row
            // r computes every padded row that folds onto r (rows 0..=ph for r = 0, the last
            // ph+1 rows for r = H−1), so the fold writes only row r.
            let (dyq, hq, wq) = pad_nhwc(dy, 2 * ph, 2 * pw, Padding::Zero, 0);
            let (hp, wp) = (h + 2 * ph, wd + 2 * pw);
            let groups: Vec<(usize, usize)> = if h == 1 {
                vec![(0, hp)]
            } else {
                (0..h)
                    .map(|r| match r {
                        0 => (0, ph + 1),
                        r if r == h - 1 => (r + ph, ph + 1),
                        r => (r + ph, 1),
                    })
                    .collect()
            };
            let dxp = SyncPtr(dx.data.as_mut_ptr());
            let sink = move |ni: usize, r: usize, rows: &[f32]| {
                for ci in 0..c {
                    // SAFETY: row (ni, r) of every plane is written by this task only.
                    let drow = unsafe {
                        std::slice::from_raw_parts_mut(dxp.get().add(((ni * c + ci) * h + r) * wd), wd)
                    };
                    for row in rows.chunks_exact(wp * opad) {
                        for (xx, px) in row.chunks_exact(opad).enumerate() {
                            let sx = (xx as isize - pw as isize).clamp(0, wd as isize - 1) as usize;
                            drow[sx] += px[ci];
                        }
                    }
                }
            };
            correlate_rows(&dyq, n, hq, wq, o, kh, kw, &pk, None, hp, wp, &groups, &sink);
        }
    }
}

/// Weight gradient of one (input channel, kernel row) for O ≤ [`SMALL_OUT_MAX`] output channels
/// and KW kernel columns, lanes along pixel rows: acc[kx][o] += dy[o](row y, 16 px) ·
/// x(row y + ky, the same 16 px shifted by kx), over every image and row; returns the lane
/// sums. `x` points at (image 0, channel, row ky, column 0) of the padded planar input (row
/// stride `wq`, image stride `xs`); `dy` at (image 0, channel 0, row 0) of dy widened to nv·16
/// columns with zeros (row stride nv·16, channel stride `os`, image stride `ds`).
///
/// # Safety
/// Rows 0..h (+ ky) of n images, columns 0..nv·16 + KW − 1 of `x` and 0..nv·16 of `dy` in bounds.
#[inline(always)]
#[allow(clippy::too_many_arguments, clippy::needless_range_loop)]
unsafe fn dw_px<const O: usize, const KW: usize>(
    x: *const f32,
    wq: usize,
    xs: usize,
    dy: *const f32,
    os: usize,
    ds: usize,
    n: usize,
    h: usize,
    nv: usize,
) -> [[f32; O]; KW] {
    let mut acc = [[f32x16::ZERO; O]; KW];
    for ni in 0..n {
        for y in 0..h {
            let xr = x.add(ni * xs + y * wq);
            let dr = dy.add(ni * ds + y * nv * L);
            for v in 0..nv {
                let mut g = [f32x16::ZERO; O];
                for o in 0..O {
                    g[o] = (dr.add(o * os + v * L) as *const f32x16).read_unaligned();
                }
                for kx in 0..KW {
                    let xv = (xr.add(v * L + kx) as *const f32x16).read_unaligned();
                    for o in 0..O {
                        acc[kx][o] = xv.mul_add(g[o], acc[kx][o]);
                    }
                }
            }
        }
    }
    let mut out = [[0.0; O]; KW];
    for kx in 0..KW {
        for o in 0..O {
            out[kx][o] = acc[kx][o].reduce_add();
        }
    }
    out
}

/// dw += ∂L/∂w for o ≤ [`SMALL_OUT_MAX`] and kw ∈ {1, 3, 5} (else returns false and does
/// nothing): one rayon task per (input channel, kernel row), each summing over every pixel in a
/// fixed order ([`dw_px`]), so results do not depend on the thread count.
fn conv2d_weight_grad_small_out(x: &Tensor, dy: &Tensor, pad: Padding, dw: &mut Tensor) -> bool {
    let (n, c, h, wd) = x.dims4();
    let (o, _, kh, kw) = dw.dims4();
    if o > SMALL_OUT_MAX || !matches!(kw, 1 | 3 | 5) {
        return false;
    }
    let (ph, pw) = (kh / 2, kw / 2);
    let nv = wd.div_ceil(L);
    let wq = nv * L + kw - 1;
    let (xp, hp) = pad_planar(x, ph, pw, pad, wq);
    let rw = nv * L;
    let mut dyq = Scratch::zeroed(n * o * h * rw);
    dyq.par_chunks_mut(rw)
        .enumerate()
        .for_each(|(r, dst)| dst[..wd].copy_from_slice(&dy.data[r * wd..][..wd]));
    let sums: Vec<Vec<f32>> = (0..c * kh)
        .into_par_iter()
        .map(|task| {
            let (ci, ky) = (task / kh, task % kh);
            // SAFETY: image ni, channel ci, rows ky..ky+h ≤ hp, columns < nv·16 + kw − 1 = wq of
            // xp; dyq holds n·o·h rows of nv·16 floats.
            unsafe {
                let xptr = xp.as_ptr().add((ci * hp + ky) * wq);
                let (xs, os, ds, dyp) = (c * hp * wq, h * rw, o * h * rw, dyq.as_ptr());
                macro_rules! run {
                    ($o:literal, $kw:literal) => {
                        dw_px::<$o, $kw>(xptr, wq, xs, dyp, os, ds, n, h, nv)
                            .iter()
                            .flatten()
                            .copied()
                            .collect()
                    };
                }
                match (o, kw) {
                    (1, 1) => run!(1, 1),
                    (1, 3) => run!(1, 3),
                    (1, _) => run!(1, 5),
                    (2, 1) => run!(2, 1),
                    (2, 3) => run!(2, 3),
                    (2, _) => run!(2, 5),
                    (3, 1) => run!(3, 1),
                    (3, 3) => run!(3, 3),
                    (3, _) => run!(3, 5),
                    (_, 1) => run!(4, 1),
                    (_, 3) => run!(4, 3),
                    _ => run!(4, 5),
                }
            }
        })
        .collect();
    // sums[(ci, ky)] = [kx][o]
    for (task, v) in sums.iter().enumerate() {
        let (ci, ky) = (task / kh, task % kh);
        for kx in 0..kw {
            for oi in 0..o {
                dw.data[((oi * c + ci) * kh + ky) * kw + kx] += v[kx * o + oi];
            }
        }
    }
    true
}

/// Σ of equal-length partial sums, added in their order (contiguous, vectorised, in parallel
/// over 4096-float chunks): the same bits for any thread count. None if there are none.
fn sum_partials(partials: Vec<Scratch>) -> Option<Scratch> {
    let mut partials = partials.into_iter();
    let mut sum = partials.next()?;
    let rest: Vec<Scratch> = partials.collect();
    sum.par_chunks_mut(4096).enumerate().for_each(|(i, dst)| {
        for p in &rest {
            for (d, v) in dst.iter_mut().zip(&p[i * 4096..]) {
                *d += v;
            }
        }
    });
    Some(sum)
}

/// Pixels per inner block of the weight gradient (dy and x blocks stay in L1/L2).
const DW_SUB: usize = 128;

/// dw += ∂L/∂w, accumulated over all pixels per tap with the [`micro_dw`] kernel:
/// dW[:, :, ky, kx] += Σ_g dYg[g] ⊗ Xp[g + ky·Wp + kx], where g = (n·Hp + y)·Wp + x runs over the
/// padded pixel grid of the rows y < H (dYg, dy on that grid, is zero where x ≥ W). The pixels
/// are cut into a fixed number of parts (from the problem size, not the thread count), each
/// summed into its own partial dW; the partials are added in a fixed order (deterministic).
/// x: (N, C, H, W), dy: (N, O, H, W), dw: (O, C, KH, KW).
pub fn conv2d_weight_grad(x: &Tensor, dy: &Tensor, pad: Padding, dw: &mut Tensor) {
    if conv2d_weight_grad_small_out(x, dy, pad, dw) {
        return;
    }
    let (o, c, kh, kw) = dw.dims4();
    if winograd::eligible_weight_grad(c, o, kh, kw) {
        return winograd::weight_grad(x, dy, pad, dw);
    }
    let (n, _, h, wd) = x.dims4();
    let (ph, pw) = (kh / 2, kw / 2);
    let (hp, wp) = (h + 2 * ph, wd + 2 * pw);
    let extra = (kh - 1) * wp + (kw - 1);
    let (xp, _, _) = pad_nhwc(x, ph, pw, pad, extra);
    let opad = o.div_ceil(L) * L;
    // dy on the padded grid, channels last (rows y ≥ H are never read).
    let mut dyg = Scratch::zeroed(n * hp * wp * opad);
    dyg.par_chunks_mut(wp * opad).enumerate().for_each(|(r, dst)| {
        let (ni, yy) = (r / hp, r % hp);
        if yy >= h {
            return;
        }
        for oi in 0..o {
            let src = &dy.data[((ni * o + oi) * h + yy) * wd..][..wd];
            for (xx, v) in src.iter().enumerate() {
                dst[xx * opad + oi] = *v;
            }
        }
    });
    // Pixel segments: the rows y < H of each image, cut into ≤ DW_SUB-pixel blocks.
    let blocks: Vec<(usize, usize)> =
        (0..n).flat_map(|ni| tiles(h * wp, DW_SUB).map(move |(s, l)| (ni * hp * wp + s, l))).collect();
    // At least 4 parts (load balance on small images), at most 16 (memory for partials).
    let parts = (n * h * wp).div_ceil(2048).clamp(4, 16).min(blocks.len());
    let taps = kh * kw;
    let oblocks: Vec<(usize, usize)> =
        (0..opad).step_by(OB).map(|ob| (ob, ((opad - ob) / L).min(OB / L))).collect();
    let partials: Vec<Scratch> = (0..parts)
        .into_par_iter()
        .map(|pi| {
            let mut part = Scratch::zeroed(taps * c * opad);
            let (b0, b1) = (blocks.len() * pi / parts, blocks.len() * (pi + 1) / parts);
            for &(g0, len) in &blocks[b0..b1] {
                for t in 0..taps {
                    let off = (t / kw) * wp + t % kw;
                    for &(ob, ov) in &oblocks {
                        for (c0, np) in tiles(c, pmax(ov)) {
                            // SAFETY: pixels g0+off .. g0+off+len of xp (len ≤ N·Hp·Wp + extra
                            // by construction), pixels g0 .. g0+len of dyg, and channels
                            // c0..c0+np, ob..ob+16·ov of the partial are in bounds.
                            unsafe {
                                let xptr = xp.as_ptr().add((g0 + off) * c + c0);
                                let dptr = dyg.as_ptr().add(g0 * opad + ob);
                                let aptr = part.as_mut_ptr().add((t * c + c0) * opad + ob);
                                match ov {
                                    4 => dispatch_p!(micro_dw, 4, np, xptr, c, dptr, opad, len, aptr, opad),
                                    3 => dispatch_p!(micro_dw, 3, np, xptr, c, dptr, opad, len, aptr, opad),
                                    2 => dispatch_p!(micro_dw, 2, np, xptr, c, dptr, opad, len, aptr, opad),
                                    _ => dispatch_p!(micro_dw, 1, np, xptr, c, dptr, opad, len, aptr, opad),
                                }
                            }
                        }
                    }
                }
            }
            part
        })
        .collect();
    // Fixed-order sum of the partials, then scatter into dw (OIHW).
    let Some(sum) = sum_partials(partials) else {
        return;
    };
    for t in 0..taps {
        for ci in 0..c {
            let src = &sum[(t * c + ci) * opad..][..o];
            for (oi, v) in src.iter().enumerate() {
                dw.data[(oi * c + ci) * taps + t] += v;
            }
        }
    }
}

mod winograd;
