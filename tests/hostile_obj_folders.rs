//! Folders of OBJ frames that are not one shot: two shots side by side, a stray
//! `geometry.npy` beside the frames, a frame that is a dangling link. Each is refused with a
//! message naming what was found, before anything is written.

#[path = "common/tempdir.rs"]
mod tempdir;
use std::path::Path;
use std::process::Command;
use tempdir::TempDir;

/// A 3 × 3 grid frame, lifted by `y`.
fn grid(y: f32) -> String {
    let mut s = String::new();
    for j in 0..3 {
        for i in 0..3 {
            s += &format!("v {} {y} {}\n", i as f32 * 0.1, j as f32 * 0.1);
        }
    }
    for j in 0..2 {
        for i in 0..2 {
            let v = 1 + j * 3 + i;
            s += &format!("f {} {} {} {}\n", v, v + 1, v + 4, v + 3);
        }
    }
    s
}

fn frames(dir: &Path, stem: &str, n: usize) {
    std::fs::create_dir_all(dir).unwrap();
    for k in 0..n {
        std::fs::write(dir.join(format!("{stem}{k:04}.obj")), grid(k as f32 * 0.01)).unwrap();
    }
}

/// `upscale dir --out d/out`: refused with exit 1, the message holding each of `want`, and no
/// output folder made.
fn refused(d: &TempDir, dir: &Path, want: &[&str]) {
    let out = d.join("out");
    let o = Command::new(env!("CARGO_BIN_EXE_anisocb"))
        .args(["upscale", dir.to_str().unwrap(), "--out", out.to_str().unwrap()])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    for w in want {
        assert!(err.contains(w), "message lacks {w:?}: {err}");
    }
    assert!(!out.exists(), "a refused run made the output folder");
}

#[test]
fn two_shots_in_one_folder_are_refused_naming_both() {
    let d = TempDir::new("two-shots");
    frames(&d.join("in"), "shotA_", 3);
    frames(&d.join("in"), "shotB_", 2);
    refused(&d, &d.join("in"), &["two shots", "shotA_*.obj (3 frames)", "shotB_*.obj (2 frames)"]);
    // One shot with a lone extra mesh beside it (a rest pose) is still one shot.
    std::fs::remove_file(d.join("in/shotB_0001.obj")).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_anisocb"))
        .args(["upscale", d.arg("in").as_str(), "--out", d.arg("ok").as_str()])
        .output()
        .unwrap();
    assert!(!String::from_utf8_lossy(&o.stderr).contains("two shots"));
}

#[test]
fn a_stray_geometry_npy_beside_obj_frames_is_refused() {
    let d = TempDir::new("stray-npy");
    frames(&d.join("in"), "f_", 3);
    std::fs::write(d.join("in/geometry.npy"), b"not even an npy").unwrap();
    refused(&d, &d.join("in"), &["both geometry.npy and 3 OBJ frames", "f_0000.obj"]);
}

#[test]
fn a_frame_that_is_a_dangling_link_is_refused_not_skipped() {
    let d = TempDir::new("dangling");
    frames(&d.join("in"), "f_", 3);
    std::os::unix::fs::symlink(d.join("gone.obj"), d.join("in/f_0003.obj")).unwrap();
    refused(&d, &d.join("in"), &["f_0003.obj", "does not exist"]);
}
