//! Invariance check of `eval`: a run upscaled moved, turned and scaled (each frame its own
//! similarity transform) against the unmoved output transformed the same way; a model that
//! works in the cloth's own frame gives the same cloth.

use crate::error::Result;
use crate::eval::metrics::sequence_metrics;
use crate::geom::cloth_frame::Affine;
use crate::geom::geometry_image::images_to_sequence;
use crate::geom::GridMesh;
use crate::nn::bundle::AnisoCb;
use crate::ops::{Ops, Precision};
use crate::sr::params::UpscaleParams;
use crate::sr::upscale::upscale_images;

/// One line of `invariance.md`.
pub struct InvarianceRow {
    run: String,
    transform: &'static str,
    /// max over frames and vertices of |out(T·lr) − T·out(lr)|, in LR mean edge lengths of the
    /// transformed input.
    max_dev_edges: f32,
    /// vertex RMSE against T·HR, and the unmoved run's RMSE against HR (metres).
    rmse_moved: f32,
    rmse_unmoved: f32,
}

/// A per-frame similarity `p ↦ s·Q·p + d` as an [`Affine`].
fn similarity(axis: [f64; 3], angle_rad: f64, s: f64, d: [f64; 3]) -> Affine {
    let a = crate::geom::vec3::normalize_or(axis, [0.0, 1.0, 0.0]);
    let (sn, c) = angle_rad.sin_cos();
    let k = [[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]];
    let m = std::array::from_fn(|r| {
        std::array::from_fn(|q| {
            let kk: f64 = (0..3).map(|i| k[r][i] * k[i][q]).sum();
            s * ((r == q) as u8 as f64 + sn * k[r][q] + (1.0 - c) * kk)
        })
    });
    Affine { m, t: d }
}

fn apply_mesh(t: &Affine, m: &GridMesh) -> GridMesh {
    GridMesh::new(m.w, m.h, m.pos.iter().map(|p| t.point(p.map(|v| v as f64)).map(|v| v as f32)).collect())
}

/// Upscale the run moved, turned and scaled (each frame its own transform) and compare with the
/// unmoved output transformed the same way.
pub fn invariance_rows(
    ops: &dyn Ops,
    model: &AnisoCb,
    run: &str,
    lr: &[GridMesh],
    ours: &[GridMesh],
    hr: &[GridMesh],
    precision: Precision,
) -> Result<Vec<InvarianceRow>> {
    let n = lr.len().max(2) as f64 - 1.0;
    type PerFrame = Box<dyn Fn(f64) -> Affine>;
    let transforms: [(&'static str, PerFrame); 3] = [
        (
            "falling 4 m (translation)",
            Box::new(|t| similarity([0.0, 1.0, 0.0], 0.0, 1.0, [1.0, -4.0 * t * t, 2.0])),
        ),
        (
            "turned 90°..150° about a tilted axis",
            Box::new(|t| similarity([0.3, 1.0, 0.2], (90.0 + 60.0 * t).to_radians(), 1.0, [0.0; 3])),
        ),
        (
            "scaled ×1.3..×1.7",
            Box::new(|t| similarity([0.0, 1.0, 0.0], 0.0, 1.5 + 0.2 * (6.0 * t).sin(), [0.0; 3])),
        ),
    ];
    let rmse_unmoved = sequence_metrics(ours, hr, None)?.mean.rmse;
    let mut rows = Vec::new();
    for (name, tf) in &transforms {
        let ts: Vec<Affine> = (0..lr.len()).map(|k| tf(k as f64 / n)).collect();
        let lr_t: Vec<GridMesh> = lr.iter().zip(&ts).map(|(m, t)| apply_mesh(t, m)).collect();
        let dom = crate::geom::Domain::enclosing(&lr_t, 0.05);
        let img = crate::geom::geometry_image::sequence_to_images(&lr_t, &dom);
        let params = UpscaleParams { precision, ..UpscaleParams::default() };
        let up = upscale_images(ops, model, &img, &dom, &params, &mut |_| {})?;
        let out = images_to_sequence(&up.hr, &dom);
        let (mut dev, mut rmse) = (0.0f32, 0.0f64);
        for k in 0..lr.len() {
            let want = apply_mesh(&ts[k], &ours[k]);
            let edge = crate::geom::cloth_frame::ClothFrame::of_mesh(&lr_t[k]).unit
                / (lr_t[k].w.max(lr_t[k].h) - 1) as f64;
            for (a, b) in out[k].pos.iter().zip(&want.pos) {
                let d = crate::geom::vec3::norm(crate::geom::vec3::sub(*a, *b));
                dev = dev.max((d as f64 / edge) as f32);
            }
            // In the unmoved run's metres: divide by the frame's scale factor.
            let scale = ts[k].m.iter().map(|r| r[0] * r[0]).sum::<f64>().sqrt();
            let err = crate::eval::metrics::vertex_rmse(&out[k], &apply_mesh(&ts[k], &hr[k]))? as f64;
            rmse += err / scale / lr.len() as f64;
        }
        rows.push(InvarianceRow {
            run: run.to_string(),
            transform: name,
            max_dev_edges: dev,
            rmse_moved: rmse as f32,
            rmse_unmoved,
        });
    }
    Ok(rows)
}

pub fn invariance_markdown(rows: &[InvarianceRow]) -> String {
    let mut s = String::from(
        "# Moved, turned and scaled inputs\n\nEach held-out run's LR frames transformed (a different transform per frame) and \
         upscaled; `max deviation` = largest distance between that output and the unmoved output transformed the same way, \
         in LR edge lengths; RMSE against the truth transformed the same way (scaled runs: divided by each frame's scale, so in the unmoved run's metres).\n\n\
         | run | transform | max deviation (LR edges) | RMSE moved (mm) | RMSE unmoved (mm) | ratio |\n|---|---|---:|---:|---:|---:|\n",
    );
    for r in rows {
        s.push_str(&format!(
            "| {} | {} | {:.2e} | {:.3} | {:.3} | {:.3} |\n",
            r.run,
            r.transform,
            r.max_dev_edges,
            1e3 * r.rmse_moved,
            1e3 * r.rmse_unmoved,
            r.rmse_moved / r.rmse_unmoved.max(f32::MIN_POSITIVE)
        ));
    }
    s
}
