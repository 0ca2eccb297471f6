//! Checks of the XPBD cloth simulator and its scenarios.

#[path = "common/tempdir.rs"]
mod tempdir;
use anisocb::cloth::collision::{Cuboid, Sphere};
use anisocb::cloth::run_io::{read_run, write_pair, write_single};
use anisocb::cloth::scenarios::run_at;
use anisocb::cloth::tracking::{bilinear_targets, Restriction, TrackingMode};
use anisocb::cloth::{paired_run, run_single, Material, Scenario, ScenarioSpec};
use anisocb::geom::geometry_image::{image_to_mesh, sequence_to_images};
use anisocb::geom::mesh::{border_loop, closed_loop_length, dist};
use anisocb::geom::{Domain, GridMesh};
use tempdir::TempDir;

fn spec(s: Scenario, w: usize, h: usize, frames: usize) -> ScenarioSpec {
    let mut sp = ScenarioSpec::new(s);
    sp.w = w;
    sp.h = h;
    sp.frames = frames;
    sp
}

fn bits(frames: &[GridMesh]) -> Vec<u32> {
    frames.iter().flat_map(|f| f.pos.iter().flat_map(|p| p.map(f32::to_bits))).collect()
}

#[test]
fn scenario_names_round_trip() {
    for s in Scenario::ALL {
        assert_eq!(Scenario::from_name(s.name()).unwrap(), s);
        assert!(!s.description().is_empty(), "{s} has no description");
    }
    assert!(Scenario::from_name("cape").is_err());
}

#[test]
fn pinned_vertices_do_not_move() {
    // The drape's corners follow their kinematic path; the flag's pinned edge too. With a
    // static pin set (kinematics evaluated at the anchor) check that free cloth never drags a
    // pin away from where the kinematics put it.
    for s in [Scenario::Flag, Scenario::Drape, Scenario::Twist] {
        let sp = spec(s, 12, 10, 40);
        let (cloth, scene) = sp.setup(sp.w, sp.h);
        let frames = run_single(&sp).unwrap();
        for (k, f) in frames.iter().enumerate() {
            let t = k as f32 * sp.params.dt;
            for pin in &cloth.pins {
                let want = scene.kinematics.position(pin.anchor, pin.side, t);
                let got = f.pos[pin.vertex];
                assert!(
                    dist(want, got) < 1e-5,
                    "{s}: frame {k} pin {} at {got:?}, want {want:?}",
                    pin.vertex
                );
            }
        }
    }
    // A flag whose edge does not flap: the pinned row stays exactly at rest.
    let mut sp = spec(Scenario::Flag, 10, 10, 30);
    sp.params.gravity = [0.0, -9.81, 0.0];
    let frames = run_single(&sp).unwrap();
    let rest = &frames[0];
    let (cloth, _) = sp.setup(10, 10);
    assert_eq!(cloth.pins.len(), 10);
    for p in &cloth.pins {
        assert_eq!(rest.pos[p.vertex], p.anchor);
    }
}

#[test]
fn stretch_stays_within_a_few_percent_for_stiff_cloth() {
    // Denim flag hanging under gravity and wind: mean edge strain of the last frames is small
    // and no edge stretches more than 10 %.
    let mut sp = spec(Scenario::Flag, 24, 24, 90);
    sp.material = Material::DENIM;
    let frames = run_single(&sp).unwrap();
    let rest = &frames[0];
    let mut worst = 0.0f32;
    let mut mean = 0.0f32;
    let mut n = 0;
    for f in &frames[60..] {
        for j in 0..f.h {
            for i in 0..f.w - 1 {
                let (a, b) = (f.idx(i, j), f.idx(i + 1, j));
                let s = dist(f.pos[a], f.pos[b]) / dist(rest.pos[a], rest.pos[b]) - 1.0;
                worst = worst.max(s);
                mean += s.abs();
                n += 1;
            }
        }
    }
    mean /= n as f32;
    println!("row-edge strain: mean |s| {mean:.4}, max {worst:.4}");
    assert!(mean < 0.03, "mean strain {mean}");
    assert!(worst < 0.10, "max strain {worst}");
}

#[test]
fn nothing_penetrates_the_sphere_beyond_the_margin() {
    for s in [Scenario::FlagSphere, Scenario::Drape, Scenario::Drop] {
        let sp = spec(s, 20, 20, 120);
        let (_, scene) = sp.setup(sp.w, sp.h);
        let Sphere { center, radius } = scene.colliders.sphere.unwrap();
        let frames = run_single(&sp).unwrap();
        let mut closest = f32::INFINITY;
        for f in &frames {
            for p in &f.pos {
                closest = closest.min(dist(*p, center));
            }
        }
        println!("{s}: closest vertex {closest:.4} m from the centre, radius {radius}");
        assert!(closest >= radius - 1e-4, "{s}: a vertex is {closest} from the centre (radius {radius})");
        assert!(closest < radius + 0.05, "{s}: the cloth never reached the sphere (closest {closest})");
    }
}

/// Length (m) of the border loop `ring` of `mesh`, and of its shadow on the ground plane (y = 0):
/// a hem hanging in folds has a shadow far shorter than itself.
fn border_and_footprint(mesh: &GridMesh, ring: &[usize]) -> (f64, f64) {
    let len = closed_loop_length(ring, |v| mesh.pos[v].map(f64::from));
    let shadow = closed_loop_length(ring, |v| [mesh.pos[v][0] as f64, 0.0, mesh.pos[v][2] as f64]);
    (len, shadow)
}

#[test]
fn a_dropped_sheet_lands_on_the_sphere_and_its_hem_hangs_in_folds() {
    // Nothing pinned: the sheet falls, its middle comes to rest on top of the sphere and the
    // free hem hangs down around it (the folds cloth from other tools has at its border).
    let sp = spec(Scenario::Drop, 20, 20, 90);
    let (cloth, scene) = sp.setup(sp.w, sp.h);
    assert!(cloth.pins.is_empty(), "the dropped sheet has no pins");
    let Sphere { center, radius } = scene.colliders.sphere.unwrap();
    let frames = run_single(&sp).unwrap();
    let last = frames.last().unwrap();
    let top = center[1] + radius;
    let mid = last.pos[last.idx(sp.w / 2, sp.h / 2)];
    assert!(
        (mid[1] - top).abs() < 0.03,
        "the middle rests at y = {} m, the sphere's top is at {top}",
        mid[1]
    );
    let ring = border_loop(sp.w, sp.h);
    let hem_y = ring.iter().map(|&v| last.pos[v][1]).sum::<f32>() / ring.len() as f32;
    assert!(hem_y < top - radius, "the hem hangs at y = {hem_y} m on average, the top is at {top}");
    // Hanging folds: the border loop is far shorter in the ground plane than it is long.
    let (loop_len, flat_len) = border_and_footprint(last, &ring);
    assert!(flat_len < 0.9 * loop_len, "border {loop_len} m long, {flat_len} m seen from above: no folds");
    let lowest = last.pos.iter().map(|p| p[1]).fold(f32::INFINITY, f32::min);
    assert!(lowest > -1e-4, "a vertex went through the ground: y = {lowest}");
}

#[test]
fn a_sheet_dropped_on_a_table_hangs_down_its_sides_and_never_enters_it() {
    // The tablecloth: the middle rests on the table top, the free hem hangs down all four
    // sides, clear of the ground, in folds; no vertex gets inside the box beyond the margin.
    let sp = spec(Scenario::DropTable, 20, 20, 60);
    let (cloth, scene) = sp.setup(sp.w, sp.h);
    assert!(cloth.pins.is_empty(), "the dropped sheet has no pins");
    let Cuboid { center, half } = scene.colliders.cuboid.unwrap();
    let frames = run_single(&sp).unwrap();
    for (t, f) in frames.iter().enumerate() {
        for p in &f.pos {
            let depth = (0..3).map(|k| half[k] - (p[k] - center[k]).abs()).fold(f32::INFINITY, f32::min);
            assert!(depth < 1e-4, "frame {t}: a vertex is {depth} m inside the table");
        }
    }
    let last = frames.last().unwrap();
    let top = center[1] + half[1];
    let mid = last.pos[last.idx(sp.w / 2, sp.h / 2)];
    assert!((mid[1] - top).abs() < 0.03, "the middle rests at y = {} m, the top is at {top}", mid[1]);
    let ring = border_loop(sp.w, sp.h);
    for &v in &ring {
        let y = last.pos[v][1];
        assert!(y < top - 0.05 && y > 0.02, "a hem vertex is at y = {y} m (top {top} m, ground 0)");
    }
    let (loop_len, flat_len) = border_and_footprint(last, &ring);
    assert!(flat_len < 0.97 * loop_len, "border {loop_len} m long, {flat_len} m seen from above: no folds");
}

#[test]
fn same_seed_gives_bit_identical_runs() {
    let mut sp = spec(Scenario::FlagSphere, 10, 10, 25);
    sp.seed = 7;
    let (a_lr, a_hr) = paired_run(&sp).unwrap();
    let (b_lr, b_hr) = paired_run(&sp).unwrap();
    assert_eq!(bits(&a_lr), bits(&b_lr));
    assert_eq!(bits(&a_hr), bits(&b_hr));
    sp.seed = 8;
    let c = run_single(&sp).unwrap();
    assert_ne!(bits(&a_lr), bits(&c), "the seed should change the wind");
}

#[test]
fn geometry_images_of_a_run_round_trip() {
    let frames = run_single(&spec(Scenario::Twist, 16, 6, 30)).unwrap();
    let d = Domain::enclosing(&frames, 0.05);
    let img = sequence_to_images(&frames, &d);
    assert_eq!(img.shape, vec![30, 3, 6, 16]);
    assert!(img.data.iter().all(|&c| (0.0..=1.0).contains(&c)));
    for (k, f) in frames.iter().enumerate() {
        let back = image_to_mesh(&img, k, &d);
        for (a, b) in f.pos.iter().zip(&back.pos) {
            for c in 0..3 {
                assert!((a[c] - b[c]).abs() <= 4.0 * f32::EPSILON * (1.0 + a[c].abs()), "{a:?} vs {b:?}");
            }
        }
    }
}

/// The HR-twin studies of docs/research/wrinkles.md (`simulate --hr-jitter / --hr-restart / --hr-blind`)
/// change the HR run only, and only where they say: the LR run stays bit for bit, a restart at
/// frame F leaves frames 0..=F alone, a blind run starts from the LR surface.
#[test]
fn hr_twin_studies_change_only_the_hr_run_and_only_where_they_say() {
    let sp = spec(Scenario::Drape, 8, 8, 12);
    let (lr, hr) = paired_run(&sp).unwrap();
    let twin = |f: &dyn Fn(&mut ScenarioSpec)| {
        let mut s = sp.clone();
        f(&mut s);
        let (l, h) = paired_run(&s).unwrap();
        assert_eq!(bits(&l), bits(&lr), "the LR run must not change");
        h
    };
    let frame_bits = |h: &[GridMesh], k: usize| bits(&h[k..k + 1]);
    let jittered = twin(&|s| s.hr_jitter = 1e-4);
    assert_ne!(frame_bits(&jittered, 0), frame_bits(&hr, 0), "the jitter moves the rest state");
    let max_jitter = hr[0].pos.iter().zip(&jittered[0].pos).map(|(a, b)| dist(*a, *b)).fold(0.0, f32::max);
    assert!(max_jitter <= 1e-4 * 3f32.sqrt() * 1.01, "jitter {max_jitter} m beyond ±0.1 mm per coordinate");
    let restarted = twin(&|s| s.hr_restart = 5);
    for k in 0..=5 {
        assert_eq!(frame_bits(&restarted, k), frame_bits(&hr, k), "frame {k} is before the restart");
    }
    assert_ne!(frame_bits(&restarted, 6), frame_bits(&hr, 6), "the restart changes what follows it");
    let blind = twin(&|s| s.hr_blind = true);
    assert_eq!(frame_bits(&blind, 0), frame_bits(&hr, 0));
    assert_ne!(
        frame_bits(&blind, 2),
        frame_bits(&hr, 2),
        "a blind run has no sphere and starts on the LR surface"
    );
    let mut bad = sp.clone();
    bad.hr_jitter = f32::NAN;
    assert!(paired_run(&bad).is_err(), "a NaN jitter must be refused");
}

/// Mean distance (m) between HR vertices and the LR run sampled at their rest (u, v).
fn lr_hr_gap(lr: &[GridMesh], hr: &[GridMesh]) -> f32 {
    let mut s = 0.0;
    let mut n = 0;
    for (l, h) in lr.iter().zip(hr) {
        let t = bilinear_targets(l, h.w, h.h);
        for (a, b) in t.iter().zip(&h.pos) {
            s += dist(*a, *b);
            n += 1;
        }
    }
    s / n as f32
}

#[test]
fn tracking_reduces_the_low_frequency_lr_hr_difference() {
    let mut sp = spec(Scenario::FlagSphere, 12, 12, 150);
    sp.tracking = 0.0;
    let (lr, hr_free) = paired_run(&sp).unwrap();
    sp.tracking = anisocb::cloth::scenarios::DEFAULT_TRACKING;
    let (lr2, hr_tracked) = paired_run(&sp).unwrap();
    assert_eq!(bits(&lr), bits(&lr2), "the LR run must not depend on tracking");
    let (free, tracked) = (lr_hr_gap(&lr, &hr_free), lr_hr_gap(&lr, &hr_tracked));
    println!("mean LR/HR gap: free {free:.4} m, tracked {tracked:.4} m");
    assert!(tracked < 0.8 * free, "tracking should pull HR toward LR: free {free}, tracked {tracked}");
}

#[test]
fn run_directory_round_trips() {
    let dir = TempDir::new("sim-test");
    let sp = spec(Scenario::TwistZeroG, 8, 4, 5);
    let frames = run_at(&sp, 8, 4, None, &mut |_| {}).unwrap();
    let img = write_single(&dir.join("one"), &sp, &frames, true).unwrap();
    let one = read_run(&dir.join("one")).unwrap();
    let (img2, d) = (one.images, one.domain);
    assert_eq!(img, img2);
    let meta = std::fs::read_to_string(dir.join("one/meta.json")).unwrap();
    assert!(meta.contains("\"scenario\": \"twist-zero-g\""), "{meta}");
    assert_eq!(one.meta.unwrap().get("scenario").and_then(|v| v.as_str()), Some("twist-zero-g"));
    let back = anisocb::geom::obj::read_obj_grid(&dir.join("one/obj/frame_0004.obj")).unwrap();
    assert_eq!(back, frames[4]);
    let dm = image_to_mesh(&img2, 4, &d);
    assert!(dm.pos.iter().zip(&frames[4].pos).all(|(a, b)| dist(*a, *b) < 1e-5));

    let (lr, hr) = paired_run(&sp).unwrap();
    let written = write_pair(&dir.join("pair"), &sp, &lr, &hr, false).unwrap();
    let (l, h) = (read_run(&dir.join("pair/lr")).unwrap(), read_run(&dir.join("pair/hr")).unwrap());
    let (li, ld, hi, hd) = (l.images, l.domain, h.images, h.domain);
    assert_eq!(ld, hd, "LR and HR must share one domain");
    assert_eq!(li.shape, vec![5, 3, 4, 8]);
    assert_eq!(hi.shape, vec![5, 3, 8, 16]);
    let hmeta = std::fs::read_to_string(dir.join("pair/hr/meta.json")).unwrap();
    assert!(hmeta.contains("\"role\": \"hr\""));
    let back = anisocb::cloth::run_io::read_pair(&dir.join("pair")).unwrap();
    assert_eq!((back.lr, back.hr, back.domain), (written.lr, written.hr, written.domain));
    assert!(read_run(&dir.join("missing")).is_err());
}

/// Mean |strain| of row and column edges over frames `from..`.
fn mean_strain(frames: &[GridMesh], from: usize) -> f32 {
    let rest = &frames[0];
    let (mut s, mut n) = (0.0f32, 0usize);
    for f in &frames[from..] {
        for j in 0..f.h {
            for i in 0..f.w {
                let v = f.idx(i, j);
                for u in [(i + 1 < f.w).then(|| v + 1), (j + 1 < f.h).then(|| v + f.w)].into_iter().flatten()
                {
                    s += (dist(f.pos[v], f.pos[u]) / dist(rest.pos[v], rest.pos[u]) - 1.0).abs();
                    n += 1;
                }
            }
        }
    }
    s / n as f32
}

#[test]
fn hr_run_of_a_pair_is_as_inextensible_as_the_lr_run() {
    for s in [Scenario::Flag, Scenario::Twist] {
        let (w, h) = if s == Scenario::Flag { (12, 12) } else { (16, 6) };
        let sp = spec(s, w, h, 60);
        let (lr, hr) = paired_run(&sp).unwrap();
        let (a, b) = (mean_strain(&lr, 20), mean_strain(&hr, 20));
        println!("{s}: mean |strain| LR {a:.4}, HR {b:.4}");
        assert!(b < 1.5 * a + 0.01, "{s}: HR stretches more than LR ({b} vs {a})");
    }
}

#[test]
fn obj_frames_of_a_run_read_back_as_one_sequence() {
    let dir = TempDir::new("sim-seq");
    let sp = spec(Scenario::Twist, 9, 4, 12);
    let frames = run_single(&sp).unwrap();
    write_single(&dir, &sp, &frames, true).unwrap();
    let files = anisocb::geom::obj::list_obj_files(&dir.join("obj")).unwrap();
    assert_eq!(files.len(), 12);
    let (back, style) = anisocb::geom::obj::read_obj_sequence(&files).unwrap();
    assert_eq!(style, anisocb::geom::obj::FaceStyle::Quads);
    assert_eq!(back, frames);
}

#[test]
fn parallel_colour_sweeps_give_the_same_bits_as_serial() {
    let mut sp = spec(Scenario::FlagSphere, 40, 40, 12);
    sp.params.parallel_min_colour = usize::MAX;
    let serial = run_single(&sp).unwrap();
    sp.params.parallel_min_colour = 1;
    let parallel = run_single(&sp).unwrap();
    assert_eq!(bits(&serial), bits(&parallel));
}

/// RMS (m) over the interior of X − S(X), S = Catmull-Rom resampling down to the LR grid and
/// back: how much folding finer than the LR grid a run holds (a smooth sheet scores ≈ 0).
fn fine_detail(frames: &[GridMesh], lr_w: usize, lr_h: usize) -> f64 {
    use anisocb::ops::resample::resize;
    use anisocb::ops::Interp;
    let (w, h) = (frames[0].w, frames[0].h);
    let (mut s, mut n) = (0.0f64, 0usize);
    for f in frames {
        let x = anisocb::tensor::Tensor::from_vec(
            &[1, 3, h, w],
            (0..3).flat_map(|c| f.pos.iter().map(move |p| p[c])).collect(),
        )
        .unwrap();
        let sm = resize(&resize(&x, lr_h, lr_w, Interp::CatmullRom), h, w, Interp::CatmullRom);
        for c in 0..3 {
            for j in 2..h - 2 {
                for i in 2..w - 2 {
                    let k = c * h * w + j * w + i;
                    s += ((x.data[k] - sm.data[k]) as f64).powi(2);
                    n += 1;
                }
            }
        }
    }
    (3.0 * s / n.max(1) as f64).sqrt()
}

/// Mean distance (m) between the coarse view of the HR run and the same view of the LR run.
fn coarse_gap(lr: &[GridMesh], hr: &[GridMesh]) -> f32 {
    let r = Restriction::new(lr[0].w, lr[0].h, hr[0].w, hr[0].h);
    let (mut s, mut n) = (0.0, 0);
    for (l, h) in lr.iter().zip(hr) {
        for (a, b) in r.targets(l).iter().zip(&r.apply(&h.pos)) {
            s += dist(*a, *b);
            n += 1;
        }
    }
    s / n as f32
}

#[test]
fn coarse_tracking_holds_the_lr_shape_and_leaves_the_fine_folds_free() {
    // A dropped sheet: its hem falls into folds finer than the LR grid. Per-vertex tracking
    // pulls every HR vertex onto the LR surface and flattens them; coarse tracking holds only
    // the LR-scale averages, so the HR run keeps more of its own folds while its coarse shape
    // stays on the LR run (a free HR run drifts far from it).
    let mut sp = spec(Scenario::Drop, 32, 32, 50);
    sp.vary = 3;
    let run = |tracking: f32, mode: TrackingMode| {
        let mut s = sp.clone();
        (s.tracking, s.tracking_mode) = (tracking, mode);
        paired_run(&s).unwrap()
    };
    let (lr, free) = run(0.0, TrackingMode::Coarse);
    let (_, vertex) = run(1000.0, TrackingMode::Vertex);
    let (_, coarse) = run(1000.0, TrackingMode::Coarse);
    let rough = [&free, &vertex, &coarse].map(|f| fine_detail(&f[25..], 32, 32));
    let gap = [&free, &vertex, &coarse].map(|f| coarse_gap(&lr, f));
    println!("fine detail (mm) free/vertex/coarse: {:?}", rough.map(|r| r * 1e3));
    println!("coarse gap (mm) free/vertex/coarse: {:?}", gap.map(|g| g * 1e3));
    assert!(
        rough[2] > 1.1 * rough[1],
        "coarse tracking should keep more fine folds than per-vertex: {rough:?}"
    );
    assert!(gap[2] < 0.5 * gap[0], "coarse tracking should hold the LR shape: {gap:?}");
}

#[test]
fn restriction_of_a_flat_hr_sheet_meets_the_lr_targets_exactly() {
    // The coarse targets restrict the LR surface sampled at the HR vertices, so an HR sheet
    // lying on a flat (or bilinear) LR sheet satisfies every coarse constraint, border nodes
    // included (their clipped tents are biased, but the same way on both sides).
    let (lw, lh, hw, hh) = (5, 4, 10, 8);
    let lr = GridMesh::new(
        lw,
        lh,
        (0..lh)
            .flat_map(|j| (0..lw).map(move |i| [0.3 * i as f32, 0.1 * (i * j) as f32, -0.2 * j as f32]))
            .collect(),
    );
    let r = Restriction::new(lw, lh, hw, hh);
    for n in 0..r.nodes() {
        let s: f32 = r.node(n).map(|(_, w)| w).sum();
        assert!((s - 1.0).abs() < 1e-6, "node {n}: weights sum to {s}");
    }
    let hr = bilinear_targets(&lr, hw, hh);
    for (a, b) in r.targets(&lr).iter().zip(&r.apply(&hr)) {
        assert!(dist(*a, *b) < 1e-6, "{a:?} vs {b:?}");
    }
}
