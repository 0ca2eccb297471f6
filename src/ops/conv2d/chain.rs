//! The fp32 chain: a trunk's 3×3 convs (Winograd) from one padded channels-last activation
//! ([`F32Act`]) to the next, the residual adds, ReLUs and the pixel shuffle fused into the
//! stores. The fp32 twin of the bf16 tiles' [`amx::Act`] chain: between two convs there is no
//! NCHW tensor, so neither the transpose of every output row into planes ([`planes_store`])
//! nor the padded channels-last copy of every input row ([`pad_row_nhwc`]) runs. Each value is
//! the one [`conv2d_packed`] computes (the same sums in the same order, the same adds and
//! ReLUs after them), so the output has the same bits as the convs run one by one on NCHW
//! tensors (`tests/conv_fast_vs_ref.rs`).

use super::amx::ActEpilogue;
use super::*;

/// fp32 activations (N, C, H, W) in the layout the Winograd kernel reads
/// ([`winograd::Input::Padded`]): channels-last, padded by one pixel for a 3×3 conv, on a grid
/// of hp × wp = (4⌈H/4⌉ + 2) × (4⌈W/4⌉ + 2) pixels per image (whole tiles of either
/// [`winograd::Tile`]); pixel (n, Y, X)
/// of the padded grid at ((n·hp + Y)·wp + X)·C. Rows and columns beyond H + 2, W + 2 are zero.
pub struct F32Act {
    data: Scratch,
    /// (N, C, H, W) of the activation (unpadded).
    pub shape: [usize; 4],
    pad: Padding,
}

impl F32Act {
    /// The padded grid of an H × W activation: (hp, wp).
    fn grid(h: usize, w: usize) -> (usize, usize) {
        (4 * h.div_ceil(4) + 2, 4 * w.div_ceil(4) + 2)
    }

    /// `x` (N, C, H, W) padded for a 3×3 conv with `pad`.
    pub fn from_nchw(x: &Tensor, pad: Padding) -> F32Act {
        let (n, c, h, w) = x.dims4();
        let (hp, wp) = F32Act::grid(h, w);
        let (data, ..) = pad_nhwc_to(x, 1, 1, pad, hp, wp, 0);
        F32Act { data, shape: [n, c, h, w], pad }
    }

    /// Back to an NCHW tensor (for tests and for an op outside the chain).
    pub fn to_nchw(&self) -> Tensor {
        let [n, c, h, w] = self.shape;
        let (hp, wp) = F32Act::grid(h, w);
        let mut y = Tensor::for_overwrite(&[n, c, h, w]);
        for ni in 0..n {
            for yy in 0..h {
                let src = &self.data[((ni * hp + yy + 1) * wp + 1) * c..][..w * c];
                for (xx, px) in src.chunks_exact(c).enumerate() {
                    for (ci, &v) in px.iter().enumerate() {
                        y.data[((ni * c + ci) * h + yy) * w + xx] = v;
                    }
                }
            }
        }
        y
    }

    /// An activation of `shape` whose every element the caller writes: [`act_store`]'s sink.
    fn overwritten(shape: [usize; 4], pad: Padding) -> F32Act {
        let [n, c, h, w] = shape;
        let (hp, wp) = F32Act::grid(h, w);
        F32Act { data: Scratch::overwritten(n * hp * wp * c), shape, pad }
    }
}

/// `x` (N, C, H, W) through `packed` (any kernel but the small-output and the bf16 ones) with
/// bias `b`, into an [`F32Act`] with the same padding: the chain's first conv, as
/// [`conv2d_packed`] computes it.
pub fn conv_to_f32_act(x: &Tensor, packed: &PackedConv, b: Option<&Tensor>, pad: Padding) -> F32Act {
    let (n, _, h, w) = x.dims4();
    let o = packed.shape[0];
    let opad = match &packed.kind {
        PackedKind::Winograd(pk, _) | PackedKind::Direct(pk) => pk.opad,
        _ => panic!("conv_to_f32_act: weights packed for a kernel outside the fp32 chain"),
    };
    let mut y = F32Act::overwritten([n, o, h, w], pad);
    let sink = act_store(&mut y, opad, o, 1, ActEpilogue::default());
    correlate_packed(x, packed, b, pad, &sink);
    drop(sink);
    y
}

/// A 3×3 Winograd conv from one [`F32Act`] to the next, with bias `b`, then `epi` (the skip an
/// [`F32Act`] of the output's shape) and, for `shuffle` = r > 1, the pixel shuffle by r: the
/// output is (N, O/r², rH, rW).
pub fn conv_f32_act(
    x: &F32Act,
    packed: &PackedConv,
    b: Option<&Tensor>,
    epi: ActEpilogue<F32Act>,
    shuffle: usize,
) -> F32Act {
    let PackedKind::Winograd(pk, tile) = &packed.kind else {
        panic!("conv_f32_act: weights not packed for the Winograd kernel")
    };
    let [n, c, h, w] = x.shape;
    let [o, c2, ..] = packed.shape;
    assert_eq!(c, c2, "conv_f32_act: x has {c} channels, weight expects {c2}");
    let r = shuffle;
    assert!(r >= 1 && o.is_multiple_of(r * r), "conv_f32_act: {o} outputs do not shuffle by {r}");
    let mut y = F32Act::overwritten([n, o / (r * r), h * r, w * r], x.pad);
    let bias = padded_bias(b, pk.opad);
    let sink = act_store(&mut y, pk.opad, o, r, epi);
    let (hp, wp) = F32Act::grid(h, w);
    let input = winograd::Input::Padded { xp: &x.data, hp, wp };
    winograd::correlate(&input, n, c, pk, *tile, bias.as_deref(), h, w, &sink);
    drop(sink);
    y
}

/// A trunk's last two convs on the chain: [`conv_f32_act`] with ReLU, then `last`, a conv of
/// ≤ [`SMALL_OUT_MAX`] outputs, as [`conv2d_packed`] without epilogue; the first stores
/// straight into the padded planar input of the second ([`relu_into_small_out`]).
pub fn conv_f32_act_relu_small_out(
    x: &F32Act,
    packed: &PackedConv,
    b: Option<&Tensor>,
    last: &PackedConv,
    b_last: Option<&Tensor>,
) -> Tensor {
    let PackedKind::Winograd(pk, tile) = &packed.kind else {
        panic!("conv_f32_act_relu_small_out: weights not packed for the Winograd kernel")
    };
    let [n, c, h, w] = x.shape;
    let [o, c2, ..] = packed.shape;
    assert_eq!(c, c2, "conv_f32_act_relu_small_out: x has {c} channels, weight expects {c2}");
    let bias = padded_bias(b, pk.opad);
    let (hp, wp) = F32Act::grid(h, w);
    let input = winograd::Input::Padded { xp: &x.data, hp, wp };
    relu_into_small_out([n, o, h, w], pk.opad, last, b_last, x.pad, &|sink| {
        winograd::correlate(&input, n, c, pk, *tile, bias.as_deref(), h, w, sink)
    })
}

/// `b` padded with zeros to `opad` channels (a pooled buffer: this runs for every conv).
pub(super) fn padded_bias(b: Option<&Tensor>, opad: usize) -> Option<Scratch> {
    b.map(|b| {
        let mut v = Scratch::zeroed(opad);
        v[..b.len()].copy_from_slice(&b.data);
        v
    })
}

/// The sink of a conv of `o` outputs into `y` (N, O/r², rH, rW, allocated by the caller): row
/// (n, yy) of the kernels' NHWC scratch (pixel stride `opad` ≥ O) with `epi` applied, output
/// channel q = c·r² + i·r + j to pixel (r·yy + i, r·x + j), channel c (PyTorch's pixel shuffle);
/// each stored row's border pixels, and the top and bottom border rows by the task that writes
/// the row next to them, filled by the padding (zero, or a copy of the pixel inside). Every
/// element of `y` is written once the conv has run.
fn act_store<'a>(
    y: &'a mut F32Act,
    opad: usize,
    o: usize,
    r: usize,
    epi: ActEpilogue<'a, F32Act>,
) -> impl Fn(usize, usize, &[f32]) + Sync + 'a {
    let [n, oc, ho, wo] = y.shape;
    assert!(oc * r * r == o && o <= opad && ho % r == 0 && wo % r == 0);
    let (h, w) = (ho / r, wo / r);
    let (hp, wp) = F32Act::grid(ho, wo);
    if let Some(s) = epi.skip {
        assert!(r == 1 && s.shape == y.shape, "conv_f32_act: the skip is not the output's shape");
    }
    let pad = y.pad;
    let out = SyncPtr(y.data.as_mut_ptr());
    let skip = epi.skip.map(|s| &s.data[..]);
    let relu = epi.relu;
    let line_len = wp * oc;
    move |ni: usize, yy: usize, row: &[f32]| {
        assert!(ni < n && yy < h && row.len() >= w * opad);
        let img = ni * hp * line_len;
        for i in 0..r {
            let at = img + (r * yy + i + 1) * line_len;
            // SAFETY: LR row yy of image ni is this task's; it writes padded HR rows r·yy + i + 1
            // (i < r) of that image, each line_len floats inside the n·hp·wp·oc of y.
            let line = unsafe { std::slice::from_raw_parts_mut(out.get().add(at), line_len) };
            if r == 1 {
                let sk = skip.map(|s| &s[at + oc..][..w * oc]);
                store_row(row, opad, oc, w, &mut line[oc..], sk, relu);
            } else {
                for (xx, px) in row.chunks_exact(opad).take(w).enumerate() {
                    for j in 0..r {
                        let d = &mut line[(r * xx + j + 1) * oc..][..oc];
                        for (cc, v) in d.iter_mut().enumerate() {
                            let s = px[cc * r * r + i * r + j];
                            *v = if relu { relu1(s) } else { s };
                        }
                    }
                }
            }
            // The left and right border pixels, and the columns past W + 2 (zero).
            let (left, right) = line.split_at_mut((wo + 1) * oc);
            let (right, beyond) = right.split_at_mut(oc);
            match pad {
                Padding::Replicate => {
                    let (l0, l1) = left.split_at_mut(oc);
                    l0.copy_from_slice(&l1[..oc]);
                    right.copy_from_slice(&left[wo * oc..]);
                }
                Padding::Zero => {
                    left[..oc].fill(0.0);
                    right.fill(0.0);
                }
            }
            beyond.fill(0.0);
        }
        // The top border row after row 0, the bottom one (and the rows past H + 2) after row
        // H − 1, while the row next to them is in cache.
        // SAFETY: the rows named are image ni's (inside y); the border rows are written by the
        // task of LR row 0 or h − 1 only, and the row copied was written just above by it.
        unsafe {
            let at = |row: usize| out.get().add(img + row * line_len);
            let fill = |to: usize, from: usize| match pad {
                Padding::Replicate => std::ptr::copy_nonoverlapping(at(from), at(to), line_len),
                Padding::Zero => std::ptr::write_bytes(at(to), 0, line_len),
            };
            if yy == 0 {
                fill(0, 1);
            }
            if yy + 1 == h {
                fill(ho + 1, ho);
                std::ptr::write_bytes(at(ho + 2), 0, (hp - ho - 2) * line_len);
            }
        }
    }
}

/// `dst[x·c + k] = relu?(src[x·opad + k] + skip[x·c + k])` for x < w, k < c: a conv's output row
/// into a channels-last line with the epilogue [`planes_store`] applies (the same adds and
/// ReLU, 8 lanes at a time where whole).
fn store_row(
    src: &[f32],
    opad: usize,
    c: usize,
    w: usize,
    dst: &mut [f32],
    skip: Option<&[f32]>,
    relu: bool,
) {
    let c8 = c / 8 * 8;
    for xx in 0..w {
        let (s, d) = (&src[xx * opad..][..c], &mut dst[xx * c..][..c]);
        let sk = skip.map(|k| &k[xx * c..][..c]);
        for k in (0..c8).step_by(8) {
            let mut v = f32x8::from(<[f32; 8]>::try_from(&s[k..k + 8]).unwrap());
            if let Some(sk) = sk {
                v += f32x8::from(<[f32; 8]>::try_from(&sk[k..k + 8]).unwrap());
            }
            if relu {
                v = v.simd_lt(f32x8::ZERO).select(f32x8::ZERO, v);
            }
            d[k..k + 8].copy_from_slice(&v.to_array());
        }
        for k in c8..c {
            let mut v = s[k];
            if let Some(sk) = sk {
                v += sk[k];
            }
            d[k] = if relu { relu1(v) } else { v };
        }
    }
}
