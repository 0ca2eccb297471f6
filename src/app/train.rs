//! `anisocb train`: train GeometryNet / BoundaryNet / EnhanceNet (or all three) on a dataset.

use super::ui::{progress, save_png};
use crate::error::{Error, Result};
use crate::eval::linear::LinearUpsampler;
use crate::io::json::{Object, Value};
use crate::nn::config::{parse_padding, parse_upsample};
use crate::nn::{NetConfig, NetKind};
use crate::ops::{AdamParams, Interp};
use crate::pipeline::folder::{self, Ownership};
use crate::train::patches::{gather, interpolate_all, split, TrainingData};
use crate::train::trainer::{train, train_all, Event, TrainOptions, TRAIN_FILES};
use crate::viz::plot::loss_plot;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Training set written by `anisocb dataset` (data.npz).
    #[arg(long)]
    pub data: PathBuf,
    /// Which network: geometry, boundary, enhance, all (one after another, into one bundle),
    /// or linear (the learned linear upsampler baseline of `anisocb eval --linear`: one ridge
    /// regression, seconds).
    #[arg(long, default_value = "geometry")]
    pub net: String,
    /// Net size: small (C=32, 4 blocks; CPU), paper (C=64, 10 blocks) or tiny (tests).
    #[arg(long, default_value = "small")]
    pub config: String,
    /// Conv padding: zero (paper) or replicate.
    #[arg(long, default_value = "zero")]
    pub padding: String,
    /// The interpolation U that GeometryNet's residual (and the linear upsampler's) refines:
    /// catmull-rom (Keys a = −0.5: evenly spaced vertices stay evenly spaced, so the residual
    /// is the cloth's detail and not a correction of the kernel) or bicubic (Keys a = −0.75,
    /// the paper's and PyTorch's, which bunches the vertices of an even row in a pattern tied
    /// to the grid). Saved in the weights; `upscale` and `eval` follow it.
    #[arg(long, default_value = "catmull-rom")]
    pub upsample: String,
    /// Output folder: checkpoint.npz, loss.csv, loss.png, weights.npz (with --net all, one
    /// folder of them per net and the bundle), train.json. Created if missing, or empty, or one
    /// that an earlier training on the same data owns (its train.json); anything else there is
    /// refused (see --overwrite). One run at a time trains into it (a lock).
    #[arg(long)]
    pub out: PathBuf,
    /// Train into --out even though it holds files no training on this data wrote (those this
    /// run writes are replaced, the rest left); without --resume, an existing checkpoint is
    /// removed and training starts again.
    #[arg(long)]
    pub overwrite: bool,
    /// Optimisation steps per net.
    #[arg(long, default_value_t = 2000)]
    pub steps: u64,
    #[arg(long, default_value_t = 32)]
    pub batch: usize,
    /// LR patch side in pixels (HR patch = 2× it); clamped to the frame size.
    #[arg(long, default_value_t = 16)]
    pub patch: usize,
    /// Adam learning rate.
    #[arg(long, default_value_t = 1e-4)]
    pub lr: f32,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Fraction of frames (the last ones) held out for validation.
    #[arg(long, default_value_t = 0.1)]
    pub val_frac: f32,
    /// Validation every N steps (and at the end).
    #[arg(long, default_value_t = 100)]
    pub val_every: u64,
    /// Checkpoint every N steps (and at the end).
    #[arg(long, default_value_t = 500)]
    pub checkpoint_every: u64,
    /// BCE weight of positive pixels for boundary/enhance (1 = plain BCE, calibrated maps).
    #[arg(long, default_value_t = 1.0)]
    pub pos_weight: f32,
    /// GeometryNet: weight of the edge-vector term (error of every mesh edge vector, which
    /// punishes swimming edge lengths and noisy normals) added to the position MSE; 0 = the
    /// paper's loss alone.
    #[arg(long, default_value_t = 1.0)]
    pub edge_weight: f32,
    /// GeometryNet: weight of the curvature term (error of the 5-point Laplacian of the
    /// positions, i.e. of the mean-curvature normal: bumps and dents that show in shading);
    /// 0 = off.
    #[arg(long, default_value_t = 0.0)]
    pub laplacian_weight: f32,
    /// GeometryNet: weight of the edge-length term (error of every mesh edge's length: a net
    /// that averages wrinkles it cannot place shrinks the cloth in its plane, and this prices
    /// the shortening); 0 = off.
    #[arg(long, default_value_t = 0.0)]
    pub length_weight: f32,
    /// GeometryNet: weight of the wrinkle-energy term (error of the local fold amplitude, the
    /// RMS of the detail beyond the LR frame in a window, but not of where the folds lie: the
    /// MSE averages out folds whose phase the LR frame leaves open, and this term asks for them
    /// back); 0 = off.
    #[arg(long, default_value_t = 0.0)]
    pub detail_weight: f32,
    /// GeometryNet: radius of the wrinkle-energy term's window in HR pixels (window 2R+1 square).
    #[arg(long, default_value_t = 3)]
    pub detail_radius: usize,
    /// GeometryNet: let the wrinkle-energy term count the detail's in-plane components too
    /// (by default only its part along the surface normal counts, as in `eval`'s wrinkle
    /// metric: with all three a net met the energy with in-plane ripples instead of folds).
    #[arg(long)]
    pub detail_all_components: bool,
    /// Mirror each training sample at random (left-right, top-bottom, both or neither, with
    /// the cloth frame the mirrored grid gets), so the nets treat a grid whichever way it runs.
    /// Not used for the shipped model: the orientation of a training clip is information
    /// (GeometryNet's validation loss +59 %), and `upscale --mirrors` gains without it.
    #[arg(long)]
    pub mirror_augment: bool,
    /// Ridge strength λ of `--net linear` (relative to the features' mean variance).
    #[arg(long, default_value_t = 1e-3)]
    pub ridge: f64,
    /// Continue from OUT/checkpoint.npz, bit-identically to an uninterrupted run (same device).
    /// The checkpoint vouches for the folder (same options, same data): its files are this
    /// run's even without train.json (a folder of an earlier version, or `--net geometry`'s
    /// OUT/geometry for `--net all`).
    #[arg(long)]
    pub resume: bool,
    /// Start from these weights instead of a random init, to fine-tune them on this data: a
    /// one-net weights file or a bundle (its first GeometryNet, or its map net of --net), of the
    /// same --config, --padding, --upsample and input frame. Adam starts afresh.
    #[arg(long, value_name = "WEIGHTS")]
    pub init: Option<std::path::PathBuf>,
    /// Where the ops run: cpu, or cuda (feature `cuda`, needs an NVIDIA GPU).
    #[arg(long, default_value = "cpu")]
    pub device: String,
}

pub fn run(a: Args) -> Result<()> {
    if a.steps == 0 && a.net != "linear" {
        return Err(Error::config(
            "--steps 0 would write untrained weights: give the number of optimisation steps (≥ 1)",
        ));
    }
    let upsample = parse_upsample(&a.upsample)?;
    let config =
        NetConfig::preset(&a.config)?.with_padding(parse_padding(&a.padding)?).with_upsample(upsample);
    let ops = crate::cuda::ops_for_device(&a.device)?;
    let data = TrainingData::load(&a.data)?;
    if a.net == "linear" {
        return fit_linear(ops.as_ref(), &data, &a, upsample);
    }
    let which = if a.net == "all" { None } else { Some(NetKind::parse(&a.net)?) };
    let config = config.with_input_frame(data.input_frame);
    let opts = TrainOptions {
        config,
        steps: a.steps,
        batch: a.batch,
        patch: a.patch,
        adam: AdamParams { lr: a.lr, ..AdamParams::default() },
        seed: a.seed,
        val_frac: a.val_frac,
        val_every: a.val_every,
        checkpoint_every: a.checkpoint_every,
        pos_weight: a.pos_weight,
        edge_weight: a.edge_weight,
        laplacian_weight: a.laplacian_weight,
        length_weight: a.length_weight,
        detail_weight: a.detail_weight,
        detail_radius: a.detail_radius,
        detail_normal_only: !a.detail_all_components,
        mirror: a.mirror_augment,
        resume: a.resume,
        init: a.init.clone(),
        out: a.out.clone(),
    };
    opts.check(&data)?;
    let own = ownership(&a);
    let claim = claim(&a, &own)?;
    if a.overwrite && !a.resume {
        // Start again: the checkpoints this run would otherwise refuse to train over.
        for f in own.files.iter().filter(|f| f.ends_with("checkpoint.npz")) {
            let p = a.out.join(f);
            if p.exists() {
                std::fs::remove_file(&p).map_err(|e| Error::io(&p, e))?;
            }
        }
    }
    // The summary says the run started once the checkpoint (with --resume) has been read.
    let mut started: Option<Result<()>> = None;
    let mut pb = progress(a.steps, "train");
    let mut ema: Option<f32> = None;
    let mut val: Option<f32> = None;
    let mut png_err = None;
    let mut on_event = |e: Event| match e {
        Event::Start { net, start, steps, train_frames, val_frames, baseline_val } => {
            started.get_or_insert_with(|| own.write_summary(&a.out, Object::new(), false));
            pb.finish_and_clear();
            pb = progress(steps, net.name());
            pb.set_position(start);
            ema = None;
            val = None;
            let line = format!(
                "{}: {} params, {train_frames} training / {val_frames} validation frames{}",
                net.name(),
                crate::nn::Trunk::zeros(net, config).num_params(),
                if start > 0 { format!(", resuming at step {start}") } else { String::new() }
            );
            // eprintln under suspend: shown also when stderr is not a terminal (bar hidden).
            pb.suspend(|| eprintln!("{line}"));
            if let Some(b) = baseline_val {
                pb.suspend(|| eprintln!("U alone (R = 0, {}): validation loss {b:.4e}", upsample.name()));
            }
        }
        Event::Step { step, loss, .. } => {
            let e = ema.map_or(loss, |e| 0.95 * e + 0.05 * loss);
            ema = Some(e);
            pb.set_position(step);
            let v = val.map_or(String::new(), |v| format!(" val {v:.3e}"));
            pb.set_message(format!("loss {e:.3e}{v}"));
        }
        Event::Validation { loss, .. } => val = Some(loss),
        Event::Checkpoint { net, dir, history, .. } => {
            let png = loss_plot(net.name(), history)
                .render(640, 360)
                .and_then(|img| save_png(&dir.join("loss.png"), &img));
            if let Err(e) = png {
                png_err.get_or_insert(e);
            }
        }
    };
    let summary = match which {
        Some(kind) => {
            let r = train(ops.as_ref(), &data, kind, &opts, &mut on_event)?;
            format!(
                "{}: train loss {:.4e}, val loss {}{}, {:.1} samples/s → {}",
                kind.name(),
                r.last_train_loss,
                r.last_val_loss.map_or("-".into(), |v| format!("{v:.4e}")),
                r.baseline_val_loss.map_or(String::new(), |b| format!(" (U alone {b:.4e})")),
                r.samples_per_s,
                r.weights.display()
            )
        }
        None => {
            let (_, reports) = train_all(ops.as_ref(), &data, &opts, &mut on_event)?;
            let mut s: Vec<String> = reports
                .iter()
                .map(|r| {
                    format!(
                        "{}: train {:.4e} val {}",
                        r.trunk.kind.name(),
                        r.last_train_loss,
                        r.last_val_loss.map_or("-".into(), |v| format!("{v:.4e}"))
                    )
                })
                .collect();
            s.push(format!("bundle → {}", a.out.join("weights.npz").display()));
            s.join("\n")
        }
    };
    pb.finish_and_clear();
    if let Some(e) = png_err {
        return Err(e);
    }
    started.unwrap_or(Ok(()))?;
    own.write_summary(&a.out, Object::new(), true)?;
    drop(claim);
    println!("{summary}");
    Ok(())
}

/// Who this run is for its output folder ([`folder::claim`]): the data set, the settings that
/// decide the weights, and every file it writes (one folder per net with `--net all`).
fn ownership(a: &Args) -> Ownership {
    let settings = Object::new()
        .str("net", &a.net)
        .str("config", &a.config)
        .str("padding", &a.padding)
        .str("upsample", &a.upsample)
        .num("steps", a.steps)
        .num("batch", a.batch)
        .num("patch", a.patch)
        .num("lr", a.lr)
        .num("seed", a.seed)
        .num("val_frac", a.val_frac)
        .num("val_every", a.val_every)
        .num("checkpoint_every", a.checkpoint_every)
        .num("pos_weight", a.pos_weight)
        .num("edge_weight", a.edge_weight)
        .num("laplacian_weight", a.laplacian_weight)
        .num("length_weight", a.length_weight)
        .num("detail_weight", a.detail_weight)
        .num("detail_radius", a.detail_radius)
        .val("detail_all_components", Value::Bool(a.detail_all_components))
        .val("mirror_augment", Value::Bool(a.mirror_augment))
        .num("ridge", a.ridge)
        .str("device", &a.device);
    // Written only when given, so folders of earlier runs still belong to the same settings.
    let settings = match &a.init {
        Some(p) => settings.str("init", &p.display().to_string()),
        None => settings,
    };
    let files: Vec<String> = match a.net.as_str() {
        "linear" => vec!["weights.npz".into()],
        "all" => NetKind::ALL
            .iter()
            .flat_map(|k| TRAIN_FILES.iter().map(move |f| format!("{}/{f}", k.name())))
            .chain(["weights.npz".to_string()])
            .collect(),
        _ => TRAIN_FILES.iter().map(|f| f.to_string()).collect(),
    };
    Ownership {
        job: "train",
        noun: "data set",
        inputs: folder::canonical(std::slice::from_ref(&a.data)),
        settings: settings.into(),
        summary: "train.json".into(),
        files,
    }
}

/// Claim `--out` for this run; with `--resume` the checkpoint vouches for the folder's files
/// (they are taken as this run's, see `--resume`).
fn claim(a: &Args, own: &Ownership) -> Result<folder::Claim> {
    let claim = folder::claim(&a.out, own, a.overwrite || a.resume)?;
    for n in &claim.removed {
        eprintln!("note: removed {n}, an earlier run's output that this run does not write");
    }
    Ok(claim)
}

/// `--net linear`: fit [`LinearUpsampler`] on the training frames, report its validation MSE
/// next to bicubic's, write `OUT/weights.npz`.
fn fit_linear(ops: &dyn crate::ops::Ops, data: &TrainingData, a: &Args, upsample: Interp) -> Result<()> {
    let (train_idx, val_idx) = split(data.len(), a.val_frac)?;
    let u = interpolate_all(ops, data, upsample);
    let mut resid = data.hr.clone();
    for (r, u) in resid.data.iter_mut().zip(&u.data) {
        *r -= u;
    }
    let fit = LinearUpsampler::fit(
        &gather(&data.lr, &train_idx),
        &gather(&resid, &train_idx),
        a.ridge,
        data.input_frame,
        upsample,
    )?;
    if !val_idx.is_empty() {
        let (uv, hv) = (gather(&u, &val_idx), gather(&data.hr, &val_idx));
        let mut est = fit.residual(&gather(&data.lr, &val_idx))?;
        for (e, u) in est.data.iter_mut().zip(&uv.data) {
            *e += u;
        }
        eprintln!(
            "linear: validation MSE {:.4e} ({} alone {:.4e}) on {} frames",
            ops.mse(&est, &hv).0,
            upsample.name(),
            ops.mse(&uv, &hv).0,
            val_idx.len()
        );
    }
    let own = ownership(a);
    let claim = claim(a, &own)?;
    let path = a.out.join("weights.npz");
    crate::io::write_npz(&path, &fit.to_npz())?;
    own.write_summary(&a.out, Object::new(), true)?;
    drop(claim);
    eprintln!("linear upsampler (λ = {}, {} input) → {}", a.ridge, data.input_frame.name(), path.display());
    Ok(())
}
