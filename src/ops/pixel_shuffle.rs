//! Pixel shuffle / unshuffle by any factor r, PyTorch's channel order:
//! y[n, c, h·r + i, w·r + j] = x[n, c·r² + i·r + j, h, w].
//!
//! Both are pure permutations, so each is the other's backward. The fast paths thread over
//! output planes and write each output row sequentially; they copy exactly the same values as
//! the references (bitwise equal).

use crate::tensor::Tensor;
use rayon::prelude::*;

/// Planes (elements) below which threading is skipped.
const PAR_MIN: usize = 1 << 15;

/// x: (N, C·r², H, W) → (N, C, H·r, W·r).
pub fn pixel_shuffle_ref(x: &Tensor, r: usize) -> Tensor {
    let (n, cr2, h, w) = x.dims4();
    assert!(r >= 1 && cr2 % (r * r) == 0, "pixel_shuffle: {cr2} channels not divisible by r²={}", r * r);
    let c = cr2 / (r * r);
    let mut y = Tensor::zeros(&[n, c, h * r, w * r]);
    for ni in 0..n {
        for ci in 0..c {
            for i in 0..r {
                for j in 0..r {
                    for hi in 0..h {
                        for wi in 0..w {
                            let src = x.idx4(ni, ci * r * r + i * r + j, hi, wi);
                            let dst = y.idx4(ni, ci, hi * r + i, wi * r + j);
                            y.data[dst] = x.data[src];
                        }
                    }
                }
            }
        }
    }
    y
}

/// x: (N, C, H·r, W·r) → (N, C·r², H, W). Inverse (and backward) of [`pixel_shuffle_ref`].
pub fn pixel_unshuffle_ref(x: &Tensor, r: usize) -> Tensor {
    let (n, c, hr, wr) = x.dims4();
    assert!(r >= 1 && hr % r == 0 && wr % r == 0, "pixel_unshuffle: {hr}x{wr} not divisible by r={r}");
    let (h, w) = (hr / r, wr / r);
    let mut y = Tensor::zeros(&[n, c * r * r, h, w]);
    for ni in 0..n {
        for ci in 0..c {
            for i in 0..r {
                for j in 0..r {
                    for hi in 0..h {
                        for wi in 0..w {
                            let src = x.idx4(ni, ci, hi * r + i, wi * r + j);
                            let dst = y.idx4(ni, ci * r * r + i * r + j, hi, wi);
                            y.data[dst] = x.data[src];
                        }
                    }
                }
            }
        }
    }
    y
}

/// Fast [`pixel_shuffle_ref`]: one task per output plane (n, c).
pub fn pixel_shuffle(x: &Tensor, r: usize) -> Tensor {
    let (n, cr2, h, w) = x.dims4();
    assert!(r >= 1 && cr2 % (r * r) == 0, "pixel_shuffle: {cr2} channels not divisible by r²={}", r * r);
    let c = cr2 / (r * r);
    let (ho, wo) = (h * r, w * r);
    let mut y = Tensor::for_overwrite(&[n, c, ho, wo]);
    if y.is_empty() {
        return y;
    }
    let plane_in = h * w;
    // One output plane (n, c) reads the r² input planes (n, c·r² .. (c+1)·r²).
    let body = |p: usize, out: &mut [f32]| {
        let src = &x.data[p * r * r * plane_in..(p + 1) * r * r * plane_in];
        for (yo, row) in out.chunks_exact_mut(wo).enumerate() {
            let (hi, i) = (yo / r, yo % r);
            // Output row (hi·r + i) interleaves row hi of the r input planes i·r + j.
            for j in 0..r {
                let base = (i * r + j) * plane_in + hi * w;
                let srow = &src[base..base + w];
                for (o, &s) in row[j..].iter_mut().step_by(r).zip(srow) {
                    *o = s;
                }
            }
        }
    };
    if y.len() < PAR_MIN {
        y.data.chunks_exact_mut(ho * wo).enumerate().for_each(|(p, o)| body(p, o));
    } else {
        y.data.par_chunks_exact_mut(ho * wo).enumerate().for_each(|(p, o)| body(p, o));
    }
    y
}

/// Fast [`pixel_unshuffle_ref`]: one task per output plane (n, c·r² + i·r + j).
pub fn pixel_unshuffle(x: &Tensor, r: usize) -> Tensor {
    let (n, c, hr, wr) = x.dims4();
    assert!(r >= 1 && hr % r == 0 && wr % r == 0, "pixel_unshuffle: {hr}x{wr} not divisible by r={r}");
    let (h, w) = (hr / r, wr / r);
    let mut y = Tensor::zeros(&[n, c * r * r, h, w]);
    if y.is_empty() {
        return y;
    }
    let body = |q: usize, out: &mut [f32]| {
        let (p, s) = (q / (r * r), q % (r * r));
        let (i, j) = (s / r, s % r);
        let src = &x.data[p * hr * wr..(p + 1) * hr * wr];
        for (hi, row) in out.chunks_exact_mut(w).enumerate() {
            let srow = &src[(hi * r + i) * wr..(hi * r + i + 1) * wr];
            for (wi, v) in row.iter_mut().enumerate() {
                *v = srow[wi * r + j];
            }
        }
    };
    if y.len() < PAR_MIN {
        y.data.chunks_exact_mut(h * w).enumerate().for_each(|(q, o)| body(q, o));
    } else {
        y.data.par_chunks_exact_mut(h * w).enumerate().for_each(|(q, o)| body(q, o));
    }
    y
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::testing::TestRng;

    #[test]
    fn fast_pixel_shuffle_matches_ref_and_unshuffle_inverts_it() {
        let mut rng = TestRng::new(2);
        for case in 0..24 {
            let r = [1, 2, 3, 4][case % 4];
            let (n, c) = (rng.range(1, 3), rng.range(1, 5));
            let (h, w) = (rng.range(1, 13), rng.range(1, 13));
            let big = case == 23;
            let (h, w) = if big { (64, 71) } else { (h, w) };
            let x = rng.tensor(&[n, c * r * r, h, w], -1.0, 1.0);
            let y = pixel_shuffle(&x, r);
            assert_eq!(y, pixel_shuffle_ref(&x, r), "shuffle r={r} {:?}", x.shape);
            assert_eq!(y.shape, vec![n, c, h * r, w * r]);
            let back = pixel_unshuffle(&y, r);
            assert_eq!(back, pixel_unshuffle_ref(&y, r), "unshuffle r={r} {:?}", y.shape);
            assert_eq!(back, x, "unshuffle(shuffle(x)) != x, r={r}");
        }
    }

    #[test]
    fn pixel_shuffle_uses_pytorch_channel_order() {
        // torch.nn.functional.pixel_shuffle(arange(8).reshape(1,8,1,1), 2) →
        // [[[[0,1],[2,3]],[[4,5],[6,7]]]]
        let x = Tensor { shape: [1, 8, 1, 1].into(), data: (0..8).map(|v| v as f32).collect() };
        let y = pixel_shuffle(&x, 2);
        assert_eq!(y.shape, vec![1, 2, 2, 2]);
        assert_eq!(y.data, (0..8).map(|v| v as f32).collect::<Vec<_>>());
        let x = Tensor { shape: [1, 4, 1, 2].into(), data: (0..8).map(|v| v as f32).collect() };
        // channel k at (0, w) goes to (k/2, 2w + k%2)
        assert_eq!(pixel_shuffle(&x, 2).data, vec![0., 2., 1., 3., 4., 6., 5., 7.]);
    }
}
