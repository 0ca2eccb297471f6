//! Audit of the losses against references written by JAX/NumPy
//! (tests/fixtures/gen_losses.py → tests/fixtures/losses/*.npy; versions in VERSIONS.txt):
//! the edge-vector, curvature (Laplacian) and edge-length losses and their gradients, the
//! combined GeometryNet loss (MSE + w·edge, MSE + w_e·edge + w_l·laplacian,
//! MSE + w_e·edge + w_n·length and MSE + w·detail), the wrinkle-energy loss, and
//! the cloth frame (origin, unit, rotation as NumPy's SVD polar factor). Each loss is checked
//! through two op tables: `RefOps` (the scalar `*_ref` specs) and `Cpu` (the nets' CPU path).
//!
//! Tolerances (references in f64): losses rtol 1e-5 (f64-accumulated means), gradients
//! atol 1e-8 + rtol 1e-5 (magnitude ~1/count); the frame atol 1e-5 (f32 positions of
//! magnitude ≤ 3 m, f64 arithmetic after that).

#[path = "common/close.rs"]
mod close;
use anisocb::geom::cloth_frame::ClothFrame;
use anisocb::geom::GridMesh;
use anisocb::io::read_npy;
use anisocb::nn::geometry_net::{estimate_loss, GeometryLoss};
use anisocb::ops::loss::DetailEnergy;
use anisocb::ops::{loss, Cpu, Ops, RefOps};
use anisocb::Tensor;
use close::assert_close_slice as close;
use std::path::PathBuf;

fn fx(name: &str) -> Tensor {
    let p =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/losses").join(format!("{name}.npy"));
    read_npy(&p).unwrap_or_else(|e| panic!("{e}"))
}

fn tables() -> [&'static dyn Ops; 2] {
    [&RefOps, &Cpu]
}

#[test]
fn edge_loss_and_gradient_match_jax() {
    for (ops, tag) in tables().into_iter().flat_map(|o| ["a", "row", "col"].map(|t| (o, t))) {
        let (p, t) = (fx(&format!("edge_{tag}_pred")), fx(&format!("edge_{tag}_target")));
        let (l, g) = ops.edge_mse(&p, &t);
        let what = |k: &str| format!("{} edge {tag} {k}", ops.name());
        close(&what("loss"), &[l], &fx(&format!("edge_{tag}_loss")).data, 0.0, 1e-5);
        close(&what("grad"), &g.data, &fx(&format!("edge_{tag}_grad")).data, 1e-8, 1e-5);
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
    for ops in tables() {
        let (l, g) =
            estimate_loss(ops, &est, &hr, (3, 4), GeometryLoss { edge: w, ..GeometryLoss::default() });
        close(&format!("{} geometry loss", ops.name()), &[l], &fx("geo_loss").data, 0.0, 1e-5);
        close(&format!("{} geometry grad", ops.name()), &g.data, &fx("geo_grad").data, 1e-8, 1e-5);
    }
}

#[test]
fn laplacian_loss_and_gradient_match_jax() {
    for ops in tables() {
        for tag in ["a", "min", "wide"] {
            let (p, t) = (fx(&format!("lap_{tag}_pred")), fx(&format!("lap_{tag}_target")));
            let (l, g) = ops.laplacian_mse(&p, &t);
            let what = |k: &str| format!("{} laplacian {tag} {k}", ops.name());
            close(&what("loss"), &[l], &fx(&format!("lap_{tag}_loss")).data, 0.0, 1e-5);
            // Gradients up to 2·20·|D|/count: atol scaled like the edge term's.
            close(&what("grad"), &g.data, &fx(&format!("lap_{tag}_grad")).data, 1e-7, 1e-5);
        }
        // Under 3×3 there is no interior pixel: no loss, no gradient.
        let p = Tensor::zeros(&[1, 3, 2, 9]);
        let (l, g) = ops.laplacian_mse(&p, &Tensor::full(&[1, 3, 2, 9], 1.0));
        assert_eq!((l, g.data.iter().all(|&v| v == 0.0)), (0.0, true), "{}", ops.name());
    }
}

#[test]
fn geometry_loss_with_edge_and_laplacian_terms_matches_jax() {
    let (u, r, hr) = (fx("geo2_u"), fx("geo2_r"), fx("geo2_hr"));
    let w = fx("geo2_weights").into_data();
    let mut est = u.clone();
    for (e, r) in est.data.iter_mut().zip(&r.data) {
        *e += r;
    }
    for ops in tables() {
        let weights = GeometryLoss { edge: w[0], laplacian: w[1], ..GeometryLoss::default() };
        let (l, g) = estimate_loss(ops, &est, &hr, (3, 4), weights);
        close(&format!("{} geometry2 loss", ops.name()), &[l], &fx("geo2_loss").data, 0.0, 1e-5);
        close(&format!("{} geometry2 grad", ops.name()), &g.data, &fx("geo2_grad").data, 1e-8, 1e-5);
    }
}

#[test]
fn edge_length_loss_and_gradient_match_jax() {
    for ops in tables() {
        for tag in ["a", "row", "two"] {
            let (p, t) = (fx(&format!("len_{tag}_pred")), fx(&format!("len_{tag}_target")));
            let (l, g) = ops.edge_length_mse(&p, &t);
            let what = |k: &str| format!("{} length {tag} {k}", ops.name());
            close(&what("loss"), &[l], &fx(&format!("len_{tag}_loss")).data, 0.0, 1e-5);
            close(&what("grad"), &g.data, &fx(&format!("len_{tag}_grad")).data, 1e-8, 1e-5);
        }
        // A zero-length edge of pred has no direction: no gradient from it, and no NaN.
        let p = Tensor::zeros(&[1, 3, 1, 2]);
        let t = Tensor { shape: [1, 3, 1, 2].into(), data: vec![0., 1., 0., 0., 0., 0.] };
        let (l, g) = ops.edge_length_mse(&p, &t);
        assert_eq!((l, g.data.iter().all(|&v| v == 0.0)), (1.0, true), "{}", ops.name());
    }
}

#[test]
fn geometry_loss_with_edge_and_length_terms_matches_jax() {
    let (u, r, hr) = (fx("geo3_u"), fx("geo3_r"), fx("geo3_hr"));
    let w = fx("geo3_weights").into_data();
    let mut est = u.clone();
    for (e, r) in est.data.iter_mut().zip(&r.data) {
        *e += r;
    }
    for ops in tables() {
        let weights = GeometryLoss { edge: w[0], length: w[1], ..GeometryLoss::default() };
        let (l, g) = estimate_loss(ops, &est, &hr, (3, 4), weights);
        close(&format!("{} geometry3 loss", ops.name()), &[l], &fx("geo3_loss").data, 0.0, 1e-5);
        close(&format!("{} geometry3 grad", ops.name()), &g.data, &fx("geo3_grad").data, 1e-8, 1e-5);
    }
}

#[test]
fn detail_energy_loss_and_gradient_match_jax() {
    for (ops, tag) in tables().into_iter().flat_map(|o| ["a", "r0", "odd", "normal"].map(|t| (o, t))) {
        let (p, t) = (fx(&format!("detail_{tag}_pred")), fx(&format!("detail_{tag}_target")));
        let k = fx(&format!("detail_{tag}_params")).into_data(); // lr_h, lr_w, r, ε
        let params = DetailEnergy { radius: k[2] as usize, eps: k[3], normal_only: k.get(4) == Some(&1.0) };
        let (l, g) = ops.detail_energy_mse(&p, &t, k[0] as usize, k[1] as usize, params);
        let what = |k: &str| format!("{} detail {tag} {k}", ops.name());
        close(&what("loss"), &[l], &fx(&format!("detail_{tag}_loss")).data, 0.0, 1e-5);
        // f32 resizes and sums against f64: rtol 1e-4 (the gradient passes through 1/a and two
        // resizes of 4×4 taps); atol at 1e-4 of the largest entry (~1/count).
        let want = fx(&format!("detail_{tag}_grad"));
        let atol = 1e-4 * want.data.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        close(&what("grad"), &g.data, &want.data, atol, 1e-4);
    }
}

#[test]
fn geometry_loss_with_detail_term_matches_jax() {
    let (u, r, hr) = (fx("geo4_u"), fx("geo4_r"), fx("geo4_hr"));
    let k = fx("geo4_detail").into_data(); // weight, lr_h, lr_w, r, ε
    let mut est = u.clone();
    for (e, r) in est.data.iter_mut().zip(&r.data) {
        *e += r;
    }
    let w = GeometryLoss {
        detail: k[0],
        detail_params: DetailEnergy { radius: k[3] as usize, eps: k[4], normal_only: false },
        ..GeometryLoss::default()
    };
    for ops in tables() {
        let (l, g) = estimate_loss(ops, &est, &hr, (k[1] as usize, k[2] as usize), w);
        close(&format!("{} geometry4 loss", ops.name()), &[l], &fx("geo4_loss").data, 0.0, 1e-5);
        close(&format!("{} geometry4 grad", ops.name()), &g.data, &fx("geo4_grad").data, 1e-7, 1e-4);
    }
}

/// RMS of the detail beyond the (lr_h, lr_w) frame, away from a 2-pixel border (where the
/// clamped taps make even a flat ramp look detailed, equally in prediction and target).
fn detail_rms(x: &Tensor, lr_h: usize, lr_w: usize) -> f64 {
    let hf = loss::detail_high_pass(x, lr_h, lr_w);
    let (n, c, h, w) = hf.dims4();
    let mut sum = 0.0f64;
    for plane in hf.data.chunks_exact(h * w) {
        for row in plane.chunks_exact(w).take(h - 2).skip(2) {
            sum += row[2..w - 2].iter().map(|&v| (v as f64).powi(2)).sum::<f64>();
        }
    }
    (sum / (n * c * (h - 4) * (w - 4)) as f64).sqrt()
}

#[test]
fn detail_energy_step_restores_wrinkles_a_smooth_prediction_averaged_out() {
    // Target: a gently curved 32×32 sheet (cloth-frame units, side 1) with folds of period
    // 3 HR pixels (finer than the 16×16 LR grid can carry) and amplitude 5 mm-ish (0.005).
    // Prediction: the same sheet without the folds, plus the faint noise any net leaves.
    let (n, h, w, lr) = (2, 32, 32, 16);
    let (mut t, mut p) = (Tensor::zeros(&[n, 3, h, w]), Tensor::zeros(&[n, 3, h, w]));
    let mut seed = 12345u64;
    let mut noise = || {
        seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((seed >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * 2e-5
    };
    for img in 0..n {
        for y in 0..h {
            for x in 0..w {
                let (u, v) = (x as f32 / (w - 1) as f32, y as f32 / (h - 1) as f32);
                let smooth = 0.05 * (u - 0.5).powi(2) + 0.02 * v;
                let fold = 0.005 * (2.0 * std::f32::consts::PI * (x as f32 / 3.0 + 0.3 * img as f32)).sin();
                for (c, val) in [u, v, smooth].into_iter().enumerate() {
                    let i = t.idx4(img, c, y, x);
                    t.data[i] = val + if c == 2 { fold } else { 0.0 };
                    p.data[i] = val + noise();
                }
            }
        }
    }
    let params = DetailEnergy::default();
    let (l0, g) = loss::detail_energy_mse(&p, &t, lr, lr, params);
    // A step that moves no pixel more than 1e-4 (a tenth of the noise-free target's detail).
    let step = 1e-4 / g.data.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    let mut p1 = p.clone();
    for (x, d) in p1.data.iter_mut().zip(&g.data) {
        *x -= step * d;
    }
    let (l1, _) = loss::detail_energy_mse(&p1, &t, lr, lr, params);
    let (r0, r1, rt) = (detail_rms(&p, lr, lr), detail_rms(&p1, lr, lr), detail_rms(&t, lr, lr));
    println!("loss {l0:.3e} → {l1:.3e}; detail RMS {r0:.3e} → {r1:.3e} (target {rt:.3e})");
    assert!(l1 < l0, "loss {l0} → {l1}");
    assert!(r1 > 1.5 * r0 && r1 < rt, "detail RMS {r0} → {r1} (target {rt})");
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
