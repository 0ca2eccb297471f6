//! The direct channel-vector kernel (everything the two others do not take): weight packing,
//! the register micro-kernel, and the row driver (see the overview in `mod.rs`).

use super::*;

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
    pub(super) fn apply(&self, y: &mut Tensor) {
        if let Some(s) = self.skip {
            crate::ops::activation::add_assign(y, s);
        }
        if self.relu {
            y.data.iter_mut().for_each(|v| *v = relu1(*v));
        }
    }
}

/// Weights packed for the micro-kernel: for each block of ≤ 64 output channels (rounded up to
/// whole vectors, zero-filled), [ky][kx][c_in][ov·16]. `get(o, c, ky, kx)` reads the logical
/// weight of output channel o, input channel c.
pub(super) struct Packed {
    pub(super) data: Scratch,
    /// (offset, vectors) per block.
    pub(super) blocks: Vec<(usize, usize)>,
    /// Output channels rounded up to a multiple of 16.
    pub(super) opad: usize,
}

pub(super) fn pack_weights(
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
/// pixels, `c` channels); `wk` at the tile's first output channel in the block's packed
/// weights, whose rows (one per tap and input channel) are `wstride` ≥ OV·16 floats apart
/// (the block's width: a tile may take part of a block, see [`ov_tile`]); `acc_out` at the row scratch
/// (pixel stride `opad`) and receives the sum, added to what it holds if `accumulate` (else
/// the tile is overwritten: the caller need not zero it).
///
/// # Safety
/// All reads/writes must be in bounds: rows y..y+kh, columns x0..x0+P+kw−1 of `xp`.
#[inline(always)]
#[allow(clippy::too_many_arguments, clippy::needless_range_loop)]
pub(super) unsafe fn micro<const OV: usize, const P: usize>(
    xp: *const f32,
    wp: usize,
    c: usize,
    kh: usize,
    kw: usize,
    wk: *const f32,
    wstride: usize,
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
pub(super) unsafe fn micro_dw<const OV: usize, const P: usize>(
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
pub(super) fn tiles(total: usize, max: usize) -> impl Iterator<Item = (usize, usize)> {
    let count = total.div_ceil(max).max(1);
    (0..count).map(move |t| {
        let start = total * t / count;
        (start, total * (t + 1) / count - start)
    })
}

/// Vectors of output channels per register tile in a weight block of `ov` vectors: the whole
/// block with AVX-512; one without it, where six pixels × one vector (12 ymm accumulators) keep
/// more multiply-adds in flight than two pixels × two vectors (8). Same bits either way.
pub(super) fn ov_tile(ov: usize) -> usize {
    if cfg!(target_feature = "avx512f") {
        ov
    } else {
        1
    }
}

/// The register tiles of one weight block of `ov` vectors over `n` pixels (or input channels):
/// (first pixel, pixels, first vector, vectors), pixels outer.
pub(super) fn reg_tiles(n: usize, ov: usize) -> impl Iterator<Item = (usize, usize, usize, usize)> {
    let ot = ov_tile(ov);
    tiles(n, pmax(ot)).flat_map(move |(x0, np)| (0..ov).step_by(ot).map(move |j0| (x0, np, j0, ot)))
}

/// Max pixels per tile for OV vectors: the P·OV accumulators, the OV weight vectors and the
/// broadcast pixel stay in registers. With AVX-512 an f32x16 is one of 32 zmm registers
/// (P·OV + OV + 1 ≤ 32); without it `wide` makes it two of 16 ymm registers
/// (2·P·OV + 2·OV + 1 ≤ 16, or one over at OV = 4), and the AVX-512 tiles would spill most of
/// their accumulators to the stack on every multiply-add. The tile size changes which outputs
/// a call computes, not the order of any output's sum: the bits are the same.
pub(super) fn pmax(ov: usize) -> usize {
    if cfg!(target_feature = "avx512f") {
        match ov {
            4 => PMAX,
            3 => 7,
            2 => 10,
            _ => 12,
        }
    } else {
        match ov {
            1 => 6,
            2 => 2,
            _ => 1,
        }
    }
}

/// Correlate a padded NHWC input (n images of hp×wp pixels, c channels) with packed weights
/// into out_h × out_w outputs per image: out[y][x] = init + Σ_taps,c w · xp[y+ky][x+kx].
/// The output rows of each image are produced in `groups` of (first row, row count), one rayon
/// task per (image, group); `sink(n, group index, rows)` then gets the group's rows as NHWC
/// scratch (rows × out_w × opad floats).
#[allow(clippy::too_many_arguments)]
pub(super) fn correlate_rows(
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
    groups: RowGroups,
    sink: &RowSink,
) {
    assert!(out_h + kh - 1 <= hp && out_w + kw - 1 <= wp);
    assert!(xp.len() >= n * hp * wp * c);
    let ng = groups.len();
    assert!((0..ng).map(|g| groups.get(g)).all(|(y0, r)| y0 + r <= out_h));
    let opad = pk.opad;
    let row_len = out_w * opad;
    let most = (0..ng).map(|g| groups.get(g).1).max().unwrap_or(0);
    let fresh = || Scratch::overwritten(most * row_len);
    (0..n * ng).into_par_iter().for_each_init(fresh, |buf: &mut Scratch, task| {
        let (ni, gi) = (task / ng, task % ng);
        let (y0, rows) = groups.get(gi);
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
                for (x0, np, j0, ot) in reg_tiles(out_w, ov) {
                    // SAFETY: rows y..y+kh ≤ hp and columns x0..x0+np+kw−1 ≤ wp of image ni
                    // (asserted above); the row scratch has out_w × opad floats; vectors
                    // j0..j0+ot of the block's ov.
                    unsafe {
                        let xptr = xp.as_ptr().add(xrow + x0 * c);
                        let (wptr, ws) = (pk.data.as_ptr().add(off + j0 * L), ov * L);
                        let aptr = row.as_mut_ptr().add(x0 * opad + bi * OB + j0 * L);
                        match ot {
                            4 => dispatch_p!(micro, 4, np, xptr, wp, c, kh, kw, wptr, ws, aptr, opad, true),
                            3 => dispatch_p!(micro, 3, np, xptr, wp, c, kh, kw, wptr, ws, aptr, opad, true),
                            2 => dispatch_p!(micro, 2, np, xptr, wp, c, kh, kw, wptr, ws, aptr, opad, true),
                            _ => dispatch_p!(micro, 1, np, xptr, wp, c, kh, kw, wptr, ws, aptr, opad, true),
                        }
                    }
                }
            }
        }
        sink(ni, gi, buf);
    });
}

/// The groups of output rows [`correlate_rows`] produces, one rayon task per (image, group).
#[derive(Clone, Copy)]
pub(super) enum RowGroups<'a> {
    /// One group per row of `out_h` rows.
    Single(usize),
    /// (first row, row count) of each group.
    List(&'a [(usize, usize)]),
}

impl RowGroups<'_> {
    fn len(self) -> usize {
        match self {
            RowGroups::Single(h) => h,
            RowGroups::List(g) => g.len(),
        }
    }

    /// (first row, row count) of group `i`.
    fn get(self, i: usize) -> (usize, usize) {
        match self {
            RowGroups::Single(_) => (i, 1),
            RowGroups::List(g) => g[i],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every (pixel, vector) of a weight block is in exactly one register tile, and no tile is
    /// wider than its kernel's registers allow (`pmax`): a tile left out or taken twice would
    /// leave outputs unwritten or summed twice on one instruction set and not the other.
    #[test]
    fn register_tiles_cover_each_pixel_and_vector_once() {
        for ov in 1..=OB / L {
            for n in 1..50 {
                let mut seen = vec![0u8; n * ov];
                for (x0, np, j0, ot) in reg_tiles(n, ov) {
                    assert!((1..=pmax(ot)).contains(&np) && (1..=ov).contains(&ot), "n {n} ov {ov}");
                    for x in x0..x0 + np {
                        for j in j0..j0 + ot {
                            seen[x * ov + j] += 1;
                        }
                    }
                }
                assert!(seen.iter().all(|&k| k == 1), "n {n} ov {ov}: {seen:?}");
            }
        }
    }
}
