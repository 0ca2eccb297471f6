//! The bf16 convolution (`--precision bf16`; AMX tiles, or AVX512_BF16 dot products under
//! `ANISOCB_NO_AMX=1` or on a CPU without tiles: `make test` runs this file both ways) against its scalar twin `conv2d_bf16_ref` (the
//! fp32 reference on bf16-rounded inputs and weights) on random shapes: widths that are not a
//! multiple of the 16-pixel tile (the lanes past the row's end), one and several 32-channel
//! blocks, output channels that are not a multiple of 16 and odd tile counts, 3×3 / 1×1 / 5×3
//! kernels, both paddings, bias, the fused epilogue; same bits on every run and thread count;
//! the fallback where the CPU has no tiles. Skipped (with a line saying so) on a CPU without
//! AVX512_BF16.

#[path = "common/close.rs"]
mod close;
#[path = "common/random.rs"]
mod random;
use anisocb::nn::config::{NetConfig, NetKind};
use anisocb::nn::layers::Trunk;
use anisocb::ops::conv2d::amx::{self, bf16, conv2d_bf16_ref, conv_act, f32_of_bf16, Act, ActEpilogue};
use anisocb::ops::conv2d::{
    conv2d, conv2d_packed, conv2d_ref, conv_act_nchw, conv_act_relu_small_out, Epilogue, PackedConv,
    Precision,
};
use anisocb::ops::pixel_shuffle::pixel_shuffle;
use anisocb::ops::{activation, Padding};
use anisocb::rng::Rng;
use anisocb::Tensor;
use close::assert_close;
use random::TestData;

fn tiles_here() -> bool {
    if !amx::available() {
        println!("skipped: this CPU has no AVX512_BF16 (or ANISOCB_NO_BF16 is set)");
    }
    amx::available()
}

/// The kernel is the one the environment and the CPU ask for: tiles only where the CPU and OS
/// have them and `ANISOCB_NO_AMX` is unset, the dot-product kernel otherwise.
#[test]
fn bf16_runs_on_tiles_or_dot_products_as_the_cpu_and_environment_say() {
    let no_amx = std::env::var_os("ANISOCB_NO_AMX").is_some();
    assert!(!(no_amx && amx::tiles()), "tiles used under ANISOCB_NO_AMX");
    assert!(!amx::tiles() || amx::available(), "tiles without AVX512_BF16");
    let kernel = match (amx::available(), amx::tiles()) {
        (false, _) => "none (fp32)",
        (true, true) => "AMX tiles",
        (true, false) => "AVX512_BF16 dot products",
    };
    println!("bf16 kernel here: {kernel}");
}

#[test]
fn bf16_rounding_is_to_nearest_even_and_keeps_nan_and_infinity() {
    // 1 + 2⁻⁸ is halfway between bf16 1.0 and 1 + 2⁻⁷: ties go to the even mantissa (1.0);
    // 1 + 3·2⁻⁸ ties upwards to 1 + 2⁻⁶ (even); just above the tie rounds up.
    assert_eq!(f32_of_bf16(bf16(1.0 + 2f32.powi(-8))), 1.0);
    assert_eq!(f32_of_bf16(bf16(1.0 + 3.0 * 2f32.powi(-8))), 1.0 + 2f32.powi(-6));
    assert_eq!(f32_of_bf16(bf16(1.0 + 2f32.powi(-8) + 2f32.powi(-20))), 1.0 + 2f32.powi(-7));
    assert_eq!(f32_of_bf16(bf16(-2.5)), -2.5);
    assert!(f32_of_bf16(bf16(f32::NAN)).is_nan());
    assert_eq!(f32_of_bf16(bf16(f32::INFINITY)), f32::INFINITY);
    assert_eq!(f32_of_bf16(bf16(f32::MAX)), f32::INFINITY, "rounds past the largest bf16");
    // Half a unit in the last place: relative error ≤ 2⁻⁸ on random values.
    let mut rng = Rng::new(3);
    for _ in 0..10_000 {
        let v = rng.uniform_in(-1e3, 1e3);
        assert!((f32_of_bf16(bf16(v)) - v).abs() <= v.abs() * 2f32.powi(-8), "{v}");
    }
}

#[allow(clippy::too_many_arguments)]
fn check(
    rng: &mut Rng,
    n: usize,
    c: usize,
    o: usize,
    h: usize,
    w: usize,
    kh: usize,
    kw: usize,
    pad: Padding,
) {
    let what = format!("n{n} c{c} o{o} {h}x{w} k{kh}x{kw} {pad:?}");
    let x = rng.tensor(&[n, c, h, w], -1.0, 1.0);
    let wt = rng.tensor(&[o, c, kh, kw], -1.0, 1.0);
    let b = rng.tensor(&[o], -1.0, 1.0);
    let packed = PackedConv::with_precision(&wt, Precision::Bf16);
    assert!(packed.is_bf16(), "{what}: not packed for the tiles");
    let got = conv2d_packed(&x, &packed, Some(&b), pad, Epilogue::NONE);
    // Only the f32 summation order differs from the twin: sums of c·kh·kw products of size ≤ 1.
    let k = (c * kh * kw) as f32;
    assert_close(&format!("bf16 {what}"), &got, &conv2d_bf16_ref(&x, &wt, Some(&b), pad), 2e-6 * k, 0.0);
    // And bf16 is what it says: within the rounding of inputs and weights of the fp32 result,
    // and not equal to it.
    let fp32 = conv2d_ref(&x, &wt, Some(&b), pad);
    assert_close(&format!("bf16 vs fp32 {what}"), &got, &fp32, 8.0 * 2f32.powi(-9) * k.sqrt(), 0.0);
    assert_ne!(got, fp32, "{what}: the bf16 kernel gave fp32's result");
}

#[test]
fn bf16_tiles_match_the_scalar_twin_on_odd_widths_tails_and_kernels() {
    if !tiles_here() {
        return;
    }
    let mut rng = Rng::new(5);
    for pad in [Padding::Zero, Padding::Replicate] {
        // The nets' shapes (32 → 32, 32 → 128 at 32² and 64²) and the edges: width 1, widths
        // 15/17/33/47 (tile tails, an odd count of pixel tiles), 64 channels (two blocks of
        // 32), outputs 20 / 48 (a part tile, an odd count of output tiles), 1×1 and 5×3.
        check(&mut rng, 1, 32, 32, 32, 32, 3, 3, pad);
        check(&mut rng, 1, 32, 128, 16, 64, 3, 3, pad);
        check(&mut rng, 2, 32, 32, 5, 1, 3, 3, pad);
        check(&mut rng, 1, 64, 20, 7, 15, 3, 3, pad);
        check(&mut rng, 2, 32, 48, 3, 17, 3, 3, pad);
        check(&mut rng, 1, 96, 33, 4, 33, 1, 1, pad);
        check(&mut rng, 1, 32, 16, 9, 47, 5, 3, pad);
    }
    for _ in 0..6 {
        let (n, c, o) = (rng.below(2) + 1, 32 * (rng.below(3) + 1), 5 + rng.below(80));
        let (h, w) = (1 + rng.below(20), 1 + rng.below(70));
        let pad = if rng.below(2) == 0 { Padding::Zero } else { Padding::Replicate };
        check(&mut rng, n, c, o, h, w, 3, 3, pad);
    }
}

#[test]
fn bf16_tiles_are_deterministic_and_fuse_the_epilogue() {
    if !tiles_here() {
        return;
    }
    let bits = |t: &Tensor| t.data.iter().map(|v| v.to_bits()).collect::<Vec<u32>>();
    let mut rng = Rng::new(9);
    let (x, w, b) = (
        rng.tensor(&[2, 32, 13, 37], -1.0, 1.0),
        rng.tensor(&[40, 32, 3, 3], -1.0, 1.0),
        rng.tensor(&[40], -1.0, 1.0),
    );
    let skip = rng.tensor(&[2, 40, 13, 37], -1.0, 1.0);
    let packed = PackedConv::with_precision(&w, Precision::Bf16);
    let run = || conv2d_packed(&x, &packed, Some(&b), Padding::Replicate, Epilogue::NONE);
    let plain = run();
    assert_eq!(bits(&plain), bits(&run()), "two runs differ");
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    assert_eq!(bits(&plain), bits(&one.install(run)), "1 thread differs from the default pool");
    let mut added = plain.clone();
    activation::add_assign(&mut added, &skip);
    let fused =
        conv2d_packed(&x, &packed, Some(&b), Padding::Replicate, Epilogue { skip: Some(&skip), relu: true });
    assert_eq!(bits(&fused), bits(&activation::relu(&added)), "skip + relu fused");
}

#[test]
fn bf16_packs_only_what_the_tiles_take_and_fp32_stays_fp32() {
    let mut rng = Rng::new(2);
    let x = rng.tensor(&[1, 32, 6, 9], -1.0, 1.0);
    // The first conv (3 channels), 16 channels, and the last convs (≤ 4 outputs) stay fp32 with
    // fp32's bits; so does every conv packed for fp32.
    for (c, o, p) in [
        (3, 32, Precision::Bf16),
        (16, 32, Precision::Bf16),
        (32, 3, Precision::Bf16),
        (32, 32, Precision::Fp32),
    ] {
        let w = rng.tensor(&[o, c, 3, 3], -1.0, 1.0);
        let packed = PackedConv::with_precision(&w, p);
        assert!(!packed.is_bf16(), "{c} → {o} {p:?} packed for the tiles");
        let xi = rng.tensor(&[1, c, 6, 9], -1.0, 1.0);
        assert_eq!(
            conv2d_packed(&xi, &packed, None, Padding::Zero, Epilogue::NONE),
            conv2d(&xi, &w, None, Padding::Zero)
        );
    }
    let w = rng.tensor(&[32, 32, 3, 3], -1.0, 1.0);
    assert_eq!(PackedConv::with_precision(&w, Precision::Bf16).is_bf16(), amx::available());
    let fastest = if amx::tiles() { Precision::Bf16 } else { Precision::Fp32Fast };
    assert_eq!(Precision::fastest_cpu(), fastest);
    assert!(Precision::Fp32.runs_on_cpu() && !Precision::Fp16.runs_on_cpu());
    assert_eq!(Precision::Bf16.runs_on_cpu(), amx::available());
    drop(x);
}

/// bf16 rounding of every value of `t` (what an [`Act`] stores).
fn rounded(t: &Tensor) -> Tensor {
    let mut r = t.clone();
    r.data.iter_mut().for_each(|v| *v = f32_of_bf16(bf16(*v)));
    r
}

#[test]
fn bf16_activation_chain_matches_the_twin_with_its_skip_relu_shuffle_and_borders() {
    // conv_act keeps the activations padded channels-last in bf16 between convs, fusing the
    // residual add, the ReLU and the pixel shuffle into the store and filling the border for
    // the next conv: each against the twin, on widths off the tile (15, 37) and both paddings,
    // with single bf16 and with hi + lo pairs (the trunk's LR part: the input exact to 2⁻¹⁷,
    // so the twin is the reference on rounded weights and the unrounded input).
    if !tiles_here() {
        return;
    }
    let mut rng = Rng::new(13);
    for split in [false, true] {
        for (pad, h, w) in [(Padding::Replicate, 9, 37), (Padding::Zero, 6, 15), (Padding::Replicate, 32, 32)]
        {
            let what = format!("{pad:?} {h}x{w} split={split}");
            let x = rng.tensor(&[2, 32, h, w], -1.0, 1.0);
            let (w1, b1) = (rng.tensor(&[32, 32, 3, 3], -0.2, 0.2), rng.tensor(&[32], -0.5, 0.5));
            let (w2, b2) = (rng.tensor(&[128, 32, 3, 3], -0.2, 0.2), rng.tensor(&[128], -0.5, 0.5));
            // What an Act holds: the value rounded, or to 2⁻¹⁷ as a pair.
            let held = |t: &Tensor| if split { t.clone() } else { rounded(t) };
            let (rtol, stored) =
                if split { (2f32.powi(-16), 2f32.powi(-16)) } else { (2f32.powi(-8), 2f32.powi(-8)) };
            let a = Act::from_nchw(&x, pad, split);
            assert_close(&format!("input act {what}"), &a.to_nchw(), &held(&x), 0.0, stored);
            // The twin: weights rounded, the input as the Act holds it.
            let twin = |x: &Tensor, w: &Tensor, b: &Tensor| conv2d_ref(&held(x), &rounded(w), Some(b), pad);
            // Conv, skip, ReLU: the sum in f32, stored once.
            let p1 = PackedConv::for_chain(&w1, Precision::Bf16, 1, split);
            let got = conv_act(&a, &p1, Some(&b1), ActEpilogue { skip: Some(&a), relu: true }, split);
            let mut want = twin(&x, &w1, &b1);
            activation::add_assign(&mut want, &held(&x));
            let want = activation::relu(&want);
            // Storing (2⁻⁸ or 2⁻¹⁶ relative) after the summation order (1e-5 absolute).
            assert_close(&format!("conv+skip+relu {what}"), &got.to_nchw(), &want, 1e-5 * 288.0, rtol);
            // The next conv reads `got` through its border: the shuffled conv against the twin
            // on the first output as stored, out as single bf16 (the HR tail's form).
            let p2 = PackedConv::for_chain(&w2, Precision::Bf16, 2, split);
            let up = conv_act(&got, &p2, Some(&b2), ActEpilogue::default(), false);
            assert_eq!(up.shape, [2, 32, 2 * h, 2 * w], "{what}: shuffled shape");
            let want_up = pixel_shuffle(&twin(&got.to_nchw(), &w2, &b2), 2);
            assert_close(
                &format!("conv+shuffle {what}"),
                &up.to_nchw(),
                &want_up,
                1e-5 * 288.0,
                2f32.powi(-8),
            );
            // And out to NCHW f32 (no rounding of the output), with the fused ReLU.
            let p3 = PackedConv::for_chain(&w1, Precision::Bf16, 1, false);
            let y = conv_act_nchw(&up, &p3, Some(&b1), Epilogue::RELU);
            let want_y = activation::relu(&conv2d_ref(&up.to_nchw(), &rounded(&w1), Some(&b1), pad));
            assert_close(&format!("conv to nchw {what}"), &y, &want_y, 1e-5 * 288.0, 0.0);
        }
    }
}

#[test]
fn bf16_rows_grouped_per_task_give_the_same_bits_whatever_the_grouping() {
    // `correlate` takes a task's rows through the tiles, then all of them through the store,
    // with at most 128 KiB of sums a task. A batch of 128-wide rows (16 KiB of sums each) on
    // 1, 3 and 5 threads groups them 8 (the cap), 6 and 4 to a task: the same bits, with the
    // skip, the ReLU and hi + lo pairs, and the shuffle; and the twin's values.
    if !tiles_here() {
        return;
    }
    let bits = |a: &Act| a.to_nchw().data.iter().map(|v| v.to_bits()).collect::<Vec<u32>>();
    let mut rng = Rng::new(21);
    let x = rng.tensor(&[4, 32, 32, 128], -1.0, 1.0);
    let (w1, b1) = (rng.tensor(&[32, 32, 3, 3], -0.2, 0.2), rng.tensor(&[32], -0.5, 0.5));
    let (w2, b2) = (rng.tensor(&[128, 32, 3, 3], -0.2, 0.2), rng.tensor(&[128], -0.5, 0.5));
    let a = Act::from_nchw(&x, Padding::Replicate, true);
    let p1 = PackedConv::for_chain(&w1, Precision::Bf16, 1, true);
    let p2 = PackedConv::for_chain(&w2, Precision::Bf16, 2, true);
    let run = || {
        let y = conv_act(&a, &p1, Some(&b1), ActEpilogue { skip: Some(&a), relu: true }, true);
        let up = conv_act(&y, &p2, Some(&b2), ActEpilogue::default(), false);
        (bits(&y), bits(&up), y)
    };
    let pool = |t: usize| rayon::ThreadPoolBuilder::new().num_threads(t).build().unwrap();
    let (y_bits, up_bits, y) = pool(1).install(run);
    for t in [3, 5] {
        let (yb, ub, _) = pool(t).install(run);
        assert!(yb == y_bits && ub == up_bits, "{t} threads differ from 1");
    }
    let mut want = conv2d_ref(&x, &rounded(&w1), Some(&b1), Padding::Replicate);
    activation::add_assign(&mut want, &x);
    let want = activation::relu(&want);
    assert_close("grouped rows against the twin", &y.to_nchw(), &want, 1e-5 * 288.0, 2f32.powi(-16));
}

#[test]
fn tile_conv_stored_into_the_last_convs_input_gives_the_bits_of_the_two_convs_apart() {
    // A trunk's last two convs fused (the tile conv's ReLU'd f32 output written straight into the
    // padded planar input of the ≤ 4-output conv, its border filled after) against the same two
    // convs through an NCHW tensor: the same bits, on widths on and off the 16-pixel vectors,
    // both paddings, 3×3 / 1×1 / 5×3 last kernels, 1, 3 and 4 outputs, a batch of two, single
    // and split input; and a last conv of 8 outputs (not the small-output kernel) goes the long way.
    if !tiles_here() {
        return;
    }
    let mut rng = Rng::new(29);
    for split in [false, true] {
        for (pad, h, w) in [(Padding::Replicate, 9, 37), (Padding::Zero, 6, 15), (Padding::Replicate, 5, 32)]
        {
            for (o, kh, kw) in [(3, 3, 3), (1, 1, 1), (4, 5, 3), (8, 3, 3)] {
                let what = format!("{pad:?} {h}x{w} split={split} last {o}x{kh}x{kw}");
                let a = Act::from_nchw(&rng.tensor(&[2, 32, h, w], -1.0, 1.0), pad, split);
                let (w1, b1) = (rng.tensor(&[32, 32, 3, 3], -0.2, 0.2), rng.tensor(&[32], -0.5, 0.5));
                let (w2, b2) = (rng.tensor(&[o, 32, kh, kw], -0.2, 0.2), rng.tensor(&[o], -0.5, 0.5));
                let p1 = PackedConv::for_chain(&w1, Precision::Bf16, 1, split);
                let p2 = PackedConv::with_precision(&w2, Precision::Bf16);
                let apart = conv_act_nchw(&a, &p1, Some(&b1), Epilogue::RELU);
                let want = conv2d_packed(&apart, &p2, Some(&b2), pad, Epilogue::NONE);
                let got = conv_act_relu_small_out(&a, &p1, Some(&b1), &p2, Some(&b2), pad);
                assert_eq!(got.shape, want.shape, "{what}");
                let same = got.data.iter().zip(&want.data).all(|(g, w)| g.to_bits() == w.to_bits());
                assert!(same, "{what}: the fused convs differ from the two apart");
            }
        }
    }
}

#[test]
fn first_conv_stored_straight_into_the_tiles_layout_gives_the_bits_of_the_nchw_way() {
    // A trunk's first conv (3 → C, fp32) stored as an Act as it runs (`conv_to_act`) against
    // the conv to an NCHW tensor and that tensor padded into an Act: the same bf16 values and
    // borders (so the same bits downstream), rounded and split, both paddings, widths on and
    // off the 16-pixel tiles, a batch of two.
    if !tiles_here() {
        return;
    }
    let mut rng = Rng::new(37);
    for split in [false, true] {
        for (pad, h, w) in [(Padding::Replicate, 9, 37), (Padding::Zero, 6, 15), (Padding::Replicate, 1, 32)]
        {
            let what = format!("{pad:?} {h}x{w} split={split}");
            let x = rng.tensor(&[2, 3, h, w], -1.0, 1.0);
            let (wt, b) = (rng.tensor(&[32, 3, 3, 3], -0.5, 0.5), rng.tensor(&[32], -0.5, 0.5));
            let p = PackedConv::with_precision(&wt, Precision::Bf16);
            assert!(!p.is_bf16(), "{what}: a 3-channel conv packed for the tiles");
            let want = Act::from_nchw(&conv2d_packed(&x, &p, Some(&b), pad, Epilogue::NONE), pad, split);
            let got = amx::conv_to_act(&x, &p, Some(&b), pad, split);
            assert!(got.shape == want.shape && got.is_split() == split, "{what}: shape or form");
            let bits = |t: &Tensor| t.data.iter().map(|v| v.to_bits()).collect::<Vec<u32>>();
            assert_eq!(bits(&got.to_nchw()), bits(&want.to_nchw()), "{what}: the stored values differ");
            // The borders, as the next conv reads them.
            let (w2, b2) = (rng.tensor(&[16, 32, 3, 3], -0.2, 0.2), rng.tensor(&[16], -0.5, 0.5));
            let p2 = PackedConv::for_chain(&w2, Precision::Bf16, 1, split);
            let next = |a: &Act| bits(&conv_act_nchw(a, &p2, Some(&b2), Epilogue::NONE));
            assert_eq!(next(&got), next(&want), "{what}: the next conv reads other borders");
        }
    }
}

#[test]
fn bf16_trunk_stays_within_bf16_rounding_of_the_fp32_trunk_and_is_deterministic() {
    // Every net of the shipped shape (small config: 32 channels, replicate padding) and the
    // paper's (64 channels), on a smooth input: the bf16 forward (`Trunk::pack(Bf16)`: the
    // chain of Acts) within 1 % of the output's scale of the fp32 forward, not equal to it,
    // and the same bits run to run.
    if !tiles_here() {
        return;
    }
    let ops = anisocb::ops::Cpu;
    for (config, kind) in [
        (NetConfig::small().with_padding(Padding::Replicate), NetKind::Geometry),
        (NetConfig::small().with_padding(Padding::Replicate), NetKind::Boundary),
        (NetConfig::paper(), NetKind::Geometry),
    ] {
        let net = Trunk::init(kind, config, 4);
        let mut x = Tensor::zeros(&[2, 3, 12, 20]);
        for (i, v) in x.data.iter_mut().enumerate() {
            *v = (i as f32 * 0.37).sin() * 0.5;
        }
        let fp32 = net.forward_packed(&ops, &x, &net.pack(Precision::Fp32));
        let packed = net.pack(Precision::Bf16);
        let got = net.forward_packed(&ops, &x, &packed);
        assert_eq!(got, net.forward_packed(&ops, &x, &packed), "{kind:?}: two runs differ");
        assert_ne!(got, fp32, "{kind:?}: the bf16 forward gave fp32's result");
        let scale = fp32.data.iter().fold(0f32, |m, v| m.max(v.abs()));
        assert!(scale > 0.0);
        assert_close(&format!("{kind:?} {}", config.channels), &got, &fp32, 0.01 * scale, 0.0);
    }
}

#[test]
fn only_geometrynets_lr_part_reads_hi_lo_pairs_the_map_nets_read_single_bf16() {
    // Trunk::pack(Bf16): GeometryNet's blocks and upscale conv read hi + lo pairs (single
    // rounding there moved held-out vertices by up to 0.36 mm); its HR tail and every conv of
    // BoundaryNet and EnhanceNet, whose outputs only gate R, read one bf16 (docs/performance.md).
    if !tiles_here() {
        return;
    }
    let config = NetConfig::small().with_padding(Padding::Replicate);
    for (kind, lr_pairs) in [(NetKind::Geometry, true), (NetKind::Boundary, false), (NetKind::Enhance, false)]
    {
        let net = Trunk::init(kind, config, 4);
        let packed = net.pack(Precision::Bf16);
        let names: Vec<String> = net.convs().into_iter().map(|(n, _)| n).collect();
        for (name, p) in names.iter().zip(&packed) {
            let lr = name.starts_with("blocks") || name.starts_with("upscale");
            assert_eq!(p.is_split(), lr && lr_pairs && p.is_bf16(), "{kind:?} {name}: pairs or not");
        }
        assert!(packed.iter().filter(|p| p.is_bf16()).count() > 1, "{kind:?}: too few tile convs");
    }
}
