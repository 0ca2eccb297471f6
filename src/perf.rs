//! Speed measurement helpers for benchmarks (`anisocb bench`, `cargo bench`): this machine's
//! fp32 FMA peak, a wall-clock timer, and the engine's conv benchmark table. Never used by
//! tests (speed lives in benchmarks, not in timed tests).

use std::time::{Duration, Instant};

use wide::f32x16;

use crate::ops::conv2d::{
    amx, conv2d, conv2d_input_grad, conv2d_packed, conv2d_ref, conv2d_weight_grad, Epilogue, PackedConv,
    Padding,
};
use crate::ops::Precision;
use crate::tensor::Tensor;

/// Independent FMA chains (f32x16) per thread: enough to cover FMA latency × ports (4 × 2 on
/// AVX-512), and few enough to stay in registers. Without AVX-512 an f32x16 is two ymm
/// registers of 16: 16 chains spilled to the stack and the probe read 28 GFLOP/s a core on a
/// Zen 3 that does 93 (2026-11-28); 6 chains (12 ymm, 4 cycles × 2 ports × 8 lanes in flight
/// with room to spare) measure the 93.
const CHAINS: usize = if cfg!(target_feature = "avx512f") { 16 } else { 6 };

/// One thread's FMA loop: `iters` rounds of CHAINS independent f32x16 FMAs.
/// Returns a value that depends on every chain, so nothing is optimised away.
#[inline(never)]
fn fma_loop(iters: u64, seed: f32) -> f32 {
    let a = std::hint::black_box(f32x16::splat(0.999_999));
    let b = std::hint::black_box(f32x16::splat(1e-7));
    let mut acc = [f32x16::splat(seed); CHAINS];
    for (i, v) in acc.iter_mut().enumerate() {
        *v += f32x16::splat(i as f32 * 1e-3);
    }
    for _ in 0..iters {
        for v in acc.iter_mut() {
            *v = v.mul_add(a, b);
        }
    }
    acc.iter().fold(f32x16::ZERO, |s, v| s + *v).reduce_add()
}

/// Measured fp32 FMA peak in GFLOP/s (1 FMA = 2 flops) with `threads` threads running wide
/// f32x16 FMA chains concurrently for about `secs` seconds; the best of a few runs.
pub fn fma_peak_gflops(threads: usize, secs: f64) -> f64 {
    let threads = threads.max(1);
    // Calibrate: iterations for ~secs/3 on one thread.
    let t0 = Instant::now();
    let mut iters = 1u64 << 16;
    std::hint::black_box(fma_loop(iters, 1.0));
    let dt = t0.elapsed().as_secs_f64().max(1e-6);
    iters = ((iters as f64) * (secs / 3.0) / dt).max(1e5) as u64;
    let mut best = 0.0f64;
    for _ in 0..3 {
        let start = std::sync::Barrier::new(threads + 1);
        let t = std::thread::scope(|s| {
            let hs: Vec<_> = (0..threads)
                .map(|i| {
                    let start = &start;
                    s.spawn(move || {
                        start.wait();
                        std::hint::black_box(fma_loop(iters, i as f32));
                    })
                })
                .collect();
            start.wait();
            let t0 = Instant::now();
            for h in hs {
                h.join().expect("FMA peak thread panicked");
            }
            t0.elapsed().as_secs_f64()
        });
        let flops = (threads as u64 * iters * CHAINS as u64 * 16 * 2) as f64;
        best = best.max(flops / t / 1e9);
    }
    best
}

/// Wall-clock timings of repeated calls.
#[derive(Clone, Copy, Debug)]
pub struct Timing {
    /// Fastest call (seconds).
    pub best: f64,
    /// Median call (seconds).
    pub median: f64,
    pub reps: usize,
    /// Fastest call in on-CPU time of the calling thread (seconds; Linux only). Equals the
    /// compute time when all work runs on the calling thread (a 1-thread pool), and is then
    /// robust against other processes competing for the cores.
    pub cpu_best: Option<f64>,
}

/// On-CPU time of the calling thread in seconds (`clock_gettime(CLOCK_THREAD_CPUTIME_ID)`,
/// Linux only; None elsewhere).
pub fn thread_cpu_seconds() -> Option<f64> {
    #[cfg(target_os = "linux")]
    {
        #[repr(C)]
        struct Timespec {
            sec: i64,
            nsec: i64,
        }
        extern "C" {
            fn clock_gettime(clk: i32, tp: *mut Timespec) -> i32;
        }
        const CLOCK_THREAD_CPUTIME_ID: i32 = 3;
        let mut ts = Timespec { sec: 0, nsec: 0 };
        // SAFETY: clock_gettime writes one timespec (two 64-bit fields on x86-64/aarch64 Linux).
        let rc = unsafe { clock_gettime(CLOCK_THREAD_CPUTIME_ID, &mut ts) };
        if rc == 0 {
            return Some(ts.sec as f64 + ts.nsec as f64 * 1e-9);
        }
    }
    None
}

/// Call `f` once to warm up, then repeatedly until `min_reps` calls and `min_time` have passed
/// (at most `max_reps` calls).
pub fn time_fn(mut f: impl FnMut(), min_reps: usize, max_reps: usize, min_time: Duration) -> Timing {
    f();
    let mut ts = Vec::new();
    let mut cpu_best: Option<f64> = None;
    let t_all = Instant::now();
    while ts.len() < max_reps.max(1) && (ts.len() < min_reps || t_all.elapsed() < min_time) {
        let c0 = thread_cpu_seconds();
        let t0 = Instant::now();
        f();
        ts.push(t0.elapsed().as_secs_f64());
        if let (Some(a), Some(b)) = (c0, thread_cpu_seconds()) {
            cpu_best = Some(cpu_best.map_or(b - a, |m: f64| m.min(b - a)));
        }
    }
    ts.sort_by(|a, b| a.total_cmp(b));
    Timing { best: ts[0], median: ts[ts.len() / 2], reps: ts.len(), cpu_best }
}

/// One conv benchmark case: x (n, c, h, w), weights (o, c, 3, 3).
#[derive(Clone, Copy, Debug)]
pub struct ConvCase {
    pub n: usize,
    pub c: usize,
    pub o: usize,
    pub h: usize,
    pub w: usize,
}

impl ConvCase {
    /// Flops of one 3×3 pass (forward, input gradient and weight gradient each cost the same).
    pub fn flops(&self) -> f64 {
        2.0 * (self.n * self.o * self.c * self.h * self.w * 9) as f64
    }
    pub fn label(&self) -> String {
        format!("{}x{}x{}x{} {}→{}", self.n, self.c, self.h, self.w, self.c, self.o)
    }
}

/// The benchmark shapes (3×3, replicate padding as in the networks).
pub fn conv_cases(quick: bool) -> Vec<ConvCase> {
    let mut v = vec![
        ConvCase { n: 1, c: 64, o: 64, h: 32, w: 32 },
        ConvCase { n: 16, c: 64, o: 64, h: 32, w: 32 },
        ConvCase { n: 1, c: 64, o: 64, h: 64, w: 64 },
    ];
    if !quick {
        v.push(ConvCase { n: 16, c: 64, o: 64, h: 64, w: 64 });
    }
    v.push(ConvCase { n: 1, c: 64, o: 64, h: 128, w: 128 });
    v.push(ConvCase { n: 1, c: 64, o: 256, h: 32, w: 32 });
    v
}

/// Which pass of the conv a row measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pass {
    Forward,
    /// The forward of `--precision fp32-fast` (Winograd F(4×4, 3×3)), its weights packed once
    /// as inference packs them (the other rows pack on every call, as [`conv2d`] does); its
    /// GFLOP/s count the direct conv's multiply-adds.
    ForwardFast,
    /// The forward of `--precision bf16` ([`amx::conv_act`], from one bf16 activation to the
    /// next, weights packed once), on a CPU with the bf16 kernels only: the input as hi + lo
    /// pairs (`Bf16Pairs`, how a trunk's low-resolution convs read it, twice the tile work) or
    /// rounded once (`Bf16`, the high-resolution tail). Its GFLOP/s count the direct conv's
    /// multiply-adds once, pairs or not.
    Bf16Pairs,
    Bf16,
    InputGrad,
    WeightGrad,
    /// The scalar reference forward (`conv2d_ref`), for before/after comparison.
    ForwardRef,
}

impl Pass {
    pub fn name(&self) -> &'static str {
        match self {
            Pass::Forward => "forward",
            Pass::ForwardFast => "fwd fp32-fast, packed",
            Pass::Bf16Pairs => "fwd bf16 pairs, packed",
            Pass::Bf16 => "fwd bf16, packed",
            Pass::InputGrad => "input-grad",
            Pass::WeightGrad => "weight-grad",
            Pass::ForwardRef => "forward (scalar ref)",
        }
    }
}

/// One measured row of the table.
#[derive(Clone, Debug)]
pub struct ConvRow {
    pub case: ConvCase,
    pub pass: Pass,
    pub timing: Timing,
    /// GFLOP/s at the median time.
    pub gflops: f64,
}

fn det_tensor(shape: &[usize], seed: u32) -> Tensor {
    let n: usize = shape.iter().product();
    let data = (0..n as u32)
        .map(|i| {
            let h = (i ^ seed).wrapping_mul(0x9E37_79B1).rotate_left(13).wrapping_mul(0x85EB_CA6B);
            (h >> 8) as f32 / (1u32 << 24) as f32 - 0.5
        })
        .collect();
    Tensor { shape: shape.into(), data }
}

/// Time forward, input gradient and weight gradient of `case` (replicate padding) on the
/// current rayon pool. `with_ref` also times the scalar reference forward (slow).
pub fn bench_conv_case(case: ConvCase, quick: bool, with_ref: bool) -> Vec<ConvRow> {
    let pad = Padding::Replicate;
    let x = det_tensor(&[case.n, case.c, case.h, case.w], 1);
    let w = det_tensor(&[case.o, case.c, 3, 3], 2);
    let b = det_tensor(&[case.o], 3);
    let dy = det_tensor(&[case.n, case.o, case.h, case.w], 4);
    let (min_reps, max_reps, min_time) =
        if quick { (3, 50, Duration::from_millis(150)) } else { (10, 500, Duration::from_millis(600)) };
    let mut rows = Vec::new();
    let mut push = |pass: Pass, t: Timing| {
        rows.push(ConvRow { case, pass, timing: t, gflops: case.flops() / t.median / 1e9 });
    };
    let t =
        time_fn(|| drop(std::hint::black_box(conv2d(&x, &w, Some(&b), pad))), min_reps, max_reps, min_time);
    push(Pass::Forward, t);
    let fast = PackedConv::with_precision(&w, Precision::Fp32Fast);
    let t = time_fn(
        || drop(std::hint::black_box(conv2d_packed(&x, &fast, Some(&b), pad, Epilogue::NONE))),
        min_reps,
        max_reps,
        min_time,
    );
    push(Pass::ForwardFast, t);
    if amx::available() {
        for (pass, split) in [(Pass::Bf16Pairs, true), (Pass::Bf16, false)] {
            let packed = PackedConv::for_chain(&w, Precision::Bf16, 1, split);
            let xa = amx::Act::from_nchw(&x, pad, split);
            let epi = amx::ActEpilogue::default();
            let t = time_fn(
                || drop(std::hint::black_box(amx::conv_act(&xa, &packed, Some(&b), epi, false))),
                min_reps,
                max_reps,
                min_time,
            );
            push(pass, t);
        }
    }
    let mut dx = Tensor::zeros(&x.shape);
    let t = time_fn(|| conv2d_input_grad(&w, &dy, pad, &mut dx), min_reps, max_reps, min_time);
    push(Pass::InputGrad, t);
    let mut dw = Tensor::zeros(&w.shape);
    let t = time_fn(|| conv2d_weight_grad(&x, &dy, pad, &mut dw), min_reps, max_reps, min_time);
    push(Pass::WeightGrad, t);
    if with_ref {
        let t =
            time_fn(|| drop(std::hint::black_box(conv2d_ref(&x, &w, Some(&b), pad))), 1, 3, Duration::ZERO);
        push(Pass::ForwardRef, t);
    }
    rows
}

/// The whole benchmark as printable text lines: FMA peak (1 thread and `threads` threads), then
/// one line per case and pass with ms, GFLOP/s and % of the all-threads peak.
/// `threads` = 0 uses rayon's default pool size.
pub fn run_conv_bench(
    threads: usize,
    quick: bool,
    with_ref: bool,
    mut out: impl FnMut(&str),
) -> crate::Result<()> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| crate::Error::config(format!("cannot start {threads} threads: {e}")))?;
    let nt = pool.current_num_threads();
    let secs = if quick { 0.3 } else { 1.0 };
    let p1 = fma_peak_gflops(1, secs);
    let pn = fma_peak_gflops(nt, secs);
    out(&format!("fp32 FMA peak (f32x16 chains): 1 thread {p1:.1} GFLOP/s, {nt} threads {pn:.1} GFLOP/s"));
    if let Ok(l) = std::fs::read_to_string("/proc/loadavg") {
        out(&format!("load average at start: {}", l.trim()));
        let load1: f64 = l.split_whitespace().next().and_then(|v| v.parse().ok()).unwrap_or(0.0);
        let cores = std::thread::available_parallelism().map_or(1, |c| c.get());
        if load1 > 0.5 * cores as f64 {
            out(&format!(
                "warning: the machine is busy (load {load1:.1} on {cores} cores): wall-clock times and the \
                 peak are understated; `--threads 1` adds an on-CPU-time column that is not"
            ));
        }
    }
    out(match (amx::available(), amx::tiles()) {
        (true, true) => "bf16 rows: AMX tiles (tdpbf16ps)",
        (true, false) => "bf16 rows: AVX512_BF16 dot products (vdpbf16ps; no AMX tiles, or ANISOCB_NO_AMX=1)",
        (false, _) => "bf16 rows: none (no AVX512_BF16 on this CPU, or ANISOCB_NO_BF16=1)",
    });
    out(&format!(
        "{:<22} {:<22} {:>9} {:>9} {:>9} {:>7}{}",
        "3x3 conv (replicate)",
        "pass",
        "median ms",
        "best ms",
        "GFLOP/s",
        "% peak",
        if nt == 1 { "   cpu ms  GFLOP/s(cpu) %peak(cpu)" } else { "" }
    ));
    let lines = pool.install(|| {
        let mut lines = Vec::new();
        let mut out = |l: &str| lines.push(l.to_string());
        let mut fb_small = 0.0;
        for (i, case) in conv_cases(quick).into_iter().enumerate() {
            let rows = bench_conv_case(case, quick, with_ref && i == 0);
            for r in &rows {
                // With one thread, also the on-CPU time (robust when other processes load the cores).
                let cpu = match (nt, r.timing.cpu_best) {
                    (1, Some(t)) if t > 0.0 => {
                        let g = r.case.flops() / t / 1e9;
                        format!(" {:>8.3} {:>12.1} {:>10.1}%", t * 1e3, g, 100.0 * g / p1)
                    }
                    _ => String::new(),
                };
                out(&format!(
                    "{:<22} {:<22} {:>9.3} {:>9.3} {:>9.1} {:>6.1}%{}",
                    r.case.label(),
                    r.pass.name(),
                    r.timing.median * 1e3,
                    r.timing.best * 1e3,
                    r.gflops,
                    100.0 * r.gflops / pn,
                    cpu
                ));
            }
            let training = [Pass::Forward, Pass::InputGrad, Pass::WeightGrad];
            let sum: f64 = rows.iter().filter(|r| training.contains(&r.pass)).map(|r| r.timing.median).sum();
            out(&format!("{:<22} {:<22} {:>9.3}", case.label(), "fwd + both grads", sum * 1e3));
            if i == 0 {
                fb_small = rows[0].timing.median;
            }
        }
        out(&format!("target check: forward 1x64x32x32 {:.3} ms (target ≤ 0.24 ms)", fb_small * 1e3));
        lines
    });
    for l in &lines {
        out(l);
    }
    Ok(())
}
