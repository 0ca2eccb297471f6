//! Dense f32 tensors, row-major. Images and activations are NCHW; conv weights are OIHW
//! (PyTorch's layout), so weights move to and from PyTorch/JAX through `.npz` unchanged.

use crate::error::{Error, Result};
use crate::pool;

/// A dense f32 tensor. Its buffer comes from and goes back to the per-thread pool
/// ([`crate::pool`]): activations of the same sizes are made and dropped at every layer.
#[derive(Debug, PartialEq)]
pub struct Tensor {
    pub shape: Vec<usize>,
    pub data: Vec<f32>,
}

impl Clone for Tensor {
    fn clone(&self) -> Self {
        let mut data = pool::take(self.data.len());
        data.clear();
        data.extend_from_slice(&self.data);
        Tensor { shape: self.shape.clone(), data }
    }
}

impl Drop for Tensor {
    fn drop(&mut self) {
        pool::give(std::mem::take(&mut self.data));
    }
}

impl Tensor {
    pub fn zeros(shape: &[usize]) -> Self {
        Tensor { shape: shape.to_vec(), data: pool::zeroed(shape.iter().product()) }
    }

    /// A tensor whose values are unspecified (stale ones from the pool): for kernels that write
    /// every element before anything reads it, and skip the zeroing pass.
    pub fn for_overwrite(shape: &[usize]) -> Self {
        Tensor { shape: shape.to_vec(), data: pool::overwritten(shape.iter().product()) }
    }

    pub fn full(shape: &[usize], v: f32) -> Self {
        Tensor { shape: shape.to_vec(), data: pool::filled(shape.iter().product(), v) }
    }

    pub fn from_vec(shape: &[usize], data: Vec<f32>) -> Result<Self> {
        let n: usize = shape.iter().product();
        if n != data.len() {
            return Err(Error::shape(format!("shape {:?} needs {} values, got {}", shape, n, data.len())));
        }
        Ok(Tensor { shape: shape.to_vec(), data })
    }

    /// The values, moved out (the buffer leaves the pool's care).
    pub fn into_data(mut self) -> Vec<f32> {
        std::mem::take(&mut self.data)
    }

    pub fn len(&self) -> usize {
        self.data.len()
    }

    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    pub fn rank(&self) -> usize {
        self.shape.len()
    }

    /// (N, C, H, W) of a rank-4 tensor; panics on another rank (a programming error, not input).
    pub fn dims4(&self) -> (usize, usize, usize, usize) {
        assert_eq!(self.shape.len(), 4, "expected NCHW, got shape {:?}", self.shape);
        (self.shape[0], self.shape[1], self.shape[2], self.shape[3])
    }

    /// Checked variant of [`Tensor::dims4`] for data that came from outside.
    pub fn expect_rank4(&self, what: &str) -> Result<(usize, usize, usize, usize)> {
        if self.shape.len() != 4 {
            return Err(Error::shape(format!("{what}: expected (N, C, H, W), got shape {:?}", self.shape)));
        }
        Ok(self.dims4())
    }

    pub fn reshape(mut self, shape: &[usize]) -> Result<Self> {
        if shape.iter().product::<usize>() != self.data.len() {
            return Err(Error::shape(format!("cannot reshape {:?} to {:?}", self.shape, shape)));
        }
        self.shape = shape.to_vec();
        Ok(self)
    }

    /// Index of element (n, c, y, x) in an NCHW tensor.
    #[inline]
    pub fn idx4(&self, n: usize, c: usize, y: usize, x: usize) -> usize {
        ((n * self.shape[1] + c) * self.shape[2] + y) * self.shape[3] + x
    }

    /// Samples `n0..n0+count` of the leading axis, as a new tensor.
    pub fn slice_batch(&self, n0: usize, count: usize) -> Tensor {
        let per: usize = self.shape[1..].iter().product();
        let mut shape = self.shape.clone();
        shape[0] = count;
        Tensor { shape, data: self.data[n0 * per..(n0 + count) * per].to_vec() }
    }

    /// A (N, C, H, W) tensor mirrored along its rows (`flip_rows`: row i ↔ H − 1 − i) and/or
    /// its columns (`flip_cols`: column j ↔ W − 1 − j). Its own inverse.
    pub fn flipped(&self, flip_rows: bool, flip_cols: bool) -> Tensor {
        let (n, c, h, w) = (self.shape[0], self.shape[1], self.shape[2], self.shape[3]);
        let mut out = Tensor::for_overwrite(&self.shape);
        for (dst, src) in out.data.chunks_exact_mut(h * w).zip(self.data.chunks_exact(h * w)).take(n * c) {
            for i in 0..h {
                let si = if flip_rows { h - 1 - i } else { i };
                let (d, s) = (&mut dst[i * w..(i + 1) * w], &src[si * w..(si + 1) * w]);
                if flip_cols {
                    d.iter_mut().zip(s.iter().rev()).for_each(|(a, b)| *a = *b);
                } else {
                    d.copy_from_slice(s);
                }
            }
        }
        out
    }

    /// Append `other`'s samples (same trailing shape) after this tensor's.
    pub fn append_batch(&mut self, other: &Tensor) {
        assert_eq!(self.shape[1..], other.shape[1..], "append_batch: trailing shapes differ");
        self.data.extend_from_slice(&other.data);
        self.shape[0] += other.shape[0];
    }

    /// Drop the first `n` samples of the leading axis.
    pub fn drop_batch_front(&mut self, n: usize) {
        let per: usize = self.shape[1..].iter().product();
        self.data.drain(..n * per);
        self.shape[0] -= n;
    }

    /// First non-finite value, as (flat index, value).
    pub fn first_non_finite(&self) -> Option<(usize, f32)> {
        self.data.iter().enumerate().find(|(_, v)| !v.is_finite()).map(|(i, v)| (i, *v))
    }

    pub fn max_abs_diff(&self, other: &Tensor) -> f32 {
        assert_eq!(self.shape, other.shape);
        self.data.iter().zip(&other.data).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flipped_mirrors_rows_and_columns_and_is_its_own_inverse() {
        // (2, 1, 2, 3): sample 1 is sample 0 + 10.
        let t =
            Tensor::from_vec(&[2, 1, 2, 3], (0..12).map(|v| (v / 6 * 10 + v % 6) as f32).collect()).unwrap();
        assert_eq!(t.flipped(false, true).data[..6], [2.0, 1.0, 0.0, 5.0, 4.0, 3.0]);
        assert_eq!(t.flipped(true, false).data[6..], [13.0, 14.0, 15.0, 10.0, 11.0, 12.0]);
        assert_eq!(t.flipped(true, true).data[..6], [5.0, 4.0, 3.0, 2.0, 1.0, 0.0]);
        for (r, c) in [(false, false), (false, true), (true, false), (true, true)] {
            assert_eq!(t.flipped(r, c).flipped(r, c), t);
        }
    }
}
