//! The wrinkle-detail metric (`eval::metrics::wrinkle_*`): audited against NumPy
//! (tests/fixtures/gen_wrinkle.py → tests/fixtures/wrinkle/*.npy; versions in VERSIONS.txt),
//! invariant under rigid motions, and near zero for a Catmull-Rom upsampled LR sequence.
//!
//! Tolerances (references in f64 from the same f32 positions): the Rust resampling runs in f32
//! on coordinates up to ~1 m, so S(X) and D agree to atol 2e-6 m + rtol 1e-4; normals (unit)
//! atol 1e-5; the statistics (f64 sums of those D) rtol 1e-4.

#[path = "common/close.rs"]
mod close;
use anisocb::eval::baseline::interpolate_sequence;
use anisocb::eval::metrics::{grid_normals, lr_round_trip, wrinkle_detail, wrinkle_stats};
use anisocb::geom::{Domain, GridMesh};
use anisocb::io::read_npy;
use anisocb::ops::{Cpu, Interp};
use anisocb::Tensor;
use close::assert_close_slice as close;
use std::path::PathBuf;

fn fx(name: &str) -> Tensor {
    let p =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/wrinkle").join(format!("{name}.npy"));
    read_npy(&p).unwrap_or_else(|e| panic!("{e}"))
}

/// A (T, H, W, 3) fixture as T grids.
fn frames(t: &Tensor) -> Vec<GridMesh> {
    let (n, h, w) = (t.shape[0], t.shape[1], t.shape[2]);
    let per = h * w * 3;
    (0..n)
        .map(|k| {
            let d = &t.data[k * per..(k + 1) * per];
            GridMesh::new(w, h, d.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect())
        })
        .collect()
}

fn flat_pos(ms: &[GridMesh]) -> Vec<f32> {
    ms.iter().flat_map(|m| m.pos.iter().flatten().copied()).collect()
}

#[test]
fn wrinkle_detail_and_stats_match_numpy() {
    for case in ["a", "odd"] {
        let (x, y) = (frames(&fx(&format!("{case}_x"))), frames(&fx(&format!("{case}_y"))));
        let lr = fx(&format!("{case}_lr")).into_data();
        let (lw, lh) = (lr[0] as usize, lr[1] as usize);
        let s: Vec<GridMesh> = x.iter().map(|m| lr_round_trip(m, lw, lh)).collect();
        close(&format!("{case} S(X)"), &flat_pos(&s), &fx(&format!("{case}_sx")).data, 2e-6, 1e-4);
        let n: Vec<f32> = s.iter().flat_map(|m| grid_normals(m).into_iter().flatten()).collect();
        close(&format!("{case} normals"), &n, &fx(&format!("{case}_nx")).data, 1e-5, 0.0);
        for (seq, tag) in [(&x, "dx"), (&y, "dy")] {
            let d: Vec<f32> = seq.iter().flat_map(|m| wrinkle_detail(m, lw, lh).unwrap()).collect();
            close(&format!("{case} D {tag}"), &d, &fx(&format!("{case}_{tag}")).data, 2e-6, 1e-4);
        }
        let st = wrinkle_stats(&y, &x, lw, lh).unwrap();
        close(&format!("{case} stats"), &st.values(), &fx(&format!("{case}_stats")).data, 0.0, 1e-4);
    }
}

/// A 1.2 m × 0.8 m sheet, gently curved, with folds of `amp` metres (wavelength 0.16 m, which a
/// 32 × 24 grid holds) and `fine` metres (wavelength 0.05 m, which it does not), moving with `t`.
fn wrinkled(w: usize, h: usize, amp: f32, fine: f32, t: f32) -> GridMesh {
    let mut m = GridMesh::flat(w, h, 1.2, 0.8);
    for p in &mut m.pos {
        let base = 0.3 * (1.5 * p[0]).sin() + 0.1 * (2.0 * p[1]).cos();
        p[2] =
            base + amp * (40.0 * p[0] + 9.0 * p[1] + t).sin() + fine * (125.0 * p[0] - 30.0 * p[1] + t).sin();
    }
    m
}

#[test]
fn wrinkle_detail_is_unchanged_by_a_rigid_motion() {
    let seq: Vec<GridMesh> = (0..3).map(|t| wrinkled(24, 18, 0.004, 0.002, t as f32)).collect();
    let (ax, ang) = ([0.3f64, 1.0, -0.4], 2.1f64);
    let norm = (ax[0] * ax[0] + ax[1] * ax[1] + ax[2] * ax[2]).sqrt();
    let a = ax.map(|c| c / norm);
    // Rodrigues: R = I + sin θ K + (1 − cos θ) K².
    let k = [[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]];
    let r: [[f64; 3]; 3] = std::array::from_fn(|i| {
        std::array::from_fn(|j| {
            let kk: f64 = (0..3).map(|m| k[i][m] * k[m][j]).sum();
            (i == j) as u8 as f64 + ang.sin() * k[i][j] + (1.0 - ang.cos()) * kk
        })
    });
    let shift = [1.5f64, -0.7, 2.2];
    let moved: Vec<GridMesh> = seq
        .iter()
        .map(|m| {
            let pos = m
                .pos
                .iter()
                .map(|p| {
                    std::array::from_fn(|i| {
                        ((0..3).map(|j| r[i][j] * p[j] as f64).sum::<f64>() + shift[i]) as f32
                    })
                })
                .collect();
            GridMesh::new(m.w, m.h, pos)
        })
        .collect();
    let d =
        |s: &[GridMesh]| -> Vec<f32> { s.iter().flat_map(|m| wrinkle_detail(m, 12, 9).unwrap()).collect() };
    let (d0, d1) = (d(&seq), d(&moved));
    // f32 positions up to ~2.5 m after the shift: a few 1e-7 m of rounding per coordinate.
    close("D of the moved sequence", &d1, &d0, 5e-6, 1e-3);
    let rms = (d0.iter().map(|v| v * v).sum::<f32>() / d0.len() as f32).sqrt();
    assert!(rms > 1e-3, "the test sheet has wrinkles: RMS(D) {rms} m");
    let st = wrinkle_stats(&moved, &seq, 12, 9).unwrap();
    assert!(
        (st.ratio - 1.0).abs() < 1e-3 && st.corr > 0.9999 && (st.change_ratio - 1.0).abs() < 1e-3,
        "{st:?}"
    );
}

#[test]
fn catmull_rom_upsampled_lr_has_almost_no_wrinkle_detail() {
    // The truth: 64 × 48 with both folds; the LR input: 32 × 24 with the coarse folds only
    // (a coarse simulation cannot hold the fine ones).
    let (amp, fine) = (0.004, 0.002);
    let hr: Vec<GridMesh> = (0..4).map(|t| wrinkled(64, 48, amp, fine, 0.5 * t as f32)).collect();
    let lr: Vec<GridMesh> = (0..4).map(|t| wrinkled(32, 24, amp, 0.0, 0.5 * t as f32)).collect();
    let domain = Domain::enclosing(&lr, 0.05);
    let cr = interpolate_sequence(&Cpu, &lr, &domain, 2, Interp::CatmullRom).unwrap();
    let st = wrinkle_stats(&cr, &hr, 32, 24).unwrap();
    println!("{st:?}");
    assert!(st.truth_rms_mm > 1.0, "{st:?}");
    // Not exactly 0: the round trip samples the 64-grid between its vertices (31/63 per step)
    // and so damps the coarse folds by ~1.5 % (measured: 0.059 mm, 3.6 % of the truth's RMS).
    assert!(st.rms_mm < 0.1 * st.truth_rms_mm, "Catmull-Rom output keeps wrinkle detail: {st:?}");
    assert!(st.rms_mm < 0.02 * 1e3 * amp, "more than 2 % of the LR folds' amplitude: {st:?}");
    // A flat sheet has none at all.
    let flat = GridMesh::flat(20, 16, 1.0, 0.8);
    assert!(wrinkle_detail(&flat, 10, 8).unwrap().iter().all(|v| v.abs() < 1e-6));
    // Too small a grid, or frame counts that differ, are errors, not NaN.
    assert!(wrinkle_detail(&GridMesh::flat(4, 9, 1.0, 1.0), 2, 2).is_err());
    assert!(wrinkle_stats(&hr[..2], &hr, 32, 24).is_err());
}
