//! What an output folder may hold and how it is written: temporary files are created
//! exclusively, never through a link planted in the folder.

#[path = "common/tempdir.rs"]
mod tempdir;
use anisocb::io::atomic::write_atomic_bytes;
use tempdir::TempDir;

#[test]
fn a_symlink_planted_at_a_temp_name_is_never_followed() {
    let d = TempDir::new("temp-symlink");
    let victim = d.join("victim.txt");
    std::fs::write(&victim, b"someone else's file").unwrap();
    // Every temp name this process can take first (`.NAME.tmp.<pid>.<n>`), a link to the victim.
    for n in 0..64 {
        let link = d.join(format!(".out.json.tmp.{}.{n}", std::process::id()));
        std::os::unix::fs::symlink(&victim, link).unwrap();
    }
    write_atomic_bytes(&d.join("out.json"), b"{}").unwrap();
    assert_eq!(std::fs::read(d.join("out.json")).unwrap(), b"{}");
    assert_eq!(std::fs::read(&victim).unwrap(), b"someone else's file", "the link was followed");
}

fn anisocb(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_anisocb")).args(args).output().unwrap()
}

/// `n` frames of a simulated drop as OBJ files in `d/name/obj`.
fn shot(d: &TempDir, name: &str, n: usize) -> String {
    let o = anisocb(&[
        "simulate",
        "--scenario",
        "drop",
        "--frames",
        &n.to_string(),
        "--obj",
        "--out",
        &d.arg(name),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    d.arg(&format!("{name}/obj"))
}

/// Every file of `dir` (names) with its bytes.
fn snapshot(dir: &std::path::Path) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap())
        .filter(|e| e.file_type().unwrap().is_file())
        .map(|e| (e.file_name().to_string_lossy().into_owned(), std::fs::read(e.path()).unwrap()))
        .collect();
    v.sort();
    v
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

#[test]
fn another_shots_folder_is_refused_and_left_as_it_was_unless_overwrite() {
    let d = TempDir::new("folder-foreign");
    let (a, b) = (shot(&d, "a", 3), shot(&d, "b", 3));
    // A folder holding another shot's frames (here b's LR frames, same names as a's output).
    let before = snapshot(std::path::Path::new(&b));
    refused(&["upscale", &a, "--out", &b], &["--out", "no upscale of these inputs wrote"]);
    assert!(snapshot(std::path::Path::new(&b)) == before, "a refused run changed the folder");
    // b's output folder, then a into it: b's summary and frames are another shot's.
    assert!(anisocb(&["upscale", &b, "--out", &d.arg("hr")]).status.success());
    refused(&["upscale", &a, "--out", &d.arg("hr")], &["--out", "another shot"]);
    let o = anisocb(&["upscale", &a, "--out", &d.arg("hr"), "--overwrite"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn a_rerun_after_the_input_shrank_removes_the_frames_it_no_longer_writes() {
    let d = TempDir::new("folder-shrink");
    let a = shot(&d, "a", 5);
    assert!(anisocb(&["upscale", &a, "--out", &d.arg("hr")]).status.success());
    let objs = |p: &str| {
        let mut v: Vec<String> =
            snapshot(&d.join(p)).into_iter().map(|(n, _)| n).filter(|n| n.ends_with(".obj")).collect();
        v.sort();
        v
    };
    let before = objs("hr");
    assert_eq!(before.len(), 5);
    std::fs::remove_file(std::path::Path::new(&a).join(&before[4])).unwrap();
    std::fs::remove_file(std::path::Path::new(&a).join(&before[3])).unwrap();
    let o = anisocb(&["upscale", &a, "--out", &d.arg("hr")]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(objs("hr"), before[..3].to_vec(), "stale frames left beside a summary of 3");
    let summary = std::fs::read_to_string(d.join("hr/upscale.json")).unwrap();
    assert!(
        summary.contains("\"complete\": true")
            && summary.contains(&before[2])
            && !summary.contains(&before[3])
    );
}

#[test]
fn a_rerun_removes_the_temporaries_a_killed_run_left_beside_its_summary_and_files() {
    let d = TempDir::new("folder-temps");
    let a = shot(&d, "a", 2);
    assert!(anisocb(&["upscale", &a, "--out", &d.arg("hr")]).status.success());
    // What runs killed between creating a temp file and renaming it leave (pid 4194305 is
    // above Linux's largest pid, so never a running process): beside a summary, a frame.
    let frame = snapshot(&d.join("hr")).into_iter().map(|(n, _)| n).find(|n| n.ends_with(".obj")).unwrap();
    let planted = [
        d.join("a/.simulate.json.tmp.4194305.0"),
        d.join("hr/.upscale.json.tmp.4194305.1"),
        d.join("hr").join(format!(".{frame}.tmp.4194305.3")),
    ];
    for p in &planted {
        std::fs::write(p, b"partial").unwrap();
    }
    shot(&d, "a", 2);
    let o = anisocb(&["upscale", &a, "--out", &d.arg("hr")]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for p in &planted {
        assert!(!p.exists(), "{} was left after the rerun", p.display());
    }
}

#[test]
fn a_slice_with_other_settings_beside_a_full_run_is_refused_unless_overwrite() {
    let d = TempDir::new("folder-slice");
    let a = shot(&d, "a", 4);
    assert!(anisocb(&["upscale", &a, "--out", &d.arg("hr")]).status.success());
    // The same settings: a farm slice of the same shot joins the folder.
    let o = anisocb(&["upscale", &a, "--out", &d.arg("hr"), "--frames", "1:3"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // Other settings would leave frames of two settings.
    refused(
        &["upscale", &a, "--out", &d.arg("hr"), "--frames", "0:2", "--eta", "1"],
        &["other settings", "upscale"],
    );
    let o = anisocb(&["upscale", &a, "--out", &d.arg("hr"), "--frames", "0:2", "--eta", "1", "--overwrite"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let names: Vec<String> = snapshot(&d.join("hr")).into_iter().map(|(n, _)| n).collect();
    assert!(
        !names.contains(&"upscale.json".to_string()) && names.contains(&"upscale.0-2.json".to_string()),
        "{names:?}"
    );
    assert_eq!(names.iter().filter(|n| n.ends_with(".obj")).count(), 2, "{names:?}");
}

#[test]
fn a_second_run_into_a_folder_being_written_is_refused_naming_the_holder() {
    let d = TempDir::new("folder-lock");
    let a = shot(&d, "a", 2);
    std::fs::create_dir_all(d.join("hr")).unwrap();
    // Another run holds the lock on hr's upscale.json.
    let lock = std::fs::File::create(d.join("hr/.upscale.json.lock")).unwrap();
    lock.try_lock().unwrap();
    refused(&["upscale", &a, "--out", &d.arg("hr")], &["--out", "being written by another run"]);
    drop(lock);
    assert!(anisocb(&["upscale", &a, "--out", &d.arg("hr")]).status.success());
}
