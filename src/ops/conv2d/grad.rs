//! The fast gradients: dx (the forward kernel on flipped, transposed weights) and dW
//! (the `micro_dw` kernel per tap, deterministic partial sums); Winograd where it applies.

use super::*;

/// dx += ∂L/∂x. dy: (N, O, H, W), w: (O, C, KH, KW), dx: (N, C, H, W).
pub fn conv2d_input_grad(w: &Tensor, dy: &Tensor, pad: Padding, dx: &mut Tensor) {
    let (n, o, h, wd) = dy.dims4();
    let (_, c, kh, kw) = w.dims4();
    let (ph, pw) = (kh / 2, kw / 2);
    // Transposed, flipped weights: w'[c][o][ky][kx] = w[o][c][kh−1−ky][kw−1−kx].
    let flipped = |ci: usize, oi: usize, ky: usize, kx: usize| {
        w.data[((oi * c + ci) * kh + kh - 1 - ky) * kw + kw - 1 - kx]
    };
    let wino = winograd::eligible(o, c, kh, kw);
    if pad == Padding::Replicate && wino {
        // The gradient w.r.t. the padded input ((H+2ph) × (W+2pw)) is the zero-padding "same"
        // gradient of dy framed by (ph, pw) zeros, which the Winograd path takes; the frame's
        // pixels are then folded onto the border pixels they replicate.
        let (hp, wp) = (h + 2 * ph, wd + 2 * pw);
        let mut dye = Tensor::zeros(&[n, o, hp, wp]);
        dye.data.par_chunks_mut(hp * wp).zip(dy.data.par_chunks(h * wd)).for_each(|(dst, src)| {
            for (y, row) in src.chunks_exact(wd).enumerate() {
                dst[(y + ph) * wp + pw..][..wd].copy_from_slice(row);
            }
        });
        let mut dxe = Tensor::zeros(&[n, c, hp, wp]);
        conv2d_input_grad(w, &dye, Padding::Zero, &mut dxe);
        dx.data.par_chunks_mut(h * wd).zip(dxe.data.par_chunks(hp * wp)).for_each(|(dst, src)| {
            for (y, row) in src.chunks_exact(wp).enumerate() {
                let dr = &mut dst[(y.saturating_sub(ph)).min(h - 1) * wd..][..wd];
                for (x, v) in row.iter().enumerate() {
                    dr[x.saturating_sub(pw).min(wd - 1)] += v;
                }
            }
        });
        return;
    }
    // Zero padding: the gradient is a "same" correlation of dy, which the Winograd path takes.
    let wino = wino && pad == Padding::Zero;
    let pk = if wino {
        winograd::pack(c, o, winograd::Tile::F2, flipped)
    } else {
        pack_weights(c, o, kh, kw, flipped)
    };
    let opad = pk.opad;
    match pad {
        Padding::Zero => {
            let (dyp, hp, wp) = if wino {
                winograd::pad_input(dy, Padding::Zero, winograd::Tile::F2)
            } else {
                pad_nhwc(dy, ph, pw, Padding::Zero, 0)
            };
            let dxp = SyncPtr(dx.data.as_mut_ptr());
            let sink = move |ni: usize, yy: usize, row: &[f32]| {
                assert!(row.len() >= wd * opad);
                // dx[ni, ·, yy, ·] += the row, moved from channels-last to the planes.
                // SAFETY: row (ni, yy) of every plane is written by this task only; the row
                // holds wd pixels of opad ≥ c floats (asserted), and `at` < c·h·wd − base.
                unsafe {
                    let d = dxp.get().add((ni * c * h + yy) * wd);
                    let f = |v: f32x8, at: usize| v + (d.add(at) as *const f32x8).read_unaligned();
                    let g = |v: f32, at: usize| v + *d.add(at);
                    transpose_map(row.as_ptr(), opad, wd, c, d, h * wd, f, g)
                };
            };
            if wino {
                let input = winograd::Input::Padded { xp: &dyp, hp, wp };
                winograd::correlate(&input, n, o, &pk, winograd::Tile::F2, None, h, wd, &sink);
            } else {
                correlate_rows(&dyp, n, hp, wp, o, kh, kw, &pk, None, h, wd, RowGroups::Single(h), &sink);
            }
        }
        Padding::Replicate => {
            // Gradient w.r.t. the padded input ((H+2ph) × (W+2pw)): a "full" correlation of dy
            // zero-padded by (kh−1, kw−1), folded onto the clamped pixels. One task per dx row
            // r computes every padded row that folds onto r (rows 0..=ph for r = 0, the last
            // ph+1 rows for r = H−1), so the fold writes only row r.
            let (dyq, hq, wq) = pad_nhwc(dy, 2 * ph, 2 * pw, Padding::Zero, 0);
            let (hp, wp) = (h + 2 * ph, wd + 2 * pw);
            let groups: Vec<(usize, usize)> = if h == 1 {
                vec![(0, hp)]
            } else {
                (0..h)
                    .map(|r| match r {
                        0 => (0, ph + 1),
                        r if r == h - 1 => (r + ph, ph + 1),
                        r => (r + ph, 1),
                    })
                    .collect()
            };
            let dxp = SyncPtr(dx.data.as_mut_ptr());
            let sink = move |ni: usize, r: usize, rows: &[f32]| {
                for ci in 0..c {
                    // SAFETY: row (ni, r) of every plane is written by this task only.
                    let drow = unsafe {
                        std::slice::from_raw_parts_mut(dxp.get().add(((ni * c + ci) * h + r) * wd), wd)
                    };
                    for row in rows.chunks_exact(wp * opad) {
                        for (xx, px) in row.chunks_exact(opad).enumerate() {
                            let sx = (xx as isize - pw as isize).clamp(0, wd as isize - 1) as usize;
                            drow[sx] += px[ci];
                        }
                    }
                }
            };
            correlate_rows(&dyq, n, hq, wq, o, kh, kw, &pk, None, hp, wp, RowGroups::List(&groups), &sink);
        }
    }
}

/// Weight gradient of one (input channel, kernel row) for O ≤ [`SMALL_OUT_MAX`] output channels
/// and KW kernel columns, lanes along pixel rows: acc[kx][o] += dy[o](row y, 16 px) ·
/// x(row y + ky, the same 16 px shifted by kx), over every image and row; returns the lane
/// sums. `x` points at (image 0, channel, row ky, column 0) of the padded planar input (row
/// stride `wq`, image stride `xs`); `dy` at (image 0, channel 0, row 0) of dy widened to nv·16
/// columns with zeros (row stride nv·16, channel stride `os`, image stride `ds`).
///
/// # Safety
/// Rows 0..h (+ ky) of n images, columns 0..nv·16 + KW − 1 of `x` and 0..nv·16 of `dy` in bounds.
#[inline(always)]
#[allow(clippy::too_many_arguments, clippy::needless_range_loop)]
pub(super) unsafe fn dw_px<const O: usize, const KW: usize>(
    x: *const f32,
    wq: usize,
    xs: usize,
    dy: *const f32,
    os: usize,
    ds: usize,
    n: usize,
    h: usize,
    nv: usize,
) -> [[f32; O]; KW] {
    let mut acc = [[f32x16::ZERO; O]; KW];
    for ni in 0..n {
        for y in 0..h {
            let xr = x.add(ni * xs + y * wq);
            let dr = dy.add(ni * ds + y * nv * L);
            for v in 0..nv {
                let mut g = [f32x16::ZERO; O];
                for o in 0..O {
                    g[o] = (dr.add(o * os + v * L) as *const f32x16).read_unaligned();
                }
                for kx in 0..KW {
                    let xv = (xr.add(v * L + kx) as *const f32x16).read_unaligned();
                    for o in 0..O {
                        acc[kx][o] = xv.mul_add(g[o], acc[kx][o]);
                    }
                }
            }
        }
    }
    let mut out = [[0.0; O]; KW];
    for kx in 0..KW {
        for o in 0..O {
            out[kx][o] = acc[kx][o].reduce_add();
        }
    }
    out
}

/// dw += ∂L/∂w for o ≤ [`SMALL_OUT_MAX`] and kw ∈ {1, 3, 5} (else returns false and does
/// nothing): one rayon task per (input channel, kernel row), each summing over every pixel in a
/// fixed order ([`dw_px`]), so results do not depend on the thread count.
pub(super) fn conv2d_weight_grad_small_out(x: &Tensor, dy: &Tensor, pad: Padding, dw: &mut Tensor) -> bool {
    let (n, c, h, wd) = x.dims4();
    let (o, _, kh, kw) = dw.dims4();
    if o > SMALL_OUT_MAX || !matches!(kw, 1 | 3 | 5) {
        return false;
    }
    let (ph, pw) = (kh / 2, kw / 2);
    let nv = wd.div_ceil(L);
    let wq = nv * L + kw - 1;
    let (xp, hp) = pad_planar(x, ph, pw, pad, wq);
    let rw = nv * L;
    let mut dyq = Scratch::zeroed(n * o * h * rw);
    dyq.par_chunks_mut(rw)
        .enumerate()
        .for_each(|(r, dst)| dst[..wd].copy_from_slice(&dy.data[r * wd..][..wd]));
    let sums: Vec<Vec<f32>> = (0..c * kh)
        .into_par_iter()
        .map(|task| {
            let (ci, ky) = (task / kh, task % kh);
            // SAFETY: image ni, channel ci, rows ky..ky+h ≤ hp, columns < nv·16 + kw − 1 = wq of
            // xp; dyq holds n·o·h rows of nv·16 floats.
            unsafe {
                let xptr = xp.as_ptr().add((ci * hp + ky) * wq);
                let (xs, os, ds, dyp) = (c * hp * wq, h * rw, o * h * rw, dyq.as_ptr());
                macro_rules! run {
                    ($o:literal, $kw:literal) => {
                        dw_px::<$o, $kw>(xptr, wq, xs, dyp, os, ds, n, h, nv)
                            .iter()
                            .flatten()
                            .copied()
                            .collect()
                    };
                }
                match (o, kw) {
                    (1, 1) => run!(1, 1),
                    (1, 3) => run!(1, 3),
                    (1, _) => run!(1, 5),
                    (2, 1) => run!(2, 1),
                    (2, 3) => run!(2, 3),
                    (2, _) => run!(2, 5),
                    (3, 1) => run!(3, 1),
                    (3, 3) => run!(3, 3),
                    (3, _) => run!(3, 5),
                    (_, 1) => run!(4, 1),
                    (_, 3) => run!(4, 3),
                    _ => run!(4, 5),
                }
            }
        })
        .collect();
    // sums[(ci, ky)] = [kx][o]
    for (task, v) in sums.iter().enumerate() {
        let (ci, ky) = (task / kh, task % kh);
        for kx in 0..kw {
            for oi in 0..o {
                dw.data[((oi * c + ci) * kh + ky) * kw + kx] += v[kx * o + oi];
            }
        }
    }
    true
}

/// Σ of equal-length partial sums, added in their order (contiguous, vectorised, in parallel
/// over 4096-float chunks): the same bits for any thread count. None if there are none.
pub(super) fn sum_partials(partials: Vec<Scratch>) -> Option<Scratch> {
    let mut partials = partials.into_iter();
    let mut sum = partials.next()?;
    let rest: Vec<Scratch> = partials.collect();
    sum.par_chunks_mut(4096).enumerate().for_each(|(i, dst)| {
        for p in &rest {
            for (d, v) in dst.iter_mut().zip(&p[i * 4096..]) {
                *d += v;
            }
        }
    });
    Some(sum)
}

/// Pixels per inner block of the weight gradient (dy and x blocks stay in L1/L2).
pub(super) const DW_SUB: usize = 128;

/// dw += ∂L/∂w, accumulated over all pixels per tap with the [`micro_dw`] kernel:
/// dW[:, :, ky, kx] += Σ_g dYg[g] ⊗ Xp[g + ky·Wp + kx], where g = (n·Hp + y)·Wp + x runs over the
/// padded pixel grid of the rows y < H (dYg, dy on that grid, is zero where x ≥ W). The pixels
/// are cut into a fixed number of parts (from the problem size, not the thread count), each
/// summed into its own partial dW; the partials are added in a fixed order (deterministic).
/// x: (N, C, H, W), dy: (N, O, H, W), dw: (O, C, KH, KW).
pub fn conv2d_weight_grad(x: &Tensor, dy: &Tensor, pad: Padding, dw: &mut Tensor) {
    if conv2d_weight_grad_small_out(x, dy, pad, dw) {
        return;
    }
    let (o, c, kh, kw) = dw.dims4();
    if winograd::eligible_weight_grad(c, o, kh, kw) {
        return winograd::weight_grad(x, dy, pad, dw);
    }
    let (n, _, h, wd) = x.dims4();
    let (ph, pw) = (kh / 2, kw / 2);
    let (hp, wp) = (h + 2 * ph, wd + 2 * pw);
    let extra = (kh - 1) * wp + (kw - 1);
    let (xp, _, _) = pad_nhwc(x, ph, pw, pad, extra);
    let opad = o.div_ceil(L) * L;
    // dy on the padded grid, channels last (rows y ≥ H are never read).
    let mut dyg = Scratch::zeroed(n * hp * wp * opad);
    dyg.par_chunks_mut(wp * opad).enumerate().for_each(|(r, dst)| {
        let (ni, yy) = (r / hp, r % hp);
        if yy >= h {
            return;
        }
        for oi in 0..o {
            let src = &dy.data[((ni * o + oi) * h + yy) * wd..][..wd];
            for (xx, v) in src.iter().enumerate() {
                dst[xx * opad + oi] = *v;
            }
        }
    });
    // Pixel segments: the rows y < H of each image, cut into ≤ DW_SUB-pixel blocks.
    let blocks: Vec<(usize, usize)> =
        (0..n).flat_map(|ni| tiles(h * wp, DW_SUB).map(move |(s, l)| (ni * hp * wp + s, l))).collect();
    // At least 4 parts (load balance on small images), at most 16 (memory for partials).
    let parts = (n * h * wp).div_ceil(2048).clamp(4, 16).min(blocks.len());
    let taps = kh * kw;
    let oblocks: Vec<(usize, usize)> =
        (0..opad).step_by(OB).map(|ob| (ob, ((opad - ob) / L).min(OB / L))).collect();
    let partials: Vec<Scratch> = (0..parts)
        .into_par_iter()
        .map(|pi| {
            let mut part = Scratch::zeroed(taps * c * opad);
            let (b0, b1) = (blocks.len() * pi / parts, blocks.len() * (pi + 1) / parts);
            for &(g0, len) in &blocks[b0..b1] {
                for t in 0..taps {
                    let off = (t / kw) * wp + t % kw;
                    for &(ob, ov) in &oblocks {
                        for (c0, np, j0, ot) in reg_tiles(c, ov) {
                            // SAFETY: pixels g0+off .. g0+off+len of xp (len ≤ N·Hp·Wp + extra
                            // by construction), pixels g0 .. g0+len of dyg, and channels
                            // c0..c0+np, ob+16·j0..ob+16·(j0+ot) of the partial are in bounds.
                            unsafe {
                                let xptr = xp.as_ptr().add((g0 + off) * c + c0);
                                let dptr = dyg.as_ptr().add(g0 * opad + ob + j0 * L);
                                let aptr = part.as_mut_ptr().add((t * c + c0) * opad + ob + j0 * L);
                                match ot {
                                    4 => dispatch_p!(micro_dw, 4, np, xptr, c, dptr, opad, len, aptr, opad),
                                    3 => dispatch_p!(micro_dw, 3, np, xptr, c, dptr, opad, len, aptr, opad),
                                    2 => dispatch_p!(micro_dw, 2, np, xptr, c, dptr, opad, len, aptr, opad),
                                    _ => dispatch_p!(micro_dw, 1, np, xptr, c, dptr, opad, len, aptr, opad),
                                }
                            }
                        }
                    }
                }
            }
            part
        })
        .collect();
    // Fixed-order sum of the partials, then scatter into dw (OIHW).
    let Some(sum) = sum_partials(partials) else {
        return;
    };
    for t in 0..taps {
        for ci in 0..c {
            let src = &sum[(t * c + ci) * opad..][..o];
            for (oi, v) in src.iter().enumerate() {
                dw.data[(oi * c + ci) * taps + t] += v;
            }
        }
    }
}
