//! `upscale --physics` (cloth/follow.rs, pipeline/physics.rs): the HR cloth coarse-tracked to
//! the shot keeps a still cloth where the shot has it (by the drift correction), forms folds
//! the LR grid cannot hold where the shot compresses the cloth, keeps the shot's coarse shape
//! (in `detail` output exactly, in `cloth` output by its drift correction), gives the same
//! bits twice, and refuses what it cannot do.

#[path = "common/tempdir.rs"]
mod tempdir;

use anisocb::cloth::collision::{Cuboid, Sphere};
use anisocb::cloth::follow::{FollowOutput, FollowParams, Follower, PinnedEdges};
use anisocb::cloth::scenarios::{run_single, Scenario, ScenarioSpec};
use anisocb::cloth::tracking::bilinear_targets;
use anisocb::eval::metrics::{lr_round_trip, wrinkle_detail};
use anisocb::geom::obj::write_obj_grid;
use anisocb::geom::GridMesh;
use anisocb::nn::weights::embedded_model;
use anisocb::pipeline::job::FrameSpan;
use anisocb::pipeline::{upscale_files, Quiet, UpscaleJob};
use tempdir::TempDir;

/// A flat `w × h` sheet of side 1.2 m in the xz plane, squeezed along x by `squeeze` (fraction).
fn sheet(w: usize, h: usize, squeeze: f32) -> GridMesh {
    let pos = (0..w * h)
        .map(|v| {
            let (u, t) = ((v % w) as f32 / (w - 1) as f32, (v / w) as f32 / (h - 1) as f32);
            [(u - 0.5) * 1.2 * (1.0 - squeeze), 1.0, (t - 0.5) * 1.2]
        })
        .collect();
    GridMesh::new(w, h, pos)
}

/// The HR frames a shot of LR frames gives on the LR surface, with ±0.05 mm of seeded noise
/// across it (what the nets give: smooth, not perfectly flat).
fn on_lr_surface(lr: &[GridMesh]) -> Vec<GridMesh> {
    let mut rng = anisocb::rng::Rng::new(7);
    lr.iter()
        .map(|m| {
            let mut pos = bilinear_targets(m, 2 * m.w, 2 * m.h);
            pos.iter_mut().for_each(|p| p[1] += rng.uniform_in(-5e-5, 5e-5));
            GridMesh::new(2 * m.w, 2 * m.h, pos)
        })
        .collect()
}

fn follow(frames: &[GridMesh], p: &FollowParams) -> Vec<GridMesh> {
    Follower::run(frames, (frames[0].w / 2, frames[0].h / 2), p).unwrap()
}

fn rms_gap(a: &GridMesh, b: &GridMesh) -> f32 {
    let s: f32 =
        a.pos.iter().zip(&b.pos).map(|(p, q)| (0..3).map(|c| (p[c] - q[c]).powi(2)).sum::<f32>()).sum();
    (s / a.pos.len() as f32).sqrt()
}

fn rms(v: &[f32]) -> f32 {
    (v.iter().map(|x| x * x).sum::<f32>() / v.len() as f32).sqrt()
}

#[test]
fn physics_pass_keeps_a_still_cloth_where_the_shot_has_it() {
    // 30 frames of a sheet at rest under gravity. The simulated cloth hangs below the shot on
    // its springs, as the training truth's HR runs hang below their LR runs (the targets are
    // not raised to carry its weight: docs/research/wrinkles.md, "The physics pass"); at most
    // g/strength (4.9 mm at the default 2000 1/s²), measured 4.3 mm.
    let frames = on_lr_surface(&vec![sheet(12, 12, 0.0); 30]);
    let gap = |p: &FollowParams| {
        let out = follow(&frames, p);
        out.iter().zip(&frames).map(|(o, t)| rms_gap(o, t)).fold(0.0f32, f32::max)
    };
    let hangs = gap(&FollowParams { drift_seconds: f32::INFINITY, ..FollowParams::default() });
    assert!(
        (1e-3..9.81 / FollowParams::default().strength).contains(&hangs),
        "without its drift correction a still sheet hangs {hangs} m RMS off the shot, not 1 mm to g/strength"
    );
    // `cloth` output (the default) takes that sag out from the first frame: the output is the
    // shot's sheet within the hem's sway. Measured 0.16 mm.
    let worst = gap(&FollowParams::default());
    assert!(worst < 0.5e-3, "a still sheet comes out {worst} m RMS off the shot");
    // That sway is the only detail the still sheet gains, in either output: measured 0.18 mm
    // RMS(D) at its peak in both (1.22 mm when the cloth started from the first frame: the
    // hem's modes finer than the LR grid, which only the material damps, swung for seconds;
    // 0.79 mm with the undamped attachment and a 1 s settle, 0.45 mm with that settle
    // critically damped; 0.31 mm at the earlier damped defaults).
    for output in [FollowOutput::Detail, FollowOutput::Cloth] {
        let out = follow(&frames, &FollowParams { output, ..FollowParams::default() });
        let detail = out.iter().map(|o| rms(&wrinkle_detail(o, 12, 12).unwrap())).fold(0.0f32, f32::max);
        eprintln!("still sheet: hangs {hangs} m, output {worst} m RMS off the shot, {output:?} output RMS(D) ≤ {detail} m");
        assert!(detail < 0.4e-3, "{output:?} output: a still sheet gains {detail} m RMS of folds");
    }
}

#[test]
fn critical_damping_stills_the_cloth_after_a_landing_where_undamped_it_rings() {
    // A sheet falls for 10 frames at 24 fps (0.77 m) and stops dead: a landing, as Blender's
    // sheets land. Undamped (the default, as the training truth's runs) the attachment rings
    // afterwards; at 1 of critical (`--physics-damping 1`, the setting for Blender shots:
    // docs/research/wrinkles.md, "Blender shots") the cloth is still sooner. Measured: the output's
    // frame-to-frame motion, RMS over vertices and the steps from 3 to 23 frames after the
    // stop, 45 mm undamped (stopped at 4.1 m/s, the cloth swings by centimetres), 7.5 mm damped.
    let fall = |k: usize| 0.5 * 9.81 * (k.min(10) as f32 / 24.0).powi(2);
    let lr: Vec<GridMesh> = (0..34)
        .map(|k| {
            let mut m = sheet(12, 12, 0.0);
            m.pos.iter_mut().for_each(|p| p[1] -= fall(k));
            m
        })
        .collect();
    let frames = on_lr_surface(&lr);
    let after = |damping: f32| {
        let out = follow(&frames, &FollowParams { fps: 24.0, damping, ..FollowParams::default() });
        let steps: Vec<f32> = out[13..].windows(2).map(|w| rms_gap(&w[1], &w[0])).collect();
        rms(&steps)
    };
    let (undamped, damped) = (after(0.0), after(1.0));
    eprintln!("after the stop: {undamped} m a frame undamped, {damped} m at critical");
    assert!(
        undamped > 10e-3,
        "undamped, the landed cloth moves only {undamped} m a frame: no ring to take out"
    );
    assert!(
        damped < 0.5 * undamped,
        "critical damping leaves {damped} m a frame after the stop (undamped {undamped})"
    );
}

#[test]
fn physics_pass_forms_folds_finer_than_the_lr_grid_where_the_shot_compresses_the_cloth() {
    // The LR sheet is pushed together along x by 15 % over 40 frames and stays flat: the LR
    // grid holds no fold. The HR cloth cannot shorten, so it buckles at its own wavelength.
    let lr: Vec<GridMesh> = (0..40).map(|k| sheet(16, 16, 0.15 * (k as f32 / 39.0))).collect();
    let frames = on_lr_surface(&lr);
    let input = rms(&wrinkle_detail(frames.last().unwrap(), 16, 16).unwrap());
    assert!(input < 1e-4, "the compressed LR sheet itself holds detail: {input} m");
    // `cloth` output (the default) buckles too, its coarse shape the shot's within a fraction
    // of the folds' depth.
    let p = FollowParams { gravity: [0.0; 3], ..FollowParams::default() };
    let cloth = follow(&frames, &p);
    let (last, shot) = (cloth.last().unwrap(), frames.last().unwrap());
    let folds = rms(&wrinkle_detail(last, 16, 16).unwrap());
    let coarse = rms_gap(&lr_round_trip(last, 16, 16), &lr_round_trip(shot, 16, 16));
    assert!(
        folds > 1e-3 && coarse < 0.5 * folds,
        "cloth output: {folds} m of folds, coarse shape {coarse} m off"
    );
    let p = FollowParams { output: FollowOutput::Detail, ..p };
    let out = follow(&frames, &p);
    let last = out.last().unwrap();
    let folds = rms(&wrinkle_detail(last, 16, 16).unwrap());
    assert!(folds > 1e-3, "the HR cloth did not buckle: RMS(D) {folds} m");
    // `detail` output keeps the shot's coarse shape: only folds finer than the LR grid added.
    let coarse = rms_gap(&lr_round_trip(last, 16, 16), &lr_round_trip(frames.last().unwrap(), 16, 16));
    assert!(coarse < 0.3 * folds, "the coarse shape moved {coarse} m for {folds} m of folds");
    // ... and its border: the outermost ring is the shot's, bit for bit.
    let ring = (0..32 * 32).filter(|v| [v % 32, v / 32].iter().any(|&c| c == 0 || c == 31));
    assert!(ring.into_iter().all(|v| last.pos[v] == shot.pos[v]), "the border moved off the shot");
    // The same shot gives the same bits.
    let again = follow(&frames, &p);
    assert!(out.iter().zip(&again).all(|(a, b)| a.pos == b.pos), "two passes over one shot differ");
}

#[test]
fn physics_pass_pinned_edges_follow_the_shot_exactly_and_only_they() {
    // The shot carries the sheet's left and right edges up and over by 5 cm in 20 frames.
    let lr: Vec<GridMesh> = (0..20)
        .map(|k| {
            let mut m = sheet(10, 10, 0.0);
            m.pos
                .iter_mut()
                .for_each(|p| (p[1], p[2]) = (p[1] + 0.05 * k as f32 / 19.0, p[2] - 0.002 * k as f32));
            m
        })
        .collect();
    let frames = on_lr_surface(&lr);
    let pins = PinnedEdges::parse("left, right").unwrap();
    assert_eq!(pins.names(), "left,right");
    let p = FollowParams { pins, ..FollowParams::default() };
    let out = follow(&frames, &p);
    let held = pins.vertices(20, 20);
    assert_eq!(held.len(), 40);
    assert!(held.iter().all(|&v| v % 20 == 0 || v % 20 == 19));
    for (k, (o, t)) in out.iter().zip(&frames).enumerate() {
        assert!(held.iter().all(|&v| o.pos[v] == t.pos[v]), "frame {k}: a pinned vertex left the shot");
    }
    // The free middle hangs on its springs between the held edges: off the shot, but not far.
    let last = out.last().unwrap();
    let mid = last.pos[10 * 20 + 10][1] - frames.last().unwrap().pos[10 * 20 + 10][1];
    assert!(mid.abs() > 1e-6 && mid.abs() < 2e-2, "the middle is {mid} m off the shot");
    // Corners pin four vertices; a name it does not know is refused, naming the choices.
    assert_eq!(PinnedEdges::parse("corners").unwrap().vertices(20, 20), vec![0, 19, 380, 399]);
    assert!(PinnedEdges::parse("none").unwrap().is_empty());
    let e = PinnedEdges::parse("top,middle").unwrap_err().to_string();
    assert!(e.contains("middle") && e.contains("corners"), "{e}");
}

#[test]
fn cloth_output_takes_out_the_lag_the_pass_cannot_explain_over_its_drift_time() {
    // The shot rises with a steady 3 m/s² for 3 s after standing still: the springs carry the
    // cloth along ≈ a/strength below the shot (a push the pass does not know, as a shot's wind
    // or collider is). The drift correction takes that out over its time constant.
    let lr: Vec<GridMesh> = (0..90)
        .map(|k| {
            let t = k as f32 / 30.0;
            let mut m = sheet(8, 8, 0.0);
            m.pos.iter_mut().for_each(|p| p[1] += 1.5 * t * t);
            m
        })
        .collect();
    let frames = on_lr_surface(&lr);
    let gap = |drift_seconds: f32| {
        let out = follow(&frames, &FollowParams { drift_seconds, ..FollowParams::default() });
        let (o, t) = (out.last().unwrap(), frames.last().unwrap());
        rms_gap(&lr_round_trip(o, 8, 8), &lr_round_trip(t, 8, 8))
    };
    let (off, default, every) = (gap(f32::INFINITY), gap(FollowParams::default().drift_seconds), gap(0.0));
    eprintln!("coarse gap after 3 s at 3 m/s²: off {off} m, default {default} m, every frame {every} m");
    assert!(off > 3e-4, "the springs should lag the accelerating shot: {off} m");
    // Measured: 5.5 mm without the correction (the lag and the cloth's sag on its springs:
    // 2.6 mm at the earlier defaults, 3000 1/s² with the targets raised to carry its weight),
    // 0.76 mm at the default 3 s, 0.03 mm every frame.
    assert!(default < 0.5 * off, "the default drift correction left {default} m of {off} m");
    assert!(every < 0.1 * off, "the full correction left {every} m of {off} m");
}

#[test]
fn each_scenarios_held_edges_and_colliders_are_what_runs_tell_the_pass() {
    for sc in Scenario::ALL {
        let spec = ScenarioSpec::new(sc);
        let (cloth, _) = spec.setup(9, 7);
        let mut pinned: Vec<usize> = cloth.pins.iter().map(|p| p.vertex).collect();
        pinned.sort_unstable();
        assert_eq!(pinned, sc.held_edges().vertices(9, 7), "{}", sc.name());
    }
    // What eval --physics reads of a run: gravity, frame rate, material, the held edges.
    let meta = anisocb::cloth::run_io::meta_json(
        &ScenarioSpec::new(Scenario::TwistZeroG),
        "hr",
        8,
        8,
        &anisocb::geom::Domain::UNIT,
    );
    let p = FollowParams::for_run(&meta);
    assert_eq!((p.gravity, p.fps, p.pins.names().as_str()), ([0.0; 3], 30.0, "left,right"));
    // ... and the colliders of its variant (a run's meta.json names the scenario, the LR grid and
    // the variation seed), here a varied drop's sphere and floor.
    let mut spec = ScenarioSpec::new(Scenario::Drop);
    (spec.w, spec.h, spec.vary) = (16, 16, 5);
    let scene = spec.setup(16, 16).1;
    let p = FollowParams::for_run(&anisocb::cloth::run_io::meta_json(
        &spec,
        "hr",
        32,
        32,
        &anisocb::geom::Domain::UNIT,
    ));
    assert_eq!((p.sphere, p.cuboid, p.ground), (scene.colliders.sphere, None, Some(0.0)));
    assert!(
        p.sphere.is_some() && p.sphere != ScenarioSpec::new(Scenario::Drop).setup(16, 16).1.colliders.sphere
    );
}

#[test]
fn physics_pass_keeps_the_output_above_a_named_floor_and_out_of_named_colliders() {
    // The shot lowers a sheet onto y = 1 m and squeezes it: the folds would hang below it.
    let lr: Vec<GridMesh> = (0..30).map(|k| sheet(12, 12, 0.12 * (k as f32 / 29.0))).collect();
    let frames = on_lr_surface(&lr);
    // Frame 0 is the shot's own (the cloth starts there); the floor holds from frame 1 on.
    let lowest =
        |out: &[GridMesh]| out[1..].iter().flat_map(|m| m.pos.iter().map(|p| p[1])).fold(f32::MAX, f32::min);
    let free = follow(&frames, &FollowParams::default());
    assert!(lowest(&free) < 0.999, "the folds should dip below the shot's sheet: lowest {} m", lowest(&free));
    let floor = follow(&frames, &FollowParams { ground: Some(1.0), ..FollowParams::default() });
    assert!(lowest(&floor) >= 1.0, "a vertex went below the floor: {} m", lowest(&floor));
    // A sphere and a table top just under the middle of the sheet: nothing inside them.
    let sphere = Sphere { center: [0.0, 0.9, 0.0], radius: 0.0998 };
    let cuboid = Cuboid { center: [0.3, 0.8, 0.0], half: [0.1, 0.1998, 0.1] };
    let out = follow(
        &frames,
        &FollowParams { sphere: Some(sphere), cuboid: Some(cuboid), ..FollowParams::default() },
    );
    let inside = |p: &[f32; 3]| {
        let d: [f32; 3] = std::array::from_fn(|c| p[c] - sphere.center[c]);
        let in_box = (0..3).all(|c| (p[c] - cuboid.center[c]).abs() < cuboid.half[c] - 1e-6);
        (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() < sphere.radius - 1e-6 || in_box
    };
    assert!(
        free[1..].iter().flat_map(|m| &m.pos).any(inside),
        "the free folds should reach into the colliders"
    );
    assert!(!out[1..].iter().flat_map(|m| &m.pos).any(inside), "an output vertex is inside a collider");
    // z-up: the floor is along −gravity.
    let zup = FollowParams { gravity: [0.0, 0.0, -9.81], ground: Some(-0.5), ..FollowParams::default() };
    let out = follow(&frames, &zup);
    assert!(out[1..].iter().flat_map(|m| &m.pos).all(|p| p[2] >= -0.5), "z-up floor crossed");
    let e =
        Follower::new(&frames[0], (12, 12), &FollowParams { gravity: [0.0; 3], ground: Some(0.0), ..zup })
            .err()
            .expect("a floor without a gravity accepted")
            .to_string();
    assert!(e.contains("ground") && e.contains("gravity"), "{e}");
}

#[test]
fn physics_pass_refuses_bad_settings_and_frames_with_a_message() {
    let frames = on_lr_surface(&[sheet(8, 8, 0.0)]);
    // Each refusal names the library's field (the command line renames it to its flag).
    for (p, what) in [
        (FollowParams { gravity: [0.0, f32::NAN, 0.0], ..FollowParams::default() }, "gravity"),
        (FollowParams { fps: 0.0, ..FollowParams::default() }, "fps"),
        (FollowParams { strength: -1.0, ..FollowParams::default() }, "strength"),
        (FollowParams { damping: f32::INFINITY, ..FollowParams::default() }, "damping"),
        (FollowParams { drift_seconds: f32::NAN, ..FollowParams::default() }, "drift_seconds"),
        (FollowParams { drift_seconds: -1.0, ..FollowParams::default() }, "drift_seconds"),
    ] {
        let e = Follower::new(&frames[0], (8, 8), &p).err().expect("bad setting accepted");
        assert!(matches!(e, anisocb::Error::Invalid { field, .. } if field == what), "{what}: {e}");
    }
    let mut f = Follower::new(&frames[0], (8, 8), &FollowParams::default()).unwrap();
    let mut bad = frames[0].clone();
    bad.pos[5][1] = f32::NAN;
    assert!(f.step(&bad, 3).unwrap_err().to_string().contains("frame 3"));
    let small = sheet(8, 8, 0.0);
    assert!(f.step(&small, 4).unwrap_err().to_string().contains("frame 4"));
}

#[test]
fn upscale_physics_runs_on_files_and_refuses_a_slice_that_does_not_start_at_frame_0() {
    let d = TempDir::new("physics-job");
    let mut spec = ScenarioSpec::new(Scenario::Drape);
    (spec.w, spec.h, spec.frames, spec.seed) = (12, 12, 8, 3);
    let run = run_single(&spec).unwrap();
    std::fs::create_dir_all(d.join("in")).unwrap();
    for (k, f) in run.iter().enumerate() {
        write_obj_grid(&d.join("in").join(format!("f_{k:03}.obj")), f, true).unwrap();
    }
    let model = embedded_model().unwrap();
    let mut job = UpscaleJob::new(vec![d.join("in")], d.join("out"));
    job.physics = Some(FollowParams::default());
    let done = upscale_files(&anisocb::ops::Cpu, &model, &job.clone().check().unwrap(), &mut Quiet).unwrap();
    assert_eq!((done.frames, done.hr), (8, (24, 24)));
    // Frame 0 is the nets' (the cloth starts there), later frames the pass's.
    let mut plain = job.clone();
    (plain.physics, plain.out) = (None, d.join("plain"));
    upscale_files(&anisocb::ops::Cpu, &model, &plain.check().unwrap(), &mut Quiet).unwrap();
    let read = |dir: &str, k: usize| std::fs::read(d.join(dir).join(format!("f_{k:03}.obj"))).unwrap();
    assert_eq!(read("out", 0), read("plain", 0));
    assert_ne!(read("out", 7), read("plain", 7));
    // Refused when the job is checked, before a file is read or the output folder is made.
    job.frames = Some(FrameSpan::parse("2:8").unwrap());
    job.out = d.join("slice");
    let e = job.check().unwrap_err().to_string();
    assert!(e.contains("frames") && e.contains("physics pass") && e.contains("start"), "{e}");
    assert!(!d.join("slice").exists());
}

#[test]
fn physics_pass_turned_with_its_gravity_gives_the_turned_cloth_bit_for_bit() {
    // The pass is a simulation in the shot's metres and axes, with no axis of its own: the
    // same shot turned a quarter turn about z (exact in floating point), with its gravity
    // turned alike, gives the same cloth turned, to the bit. A turn that rounds the
    // coordinates gives the folds' buckling another start: on this flat sheet, squeezed until
    // it buckles, moving the shot 1 mm moved the folds 0.75 mm RMS and a 53° turn 11 mm (of
    // 16 mm of folds); docs/research/wrinkles.md, "The physics pass", Invariance. A shot turned
    // differently each frame is another motion (the cloth feels the turning).
    let lr: Vec<GridMesh> = (0..30).map(|k| sheet(12, 12, 0.12 * (k as f32 / 29.0))).collect();
    let frames = on_lr_surface(&lr);
    let turn = |p: [f32; 3]| [-p[1], p[0], p[2]];
    let turn_all = |ms: &[GridMesh]| -> Vec<GridMesh> {
        ms.iter().map(|m| GridMesh::new(m.w, m.h, m.pos.iter().map(|&p| turn(p)).collect())).collect()
    };
    let pins = PinnedEdges::parse("left").unwrap();
    let p = FollowParams { pins, ..FollowParams::default() };
    let out = follow(&frames, &p);
    let out_turned = follow(&turn_all(&frames), &FollowParams { gravity: turn(p.gravity), ..p });
    let folds = rms(&wrinkle_detail(out.last().unwrap(), 12, 12).unwrap());
    assert!(folds > 5e-4, "the shot should fold: {folds} m");
    for (k, (a, b)) in turn_all(&out).iter().zip(&out_turned).enumerate() {
        assert!(a.pos == b.pos, "frame {k}: the turned shot's cloth is not the cloth turned");
    }
}

#[test]
fn physics_pass_that_cannot_follow_the_shot_is_an_error_naming_the_frame_and_causes() {
    // A flag held at its top; from frame 10 on the shot is 2 m to the side (two shots in one
    // folder, a snap, a unit mix-up): the pass's cloth cannot be there, and says so.
    let mut spec = ScenarioSpec::new(Scenario::Flag);
    (spec.w, spec.h, spec.frames, spec.seed) = (12, 12, 16, 3);
    let run = run_single(&spec).unwrap();
    let mut up = anisocb::pipeline::Upscaler::embedded().unwrap().with_physics(pins_top()).unwrap();
    let mut err = None;
    for (k, f) in run.iter().enumerate() {
        let mut f = f.clone();
        if k >= 10 {
            f.pos.iter_mut().for_each(|p| p[0] += 2.0);
        }
        if let Err(e) = up.push(&f) {
            err = Some((k, e.to_string()));
            break;
        }
    }
    let (k, e) = err.expect("a 2 m jump was followed without a word");
    assert_eq!(k, 10, "{e}");
    assert!(e.contains("frame 10") && e.contains("metres") && e.contains("one shot"), "{e}");
    // The same shot without the jump runs to the end.
    let mut up = anisocb::pipeline::Upscaler::embedded().unwrap().with_physics(pins_top()).unwrap();
    for f in &run {
        up.push(f).unwrap();
    }
}

fn pins_top() -> FollowParams {
    FollowParams { pins: PinnedEdges::parse("top").unwrap(), ..FollowParams::default() }
}
