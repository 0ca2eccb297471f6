//! Training throughput (samples/s: batch 32 of 16×16 LR patches → 32×32 HR, forward + backward
//! and Adam) and inference time per 32×32 → 64×64 frame, for the `small` and `paper` configs.
//!
//! `cargo bench --bench train [-- small|paper]`. Compare with JAX/XLA: `python3 benches/train_jax.py`.

use anisocb::nn::{AnisoCb, GeometryNet, NetConfig, NetKind};
use anisocb::ops::{AdamParams, Cpu, Ops};
use anisocb::train::adam::Adam;
use anisocb::Tensor;
use std::time::Instant;

fn random(shape: &[usize], seed: u64) -> Tensor {
    let mut rng = anisocb::nn::Rng::new(seed);
    let mut t = Tensor::zeros(shape);
    t.data.iter_mut().for_each(|v| *v = rng.uniform());
    t
}

fn main() {
    let only: Option<String> = std::env::args().skip(1).find(|a| a == "small" || a == "paper");
    let ops: &dyn Ops = &Cpu;
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
        let u = anisocb::nn::geometry_net::interpolate(ops, &lr, 2);
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
