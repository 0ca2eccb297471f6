//! Audit of every engine op against references written by JAX/optax
//! (tests/fixtures/gen_ops.py → tests/fixtures/ops/*.npy; versions in VERSIONS.txt).
//!
//! Each op is checked through two op tables: `RefOps` (the scalar `*_ref` specs) and `Cpu`
//! (the fast kernels). A check passes when |got − want| ≤ atol + rtol·|want| everywhere; on
//! failure it prints the first mismatches and the largest difference.
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

use anisocb::io::read_npy;
use anisocb::ops::{
    activation, adam, conv2d, loss, pixel_shuffle, resample, AdamParams, Cpu, Interp, Ops, Padding,
};
use anisocb::train::adam::Adam;
use anisocb::Tensor;
use std::path::PathBuf;

/// The op table of the scalar references.
struct RefOps;

impl Ops for RefOps {
    fn name(&self) -> &'static str {
        "ref"
    }
    fn conv2d(&self, x: &Tensor, w: &Tensor, b: Option<&Tensor>, pad: Padding) -> Tensor {
        conv2d::conv2d_ref(x, w, b, pad)
    }
    fn conv2d_backward(
        &self,
        x: &Tensor,
        w: &Tensor,
        dy: &Tensor,
        pad: Padding,
        dx: Option<&mut Tensor>,
        dw: &mut Tensor,
        db: Option<&mut Tensor>,
    ) {
        conv2d::conv2d_backward_ref(x, w, dy, pad, dx, dw, db)
    }
    fn relu(&self, x: &Tensor) -> Tensor {
        activation::relu_ref(x)
    }
    fn relu_backward(&self, x: &Tensor, dy: &Tensor, dx: &mut Tensor) {
        activation::relu_backward_ref(x, dy, dx)
    }
    fn add_assign(&self, a: &mut Tensor, b: &Tensor) {
        activation::add_assign_ref(a, b)
    }
    fn pixel_shuffle(&self, x: &Tensor, r: usize) -> Tensor {
        pixel_shuffle::pixel_shuffle_ref(x, r)
    }
    fn pixel_unshuffle(&self, x: &Tensor, r: usize) -> Tensor {
        pixel_shuffle::pixel_unshuffle_ref(x, r)
    }
    fn resize(&self, x: &Tensor, out_h: usize, out_w: usize, mode: Interp) -> Tensor {
        resample::resize_ref(x, out_h, out_w, mode)
    }
    fn resize_backward(&self, dy: &Tensor, mode: Interp, dx: &mut Tensor) {
        resample::resize_backward_ref(dy, mode, dx)
    }
    fn sigmoid(&self, x: &Tensor) -> Tensor {
        activation::sigmoid_ref(x)
    }
    fn mse(&self, pred: &Tensor, target: &Tensor) -> (f32, Tensor) {
        loss::mse_ref(pred, target)
    }
    fn bce_with_logits(&self, logits: &Tensor, target: &Tensor, pos_weight: f32) -> (f32, Tensor) {
        loss::bce_with_logits_ref(logits, target, pos_weight)
    }
    fn adam_update(
        &self,
        p: &mut [f32],
        g: &[f32],
        m: &mut [f32],
        v: &mut [f32],
        step: u64,
        hp: &AdamParams,
    ) {
        adam::adam_update_ref(p, g, m, v, step, hp)
    }
}

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
