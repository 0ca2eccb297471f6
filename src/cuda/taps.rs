//! Host-side resampling taps for the GPU resize kernels (`kernels/resample.cu`).
//!
//! The GPU only gathers: the per-axis source indices and weights are computed here with the
//! same f32 expressions as the CPU path (`ops::resample`: align corners, s = d·(in−1)/(out−1),
//! bilinear or Keys cubic a = −0.75 with border-clamped indices), so both paths interpolate
//! with identical weights. Pure Rust, compiled with or without the `cuda` feature, and tested
//! against the CPU reference by applying the taps on the host in the kernels' order.

use crate::ops::Interp;

const CUBIC_A: f32 = -0.75;

/// Forward taps along one axis: output index d reads `idx[d·k + a]` with weight `w[d·k + a]`.
#[derive(Clone, Debug, PartialEq)]
pub struct AxisTaps {
    /// Taps per output index (2 bilinear, 4 bicubic).
    pub k: usize,
    pub idx: Vec<i32>,
    pub w: Vec<f32>,
}

/// Transposed taps (CSR): source index i is read by outputs `o[ptr[i]..ptr[i + 1]]` with the
/// weights `w[..]` (taps of one output that clamp onto the same source are merged).
#[derive(Clone, Debug, PartialEq)]
pub struct AxisCsr {
    pub ptr: Vec<i32>,
    pub o: Vec<i32>,
    pub w: Vec<f32>,
}

fn scale(in_n: usize, out_n: usize) -> f32 {
    if out_n > 1 {
        (in_n as f32 - 1.0) / (out_n as f32 - 1.0)
    } else {
        0.0
    }
}

fn cubic_weights(t: f32) -> [f32; 4] {
    let a = CUBIC_A;
    let c1 = |x: f32| ((a + 2.0) * x - (a + 3.0)) * x * x + 1.0;
    let c2 = |x: f32| ((a * x - 5.0 * a) * x + 8.0 * a) * x - 4.0 * a;
    [c2(t + 1.0), c1(t), c1(1.0 - t), c2(2.0 - t)]
}

/// Taps of every output index along an axis of `in_n` (≥ 1) source samples.
pub fn axis_taps(in_n: usize, out_n: usize, mode: Interp) -> AxisTaps {
    assert!(in_n >= 1, "resize: empty axis");
    let sc = scale(in_n, out_n);
    let last = in_n as isize - 1;
    let k = match mode {
        Interp::Bilinear => 2,
        Interp::Bicubic => 4,
    };
    let mut t = AxisTaps { k, idx: Vec::with_capacity(out_n * k), w: Vec::with_capacity(out_n * k) };
    for d in 0..out_n {
        let s = sc * d as f32;
        match mode {
            Interp::Bilinear => {
                let i0 = (s.floor() as usize).min(in_n - 1);
                let i1 = (i0 + 1).min(in_n - 1);
                let f = (s - i0 as f32).clamp(0.0, 1.0);
                t.idx.extend_from_slice(&[i0 as i32, i1 as i32]);
                t.w.extend_from_slice(&[1.0 - f, f]);
            }
            Interp::Bicubic => {
                let fl = s.floor();
                let i = fl as isize;
                for o in -1..=2 {
                    t.idx.push((i + o).clamp(0, last) as i32);
                }
                t.w.extend_from_slice(&cubic_weights(s - fl));
            }
        }
    }
    t
}

/// Transpose forward taps over `in_n` source indices, entries ordered by output index.
pub fn transpose(t: &AxisTaps, in_n: usize) -> AxisCsr {
    let out_n = t.idx.len().checked_div(t.k).unwrap_or(0);
    let mut cols: Vec<Vec<(i32, f32)>> = vec![Vec::new(); in_n];
    for d in 0..out_n {
        for a in 0..t.k {
            let i = t.idx[d * t.k + a] as usize;
            let w = t.w[d * t.k + a];
            match cols[i].last_mut() {
                Some(last) if last.0 == d as i32 => last.1 += w,
                _ => cols[i].push((d as i32, w)),
            }
        }
    }
    let mut csr = AxisCsr { ptr: Vec::with_capacity(in_n + 1), o: Vec::new(), w: Vec::new() };
    csr.ptr.push(0);
    for col in cols {
        for (o, w) in col {
            csr.o.push(o);
            csr.w.push(w);
        }
        csr.ptr.push(csr.o.len() as i32);
    }
    csr
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ops::resample::{resize_backward_ref, resize_ref};
    use crate::tensor::Tensor;

    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            self.0
        }
        fn range(&mut self, lo: usize, hi: usize) -> usize {
            lo + (self.next() % (hi - lo + 1) as u64) as usize
        }
        fn tensor(&mut self, shape: &[usize]) -> Tensor {
            let n = shape.iter().product();
            let data = (0..n).map(|_| (self.next() >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0).collect();
            Tensor { shape: shape.to_vec(), data }
        }
    }

    /// `resize_fwd` of kernels/resample.cu, run on the host.
    fn gather_fwd(x: &Tensor, oh: usize, ow: usize, mode: Interp) -> Tensor {
        let (n, c, h, w) = x.dims4();
        let (ty, tx) = (axis_taps(h, oh, mode), axis_taps(w, ow, mode));
        let mut y = Tensor::zeros(&[n, c, oh, ow]);
        for (e, out) in y.data.iter_mut().enumerate() {
            let (ox, oy, p) = (e % ow, (e / ow) % oh, e / (ow * oh));
            let mut acc = 0.0f32;
            for a in 0..ty.k {
                let row = p * h * w + ty.idx[oy * ty.k + a] as usize * w;
                let mut s = 0.0f32;
                for b in 0..tx.k {
                    s += tx.w[ox * tx.k + b] * x.data[row + tx.idx[ox * tx.k + b] as usize];
                }
                acc += ty.w[oy * ty.k + a] * s;
            }
            *out = acc;
        }
        y
    }

    /// `resize_bwd` of kernels/resample.cu, run on the host.
    fn gather_bwd(dy: &Tensor, mode: Interp, dx: &mut Tensor) {
        let (_, _, oh, ow) = dy.dims4();
        let (_, _, h, w) = dx.dims4();
        let cy = transpose(&axis_taps(h, oh, mode), h);
        let cx = transpose(&axis_taps(w, ow, mode), w);
        for (e, out) in dx.data.iter_mut().enumerate() {
            let (ix, iy, p) = (e % w, (e / w) % h, e / (w * h));
            let mut acc = 0.0f32;
            for a in cy.ptr[iy] as usize..cy.ptr[iy + 1] as usize {
                let row = p * oh * ow + cy.o[a] as usize * ow;
                let mut s = 0.0f32;
                for b in cx.ptr[ix] as usize..cx.ptr[ix + 1] as usize {
                    s += cx.w[b] * dy.data[row + cx.o[b] as usize];
                }
                acc += cy.w[a] * s;
            }
            *out += acc;
        }
    }

    #[test]
    fn gpu_resize_taps_reproduce_the_cpu_reference() {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        for case in 0..30 {
            let mode = if case % 2 == 0 { Interp::Bilinear } else { Interp::Bicubic };
            let (n, c, h, w) = (rng.range(1, 2), rng.range(1, 3), rng.range(1, 9), rng.range(1, 9));
            let (oh, ow) = if case % 3 == 0 { (rng.range(1, 20), rng.range(1, 20)) } else { (2 * h, 2 * w) };
            let x = rng.tensor(&[n, c, h, w]);
            // Same weights, same summation order as the reference: bitwise equal.
            assert_eq!(
                gather_fwd(&x, oh, ow, mode),
                resize_ref(&x, oh, ow, mode),
                "{mode:?} {:?}→{oh}x{ow}",
                x.shape
            );
            let dy = rng.tensor(&[n, c, oh, ow]);
            let mut a = rng.tensor(&[n, c, h, w]);
            let mut b = a.clone();
            gather_bwd(&dy, mode, &mut a);
            resize_backward_ref(&dy, mode, &mut b);
            let worst = a.max_abs_diff(&b);
            assert!(worst < 1e-5, "{mode:?} {:?}→{oh}x{ow}: backward differs by {worst}", x.shape);
        }
    }
}
