//! Metrics against the HR ground truth: zero for identical meshes, known values for simple
//! motions (translation, scaling, constant offsets), Hausdorff equal to a brute-force search.

use anisocb::eval::metrics::*;
use anisocb::geom::mesh::{border_loop, ring_loop};
use anisocb::geom::GridMesh;
use anisocb::rng::Rng;
use anisocb::Tensor;

fn wavy(w: usize, h: usize, phase: f32) -> GridMesh {
    let mut m = GridMesh::flat(w, h, 1.2, 0.8);
    for p in &mut m.pos {
        p[2] = 0.05 * (7.0 * p[0] + phase).sin() * (3.0 * p[1]).cos();
    }
    m
}

fn moved(m: &GridMesh, f: impl Fn([f32; 3]) -> [f32; 3]) -> GridMesh {
    GridMesh::new(m.w, m.h, m.pos.iter().map(|&p| f(p)).collect())
}

#[test]
fn metrics_are_zero_for_identical_meshes() {
    let frames: Vec<GridMesh> = (0..4).map(|t| wavy(13, 9, t as f32 * 0.3)).collect();
    let s = sequence_metrics(&frames, &frames, None).unwrap();
    for f in &s.per_frame {
        assert_eq!(f.rmse, 0.0);
        assert_eq!(f.boundary_rmse, 0.0);
        assert_eq!(f.hausdorff, 0.0);
        assert_eq!(f.boundary_length_ratio, 1.0);
        assert_eq!(f.area_ratio, 1.0);
        assert!(f.normal_angle_deg < 1e-3, "{}", f.normal_angle_deg);
        assert_eq!(f.curvature_err, 0.0);
    }
    assert_eq!(s.flicker, 0.0);
    assert_eq!(s.flicker_per_step.len(), 3);
}

#[test]
fn translated_sheet_has_known_errors() {
    // A flat sheet moved 0.5 m along its normal: every vertex is 0.5 m off, and the nearest
    // vertex of the other sheet is its twin, so Hausdorff = 0.5 too; shape metrics unchanged.
    let gt = GridMesh::flat(11, 7, 1.0, 0.6);
    let pred = moved(&gt, |p| [p[0], p[1], p[2] + 0.5]);
    let f = frame_metrics(&pred, &gt, &border_mask(11, 7)).unwrap();
    assert!((f.rmse - 0.5).abs() < 1e-6, "{f:?}");
    assert!((f.boundary_rmse - 0.5).abs() < 1e-6, "{f:?}");
    assert!((f.hausdorff - 0.5).abs() < 1e-6, "{f:?}");
    assert!((f.boundary_length_ratio - 1.0).abs() < 1e-6, "{f:?}");
    assert!((f.area_ratio - 1.0).abs() < 1e-6, "{f:?}");
    assert!(f.normal_angle_deg < 1e-3, "{f:?}");
    // In-plane translation by (0.3, 0.4): RMSE is the full 0.5 m.
    let pred = moved(&gt, |p| [p[0] + 0.3, p[1] + 0.4, p[2]]);
    assert!((vertex_rmse(&pred, &gt).unwrap() - 0.5).abs() < 1e-6);
}

#[test]
fn boundary_length_ratio_of_uniformly_scaled_sheet_equals_scale() {
    let gt = wavy(17, 11, 0.4);
    for s in [0.9f32, 0.995, 1.25] {
        let pred = moved(&gt, |p| p.map(|x| s * x));
        let f = frame_metrics(&pred, &gt, &border_mask(17, 11)).unwrap();
        assert!((f.boundary_length_ratio - s).abs() < 1e-5, "scale {s}: {f:?}");
        assert!((f.area_ratio - s * s).abs() < 1e-5, "scale {s}: {f:?}");
    }
    // Flat 2 × 1 sheet: perimeter 6, area 2.
    let m = GridMesh::flat(5, 4, 2.0, 1.0);
    assert!((border_length(&m) - 6.0).abs() < 1e-5);
    assert!((surface_area(&m) - 2.0).abs() < 1e-5);
    assert_eq!(border_loop(5, 4).len(), 2 * (5 + 4) - 4);
}

#[test]
fn ring_loops_partition_the_grid_into_closed_neighbour_to_neighbour_loops() {
    for (w, h) in [(1, 1), (1, 4), (2, 2), (5, 4), (7, 7), (9, 6), (8, 3)] {
        let mut seen = vec![0u8; w * h];
        for r in 0..w.max(h) {
            let l = ring_loop(w, h, r);
            if r == 0 {
                assert_eq!(l, border_loop(w, h));
            }
            for &v in &l {
                seen[v] += 1;
                let (i, j) = (v % w, v / w);
                assert_eq!(i.min(j).min(w - 1 - i).min(h - 1 - j), r, "{w}x{h} ring {r}: vertex {v}");
            }
            // Consecutive vertices (and last → first, where the ring is a real loop: at least
            // 2 × 2) are grid neighbours.
            let step = |a: usize, b: usize| (a % w).abs_diff(b % w) + (a / w).abs_diff(b / w);
            for k in 1..l.len() {
                assert_eq!(step(l[k - 1], l[k]), 1, "{w}x{h} ring {r}: {l:?}");
            }
            if w >= 2 * r + 2 && h >= 2 * r + 2 {
                assert_eq!(step(l[l.len() - 1], l[0]), 1, "{w}x{h} ring {r}: {l:?}");
            }
        }
        assert!(seen.iter().all(|&c| c == 1), "{w}x{h}: every vertex in exactly one ring: {seen:?}");
    }
}

#[test]
fn flicker_is_zero_for_constant_offset_and_equals_velocity_error() {
    let gt: Vec<GridMesh> = (0..5).map(|t| wavy(9, 9, t as f32 * 0.2)).collect();
    let offset: Vec<GridMesh> =
        gt.iter().map(|m| moved(m, |p| [p[0] + 0.1, p[1] - 0.2, p[2] + 0.05])).collect();
    let (steps, all) = flicker(&offset, &gt).unwrap();
    assert!(all < 1e-6 && steps.iter().all(|&s| s < 1e-6), "{steps:?}");
    // A drift of 0.01 m/frame along x that the truth does not have: flicker = 0.01.
    let drift: Vec<GridMesh> =
        gt.iter().enumerate().map(|(t, m)| moved(m, |p| [p[0] + 0.01 * t as f32, p[1], p[2]])).collect();
    let (steps, all) = flicker(&drift, &gt).unwrap();
    assert!((all - 0.01).abs() < 1e-6, "{all}");
    assert!(steps.iter().all(|&s| (s - 0.01).abs() < 1e-6), "{steps:?}");
}

#[test]
fn hausdorff_matches_brute_force_on_random_meshes() {
    let mut rng = Rng::new(42);
    for (w, h) in [(3, 2), (9, 7), (31, 17), (64, 40)] {
        let rand_mesh = |rng: &mut Rng| {
            let mut m = GridMesh::flat(w, h, 1.0, 1.0);
            for p in &mut m.pos {
                *p = [p[0] + 0.3 * rng.uniform(), p[1] + 0.3 * rng.uniform(), 0.5 * rng.uniform()];
            }
            m
        };
        let (a, b) = (rand_mesh(&mut rng), rand_mesh(&mut rng));
        let directed = |x: &GridMesh, y: &GridMesh| {
            x.pos
                .iter()
                .map(|p| {
                    y.pos.iter().map(|q| anisocb::geom::mesh::dist(*p, *q)).fold(f32::INFINITY, f32::min)
                })
                .fold(0.0f32, f32::max)
        };
        // Also a far, unrelated pair (mirrored and shifted), where no early exit helps.
        let far = moved(&b, |p| [p[1] + 0.7, p[0], -p[2]]);
        for (x, y) in [(&a, &b), (&a, &far)] {
            let want = directed(x, y).max(directed(y, x));
            let got = hausdorff(x, y).unwrap();
            assert!((got - want).abs() <= 1e-5 * (1.0 + want), "{w}x{h}: {got} vs brute force {want}");
        }
    }
}

#[test]
fn boundary_rmse_uses_the_given_mask() {
    let gt = GridMesh::flat(4, 3, 1.0, 1.0);
    let mut pred = gt.clone();
    pred.pos[5][2] = 1.0; // interior vertex (1, 1)
    let border = border_mask(4, 3);
    assert!(!border[5] && border[0] && border[11]);
    assert_eq!(border.iter().filter(|&&b| b).count(), 10);
    assert_eq!(masked_rmse(&pred, &gt, &border).unwrap(), 0.0);
    let mut map = Tensor::zeros(&[1, 1, 3, 4]);
    map.data[5] = 1.0;
    map.data[6] = 1.0;
    let mask = mask_from_map(&map, 4, 3, 0.5).unwrap();
    // Two masked vertices, one with error 1: √(1/2).
    assert!((masked_rmse(&pred, &gt, &mask).unwrap() - 0.5f32.sqrt()).abs() < 1e-6);
    assert!(mask_from_map(&map, 3, 4, 0.5).is_err());
}

#[test]
fn sequence_metrics_report_worst_frames_and_json() {
    let gt: Vec<GridMesh> = (0..4).map(|_| GridMesh::flat(5, 5, 1.0, 1.0)).collect();
    let errs = [0.1f32, 0.4, 0.0, 0.2];
    let pred: Vec<GridMesh> =
        gt.iter().zip(errs).map(|(m, e)| moved(m, |p| [p[0], p[1], p[2] + e])).collect();
    let s = sequence_metrics(&pred, &gt, None).unwrap();
    assert_eq!(s.worst_frames(2), vec![1, 3]);
    assert!((s.mean.rmse - 0.175).abs() < 1e-6, "{:?}", s.mean);
    assert!((s.worst.rmse - 0.4).abs() < 1e-6);
    let j = s.to_json();
    assert!(j.starts_with("{\"mean\": {\"rmse\": ") && j.contains("\"flicker_per_step\": ["), "{j}");
    assert!(sequence_metrics(&pred[..2], &gt, None).is_err());
    assert!(vertex_rmse(&GridMesh::flat(3, 3, 1.0, 1.0), &gt[0]).is_err());
}

#[test]
fn mean_curvature_of_a_cylinder_is_half_the_inverse_radius() {
    // A sheet rolled onto a cylinder of radius 0.5 m (half a turn): H = 1/(2r) = 1 /m inside;
    // a flat sheet has H = 0, so the curvature error between them is ≈ 1 /m.
    let r = 0.5f32;
    let flat = GridMesh::flat(41, 11, std::f32::consts::PI * r, 0.5);
    let rolled = moved(&flat, |p| {
        let a = p[0] / r;
        [r * a.sin(), p[1], r * (1.0 - a.cos())]
    });
    let h = mean_curvature(&rolled);
    for j in 1..10 {
        for i in 1..40 {
            let v = rolled.idx(i, j);
            assert!((h[v] - 1.0).abs() < 0.01, "H at ({i}, {j}) = {}", h[v]);
        }
    }
    assert!(mean_curvature(&flat).iter().all(|&x| x.abs() < 1e-6));
    let e = curvature_error(&rolled, &flat).unwrap();
    assert!((e - 1.0).abs() < 0.01, "{e}");
}
