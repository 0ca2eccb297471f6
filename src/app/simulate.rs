//! `anisocb simulate`: run a cloth scenario (XPBD) at one resolution or as an LR/HR pair and
//! write run directories (see [`crate::cloth::run_io`]) plus a preview picture of each.

use crate::app::ui::{progress, save_png};
use crate::cloth::garments::{garment_run, Garment, GarmentSpec, GARMENT_HELP};
use crate::cloth::run_io::{obj_frame_name, write_garment_run, write_pair, write_single, RUN_FILES};
use crate::cloth::scenarios::{paired_run_with_progress, run_at, SCENARIO_HELP};
use crate::cloth::{Material, Scenario, ScenarioSpec};
use crate::error::{Error, Result};
use crate::io::json::{Object, Value};
use crate::pipeline::folder::{self, Ownership};
use crate::tensor::Tensor;
use crate::viz::sheet::frame_strip;
use std::path::{Path, PathBuf};

#[derive(clap::Args, Debug)]
#[command(after_help = format!("{SCENARIO_HELP}\n\n{GARMENT_HELP}"))]
pub struct Args {
    /// Scenario or garment name (listed below).
    #[arg(long, default_value = "twist")]
    pub scenario: String,
    /// Low-resolution grid as COLSxROWS vertices (default: the scenario's, 32x32 or 32x10).
    #[arg(long)]
    pub res: Option<String>,
    /// Number of frames (frame 0 is the rest state).
    #[arg(long, default_value_t = 200)]
    pub frames: usize,
    /// Seed of the wind gusts.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Randomise the scene with this seed (cloth size, material, wind, flapping, obstacle
    /// (sphere, table) size and place, drape and twist speeds); 0 = the scenario as in the
    /// paper. Overrides --material.
    #[arg(long, default_value_t = 0)]
    pub vary: u64,
    /// Material preset: silk, cotton, denim, rubber.
    #[arg(long, default_value = "cotton")]
    pub material: String,
    /// Simulate an LR/HR pair into OUT/lr and OUT/hr (a garment: the HR run is the LR mesh
    /// subdivided once, held to the LR run at its vertices).
    #[arg(long)]
    pub pair: bool,
    /// HR upscale factor for --pair (vertices per side).
    #[arg(long, default_value_t = 2)]
    pub scale: usize,
    /// HR→LR tracking strength in 1/s² for --pair (0 = off: the HR run drifts from its twin).
    #[arg(long, default_value_t = crate::cloth::scenarios::DEFAULT_TRACKING)]
    pub tracking: f32,
    /// What tracking holds: `coarse` = one averaged constraint per LR node, so the HR run's
    /// own folds finer than the LR grid form freely (the training truth); `vertex` = every HR
    /// vertex pulled to the LR surface (flattens those folds; the truth of older models).
    #[arg(long, default_value = "coarse")]
    pub track: String,
    /// Add up to this many metres of seeded noise to the tracked HR run's rest positions
    /// (--pair): a twin of the HR truth under the same LR run, to measure how much of its
    /// fine detail the LR run fixes (docs/research/wrinkles.md). 0 = none.
    #[arg(long, default_value_t = 0.0)]
    pub hr_jitter: f32,
    /// At this frame, put the tracked HR run (--pair) back on the LR run's surface and let its
    /// folds form again: how long a window of LR frames fixes the HR detail (docs/research/wrinkles.md).
    /// 0 = never.
    #[arg(long, default_value_t = 0)]
    pub hr_restart: usize,
    /// Let the tracked HR run (--pair) know only its LR run: no colliders, no wind, started on
    /// the LR surface; gravity, material and pins as the scenario's. What a physics upscaler of
    /// someone else's cloth could reach (docs/research/wrinkles.md).
    #[arg(long)]
    pub hr_blind: bool,
    /// XPBD substeps per frame.
    #[arg(long)]
    pub substeps: Option<usize>,
    /// Seconds per frame.
    #[arg(long)]
    pub dt: Option<f32>,
    /// Turn gravity off.
    #[arg(long)]
    pub no_gravity: bool,
    /// Also write every frame as OBJ (quads) under OUT/obj/.
    #[arg(long)]
    pub obj: bool,
    /// Output directory: created if missing, or empty, or one that an earlier simulation of
    /// the same scene (scenario, seed, --vary, --pair) owns, as its simulate.json says (the
    /// files it wrote and this run does not are removed); anything else there is refused (see
    /// --overwrite). One run at a time writes it (a lock).
    #[arg(long)]
    pub out: PathBuf,
    /// Write into --out even though it holds files no simulation of this scene wrote (those
    /// this run writes are replaced, the rest left).
    #[arg(long)]
    pub overwrite: bool,
}

/// Parse "32x10" into (32, 10).
pub fn parse_res(s: &str) -> Result<(usize, usize)> {
    let bad = || Error::config(format!("--res must look like 32x10 (columns x rows), got '{s}'"));
    let (a, b) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    let w = a.trim().parse().map_err(|_| bad())?;
    let h = b.trim().parse().map_err(|_| bad())?;
    Ok((w, h))
}

/// Build the spec from the command line.
pub fn spec_from_args(a: &Args) -> Result<ScenarioSpec> {
    let mut spec = ScenarioSpec::new(Scenario::from_name(&a.scenario)?);
    if let Some(r) = &a.res {
        (spec.w, spec.h) = parse_res(r)?;
    }
    spec.frames = a.frames;
    spec.seed = a.seed;
    spec.vary = a.vary;
    spec.material = Material::from_name(&a.material)?;
    spec.scale = a.scale;
    spec.tracking = a.tracking;
    spec.hr_jitter = a.hr_jitter;
    spec.hr_restart = a.hr_restart;
    spec.hr_blind = a.hr_blind;
    spec.tracking_mode = crate::cloth::tracking::TrackingMode::from_name(&a.track)?;
    set_sim_params(a, &mut spec.params);
    spec.validate()?;
    Ok(spec)
}

/// `--substeps`, `--dt` and `--no-gravity` on the scene's simulation parameters.
fn set_sim_params(a: &Args, p: &mut crate::cloth::SimParams) {
    if let Some(s) = a.substeps {
        p.substeps = s;
    }
    if let Some(dt) = a.dt {
        p.dt = dt;
    }
    if a.no_gravity {
        p.gravity = [0.0; 3];
    }
}

fn write_preview(dir: &Path, images: &Tensor) -> Result<()> {
    save_png(&dir.join("preview.png"), &frame_strip(images, 6, 160)?)
}

/// The garment spec of the command line (`--scenario` names a garment); the sheet-only
/// options are refused.
pub fn garment_spec_from_args(a: &Args, garment: Garment) -> Result<GarmentSpec> {
    let sheet_only = [
        ("--res", a.res.is_some()),
        ("--scale", a.scale != 2),
        ("--track", a.track != "coarse"),
        ("--hr-restart", a.hr_restart != 0),
        ("--hr-blind", a.hr_blind),
        ("--obj", a.obj),
    ];
    if let Some((flag, _)) = sheet_only.iter().find(|f| f.1) {
        return Err(Error::config(format!(
            "{flag} is for the sheet scenarios; a garment has its own mesh (its LR resolution is the \
             garment's, its HR run the LR mesh subdivided once, tracked coarsely) and always writes OBJ \
             frames: leave {flag} out"
        )));
    }
    let mut spec = GarmentSpec::new(garment);
    spec.frames = a.frames;
    spec.seed = a.seed;
    spec.vary = a.vary;
    spec.material = Material::from_name(&a.material)?;
    spec.tracking = a.tracking;
    spec.hr_jitter = a.hr_jitter;
    set_sim_params(a, &mut spec.params);
    spec.validate()?;
    Ok(spec)
}

/// `simulate` for a garment: OUT/lr (and with --pair OUT/hr), OUT/collider, OUT/pins.txt,
/// OUT/scene.json, and a picture of a few frames.
fn run_garment(a: &Args, garment: Garment) -> Result<()> {
    let spec = garment_spec_from_args(a, garment)?;
    let own = garment_ownership(a, &spec);
    let claim = folder::claim(&a.out, &own, a.overwrite)?;
    for n in &claim.removed {
        eprintln!("note: removed {n}, an earlier run's output that this run does not write");
    }
    own.write_summary(&a.out, Object::new(), false)?;
    let t0 = std::time::Instant::now();
    let runs = if a.pair { 2 } else { 1 };
    let pb = progress((runs * spec.frames) as u64, "simulate");
    pb.set_message(format!("{garment}"));
    let run = garment_run(&spec, a.pair, &mut |k| pb.set_position(k as u64 + 1))?;
    pb.finish_and_clear();
    write_garment_run(&a.out, &spec, &run)?;
    write_garment_preview(&a.out.join("preview.png"), &run)?;
    eprintln!(
        "simulated {garment}: {} LR vertices{}, {} frames in {:.1} s → {}/{{{}collider}} (preview.png)",
        run.mesh.pos.len(),
        if a.pair { format!(" / {} HR", run.sub.hr_vertices()) } else { String::new() },
        spec.frames,
        t0.elapsed().as_secs_f32(),
        a.out.display(),
        if a.pair { "lr,hr," } else { "lr," }
    );
    own.write_summary(&a.out, Object::new(), true)?;
    drop(claim);
    Ok(())
}

/// [`ownership`] of a garment run: the garment, seed, variation, single or pair, and every file
/// [`write_garment_run`] and the preview write.
fn garment_ownership(a: &Args, spec: &GarmentSpec) -> Ownership {
    let inputs = vec![
        format!("garment {}", spec.garment.name()),
        format!("seed {}", spec.seed),
        format!("vary {}", spec.vary),
        (if a.pair { "pair" } else { "single" }).to_string(),
    ];
    let p = &spec.params;
    let settings = Object::new()
        .num("frames", spec.frames)
        .str("material", &a.material)
        .val("tracking", Value::real(spec.tracking))
        .num("substeps", p.substeps)
        .val("dt", Value::real(p.dt))
        .val("gravity", Value::reals(&p.gravity));
    let n = spec.frames;
    let frames =
        |dir: &'static str, stem: &'static str| (0..n).map(move |k| format!("{dir}/{stem}_{k:04}.obj"));
    let mut files: Vec<String> = frames("lr", "cloth").chain(frames("collider", "body")).collect();
    if a.pair {
        files.extend(frames("hr", "cloth"));
    }
    if !spec.scene().mesh.pins.is_empty() {
        files.push("pins.txt".into());
    }
    files.extend(["scene.json".to_string(), "preview.png".to_string()]);
    Ownership {
        job: "simulate",
        noun: "scene",
        inputs,
        settings: settings.into(),
        summary: "simulate.json".into(),
        files,
    }
}

/// `preview.png` of a garment run: four frames of the LR run (and below, the HR run) on the
/// body in grey, one camera for all.
fn write_garment_preview(path: &Path, run: &crate::cloth::garments::GarmentRun) -> Result<()> {
    use crate::eval::mesh::triangles;
    use crate::geom::GridMesh;
    use crate::viz::render::{render_layers, Camera, Layer, Shading, View, PROP_TINT};
    let t = run.lr.len();
    let picks = [0, t / 3, 2 * t / 3, t - 1];
    let one_row = |p: &[[f32; 3]]| GridMesh::new(p.len(), 1, p.to_vec());
    let (lr_tris, hr_tris, body_tris) =
        (triangles(&run.mesh.faces), triangles(&run.sub.faces), triangles(&run.body_faces));
    let all: Vec<[f32; 3]> = picks.iter().flat_map(|&k| run.lr[k].iter().copied()).collect();
    let (lo, hi) = crate::geom::mesh::bounds(&all);
    let cam = Camera::fit(&View::default(), lo, hi, 240, 240)?;
    let mut rows = Vec::new();
    for (frames, tris, name) in [(&run.lr, &lr_tris, "LR"), (&run.hr, &hr_tris, "HR")] {
        if frames.is_empty() {
            continue;
        }
        let mut tiles = Vec::new();
        for &k in &picks {
            let (cloth, body) = (one_row(&frames[k]), one_row(&run.body[k]));
            let layers = [
                Layer { tris: Some(tris), mesh: &cloth, colors: None, tint: None },
                Layer { tris: Some(&body_tris), mesh: &body, colors: None, tint: Some(PROP_TINT) },
            ];
            let mut pic = render_layers(&layers, &cam, &Shading::default())?;
            pic.label(&format!("{name}, frame {k}"), 1);
            tiles.push(pic);
        }
        rows.push(crate::viz::image::hstack(&tiles, 6, [255; 3]));
    }
    save_png(path, &crate::viz::image::vstack(&rows, 6, [255; 3]))
}

/// Who this run is for its output folder ([`crate::pipeline::folder`]): the scene (scenario,
/// seed, variation, single or pair), the settings, and every file it writes.
fn ownership(a: &Args, spec: &ScenarioSpec) -> Ownership {
    let inputs = vec![
        format!("scenario {}", spec.scenario.name()),
        format!("seed {}", spec.seed),
        format!("vary {}", spec.vary),
        (if a.pair { "pair" } else { "single" }).to_string(),
    ];
    let p = &spec.params;
    let settings = Object::new()
        .val("res", vec![Value::num(spec.w), Value::num(spec.h)])
        .num("frames", spec.frames)
        .str("material", &a.material)
        .num("scale", spec.scale)
        .val("tracking", Value::real(spec.tracking))
        .str("track", &a.track)
        .val("hr_jitter", Value::real(spec.hr_jitter))
        .num("hr_restart", spec.hr_restart)
        .val("hr_blind", Value::Bool(spec.hr_blind))
        .num("substeps", p.substeps)
        .val("dt", Value::real(p.dt))
        .val("gravity", Value::reals(&p.gravity))
        .val("obj", Value::Bool(a.obj));
    let run = |prefix: &str| {
        let mut f: Vec<String> =
            RUN_FILES.iter().chain(["preview.png"].iter()).map(|n| format!("{prefix}{n}")).collect();
        if a.obj {
            f.extend((0..spec.frames).map(|k| format!("{prefix}obj/{}", obj_frame_name(k))));
        }
        f
    };
    let files = if a.pair { [run("lr/"), run("hr/")].concat() } else { run("") };
    Ownership {
        job: "simulate",
        noun: "scene",
        inputs,
        settings: settings.into(),
        summary: "simulate.json".into(),
        files,
    }
}

pub fn run(a: Args) -> Result<()> {
    if let Some(g) = Garment::from_name(&a.scenario) {
        return run_garment(&a, g);
    }
    let spec = spec_from_args(&a)?;
    let own = ownership(&a, &spec);
    let claim = folder::claim(&a.out, &own, a.overwrite)?;
    for n in &claim.removed {
        eprintln!("note: removed {n}, an earlier run's output that this run does not write");
    }
    own.write_summary(&a.out, Object::new(), false)?;
    let t0 = std::time::Instant::now();
    if a.pair {
        let pb = progress(2 * spec.frames as u64, "simulate");
        pb.set_message(format!(
            "{} {}x{} + {}x{}",
            spec.scenario,
            spec.w,
            spec.h,
            spec.scale * spec.w,
            spec.scale * spec.h
        ));
        let (lr, hr) = paired_run_with_progress(&spec, &mut |k| pb.set_position(k as u64 + 1))?;
        pb.finish_and_clear();
        let pair = write_pair(&a.out, &spec, &lr, &hr, a.obj)?;
        write_preview(&a.out.join("lr"), &pair.lr)?;
        write_preview(&a.out.join("hr"), &pair.hr)?;
        eprintln!(
            "simulated {} pair {}x{} / {}x{}, {} frames in {:.1} s → {}/{{lr,hr}}",
            spec.scenario,
            spec.w,
            spec.h,
            hr[0].w,
            hr[0].h,
            spec.frames,
            t0.elapsed().as_secs_f32(),
            a.out.display()
        );
    } else {
        let pb = progress(spec.frames as u64, "simulate");
        pb.set_message(format!("{} {}x{}", spec.scenario, spec.w, spec.h));
        let frames = run_at(&spec, spec.w, spec.h, None, &mut |k| pb.set_position(k as u64 + 1))?;
        pb.finish_and_clear();
        let images = write_single(&a.out, &spec, &frames, a.obj)?;
        write_preview(&a.out, &images)?;
        eprintln!(
            "simulated {} {}x{}, {} frames in {:.1} s → {}",
            spec.scenario,
            spec.w,
            spec.h,
            spec.frames,
            t0.elapsed().as_secs_f32(),
            a.out.display()
        );
    }
    // No timings: two runs of one scene leave the same bytes.
    own.write_summary(&a.out, Object::new(), true)?;
    drop(claim);
    Ok(())
}
