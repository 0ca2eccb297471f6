//! The bf16 forward on AMX tiles or AVX512_BF16 (`--precision bf16`): inference only; training, `audit` and
//! the fp32 path never come here.
//!
//! Inputs and weights are rounded to bf16 (round to nearest even, [`bf16`]), products are
//! summed in f32 by `tdpbf16ps`. A tile holds 16 rows of 64 bytes: an input tile (A) is 16
//! consecutive output pixels × 32 input channels of one tap, read straight from the padded
//! channels-last bf16 input (row stride: one pixel), so no im2col copy is made; a weight tile
//! (B) is 16 pairs of input channels × 16 output channels × 2 (the pair interleaved, AMX's
//! "VNNI" layout), packed once ([`pack`]); an accumulator tile (C) is 16 pixels × 16 output
//! channels in f32. Eight tile registers: up to 2 × 2 accumulators, 2 input and 2 weight
//! tiles, so each tile loaded feeds two products (a weight tile four, on hi + lo pairs). The
//! row scratch starts at the bias, the tiles accumulate on it, and the same store as the fp32
//! kernels ([`super::conv2d_packed`]'s sink) moves it to NCHW with the skip and ReLU.
//!
//! Without tiles (a CPU with AVX512_BF16 only, or `ANISOCB_NO_AMX=1`) the same packed weights
//! and activations go through [`block_dot`]: `vdpbf16ps` against each input pixel's channel
//! pair broadcast, the result in the same row scratch ([`tiles`] says which runs).
//!
//! Output rows are padded to whole 16-pixel tiles: the lanes past the row's end read the next
//! padded row (or the zero slack after the last) and are never stored. Same input, same bits:
//! the tile arithmetic has one order, and tasks are whole rows.
//!
//! The twin this is tested against is [`conv2d_bf16_ref`]: the scalar reference on the
//! bf16-rounded input and weights (tests/conv_fast_vs_ref.rs).

use super::*;
use std::arch::asm;
use std::sync::OnceLock;

/// Input channels per tile (32 bf16 = 64 bytes) and pixels / output channels per tile.
const KT: usize = 32;
const T: usize = 16;
/// bf16 values per tile (16 rows × 32).
const TILE: usize = T * KT;

/// f32 → bf16, round to nearest even; NaN stays a (quiet) NaN.
#[inline(always)]
pub fn bf16(v: f32) -> u16 {
    let u = v.to_bits();
    if v.is_nan() {
        return ((u >> 16) | 0x40) as u16;
    }
    ((u + 0x7fff + ((u >> 16) & 1)) >> 16) as u16
}

/// bf16 → f32 (exact).
#[inline(always)]
pub fn f32_of_bf16(b: u16) -> f32 {
    f32::from_bits((b as u32) << 16)
}

/// A pooled f32 buffer viewed from a 64-byte boundary on: a tile row (64 bytes) then never
/// straddles two cache lines (unaligned tiles ran the convs at half the speed).
pub(super) struct Aligned {
    buf: Scratch,
    off: usize,
    len: usize,
}

impl Aligned {
    /// `len` floats, values unspecified.
    pub(super) fn new(len: usize) -> Aligned {
        let buf = Scratch::overwritten(len + 15);
        let off = (64 - buf.as_ptr() as usize % 64) % 64 / 4;
        Aligned { buf, off, len }
    }
}

impl std::ops::Deref for Aligned {
    type Target = [f32];
    fn deref(&self) -> &[f32] {
        &self.buf[self.off..self.off + self.len]
    }
}

impl std::ops::DerefMut for Aligned {
    fn deref_mut(&mut self) -> &mut [f32] {
        &mut self.buf[self.off..self.off + self.len]
    }
}

/// Whether this CPU runs the bf16 kernels: AMX tiles ([`tiles`]) or, without them, AVX512_BF16
/// dot products (`vdpbf16ps`: Intel since Cooper Lake, AMD since Zen 4). Checked once;
/// `ANISOCB_NO_BF16=1` says no (to run the fp32 fallback on a machine that has them, as a CPU
/// without AVX-512 would).
pub fn available() -> bool {
    static AVAILABLE: OnceLock<bool> = OnceLock::new();
    *AVAILABLE.get_or_init(|| std::env::var_os("ANISOCB_NO_BF16").is_none() && has_avx512_bf16())
}

/// Whether the bf16 kernels run on AMX tiles: [`available`], and the CPU has AMX-BF16 tiles and
/// the OS lets this process use them (on Linux the tile data state must be asked for once per
/// process: `arch_prctl(ARCH_REQ_XCOMP_PERM)`). `ANISOCB_NO_AMX=1` says no: the dot-product
/// kernel then runs, as on a CPU with AVX512_BF16 and no tiles.
pub fn tiles() -> bool {
    static TILES: OnceLock<bool> = OnceLock::new();
    *TILES.get_or_init(|| available() && std::env::var_os("ANISOCB_NO_AMX").is_none() && detect_tiles())
}

#[cfg(target_arch = "x86_64")]
fn has_avx512_bf16() -> bool {
    std::arch::is_x86_feature_detected!("avx512f") && std::arch::is_x86_feature_detected!("avx512bf16")
}

#[cfg(not(target_arch = "x86_64"))]
fn has_avx512_bf16() -> bool {
    false
}

#[cfg(all(target_arch = "x86_64", target_os = "linux"))]
fn detect_tiles() -> bool {
    use std::arch::x86_64::{__cpuid, __cpuid_count};
    // CPUID.(EAX=7,ECX=0):EDX bit 22 AMX-BF16, bit 24 AMX-TILE.
    let has = __cpuid(0).eax >= 7 && (__cpuid_count(7, 0).edx >> 22) & 0b101 == 0b101;
    if !has {
        return false;
    }
    const SYS_ARCH_PRCTL: i64 = 158;
    const ARCH_REQ_XCOMP_PERM: i64 = 0x1023;
    const XFEATURE_XTILEDATA: i64 = 18;
    let ret: i64;
    // SAFETY: arch_prctl(ARCH_REQ_XCOMP_PERM, XTILEDATA) only grants this process the tile
    // state (or fails with -errno on a kernel without it); the syscall clobbers rcx and r11.
    unsafe {
        asm!("syscall", inlateout("rax") SYS_ARCH_PRCTL => ret, in("rdi") ARCH_REQ_XCOMP_PERM,
            in("rsi") XFEATURE_XTILEDATA, lateout("rcx") _, lateout("r11") _, options(nostack));
    }
    ret == 0
}

#[cfg(not(all(target_arch = "x86_64", target_os = "linux")))]
fn detect_tiles() -> bool {
    false
}

/// Whether [`pack`] takes a conv of `c` input and `o` output channels (the rest stay fp32:
/// the 3-channel first conv and the small last convs, which also keep the geometry's own
/// precision at both ends of a net).
pub(super) fn eligible(c: usize, o: usize) -> bool {
    c.is_multiple_of(KT) && o > SMALL_OUT_MAX
}

/// Weights packed into B tiles, [tap][c block of 32][o block of 16][16 pairs][16 × 2]; for
/// split inputs one copy, which both halves are multiplied by ([`block`]).
pub(super) struct AmxPacked {
    /// The tiles, from `data[off]` (64-byte aligned) on.
    data: Vec<u16>,
    off: usize,
    /// (O, C, KH, KW).
    shape: [usize; 4],
    /// Output channels rounded up to a multiple of 16.
    pub(super) opad: usize,
    /// The pixel shuffle r its output channels are ordered for ([`pack`]); 1: none.
    pub(super) shuffle: usize,
    /// Inputs as bf16 pairs hi + lo ([`split`]): `shape[1]` counts both halves.
    pub(super) split: bool,
}

/// Pack (O, C, KH, KW) weights, `get(o, c, ky, kx)`. With `shuffle` = r > 1 the output channels
/// are reordered for a pixel shuffle fused into the store ([`conv_act`]): packed channel
/// q = (i·r + j)·(O/r²) + c computes channel c·r² + i·r + j, so the channels of each of the r²
/// sub-pixels lie together.
pub(super) fn pack(
    o: usize,
    c: usize,
    kh: usize,
    kw: usize,
    shuffle: usize,
    split: bool,
    get: impl Fn(usize, usize, usize, usize) -> f32,
) -> AmxPacked {
    assert!(c.is_multiple_of(KT), "amx: {c} input channels is not a multiple of {KT}");
    // Split inputs: channels [hi 0..c, lo 0..c], both times the same weights, packed once.
    let r2 = shuffle * shuffle;
    assert!(o.is_multiple_of(r2), "amx: {o} output channels do not shuffle by {shuffle}");
    let get = |q: usize, ci: usize, ky: usize, kx: usize| get((q % (o / r2)) * r2 + q / (o / r2), ci, ky, kx);
    let (nkb, nob) = (c / KT, o.div_ceil(T));
    let len = kh * kw * nkb * nob * TILE;
    let mut data = vec![0u16; len + 32];
    let off = (64 - data.as_ptr() as usize % 64) % 64 / 2;
    for (i, tile) in data[off..off + len].chunks_exact_mut(TILE).enumerate() {
        let (tap, kb, ob) = (i / (nkb * nob), i / nob % nkb, i % nob);
        let (ky, kx) = (tap / kw, tap % kw);
        for (r, row) in tile.chunks_exact_mut(2 * T).enumerate() {
            for j in 0..T {
                let oi = ob * T + j;
                if oi < o {
                    for e in 0..2 {
                        row[2 * j + e] = bf16(get(oi, kb * KT + 2 * r + e, ky, kx));
                    }
                }
            }
        }
    }
    AmxPacked { data, off, shape: [o, c << split as usize, kh, kw], opad: nob * T, shuffle, split }
}

/// `x` (N, C, H, W) padded by (ph, pw) as bf16 channels-last: pixel (n, Y, X) at
/// ((n·Hp + Y)·Wp + X)·C (`split`: 2C, [`store_bf16`]), with 16 zero pixels of slack after
/// the last (the tiles' spill).
/// Returned as pooled f32 scratch holding the bf16 values two to a slot, and Hp, Wp.
pub(super) fn pad_input(
    x: &Tensor,
    ph: usize,
    pw: usize,
    pad: Padding,
    split: bool,
) -> (Aligned, usize, usize) {
    let (n, c0, h, w) = x.dims4();
    let c = if split { 2 * c0 } else { c0 };
    let (hp, wp) = (h + 2 * ph, w + 2 * pw);
    let row_len = wp * c;
    let mut out = Aligned::new(((n * hp * wp + T) * c).div_ceil(2));
    let bf: &mut [u16] = bytemuck::cast_slice_mut(&mut out[..]);
    let (body, slack) = bf.split_at_mut(n * hp * row_len);
    slack.fill(0);
    // Rows per rayon task: ≥ 2¹⁴ values, so small images are converted on one thread.
    let min_rows = ((1 << 14) / row_len.max(1)).max(1);
    let fresh = || Scratch::overwritten(wp * c0);
    body.par_chunks_mut(row_len).with_min_len(min_rows).enumerate().for_each_init(fresh, |f, (r, dst)| {
        pad_row_nhwc(x, r / hp, r % hp, ph, pw, pad, f);
        let simd = available();
        for (d, v) in dst.chunks_exact_mut(c).zip(f.chunks_exact(c0)) {
            if simd {
                // SAFETY: `available()` includes AVX-512F; d holds C (split: 2C) values for v's C.
                unsafe { store_bf16_avx512(d, v, split) }
            } else {
                store_bf16(d, v, split);
            }
        }
    });
    (out, hp, wp)
}

/// One pixel's channels `v` as bf16 into `d`: rounded (`d.len()` = C), or split (2C: the hi
/// parts, then the lo parts, `hi + lo` = v to 2⁻¹⁷ relative).
#[inline(always)]
fn store_bf16(d: &mut [u16], v: &[f32], split: bool) {
    if split {
        let (hi, lo) = d.split_at_mut(v.len());
        store_bf16_split(hi, lo, v);
    } else {
        d.iter_mut().zip(v).for_each(|(d, &v)| *d = bf16(v));
    }
}

/// [`store_bf16`] 16 values at a time: [`bf16`]'s integer rounding (ties to even, NaN kept
/// quiet, subnormals rounded as any value), so the same bits as the scalar twin.
///
/// # Safety
/// The CPU has AVX-512F; `d` holds `v.len()` values, twice that if `split`.
#[target_feature(enable = "avx512f")]
unsafe fn store_bf16_avx512(d: &mut [u16], v: &[f32], split: bool) {
    use std::arch::x86_64::*;
    let c = v.len();
    assert_eq!(d.len(), c * (1 + split as usize), "store_bf16: {} slots for {c} values", d.len());
    let round = |x: __m512| -> __m256i {
        let u = _mm512_castps_si512(x);
        let odd = _mm512_and_si512(_mm512_srli_epi32::<16>(u), _mm512_set1_epi32(1));
        let r =
            _mm512_srli_epi32::<16>(_mm512_add_epi32(_mm512_add_epi32(u, _mm512_set1_epi32(0x7fff)), odd));
        let quiet = _mm512_or_si512(_mm512_srli_epi32::<16>(u), _mm512_set1_epi32(0x40));
        let nan = _mm512_cmp_ps_mask::<_CMP_UNORD_Q>(x, x);
        _mm512_cvtepi32_epi16(_mm512_mask_blend_epi32(nan, r, quiet))
    };
    let widen = |h: __m256i| _mm512_castsi512_ps(_mm512_slli_epi32::<16>(_mm512_cvtepu16_epi32(h)));
    let c16 = c / 16 * 16;
    for c0 in (0..c16).step_by(16) {
        let x = _mm512_loadu_ps(v.as_ptr().add(c0));
        let hi = round(x);
        _mm256_storeu_si256(d.as_mut_ptr().add(c0) as *mut __m256i, hi);
        if split {
            let lo = round(_mm512_sub_ps(x, widen(hi)));
            _mm256_storeu_si256(d.as_mut_ptr().add(c + c0) as *mut __m256i, lo);
        }
    }
    if split {
        let (hi, lo) = d.split_at_mut(c);
        store_bf16_split(&mut hi[c16..], &mut lo[c16..], &v[c16..]);
    } else {
        store_bf16(&mut d[c16..], &v[c16..], false);
    }
}

/// `v` as bf16 pairs: hi = bf16(v), lo = bf16(v − hi).
#[inline(always)]
fn store_bf16_split(hi: &mut [u16], lo: &mut [u16], v: &[f32]) {
    for ((h, l), &v) in hi.iter_mut().zip(lo).zip(v) {
        *h = bf16(v);
        *l = bf16(v - f32_of_bf16(*h));
    }
}

/// [`store_pixel`] for w pixels: source pixel x at `row[x·opad + off ..][..oc]`, its bias
/// `bias[..oc]`, destination at `out[x·stride ..]` (a pixel-shuffled row: every r-th pixel),
/// skip pixel x at `skip[x·os ..]`. One call a row: the bounds are checked once here, and the
/// row's options pick one instance of the pixel loop, so no pixel tests them again.
///
/// # Safety
/// The CPU has AVX512F and AVX512_BF16.
#[target_feature(enable = "avx512f,avx512bf16")]
#[allow(clippy::too_many_arguments)]
unsafe fn store_pixels(
    row: &[f32],
    opad: usize,
    off: usize,
    oc: usize,
    bias: Option<&[f32]>,
    w: usize,
    out: &mut [u16],
    stride: usize,
    skip: Option<&[u16]>,
    relu: bool,
    split: bool,
) {
    let os = oc * (1 + split as usize);
    if w == 0 {
        return;
    }
    assert!(oc <= opad && off + oc <= opad && row.len() >= (w - 1) * opad + off + oc);
    assert!(stride >= os && out.len() >= (w - 1) * stride + os);
    assert!(bias.is_none_or(|b| b.len() >= oc) && skip.is_none_or(|s| s.len() >= w * os));
    let src = row.as_ptr().add(off);
    let b = bias.map_or(std::ptr::null(), |b| b.as_ptr());
    let sk = skip.map_or(std::ptr::null(), |s| s.as_ptr());
    let dst = out.as_mut_ptr();
    macro_rules! pick {
        ($($b:literal $s:literal $r:literal $p:literal),*) => {
            match (bias.is_some(), skip.is_some(), relu, split) {
                $(($b, $s, $r, $p) => for x in 0..w {
                    store_pixel::<$b, $s, $r, $p>(src.add(x * opad), b, sk.add(x * os * $s as usize),
                        dst.add(x * stride), oc)
                },)*
            }
        };
    }
    pick!(false false false false, false false false true, false false true false, false false true true,
        false true false false, false true false true, false true true false, false true true true,
        true false false false, true false false true, true false true false, true false true true,
        true true false false, true true false true, true true true false, true true true true);
}

/// The epilogue of one output pixel of [`conv_act`]: `src` (the conv's C sums, f32) + `bias`,
/// then + the skip's values (hi + lo where split), ReLU, stored as bf16 (split: hi, then lo)
/// into `px`.
/// 16 channels at a time with `vcvtneps2bf16` (round to nearest even like [`bf16`]; it reads
/// f32 subnormals, below 1.2·10⁻³⁸, as 0), the rest one by one.
///
/// # Safety
/// The CPU has AVX512F and AVX512_BF16; `src` (and `bias` where BIAS) hold C values, `px` (and
/// `sk` where SKIP) C values, 2C where SPLIT.
#[target_feature(enable = "avx512f,avx512bf16")]
#[inline]
unsafe fn store_pixel<const BIAS: bool, const SKIP: bool, const RELU: bool, const SPLIT: bool>(
    src: *const f32,
    bias: *const f32,
    sk: *const u16,
    px: *mut u16,
    c: usize,
) {
    use std::arch::x86_64::*;
    let widen = |p: *const u16| {
        _mm512_castsi512_ps(_mm512_slli_epi32::<16>(_mm512_cvtepu16_epi32(_mm256_loadu_si256(
            p as *const __m256i,
        ))))
    };
    let c16 = c / 16 * 16;
    for c0 in (0..c16).step_by(16) {
        let mut v = _mm512_loadu_ps(src.add(c0));
        if BIAS {
            v = _mm512_add_ps(v, _mm512_loadu_ps(bias.add(c0)));
        }
        if SKIP {
            v = _mm512_add_ps(v, widen(sk.add(c0)));
            if SPLIT {
                v = _mm512_add_ps(v, widen(sk.add(c + c0)));
            }
        }
        if RELU {
            // max(0, v): v where it is not below 0 (−0 and NaN kept, as `relu1`).
            v = _mm512_max_ps(_mm512_setzero_ps(), v);
        }
        let hi: __m256i = std::mem::transmute(_mm512_cvtneps_pbh(v));
        _mm256_storeu_si256(px.add(c0) as *mut __m256i, hi);
        if SPLIT {
            let rest = _mm512_sub_ps(v, widen(px.add(c0)));
            let lo: __m256i = std::mem::transmute(_mm512_cvtneps_pbh(rest));
            _mm256_storeu_si256(px.add(c + c0) as *mut __m256i, lo);
        }
    }
    for k in c16..c {
        let mut v = *src.add(k);
        if BIAS {
            v += *bias.add(k);
        }
        if SKIP {
            v += f32_of_bf16(*sk.add(k)) + if SPLIT { f32_of_bf16(*sk.add(c + k)) } else { 0.0 };
        }
        let v = if RELU { relu1(v) } else { v };
        *px.add(k) = bf16(v);
        if SPLIT {
            *px.add(c + k) = bf16(v - f32_of_bf16(*px.add(k)));
        }
    }
}

/// The tile configuration: palette 1, all eight tiles 16 rows × 64 bytes.
#[repr(C, align(64))]
struct TileConfig([u8; 64]);

const CONFIG: TileConfig = {
    let mut b = [0u8; 64];
    b[0] = 1;
    let mut t = 0;
    while t < 8 {
        b[16 + 2 * t] = 64;
        b[48 + t] = T as u8;
        t += 1;
    }
    TileConfig(b)
};

macro_rules! tile_load {
    ($t:literal, $p:expr, $stride:expr) => {
        asm!(concat!("tileloadd tmm", $t, ", [{p} + {s}*1]"), p = in(reg) $p, s = in(reg) $stride,
            options(nostack, readonly))
    };
}
macro_rules! tile_store {
    ($t:literal, $p:expr, $stride:expr) => {
        asm!(concat!("tilestored [{p} + {s}*1], tmm", $t), p = in(reg) $p, s = in(reg) $stride,
            options(nostack))
    };
}
macro_rules! tile_dot {
    ($c:literal, $a:literal, $b:literal) => {
        asm!(concat!("tdpbf16ps tmm", $c, ", tmm", $a, ", tmm", $b), options(nostack, nomem))
    };
}

/// One block of MT ≤ 2 pixel tiles × NT ≤ 2 output-channel tiles of one output row: C tiles
/// loaded from `acc` (f32, pixel stride `opad`), += Σ over taps and channel blocks, stored back.
/// `x` points at the block's first input pixel (tap 0, channel 0) of the padded bf16 input
/// (row stride `wp` pixels, `c` channels); `w` at the packed tile of (tap 0, block 0, this
/// o block). `halves` = 2 for split inputs: each weight tile, loaded once, multiplies the hi
/// block and then the lo block of its channels (6 tile loads for 8 products instead of 8, and
/// half the weights to keep in L1).
///
/// # Safety
/// The tile configuration is loaded on this thread; every tile read and written is in bounds.
#[allow(clippy::too_many_arguments)]
unsafe fn block<const MT: usize, const NT: usize>(
    x: *const u16,
    wp: usize,
    c: usize,
    kh: usize,
    kw: usize,
    w: *const u16,
    nob: usize,
    halves: usize,
    acc: *mut f32,
    opad: usize,
) {
    let (xs, cs, ws) = (c * 2, opad * 4, 2 * T * 2);
    let c01 = acc.add(T);
    let (c10, c11) = (acc.add(T * opad), acc.add(T * opad + T));
    asm!("tilezero tmm0", "tilezero tmm1", "tilezero tmm2", "tilezero tmm3", options(nostack, nomem));
    let nkb = c / KT / halves;
    for ky in 0..kh {
        for kx in 0..kw {
            let xt = x.add((ky * wp + kx) * c);
            let wt = w.add((ky * kw + kx) * nkb * nob * TILE);
            for kb in 0..nkb {
                let b0 = wt.add(kb * nob * TILE);
                tile_load!("6", b0, ws);
                if NT == 2 {
                    tile_load!("7", b0.add(TILE), ws);
                }
                for h in 0..halves {
                    let a0 = xt.add((h * nkb + kb) * KT);
                    tile_load!("4", a0, xs);
                    tile_dot!("0", "4", "6");
                    if NT == 2 {
                        tile_dot!("1", "4", "7");
                    }
                    if MT == 2 {
                        tile_load!("5", a0.add(T * c), xs);
                        tile_dot!("2", "5", "6");
                        if NT == 2 {
                            tile_dot!("3", "5", "7");
                        }
                    }
                }
            }
        }
    }
    tile_store!("0", acc, cs);
    if NT == 2 {
        tile_store!("1", c01, cs);
    }
    if MT == 2 {
        tile_store!("2", c10, cs);
        if NT == 2 {
            tile_store!("3", c11, cs);
        }
    }
}

/// [`block`] with AVX512_BF16 dot products instead of tiles, for a CPU without AMX: the same
/// packed weights and the same result. A B tile's row r holds the channel pairs (2r, 2r + 1) of
/// 16 output channels, which is what one `vdpbf16ps` multiplies with an input pixel's pair r
/// broadcast to every lane; 8 pixels × NT tiles of 16 channels are accumulated in registers,
/// over the taps and channel blocks in the tiles' order.
///
/// # Safety
/// The CPU has AVX512F and AVX512_BF16; every input pixel, weight row and accumulator of the
/// block is in bounds (as for [`block`]).
#[target_feature(enable = "avx512f,avx512bf16")]
#[allow(clippy::too_many_arguments)]
unsafe fn block_dot<const MT: usize, const NT: usize>(
    x: *const u16,
    wp: usize,
    c: usize,
    kh: usize,
    kw: usize,
    w: *const u16,
    nob: usize,
    halves: usize,
    acc: *mut f32,
    opad: usize,
) {
    use std::arch::x86_64::*;
    const G: usize = 8;
    let nkb = c / KT / halves;
    for g in (0..MT * T).step_by(G) {
        let mut s = [[_mm512_setzero_ps(); NT]; G];
        for ky in 0..kh {
            for kx in 0..kw {
                let xt = x.add((ky * wp + kx + g) * c);
                let wt = w.add((ky * kw + kx) * nkb * nob * TILE);
                for (kb, h) in (0..nkb).flat_map(|kb| (0..halves).map(move |h| (kb, h))) {
                    let (a0, b0) = (xt.add((h * nkb + kb) * KT), wt.add(kb * nob * TILE));
                    for r in 0..KT / 2 {
                        let b: [__m512bh; NT] = std::array::from_fn(|t| {
                            std::mem::transmute::<__m512i, __m512bh>(_mm512_loadu_si512(
                                b0.add(t * TILE + r * 2 * T) as *const __m512i,
                            ))
                        });
                        for (p, sp) in s.iter_mut().enumerate() {
                            let pair = (a0.add(p * c + 2 * r) as *const i32).read_unaligned();
                            let a = std::mem::transmute::<__m512i, __m512bh>(_mm512_set1_epi32(pair));
                            for (st, bt) in sp.iter_mut().zip(&b) {
                                *st = _mm512_dpbf16_ps(*st, a, *bt);
                            }
                        }
                    }
                }
            }
        }
        for (p, sp) in s.iter().enumerate() {
            for (t, st) in sp.iter().enumerate() {
                _mm512_storeu_ps(acc.add((g + p) * opad + t * T), *st);
            }
        }
    }
}

/// The most bytes of f32 sums [`correlate`] keeps between the tiles and the sink (a group of
/// rows): well inside a core's L2, so the sink reads them back from it.
const GROUP_BYTES: usize = 128 << 10;

/// Correlate the padded bf16 input ([`pad_input`]: n images of hp × wp pixels, c channels)
/// with `pk` into out_h × out_w outputs per image, starting from `init` (the bias, opad
/// floats) or 0; `sink(n, y, row)` gets each output row as NHWC scratch (≥ out_w × opad
/// floats). Tasks are runs of whole rows.
#[allow(clippy::too_many_arguments)]
pub(super) fn correlate(
    xp: &[f32],
    n: usize,
    hp: usize,
    wp: usize,
    pk: &AmxPacked,
    init: Option<&[f32]>,
    out_h: usize,
    out_w: usize,
    sink: &RowSink,
) {
    assert!(available(), "amx: bf16 kernels used on a CPU without AVX512_BF16");
    let tiles = tiles();
    let [_, c, kh, kw] = pk.shape;
    assert_eq!(xp.len() * 2 / (n * hp * wp + T).max(1), c, "amx: the input has another channel count");
    let (opad, nob, halves) = (pk.opad, pk.opad / T, 1 + pk.split as usize);
    let mt = out_w.div_ceil(T);
    assert!(out_h + kh - 1 <= hp && out_w + kw - 1 <= wp);
    // The last tile's reads end (mt·16 − out_w) pixels past the last padded row: the slack.
    assert!(xp.len() * 2 >= (n * hp * wp + T) * c, "amx: the padded input has no slack");
    // Every tile row loaded or stored starts on a 64-byte line: the buffers are [`Aligned`], a
    // pixel holds 32·k bf16 channels (64·k bytes) and a weight tile 1 KiB. A tile load split
    // across two lines measured about 3× slower, and was then no longer hidden behind the
    // products (docs/performance.md, "The tile loop on its own").
    assert!(
        (xp.as_ptr() as usize).is_multiple_of(64) && (pk.data[pk.off..].as_ptr() as usize).is_multiple_of(64),
        "amx: a tile operand is off its 64-byte lines"
    );
    let row_len = mt * T * opad;
    let rows = n * out_h;
    // Runs of rows per task: a row of a 32-channel 64-wide conv is about a microsecond of
    // tile work, as much as handing a task to a thread, so several rows go to each task.
    // A task's sums stay within GROUP_BYTES, so its sink reads them from the core's own cache.
    let per_task =
        rows.div_ceil(8 * rayon::current_num_threads()).clamp(1, (GROUP_BYTES / (row_len * 4)).max(1));
    let xb = xp.as_ptr() as *const u16 as usize;
    // A task's rows go through the tiles first, all of them, and then through the sink: every
    // switch between the tile products and the AVX-512 stores costs about half a microsecond
    // (about a row's worth of stores), so a task switches once rather than once a row.
    let fresh = || Aligned::new(row_len * per_task);
    (0..rows.div_ceil(per_task)).into_par_iter().for_each_init(fresh, |scratch: &mut Aligned, task| {
        let task_rows = task * per_task..((task + 1) * per_task).min(rows);
        if tiles {
            // SAFETY: the configuration is a valid palette-1 layout; tiles are released below.
            unsafe {
                asm!("ldtilecfg [{0}]", in(reg) &CONFIG as *const TileConfig, options(nostack, readonly))
            };
        }
        for (row, r) in scratch.chunks_exact_mut(row_len).zip(task_rows.clone()) {
            let (ni, y) = (r / out_h, r % out_h);
            let x_row = ((ni * hp + y) * wp) * c;
            for m in (0..mt).step_by(2) {
                let two_m = m + 1 < mt;
                for ob in (0..nob).step_by(2) {
                    let two_o = ob + 1 < nob;
                    // SAFETY: rows y..y+kh of image ni and pixels m·16 .. m·16+32+kw−1 of them
                    // (past the row's end into the next row or the slack, asserted above); the
                    // packed tiles of o blocks ob, ob+1 < nob; the row holds mt·16 pixels.
                    unsafe {
                        let x = (xb as *const u16).add(x_row + m * T * c);
                        let w = pk.data.as_ptr().add(pk.off + ob * TILE);
                        let acc = row.as_mut_ptr().add(m * T * opad + ob * T);
                        match (tiles, two_m, two_o) {
                            (true, true, true) => block::<2, 2>(x, wp, c, kh, kw, w, nob, halves, acc, opad),
                            (true, true, false) => block::<2, 1>(x, wp, c, kh, kw, w, nob, halves, acc, opad),
                            (true, false, true) => block::<1, 2>(x, wp, c, kh, kw, w, nob, halves, acc, opad),
                            (true, false, false) => {
                                block::<1, 1>(x, wp, c, kh, kw, w, nob, halves, acc, opad)
                            }
                            (false, true, true) => {
                                block_dot::<2, 2>(x, wp, c, kh, kw, w, nob, halves, acc, opad)
                            }
                            (false, true, false) => {
                                block_dot::<2, 1>(x, wp, c, kh, kw, w, nob, halves, acc, opad)
                            }
                            (false, false, true) => {
                                block_dot::<1, 2>(x, wp, c, kh, kw, w, nob, halves, acc, opad)
                            }
                            (false, false, false) => {
                                block_dot::<1, 1>(x, wp, c, kh, kw, w, nob, halves, acc, opad)
                            }
                        }
                    }
                }
            }
        }
        if tiles {
            // SAFETY: ends this thread's use of the tiles (their state is not kept across tasks).
            unsafe { asm!("tilerelease", options(nostack, nomem)) };
        }
        for (row, r) in scratch.chunks_exact_mut(row_len).zip(task_rows) {
            if let Some(b) = init {
                for px in row.chunks_exact_mut(opad) {
                    px.iter_mut().zip(&b[..opad]).for_each(|(v, &b)| *v += b);
                }
            }
            sink(r / out_h, r % out_h, row);
        }
    });
}

/// Activations between bf16 convs (a trunk's inner layers, [`crate::nn::layers::Trunk`]):
/// n images of H × W pixels and C channels, bf16, channels-last, padded by one pixel on every
/// side (filled for `pad`) with [`pad_input`]'s slack: what the next 3×3 conv reads as it is,
/// so the activations between two bf16 convs are never moved to NCHW f32 and back.
pub struct Act {
    data: Aligned,
    /// (N, C, H, W) of the activation (unpadded).
    pub shape: [usize; 4],
    pad: Padding,
    /// Each value as a pair of bf16, hi + lo ([`store_bf16`]): 2C values a pixel.
    split: bool,
}

impl Act {
    /// `x` (N, C, H, W) in bf16, padded for a 3×3 conv: rounded, or `split` into hi + lo.
    pub fn from_nchw(x: &Tensor, pad: Padding, split: bool) -> Act {
        let (n, c, h, w) = x.dims4();
        let (data, ..) = pad_input(x, 1, 1, pad, split);
        Act { data, shape: [n, c, h, w], pad, split }
    }

    /// An activation of `shape` whose every pixel the caller writes ([`act_store`]); the slack
    /// after the last image zero.
    fn overwritten(shape: [usize; 4], pad: Padding, split: bool) -> Act {
        let [n, c, h, w] = shape;
        let os = c * (1 + split as usize);
        let len = n * (h + 2) * (w + 2) * os;
        let mut data = Aligned::new((len + T * os).div_ceil(2));
        let v: &mut [u16] = bytemuck::cast_slice_mut(&mut data[..]);
        v[len..].fill(0);
        Act { data, shape, pad, split }
    }

    /// bf16 values a pixel: C, or 2C split.
    pub(super) fn stored(&self) -> usize {
        self.shape[1] * (1 + self.split as usize)
    }

    /// The padded bf16 values, pixel (n, Y, X) of the padded grid at ((n·(H+2) + Y)·(W+2) + X)·C
    /// (2C split).
    fn values(&self) -> &[u16] {
        &bytemuck::cast_slice(&self.data[..])[..self.padded_len()]
    }

    /// Whether each value is a hi + lo pair of bf16.
    pub fn is_split(&self) -> bool {
        self.split
    }

    /// The buffer [`correlate`] reads (bf16 values, two to an f32 slot).
    pub(super) fn padded(&self) -> &[f32] {
        &self.data
    }

    fn padded_len(&self) -> usize {
        let [n, _, h, w] = self.shape;
        n * (h + 2) * (w + 2) * self.stored()
    }

    /// As NCHW f32 (exact: bf16 widens losslessly; split: hi + lo).
    pub fn to_nchw(&self) -> Tensor {
        let [n, c, h, w] = self.shape;
        let (v, cs) = (self.values(), self.stored());
        let mut t = Tensor::for_overwrite(&[n, c, h, w]);
        for ni in 0..n {
            for y in 0..h {
                for x in 0..w {
                    let px = &v[((ni * (h + 2) + y + 1) * (w + 2) + x + 1) * cs..][..cs];
                    for ci in 0..c {
                        let lo = if self.split { f32_of_bf16(px[c + ci]) } else { 0.0 };
                        t.data[((ni * c + ci) * h + y) * w + x] = f32_of_bf16(px[ci]) + lo;
                    }
                }
            }
        }
        t
    }
}

/// What [`conv_act`] does to conv(x) + b as it stores it: add `skip` (an [`Act`] of the
/// output's shape), ReLU, then the pixel shuffle the weights were packed for. The fp32 chain
/// ([`super::chain::conv_f32_act`]) takes the same with its own activations (`A`).
pub struct ActEpilogue<'a, A = Act> {
    pub skip: Option<&'a A>,
    pub relu: bool,
}

impl<A> Clone for ActEpilogue<'_, A> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<A> Copy for ActEpilogue<'_, A> {}

impl<A> Default for ActEpilogue<'_, A> {
    fn default() -> Self {
        ActEpilogue { skip: None, relu: false }
    }
}

/// A 3×3 conv from one [`Act`] to the next, on the tiles: `packed` must be bf16
/// ([`PackedConv::is_bf16`]) and take `x`'s form (split or not, [`PackedConv::for_chain`]);
/// with weights packed for a shuffle by r the output is the pixel-shuffled (N, O/r², rH, rW).
/// The sum, skip and ReLU are in f32, stored once as bf16: split into hi + lo pairs if
/// `out_split` (the form the next conv takes), else rounded.
pub fn conv_act(x: &Act, packed: &PackedConv, b: Option<&Tensor>, epi: ActEpilogue, out_split: bool) -> Act {
    let PackedKind::Amx(pk) = &packed.kind else { panic!("conv_act: weights not packed for the tiles") };
    let [n, _, h, w] = x.shape;
    let [o, c2, kh, kw] = pk.shape;
    let c = x.stored();
    assert!(c == c2 && kh == 3 && kw == 3, "conv_act: a 3×3 conv of {c2} stored channels on {c}");
    let r = pk.shuffle;
    assert_eq!(x.split, pk.split, "conv_act: the input is not in the weights' bf16 form");
    let oc = o / (r * r);
    if let Some(s) = epi.skip {
        assert!(
            r == 1 && s.shape == [n, o, h, w] && s.split == out_split,
            "conv_act: the skip is not the output's shape"
        );
    }
    let mut y = Act::overwritten([n, oc, h * r, w * r], x.pad, out_split);
    // The bias in the packed channel order (a pooled buffer: no allocation per conv).
    let init = b.map(|b| {
        let mut v = Scratch::zeroed(pk.opad);
        for (q, d) in v[..o].iter_mut().enumerate() {
            *d = b.data[(q % oc) * r * r + q / oc];
        }
        v
    });
    let sink = act_store(&mut y, pk.opad, r, init.as_deref(), epi.skip.map(|s| s.values()), epi.relu);
    // The bias is added in the store (`init` None here): the same (sum + bias) + skip as ever.
    correlate(x.padded(), n, h + 2, w + 2, pk, None, h, w, &sink);
    drop(sink);
    y
}

/// `x` (N, C, H, W) f32 through `packed` (an fp32 kernel: the 3-channel first conv of a trunk)
/// with bias `b`, stored as an [`Act`] padded for `pad`, rounded or `split`: how a chain of bf16
/// convs starts, each value the bf16 of what [`conv2d_packed`] computes, without the NCHW
/// tensor and the channels-last copy of it ([`Act::from_nchw`]) between the two.
pub fn conv_to_act(x: &Tensor, packed: &PackedConv, b: Option<&Tensor>, pad: Padding, split: bool) -> Act {
    let (n, _, h, w) = x.dims4();
    let opad = match &packed.kind {
        PackedKind::Winograd(pk, _) | PackedKind::Direct(pk) => pk.opad,
        _ => panic!("conv_to_act: weights packed for a kernel outside fp32"),
    };
    assert!(available(), "amx: bf16 activations on a CPU without AVX512_BF16");
    let mut y = Act::overwritten([n, packed.shape[0], h, w], pad, split);
    let sink = act_store(&mut y, opad, 1, None, None, false);
    correlate_packed(x, packed, b, pad, &sink);
    drop(sink);
    y
}

/// The sink of a conv into `y` (N, O/r², rH, rW, [`Act::overwritten`]): output row (n, yy) of
/// the kernel's scratch (pixel stride `opad`) + `init` (the bias, packed order), + `skip` (an
/// Act's values of y's shape), ReLU, pixel-shuffled by r, stored as bf16 (split where y is);
/// each stored row's border pixels, and the top and bottom border rows by the task that writes
/// the row next to them, filled for y's padding (zero, or a copy of the pixel inside).
fn act_store<'a>(
    y: &'a mut Act,
    opad: usize,
    r: usize,
    init: Option<&'a [f32]>,
    skip: Option<&'a [u16]>,
    relu: bool,
) -> impl Fn(usize, usize, &[f32]) + Sync + 'a {
    assert!(available(), "amx: bf16 activations on a CPU without AVX512_BF16");
    let [n, oc, ho, wo] = y.shape;
    let (h, w, split, pad) = (ho / r, wo / r, y.split, y.pad);
    // Stored values a pixel of the output (hi and lo halves when split).
    let os = y.stored();
    assert!(oc * r * r <= opad && init.is_none_or(|b| b.len() >= oc * r * r));
    let out = SyncPtr(y.data.as_mut_ptr());
    move |ni: usize, yy: usize, row: &[f32]| {
        assert!(ni < n && yy < h, "amx: the store got row {yy} of image {ni} of {n} × {h}");
        let dst = out.get() as *mut u16;
        for i in 0..r {
            let yo = (ni * (ho + 2) + r * yy + i + 1) * (wo + 2);
            // SAFETY: LR row yy of image ni is this task's; it writes HR rows r·yy .. r·yy + r
            // (padded: + 1) of that image, columns 0 .. wo + 2, all inside the n·(ho+2)·(wo+2)
            // pixels of os values; the row scratch holds w pixels of opad ≥ O floats.
            let line = unsafe { std::slice::from_raw_parts_mut(dst.add(yo * os), (wo + 2) * os) };
            for j in 0..r {
                let sk = skip.map(|s| &s[(yo + 1) * os..][..w * os]);
                // SAFETY: `available()` (asserted above) includes AVX512_BF16; the slices'
                // lengths are checked inside.
                unsafe {
                    store_pixels(
                        row,
                        opad,
                        (i * r + j) * oc,
                        oc,
                        init.map(|b| &b[(i * r + j) * oc..]),
                        w,
                        &mut line[(j + 1) * os..],
                        r * os,
                        sk,
                        relu,
                        split,
                    )
                };
            }
            // The left and right border pixels of the padded row.
            let (l, rr) = match pad {
                Padding::Zero => (None, None),
                Padding::Replicate => (Some(1), Some(wo)),
            };
            for (to, from) in [(0, l), (wo + 1, rr)] {
                match from {
                    Some(f) => line.copy_within(f * os..(f + 1) * os, to * os),
                    None => line[to * os..(to + 1) * os].fill(0),
                }
            }
        }
        // The top and bottom border rows, by the task that wrote the row next to them, while
        // that row is in cache: padded row 0 after HR row 0 (LR row 0), row ho + 1 after HR
        // row ho − 1 (LR row h − 1).
        let row = (wo + 2) * os;
        for (to, from, at) in [(0, 1, 0), (ho + 1, ho, h.saturating_sub(1))] {
            if yy != at {
                continue;
            }
            let img = ni * (ho + 2) * row;
            // SAFETY: rows `to` and `from` of image ni lie inside the buffer (as the lines
            // above); `to` is written by this task only, and `from` was written just above.
            unsafe {
                let d = dst.add(img + to * row);
                match pad {
                    Padding::Replicate => std::ptr::copy_nonoverlapping(dst.add(img + from * row), d, row),
                    Padding::Zero => std::ptr::write_bytes(d, 0, row),
                }
            }
        }
    }
}

/// The scalar twin: [`conv2d_ref`] on `x` and `w` rounded to bf16 (sums in f64, so the only
/// difference from the tiles is their f32 summation order).
pub fn conv2d_bf16_ref(x: &Tensor, w: &Tensor, b: Option<&Tensor>, pad: Padding) -> Tensor {
    let round = |t: &Tensor| {
        let mut r = t.clone();
        r.data.iter_mut().for_each(|v| *v = f32_of_bf16(bf16(*v)));
        r
    };
    conv2d_ref(&round(x), &round(w), b, pad)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every tile the kernel loads starts on a 64-byte line: the padded activations (of any
    /// shape, split or not, in whatever buffer the pool hands out), each pixel of them, the
    /// packed weights and the row scratch. A load split across two lines took about 3× the
    /// time of one on its line, and the products no longer hid it.
    #[test]
    fn every_tile_operand_starts_on_a_64_byte_line() {
        let line = |p: *const u16| p as usize % 64;
        let (mut keep, mut bytes) = (Vec::new(), Vec::new());
        for (i, &(n, c, h, w, split)) in
            [(1, 32, 5, 7, false), (2, 32, 16, 16, true), (1, 64, 3, 33, false), (3, 32, 1, 1, true)]
                .iter()
                .enumerate()
        {
            // Buffers of odd sizes held meanwhile, so the next ones start elsewhere.
            keep.push(Aligned::new(17 + 13 * i));
            bytes.push(vec![0u8; 3 + 5 * i]);
            let x = Tensor::zeros(&[n, c, h, w]);
            for a in [
                Act::from_nchw(&x, Padding::Zero, split),
                Act::overwritten([n, c, h, w], Padding::Replicate, split),
            ] {
                assert_eq!(line(a.values().as_ptr()), 0, "activation {:?} split {split}", a.shape);
                assert_eq!(a.stored() * 2 % 64, 0, "a pixel of {:?} is not whole lines", a.shape);
            }
            let pk = pack(16 * (i + 1), c, 3, 3, 1, split, |_, _, _, _| 0.5);
            assert_eq!(line(pk.data[pk.off..].as_ptr()), 0, "weights {:?}", pk.shape);
            assert_eq!(Aligned::new(100 + i).as_ptr() as usize % 64, 0, "row scratch");
        }
        drop((keep, bytes));
    }

    /// The 16-lane store is the scalar [`store_bf16`] bit for bit: ties to even, NaN kept
    /// quiet, ±0, subnormals, infinities, the largest finite values, and every tail length.
    #[test]
    fn the_avx512_bf16_store_has_the_bits_of_the_scalar_twin() {
        if !available() {
            return;
        }
        let mut rng = crate::rng::Rng::new(7);
        let special = [
            0.0f32,
            -0.0,
            f32::NAN,
            -f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MAX,
            -f32::MAX,
            f32::MIN_POSITIVE,
            1e-40,
            -1e-40,
            f32::from_bits(0x3f80_8000), // a tie, rounds to even (down)
            f32::from_bits(0x3f81_8000), // a tie, rounds to even (up)
            f32::from_bits(0x7f7f_ffff),
        ];
        for len in [1usize, 5, 15, 16, 17, 31, 32, 33, 64, 70] {
            let v: Vec<f32> = (0..len)
                .map(
                    |i| if i % 3 == 0 { special[i / 3 % special.len()] } else { (rng.uniform() - 0.5) * 1e3 },
                )
                .collect();
            for split in [false, true] {
                let n = len * (1 + split as usize);
                let (mut want, mut got) = (vec![0u16; n], vec![1u16; n]);
                store_bf16(&mut want, &v, split);
                // SAFETY: `available()` includes AVX-512F; the lengths match.
                unsafe { store_bf16_avx512(&mut got, &v, split) };
                assert_eq!(got, want, "len {len} split {split}");
            }
        }
    }
}
