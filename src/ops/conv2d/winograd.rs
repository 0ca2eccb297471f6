//! Winograd F(2×2, 3×3) for the 3×3 convolutions with many channels (the nets' trunks).
//!
//! Direct 3×3 convolution needs 9 multiply-adds per (output pixel, c_in, c_out); F(2×2, 3×3)
//! needs 16 per 2×2 output tile, 4 per pixel (Lavin & Gray 2016, "Fast Algorithms for
//! Convolutional Neural Networks"): each 4×4 input tile d and 3×3 kernel g are transformed,
//! V = Bᵀ d B and U = G g Gᵀ, multiplied element-wise and summed over c_in (16 small GEMMs,
//! one per tile position), and the 4×4 sum M goes back to the 2×2 output as Aᵀ M A.
//!
//!   Bᵀ = [1 0 −1 0; 0 1 1 0; 0 −1 1 0; 0 1 0 −1]
//!   G  = [1 0 0; ½ ½ ½; ½ −½ ½; 0 0 1]
//!   Aᵀ = [1 1 1 0; 0 1 −1 −1]
//!
//! Every entry is 0, ±1 or ±½, so the transforms add no rounding beyond the adds themselves;
//! the fast-vs-reference and JAX audits pass at the direct kernel's tolerances.
//!
//! F(4×4, 3×3) ([`Tile::F4`], `--precision fp32-fast` only) takes 6×6 input tiles to 4×4
//! outputs: 36 multiply-adds per tile, 2.25 per pixel, 1.8× fewer than F(2×2, 3×3), with
//! the interpolation points 0, ±1, ±2, ∞ (Lavin & Gray's matrices):
//!
//!   Bᵀ = [4 0 −5 0 1 0; 0 −4 −4 1 1 0; 0 4 −4 −1 1 0; 0 −2 −1 2 1 0; 0 2 −1 −2 1 0; 0 4 0 −5 0 1]
//!   G  = [¼ 0 0; −⅙ −⅙ −⅙; −⅙ ⅙ −⅙; 1⁄24 1⁄12 ⅙; 1⁄24 −1⁄12 ⅙; 0 0 1]
//!   Aᵀ = [1 1 1 1 1 0; 0 1 −1 2 −2 0; 0 1 1 4 4 0; 0 1 −1 8 −8 1]
//!
//! Its factors 5 and ⅙ round and 4, 8 grow the terms: the sums differ from the exact ones
//! 5–9× as much as F(2×2, 3×3)'s (about 2·10⁻⁵ of a 64-channel conv's typical output on random
//! inputs, against 4·10⁻⁶), so it is not the audited fp32 path and training never uses it.
//!
//! Layout: the padded channels-last input of [`super::pad_nhwc_to`], grown to whole tiles; one
//! rayon task per (image, row of tiles). A task transforms its tiles into V[pos][tile][c_in]
//! (channel vectors: 16 input channels per SIMD op), runs the direct kernel's register-tiled
//! micro-kernel as a 1×1 "convolution" per position against U[pos][c_in][c_out] (packed like
//! the direct weights, positions as taps), and transforms M[pos][tile][c_out] back into two
//! NHWC output rows for the caller's sink. Same order of operations on every run: results do
//! not depend on the thread count.

use super::{
    micro, micro_dw, pad_nhwc_to, pad_row_nhwc, reg_tiles, sum_partials, tiles, Packed, Padding, RowSink,
    Scratch, SyncPtr, L, OB, SMALL_OUT_MAX,
};
use crate::tensor::Tensor;
use rayon::prelude::*;
use wide::f32x16;

/// Positions of a 4×4 transformed tile (F(2×2, 3×3)).
const POS: usize = 16;
/// Output pixels per chunk of a row of tiles in the forward (V and M of a chunk stay in L2).
const CHUNK_PX: usize = 64;

/// The Winograd variant: F(m×m, 3×3) turns (m + 2)² input tiles into m × m outputs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Tile {
    /// F(2×2, 3×3): the audited fp32 path and training's.
    F2,
    /// F(4×4, 3×3): `--precision fp32-fast`.
    F4,
}

impl Tile {
    /// Output pixels per side of a tile.
    pub(super) fn m(self) -> usize {
        match self {
            Tile::F2 => 2,
            Tile::F4 => 4,
        }
    }

    /// Input pixels per side of a tile (m + 2).
    fn t(self) -> usize {
        self.m() + 2
    }

    /// Positions of a transformed tile.
    fn pos(self) -> usize {
        self.t() * self.t()
    }
}

/// Whether the Winograd path takes a convolution: 3×3 kernel, input channels a whole number of
/// vectors, more output channels than the pixel-vector path takes.
pub(super) fn eligible(c: usize, o: usize, kh: usize, kw: usize) -> bool {
    kh == 3 && kw == 3 && c > 0 && c.is_multiple_of(L) && o > SMALL_OUT_MAX
}

/// U = G g Gᵀ (row-major 4×4) of a 3×3 kernel g (row-major), for 16 kernels at once.
fn kernel_transform(g: [f32x16; 9]) -> [f32x16; POS] {
    let half = f32x16::splat(0.5);
    // G g: 4×3.
    let mut t = [[f32x16::ZERO; 3]; 4];
    for kx in 0..3 {
        let (g0, g1, g2) = (g[kx], g[3 + kx], g[6 + kx]);
        t[0][kx] = g0;
        t[1][kx] = half * (g0 + g1 + g2);
        t[2][kx] = half * (g0 - g1 + g2);
        t[3][kx] = g2;
    }
    // (G g) Gᵀ: 4×4.
    let mut u = [f32x16::ZERO; POS];
    for (i, [a, b, c]) in t.into_iter().enumerate() {
        u[i * 4] = a;
        u[i * 4 + 1] = half * (a + b + c);
        u[i * 4 + 2] = half * (a - b + c);
        u[i * 4 + 3] = c;
    }
    u
}

/// U = G g Gᵀ (row-major 6×6) of one 3×3 kernel g (row-major) for F(4×4, 3×3), in f64 and
/// rounded once.
fn kernel_transform4(g: [f32; 9]) -> [f32; 36] {
    const G: [[f64; 3]; 6] = [
        [0.25, 0.0, 0.0],
        [-1.0 / 6.0, -1.0 / 6.0, -1.0 / 6.0],
        [-1.0 / 6.0, 1.0 / 6.0, -1.0 / 6.0],
        [1.0 / 24.0, 1.0 / 12.0, 1.0 / 6.0],
        [1.0 / 24.0, -1.0 / 12.0, 1.0 / 6.0],
        [0.0, 0.0, 1.0],
    ];
    // G g: 6×3, then (G g) Gᵀ: 6×6.
    let gg: [[f64; 3]; 6] =
        G.map(|gi| std::array::from_fn(|kx| (0..3).map(|ky| gi[ky] * g[ky * 3 + kx] as f64).sum()));
    std::array::from_fn(|p| (0..3).map(|kx| gg[p / 6][kx] * G[p % 6][kx]).sum::<f64>() as f32)
}

/// Transformed weights packed like [`super::pack_weights`] with the tile's positions as taps:
/// per block of ≤ 64 output channels, [pos][c_in][ov·16] (lanes past `o` zero).
/// `get(o, c, ky, kx)` reads the 3×3 weight.
pub(super) fn pack(
    o: usize,
    c: usize,
    tile: Tile,
    get: impl Fn(usize, usize, usize, usize) -> f32 + Sync,
) -> Packed {
    let npos = tile.pos();
    let opad = o.div_ceil(L) * L;
    let mut data = Scratch::overwritten(opad * c * npos);
    let mut blocks = Vec::new();
    let mut off = 0;
    for ob in (0..opad).step_by(OB) {
        let ov = ((opad - ob) / L).min(OB / L);
        let wdt = ov * L;
        let block = &mut data[off..off + npos * c * wdt];
        let bp = SyncPtr(block.as_mut_ptr());
        // Rayon tasks of ≥ 2048 kernels (≈ 20 µs): smaller layers are packed on one thread.
        (0..c).into_par_iter().with_min_len(2048 / wdt).for_each(|ci| {
            for jv in 0..ov {
                // 16 output channels' kernels, one per lane (lanes past `o` zero).
                let mut g = [[0.0f32; L]; 9];
                for l in 0..L.min(o.saturating_sub(ob + jv * L)) {
                    for (t, gt) in g.iter_mut().enumerate() {
                        gt[l] = get(ob + jv * L + l, ci, t / 3, t % 3);
                    }
                }
                let mut u = [f32x16::ZERO; 36];
                match tile {
                    Tile::F2 => u[..POS].copy_from_slice(&kernel_transform(g.map(f32x16::from))),
                    Tile::F4 => {
                        let mut lanes = [[0.0f32; L]; 36];
                        for l in 0..L {
                            let ul = kernel_transform4(std::array::from_fn(|t| g[t][l]));
                            for (p, v) in ul.into_iter().enumerate() {
                                lanes[p][l] = v;
                            }
                        }
                        u = lanes.map(f32x16::from);
                    }
                }
                for (pos, u) in u.into_iter().take(npos).enumerate() {
                    // SAFETY: (pos·c + ci)·wdt + jv·16 + 16 ≤ npos·c·wdt, the block's length;
                    // input channel ci's vectors are written by this task only.
                    unsafe { st(bp.get().add((pos * c + ci) * wdt + jv * L), u) };
                }
            }
        });
        blocks.push((off, ov));
        off += npos * c * wdt;
    }
    Packed { data, blocks, opad }
}

/// Padded channels-last copy of `x` for the m × m tiles of an H × W output: (H + 2) × (W + 2)
/// pixels with `pad` applied, grown with zeros to (m⌈H/m⌉ + 2) × (m⌈W/m⌉ + 2). Returns
/// (buffer, hp, wp).
pub(super) fn pad_input(x: &Tensor, pad: Padding, tile: Tile) -> (Scratch, usize, usize) {
    let (_, _, h, w) = x.dims4();
    let m = tile.m();
    pad_nhwc_to(x, 1, 1, pad, m * h.div_ceil(m) + 2, m * w.div_ceil(m) + 2, 0)
}

/// What [`correlate`] reads.
pub(super) enum Input<'a> {
    /// [`pad_input`]'s buffer: n images of hp × wp padded NHWC pixels.
    Padded { xp: &'a [f32], hp: usize, wp: usize },
    /// The NCHW tensor: each task pads the four input rows of its row of tiles itself. Rows
    /// shared by two rows of tiles are transposed twice, but the convolution is one parallel
    /// loop instead of two, which pays on small inputs (see [`FUSE_PAD_MAX`]).
    Nchw { x: &'a Tensor, pad: Padding },
}

/// Largest input (floats) whose forward pads inside the tasks ([`Input::Nchw`]). Interleaved
/// A/B on the peer bench's rows (2-core machine): at 2¹⁶, 64→64 on one 32×32 image 7 % faster,
/// the other rows within ±2 %; at 2²¹ (every row) 32→32 on 64×64 and the small nets 9–11 %
/// slower, the transposing twice no longer paid for by the loop saved.
pub(super) const FUSE_PAD_MAX: usize = 1 << 16;

/// Unaligned vector load / store.
#[inline(always)]
unsafe fn ld(p: *const f32) -> f32x16 {
    (p as *const f32x16).read_unaligned()
}

#[inline(always)]
unsafe fn st(p: *mut f32, v: f32x16) {
    (p as *mut f32x16).write_unaligned(v)
}

/// V[pos][t][c] = (Bᵀ d B)[pos] for the `tw` 4×4 input tiles of one row of tiles: `xb` points at
/// the row's top-left pixel of a padded NHWC buffer (row stride `wp` pixels, `c` channels, a
/// multiple of 16), tile t at columns 2t..2t+4; `v` receives tile t at t·c, position stride `vs`.
///
/// # Safety
/// Rows 0..4 and columns 0..2tw+2 of `xb`, and 16 positions × tw tiles of `v` in bounds.
#[inline(always)]
#[allow(clippy::needless_range_loop)]
unsafe fn input_tiles(xb: *const f32, wp: usize, c: usize, tw: usize, v: *mut f32, vs: usize) {
    for tx in 0..tw {
        let (xb, vb) = (xb.add(2 * tx * c), v.add(tx * c));
        for k in (0..c).step_by(L) {
            let d = |i: usize, j: usize| ld(xb.add((i * wp + j) * c + k));
            let mut t = [[f32x16::ZERO; 4]; 4];
            for j in 0..4 {
                let (d0, d1, d2, d3) = (d(0, j), d(1, j), d(2, j), d(3, j));
                t[0][j] = d0 - d2;
                t[1][j] = d1 + d2;
                t[2][j] = d2 - d1;
                t[3][j] = d1 - d3;
            }
            for (i, [t0, t1, t2, t3]) in t.into_iter().enumerate() {
                for (j, r) in [t0 - t2, t1 + t2, t2 - t1, t1 - t3].into_iter().enumerate() {
                    st(vb.add((i * 4 + j) * vs + k), r);
                }
            }
        }
    }
}

/// Bᵀ d of one column (or row) of a 6×6 tile, F(4×4, 3×3), with fused multiply-adds (this
/// path is not the audited one: 14 operations instead of 21).
#[inline(always)]
fn bt6([d0, d1, d2, d3, d4, d5]: [f32x16; 6]) -> [f32x16; 6] {
    let (two, four, m4, m5) =
        (f32x16::splat(2.0), f32x16::splat(4.0), f32x16::splat(-4.0), f32x16::splat(-5.0));
    let (a, b) = (d4 - d2, two * (d3 - d1));
    [
        four.mul_add(d0, m5.mul_add(d2, d4)),
        m4.mul_add(d1 + d2, d3 + d4),
        four.mul_add(d1 - d2, d4 - d3),
        a + b,
        a - b,
        four.mul_add(d1, m5.mul_add(d3, d5)),
    ]
}

/// [`input_tiles`] for F(4×4, 3×3): V[pos][t][c] = (Bᵀ d B)[pos] (36 positions) for the `tw`
/// 6×6 input tiles of one row of tiles, tile t at columns 4t..4t+6. Bᵀ d is taken once per
/// input column into `col` (neighbouring tiles share two columns), then B row by row.
/// The intermediates go through `col`, not arrays on the stack, which the compiler zeroed and
/// copied with `memset` and `memmove` (11 % of `upscale`'s samples).
///
/// # Safety
/// Rows 0..6 and columns 0..4tw+2 of `xb`, 36 positions × tw tiles of `v`, and
/// [`col_len`]`(tw)` floats of `col` in bounds.
#[inline(always)]
unsafe fn input_tiles4(
    xb: *const f32,
    wp: usize,
    c: usize,
    tw: usize,
    v: *mut f32,
    vs: usize,
    col: *mut f32,
) {
    for k in (0..c).step_by(L) {
        for x in 0..4 * tw + 2 {
            let cx = bt6(std::array::from_fn(|i| ld(xb.add((i * wp + x) * c + k))));
            for (i, r) in cx.into_iter().enumerate() {
                st(col.add((x * 6 + i) * L), r);
            }
        }
        for tx in 0..tw {
            let vb = v.add(tx * c + k);
            for i in 0..6 {
                let row = bt6(std::array::from_fn(|j| ld(col.add(((4 * tx + j) * 6 + i) * L))));
                for (j, r) in row.into_iter().enumerate() {
                    st(vb.add((i * 6 + j) * vs), r);
                }
            }
        }
    }
}

/// Floats of [`input_tiles4`]'s column scratch for `tw` tiles.
fn col_len(tw: usize) -> usize {
    (4 * tw + 2) * 6 * L
}

/// Two output rows init + Aᵀ M A of the `ntw` tiles of M (tile t at t·opad, position stride
/// `ms`), F(2×2, 3×3): pixels 2t, 2t + 1 at `out` (pixel stride `opad`, row stride `row_len`).
///
/// # Safety
/// 16 positions × ntw tiles of M, 2 rows × 2ntw pixels of `out`, `init` of opad floats.
#[inline(always)]
#[allow(clippy::needless_range_loop)]
unsafe fn output_tiles(
    m: *const f32,
    ms: usize,
    ntw: usize,
    opad: usize,
    init: Option<&[f32]>,
    out: *mut f32,
    row_len: usize,
) {
    for tx in 0..ntw {
        let (mb, ob) = (m.add(tx * opad), out.add(2 * tx * opad));
        for k in (0..opad).step_by(L) {
            let mm = |i: usize, j: usize| ld(mb.add((i * 4 + j) * ms + k));
            let b0 = init.map_or(f32x16::ZERO, |b| ld(b.as_ptr().add(k)));
            let mut s = [[f32x16::ZERO; 4]; 2];
            for j in 0..4 {
                let (m0, m1, m2, m3) = (mm(0, j), mm(1, j), mm(2, j), mm(3, j));
                s[0][j] = m0 + m1 + m2;
                s[1][j] = m1 - m2 - m3;
            }
            for (r, [s0, s1, s2, s3]) in s.into_iter().enumerate() {
                st(ob.add(r * row_len + k), b0 + (s0 + s1 + s2));
                st(ob.add(r * row_len + opad + k), b0 + (s1 - s2 - s3));
            }
        }
    }
}

/// Aᵀ m of one column (or row) of a 6×6 tile, F(4×4, 3×3), with fused multiply-adds.
#[inline(always)]
fn at6([m0, m1, m2, m3, m4, m5]: [f32x16; 6]) -> [f32x16; 4] {
    let (two, four, eight) = (f32x16::splat(2.0), f32x16::splat(4.0), f32x16::splat(8.0));
    let (p12, d12, p34, d34) = (m1 + m2, m1 - m2, m3 + m4, m3 - m4);
    [(m0 + p12) + p34, two.mul_add(d34, d12), four.mul_add(p34, p12), eight.mul_add(d34, d12) + m5]
}

/// [`output_tiles`] for F(4×4, 3×3): four output rows, pixels 4t..4t+4 of tile t; Aᵀ m per
/// column through `tmp` (24 vectors), then A per row.
///
/// # Safety
/// 36 positions × ntw tiles of M, 4 rows × 4ntw pixels of `out`, `init` of opad floats, 24·16
/// floats of `tmp`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
unsafe fn output_tiles4(
    m: *const f32,
    ms: usize,
    ntw: usize,
    opad: usize,
    init: Option<&[f32]>,
    out: *mut f32,
    row_len: usize,
    tmp: *mut f32,
) {
    for tx in 0..ntw {
        let (mb, ob) = (m.add(tx * opad), out.add(4 * tx * opad));
        for k in (0..opad).step_by(L) {
            let b0 = init.map_or(f32x16::ZERO, |b| ld(b.as_ptr().add(k)));
            for j in 0..6 {
                let col = at6(std::array::from_fn(|i| ld(mb.add((i * 6 + j) * ms + k))));
                for (r, v) in col.into_iter().enumerate() {
                    st(tmp.add((r * 6 + j) * L), v);
                }
            }
            for r in 0..4 {
                let row = at6(std::array::from_fn(|j| ld(tmp.add((r * 6 + j) * L))));
                for (x, v) in row.into_iter().enumerate() {
                    st(ob.add(r * row_len + x * opad + k), b0 + v);
                }
            }
        }
    }
}

/// 3×3 correlation of a padded NHWC input (n images of hp × wp pixels, c channels, with
/// hp ≥ m⌈out_h/m⌉ + 2 and wp ≥ m⌈out_w/m⌉ + 2 for the tile's m) with weights from [`pack`]
/// for `tile`, into out_h × out_w outputs per image: out[y][x] = init + Σ_{ky,kx,c} w ·
/// xp[y + ky][x + kx]. For every output row, `sink(n, y, row)` gets the row as NHWC scratch
/// (out_w or more pixels × opad floats).
#[allow(clippy::too_many_arguments)]
pub(super) fn correlate(
    input: &Input,
    n: usize,
    c: usize,
    pk: &Packed,
    tile: Tile,
    init: Option<&[f32]>,
    out_h: usize,
    out_w: usize,
    sink: &RowSink,
) {
    let (m, npos) = (tile.m(), tile.pos());
    let (th, tw) = (out_h.div_ceil(m), out_w.div_ceil(m));
    let (hp, wp) = match *input {
        Input::Padded { xp, hp, wp } => {
            assert!(xp.len() >= n * hp * wp * c);
            (hp, wp)
        }
        Input::Nchw { x, .. } => {
            assert_eq!(x.dims4(), (n, c, out_h, out_w));
            (m * th + 2, m * tw + 2)
        }
    };
    assert!(c.is_multiple_of(L) && hp >= m * th + 2 && wp >= m * tw + 2);
    let opad = pk.opad;
    assert!(pk.data.len() >= npos * c * opad && init.is_none_or(|b| b.len() >= opad));
    // One output row of the task, NHWC.
    let row_len = m * tw * opad;
    // A row of tiles is done in chunks of ≤ CHUNK_PX pixels, so V and M stay in L2 on wide
    // images. Their position strides are one cache line more than the data, so the streams a
    // transform reads or writes are not 4 KiB apart (4K aliasing stalls loads behind stores).
    let chunk = tw.min(CHUNK_PX / m);
    // Short rows of tiles (small images, F(4×4)'s 8 tiles a row at 32²) are taken g rows to a
    // task, so the products' register tiles run on up to `chunk` tiles, not a few: as many g
    // as fit a chunk while every thread keeps about four tasks. Which tiles share a product call
    // never changes an output's sum: the bits do not depend on g.
    let fit = if 2 * tw <= CHUNK_PX / m { (CHUNK_PX / m) / tw } else { 1 };
    let g = fit.min((n * th / (4 * rayon::current_num_threads())).max(1)).min(th);
    let groups = th.div_ceil(g);
    let tiles_max = chunk.max(g * tw);
    let (vs, ms) = (tiles_max * c + L, tiles_max * opad + L);
    (0..n * groups).into_par_iter().for_each_init(
        || {
            (
                // F(4×4, 3×3)'s transforms take their intermediates past V's and M's end.
                Scratch::overwritten(npos * vs + if tile == Tile::F4 { col_len(chunk) } else { 0 }),
                Scratch::overwritten(npos * ms + if tile == Tile::F4 { 24 * L } else { 0 }),
                Scratch::overwritten(g * m * row_len),
                Scratch::overwritten(if matches!(input, Input::Nchw { .. }) {
                    (g * m + 2) * wp * c
                } else {
                    0
                }),
            )
        },
        |(v, mt, out, strip): &mut (Scratch, Scratch, Scratch, Scratch), task| {
            let (ni, ty0) = (task / groups, (task % groups) * g);
            let nr = g.min(th - ty0); // rows of tiles in this task
                                      // The task's m·nr + 2 padded input rows: in the padded buffer, or padded here.
            let (rows, r0) = match *input {
                Input::Padded { xp, .. } => (xp, (ni * hp + m * ty0) * wp * c),
                Input::Nchw { x, pad } => {
                    for (r, dst) in strip.chunks_exact_mut(wp * c).take(m * nr + 2).enumerate() {
                        pad_row_nhwc(x, ni, m * ty0 + r, 1, 1, pad, dst);
                    }
                    (&strip[..], 0)
                }
            };
            for (tx0, ntw) in tiles(tw, chunk) {
                // With nr > 1 the chunk is the whole row (tw ≤ chunk): its nr rows of tiles
                // side by side in V and M, row r's tiles from r·ntw on.
                for r in 0..nr {
                    // V[pos][tile][c] = Bᵀ d B.
                    // SAFETY: the tiles cover rows m(ty0 + r)..m(ty0 + r + 1) + 2 ≤ hp, columns
                    // m·tx0..m(tx0+ntw)+2 ≤ wp of image ni (asserted above), at r0 in `rows`;
                    // V holds nr·ntw ≤ tiles_max tiles per position.
                    unsafe {
                        let xb = rows.as_ptr().add(r0 + (m * r * wp + m * tx0) * c);
                        let vb = v.as_mut_ptr().add(r * ntw * c);
                        match tile {
                            Tile::F2 => input_tiles(xb, wp, c, ntw, vb, vs),
                            Tile::F4 => {
                                let col = v.as_mut_ptr().add(npos * vs);
                                input_tiles4(xb, wp, c, ntw, vb, vs, col)
                            }
                        }
                    };
                }
                let nt = nr * ntw;
                // M[pos][tile][o] = Σ_c V[pos][tile][c] · U[pos][c][o] (every element written).
                for pos in 0..npos {
                    for (bi, &(off, ov)) in pk.blocks.iter().enumerate() {
                        for (x0, np, j0, ot) in reg_tiles(nt, ov) {
                            // SAFETY: tiles x0..x0+np < nt of position pos in V (c floats each)
                            // and in M (opad floats each, channels bi·64..bi·64+ov·16 ≤ opad);
                            // the block's position pos holds c rows of ov·16 weights, of which
                            // the tile takes vectors j0..j0+ot.
                            unsafe {
                                let xptr = v.as_ptr().add(pos * vs + x0 * c);
                                let wptr = pk.data.as_ptr().add(off + pos * c * ov * L + j0 * L);
                                let ws = ov * L;
                                let aptr = mt.as_mut_ptr().add(pos * ms + x0 * opad + bi * OB + j0 * L);
                                match ot {
                                    4 => dispatch_p!(
                                        micro, 4, np, xptr, 0, c, 1, 1, wptr, ws, aptr, opad, false
                                    ),
                                    3 => dispatch_p!(
                                        micro, 3, np, xptr, 0, c, 1, 1, wptr, ws, aptr, opad, false
                                    ),
                                    2 => dispatch_p!(
                                        micro, 2, np, xptr, 0, c, 1, 1, wptr, ws, aptr, opad, false
                                    ),
                                    _ => dispatch_p!(
                                        micro, 1, np, xptr, 0, c, 1, 1, wptr, ws, aptr, opad, false
                                    ),
                                }
                            }
                        }
                    }
                }
                for r in 0..nr {
                    // m output rows per row of tiles: init + Aᵀ M A.
                    // SAFETY: tiles r·ntw..(r+1)·ntw of M at every position; pixels
                    // m·tx0..m(tx0+ntw) of rows m·r..m·r+m of `out` (g·m rows of m·tw pixels
                    // of opad floats); init has opad floats.
                    unsafe {
                        let mb = mt.as_ptr().add(r * ntw * opad);
                        let ob = out.as_mut_ptr().add(m * r * row_len + m * tx0 * opad);
                        match tile {
                            Tile::F2 => output_tiles(mb, ms, ntw, opad, init, ob, row_len),
                            Tile::F4 => {
                                let tmp = mt.as_mut_ptr().add(npos * ms);
                                output_tiles4(mb, ms, ntw, opad, init, ob, row_len, tmp)
                            }
                        }
                    }
                }
            }
            for (r, row) in out.chunks_exact(row_len).take(m * nr).enumerate() {
                if m * ty0 + r < out_h {
                    sink(ni, m * ty0 + r, row);
                }
            }
        },
    );
}

// ---------------------------------------------------------------------------------------------
// Weight gradient. The forward is y = Aᵀ [U ⊙ V] A per tile with U = G g Gᵀ, so
//   ∂L/∂g = Gᵀ [ Σ_tiles (A dY Aᵀ) ⊙ (Bᵀ d B) ] G,
// where dY is the tile's 2×2 output gradient (0 past the image). The sum over tiles is one GEMM
// per position, dU[pos][c][o] = Σ_t V[pos][t][c] · Z[pos][t][o] with Z = A dY Aᵀ: 16 multiply-
// adds per tile per (c, o) instead of 36.
// ---------------------------------------------------------------------------------------------

/// Whether [`weight_grad`] takes a gradient: 3×3, input and output channels whole vectors.
pub(super) fn eligible_weight_grad(c: usize, o: usize, kh: usize, kw: usize) -> bool {
    kh == 3 && kw == 3 && c > 0 && c.is_multiple_of(L) && o > 0 && o.is_multiple_of(L)
}

/// Tiles per part of the weight gradient's sum (V and Z of a part stay in L2).
const DW_TILES: usize = 128;

/// dw += ∂L/∂w (same contract as [`super::conv2d_weight_grad`]) for [`eligible_weight_grad`]
/// shapes. The rows of tiles are cut into parts of about [`DW_TILES`] tiles (from the problem
/// size, not the thread count), each summed into its own partial dU; the partials are added in
/// a fixed order, so results do not depend on the thread count.
#[allow(clippy::needless_range_loop)]
pub(super) fn weight_grad(x: &Tensor, dy: &Tensor, pad: Padding, dw: &mut Tensor) {
    let (n, c, h, w) = x.dims4();
    let o = dy.shape[1];
    assert!(eligible_weight_grad(c, o, 3, 3) && dw.shape == [o, c, 3, 3]);
    let (th, tw) = (h.div_ceil(2), w.div_ceil(2));
    let (xp, hp, wp) = pad_input(x, pad, Tile::F2);
    // dy channels-last on the 2th × 2tw tile grid, zero past the image.
    let (dq, _, _) = pad_nhwc_to(dy, 0, 0, Padding::Zero, 2 * th, 2 * tw, 0);
    let rows = n * th; // rows of tiles
    let rows_per_part = (DW_TILES / tw).clamp(1, rows);
    let parts = rows.div_ceil(rows_per_part);
    let (vs, zs) = (rows_per_part * tw * c + L, rows_per_part * tw * o + L);
    let oblocks: Vec<(usize, usize)> =
        (0..o).step_by(OB).map(|ob| (ob, ((o - ob) / L).min(OB / L))).collect();
    let partials: Vec<Scratch> = (0..parts)
        .into_par_iter()
        .map(|pi| {
            let (r0, r1) = (pi * rows_per_part, ((pi + 1) * rows_per_part).min(rows));
            let nt = (r1 - r0) * tw; // tiles in this part
            let mut v = Scratch::overwritten(POS * vs);
            let mut z = Scratch::overwritten(POS * zs);
            for r in r0..r1 {
                let (ni, ty) = (r / th, r % th);
                let t0 = (r - r0) * tw;
                // SAFETY: tile row ty of image ni lies inside xp (hp ≥ 2th + 2, wp ≥ 2tw + 2) and
                // dq (2th × 2tw pixels of o channels); V and Z hold nt ≤ rows_per_part·tw tiles.
                unsafe {
                    input_tiles(
                        xp.as_ptr().add((ni * hp + 2 * ty) * wp * c),
                        wp,
                        c,
                        tw,
                        v.as_mut_ptr().add(t0 * c),
                        vs,
                    );
                    grad_tiles(
                        dq.as_ptr().add((ni * 2 * th + 2 * ty) * 2 * tw * o),
                        tw,
                        o,
                        z.as_mut_ptr().add(t0 * o),
                        zs,
                    );
                }
            }
            // dU[pos][c][o] = Σ_t V[pos][t][c] · Z[pos][t][o].
            let mut du = Scratch::zeroed(POS * c * o);
            for pos in 0..POS {
                for &(ob, ov) in &oblocks {
                    for (c0, np, j0, ot) in reg_tiles(c, ov) {
                        // SAFETY: nt tiles of V (stride c) and Z (stride o) at position pos,
                        // channels c0..c0+np of V, ob+16·j0..ob+16·(j0+ot) ≤ o of Z and of dU.
                        unsafe {
                            let xptr = v.as_ptr().add(pos * vs + c0);
                            let dptr = z.as_ptr().add(pos * zs + ob + j0 * L);
                            let aptr = du.as_mut_ptr().add((pos * c + c0) * o + ob + j0 * L);
                            match ot {
                                4 => dispatch_p!(micro_dw, 4, np, xptr, c, dptr, o, nt, aptr, o),
                                3 => dispatch_p!(micro_dw, 3, np, xptr, c, dptr, o, nt, aptr, o),
                                2 => dispatch_p!(micro_dw, 2, np, xptr, c, dptr, o, nt, aptr, o),
                                _ => dispatch_p!(micro_dw, 1, np, xptr, c, dptr, o, nt, aptr, o),
                            }
                        }
                    }
                }
            }
            du
        })
        .collect();
    // Fixed-order sum of the partials, then dw[o][c] += Gᵀ dU G.
    let Some(du) = sum_partials(partials) else {
        return;
    };
    for ci in 0..c {
        for oi in 0..o {
            let m = |i: usize, j: usize| du[((i * 4 + j) * c + ci) * o + oi];
            // Gᵀ M: 3×4, then (Gᵀ M) G: 3×3.
            let mut t = [[0.0f32; 4]; 3];
            for j in 0..4 {
                let (m0, m1, m2, m3) = (m(0, j), m(1, j), m(2, j), m(3, j));
                t[0][j] = m0 + 0.5 * (m1 + m2);
                t[1][j] = 0.5 * (m1 - m2);
                t[2][j] = 0.5 * (m1 + m2) + m3;
            }
            let g = &mut dw.data[(oi * c + ci) * 9..][..9];
            for (ky, [t0, t1, t2, t3]) in t.into_iter().enumerate() {
                g[ky * 3] += t0 + 0.5 * (t1 + t2);
                g[ky * 3 + 1] += 0.5 * (t1 - t2);
                g[ky * 3 + 2] += 0.5 * (t1 + t2) + t3;
            }
        }
    }
}

/// Z[pos][t][o] = (A dY Aᵀ)[pos] for the `tw` 2×2 output-gradient tiles of one row of tiles:
/// `dq` points at the row's top-left pixel of an NHWC buffer (row stride 2tw pixels, `o`
/// channels, a multiple of 16); `z` receives tile t at t·o, position stride `zs`.
///
/// # Safety
/// Rows 0..2 and columns 0..2tw of `dq`, and 16 positions × tw tiles of `z` in bounds.
#[inline(always)]
#[allow(clippy::needless_range_loop)]
unsafe fn grad_tiles(dq: *const f32, tw: usize, o: usize, z: *mut f32, zs: usize) {
    for tx in 0..tw {
        let (db, zb) = (dq.add(2 * tx * o), z.add(tx * o));
        for k in (0..o).step_by(L) {
            let d = |a: usize, b: usize| ld(db.add((a * 2 * tw + b) * o + k));
            // A dY: 4×2 (rows dY0, dY0 + dY1, dY0 − dY1, −dY1), then (A dY) Aᵀ: 4×4.
            let mut t = [[f32x16::ZERO; 2]; 4];
            for b in 0..2 {
                let (d0, d1) = (d(0, b), d(1, b));
                t[0][b] = d0;
                t[1][b] = d0 + d1;
                t[2][b] = d0 - d1;
                t[3][b] = f32x16::ZERO - d1;
            }
            for (i, [t0, t1]) in t.into_iter().enumerate() {
                for (j, r) in [t0, t0 + t1, t0 - t1, f32x16::ZERO - t1].into_iter().enumerate() {
                    st(zb.add((i * 4 + j) * zs + k), r);
                }
            }
        }
    }
}
