//! Dense f32 tensors, row-major. Images and activations are NCHW; conv weights are OIHW
//! (PyTorch's layout), so weights move to and from PyTorch/JAX through `.npz` unchanged.

use crate::error::{Error, Result};
use crate::pool;
use std::fmt;
use std::ops::{Deref, DerefMut};

/// Most axes a tensor has (a `.npy` of more is refused when read).
pub const MAX_RANK: usize = 6;

/// A tensor's dimensions, held inline: a tensor is made for every layer of every frame, and
/// its shape then costs no allocation. Derefs to `[usize]` (`shape[0]`, `shape.len()`,
/// `&shape[1..]`, `shape.iter()`); compares with arrays, slices and vectors of dimensions.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct Shape {
    /// The first `rank` entries; the rest are 0 (so the derived equality is the slices').
    dims: [usize; MAX_RANK],
    rank: usize,
}

impl Shape {
    /// `dims` as a shape; panics beyond [`MAX_RANK`] axes (a programming error: data from
    /// outside goes through [`Shape::try_new`]).
    pub fn new(dims: &[usize]) -> Shape {
        Shape::try_new(dims).unwrap_or_else(|e| panic!("{e}"))
    }

    /// `dims` as a shape, or an error beyond [`MAX_RANK`] axes.
    pub fn try_new(dims: &[usize]) -> Result<Shape> {
        if dims.len() > MAX_RANK {
            return Err(Error::shape(format!("shape {dims:?} has {} axes; at most {MAX_RANK}", dims.len())));
        }
        let mut s = Shape { dims: [0; MAX_RANK], rank: dims.len() };
        s.dims[..dims.len()].copy_from_slice(dims);
        Ok(s)
    }

    /// Elements of a tensor of this shape.
    pub fn numel(&self) -> usize {
        self.iter().product()
    }
}

impl Deref for Shape {
    type Target = [usize];
    fn deref(&self) -> &[usize] {
        &self.dims[..self.rank]
    }
}

impl DerefMut for Shape {
    fn deref_mut(&mut self) -> &mut [usize] {
        &mut self.dims[..self.rank]
    }
}

impl fmt::Debug for Shape {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(&**self, f)
    }
}

impl From<&[usize]> for Shape {
    fn from(dims: &[usize]) -> Shape {
        Shape::new(dims)
    }
}

impl<const N: usize> From<[usize; N]> for Shape {
    fn from(dims: [usize; N]) -> Shape {
        Shape::new(&dims)
    }
}

impl From<Vec<usize>> for Shape {
    fn from(dims: Vec<usize>) -> Shape {
        Shape::new(&dims)
    }
}

impl<const N: usize> PartialEq<[usize; N]> for Shape {
    fn eq(&self, other: &[usize; N]) -> bool {
        **self == *other
    }
}

impl PartialEq<[usize]> for Shape {
    fn eq(&self, other: &[usize]) -> bool {
        **self == *other
    }
}

impl PartialEq<&[usize]> for Shape {
    fn eq(&self, other: &&[usize]) -> bool {
        **self == **other
    }
}

impl PartialEq<Vec<usize>> for Shape {
    fn eq(&self, other: &Vec<usize>) -> bool {
        **self == **other
    }
}

/// A dense f32 tensor. Its buffer comes from and goes back to the process-wide pool
/// ([`crate::pool`]): activations of the same sizes are made and dropped at every layer.
#[derive(Debug, PartialEq)]
pub struct Tensor {
    pub shape: Shape,
    pub data: Vec<f32>,
}

impl Clone for Tensor {
    fn clone(&self) -> Self {
        let mut data = pool::take(self.data.len());
        data.clear();
        data.extend_from_slice(&self.data);
        Tensor { shape: self.shape, data }
    }
}

impl Drop for Tensor {
    fn drop(&mut self) {
        pool::give(std::mem::take(&mut self.data));
    }
}

impl Tensor {
    pub fn zeros(shape: &[usize]) -> Self {
        Tensor { shape: Shape::new(shape), data: pool::zeroed(shape.iter().product()) }
    }

    /// A tensor whose values are unspecified (stale ones from the pool): for kernels that write
    /// every element before anything reads it, and skip the zeroing pass.
    pub fn for_overwrite(shape: &[usize]) -> Self {
        Tensor { shape: Shape::new(shape), data: pool::overwritten(shape.iter().product()) }
    }

    pub fn full(shape: &[usize], v: f32) -> Self {
        Tensor { shape: Shape::new(shape), data: pool::filled(shape.iter().product(), v) }
    }

    pub fn from_vec(shape: &[usize], data: Vec<f32>) -> Result<Self> {
        let (s, n) = (Shape::try_new(shape)?, shape.iter().product::<usize>());
        if n != data.len() {
            return Err(Error::shape(format!("shape {:?} needs {} values, got {}", shape, n, data.len())));
        }
        Ok(Tensor { shape: s, data })
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
        self.shape = Shape::try_new(shape)?;
        Ok(self)
    }

    /// Index of element (n, c, y, x) in an NCHW tensor.
    #[inline]
    pub fn idx4(&self, n: usize, c: usize, y: usize, x: usize) -> usize {
        ((n * self.shape[1] + c) * self.shape[2] + y) * self.shape[3] + x
    }

    /// Samples `n0..n0+count` of the leading axis, as a new tensor.
    pub fn slice_batch(&self, n0: usize, count: usize) -> Tensor {
        let mut t = Tensor { shape: self.shape, data: Vec::new() };
        t.assign_batch(self, n0, count);
        t
    }

    /// Make this tensor samples `n0..n0+count` of `src`'s leading axis ([`Tensor::slice_batch`]
    /// in place): its own buffer if that has room, else a pooled one.
    pub fn assign_batch(&mut self, src: &Tensor, n0: usize, count: usize) {
        let per: usize = src.shape[1..].iter().product();
        self.make_room(count * per);
        self.data.clear();
        self.data.extend_from_slice(&src.data[n0 * per..(n0 + count) * per]);
        self.shape = src.shape;
        self.shape[0] = count;
    }

    /// Make this tensor `shape` zeros ([`Tensor::zeros`] in place): its own buffer if that has
    /// room, else a pooled one.
    pub fn reset_zeros(&mut self, shape: &[usize]) {
        let s = Shape::new(shape);
        self.make_room(s.numel());
        self.data.clear();
        self.data.resize(s.numel(), 0.0);
        self.shape = s;
    }

    /// A buffer with room for `len` floats: this one, or a pooled one in its place.
    fn make_room(&mut self, len: usize) {
        if self.data.capacity() < len {
            pool::give(std::mem::replace(&mut self.data, pool::take(len)));
        }
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
    fn shapes_are_inline_slices_of_at_most_max_rank_axes() {
        let mut s = Shape::new(&[2, 3, 4]);
        s[0] = 5;
        assert_eq!((s.len(), s.numel(), &s[1..]), (3, 60, &[3, 4][..]));
        assert_eq!(s, [5, 3, 4]);
        assert_eq!(s, vec![5, 3, 4]);
        assert_eq!(format!("{s:?}"), "[5, 3, 4]");
        assert_ne!(Shape::new(&[5, 3]), Shape::new(&[5, 3, 0]));
        assert!(Shape::try_new(&[1; MAX_RANK + 1]).is_err());
        assert!(Tensor::from_vec(&[1; MAX_RANK + 1], vec![0.0]).is_err());
    }

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
