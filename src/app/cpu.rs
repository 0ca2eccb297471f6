//! Refuse to run, with a clear message, on a CPU that lacks the instructions this binary was
//! compiled for (instead of dying on SIGILL). Keep this file free of wide arithmetic.

/// Check every x86 feature enabled at compile time against the running CPU.
#[inline(never)]
pub fn check_cpu_features() -> Result<(), String> {
    #[cfg(target_arch = "x86_64")]
    {
        let mut missing = Vec::new();
        macro_rules! need {
            ($($f:tt),*) => {$(
                if cfg!(target_feature = $f) && !std::arch::is_x86_feature_detected!($f) {
                    missing.push($f);
                }
            )*};
        }
        need!("sse4.2", "avx", "avx2", "fma", "bmi2", "avx512f", "avx512bw", "avx512vl", "avx512dq");
        if !missing.is_empty() {
            return Err(format!(
                "this binary was built for a CPU with {} but this CPU lacks them. \
                 Use the portable build (`make dist`, baseline x86-64-v3 = AVX2+FMA) or rebuild from \
                 source on this machine (`cargo build --release`).",
                missing.join(", ")
            ));
        }
    }
    Ok(())
}
