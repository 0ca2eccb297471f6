//! The scalar reference convolution, forward and backward: the contract every fast kernel
//! is tested against (tests/conv_fast_vs_ref.rs), and the padding rule they share.

use crate::tensor::Tensor;

/// How pixels outside the image are read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Padding {
    /// Outside pixels are 0 (PyTorch `padding_mode="zeros"`).
    Zero,
    /// Outside pixels repeat the nearest border pixel (PyTorch `padding_mode="replicate"`).
    Replicate,
}

/// Source index for a padded coordinate, or None where zero padding reads a 0.
#[inline]
pub fn pad_index(p: isize, n: usize, pad: Padding) -> Option<usize> {
    if p >= 0 && (p as usize) < n {
        Some(p as usize)
    } else {
        match pad {
            Padding::Zero => None,
            Padding::Replicate => Some(p.clamp(0, n as isize - 1) as usize),
        }
    }
}

/// Reference forward: the spec. y = b + Σ_c Σ_taps w · x(shifted).
pub fn conv2d_ref(x: &Tensor, w: &Tensor, b: Option<&Tensor>, pad: Padding) -> Tensor {
    let (n, c, h, wd) = x.dims4();
    let (o, c2, kh, kw) = w.dims4();
    assert_eq!(c, c2, "conv2d: x has {c} channels, weight expects {c2}");
    assert!(kh % 2 == 1 && kw % 2 == 1, "conv2d: odd kernels only, got {kh}x{kw}");
    let (ph, pw) = ((kh / 2) as isize, (kw / 2) as isize);
    let mut y = Tensor::zeros(&[n, o, h, wd]);
    for ni in 0..n {
        for oi in 0..o {
            for yy in 0..h {
                for xx in 0..wd {
                    let mut acc = b.map_or(0.0, |b| b.data[oi]);
                    for ci in 0..c {
                        for ky in 0..kh {
                            let Some(sy) = pad_index(yy as isize + ky as isize - ph, h, pad) else {
                                continue;
                            };
                            for kx in 0..kw {
                                let Some(sx) = pad_index(xx as isize + kx as isize - pw, wd, pad) else {
                                    continue;
                                };
                                acc += w.data[w.idx4(oi, ci, ky, kx)] * x.data[x.idx4(ni, ci, sy, sx)];
                            }
                        }
                    }
                    let i = y.idx4(ni, oi, yy, xx);
                    y.data[i] = acc;
                }
            }
        }
    }
    y
}

/// Reference backward. Adds into `dx` (if given), `dw` and `db` (if given).
/// dy: (N, O, H, W); dx like x; dw like w; db: (O).
pub fn conv2d_backward_ref(
    x: &Tensor,
    w: &Tensor,
    dy: &Tensor,
    pad: Padding,
    dx: Option<&mut Tensor>,
    dw: &mut Tensor,
    db: Option<&mut Tensor>,
) {
    let (n, c, h, wd) = x.dims4();
    let (o, _, kh, kw) = w.dims4();
    let (ph, pw) = ((kh / 2) as isize, (kw / 2) as isize);
    let mut dx = dx;
    for ni in 0..n {
        for oi in 0..o {
            for yy in 0..h {
                for xx in 0..wd {
                    let g = dy.data[dy.idx4(ni, oi, yy, xx)];
                    for ci in 0..c {
                        for ky in 0..kh {
                            let Some(sy) = pad_index(yy as isize + ky as isize - ph, h, pad) else {
                                continue;
                            };
                            for kx in 0..kw {
                                let Some(sx) = pad_index(xx as isize + kx as isize - pw, wd, pad) else {
                                    continue;
                                };
                                let xi = x.idx4(ni, ci, sy, sx);
                                let wi = w.idx4(oi, ci, ky, kx);
                                dw.data[wi] += g * x.data[xi];
                                if let Some(dx) = dx.as_deref_mut() {
                                    dx.data[xi] += g * w.data[wi];
                                }
                            }
                        }
                    }
                }
            }
        }
    }
    if let Some(db) = db {
        for ni in 0..n {
            for oi in 0..o {
                let s: f32 = (0..h * wd).map(|k| dy.data[(ni * o + oi) * h * wd + k]).sum();
                db.data[oi] += s;
            }
        }
    }
}
