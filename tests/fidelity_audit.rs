//! Audit of the fidelity additions against references written by JAX/NumPy
//! (tests/fixtures/gen_losses.py → tests/fixtures/losses/*.npy; versions in VERSIONS.txt):
//! the edge-vector, curvature (Laplacian) and edge-length losses and their gradients, the
//! combined GeometryNet loss (MSE + w·edge, MSE + w_e·edge + w_l·laplacian and
//! MSE + w_e·edge + w_n·length), and
//! the cloth frame (origin, unit, rotation as NumPy's SVD polar factor).
//!
//! Tolerances (references in f64): losses rtol 1e-5 (f64-accumulated means), gradients
//! atol 1e-8 + rtol 1e-5 (magnitude ~1/count); the frame atol 1e-5 (f32 positions of
//! magnitude ≤ 3 m, f64 arithmetic after that).

use anisocb::geom::cloth_frame::ClothFrame;
use anisocb::geom::GridMesh;
use anisocb::io::read_npy;
use anisocb::nn::geometry_net::{estimate_loss, GeometryLoss};
use anisocb::ops::{loss, Cpu};
use anisocb::Tensor;
use std::path::PathBuf;

fn fx(name: &str) -> Tensor {
    let p =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/losses").join(format!("{name}.npy"));
    read_npy(&p).unwrap_or_else(|e| panic!("{e}"))
}

fn close(what: &str, got: &[f32], want: &[f32], atol: f32, rtol: f32) {
    assert_eq!(got.len(), want.len(), "{what}: length");
    let mut worst = (0.0f32, 0usize);
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        let d = (g - w).abs();
        assert!(d <= atol + rtol * w.abs(), "{what}[{i}]: got {g}, want {w} (diff {d})");
        if d > worst.0 {
            worst = (d, i);
        }
    }
    println!("{what}: largest diff {:.2e} at {}", worst.0, worst.1);
}

#[test]
fn edge_loss_and_gradient_match_jax() {
    for tag in ["a", "row", "col"] {
        let (p, t) = (fx(&format!("edge_{tag}_pred")), fx(&format!("edge_{tag}_target")));
        let (l, g) = loss::edge_mse(&p, &t);
        close(&format!("edge {tag} loss"), &[l], &fx(&format!("edge_{tag}_loss")).data, 0.0, 1e-5);
        close(&format!("edge {tag} grad"), &g.data, &fx(&format!("edge_{tag}_grad")).data, 1e-8, 1e-5);
    }
}

#[test]
fn geometry_loss_with_edge_term_matches_jax() {
    let (u, r, hr) = (fx("geo_u"), fx("geo_r"), fx("geo_hr"));
    let w = fx("geo_weight").data[0];
    let mut est = u.clone();
    for (e, r) in est.data.iter_mut().zip(&r.data) {
        *e += r;
    }
    let (l, g) = estimate_loss(&Cpu, &est, &hr, GeometryLoss { edge: w, laplacian: 0.0, length: 0.0 });
    close("geometry loss", &[l], &fx("geo_loss").data, 0.0, 1e-5);
    close("geometry grad", &g.data, &fx("geo_grad").data, 1e-8, 1e-5);
}

#[test]
fn laplacian_loss_and_gradient_match_jax() {
    for tag in ["a", "min", "wide"] {
        let (p, t) = (fx(&format!("lap_{tag}_pred")), fx(&format!("lap_{tag}_target")));
        let (l, g) = loss::laplacian_mse(&p, &t);
        close(&format!("laplacian {tag} loss"), &[l], &fx(&format!("lap_{tag}_loss")).data, 0.0, 1e-5);
        // Gradients up to 2·20·|D|/count: atol scaled like the edge term's.
        close(&format!("laplacian {tag} grad"), &g.data, &fx(&format!("lap_{tag}_grad")).data, 1e-7, 1e-5);
    }
    // Under 3×3 there is no interior pixel: no loss, no gradient.
    let p = Tensor::zeros(&[1, 3, 2, 9]);
    let (l, g) = loss::laplacian_mse(&p, &Tensor::full(&[1, 3, 2, 9], 1.0));
    assert_eq!((l, g.data.iter().all(|&v| v == 0.0)), (0.0, true));
}

#[test]
fn geometry_loss_with_edge_and_laplacian_terms_matches_jax() {
    let (u, r, hr) = (fx("geo2_u"), fx("geo2_r"), fx("geo2_hr"));
    let w = fx("geo2_weights").into_data();
    let mut est = u.clone();
    for (e, r) in est.data.iter_mut().zip(&r.data) {
        *e += r;
    }
    let (l, g) = estimate_loss(&Cpu, &est, &hr, GeometryLoss { edge: w[0], laplacian: w[1], length: 0.0 });
    close("geometry2 loss", &[l], &fx("geo2_loss").data, 0.0, 1e-5);
    close("geometry2 grad", &g.data, &fx("geo2_grad").data, 1e-8, 1e-5);
}

#[test]
fn edge_length_loss_and_gradient_match_jax() {
    for tag in ["a", "row", "two"] {
        let (p, t) = (fx(&format!("len_{tag}_pred")), fx(&format!("len_{tag}_target")));
        let (l, g) = loss::edge_length_mse(&p, &t);
        close(&format!("length {tag} loss"), &[l], &fx(&format!("len_{tag}_loss")).data, 0.0, 1e-5);
        close(&format!("length {tag} grad"), &g.data, &fx(&format!("len_{tag}_grad")).data, 1e-8, 1e-5);
    }
    // A zero-length edge of pred has no direction: no gradient from it, and no NaN.
    let p = Tensor::zeros(&[1, 3, 1, 2]);
    let (l, g) =
        loss::edge_length_mse(&p, &Tensor { shape: vec![1, 3, 1, 2], data: vec![0., 1., 0., 0., 0., 0.] });
    assert_eq!((l, g.data.iter().all(|&v| v == 0.0)), (1.0, true));
}

#[test]
fn geometry_loss_with_edge_and_length_terms_matches_jax() {
    let (u, r, hr) = (fx("geo3_u"), fx("geo3_r"), fx("geo3_hr"));
    let w = fx("geo3_weights").into_data();
    let mut est = u.clone();
    for (e, r) in est.data.iter_mut().zip(&r.data) {
        *e += r;
    }
    let (l, g) = estimate_loss(&Cpu, &est, &hr, GeometryLoss { edge: w[0], laplacian: 0.0, length: w[1] });
    close("geometry3 loss", &[l], &fx("geo3_loss").data, 0.0, 1e-5);
    close("geometry3 grad", &g.data, &fx("geo3_grad").data, 1e-8, 1e-5);
}

#[test]
fn cloth_frame_matches_numpy_svd_polar_factor() {
    for tag in ["square", "strip"] {
        let size = fx(&format!("frame_{tag}_size"));
        let (w, h) = (size.data[0] as usize, size.data[1] as usize);
        let pos = fx(&format!("frame_{tag}_pos"));
        let mesh = GridMesh::new(w, h, pos.data.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect());
        let f = ClothFrame::of_mesh(&mesh);
        let o: Vec<f32> = f.origin.iter().map(|&v| v as f32).collect();
        close(&format!("{tag} origin"), &o, &fx(&format!("frame_{tag}_origin")).data, 1e-5, 0.0);
        close(&format!("{tag} unit"), &[f.unit as f32], &fx(&format!("frame_{tag}_unit")).data, 1e-5, 1e-5);
        let rot: Vec<f32> = f.rot.iter().flatten().map(|&v| v as f32).collect();
        close(&format!("{tag} rotation"), &rot, &fx(&format!("frame_{tag}_rot")).data, 1e-5, 0.0);
    }
}
