//! Any cloth, not only a rectangular sheet (issue 45): a skirt, a round tablecloth, a T-shaped
//! sheet, a sheet with a hole, an unwelded sheet and a textured mixed mesh upscale to their own
//! subdivision plus the nets' detail, keep their UVs, materials and groups, stay closed where
//! they were welded, move with the cloth, and what is not a cloth surface is refused by name.

#[path = "common/meshes.rs"]
mod meshes;
#[path = "common/tempdir.rs"]
mod tempdir;

use anisocb::cloth::follow::{FollowOutput, FollowParams, Follower, PinnedEdges};
use anisocb::eval::mesh::mesh_detail;
use anisocb::geom::obj::parse_obj;
use anisocb::geom::surface::Subdivision;
use anisocb::io::point_cache::{write_frame, write_header, CacheFormat, CacheHeader};
use anisocb::nn::weights::embedded_model;
use anisocb::ops::Cpu;
use anisocb::pipeline::{upscale_files, OutputFormat, Quiet, Summary, UpscaleJob};
use meshes::Mesh;
use std::path::Path;
use tempdir::TempDir;

/// Write `frames` as `dir/in/f_000k.obj`.
fn write_frames(dir: &Path, frames: &[Mesh]) -> std::path::PathBuf {
    let d = dir.join("in");
    std::fs::create_dir_all(&d).unwrap();
    for (k, m) in frames.iter().enumerate() {
        std::fs::write(d.join(format!("f_{k:04}.obj")), m.obj()).unwrap();
    }
    d
}

fn run(job: UpscaleJob) -> anisocb::Result<Summary> {
    upscale_files(&Cpu, &embedded_model().unwrap(), &job.check()?, &mut Quiet)
}

fn read(path: &Path) -> anisocb::geom::obj::ObjMesh {
    parse_obj(&std::fs::read_to_string(path).unwrap(), path).unwrap()
}

fn extent(pos: &[[f32; 3]]) -> f32 {
    (0..3)
        .map(|k| {
            let (lo, hi) = pos.iter().fold((f32::MAX, f32::MIN), |(l, h), p| (l.min(p[k]), h.max(p[k])));
            hi - lo
        })
        .fold(0.0, f32::max)
}

#[test]
fn every_cloth_shape_upscales_to_its_subdivision_plus_the_nets_detail() {
    let shapes = [
        ("skirt", meshes::skirt(24, 8)),
        ("tablecloth", meshes::tablecloth(24, 6, 0.5)),
        ("t_shape", meshes::t_shape(13, 13, 4)),
        ("holed", meshes::holed_sheet(13)),
        ("unwelded", meshes::unwelded_sheet(8)),
        ("mixed", meshes::mixed_textured(9)),
    ];
    for (name, m) in shapes {
        let dir = TempDir::new(&format!("any-mesh-{name}"));
        let frames = [m.clone(), m.rippled(0.01, 0.5), m.moved(0.3, [0.1, 0.0, -0.2])];
        let input = write_frames(&dir, &frames);
        let out = dir.join("out");
        let done = run(UpscaleJob::new(vec![input], &out)).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(done.frames, 3, "{name}");
        let sub = Subdivision::of(m.pos.len(), &m.faces);
        for (k, lr) in frames.iter().enumerate() {
            let hr = read(&out.join(format!("f_{k:04}.obj")));
            assert_eq!(hr.pos.len(), sub.hr_vertices(), "{name} frame {k}");
            assert_eq!(hr.faces, sub.faces, "{name} frame {k}: the subdivided faces, in order");
            let base = sub.apply(&lr.pos);
            let d: Vec<f32> = hr
                .pos
                .iter()
                .zip(&base)
                .map(|(a, b)| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt())
                .collect();
            let rms = (d.iter().map(|x| x * x).sum::<f32>() / d.len() as f32).sqrt();
            let max = d.iter().copied().fold(0.0, f32::max);
            let ext = extent(&lr.pos);
            eprintln!(
                "{name} frame {k}: detail RMS {:.2} mm, max {:.2} mm on a {ext:.2} m cloth",
                1e3 * rms,
                1e3 * max
            );
            // The nets add folds of a few percent of the cloth at most (the same bound
            // `check_detail_size` puts on a sheet is 50 %; a broken atlas gives metres).
            assert!(
                rms.is_finite() && rms < 0.02 * ext && max < 0.1 * ext,
                "{name} frame {k}: rms {rms}, max {max}"
            );
            assert!(rms > 1e-6, "{name} frame {k}: no detail at all: the nets' output was not read");
        }
    }
}

#[test]
fn a_mesh_keeps_its_uvs_materials_groups_and_normals() {
    let dir = TempDir::new("any-mesh-attrs");
    let m = meshes::mixed_textured(7);
    let input = write_frames(&dir, std::slice::from_ref(&m));
    let out = dir.join("out");
    run(UpscaleJob::new(vec![input], &out)).unwrap();
    let text = std::fs::read_to_string(out.join("f_0000.obj")).unwrap();
    let hr = read(&out.join("f_0000.obj"));
    let (uv, fuv) = m.uv.clone().unwrap();
    let s = Subdivision::of(uv.len(), &fuv);
    assert_eq!(hr.uv, s.apply(&uv), "UVs subdivided with their own faces");
    assert_eq!(hr.face_uv, s.faces);
    let tags: Vec<(usize, String)> = m.tags.iter().map(|(k, l)| (4 * k, l.clone())).collect();
    assert_eq!(hr.tags, tags, "each tag before the first of its face's four HR faces");
    assert!(text.lines().filter(|l| l.starts_with("vn ")).count() == hr.pos.len());
    assert!(text.contains("usemtl lining") && text.contains("g back"));
}

#[test]
fn an_unwelded_sheet_stays_closed_where_its_vertices_met() {
    let dir = TempDir::new("any-mesh-unwelded");
    let m = meshes::unwelded_sheet(8).rippled(0.02, 0.0);
    let input = write_frames(&dir, std::slice::from_ref(&m));
    let out = dir.join("out");
    run(UpscaleJob::new(vec![input], &out)).unwrap();
    let hr = read(&out.join("f_0000.obj"));
    let sub = Subdivision::of(m.pos.len(), &m.faces);
    let base = sub.apply(&m.pos);
    // HR vertices whose subdivision puts them at one place (corners and shared edges'
    // midpoints of neighbouring quads) come out at one place.
    let mut pairs = 0;
    for a in 0..base.len() {
        for b in a + 1..base.len() {
            if base[a] == base[b] {
                pairs += 1;
                assert_eq!(hr.pos[a], hr.pos[b], "HR vertices {a} and {b} were one point and came apart");
            }
        }
    }
    assert!(pairs > 100, "{pairs}");
}

#[test]
fn a_moved_and_turned_mesh_gives_the_same_result_moved_and_turned() {
    let dir = TempDir::new("any-mesh-moved");
    let m = meshes::skirt(20, 6);
    let (angle, t) = (0.7f32, [0.3f32, -0.1, 0.25]);
    let input = write_frames(&dir, &[m.clone(), m.moved(angle, t)]);
    let out = dir.join("out");
    run(UpscaleJob::new(vec![input], &out)).unwrap();
    let a = read(&out.join("f_0000.obj"));
    let b = read(&out.join("f_0001.obj"));
    let moved = Mesh { pos: a.pos.clone(), ..m.clone() }.moved(angle, t);
    let worst = moved
        .pos
        .iter()
        .zip(&b.pos)
        .map(|(p, q)| (0..3).map(|k| (p[k] - q[k]).abs()).fold(0.0, f32::max))
        .fold(0.0, f32::max);
    assert!(worst < 2e-4, "the turned skirt's HR frame is {worst} m from the first frame's turned");
}

#[test]
fn a_scaled_mesh_gives_the_same_result_scaled() {
    // The same skirt 1.7 times the size (not a power of two, whose scaling is exact in floats)
    // is another shot (its chart and texel come from its own first frame); its HR frames are the
    // first shot's, scaled, as on a grid.
    let dir = TempDir::new("any-mesh-scaled");
    let m = meshes::skirt(20, 6);
    let frames = [m.clone(), m.rippled(0.01, 0.5)];
    let big = |f: &Mesh| Mesh { pos: f.pos.iter().map(|p| p.map(|c| 1.7 * c)).collect(), ..f.clone() };
    let small_in = write_frames(&dir.join("small"), &frames);
    let big_in = write_frames(&dir.join("big"), &frames.iter().map(big).collect::<Vec<_>>());
    run(UpscaleJob::new(vec![small_in], dir.join("small/out"))).unwrap();
    run(UpscaleJob::new(vec![big_in], dir.join("big/out"))).unwrap();
    for k in 0..2 {
        let a = read(&dir.join(format!("small/out/f_{k:04}.obj")));
        let b = read(&dir.join(format!("big/out/f_{k:04}.obj")));
        let worst = a
            .pos
            .iter()
            .zip(&b.pos)
            .map(|(p, q)| (0..3).map(|c| (1.7 * p[c] - q[c]).abs()).fold(0.0, f32::max))
            .fold(0.0, f32::max);
        println!("frame {k}: {worst:e} m");
        assert!(
            worst < 3.4e-4,
            "frame {k}: the scaled skirt's HR frame is {worst} m from the first's scaled"
        );
    }
}

#[test]
fn a_point_cache_of_a_mesh_gives_the_obj_sequences_vertices() {
    let dir = TempDir::new("any-mesh-cache");
    let m = meshes::tablecloth(20, 5, 0.4);
    let frames = [m.clone(), m.rippled(0.01, 1.0), m.moved(0.2, [0.0, 0.1, 0.0])];
    let objs = write_frames(&dir, &frames);
    run(UpscaleJob::new(vec![objs], dir.join("out_obj"))).unwrap();
    let cache = dir.join("cloth.pc2");
    let mut bytes = Vec::new();
    write_header(&mut bytes, &CacheHeader::new(CacheFormat::Pc2, m.pos.len(), 3, 24.0)).unwrap();
    for f in &frames {
        write_frame(&mut bytes, CacheFormat::Pc2, &f.pos).unwrap();
    }
    std::fs::write(&cache, bytes).unwrap();
    let rest = dir.join("rest.obj");
    std::fs::write(&rest, m.obj()).unwrap();
    let mut job = UpscaleJob::new(vec![cache], dir.join("out_pc2"));
    job.rest = Some(rest);
    run(job).unwrap();
    let mut hr = anisocb::io::point_cache::PointCacheReader::open(&dir.join("out_pc2/cloth.pc2")).unwrap();
    let n = hr.header().points;
    let pts = hr.read_frames(0..3).unwrap();
    for k in 0..3 {
        let obj = read(&dir.join(format!("out_obj/f_{k:04}.obj")));
        assert_eq!(obj.pos.len(), n);
        for (p, q) in obj.pos.iter().zip(&pts[k * n..(k + 1) * n]) {
            assert_eq!(p, q, "frame {k}: the cache and the OBJ frames disagree");
        }
    }
    assert!(dir.join("out_pc2/rest.obj").exists(), "the HR rest mesh is written beside the cache");
}

#[test]
fn meshes_that_are_not_cloth_surfaces_and_grid_only_options_are_refused() {
    let dir = TempDir::new("any-mesh-refused");
    let m = meshes::t_shape(9, 9, 3);
    // An edge in three faces: a fin on an edge between two cells.
    let mut fin = m.clone();
    let f0 = fin.faces[0].clone();
    fin.pos.push([0.0, 0.0, 0.3]);
    fin.faces.push(vec![f0[1], f0[2], (fin.pos.len() - 1) as u32]);
    let input = write_frames(&dir.path().join("fin"), &[fin]);
    let e = run(UpscaleJob::new(vec![input], dir.join("o1"))).unwrap_err().to_string();
    assert!(e.contains("shared by 3 faces") && e.contains("f_0000.obj"), "{e}");
    // The topology changes in the second frame.
    let mut other = m.clone();
    other.faces.swap(0, 1);
    let input = write_frames(&dir.path().join("topo"), &[m.clone(), other]);
    let e = run(UpscaleJob::new(vec![input], dir.join("o2"))).unwrap_err().to_string();
    assert!(e.contains("frame 1 has another topology") && e.contains("f_0001.obj"), "{e}");
    // Grid-only options: held grid edges, geometry.npy output.
    let input = write_frames(&dir.path().join("ok"), std::slice::from_ref(&m));
    let mut job = UpscaleJob::new(vec![input.clone()], dir.join("o3"));
    job.physics = Some(FollowParams { pins: PinnedEdges::parse("top").unwrap(), ..FollowParams::default() });
    let e = run(job).unwrap_err().to_string();
    assert!(e.contains("held grid edges") && e.contains("mesh"), "{e}");
    let mut job = UpscaleJob::new(vec![input], dir.join("o4"));
    job.format = OutputFormat::Npy;
    let e = run(job).unwrap_err().to_string();
    assert!(e.contains("write OBJ frames or a point cache"), "{e}");
}

#[test]
fn eval_meshes_matches_an_hr_run_in_any_vertex_order_and_scores_it() {
    use anisocb::eval::mesh::{evaluate_mesh_run, MeshRun};
    let dir = TempDir::new("any-mesh-eval");
    let m = meshes::skirt(16, 5);
    let frames = [m.clone(), m.rippled(0.01, 0.3), m.rippled(0.02, 0.6)];
    // The HR run: the LR frames subdivided, with its vertices in another order (reversed).
    let sub = Subdivision::of(m.pos.len(), &m.faces);
    let n = sub.hr_vertices() as u32;
    let hr: Vec<Mesh> = frames
        .iter()
        .map(|f| {
            let p = sub.apply(&f.pos);
            Mesh {
                pos: p.iter().rev().copied().collect(),
                faces: sub.faces.iter().map(|f| f.iter().map(|v| n - 1 - v).collect()).collect(),
                uv: None,
                tags: Vec::new(),
                normals: false,
            }
        })
        .collect();
    write_frames(&dir.path().join("run"), &frames);
    std::fs::rename(dir.join("run/in"), dir.join("run/lr")).unwrap();
    write_frames(&dir.path().join("run"), &hr);
    std::fs::rename(dir.join("run/in"), dir.join("run/hr")).unwrap();
    let run = MeshRun::read(&dir.join("run")).unwrap();
    let e = evaluate_mesh_run(&Cpu, &embedded_model().unwrap(), &Default::default(), &run, None).unwrap();
    let by = |name: &str| e.scores.iter().find(|s| s.method == name).unwrap();
    // The truth is the linear subdivision: it scores 0 against it, and has no detail.
    assert!(by("linear subdivision").rmse < 1e-6, "{:?}", by("linear subdivision"));
    assert!(by("HR run (truth)").detail < 1e-6);
    assert!(by("anisocb").rmse > 0.0 && by("Catmull-Clark").rmse > 0.0);
    // The curved subdivision (the nets' base) rounds the tube's facets: off the flat truth, but
    // by no more than an arc's sagitta (about 3 mm here: 6-12 cm edges on a 16-30 cm radius).
    let curved = by("curved subdivision");
    assert!(curved.rmse > 1e-4 && curved.rmse < 5e-3, "{curved:?}");
    // An HR run that is not the LR mesh subdivided is refused.
    std::fs::remove_dir_all(dir.join("run/hr")).unwrap();
    write_frames(&dir.path().join("run"), &frames);
    std::fs::rename(dir.join("run/in"), dir.join("run/hr")).unwrap();
    let err = MeshRun::read(&dir.join("run")).err().unwrap().to_string();
    assert!(err.contains("subdivided once"), "{err}");
}

#[test]
fn a_regular_grid_gives_the_bytes_it_gave_before_any_mesh_input() {
    let fixture = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/grid_bytes");
    let dir = TempDir::new("any-mesh-grid-bytes");
    let out = dir.join("out");
    // The fixture's bytes are the fp32 path's (the default on a CPU without AMX tiles).
    let mut job = UpscaleJob::new(vec![fixture.join("lr")], &out);
    job.params.precision = anisocb::ops::Precision::Fp32;
    let done = run(job).unwrap();
    assert_eq!((done.lr, done.mesh), ((12, 10), None), "read as a grid");
    for k in 0..3 {
        let name = format!("f_{k:04}.obj");
        let (now, then) =
            (std::fs::read(out.join(&name)).unwrap(), std::fs::read(fixture.join("hr").join(&name)).unwrap());
        assert!(now == then, "{name}: not the bytes upscale wrote before any-mesh input");
    }
}

#[test]
fn the_upscaler_gives_a_mesh_the_vertices_upscale_writes() {
    use anisocb::pipeline::Upscaler;
    let dir = TempDir::new("any-mesh-upscaler");
    let m = meshes::mixed_textured(8);
    let frames: Vec<Mesh> = (0..5).map(|k| m.rippled(0.01, 0.4 * k as f32)).collect();
    let input = write_frames(&dir, &frames);
    let out = dir.join("out");
    let mut job = UpscaleJob::new(vec![input.clone()], &out);
    job.params.temporal = 1;
    run(job).unwrap();
    let (uv, fuv) = m.uv.clone().unwrap();
    let params = anisocb::sr::params::UpscaleParams { temporal: 1, ..Default::default() };
    let mut up = Upscaler::new(embedded_model().unwrap(), params)
        .unwrap()
        .with_mesh(m.faces.clone(), &frames[0].pos, Some((&uv, &fuv)))
        .unwrap();
    assert_eq!(up.hr_faces().unwrap(), Subdivision::of(m.pos.len(), &m.faces).faces.as_slice());
    let mut got = Vec::new();
    for f in &frames {
        got.extend(up.push_mesh(&f.pos).unwrap());
    }
    assert_eq!(got.len(), 4, "one frame held back at temporal radius 1");
    got.extend(up.flush_mesh().unwrap());
    for (k, hr) in got.iter().enumerate() {
        let file = read(&out.join(format!("f_{k:04}.obj")));
        assert!(file.pos == *hr, "frame {k}: the Upscaler's vertices are not upscale's");
    }
    // A grid frame given to a mesh Upscaler is refused.
    assert!(up.push(&anisocb::geom::GridMesh::flat(4, 4, 1.0, 1.0)).is_err());
    // With the physics pass, set before or after the mesh: the vertices `upscale --physics`
    // writes, and a second shot starts a new cloth.
    let out = dir.join("out-physics");
    let mut job = UpscaleJob::new(vec![input], &out);
    job.params.temporal = 1;
    job.physics = Some(FollowParams::default());
    run(job).unwrap();
    let plain = read(&dir.join("out").join("f_0004.obj")).pos;
    assert!(read(&out.join("f_0004.obj")).pos != plain, "the pass changed nothing");
    for physics_first in [true, false] {
        let up = Upscaler::new(embedded_model().unwrap(), params).unwrap();
        let mut up = if physics_first {
            up.with_physics(FollowParams::default()).unwrap().with_mesh(
                m.faces.clone(),
                &frames[0].pos,
                Some((&uv, &fuv)),
            )
        } else {
            up.with_mesh(m.faces.clone(), &frames[0].pos, Some((&uv, &fuv)))
                .unwrap()
                .with_physics(FollowParams::default())
        }
        .unwrap();
        for shot in 0..2 {
            let mut got = Vec::new();
            for f in &frames {
                got.extend(up.push_mesh(&f.pos).unwrap());
            }
            got.extend(up.flush_mesh().unwrap());
            for (k, hr) in got.iter().enumerate() {
                let file = read(&out.join(format!("f_{k:04}.obj")));
                assert!(file.pos == *hr, "shot {shot} frame {k}: not upscale --physics's vertices");
            }
        }
    }
}

/// RMS of `v`.
fn rms(v: &[f32]) -> f32 {
    (v.iter().map(|x| x * x).sum::<f32>() / v.len().max(1) as f32).sqrt()
}

#[test]
fn the_physics_pass_forms_folds_finer_than_the_lr_mesh_on_a_mesh_that_is_not_a_grid() {
    // A flat sheet with a hole and a flat disk of triangles, pushed together along x by 15 %
    // over 40 frames: the LR mesh holds no fold; the HR cloth cannot shorten, so it buckles.
    for (name, m) in [("holed", meshes::holed_sheet(13)), ("disk", meshes::tablecloth(20, 5, 0.5))] {
        let flat: Vec<[f32; 3]> = m.pos.iter().map(|p| [p[0], 1.0, p[2] + p[1]]).collect();
        let sub = Subdivision::of(m.pos.len(), &m.faces);
        let n = m.pos.len();
        let mut rng = anisocb::rng::Rng::new(7);
        let frames: Vec<Vec<[f32; 3]>> = (0..40)
            .map(|k| {
                let s = 1.0 - 0.15 * k as f32 / 39.0;
                let lr: Vec<[f32; 3]> = flat.iter().map(|p| [p[0] * s, p[1], p[2]]).collect();
                let mut hr = sub.apply(&lr);
                hr.iter_mut().for_each(|p| p[1] += rng.uniform_in(-5e-5, 5e-5));
                hr
            })
            .collect();
        for output in [FollowOutput::Cloth, FollowOutput::Detail] {
            let p = FollowParams { gravity: [0.0; 3], output, ..FollowParams::default() };
            let run = |frames: &[Vec<[f32; 3]>]| -> Vec<Vec<[f32; 3]>> {
                let mut f = Follower::new_mesh(&frames[0], sub.clone(), n, &p).unwrap();
                let mut out = vec![frames[0].clone()];
                for (k, t) in frames.iter().enumerate().skip(1) {
                    out.push(f.step_mesh(t, k).unwrap());
                }
                out
            };
            let out = run(&frames);
            let (last, shot) = (out.last().unwrap(), frames.last().unwrap());
            let input = rms(&mesh_detail(&sub, n, shot));
            let folds = rms(&mesh_detail(&sub, n, last));
            // The coarse shape: the tent averages the tracking holds (one per LR vertex).
            let r = anisocb::cloth::tracking::Restriction::of_subdivision(&sub, n);
            let coarse: Vec<f32> = r
                .apply(last)
                .iter()
                .zip(r.apply(shot))
                .map(|(a, b)| (0..3).map(|c| (a[c] - b[c]).powi(2)).sum::<f32>().sqrt())
                .collect();
            eprintln!(
                "{name} {output:?}: folds {:.2} mm (shot {:.3} mm), coarse off {:.2} mm",
                1e3 * folds,
                1e3 * input,
                1e3 * rms(&coarse)
            );
            assert!(input < 1e-4, "{name}: the shot itself holds detail {input}");
            assert!(folds > 1e-3, "{name} {output:?}: the HR cloth did not buckle: {folds} m");
            assert!(
                rms(&coarse) < 0.5 * folds,
                "{name} {output:?}: coarse shape {} m off for {folds} m of folds",
                rms(&coarse)
            );
            assert!(out == run(&frames), "{name}: two passes over one shot differ");
        }
    }
}

#[test]
fn upscale_physics_on_a_mesh_keeps_the_output_out_of_a_named_sphere() {
    use anisocb::cloth::collision::Sphere;
    let dir = TempDir::new("any-mesh-physics");
    // A round tablecloth settling over a ball: each frame a little lower over it.
    let m = meshes::tablecloth(20, 5, 0.5);
    let frames: Vec<Mesh> = (0..12).map(|k| m.moved(0.0, [0.0, 0.3 - 0.01 * k as f32, 0.0])).collect();
    let input = write_frames(&dir, &frames);
    let sphere = Sphere { center: [0.0, -0.05, 0.0], radius: 0.2 };
    let mut job = UpscaleJob::new(vec![input], dir.join("out"));
    job.physics = Some(FollowParams { sphere: Some(sphere), fps: 24.0, ..FollowParams::default() });
    let done = run(job).unwrap();
    assert_eq!(done.frames, 12);
    let mut deepest = 0.0f32;
    for k in 0..12 {
        let hr = read(&dir.join(format!("out/f_{k:04}.obj")));
        for p in &hr.pos {
            let d = (0..3).map(|c| (p[c] - sphere.center[c]).powi(2)).sum::<f32>().sqrt();
            deepest = deepest.max(sphere.radius - d);
        }
    }
    assert!(deepest <= 1e-3, "an output vertex is {deepest} m inside the sphere");
}

#[test]
fn held_vertices_of_a_mesh_follow_the_shot_exactly_and_the_rest_of_it_hangs() {
    // A T-shaped sheet hanging in y, held by its top row, carried 20 cm sideways over the shot.
    let m = meshes::t_shape(9, 9, 3);
    let n = m.pos.len();
    let top: Vec<u32> = (0..n as u32).filter(|&v| m.pos[v as usize][1] == 0.0).collect();
    assert!(top.len() == 9, "{}", top.len());
    let sub = Subdivision::of(n, &m.faces);
    let frames: Vec<Vec<[f32; 3]>> =
        (0..24).map(|k| sub.apply(&m.moved(0.0, [0.2 * k as f32 / 23.0, 1.0, 0.0]).pos)).collect();
    let p = FollowParams { pin_vertices: top.clone(), fps: 24.0, ..FollowParams::default() };
    let mut f = Follower::new_mesh(&frames[0], sub.clone(), n, &p).unwrap();
    // Held: the top row and the midpoints between its vertices (17 HR vertices).
    let held: Vec<usize> =
        (0..sub.hr_vertices()).filter(|&v| sub.weights()[v].iter().all(|(u, _)| top.contains(u))).collect();
    assert_eq!(held.len(), 17);
    let mut moved = 0.0f32;
    for (k, t) in frames.iter().enumerate().skip(1) {
        let out = f.step_mesh(t, k).unwrap();
        for &v in &held {
            assert_eq!(out[v], t[v], "frame {k}: held vertex {v} is not the shot's");
        }
        moved = moved.max(out.iter().zip(t).map(|(a, b)| (a[1] - b[1]).abs()).fold(0.0, f32::max));
    }
    assert!(moved > 0.0, "the free cloth never left the shot");
    // A vertex number beyond the mesh, and pins on a grid, are refused by name.
    let bad = FollowParams { pin_vertices: vec![n as u32], ..FollowParams::default() };
    let e = Follower::new_mesh(&frames[0], sub, n, &bad).err().unwrap().to_string();
    assert!(e.contains(&format!("vertex {}", n + 1)), "{e}");
    let grid = anisocb::geom::GridMesh::flat(8, 8, 1.0, 1.0);
    assert!(Follower::new(&grid, (4, 4), &FollowParams { pin_vertices: vec![0], ..FollowParams::default() })
        .is_err());
}
