//! Element-wise ops: ReLU (+ backward), residual add, sigmoid. Any shape (flat over the data).
//!
//! Fast paths: these are memory-bound, so "fast" means rayon over fixed chunks plus loops the
//! compiler vectorizes (plain element-wise bodies with no reduction; with the development
//! build's `target-cpu=native` they become AVX-512). Each fast path computes every element with
//! exactly the same scalar expression as its `*_ref`, so fast and ref agree bit for bit.
//! Below [`PAR_MIN`] elements the fast path runs single-threaded.

use crate::tensor::Tensor;
use rayon::prelude::*;

/// Element count below which splitting across threads costs more than it saves.
pub(crate) const PAR_MIN: usize = 1 << 15;
/// Chunk length (elements) for threaded element-wise loops; fixed so results never depend
/// on the thread count.
pub(crate) const CHUNK: usize = 1 << 14;

/// Apply `f` to matching chunks of `out` and `a` (threaded when large).
pub(crate) fn par_zip_mut(out: &mut [f32], a: &[f32], f: impl Fn(&mut [f32], &[f32]) + Sync) {
    assert_eq!(out.len(), a.len());
    if out.len() < PAR_MIN {
        f(out, a);
    } else {
        out.par_chunks_mut(CHUNK).zip(a.par_chunks(CHUNK)).for_each(|(o, a)| f(o, a));
    }
}

/// ReLU that propagates NaN (so the trainer's non-finite checks still see it).
#[inline(always)]
pub(crate) fn relu1(v: f32) -> f32 {
    if v < 0.0 {
        0.0
    } else {
        v
    }
}

/// Numerically stable logistic function (no overflow of exp for large |z|).
#[inline(always)]
fn sigmoid1(z: f32) -> f32 {
    if z >= 0.0 {
        1.0 / (1.0 + (-z).exp())
    } else {
        let e = z.exp();
        e / (1.0 + e)
    }
}

/// y = max(x, 0); NaN stays NaN. Any shape.
pub fn relu_ref(x: &Tensor) -> Tensor {
    Tensor { shape: x.shape, data: x.data.iter().map(|&v| relu1(v)).collect() }
}

/// Fast [`relu_ref`].
pub fn relu(x: &Tensor) -> Tensor {
    let mut y = Tensor::for_overwrite(&x.shape);
    par_zip_mut(&mut y.data, &x.data, |o, a| {
        for (o, &a) in o.iter_mut().zip(a) {
            *o = relu1(a);
        }
    });
    y
}

/// dx += dy ⊙ [x > 0]. x, dy, dx: same shape.
pub fn relu_backward_ref(x: &Tensor, dy: &Tensor, dx: &mut Tensor) {
    assert_eq!(x.shape, dy.shape, "relu_backward: x and dy shapes differ");
    assert_eq!(x.shape, dx.shape, "relu_backward: x and dx shapes differ");
    for i in 0..x.len() {
        dx.data[i] += if x.data[i] > 0.0 { dy.data[i] } else { 0.0 };
    }
}

/// Fast [`relu_backward_ref`].
pub fn relu_backward(x: &Tensor, dy: &Tensor, dx: &mut Tensor) {
    assert_eq!(x.shape, dy.shape, "relu_backward: x and dy shapes differ");
    assert_eq!(x.shape, dx.shape, "relu_backward: x and dx shapes differ");
    let body = |dx: &mut [f32], x: &[f32], dy: &[f32]| {
        for ((d, &x), &g) in dx.iter_mut().zip(x).zip(dy) {
            *d += if x > 0.0 { g } else { 0.0 };
        }
    };
    if x.len() < PAR_MIN {
        body(&mut dx.data, &x.data, &dy.data);
    } else {
        dx.data
            .par_chunks_mut(CHUNK)
            .zip(x.data.par_chunks(CHUNK))
            .zip(dy.data.par_chunks(CHUNK))
            .for_each(|((d, x), g)| body(d, x, g));
    }
}

/// a += b (same shape).
pub fn add_assign_ref(a: &mut Tensor, b: &Tensor) {
    assert_eq!(a.shape, b.shape, "add_assign: shapes differ");
    for (a, &b) in a.data.iter_mut().zip(&b.data) {
        *a += b;
    }
}

/// Fast [`add_assign_ref`].
pub fn add_assign(a: &mut Tensor, b: &Tensor) {
    assert_eq!(a.shape, b.shape, "add_assign: shapes differ");
    par_zip_mut(&mut a.data, &b.data, |o, b| {
        for (o, &b) in o.iter_mut().zip(b) {
            *o += b;
        }
    });
}

/// y = 1 / (1 + e^(−x)), stable for large |x|. Any shape.
pub fn sigmoid_ref(x: &Tensor) -> Tensor {
    Tensor { shape: x.shape, data: x.data.iter().map(|&v| sigmoid1(v)).collect() }
}

/// Fast [`sigmoid_ref`] (threads only: `exp` is libm's scalar, kept for bitwise agreement).
pub fn sigmoid(x: &Tensor) -> Tensor {
    let mut y = Tensor::for_overwrite(&x.shape);
    par_zip_mut(&mut y.data, &x.data, |o, a| {
        for (o, &a) in o.iter_mut().zip(a) {
            *o = sigmoid1(a);
        }
    });
    y
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::testing::TestRng;

    /// Lengths around the thread threshold and SIMD tails.
    fn lengths() -> Vec<usize> {
        vec![1, 7, 15, 16, 17, 1000, PAR_MIN - 1, PAR_MIN, PAR_MIN + 17, 3 * CHUNK + 5]
    }

    #[test]
    fn fast_elementwise_ops_match_ref_bitwise() {
        let mut rng = TestRng::new(1);
        for n in lengths() {
            let x = rng.tensor(&[n], -3.0, 3.0);
            let dy = rng.tensor(&[n], -1.0, 1.0);
            assert_eq!(relu(&x), relu_ref(&x), "relu n={n}");
            assert_eq!(sigmoid(&x), sigmoid_ref(&x), "sigmoid n={n}");
            let mut a = rng.tensor(&[n], -1.0, 1.0);
            let mut b = a.clone();
            relu_backward(&x, &dy, &mut a);
            relu_backward_ref(&x, &dy, &mut b);
            assert_eq!(a, b, "relu_backward n={n}");
            add_assign(&mut a, &dy);
            add_assign_ref(&mut b, &dy);
            assert_eq!(a, b, "add_assign n={n}");
        }
    }

    #[test]
    fn relu_keeps_nan_and_sigmoid_saturates_without_nan() {
        let x = Tensor { shape: [4].into(), data: vec![f32::NAN, -1.0, 2.0, 0.0] };
        let y = relu(&x);
        assert!(y.data[0].is_nan());
        assert_eq!(&y.data[1..], &[0.0, 2.0, 0.0]);
        let s = sigmoid(&Tensor { shape: [3].into(), data: vec![-200.0, 0.0, 200.0] });
        assert_eq!(s.data, vec![0.0, 0.5, 1.0]);
    }
}
