//! Properties of the ground-truth boundary and enhance maps.

use anisocb::geom::anisotropy::{boundary_map, BoundaryParams};
use anisocb::geom::geometry_image::mesh_to_image;
use anisocb::geom::vec3::{cross, dot, normalize_or};
use anisocb::geom::Domain;
use anisocb::geom::GridMesh;
use anisocb::imgproc::{enhance_map, CannyParams};

/// A `w × h` sheet folded about the column `i = fold` by `angle` degrees (0 = flat).
fn folded(w: usize, h: usize, fold: usize, angle: f32) -> GridMesh {
    let mut m = GridMesh::flat(w, h, 1.0, h as f32 / w as f32);
    let x0 = m.pos[fold][0];
    let (s, c) = angle.to_radians().sin_cos();
    for p in m.pos.iter_mut() {
        let dx = p[0] - x0;
        if dx > 0.0 {
            p[0] = x0 + dx * c;
            p[2] = dx * s;
        }
    }
    m
}

fn rotate(m: &GridMesh, axis: [f32; 3], angle: f32, shift: [f32; 3]) -> GridMesh {
    let k = normalize_or(axis, axis);
    let (s, c) = angle.sin_cos();
    let pos = m
        .pos
        .iter()
        .map(|v| {
            // Rodrigues: v c + (k × v) s + k (k·v)(1 − c)
            let (kv, cr) = (dot(k, *v), cross(k, *v));
            std::array::from_fn(|q| v[q] * c + cr[q] * s + k[q] * kv * (1.0 - c) + shift[q])
        })
        .collect();
    GridMesh::new(m.w, m.h, pos)
}

#[test]
fn flat_sheet_boundary_map_is_exactly_its_border() {
    for (w, h) in [(12, 10), (33, 17), (64, 64)] {
        let rest = GridMesh::flat(w, h, 1.3, 0.9);
        let d = rest.longest_edge();
        for m in [rest.clone(), rotate(&rest, [0.3, -1.0, 0.7], 0.9, [5.0, -2.0, 1.5])] {
            let b = boundary_map(&m, d, &BoundaryParams::default()).unwrap();
            for j in 0..h {
                for i in 0..w {
                    let v = m.idx(i, j);
                    assert_eq!(b.mask[v] == 1, m.is_border(i, j), "{w}x{h} ({i},{j}) ratio {}", b.ratio[v]);
                }
            }
        }
    }
}

#[test]
fn sharp_fold_lights_up_the_fold_line() {
    let (w, h, fold) = (32, 20, 15);
    let rest = GridMesh::flat(w, h, 1.0, h as f32 / w as f32);
    let d = rest.longest_edge();
    let m = folded(w, h, fold, 120.0);
    let b = boundary_map(&m, d, &BoundaryParams::default()).unwrap();
    for j in 0..h {
        assert_eq!(
            b.mask[m.idx(fold, j)],
            1,
            "fold line vertex ({fold},{j}) ratio {}",
            b.ratio[m.idx(fold, j)]
        );
        // Far from the fold (more than r = 2d away) and off the border the sheet is flat.
        for i in [3, 8, 24, 28] {
            if !m.is_border(i, j) {
                assert_eq!(b.mask[m.idx(i, j)], 0, "({i},{j}) ratio {}", b.ratio[m.idx(i, j)]);
            }
        }
    }
}

#[test]
fn ratio_is_invariant_to_rotation_and_translation() {
    let rest = GridMesh::flat(20, 14, 1.0, 0.7);
    let d = rest.longest_edge();
    let mut m = folded(20, 14, 9, 70.0);
    for (k, p) in m.pos.iter_mut().enumerate() {
        p[2] += 0.01 * (k as f32 * 0.7).sin();
    }
    let moved = rotate(&m, [1.0, 2.0, -0.5], 2.1, [3.0, -7.0, 0.25]);
    let a = boundary_map(&m, d, &BoundaryParams::default()).unwrap();
    let b = boundary_map(&moved, d, &BoundaryParams::default()).unwrap();
    let worst = a.ratio.iter().zip(&b.ratio).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
    println!("max |Δ σ3/σ1| = {worst:.3e}");
    assert!(worst < 1e-4, "σ3/σ1 changed by {worst} under a rigid motion");
}

#[test]
fn boundary_map_is_bitwise_deterministic() {
    let rest = GridMesh::flat(40, 30, 1.0, 0.75);
    let m = folded(40, 30, 17, 95.0);
    let a = boundary_map(&m, rest.longest_edge(), &BoundaryParams::default()).unwrap();
    let b = boundary_map(&m, rest.longest_edge(), &BoundaryParams::default()).unwrap();
    assert_eq!(a, b);
}

#[test]
fn flat_sheet_geometry_image_has_no_canny_edges_with_default_thresholds() {
    for n in [64, 128, 256] {
        let m = GridMesh::flat(n, n, 1.0, 1.0);
        let dom = Domain::enclosing(std::slice::from_ref(&m), 0.05);
        let e = enhance_map(&mesh_to_image(&m, &dom), &CannyParams::default()).unwrap();
        assert_eq!(e.data.iter().sum::<f32>(), 0.0, "{n}x{n}");
    }
}

#[test]
fn invalid_parameters_are_errors_not_panics() {
    let m = GridMesh::flat(5, 5, 1.0, 1.0);
    let bad = BoundaryParams { gamma: -1.0, ..Default::default() };
    assert!(boundary_map(&m, 0.25, &bad).is_err());
    assert!(boundary_map(&m, 0.0, &BoundaryParams::default()).is_err());
    let img = mesh_to_image(&m, &Domain::enclosing(std::slice::from_ref(&m), 0.0));
    assert!(enhance_map(&img, &CannyParams { sigma: 1.0, low: 0.5, high: 0.1 }).is_err());
}

/// σ3/σ1 on the fold line grows with the crease angle up to a right angle (printed: the
/// γ tuning aid); with the default γ every crease of 45° or more is a boundary.
#[test]
fn fold_ratio_grows_with_crease_angle_up_to_a_right_angle() {
    let (w, h, fold) = (32, 20, 15);
    let d = GridMesh::flat(w, h, 1.0, h as f32 / w as f32).longest_edge();
    let mut last = -1.0;
    for angle in [10.0, 20.0, 30.0, 45.0, 60.0, 90.0] {
        let m = folded(w, h, fold, angle);
        let b = boundary_map(&m, d, &BoundaryParams::default()).unwrap();
        let r = b.ratio[m.idx(fold, h / 2)];
        println!("crease {angle:>5}°: σ3/σ1 on the fold = {r:.4}");
        assert!(r > last);
        assert_eq!(b.mask[m.idx(fold, h / 2)] == 1, angle >= 45.0, "crease {angle}°");
        last = r;
    }
}
