//! `anisocb eval`: anisocb against the methods a user would otherwise use, on held-out runs,
//! as numbers (markdown + JSON tables), per-frame plots, error renders and close-ups where the
//! truth's folds are (`--flipbook`: animated); `--speed` adds the study of (LR simulation +
//! upscaling) vs HR simulation.
//!
//! This file parses, prints and draws: which methods run and how, their scores, the tables
//! and the speed study are the library's ([`crate::eval::methods`], [`crate::eval::report`],
//! [`crate::eval::speed`]).

use super::setup::{load_geometry_net, load_model, set_threads};
use super::ui::{progress, save_apng, save_png};
use crate::cloth::run_io::{pair_dir, pair_label, read_pair};
use crate::error::Result;
use crate::eval::invariance::invariance_markdown;
use crate::eval::linear::LinearUpsampler;
use crate::eval::mesh::{evaluate_mesh_run, mesh_markdown, triangles, MeshRun, MeshRunEval, MeshScores};
use crate::eval::methods::{default_method, evaluate_run, Contenders, EvalOptions, Method, RunEval, PHYSICS};
use crate::eval::metrics::vertex_errors;
use crate::eval::report::{cells_json, results_document, Cell};
use crate::eval::speed::speed_study;
use crate::geom::GridMesh;
use crate::io::json::{write_json, Layout, Object, Value};
use crate::io::write_atomic_bytes;
use crate::nn::bundle::AnisoCb;
use crate::ops::Precision;
use crate::pipeline::folder::{self, Ownership};
use crate::viz::closeup;
use crate::viz::heat::{render_heat_row, scale_max, ScalarColors};
use crate::viz::image::vstack;
use crate::viz::plot::LinePlot;
use crate::viz::render::{Shading, Tile, View};
use crate::viz::sheet::pick_frames;
use std::path::{Path, PathBuf};

#[derive(clap::Args, Debug)]
#[command(after_help = "Methods compared (all on the same held-out runs, against their HR run):
  bicubic            the LR geometry image interpolated x2 (align corners), Keys a = -0.75 (PyTorch's bicubic)
  catmull-rom        the same with a = -0.5 (Catmull-Rom), which keeps evenly spaced vertices evenly spaced
  linear             learned linear upsampler (Kavan et al. 2011 spirit), U + ridge regression (--linear FILE)
  GeometryNet [NAME] one residual SR net alone, U + R (--prior FILE): the prior method (Chen et al. 2018
                     style), or weights/domain-x2.npz, GeometryNet trained in the paper's domain frame
  anisocb [NAME]     another anisocb bundle, e.g. one trained in the paper's domain frame (--also FILE)
  anisocb -boundary  anisocb without BoundaryNet: U + (1 + eta Ge) R
  anisocb eta=E      anisocb in full, Eq 12, for each --eta value
  anisocb paper      the paper-size config (--paper FILE), eta = default

Example (the headline table: README, commands in docs/results.md):
  anisocb simulate --scenario flag-sphere --pair --seed 1000 --frames 120 --tracking 1000 --track vertex --out runs/flag-sphere
  anisocb simulate --scenario twist-zero-g --res 32x32 --pair --seed 1000 --frames 120 --tracking 1000 --track vertex --out runs/twist-zero-g
  anisocb eval --runs runs/* --prior weights/domain-x2.npz --linear weights/linear-x2.npz --moved --out eval-out")]
pub struct Args {
    /// Held-out run pairs (`anisocb simulate --pair --out DIR`).
    #[arg(long, required_unless_present = "meshes", num_args = 1..)]
    pub runs: Vec<PathBuf>,
    /// Held-out runs of meshes that are not grids (garments): each DIR holds `lr/` and `hr/`
    /// OBJ frames (the HR run is the LR mesh subdivided once, simulated on its own) and
    /// optionally `collider/` (a closed mesh per frame). Compares the linear, smooth and curved
    /// (the base of anisocb's detail) subdivisions with anisocb (vertex errors, normals, wrinkle
    /// detail and its flicker against the HR run's, penetration): `meshes.md`, `meshes.json`
    /// (research/blender/make_garments.py makes such runs with Blender's cloth).
    #[arg(long, num_args = 1..)]
    pub meshes: Vec<PathBuf>,
    /// Output directory: created if missing, or empty, or one that an earlier evaluation of
    /// the same runs owns, as its eval.json says (the files it wrote and this run does not are
    /// removed); anything else there is refused (see --overwrite). One run at a time writes it
    /// (a lock).
    #[arg(long, default_value = "eval-out")]
    pub out: PathBuf,
    /// Write into --out even though it holds files no evaluation of these runs wrote (those
    /// this run writes are replaced, the rest left).
    #[arg(long)]
    pub overwrite: bool,
    /// anisocb weights (default: the embedded model).
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// A GeometryNet used alone (U + R): the prior method's setup, e.g. weights/domain-x2.npz
    /// (trained on the paper's Eq 1 normalisation).
    #[arg(long)]
    pub prior: Option<PathBuf>,
    /// A paper-size (C=64, 10 blocks) anisocb bundle to compare with the small one.
    #[arg(long)]
    pub paper: Option<PathBuf>,
    /// The learned linear upsampler (`anisocb train --net linear`), the cheap yardstick.
    #[arg(long)]
    pub linear: Option<PathBuf>,
    /// More anisocb bundles to compare (e.g. trained with `dataset --input-frame domain`),
    /// labelled by file name.
    #[arg(long, num_args = 1..)]
    pub also: Vec<PathBuf>,
    /// Also upscale each run moved (falling 4 m), turned (about a tilted axis, by a different
    /// angle each frame) and scaled (differently each frame), and report how far the output
    /// is from the unmoved output transformed the same way (invariance.md).
    #[arg(long)]
    pub moved: bool,
    /// Enhancement factors η to evaluate, comma-separated.
    #[arg(long, value_delimiter = ',', default_values_t = vec![0.0, 0.5, 1.0])]
    pub eta: Vec<f32>,
    /// Worst frames rendered per scenario.
    #[arg(long, default_value_t = 2)]
    pub worst: usize,
    /// Also write `<scenario>-flipbook.png`: an animated PNG (15 fps) of the close-up window
    /// where the truth's middle frame has the most wrinkle detail, LR | Catmull-Rom | anisocb |
    /// HR, every frame (every 2nd above 60).
    #[arg(long)]
    pub flipbook: bool,
    /// Also evaluate the physics pass (`upscale --physics`, default settings) on the default
    /// model's frames, with each run's gravity, frame rate and material from its meta.json and
    /// its scenario's held edges (`--physics-pin`), as the artist of the shot would give them;
    /// the close-ups and flip-book then show it too (`<scenario>-wrinkles-physics.png`, …).
    #[arg(long)]
    pub physics: bool,
    /// Also run the speed study (LR sim + upscale vs HR sim at 32, 64, 128 LR grids).
    #[arg(long)]
    pub speed: bool,
    /// Worker threads, 1 to 1024 (default: all cores).
    #[arg(long, value_parser = super::setup::parse_threads)]
    pub threads: Option<usize>,
    /// Compute device: cpu or cuda.
    #[arg(long, default_value = "cpu")]
    pub device: String,
    /// The nets' arithmetic in every anisocb row, as `upscale --precision`: auto (what upscale
    /// runs here by default), fp32, fp32-fast, bf16 or fp16.
    #[arg(long, default_value = "auto", value_parser = ["auto", "fp32", "fp32-fast", "bf16", "fp16"])]
    pub precision: String,
}

pub fn run(a: Args) -> Result<()> {
    set_threads(a.threads)?;
    let ops = crate::cuda::ops_for_device(&a.device)?;
    let precision = Precision::resolve(&a.precision, ops.as_ref())?;
    let model = load_model(a.weights.as_deref())?;
    let own = ownership(&a, &model, ops.name(), precision)?;
    let claim = folder::claim(&a.out, &own, a.overwrite)?;
    for n in &claim.removed {
        eprintln!("note: removed {n}, an earlier run's output that this run does not write");
    }
    own.write_summary(&a.out, Object::new(), false)?;
    if !a.meshes.is_empty() {
        let params = crate::sr::params::UpscaleParams { precision, ..Default::default() };
        let mut rows = Vec::new();
        let pb = progress(a.meshes.len() as u64, "eval meshes");
        for dir in &a.meshes {
            let run = MeshRun::read(dir)?;
            let physics = a.physics.then(crate::cloth::follow::FollowParams::blender_shot);
            let e = evaluate_mesh_run(ops.as_ref(), &model, &params, &run, physics.as_ref())?;
            write_mesh_pictures(&a.out, &run, &e)?;
            write_mesh_closeups(&a.out, &run, &e, a.flipbook)?;
            rows.push((run.name.clone(), e.scores));
            pb.inc(1);
        }
        pb.finish_and_clear();
        let md = mesh_markdown(&rows);
        write_atomic_bytes(&a.out.join("meshes.md"), md.as_bytes())?;
        write_json(&a.out.join("meshes.json"), &mesh_json(&rows), Layout::Rows)?;
        println!("{md}");
        println!(
            "wrote {}/: meshes.md, meshes.json, <run>-meshes.png (LR | the subdivisions | anisocb | HR run, \
             middle and last frame, the collider in grey; the second picture shaded by normals), \
             <run>-closeup.png (the window of most wrinkle detail, three frames){}",
            a.out.display(),
            if a.flipbook { ", <run>-flipbook.png (that window animated)" } else { "" }
        );
        if a.runs.is_empty() {
            own.write_summary(&a.out, Object::new(), true)?;
            drop(claim);
            return Ok(());
        }
    }
    let others = Contenders {
        prior: a.prior.as_deref().map(|p| Ok((stem(p), load_geometry_net(p)?))).transpose()?,
        paper: a.paper.as_deref().map(AnisoCb::load).transpose()?,
        linear: a.linear.as_deref().map(LinearUpsampler::load).transpose()?,
        also: a.also.iter().map(|p| Ok((stem(p), AnisoCb::load(p)?))).collect::<Result<_>>()?,
    };
    let opts = EvalOptions { etas: a.eta.clone(), physics: a.physics, moved: a.moved, precision };
    let mut invariance = Vec::new();
    let mut cells = Vec::new();
    let pb = progress(a.runs.len() as u64, "eval");
    for dir in &a.runs {
        let run = evaluate_run(ops.as_ref(), &model, &others, &read_pair(dir)?, &opts)?;
        write_pictures(&a, &run)?;
        invariance.extend(run.invariance);
        cells.extend(run.cells);
        pb.inc(1);
    }
    pb.finish_and_clear();
    let runs: Vec<String> = a.runs.iter().map(|p| p.display().to_string()).collect();
    let md = results_document(&runs, &cells);
    write_atomic_bytes(&a.out.join("results.md"), md.as_bytes())?;
    if a.moved {
        let inv = invariance_markdown(&invariance);
        write_atomic_bytes(&a.out.join("invariance.md"), inv.as_bytes())?;
        println!("{inv}");
    }
    write_json(&a.out.join("results.json"), &cells_json(&cells), Layout::Rows)?;
    println!("{md}");
    if a.speed {
        let s = speed_study(ops.as_ref(), &model)?;
        write_atomic_bytes(&a.out.join("speed.md"), s.as_bytes())?;
        println!("{s}");
    }
    println!(
        "wrote {}/: results.md, results.json, <scenario>-rmse.png, <scenario>-worst.png, \
         <scenario>-wrinkles.png (close-ups where the truth's folds are, normal shading){}",
        a.out.display(),
        if a.flipbook { ", <scenario>-flipbook.png (animated close-up)" } else { "" }
    );
    own.write_summary(&a.out, Object::new(), true)?;
    drop(claim);
    Ok(())
}

/// Who this run is for its output folder ([`folder::claim`]): the runs, the settings that
/// decide the tables and pictures (the weights by a checksum), and every file it writes (the
/// pictures are named by each run's label, known before the run is read).
fn ownership(a: &Args, model: &AnisoCb, device: &str, precision: Precision) -> Result<Ownership> {
    let paths =
        |v: &[PathBuf]| Value::from(folder::canonical(v).into_iter().map(Value::from).collect::<Vec<_>>());
    let one = |p: &Option<PathBuf>| p.as_ref().map_or(Value::Null, |p| paths(std::slice::from_ref(p)));
    let settings = Object::new()
        .str("weights", &format!("{:016x}", model.checksum()))
        .val("prior", one(&a.prior))
        .val("paper", one(&a.paper))
        .val("linear", one(&a.linear))
        .val("also", paths(&a.also))
        .val("moved", Value::Bool(a.moved))
        .val("eta", Value::reals(&a.eta))
        .num("worst", a.worst)
        .val("flipbook", Value::Bool(a.flipbook))
        .val("physics", Value::Bool(a.physics))
        .val("speed", Value::Bool(a.speed))
        .str("device", device)
        .str("precision", precision.name());
    let mut files = Vec::new();
    if !a.meshes.is_empty() {
        files.extend(["meshes.md", "meshes.json"].map(String::from));
        files.extend(a.meshes.iter().map(|d| format!("{}-meshes.png", MeshRun::name_of(d))));
    }
    if !a.runs.is_empty() {
        files.extend(["results.md", "results.json"].map(String::from));
        for (on, name) in [(a.moved, "invariance.md"), (a.speed, "speed.md")] {
            if on {
                files.push(name.into());
            }
        }
        for dir in &a.runs {
            let label = pair_label(&pair_dir(dir)?);
            files.push(format!("{label}-rmse.png"));
            if a.worst > 0 {
                files.push(format!("{label}-worst.png"));
            }
            for (on, suffix) in [(true, ""), (a.physics, "-physics")] {
                if on {
                    files.push(format!("{label}-wrinkles{suffix}.png"));
                    if a.flipbook {
                        files.push(format!("{label}-flipbook{suffix}.png"));
                    }
                }
            }
        }
    }
    files.sort();
    files.dedup();
    Ok(Ownership {
        job: "eval",
        noun: "set of runs",
        inputs: folder::canonical(&[a.runs.clone(), a.meshes.clone()].concat()),
        settings: settings.into(),
        summary: "eval.json".into(),
        files,
    })
}

/// `<run>-meshes.png`: for the middle and the last frame, the LR frame and every method's HR
/// frame side by side (one camera for all), the collider in grey; below, the same shaded by
/// normals, where folds and faceting show.
fn write_mesh_pictures(out: &Path, run: &MeshRun, e: &MeshRunEval) -> Result<()> {
    use crate::viz::render::{render_layers, Camera, Layer, PROP_TINT};
    let t = run.lr.frames.len();
    let (lr_tris, hr_tris) = (triangles(&run.lr.faces), triangles(&e.hr_faces));
    let col_tris = run.collider.as_ref().map(|c| triangles(&c.faces));
    let one_row = |p: &[[f32; 3]]| GridMesh::new(p.len(), 1, p.to_vec());
    let view = View::default();
    let mut rows = Vec::new();
    for look in [Shading::default(), Shading::normals(1.5)] {
        for f in [t / 2, t - 1] {
            let mut all: Vec<[f32; 3]> = run.lr.frames[f].clone();
            for (_, m) in &e.frames {
                all.extend_from_slice(&m[f]);
            }
            let (lo, hi) = crate::geom::mesh::bounds(&all);
            let cam = Camera::fit(&view, lo, hi, 320, 320)?;
            let prop = run.collider.as_ref().map(|c| one_row(&c.frames[f.min(c.frames.len() - 1)]));
            let mut tiles = Vec::new();
            let mut tile = |pos: &[[f32; 3]], tris: &[[usize; 3]], label: &str| -> Result<()> {
                let m = one_row(pos);
                let mut layers = vec![Layer { tris: Some(tris), mesh: &m, colors: None, tint: None }];
                if let (Some(p), Some(ct)) = (&prop, &col_tris) {
                    layers.push(Layer { tris: Some(ct), mesh: p, colors: None, tint: Some(PROP_TINT) });
                }
                let mut pic = render_layers(&layers, &cam, &look)?;
                pic.label(&format!("{label}, frame {f}"), 1);
                tiles.push(pic);
                Ok(())
            };
            tile(&run.lr.frames[f], &lr_tris, "LR")?;
            for (name, m) in &e.frames {
                tile(&m[f], &hr_tris, name)?;
            }
            rows.push(crate::viz::image::hstack(&tiles, 6, [255; 3]));
        }
    }
    save_png(&out.join(format!("{}-meshes.png", run.name)), &vstack(&rows, 6, [255; 3]))
}

/// `<run>-closeup.png`: the window around the HR vertex where the truth's middle frame has the
/// most wrinkle detail (a fifth of the cloth's size across), at three frames of the second half,
/// LR | every method | HR run, under a raking light; the camera follows the truth's window
/// frame by frame, so cloth that moves as a whole stands still and detail that swims shows.
/// With `flipbook`, `<run>-flipbook.png`: that row for every frame (every 2nd above 60),
/// animated.
fn write_mesh_closeups(out: &Path, run: &MeshRun, e: &MeshRunEval, flipbook: bool) -> Result<()> {
    use crate::eval::mesh::mesh_detail;
    use crate::viz::render::{render_layers, Camera, Layer, PROP_TINT};
    let truth = &run.hr;
    let t = truth.len();
    let lr_n = run.lr.frames[0].len();
    let sub = crate::geom::surface::Subdivision::of(lr_n, &run.lr.faces);
    let mid = t / 2;
    let d = mesh_detail(&sub, lr_n, &truth[mid]);
    let centre = (lr_n..d.len()).max_by(|&a, &b| d[a].abs().total_cmp(&d[b].abs())).unwrap_or(0);
    let (lo, hi) = crate::geom::mesh::bounds(&truth[mid]);
    let radius = 0.1 * (0..3).map(|k| hi[k] - lo[k]).fold(0.0f32, f32::max);
    let c = truth[mid][centre];
    let window: Vec<usize> =
        (0..truth[mid].len()).filter(|&v| crate::geom::mesh::dist(truth[mid][v], c) < radius).collect();
    let (lr_tris, hr_tris) = (triangles(&run.lr.faces), triangles(&e.hr_faces));
    let col_tris = run.collider.as_ref().map(|c| triangles(&c.faces));
    let one_row = |p: &[[f32; 3]]| GridMesh::new(p.len(), 1, p.to_vec());
    let row = |k: usize, size: usize| -> Result<Vec<crate::viz::image::Rgb8>> {
        let pts: Vec<[f32; 3]> = window.iter().map(|&v| truth[k][v]).collect();
        let (lo, hi) = crate::geom::mesh::bounds(&pts);
        let cam = Camera::fit(&View::default(), lo, hi, size, size)?;
        let prop = run.collider.as_ref().map(|c| one_row(&c.frames[k.min(c.frames.len() - 1)]));
        let tile = |pos: &[[f32; 3]], tris: &[[usize; 3]], label: &str| -> Result<crate::viz::image::Rgb8> {
            let m = one_row(pos);
            let mut layers = vec![Layer { tris: Some(tris), mesh: &m, colors: None, tint: None }];
            if let (Some(p), Some(ct)) = (&prop, &col_tris) {
                layers.push(Layer { tris: Some(ct), mesh: p, colors: None, tint: Some(PROP_TINT) });
            }
            let mut pic = render_layers(&layers, &cam, &Shading::default())?;
            pic.label(&format!("{label}, frame {k}"), 1);
            Ok(pic)
        };
        let mut tiles = vec![tile(&run.lr.frames[k], &lr_tris, "LR")?];
        for (name, m) in &e.frames {
            tiles.push(tile(&m[k], &hr_tris, name)?);
        }
        Ok(tiles)
    };
    let rows = pick_frames(t, 3).into_iter().map(|k| row(k, 240)).collect::<Result<Vec<_>>>()?;
    save_png(
        &out.join(format!("{}-closeup.png", run.name)),
        &crate::viz::sheet::sheet(&rows, 6, 0, [255; 3]),
    )?;
    if flipbook {
        let step = if t > 60 { 2 } else { 1 };
        let pics = (0..t)
            .step_by(step)
            .map(|k| Ok(crate::viz::image::hstack(&row(k, 200)?, 6, [255; 3])))
            .collect::<Result<Vec<_>>>()?;
        save_apng(&out.join(format!("{}-flipbook.png", run.name)), &pics, FLIPBOOK_FPS)?;
    }
    Ok(())
}

/// The mesh runs' scores as JSON rows (metres, degrees, shares).
fn mesh_json(rows: &[(String, Vec<MeshScores>)]) -> crate::io::json::Value {
    use crate::io::json::{Object, Value};
    let r: Vec<Value> = rows
        .iter()
        .flat_map(|(name, scores)| {
            scores.iter().map(move |s| {
                Object::new()
                    .str("run", name)
                    .str("method", &s.method)
                    .num("rmse_m", s.rmse)
                    .num("max_error_m", s.max_error)
                    .num("velocity_error_m", s.velocity_error)
                    .num("normal_deg", s.normal_deg)
                    .num("border_ratio", s.border_ratio)
                    .num("detail_m", s.detail)
                    .num("flicker_m", s.flicker)
                    .num("inside_share", s.inside)
                    .num("deepest_m", s.depth)
                    .into()
            })
        })
        .collect();
    Value::Arr(r)
}

/// One run's pictures: `<scenario>-rmse.png`, `-worst.png` (with `--worst`), `-wrinkles.png`
/// (and `-flipbook.png`), the physics pass's close-ups with `--physics`.
fn write_pictures(a: &Args, run: &RunEval) -> Result<()> {
    let (out, scenario) = (&a.out, &run.scenario);
    write_plots(out, scenario, &run.cells)?;
    if a.worst > 0 {
        write_worst_renders(out, scenario, &run.lr, &run.methods, &run.hr, &run.cells, a.worst)?;
    }
    let ours = default_method();
    write_closeups(out, scenario, &run.lr, &run.methods, &run.hr, (&ours, ""), a.flipbook)?;
    if a.physics {
        write_closeups(out, scenario, &run.lr, &run.methods, &run.hr, (PHYSICS, "-physics"), a.flipbook)?;
    }
    Ok(())
}

fn write_plots(out: &Path, scenario: &str, rows: &[Cell]) -> Result<()> {
    let mut pics = Vec::new();
    for (title, pick) in [("vertex RMSE per frame (mm)", 0usize), ("boundary RMSE per frame (mm)", 1usize)] {
        let mut plot = LinePlot::new(&format!("{scenario}: {title}")).labels("frame", "mm");
        for c in rows {
            let ys: Vec<f32> = c.metrics.per_frame.iter().map(|f| 1e3 * f.values()[pick]).collect();
            plot = plot.series_y(&c.method, &ys);
        }
        pics.push(plot.render(720, 360)?);
    }
    let img = vstack(&pics, 8, [255; 3]);
    save_png(&out.join(format!("{scenario}-rmse.png")), &img)
}

fn write_worst_renders(
    out: &Path,
    scenario: &str,
    lr: &[GridMesh],
    methods: &[Method],
    hr: &[GridMesh],
    rows: &[Cell],
    worst: usize,
) -> Result<()> {
    // Worst frames of the full anisocb at the default η (the method a user runs).
    let target = default_method();
    let idx = rows.iter().position(|c| c.method == target).unwrap_or(rows.len() - 1);
    let frames = rows[idx].metrics.worst_frames(worst);
    let shown: Vec<&Method> = methods
        .iter()
        .filter(|m| m.name == "bicubic" || m.name.starts_with("linear") || m.name == target)
        .collect();
    let (view, shade) = (View::default(), Shading::default());
    let mut pics = Vec::new();
    for &k in &frames {
        let errs: Vec<Vec<f32>> = shown
            .iter()
            .map(|m| Ok(vertex_errors(&m.meshes[k], &hr[k])?.iter().map(|v| 1e3 * v).collect()))
            .collect::<Result<_>>()?;
        let hi = scale_max(errs.iter().flatten(), 1e-3);
        let lr_label = format!("LR frame {k}");
        let mut tiles = vec![Tile { mesh: &lr[k], label: &lr_label, colors: None }];
        for (m, e) in shown.iter().zip(&errs) {
            tiles.push(Tile {
                mesh: &m.meshes[k],
                label: &m.name,
                colors: Some(ScalarColors { values: e, lo: 0.0, hi }),
            });
        }
        tiles.push(Tile { mesh: &hr[k], label: "HR (truth)", colors: None });
        pics.push(render_heat_row(&tiles, &view, &shade, (260, 260), 6, (0.0, hi), "err mm")?);
    }
    let img = vstack(&pics, 6, [255; 3]);
    save_png(&out.join(format!("{scenario}-worst.png")), &img)
}

/// `{scenario}-wrinkles{suffix}.png`: close-ups of 3 frames where the truth has the most
/// wrinkle detail, LR | Catmull-Rom | the method `shown.0` (the default model at the default
/// η, or the physics pass) | HR; with `flipbook` also `{scenario}-flipbook{suffix}.png`, the
/// animated close-up of the whole run.
fn write_closeups(
    out: &Path,
    scenario: &str,
    lr: &[GridMesh],
    methods: &[Method],
    hr: &[GridMesh],
    (method, suffix): (&str, &str),
    flipbook: bool,
) -> Result<()> {
    let find = |name: &str| methods.iter().find(|m| m.name == name).map(|m| &m.meshes[..]);
    let (Some(cr), Some(ours)) = (find("catmull-rom"), find(method)) else {
        return Ok(());
    };
    let seq: Vec<closeup::Frame> = (0..hr.len())
        .map(|k| closeup::Frame {
            lr: &lr[k],
            catmull_rom: &cr[k],
            ours: &ours[k],
            ours_label: method,
            truth: &hr[k],
        })
        .collect();
    let shown: Vec<(usize, closeup::Frame)> =
        pick_frames(hr.len(), 3).into_iter().map(|k| (k, seq[k])).collect();
    let img = closeup::closeup_rows(&shown, closeup::CLOSEUP_LR_SIZE, 256)?;
    save_png(&out.join(format!("{scenario}-wrinkles{suffix}.png")), &img)?;
    if flipbook {
        let pics = closeup::flipbook_frames(&seq, closeup::CLOSEUP_LR_SIZE, 200)?;
        save_apng(&out.join(format!("{scenario}-flipbook{suffix}.png")), &pics, FLIPBOOK_FPS)?;
    }
    Ok(())
}

/// Frame rate of the flip-books: the runs are at 30 fps, so every 2nd frame (runs over 60
/// frames) plays in real time.
const FLIPBOOK_FPS: u16 = 15;

fn stem(p: &Path) -> String {
    p.file_stem().unwrap_or_default().to_string_lossy().into_owned()
}
