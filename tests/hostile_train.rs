//! A catalogue of hostile inputs to `anisocb train` and `anisocb dataset`: data sets that are
//! garbage, empty, partial or missing, an `--out` below a regular file, a corrupt checkpoint to
//! `--resume` from, `--steps 0`, and a data set `--out` (or `--png`) that would replace a run's
//! own files. Each exits 1 with the file and the problem on stderr, and leaves nothing written.
//! Broken weights files are in tests/hostile_npy.rs.

#[path = "common/hostile.rs"]
mod hostile;
#[path = "common/tempdir.rs"]
mod tempdir;
use anisocb::io::NpzEntries;
use hostile::{anisocb, file_names, ramp, scratch, write};
use std::path::{Path, PathBuf};

/// `anisocb train --data DATA --config tiny --steps 2 EXTRA... --out OUT`.
fn train_tiny(data: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    let (data, out) = (data.to_str().unwrap(), out.to_str().unwrap());
    let mut args = vec!["train", "--data", data, "--config", "tiny", "--steps", "2"];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["--out", out]);
    anisocb(&args)
}

/// `anisocb train` on bad input: exit 1, the file and the problem on stderr, no output left.
#[test]
fn cli_train_refuses_bad_inputs_and_writes_nothing() {
    let d = scratch("cli_train");
    let garbage = write(&d, "garbage.npz", b"definitely not a zip file, just some words here");
    let empty = write(&d, "empty.npz", &[]);
    let mut e = NpzEntries::default();
    e.push_array("lr", ramp(&[2, 3, 4, 4]));
    let partial = d.join("partial.npz");
    anisocb::io::write_npz(&partial, &e).unwrap();
    let blocker = write(&d, "a_file", b"x");
    let missing = d.join("missing.npz");
    let cases: Vec<(&Path, PathBuf, &[&str])> = vec![
        (&garbage, d.join("out1"), &["garbage.npz", "not an .npz (zip) file"]),
        (&empty, d.join("out2"), &["empty.npz", "empty file"]),
        (&partial, d.join("out3"), &["partial.npz", "missing array 'hr'"]),
        (&missing, d.join("out4"), &["missing.npz", "No such file"]),
    ];
    for (data, out, want) in cases {
        let o = train_tiny(data, &out, &[]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{err}");
        for w in want {
            assert!(err.contains(w), "stderr lacks {w:?}: {err}");
        }
        assert!(!out.exists() || file_names(&out).is_empty(), "{:?} left {:?}", out, file_names(&out));
    }
    // A good data set but an --out below a regular file.
    let mut good = NpzEntries::default();
    good.push_array("lr", ramp(&[2, 3, 4, 4]));
    good.push_array("hr", ramp(&[2, 3, 8, 8]));
    good.push_array("boundary", ramp(&[2, 1, 8, 8]));
    good.push_array("edges", ramp(&[2, 1, 8, 8]));
    let data = d.join("data.npz");
    anisocb::io::write_npz(&data, &good).unwrap();
    let out = blocker.join("run");
    let o = train_tiny(&data, &out, &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains(&out.display().to_string()) && err.contains("cannot create output directory"),
        "{err}"
    );
    assert_eq!(std::fs::read(&blocker).unwrap(), b"x");
    // --resume from a corrupt checkpoint names it and keeps it.
    let out = d.join("resume");
    std::fs::create_dir_all(&out).unwrap();
    let ckpt = write(&out, "checkpoint.npz", b"PK\x03\x04 truncated checkpoint");
    let o = train_tiny(&data, &out, &["--resume"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains(&ckpt.display().to_string()), "{err}");
    // Nothing written but the folder's lock (empty once the run is gone): no train.json says
    // the run started.
    assert_eq!(file_names(&out), [".train.json.lock", "checkpoint.npz"]);
    assert_eq!(std::fs::read(out.join(".train.json.lock")).unwrap(), b"");
    // --steps 0 would write untrained weights.
    let out = d.join("zero_steps");
    let (ds, os) = (data.to_str().unwrap(), out.to_str().unwrap());
    let o = anisocb(&["train", "--data", ds, "--config", "tiny", "--steps", "0", "--out", os]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("--steps 0") && err.contains("untrained"), "{err}");
    assert!(!out.exists(), "{:?}", file_names(&out));
}

#[test]
fn dataset_refuses_an_out_that_would_replace_a_runs_files() {
    let d = scratch("dataset_out");
    let run = d.join("run");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let o = anisocb(&[
        "simulate",
        "--scenario",
        "drop",
        "--res",
        "8x8",
        "--frames",
        "3",
        "--pair",
        "--out",
        &s(&run),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let geometry = run.join("lr").join("geometry.npy");
    let before = std::fs::read(&geometry).unwrap();
    let dataset = |out: &Path, extra: &[&str]| {
        let mut args = vec!["dataset".to_string(), "--runs".into(), s(&run), "--out".into(), s(out)];
        args.extend(extra.iter().map(|a| a.to_string()));
        anisocb(&args.iter().map(String::as_str).collect::<Vec<_>>())
    };
    // The run's own geometry.npy as --out, an existing file of the run renamed .npz, a .png
    // over a run file.
    let inside = write(&run.join("hr"), "old.npz", b"kept");
    let png_over = run.join("lr").join("geometry.png");
    std::fs::write(&png_over, b"kept").unwrap();
    for (out, extra, want) in [
        (geometry.clone(), vec![], "expected a .npz"),
        (inside.clone(), vec![], "is a file of the run"),
        (d.join("ok.npz"), vec!["--png".to_string(), s(&png_over)], "is a file of the run"),
    ] {
        let o = dataset(&out, &extra.iter().map(String::as_str).collect::<Vec<_>>());
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{out:?}: {err}");
        assert!(err.contains(want), "{out:?}: {err}");
    }
    assert_eq!(std::fs::read(&geometry).unwrap(), before);
    assert_eq!(std::fs::read(&inside).unwrap(), b"kept");
    assert_eq!(std::fs::read(&png_over).unwrap(), b"kept");
    assert!(!d.join("ok.npz").exists());
    // A new file beside the runs is fine.
    let o = dataset(&d.join("data.npz"), &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}
