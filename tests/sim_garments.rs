//! Checks of the garment scenes (issue 45, step 3): every garment is a surface anisocb takes,
//! its body's parts never overlap, its runs stay finite and outside the body, pins ride on the
//! body, the HR run keeps to the LR run at the LR vertices and has folds of its own, the same
//! seed gives the same bits, and the folder it writes is what `eval --meshes` reads.

#[path = "common/tempdir.rs"]
mod tempdir;
use anisocb::cloth::garments::{garment_run, Garment, GarmentSpec};
use anisocb::cloth::run_io::write_garment_run;
use anisocb::cloth::tracking::Restriction;
use anisocb::eval::mesh::{mesh_detail, penetration, MeshFrames, MeshRun};
use anisocb::geom::surface::Surface;
use std::path::Path;
use tempdir::TempDir;

fn spec(g: Garment, frames: usize) -> GarmentSpec {
    GarmentSpec { frames, ..GarmentSpec::new(g) }
}

fn rms(a: &[[f32; 3]], b: &[[f32; 3]]) -> f32 {
    let s: f32 = a.iter().zip(b).map(|(p, q)| (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f32>()).sum();
    (s / a.len() as f32).sqrt()
}

#[test]
fn garment_names_round_trip_and_every_garment_is_a_surface_that_is_not_a_grid() {
    for g in Garment::ALL {
        assert_eq!(Garment::from_name(g.name()), Some(g));
        let scene = spec(g, 2).scene();
        let m = &scene.mesh;
        Surface::new(m.pos.len(), m.faces.clone(), Path::new(g.name()))
            .unwrap_or_else(|e| panic!("{g} is not a surface: {e}"));
        assert_eq!(m.faces.len(), m.face_uv.len(), "{g}: a UV face per face");
        assert!(
            m.uv.iter().all(|t| t.iter().all(|c| (0.0..=1.0).contains(c))),
            "{g}: UVs in the unit square"
        );
        // Not a W×H grid: the grid reader refuses it, so `upscale` takes the any-mesh path.
        let obj =
            anisocb::geom::obj::ObjMesh { pos: m.pos.clone(), faces: m.faces.clone(), ..Default::default() };
        assert!(anisocb::geom::obj::obj_to_grid(&obj, Path::new(g.name())).is_err(), "{g} reads as a grid");
    }
    assert_eq!(Garment::from_name("twist"), None);
}

#[test]
fn body_parts_never_overlap_while_they_move() {
    for g in Garment::ALL {
        let sp = spec(g, 90);
        let body = sp.scene().body;
        if body.parts.len() < 2 {
            continue;
        }
        let frames = |i: usize| -> MeshFrames {
            let p = &body.parts[i];
            let posed = (0..sp.frames)
                .step_by(3)
                .map(|k| {
                    let m = body.poses(k as f32 * sp.params.dt)[i];
                    p.pos.iter().map(|x| m.apply(*x)).collect()
                })
                .collect();
            MeshFrames { faces: p.faces.clone(), frames: posed }
        };
        for a in 0..body.parts.len() {
            for b in 0..body.parts.len() {
                if a != b {
                    let (share, deepest) = penetration(&frames(a).frames, &frames(b));
                    assert_eq!(share, 0.0, "{g}: part {a} enters part {b} ({deepest} m deep)");
                }
            }
        }
    }
}

#[test]
fn garment_pairs_stay_finite_and_outside_the_body_and_pins_ride_on_it() {
    for g in Garment::ALL {
        let sp = spec(g, 24);
        let run = garment_run(&sp, true, &mut |_| {}).unwrap_or_else(|e| panic!("{g}: {e}"));
        assert_eq!((run.lr.len(), run.hr.len()), (24, 24));
        assert_eq!(run.hr[0].len(), run.sub.hr_vertices());
        let body = MeshFrames { faces: run.body_faces.clone(), frames: run.body.clone() };
        for (name, frames) in [("LR", &run.lr), ("HR", &run.hr)] {
            assert!(
                frames.iter().flatten().all(|p| p.iter().all(|c| c.is_finite())),
                "{g} {name}: not finite"
            );
            let (share, deepest) = penetration(frames, &body);
            assert!(
                deepest <= 1e-3,
                "{g} {name}: {:.3} % of vertex-frames inside the body, {deepest} m deep",
                100.0 * share
            );
        }
        // A pinned vertex is where its part carries its rest position.
        let scene = sp.scene();
        for k in [0, 11, 23] {
            let poses = scene.body.poses(k as f32 * sp.params.dt);
            for &(v, part) in &scene.mesh.pins {
                let want = poses[part].apply(scene.mesh.pos[v as usize]);
                let got = run.lr[k][v as usize];
                assert!(
                    (0..3).all(|c| (got[c] - want[c]).abs() < 1e-5),
                    "{g} frame {k} pin {v}: {got:?} vs {want:?}"
                );
            }
        }
        // The cloth moved: gravity and the body act on it.
        assert!(rms(&run.lr[23], &run.lr[0]) > 5e-3, "{g}: the cloth did not move");
    }
}

#[test]
fn the_hr_run_keeps_to_the_lr_run_at_its_vertices_and_has_folds_of_its_own() {
    let sp = spec(Garment::Skirt, 45);
    let run = garment_run(&sp, true, &mut |_| {}).unwrap();
    let n = run.mesh.pos.len();
    let r = Restriction::of_subdivision(&run.sub, n);
    let k = 44;
    // The HR run's coarse shape (its tent averages at the LR vertices) against the LR run's.
    let coarse = rms(&r.apply(&run.hr[k]), &r.apply(&run.sub.apply(&run.lr[k])));
    let motion = rms(&run.lr[k], &run.lr[0]);
    assert!(coarse < 0.15 * motion, "HR drifts from LR: {coarse} m (the cloth moved {motion} m)");
    // Folds finer than the LR mesh: the HR run's detail is millimetres, the LR's subdivision none.
    let d = mesh_detail(&run.sub, n, &run.hr[k]);
    let detail = (d[n..].iter().map(|x| x * x).sum::<f32>() / (d.len() - n) as f32).sqrt();
    assert!(detail > 1e-3, "HR detail {detail} m");
    let flat = mesh_detail(&run.sub, n, &run.sub.apply(&run.lr[k]));
    assert!(flat.iter().all(|x| x.abs() < 1e-5));
}

#[test]
fn the_same_seed_gives_the_same_bits_and_another_seed_another_breeze() {
    let bits = |seed: u64| {
        let sp = GarmentSpec { seed, ..spec(Garment::HoledSheet, 8) };
        let run = garment_run(&sp, true, &mut |_| {}).unwrap();
        run.lr.iter().chain(&run.hr).flatten().flat_map(|p| p.map(f32::to_bits)).collect::<Vec<u32>>()
    };
    assert_eq!(bits(3), bits(3));
    assert_ne!(bits(3), bits(4));
}

#[test]
fn varied_garments_differ_and_seed_zero_is_the_garment_as_given() {
    let scene = |vary: u64| GarmentSpec { vary, ..spec(Garment::Cape, 2) }.scene().mesh.pos;
    assert_eq!(scene(0), spec(Garment::Cape, 2).scene().mesh.pos);
    assert_ne!(scene(0), scene(5));
    assert_ne!(scene(5), scene(6));
}

#[test]
fn a_garment_folder_is_what_eval_meshes_reads() {
    let dir = TempDir::new("garment-run");
    let sp = spec(Garment::Tshirt, 6);
    let run = garment_run(&sp, true, &mut |_| {}).unwrap();
    write_garment_run(dir.path(), &sp, &run).unwrap();
    let read = MeshRun::read(dir.path()).unwrap();
    assert_eq!(read.lr.faces, run.mesh.faces);
    assert_eq!(read.lr.frames.len(), 6);
    // Positions go through the OBJ text: as printed, f32 round trip.
    for (a, b) in read.hr.iter().zip(&run.hr) {
        assert!(rms(a, b) < 1e-6, "HR frames read back in another order");
    }
    assert!((read.fps - 30.0).abs() < 1e-3);
    let body = read.collider.expect("the body is written as the collider");
    assert_eq!(body.frames.len(), 6);
    assert!(!read.first.uv.is_empty(), "the pattern's UVs are written");
    // The collar's pins, read back as the physics pass takes them (0-based).
    let mut want: Vec<u32> = run.mesh.pins.iter().map(|p| p.0).collect();
    want.sort_unstable();
    assert!(!want.is_empty());
    assert_eq!(read.pins, want);
}

#[test]
fn simulate_a_garment_twice_into_its_folder_and_refuse_another_scenes() {
    let dir = TempDir::new("garment-cli");
    let out = dir.path().join("tshirt");
    let sim = |args: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_anisocb"))
            .arg("simulate")
            .args(args)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap()
    };
    let o = sim(&["--scenario", "tshirt", "--pair", "--frames", "5"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for f in [
        "lr/cloth_0004.obj",
        "hr/cloth_0004.obj",
        "collider/body_0004.obj",
        "pins.txt",
        "scene.json",
        "preview.png",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    // The same garment again, shorter: its own folder, the frames it no longer writes removed.
    let o = sim(&["--scenario", "tshirt", "--pair", "--frames", "3"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(!out.join("lr/cloth_0004.obj").exists() && out.join("lr/cloth_0002.obj").is_file());
    // Another garment, a sheet option on a garment: refused, the folder as it was.
    let o = sim(&["--scenario", "skirt", "--frames", "3"]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("simulate.json"));
    let o = sim(&["--scenario", "tshirt", "--pair", "--frames", "3", "--res", "8x8"]);
    assert!(
        !o.status.success()
            && String::from_utf8_lossy(&o.stderr).contains("--res is for the sheet scenarios")
    );
    assert!(out.join("lr/cloth_0002.obj").is_file());
}

#[test]
fn a_garment_run_becomes_sheet_sized_windows_of_a_dataset_and_is_held_out_by_its_name() {
    let dir = TempDir::new("garment-dataset");
    let sp = spec(Garment::Skirt, 3);
    let run = garment_run(&sp, true, &mut |_| {}).unwrap();
    let pair = dir.path().join("skirt-3");
    write_garment_run(&pair, &sp, &run).unwrap();
    let out = dir.path().join("data.npz");
    let args = |extra: &[&str]| {
        let mut a =
            vec!["anisocb", "dataset", "--runs", pair.to_str().unwrap(), "--out", out.to_str().unwrap()];
        a.extend_from_slice(extra);
        a.into_iter().map(String::from).collect::<Vec<_>>()
    };
    assert_eq!(anisocb::app::main_with_args(args(&["--overwrite"])), 0);
    let e = anisocb::io::read_npz(&out).unwrap();
    let (lr, hr) = (e.array("lr").unwrap(), e.array("hr").unwrap());
    // Without sheets the windows are the sheets' training size: 32² LR, 64² HR.
    assert_eq!(&lr.shape[1..], &[3, 32, 32]);
    assert_eq!(&hr.shape[1..], &[3, 64, 64]);
    assert_eq!(lr.shape[0] % 3, 0, "3 frames per window");
    assert!(lr.data.iter().chain(&hr.data).all(|v| v.is_finite()));
    let frames = String::from_utf8(e.file("frames.json").unwrap().to_vec()).unwrap();
    assert!(
        frames.contains("\"run\": \"skirt-3@0\"") && frames.contains("\"scenario\": \"skirt\""),
        "{frames}"
    );
    // The HR window shows the same cloth as the LR one at twice the pixels: each HR pixel within
    // a tenth of the window's extent (the cloth frame's unit) of its nearest LR pixel. (The
    // exact alignment is `geom::layout`'s test.)
    let n = 32;
    let mut diff = 0.0f32;
    for c in 0..3 {
        for yy in 0..2 * n {
            for xx in 0..2 * n {
                let s = (n - 1) as f32 / (2 * n - 1) as f32;
                let (x, y) = ((xx as f32 * s).round() as usize, (yy as f32 * s).round() as usize);
                let d = hr.data[(c * 2 * n + yy) * 2 * n + xx] - lr.data[(c * n + y) * n + x];
                diff = diff.max(d.abs());
            }
        }
    }
    assert!(diff > 1e-4 && diff < 0.1, "largest HR − LR difference {diff} (cloth-frame units)");
    // Held out by scenario or by its folder's name: no run left.
    for name in ["skirt", "skirt-3"] {
        let code = anisocb::app::main_with_args(args(&["--overwrite", "--holdout", name]));
        assert_ne!(code, 0, "--holdout {name} kept the run");
    }
}

/// `simulate --scenario G --pair --hr-jitter M` (the garment twin study of
/// docs/research/wrinkles.md): the LR run stays bit for bit, the HR run starts moved by at most
/// M per coordinate (pinned vertices not at all), and a bad jitter is refused.
#[test]
fn a_garment_hr_twin_changes_only_the_hr_run_within_its_jitter() {
    let sp = spec(Garment::Cape, 6);
    let run = garment_run(&sp, true, &mut |_| {}).unwrap();
    let twin = garment_run(&GarmentSpec { hr_jitter: 1e-4, ..sp.clone() }, true, &mut |_| {}).unwrap();
    let bits =
        |f: &[Vec<[f32; 3]>]| f.iter().flatten().flat_map(|p| p.map(f32::to_bits)).collect::<Vec<u32>>();
    assert_eq!(bits(&twin.lr), bits(&run.lr), "the LR run must not change");
    assert_ne!(bits(&twin.hr[..1]), bits(&run.hr[..1]), "the jitter moves the HR start");
    let moved: Vec<f32> = run.hr[0]
        .iter()
        .zip(&twin.hr[0])
        .map(|(a, b)| (0..3).map(|k| (a[k] - b[k]).abs()).fold(0.0, f32::max))
        .collect();
    assert!(moved.iter().all(|&d| d <= 1.0001e-4), "a start moved by more than the jitter");
    let pinned: Vec<usize> = run.mesh.pins.iter().map(|p| p.0 as usize).collect();
    assert!(pinned.iter().all(|&v| moved[v] == 0.0), "a pinned vertex moved");
    for bad in [f32::NAN, -1e-4, 0.5] {
        let e = garment_run(&GarmentSpec { hr_jitter: bad, ..sp.clone() }, true, &mut |_| {});
        assert!(e.is_err(), "jitter {bad} must be refused");
    }
}
