//! `anisocb dataset` on synthetic run pairs written in the simulator's on-disk format.

use anisocb::geom::geometry_image::sequence_to_images;
use anisocb::geom::{Domain, GridMesh};
use anisocb::io::{read_npz, write_npy};
use std::path::{Path, PathBuf};

/// A sheet bent about its middle column by `angle`, with wrinkles of amplitude `amp` (metres).
fn sheet(w: usize, h: usize, angle: f32, amp: f32) -> GridMesh {
    let mut m = GridMesh::flat(w, h, 1.0, 0.75);
    let (s, c) = angle.sin_cos();
    for p in m.pos.iter_mut() {
        let dx = p[0] - 0.5;
        p[2] = amp * (p[1] * 20.0).sin();
        if dx > 0.0 {
            p[0] = 0.5 + dx * c;
            p[2] += dx * s;
        }
    }
    m
}

fn write_pair(dir: &Path, scenario: &str, seed: u64, frames: usize) {
    write_moved_pair(dir, scenario, seed, frames, &|p| p);
}

/// [`write_pair`] with every vertex of frame f moved by `moved(p)`.
fn write_moved_pair(
    dir: &Path,
    scenario: &str,
    seed: u64,
    frames: usize,
    moved: &dyn Fn([f32; 3]) -> [f32; 3],
) {
    for (sub, w, h, amp) in [("lr", 16, 12, 0.0), ("hr", 32, 24, 0.01)] {
        let d = dir.join(sub);
        std::fs::create_dir_all(&d).unwrap();
        let seq: Vec<GridMesh> = (0..frames)
            .map(|f| {
                let m = sheet(w, h, 0.6 * f as f32, amp);
                GridMesh::new(w, h, m.pos.iter().map(|&p| moved(p)).collect())
            })
            .collect();
        let dom = Domain::enclosing(&seq, if sub == "lr" { 0.05 } else { 0.1 });
        write_npy(&d.join("geometry.npy"), &sequence_to_images(&seq, &dom)).unwrap();
        write_npy(&d.join("domain.npy"), &dom.to_tensor()).unwrap();
        std::fs::write(d.join("meta.json"), format!("{{\"scenario\": \"{scenario}\", \"seed\": {seed}}}"))
            .unwrap();
    }
}

fn scratch(name: &str) -> PathBuf {
    let d = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("anisocb-maps-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn run(args: &[&str]) -> i32 {
    anisocb::app::main_with_args(std::iter::once("anisocb").chain(args.iter().copied()))
}

#[test]
fn dataset_pairs_lr_with_hr_and_maps_in_the_documented_layout() {
    let root = scratch("layout");
    write_pair(&root.join("a"), "fold", 1, 3);
    write_pair(&root.join("b"), "fold", 2, 2);
    write_pair(&root.join("c"), "drape", 3, 2);
    let out = root.join("data.npz");
    let (a, b, c) = (root.join("a"), root.join("b/lr"), root.join("c"));
    let code = run(&[
        "dataset",
        "--runs",
        a.to_str().unwrap(),
        b.to_str().unwrap(),
        c.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--holdout",
        "drape",
        "--input-frame",
        "domain",
    ]);
    assert_eq!(code, 0);
    let z = read_npz(&out).unwrap();
    let n = 5;
    assert_eq!(z.require(&out, "lr").unwrap().shape, [n, 3, 12, 16]);
    assert_eq!(z.require(&out, "hr").unwrap().shape, [n, 3, 24, 32]);
    for name in ["boundary", "edges"] {
        let t = z.require(&out, name).unwrap();
        assert_eq!(t.shape, [n, 1, 24, 32]);
        assert!(t.data.iter().all(|&v| v == 0.0 || v == 1.0), "{name} not binary");
    }
    assert_eq!(z.require(&out, "domain").unwrap().shape, [n, 2, 3]);
    // Frame 0 of run a is flat: its boundary map is its border.
    let bnd = z.require(&out, "boundary").unwrap();
    for j in 0..24 {
        for i in 0..32 {
            let border = i == 0 || j == 0 || i == 31 || j == 23;
            assert_eq!(bnd.data[bnd.idx4(0, 0, j, i)] == 1.0, border, "({i},{j})");
        }
    }
    // Frame 2 of run a has a sharp bend at the middle: marked beyond the border.
    let inner: f32 =
        (1..23).flat_map(|j| (1..31).map(move |i| (i, j))).map(|(i, j)| bnd.data[bnd.idx4(2, 0, j, i)]).sum();
    assert!(inner > 0.0, "the bend was not marked");
    // The LR image was re-encoded into the HR domain: its corners match the HR corners in x, y
    // (z differs by the HR wrinkles).
    let (lr, hr) = (z.require(&out, "lr").unwrap(), z.require(&out, "hr").unwrap());
    for c in 0..2 {
        assert!((lr.data[lr.idx4(1, c, 0, 0)] - hr.data[hr.idx4(1, c, 0, 0)]).abs() < 1e-5);
    }
    let frames = String::from_utf8(z.file("frames.json").unwrap().to_vec()).unwrap();
    assert_eq!(frames.matches("\"frame\"").count(), n);
    assert!(frames.contains("\"seed\": 2") && !frames.contains("drape"), "{frames}");
    // Runs are recorded by name, never by the machine path they were read from.
    assert!(frames.contains("\"run\": \"a\"") && !frames.contains(root.to_str().unwrap()), "{frames}");
    let params = String::from_utf8(z.file("params.json").unwrap().to_vec()).unwrap();
    assert!(params.contains("\"gamma\": 0.05") && params.contains("\"holdout\": [\"drape\"]"), "{params}");
    assert!(root.join("data.png").is_file());
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn dataset_output_is_bitwise_deterministic() {
    let root = scratch("determinism");
    write_pair(&root.join("a"), "fold", 1, 3);
    let a = root.join("a");
    let outs: Vec<Vec<u8>> = (0..2)
        .map(|k| {
            let out = root.join(format!("d{k}.npz"));
            assert_eq!(run(&["dataset", "--runs", a.to_str().unwrap(), "--out", out.to_str().unwrap()]), 0);
            std::fs::read(out).unwrap()
        })
        .collect();
    assert_eq!(outs[0], outs[1]);
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn dataset_names_the_directory_that_is_not_a_run() {
    let root = scratch("bad");
    let out = root.join("d.npz");
    assert_eq!(run(&["dataset", "--runs", root.to_str().unwrap(), "--out", out.to_str().unwrap()]), 1);
    let r = anisocb::cloth::run_io::read_pair(&root);
    assert!(r.is_err_and(|e| e.to_string().contains(root.to_str().unwrap())));
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn cloth_frame_dataset_does_not_depend_on_where_the_run_is() {
    let root = scratch("cloth-frame");
    write_pair(&root.join("a"), "fold", 1, 3);
    // The same run turned 90° about y, moved 5 m and scaled ×2.
    write_moved_pair(&root.join("b"), "fold", 1, 3, &|p| [2.0 * p[2] + 5.0, 2.0 * p[1] - 3.0, -2.0 * p[0]]);
    let read = |name: &str| {
        let out = root.join(format!("{name}.npz"));
        let dir = root.join(name);
        assert_eq!(run(&["dataset", "--runs", dir.to_str().unwrap(), "--out", out.to_str().unwrap()]), 0);
        read_npz(&out).unwrap()
    };
    let (a, b) = (read("a"), read("b"));
    for name in ["lr", "hr", "boundary", "edges"] {
        let (x, y) = (a.require(Path::new("a"), name).unwrap(), b.require(Path::new("b"), name).unwrap());
        let d = x.max_abs_diff(y);
        assert!(d < 1e-4, "{name}: moved run differs by {d}");
    }
    let _ = std::fs::remove_dir_all(&root);
}
