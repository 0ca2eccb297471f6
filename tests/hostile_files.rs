//! Inputs that are not files of their kind: a device that never ends (`/dev/zero`), a folder,
//! and option values at the edge of the integers. Each is refused (or run) with a message,
//! never read until memory runs out, never a panic.

#[path = "common/tempdir.rs"]
mod tempdir;
use std::process::{Command, Output};
use tempdir::TempDir;

fn anisocb(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_anisocb")).args(args).output().unwrap()
}

fn sim(d: &TempDir) -> String {
    let o = anisocb(&["simulate", "--scenario", "drop", "--frames", "4", "--obj", "--out", &d.arg("sim")]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    d.arg("sim/obj")
}

#[test]
fn a_device_given_as_a_mesh_or_weights_is_refused_not_read_until_memory_runs_out() {
    let d = TempDir::new("hostile-dev");
    let frames = sim(&d);
    // An OBJ frame that is a link to the device.
    std::os::unix::fs::symlink("/dev/zero", d.join("zero.obj")).unwrap();
    for args in [
        vec!["upscale", &d.arg("zero.obj"), "--out", &d.arg("o1")],
        vec!["upscale", &frames, "--out", &d.arg("o2"), "--weights", "/dev/zero"],
    ] {
        let o = anisocb(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
        assert!(err.contains("zero") && err.contains("not a regular file"), "{args:?}: {err}");
    }
}

#[test]
fn a_chunk_at_the_integer_limit_upscales_the_slice() {
    let d = TempDir::new("hostile-chunk");
    let frames = sim(&d);
    let o = anisocb(&[
        "upscale",
        &frames,
        "--out",
        &d.arg("o"),
        "--frames",
        "1:3",
        "--chunk",
        &u64::MAX.to_string(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(
        std::fs::read_dir(d.join("o"))
            .unwrap()
            .filter(|e| e.as_ref().unwrap().path().extension().is_some_and(|x| x == "obj"))
            .count(),
        2
    );
}

#[test]
fn bundle_refuses_to_write_over_one_of_its_inputs() {
    let d = TempDir::new("hostile-bundle");
    let w = d.join("w.npz");
    std::fs::copy(concat!(env!("CARGO_MANIFEST_DIR"), "/weights/anisocb-x2.npz"), &w).unwrap();
    let before = std::fs::read(&w).unwrap();
    let s = w.to_str().unwrap();
    // The same file under another spelling, as the last of the three.
    let other = format!("{}/./w.npz", d.path().display());
    let o = anisocb(&["bundle", "--geometry", s, "--boundary", s, "--enhance", s, "--out", &other]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("--out") && err.contains("is the input"), "{err}");
    assert!(std::fs::read(&w).unwrap() == before, "the input bundle was rewritten");
}
