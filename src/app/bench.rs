//! `anisocb bench`: this machine's FMA peak, then the engine's 3×3 conv hot paths (forward,
//! the forward of `--precision fp32-fast`, input gradient, weight gradient) in ms, GFLOP/s and
//! % of peak.

use crate::error::Result;
use crate::ops::Padding;
use crate::tensor::Tensor;
use std::time::Instant;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Fewer repetitions and skip the largest shape (16×64×64×64).
    #[arg(long)]
    pub quick: bool,
    /// Worker threads (0 = all cores).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Also time the scalar reference forward on 1×64×32×32 (before/after comparison).
    #[arg(long = "ref")]
    pub with_ref: bool,
    /// Compute device: cpu (the full table above) or cuda (conv forward + backward through the op table).
    #[arg(long, default_value = "cpu")]
    pub device: String,
}

pub fn run(args: Args) -> Result<()> {
    let ops = crate::cuda::ops_for_device(&args.device)?;
    if args.device.trim().eq_ignore_ascii_case("cpu") {
        return crate::perf::run_conv_bench(args.threads, args.quick, args.with_ref, |l| println!("{l}"));
    }
    // Another backend: forward and full backward of each case through the op table.
    println!("{:<22} {:>14} {:>14} {:>10}", "3x3 conv", "forward ms", "fwd+bwd ms", "GFLOP/s");
    for case in crate::perf::conv_cases(args.quick) {
        let t = |shape: &[usize]| Tensor::full(shape, 0.01);
        let (x, w) = (t(&[case.n, case.c, case.h, case.w]), t(&[case.o, case.c, 3, 3]));
        let dy = t(&[case.n, case.o, case.h, case.w]);
        let reps = if args.quick { 5 } else { 20 };
        let time = |f: &mut dyn FnMut()| {
            f(); // warm-up (kernel compilation, allocation)
            let s = Instant::now();
            for _ in 0..reps {
                f();
            }
            1e3 * s.elapsed().as_secs_f64() / reps as f64
        };
        let fwd = time(&mut || drop(ops.conv2d(&x, &w, None, Padding::Replicate)));
        let (mut dx, mut dw) = (Tensor::zeros(&x.shape), Tensor::zeros(&w.shape));
        let all = time(&mut || {
            drop(ops.conv2d(&x, &w, None, Padding::Replicate));
            ops.conv2d_backward(&x, &w, &dy, Padding::Replicate, Some(&mut dx), &mut dw, None);
        });
        println!("{:<22} {fwd:>14.3} {all:>14.3} {:>10.1}", case.label(), 3.0 * case.flops() / all / 1e6);
    }
    println!("(device: {}; times include host↔device copies)", ops.name());
    bundle_on_device(ops.as_ref(), args.quick)
}

/// The shipped bundle with every mirror view (16 net passes a frame), device-resident
/// ([`crate::cuda::nets_views`]): ms a frame by chunk size, then the op-by-op path once.
fn bundle_on_device(ops: &dyn crate::ops::Ops, quick: bool) -> Result<()> {
    use crate::cuda::{nets_views, MirrorView};
    use crate::geom::cloth_frame::{net_axes, GRID_MIRRORS};
    let model = crate::nn::weights::embedded_model()?;
    let views: Vec<MirrorView> = GRID_MIRRORS
        .iter()
        .map(|&(rows, cols)| MirrorView { rows, cols, axes: net_axes(rows, cols, model.input_frame()) })
        .collect();
    // A gently folded sheet in the nets' [0, 1] frame.
    let sheet = |n: usize, s: usize| {
        let mut x = Tensor::zeros(&[n, 3, s, s]);
        for f in 0..n {
            for i in 0..s * s {
                let (u, v) = ((i % s) as f32 / (s - 1) as f32, (i / s) as f32 / (s - 1) as f32);
                let base = f * 3 * s * s + i;
                x.data[base] = u;
                x.data[base + s * s] = v;
                x.data[base + 2 * s * s] = 0.5 + 0.05 * (9.0 * u + 0.3 * f as f32).sin() * v;
            }
        }
        x
    };
    println!();
    println!(
        "shipped bundle, 4 mirror views x 4 nets a frame (16 passes), device-resident (fp16 tensor cores):"
    );
    if let Some(c) = ops.as_cuda() {
        if let Err(why) = c.tensor_cores() {
            println!("  unavailable: {why}");
            return crate::ops::check_device(ops);
        }
    }
    let reps = if quick { 5 } else { 20 };
    let nets = model.packed();
    // Median ms a frame of `reps` runs on `frames` frames (a first run packs and warms up).
    let median_ms = |x: &Tensor, enhance: bool| -> Option<(f64, f64)> {
        let frames = x.shape[0] as f64;
        let mut ms = Vec::with_capacity(reps);
        for rep in 0..=reps {
            let t = Instant::now();
            drop(nets_views(ops, &nets, x, &views, enhance)?);
            if rep > 0 {
                ms.push(1e3 * t.elapsed().as_secs_f64() / frames);
            }
        }
        ms.sort_by(f64::total_cmp);
        Some((ms[ms.len() / 2], ms[0]))
    };
    for s in [64usize, 32] {
        for chunk in [16usize, 1] {
            let Some((median, min)) = median_ms(&sheet(chunk, s), true) else {
                println!("  {}: no device-resident path here", ops.name());
                return Ok(());
            };
            println!(
                "  {s}x{s} -> {}x{}, chunk {chunk:>2}: {median:.3} ms a frame (median of {reps}; min {min:.3})",
                2 * s,
                2 * s
            );
        }
    }
    // The shipped default η = 0 skips EnhanceNet (12 passes a frame).
    if let Some((median, _)) = median_ms(&sheet(16, 64), false) {
        println!(
            "  64x64 -> 128x128, chunk 16, without EnhanceNet (η = 0, the default): {median:.3} ms a frame"
        );
    }
    // The op-by-op path (each op uploads its inputs and downloads its output), one frame.
    let x = sheet(1, 64);
    let t = Instant::now();
    for v in &views {
        let xv = crate::geom::cloth_frame::mirror_net_images(&x, v.rows, v.cols, model.input_frame(), true);
        drop(model.packed().forward_with(ops, &xv, true)?);
    }
    println!(
        "  64x64, op by op with copies (fp32), chunk  1: {:.1} ms a frame",
        1e3 * t.elapsed().as_secs_f64()
    );
    crate::ops::check_device(ops)
}
