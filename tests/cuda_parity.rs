//! Parity of the CUDA op table with the CPU engine: every op on random odd shapes, a small
//! network's forward + backward, and 10 Adam steps of training. Compiled in every build; on a
//! machine without the `cuda` feature, a driver or a GPU each test prints
//! "skipped: no CUDA device (...)" and passes. The same checks also run with the CPU op table
//! standing in for the device, so the harness itself (shapes, tolerances) is always exercised.

#[path = "common/close.rs"]
mod close;
use anisocb::rng::Rng;
use close::{assert_close, assert_close_f32};
#[path = "common/random.rs"]
mod random;
use anisocb::cuda::{ops_for_device, DeviceTrainer, MirrorView, StepLoss};
use anisocb::geom::cloth_frame::{mirror_net_images, mirrored_axes, InputFrame, GRID_MIRRORS};
use anisocb::nn::geometry_net::{estimate_loss, geometry_loss, GeometryLoss};
use anisocb::nn::map_net::map_loss;
use anisocb::nn::{AnisoCb, NetConfig, NetKind, Trunk};
use anisocb::ops::conv2d::{conv2d_backward_ref, conv2d_ref};
use anisocb::ops::loss::DetailEnergy;
use anisocb::ops::{AdamParams, Cpu, Interp, Ops, Padding};
use anisocb::train::adam::Adam;
use anisocb::{Error, Tensor};
use random::TestData;

/// The device under test, or None (and the skip line) where there is none.
fn device() -> Option<Box<dyn Ops>> {
    match ops_for_device("cuda") {
        Ok(ops) => Some(ops),
        Err(e) => {
            println!("skipped: no CUDA device ({e})");
            None
        }
    }
}

// ---------------------------------------------------------------- the checks, device-agnostic

fn check_conv2d(dev: &dyn Ops) {
    let mut rng = Rng::new(0x5eed_c0de);
    for case in 0..12 {
        let (n, c, o) = (rng.range(1, 3), rng.range(1, 9), rng.range(1, 9));
        let (h, w) = (rng.range(1, 13), rng.range(1, 13));
        let (kh, kw) =
            if case % 4 == 3 { (2 * rng.range(0, 2) + 1, 2 * rng.range(0, 2) + 1) } else { (3, 3) };
        // One wide case crosses the 64-channel tile edge.
        let (c, o) = if case == 5 { (67, 70) } else { (c, o) };
        let pad = if case % 2 == 0 { Padding::Zero } else { Padding::Replicate };
        let x = rng.tensor(&[n, c, h, w], -1.0, 1.0);
        let wt = rng.tensor(&[o, c, kh, kw], -0.5, 0.5);
        let b = rng.tensor(&[o], -0.5, 0.5);
        let tag = format!("conv2d {:?} w {:?} {pad:?}", x.shape, wt.shape);
        let bias = if case % 3 == 2 { None } else { Some(&b) };
        assert_close(&tag, &dev.conv2d(&x, &wt, bias, pad), &conv2d_ref(&x, &wt, bias, pad), 1e-4, 1e-4);

        let dy = rng.tensor(&[n, o, h, w], -1.0, 1.0);
        let (mut dx, mut dw, mut db) =
            (rng.tensor(&x.shape, -1.0, 1.0), rng.tensor(&wt.shape, -1.0, 1.0), rng.tensor(&[o], -1.0, 1.0));
        let (mut rdx, mut rdw, mut rdb) = (dx.clone(), dw.clone(), db.clone());
        dev.conv2d_backward(&x, &wt, &dy, pad, Some(&mut dx), &mut dw, Some(&mut db));
        conv2d_backward_ref(&x, &wt, &dy, pad, Some(&mut rdx), &mut rdw, Some(&mut rdb));
        assert_close(&format!("{tag} dx"), &dx, &rdx, 1e-4, 1e-4);
        assert_close(&format!("{tag} dw"), &dw, &rdw, 2e-4, 1e-4);
        assert_close(&format!("{tag} db"), &db, &rdb, 1e-4, 1e-4);

        // Optional gradients left out.
        let mut dw2 = Tensor::zeros(&wt.shape);
        let mut rdw2 = dw2.clone();
        dev.conv2d_backward(&x, &wt, &dy, pad, None, &mut dw2, None);
        conv2d_backward_ref(&x, &wt, &dy, pad, None, &mut rdw2, None);
        assert_close(&format!("{tag} dw only"), &dw2, &rdw2, 2e-4, 1e-4);
    }
}

fn check_elementwise(dev: &dyn Ops) {
    let mut rng = Rng::new(11);
    for len in [1usize, 7, 255, 257, 4099] {
        let shape = [1, 1, 1, len];
        let mut x = rng.tensor(&shape, -3.0, 3.0);
        x.data[0] = 0.0;
        assert_close(&format!("relu {len}"), &dev.relu(&x), &Cpu.relu(&x), 0.0, 0.0);
        let dy = rng.tensor(&shape, -1.0, 1.0);
        let mut a = rng.tensor(&shape, -1.0, 1.0);
        let mut b = a.clone();
        dev.relu_backward(&x, &dy, &mut a);
        Cpu.relu_backward(&x, &dy, &mut b);
        assert_close(&format!("relu_backward {len}"), &a, &b, 0.0, 0.0);
        let mut a = rng.tensor(&shape, -1.0, 1.0);
        let mut b = a.clone();
        dev.add_assign(&mut a, &dy);
        Cpu.add_assign(&mut b, &dy);
        assert_close(&format!("add_assign {len}"), &a, &b, 0.0, 0.0);
        let z = rng.tensor(&shape, -40.0, 40.0);
        assert_close(&format!("sigmoid {len}"), &dev.sigmoid(&z), &Cpu.sigmoid(&z), 1e-7, 1e-6);
    }
}

fn check_pixel_shuffle(dev: &dyn Ops) {
    let mut rng = Rng::new(12);
    for _ in 0..6 {
        let (n, c, h, w, r) =
            (rng.range(1, 2), rng.range(1, 5), rng.range(1, 7), rng.range(1, 7), rng.range(1, 3));
        let x = rng.tensor(&[n, c * r * r, h, w], -1.0, 1.0);
        let y = dev.pixel_shuffle(&x, r);
        assert_close(&format!("pixel_shuffle {:?} r={r}", x.shape), &y, &Cpu.pixel_shuffle(&x, r), 0.0, 0.0);
        assert_close(
            &format!("pixel_unshuffle {:?} r={r}", y.shape),
            &dev.pixel_unshuffle(&y, r),
            &x,
            0.0,
            0.0,
        );
    }
}

fn check_resize(dev: &dyn Ops) {
    let mut rng = Rng::new(13);
    for case in 0..12 {
        let mode = [Interp::Bilinear, Interp::Bicubic, Interp::CatmullRom][case % 3];
        let (n, c, h, w) = (rng.range(1, 2), rng.range(1, 3), rng.range(1, 11), rng.range(1, 11));
        let (oh, ow) = if case % 4 == 0 { (rng.range(1, 23), rng.range(1, 23)) } else { (2 * h, 2 * w) };
        let x = rng.tensor(&[n, c, h, w], -1.0, 1.0);
        let tag = format!("resize {mode:?} {:?} -> {oh}x{ow}", x.shape);
        assert_close(&tag, &dev.resize(&x, oh, ow, mode), &Cpu.resize(&x, oh, ow, mode), 1e-6, 1e-5);
        let dy = rng.tensor(&[n, c, oh, ow], -1.0, 1.0);
        let mut a = rng.tensor(&x.shape, -1.0, 1.0);
        let mut b = a.clone();
        dev.resize_backward(&dy, mode, &mut a);
        Cpu.resize_backward(&dy, mode, &mut b);
        assert_close(&format!("{tag} backward"), &a, &b, 1e-5, 1e-5);
    }
}

fn check_losses(dev: &dyn Ops) {
    let mut rng = Rng::new(14);
    for len in [1usize, 300, 5001] {
        let shape = [1, 1, 1, len];
        let (p, t) = (rng.tensor(&shape, -1.0, 1.0), rng.tensor(&shape, -1.0, 1.0));
        let ((lg, gg), (lc, gc)) = (dev.mse(&p, &t), Cpu.mse(&p, &t));
        assert_close_f32(&format!("mse loss {len}"), lg, lc, 1e-7, 1e-5);
        assert_close(&format!("mse grad {len}"), &gg, &gc, 1e-9, 1e-6);
        let z = rng.tensor(&shape, -30.0, 30.0);
        let mut tt = rng.tensor(&shape, 0.0, 1.0);
        for v in tt.data.iter_mut().skip(len / 2) {
            *v = (*v > 0.8) as u8 as f32;
        }
        let ((lg, gg), (lc, gc)) = (dev.bce_with_logits(&z, &tt, 3.5), Cpu.bce_with_logits(&z, &tt, 3.5));
        assert_close_f32(&format!("bce loss {len}"), lg, lc, 1e-6, 1e-5);
        assert_close(&format!("bce grad {len}"), &gg, &gc, 1e-8, 1e-5);
    }
}

/// The geometry losses (GeometryNet's extra terms) have no kernels: the table computes them on
/// the host with the CPU table's code, so the same bits.
fn check_geometry_losses(dev: &dyn Ops) {
    let mut rng = Rng::new(17);
    for (n, c, h, w) in [(1, 3, 1, 5), (2, 3, 7, 9), (1, 2, 12, 11)] {
        let (p, t) = (rng.tensor(&[n, c, h, w], -1.0, 1.0), rng.tensor(&[n, c, h, w], -1.0, 1.0));
        let tag = |op: &str| format!("{op} {:?}", p.shape);
        for (op, (lg, gg), (lc, gc)) in [
            ("edge_mse", dev.edge_mse(&p, &t), Cpu.edge_mse(&p, &t)),
            ("edge_length_mse", dev.edge_length_mse(&p, &t), Cpu.edge_length_mse(&p, &t)),
            ("laplacian_mse", dev.laplacian_mse(&p, &t), Cpu.laplacian_mse(&p, &t)),
        ] {
            assert_close_f32(&tag(op), lg, lc, 0.0, 0.0);
            assert_close(&format!("{} grad", tag(op)), &gg, &gc, 0.0, 0.0);
        }
        let d = DetailEnergy { normal_only: c == 3, ..DetailEnergy::default() };
        let ((lg, gg), (lc, gc)) = (
            dev.detail_energy_mse(&p, &t, h.div_ceil(2), w.div_ceil(2), d),
            Cpu.detail_energy_mse(&p, &t, h.div_ceil(2), w.div_ceil(2), d),
        );
        assert_close_f32(&tag("detail_energy_mse"), lg, lc, 0.0, 0.0);
        assert_close(&format!("{} grad", tag("detail_energy_mse")), &gg, &gc, 0.0, 0.0);
    }
}

// ------------------------------------------------- a small network, forward and backward

/// conv_in (3→C) → relu → conv (C→C) → + skip → conv (C→4·3) → pixel shuffle ×2 → + bicubic ×2
/// of the input; MSE against a target. A miniature GeometryNet touching every op but the BCE.
struct Net {
    w: Vec<Tensor>,
    b: Vec<Tensor>,
}

const WIDTH: usize = 6;

impl Net {
    fn new(rng: &mut Rng) -> Net {
        let shapes = [[WIDTH, 3, 3, 3], [WIDTH, WIDTH, 3, 3], [12, WIDTH, 3, 3]];
        let w = shapes.iter().map(|s| rng.tensor(s, -0.3, 0.3)).collect();
        let b = shapes.iter().map(|s| rng.tensor(&[s[0]], -0.1, 0.1)).collect();
        Net { w, b }
    }

    /// (loss, output, gradients of w and b).
    fn step(&self, ops: &dyn Ops, x: &Tensor, target: &Tensor) -> (f32, Tensor, Vec<Tensor>, Vec<Tensor>) {
        let (_, _, h, w) = x.dims4();
        let pad = Padding::Replicate;
        let a0 = ops.conv2d(x, &self.w[0], Some(&self.b[0]), pad);
        let r0 = ops.relu(&a0);
        let mut a1 = ops.conv2d(&r0, &self.w[1], Some(&self.b[1]), pad);
        ops.add_assign(&mut a1, &r0);
        let a2 = ops.conv2d(&a1, &self.w[2], Some(&self.b[2]), Padding::Zero);
        let mut y = ops.pixel_shuffle(&a2, 2);
        let u = ops.resize(x, 2 * h, 2 * w, Interp::Bicubic);
        ops.add_assign(&mut y, &u);
        let (loss, dy) = ops.mse(&y, target);

        let mut dw: Vec<Tensor> = self.w.iter().map(|t| Tensor::zeros(&t.shape)).collect();
        let mut db: Vec<Tensor> = self.b.iter().map(|t| Tensor::zeros(&t.shape)).collect();
        let da2 = ops.pixel_unshuffle(&dy, 2);
        let mut da1 = Tensor::zeros(&a1.shape);
        ops.conv2d_backward(
            &a1,
            &self.w[2],
            &da2,
            Padding::Zero,
            Some(&mut da1),
            &mut dw[2],
            Some(&mut db[2]),
        );
        let mut dr0 = da1.clone(); // the skip
        ops.conv2d_backward(&r0, &self.w[1], &da1, pad, Some(&mut dr0), &mut dw[1], Some(&mut db[1]));
        let mut da0 = Tensor::zeros(&a0.shape);
        ops.relu_backward(&a0, &dr0, &mut da0);
        let mut dx = Tensor::zeros(&x.shape);
        ops.conv2d_backward(x, &self.w[0], &da0, pad, Some(&mut dx), &mut dw[0], Some(&mut db[0]));
        ops.resize_backward(&dy, Interp::Bicubic, &mut dx); // exercised, then unused
        (loss, y, dw, db)
    }
}

fn check_network(dev: &dyn Ops) {
    let mut rng = Rng::new(15);
    let net = Net::new(&mut rng);
    let x = rng.tensor(&[2, 3, 7, 9], 0.0, 1.0);
    let target = rng.tensor(&[2, 3, 14, 18], 0.0, 1.0);
    let (lg, yg, dwg, dbg) = net.step(dev, &x, &target);
    let (lc, yc, dwc, dbc) = net.step(&Cpu, &x, &target);
    assert_close_f32("network loss", lg, lc, 1e-6, 1e-4);
    assert_close("network output", &yg, &yc, 1e-4, 1e-4);
    for i in 0..3 {
        assert_close(&format!("network dw{i}"), &dwg[i], &dwc[i], 1e-5, 1e-3);
        assert_close(&format!("network db{i}"), &dbg[i], &dbc[i], 1e-5, 1e-3);
    }
}

fn check_adam_training(dev: &dyn Ops) {
    let mut rng = Rng::new(16);
    let net0 = Net::new(&mut rng);
    let x = rng.tensor(&[2, 3, 5, 6], 0.0, 1.0);
    let target = rng.tensor(&[2, 3, 10, 12], 0.0, 1.0);
    let hp = AdamParams { lr: 1e-3, ..Default::default() };
    let train = |ops: &dyn Ops| {
        let mut net = Net { w: net0.w.clone(), b: net0.b.clone() };
        let mut mom: Vec<(Vec<f32>, Vec<f32>)> =
            net.w.iter().chain(&net.b).map(|t| (vec![0.0; t.len()], vec![0.0; t.len()])).collect();
        let mut losses = Vec::new();
        for step in 1..=10u64 {
            let (loss, _, dw, db) = net.step(ops, &x, &target);
            losses.push(loss);
            let params = net.w.iter_mut().chain(net.b.iter_mut());
            for ((p, g), (m, v)) in params.zip(dw.iter().chain(&db)).zip(mom.iter_mut()) {
                ops.adam_update(&mut p.data, &g.data, m, v, step, &hp);
            }
        }
        (net, losses)
    };
    let (ng, lg) = train(dev);
    let (nc, lc) = train(&Cpu);
    for (i, (a, b)) in lg.iter().zip(&lc).enumerate() {
        assert_close_f32(&format!("training loss step {}", i + 1), *a, *b, 1e-6, 1e-3);
    }
    assert!(lc[9] < lc[0], "10 Adam steps should lower the loss: {lc:?}");
    for i in 0..3 {
        assert_close(&format!("trained w{i}"), &ng.w[i], &nc.w[i], 1e-5, 1e-3);
        assert_close(&format!("trained b{i}"), &ng.b[i], &nc.b[i], 1e-5, 1e-3);
    }
}

// ---------------------------------------------------------------- the tests

#[test]
fn cuda_request_without_gpu_is_a_readable_error_not_a_panic() {
    match ops_for_device("cuda") {
        Ok(ops) => assert_eq!(ops.name(), "cuda"),
        Err(e) => {
            let msg = e.to_string();
            println!("--device cuda here: {msg}");
            assert!(matches!(e, Error::Device(_)), "expected a device error, got {msg}");
            assert!(
                msg.contains("cuda") || msg.contains("CUDA"),
                "the message should say what is missing: {msg}"
            );
        }
    }
    assert_eq!(ops_for_device("cpu").expect("cpu always works").name(), "cpu");
}

#[test]
fn parity_harness_self_check_with_cpu_as_device() {
    // The same checks with the CPU standing in for the GPU: guards the harness itself.
    check_conv2d(&Cpu);
    check_elementwise(&Cpu);
    check_pixel_shuffle(&Cpu);
    check_resize(&Cpu);
    check_losses(&Cpu);
    check_geometry_losses(&Cpu);
    check_network(&Cpu);
    check_adam_training(&Cpu);
}

#[test]
fn cuda_conv2d_matches_cpu_reference() {
    if let Some(dev) = device() {
        check_conv2d(dev.as_ref());
    }
}

#[test]
fn cuda_elementwise_ops_match_cpu() {
    if let Some(dev) = device() {
        check_elementwise(dev.as_ref());
    }
}

#[test]
fn cuda_pixel_shuffle_matches_cpu() {
    if let Some(dev) = device() {
        check_pixel_shuffle(dev.as_ref());
    }
}

#[test]
fn cuda_resize_matches_cpu() {
    if let Some(dev) = device() {
        check_resize(dev.as_ref());
    }
}

#[test]
fn cuda_losses_match_cpu() {
    if let Some(dev) = device() {
        check_losses(dev.as_ref());
    }
}

#[test]
fn cuda_geometry_losses_are_the_cpu_bits() {
    if let Some(dev) = device() {
        check_geometry_losses(dev.as_ref());
    }
}

#[test]
fn cuda_network_forward_backward_matches_cpu() {
    if let Some(dev) = device() {
        check_network(dev.as_ref());
    }
}

#[test]
fn cuda_ten_adam_steps_match_cpu() {
    if let Some(dev) = device() {
        check_adam_training(dev.as_ref());
    }
}

// ------------------------------------------- the whole bundle on the device (kernels/infer.cu)

/// CPU reference of [`anisocb::cuda::nets_views`]: each view through `forward_with`, its
/// outputs mirrored back and averaged, as `sr::upscale` does op by op.
fn nets_views_cpu(model: &AnisoCb, x: &Tensor, views: &[MirrorView], enhance: bool) -> [Tensor; 4] {
    let frame = model.input_frame();
    let mut acc: Option<[Tensor; 4]> = None;
    for v in views {
        let o =
            model.forward_with(&Cpu, &mirror_net_images(x, v.rows, v.cols, frame, true), enhance).unwrap();
        let back = [
            o.interpolated.clone(),
            mirror_net_images(&o.residual, v.rows, v.cols, frame, false),
            o.boundary.flipped(v.rows, v.cols),
            o.enhance.flipped(v.rows, v.cols),
        ];
        match acc.as_mut() {
            None => acc = Some(back),
            Some(a) => {
                for (a, b) in a.iter_mut().skip(1).zip(&back[1..]) {
                    a.data.iter_mut().zip(&b.data).for_each(|(s, t)| *s += t);
                }
            }
        }
    }
    let mut a = acc.expect("one view at least");
    for t in a.iter_mut().skip(1) {
        t.data.iter_mut().for_each(|s| *s /= views.len() as f32);
    }
    a
}

/// Every net and mirror view at once on the device (fp16 operands, fp32 accumulation) against
/// the CPU's fp32 forward of each view: bundles of the shipped shape and of channel counts the
/// kernels pad (8 → 16), an ensemble of two GeometryNets, both paddings, odd sizes, one view
/// and four. Tolerance: fp16 keeps 11 significant bits, so each output may differ by about
/// 2⁻¹¹ of the activations' size per layer; 1e-2 of the output's own range over ~14 layers.
#[test]
fn cuda_whole_bundle_on_the_device_matches_cpu() {
    let Some(dev) = device() else { return };
    let mut rng = Rng::new(0xb0_d1e5);
    let cases = [
        (32, 4, Padding::Replicate, 16, 16, 3, true, 4),
        (8, 1, Padding::Zero, 7, 13, 2, false, 1),
        (32, 2, Padding::Replicate, 9, 5, 1, true, 4),
    ];
    for (channels, blocks, padding, h, w, n, ensemble, nv) in cases {
        let cfg = NetConfig {
            channels,
            blocks,
            padding,
            input_frame: InputFrame::Cloth,
            upsample: Interp::CatmullRom,
            ..NetConfig::small()
        };
        let mut model = AnisoCb::new(cfg, rng.range(0, 1000) as u64);
        if ensemble {
            model = model.with_more_geometry(vec![Trunk::init(NetKind::Geometry, cfg, 77)]).unwrap();
        }
        let x = rng.tensor(&[n, 3, h, w], 0.0, 1.0);
        let views: Vec<MirrorView> = GRID_MIRRORS[..nv]
            .iter()
            .map(|&(rows, cols)| MirrorView { rows, cols, axes: mirrored_axes(rows, cols) })
            .collect();
        let Some(got) = anisocb::cuda::nets_views(dev.as_ref(), &model.packed(), &x, &views, true) else {
            println!("skipped: this GPU has no tensor-core path");
            return;
        };
        assert!(dev.take_error().is_none(), "a driver failure in nets_views");
        let want = nets_views_cpu(&model, &x, &views, true);
        let tag = format!("C={channels} blocks={blocks} {padding:?} {n}x{h}x{w} views {nv}");
        let range = |t: &Tensor| t.data.iter().fold(0f32, |m, v| m.max(v.abs()));
        assert_close(&format!("{tag} U"), &got.interpolated, &want[0], 1e-6, 1e-5);
        for (name, g, wt) in
            [("R", &got.residual, &want[1]), ("Γb", &got.boundary, &want[2]), ("Γe", &got.enhance, &want[3])]
        {
            assert_close(&format!("{tag} {name}"), g, wt, 1e-2 * range(wt).max(1e-3), 0.0);
        }
    }
}

// ------------------------------------------------------ device-resident training (cuda::train)

/// GeometryNet's loss on the device (`kernels/loss.cu` geometry_loss: MSE + edge-vector +
/// edge-length terms) against [`estimate_loss`] on the CPU: the gradient bit for bit (the kernel
/// gathers each term in the order the CPU scatters it), the loss to the rounding of its f64
/// sums' order; shapes one pixel wide or tall, edges of zero length in the prediction, terms
/// of weight 0. The Laplacian and wrinkle-energy terms have no kernel: `None`.
#[test]
fn cuda_geometry_loss_kernel_gives_the_cpus_gradient_bits() {
    let Some(dev) = device() else { return };
    let Some(cuda) = dev.as_cuda() else { return };
    let mut rng = Rng::new(0x6e0);
    let weights = [
        GeometryLoss::default(),
        GeometryLoss { edge: 1.0, ..GeometryLoss::default() },
        GeometryLoss { edge: 1.0, length: 4.0, ..GeometryLoss::default() },
        GeometryLoss { length: 2.0, ..GeometryLoss::default() },
    ];
    for shape in [[2, 3, 5, 7], [1, 3, 1, 6], [3, 3, 4, 1], [32, 3, 32, 32], [1, 2, 9, 8]] {
        let (mut p, t) = (rng.tensor(&shape, -1.0, 1.0), rng.tensor(&shape, -1.0, 1.0));
        let plane = shape[2] * shape[3];
        for ch in 0..shape[1] {
            p.data[ch * plane] = 0.25; // the first two pixels coincide: an edge of zero length
            p.data[ch * plane + 1] = 0.25;
        }
        for w in weights {
            let tag = format!("{shape:?} {w:?}");
            let (lg, gg) = cuda.geometry_loss(&p, &t, w).expect("a kernel for these terms");
            assert!(dev.take_error().is_none(), "a driver failure");
            let (lc, gc) = estimate_loss(&Cpu, &p, &t, (shape[2].div_ceil(2), shape[3].div_ceil(2)), w);
            assert_close_f32(&format!("{tag} loss"), lg, lc, 1e-9, 1e-6);
            let bits = |t: &Tensor| t.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert!(bits(&gg) == bits(&gc), "{tag}: the gradient differs from the CPU's bits");
        }
        let lap = GeometryLoss { laplacian: 1.0, ..GeometryLoss::default() };
        assert!(cuda.geometry_loss(&p, &t, lap).is_none(), "no kernel for the Laplacian");
    }
}

/// Ten steps of the device-resident trainer (the trunk, its gradients and Adam's moments kept
/// on the GPU) against the CPU's op-by-op steps: GeometryNet with the paper's MSE, GeometryNet
/// with the edge and edge-length terms (on the device), GeometryNet with a Laplacian term
/// (computed on the host from the downloaded estimate), and BoundaryNet's BCE; the losses of every step, a validation loss (forward only), then the weights and
/// moments it stores back. Tolerances as
/// the op table's training parity above (fp32 on both sides, different summation orders).
#[test]
fn cuda_device_resident_training_matches_cpu() {
    let Some(dev) = device() else { return };
    let Some(cuda) = dev.as_cuda() else { return };
    let mut rng = Rng::new(0x7a12);
    let edges = GeometryLoss { edge: 0.5, length: 4.0, ..GeometryLoss::default() };
    let laplacian = GeometryLoss { edge: 0.5, laplacian: 0.25, ..GeometryLoss::default() };
    let cases = [
        (NetKind::Geometry, StepLoss::Geometry(GeometryLoss::default())),
        (NetKind::Geometry, StepLoss::Geometry(edges)),
        (NetKind::Geometry, StepLoss::Geometry(laplacian)),
        (NetKind::Boundary, StepLoss::Map { pos_weight: 2.0 }),
    ];
    for (kind, loss) in cases {
        let cfg = NetConfig { channels: 8, blocks: 2, padding: Padding::Replicate, ..NetConfig::small() };
        let mut host = Trunk::init(kind, cfg, 5);
        let sizes: Vec<usize> = host.params().iter().map(|(_, t)| t.len()).collect();
        let mut host_adam = Adam::new(AdamParams { lr: 1e-3, ..AdamParams::default() }, &sizes);
        let mut dt = DeviceTrainer::new(cuda, &host, &host_adam).expect("upload");
        let oc = kind.out_channels();
        for step in 0..10 {
            let lr = rng.tensor(&[3, 3, 7, 9], 0.0, 1.0);
            let u = rng.tensor(&[3, oc, 14, 18], 0.0, 1.0);
            let t = rng.tensor(&[3, oc, 14, 18], 0.0, 1.0);
            let got = dt.step(&lr, &u, &t, loss);
            assert!(dev.take_error().is_none(), "a driver failure in the training step");
            let mut g = host.zeros_like();
            let want = match loss {
                StepLoss::Geometry(w) => geometry_loss(&Cpu, &host, &lr, &u, &t, w, Some(&mut g)),
                StepLoss::Map { pos_weight } => map_loss(&Cpu, &host, &lr, &t, pos_weight, Some(&mut g)),
            }
            .unwrap();
            let gs: Vec<&[f32]> = g.params().into_iter().map(|(_, g)| g.data.as_slice()).collect();
            let mut ps: Vec<&mut [f32]> =
                host.params_mut().into_iter().map(|p| p.data.as_mut_slice()).collect();
            host_adam.step(&Cpu, &mut ps, &gs);
            assert_close_f32(&format!("{kind:?} {loss:?} loss step {}", step + 1), got, want, 1e-5, 1e-4);
        }
        // The validation loss of the trained weights, forward only.
        let (lr, u, t) = (
            rng.tensor(&[2, 3, 5, 6], 0.0, 1.0),
            rng.tensor(&[2, oc, 10, 12], 0.0, 1.0),
            rng.tensor(&[2, oc, 10, 12], 0.0, 1.0),
        );
        let want = match loss {
            StepLoss::Geometry(w) => geometry_loss(&Cpu, &host, &lr, &u, &t, w, None),
            StepLoss::Map { pos_weight } => map_loss(&Cpu, &host, &lr, &t, pos_weight, None),
        }
        .unwrap();
        assert_close_f32(
            &format!("{kind:?} {loss:?} validation loss"),
            dt.loss(&lr, &u, &t, loss),
            want,
            1e-5,
            1e-4,
        );
        let (mut stored, mut stored_adam) = (host.zeros_like(), host_adam.clone());
        dt.store(&mut stored, &mut stored_adam).expect("download");
        for ((name, a), (_, b)) in stored.params().into_iter().zip(host.params()) {
            assert_close(&format!("{kind:?} {loss:?} trained {name}"), a, b, 1e-5, 1e-3);
        }
        assert_eq!(stored_adam.step, host_adam.step, "Adam's step count");
        for (a, b) in stored_adam.m.iter().zip(&host_adam.m) {
            close::assert_close_slice(&format!("{kind:?} Adam m"), a, b, 1e-6, 1e-3);
        }
    }
}

/// `--precision`: auto is bf16 on a CPU with AMX tiles, else fp32, and fp16 on a GPU with
/// tensor cores; fp16 on the CPU
/// is refused saying where it runs; fp32 on the GPU turns the tensor-core path off.
#[test]
fn precision_resolves_per_device_and_fp32_turns_the_tensor_cores_off() {
    use anisocb::pipeline::job::Precision;
    assert_eq!(Precision::resolve("auto", &Cpu).unwrap(), Precision::fastest_cpu());
    assert_eq!(Precision::resolve("fp32", &Cpu).unwrap(), Precision::Fp32);
    let e = Precision::resolve("fp16", &Cpu).unwrap_err();
    assert!(
        matches!(e, Error::Invalid { field: "precision", .. }) && e.to_string().contains("--device cuda"),
        "{e}"
    );
    assert!(Precision::resolve("fp8", &Cpu).is_err());
    let Some(dev) = device() else { return };
    let cuda = dev.as_cuda().expect("the cuda table");
    if cuda.tensor_cores().is_err() {
        println!("skipped: this GPU has no tensor-core path");
        return;
    }
    let model = AnisoCb::new(NetConfig { channels: 8, blocks: 1, ..NetConfig::small() }, 3);
    let x = Rng::new(5).tensor(&[1, 3, 6, 6], 0.0, 1.0);
    let view = [MirrorView { rows: false, cols: false, axes: [false; 3] }];
    assert_eq!(Precision::resolve("auto", dev.as_ref()).unwrap(), Precision::Fp16);
    assert!(anisocb::cuda::nets_views(dev.as_ref(), &model.packed(), &x, &view, true).is_some());
    assert_eq!(Precision::resolve("fp32", dev.as_ref()).unwrap(), Precision::Fp32);
    assert!(anisocb::cuda::nets_views(dev.as_ref(), &model.packed(), &x, &view, true).is_none());
    cuda.use_tensor_cores(true);
}
