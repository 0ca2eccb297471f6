//! Training throughput (samples/s: batch 32 of 16×16 LR patches → 32×32 HR, forward + backward
//! and Adam) and inference time per 32×32 → 64×64 frame, for the `small` and `paper` configs.
//!
//! `cargo bench --bench train [-- small|paper]`. Side by side with JAX/XLA and ONNX Runtime: `make bench-peers`.

use anisocb::nn::{AnisoCb, GeometryNet, NetConfig, NetKind};
use anisocb::ops::loss::DetailEnergy;
use anisocb::ops::{AdamParams, Cpu, Interp, Ops, Padding};
use anisocb::train::adam::Adam;
use anisocb::Tensor;
use std::collections::BTreeMap;
use std::sync::Mutex;
use std::time::Instant;

fn random(shape: &[usize], seed: u64) -> Tensor {
    let mut rng = anisocb::rng::Rng::new(seed);
    let mut t = Tensor::zeros(shape);
    t.data.iter_mut().for_each(|v| *v = rng.uniform());
    t
}

/// Wraps an op table and adds up the wall time of each op (`-- profile`).
struct Timed<'a> {
    inner: &'a dyn Ops,
    t: Mutex<BTreeMap<&'static str, (f64, u64)>>,
}

impl Timed<'_> {
    fn time<R>(&self, name: &'static str, f: impl FnOnce() -> R) -> R {
        let t0 = Instant::now();
        let r = f();
        let mut m = self.t.lock().unwrap();
        let e = m.entry(name).or_default();
        e.0 += t0.elapsed().as_secs_f64();
        e.1 += 1;
        r
    }
}

impl Ops for Timed<'_> {
    fn name(&self) -> &'static str {
        "timed"
    }
    fn conv2d(&self, x: &Tensor, w: &Tensor, b: Option<&Tensor>, pad: Padding) -> Tensor {
        self.time("conv2d", || self.inner.conv2d(x, w, b, pad))
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
        self.time("conv2d_backward", || self.inner.conv2d_backward(x, w, dy, pad, dx, dw, db))
    }
    fn relu(&self, x: &Tensor) -> Tensor {
        self.time("relu", || self.inner.relu(x))
    }
    fn relu_backward(&self, x: &Tensor, dy: &Tensor, dx: &mut Tensor) {
        self.time("relu_backward", || self.inner.relu_backward(x, dy, dx))
    }
    fn add_assign(&self, a: &mut Tensor, b: &Tensor) {
        self.time("add_assign", || self.inner.add_assign(a, b))
    }
    fn pixel_shuffle(&self, x: &Tensor, r: usize) -> Tensor {
        self.time("pixel_shuffle", || self.inner.pixel_shuffle(x, r))
    }
    fn pixel_unshuffle(&self, x: &Tensor, r: usize) -> Tensor {
        self.time("pixel_unshuffle", || self.inner.pixel_unshuffle(x, r))
    }
    fn resize(&self, x: &Tensor, h: usize, w: usize, m: Interp) -> Tensor {
        self.time("resize", || self.inner.resize(x, h, w, m))
    }
    fn resize_backward(&self, dy: &Tensor, m: Interp, dx: &mut Tensor) {
        self.time("resize_backward", || self.inner.resize_backward(dy, m, dx))
    }
    fn sigmoid(&self, x: &Tensor) -> Tensor {
        self.time("sigmoid", || self.inner.sigmoid(x))
    }
    fn mse(&self, p: &Tensor, t: &Tensor) -> (f32, Tensor) {
        self.time("mse", || self.inner.mse(p, t))
    }
    fn bce_with_logits(&self, z: &Tensor, t: &Tensor, w: f32) -> (f32, Tensor) {
        self.time("bce_with_logits", || self.inner.bce_with_logits(z, t, w))
    }
    fn edge_mse(&self, p: &Tensor, t: &Tensor) -> (f32, Tensor) {
        self.time("edge_mse", || self.inner.edge_mse(p, t))
    }
    fn edge_length_mse(&self, p: &Tensor, t: &Tensor) -> (f32, Tensor) {
        self.time("edge_length_mse", || self.inner.edge_length_mse(p, t))
    }
    fn laplacian_mse(&self, p: &Tensor, t: &Tensor) -> (f32, Tensor) {
        self.time("laplacian_mse", || self.inner.laplacian_mse(p, t))
    }
    fn detail_energy_mse(
        &self,
        p: &Tensor,
        t: &Tensor,
        h: usize,
        w: usize,
        d: DetailEnergy,
    ) -> (f32, Tensor) {
        self.time("detail_energy_mse", || self.inner.detail_energy_mse(p, t, h, w, d))
    }
    fn adam_update(&self, p: &mut [f32], g: &[f32], m: &mut [f32], v: &mut [f32], s: u64, hp: &AdamParams) {
        self.time("adam_update", || self.inner.adam_update(p, g, m, v, s, hp))
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let only = args.iter().find(|a| *a == "small" || *a == "paper").cloned();
    let timed = Timed { inner: &Cpu, t: Mutex::new(BTreeMap::new()) };
    let profile = args.iter().any(|a| a == "profile");
    let ops: &dyn Ops = if profile { &timed } else { &Cpu };
    println!(
        "threads: {} (rayon); the machine is shared, numbers are under load",
        rayon::current_num_threads()
    );
    for (name, cfg) in [("small", NetConfig::small()), ("paper", NetConfig::paper())] {
        if only.as_deref().is_some_and(|o| o != name) {
            continue;
        }
        let (b, p) = (32usize, 16usize);
        let mut net = GeometryNet::new(cfg, 1);
        let lr = random(&[b, 3, p, p], 2);
        let hr = random(&[b, 3, 2 * p, 2 * p], 3);
        let u = anisocb::nn::geometry_net::interpolate(ops, &lr, 2, cfg.upsample);
        let mut grads = net.trunk.zeros_like();
        let sizes: Vec<usize> = net.trunk.params().iter().map(|(_, t)| t.len()).collect();
        let mut adam = Adam::new(AdamParams::default(), &sizes);
        let mut step = |net: &mut GeometryNet| {
            grads.fill_zero();
            net.loss(ops, &lr, &u, &hr, Some(&mut grads)).unwrap();
            let gs: Vec<&[f32]> = grads.params().into_iter().map(|(_, g)| g.data.as_slice()).collect();
            let mut ps: Vec<&mut [f32]> =
                net.trunk.params_mut().into_iter().map(|p| p.data.as_mut_slice()).collect();
            adam.step(ops, &mut ps, &gs);
        };
        step(&mut net); // warm-up
        let steps = if name == "paper" { 3 } else { 8 };
        let t = Instant::now();
        for _ in 0..steps {
            step(&mut net);
        }
        let s = t.elapsed().as_secs_f64() / steps as f64;
        let flop = 3.0 * 2.0 * (cfg.macs_per_lr_pixel(NetKind::Geometry) * b * p * p) as f64;
        println!(
            "{name:>5} GeometryNet train: {:.1} samples/s ({:.1} ms/step of {b}×{p}×{p}, ≈{:.1} GFLOP/s)",
            b as f64 / s,
            s * 1e3,
            flop / s / 1e9
        );
        if profile {
            let mut m = timed.t.lock().unwrap();
            for (op, (secs, calls)) in m.iter() {
                println!(
                    "      {op:>16}: {:7.1} ms/step ({} calls)",
                    secs * 1e3 / (steps + 1) as f64,
                    calls / (steps + 1)
                );
            }
            m.clear();
        }

        let frame = random(&[1, 3, 32, 32], 4);
        let bundle = AnisoCb::new(cfg, 5);
        let reps = if name == "paper" { 5 } else { 20 };
        let _ = bundle.geometry.forward(ops, &frame).unwrap();
        let t = Instant::now();
        for _ in 0..reps {
            std::hint::black_box(bundle.geometry.forward(ops, &frame).unwrap());
        }
        let g_ms = t.elapsed().as_secs_f64() * 1e3 / reps as f64;
        let t = Instant::now();
        for _ in 0..reps {
            std::hint::black_box(bundle.forward(ops, &frame).unwrap());
        }
        let all_ms = t.elapsed().as_secs_f64() * 1e3 / reps as f64;
        println!("{name:>5} inference 32×32 → 64×64: GeometryNet {g_ms:.2} ms/frame, all three nets {all_ms:.2} ms/frame");
    }
}
