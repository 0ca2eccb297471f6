//! Ground-truth maps for one HR frame: boundary map (Laplacian, hashed neighbours, 3×3 eigen)
//! and enhance map (3-channel Canny), 64×64 and 256×256. `cargo bench --bench maps`.

use anisocb::geom::anisotropy::{boundary_map, BoundaryParams};
use anisocb::geom::geometry_image::mesh_to_image;
use anisocb::geom::{Domain, GridMesh};
use anisocb::imgproc::{enhance_map, CannyParams};
use std::time::Instant;

/// A wrinkled sheet with a crease: the kind of frame the dataset builder sees.
fn frame(n: usize) -> (GridMesh, f32) {
    let rest = GridMesh::flat(n, n, 1.0, 1.0);
    let d = rest.longest_edge();
    let mut m = rest;
    for p in m.pos.iter_mut() {
        let dx = p[0] - 0.5;
        p[2] = 0.01 * (p[1] * 30.0).sin();
        if dx > 0.0 {
            p[0] = 0.5 + dx * 0.5;
            p[2] += dx * 0.87;
        }
    }
    (m, d)
}

fn median_ms(reps: usize, mut f: impl FnMut()) -> f64 {
    f();
    let mut t: Vec<f64> = (0..reps)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[reps / 2]
}

fn main() {
    println!("threads: {}", rayon::current_num_threads());
    for n in [64, 256] {
        let (m, d) = frame(n);
        let dom = Domain::enclosing(std::slice::from_ref(&m), 0.05);
        let img = mesh_to_image(&m, &dom);
        let reps = if n <= 64 { 51 } else { 11 };
        let bp = BoundaryParams::default();
        let cp = CannyParams::default();
        let tb = median_ms(reps, || {
            std::hint::black_box(boundary_map(&m, d, &bp).unwrap());
        });
        let te = median_ms(reps, || {
            std::hint::black_box(enhance_map(&img, &cp).unwrap());
        });
        println!(
            "maps {n}x{n}: boundary {tb:.3} ms ({:.2} µs/vertex), enhance (3-channel Canny) {te:.3} ms, total {:.3} ms",
            tb * 1e3 / (n * n) as f64,
            tb + te
        );
    }
}
