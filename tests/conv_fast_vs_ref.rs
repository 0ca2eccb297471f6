//! The fast conv2d paths (SIMD + rayon) against the scalar reference on random shapes: odd
//! sizes, C_in ≠ C_out, channel counts that are not multiples of 16, 1×1 / 3×3 / 5×5 / 3×5
//! kernels, both paddings, with and without bias and dx; gradients must accumulate (+=).

#[path = "common/close.rs"]
mod close;
use anisocb::rng::Rng;
use close::assert_close;
#[path = "common/random.rs"]
mod random;
use anisocb::ops::conv2d::amx::ActEpilogue;
use anisocb::ops::conv2d::chain::{conv_f32_act, conv_f32_act_relu_small_out, conv_to_f32_act, F32Act};
use anisocb::ops::conv2d::{
    conv2d, conv2d_backward, conv2d_backward_ref, conv2d_packed, conv2d_ref, Epilogue, PackedConv,
};
use anisocb::ops::pixel_shuffle::pixel_shuffle;
use anisocb::ops::{activation, Cpu, Padding, Precision};
use anisocb::Tensor;
use random::TestData;

#[allow(clippy::too_many_arguments)]
fn check_case(
    rng: &mut Rng,
    n: usize,
    c: usize,
    o: usize,
    h: usize,
    w: usize,
    kh: usize,
    kw: usize,
    pad: Padding,
    bias: bool,
    with_dx: bool,
) {
    let what = format!("n{n} c{c} o{o} {h}x{w} k{kh}x{kw} {pad:?} bias={bias} dx={with_dx}");
    let x = rng.tensor(&[n, c, h, w], -1.0, 1.0);
    let wt = rng.tensor(&[o, c, kh, kw], -1.0, 1.0);
    let b = bias.then(|| rng.tensor(&[o], -1.0, 1.0));
    let tol_scale = ((c * kh * kw) as f32).sqrt();
    let y_fast = conv2d(&x, &wt, b.as_ref(), pad);
    let y_ref = conv2d_ref(&x, &wt, b.as_ref(), pad);
    assert_close(&format!("forward {what}"), &y_fast, &y_ref, 1e-5 * tol_scale, 1e-4);

    let dy = rng.tensor(&[n, o, h, w], -1.0, 1.0);
    // Gradients accumulate: start from the same non-zero buffers.
    let dx0 = rng.tensor(&[n, c, h, w], -1.0, 1.0);
    let dw0 = rng.tensor(&[o, c, kh, kw], -1.0, 1.0);
    let db0 = rng.tensor(&[o], -1.0, 1.0);
    let (mut dx_f, mut dw_f, mut db_f) = (dx0.clone(), dw0.clone(), db0.clone());
    let (mut dx_r, mut dw_r, mut db_r) = (dx0.clone(), dw0.clone(), db0.clone());
    conv2d_backward(&x, &wt, &dy, pad, with_dx.then_some(&mut dx_f), &mut dw_f, bias.then_some(&mut db_f));
    conv2d_backward_ref(
        &x,
        &wt,
        &dy,
        pad,
        with_dx.then_some(&mut dx_r),
        &mut dw_r,
        bias.then_some(&mut db_r),
    );
    let dx_tol = 1e-5 * ((o * kh * kw) as f32).sqrt() * 2.0;
    let dw_tol = 1e-5 * ((n * h * w) as f32).sqrt() * 2.0;
    if with_dx {
        assert_close(&format!("dx {what}"), &dx_f, &dx_r, dx_tol, 1e-4);
    } else {
        assert_eq!(dx_f, dx0, "dx untouched when not requested");
    }
    assert_close(&format!("dw {what}"), &dw_f, &dw_r, dw_tol, 1e-4);
    if bias {
        assert_close(&format!("db {what}"), &db_f, &db_r, 1e-5 * ((n * h * w) as f32).sqrt() * 2.0, 1e-4);
    } else {
        assert_eq!(db_f, db0, "db untouched when not requested");
    }
}

#[test]
fn conv_fast_matches_ref_on_fixed_edge_shapes() {
    let mut rng = Rng::new(1);
    for pad in [Padding::Zero, Padding::Replicate] {
        // first layer (C_in = 3), last layers (C_out = 1, 3), the hot 64→64, 64→256 upscaling,
        // channel tails (17, 33, 70), 1×1 / 5×5 / 3×5 kernels, tiny images (1×1, 2×3).
        check_case(&mut rng, 2, 3, 32, 7, 9, 3, 3, pad, true, true);
        check_case(&mut rng, 1, 32, 1, 9, 5, 3, 3, pad, true, true);
        check_case(&mut rng, 1, 64, 3, 6, 13, 3, 3, pad, false, true);
        check_case(&mut rng, 1, 64, 64, 8, 8, 3, 3, pad, true, true);
        check_case(&mut rng, 1, 16, 256, 5, 7, 3, 3, pad, true, true);
        check_case(&mut rng, 2, 17, 33, 11, 3, 3, 3, pad, true, false);
        check_case(&mut rng, 1, 70, 70, 5, 19, 3, 3, pad, false, true);
        check_case(&mut rng, 1, 5, 7, 9, 11, 1, 1, pad, true, true);
        check_case(&mut rng, 1, 5, 20, 9, 11, 5, 5, pad, true, true);
        check_case(&mut rng, 1, 4, 6, 8, 10, 3, 5, pad, false, true);
        check_case(&mut rng, 1, 3, 5, 1, 1, 3, 3, pad, true, true);
        check_case(&mut rng, 3, 2, 3, 2, 3, 5, 5, pad, true, true);
        check_case(&mut rng, 1, 8, 8, 40, 3, 3, 3, pad, true, true);
    }
}

#[test]
fn conv_fast_matches_ref_on_random_shapes() {
    let mut rng = Rng::new(42);
    for _ in 0..30 {
        let n = 1 + (rng.next_u64() % 3) as usize;
        let c = 1 + (rng.next_u64() % 40) as usize;
        let o = 1 + (rng.next_u64() % 80) as usize;
        let h = 1 + (rng.next_u64() % 14) as usize;
        let w = 1 + (rng.next_u64() % 14) as usize;
        let k = [1, 3, 3, 3, 5][(rng.next_u64() % 5) as usize];
        let pad = if rng.next_u64().is_multiple_of(2) { Padding::Zero } else { Padding::Replicate };
        let bias = rng.next_u64().is_multiple_of(2);
        let with_dx = !rng.next_u64().is_multiple_of(4);
        check_case(&mut rng, n, c, o, h, w, k, k, pad, bias, with_dx);
    }
}

#[test]
fn conv_few_outputs_matches_ref_on_wide_rows_and_tails() {
    // The pixel-vector path (≤ SMALL_OUT_MAX output channels): rows shorter than, equal to and
    // longer than whole 16-pixel vectors and 4-vector tiles, with the kernel's overhang.
    assert_eq!(anisocb::ops::conv2d::SMALL_OUT_MAX, 4);
    let mut rng = Rng::new(11);
    for (o, w) in [(1, 1), (3, 15), (1, 16), (2, 17), (3, 63), (4, 64), (1, 65), (3, 130)] {
        for (k, pad) in
            [(3, Padding::Zero), (3, Padding::Replicate), (5, Padding::Replicate), (1, Padding::Zero)]
        {
            let (n, c, h) = (1 + w % 2, 1 + (w % 7) * 5, 1 + w % 9);
            check_case(&mut rng, n, c, o, h, w, k, k, pad, w % 2 == 1, true);
        }
    }
}

/// (n, c, o, h, w) of the Winograd tests: images with odd and even sides down to 1×1 (partial
/// tiles), tile rows shorter and longer than one register tile, output channels that are not
/// whole vectors or whole 64-channel blocks. Inputs of up to 2¹⁶ floats are padded inside the
/// tasks, larger ones into a buffer first: the last three cases sit on either side of that line
/// (65 520, 67 600 and, two images, 65 600).
const WINOGRAD_SHAPES: [(usize, usize, usize, usize, usize); 12] = [
    (1, 16, 5, 1, 1),
    (1, 16, 16, 1, 2),
    (2, 16, 16, 2, 3),
    (1, 32, 17, 3, 2),
    (1, 32, 32, 7, 9),
    (1, 48, 65, 6, 13),
    (2, 64, 64, 9, 8),
    (1, 64, 80, 5, 29),
    (1, 32, 3 * 16, 16, 16),
    (1, 16, 32, 63, 65),
    (1, 16, 32, 65, 65),
    (2, 16, 24, 41, 50),
];

#[test]
fn conv_winograd_matches_ref_on_odd_sizes_and_channel_tails() {
    // The Winograd F(2×2, 3×3) path (3×3, C_in a multiple of 16, C_out > 4) on
    // [`WINOGRAD_SHAPES`]. With replicate padding the input gradient takes the same path on dy
    // framed by zeros and folds the frame onto the border (one-row images fold three rows onto
    // one).
    let mut rng = Rng::new(5);
    for (n, c, o, h, w) in WINOGRAD_SHAPES {
        for pad in [Padding::Zero, Padding::Replicate] {
            check_case(&mut rng, n, c, o, h, w, 3, 3, pad, h % 2 == 1, true);
        }
    }
}

#[test]
fn conv_winograd_f4_matches_ref_on_odd_sizes_and_channel_tails() {
    // `--precision fp32-fast`: the trunks' convs by Winograd F(4×4, 3×3) (6×6 input tiles, 4×4
    // outputs) on [`WINOGRAD_SHAPES`] (sides not multiples of 4 are partial tiles here) and
    // 128 channels. Its transforms multiply by 4, 5,
    // 8 and ⅙, which round: the tolerance is the F(2×2) test's absolute one times 4 (on the
    // cases with 32 or more channels, F(4×4)'s largest differences measured 5–9× F(2×2)'s, and
    // 2–4× below this tolerance), the relative one the same.
    let mut rng = Rng::new(6);
    for (n, c, o, h, w) in WINOGRAD_SHAPES.into_iter().chain([(1, 128, 128, 8, 8)]) {
        for pad in [Padding::Zero, Padding::Replicate] {
            let what = format!("n{n} c{c} o{o} {h}x{w} {pad:?}");
            let x = rng.tensor(&[n, c, h, w], -1.0, 1.0);
            let wt = rng.tensor(&[o, c, 3, 3], -1.0, 1.0);
            let b = rng.tensor(&[o], -1.0, 1.0);
            let packed = PackedConv::with_precision(&wt, Precision::Fp32Fast);
            assert!(packed.is_winograd(), "{what}");
            let y = conv2d_packed(&x, &packed, Some(&b), pad, Epilogue::NONE);
            let y_ref = conv2d_ref(&x, &wt, Some(&b), pad);
            let tol = 4e-5 * ((c * 9) as f32).sqrt();
            assert_close(&format!("F(4×4, 3×3) {what}"), &y, &y_ref, tol, 1e-4);
        }
    }
    // What Winograd does not take (the first conv's 3 channels, the last conv's ≤ 4 outputs, 1×1
    // kernels) keeps fp32's kernels and bits; `fp32-fast` is a CPU precision only.
    let bits = |t: &Tensor| t.data.iter().map(|v| v.to_bits()).collect::<Vec<u32>>();
    for (c, o, k) in [(3, 32, 3), (32, 3, 3), (32, 32, 1)] {
        let x = rng.tensor(&[1, c, 7, 9], -1.0, 1.0);
        let wt = rng.tensor(&[o, c, k, k], -1.0, 1.0);
        let packed = PackedConv::with_precision(&wt, Precision::Fp32Fast);
        let y = conv2d_packed(&x, &packed, None, Padding::Replicate, Epilogue::NONE);
        assert_eq!(bits(&y), bits(&conv2d(&x, &wt, None, Padding::Replicate)), "{c} → {o} {k}×{k}");
    }
    assert_eq!(Precision::resolve("fp32-fast", &Cpu).unwrap(), Precision::Fp32Fast);
    assert_eq!(Precision::Fp32Fast.name(), "fp32-fast");
    assert!(Precision::Fp32Fast.runs_on_cpu());
}

#[test]
fn conv_fast_is_deterministic() {
    // Same bits on every run and for any thread count, on the channel-vector path (19 → 23),
    // the Winograd paths (32 → 23: forward and input gradient; 32 → 32: the weight gradient
    // too) and the pixel-vector path (19 → 3), zero and replicate padding.
    for (c, o, pad) in [
        (19, 23, Padding::Replicate),
        (32, 32, Padding::Zero),
        (32, 23, Padding::Replicate),
        (19, 3, Padding::Replicate),
    ] {
        let mut rng = Rng::new(7);
        let x = rng.tensor(&[2, c, 13, 37], -1.0, 1.0);
        let w = rng.tensor(&[o, c, 3, 3], -1.0, 1.0);
        let dy = rng.tensor(&[2, o, 13, 37], -1.0, 1.0);
        let run = || {
            let y = conv2d(&x, &w, None, pad);
            let mut dx = Tensor::zeros(&x.shape);
            let mut dw = Tensor::zeros(&w.shape);
            conv2d_backward(&x, &w, &dy, pad, Some(&mut dx), &mut dw, None);
            (y, dx, dw)
        };
        let bits = |t: &(Tensor, Tensor, Tensor)| {
            [&t.0, &t.1, &t.2].map(|t| t.data.iter().map(|v| v.to_bits()).collect::<Vec<u32>>())
        };
        let a = bits(&run());
        assert_eq!(a, bits(&run()), "{c} → {o} {pad:?}: two runs differ");
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        assert_eq!(a, bits(&one.install(run)), "{c} → {o} {pad:?}: 1 thread differs from the default pool");
    }
}

#[test]
fn packed_weights_and_fused_epilogues_give_the_bits_of_the_separate_ops() {
    // Weights packed once (PackedConv, what inference keeps) and used on two inputs, with the
    // residual add and the ReLU fused into the store (Epilogue): the same bits as conv2d, which
    // packs per call, followed by add_assign and relu, on each kernel: pixel-vector (19 → 3),
    // Winograd (32 → 23, 48 → 64), direct channel-vector (19 → 23 at 3×3, 16 → 20 at 5×3).
    let bits = |t: &Tensor| t.data.iter().map(|v| v.to_bits()).collect::<Vec<u32>>();
    let mut rng = Rng::new(11);
    for (c, o, kh, kw) in [(19, 3, 3, 3), (32, 23, 3, 3), (48, 64, 3, 3), (19, 23, 3, 3), (16, 20, 5, 3)] {
        let w = rng.tensor(&[o, c, kh, kw], -1.0, 1.0);
        let b = rng.tensor(&[o], -1.0, 1.0);
        let packed = PackedConv::new(&w);
        assert_eq!(packed.shape(), [o, c, kh, kw]);
        for (n, h, wd, pad) in [(2, 13, 37, Padding::Replicate), (1, 8, 5, Padding::Zero)] {
            let x = rng.tensor(&[n, c, h, wd], -1.0, 1.0);
            let skip = rng.tensor(&[n, o, h, wd], -1.0, 1.0);
            let what = format!("{c} → {o} {kh}×{kw}, {n}×{h}×{wd} {pad:?}");
            let plain = conv2d(&x, &w, Some(&b), pad);
            assert_eq!(
                bits(&conv2d_packed(&x, &packed, Some(&b), pad, Epilogue::NONE)),
                bits(&plain),
                "{what}"
            );
            let relu = activation::relu(&plain);
            assert!(relu.data.contains(&0.0) && relu.data.iter().any(|&v| v > 0.0));
            assert_eq!(
                bits(&conv2d_packed(&x, &packed, Some(&b), pad, Epilogue::RELU)),
                bits(&relu),
                "{what} relu"
            );
            let mut added = plain.clone();
            activation::add_assign(&mut added, &skip);
            let epi = Epilogue { skip: Some(&skip), relu: false };
            assert_eq!(bits(&conv2d_packed(&x, &packed, Some(&b), pad, epi)), bits(&added), "{what} skip");
            let epi = Epilogue { skip: Some(&skip), relu: true };
            let both = activation::relu(&added);
            assert_eq!(
                bits(&conv2d_packed(&x, &packed, Some(&b), pad, epi)),
                bits(&both),
                "{what} skip, relu"
            );
        }
    }
}

#[test]
fn fp32_chain_gives_the_bits_of_the_convs_one_by_one() {
    // The fp32 chain (what the CPU runs a trunk's convs on: padded channels-last activations
    // from conv to conv, epilogues and the pixel shuffle fused into the stores) against
    // conv2d_packed on NCHW tensors with the same epilogues and the pixel_shuffle op, step by
    // step and bit for bit: odd and even sizes, both paddings, 16·k channels (32 and 48), a
    // residual block, shuffles by 2 and 3, the last two convs into a 1-, 3- and 4-output conv of
    // 3×3 or 1×1, and the same bits on one thread. With the weights packed for F(4×4, 3×3)
    // (`fp32-fast`) too, whose 4×4 tiles the chain's padded grid must hold.
    let bits = |t: &Tensor| t.data.iter().map(|v| v.to_bits()).collect::<Vec<u32>>();
    let mut rng = Rng::new(12);
    for precision in [Precision::Fp32, Precision::Fp32Fast] {
        let cases = [
            (2, 13, 37, 32, 2, 3, 3, Padding::Replicate),
            (1, 8, 6, 48, 3, 1, 3, Padding::Zero),
            (1, 5, 9, 16, 2, 4, 1, Padding::Replicate),
            (3, 1, 1, 32, 2, 3, 3, Padding::Zero),
        ];
        for (n, h, w, c, r, o_last, k_last, pad) in cases {
            let what = format!(
                "{}: {n}×{h}×{w}, {c} channels, shuffle {r}, last {o_last} {k_last}×{k_last}, {pad:?}",
                precision.name()
            );
            let conv = |rng: &mut Rng, o: usize, ci: usize, k: usize| {
                let wt = rng.tensor(&[o, ci, k, k], -0.5, 0.5);
                (PackedConv::with_precision(&wt, precision), rng.tensor(&[o], -0.5, 0.5))
            };
            let (p_in, b_in) = conv(&mut rng, c, 3, 3);
            let (p1, b1) = conv(&mut rng, c, c, 3);
            let (p2, b2) = conv(&mut rng, c, c, 3);
            let (pu, bu) = conv(&mut rng, c * r * r, c, 3);
            let (pt, bt) = conv(&mut rng, c, c, 3);
            let (pl, bl) = conv(&mut rng, o_last, c, k_last);
            assert!(p1.is_winograd() && pu.is_winograd() && pl.is_small_out(), "{what}");
            let x = rng.tensor(&[n, 3, h, w], -1.0, 1.0);
            let run = || {
                let mut steps = Vec::new();
                let a = conv_to_f32_act(&x, &p_in, Some(&b_in), pad);
                steps.push(a.to_nchw());
                let r1 = conv_f32_act(&a, &p1, Some(&b1), ActEpilogue { skip: None, relu: true }, 1);
                steps.push(r1.to_nchw());
                let a = conv_f32_act(&r1, &p2, Some(&b2), ActEpilogue { skip: Some(&a), relu: false }, 1);
                steps.push(a.to_nchw());
                let z = conv_f32_act(&a, &pu, Some(&bu), ActEpilogue::default(), r);
                assert_eq!(z.shape, [n, c, r * h, r * w], "{what}");
                steps.push(z.to_nchw());
                steps.push(conv_f32_act_relu_small_out(&z, &pt, Some(&bt), &pl, Some(&bl)));
                steps
            };
            let chain = run();
            // The same convs on NCHW tensors, one by one.
            let a = conv2d_packed(&x, &p_in, Some(&b_in), pad, Epilogue::NONE);
            let r1 = conv2d_packed(&a, &p1, Some(&b1), pad, Epilogue::RELU);
            let a2 = conv2d_packed(&r1, &p2, Some(&b2), pad, Epilogue { skip: Some(&a), relu: false });
            let z = pixel_shuffle(&conv2d_packed(&a2, &pu, Some(&bu), pad, Epilogue::NONE), r);
            let t = conv2d_packed(&z, &pt, Some(&bt), pad, Epilogue::RELU);
            let y = conv2d_packed(&t, &pl, Some(&bl), pad, Epilogue::NONE);
            assert!(y.data.iter().all(|v| v.is_finite()) && r1.data.contains(&0.0), "{what}");
            for (step, (got, want)) in
                ["conv_in", "conv1 + relu", "conv2 + skip", "upscale + shuffle", "tail"]
                    .iter()
                    .zip(chain.iter().zip([&a, &r1, &a2, &z, &y]))
            {
                assert_eq!(got.shape, want.shape, "{what}: {step}");
                assert_eq!(bits(got), bits(want), "{what}: {step}");
            }
            let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
            assert_eq!(bits(&one.install(run)[4]), bits(&y), "{what}: one thread");
            // The round trip through the chain's layout.
            assert_eq!(bits(&F32Act::from_nchw(&a2, pad).to_nchw()), bits(&a2), "{what}: from_nchw");
        }
    }
}

/// The comparator itself: a NaN or an infinity from the fast kernel must fail it.
#[test]
fn fast_vs_reference_comparator_fails_on_nan_and_infinity() {
    let r = Tensor::from_vec(&[1, 1, 1, 3], vec![1.0, 2.0, 3.0]).unwrap();
    assert_close("identical", &r, &r, 1e-6, 1e-6);
    for bad in [f32::NAN, f32::INFINITY] {
        let mut f = r.clone();
        f.data[1] = bad;
        let caught = std::panic::catch_unwind(|| assert_close("fast", &f, &r, 1e-6, 1e-6));
        assert!(caught.is_err(), "a {bad} from the fast kernel passed the comparator");
    }
}
