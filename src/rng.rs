//! Deterministic random numbers: same seed, same stream, on every machine and thread count.
//!
//! - [`splitmix64`]: the 64-bit mixer everything here is built on; also derives sub-seeds
//!   ([`mix_seed`]) for streams keyed by (seed, purpose, index).
//! - [`SplitMix64`]: the bare splitmix64 stream (scenario randomness: wind gusts).
//! - [`Rng`]: xoshiro256** (Blackman & Vigna) seeded through splitmix64 (weight init, patch
//!   sampling); its state is four `u64`s, so it can be saved.
//!
//! Both draw uniform floats from the top 24 bits of a word, so `uniform` is exact in f32.

/// splitmix64 step: a good 64-bit mixer, also used to derive independent sub-seeds.
#[inline]
pub fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Mix several words into one seed (for streams keyed by (seed, purpose, index)).
pub fn mix_seed(words: &[u64]) -> u64 {
    let mut s = 0x6A09_E667_F3BC_C908u64;
    let mut out = 0;
    for &w in words {
        s ^= w;
        out = splitmix64(&mut s);
        s = out;
    }
    out
}

/// Uniform in [0, 1) from the top 24 bits of `bits` (every value exact in f32).
#[inline]
fn unit_f32(bits: u64) -> f32 {
    (bits >> 40) as f32 / (1u64 << 24) as f32
}

/// The bare splitmix64 stream; the field is the state (`SplitMix64(s)` continues from `s`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SplitMix64(pub u64);

/// The float samplers both generators share, written once over their `next_u64`.
macro_rules! uniform_methods {
    () => {
        /// Uniform in [0, 1) with 24 bits of precision.
        #[inline]
        pub fn uniform(&mut self) -> f32 {
            unit_f32(self.next_u64())
        }

        /// Uniform in [lo, hi).
        #[inline]
        pub fn uniform_in(&mut self, lo: f32, hi: f32) -> f32 {
            lo + (hi - lo) * self.uniform()
        }
    };
}

impl SplitMix64 {
    /// A stream for `seed` (decorrelated from the raw state `seed` by the golden-ratio xor).
    pub fn new(seed: u64) -> Self {
        SplitMix64(seed ^ 0x9E37_79B9_7F4A_7C15)
    }

    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        splitmix64(&mut self.0)
    }

    uniform_methods!();
}

/// xoshiro256** seeded through splitmix64.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Rng {
    pub state: [u64; 4],
}

impl Rng {
    pub fn new(seed: u64) -> Self {
        let mut sm = seed;
        let state = [splitmix64(&mut sm), splitmix64(&mut sm), splitmix64(&mut sm), splitmix64(&mut sm)];
        Rng { state }
    }

    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        let s = &mut self.state;
        let result = s[1].wrapping_mul(5).rotate_left(7).wrapping_mul(9);
        let t = s[1] << 17;
        s[2] ^= s[0];
        s[3] ^= s[1];
        s[1] ^= s[2];
        s[0] ^= s[3];
        s[2] ^= t;
        s[3] = s[3].rotate_left(45);
        result
    }

    uniform_methods!();

    /// Uniform integer in 0..n (n > 0), by Lemire's multiply-shift (bias < 2⁻³² for small n).
    #[inline]
    pub fn below(&mut self, n: usize) -> usize {
        debug_assert!(n > 0);
        (((self.next_u64() >> 32) * n as u64) >> 32) as usize
    }

    /// Fisher–Yates shuffle.
    pub fn shuffle<T>(&mut self, v: &mut [T]) {
        for i in (1..v.len()).rev() {
            let j = self.below(i + 1);
            v.swap(i, j);
        }
    }
}

/// Random test data for the unit tests of the ops (a [`SplitMix64`] stream).
#[cfg(test)]
pub(crate) mod testing {
    use super::SplitMix64;
    use crate::tensor::Tensor;

    pub(crate) struct TestRng(pub SplitMix64);

    impl TestRng {
        /// The raw stream from state `state`.
        pub(crate) fn new(state: u64) -> TestRng {
            TestRng(SplitMix64(state))
        }
        /// Uniform in [lo, hi).
        pub(crate) fn uniform(&mut self, lo: f32, hi: f32) -> f32 {
            self.0.uniform_in(lo, hi)
        }
        /// Integer in lo..=hi.
        pub(crate) fn range(&mut self, lo: usize, hi: usize) -> usize {
            lo + (self.0.next_u64() % (hi - lo + 1) as u64) as usize
        }
        pub(crate) fn tensor(&mut self, shape: &[usize], lo: f32, hi: f32) -> Tensor {
            let n = shape.iter().product();
            Tensor { shape: shape.into(), data: (0..n).map(|_| self.uniform(lo, hi)).collect() }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_stream_and_uniform_in_range() {
        let mut a = Rng::new(7);
        let mut b = Rng::new(7);
        for _ in 0..1000 {
            let u = a.uniform();
            assert_eq!(u.to_bits(), b.uniform().to_bits());
            assert!((0.0..1.0).contains(&u));
        }
        assert_ne!(Rng::new(1).next_u64(), Rng::new(2).next_u64());
    }

    #[test]
    fn below_covers_range_roughly_evenly() {
        let mut r = Rng::new(3);
        let mut counts = [0usize; 5];
        for _ in 0..50_000 {
            counts[r.below(5)] += 1;
        }
        assert!(counts.iter().all(|&c| (9_000..11_000).contains(&c)), "{counts:?}");
    }

    #[test]
    fn splitmix_stream_is_the_mixer_on_its_state() {
        let mut s = SplitMix64::new(5);
        let mut state = 5 ^ 0x9E37_79B9_7F4A_7C15;
        for _ in 0..10 {
            let want = splitmix64(&mut state);
            assert_eq!(s.next_u64(), want);
            assert_eq!(s.0, state);
        }
        let u = SplitMix64(9).uniform_in(-2.0, 3.0);
        assert!((-2.0..3.0).contains(&u));
    }
}
