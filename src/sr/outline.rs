//! The outline floor ([`super::params::UpscaleParams::keep_outline`]): the HR border never shorter
//! than the LR frame's own border polyline, in the nets' (cloth) frame.

use crate::geom::mesh::{closed_loop_length, ring_vertices};
use crate::geom::vec3::{cross, dot, norm, sub};
use crate::pool;
use crate::tensor::Tensor;
use std::borrow::Borrow;

/// Length of the closed loop through pixels `ring` of one planar image `img` (3 × px):
/// `Σ_k |p_{k+1} − p_k|`, the last back to the first. `ring`: a list of pixels or
/// [`ring_vertices`].
pub fn loop_length<I: IntoIterator<Item: Borrow<usize>>>(img: &[f32], ring: I) -> f32 {
    loop_length_blend(img, img, 1.0, ring)
}

/// [`loop_length`] of `base + a (hr − base)` (planar 3 × px images), accumulated in f64.
fn loop_length_blend<I: IntoIterator<Item: Borrow<usize>>>(hr: &[f32], base: &[f32], a: f32, ring: I) -> f32 {
    let px = hr.len() / 3;
    let at = |v: usize| -> [f64; 3] {
        std::array::from_fn(|c| (base[c * px + v] + a * (hr[c * px + v] - base[c * px + v])) as f64)
    };
    closed_loop_length(ring, at) as f32
}

/// What the outline floor scales toward: `hr` (planar 3 × rH × rW, composed over the
/// interpolation `u`) with, on the two outermost rings, the component of the correction
/// hr − u along U's surface normal removed. U's normal at a pixel is the cross product of its
/// grid derivatives (central differences, one-sided at the border); where it is degenerate
/// nothing is removed. The normal component is what flattens a hem's folds; the in-plane
/// part of the correction, which places the border, is kept. A pooled buffer ([`pool::give`] it
/// back).
pub fn outline_base(hr: &[f32], u: &[f32], hh: usize, hw: usize) -> Vec<f32> {
    let px = hh * hw;
    let at = |img: &[f32], v: usize| -> [f32; 3] { std::array::from_fn(|c| img[c * px + v]) };
    let mut base = pool::take(hr.len());
    base.clear();
    base.extend_from_slice(hr);
    for r in 0..2 {
        for v in ring_vertices(hw, hh, r) {
            let (x, y) = (v % hw, v / hw);
            let (x0, x1) = (y * hw + x.saturating_sub(1), y * hw + (x + 1).min(hw - 1));
            let (y0, y1) = (y.saturating_sub(1) * hw + x, (y + 1).min(hh - 1) * hw + x);
            let n = cross(sub(at(u, x1), at(u, x0)), sub(at(u, y1), at(u, y0)));
            let len = norm(n);
            if len.is_nan() || len <= 1e-12 {
                continue;
            }
            let n = n.map(|c| c / len);
            let d = dot(sub(at(hr, v), at(u, v)), n);
            for c in 0..3 {
                base[c * px + v] -= d * n[c];
            }
        }
    }
    base
}

/// The outline floor's weight for one frame: the largest α ∈ [0, 1] (to 2⁻²⁰, by bisection)
/// whose border loop `ring` ([`crate::geom::mesh::border_loop`] of the rW × rH grid) of `base + α (hr − base)`
/// (planar 3 × rH × rW images; `base` from [`outline_base`]) is at least `floor` long; 1 if `hr`'s already is, 0 if not even `base`'s.
pub fn outline_weight<I>(hr: &[f32], base: &[f32], ring: I, floor: f32) -> f32
where
    I: IntoIterator<Item: Borrow<usize>> + Clone,
{
    let len = |a: f32| loop_length_blend(hr, base, a, ring.clone());
    if len(1.0) >= floor {
        return 1.0;
    }
    if len(0.0) < floor {
        return 0.0;
    }
    // len(lo) ≥ floor > len(hi) throughout.
    let (mut lo, mut hi) = (0.0f32, 1.0f32);
    for _ in 0..20 {
        let mid = 0.5 * (lo + hi);
        if len(mid) >= floor {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

/// `hr ← base + w (hr − base)` with w = α on the border ring of the planar 3 × rH × rW images
/// and (1 + α)/2 on the ring inside it (no step between the two rings and the interior's full
/// weight).
pub fn blend_outer_rings(hr: &mut [f32], base: &[f32], hh: usize, hw: usize, a: f32) {
    let px = hh * hw;
    for (r, w) in [(0, a), (1, 0.5 * (1.0 + a))] {
        for v in ring_vertices(hw, hh, r) {
            for c in 0..3 {
                let i = c * px + v;
                hr[i] = base[i] + w * (hr[i] - base[i]);
            }
        }
    }
}

/// Set the border pixels of every (N, 1, H, W) map to `v`.
pub fn set_border(map: &mut Tensor, v: f32) {
    let (n, c, h, w) = map.dims4();
    for plane in map.data.chunks_exact_mut(h * w).take(n * c) {
        for x in 0..w {
            plane[x] = v;
            plane[(h - 1) * w + x] = v;
        }
        for y in 0..h {
            plane[y * w] = v;
            plane[y * w + w - 1] = v;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::mesh::border_loop;

    /// A flat `w × h` grid (planar 3 × h × w image) with spacing 1, its border ring pulled
    /// toward the centre by `pull` (a shorter outline).
    fn flat_with_border_pulled(w: usize, h: usize, pull: f32) -> Vec<f32> {
        let px = w * h;
        let mut img = vec![0.0f32; 3 * px];
        let (cx, cy) = ((w - 1) as f32 / 2.0, (h - 1) as f32 / 2.0);
        for j in 0..h {
            for i in 0..w {
                let border = i == 0 || j == 0 || i == w - 1 || j == h - 1;
                let s = if border { 1.0 - pull } else { 1.0 };
                img[j * w + i] = cx + s * (i as f32 - cx);
                img[px + j * w + i] = cy + s * (j as f32 - cy);
            }
        }
        img
    }

    #[test]
    fn outline_weight_is_the_largest_blend_whose_border_reaches_the_floor() {
        let (w, h) = (9, 7);
        let ring = border_loop(w, h);
        let u = flat_with_border_pulled(w, h, 0.0);
        let hr = flat_with_border_pulled(w, h, 0.1); // 10 % shorter outline
        let (lu, lh) = (loop_length(&u, &ring), loop_length(&hr, &ring));
        assert!((lu - 2.0 * (8.0 + 6.0)).abs() < 1e-5 && (lh - 0.9 * lu).abs() < 1e-4, "{lu} {lh}");
        // Long enough already: 1; not even U: 0; in between: where the length crosses the floor.
        assert_eq!(outline_weight(&hr, &u, &ring, lh), 1.0);
        assert_eq!(outline_weight(&hr, &u, &ring, 1.01 * lu), 0.0);
        let floor = 0.95 * lu;
        let a = outline_weight(&hr, &u, &ring, floor);
        let len = |a: f32| loop_length_blend(&hr, &u, a, &ring);
        assert!(len(a) >= floor && len(a + 1e-5) < floor, "α = {a}: {} vs floor {floor}", len(a));
        assert!((a - 0.5).abs() < 1e-4, "the outline shrinks linearly with α here: α = {a}");
    }

    #[test]
    fn outline_base_removes_only_the_normal_part_of_the_correction_on_two_rings() {
        // U: the flat grid z = 0 (normal ±z everywhere); hr: U moved in x, y and z everywhere.
        let (w, h) = (9, 8);
        let px = w * h;
        let u = flat_with_border_pulled(w, h, 0.0);
        let mut hr = u.clone();
        for v in 0..px {
            hr[v] += 0.1 + 0.01 * v as f32;
            hr[px + v] -= 0.2;
            hr[2 * px + v] += 0.3 + 0.02 * (v % 5) as f32;
        }
        let base = outline_base(&hr, &u, h, w);
        for v in 0..px {
            let (i, j) = (v % w, v / w);
            let outer = i.min(j).min(w - 1 - i).min(h - 1 - j) < 2;
            assert_eq!([base[v], base[px + v]], [hr[v], hr[px + v]], "in-plane part kept at ({i}, {j})");
            let want_z = if outer { u[2 * px + v] } else { hr[2 * px + v] };
            assert!(
                (base[2 * px + v] - want_z).abs() < 1e-6,
                "({i}, {j}): z {} vs {want_z}",
                base[2 * px + v]
            );
        }
    }

    #[test]
    fn blend_outer_rings_scales_the_correction_on_two_rings_only() {
        let (w, h, a) = (8, 6, 0.25f32);
        let u = vec![1.0f32; 3 * w * h];
        let mut hr: Vec<f32> = (0..3 * w * h).map(|k| 1.0 + (k % 7) as f32).collect();
        let before = hr.clone();
        blend_outer_rings(&mut hr, &u, h, w, a);
        for c in 0..3 {
            for j in 0..h {
                for i in 0..w {
                    let k = c * w * h + j * w + i;
                    let want = match i.min(j).min(w - 1 - i).min(h - 1 - j) {
                        0 => 1.0 + a * (before[k] - 1.0),
                        1 => 1.0 + 0.5 * (1.0 + a) * (before[k] - 1.0),
                        _ => before[k],
                    };
                    assert!((hr[k] - want).abs() < 1e-6, "({c}, {j}, {i}): {} vs {want}", hr[k]);
                }
            }
        }
    }
}
