//! Audit of every engine op against references written by JAX/optax
//! (tests/fixtures/gen_ops.py → tests/fixtures/ops/*.npy; versions in VERSIONS.txt).
//!
//! Each op is checked through two op tables: `RefOps` (the scalar `*_ref` specs) and `Cpu`
//! (the fast kernels). A check passes when |got − want| ≤ atol + rtol·|want| everywhere; on
//! failure it prints the first mismatches and the largest difference. The last test checks
//! the two tables against each other on every op of the table, at random odd shapes.
//!
//! Tolerances (the references are computed in f64, so they bound our f32 rounding only):
//! - pixel shuffle / unshuffle, relu: exact (pure copies / selections).
//! - conv2d: atol 2e-5, rtol 1e-4 — f32 sums of ≤ 150 products of magnitude ≤ 1
//!   (dw sums N·H·W ≤ 126 products); observed error is ~1e-6.
//! - resize: atol 1e-5, rtol 1e-5 — 4×4 taps, weights ≤ 1.2 in magnitude.
//! - losses: rtol 1e-5 on the mean (f64-accumulated), atol 1e-8 + rtol 1e-5 on gradients
//!   (magnitude ~1/count).
//! - Adam, 10 steps: losses rtol 1e-4, final weights atol 1e-5 + rtol 1e-4 — f32 forward and
//!   backward feeding a normalized update (each step moves a weight by ≤ lr = 1e-3).

#[path = "common/random.rs"]
mod random;
use anisocb::io::read_npy;
use anisocb::ops::conv2d::{Epilogue, PackedConv};
use anisocb::ops::loss::DetailEnergy;
use anisocb::ops::{AdamParams, Cpu, Interp, Ops, Padding, RefOps};
use anisocb::rng::Rng;
use anisocb::train::adam::Adam;
use anisocb::Tensor;
use random::TestData;
use std::path::PathBuf;

fn tables() -> [&'static dyn Ops; 2] {
    [&RefOps, &Cpu]
}

fn fixture(name: &str) -> Tensor {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/ops").join(format!("{name}.npy"));
    read_npy(&path).unwrap_or_else(|e| panic!("{e} (regenerate with python3 tests/fixtures/gen_ops.py)"))
}

/// Compare `got` with `want` element-wise; panic listing the first mismatches and the largest
/// difference. Returns the largest absolute difference.
fn check(what: &str, got: &[f32], want: &[f32], atol: f32, rtol: f32) -> f32 {
    assert_eq!(got.len(), want.len(), "{what}: {} values, reference has {}", got.len(), want.len());
    let mut worst = (0.0f32, 0usize);
    let mut bad = Vec::new();
    for (i, (&g, &w)) in got.iter().zip(want).enumerate() {
        let d = (g - w).abs();
        if d > worst.0 || d.is_nan() {
            worst = (if d.is_nan() { f32::INFINITY } else { d }, i);
        }
        if d.is_nan() || d > atol + rtol * w.abs() {
            bad.push(i);
        }
    }
    if !bad.is_empty() {
        let first: Vec<String> =
            bad.iter().take(5).map(|&i| format!("[{i}] got {} want {}", got[i], want[i])).collect();
        panic!(
            "{what}: {} of {} values outside atol {atol} + rtol {rtol}; first: {}; largest diff {} at [{}] (got {} want {})",
            bad.len(),
            got.len(),
            first.join(", "),
            worst.0,
            worst.1,
            got[worst.1],
            want[worst.1]
        );
    }
    worst.0
}

fn check_t(what: &str, got: &Tensor, want: &Tensor, atol: f32, rtol: f32) -> f32 {
    assert_eq!(got.shape, want.shape, "{what}: shape");
    check(what, &got.data, &want.data, atol, rtol)
}

#[test]
fn conv2d_forward_and_gradients_match_jax() {
    let cases = [
        ("conv3x3_zero", Padding::Zero),
        ("conv3x3_replicate", Padding::Replicate),
        ("conv5x5_zero", Padding::Zero),
        ("conv5x5_replicate", Padding::Replicate),
        ("conv1x1_zero", Padding::Zero),
        ("conv3x3_replicate_tiny", Padding::Replicate),
    ];
    let (atol, rtol) = (2e-5, 1e-4);
    for ops in tables() {
        for (name, pad) in cases {
            let f = |k: &str| fixture(&format!("{name}_{k}"));
            let (x, w, b, dy) = (f("x"), f("w"), f("b"), f("dy"));
            let tag = |t: &str| format!("{} {name} {t}", ops.name());
            let y = ops.conv2d(&x, &w, Some(&b), pad);
            let mut worst = check_t(&tag("y"), &y, &f("y"), atol, rtol);
            let (mut dx, mut dw, mut db) =
                (Tensor::zeros(&x.shape), Tensor::zeros(&w.shape), Tensor::zeros(&b.shape));
            ops.conv2d_backward(&x, &w, &dy, pad, Some(&mut dx), &mut dw, Some(&mut db));
            worst = worst.max(check_t(&tag("dx"), &dx, &f("dx"), atol, rtol));
            worst = worst.max(check_t(&tag("dw"), &dw, &f("dw"), atol, rtol));
            worst = worst.max(check_t(&tag("db"), &db, &f("db"), atol, rtol));
            println!("{}: largest diff {worst:e}", tag("all"));
        }
    }
}

#[test]
fn relu_matches_jax_exactly() {
    let (x, dy) = (fixture("relu_x"), fixture("relu_dy"));
    for ops in tables() {
        check_t(&format!("{} relu y", ops.name()), &ops.relu(&x), &fixture("relu_y"), 0.0, 0.0);
        let mut dx = Tensor::zeros(&x.shape);
        ops.relu_backward(&x, &dy, &mut dx);
        check_t(&format!("{} relu dx", ops.name()), &dx, &fixture("relu_dx"), 0.0, 0.0);
    }
}

#[test]
fn pixel_shuffle_and_unshuffle_match_jax_exactly() {
    for ops in tables() {
        for r in [2, 3] {
            let x = fixture(&format!("pixel_shuffle_r{r}_x"));
            let y = ops.pixel_shuffle(&x, r);
            check_t(
                &format!("{} shuffle r={r}", ops.name()),
                &y,
                &fixture(&format!("pixel_shuffle_r{r}_y")),
                0.0,
                0.0,
            );
            let z = fixture(&format!("pixel_unshuffle_r{r}_x"));
            let u = ops.pixel_unshuffle(&z, r);
            let want = fixture(&format!("pixel_unshuffle_r{r}_y"));
            check_t(&format!("{} unshuffle r={r}", ops.name()), &u, &want, 0.0, 0.0);
        }
    }
}

#[test]
fn align_corners_resize_and_its_gradient_match_jax() {
    let cases = [
        ("resize_x2_bilinear", Interp::Bilinear),
        ("resize_x3_bilinear", Interp::Bilinear),
        ("resize_x2_bicubic", Interp::Bicubic),
        ("resize_x3_bicubic", Interp::Bicubic),
        ("resize_odd_bicubic", Interp::Bicubic),
        ("resize_odd_bilinear", Interp::Bilinear),
        ("resize_x2_catmull_rom", Interp::CatmullRom),
        ("resize_odd_catmull_rom", Interp::CatmullRom),
    ];
    for ops in tables() {
        for (name, mode) in cases {
            let f = |k: &str| fixture(&format!("{name}_{k}"));
            let (x, dy, want_y) = (f("x"), f("dy"), f("y"));
            let (oh, ow) = (want_y.shape[2], want_y.shape[3]);
            let y = ops.resize(&x, oh, ow, mode);
            let a = check_t(&format!("{} {name} y", ops.name()), &y, &want_y, 1e-5, 1e-5);
            let mut dx = Tensor::zeros(&x.shape);
            ops.resize_backward(&dy, mode, &mut dx);
            let b = check_t(&format!("{} {name} dx", ops.name()), &dx, &f("dx"), 1e-5, 1e-5);
            println!("{} {name}: largest diff y {a:e}, dx {b:e}", ops.name());
        }
    }
}

#[test]
fn mse_and_bce_with_logits_match_jax_including_extreme_logits() {
    for ops in tables() {
        let (p, t) = (fixture("mse_pred"), fixture("mse_target"));
        let (l, g) = ops.mse(&p, &t);
        check(&format!("{} mse loss", ops.name()), &[l], &fixture("mse_loss").data, 0.0, 1e-5);
        check_t(&format!("{} mse grad", ops.name()), &g, &fixture("mse_grad"), 1e-8, 1e-5);

        let (z, t) = (fixture("bce_logits"), fixture("bce_target"));
        for (tag, w) in [("nowt", 1.0), ("posw", 3.7)] {
            let (l, g) = ops.bce_with_logits(&z, &t, w);
            check(
                &format!("{} bce {tag} loss", ops.name()),
                &[l],
                &fixture(&format!("bce_{tag}_loss")).data,
                0.0,
                1e-5,
            );
            let want = fixture(&format!("bce_{tag}_grad"));
            check_t(&format!("{} bce {tag} grad", ops.name()), &g, &want, 1e-8, 1e-5);
        }
    }
}

/// conv(3→8, zero pad) · relu · conv(8→3, replicate pad), MSE: loss, and gradients into
/// `grads` (same order as the parameters: w1, b1, w2, b2).
fn stack_loss_and_grads(
    ops: &dyn Ops,
    p: &[Tensor],
    x: &Tensor,
    target: &Tensor,
    grads: &mut [Tensor],
) -> f32 {
    let h_pre = ops.conv2d(x, &p[0], Some(&p[1]), Padding::Zero);
    let h = ops.relu(&h_pre);
    let y = ops.conv2d(&h, &p[2], Some(&p[3]), Padding::Replicate);
    let (loss, dy) = ops.mse(&y, target);
    for g in grads.iter_mut() {
        g.data.iter_mut().for_each(|v| *v = 0.0);
    }
    let (g01, g23) = grads.split_at_mut(2);
    let mut dh = Tensor::zeros(&h.shape);
    let (gw2, gb2) = g23.split_at_mut(1);
    ops.conv2d_backward(&h, &p[2], &dy, Padding::Replicate, Some(&mut dh), &mut gw2[0], Some(&mut gb2[0]));
    let mut dh_pre = Tensor::zeros(&h_pre.shape);
    ops.relu_backward(&h_pre, &dh, &mut dh_pre);
    let (gw1, gb1) = g01.split_at_mut(1);
    ops.conv2d_backward(x, &p[0], &dh_pre, Padding::Zero, None, &mut gw1[0], Some(&mut gb1[0]));
    loss
}

#[test]
fn ten_adam_steps_on_a_conv_stack_follow_optax() {
    let names = ["w1", "b1", "w2", "b2"];
    let (x, target) = (fixture("adam_x"), fixture("adam_target"));
    let want_losses = fixture("adam_losses");
    for ops in tables() {
        let mut p: Vec<Tensor> = names.iter().map(|n| fixture(&format!("adam_init_{n}"))).collect();
        let mut grads: Vec<Tensor> = p.iter().map(|t| Tensor::zeros(&t.shape)).collect();
        let sizes: Vec<usize> = p.iter().map(Tensor::len).collect();
        let mut opt = Adam::new(AdamParams { lr: 1e-3, ..Default::default() }, &sizes);
        let mut losses = Vec::new();
        for _ in 0..want_losses.len() {
            losses.push(stack_loss_and_grads(ops, &p, &x, &target, &mut grads));
            let mut pr: Vec<&mut [f32]> = p.iter_mut().map(|t| t.data.as_mut_slice()).collect();
            let gr: Vec<&[f32]> = grads.iter().map(|t| t.data.as_slice()).collect();
            opt.step(ops, &mut pr, &gr);
        }
        let a = check(&format!("{} adam losses", ops.name()), &losses, &want_losses.data, 0.0, 1e-4);
        let mut worst = 0.0f32;
        for (n, t) in names.iter().zip(&p) {
            let want = fixture(&format!("adam_final_{n}"));
            worst = worst.max(check_t(&format!("{} adam final {n}", ops.name()), t, &want, 1e-5, 1e-4));
        }
        println!(
            "{} adam: loss {} → {}, largest diff losses {a:e}, weights {worst:e}",
            ops.name(),
            losses[0],
            losses[9]
        );
    }
}

/// Largest |got − want| at or below `rel` of want's largest entry (a gradient's entries span
/// decades: a tolerance on each would be loose on the large ones or fail on the tiny ones).
fn check_rel(what: &str, got: &Tensor, want: &Tensor, rel: f32) {
    let top = want.data.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    check_t(what, got, want, rel * top, 0.0);
}

/// `RefOps` (the specs) against `Cpu` (the fast paths) on every op of the table, through the
/// table the nets and the trainer run on, at random odd shapes: 1-pixel and prime sizes,
/// channel counts off the SIMD widths, lengths across the threading threshold.
///
/// Exact where the fast path computes the reference's expression element by element (copies,
/// element-wise ops and their gradients, the resize forward, the MSE and BCE gradients, Adam).
/// Otherwise within the rounding of another summation order: conv2d as in
/// tests/conv_fast_vs_ref.rs (1e-5·√terms + rtol 1e-4), the resize backward 1e-5, loss means
/// rtol 1e-5 (f64 sums), geometry-loss gradients 1e-5 of their largest entry (gathered per
/// pixel in the specs, scattered per edge or window in the fast paths).
#[test]
fn ref_ops_and_cpu_agree_on_every_op_at_random_odd_shapes() {
    let (r, c): (&dyn Ops, &dyn Ops) = (&RefOps, &Cpu);
    let mut rng = Rng::new(0x7ab1e);

    // conv2d, conv2d_packed (fused epilogue on Cpu, the trait's default on RefOps),
    // conv2d_backward (accumulating into non-zero buffers, optional gradients left out).
    for case in 0..16 {
        let (n, ci, co) = (rng.range(1, 2), rng.range(1, 9), rng.range(1, 9));
        let (ci, co) = if case == 7 { (17, 33) } else { (ci, co) };
        let (h, w) = (rng.range(1, 13), rng.range(1, 13));
        let (kh, kw) = [(3, 3), (1, 1), (5, 5), (3, 5)][case % 4];
        let pad = if case % 2 == 0 { Padding::Zero } else { Padding::Replicate };
        let x = rng.tensor(&[n, ci, h, w], -1.0, 1.0);
        let wt = rng.tensor(&[co, ci, kh, kw], -1.0, 1.0);
        let b = rng.tensor(&[co], -1.0, 1.0);
        let bias = (case % 3 != 2).then_some(&b);
        let tag = format!("conv2d {:?} w {:?} {pad:?} bias {}", x.shape, wt.shape, bias.is_some());
        let tol = 1e-5 * ((ci * kh * kw) as f32).sqrt();
        check_t(&tag, &c.conv2d(&x, &wt, bias, pad), &r.conv2d(&x, &wt, bias, pad), tol, 1e-4);
        let skip = rng.tensor(&[n, co, h, w], -1.0, 1.0);
        let epi = Epilogue { skip: (case % 2 == 0).then_some(&skip), relu: case % 3 != 0 };
        let packed = PackedConv::new(&wt);
        let (yc, yr) = (
            c.conv2d_packed(&x, &wt, &packed, bias, pad, epi),
            r.conv2d_packed(&x, &wt, &packed, bias, pad, epi),
        );
        check_t(&format!("{tag} packed {epi:?}"), &yc, &yr, tol, 1e-4);

        let dy = rng.tensor(&[n, co, h, w], -1.0, 1.0);
        let (dx0, dw0, db0) = (rng.tensor(&x.shape, -1.0, 1.0), rng.tensor(&wt.shape, -1.0, 1.0), b.clone());
        let with_dx = case % 4 != 3;
        let grads = |ops: &dyn Ops| {
            let (mut dx, mut dw, mut db) = (dx0.clone(), dw0.clone(), db0.clone());
            let (dxo, dbo) = (with_dx.then_some(&mut dx), bias.is_some().then_some(&mut db));
            ops.conv2d_backward(&x, &wt, &dy, pad, dxo, &mut dw, dbo);
            (dx, dw, db)
        };
        let ((dxc, dwc, dbc), (dxr, dwr, dbr)) = (grads(c), grads(r));
        let sum_tol = 2e-5 * ((n * h * w) as f32).sqrt();
        check_t(&format!("{tag} dx"), &dxc, &dxr, 2e-5 * ((co * kh * kw) as f32).sqrt(), 1e-4);
        check_t(&format!("{tag} dw"), &dwc, &dwr, sum_tol, 1e-4);
        check_t(&format!("{tag} db"), &dbc, &dbr, sum_tol, 1e-4);
    }

    // Element-wise ops, below and above the threading threshold (2^15 elements).
    for shape in [[1, 1, 1, 1], [2, 3, 5, 7], [1, 3, 11, 1009]] {
        let mut x = rng.tensor(&shape, -4.0, 4.0);
        x.data[0] = 0.0;
        let (dy, dx0) = (rng.tensor(&shape, -1.0, 1.0), rng.tensor(&shape, -1.0, 1.0));
        let tag = |op: &str| format!("{op} {shape:?}");
        check_t(&tag("relu"), &c.relu(&x), &r.relu(&x), 0.0, 0.0);
        check_t(&tag("sigmoid"), &c.sigmoid(&x), &r.sigmoid(&x), 0.0, 0.0);
        let (mut dxc, mut dxr) = (dx0.clone(), dx0.clone());
        c.relu_backward(&x, &dy, &mut dxc);
        r.relu_backward(&x, &dy, &mut dxr);
        check_t(&tag("relu_backward"), &dxc, &dxr, 0.0, 0.0);
        let (mut ac, mut ar) = (dx0.clone(), dx0);
        c.add_assign(&mut ac, &dy);
        r.add_assign(&mut ar, &dy);
        check_t(&tag("add_assign"), &ac, &ar, 0.0, 0.0);
    }

    // pixel_shuffle and pixel_unshuffle.
    for case in 0..6 {
        let s = 2 + case % 2;
        let (n, ch, h, w) = (rng.range(1, 2), rng.range(1, 5), rng.range(1, 7), rng.range(1, 7));
        let x = rng.tensor(&[n, ch * s * s, h, w], -1.0, 1.0);
        let tag = format!("pixel_shuffle {:?} r={s}", x.shape);
        check_t(&tag, &c.pixel_shuffle(&x, s), &r.pixel_shuffle(&x, s), 0.0, 0.0);
        let y = rng.tensor(&[n, ch, h * s, w * s], -1.0, 1.0);
        let tag = format!("pixel_unshuffle {:?} r={s}", y.shape);
        check_t(&tag, &c.pixel_unshuffle(&y, s), &r.pixel_unshuffle(&y, s), 0.0, 0.0);
    }

    // resize and resize_backward: down, up ×2 and ×3, arbitrary, to and from 1 pixel.
    for case in 0..18 {
        let mode = [Interp::Bilinear, Interp::Bicubic, Interp::CatmullRom][case % 3];
        let (n, ch, h, w) = (rng.range(1, 2), rng.range(1, 3), rng.range(1, 11), rng.range(1, 11));
        let (oh, ow) = match case / 3 {
            0 | 1 => (rng.range(1, 23), rng.range(1, 23)),
            2 | 3 => (2 * h, 2 * w),
            4 => (3 * h, 3 * w),
            _ => (1, rng.range(1, 5)),
        };
        let x = rng.tensor(&[n, ch, h, w], -1.0, 1.0);
        let tag = format!("resize {mode:?} {:?} → {oh}×{ow}", x.shape);
        check_t(&tag, &c.resize(&x, oh, ow, mode), &r.resize(&x, oh, ow, mode), 0.0, 0.0);
        let dy = rng.tensor(&[n, ch, oh, ow], -1.0, 1.0);
        let dx0 = rng.tensor(&x.shape, -1.0, 1.0);
        let (mut dxc, mut dxr) = (dx0.clone(), dx0);
        c.resize_backward(&dy, mode, &mut dxc);
        r.resize_backward(&dy, mode, &mut dxr);
        check_t(&format!("{tag} backward"), &dxc, &dxr, 1e-5, 1e-5);
    }

    // mse and bce_with_logits, below and above the threading threshold.
    for shape in [[1, 1, 1, 1], [2, 3, 5, 7], [1, 3, 11, 1009]] {
        let (p, t) = (rng.tensor(&shape, -2.0, 2.0), rng.tensor(&shape, 0.0, 1.0));
        let ((lc, gc), (lr, gr)) = (c.mse(&p, &t), r.mse(&p, &t));
        check(&format!("mse {shape:?}"), &[lc], &[lr], 0.0, 1e-5);
        check_t(&format!("mse grad {shape:?}"), &gc, &gr, 0.0, 0.0);
        let z = rng.tensor(&shape, -30.0, 30.0);
        let ((lc, gc), (lr, gr)) = (c.bce_with_logits(&z, &t, 3.5), r.bce_with_logits(&z, &t, 3.5));
        check(&format!("bce {shape:?}"), &[lc], &[lr], 0.0, 1e-5);
        check_t(&format!("bce grad {shape:?}"), &gc, &gr, 0.0, 0.0);
    }

    // The geometry losses: grids of one row or column and under 3×3 included.
    for case in 0..12 {
        let (n, ch) = (rng.range(1, 2), rng.range(1, 5));
        let (h, w) =
            if case < 3 { [(1, 9), (7, 1), (2, 2)][case] } else { (rng.range(1, 13), rng.range(1, 13)) };
        let (p, t) = (rng.tensor(&[n, ch, h, w], -1.0, 1.0), rng.tensor(&[n, ch, h, w], -1.0, 1.0));
        let tag = |op: &str| format!("{op} {:?}", p.shape);
        for (op, (lc, gc), (lr, gr)) in [
            ("edge_mse", c.edge_mse(&p, &t), r.edge_mse(&p, &t)),
            ("edge_length_mse", c.edge_length_mse(&p, &t), r.edge_length_mse(&p, &t)),
            ("laplacian_mse", c.laplacian_mse(&p, &t), r.laplacian_mse(&p, &t)),
        ] {
            check(&tag(op), &[lc], &[lr], 0.0, 1e-5);
            check_rel(&format!("{} grad", tag(op)), &gc, &gr, 1e-5);
        }
    }
    for case in 0..8 {
        let normal_only = case % 2 == 0;
        let ch = if normal_only { 3 } else { 1 + case % 3 };
        let (n, h, w) = (rng.range(1, 2), rng.range(2, 12), rng.range(2, 12));
        let (lr_h, lr_w) = (rng.range(1, h), rng.range(1, w));
        let params = DetailEnergy { radius: rng.range(0, 4), eps: 1e-4, normal_only };
        // A tilted sheet (normals defined) with detail on it; pred = target + noise.
        let mut t = rng.tensor(&[n, ch, h, w], -0.05, 0.05);
        for (i, v) in t.data.iter_mut().enumerate() {
            let (k, y, x) = ((i / (h * w)) % ch, (i / w) % h, i % w);
            *v += [x as f32 / w as f32, y as f32 / h as f32, 0.0][k];
        }
        let mut p = t.clone();
        p.data.iter_mut().for_each(|v| *v += rng.uniform_in(-0.03, 0.03));
        let tag = format!("detail_energy_mse {:?} lr {lr_h}×{lr_w} {params:?}", p.shape);
        let ((lc, gc), (lr, gr)) = (
            c.detail_energy_mse(&p, &t, lr_h, lr_w, params),
            r.detail_energy_mse(&p, &t, lr_h, lr_w, params),
        );
        check(&tag, &[lc], &[lr], 0.0, 1e-5);
        check_rel(&format!("{tag} grad"), &gc, &gr, 1e-5);
    }

    // adam_update: first and a later step, below and above the threading threshold.
    for (len, step) in [(1usize, 1u64), (1009, 7), (40_009, 2)] {
        let hp = AdamParams { lr: 1e-3, ..AdamParams::default() };
        let g = rng.tensor(&[len], -1.0, 1.0).into_data();
        let p0 = rng.tensor(&[len], -1.0, 1.0).into_data();
        let m0 = rng.tensor(&[len], -0.1, 0.1).into_data();
        let v0 = rng.tensor(&[len], 0.0, 0.1).into_data();
        let run = |ops: &dyn Ops| {
            let (mut p, mut m, mut v) = (p0.clone(), m0.clone(), v0.clone());
            ops.adam_update(&mut p, &g, &mut m, &mut v, step, &hp);
            [p, m, v]
        };
        for (k, (a, b)) in run(c).iter().zip(&run(r)).enumerate() {
            check(&format!("adam_update len {len} step {step} {}", ["p", "m", "v"][k]), a, b, 0.0, 0.0);
        }
    }
}
