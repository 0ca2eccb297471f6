//! Crash safety: `anisocb train` and `anisocb upscale` are killed (SIGKILL) at pseudo-random
//! moments, in a bounded loop, and rerun. Every checkpoint on disk must always be complete
//! (loadable), `--resume` must finish with exactly the bytes of an uninterrupted run, and a
//! rerun of `upscale` must complete its output sequence identically. Kill moments come from a
//! fixed-seed PRNG scaled by the measured duration of a clean run, so they land at varied
//! points (before the first checkpoint, mid-write, after the last) on any machine speed.

#[path = "common/tempdir.rs"]
mod tempdir;
use anisocb::rng::Rng;
use tempdir::TempDir;
#[path = "common/random.rs"]
mod random;
use anisocb::io::{read_npz, write_npz, NpzEntries};
use anisocb::tensor::Tensor;
use random::TestData;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn scratch(test: &str) -> TempDir {
    TempDir::new(&format!("crash-{test}"))
}

fn bin() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_anisocb"));
    c.stdout(Stdio::null()).stderr(Stdio::piped()).env("RAYON_NUM_THREADS", "1");
    c
}

/// Run to completion; panic with stderr on failure. Returns the wall time.
fn run_ok(args: &[&str]) -> Duration {
    let t = Instant::now();
    let o = bin().args(args).output().unwrap();
    assert!(o.status.success(), "anisocb {args:?} failed: {}", String::from_utf8_lossy(&o.stderr));
    t.elapsed()
}

/// Start, then SIGKILL after `after` unless it finished first. Returns true if it finished.
fn run_killed(args: &[&str], after: Duration) -> bool {
    run_killed_when(args, |t| t >= after)
}

/// Start, then SIGKILL as soon as `kill_now(elapsed)` says so, unless it finished first.
fn run_killed_when(args: &[&str], mut kill_now: impl FnMut(Duration) -> bool) -> bool {
    let mut child = bin().args(args).spawn().unwrap();
    let t = Instant::now();
    while !kill_now(t.elapsed()) {
        if let Some(status) = child.try_wait().unwrap() {
            let mut err = String::new();
            use std::io::Read;
            child.stderr.take().unwrap().read_to_string(&mut err).unwrap();
            assert!(status.success(), "anisocb {args:?} failed: {err}");
            return true;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    false
}

/// Files in `dir` as (name, bytes), sorted by name, without temporaries of atomic writes.
fn snapshot(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap())
        .filter(|e| e.file_type().unwrap().is_file())
        .map(|e| (e.file_name().to_string_lossy().into_owned(), std::fs::read(e.path()).unwrap()))
        .filter(|(n, _)| !is_temp(n))
        .collect();
    v.sort();
    v
}

fn is_temp(name: &str) -> bool {
    name.starts_with('.') && name.contains(".tmp.")
}

fn temps(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .map(|r| {
            r.map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).filter(|n| is_temp(n)).collect()
        })
        .unwrap_or_default()
}

/// A tiny training set: 4 frames, LR 6×6, HR 12×12, smooth waves.
fn tiny_dataset(path: &Path) {
    let (n, h, w) = (4usize, 6usize, 6usize);
    let img = |n: usize, c: usize, h: usize, w: usize, f: &dyn Fn(usize, usize, usize, usize) -> f32| {
        let mut t = Tensor::zeros(&[n, c, h, w]);
        for a in 0..n {
            for b in 0..c {
                for y in 0..h {
                    for x in 0..w {
                        let i = t.idx4(a, b, y, x);
                        t.data[i] = f(a, b, y, x);
                    }
                }
            }
        }
        t
    };
    let wave = |s: usize| {
        move |a: usize, b: usize, y: usize, x: usize| {
            let (u, v) = (x as f32 / s as f32, y as f32 / s as f32);
            match b {
                0 => u,
                1 => v,
                _ => 0.5 + 0.2 * (6.0 * u + a as f32).sin() * (4.0 * v).cos(),
            }
        }
    };
    let mut e = NpzEntries::default();
    e.push_array("lr", img(n, 3, h, w, &wave(w - 1)));
    e.push_array("hr", img(n, 3, 2 * h, 2 * w, &wave(2 * w - 1)));
    e.push_array("boundary", img(n, 1, 2 * h, 2 * w, &|_, _, y, x| (x == 0 || y == 0) as u8 as f32));
    e.push_array("edges", img(n, 1, 2 * h, 2 * w, &|_, _, y, x| ((x + y) % 7 == 0) as u8 as f32));
    write_npz(path, &e).unwrap();
}

#[test]
fn killed_training_resumes_to_the_same_bits_and_never_leaves_a_partial_checkpoint() {
    let d = scratch("train");
    let data = d.join("data.npz");
    tiny_dataset(&data);
    let data_s = data.to_str().unwrap().to_string();
    let args = |out: &Path| -> Vec<String> {
        [
            "train",
            "--data",
            &data_s,
            "--net",
            "geometry",
            "--config",
            "tiny",
            "--steps",
            "80",
            "--batch",
            "2",
            "--patch",
            "4",
            "--val-every",
            "10",
            "--checkpoint-every",
            "4",
            "--seed",
            "7",
            "--out",
        ]
        .iter()
        .map(|s| s.to_string())
        .chain([out.to_str().unwrap().to_string()])
        .collect()
    };
    let reference = d.join("reference");
    let a: Vec<String> = args(&reference);
    let clean = run_ok(&a.iter().map(String::as_str).collect::<Vec<_>>());
    let want = snapshot(&reference);
    assert!(
        want.iter().any(|(n, _)| n == "weights.npz"),
        "{:?}",
        want.iter().map(|f| &f.0).collect::<Vec<_>>()
    );

    let out = d.join("killed");
    let mut rng =
        Rng::new(std::env::var("ANISOCB_CRASH_SEED").ok().and_then(|s| s.parse().ok()).unwrap_or(0xC0FFEE));
    let (mut kills, mut done) = (0, false);
    for _ in 0..8 {
        let ckpt = out.join("checkpoint.npz");
        let mut a = args(&out);
        if ckpt.exists() {
            a.push("--resume".into());
        }
        // The first kill comes early (before any checkpoint, on any machine speed); later
        // ones after 1–4 new checkpoint versions plus 0–15 ms, so they fall before, during
        // and after checkpoint writes whatever the load on the machine.
        let argv: Vec<&str> = a.iter().map(String::as_str).collect();
        let what;
        if kills == 0 {
            let after = clean.mul_f64(0.03);
            what = format!("after {after:?}");
            done = run_killed(&argv, after);
        } else {
            let (target, jitter) = (1 + rng.next_u64() % 4, Duration::from_micros(rng.next_u64() % 15_000));
            what = format!("after {target} checkpoints + {jitter:?}");
            let stamp = || std::fs::metadata(&ckpt).and_then(|m| m.modified()).ok();
            let (mut last, mut seen, mut since) = (stamp(), 0, None::<Duration>);
            done = run_killed_when(&argv, |t| {
                if let Some(s) = since {
                    return t >= s + jitter;
                }
                let now = stamp();
                if now != last {
                    (last, seen) = (now, seen + 1);
                    if seen >= target {
                        since = Some(t);
                    }
                }
                false
            });
        }
        let step = std::fs::read_to_string(out.join("loss.csv")).map(|s| s.lines().count()).unwrap_or(0);
        eprintln!("train: kill {what}: finished={done}, loss.csv rows={step}");
        if ckpt.exists() {
            let e = read_npz(&ckpt).unwrap_or_else(|e| panic!("partial checkpoint after a kill: {e}"));
            assert!(e.file("trainer.json").is_some(), "checkpoint without trainer.json");
        }
        if done {
            break;
        }
        kills += 1;
    }
    if !done {
        let mut a = args(&out);
        if out.join("checkpoint.npz").exists() {
            a.push("--resume".into());
        }
        run_ok(&a.iter().map(String::as_str).collect::<Vec<_>>());
    }
    assert!(kills > 0, "no run was interrupted (clean run took {clean:?})");
    let got = snapshot(&out);
    let names = |s: &[(String, Vec<u8>)]| s.iter().map(|f| f.0.clone()).collect::<Vec<_>>();
    assert_eq!(names(&got), names(&want));
    for ((n, a), (_, b)) in got.iter().zip(&want) {
        if n.ends_with(".png") {
            continue; // pictures may be redrawn; their data is loss.csv
        }
        assert!(a == b, "{n} differs after {kills} kills and resumes");
    }
    assert!(temps(&out).is_empty(), "stray temporary files after resume: {:?}", temps(&out));
    eprintln!("train: {kills} kills, clean run {clean:?}");
}

/// An OBJ of a w×h grid of quads (vertex (i, j) at j*w+i), one frame of a wave.
fn grid_obj(w: usize, h: usize, t: f32) -> String {
    let mut s = String::new();
    for j in 0..h {
        for i in 0..w {
            let (x, y) = (i as f32 / (w - 1) as f32, j as f32 / (h - 1) as f32);
            s += &format!("v {x} {y} {}\n", 0.1 * (4.0 * x + t).sin());
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

#[test]
fn killed_upscale_reruns_to_a_complete_identical_sequence() {
    let d = scratch("upscale");
    let input = d.join("frames");
    std::fs::create_dir_all(&input).unwrap();
    for f in 0..24 {
        std::fs::write(input.join(format!("frame_{f}.obj")), grid_obj(8, 6, f as f32 * 0.2)).unwrap();
    }
    let inp = input.to_str().unwrap().to_string();
    let reference = d.join("reference");
    let clean = run_ok(&["upscale", &inp, "--out", reference.to_str().unwrap()]);
    let meshes = |dir: &Path| -> Vec<(String, Vec<u8>)> {
        snapshot(dir).into_iter().filter(|(n, _)| n.ends_with(".obj") || n.ends_with(".npy")).collect()
    };
    let want = meshes(&reference);
    assert!(
        want.len() >= 24,
        "expected 24 output frames, got {:?}",
        want.iter().map(|f| &f.0).collect::<Vec<_>>()
    );
    let out = d.join("killed");
    let outs = out.to_str().unwrap().to_string();
    let mut rng = Rng::new(0xBEEF);
    let mut kills = 0;
    for _ in 0..6 {
        if run_killed(&["upscale", &inp, "--out", &outs], clean.mul_f64(0.05 + 0.9 * rng.unit_f64())) {
            break;
        }
        kills += 1;
        // Whatever is there is a complete file: every OBJ present parses.
        if out.exists() {
            for (n, b) in meshes(&out) {
                if let Some((_, w)) = want.iter().find(|(m, _)| *m == n) {
                    assert!(b == *w, "{n} differs from the clean run's after a kill (partial write?)");
                }
            }
            // Only a run that wrote every frame may call the folder complete.
            if let Ok(j) = std::fs::read_to_string(out.join("upscale.json")) {
                if !j.contains("\"complete\": false") {
                    assert!(j.contains("\"complete\": true"), "{j}");
                    assert!(meshes(&out) == want, "upscale.json says complete after a kill: {j}");
                }
            }
        }
    }
    run_ok(&["upscale", &inp, "--out", &outs]);
    let j = std::fs::read_to_string(out.join("upscale.json")).unwrap();
    assert!(j.contains("\"complete\": true"), "{j}");
    assert!(temps(&out).is_empty(), "stray temporary files after the rerun: {:?}", temps(&out));
    assert!(meshes(&out) == want, "rerun after {kills} kills did not complete the sequence identically");
}
