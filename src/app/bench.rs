//! `anisocb bench`: this machine's FMA peak, then the engine's 3×3 conv hot paths (forward,
//! input gradient, weight gradient) in ms, GFLOP/s and % of peak.

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
    Ok(())
}
