//! The pipeline as a library (`anisocb::pipeline`): a Rust program upscales files to the bytes
//! the command line writes, and frames in memory one at a time to the bits the command line
//! gives them, temporal context included.

#[path = "common/tempdir.rs"]
mod tempdir;

use anisocb::cloth::scenarios::{run_single, Scenario, ScenarioSpec};
use anisocb::geom::obj::{read_obj_grid, write_obj_grid};
use anisocb::geom::GridMesh;
use anisocb::pipeline::{upscale_files, Quiet, UpscaleJob, Upscaler};
use anisocb::sr::upscale::{embedded_model, UpscaleParams};
use std::path::Path;
use std::process::Command;
use tempdir::TempDir;

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_anisocb")
}

/// A short drape as OBJ frames `f_000.obj` … in `dir`.
fn drape_frames(dir: &Path, frames: usize) -> Vec<GridMesh> {
    let mut spec = ScenarioSpec::new(Scenario::Drape);
    (spec.w, spec.h, spec.frames, spec.seed) = (12, 12, frames, 3);
    let run = run_single(&spec).unwrap();
    std::fs::create_dir_all(dir).unwrap();
    for (k, f) in run.iter().enumerate() {
        write_obj_grid(&dir.join(format!("f_{k:03}.obj")), f, true).unwrap();
    }
    run
}

fn cli(args: &[&str]) {
    let o = Command::new(bin()).arg("upscale").args(args).output().unwrap();
    assert!(o.status.success(), "upscale {args:?} failed: {}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn library_job_writes_the_cli_bytes() {
    let d = TempDir::new("lib-job");
    drape_frames(&d.join("in"), 6);
    cli(&[&d.arg("in"), "--out", &d.arg("cli"), "--temporal", "1"]);
    let mut job = UpscaleJob::new(vec![d.join("in")], d.join("lib"));
    job.params.temporal = 1;
    let done = upscale_files(&anisocb::ops::Cpu, &embedded_model().unwrap(), &job, &mut Quiet).unwrap();
    assert_eq!((done.frames, done.lr, done.hr), (6, (12, 12), (24, 24)));
    for k in 0..6 {
        let name = format!("f_{k:03}.obj");
        let (a, b) =
            (std::fs::read(d.join("cli").join(&name)).unwrap(), std::fs::read(d.join("lib").join(&name)));
        assert!(a == b.unwrap(), "{name}: the library wrote other bytes than the CLI");
    }
}

#[test]
fn upscaler_frame_by_frame_gives_the_cli_bits_with_its_temporal_context() {
    let d = TempDir::new("lib-frames");
    let lr = drape_frames(&d.join("in"), 7);
    for temporal in [0usize, 2] {
        let out = d.arg(&format!("cli-{temporal}"));
        cli(&[&d.arg("in"), "--out", &out, "--temporal", &temporal.to_string()]);
        let params = UpscaleParams { temporal, ..UpscaleParams::default() };
        let mut up = Upscaler::new(embedded_model().unwrap(), params).unwrap().with_threads(2).unwrap();
        assert_eq!(up.latency(), temporal);
        let mut hr = Vec::new();
        for (k, f) in lr.iter().enumerate() {
            let got = up.push(f).unwrap();
            // A result comes out once the `temporal` frames after it are in.
            assert_eq!(got.is_some(), k >= temporal, "frame {k}, temporal {temporal}");
            hr.extend(got);
        }
        hr.extend(up.flush().unwrap());
        assert_eq!(hr.len(), lr.len());
        for (k, m) in hr.iter().enumerate() {
            let cli = read_obj_grid(&Path::new(&out).join(format!("f_{k:03}.obj"))).unwrap();
            let same =
                cli.pos.iter().flatten().zip(m.pos.iter().flatten()).all(|(a, b)| a.to_bits() == b.to_bits());
            assert!(
                same && (cli.w, cli.h) == (m.w, m.h),
                "frame {k}, temporal {temporal}: not the CLI's bits"
            );
        }
        // After a flush the next push starts a new shot: the same frames give the same bits.
        let mut again: Vec<GridMesh> = lr.iter().filter_map(|f| up.push(f).unwrap()).collect();
        again.extend(up.flush().unwrap());
        assert!(again.iter().zip(&hr).all(|(a, b)| a.pos == b.pos), "a second shot differs");
    }
}

#[test]
fn upscaler_refuses_a_frame_of_another_grid_and_names_a_non_finite_frame() {
    let d = TempDir::new("lib-refuse");
    let lr = drape_frames(&d.join("in"), 3);
    let mut up = Upscaler::embedded().unwrap();
    up.push(&lr[0]).unwrap();
    let small = GridMesh::new(4, 3, vec![[0.0; 3]; 12]);
    let e = up.push(&small).unwrap_err().to_string();
    assert!(e.contains("4×3") && e.contains("12×12"), "{e}");
    let mut bad = lr[1].clone();
    bad.pos[5][1] = f32::NAN;
    let e = up.push(&bad).unwrap_err().to_string();
    assert!(e.contains("non-finite") && e.contains("frame 1"), "{e}");
}
