//! The grid's geometry losses GeometryNet trains with besides the MSE: on the grid's edges
//! ([`edge_mse`]), their lengths ([`edge_length_mse`]) and the Laplacian ([`laplacian_mse`]);
//! each with its scalar `_ref` twin (the detail energy is in [`super::detail`]). Conventions as in [`super`]: (mean loss, gradient w.r.t. the prediction), sums
//! in f64.

use super::check;
use crate::tensor::Tensor;

/// Edge-vector error (first differences): with `D = pred − target` (N, C, H, W),
/// `mean over the grid's edges of (D[y, x+1] − D[y, x])²` (H·(W−1) row edges and (H−1)·W
/// column edges per channel) and its gradient w.r.t. pred. On a geometry image this is the
/// error of every edge vector of the mesh: it punishes what MSE barely sees, the
/// pixel-to-pixel noise that makes edge lengths swim and normals flicker. Plain loops: the
/// HR patches it runs on are small (not a hot path); the sum is in f64. [`Cpu`](super::Cpu)'s
/// path of [`Ops::edge_mse`](super::Ops::edge_mse); its spec is [`edge_mse_ref`].
pub fn edge_mse(pred: &Tensor, target: &Tensor) -> (f32, Tensor) {
    check(pred, target, "edge_mse");
    let (n, c, h, w) = pred.dims4();
    let count = (n * c * (h * w.saturating_sub(1) + h.saturating_sub(1) * w)).max(1);
    let mut g = Tensor::zeros(&pred.shape);
    let mut sum = 0.0f64;
    let d = |i: usize| pred.data[i] - target.data[i];
    for plane in 0..n * c {
        let base = plane * h * w;
        for y in 0..h {
            for x in 0..w {
                let i = base + y * w + x;
                for j in [(x + 1 < w).then_some(i + 1), (y + 1 < h).then_some(i + w)].into_iter().flatten() {
                    let e = d(j) - d(i);
                    sum += (e as f64) * (e as f64);
                    let ge = 2.0 * e / count as f32;
                    g.data[j] += ge;
                    g.data[i] -= ge;
                }
            }
        }
    }
    ((sum / count as f64) as f32, g)
}
/// The spec of [`edge_mse`], written pixel by pixel: each pixel's gradient is gathered from the
/// (up to four) grid edges that touch it, `+e` from an edge that ends there and `−e` from one
/// that starts there, where [`edge_mse`] scatters each edge into its two ends. Same loss and
/// count; agrees to rounding.
pub fn edge_mse_ref(pred: &Tensor, target: &Tensor) -> (f32, Tensor) {
    check(pred, target, "edge_mse");
    let (n, c, h, w) = pred.dims4();
    let count = (n * c * (h * w.saturating_sub(1) + h.saturating_sub(1) * w)).max(1);
    let d = |p: usize, y: usize, x: usize| {
        let i = (p * h + y) * w + x;
        pred.data[i] - target.data[i]
    };
    // Errors of the edges (y, x) → (y, x + 1) and (y, x) → (y + 1, x); 0 past the grid.
    let right = |p: usize, y: usize, x: usize| if x + 1 < w { d(p, y, x + 1) - d(p, y, x) } else { 0.0 };
    let down = |p: usize, y: usize, x: usize| if y + 1 < h { d(p, y + 1, x) - d(p, y, x) } else { 0.0 };
    let mut g = Tensor::zeros(&pred.shape);
    let mut sum = 0.0f64;
    for p in 0..n * c {
        for y in 0..h {
            for x in 0..w {
                let (er, ed) = (right(p, y, x), down(p, y, x));
                sum += (er as f64) * (er as f64) + (ed as f64) * (ed as f64);
                let el = if x > 0 { right(p, y, x - 1) } else { 0.0 };
                let eu = if y > 0 { down(p, y - 1, x) } else { 0.0 };
                g.data[(p * h + y) * w + x] = 2.0 * (el + eu - er - ed) / count as f32;
            }
        }
    }
    ((sum / count as f64) as f32, g)
}

/// Edge-length error: with the C channels of a pixel as a point (xyz on a geometry image),
/// `mean over the grid's edges of (|P[j] − P[i]| − |T[j] − T[i]|)²` (H·(W−1) row edges and
/// (H−1)·W column edges per image, N images) and its gradient w.r.t. pred; an edge of pred with
/// zero length gets no gradient. [`edge_mse`] already holds the error of each edge vector, but
/// a net that cannot place a wrinkle averages its possible phases, and the average of tilted
/// edge vectors is shorter: the mesh contracts in its plane (area 2–3 % below the truth on a
/// twisted strip, outlines shrinking on cloth from another solver). This term prices the
/// shortening itself. Plain loops, f64 sum (small patches). [`Cpu`](super::Cpu)'s path of
/// [`Ops::edge_length_mse`](super::Ops::edge_length_mse); its spec is [`edge_length_mse_ref`].
pub fn edge_length_mse(pred: &Tensor, target: &Tensor) -> (f32, Tensor) {
    check(pred, target, "edge_length_mse");
    let (n, c, h, w) = pred.dims4();
    let count = (n * (h * w.saturating_sub(1) + h.saturating_sub(1) * w)).max(1);
    let (px, scale) = (h * w, 2.0 / count as f32);
    let mut g = Tensor::zeros(&pred.shape);
    let mut sum = 0.0f64;
    for img in 0..n {
        let base = img * c * px;
        let (p, t) = (&pred.data[base..base + c * px], &target.data[base..base + c * px]);
        let gi = &mut g.data[base..base + c * px];
        let len = |v: &[f32], a: usize, b: usize| {
            (0..c).map(|k| (v[k * px + b] - v[k * px + a]).powi(2)).sum::<f32>().sqrt()
        };
        for y in 0..h {
            for x in 0..w {
                let a = y * w + x;
                for b in [(x + 1 < w).then_some(a + 1), (y + 1 < h).then_some(a + w)].into_iter().flatten() {
                    let (lp, lt) = (len(p, a, b), len(t, a, b));
                    let e = lp - lt;
                    sum += (e as f64) * (e as f64);
                    if lp > 0.0 {
                        let k = scale * e / lp;
                        for ch in 0..c {
                            let d = k * (p[ch * px + b] - p[ch * px + a]);
                            gi[ch * px + b] += d;
                            gi[ch * px + a] -= d;
                        }
                    }
                }
            }
        }
    }
    ((sum / count as f64) as f32, g)
}
/// The spec of [`edge_length_mse`], written pixel by pixel: each pixel's gradient is gathered
/// from the (up to four) grid edges that touch it, `+k·(P[b] − P[a])` at the edge's end b and
/// `−k·(…)` at its start a, k = 2·e / (count·|P[b] − P[a]|), 0 for a zero-length edge of pred.
/// Agrees with [`edge_length_mse`] to rounding.
pub fn edge_length_mse_ref(pred: &Tensor, target: &Tensor) -> (f32, Tensor) {
    check(pred, target, "edge_length_mse");
    let (n, c, h, w) = pred.dims4();
    let count = (n * (h * w.saturating_sub(1) + h.saturating_sub(1) * w)).max(1);
    let at = |img: usize, ch: usize, y: usize, x: usize| ((img * c + ch) * h + y) * w + x;
    let length = |v: &Tensor, img: usize, a: (usize, usize), b: (usize, usize)| {
        let mut s = 0.0f32;
        for ch in 0..c {
            let e = v.data[at(img, ch, b.0, b.1)] - v.data[at(img, ch, a.0, a.1)];
            s += e * e;
        }
        s.sqrt()
    };
    // Of the edge a → b: (length error e, pred's length).
    let edge = |img: usize, a: (usize, usize), b: (usize, usize)| {
        let lp = length(pred, img, a, b);
        (lp - length(target, img, a, b), lp)
    };
    let mut g = Tensor::zeros(&pred.shape);
    let mut sum = 0.0f64;
    for img in 0..n {
        for y in 0..h {
            for x in 0..w {
                let me = (y, x);
                // The edges touching this pixel: (start, end); each edge's loss is counted at
                // its start (the right and down edges).
                let mut edges = Vec::with_capacity(4);
                if x + 1 < w {
                    edges.push((me, (y, x + 1)));
                }
                if y + 1 < h {
                    edges.push((me, (y + 1, x)));
                }
                for &e in &edges {
                    let (err, _) = edge(img, e.0, e.1);
                    sum += (err as f64) * (err as f64);
                }
                if x > 0 {
                    edges.push(((y, x - 1), me));
                }
                if y > 0 {
                    edges.push(((y - 1, x), me));
                }
                for (a, b) in edges {
                    let (err, lp) = edge(img, a, b);
                    if lp > 0.0 {
                        let sign = if b == me { 1.0 } else { -1.0 };
                        for ch in 0..c {
                            let dv = pred.data[at(img, ch, b.0, b.1)] - pred.data[at(img, ch, a.0, a.1)];
                            g.data[at(img, ch, y, x)] += sign * 2.0 * err * dv / (count as f32 * lp);
                        }
                    }
                }
            }
        }
    }
    ((sum / count as f64) as f32, g)
}

/// Curvature error (second differences): with `D = pred − target` (N, C, H, W) and the
/// 5-point Laplacian `ΔD[y, x] = D[y−1, x] + D[y+1, x] + D[y, x−1] + D[y, x+1] − 4 D[y, x]` at
/// the (H−2)·(W−2) interior pixels, `mean over them and the channels of (ΔD)²`, and its
/// gradient w.r.t. pred (0 for grids under 3×3). On a geometry image ΔD is the error of the
/// discrete mean-curvature normal: what shows in shading as bumps and dents that are not in
/// the truth, and what MSE and the edge term weigh least. Plain loops, f64 sum (small patches).
/// [`Cpu`](super::Cpu)'s path of [`Ops::laplacian_mse`](super::Ops::laplacian_mse); its spec is
/// [`laplacian_mse_ref`].
pub fn laplacian_mse(pred: &Tensor, target: &Tensor) -> (f32, Tensor) {
    check(pred, target, "laplacian_mse");
    let (n, c, h, w) = pred.dims4();
    let mut g = Tensor::zeros(&pred.shape);
    if h < 3 || w < 3 {
        return (0.0, g);
    }
    let count = n * c * (h - 2) * (w - 2);
    let mut sum = 0.0f64;
    let d = |i: usize| pred.data[i] - target.data[i];
    for plane in 0..n * c {
        let base = plane * h * w;
        for y in 1..h - 1 {
            for x in 1..w - 1 {
                let i = base + y * w + x;
                let l = d(i - w) + d(i + w) + d(i - 1) + d(i + 1) - 4.0 * d(i);
                sum += (l as f64) * (l as f64);
                let gl = 2.0 * l / count as f32;
                for j in [i - w, i + w, i - 1, i + 1] {
                    g.data[j] += gl;
                }
                g.data[i] -= 4.0 * gl;
            }
        }
    }
    ((sum / count as f64) as f32, g)
}
/// The spec of [`laplacian_mse`], written pixel by pixel: with `L = ΔD` at the interior pixels
/// and 0 on the border, the gradient is `2/count · ΔL` (the 5-point stencil is symmetric, so
/// it is its own transpose), gathered at each pixel where [`laplacian_mse`] scatters each
/// stencil into its five pixels. Agrees to rounding.
pub fn laplacian_mse_ref(pred: &Tensor, target: &Tensor) -> (f32, Tensor) {
    check(pred, target, "laplacian_mse");
    let (n, c, h, w) = pred.dims4();
    let mut g = Tensor::zeros(&pred.shape);
    if h < 3 || w < 3 {
        return (0.0, g);
    }
    let count = n * c * (h - 2) * (w - 2);
    let d = |p: usize, y: usize, x: usize| {
        let i = (p * h + y) * w + x;
        pred.data[i] - target.data[i]
    };
    // ΔD at (y, x) if it is interior, else 0 (signed coordinates: the stencil of a border
    // pixel reaches one step outside).
    let lap = |p: usize, y: isize, x: isize| {
        if y < 1 || x < 1 || y > h as isize - 2 || x > w as isize - 2 {
            return 0.0;
        }
        let (y, x) = (y as usize, x as usize);
        d(p, y - 1, x) + d(p, y + 1, x) + d(p, y, x - 1) + d(p, y, x + 1) - 4.0 * d(p, y, x)
    };
    let mut sum = 0.0f64;
    for p in 0..n * c {
        for y in 0..h as isize {
            for x in 0..w as isize {
                let l = lap(p, y, x);
                sum += (l as f64) * (l as f64);
                let around = lap(p, y - 1, x) + lap(p, y + 1, x) + lap(p, y, x - 1) + lap(p, y, x + 1);
                g.data[(p * h + y as usize) * w + x as usize] = 2.0 * (around - 4.0 * l) / count as f32;
            }
        }
    }
    ((sum / count as f64) as f32, g)
}
