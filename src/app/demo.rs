//! `anisocb demo`: simulate a held-out scenario at LR and HR, upscale the LR run with the
//! embedded weights, compare bicubic interpolation and anisocb against the HR run, and write
//! OBJ sequences, a metrics table and pictures to `demo-out/`.

use super::setup::{load_model, set_threads};
use super::ui::{progress, save_png};
use crate::cloth::follow::{FollowParams, Follower};
use crate::cloth::run_io::{obj_frame_name, write_pair, RUN_FILES};
use crate::cloth::scenarios::{paired_run_with_progress, Scenario, ScenarioSpec, SCENARIO_HELP};
use crate::error::Result;
use crate::eval::methods::PHYSICS;
use crate::eval::metrics::{border_mask, sequence_metrics, vertex_errors, wrinkle_stats, SequenceMetrics};
use crate::eval::report::{metrics_table, Column};
use crate::geom::geometry_image::images_to_sequence;
use crate::geom::obj::write_obj_grid;
use crate::geom::GridMesh;
use crate::io::atomic::ensure_dir;
use crate::io::json::{write_json, Layout, Object};
use crate::io::write_atomic_bytes;
use crate::nn::geometry_net::interpolate;
use crate::ops::Interp;
use crate::pipeline::folder::{self, Ownership};
use crate::sr::compose::DEFAULT_ETA;
use crate::sr::params::UpscaleParams;
use crate::sr::upscale::upscale_images;
use crate::tensor::Tensor;
use crate::viz::closeup;
use crate::viz::heat::{render_heat_row, scale_max, ScalarColors};
use crate::viz::image::{hstack, image_rgb8, upscale_nearest, vstack, Rgb8};
use crate::viz::render::{render_row, Shading, Tile, View};
use crate::viz::sheet::pick_frames;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The scenario the shipped weights never saw in training (see weights/README.md).
pub const HELD_OUT_SCENARIO: &str = "flag-sphere";
/// Its seed (training runs use seeds 1..=N of the other scenarios).
pub const HELD_OUT_SEED: u64 = 1000;

#[derive(clap::Args, Debug)]
#[command(after_help = SCENARIO_HELP)]
pub struct Args {
    /// Output directory: created if missing, or empty, or one that an earlier demo of the same
    /// scene (scenario, seed) owns, as its demo.json says; anything else there is refused (see
    /// --overwrite). One run at a time writes it (a lock).
    #[arg(long, default_value = "demo-out")]
    pub out: PathBuf,
    /// Write into --out even though it holds files no demo of this scene wrote (those this run
    /// writes are replaced, the rest left).
    #[arg(long)]
    pub overwrite: bool,
    /// Scenario to simulate (the default is held out of the shipped model's training data).
    #[arg(long, default_value = HELD_OUT_SCENARIO)]
    pub scenario: String,
    /// Frames to simulate (at 30 fps).
    #[arg(long, default_value_t = 120)]
    pub frames: usize,
    /// Random seed of the scenario (wind gusts, perturbations).
    #[arg(long, default_value_t = HELD_OUT_SEED)]
    pub seed: u64,
    /// Wrinkle enhancement η ≥ 0 (Eq 12).
    #[arg(long, default_value_t = DEFAULT_ETA)]
    pub eta: f32,
    /// HR→LR tracking strength of the ground-truth run, 1/s² (see `anisocb simulate --help`).
    #[arg(long)]
    pub tracking: Option<f32>,
    /// Weights file instead of the embedded model.
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// Worker threads, 1 to 1024 (default: all cores).
    #[arg(long, value_parser = super::setup::parse_threads)]
    pub threads: Option<usize>,
    /// Compute device: cpu or cuda.
    #[arg(long, default_value = "cpu")]
    pub device: String,
}

/// Mean metrics of one method, in millimetres where lengths.
pub struct Row {
    pub method: String,
    pub metrics: SequenceMetrics,
}

/// The columns of the demo's table (lengths in mm).
pub const COLUMNS: [Column; 9] = [
    Column::Rmse,
    Column::BoundaryRmse,
    Column::Hausdorff,
    Column::BorderLengthRatio,
    Column::NormalAngle,
    Column::Flicker,
    Column::StedTemporal,
    Column::WrinkleRatio,
    Column::WrinkleCorr,
];

pub fn run(a: Args) -> Result<()> {
    set_threads(a.threads)?;
    let t0 = Instant::now();
    let ops = crate::cuda::ops_for_device(&a.device)?;
    let model = load_model(a.weights.as_deref())?;
    let mut spec = ScenarioSpec::new(Scenario::from_name(&a.scenario)?);
    spec.frames = a.frames;
    spec.seed = a.seed;
    spec.scale = model.scale();
    if let Some(t) = a.tracking {
        spec.tracking = t;
    }
    spec.validate()?;
    let own = ownership(&a, &spec, &model, ops.name());
    let claim = folder::claim(&a.out, &own, a.overwrite)?;
    for n in &claim.removed {
        eprintln!("note: removed {n}, an earlier run's output that this run does not write");
    }
    own.write_summary(&a.out, Object::new(), false)?;

    // 1. Simulate the pair (HR is the ground truth).
    let pb = progress(2 * spec.frames as u64, "simulate");
    let (lr, hr) = paired_run_with_progress(&spec, &mut |k| pb.set_position(k as u64))?;
    pb.finish_and_clear();
    let sim_s = t0.elapsed().as_secs_f64();
    let pair = write_pair(&a.out.join("sim"), &spec, &lr, &hr, false)?;
    let domain = pair.domain;

    // 2. Upscale.
    let t1 = Instant::now();
    let pb = progress(spec.frames as u64, "upscale");
    // All three nets run, whatever --eta: maps.png shows Γe.
    let params = UpscaleParams { enhance_map: true, ..UpscaleParams::default() };
    let up =
        upscale_images(ops.as_ref(), &model, &pair.lr, &domain, &params, &mut |k| pb.set_position(k as u64))?;
    pb.finish_and_clear();
    let up_s = t1.elapsed().as_secs_f64();
    let ours_img = up.with_eta(a.eta)?;
    let ours = images_to_sequence(&ours_img, &domain);
    // The yardstick: PyTorch's bicubic (Keys a = −0.75), whatever U the model refines.
    let keys = interpolate(ops.as_ref(), &pair.lr, model.scale(), Interp::Bicubic);
    let bicubic = images_to_sequence(&keys, &domain);
    // The better cubic: Catmull-Rom (a = −0.5), the U the shipped model refines.
    let cr =
        images_to_sequence(&interpolate(ops.as_ref(), &pair.lr, model.scale(), Interp::CatmullRom), &domain);
    // The physics pass (`upscale --physics`, opt in) on anisocb's frames, told the scene's
    // gravity, frame rate, material and held edges as its artist would tell it.
    let physics = Follower::run(&ours, (lr[0].w, lr[0].h), &FollowParams::for_run(&pair.meta))?;

    // 3. Metrics against the HR run.
    let mask = border_mask(hr[0].w, hr[0].h);
    // Wrinkle detail is what the LR grid cannot hold (docs/research/wrinkles.md).
    let metrics_of = |seq: &[GridMesh]| -> Result<SequenceMetrics> {
        let mut m = sequence_metrics(seq, &hr, Some(&mask))?;
        m.wrinkle = Some(wrinkle_stats(seq, &hr, lr[0].w, lr[0].h)?);
        Ok(m)
    };
    let mut rows = vec![
        Row { method: "bicubic interpolation".into(), metrics: metrics_of(&bicubic)? },
        Row { method: "catmull-rom interpolation".into(), metrics: metrics_of(&cr)? },
    ];
    if a.eta != 0.0 {
        let plain = images_to_sequence(&up.with_eta(0.0)?, &domain);
        rows.push(Row { method: "anisocb, η = 0".into(), metrics: metrics_of(&plain)? });
    }
    rows.push(Row { method: format!("anisocb, η = {}", a.eta), metrics: metrics_of(&ours)? });
    rows.push(Row { method: PHYSICS.into(), metrics: metrics_of(&physics)? });
    let table = metrics_table(rows.iter().map(|r| (r.method.as_str(), &r.metrics)), &COLUMNS);
    let header = format!(
        "anisocb demo: scenario `{}` (seed {}, held out of training), {} frames, LR {}x{} -> HR {}x{}\n\
         simulation (LR + HR) {:.1} s, upscaling {:.1} s ({:.1} ms/frame, {})\n\n",
        spec.scenario,
        spec.seed,
        spec.frames,
        lr[0].w,
        lr[0].h,
        hr[0].w,
        hr[0].h,
        sim_s,
        up_s,
        1e3 * up_s / spec.frames as f64,
        ops.name()
    );
    write_atomic_bytes(&a.out.join("metrics.md"), format!("{header}{table}").as_bytes())?;
    let methods = rows.iter().fold(Object::new(), |o, r| o.val(&r.method, r.metrics.to_value()));
    let json = Object::new()
        .str("scenario", spec.scenario.name())
        .num("seed", spec.seed)
        .num("frames", spec.frames)
        .num("eta", a.eta)
        .val("methods", methods);
    write_json(&a.out.join("metrics.json"), &json.into(), Layout::Compact)?;

    // 4. OBJ sequences.
    let pb = progress(5 * spec.frames as u64, "write obj");
    let seqs = [&lr, &hr, &bicubic, &ours, &physics];
    for (name, seq) in OBJ_FOLDERS.into_iter().zip(seqs) {
        let dir = a.out.join(name);
        ensure_dir(&dir)?;
        for (k, m) in seq.iter().enumerate() {
            write_obj_grid(&dir.join(obj_frame_name(k)), m, true)?;
            pb.inc(1);
        }
    }
    pb.finish_and_clear();

    // 5. Pictures.
    let frames = pick_frames(spec.frames, 3);
    let [.., wrinkles, wrinkles_physics] = PICTURES;
    write_pictures(&a.out, &frames, &lr, &bicubic, &ours, &hr, up.boundary(), up.enhance(), &ours_img)?;
    for (seq, label, file) in [(&ours, "anisocb", wrinkles), (&physics, PHYSICS, wrinkles_physics)] {
        let shown: Vec<(usize, closeup::Frame)> = frames
            .iter()
            .map(|&k| {
                let f = closeup::Frame {
                    lr: &lr[k],
                    catmull_rom: &cr[k],
                    ours: &seq[k],
                    ours_label: label,
                    truth: &hr[k],
                };
                (k, f)
            })
            .collect();
        save_png(&a.out.join(file), &closeup::closeup_rows(&shown, closeup::CLOSEUP_LR_SIZE, 256)?)?;
    }

    println!("{header}{table}");
    let out = a.out.display();
    println!("wrote {out}/:");
    println!("  compare.png         shaded renders LR | bicubic | anisocb | HR for frames {frames:?}");
    println!("  error.png           per-vertex error (mm) of bicubic and anisocb vs HR");
    println!("  wrinkles.png        close-ups where the truth's folds are, LR | Catmull-Rom | anisocb | HR, normal shading");
    println!("  wrinkles-physics.png  the same with the physics pass (upscale --physics) in anisocb's place");
    println!("  maps.png            anisocb geometry image, predicted boundary map Γb, wrinkle map Γe");
    println!("  metrics.md, .json   the table above (per frame in the JSON)");
    println!("  lr/ hr/ bicubic/ anisocb/ anisocb-physics/   OBJ sequences (frame_0000.obj ...); sim/ the simulated runs");
    println!("total {:.1} s", t0.elapsed().as_secs_f64());
    own.write_summary(&a.out, Object::new(), true)?;
    drop(claim);
    Ok(())
}

/// The demo's OBJ sequences, one folder each: LR, HR, bicubic, anisocb, the physics pass.
const OBJ_FOLDERS: [&str; 5] = ["lr", "hr", "bicubic", "anisocb", "anisocb-physics"];
/// The demo's pictures.
const PICTURES: [&str; 5] = ["compare.png", "error.png", "maps.png", "wrinkles.png", "wrinkles-physics.png"];

/// Who this run is for its output folder ([`folder::claim`]): the scene (scenario, seed), the
/// settings that decide the output, and every file it writes.
fn ownership(a: &Args, spec: &ScenarioSpec, model: &crate::nn::bundle::AnisoCb, device: &str) -> Ownership {
    let settings = Object::new()
        .num("frames", spec.frames)
        .num("eta", a.eta)
        .num("tracking", spec.tracking)
        .str("weights", &format!("{:016x}", model.checksum()))
        .str("device", device);
    let mut files: Vec<String> = ["lr", "hr"]
        .iter()
        .flat_map(|half| RUN_FILES.iter().map(move |f| format!("sim/{half}/{f}")))
        .chain(["metrics.md", "metrics.json"].map(String::from))
        .chain(PICTURES.map(String::from))
        .collect();
    for dir in OBJ_FOLDERS {
        files.extend((0..spec.frames).map(|k| format!("{dir}/{}", obj_frame_name(k))));
    }
    Ownership {
        job: "demo",
        noun: "scene",
        inputs: vec![format!("scenario {}", spec.scenario.name()), format!("seed {}", spec.seed)],
        settings: settings.into(),
        summary: "demo.json".into(),
        files,
    }
}

#[allow(clippy::too_many_arguments)]
fn write_pictures(
    out: &Path,
    frames: &[usize],
    lr: &[GridMesh],
    bicubic: &[GridMesh],
    ours: &[GridMesh],
    hr: &[GridMesh],
    gb: &Tensor,
    ge: &Tensor,
    hr_images: &Tensor,
) -> Result<()> {
    let (view, shade) = (View::default(), Shading::default());
    let mut rows = Vec::new();
    let mut err_rows = Vec::new();
    let mut map_rows = Vec::new();
    // Per-vertex errors in mm, one colour scale for all frames.
    let mm = |p: &GridMesh, k: usize| -> Result<Vec<f32>> {
        Ok(vertex_errors(p, &hr[k])?.iter().map(|v| 1e3 * v).collect())
    };
    let errs: Vec<(Vec<f32>, Vec<f32>)> =
        frames.iter().map(|&k| Ok((mm(&bicubic[k], k)?, mm(&ours[k], k)?))).collect::<Result<_>>()?;
    let err_hi = scale_max(errs.iter().flat_map(|(b, o)| b.iter().chain(o)), 1e-3);
    for (&k, (mb, mo)) in frames.iter().zip(&errs) {
        let tiles = [
            Tile { mesh: &lr[k], label: &format!("LR  frame {k}"), colors: None },
            Tile { mesh: &bicubic[k], label: "bicubic", colors: None },
            Tile { mesh: &ours[k], label: "anisocb", colors: None },
            Tile { mesh: &hr[k], label: "HR (truth)", colors: None },
        ];
        rows.push(render_row(&tiles, &view, &shade, 320, 320, 6)?);
        let etiles = [
            Tile {
                mesh: &bicubic[k],
                label: &format!("bicubic error  frame {k}"),
                colors: Some(ScalarColors { values: mb, lo: 0.0, hi: err_hi }),
            },
            Tile {
                mesh: &ours[k],
                label: "anisocb error",
                colors: Some(ScalarColors { values: mo, lo: 0.0, hi: err_hi }),
            },
        ];
        err_rows.push(render_heat_row(&etiles, &view, &shade, (320, 320), 6, (0.0, err_hi), "err mm")?);
        let geo = image_rgb8(&hr_images.slice_batch(k, 1))?;
        let b = image_rgb8(&gb.slice_batch(k, 1))?;
        let e = image_rgb8(&ge.slice_batch(k, 1))?;
        let s = (256 / geo.h.max(1)).max(1);
        let mut tiles: Vec<Rgb8> = [geo, b, e].iter().map(|t| upscale_nearest(t, s)).collect();
        for (t, l) in
            tiles.iter_mut().zip([format!("anisocb image  frame {k}"), "boundary".into(), "wrinkles".into()])
        {
            t.label(&l, 1);
        }
        // Grey gaps: where Γb is white along the border it would vanish against white.
        map_rows.push(hstack(&tiles, 6, [128; 3]));
    }
    let [compare, error, maps, ..] = PICTURES;
    for (name, rows) in [(compare, rows), (error, err_rows), (maps, map_rows)] {
        let img = vstack(&rows, 6, [255; 3]);
        save_png(&out.join(name), &img)?;
    }
    Ok(())
}
