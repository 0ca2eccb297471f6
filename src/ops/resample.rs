//! Resizing with align-corners semantics (PyTorch `F.interpolate(..., align_corners=True)`),
//! bilinear or cubic convolution (Keys' kernel with a = −0.75, PyTorch's bicubic, or a = −0.5,
//! Catmull-Rom; sample indices clamped to the border), forward and backward. The ×r upsampling of the pipeline is `resize(x, r·H, r·W)`.
//!
//! Output index d maps to source coordinate s = d · (in − 1)/(out − 1) (0 when out = 1),
//! computed in f32 as PyTorch does. x: (N, C, H, W) → y: (N, C, out_h, out_w).
//!
//! Both directions are separable: y = A_h · X · A_wᵀ per plane, with A a sparse matrix of 2
//! (bilinear) or 4 (bicubic) taps per output row. The fast forward applies A_w to each input
//! row, then A_h over rows; that is the same float operations in the same order as the
//! per-pixel reference (interpolate along x in each source row, then along y), so the two agree
//! bit for bit. The fast backward applies A_hᵀ over rows, then A_wᵀ along each row: a different
//! summation order than the reference's per-pixel scatter, so it agrees to rounding.

use super::Interp;
use crate::pool;
use crate::tensor::Tensor;
use rayon::prelude::*;
use std::cell::RefCell;
use std::rc::Rc;

/// Keys' cubic-convolution parameter a of a cubic mode: −0.75 (PyTorch's and OpenCV's bicubic)
/// or −0.5 (Catmull-Rom, the only a for which the kernel reproduces linear and quadratic
/// functions: with −0.75 an evenly spaced row of vertices comes out unevenly spaced).
fn cubic_a(mode: Interp) -> f32 {
    match mode {
        Interp::CatmullRom => -0.5,
        _ => -0.75,
    }
}

/// Work (output elements) below which threading is skipped.
const PAR_MIN: usize = 1 << 14;

/// Taps along one axis: output index d reads source `idx[d·k + a]` with weight `w[d·k + a]`,
/// a < k. The CPU fast path and the GPU kernels (`kernels/resample.cu`) both apply these, so
/// every path interpolates with identical weights.
#[derive(Clone, Debug, PartialEq)]
pub struct AxisTaps {
    /// Taps per output index (2 bilinear, 4 bicubic).
    pub k: usize,
    pub idx: Vec<usize>,
    pub w: Vec<f32>,
}

/// Transposed taps (CSR), for backends that only gather: source index i is read by outputs
/// `o[ptr[i]..ptr[i + 1]]` with the weights `w[..]` (taps of one output that clamp onto the
/// same source are merged), entries ordered by output index.
#[derive(Clone, Debug, PartialEq)]
pub struct AxisCsr {
    pub ptr: Vec<usize>,
    pub o: Vec<usize>,
    pub w: Vec<f32>,
}

/// Align-corners scale, f32 as PyTorch computes it.
fn scale(in_n: usize, out_n: usize) -> f32 {
    if out_n > 1 {
        (in_n as f32 - 1.0) / (out_n as f32 - 1.0)
    } else {
        0.0
    }
}

/// Keys cubic weights for the 4 samples at offsets −1, 0, 1, 2 from floor(s), t = s − floor(s).
#[inline]
fn cubic_weights(t: f32, a: f32) -> [f32; 4] {
    // |x| ≤ 1: ((a+2)|x| − (a+3))|x|² + 1;  1 < |x| < 2: ((a|x| − 5a)|x| + 8a)|x| − 4a
    let c1 = |x: f32| ((a + 2.0) * x - (a + 3.0)) * x * x + 1.0;
    let c2 = |x: f32| ((a * x - 5.0 * a) * x + 8.0 * a) * x - 4.0 * a;
    [c2(t + 1.0), c1(t), c1(1.0 - t), c2(2.0 - t)]
}

/// The taps of output index `d` along an axis of `in_n` samples: (indices, weights).
#[inline]
fn taps_at(d: usize, in_n: usize, sc: f32, mode: Interp) -> ([usize; 4], [f32; 4], usize) {
    let s = sc * d as f32;
    match mode {
        Interp::Bilinear => {
            let i0 = (s.floor() as usize).min(in_n - 1);
            let i1 = (i0 + 1).min(in_n - 1);
            let t = (s - i0 as f32).clamp(0.0, 1.0);
            ([i0, i1, 0, 0], [1.0 - t, t, 0.0, 0.0], 2)
        }
        Interp::Bicubic | Interp::CatmullRom => {
            let f = s.floor();
            let t = s - f;
            let i = f as isize;
            let last = in_n as isize - 1;
            let at = |o: isize| (i + o).clamp(0, last) as usize;
            ([at(-1), at(0), at(1), at(2)], cubic_weights(t, cubic_a(mode)), 4)
        }
    }
}

/// Taps of every output index along an axis of `in_n` (≥ 1) source samples.
pub fn axis_taps(in_n: usize, out_n: usize, mode: Interp) -> AxisTaps {
    assert!(in_n >= 1, "resize: empty axis");
    let sc = scale(in_n, out_n);
    let k = match mode {
        Interp::Bilinear => 2,
        Interp::Bicubic | Interp::CatmullRom => 4,
    };
    let mut t = AxisTaps { k, idx: Vec::with_capacity(out_n * k), w: Vec::with_capacity(out_n * k) };
    for d in 0..out_n {
        let (idx, w, _) = taps_at(d, in_n, sc, mode);
        t.idx.extend_from_slice(&idx[..k]);
        t.w.extend_from_slice(&w[..k]);
    }
    t
}

/// [`axis_taps`], remembered per thread for the last few axes: the pipeline resizes frames of
/// one size over and over, and would otherwise build (allocate) the same taps for every frame.
fn cached_taps(in_n: usize, out_n: usize, mode: Interp) -> Rc<AxisTaps> {
    const KEEP: usize = 8;
    type Cache = RefCell<Vec<((usize, usize, Interp), Rc<AxisTaps>)>>;
    thread_local! {
        static CACHE: Cache = const { RefCell::new(Vec::new()) };
    }
    CACHE.with(|c| {
        let mut c = c.borrow_mut();
        let key = (in_n, out_n, mode);
        if let Some((_, t)) = c.iter().find(|(k, _)| *k == key) {
            return t.clone();
        }
        let t = Rc::new(axis_taps(in_n, out_n, mode));
        if c.len() == KEEP {
            c.remove(0);
        }
        c.push((key, t.clone()));
        t
    })
}

/// Transpose forward taps over `in_n` source indices.
pub fn transpose(t: &AxisTaps, in_n: usize) -> AxisCsr {
    let out_n = t.idx.len().checked_div(t.k).unwrap_or(0);
    let mut cols: Vec<Vec<(usize, f32)>> = vec![Vec::new(); in_n];
    for d in 0..out_n {
        for a in 0..t.k {
            let (i, w) = (t.idx[d * t.k + a], t.w[d * t.k + a]);
            match cols[i].last_mut() {
                Some(last) if last.0 == d => last.1 += w,
                _ => cols[i].push((d, w)),
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
        csr.ptr.push(csr.o.len());
    }
    csr
}

/// Reference forward, per output pixel: interpolate along x in each of the source rows, then
/// along y. x: (N, C, H, W) → (N, C, out_h, out_w).
pub fn resize_ref(x: &Tensor, out_h: usize, out_w: usize, mode: Interp) -> Tensor {
    let (n, c, h, w) = x.dims4();
    assert!(h > 0 && w > 0, "resize: empty input {:?}", x.shape);
    let (sh, sw) = (scale(h, out_h), scale(w, out_w));
    let mut y = Tensor::zeros(&[n, c, out_h, out_w]);
    for ni in 0..n {
        for ci in 0..c {
            for oy in 0..out_h {
                let (iy, wy, ky) = taps_at(oy, h, sh, mode);
                for ox in 0..out_w {
                    let (ix, wx, kx) = taps_at(ox, w, sw, mode);
                    let mut acc = 0.0f32;
                    for a in 0..ky {
                        let mut row = 0.0f32;
                        for b in 0..kx {
                            row += wx[b] * x.data[x.idx4(ni, ci, iy[a], ix[b])];
                        }
                        acc += wy[a] * row;
                    }
                    let i = y.idx4(ni, ci, oy, ox);
                    y.data[i] = acc;
                }
            }
        }
    }
    y
}

/// Reference backward: scatter each dy pixel into its source taps. Adds into dx.
/// dy: (N, C, out_h, out_w), dx: (N, C, H, W).
pub fn resize_backward_ref(dy: &Tensor, mode: Interp, dx: &mut Tensor) {
    let (n, c, out_h, out_w) = dy.dims4();
    let (n2, c2, h, w) = dx.dims4();
    assert_eq!((n, c), (n2, c2), "resize_backward: dy {:?} vs dx {:?}", dy.shape, dx.shape);
    let (sh, sw) = (scale(h, out_h), scale(w, out_w));
    for ni in 0..n {
        for ci in 0..c {
            for oy in 0..out_h {
                let (iy, wy, ky) = taps_at(oy, h, sh, mode);
                for ox in 0..out_w {
                    let (ix, wx, kx) = taps_at(ox, w, sw, mode);
                    let g = dy.data[dy.idx4(ni, ci, oy, ox)];
                    for a in 0..ky {
                        for b in 0..kx {
                            let i = dx.idx4(ni, ci, iy[a], ix[b]);
                            dx.data[i] += wy[a] * wx[b] * g;
                        }
                    }
                }
            }
        }
    }
}

/// Fast [`resize_ref`]: separable, one task per plane (bitwise equal to the reference).
pub fn resize(x: &Tensor, out_h: usize, out_w: usize, mode: Interp) -> Tensor {
    let (n, c, h, w) = x.dims4();
    assert!(h > 0 && w > 0, "resize: empty input {:?}", x.shape);
    let mut y = Tensor::zeros(&[n, c, out_h, out_w]);
    if y.is_empty() {
        return y;
    }
    let (th, tw) = (cached_taps(h, out_h, mode), cached_taps(w, out_w, mode));
    let (th, tw): (&AxisTaps, &AxisTaps) = (&th, &tw);
    let body = |p: usize, out: &mut [f32]| {
        let src = &x.data[p * h * w..(p + 1) * h * w];
        // tmp[iy][ox]: each source row interpolated along x (every row written). Rows no tap
        // reads are skipped only implicitly (they cost little next to the output).
        let mut tmp = pool::overwritten(h * out_w);
        for (srow, trow) in src.chunks_exact(w).zip(tmp.chunks_exact_mut(out_w)) {
            for (ox, t) in trow.iter_mut().enumerate() {
                let mut row = 0.0f32;
                for b in 0..tw.k {
                    row += tw.w[ox * tw.k + b] * srow[tw.idx[ox * tw.k + b]];
                }
                *t = row;
            }
        }
        for (oy, orow) in out.chunks_exact_mut(out_w).enumerate() {
            for a in 0..th.k {
                let wy = th.w[oy * th.k + a];
                let iy = th.idx[oy * th.k + a];
                let trow = &tmp[iy * out_w..(iy + 1) * out_w];
                for (o, &t) in orow.iter_mut().zip(trow) {
                    *o += wy * t;
                }
            }
        }
        pool::give(tmp);
    };
    let plane = out_h * out_w;
    if y.len() < PAR_MIN {
        y.data.chunks_exact_mut(plane).enumerate().for_each(|(p, o)| body(p, o));
    } else {
        y.data.par_chunks_exact_mut(plane).enumerate().for_each(|(p, o)| body(p, o));
    }
    y
}

/// Fast [`resize_backward_ref`]: dx += A_hᵀ · dy · A_w per plane, one task per plane.
pub fn resize_backward(dy: &Tensor, mode: Interp, dx: &mut Tensor) {
    let (n, c, out_h, out_w) = dy.dims4();
    let (n2, c2, h, w) = dx.dims4();
    assert_eq!((n, c), (n2, c2), "resize_backward: dy {:?} vs dx {:?}", dy.shape, dx.shape);
    if dy.is_empty() || dx.is_empty() {
        return;
    }
    let (th, tw) = (axis_taps(h, out_h, mode), axis_taps(w, out_w, mode));
    let body = |p: usize, dxp: &mut [f32]| {
        let g = &dy.data[p * out_h * out_w..(p + 1) * out_h * out_w];
        // tmp[iy][ox] = Σ_oy A_h[oy, iy] · dy[oy][ox]  (row axpys, vectorized over ox)
        let mut tmp = vec![0.0f32; h * out_w];
        for (oy, grow) in g.chunks_exact(out_w).enumerate() {
            for a in 0..th.k {
                let wy = th.w[oy * th.k + a];
                let iy = th.idx[oy * th.k + a];
                for (t, &gv) in tmp[iy * out_w..(iy + 1) * out_w].iter_mut().zip(grow) {
                    *t += wy * gv;
                }
            }
        }
        // dx[iy][ix] += Σ_ox A_w[ox, ix] · tmp[iy][ox]
        for (trow, drow) in tmp.chunks_exact(out_w).zip(dxp.chunks_exact_mut(w)) {
            for (ox, &t) in trow.iter().enumerate() {
                for b in 0..tw.k {
                    drow[tw.idx[ox * tw.k + b]] += tw.w[ox * tw.k + b] * t;
                }
            }
        }
    };
    let plane = h * w;
    if dy.len() < PAR_MIN {
        dx.data.chunks_exact_mut(plane).enumerate().for_each(|(p, d)| body(p, d));
    } else {
        dx.data.par_chunks_exact_mut(plane).enumerate().for_each(|(p, d)| body(p, d));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::testing::TestRng;

    fn close(a: &Tensor, b: &Tensor, atol: f32, rtol: f32) -> Result<(), String> {
        assert_eq!(a.shape, b.shape);
        let mut worst = (0.0f32, 0usize);
        for (i, (&x, &y)) in a.data.iter().zip(&b.data).enumerate() {
            let d = (x - y).abs();
            if d > atol + rtol * y.abs() && d > worst.0 {
                worst = (d, i);
            }
        }
        if worst.0 > 0.0 {
            Err(format!(
                "largest diff {} at {} ({} vs {})",
                worst.0, worst.1, a.data[worst.1], b.data[worst.1]
            ))
        } else {
            Ok(())
        }
    }

    #[test]
    fn fast_resize_matches_ref_on_odd_shapes() {
        let mut rng = TestRng::new(3);
        for case in 0..40 {
            let mode = MODES[case % 3];
            let (n, c) = (rng.range(1, 2), rng.range(1, 4));
            let (h, w) = (rng.range(1, 11), rng.range(1, 11));
            let (oh, ow) = if case % 4 == 0 {
                (rng.range(1, 25), rng.range(1, 25))
            } else {
                let r = rng.range(2, 3);
                (h * r, w * r)
            };
            let (h, w, oh, ow) = if case >= 38 { (33, 47, 66, 94) } else { (h, w, oh, ow) };
            let x = rng.tensor(&[n, c, h, w], -1.0, 1.0);
            let y = resize(&x, oh, ow, mode);
            assert_eq!(y, resize_ref(&x, oh, ow, mode), "{mode:?} {:?} → {oh}x{ow}", x.shape);
            let dy = rng.tensor(&[n, c, oh, ow], -1.0, 1.0);
            let mut a = rng.tensor(&[n, c, h, w], -1.0, 1.0);
            let mut b = a.clone();
            resize_backward(&dy, mode, &mut a);
            resize_backward_ref(&dy, mode, &mut b);
            close(&a, &b, 1e-5, 1e-5).unwrap_or_else(|e| panic!("backward {mode:?} {:?}: {e}", x.shape));
        }
    }

    const MODES: [Interp; 3] = [Interp::Bilinear, Interp::Bicubic, Interp::CatmullRom];

    #[test]
    fn catmull_rom_keeps_an_evenly_spaced_row_even_and_keys_does_not() {
        // A ramp 0..11 (12 evenly spaced vertices) to 24: away from the border (where the
        // clamped taps read a repeated sample) every output must be d·11/23.
        let x = Tensor { shape: [1, 1, 1, 12].into(), data: (0..12).map(|i| i as f32).collect() };
        let err = |mode| {
            let y = resize(&x, 1, 24, mode);
            (3..21).map(|d| (y.data[d] - d as f32 * 11.0 / 23.0).abs()).fold(0.0f32, f32::max)
        };
        assert!(err(Interp::CatmullRom) < 1e-5, "Catmull-Rom: {}", err(Interp::CatmullRom));
        assert!(err(Interp::Bilinear) < 1e-5);
        assert!(err(Interp::Bicubic) > 1e-3, "Keys a = −0.75 is known not to reproduce a ramp");
    }

    #[test]
    fn resize_keeps_corners_and_constants() {
        let mut rng = TestRng::new(4);
        let x = rng.tensor(&[1, 2, 5, 7], -1.0, 1.0);
        for mode in MODES {
            let y = resize(&x, 15, 21, mode);
            for c in 0..2 {
                assert_eq!(y.data[y.idx4(0, c, 0, 0)], x.data[x.idx4(0, c, 0, 0)]);
                assert!((y.data[y.idx4(0, c, 14, 20)] - x.data[x.idx4(0, c, 4, 6)]).abs() < 1e-6);
            }
            let k = resize(&Tensor::full(&[1, 1, 4, 6], 0.25), 9, 13, mode);
            assert!(k.data.iter().all(|v| (v - 0.25).abs() < 1e-6), "{mode:?} moved a constant");
        }
    }

    #[test]
    fn resize_backward_is_the_adjoint_of_forward() {
        // <resize(x), g> == <x, resize_backward(g)>
        let mut rng = TestRng::new(5);
        for mode in MODES {
            let x = rng.tensor(&[2, 3, 6, 5], -1.0, 1.0);
            let g = rng.tensor(&[2, 3, 18, 15], -1.0, 1.0);
            let y = resize(&x, 18, 15, mode);
            let mut dx = Tensor::zeros(&x.shape);
            resize_backward(&g, mode, &mut dx);
            let lhs: f64 = y.data.iter().zip(&g.data).map(|(a, b)| (a * b) as f64).sum();
            let rhs: f64 = x.data.iter().zip(&dx.data).map(|(a, b)| (a * b) as f64).sum();
            assert!((lhs - rhs).abs() < 1e-4 * lhs.abs().max(1.0), "{mode:?}: {lhs} vs {rhs}");
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
                let row = p * h * w + ty.idx[oy * ty.k + a] * w;
                let mut s = 0.0f32;
                for b in 0..tx.k {
                    s += tx.w[ox * tx.k + b] * x.data[row + tx.idx[ox * tx.k + b]];
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
            for a in cy.ptr[iy]..cy.ptr[iy + 1] {
                let row = p * oh * ow + cy.o[a] * ow;
                let mut s = 0.0f32;
                for b in cx.ptr[ix]..cx.ptr[ix + 1] {
                    s += cx.w[b] * dy.data[row + cx.o[b]];
                }
                acc += cy.w[a] * s;
            }
            *out += acc;
        }
    }

    #[test]
    fn gpu_resize_taps_reproduce_the_cpu_reference() {
        let mut rng = TestRng::new(0x9e37_79b9_7f4a_7c15);
        for case in 0..30 {
            let mode = MODES[case % 3];
            let (n, c, h, w) = (rng.range(1, 2), rng.range(1, 3), rng.range(1, 9), rng.range(1, 9));
            let (oh, ow) = if case % 4 == 0 { (rng.range(1, 20), rng.range(1, 20)) } else { (2 * h, 2 * w) };
            let x = rng.tensor(&[n, c, h, w], -1.0, 1.0);
            // Same weights, same summation order as the reference: bitwise equal.
            assert_eq!(
                gather_fwd(&x, oh, ow, mode),
                resize_ref(&x, oh, ow, mode),
                "{mode:?} {:?}→{oh}x{ow}",
                x.shape
            );
            let dy = rng.tensor(&[n, c, oh, ow], -1.0, 1.0);
            let mut a = rng.tensor(&[n, c, h, w], -1.0, 1.0);
            let mut b = a.clone();
            gather_bwd(&dy, mode, &mut a);
            resize_backward_ref(&dy, mode, &mut b);
            let worst = a.max_abs_diff(&b);
            assert!(worst < 1e-5, "{mode:?} {:?}→{oh}x{ow}: backward differs by {worst}", x.shape);
        }
    }
}
