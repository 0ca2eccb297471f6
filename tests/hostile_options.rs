//! A catalogue of hostile option values and usage errors: unknown commands, `anisocb upscale`
//! options and physics-pass settings that are absurd (out of range, NaN, infinite), thread
//! counts that would hang, temporal radii whose weights could overflow, and inputs given the
//! wrong way (a single net for a bundle, two point caches, a cache without its rest mesh). Each
//! refusal exits 1 (2 for what clap refuses), names what is wrong and writes nothing.

#[path = "common/hostile.rs"]
mod hostile;
#[path = "common/tempdir.rs"]
mod tempdir;
use anisocb::tensor::Tensor;
use hostile::{anisocb, grid_obj, grid_xyz, obj_shot, pc2_raw, scratch, upscale_refused, write};
use std::path::Path;

#[test]
fn cli_usage_errors_exit_2() {
    let o = anisocb(&["no-such-command"]);
    assert_eq!(o.status.code(), Some(2), "{o:?}");
    let o = anisocb(&["--help"]);
    assert_eq!(o.status.code(), Some(0), "{o:?}");
}

#[test]
fn upscale_refuses_absurd_option_values_and_physics_settings_before_reading_or_writing() {
    let d = scratch("upscale_values");
    let shot = obj_shot(&d, "shot", 2);
    let (inp, out) = (shot.to_str().unwrap(), d.join("out"));
    let o = out.to_str().unwrap();
    let cases: &[(&[&str], &[&str])] = &[
        (&["--eta", "1e30"], &["--eta", "from -1 to 10", "1000000000000000000000000000000"]),
        (&["--eta=-1.5"], &["--eta", "from -1 to 10"]),
        (&["--eta", "NaN"], &["--eta", "NaN"]),
        (&["--eta", "inf"], &["--eta", "inf"]),
        (&["--margin", "1e30"], &["--margin", "from 0 to 1"]),
        (&["--margin=-0.1"], &["--margin", "from 0 to 1"]),
        (&["--margin", "NaN"], &["--margin"]),
        (&["--temporal", "65"], &["--temporal", "at most 64", "65"]),
        (&["--temporal", "1000000"], &["--temporal", "at most 64"]),
        (&["--batch", "0"], &["--batch", "1 to 1024"]),
        (&["--batch", "100000000"], &["--batch", "1 to 1024"]),
        (&["--strain-iters", "1000000000"], &["--strain-iters", "at most 1000"]),
        (&["--chunk", "0"], &["--chunk", "must be ≥ 1"]),
        (&["--physics", "--physics-pin", "top,middle"], &["--physics-pin", "middle", "corners"]),
        (&["--physics", "--material", "velvet"], &["velvet", "silk"]),
        (&["--physics", "--fps", "0"], &["--fps", "1 to 1000"]),
        (&["--physics", "--physics-substeps", "NaN"], &["--physics-substeps"]),
        (&["--physics", "--gravity", "0,nan,0"], &["--gravity"]),
        (&["--physics", "--physics-drift", "NaN"], &["--physics-drift", "seconds"]),
        (&["--physics", "--physics-sphere", "1,2,3"], &["--physics-sphere", "4 numbers"]),
        (&["--physics", "--physics-box", "0,0.4,0,0.5,-0.4,0.5"], &["--physics-box", "half extents"]),
    ];
    for (extra, want) in cases {
        let mut args = vec![inp, "--out", o];
        args.extend_from_slice(extra);
        upscale_refused(&args, 1, want);
        assert!(!out.exists(), "{extra:?}: --out was created by a refused run");
    }
    // The checks come before the input is even opened: a missing input gets the option's error.
    upscale_refused(&["no/such/dir", "--out", o, "--eta", "1e30"], 1, &["--eta"]);
}

#[test]
fn upscale_refuses_thread_counts_that_would_hang() {
    let d = scratch("upscale_threads");
    let shot = obj_shot(&d, "shot", 1);
    let (inp, out) = (shot.to_str().unwrap(), d.join("out"));
    let o = out.to_str().unwrap();
    // Parsed before the worker pool is built, so clap refuses them (usage error, exit 2).
    upscale_refused(&[inp, "--out", o, "--threads", "100000"], 2, &["--threads", "more than 1024"]);
    upscale_refused(&[inp, "--out", o, "--threads", "0"], 2, &["--threads must be ≥ 1"]);
    upscale_refused(&[inp, "--out", o, "--threads=-3"], 2, &["--threads", "whole number"]);
    assert!(!out.exists());
    // demo and eval take the same bound.
    for cmd in ["demo", "eval"] {
        let r = anisocb(&[cmd, "--threads", "100000"]);
        let err = String::from_utf8_lossy(&r.stderr);
        assert_eq!(r.status.code(), Some(2), "{cmd}: {err}");
        assert!(err.contains("more than 1024"), "{cmd}: {err}");
    }
}

/// Binomial weights of the largest accepted radius, and of radii far beyond it (a library
/// caller is not bound by the CLI's check), stay finite: a constant sequence stays constant.
#[test]
fn temporal_smoothing_weights_do_not_overflow_at_any_radius() {
    use anisocb::sr::params::{UpscaleParams, MAX_TEMPORAL};
    use anisocb::sr::temporal::smooth_in_time;
    let x = Tensor::from_vec(&[5, 1, 1, 2], vec![0.25; 10]).unwrap();
    for k in [1, MAX_TEMPORAL, 600, 2000] {
        let y = smooth_in_time(&x, k);
        assert!(y.data.iter().all(|v| (v - 0.25).abs() < 1e-6), "radius {k}: {:?}", y.data);
    }
    let p = UpscaleParams { temporal: MAX_TEMPORAL + 1, ..UpscaleParams::default() };
    assert!(p.validate().unwrap_err().to_string().contains("at most 64"));
    assert!(UpscaleParams { temporal: MAX_TEMPORAL, ..UpscaleParams::default() }.validate().is_ok());
}

#[test]
fn upscale_messages_say_what_is_wrong_with_what_was_given() {
    let d = scratch("upscale_messages");
    let shot = obj_shot(&d, "shot", 2);
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let out = s(&d.join("out"));
    // A single net where a bundle is needed: called a single net, with the way to bundle it.
    let single = Path::new(env!("CARGO_MANIFEST_DIR")).join("weights/domain-x2.npz");
    upscale_refused(
        &[&s(&shot), "--out", &out, "--weights", &s(&single)],
        1,
        &["single geometry net", "anisocb bundle"],
    );
    // Two point caches at once: both named, one per run.
    let xyz = grid_xyz(4, 4, 2);
    let a = write(&d, "a.pc2", &pc2_raw(b"POINTCACHE2\0", 1, 16, 0.0, 1.0, 2, &xyz));
    let b = write(&d, "b.pc2", &pc2_raw(b"POINTCACHE2\0", 1, 16, 0.0, 1.0, 2, &xyz));
    let rest = write(&d, "rest.obj", grid_obj(4, 4).as_bytes());
    upscale_refused(
        &[&s(&a), &s(&b), "--rest", &s(&rest), "--out", &out],
        1,
        &["2 of them point caches", "a.pc2", "b.pc2", "one point cache per run"],
    );
    // A cache without its rest mesh: the message reads as one sentence.
    let err = upscale_refused(
        &[&s(&a), "--out", &out],
        1,
        &["--rest", "rest mesh: an OBJ exported from the same object"],
    );
    assert!(!err.contains("  "), "stray spaces: {err:?}");
}
