//! Weights files: round trips, deterministic initialisation, and refusal of mismatched files
//! with a message that lists what differs.

use anisocb::io::{read_npz, write_npz};
use anisocb::nn::weights::{load_any, load_net, save_net, Weights};
use anisocb::nn::{AnisoCb, NetConfig, NetKind, Trunk};
use anisocb::ops::{Cpu, Padding, Precision};
use anisocb::Tensor;
use std::path::PathBuf;

fn tmp(name: &str) -> PathBuf {
    let d = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("anisocb-nets-weights-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d.join(name)
}

#[test]
fn same_seed_gives_same_bits_and_other_seed_differs() {
    let a = Trunk::init(NetKind::Geometry, NetConfig::small(), 42);
    let b = Trunk::init(NetKind::Geometry, NetConfig::small(), 42);
    let c = Trunk::init(NetKind::Geometry, NetConfig::small(), 43);
    assert_eq!(a, b);
    assert_ne!(a.blocks[0].conv1.weight, c.blocks[0].conv1.weight);
    // The map nets get streams of their own.
    let d = Trunk::init(NetKind::Boundary, NetConfig::small(), 42);
    assert_ne!(a.conv_in.weight, d.conv_in.weight);
}

#[test]
fn paper_preset_has_the_papers_shapes_and_names() {
    let t = Trunk::zeros(NetKind::Geometry, NetConfig::paper());
    let names: Vec<String> = t.params().into_iter().map(|(n, _)| n).collect();
    assert_eq!(names.len(), 2 * (1 + 20 + 1 + 4));
    assert_eq!(names[0], "conv_in.weight");
    assert!(names.contains(&"blocks.9.conv2.bias".to_string()));
    assert_eq!(t.upscale.weight.shape, vec![256, 64, 3, 3]);
    assert_eq!(t.tail[3].weight.shape, vec![3, 64, 3, 3]);
    assert_eq!(Trunk::zeros(NetKind::Enhance, NetConfig::paper()).tail[3].weight.shape, vec![1, 64, 3, 3]);
}

#[test]
fn net_and_bundle_files_round_trip_bit_exactly() {
    let cfg = NetConfig::tiny().with_padding(Padding::Replicate);
    let t = Trunk::init(NetKind::Boundary, cfg, 5);
    let p = tmp("net.npz");
    save_net(&p, &t).unwrap();
    assert_eq!(load_net(&p, Some((NetKind::Boundary, cfg))).unwrap(), t);
    let b = AnisoCb::new(NetConfig::tiny(), 9);
    let pb = tmp("bundle.npz");
    b.save(&pb).unwrap();
    assert_eq!(AnisoCb::load(&pb).unwrap(), b);
    assert!(matches!(load_any(&pb).unwrap(), Weights::Bundle(_)));
    assert!(matches!(load_any(&p).unwrap(), Weights::Net(_)));
    let e = read_npz(&pb).unwrap();
    assert!(e.array("geometry.blocks.1.conv2.weight").is_some());
    assert!(e.file("enhance.config.json").is_some());
}

#[test]
fn mismatched_weights_are_refused_with_a_readable_message() {
    let p = tmp("small.npz");
    save_net(&p, &Trunk::init(NetKind::Geometry, NetConfig::small(), 1)).unwrap();
    // Config differs from what the caller expects.
    let err = load_net(&p, Some((NetKind::Boundary, NetConfig::paper()))).unwrap_err().to_string();
    println!("{err}");
    assert!(err.contains("small.npz"), "{err}");
    assert!(err.contains("kind: geometry vs boundary"), "{err}");
    assert!(err.contains("channels: 32 vs 64") && err.contains("blocks: 4 vs 10"), "{err}");

    // Arrays that do not fit their own config: one missing, one reshaped, one extra.
    let mut e = read_npz(&p).unwrap();
    e.arrays.retain(|(n, _)| n != "blocks.2.conv1.bias");
    for (n, t) in e.arrays.iter_mut() {
        if n == "tail.3.weight" {
            *t = Tensor::zeros(&[1, 32, 3, 3]);
        }
    }
    e.push_array("head.weight", Tensor::zeros(&[1]));
    let q = tmp("broken.npz");
    write_npz(&q, &e).unwrap();
    let err = load_net(&q, None).unwrap_err().to_string();
    println!("{err}");
    assert!(err.contains("missing 1: blocks.2.conv1.bias"), "{err}");
    assert!(err.contains("tail.3.weight is [1, 32, 3, 3], expected [3, 32, 3, 3]"), "{err}");
    assert!(err.contains("unexpected 1: head.weight"), "{err}");

    // Not a weights file at all.
    let mut e = read_npz(&p).unwrap();
    e.files.clear();
    write_npz(&q, &e).unwrap();
    let err = load_net(&q, None).unwrap_err().to_string();
    assert!(err.contains("not an anisocb weights file"), "{err}");
}

/// A bundle may hold several GeometryNets (an ensemble over training seeds): it round-trips
/// with all of them, R is the mean of their residuals and U the first's, and a member of
/// another configuration is refused.
#[test]
fn ensemble_bundle_round_trips_and_averages_its_geometry_nets() {
    let cfg = NetConfig::tiny();
    let m = AnisoCb::new(cfg, 5).with_more_geometry(vec![Trunk::init(NetKind::Geometry, cfg, 6)]).unwrap();
    let path = tmp("ensemble.npz");
    m.save(&path).unwrap();
    let back = match load_any(&path).unwrap() {
        Weights::Bundle(b) => *b,
        Weights::Net(_) => panic!("an ensemble bundle loaded as a single net"),
    };
    assert_eq!(back, m, "round trip keeps both GeometryNets bit for bit");
    let x =
        Tensor::from_vec(&[2, 3, 5, 7], (0..210).map(|v| ((v * 37 % 101) as f32) / 101.0).collect()).unwrap();
    let out = m.forward(&anisocb::ops::Cpu, &x).unwrap();
    let (u1, r1) = m.geometry.forward(&anisocb::ops::Cpu, &x).unwrap();
    let (_, r2) = m.more_geometry[0].forward(&anisocb::ops::Cpu, &x).unwrap();
    assert_eq!(out.interpolated, u1);
    let mean: Vec<f32> = r1.data.iter().zip(&r2.data).map(|(a, b)| (a + b) * 0.5).collect();
    assert_eq!(out.residual.data, mean);
    assert!(r1.max_abs_diff(&r2) > 0.0, "the two members must differ for the test to tell");
    let other = Trunk::init(NetKind::Geometry, cfg.with_padding(Padding::Replicate), 7);
    let err = AnisoCb::new(cfg, 5).with_more_geometry(vec![other]).unwrap_err().to_string();
    assert!(err.contains("differs from the first"), "{err}");
    let err = AnisoCb::new(cfg, 5)
        .with_more_geometry(vec![Trunk::init(NetKind::Boundary, cfg, 7)])
        .unwrap_err()
        .to_string();
    assert!(err.contains("boundary"), "{err}");
}

#[test]
fn packed_bundle_gives_the_bits_of_the_plain_bundle() {
    // `upscale` packs every conv's weights once (AnisoCb::packed) instead of on every call:
    // an ensemble bundle, EnhanceNet on and off, a batch of two frames and a lone frame.
    let cfg = NetConfig::small();
    let m = AnisoCb::new(cfg, 5).with_more_geometry(vec![Trunk::init(NetKind::Geometry, cfg, 6)]).unwrap();
    let nets = m.packed();
    let mut rng = anisocb::rng::Rng::new(3);
    for n in [2, 1] {
        let mut x = Tensor::zeros(&[n, 3, 13, 18]);
        x.data.iter_mut().for_each(|v| *v = rng.uniform() - 0.5);
        for enhance in [true, false] {
            let (a, b) =
                (m.forward_with(&Cpu, &x, enhance).unwrap(), nets.forward_with(&Cpu, &x, enhance).unwrap());
            for (what, p, q) in [
                ("U", &a.interpolated, &b.interpolated),
                ("R", &a.residual, &b.residual),
                ("Γb", &a.boundary, &b.boundary),
                ("Γe", &a.enhance, &b.enhance),
            ] {
                let bits = |t: &Tensor| t.data.iter().map(|v| v.to_bits()).collect::<Vec<u32>>();
                assert_eq!(bits(p), bits(q), "{what} differs (batch {n}, enhance {enhance})");
            }
        }
    }
}

#[test]
fn frames_beyond_one_cpu_pass_give_the_bits_of_each_frame_alone() {
    // On the CPU the nets take CPU_PASS_BYTES' worth of frames a pass (their widest activation,
    // C·r²·H·W floats a frame): the small config at 64² (2 MiB a frame) runs 2 a pass, at 32²
    // 8. Five 64² frames (passes of 2, 2, 1), fp32 and bf16, EnhanceNet on and off, give each
    // frame's outputs as that frame run alone.
    let cfg = NetConfig::small();
    let m = AnisoCb::new(cfg, 5);
    let mut rng = anisocb::rng::Rng::new(7);
    let mut x = Tensor::zeros(&[5, 3, 64, 64]);
    x.data.iter_mut().for_each(|v| *v = rng.uniform() - 0.5);
    assert_eq!(m.frames_per_pass(&Cpu, &x), 2);
    assert_eq!(m.frames_per_pass(&Cpu, &Tensor::zeros(&[1, 3, 32, 32])), 8);
    for precision in [Precision::Fp32, Precision::Bf16] {
        let nets = m.packed_as(precision);
        for enhance in [true, false] {
            let all = nets.forward_with(&Cpu, &x, enhance).unwrap();
            for f in 0..5 {
                let one = nets.forward_with(&Cpu, &x.slice_batch(f, 1), enhance).unwrap();
                for (what, p, q) in [
                    ("U", &all.interpolated, &one.interpolated),
                    ("R", &all.residual, &one.residual),
                    ("Γb", &all.boundary, &one.boundary),
                    ("Γe", &all.enhance, &one.enhance),
                ] {
                    assert_eq!(p.shape[0], 5, "{what}: frames");
                    let bits = |t: &[f32]| t.iter().map(|v| v.to_bits()).collect::<Vec<u32>>();
                    let per = q.data.len();
                    assert_eq!(
                        bits(&p.data[f * per..][..per]),
                        bits(&q.data),
                        "{what} of frame {f} differs ({precision:?}, enhance {enhance})"
                    );
                }
            }
        }
    }
}
