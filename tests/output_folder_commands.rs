//! The output-folder rule (src/pipeline/folder.rs) for every command besides `upscale`
//! (tests/output_folder.rs): `simulate`, `train`, `eval` and `demo` write into a new or empty
//! folder or one an earlier run of the same job owns; anything else is refused naming a foreign
//! file unless `--overwrite`; a second run while one holds the folder's lock is refused; an
//! earlier run's files this run does not write are removed. `dataset` and `bundle` write one
//! file: another kind of file there is refused unless `--overwrite`, and so is a file being
//! written.

#[path = "common/tempdir.rs"]
mod tempdir;
use std::path::Path;
use tempdir::TempDir;

fn anisocb(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_anisocb")).args(args).output().unwrap()
}

fn ok(args: &[&str]) -> String {
    let o = anisocb(args);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "{args:?} failed: {err}");
    err
}

fn refused(args: &[&str], want: &[&str]) -> String {
    let o = anisocb(args);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(1), "{args:?} was not refused: {err}");
    for w in want {
        assert!(err.contains(w), "{args:?}: message lacks {w:?}: {err}");
    }
    err
}

/// Every file under `dir` (paths inside it, `.`-names left out), with its bytes.
fn snapshot(dir: &Path) -> Vec<(String, Vec<u8>)> {
    fn walk(root: &Path, dir: &Path, out: &mut Vec<(String, Vec<u8>)>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let e = e.unwrap();
            let name = e.file_name().to_string_lossy().into_owned();
            if name.starts_with('.') {
                continue;
            }
            if e.file_type().unwrap().is_dir() {
                walk(root, &e.path(), out);
            } else {
                let rel = e.path().strip_prefix(root).unwrap().to_string_lossy().into_owned();
                out.push((rel, std::fs::read(e.path()).unwrap()));
            }
        }
    }
    let mut v = Vec::new();
    walk(dir, dir, &mut v);
    v.sort();
    v
}

/// Hold the lock a run of `summary` takes in `dir`, as another run would, while `f` runs.
fn while_locked(dir: &Path, summary: &str, f: impl FnOnce()) {
    std::fs::create_dir_all(dir).unwrap();
    let lock = std::fs::File::create(dir.join(format!(".{summary}.lock"))).unwrap();
    lock.try_lock().unwrap();
    f();
    drop(lock);
}

/// A foreign file in `out` refuses the command `args` (naming it, the folder left as it was);
/// `--overwrite` writes beside it and keeps it.
fn foreign_file_refused_unless_overwrite(out: &Path, args: &[&str]) {
    std::fs::create_dir_all(out).unwrap();
    std::fs::write(out.join("notes.txt"), b"someone's notes").unwrap();
    let before = snapshot(out);
    refused(args, &["--out", "notes.txt", "overwrite"]);
    assert!(snapshot(out) == before, "{args:?}: a refused run changed the folder");
    let with: Vec<&str> = args.iter().copied().chain(["--overwrite"]).collect();
    ok(&with);
    assert_eq!(std::fs::read(out.join("notes.txt")).unwrap(), b"someone's notes");
}

fn sim_args<'a>(out: &'a str, scenario: &'a str, frames: &'a str) -> Vec<&'a str> {
    vec!["simulate", "--scenario", scenario, "--res", "8x8", "--frames", frames, "--obj", "--out", out]
}

#[test]
fn simulate_keeps_to_its_folder_and_removes_the_frames_a_shorter_rerun_does_not_write() {
    let d = TempDir::new("cmd-simulate");
    let out = d.arg("sim");
    foreign_file_refused_unless_overwrite(&d.join("sim"), &sim_args(&out, "drop", "5"));
    // A refused rerun removes nothing, not even the frames it would have found stale.
    refused(&sim_args(&out, "drop", "3"), &["notes.txt"]);
    assert!(d.join("sim/obj/frame_0004.obj").is_file(), "a refused run removed a stale frame");
    std::fs::remove_file(d.join("sim/notes.txt")).unwrap();
    // The same scene again, shorter: accepted, and the frames it no longer writes are gone.
    let err = ok(&sim_args(&out, "drop", "3"));
    assert!(err.contains("removed obj/frame_0004.obj"), "{err}");
    let names: Vec<String> = snapshot(&d.join("sim")).into_iter().map(|(n, _)| n).collect();
    assert!(names.contains(&"obj/frame_0002.obj".to_string()), "{names:?}");
    assert!(
        !names.iter().any(|n| n.ends_with("frame_0003.obj") || n.ends_with("frame_0004.obj")),
        "{names:?}"
    );
    let summary = std::fs::read_to_string(d.join("sim/simulate.json")).unwrap();
    assert!(summary.contains("\"complete\": true") && summary.contains("obj/frame_0002.obj"), "{summary}");
    assert!(!summary.contains("frame_0003"), "{summary}");
    // Another scene's folder.
    let before = snapshot(&d.join("sim"));
    refused(&sim_args(&out, "twist", "3"), &["--out", "simulate.json", "another scene"]);
    assert!(snapshot(&d.join("sim")) == before);
    // A pair into the folder of a single run is another job too; a pair of its own reruns.
    let pair = d.arg("pair");
    let mut args = sim_args(&pair, "drop", "3");
    args.push("--pair");
    ok(&args);
    ok(&args);
    assert!(d.join("pair/lr/obj/frame_0002.obj").is_file() && d.join("pair/hr/geometry.npy").is_file());
    // A run while another holds the folder.
    while_locked(&d.join("sim"), "simulate.json", || {
        refused(&sim_args(&out, "drop", "3"), &["--out", "being written by another run"]);
    });
    ok(&sim_args(&out, "drop", "3"));
}

/// A data set of a tiny simulated pair, `d/data.npz`.
fn data_set(d: &TempDir) -> String {
    let pair = d.arg("pair");
    ok(&["simulate", "--scenario", "drop", "--res", "8x8", "--frames", "4", "--pair", "--out", &pair]);
    let data = d.arg("data.npz");
    ok(&["dataset", "--runs", &pair, "--out", &data]);
    data
}

fn train_args<'a>(data: &'a str, out: &'a str, net: &'a str) -> Vec<&'a str> {
    vec![
        "train", "--data", data, "--net", net, "--config", "tiny", "--steps", "2", "--patch", "4", "--out",
        out,
    ]
}

#[test]
fn train_keeps_to_its_folder_resumes_in_it_and_starts_again_with_overwrite() {
    let d = TempDir::new("cmd-train");
    let data = data_set(&d);
    let out = d.arg("train");
    foreign_file_refused_unless_overwrite(&d.join("train"), &train_args(&data, &out, "geometry"));
    std::fs::remove_file(d.join("train/notes.txt")).unwrap();
    let summary = std::fs::read_to_string(d.join("train/train.json")).unwrap();
    assert!(summary.contains("\"complete\": true") && summary.contains("checkpoint.npz"), "{summary}");
    // The same training again: its checkpoint is resumed, or started again with --overwrite.
    refused(&train_args(&data, &out, "geometry"), &["checkpoint already exists", "resume it"]);
    let mut resume = train_args(&data, &out, "geometry");
    resume.push("--resume");
    ok(&resume);
    let mut again = train_args(&data, &out, "geometry");
    again.push("--overwrite");
    ok(&again);
    // The linear upsampler on the same data into the same folder: the net's files are stale.
    ok(&train_args(&data, &out, "linear"));
    let names: Vec<String> = snapshot(&d.join("train")).into_iter().map(|(n, _)| n).collect();
    assert_eq!(names, ["train.json", "weights.npz"]);
    // Another data set's training folder.
    let other = d.arg("other.npz");
    std::fs::copy(&data, &other).unwrap();
    refused(&train_args(&other, &out, "linear"), &["--out", "train.json", "another data set"]);
    while_locked(&d.join("train"), "train.json", || {
        refused(&train_args(&data, &out, "linear"), &["--out", "being written by another run"]);
    });
}

#[test]
fn train_resume_takes_a_folder_its_checkpoint_vouches_for() {
    // `--net all --resume` over the folder of `--net geometry --out OUT/geometry`, as
    // weights/make_weights.sh trains: the checkpoint, not a train.json, says it is this run's.
    let d = TempDir::new("cmd-train-resume");
    let data = data_set(&d);
    let out = d.arg("train");
    let geometry = d.arg("train/geometry");
    ok(&train_args(&data, &geometry, "geometry"));
    let mut all = train_args(&data, &out, "all");
    all.push("--resume");
    ok(&all);
    assert!(d.join("train/weights.npz").is_file() && d.join("train/enhance/weights.npz").is_file());
}

#[test]
fn eval_keeps_to_its_folder_and_removes_pictures_a_rerun_does_not_draw() {
    let d = TempDir::new("cmd-eval");
    let pair = d.arg("run");
    ok(&["simulate", "--scenario", "drop", "--res", "16x16", "--frames", "4", "--pair", "--out", &pair]);
    let out = d.arg("eval");
    let args = |extra: &[&'static str]| -> Vec<String> {
        ["eval", "--runs", &pair, "--eta", "0", "--worst", "0", "--out", &out]
            .iter()
            .map(|s| s.to_string())
            .chain(extra.iter().map(|s| s.to_string()))
            .collect()
    };
    let run = |extra: &[&'static str]| ok(&args(extra).iter().map(String::as_str).collect::<Vec<_>>());
    foreign_file_refused_unless_overwrite(
        &d.join("eval"),
        &args(&["--flipbook"]).iter().map(String::as_str).collect::<Vec<_>>(),
    );
    assert!(d.join("eval/run-flipbook.png").is_file());
    // Still someone else's after an --overwrite run: the next run without it is refused.
    refused(&args(&[]).iter().map(String::as_str).collect::<Vec<_>>(), &["notes.txt"]);
    std::fs::remove_file(d.join("eval/notes.txt")).unwrap();
    let err = run(&[]);
    assert!(err.contains("removed run-flipbook.png"), "{err}");
    assert!(!d.join("eval/run-flipbook.png").exists() && d.join("eval/run-wrinkles.png").is_file());
    // Other runs' evaluation folder.
    let other = d.arg("other");
    ok(&["simulate", "--scenario", "drop", "--res", "16x16", "--frames", "4", "--pair", "--out", &other]);
    refused(
        &["eval", "--runs", &other, "--eta", "0", "--worst", "0", "--out", &out],
        &["--out", "eval.json", "another set of runs"],
    );
    while_locked(&d.join("eval"), "eval.json", || {
        refused(&args(&[]).iter().map(String::as_str).collect::<Vec<_>>(), &["being written by another run"]);
    });
}

#[test]
fn demo_keeps_to_its_folder_and_removes_the_frames_a_shorter_rerun_does_not_write() {
    let d = TempDir::new("cmd-demo");
    let out = d.arg("demo");
    let args = |frames: &'static str| vec!["demo", "--frames", frames, "--out", out.as_str()];
    foreign_file_refused_unless_overwrite(&d.join("demo"), &args("5"));
    assert!(d.join("demo/anisocb/frame_0004.obj").is_file());
    std::fs::remove_file(d.join("demo/notes.txt")).unwrap();
    let err = ok(&args("4"));
    assert!(err.contains("removed anisocb/frame_0004.obj"), "{err}");
    for sub in ["lr", "hr", "bicubic", "anisocb", "anisocb-physics"] {
        assert!(!d.join(format!("demo/{sub}/frame_0004.obj")).exists(), "{sub}");
        assert!(d.join(format!("demo/{sub}/frame_0003.obj")).is_file(), "{sub}");
    }
    // Another scene's demo folder.
    refused(
        &["demo", "--frames", "4", "--seed", "7", "--out", &out],
        &["--out", "demo.json", "another scene"],
    );
    while_locked(&d.join("demo"), "demo.json", || {
        refused(&args("4"), &["being written by another run"]);
    });
}

#[test]
fn dataset_replaces_only_a_data_set_and_not_while_another_run_writes_it() {
    let d = TempDir::new("cmd-dataset");
    let data = data_set(&d);
    let pair = d.arg("pair");
    // A rerun replaces its own data set.
    ok(&["dataset", "--runs", &pair, "--out", &data]);
    // Someone's file of that name.
    let notes = d.arg("notes.npz");
    std::fs::write(&notes, b"someone's notes").unwrap();
    refused(&["dataset", "--runs", &pair, "--out", &notes], &["--out", "notes.npz", "not a data set"]);
    assert_eq!(std::fs::read(&notes).unwrap(), b"someone's notes");
    assert!(!d.join("notes.png").exists(), "a refused run wrote its contact sheet");
    ok(&["dataset", "--runs", &pair, "--out", &notes, "--overwrite"]);
    assert!(anisocb::io::read_npz(Path::new(&notes)).unwrap().file("frames.json").is_some());
    // A contact sheet over a file that is no picture.
    let sheet = d.arg("sheet.png");
    std::fs::write(&sheet, b"not a picture").unwrap();
    refused(&["dataset", "--runs", &pair, "--out", &data, "--png", &sheet], &["sheet.png", "not a PNG"]);
    // Its own --boundary-benefit weights, under another spelling.
    let w = d.arg("w.npz");
    std::fs::copy(concat!(env!("CARGO_MANIFEST_DIR"), "/weights/anisocb-x2.npz"), &w).unwrap();
    let link = d.arg("link.npz");
    std::os::unix::fs::symlink(&w, &link).unwrap();
    refused(
        &["dataset", "--runs", &pair, "--out", &link, "--boundary-benefit", &w],
        &["--boundary-benefit", "replace"],
    );
    while_locked(d.path(), "data.npz", || {
        refused(&["dataset", "--runs", &pair, "--out", &data], &["being written by another run"]);
    });
}

#[test]
fn bundle_replaces_only_a_weights_file_never_its_input_and_not_while_another_run_writes_it() {
    let d = TempDir::new("cmd-bundle");
    let w = d.arg("w.npz");
    std::fs::copy(concat!(env!("CARGO_MANIFEST_DIR"), "/weights/anisocb-x2.npz"), &w).unwrap();
    let before = std::fs::read(&w).unwrap();
    let args = |out: &str, extra: &[&str]| -> Vec<String> {
        ["bundle", "--geometry", &w, "--boundary", &w, "--enhance", &w, "--out", out]
            .iter()
            .chain(extra)
            .map(|s| s.to_string())
            .collect()
    };
    let run =
        |out: &str, extra: &[&str]| anisocb(&args(out, extra).iter().map(String::as_str).collect::<Vec<_>>());
    // Its input under other spellings (a link, a hard link), even with --overwrite.
    let (link, hard) = (d.arg("link.npz"), d.arg("hard.npz"));
    std::os::unix::fs::symlink(&w, &link).unwrap();
    std::fs::hard_link(&w, &hard).unwrap();
    for out in [&link, &hard] {
        let o = run(out, &["--overwrite"]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(err.contains("is the input"), "{err}");
    }
    assert!(std::fs::read(&w).unwrap() == before, "the input bundle was rewritten");
    // A new bundle, then the same again over it.
    let out = d.arg("b.npz");
    assert!(run(&out, &[]).status.success());
    assert!(run(&out, &[]).status.success());
    // Someone's file.
    let notes = d.arg("notes.npz");
    std::fs::write(&notes, b"someone's notes").unwrap();
    let o = run(&notes, &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.code() == Some(1) && err.contains("not a weights file"), "{err}");
    assert_eq!(std::fs::read(&notes).unwrap(), b"someone's notes");
    assert!(run(&notes, &["--overwrite"]).status.success());
    while_locked(d.path(), "b.npz", || {
        let o = run(&out, &[]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.code() == Some(1) && err.contains("being written by another run"), "{err}");
    });
}
