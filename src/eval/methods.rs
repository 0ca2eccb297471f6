//! What `anisocb eval` compares on a held-out run, and how: the interpolations, the learned
//! linear upsampler, a GeometryNet alone, anisocb and its ablations and variants, other
//! bundles, the physics pass; each method's HR meshes scored against the run's HR truth
//! ([`evaluate_run`]). The tables are in [`super::report`], the pictures in the CLI.

use super::invariance::{invariance_rows, InvarianceRow};
use super::linear::LinearUpsampler;
use super::metrics::{border_band, sequence_metrics, wrinkle_stats};
use super::report::{Cell, BAND_ROWS};
use crate::cloth::follow::{FollowParams, Follower};
use crate::cloth::run_io::RunPair;
use crate::error::Result;
use crate::geom::cloth_frame::{from_cloth_frames, to_cloth_frames, InputFrame};
use crate::geom::geometry_image::images_to_sequence;
use crate::geom::{Domain, GridMesh};
use crate::nn::bundle::AnisoCb;
use crate::nn::geometry_net::{interpolate, GeometryNet};
use crate::ops::{Interp, Ops, Precision};
use crate::sr::compose::{compose, DEFAULT_ETA};
use crate::sr::params::{UpscaleParams, EVAL_STRAIN_ITERS};
use crate::sr::upscale::upscale_images;
use crate::tensor::Tensor;

/// The physics pass's row and label (`demo` and `eval`).
pub const PHYSICS: &str = "anisocb --physics";

/// The row of the shipped defaults (the full anisocb at [`DEFAULT_ETA`]): the ratio and
/// invariance tables, the physics pass and the worst-frame renders are about it.
pub fn default_method() -> String {
    format!("anisocb, eta={DEFAULT_ETA}")
}

/// `etas` with the shipped default η in front when it is not among them: it is always
/// evaluated (see [`default_method`]).
pub fn with_default_eta(etas: &[f32]) -> Vec<f32> {
    let mut out = etas.to_vec();
    if !out.contains(&DEFAULT_ETA) {
        out.insert(0, DEFAULT_ETA);
    }
    out
}

/// One method's HR sequence for one run: T meshes of the HR grid, positions in metres.
pub struct Method {
    pub name: String,
    pub meshes: Vec<GridMesh>,
}

/// The models a run is upscaled with besides the main one (each optional), the names those
/// labelled by their file carry in their rows.
#[derive(Default)]
pub struct Contenders {
    /// A GeometryNet used alone (`U + R`): the prior method's setup.
    pub prior: Option<(String, GeometryNet)>,
    /// The paper-size anisocb config.
    pub paper: Option<AnisoCb>,
    /// The learned linear upsampler, the cheap yardstick.
    pub linear: Option<LinearUpsampler>,
    /// More anisocb bundles.
    pub also: Vec<(String, AnisoCb)>,
}

/// What [`evaluate_run`] does besides the methods of [`methods_for_run`].
#[derive(Clone, Debug, Default)]
pub struct EvalOptions {
    /// Enhancement factors η of the full anisocb rows (the default one is added,
    /// [`with_default_eta`]).
    pub etas: Vec<f32>,
    /// Add the physics pass on the default row's frames ([`PHYSICS`]).
    pub physics: bool,
    /// Also upscale the run moved, turned and scaled ([`invariance_rows`]).
    pub moved: bool,
    /// The nets' arithmetic in every anisocb row.
    pub precision: Precision,
}

/// One held-out run evaluated: its meshes, every method's, and their scores.
pub struct RunEval {
    /// The run's label (its directory name).
    pub scenario: String,
    /// The LR run and the HR truth as meshes, T frames each (metres).
    pub lr: Vec<GridMesh>,
    pub hr: Vec<GridMesh>,
    pub methods: Vec<Method>,
    /// One per method, in the same order: means over frames against `hr`, border band of
    /// [`BAND_ROWS`] rows, wrinkle detail beyond the LR grid.
    pub cells: Vec<Cell>,
    /// With [`EvalOptions::moved`]: the default row moved, turned and scaled.
    pub invariance: Vec<InvarianceRow>,
}

/// `U + residual(frame in the residual's coordinates)` for every frame, in `domain`: `u` (T, 3,
/// rH, rW) the interpolation the residual was trained over, `lr` (T, 3, H, W) in `domain`;
/// the residual is called frame by frame on (1, 3, H, W) in its `input` frame and its output
/// (1, 3, rH, rW), a vector field, goes back to the domain.
fn plus_residual(
    u: &Tensor,
    lr: &Tensor,
    domain: &Domain,
    input: InputFrame,
    residual: &mut dyn FnMut(&Tensor) -> Result<Tensor>,
) -> Result<Tensor> {
    let (x, maps) = to_cloth_frames(input, lr, domain);
    let mut r = Tensor::zeros(&u.shape);
    let per = r.len() / r.shape[0];
    for k in 0..lr.shape[0] {
        let rk = residual(&x.slice_batch(k, 1))?;
        r.data[k * per..(k + 1) * per].copy_from_slice(&rk.data);
    }
    from_cloth_frames(&mut r, &maps, false);
    compose(u, &r, None, None, 0.0)
}

/// Every method's HR sequence for the LR run `lr` (T, 3, H, W) in `domain`: bicubic,
/// Catmull-Rom, the contenders, anisocb without BoundaryNet, the variants of the shipped
/// settings (cloth-frame models: strain limit, temporal smoothing, mirrors, outline floor),
/// anisocb at each of `etas`, the paper config and the other bundles, in that order.
pub fn methods_for_run(
    ops: &dyn Ops,
    model: &AnisoCb,
    others: &Contenders,
    lr: &Tensor,
    domain: &Domain,
    etas: &[f32],
    precision: Precision,
) -> Result<Vec<Method>> {
    let p = UpscaleParams { precision, ..UpscaleParams::default() };
    // Every η is composed from one run of the nets, so EnhanceNet runs whatever the default η.
    let up = upscale_images(ops, model, lr, domain, &UpscaleParams { enhance_map: true, ..p }, &mut |_| {})?;
    // Each model's residual goes onto the interpolation it was trained over (its `upsample`).
    let scale = model.scale();
    let keys = interpolate(ops, lr, scale, Interp::Bicubic);
    let catmull_rom = interpolate(ops, lr, scale, Interp::CatmullRom);
    let u_of = |m: Interp| if m == Interp::CatmullRom { &catmull_rom } else { &keys };
    let mut out = vec![
        Method { name: "bicubic".into(), meshes: images_to_sequence(&keys, domain) },
        Method { name: "catmull-rom".into(), meshes: images_to_sequence(&catmull_rom, domain) },
    ];
    if let Some(l) = &others.linear {
        let hr = plus_residual(u_of(l.upsample), lr, domain, l.input_frame, &mut |x| l.residual(x))?;
        out.push(Method { name: "linear upsampler".into(), meshes: images_to_sequence(&hr, domain) });
    }
    if let Some((name, g)) = &others.prior {
        let input = g.trunk.config.input_frame;
        let u = u_of(g.trunk.config.upsample);
        let hr = plus_residual(u, lr, domain, input, &mut |x| Ok(g.forward(ops, x)?.1))?;
        out.push(Method {
            name: format!("GeometryNet only [{name}]"),
            meshes: images_to_sequence(&hr, domain),
        });
    }
    // Without BoundaryNet's gate (the outline floor as in the full pipeline).
    let no_b = up.without_boundary(DEFAULT_ETA)?;
    out.push(Method {
        name: format!("anisocb -boundary, eta={DEFAULT_ETA}"),
        meshes: images_to_sequence(&no_b, domain),
    });
    // A row of the pipeline run with other settings than the defaults.
    let variant = |m: &AnisoCb, params: &UpscaleParams, what: &str| -> Result<Method> {
        let hr = upscale_images(ops, m, lr, domain, params, &mut |_| {})?.hr;
        Ok(Method {
            name: format!("anisocb {what}, eta={DEFAULT_ETA}"),
            meshes: images_to_sequence(&hr, domain),
        })
    };
    if model.input_frame() == InputFrame::Cloth {
        let sp = UpscaleParams { strain_iters: EVAL_STRAIN_ITERS, ..p };
        out.push(variant(model, &sp, &format!("+ strain limit ({EVAL_STRAIN_ITERS} iterations)"))?);
        // The other side of the temporal-smoothing choice: off if it is on by default, radius
        // 2 (the earlier default) if it is off.
        let tp = UpscaleParams { temporal: if p.temporal == 0 { 2 } else { 0 }, ..p };
        let what = if tp.temporal == 0 {
            "per frame (no temporal smoothing)".to_string()
        } else {
            format!("+ temporal smoothing (radius {})", tp.temporal)
        };
        out.push(variant(model, &tp, &what)?);
        let mp = UpscaleParams { mirrors: !p.mirrors, ..p };
        out.push(variant(
            model,
            &mp,
            if mp.mirrors { "+ mirror averaging" } else { "without mirror averaging" },
        )?);
        // The outline floor only recomposes the same network outputs.
        let mut flipped = up.clone();
        flipped.set_keep_outline(!up.keeps_outline());
        let what = if flipped.keeps_outline() { "+ outline floor" } else { "without outline floor" };
        out.push(Method {
            name: format!("anisocb {what}, eta={DEFAULT_ETA}"),
            meshes: images_to_sequence(&flipped.with_eta(DEFAULT_ETA)?, domain),
        });
    }
    for &eta in etas {
        out.push(Method {
            name: format!("anisocb, eta={eta}"),
            meshes: images_to_sequence(&up.with_eta(eta)?, domain),
        });
    }
    if let Some(pm) = &others.paper {
        out.push(variant(pm, &p, "paper config")?);
    }
    for (name, m) in &others.also {
        out.push(variant(m, &p, &format!("[{name}]"))?);
    }
    Ok(out)
}

/// Evaluate `model` and the contenders on one held-out run pair: [`methods_for_run`] (at
/// `opts.etas` and the default η), then the physics pass and the invariance check if asked,
/// then every method scored against the HR truth.
pub fn evaluate_run(
    ops: &dyn Ops,
    model: &AnisoCb,
    others: &Contenders,
    pair: &RunPair,
    opts: &EvalOptions,
) -> Result<RunEval> {
    let (lr, domain) = (&pair.lr, &pair.domain);
    // Runs are labelled by their directory name (unique, and the user's own naming).
    let scenario = pair.label();
    let hr = images_to_sequence(&pair.hr, domain);
    let lr_m = images_to_sequence(lr, domain);
    let mut methods =
        methods_for_run(ops, model, others, lr, domain, &with_default_eta(&opts.etas), opts.precision)?;
    let ours = default_method();
    let mut invariance = Vec::new();
    if opts.physics {
        let o = &methods.iter().find(|m| m.name == ours).unwrap().meshes;
        let p = FollowParams::for_run(&pair.meta);
        let meshes = Follower::run(o, (lr.shape[3], lr.shape[2]), &p)?;
        methods.push(Method { name: PHYSICS.into(), meshes });
    }
    if opts.moved {
        let o = &methods.iter().find(|m| m.name == ours).unwrap().meshes;
        invariance = invariance_rows(ops, model, &scenario, &lr_m, o, &hr, opts.precision)?;
    }
    let mask = border_band(hr[0].w, hr[0].h, BAND_ROWS);
    // Wrinkle detail is what the grid every method upscaled (lr: (T, 3, h, w)) cannot hold.
    let (lr_w, lr_h) = (lr.shape[3], lr.shape[2]);
    let mut cells = Vec::new();
    for m in &methods {
        let mut metrics = sequence_metrics(&m.meshes, &hr, Some(&mask))?;
        metrics.wrinkle = Some(wrinkle_stats(&m.meshes, &hr, lr_w, lr_h)?);
        cells.push(Cell { method: m.name.clone(), scenario: scenario.clone(), metrics });
    }
    Ok(RunEval { scenario, lr: lr_m, hr, methods, cells, invariance })
}
