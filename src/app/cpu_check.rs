//! Refuse to run, with a clear message, on a CPU that lacks the instructions this binary was
//! compiled for (instead of dying on SIGILL).
//!
//! Limitation: Rust has no way to compile one function for a *lower* CPU than the rest of the
//! crate (`#[target_feature]` only adds features), so this check is compiled with the same
//! `-C target-cpu` as everything else. It stays safe in practice because the path that runs
//! before the verdict does no arithmetic the compiler could vectorise: CPUID queries (inside
//! std, which is precompiled for baseline x86-64), compares, and stores of `&'static str` into
//! a fixed array. The report is written from static strings, piece by piece, with no
//! formatting or heap. `main` calls it first, before parsing arguments. The fully robust
//! alternative — a separate baseline-compiled launcher that execs the real binary — is not
//! worth a second binary for the features at stake here.

use std::io::Write;

/// Longest list of features we check (the `need!` list below has fewer).
const MAX_MISSING: usize = 32;

/// Features this binary was compiled to assume that the running CPU lacks, in a fixed array
/// so that computing it needs no heap.
#[derive(Clone, Copy, Debug)]
pub struct MissingFeatures {
    names: [&'static str; MAX_MISSING],
    len: usize,
}

impl MissingFeatures {
    pub const fn new() -> Self {
        MissingFeatures { names: [""; MAX_MISSING], len: 0 }
    }
    pub fn push(&mut self, name: &'static str) {
        if self.len < MAX_MISSING {
            self.names[self.len] = name;
            self.len += 1;
        }
    }
    pub fn as_slice(&self) -> &[&'static str] {
        &self.names[..self.len]
    }
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

impl Default for MissingFeatures {
    fn default() -> Self {
        Self::new()
    }
}

/// Which of the `compiled` features (name, enabled at compile time) `has` says are absent.
/// Separated from the CPUID query so tests can inject a CPU.
pub fn missing_from(compiled: &[(&'static str, bool)], has: impl Fn(&str) -> bool) -> MissingFeatures {
    let mut m = MissingFeatures::new();
    for &(name, on) in compiled {
        if on && !has(name) {
            m.push(name);
        }
    }
    m
}

/// Every x86 feature enabled at compile time that the running CPU lacks.
#[inline(never)]
pub fn missing_cpu_features() -> MissingFeatures {
    #[allow(unused_mut)]
    let mut m = MissingFeatures::new();
    #[cfg(target_arch = "x86_64")]
    {
        // Only features LLVM may use in ordinary (non-intrinsic) code, plus what `wide` and
        // faer use; listed in the order of the x86-64 micro-architecture levels.
        macro_rules! need {
            ($($f:tt),*) => {$(
                if cfg!(target_feature = $f) && !std::arch::is_x86_feature_detected!($f) {
                    m.push($f);
                }
            )*};
        }
        need!(
            "sse3",
            "ssse3",
            "sse4.1",
            "sse4.2",
            "popcnt",
            "avx",
            "avx2",
            "fma",
            "bmi1",
            "bmi2",
            "lzcnt",
            "f16c",
            "movbe",
            "avx512f",
            "avx512cd",
            "avx512bw",
            "avx512dq",
            "avx512vl",
            "avx512ifma",
            "avx512vbmi",
            "avx512vbmi2",
            "avx512vnni",
            "avx512bitalg",
            "avx512vpopcntdq",
            "gfni",
            "vaes",
            "vpclmulqdq"
        );
    }
    m
}

/// Write the explanation for `missing` to `w` from static pieces (no heap, no formatting).
pub fn write_missing_report(w: &mut dyn Write, missing: &[&str]) -> std::io::Result<()> {
    w.write_all(b"anisocb: this binary was built for a CPU with ")?;
    for (i, name) in missing.iter().enumerate() {
        if i > 0 {
            w.write_all(b", ")?;
        }
        w.write_all(name.as_bytes())?;
    }
    w.write_all(
        b", but this CPU lacks them (it would crash with an illegal instruction). \
          Use the portable build (`make dist`, baseline x86-64-v3 = AVX2+FMA) or rebuild from \
          source on this machine (`cargo build --release`).\n",
    )
}

/// The explanation as a string (for callers that want one; `main` uses the writer).
pub fn explain_missing(missing: &[&str]) -> String {
    let mut v = Vec::new();
    let _ = write_missing_report(&mut v, missing);
    String::from_utf8_lossy(&v).trim_end().trim_start_matches("anisocb: ").to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn report_lists_every_missing_feature() {
        let compiled =
            [("avx2", true), ("fma", true), ("avx512f", true), ("avx512bw", true), ("sse4a", false)];
        let m = missing_from(&compiled, |f| matches!(f, "avx2" | "fma"));
        assert_eq!(m.as_slice(), ["avx512f", "avx512bw"]);
        let msg = explain_missing(m.as_slice());
        assert!(msg.contains("avx512f, avx512bw, but this CPU lacks them"), "{msg}");
        assert!(msg.contains("make dist") && msg.contains("cargo build --release"), "{msg}");
    }

    #[test]
    fn features_not_compiled_in_are_never_missing() {
        let m = missing_from(&[("avx512f", false), ("avx2", true)], |_| false);
        assert_eq!(m.as_slice(), ["avx2"]);
        assert!(missing_from(&[("avx2", true)], |_| true).is_empty());
    }

    #[test]
    fn this_machine_has_what_the_build_assumes() {
        // The test binary runs on the machine it was built for (target-cpu=native).
        assert!(missing_cpu_features().is_empty(), "{:?}", missing_cpu_features().as_slice());
    }

    #[test]
    fn overlong_lists_are_capped_not_overflowed() {
        let names: Vec<(&'static str, bool)> = (0..40).map(|_| ("avx2", true)).collect();
        assert_eq!(missing_from(&names, |_| false).as_slice().len(), MAX_MISSING);
    }
}
