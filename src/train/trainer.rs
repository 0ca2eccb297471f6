//! The training loop: seeded patches → forward/backward → Adam, validation on held-out
//! frames, `loss.csv`, atomic checkpoints, bit-identical `resume`, and a NaN/Inf guard.
//!
//! Library entry points: [`train`] (one net, `DIR/weights.npz`) and [`train_all`] (the three
//! nets one after another in `DIR/{geometry,boundary,enhance}/`, then the bundle
//! `DIR/weights.npz`). Both report progress through an [`Event`] callback and draw nothing: the
//! CLI (`app/train.rs`) draws the progress bar and the PNG loss curve (`viz::plot::loss_plot`,
//! on each [`Event::Checkpoint`]) from it, so the library trains without feature `viz`.
//!
//! `DIR/checkpoint.npz` holds `net.*` (weights + `net.config.json`), `adam.*` ([`Adam::save`]),
//! `history` (K, 3: step, train loss, val loss or NaN) and `trainer.json` (step, seed and every
//! option that must not change across a resume). Sampling is keyed by (seed, step) (see
//! [`super::patches`]), so `(seed, step)` *is* the RNG state.

use super::adam::Adam;
use super::patches::{gather, interpolate_all, split, PatchSampler, TrainingData};
use crate::cuda::{DeviceTrainer, StepLoss};
use crate::error::{Error, Result};
use crate::io::json::Object;
use crate::io::{read_npz, write_atomic_bytes, write_npz, NpzEntries};
use crate::nn::geometry_net::{geometry_loss, GeometryLoss};
use crate::nn::map_net::map_loss;
use crate::nn::weights::{push_trunk, save_net, trunk_from_npz};
use crate::nn::{AnisoCb, NetConfig, NetKind, Trunk};
use crate::ops::loss::DetailEnergy;
use crate::ops::{AdamParams, Ops};
use crate::tensor::Tensor;
use std::path::{Path, PathBuf};

/// Everything a run needs besides the data. Defaults follow the paper (Adam, lr 1e-4, batch 32).
#[derive(Clone, Debug)]
pub struct TrainOptions {
    pub config: NetConfig,
    /// Optimisation steps (batches) per net.
    pub steps: u64,
    pub batch: usize,
    /// LR patch side in pixels (clamped to the frame); the HR patch is r× it.
    pub patch: usize,
    pub adam: AdamParams,
    pub seed: u64,
    /// Fraction of frames held out for validation (the last ones).
    pub val_frac: f32,
    /// Validation every this many steps (and at the last step); 0 = only at the end.
    pub val_every: u64,
    /// Checkpoint every this many steps (and at the last step); 0 = only at the end.
    pub checkpoint_every: u64,
    /// BCE weight of positive pixels for BoundaryNet/EnhanceNet (1 = plain BCE).
    pub pos_weight: f32,
    /// GeometryNet: weight of the edge-vector term added to the MSE (`ops::loss::edge_mse`;
    /// 0 = the paper's Eq 3 alone).
    pub edge_weight: f32,
    /// GeometryNet: weight of the curvature term (`ops::loss::laplacian_mse`; 0 = off).
    pub laplacian_weight: f32,
    /// GeometryNet: weight of the edge-length term (`ops::loss::edge_length_mse`; 0 = off).
    pub length_weight: f32,
    /// GeometryNet: weight of the wrinkle-energy term (`ops::loss::detail_energy_mse`: local
    /// fold amplitude, not phase; 0 = off).
    pub detail_weight: f32,
    /// GeometryNet: window radius of the wrinkle-energy term, in HR pixels.
    pub detail_radius: usize,
    /// GeometryNet: the wrinkle-energy term counts only the detail along the surface normal
    /// ([`DetailEnergy::normal_only`]); false = all three components.
    pub detail_normal_only: bool,
    /// Mirror every training sample at random into one of the grid's four mirror images
    /// ([`PatchSampler::mirror`]): the nets learn cloth whichever way its grid runs.
    pub mirror: bool,
    /// Continue from `out/checkpoint.npz`.
    pub resume: bool,
    /// Start from these weights instead of a random init (fine-tuning): the net of the trained
    /// kind and config, read from a one-net weights file or a bundle (its first GeometryNet,
    /// its BoundaryNet or EnhanceNet). Adam starts afresh.
    pub init: Option<PathBuf>,
    pub out: PathBuf,
}

/// Largest batch [`TrainOptions::check_sizes`] accepts (patches per step): the paper trains
/// with 32; beyond a few hundred a step is no better an estimate of the gradient, only larger.
pub const MAX_BATCH: usize = 4096;

/// Largest LR patch side (pixels) [`TrainOptions::check_sizes`] accepts. Patches are clamped
/// to the frame, so any side at least the frame's trains on whole frames.
pub const MAX_PATCH: usize = 1024;

/// Largest number of HR pixels in one training batch (batch × HR patch area, after clamping
/// to the frame) [`TrainOptions::check_sizes`] accepts: every layer keeps `channels` values of
/// each for the backward pass, so 2²² pixels — 128× the default of 32 patches of 32 × 32 — is
/// already 1 GiB per layer at the paper's 64 channels.
pub const MAX_BATCH_PIXELS: usize = 1 << 22;

impl TrainOptions {
    /// Refuse a batch or patch size that could not be allocated, before anything is: `batch`
    /// in 1..=[`MAX_BATCH`], `patch` in 1..=[`MAX_PATCH`], and their batch on `data` (the patch
    /// clamped to its frames, ×`scale` for the HR side) at most [`MAX_BATCH_PIXELS`] pixels.
    pub fn check_sizes(&self, data: &TrainingData) -> Result<()> {
        if self.batch == 0 || self.batch > MAX_BATCH {
            return Err(Error::invalid(
                "batch",
                format!(
                    "must be 1 to {MAX_BATCH} patches per step, got {} (the paper trains with 32)",
                    self.batch
                ),
            ));
        }
        if self.patch == 0 || self.patch > MAX_PATCH {
            return Err(Error::invalid(
                "patch",
                format!(
                    "must be 1 to {MAX_PATCH} LR pixels per side, got {} (a patch is clamped to \
                     the frame: one as large as the frame trains on whole frames)",
                    self.patch
                ),
            ));
        }
        let (h, w) = data.lr_size();
        let (hh, hw) = (self.patch.min(h) * data.scale, self.patch.min(w) * data.scale);
        let pixels = (self.batch as u128) * (hh as u128) * (hw as u128);
        if pixels > MAX_BATCH_PIXELS as u128 {
            let gib = pixels as f64 * self.config.channels as f64 * 4.0 / (1u64 << 30) as f64;
            return Err(Error::invalid(
                "batch",
                format!(
                    "{} patches of {hh}×{hw} HR pixels are {pixels} pixels per step, more than \
                     {MAX_BATCH_PIXELS}: every layer would keep {gib:.1} GiB for the backward \
                     pass; lower the batch or the patch size",
                    self.batch
                ),
            ));
        }
        Ok(())
    }

    /// GeometryNet's loss terms from `edge_weight`, `laplacian_weight`, `length_weight` and
    /// `detail_weight` / `detail_radius` (ε the default of [`DetailEnergy`]).
    pub fn geometry_loss(&self) -> GeometryLoss {
        GeometryLoss {
            edge: self.edge_weight,
            laplacian: self.laplacian_weight,
            length: self.length_weight,
            detail: self.detail_weight,
            detail_params: DetailEnergy {
                radius: self.detail_radius,
                normal_only: self.detail_normal_only,
                ..DetailEnergy::default()
            },
        }
    }
}

impl Default for TrainOptions {
    fn default() -> Self {
        TrainOptions {
            config: NetConfig::small(),
            steps: 2000,
            batch: 32,
            patch: 16,
            adam: AdamParams::default(),
            seed: 0,
            val_frac: 0.1,
            val_every: 100,
            checkpoint_every: 500,
            pos_weight: 1.0,
            edge_weight: 0.0,
            laplacian_weight: 0.0,
            length_weight: 0.0,
            detail_weight: 0.0,
            detail_radius: DetailEnergy::default().radius,
            detail_normal_only: DetailEnergy::default().normal_only,
            mirror: false,
            resume: false,
            init: None,
            out: PathBuf::from("out"),
        }
    }
}

/// One row of the loss log.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LogRow {
    /// 1-based step after which the losses were measured.
    pub step: u64,
    /// Loss of the step's training batch (before its update).
    pub train: f32,
    /// Validation loss after the step, NaN where not measured.
    pub val: f32,
}

/// What the loop tells its caller.
#[derive(Debug)]
pub enum Event<'a> {
    /// A run of `net` begins at `start` (0, or the resumed step) of `steps`. `baseline_val`:
    /// GeometryNet's validation loss with `R = 0` (bicubic alone), the number to beat.
    Start {
        net: NetKind,
        start: u64,
        steps: u64,
        train_frames: usize,
        val_frames: usize,
        baseline_val: Option<f32>,
    },
    Step {
        net: NetKind,
        step: u64,
        loss: f32,
    },
    Validation {
        net: NetKind,
        step: u64,
        loss: f32,
    },
    /// A checkpoint was written; `history` is the whole log so far (for `loss.csv` / the curve).
    Checkpoint {
        net: NetKind,
        step: u64,
        dir: &'a Path,
        history: &'a [LogRow],
    },
}

/// Result of one net's run.
#[derive(Clone, Debug)]
pub struct TrainReport {
    pub trunk: Trunk,
    pub history: Vec<LogRow>,
    pub last_train_loss: f32,
    pub last_val_loss: Option<f32>,
    /// GeometryNet only: validation MSE of the bicubic interpolation alone (`R = 0`).
    pub baseline_val_loss: Option<f32>,
    /// Training samples per second over the steps run in this process.
    pub samples_per_s: f64,
    pub weights: PathBuf,
}

/// Loss of `trunk` on a batch; adds gradients into `grads` if given.
fn batch_loss(
    ops: &dyn Ops,
    trunk: &Trunk,
    lr: &Tensor,
    u: &Tensor,
    target: &Tensor,
    o: &TrainOptions,
    grads: Option<&mut Trunk>,
) -> Result<f32> {
    match trunk.kind {
        NetKind::Geometry => geometry_loss(ops, trunk, lr, u, target, o.geometry_loss(), grads),
        _ => map_loss(ops, trunk, lr, target, o.pos_weight, grads),
    }
}

/// Mean loss over the validation frames (whole frames, 8 at a time), weighted by pixels; on
/// `device`'s copy of the weights where there is one (`trunk` is then not read).
fn validation_loss(
    ops: &dyn Ops,
    trunk: &Trunk,
    device: Option<(&DeviceTrainer, StepLoss)>,
    data: &TrainingData,
    u_all: Option<&Tensor>,
    val: &[usize],
    o: &TrainOptions,
) -> Result<Option<f32>> {
    if val.is_empty() {
        return Ok(None);
    }
    let mut sum = 0.0f64;
    for chunk in val.chunks(8) {
        let lr = gather(&data.lr, chunk);
        let u = u_all.map(|u| gather(u, chunk)).unwrap_or_else(|| Tensor::zeros(&[0]));
        let t = gather(data.target(trunk.kind), chunk);
        let l = match device {
            Some((d, loss)) => d.loss(&lr, &u, &t, loss),
            None => batch_loss(ops, trunk, &lr, &u, &t, o, None)?,
        };
        crate::ops::check_device(ops)?;
        sum += l as f64 * chunk.len() as f64;
    }
    Ok(Some((sum / val.len() as f64) as f32))
}

fn options_json(net: NetKind, o: &TrainOptions, data_fp: u64, step: u64) -> String {
    let obj = Object::default()
        .str("format", "anisocb-checkpoint")
        .num("version", 1)
        .str("net", net.name())
        .num("step", step)
        .num("seed", o.seed)
        .num("batch", o.batch)
        .num("patch", o.patch)
        .num("lr", o.adam.lr)
        .num("beta1", o.adam.beta1)
        .num("beta2", o.adam.beta2)
        .num("eps", o.adam.eps)
        .num("val_frac", o.val_frac)
        .num("pos_weight", o.pos_weight)
        .num("edge_weight", o.edge_weight)
        .num("laplacian_weight", o.laplacian_weight)
        .num("length_weight", o.length_weight)
        .str("data", &format!("{data_fp:016x}"));
    // Written only when on, so checkpoints from before the option still resume.
    let obj = if o.mirror { obj.num("mirror", 1) } else { obj };
    let obj = match &o.init {
        Some(p) => obj.str("init", &p.display().to_string()),
        None => obj,
    };
    let obj = if o.detail_weight != 0.0 {
        obj.num("detail_weight", o.detail_weight)
            .num("detail_radius", o.detail_radius)
            .num("detail_normal_only", o.detail_normal_only as usize)
    } else {
        obj
    };
    obj.to_json()
}

/// Options that must be equal for a resume to reproduce an uninterrupted run.
fn check_resumable(path: &Path, saved: &Object, net: NetKind, o: &TrainOptions, fp: u64) -> Result<u64> {
    let now = Object::parse(&options_json(net, o, fp, 0)).expect("own JSON parses");
    let mut diffs = Vec::new();
    for (k, v) in &now.0 {
        if k == "step" {
            continue;
        }
        match saved.get(k) {
            Some(s) if s == v => {}
            Some(s) => diffs.push(format!("{k}: {s} in checkpoint vs {v} now")),
            None => diffs.push(format!("{k}: missing in checkpoint")),
        }
    }
    for (k, v) in &saved.0 {
        if k != "step" && now.get(k).is_none() {
            diffs.push(format!("{k}: {v} in checkpoint, not set now"));
        }
    }
    if !diffs.is_empty() {
        return Err(Error::format(
            path,
            format!(
                "cannot resume with different options ({}); rerun with the original ones",
                diffs.join("; ")
            ),
        ));
    }
    saved
        .get("step")
        .and_then(|v| v.as_u64())
        .ok_or_else(|| Error::format(path, "trainer.json: missing 'step'"))
}

struct State {
    trunk: Trunk,
    adam: Adam,
    step: u64,
    history: Vec<LogRow>,
}

/// Adam over the trunk's parameter buffers, in [`Trunk::params`] order.
fn new_adam(trunk: &Trunk, o: &TrainOptions) -> Adam {
    let sizes: Vec<usize> = trunk.params().iter().map(|(_, t)| t.len()).collect();
    Adam::new(o.adam, &sizes)
}

fn write_checkpoint(path: &Path, net: NetKind, o: &TrainOptions, fp: u64, s: &State) -> Result<()> {
    let mut e = NpzEntries::default();
    push_trunk(&mut e, &s.trunk, "net.");
    s.adam.save("adam.", &mut e);
    let mut h = Vec::with_capacity(s.history.len() * 3);
    for r in &s.history {
        h.extend_from_slice(&[r.step as f32, r.train, r.val]);
    }
    e.push_array("history", Tensor { shape: [s.history.len(), 3].into(), data: h });
    e.push_file("trainer.json", options_json(net, o, fp, s.step).into_bytes());
    write_npz(path, &e)
}

fn read_checkpoint(path: &Path, net: NetKind, o: &TrainOptions, fp: u64) -> Result<State> {
    let e = read_npz(path)?;
    let tj =
        e.file("trainer.json").ok_or_else(|| Error::format(path, "not a checkpoint (no trainer.json)"))?;
    let saved = Object::parse(&String::from_utf8_lossy(tj)).map_err(|e| e.in_file(path))?;
    let step = check_resumable(path, &saved, net, o, fp)?;
    let trunk = trunk_from_npz(&e, "net.", path, Some((net, o.config)))?;
    let mut adam = new_adam(&trunk, o);
    adam.load(&e, "adam.", path)?;
    if adam.step != step {
        return Err(Error::format(path, format!("Adam is at step {} but the trainer at {step}", adam.step)));
    }
    let h = e.require(path, "history")?;
    let history =
        h.data.chunks_exact(3).map(|r| LogRow { step: r[0] as u64, train: r[1], val: r[2] }).collect();
    Ok(State { trunk, adam, step, history })
}

/// `loss.csv` (step, train_loss, val_loss; val empty where not measured), atomically.
pub fn write_loss_csv(path: &Path, history: &[LogRow]) -> Result<()> {
    let mut s = String::from("step,train_loss,val_loss\n");
    for r in history {
        let val = if r.val.is_nan() { String::new() } else { format!("{}", r.val) };
        s.push_str(&format!("{},{},{}\n", r.step, r.train, val));
    }
    write_atomic_bytes(path, s.as_bytes())
}

impl TrainOptions {
    /// Everything [`train`] checks before it writes anything: the config, the sizes, and that
    /// the net fits `data` (its scale, its input frame); the learning rate.
    pub fn check(&self, data: &TrainingData) -> Result<()> {
        self.config.validate()?;
        self.check_sizes(data)?;
        if self.config.scale != data.scale {
            return Err(Error::config(format!(
                "net upscale ×{} but the data is ×{} (hr vs lr shapes)",
                self.config.scale, data.scale
            )));
        }
        if self.config.input_frame != data.input_frame {
            return Err(Error::config(format!(
                "the net is configured for {} input but the data is in the {} frame",
                self.config.input_frame.name(),
                data.input_frame.name()
            )));
        }
        if !(self.adam.lr > 0.0 && self.adam.lr.is_finite()) {
            return Err(Error::config(format!("learning rate must be > 0, got {}", self.adam.lr)));
        }
        Ok(())
    }
}

/// The `net` of `config` in the weights file `path` ([`TrainOptions::init`]).
fn init_from(path: &Path, net: NetKind, config: NetConfig) -> Result<Trunk> {
    let trunk = match crate::nn::weights::load_any(path)? {
        crate::nn::weights::Weights::Net(t) => *t,
        crate::nn::weights::Weights::Bundle(b) => {
            b.named_trunks().into_iter().find(|(_, t)| t.kind == net).map(|(_, t)| t.clone()).ok_or_else(
                || Error::format(path, format!("the bundle has no {} net to start from", net.name())),
            )?
        }
    };
    if trunk.kind != net {
        return Err(Error::format(
            path,
            format!(
                "--init: these are {} weights; the {} net trained here needs {} weights (a bundle holds all three)",
                trunk.kind.name(),
                net.name(),
                net.name()
            ),
        ));
    }
    if trunk.config != config {
        return Err(Error::format(
            path,
            format!(
                "--init: these {} weights are of another configuration ({}) than the net trained here \
                 ({}): give the same --config, --padding, --upsample and input frame",
                net.name(),
                trunk.config,
                config
            ),
        ));
    }
    Ok(trunk)
}

/// The files [`train`] writes in its folder (`loss.png` by the caller, on each checkpoint).
pub const TRAIN_FILES: [&str; 4] = ["checkpoint.npz", "loss.csv", "loss.png", "weights.npz"];

/// Train one net on `data` into `opts.out`: `checkpoint.npz`, `loss.csv`, `weights.npz`.
pub fn train(
    ops: &dyn Ops,
    data: &TrainingData,
    net: NetKind,
    opts: &TrainOptions,
    on_event: &mut dyn FnMut(Event),
) -> Result<TrainReport> {
    opts.check(data)?;
    crate::io::atomic::ensure_dir(&opts.out)?;
    let ckpt = opts.out.join("checkpoint.npz");
    // Temporaries of atomic writes that a killed run left behind (never a partial file).
    for f in TRAIN_FILES {
        crate::io::atomic::remove_stale_temps(&opts.out.join(f))?;
    }
    let fp = data.fingerprint(net);
    let mut st = if opts.resume {
        if !ckpt.exists() {
            return Err(Error::invalid(
                "resume",
                format!(
                    "{}: there is no checkpoint to resume from; train from the start instead",
                    ckpt.display()
                ),
            ));
        }
        read_checkpoint(&ckpt, net, opts, fp)?
    } else {
        if ckpt.exists() {
            return Err(Error::format(
                &ckpt,
                "a checkpoint already exists here: resume it, start again over it (overwrite), or train \
                 into another folder",
            ));
        }
        let trunk = match &opts.init {
            Some(path) => init_from(path, net, opts.config)?,
            None => Trunk::init(net, opts.config, opts.seed),
        };
        State { adam: new_adam(&trunk, opts), trunk, step: 0, history: Vec::new() }
    };
    let (train_idx, val_idx) = split(data.len(), opts.val_frac)?;
    let mut sampler = PatchSampler::new(data, train_idx.clone(), opts.seed, opts.batch, opts.patch)?;
    sampler.mirror = opts.mirror;
    let u_all = (net == NetKind::Geometry).then(|| interpolate_all(ops, data, opts.config.upsample));
    let baseline_val = match &u_all {
        Some(u) if !val_idx.is_empty() => {
            let (uv, hv) = (gather(u, &val_idx), gather(&data.hr, &val_idx));
            let (_, _, lr_h, lr_w) = data.lr.dims4();
            Some(crate::nn::geometry_net::estimate_loss(ops, &uv, &hv, (lr_h, lr_w), opts.geometry_loss()).0)
        }
        _ => None,
    };
    on_event(Event::Start {
        net,
        start: st.step,
        steps: opts.steps,
        train_frames: train_idx.len(),
        val_frames: val_idx.len(),
        baseline_val,
    });
    let mut grads = st.trunk.zeros_like();
    // On a GPU: the trunk, its gradients and Adam's state stay on the device between steps
    // (validation runs there too), and come back to `st` for checkpoints and the weights file.
    let mut device = crate::cuda::device_trainer(ops, &st.trunk, &st.adam)?;
    let step_loss = match net {
        NetKind::Geometry => StepLoss::Geometry(opts.geometry_loss()),
        _ => StepLoss::Map { pos_weight: opts.pos_weight },
    };
    let t0 = std::time::Instant::now();
    let first = st.step;
    let mut last_val = st.history.iter().rev().find(|r| !r.val.is_nan()).map(|r| r.val);
    std::thread::scope(|scope| -> Result<()> {
        // On a GPU the host cuts the next batch while the device runs this step's.
        let ahead = device
            .is_some()
            .then(|| sampler.clone().ahead(scope, data, u_all.as_ref(), net, st.step..opts.steps));
        while st.step < opts.steps {
            let b = match &ahead {
                Some(rx) => rx.recv().expect("the batch thread ended early"),
                None => sampler.batch(data, u_all.as_ref(), net, st.step),
            };
            let loss = match device.as_mut() {
                Some(d) => d.step(&b.lr, &b.u, &b.target, step_loss),
                None => {
                    grads.fill_zero();
                    crate::ops::entered(ops, || {
                        batch_loss(ops, &st.trunk, &b.lr, &b.u, &b.target, opts, Some(&mut grads))
                    })?
                }
            };
            // A device failure makes the loss NaN: say what failed, not "try a lower --lr".
            crate::ops::check_device(ops)?;
            // (On the device the gradients are not inspected: a non-finite one shows as the loss.)
            let bad_grad = if device.is_some() {
                None
            } else {
                grads.params().into_iter().find_map(|(n, g)| g.first_non_finite().map(|(_, v)| (n, v)))
            };
            if !loss.is_finite() || bad_grad.is_some() {
                let what = match bad_grad {
                    Some((n, v)) if loss.is_finite() => format!("gradient of {n} is {v}"),
                    _ => format!("loss is {loss}"),
                };
                let last = if ckpt.exists() {
                    format!("the last good checkpoint is kept at {}", ckpt.display())
                } else {
                    "no checkpoint was written yet".to_string()
                };
                return Err(Error::numeric(format!(
                    "{} net, step {}: {what}; stopped ({last}). Try a lower learning rate or check the data.",
                    net.name(),
                    st.step + 1
                )));
            }
            if device.is_none() {
                let gs: Vec<&[f32]> = grads.params().into_iter().map(|(_, g)| g.data.as_slice()).collect();
                let mut ps: Vec<&mut [f32]> =
                    st.trunk.params_mut().into_iter().map(|p| p.data.as_mut_slice()).collect();
                st.adam.step(ops, &mut ps, &gs);
                // A GPU table's driver failure (its results are NaN from then on) stops the run here.
                crate::ops::check_device(ops)?;
            }
            st.step += 1;
            on_event(Event::Step { net, step: st.step, loss });
            let last_step = st.step == opts.steps;
            let validate = last_step || (opts.val_every > 0 && st.step % opts.val_every == 0);
            let checkpoint = !last_step && opts.checkpoint_every > 0 && st.step % opts.checkpoint_every == 0;
            if let (Some(d), true) = (&device, checkpoint || last_step) {
                d.store(&mut st.trunk, &mut st.adam)?;
            }
            let mut row = LogRow { step: st.step, train: loss, val: f32::NAN };
            if validate {
                let on_device = device.as_ref().map(|d| (d, step_loss));
                if let Some(vl) =
                    validation_loss(ops, &st.trunk, on_device, data, u_all.as_ref(), &val_idx, opts)?
                {
                    if !vl.is_finite() {
                        return Err(Error::numeric(format!(
                            "{} net, step {}: validation loss is {vl}; stopped (last good checkpoint kept at {})",
                            net.name(),
                            st.step,
                            ckpt.display()
                        )));
                    }
                    row.val = vl;
                    last_val = Some(vl);
                    on_event(Event::Validation { net, step: st.step, loss: vl });
                }
            }
            st.history.push(row);
            if checkpoint {
                write_checkpoint(&ckpt, net, opts, fp, &st)?;
                write_loss_csv(&opts.out.join("loss.csv"), &st.history)?;
                on_event(Event::Checkpoint { net, step: st.step, dir: &opts.out, history: &st.history });
            }
        }
        Ok(())
    })?;
    // Always (also when a resumed run had nothing left to do), so that a run killed anywhere
    // after its last step still ends with the same files as an uninterrupted one.
    write_checkpoint(&ckpt, net, opts, fp, &st)?;
    write_loss_csv(&opts.out.join("loss.csv"), &st.history)?;
    on_event(Event::Checkpoint { net, step: st.step, dir: &opts.out, history: &st.history });
    let weights = opts.out.join("weights.npz");
    save_net(&weights, &st.trunk)?;
    let secs = t0.elapsed().as_secs_f64();
    let ran = st.step - first;
    Ok(TrainReport {
        last_train_loss: st.history.last().map_or(f32::NAN, |r| r.train),
        last_val_loss: last_val,
        baseline_val_loss: baseline_val,
        samples_per_s: if secs > 0.0 { (ran * opts.batch as u64) as f64 / secs } else { 0.0 },
        history: st.history,
        trunk: st.trunk,
        weights,
    })
}

/// Train GeometryNet, BoundaryNet and EnhanceNet one after another (each in
/// `out/<net>/`, each resumable), then write the bundle `out/weights.npz`.
pub fn train_all(
    ops: &dyn Ops,
    data: &TrainingData,
    opts: &TrainOptions,
    on_event: &mut dyn FnMut(Event),
) -> Result<(AnisoCb, Vec<TrainReport>)> {
    let mut reports = Vec::new();
    for kind in NetKind::ALL {
        let out = opts.out.join(kind.name());
        // With --resume, a net whose run had not started yet starts fresh; a finished one is a no-op.
        let resume = opts.resume && out.join("checkpoint.npz").exists();
        let sub = TrainOptions { out, resume, ..opts.clone() };
        reports.push(train(ops, data, kind, &sub, on_event)?);
    }
    let mut t = reports.iter().map(|r| r.trunk.clone());
    let bundle = AnisoCb::from_trunks(t.next().unwrap(), t.next().unwrap(), t.next().unwrap())?;
    bundle.save(&opts.out.join("weights.npz"))?;
    Ok((bundle, reports))
}
