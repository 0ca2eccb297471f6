//! A catalogue of hostile and odd OBJ files and OBJ sequences, each with the error it must
//! produce or the reading it must get: malformed numbers and indices, meshes that are not a
//! regular grid, byte-order marks and line endings, sequences whose grids differ, frames whose
//! vertices are numbered differently from the first frame's, and gaps in the frame numbers.
//! Every error names the file and the problem; nothing allocates far beyond the size of the
//! file it reads (checked with a counting allocator). Folders that are not one shot are in
//! tests/hostile_obj_folders.rs.

#[path = "common/hostile.rs"]
mod hostile;
#[path = "common/tempdir.rs"]
mod tempdir;
use hostile::{anisocb, expect_err, grid_obj, scratch, upscale_refused, write};
use std::path::Path;

#[path = "common/alloc.rs"]
mod alloc;
use alloc::largest_alloc;

// ---------------------------------------------------------------------------------------------
// OBJ grids (geom::obj)

#[test]
fn obj_catalogue_each_bad_file_gives_its_error() {
    use anisocb::geom::obj::read_obj_grid;
    let d = scratch("obj");
    let good = grid_obj(3, 3);
    let lines: Vec<&str> = good.lines().collect();
    let without_vertex_5: String =
        lines.iter().enumerate().filter(|(k, _)| *k != 4).map(|(_, l)| format!("{l}\n")).collect();
    let cases: Vec<(&str, Vec<u8>, &[&str])> = vec![
        ("empty.obj", vec![], &["no faces"]),
        ("only_comments.obj", b"# nothing here\n\n".to_vec(), &["no faces"]),
        ("binary.obj", vec![0xFF, 0xFE, 0x00, 0x80, 0x81], &["UTF-8"]),
        (
            "nan.obj",
            good.replacen("v 0.1 0 0", "v nan 0 0", 1).into_bytes(),
            &["line 2", "non-finite coordinate 'nan'"],
        ),
        ("inf.obj", good.replacen("v 0.1 0 0", "v 0.1 inf 0", 1).into_bytes(), &["line 2", "non-finite"]),
        ("overflow.obj", good.replacen("v 0.1 0 0", "v 1e39 0 0", 1).into_bytes(), &["line 2", "non-finite"]),
        (
            "bad_number.obj",
            good.replacen("v 0.1 0 0", "v 0.1 zero 0", 1).into_bytes(),
            &["line 2", "bad coordinate 'zero'"],
        ),
        (
            "two_coords.obj",
            good.replacen("v 0.1 0 0", "v 0.1 0", 1).into_bytes(),
            &["line 2", "3 coordinates"],
        ),
        ("absent_vertex.obj", format!("{good}f 1 2 99 4\n").into_bytes(), &["vertex 99", "9 vertices"]),
        ("index_zero.obj", good.replacen("f 1 2", "f 0 2", 1).into_bytes(), &["vertex 0"]),
        ("missing_vertex.obj", without_vertex_5.into_bytes(), &["vertex 9", "8 vertices"]),
        ("bad_index.obj", good.replacen("f 1 2", "f one 2", 1).into_bytes(), &["bad face index 'one'"]),
        (
            "relative_too_far.obj",
            good.replacen("f 1 2", "f -99 2", 1).into_bytes(),
            &["vertex -99", "9 vertices"],
        ),
        (
            "nan_uv.obj",
            format!("vt 0.5 nan\n{good}").into_bytes(),
            &["line 1", "bad texture coordinate 'nan'"],
        ),
        ("one_uv_coord.obj", format!("vt 0.5\n{good}").into_bytes(), &["line 1", "needs u and v"]),
        (
            "absent_uv.obj",
            format!("vt 0 0\n{}", good.replacen("f 1 2", "f 1/7 2", 1)).into_bytes(),
            &["texture coordinate 7", "1 texture coordinates"],
        ),
        ("bad_uv_index.obj", good.replacen("f 1 2", "f 1/x 2", 1).into_bytes(), &["bad face index '1/x'"]),
        (
            "duplicate_vertex.obj",
            format!("v 0 0 0\n{good}").replace("f ", "f_").replace("f_", "f ").into_bytes(),
            &["not a regular grid"],
        ),
        (
            "unused_vertex.obj",
            format!("{good}v 5 5 5\n").into_bytes(),
            &["not a regular grid", "vertex 10 is not used"],
        ),
        ("pentagon.obj", format!("{good}f 1 2 3 6 5\n").into_bytes(), &["not a regular grid", "5 vertices"]),
        ("mixed.obj", format!("{good}f 1 2 5\n").into_bytes(), &["not a regular grid", "mixes"]),
        (
            "odd_triangles.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n".into(),
            &["not a regular grid", "cannot pair"],
        ),
        (
            "cube.obj",
            "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n\
             f 1 2 3 4\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n"
                .into(),
            &["not a regular grid", "corner"],
        ),
        (
            // an L shape: a 3×3 grid of cells missing one corner cell
            "l_shape.obj",
            {
                let g = grid_obj(4, 4);
                g.lines()
                    .filter(|l| *l != "f 11 12 16 15")
                    .map(|l| format!("{l}\n"))
                    .collect::<String>()
                    .into_bytes()
            },
            &["not a regular grid"],
        ),
        (
            "shared_edge.obj",
            format!("{good}v 0 0 1\nv 0.1 0 1\nf 1 2 11 10\n").into_bytes(),
            &["not a regular grid"],
        ),
        (
            "repeated_vertex.obj",
            good.replacen("f 1 2 5 4", "f 1 2 2 4", 1).into_bytes(),
            &["not a regular grid"],
        ),
    ];
    for (name, bytes, want) in cases {
        let p = write(&d, name, &bytes);
        let (r, big) = largest_alloc(|| read_obj_grid(&p));
        expect_err(r, &p, want);
        assert!(big <= 64 * 1024 + 64 * bytes.len(), "{name}: allocated {big} bytes");
    }
    let p = write(&d, "ok.obj", good.as_bytes());
    let m = read_obj_grid(&p).unwrap();
    assert_eq!((m.w, m.h), (3, 3));
    // What some exporters write, read as the plain file: a byte-order mark, CR LF, CR alone.
    let bom = [&b"\xEF\xBB\xBF"[..], good.as_bytes()].concat();
    for (name, bytes) in [
        ("bom.obj", bom),
        ("crlf.obj", good.replace('\n', "\r\n").into_bytes()),
        ("cr.obj", good.replace('\n', "\r").into_bytes()),
    ] {
        assert_eq!(read_obj_grid(&write(&d, name, &bytes)).unwrap(), m, "{name}");
    }
    // A Latin-1 byte in a comment: named with its line.
    let latin1 = [b"v 0 0 0\nv 1 0 0\n# caf".as_slice(), &[0xE9], b"\n", good.as_bytes()].concat();
    let p = write(&d, "latin1.obj", &latin1);
    expect_err(read_obj_grid(&p), &p, &["line 3", "0xE9", "not UTF-8"]);
}

#[test]
fn obj_sequences_with_differing_grids_or_no_files_are_refused() {
    use anisocb::geom::obj::{list_obj_files, read_obj_sequence};
    let d = scratch("obj_seq");
    let a = write(&d, "frame_1.obj", grid_obj(3, 3).as_bytes());
    let b = write(&d, "frame_2.obj", grid_obj(4, 3).as_bytes());
    expect_err(read_obj_sequence(&[a.clone(), b.clone()]).map(|_| ()), &b, &["4x3", "first frame is 3x3"]);
    let c = write(&d, "frame_3.obj", grid_obj(3, 3).replacen("v 0.1 0 0", "v nan 0 0", 1).as_bytes());
    expect_err(read_obj_sequence(&[a.clone(), c.clone()]).map(|_| ()), &c, &["non-finite"]);
    let empty = d.join("empty_dir");
    std::fs::create_dir_all(&empty).unwrap();
    expect_err(list_obj_files(&empty), &empty, &["no .obj files"]);
    let missing = d.join("nope.obj");
    expect_err(read_obj_sequence(&[a, missing.clone()]).map(|_| ()), &missing, &["No such file"]);
}

// ---------------------------------------------------------------------------------------------
// `anisocb upscale` on OBJ sequences: vertex order and frame numbers.

/// OBJ text of the `w × h` grid `pos` (row-major) numbered by `s`: file vertex n is vertex n
/// of the renumbered grid. `faces`: "remap" keeps the grid's own faces, renamed (so the face
/// list differs from an unnumbered file's), "template" writes the renumbered grid's faces
/// from the usual template (identical to an unnumbered file's unless `s` transposes).
fn renumbered_obj(
    w: usize,
    h: usize,
    pos: &[[f32; 3]],
    s: anisocb::geom::mesh::GridSymmetry,
    faces: &str,
) -> String {
    let src = s.source_index(w, h);
    let mut text = String::new();
    for &k in &src {
        text += &format!("v {} {} {}\n", pos[k][0], pos[k][1], pos[k][2]);
    }
    let mut file_of = vec![0; w * h];
    for (n, &k) in src.iter().enumerate() {
        file_of[k] = n + 1;
    }
    let (tw, th) = if faces == "template" { s.dims(w, h) } else { (w, h) };
    for j in 0..th - 1 {
        for i in 0..tw - 1 {
            let q = [j * tw + i, j * tw + i + 1, (j + 1) * tw + i + 1, (j + 1) * tw + i];
            let f = q.map(|v| if faces == "template" { v + 1 } else { file_of[v] });
            text += &format!("f {} {} {} {}\n", f[0], f[1], f[2], f[3]);
        }
    }
    text
}

/// Frame `t` of a 7 × 5 sheet sliding and rippling.
fn moving_sheet(t: usize) -> Vec<[f32; 3]> {
    let mut p = Vec::new();
    for j in 0..5 {
        for i in 0..7 {
            let (x, y) = (i as f32 * 0.1, j as f32 * 0.1);
            p.push([
                x + 0.005 * t as f32,
                y,
                ((i as f32 + 1.7 * j as f32) * 0.3 + 0.2 * t as f32).sin() * 0.05,
            ]);
        }
    }
    p
}

#[test]
fn upscale_puts_renumbered_frames_back_in_the_first_frames_vertex_order() {
    use anisocb::geom::mesh::GridSymmetry;
    let all = GridSymmetry::all();
    // The 8 renumberings of a 7 × 5 grid are 8 different permutations.
    let maps: Vec<Vec<usize>> = all.iter().map(|s| s.source_index(7, 5)).collect();
    for (a, m) in maps.iter().enumerate() {
        let mut sorted = m.clone();
        sorted.sort();
        assert_eq!(sorted, (0..35).collect::<Vec<_>>(), "{:?} is not a permutation", all[a]);
        assert!(maps[..a].iter().all(|o| o != m), "{:?} repeats another symmetry", all[a]);
    }
    let [id, mi, mj, both, tr, ..] = all;
    assert_eq!(
        (mi.mirror_i, mj.mirror_j, both.mirror_i && both.mirror_j, tr.transpose),
        (true, true, true, true)
    );
    let d = scratch("upscale_renumbered");
    let (plain, renum) = (d.join("plain"), d.join("renumbered"));
    for dir in [&plain, &renum, &d.join("folded")] {
        std::fs::create_dir_all(dir).unwrap();
    }
    // Frame 1: rows reversed, faces renamed; 2: transposed (a 5 × 7 grid in the file);
    // 3 and 4: turned 180° with the unnumbered file's very faces (only the positions say so);
    // 5: the first frame's order again, also with the same faces.
    let numbering = [
        (id, "template"),
        (mj, "remap"),
        (tr, "template"),
        (both, "template"),
        (both, "template"),
        (id, "template"),
    ];
    for (t, (s, faces)) in numbering.into_iter().enumerate() {
        let p = moving_sheet(t);
        write(&plain, &format!("frame_{t}.obj"), renumbered_obj(7, 5, &p, id, "template").as_bytes());
        write(&renum, &format!("frame_{t}.obj"), renumbered_obj(7, 5, &p, s, faces).as_bytes());
    }
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let run = |input: &Path, out: &Path, extra: &[&str]| {
        let mut args = vec!["upscale".to_string(), s(input), "--out".into(), s(out)];
        args.extend(extra.iter().map(|a| a.to_string()));
        let o = anisocb(&args.iter().map(String::as_str).collect::<Vec<_>>());
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stderr).into_owned()
    };
    run(&plain, &d.join("out_plain"), &[]);
    let err = run(&renum, &d.join("out_renum"), &[]);
    // Every frame comes out exactly as if it had been exported in the first frame's order.
    for t in 0..6 {
        let f = format!("frame_{t}.obj");
        let (a, b) = (
            std::fs::read(d.join("out_plain").join(&f)).unwrap(),
            std::fs::read(d.join("out_renum").join(&f)).unwrap(),
        );
        assert!(a == b, "{f}: output differs from the unnumbered shot's");
    }
    // The user is told which frames were renumbered, and only those.
    for (t, said) in [(1, true), (2, true), (3, true), (4, false), (5, true)] {
        let f = s(&renum.join(format!("frame_{t}.obj")));
        assert_eq!(
            err.contains(&format!("note: {f}: vertices numbered differently")),
            said,
            "frame {t}: {err}"
        );
    }
    // A farm slice starting inside the renumbered frames gives the full run's bytes.
    run(&renum, &d.join("out_slice"), &["--frames", "4:6"]);
    for t in 4..6 {
        let f = format!("frame_{t}.obj");
        assert!(
            std::fs::read(d.join("out_slice").join(&f)).unwrap()
                == std::fs::read(d.join("out_plain").join(&f)).unwrap(),
            "{f}"
        );
    }
    // A renumbered frame folded exactly onto itself fits two orientations equally: refused,
    // naming the frame, with nothing claimed finished.
    let folded = d.join("folded");
    let p0 = moving_sheet(0);
    let p1: Vec<[f32; 3]> = (0..35)
        .map(|k| {
            let (i, j) = (k % 7, k / 7);
            let (a, b) = (p0[k], p0[j * 7 + 6 - i]);
            [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0, (a[2] + b[2]) / 2.0]
        })
        .collect();
    write(&folded, "frame_0.obj", renumbered_obj(7, 5, &p0, id, "template").as_bytes());
    let bad = write(&folded, "frame_1.obj", renumbered_obj(7, 5, &p1, mj, "remap").as_bytes());
    let out = d.join("out_folded");
    upscale_refused(
        &[&s(&folded), "--out", &s(&out)],
        1,
        &[&s(&bad), "two orientations", "same vertex order"],
    );
    let summary = std::fs::read_to_string(out.join("upscale.json")).unwrap_or_default();
    assert!(!summary.contains("\"complete\": true"), "{summary}");
}

#[test]
fn upscale_warns_of_gaps_in_the_frame_numbers() {
    let d = scratch("upscale_gaps");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let run = |dir: &Path| {
        let o = anisocb(&["upscale", &s(dir), "--out", &s(&dir.with_extension("out"))]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stderr).into_owned()
    };
    let gap = d.join("gap");
    let every_other = d.join("every_other");
    for (dir, frames) in [(&gap, [0, 1, 2, 5]), (&every_other, [0, 2, 4, 6])] {
        std::fs::create_dir_all(dir).unwrap();
        for k in frames {
            write(dir, &format!("cloth_{k:04}.obj"), grid_obj(4, 4).as_bytes());
        }
    }
    let err = run(&gap);
    let want = format!(
        "warning: 2 frame number(s) missing between {} and {}",
        s(&gap.join("cloth_0002.obj")),
        s(&gap.join("cloth_0005.obj"))
    );
    assert!(err.contains(&want), "{err}");
    // A shot exported every other frame has no gap.
    assert!(!run(&every_other).contains("missing"));
}

/// `renumbered_obj` with one UV per vertex (the unnumbered grid's `u = i/(w−1)`,
/// `v = j/(h−1)`, carried along with its vertex when `s` renumbers it).
fn renumbered_obj_with_uv(
    w: usize,
    h: usize,
    pos: &[[f32; 3]],
    s: anisocb::geom::mesh::GridSymmetry,
) -> String {
    let src = s.source_index(w, h);
    let plain = renumbered_obj(w, h, pos, s, "template");
    let mut text = String::new();
    for &k in &src {
        let (i, j) = (k % w, k / w);
        text += &format!("vt {} {}\n", i as f32 / (w - 1) as f32, j as f32 / (h - 1) as f32);
    }
    for line in plain.lines() {
        match line.strip_prefix("f ") {
            Some(f) => {
                let c: Vec<String> = f.split_whitespace().map(|v| format!("{v}/{v}")).collect();
                text += &format!("f {}\n", c.join(" "));
            }
            None => text += &format!("{line}\n"),
        }
    }
    text
}

#[test]
fn a_sheet_that_really_turns_180_degrees_with_the_same_uvs_is_not_renumbered() {
    use anisocb::geom::mesh::GridSymmetry;
    let [id, _, _, both, ..] = GridSymmetry::all();
    let d = scratch("really_turns");
    let (turned, renum) = (d.join("turned"), d.join("renumbered"));
    for dir in [&turned, &renum] {
        std::fs::create_dir_all(dir).unwrap();
    }
    let p0 = moving_sheet(0);
    // Frame 1: the sheet turned 180° about the z axis through its middle, vertex by vertex.
    let p1: Vec<[f32; 3]> = p0.iter().map(|p| [0.6 - p[0], 0.4 - p[1], p[2]]).collect();
    write(&turned, "frame_0.obj", renumbered_obj_with_uv(7, 5, &p0, id).as_bytes());
    write(&turned, "frame_1.obj", renumbered_obj_with_uv(7, 5, &p1, id).as_bytes());
    // The same positions exported renumbered: its UVs moved with the vertices.
    write(&renum, "frame_0.obj", renumbered_obj_with_uv(7, 5, &p0, id).as_bytes());
    write(&renum, "frame_1.obj", renumbered_obj_with_uv(7, 5, &p0, both).as_bytes());
    let s = |p: &Path| p.to_str().unwrap().to_string();
    for (input, renumbered) in [(&turned, false), (&renum, true)] {
        let out = d.join(format!("out_{renumbered}"));
        let o = anisocb(&["upscale", &s(input), "--out", &s(&out)]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(err.contains("vertices numbered differently"), renumbered, "{err}");
        // Where HR vertex 0 (the corner at LR vertex 0) ends up says which way it was read.
        let hr = anisocb::geom::obj::read_obj_grid(&out.join("frame_1.obj")).unwrap();
        let lr0 = if renumbered { p0[0] } else { p1[0] };
        let d0 = (0..3).map(|k| (hr.pos[0][k] - lr0[k]).powi(2)).sum::<f32>().sqrt();
        assert!(d0 < 0.05, "renumbered {renumbered}: HR vertex 0 is {d0} m from LR vertex 0");
    }
}
