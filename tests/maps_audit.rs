//! Audits of the ground-truth maps against independent implementations (NumPy eigh/SVD on
//! the same weighted covariances; scikit-image `feature.canny`), from
//! `tests/fixtures/gen_maps.py`, and of the Jacobi eigen-solver against faer.

use anisocb::rng::Rng;
#[path = "common/random.rs"]
mod random;
use anisocb::geom::anisotropy::{covariances, covariances_ref, sym3_eigenvalues, Sym3};
use anisocb::geom::laplacian::{positions_f64, smooth};
use anisocb::geom::GridMesh;
use anisocb::imgproc::{canny, CannyParams};
use anisocb::io::read_npy;
use random::TestData;
use std::path::{Path, PathBuf};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/maps").join(name)
}

fn read_f64(name: &str) -> Vec<f64> {
    let bytes = std::fs::read(fixture(name)).expect("fixture");
    npyz::NpyFile::new(&bytes[..]).expect("npy").into_vec::<f64>().expect("f64 data")
}

fn load_mesh(name: &str) -> GridMesh {
    let t = read_npy(&fixture(&format!("mesh_{name}.npy"))).expect("mesh fixture");
    let (h, w) = (t.shape[0], t.shape[1]);
    GridMesh::new(w, h, t.data.chunks(3).map(|c| [c[0], c[1], c[2]]).collect())
}

#[test]
fn covariance_eigenvalues_match_numpy_on_flat_folded_twisted_meshes() {
    let prm = read_f64("params.npy");
    let (d, lambda, rf) = (prm[0], prm[1], prm[2]);
    for name in ["flat", "folded", "twisted"] {
        let mesh = load_mesh(name);
        let want = read_f64(&format!("eig_{name}.npy"));
        let p = positions_f64(&mesh);
        let pbar = smooth(&mesh, lambda);
        let cov = covariances(&p, &pbar, rf * d);
        let (mut worst, mut at) = (0.0f64, 0);
        let mut bad = Vec::new();
        for (v, c) in cov.iter().enumerate() {
            let got = sym3_eigenvalues(c);
            let scale = want[3 * v]; // σ1: absolute floor for the near-zero σ3 of flat patches
            for k in 0..3 {
                let r = want[3 * v + k];
                let err = (got[k] - r).abs();
                let tol = 1e-12 * scale + 1e-6 * r.abs();
                if err / tol > worst {
                    worst = err / tol;
                    at = v;
                }
                if err > tol && bad.len() < 5 {
                    bad.push(format!("vertex {v} σ{}: got {} want {r}", k + 1, got[k]));
                }
            }
        }
        println!("{name}: worst |err|/tol = {worst:.3e} at vertex {at}");
        assert!(bad.is_empty(), "{name}: eigenvalues differ from NumPy: {bad:?}");
    }
}

#[test]
fn hashed_neighbour_covariances_match_brute_force() {
    for name in ["flat", "folded", "twisted"] {
        let mesh = load_mesh(name);
        let p = positions_f64(&mesh);
        let pbar = smooth(&mesh, 0.5);
        let r = 2.0 * mesh.longest_edge() as f64;
        let fast = covariances(&p, &pbar, r);
        let slow = covariances_ref(&p, &pbar, r);
        for (v, (a, b)) in fast.iter().zip(&slow).enumerate() {
            for k in 0..6 {
                assert!(
                    (a[k] - b[k]).abs() <= 1e-12 * (b[0] + b[3] + b[5]),
                    "{name} vertex {v}: {a:?} vs {b:?}"
                );
            }
        }
    }
}

#[test]
fn jacobi_eigenvalues_match_faer_on_random_symmetric_matrices() {
    let mut rng = Rng::new(0x9E37_79B9_7F4A_7C15);
    let mut worst = 0.0f64;
    for case in 0..2000 {
        // Random PSD matrices, some nearly rank-deficient (like flat neighbourhoods).
        let a: [[f64; 3]; 3] = std::array::from_fn(|_| std::array::from_fn(|_| rng.signed_f64()));
        let squash = if case % 3 == 0 { 1e-5 } else { 1.0 };
        let mut c: Sym3 = [0.0; 6];
        let idx = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];
        for (s, &(i, j)) in idx.iter().enumerate() {
            c[s] = (0..3).map(|k| a[i][k] * a[j][k] * if k == 2 { squash } else { 1.0 }).sum();
        }
        let m = faer::Mat::<f64>::from_fn(3, 3, |i, j| {
            let (i, j) = if i <= j { (i, j) } else { (j, i) };
            c[idx.iter().position(|&q| q == (i, j)).unwrap()]
        });
        let mut want = m.self_adjoint_eigenvalues(faer::Side::Lower).expect("faer evd");
        want.sort_by(|x, y| y.total_cmp(x));
        let sv = m.singular_values().expect("faer svd");
        let got = sym3_eigenvalues(&c);
        for k in 0..3 {
            let err = (got[k] - want[k]).abs() / (want[0] * 1e-14 + want[k].abs() * 1e-12);
            worst = worst.max(err);
            assert!(err <= 1.0, "case {case}: jacobi {got:?} faer {want:?}");
            assert!((sv[k] - want[k].abs()).abs() <= 1e-13 * want[0], "svd {sv:?} vs evd {want:?}");
        }
    }
    println!("worst |err|/tol vs faer = {worst:.3e}");
}

#[test]
fn canny_matches_scikit_image_on_at_least_99_percent_of_pixels() {
    for name in ["wrinkles", "square", "blobs"] {
        let img = read_npy(&fixture(&format!("canny_{name}_img.npy"))).unwrap();
        let want = read_npy(&fixture(&format!("canny_{name}_edges.npy"))).unwrap();
        let prm = read_npy(&fixture(&format!("canny_{name}_params.npy"))).unwrap();
        let p = CannyParams { sigma: prm.data[0], low: prm.data[1], high: prm.data[2] };
        let (h, w) = (img.shape[0], img.shape[1]);
        let got = canny(&img.data, h, w, &p);
        let mut diff = Vec::new();
        for (k, (&g, &r)) in got.iter().zip(&want.data).enumerate() {
            if (g as f32) != r {
                diff.push((k / w, k % w, g, r));
            }
        }
        let agree = 1.0 - diff.len() as f64 / (h * w) as f64;
        let edges = want.data.iter().filter(|&&v| v > 0.0).count();
        println!(
            "{name}: {:.4}% agree ({} differ, {edges} skimage edge pixels), first: {:?}",
            100.0 * agree,
            diff.len(),
            &diff[..diff.len().min(5)]
        );
        assert!(agree >= 0.99, "{name}: only {:.3}% of pixels agree with skimage", 100.0 * agree);
    }
}
