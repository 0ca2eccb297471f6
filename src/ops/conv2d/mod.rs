//! 2-D convolution, stride 1, odd square-or-rectangular kernels, "same" output size
//! (padding kh/2, kw/2), zero or replicate padding, optional bias.
//!
//! x: (N, C, H, W), w: (O, C, KH, KW) (OIHW), b: (O), y: (N, O, H, W).

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
// and broadcasts P input values: P·OV FMAs per P+OV loads. Without AVX-512 (16 ymm registers,
// two per f32x16) a tile is 6 pixels × one vector of a block (`direct::reg_tiles`); the tile
// size never changes the order of an output's sum, so the bits are those of any build. Each
// output row is one rayon task; the row is accumulated in a small NHWC scratch and scattered to
// NCHW at the end (no extra pass over memory). The input gradient is the same kernel with
// flipped, transposed weights on the padded dy ("full" correlation + fold of the border for
// replicate padding). The weight gradient accumulates dW_tap += dY · X_shift per tap with the
// `micro_dw` kernel (P input channels × OV·16 output channels in registers, summed over
// pixels), on the padded pixel grid so that X_shift is a plain strided view; the pixels are cut
// into fixed chunks (independent of the thread count) whose partial sums are added in a fixed
// order, so results are deterministic.
// ---------------------------------------------------------------------------------------------

use super::activation::relu1;
use rayon::prelude::*;
use wide::{f32x16, f32x8};

const L: usize = 16; // f32 lanes per vector
const OB: usize = 64; // output channels per weight block (4 vectors)
const PMAX: usize = 6; // pixels per micro-tile at OV = 4

// The micro-kernels' register-tile sizes are const generics; these pick one at run time (defined
// before the kernel modules that use them).
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

pub mod amx;
pub mod chain;
mod direct;
mod grad;
mod layout;
mod reference;
mod small_out;
mod winograd;

pub use crate::ops::Precision;
use crate::tensor::Tensor;
pub use direct::Epilogue;
use direct::*;
use grad::*;
pub use grad::{conv2d_input_grad, conv2d_weight_grad};
use layout::*;
pub use reference::{conv2d_backward_ref, conv2d_ref, pad_index, Padding};
pub use small_out::SMALL_OUT_MAX;
use small_out::*;

/// Where the fast kernels put their output: `sink(n, y, row)` gets output row y of image n as
/// NHWC scratch (the output's width or more pixels, pixel stride the packing's `opad`), once per
/// row, from any thread.
type RowSink<'a> = dyn Fn(usize, usize, &[f32]) + Sync + 'a;

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
    /// 3×3 with C a multiple of 16: [`winograd::pack`] for F(2×2, 3×3), or F(4×4, 3×3) under
    /// [`Precision::Fp32Fast`].
    Winograd(Packed, winograd::Tile),
    /// Everything else: [`pack_weights`].
    Direct(Packed),
    /// bf16 on AMX tiles ([`Precision::Bf16`], C a multiple of 32): [`amx::pack`].
    Amx(amx::AmxPacked),
}

impl PackedConv {
    /// Pack weights (O, C, KH, KW), odd kernels, for the kernel [`conv2d`] would pick.
    pub fn new(w: &Tensor) -> PackedConv {
        PackedConv::with_precision(w, Precision::Fp32)
    }

    /// [`PackedConv::new`] for the kernels of `precision` ([`Precision::Bf16`]: the AMX kernel
    /// where the conv and the CPU take it, else the fp32 one).
    pub fn with_precision(w: &Tensor, precision: Precision) -> PackedConv {
        PackedConv::packed(w, precision, 1, false)
    }

    /// [`PackedConv::with_precision`] for a conv in a chain of [`amx::Act`]s
    /// ([`amx::conv_act`]): on the bf16 tiles, with its output channels ordered for a fused
    /// pixel shuffle by `shuffle` (such weights run only there; 1: none), and taking its input
    /// as hi + lo pairs of bf16 if `split` (twice the tile work, the input exact to 2⁻¹⁷).
    /// The fp32 kernels pack as [`PackedConv::with_precision`] and leave the shuffle to its own op.
    pub fn for_chain(w: &Tensor, precision: Precision, shuffle: usize, split: bool) -> PackedConv {
        PackedConv::packed(w, precision, shuffle, split)
    }

    fn packed(w: &Tensor, precision: Precision, shuffle: usize, split: bool) -> PackedConv {
        let (o, c, kh, kw) = w.dims4();
        assert!(kh % 2 == 1 && kw % 2 == 1, "conv2d: odd kernels only, got {kh}x{kw}");
        let get = |oi: usize, ci: usize, ky: usize, kx: usize| w.data[((oi * c + ci) * kh + ky) * kw + kx];
        let kind = if precision == Precision::Bf16 && amx::eligible(c, o) && amx::available() {
            PackedKind::Amx(amx::pack(o, c, kh, kw, shuffle, split, get))
        } else if o <= SMALL_OUT_MAX {
            PackedKind::SmallOut(pack_small_out(w))
        } else if winograd::eligible(c, o, kh, kw) {
            let tile = if precision == Precision::Fp32Fast { winograd::Tile::F4 } else { winograd::Tile::F2 };
            PackedKind::Winograd(winograd::pack(o, c, tile, get), tile)
        } else {
            PackedKind::Direct(pack_weights(o, c, kh, kw, get))
        };
        PackedConv { shape: [o, c, kh, kw], kind }
    }

    /// (O, C, KH, KW) of the weights packed.
    pub fn shape(&self) -> [usize; 4] {
        self.shape
    }

    /// Whether these weights run on the bf16 tiles.
    pub fn is_bf16(&self) -> bool {
        matches!(self.kind, PackedKind::Amx(_))
    }

    /// Whether these weights run on the Winograd kernel (the fp32 chain's convs, [`chain`]).
    pub fn is_winograd(&self) -> bool {
        matches!(self.kind, PackedKind::Winograd(..))
    }

    /// Whether these weights run on the small-output kernel (≤ [`SMALL_OUT_MAX`] outputs).
    pub fn is_small_out(&self) -> bool {
        matches!(self.kind, PackedKind::SmallOut(_))
    }

    /// On the bf16 tiles: whether the inputs are hi + lo pairs ([`amx::Act`]'s split form).
    pub fn is_split(&self) -> bool {
        matches!(&self.kind, PackedKind::Amx(a) if a.split)
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
    if let PackedKind::SmallOut(wk) = &packed.kind {
        let mut y = conv2d_small_out(x, wk, [o, kh, kw], b, pad);
        epi.apply(&mut y);
        return y;
    }
    let opad = match &packed.kind {
        PackedKind::Amx(ak) => {
            assert_eq!(
                ak.shuffle, 1,
                "conv2d: weights packed for a fused pixel shuffle (amx::conv_act only)"
            );
            ak.opad
        }
        PackedKind::Winograd(pk, _) | PackedKind::Direct(pk) => pk.opad,
        PackedKind::SmallOut(_) => unreachable!(),
    };
    let mut y = Tensor::for_overwrite(&[n, o, h, wd]);
    let sink = nchw_store(&mut y, opad, epi);
    correlate_packed(x, packed, b, pad, &sink);
    drop(sink);
    y
}

/// The conv of `x` (N, C, H, W) with `packed` (any kernel but the small-output one) and bias
/// `b`: every output row (n, yy) to `sink` as the kernels' NHWC scratch (W or more pixels, pixel
/// stride the packing's `opad`). What [`conv2d_packed`] and the fp32 chain's first conv
/// ([`chain::conv_to_f32_act`]) store.
fn correlate_packed(x: &Tensor, packed: &PackedConv, b: Option<&Tensor>, pad: Padding, sink: &RowSink) {
    let (n, c, h, wd) = x.dims4();
    let [_, _, kh, kw] = packed.shape;
    let (ph, pw) = (kh / 2, kw / 2);
    match &packed.kind {
        PackedKind::Amx(ak) => {
            let bias = chain::padded_bias(b, ak.opad);
            let (xp, hp, wp) = amx::pad_input(x, ph, pw, pad, ak.split);
            amx::correlate(&xp, n, hp, wp, ak, bias.as_deref(), h, wd, sink);
        }
        PackedKind::Direct(pk) => {
            let bias = chain::padded_bias(b, pk.opad);
            let (xp, hp, wp) = pad_nhwc(x, ph, pw, pad, 0);
            correlate_rows(&xp, n, hp, wp, c, kh, kw, pk, bias.as_deref(), h, wd, RowGroups::Single(h), sink)
        }
        // Small inputs are padded row by row inside the tasks.
        PackedKind::Winograd(pk, tile) => {
            let bias = chain::padded_bias(b, pk.opad);
            let padded = (x.len() > winograd::FUSE_PAD_MAX).then(|| winograd::pad_input(x, pad, *tile));
            let input = match &padded {
                Some((xp, hp, wp)) => winograd::Input::Padded { xp, hp: *hp, wp: *wp },
                None => winograd::Input::Nchw { x, pad },
            };
            winograd::correlate(&input, n, c, pk, *tile, bias.as_deref(), h, wd, sink)
        }
        PackedKind::SmallOut(_) => panic!("correlate_packed: the small-output kernel has no row sink"),
    }
}

/// The store of the fast kernels: row (n, yy) of their NHWC scratch (wd pixels, pixel stride
/// `opad` ≥ O) into `y` (N, O, H, W), with `epi` fused: a transpose through registers.
fn nchw_store<'a>(
    y: &'a mut Tensor,
    opad: usize,
    epi: Epilogue<'a>,
) -> impl Fn(usize, usize, &[f32]) + Sync + 'a {
    let (_, o, h, wd) = y.dims4();
    if let Some(s) = epi.skip {
        assert_eq!(s.shape, y.shape, "conv2d: the skip tensor is not the output's shape");
    }
    let at = Planes { o, wd, image: o * h * wd, plane: h * wd, row: wd, origin: 0 };
    planes_store(&mut y.data, at, opad, epi)
}

/// Where [`planes_store`] puts an image's O output planes: row (n, yy) of plane j at
/// n·image + j·plane + yy·row + origin, `wd` floats.
#[derive(Clone, Copy)]
struct Planes {
    o: usize,
    wd: usize,
    image: usize,
    plane: usize,
    row: usize,
    origin: usize,
}

/// [`nchw_store`] into any layout of planes: NCHW, or [`small_out`]'s padded planar input. A
/// skip is read at the output's own offsets, so it needs the NCHW layout (a tensor of y's shape).
fn planes_store<'a>(
    dst: &'a mut [f32],
    at: Planes,
    opad: usize,
    epi: Epilogue<'a>,
) -> impl Fn(usize, usize, &[f32]) + Sync + 'a {
    let Planes { o, wd, image, plane, row, origin } = at;
    assert!(plane >= row && row >= wd && image >= o * plane && dst.len().is_multiple_of(image));
    assert!(epi.skip.is_none() || (origin == 0 && row == wd && plane * o == image));
    let n = dst.len() / image;
    let yp = SyncPtr(dst.as_mut_ptr());
    let skip = epi.skip.map(|s| s.data.as_ptr() as usize);
    let relu = epi.relu;
    move |ni: usize, yy: usize, src: &[f32]| {
        assert!(src.len() >= wd * opad && ni < n && origin + yy * row + wd <= plane);
        let base = ni * image + yy * row + origin;
        // SAFETY: row (ni, yy) of every plane is written by this task only; the row holds wd
        // pixels of opad ≥ o floats, and (ni, yy) is inside dst (asserted); a skip tensor has
        // y's shape and layout (asserted), so the offsets of y's row are in it too.
        unsafe {
            let sp = skip.map(|p| (p as *const f32).add(base));
            let f = |mut v: f32x8, at: usize| {
                if let Some(sp) = sp {
                    v += (sp.add(at) as *const f32x8).read_unaligned();
                }
                if relu {
                    // `relu1` on 8 lanes: 0 where v < 0; −0 and NaN kept.
                    v = v.simd_lt(f32x8::ZERO).select(f32x8::ZERO, v);
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
            transpose_map(src.as_ptr(), opad, wd, o, yp.get().add(base), plane, f, g)
        };
    }
}

/// [`conv2d_packed`] on an [`amx::Act`] (the bf16 tiles' padded input, kept from the conv
/// before), out to NCHW f32 with `epi`: how a chain of bf16 convs hands its result to an fp32
/// op.
pub fn conv_act_nchw(x: &amx::Act, packed: &PackedConv, b: Option<&Tensor>, epi: Epilogue) -> Tensor {
    let PackedKind::Amx(ak) = &packed.kind else { panic!("conv_act_nchw: weights not packed for the tiles") };
    assert_eq!(ak.shuffle, 1, "conv_act_nchw: weights packed for a fused pixel shuffle");
    assert_eq!(x.is_split(), ak.split, "conv_act_nchw: the input is not in the weights' bf16 form");
    let [n, c, h, wd] = x.shape;
    let [o, c2, kh, kw] = packed.shape;
    assert!(c == c2 && kh == 3 && kw == 3, "conv_act_nchw: a 3×3 conv of {c2} channels on {c}");
    let bias = chain::padded_bias(b, ak.opad);
    let mut y = Tensor::for_overwrite(&[n, o, h, wd]);
    let sink = nchw_store(&mut y, ak.opad, epi);
    amx::correlate(x.padded(), n, h + 2, wd + 2, ak, bias.as_deref(), h, wd, &sink);
    drop(sink);
    y
}

/// A trunk's last two convs on the tiles' output: [`conv_act_nchw`] with ReLU, then `last`, a
/// conv of ≤ [`SMALL_OUT_MAX`] outputs, as [`conv2d_packed`] without epilogue. The same bits,
/// without the NCHW tensor between them ([`relu_into_small_out`]).
pub fn conv_act_relu_small_out(
    x: &amx::Act,
    packed: &PackedConv,
    b: Option<&Tensor>,
    last: &PackedConv,
    b_last: Option<&Tensor>,
    pad: Padding,
) -> Tensor {
    if !matches!(last.kind, PackedKind::SmallOut(_)) {
        let z = conv_act_nchw(x, packed, b, Epilogue::RELU);
        return conv2d_packed(&z, last, b_last, pad, Epilogue::NONE);
    }
    let PackedKind::Amx(ak) = &packed.kind else {
        panic!("conv_act_relu_small_out: weights not packed for the tiles")
    };
    assert_eq!(ak.shuffle, 1, "conv_act_relu_small_out: weights packed for a fused pixel shuffle");
    assert_eq!(x.is_split(), ak.split, "conv_act_relu_small_out: the input is not in the weights' bf16 form");
    let [n, c, h, wd] = x.shape;
    let [o, c2, kh, kw] = packed.shape;
    assert!(c == c2 && kh == 3 && kw == 3, "conv_act_relu_small_out: a 3×3 conv of {c2} channels on {c}");
    let bias = chain::padded_bias(b, ak.opad);
    relu_into_small_out([n, o, h, wd], ak.opad, last, b_last, pad, &|sink| {
        amx::correlate(x.padded(), n, h + 2, wd + 2, ak, bias.as_deref(), h, wd, sink)
    })
}

/// The second half of a trunk's last two convs: `run` is the first (o outputs on an H × W
/// image, pixel stride `opad` in the rows it gives its sink); its rows, ReLU'd, go straight into
/// the padded planar input of `last` (≤ [`SMALL_OUT_MAX`] outputs, [`small_out_planar`]), each
/// row's border filled as it is stored, so no NCHW tensor lies between the two.
fn relu_into_small_out(
    [n, o, h, wd]: [usize; 4],
    opad: usize,
    last: &PackedConv,
    b_last: Option<&Tensor>,
    pad: Padding,
    run: &dyn Fn(&RowSink),
) -> Tensor {
    let PackedKind::SmallOut(wk) = &last.kind else {
        panic!("relu_into_small_out: the last conv is not small")
    };
    let [o2, c3, kh2, kw2] = last.shape;
    assert_eq!(c3, o, "relu_into_small_out: the last conv takes {c3} channels, the one before gives {o}");
    let wq = planar_width(wd, kw2);
    let border = PlanarBorder { h, w: wd, ph: kh2 / 2, pw: kw2 / 2, wq, pad };
    let plane = border.plane();
    // Every element is written: the interior by the conv's store, the border by the sink after
    // it, row by row while the row is in cache.
    let mut zp = Scratch::overwritten(n * o * plane);
    let zptr = SyncPtr(zp.as_mut_ptr());
    let at = Planes { o, wd, image: o * plane, plane, row: wq, origin: border.ph * wq + border.pw };
    let store = planes_store(&mut zp, at, opad, Epilogue::RELU);
    let sink = |ni: usize, yy: usize, row: &[f32]| {
        store(ni, yy, row);
        for j in 0..o {
            // SAFETY: plane (ni, j) lies in zp (the store asserted ni < n), and row yy with the
            // pad rows it stands for is this task's alone, as in the store.
            unsafe { border.fill_row(zptr.get().add((ni * o + j) * plane), yy) };
        }
    };
    run(&sink);
    drop(store);
    small_out_planar(&zp, [n, o, h, wd], wq, wk, [o2, kh2, kw2], b_last)
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
