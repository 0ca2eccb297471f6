//! The pipeline as a library (`anisocb::pipeline`): a Rust program upscales files to the bytes
//! the command line writes, and frames in memory one at a time to the bits the command line
//! gives them, temporal context included.

#[path = "common/tempdir.rs"]
mod tempdir;

use anisocb::cloth::follow::{FollowParams, PinnedEdges};
use anisocb::cloth::scenarios::{run_single, Scenario, ScenarioSpec};
use anisocb::geom::obj::{read_obj_grid, write_obj_grid};
use anisocb::geom::GridMesh;
use anisocb::nn::weights::embedded_model;
use anisocb::ops::loss::DetailEnergy;
use anisocb::ops::{AdamParams, Cpu, Interp, Ops, Padding};
use anisocb::pipeline::{upscale_files, Quiet, UpscaleJob, Upscaler};
use anisocb::sr::params::UpscaleParams;
use anisocb::Tensor;
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
    let done =
        upscale_files(&anisocb::ops::Cpu, &embedded_model().unwrap(), &job.check().unwrap(), &mut Quiet)
            .unwrap();
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
fn upscaler_with_physics_gives_the_cli_physics_bits_shot_after_shot() {
    let d = TempDir::new("lib-physics");
    let lr = drape_frames(&d.join("in"), 8);
    let out = d.arg("cli");
    cli(&[&d.arg("in"), "--out", &out, "--physics", "--physics-pin", "corners", "--temporal", "1"]);
    let p = FollowParams { pins: PinnedEdges::parse("corners").unwrap(), ..FollowParams::default() };
    let params = UpscaleParams { temporal: 1, ..UpscaleParams::default() };
    let mut up = Upscaler::new(embedded_model().unwrap(), params).unwrap().with_physics(p).unwrap();
    for shot in 0..2 {
        let mut hr: Vec<GridMesh> = lr.iter().filter_map(|f| up.push(f).unwrap()).collect();
        hr.extend(up.flush().unwrap());
        for (k, m) in hr.iter().enumerate() {
            let cli = read_obj_grid(&Path::new(&out).join(format!("f_{k:03}.obj"))).unwrap();
            let same =
                cli.pos.iter().flatten().zip(m.pos.iter().flatten()).all(|(a, b)| a.to_bits() == b.to_bits());
            assert!(same, "shot {shot}, frame {k}: not the bits of upscale --physics");
        }
    }
    let plain = Upscaler::embedded().unwrap().push(&lr[7]).unwrap().unwrap();
    let cli7 = read_obj_grid(&Path::new(&out).join("f_007.obj")).unwrap();
    assert_ne!(plain.pos, cli7.pos, "the physics pass changed nothing");
    let bad = FollowParams { fps: 0.0, ..FollowParams::default() };
    assert!(Upscaler::embedded().unwrap().with_physics(bad).err().unwrap().to_string().contains("fps"));
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

/// The CPU table, except that it reports a device failure once `fail_after` convolutions ran
/// and returns NaN convolutions from then on: what the CUDA table does on a driver failure
/// (out of memory, a lost device), which cannot be caused on purpose without a GPU.
struct FailingDevice {
    convs: std::sync::atomic::AtomicUsize,
    fail_after: usize,
}

impl FailingDevice {
    fn failed(&self) -> bool {
        self.convs.load(std::sync::atomic::Ordering::SeqCst) > self.fail_after
    }
}

impl Ops for FailingDevice {
    fn name(&self) -> &'static str {
        "failing"
    }
    fn conv2d(&self, x: &Tensor, w: &Tensor, b: Option<&Tensor>, pad: Padding) -> Tensor {
        self.convs.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
        if self.failed() {
            return Tensor::full(&[x.shape[0], w.shape[0], x.shape[2], x.shape[3]], f32::NAN);
        }
        Cpu.conv2d(x, w, b, pad)
    }
    #[allow(clippy::too_many_arguments)]
    fn conv2d_backward(
        &self,
        x: &Tensor,
        w: &Tensor,
        dy: &Tensor,
        pad: Padding,
        dx: Option<&mut Tensor>,
        dw: &mut Tensor,
        db: Option<&mut Tensor>,
    ) {
        Cpu.conv2d_backward(x, w, dy, pad, dx, dw, db)
    }
    fn relu(&self, x: &Tensor) -> Tensor {
        Cpu.relu(x)
    }
    fn relu_backward(&self, x: &Tensor, dy: &Tensor, dx: &mut Tensor) {
        Cpu.relu_backward(x, dy, dx)
    }
    fn add_assign(&self, a: &mut Tensor, b: &Tensor) {
        Cpu.add_assign(a, b)
    }
    fn pixel_shuffle(&self, x: &Tensor, r: usize) -> Tensor {
        Cpu.pixel_shuffle(x, r)
    }
    fn pixel_unshuffle(&self, x: &Tensor, r: usize) -> Tensor {
        Cpu.pixel_unshuffle(x, r)
    }
    fn resize(&self, x: &Tensor, h: usize, w: usize, mode: Interp) -> Tensor {
        Cpu.resize(x, h, w, mode)
    }
    fn resize_backward(&self, dy: &Tensor, mode: Interp, dx: &mut Tensor) {
        Cpu.resize_backward(dy, mode, dx)
    }
    fn sigmoid(&self, x: &Tensor) -> Tensor {
        Cpu.sigmoid(x)
    }
    fn mse(&self, pred: &Tensor, target: &Tensor) -> (f32, Tensor) {
        Cpu.mse(pred, target)
    }
    fn bce_with_logits(&self, logits: &Tensor, target: &Tensor, pos_weight: f32) -> (f32, Tensor) {
        Cpu.bce_with_logits(logits, target, pos_weight)
    }
    fn edge_mse(&self, pred: &Tensor, target: &Tensor) -> (f32, Tensor) {
        Cpu.edge_mse(pred, target)
    }
    fn edge_length_mse(&self, pred: &Tensor, target: &Tensor) -> (f32, Tensor) {
        Cpu.edge_length_mse(pred, target)
    }
    fn laplacian_mse(&self, pred: &Tensor, target: &Tensor) -> (f32, Tensor) {
        Cpu.laplacian_mse(pred, target)
    }
    fn detail_energy_mse(
        &self,
        p: &Tensor,
        t: &Tensor,
        h: usize,
        w: usize,
        d: DetailEnergy,
    ) -> (f32, Tensor) {
        Cpu.detail_energy_mse(p, t, h, w, d)
    }
    fn adam_update(
        &self,
        p: &mut [f32],
        g: &[f32],
        m: &mut [f32],
        v: &mut [f32],
        step: u64,
        hp: &AdamParams,
    ) {
        Cpu.adam_update(p, g, m, v, step, hp)
    }
    fn take_error(&self) -> Option<anisocb::Error> {
        self.failed().then(|| anisocb::Error::device("CUDA conv2d failed: out of memory (simulated)"))
    }
}

#[test]
fn a_device_failure_mid_shot_is_an_error_naming_the_device_not_nan_frames() {
    let d = TempDir::new("lib-device");
    drape_frames(&d.join("in"), 4);
    let job = UpscaleJob::new(vec![d.join("in")], d.join("out")).check().unwrap();
    let model = embedded_model().unwrap();
    let dev = FailingDevice { convs: 0.into(), fail_after: 40 };
    let e = upscale_files(&dev, &model, &job, &mut Quiet).unwrap_err();
    assert!(matches!(e, anisocb::Error::Device(_)), "{e}");
    assert!(e.to_string().contains("out of memory"), "{e}");
    // The same job on a table that does not fail runs.
    let ok = FailingDevice { convs: 0.into(), fail_after: usize::MAX };
    assert_eq!(upscale_files(&ok, &model, &job, &mut Quiet).unwrap().frames, 4);
}
