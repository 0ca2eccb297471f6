//! `anisocb bench`: this machine's FMA peak, then the engine's 3×3 conv hot paths (forward,
//! input gradient, weight gradient) in ms, GFLOP/s and % of peak.

use crate::error::Result;

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
}

pub fn run(args: Args) -> Result<()> {
    crate::ops::peak::run_conv_bench(args.threads, args.quick, args.with_ref, |l| println!("{l}"))
}
