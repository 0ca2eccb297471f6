//! `cargo bench --bench conv [-- --quick] [-- --threads N] [-- --ref]`: the same table as
//! `anisocb bench` (FMA peak, then 3×3 conv forward / input-grad / weight-grad).

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let quick = args.iter().any(|a| a == "--quick");
    let with_ref = args.iter().any(|a| a == "--ref");
    let threads = args
        .iter()
        .position(|a| a == "--threads")
        .and_then(|i| args.get(i + 1))
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    if let Err(e) = anisocb::perf::run_conv_bench(threads, quick, with_ref, |l| println!("{l}")) {
        eprintln!("conv bench: {e}");
        std::process::exit(1);
    }
}
