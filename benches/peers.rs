//! anisocb's side of `make bench-peers` (benches/peers/run.py): the rows that
//! benches/peers/ort_bench.py (ONNX Runtime), benches/peers/ov_bench.py (OpenVINO, nets only) and
//! benches/peers/jax_bench.py (JAX/XLA) time
//! too, same shapes, same work, one JSON line per row: `{"row": NAME, "ms": MEDIAN}`.
//!
//! `cargo bench --bench peers [-- conv|nets|train ...]` (no argument: every group).
//! Rows (names shared with the peer scripts, see benches/peers/rows.py):
//!   peak   this machine's fp32 FMA peak (`anisocb::perf::fma_peak_gflops`, all threads):
//!          `{"row": "fma peak", "gflops": G}`; ort_bench.py's MLAS SGEMM is the cross-check
//!   conv   3×3 conv forward, zero padding, with bias, N×C×H×W → N×O×H×W (weights packed once,
//!          the call entered into the op table)
//!   nets   the three nets (GeometryNet, BoundaryNet, EnhanceNet) on one 32×32 and one 64×64
//!          frame, small and paper configs (weights random: time does not depend on their
//!          values), in fp32 and at the default precision (`upscale --precision auto`: bf16 on
//!          AMX tiles where the CPU has them), each line naming the precision that ran
//!   train  one GeometryNet training step (forward, backward, Adam) on 32 LR 16×16 patches

use anisocb::nn::{AnisoCb, GeometryNet, NetConfig};
use anisocb::ops::conv2d::{Epilogue, PackedConv};
use anisocb::ops::{AdamParams, Cpu, Ops, Padding, Precision};
use anisocb::train::adam::Adam;
use anisocb::Tensor;
use std::time::Instant;

fn random(shape: &[usize], seed: u64) -> Tensor {
    let mut rng = anisocb::rng::Rng::new(seed);
    let mut t = Tensor::zeros(shape);
    t.data.iter_mut().for_each(|v| *v = rng.uniform() - 0.5);
    t
}

/// Median wall time of one call in ms: untimed warm-up calls for [`WARMUP_SECS`] (at least
/// one), then calls until both `min_calls` and `min_secs` are reached (at most 200 calls).
fn median_ms(min_calls: usize, min_secs: f64, f: &mut dyn FnMut()) -> f64 {
    let warm = Instant::now();
    f();
    while warm.elapsed().as_secs_f64() < WARMUP_SECS {
        f();
    }
    let start = Instant::now();
    let mut t = Vec::new();
    while t.len() < 200 && (t.len() < min_calls || start.elapsed().as_secs_f64() < min_secs) {
        let s = Instant::now();
        f();
        t.push(s.elapsed().as_secs_f64() * 1e3);
    }
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

/// Untimed calls before a row is timed (both sides, benches/peers/rows.py too): a process that
/// times its first 200 small calls straight after starting measured some rows at twice their
/// time in some processes and not in others, as the cores come up to speed and the thread
/// pool wakes (the peers' imports and session set-up warmed them before their first call).
const WARMUP_SECS: f64 = 0.25;

fn emit(row: &str, ms: f64) {
    println!("{{\"row\": \"{row}\", \"ms\": {ms:.5}}}");
}

/// [`emit`] for a row that names the precision that ran.
fn emit_precision(row: &str, ms: f64, precision: Precision) {
    println!("{{\"row\": \"{row}\", \"ms\": {ms:.5}, \"precision\": \"{}\"}}", precision.name());
}

/// (N, C, O, H, W) of the conv rows: the three 64-channel shapes, then the shapes of
/// the shipped small config (C = 32: LR trunk 32², HR tail 64², the C → 3 and C → 1 tails).
const CONVS: [(usize, usize, usize, usize, usize); 7] = [
    (1, 64, 64, 32, 32),
    (16, 64, 64, 32, 32),
    (1, 64, 64, 128, 128),
    (1, 32, 32, 32, 32),
    (1, 32, 32, 64, 64),
    (1, 32, 3, 64, 64),
    (1, 32, 1, 64, 64),
];

fn conv_rows() {
    for (n, c, o, h, w) in CONVS {
        let (x, wt, b) = (random(&[n, c, h, w], 1), random(&[o, c, 3, 3], 2), random(&[o], 3));
        // The weights packed once, outside the timed call, as ONNX Runtime prepacks a session's
        // constant weights and `upscale` packs the nets' once per run; the call entered into
        // the op table (`ops::entered`), as the nets and the trainer run.
        let pk = PackedConv::new(&wt);
        let ms = median_ms(10, 1.0, &mut || {
            let y = anisocb::ops::entered(&Cpu, || {
                Cpu.conv2d_packed(&x, &wt, &pk, Some(&b), Padding::Zero, Epilogue::NONE)
            });
            drop(std::hint::black_box(y))
        });
        emit(&format!("conv {c}->{o} {n}x{c}x{h}x{w}"), ms);
    }
}

fn configs() -> [(&'static str, NetConfig); 2] {
    [("small", NetConfig::small()), ("paper", NetConfig::paper())]
}

/// Frame sizes of the nets rows (benches/peers/rows.py `NET_SIZES`).
const NET_SIZES: [usize; 2] = [32, 64];

fn net_rows() {
    // The default is what `upscale --precision auto` runs on this CPU: bf16 on AMX tiles where
    // they are, else fp32.
    let default = Precision::fastest_cpu();
    for (name, cfg) in configs() {
        let bundle = AnisoCb::new(cfg, 5);
        // Packed once, as `upscale` does (and ONNX Runtime when it loads the model).
        let fp32 = bundle.packed();
        let fast = (default != Precision::Fp32).then(|| bundle.packed_as(default));
        for s in NET_SIZES {
            let frame = random(&[1, 3, s, s], 4);
            let row = |p: &str| format!("nets {name} 1x3x{s}x{s} [{p}]");
            let ms = median_ms(10, 1.0, &mut || {
                drop(std::hint::black_box(fp32.forward_with(&Cpu, &frame, true).unwrap()))
            });
            emit_precision(&row("fp32"), ms, Precision::Fp32);
            let ms = match &fast {
                Some(nets) => median_ms(10, 1.0, &mut || {
                    drop(std::hint::black_box(nets.forward_with(&Cpu, &frame, true).unwrap()))
                }),
                None => ms,
            };
            emit_precision(&row("default"), ms, default);
        }
    }
}

fn train_rows() {
    for (name, cfg) in configs() {
        let (b, p) = (32usize, 16usize);
        let mut net = GeometryNet::new(cfg, 1);
        let lr = random(&[b, 3, p, p], 2);
        let hr = random(&[b, 3, 2 * p, 2 * p], 3);
        let u = anisocb::nn::geometry_net::interpolate(&Cpu, &lr, 2, cfg.upsample);
        let mut grads = net.trunk.zeros_like();
        let sizes: Vec<usize> = net.trunk.params().iter().map(|(_, t)| t.len()).collect();
        let mut adam = Adam::new(AdamParams::default(), &sizes);
        let ms = median_ms(5, 2.0, &mut || {
            grads.fill_zero();
            // As the trainer runs it: the forward and backward entered into the op table.
            anisocb::ops::entered(&Cpu, || net.loss(&Cpu, &lr, &u, &hr, Some(&mut grads))).unwrap();
            let gs: Vec<&[f32]> = grads.params().into_iter().map(|(_, g)| g.data.as_slice()).collect();
            let mut ps: Vec<&mut [f32]> =
                net.trunk.params_mut().into_iter().map(|p| p.data.as_mut_slice()).collect();
            adam.step(&Cpu, &mut ps, &gs);
        });
        emit(&format!("train {name} 32x3x16x16"), ms);
    }
}

fn main() {
    // The pool as the `anisocb` binary builds it: this thread is worker 0 (ONNX Runtime, too,
    // runs its intra-op work on the calling thread).
    anisocb::ops::cpu::join_global_pool(0).expect("the global pool is built first");
    let args: Vec<String> = std::env::args().skip(1).filter(|a| !a.starts_with('-')).collect();
    let want = |g: &str| args.is_empty() || args.iter().any(|a| a == g);
    if want("peak") {
        let g = anisocb::perf::fma_peak_gflops(rayon::current_num_threads(), 1.0);
        println!("{{\"row\": \"fma peak\", \"gflops\": {g:.1}}}");
    }
    if want("conv") {
        conv_rows();
    }
    if want("nets") {
        net_rows();
    }
    if want("train") {
        train_rows();
    }
}
