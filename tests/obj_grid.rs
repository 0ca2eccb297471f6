//! OBJ grid recovery: any vertex order, quads or triangulated quads; clear errors otherwise.

use anisocb::geom::obj::{natural_cmp, obj_text, parse_obj, read_obj_grid, read_obj_grid_styled, FaceStyle};
use anisocb::geom::GridMesh;
use anisocb::rng::Rng;
use std::path::{Path, PathBuf};

fn tmp(name: &str) -> PathBuf {
    let d = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("anisocb-obj-test-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d.join(name)
}

/// A bumpy grid with distinct positions.
fn grid(w: usize, h: usize) -> GridMesh {
    let mut m = GridMesh::flat(w, h, 1.0 + 0.1 * w as f32, 0.8);
    for (k, p) in m.pos.iter_mut().enumerate() {
        p[2] = 0.05 * (k as f32 * 0.7).sin();
    }
    m
}

/// The 8 symmetries of a grid (flips and, for any shape, the transpose).
fn symmetries(m: &GridMesh) -> Vec<GridMesh> {
    let mut out = Vec::new();
    for t in [false, true] {
        for fx in [false, true] {
            for fy in [false, true] {
                let (w, h) = if t { (m.h, m.w) } else { (m.w, m.h) };
                let mut pos = Vec::with_capacity(w * h);
                for j in 0..h {
                    for i in 0..w {
                        let (i2, j2) = (if fx { w - 1 - i } else { i }, if fy { h - 1 - j } else { j });
                        let (si, sj) = if t { (j2, i2) } else { (i2, j2) };
                        pos.push(m.pos[m.idx(si, sj)]);
                    }
                }
                out.push(GridMesh::new(w, h, pos));
            }
        }
    }
    out
}

/// Write `m` with its vertices renumbered by a random permutation, faces in random order and
/// random rotation of each face's vertex cycle.
fn shuffled_obj(m: &GridMesh, quads: bool, rng: &mut Rng) -> String {
    let n = m.pos.len();
    let mut perm: Vec<usize> = (0..n).collect();
    for k in (1..n).rev() {
        perm.swap(k, rng.below(k + 1));
    }
    let mut inv = vec![0; n];
    for (new, &old) in perm.iter().enumerate() {
        inv[old] = new;
    }
    let mut s = String::new();
    for &old in &perm {
        let p = m.pos[old];
        s += &format!("v {} {} {}\n", p[0], p[1], p[2]);
    }
    let mut faces: Vec<Vec<usize>> = if quads {
        m.quads().iter().map(|q| q.to_vec()).collect()
    } else {
        m.triangles().iter().map(|t| t.to_vec()).collect()
    };
    for k in (1..faces.len()).rev() {
        faces.swap(k, rng.below(k + 1));
    }
    for f in &faces {
        let r = rng.below(f.len());
        let idx: Vec<String> = (0..f.len()).map(|k| format!("{}", inv[f[(k + r) % f.len()]] + 1)).collect();
        s += &format!("f {}\n", idx.join(" "));
    }
    s
}

#[test]
fn written_grids_read_back_identically() {
    for (w, h) in [(2, 2), (5, 3), (3, 7), (16, 16)] {
        let m = grid(w, h);
        for quads in [true, false] {
            let p = tmp(&format!("g{w}x{h}{quads}.obj"));
            anisocb::geom::obj::write_obj_grid(&p, &m, quads).unwrap();
            let g = read_obj_grid_styled(&p).unwrap();
            assert_eq!(g.mesh, m, "{w}x{h} quads={quads}");
            assert_eq!(g.style, if quads { FaceStyle::Quads } else { FaceStyle::Triangles });
        }
    }
}

#[test]
fn grid_is_recovered_from_shuffled_vertex_orders() {
    let mut rng = Rng::new(42);
    for (w, h) in [(2, 2), (2, 5), (6, 4), (9, 9), (13, 7)] {
        let m = grid(w, h);
        let syms = symmetries(&m);
        for quads in [true, false] {
            for trial in 0..4 {
                let p = tmp(&format!("s{w}x{h}{quads}{trial}.obj"));
                std::fs::write(&p, shuffled_obj(&m, quads, &mut rng)).unwrap();
                let g = read_obj_grid(&p).unwrap_or_else(|e| panic!("{w}x{h} quads={quads}: {e}"));
                assert!(
                    syms.contains(&g),
                    "{w}x{h} quads={quads}: recovered grid is not the original up to symmetry"
                );
                // Deterministic: reading again gives the same orientation.
                assert_eq!(read_obj_grid(&p).unwrap(), g);
            }
        }
    }
}

#[test]
fn triangulated_grid_with_mixed_diagonals_is_recovered() {
    // Blender's "Beauty" triangulation may split neighbouring cells along different diagonals.
    let m = grid(7, 5);
    let mut s = String::new();
    for p in &m.pos {
        s += &format!("v {} {} {}\n", p[0], p[1], p[2]);
    }
    for (k, q) in m.quads().iter().enumerate() {
        let [a, b, c, d] = q.map(|v| v + 1);
        if k % 3 == 0 {
            s += &format!("f {a} {b} {c}\nf {a} {c} {d}\n");
        } else {
            s += &format!("f {a} {b} {d}\nf {b} {c} {d}\n");
        }
    }
    let p = tmp("mixed.obj");
    std::fs::write(&p, s).unwrap();
    assert_eq!(read_obj_grid(&p).unwrap(), m);
}

fn err_of(text: &str, name: &str) -> String {
    let p = tmp(name);
    std::fs::write(&p, text).unwrap();
    let e = read_obj_grid(&p).expect_err("should be rejected").to_string();
    assert!(e.contains(name), "error does not name the file: {e}");
    e
}

#[test]
fn non_grid_meshes_are_rejected_with_clear_errors() {
    let e = err_of("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "missing.obj");
    assert!(e.contains("references vertex 4"), "{e}");
    let e = err_of("v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "nan.obj");
    assert!(e.contains("non-finite"), "{e}");
    let e = err_of("v 0 0 0\nv 1 0 0\nv 0 1 0\n", "nofaces.obj");
    assert!(e.contains("no faces"), "{e}");
    // An L-shaped quad mesh (3 cells) is not a rectangle.
    let l = "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\nv 1 1 0\nv 2 1 0\nv 0 2 0\nv 1 2 0\n\
             f 1 2 5 4\nf 2 3 6 5\nf 4 5 8 7\n";
    let e = err_of(l, "lshape.obj");
    assert!(e.contains("not a regular grid"), "{e}");
    // A pentagon.
    let e = err_of("v 0 0 0\nv 1 0 0\nv 2 1 0\nv 1 2 0\nv 0 1 0\nf 1 2 3 4 5\n", "pent.obj");
    assert!(e.contains("5 vertices"), "{e}");
    // A grid plus an unused vertex.
    let mut t = obj_text(&grid(3, 3), true);
    t += "v 9 9 9\n";
    let e = err_of(&t, "extra.obj");
    assert!(e.contains("not used"), "{e}");
    // A single triangle cannot be a grid.
    let e = err_of("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "tri.obj");
    assert!(e.contains("not a regular grid"), "{e}");
}

#[test]
fn obj_parser_accepts_slashes_and_negative_indices() {
    let t = "# comment\no plane\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nvt 0 0\nf -4/1/1 -3/1/1 -2/1/1 -1/1/1\n";
    let m = parse_obj(t, Path::new("x.obj")).unwrap();
    assert_eq!(m.faces, vec![vec![0, 1, 2, 3]]);
}

#[test]
fn negative_indices_count_back_from_the_vertices_read_so_far() {
    // Two quads, each written right after its own vertices with relative indices (how some
    // exporters write one object after another): -4 means the fourth vertex above the face
    // line, not the fourth from the end of the file.
    let v = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n";
    let t = format!("{v}vt 0 0\nf -4/-1 -3/-1 -2/-1 -1/-1\n{v}vt 1 1\nf -4/-1 -3/-1 -2/-1 -1/-1\n");
    let m = parse_obj(&t, Path::new("x.obj")).unwrap();
    assert_eq!(m.faces, vec![vec![0, 1, 2, 3], vec![4, 5, 6, 7]]);
    assert_eq!(m.face_uv, vec![vec![0; 4], vec![1; 4]]);
    let e = parse_obj("v 0 0 0\nf -2 -1 -1\n", Path::new("y.obj")).unwrap_err().to_string();
    assert!(e.contains("line 2") && e.contains("vertex -2"), "{e}");
}

#[test]
fn frame_files_sort_naturally() {
    let mut v = vec!["frame_10.obj", "frame_2.obj", "frame_1.obj", "frame_0002.obj", "a.obj"];
    v.sort_by(|a, b| natural_cmp(a, b));
    assert_eq!(v, vec!["a.obj", "frame_1.obj", "frame_0002.obj", "frame_2.obj", "frame_10.obj"]);
}
