//! Helpers shared by the hostile-input catalogues (tests/hostile_obj.rs, hostile_npy.rs,
//! hostile_point_cache.rs, hostile_options.rs, hostile_output.rs, hostile_train.rs): scratch
//! folders, files written byte for byte, the `anisocb` binary, and the error checks every
//! catalogue makes. Each test file uses a subset, hence `dead_code` is allowed. Include with
//! `#[path = "common/tempdir.rs"] mod tempdir;` and `#[path = "common/hostile.rs"] mod hostile;`
//! (it uses `crate::tempdir::TempDir`).
#![allow(dead_code)]

use crate::tempdir::TempDir;
use anisocb::tensor::Tensor;
use std::path::{Path, PathBuf};

// ---------------------------------------------------------------------------------------------
// Files and folders.

pub fn scratch(test: &str) -> TempDir {
    TempDir::new(&format!("hostile-{test}"))
}

/// Assert `r` failed with a message naming `path` and containing every piece of `want`.
#[track_caller]
pub fn expect_err<T: std::fmt::Debug>(r: anisocb::Result<T>, path: &Path, want: &[&str]) -> String {
    let msg = r.expect_err("hostile input was accepted").to_string();
    assert!(msg.contains(&path.display().to_string()), "error does not name {}: {msg}", path.display());
    for w in want {
        assert!(msg.contains(w), "error lacks {w:?}: {msg}");
    }
    msg
}

pub fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

pub fn ramp(shape: &[usize]) -> Tensor {
    let n: usize = shape.iter().product();
    Tensor::from_vec(shape, (0..n).map(|i| (i % 17) as f32 / 17.0).collect()).unwrap()
}

pub fn file_names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

// ---------------------------------------------------------------------------------------------
// The CLI.

pub fn anisocb(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_anisocb")).args(args).output().unwrap()
}

/// Run `anisocb upscale ARGS`; assert it exited `code` with every piece of `want` in stderr.
#[track_caller]
pub fn upscale_refused(args: &[&str], code: i32, want: &[&str]) -> String {
    let mut all = vec!["upscale"];
    all.extend_from_slice(args);
    let o = anisocb(&all);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(code), "{args:?} was not refused with {code}: {err}");
    for w in want {
        assert!(err.contains(w), "{args:?}: message lacks {w:?}: {err}");
    }
    err
}

// ---------------------------------------------------------------------------------------------
// Inputs: OBJ grids and point caches.

/// OBJ text of a w×h grid of quads (vertex (i, j) at j*w+i, 1-based in faces).
pub fn grid_obj(w: usize, h: usize) -> String {
    let mut s = String::new();
    for j in 0..h {
        for i in 0..w {
            s +=
                &format!("v {} {} {}\n", i as f32 * 0.1, j as f32 * 0.1, ((i + j) as f32 * 0.3).sin() * 0.05);
        }
    }
    for j in 0..h - 1 {
        for i in 0..w - 1 {
            let v = j * w + i + 1;
            s += &format!("f {} {} {} {}\n", v, v + 1, v + 1 + w, v + w);
        }
    }
    s
}

/// A folder `name` under `d` holding `n` frames `frame_K.obj` of a 4×4 grid.
pub fn obj_shot(d: &Path, name: &str, n: usize) -> PathBuf {
    let dir = d.join(name);
    std::fs::create_dir_all(&dir).unwrap();
    for k in 0..n {
        write(&dir, &format!("frame_{k}.obj"), grid_obj(4, 4).as_bytes());
    }
    dir
}

/// The vertices of [`grid_obj`]`(w, h)`, `frames` times, as a point cache's xyz.
pub fn grid_xyz(w: usize, h: usize, frames: usize) -> Vec<f32> {
    let mut v = Vec::new();
    for _ in 0..frames {
        for j in 0..h {
            for i in 0..w {
                v.extend([i as f32 * 0.1, j as f32 * 0.1, ((i + j) as f32 * 0.3).sin() * 0.05]);
            }
        }
    }
    v
}

/// A PC2 file with the given header fields (little-endian) and coordinates.
pub fn pc2_raw(
    magic: &[u8; 12],
    version: i32,
    points: i32,
    start: f32,
    rate: f32,
    frames: i32,
    xyz: &[f32],
) -> Vec<u8> {
    let mut v = magic.to_vec();
    for w in [version.to_le_bytes(), points.to_le_bytes(), start.to_le_bytes(), rate.to_le_bytes()] {
        v.extend_from_slice(&w);
    }
    v.extend_from_slice(&frames.to_le_bytes());
    v.extend(xyz.iter().flat_map(|x| x.to_le_bytes()));
    v
}

/// An MDD file with the given counts, times and coordinates (big-endian).
pub fn mdd_raw(frames: i32, points: i32, times: &[f32], xyz: &[f32]) -> Vec<u8> {
    let mut v = frames.to_be_bytes().to_vec();
    v.extend_from_slice(&points.to_be_bytes());
    v.extend(times.iter().chain(xyz).flat_map(|x| x.to_be_bytes()));
    v
}
