//! Seeded test data from the crate's one generator ([`anisocb::rng::Rng`]): the few shapes of
//! random input the integration tests draw (tensors, ranges, unit floats).

// Each test binary uses a subset of these helpers.
#![allow(dead_code)]

use anisocb::rng::Rng;
use anisocb::Tensor;

pub trait TestData {
    /// A tensor of `shape`, uniform in [lo, hi).
    fn tensor(&mut self, shape: &[usize], lo: f32, hi: f32) -> Tensor;
    /// Uniform in lo..=hi.
    fn range(&mut self, lo: usize, hi: usize) -> usize;
    /// Uniform in [0, 1), with 53 random bits.
    fn unit_f64(&mut self) -> f64;
    /// Uniform in [−1, 1), with 53 random bits.
    fn signed_f64(&mut self) -> f64;
}

impl TestData for Rng {
    fn tensor(&mut self, shape: &[usize], lo: f32, hi: f32) -> Tensor {
        let n = shape.iter().product();
        Tensor { shape: shape.into(), data: (0..n).map(|_| self.uniform_in(lo, hi)).collect() }
    }
    fn range(&mut self, lo: usize, hi: usize) -> usize {
        lo + self.below(hi - lo + 1)
    }
    fn unit_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn signed_f64(&mut self) -> f64 {
        2.0 * self.unit_f64() - 1.0
    }
}
