//! A catalogue of hostile output locations and runs that do not finish: paths that cannot be
//! written (under a regular file, in a missing folder), an `--out` that is (or links to) the
//! input, inputs whose output names collide, runs stopped part way by a bad frame or a signal,
//! and a second run into a folder another is writing. Each refusal names what is wrong and
//! writes nothing; a run that stops leaves no temporary files and an `upscale.json` marked
//! incomplete.

#[path = "common/hostile.rs"]
mod hostile;
#[path = "common/tempdir.rs"]
mod tempdir;
use anisocb::io::{write_npy, NpzEntries};
use hostile::{
    anisocb, expect_err, file_names, grid_obj, grid_xyz, obj_shot, pc2_raw, ramp, scratch, upscale_refused,
    write,
};
use std::path::{Path, PathBuf};

// ---------------------------------------------------------------------------------------------
// Output locations that cannot be written.

#[test]
fn writing_under_a_regular_file_fails_naming_the_path_and_leaves_nothing() {
    let d = scratch("unwritable");
    let file = write(&d, "a_file", b"I am a file, not a directory");
    let target = file.join("out.npy");
    expect_err(write_npy(&target, &ramp(&[2])), &target, &["Not a directory"]);
    let sub = file.join("sub");
    expect_err(
        anisocb::io::atomic::ensure_dir(&sub),
        &sub,
        &["cannot create output directory", "output folder"],
    );
    expect_err(anisocb::io::atomic::ensure_dir(&file), &file, &["not a directory"]);
    assert_eq!(file_names(&d), ["a_file"]);
    assert_eq!(std::fs::read(&file).unwrap(), b"I am a file, not a directory");
}

#[test]
fn writing_into_a_missing_directory_fails_naming_the_path() {
    let d = scratch("missing_dir");
    let target = d.join("no/such/dir/x.npz");
    expect_err(anisocb::io::write_npz(&target, &NpzEntries::default()), &target, &["No such file"]);
    assert!(file_names(&d).is_empty());
}

// ---------------------------------------------------------------------------------------------
// `anisocb upscale`: output folders that could lose a frame or overwrite the input.

/// Every file under `dir` with its bytes, to prove a refused run touched nothing.
fn snapshot(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut v = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            v.extend(snapshot(&p));
        } else {
            v.push((p.clone(), std::fs::read(&p).unwrap()));
        }
    }
    v.sort();
    v
}

#[test]
fn upscale_refuses_an_out_that_would_overwrite_the_input() {
    let d = scratch("upscale_out_is_input");
    let shot = obj_shot(&d, "shot", 2);
    let run = d.join("run");
    std::fs::create_dir_all(&run).unwrap();
    write_npy(&run.join("geometry.npy"), &ramp(&[2, 3, 4, 4])).unwrap();
    write_npy(&run.join("domain.npy"), &anisocb::geom::Domain::UNIT.to_tensor()).unwrap();
    let cache = d.join("cache");
    std::fs::create_dir_all(&cache).unwrap();
    write(&cache, "cloth.pc2", &pc2_raw(b"POINTCACHE2\0", 1, 16, 0.0, 1.0, 2, &grid_xyz(4, 4, 2)));
    write(&cache, "rest.obj", grid_obj(4, 4).as_bytes());
    let link = d.join("link_to_shot");
    std::os::unix::fs::symlink(&shot, &link).unwrap();
    let before = snapshot(&d);
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let (frame0, pc2, rest) = (shot.join("frame_0.obj"), cache.join("cloth.pc2"), cache.join("rest.obj"));
    let cases: Vec<(Vec<String>, String, PathBuf)> = vec![
        // OBJ folder into itself, however --out is spelled.
        (vec![s(&shot)], s(&shot), frame0.clone()),
        (vec![s(&shot)], format!("{}/.", s(&shot)), frame0.clone()),
        (vec![s(&shot)], format!("{}/../shot/", s(&shot)), frame0.clone()),
        (vec![s(&shot)], s(&link), frame0.clone()),
        (vec![s(&link)], s(&shot), link.join("frame_0.obj")),
        (vec![s(&frame0), s(&shot.join("frame_1.obj"))], s(&shot), frame0.clone()),
        // A run folder (geometry.npy + domain.npy), also as --format obj.
        (vec![s(&run)], s(&run), run.join("geometry.npy")),
        (vec![s(&run.join("geometry.npy"))], format!("{}/../run", s(&run)), run.join("geometry.npy")),
        (vec![s(&run), "--format".into(), "obj".into()], s(&run), run.join("geometry.npy")),
        // A point cache and its rest mesh.
        (vec![s(&pc2), "--rest".into(), s(&rest)], s(&cache), pc2.clone()),
    ];
    for (input, out, named) in &cases {
        let mut args: Vec<&str> = input.iter().map(String::as_str).collect();
        args.extend(["--out", out]);
        let err = upscale_refused(&args, 1, &["--out", out, &named.display().to_string(), "new folder"]);
        assert!(err.contains("is the folder of the input"), "{err}");
        assert!(snapshot(&d) == before, "{args:?}: a refused run changed a file");
    }
    // A rest mesh kept with the HR output: the cache is elsewhere, the rest mesh is in --out.
    let other = d.join("other");
    std::fs::create_dir_all(&other).unwrap();
    std::fs::rename(&pc2, other.join("cloth.pc2")).unwrap();
    let pc2 = other.join("cloth.pc2");
    let before = snapshot(&d);
    upscale_refused(&[&s(&pc2), "--rest", &s(&rest), "--out", &s(&cache)], 1, &[&s(&rest)]);
    assert!(snapshot(&d) == before);
    // An --out holding a hard link to an input frame under the output's name.
    let linked = d.join("linked");
    std::fs::create_dir_all(&linked).unwrap();
    std::fs::hard_link(&frame0, linked.join("frame_0.obj")).unwrap();
    let before = snapshot(&d);
    let err = upscale_refused(&[&s(&shot), "--out", &s(&linked)], 1, &[&s(&frame0), "a link"]);
    assert!(err.contains(&s(&linked.join("frame_0.obj"))), "{err}");
    assert!(snapshot(&d) == before);
    // A new folder works; the same command on its output then refuses to upscale it in place.
    let hr = d.join("hr");
    let o = anisocb(&["upscale", &s(&shot), "--out", &s(&hr)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let before = snapshot(&d);
    upscale_refused(&[&s(&hr), "--out", &s(&hr)], 1, &["is the folder of the input"]);
    assert!(snapshot(&d) == before);
}

#[test]
fn upscale_refuses_inputs_whose_output_names_collide_and_writes_nothing() {
    use std::os::unix::ffi::OsStrExt;
    let d = scratch("upscale_collide");
    let (a, b) = (obj_shot(&d, "shotA", 2), obj_shot(&d, "shotB", 2));
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let out = d.join("out");
    // Two folders with the same frame names: both named, nothing written.
    upscale_refused(
        &[&s(&a), &s(&b), "--out", &s(&out)],
        1,
        &[&s(&a.join("frame_0.obj")), &s(&b.join("frame_0.obj")), "its own output folder"],
    );
    assert!(!out.exists(), "a refused run created --out");
    // The same folder or file given twice.
    upscale_refused(&[&s(&a), &s(&a), "--out", &s(&out)], 1, &["given twice"]);
    upscale_refused(
        &[&s(&a), &s(&a.join("frame_1.obj")), "--out", &s(&out)],
        1,
        &["frame_1.obj is given twice"],
    );
    // Names that differ only in bytes that are not UTF-8 (both would read "caf\u{FFFD}.obj").
    let latin = d.join("latin1");
    std::fs::create_dir_all(&latin).unwrap();
    for name in [&b"caf\xe9.obj"[..], b"caf\xe8.obj"] {
        std::fs::write(latin.join(std::ffi::OsStr::from_bytes(name)), grid_obj(4, 4)).unwrap();
    }
    upscale_refused(&[&s(&latin), "--out", &s(&out)], 1, &["caf\\xE9.obj", "caf\\xE8.obj", "not UTF-8"]);
    assert!(!out.exists(), "a refused run created --out");
    // One such name alone is kept byte for byte, not renamed to the lossy "caf\u{FFFD}.obj".
    std::fs::remove_file(latin.join(std::ffi::OsStr::from_bytes(b"caf\xe8.obj"))).unwrap();
    let o = anisocb(&["upscale", &s(&latin), "--out", &s(&out)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.join(std::ffi::OsStr::from_bytes(b"caf\xe9.obj")).is_file(), "{:?}", file_names(&out));
    // A point cache's rest mesh named like an output frame of the cache (--format obj).
    let cache = d.join("cache");
    std::fs::create_dir_all(&cache).unwrap();
    let pc2 = write(&cache, "cloth.pc2", &pc2_raw(b"POINTCACHE2\0", 1, 16, 0.0, 1.0, 2, &grid_xyz(4, 4, 2)));
    let rest = write(&cache, "frame_0000.obj", grid_obj(4, 4).as_bytes());
    let out2 = d.join("out2");
    upscale_refused(
        &[&s(&pc2), "--rest", &s(&rest), "--format", "obj", "--out", &s(&out2)],
        1,
        &[&s(&out2.join("frame_0000.obj")), "written twice"],
    );
    assert!(!out2.exists(), "a refused run created --out");
}

// ---------------------------------------------------------------------------------------------
// Runs that do not finish, and runs side by side.

#[test]
fn upscale_stopped_part_way_leaves_upscale_json_marked_incomplete() {
    let d = scratch("upscale_incomplete");
    let good = obj_shot(&d, "good", 4);
    let frame2 = std::fs::read(good.join("frame_2.obj")).unwrap();
    let nan = grid_obj(4, 4).replacen("v 0.1 0 0", "v nan 0 0", 1);
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let out = d.join("out");
    let summary = || std::fs::read_to_string(out.join("upscale.json")).unwrap();
    let o = anisocb(&["upscale", &s(&good), "--out", &s(&out)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(summary().contains("\"complete\": true"), "{}", summary());
    // A rerun with another η that fails on frame 2 (broken since) after writing frames 0 and
    // 1: the folder now mixes both runs' frames, and its summary must say so, not keep the
    // first run's.
    write(&good, "frame_2.obj", nan.as_bytes());
    let o = anisocb(&["upscale", &s(&good), "--out", &s(&out), "--eta", "1", "--chunk", "1"]);
    assert_eq!(o.status.code(), Some(1), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stderr).contains("frame_2.obj"));
    let text = summary();
    assert!(text.contains("\"complete\": false") && !text.contains("\"complete\": true"), "{text}");
    assert!(text.contains("rerun"), "{text}");
    // Completing the run marks the folder finished again.
    write(&good, "frame_2.obj", &frame2);
    let o = anisocb(&["upscale", &s(&good), "--out", &s(&out), "--eta", "1"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(summary().contains("\"complete\": true"), "{}", summary());
    // And --help says how to tell the two apart.
    let help = String::from_utf8_lossy(&anisocb(&["upscale", "--help"]).stdout).into_owned();
    assert!(help.contains("\"complete\": false") && help.contains("\"complete\": true"), "{help}");
}

/// A 64 × 64 point cache of `frames` frames and its rest mesh in `dir` (a run of seconds).
fn long_cache(dir: &Path, frames: usize) -> (PathBuf, PathBuf) {
    std::fs::create_dir_all(dir).unwrap();
    let pc2 = write(
        dir,
        "cloth.pc2",
        &pc2_raw(b"POINTCACHE2\0", 1, 4096, 0.0, 1.0, frames as i32, &grid_xyz(64, 64, frames)),
    );
    (pc2, write(dir, "rest.obj", grid_obj(64, 64).as_bytes()))
}

/// Start `anisocb upscale CACHE --rest REST --out OUT` and wait until its streamed cache's
/// temporary file exists (the run is then under way, writing).
fn start_cache_upscale(pc2: &Path, rest: &Path, out: &Path) -> std::process::Child {
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let child = std::process::Command::new(env!("CARGO_BIN_EXE_anisocb"))
        .args(["upscale", &s(pc2), "--rest", &s(rest), "--out", &s(out), "--chunk", "1", "--threads", "1"])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = std::time::Instant::now();
    while !temp_files(out).iter().any(|f| f.starts_with(".cloth.pc2.tmp.")) {
        assert!(t0.elapsed().as_secs() < 60, "the run never started writing: {:?}", file_names(out));
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    child
}

/// Hidden temporary files in `dir` (none if it does not exist).
fn temp_files(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .map(|r| {
            r.flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.contains(".tmp."))
                .collect()
        })
        .unwrap_or_default()
}

#[test]
fn upscale_interrupted_by_sigint_or_sigterm_removes_its_temp_files() {
    let d = scratch("upscale_signal");
    let (pc2, rest) = long_cache(&d.join("in"), 60);
    for sig in ["-INT", "-TERM"] {
        let out = d.join(format!("out{sig}"));
        let child = start_cache_upscale(&pc2, &rest, &out);
        let k = std::process::Command::new("kill").args([sig, &child.id().to_string()]).status().unwrap();
        assert!(k.success());
        let o = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(130), "{sig}: {err}");
        assert!(err.contains("interrupted"), "{sig}: {err}");
        assert!(temp_files(&out).is_empty(), "{sig} left {:?}", temp_files(&out));
        let summary = std::fs::read_to_string(out.join("upscale.json")).unwrap();
        assert!(summary.contains("\"complete\": false"), "{sig}: {summary}");
    }
}

#[test]
fn a_second_run_into_an_out_being_written_is_refused_and_the_first_finishes_untouched() {
    let d = scratch("upscale_concurrent");
    let (pc2, rest) = long_cache(&d.join("in"), 30);
    let out = d.join("out");
    let first = start_cache_upscale(&pc2, &rest, &out);
    // Wait until the first run holds its folder (its summary says it started).
    let t0 = std::time::Instant::now();
    while !out.join("upscale.json").exists() && t0.elapsed().as_secs() < 60 {
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    // The second run (the same shot, or another with the same output names) is refused while
    // the first writes: the folder would mix the two. It touches none of the first's files.
    let (pc2b, restb) = long_cache(&d.join("in2"), 2);
    let s = |p: &Path| p.to_str().unwrap().to_string();
    for (c, r) in [(&pc2, &rest), (&pc2b, &restb)] {
        let o = anisocb(&["upscale", &s(c), "--rest", &s(r), "--out", &s(&out)]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(err.contains("being written by another run") && err.contains("process"), "{err}");
    }
    let o = first.wait_with_output().unwrap();
    assert!(o.status.success(), "the first run failed: {}", String::from_utf8_lossy(&o.stderr));
    assert!(temp_files(&out).is_empty(), "{:?}", temp_files(&out));
}
