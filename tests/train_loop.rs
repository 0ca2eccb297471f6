//! The training loop: bit-identical resume, overfitting a single pair, the NaN/Inf guard,
//! refusal to resume with other options, fine-tuning from given weights, patch alignment, and
//! `--net all` bundles.

use anisocb::nn::weights::load_net;
use anisocb::nn::{AnisoCb, NetConfig, NetKind};
use anisocb::ops::{AdamParams, Cpu, Ops};
use anisocb::train::patches::{split, PatchSampler, TrainingData};
use anisocb::train::trainer::{train, train_all, Event, TrainOptions};
use anisocb::Tensor;
use std::path::PathBuf;

fn tmp(name: &str) -> PathBuf {
    let d = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("anisocb-train-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// `n` frames of a smooth surface (LR h×w) with HR = bicubic(LR) + a wrinkle pattern, and
/// boundary / edge maps marking the border and the wrinkle crests.
fn synthetic(n: usize, h: usize, w: usize) -> TrainingData {
    let ops: &dyn Ops = &Cpu;
    let mut lr = Tensor::zeros(&[n, 3, h, w]);
    for f in 0..n {
        let ph = f as f32 * 0.37;
        for y in 0..h {
            for x in 0..w {
                let (u, v) = (x as f32 / (w - 1) as f32, y as f32 / (h - 1) as f32);
                let vals = [u, v, 0.5 + 0.2 * (3.0 * u + ph).sin() * (2.0 * v).cos()];
                for (c, val) in vals.iter().enumerate() {
                    let i = lr.idx4(f, c, y, x);
                    lr.data[i] = *val;
                }
            }
        }
    }
    let mut hr = ops.resize(&lr, 2 * h, 2 * w, anisocb::ops::Interp::Bicubic);
    let mut boundary = Tensor::zeros(&[n, 1, 2 * h, 2 * w]);
    let mut edges = Tensor::zeros(&[n, 1, 2 * h, 2 * w]);
    for f in 0..n {
        for y in 0..2 * h {
            for x in 0..2 * w {
                let wr = (x as f32 * 1.7 + f as f32).sin();
                let i = hr.idx4(f, 2, y, x);
                hr.data[i] += 0.02 * wr;
                let b = y == 0 || x == 0 || y == 2 * h - 1 || x == 2 * w - 1;
                let j = boundary.idx4(f, 0, y, x);
                boundary.data[j] = b as u8 as f32;
                edges.data[j] = (wr > 0.8) as u8 as f32;
            }
        }
    }
    TrainingData::new(lr, hr, boundary, edges).unwrap()
}

fn tiny_opts(out: PathBuf, steps: u64) -> TrainOptions {
    TrainOptions {
        config: NetConfig::tiny(),
        steps,
        batch: 3,
        patch: 5,
        adam: AdamParams { lr: 1e-3, ..AdamParams::default() },
        seed: 11,
        val_frac: 0.25,
        val_every: 2,
        checkpoint_every: 100,
        pos_weight: 2.0,
        edge_weight: 0.5,
        laplacian_weight: 0.25,
        length_weight: 0.5,
        detail_weight: 0.0,
        detail_radius: 3,
        detail_normal_only: true,
        // Mirrored samples: resuming must reproduce the sampler's mirrors too.
        mirror: true,
        resume: false,
        init: None,
        out,
    }
}

#[test]
fn resume_reproduces_uninterrupted_run_bit_for_bit() {
    let data = synthetic(5, 6, 7);
    for kind in [NetKind::Geometry, NetKind::Boundary] {
        let k = 4;
        let full =
            train(&Cpu, &data, kind, &tiny_opts(tmp(&format!("full-{}", kind.name())), 2 * k), &mut |_| {})
                .unwrap();
        let dir = tmp(&format!("split-{}", kind.name()));
        train(&Cpu, &data, kind, &tiny_opts(dir.clone(), k), &mut |_| {}).unwrap();
        let resumed = train(
            &Cpu,
            &data,
            kind,
            &TrainOptions { resume: true, ..tiny_opts(dir.clone(), 2 * k) },
            &mut |_| {},
        )
        .unwrap();
        assert_eq!(resumed.history.len(), full.history.len());
        for (a, b) in resumed.history.iter().zip(&full.history) {
            assert_eq!(a.train.to_bits(), b.train.to_bits(), "{}: step {} train loss", kind.name(), a.step);
            assert_eq!(a.val.to_bits(), b.val.to_bits(), "{}: step {} val loss", kind.name(), a.step);
        }
        for ((n, a), (_, b)) in resumed.trunk.params().into_iter().zip(full.trunk.params()) {
            let same = a.data.iter().zip(&b.data).all(|(x, y)| x.to_bits() == y.to_bits());
            assert!(same, "{}: {n} differs after resume", kind.name());
        }
        let on_disk = load_net(&dir.join("weights.npz"), Some((kind, NetConfig::tiny()))).unwrap();
        assert_eq!(on_disk, resumed.trunk);
        let csv = std::fs::read_to_string(dir.join("loss.csv")).unwrap();
        assert_eq!(csv.lines().count(), 1 + 2 * k as usize);
    }
}

#[test]
fn tiny_geometry_net_overfits_a_single_pair() {
    let data = synthetic(1, 6, 6);
    let opts = TrainOptions {
        batch: 1,
        patch: 6,
        val_frac: 0.0,
        adam: AdamParams { lr: 3e-3, ..AdamParams::default() },
        // The paper's loss (Eq 3) alone: the bound below is on the MSE.
        edge_weight: 0.0,
        laplacian_weight: 0.0,
        length_weight: 0.0,
        ..tiny_opts(tmp("overfit"), 1500)
    };
    let r = train(&Cpu, &data, NetKind::Geometry, &opts, &mut |_| {}).unwrap();
    let first = r.history[0].train;
    let last = r.last_train_loss;
    println!("overfit: loss {first:.3e} → {last:.3e}");
    assert!(last < 1e-5 && last < first * 1e-3, "loss {first} → {last}");
}

#[test]
fn init_starts_from_the_given_weights_and_refuses_another_net() {
    let data = synthetic(1, 6, 6);
    let pair = |out: &str, steps, init| TrainOptions {
        batch: 1,
        patch: 6,
        val_frac: 0.0,
        adam: AdamParams { lr: 3e-3, ..AdamParams::default() },
        init,
        ..tiny_opts(tmp(out), steps)
    };
    let a = pair("init-a", 300, None);
    let first = train(&Cpu, &data, NetKind::Geometry, &a, &mut |_| {}).unwrap();
    let weights = a.out.join("weights.npz");
    anisocb::nn::weights::save_net(&weights, &first.trunk).unwrap();
    // One more step from those weights starts where the 300 steps ended, far below a fresh start.
    let tuned = train(&Cpu, &data, NetKind::Geometry, &pair("init-b", 1, Some(weights.clone())), &mut |_| {})
        .unwrap();
    let fresh = train(&Cpu, &data, NetKind::Geometry, &pair("init-c", 1, None), &mut |_| {}).unwrap();
    let (start, ended, cold) = (tuned.history[0].train, first.last_train_loss, fresh.history[0].train);
    println!("init: fresh {cold:.3e}, after 300 steps {ended:.3e}, from those weights {start:.3e}");
    assert!(start < 2.0 * ended && start < 0.1 * cold, "{cold} {ended} {start}");
    // Weights of another net, or of another configuration, are refused with the file named.
    let err = train(&Cpu, &data, NetKind::Enhance, &pair("init-d", 1, Some(weights.clone())), &mut |_| {})
        .unwrap_err()
        .to_string();
    assert!(err.contains("weights.npz") && err.contains("these are geometry weights"), "{err}");
    let paper =
        TrainOptions { config: NetConfig::preset("small").unwrap(), ..pair("init-e", 1, Some(weights)) };
    let err = train(&Cpu, &data, NetKind::Geometry, &paper, &mut |_| {}).unwrap_err().to_string();
    assert!(err.contains("another configuration"), "{err}");
}

#[test]
fn nan_guard_stops_with_a_clear_message_and_keeps_the_last_good_checkpoint() {
    let data = synthetic(4, 6, 6);
    let dir = tmp("nan");
    let opts = TrainOptions {
        adam: AdamParams { lr: 1e30, ..AdamParams::default() },
        checkpoint_every: 1,
        ..tiny_opts(dir.clone(), 10)
    };
    let mut checkpoints = Vec::new();
    let err = train(&Cpu, &data, NetKind::Geometry, &opts, &mut |e| {
        if let Event::Checkpoint { step, .. } = e {
            checkpoints.push(step)
        }
    })
    .unwrap_err()
    .to_string();
    println!("{err}");
    assert!(err.contains("numeric failure") && err.contains("last good checkpoint"), "{err}");
    let last = *checkpoints.last().expect("a checkpoint before the blow-up");
    // The checkpoint on disk is the last good one, loadable and finite.
    let e = anisocb::io::read_npz(&dir.join("checkpoint.npz")).unwrap();
    let tj = String::from_utf8_lossy(e.file("trainer.json").unwrap()).into_owned();
    assert!(tj.contains(&format!("\"step\": {last}")), "{tj}");
    assert!(e.arrays.iter().all(|(_, t)| t.first_non_finite().is_none() || t.shape.len() == 2));
}

#[test]
fn resume_refuses_changed_options_and_fresh_runs_refuse_to_overwrite() {
    let data = synthetic(4, 6, 6);
    let dir = tmp("refuse");
    train(&Cpu, &data, NetKind::Enhance, &tiny_opts(dir.clone(), 2), &mut |_| {}).unwrap();
    let err = train(&Cpu, &data, NetKind::Enhance, &tiny_opts(dir.clone(), 4), &mut |_| {}).unwrap_err();
    assert!(err.to_string().contains("resume it"), "{err}");
    let changed = TrainOptions { resume: true, batch: 4, ..tiny_opts(dir.clone(), 4) };
    let err = train(&Cpu, &data, NetKind::Enhance, &changed, &mut |_| {}).unwrap_err().to_string();
    println!("{err}");
    assert!(err.contains("batch"), "{err}");
    let unmirrored = TrainOptions { resume: true, mirror: false, ..tiny_opts(dir.clone(), 4) };
    let err = train(&Cpu, &data, NetKind::Enhance, &unmirrored, &mut |_| {}).unwrap_err().to_string();
    assert!(err.contains("mirror"), "{err}");
    let other = synthetic(5, 6, 6);
    let err = train(
        &Cpu,
        &other,
        NetKind::Enhance,
        &TrainOptions { resume: true, ..tiny_opts(dir.clone(), 4) },
        &mut |_| {},
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("data:"), "{err}");
    let none = TrainOptions { resume: true, ..tiny_opts(tmp("refuse-none"), 4) };
    assert!(train(&Cpu, &data, NetKind::Enhance, &none, &mut |_| {}).is_err());
}

#[test]
fn patches_of_lr_and_targets_are_aligned_and_seeded() {
    // LR pixel value encodes (frame, y, x); HR pixel (2y+a, 2x+b) encodes its LR parent.
    let (n, h, w) = (3, 5, 7);
    let mut lr = Tensor::zeros(&[n, 3, h, w]);
    let mut hr = Tensor::zeros(&[n, 3, 2 * h, 2 * w]);
    for f in 0..n {
        for c in 0..3 {
            for y in 0..2 * h {
                for x in 0..2 * w {
                    let code = (f * 100 + (y / 2) * 10 + x / 2) as f32;
                    let i = hr.idx4(f, c, y, x);
                    hr.data[i] = code;
                    if y % 2 == 0 && x % 2 == 0 {
                        let j = lr.idx4(f, c, y / 2, x / 2);
                        lr.data[j] = code;
                    }
                }
            }
        }
    }
    let maps = Tensor::zeros(&[n, 1, 2 * h, 2 * w]);
    let data = TrainingData::new(lr, hr, maps.clone(), maps).unwrap();
    let (train_idx, val_idx) = split(n, 0.3).unwrap();
    assert_eq!((train_idx.clone(), val_idx), (vec![0, 1], vec![2]));
    let mut s = PatchSampler::new(&data, train_idx.clone(), 5, 4, 3).unwrap();
    let b = s.batch(&data, None, NetKind::Geometry, 7);
    for k in 0..4 {
        for y in 0..6 {
            for x in 0..6 {
                let want = b.lr.data[b.lr.idx4(k, 0, y / 2, x / 2)];
                assert_eq!(b.target.data[b.target.idx4(k, 0, y, x)], want);
                assert!(want < 200.0, "validation frame sampled");
            }
        }
    }
    let mut s2 = PatchSampler::new(&data, train_idx, 5, 4, 3).unwrap();
    assert_eq!(s2.batch(&data, None, NetKind::Geometry, 7).lr, b.lr);
}

#[test]
fn train_all_writes_a_loadable_bundle() {
    let data = synthetic(4, 6, 6);
    let dir = tmp("all");
    let (bundle, reports) = train_all(&Cpu, &data, &tiny_opts(dir.clone(), 2), &mut |_| {}).unwrap();
    assert_eq!(reports.len(), 3);
    assert!(reports[0].baseline_val_loss.is_some_and(|b| b > 0.0) && reports[1].baseline_val_loss.is_none());
    assert_eq!(AnisoCb::load(&dir.join("weights.npz")).unwrap(), bundle);
    let out = bundle.forward(&Cpu, &data.lr.slice_batch(0, 2)).unwrap();
    assert_eq!(out.boundary.shape, vec![2, 1, 12, 12]);
    assert!(out.enhance.data.iter().all(|p| (0.0..=1.0).contains(p)));
}
