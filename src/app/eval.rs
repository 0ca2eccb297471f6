//! `anisocb eval`: anisocb against the methods a user would otherwise use, on held-out runs,
//! as numbers (markdown + JSON tables), per-frame plots, error renders and close-ups where the
//! truth's folds are (`--flipbook`: animated); `--speed` adds the study of (LR simulation +
//! upscaling) vs HR simulation.

use super::demo::{pick_frames, PHYSICS};
use super::setup::{load_geometry_net, load_model, set_threads};
use super::ui::{progress, save_apng, save_png};
use crate::cloth::follow::{FollowParams, Follower};
use crate::cloth::run_io::read_pair;
use crate::cloth::scenarios::{run_single, Scenario, ScenarioSpec};
use crate::error::Result;
use crate::eval::invariance::{invariance_markdown, invariance_rows};
use crate::eval::linear::LinearUpsampler;
use crate::eval::metrics::{border_band, sequence_metrics, vertex_errors, wrinkle_stats, SequenceMetrics};
use crate::eval::report::{metrics_table, Column};
use crate::geom::cloth_frame::InputFrame;
use crate::geom::geometry_image::images_to_sequence;
use crate::geom::GridMesh;
use crate::io::atomic::ensure_dir;
use crate::io::json::{write_json, Layout, Object, Value};
use crate::io::write_atomic_bytes;
use crate::nn::bundle::AnisoCb;
use crate::nn::config::NetConfig;
use crate::nn::geometry_net::{interpolate, GeometryNet};
use crate::ops::{Interp, Ops};
use crate::sr::compose::{compose, DEFAULT_ETA};
use crate::sr::params::{UpscaleParams, EVAL_STRAIN_ITERS};
use crate::sr::upscale::upscale_images;
use crate::tensor::Tensor;
use crate::viz::closeup;
use crate::viz::heat::{render_heat_row, scale_max, ScalarColors};
use crate::viz::image::vstack;
use crate::viz::plot::LinePlot;
use crate::viz::render::{Shading, Tile, View};
use std::path::{Path, PathBuf};
use std::time::Instant;

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
    #[arg(long, required = true, num_args = 1..)]
    pub runs: Vec<PathBuf>,
    /// Output directory.
    #[arg(long, default_value = "eval-out")]
    pub out: PathBuf,
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
}

/// One method's HR sequence for one run.
struct Method {
    name: String,
    meshes: Vec<GridMesh>,
}

/// One method's metrics on one scenario.
pub struct Cell {
    pub method: String,
    pub scenario: String,
    pub metrics: SequenceMetrics,
}

/// The models a run is upscaled with besides the main one.
struct Others {
    prior: Option<(String, GeometryNet)>,
    paper: Option<AnisoCb>,
    linear: Option<LinearUpsampler>,
    also: Vec<(String, AnisoCb)>,
}

/// `U + residual(frame in the residual's coordinates)` for every frame, in `domain`.
fn plus_residual(
    u: &Tensor,
    lr: &Tensor,
    domain: &crate::geom::Domain,
    input: InputFrame,
    residual: &mut dyn FnMut(&Tensor) -> Result<Tensor>,
) -> Result<Tensor> {
    let mut r = Tensor::zeros(&u.shape);
    let per = r.len() / r.shape[0];
    for k in 0..lr.shape[0] {
        let (to_net, from_net) = input.image_maps(lr, k, domain);
        let mut x = lr.slice_batch(k, 1);
        to_net.apply_image(&mut x.data, true);
        let mut rk = residual(&x)?;
        from_net.apply_image(&mut rk.data, false);
        r.data[k * per..(k + 1) * per].copy_from_slice(&rk.data);
    }
    compose(u, &r, None, None, 0.0)
}

fn methods_for_run(
    ops: &dyn Ops,
    model: &AnisoCb,
    others: &Others,
    lr: &Tensor,
    domain: &crate::geom::Domain,
    etas: &[f32],
) -> Result<Vec<Method>> {
    let p = UpscaleParams::default();
    // Every η is composed from one run of the nets, so EnhanceNet runs whatever the default η.
    let up = upscale_images(ops, model, lr, domain, &UpscaleParams { enhance_map: true, ..p }, &mut |_| {})?;
    // Each model's residual goes onto the interpolation it was trained over (its `upsample`).
    let scale = model.scale();
    let keys = interpolate(ops, lr, scale, Interp::Bicubic);
    let catmull_rom = interpolate(ops, lr, scale, Interp::CatmullRom);
    let u_of = |m: Interp| if m == Interp::CatmullRom { &catmull_rom } else { &keys };
    let mut out = vec![
        Method { name: "bicubic".into(), meshes: images_to_sequence(&keys, domain) },
        Method { name: "catmull-rom".into(), meshes: images_to_sequence(&catmull_rom, domain) },
    ];
    if let Some(l) = &others.linear {
        let hr = plus_residual(u_of(l.upsample), lr, domain, l.input_frame, &mut |x| l.residual(x))?;
        out.push(Method { name: "linear upsampler".into(), meshes: images_to_sequence(&hr, domain) });
    }
    if let Some((name, g)) = &others.prior {
        let input = g.trunk.config.input_frame;
        let u = u_of(g.trunk.config.upsample);
        let hr = plus_residual(u, lr, domain, input, &mut |x| Ok(g.forward(ops, x)?.1))?;
        out.push(Method {
            name: format!("GeometryNet only [{name}]"),
            meshes: images_to_sequence(&hr, domain),
        });
    }
    // Without BoundaryNet's gate (the outline floor as in the full pipeline).
    let no_b = up.without_boundary(DEFAULT_ETA)?;
    out.push(Method {
        name: format!("anisocb -boundary, eta={DEFAULT_ETA}"),
        meshes: images_to_sequence(&no_b, domain),
    });
    // A row of the pipeline run with other settings than the defaults.
    let variant = |m: &AnisoCb, params: &UpscaleParams, what: &str| -> Result<Method> {
        let hr = upscale_images(ops, m, lr, domain, params, &mut |_| {})?.hr;
        Ok(Method {
            name: format!("anisocb {what}, eta={DEFAULT_ETA}"),
            meshes: images_to_sequence(&hr, domain),
        })
    };
    if model.input_frame() == InputFrame::Cloth {
        let sp = UpscaleParams { strain_iters: EVAL_STRAIN_ITERS, ..p };
        out.push(variant(model, &sp, &format!("+ strain limit ({EVAL_STRAIN_ITERS} iterations)"))?);
        // The other side of the temporal-smoothing choice: off if it is on by default, radius
        // 2 (the earlier default) if it is off.
        let tp = UpscaleParams { temporal: if p.temporal == 0 { 2 } else { 0 }, ..p };
        let what = if tp.temporal == 0 {
            "per frame (no temporal smoothing)".to_string()
        } else {
            format!("+ temporal smoothing (radius {})", tp.temporal)
        };
        out.push(variant(model, &tp, &what)?);
        let mp = UpscaleParams { mirrors: !p.mirrors, ..p };
        out.push(variant(
            model,
            &mp,
            if mp.mirrors { "+ mirror averaging" } else { "without mirror averaging" },
        )?);
        // The outline floor only recomposes the same network outputs.
        let mut flipped = up.clone();
        flipped.set_keep_outline(!up.keeps_outline());
        let what = if flipped.keeps_outline() { "+ outline floor" } else { "without outline floor" };
        out.push(Method {
            name: format!("anisocb {what}, eta={DEFAULT_ETA}"),
            meshes: images_to_sequence(&flipped.with_eta(DEFAULT_ETA)?, domain),
        });
    }
    for &eta in etas {
        out.push(Method {
            name: format!("anisocb, eta={eta}"),
            meshes: images_to_sequence(&up.with_eta(eta)?, domain),
        });
    }
    if let Some(pm) = &others.paper {
        out.push(variant(pm, &p, "paper config")?);
    }
    for (name, m) in &others.also {
        out.push(variant(m, &p, &format!("[{name}]"))?);
    }
    Ok(out)
}

/// Markdown: one table per scenario, methods as rows (lengths in mm), under the truth's own
/// wrinkle RMS where it was computed.
pub fn results_markdown(cells: &[Cell]) -> String {
    let mut s = String::new();
    let mut scenarios: Vec<&str> = cells.iter().map(|c| c.scenario.as_str()).collect();
    scenarios.dedup();
    for sc in scenarios {
        let rows = cells.iter().filter(|c| c.scenario == sc).map(|c| (c.method.as_str(), &c.metrics));
        s.push_str(&format!("\n### {sc}\n\n"));
        let truth = cells.iter().find_map(|c| c.metrics.wrinkle.filter(|_| c.scenario == sc));
        if let Some(w) = truth {
            s.push_str(&format!("HR truth wrinkle RMS: {:.3} mm\n\n", w.truth_rms_mm));
        }
        s.push_str(&metrics_table(rows, &Column::ALL));
    }
    s
}

/// Markdown: the shipped defaults (`anisocb, eta=DEFAULT_ETA`) against each interpolation, per
/// run: ratios of vertex RMSE, normal-angle error and STED temporal (< 1: anisocb is better),
/// then the RMSE ratio averaged over runs and of the summed RMSE. Empty without those rows.
pub fn ratios_markdown(cells: &[Cell]) -> String {
    let ours = format!("anisocb, eta={DEFAULT_ETA}");
    let mut scenarios: Vec<&str> = cells.iter().map(|c| c.scenario.as_str()).collect();
    scenarios.dedup();
    let find =
        |sc: &str, m: &str| cells.iter().find(|c| c.scenario == sc && c.method == m).map(|c| &c.metrics);
    let mut s = String::new();
    for base in ["bicubic", "catmull-rom"] {
        let mut t = format!(
            "\n### {ours} vs {base} (ratios; < 1 = anisocb better)\n\n\
             | run | vertex RMSE | normal angle | STED temporal |\n|---|---:|---:|---:|\n"
        );
        let (mut ratios, mut sums, mut any) = (Vec::new(), (0.0f64, 0.0f64), false);
        for sc in &scenarios {
            let (Some(o), Some(b)) = (find(sc, &ours), find(sc, base)) else { continue };
            any = true;
            let r = o.mean.rmse / b.mean.rmse;
            ratios.push(r as f64);
            sums.0 += o.mean.rmse as f64;
            sums.1 += b.mean.rmse as f64;
            t.push_str(&format!(
                "| {sc} | {r:.3} | {:.3} | {:.3} |\n",
                o.mean.normal_angle_deg / b.mean.normal_angle_deg,
                o.sted_temporal / b.sted_temporal
            ));
        }
        if any {
            let mean = ratios.iter().sum::<f64>() / ratios.len() as f64;
            t.push_str(&format!("| mean of the ratios | {mean:.3} | | |\n"));
            t.push_str(&format!("| ratio of the summed RMSE | {:.3} | | |\n", sums.0 / sums.1));
            s.push_str(&t);
        }
    }
    s
}

pub fn run(a: Args) -> Result<()> {
    set_threads(a.threads)?;
    // The shipped default η is always evaluated (the ratio and invariance tables use it).
    let mut etas = a.eta.clone();
    if !etas.contains(&DEFAULT_ETA) {
        etas.insert(0, DEFAULT_ETA);
    }
    let ops = crate::cuda::ops_for_device(&a.device)?;
    let model = load_model(a.weights.as_deref())?;
    let others = Others {
        prior: a.prior.as_deref().map(|p| Ok((stem(p), load_geometry_net(p)?))).transpose()?,
        paper: a.paper.as_deref().map(AnisoCb::load).transpose()?,
        linear: a.linear.as_deref().map(load_linear).transpose()?,
        also: a.also.iter().map(|p| Ok((stem(p), AnisoCb::load(p)?))).collect::<Result<_>>()?,
    };
    let mut invariance = Vec::new();
    ensure_dir(&a.out)?;
    let mut cells = Vec::new();
    let pb = progress(a.runs.len() as u64, "eval");
    for dir in &a.runs {
        let pair = read_pair(dir)?;
        let (lr, domain) = (&pair.lr, &pair.domain);
        // Runs are labelled by their directory name (unique, and the user's own naming).
        let scenario = pair.label();
        let hr = images_to_sequence(&pair.hr, domain);
        let lr_m = images_to_sequence(lr, domain);
        let mut methods = methods_for_run(ops.as_ref(), &model, &others, lr, domain, &etas)?;
        if a.physics {
            let ours =
                &methods.iter().find(|m| m.name == format!("anisocb, eta={DEFAULT_ETA}")).unwrap().meshes;
            let p = FollowParams::for_run(&pair.meta);
            let meshes = Follower::run(ours, (lr.shape[3], lr.shape[2]), &p)?;
            methods.push(Method { name: PHYSICS.into(), meshes });
        }
        if a.moved {
            let ours =
                &methods.iter().find(|m| m.name == format!("anisocb, eta={DEFAULT_ETA}")).unwrap().meshes;
            invariance.extend(invariance_rows(ops.as_ref(), &model, &scenario, &lr_m, ours, &hr)?);
        }
        let mask = border_band(hr[0].w, hr[0].h, BAND_ROWS);
        // Wrinkle detail is what the grid every method upscaled (lr: (T, 3, h, w)) cannot hold.
        let (lr_w, lr_h) = (lr.shape[3], lr.shape[2]);
        let mut rows = Vec::new();
        for m in &methods {
            let mut metrics = sequence_metrics(&m.meshes, &hr, Some(&mask))?;
            metrics.wrinkle = Some(wrinkle_stats(&m.meshes, &hr, lr_w, lr_h)?);
            rows.push(Cell { method: m.name.clone(), scenario: scenario.clone(), metrics });
        }
        write_plots(&a.out, &scenario, &rows)?;
        if a.worst > 0 {
            write_worst_renders(&a.out, &scenario, &lr_m, &methods, &hr, &rows, a.worst)?;
        }
        let ours = format!("anisocb, eta={DEFAULT_ETA}");
        write_closeups(&a.out, &scenario, &lr_m, &methods, &hr, (&ours, ""), a.flipbook)?;
        if a.physics {
            write_closeups(&a.out, &scenario, &lr_m, &methods, &hr, (PHYSICS, "-physics"), a.flipbook)?;
        }
        cells.extend(rows);
        pb.inc(1);
    }
    pb.finish_and_clear();
    let md = format!(
        "# anisocb evaluation\n\nHeld-out runs: {}. Means over frames; boundary = the border band (vertices within {BAND_ROWS} rows of the grid's border).\n\n{WRINKLE_NOTE}{}",
        a.runs.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", "),
        results_markdown(&cells) + &ratios_markdown(&cells)
    );
    write_atomic_bytes(&a.out.join("results.md"), md.as_bytes())?;
    if a.moved {
        let inv = invariance_markdown(&invariance);
        write_atomic_bytes(&a.out.join("invariance.md"), inv.as_bytes())?;
        println!("{inv}");
    }
    let json = cells
        .iter()
        .map(|c| {
            Object::new()
                .str("scenario", &c.scenario)
                .str("method", &c.method)
                .val("metrics", c.metrics.to_value())
                .into()
        })
        .collect::<Vec<Value>>();
    write_json(&a.out.join("results.json"), &json.into(), Layout::Rows)?;
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
    let target = format!("anisocb, eta={DEFAULT_ETA}");
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

/// Time per frame of LR simulation + upscaling vs HR simulation, for the small (given) and the
/// paper config (random weights: time does not depend on their values).
pub fn speed_study(ops: &dyn Ops, small: &AnisoCb) -> Result<String> {
    let paper = AnisoCb::new(NetConfig::paper(), 1);
    let mut s = String::from(
        "\n### Speed: (LR simulation + upscaling) vs HR simulation, ms per frame\n\n\
         | LR → HR grid | LR sim | HR sim | upscale small | upscale paper | LR sim + small | LR sim + paper | pays off? |\n\
         |---|---:|---:|---:|---:|---:|---:|---|\n",
    );
    let frames = 20;
    for n in [32usize, 64, 128] {
        let time_sim = |w: usize| -> Result<(f64, Vec<GridMesh>)> {
            let mut spec = ScenarioSpec::new(Scenario::Flag);
            spec.w = w;
            spec.h = w;
            spec.frames = frames;
            let t = Instant::now();
            let m = run_single(&spec)?;
            Ok((1e3 * t.elapsed().as_secs_f64() / frames as f64, m))
        };
        let (lr_ms, lr) = time_sim(n)?;
        let (hr_ms, _) = time_sim(2 * n)?;
        let d = crate::geom::Domain::enclosing(&lr, 0.05);
        let img = crate::geom::geometry_image::sequence_to_images(&lr[..4], &d);
        let time_up = |m: &AnisoCb| -> Result<f64> {
            let p = UpscaleParams { batch: 1, ..UpscaleParams::default() };
            upscale_images(ops, m, &img.slice_batch(0, 1), &d, &p, &mut |_| {})?; // warm-up
            let t = Instant::now();
            upscale_images(ops, m, &img, &d, &p, &mut |_| {})?;
            Ok(1e3 * t.elapsed().as_secs_f64() / 4.0)
        };
        let (us, up) = (time_up(small)?, time_up(&paper)?);
        let verdict = match (lr_ms + us < hr_ms, lr_ms + up < hr_ms) {
            (true, true) => "yes, both configs",
            (true, false) => "small config only",
            _ => "no",
        };
        s.push_str(&format!(
            "| {n}² → {}² | {lr_ms:.2} | {hr_ms:.2} | {us:.2} | {up:.2} | {:.2} | {:.2} | {verdict} |\n",
            2 * n,
            lr_ms + us,
            lr_ms + up
        ));
    }
    s.push_str(&format!("\n(device: {}, {} threads)\n", ops.name(), rayon::current_num_threads()));
    Ok(s)
}

/// Rows of vertices counted as the border band of the tables (the border and the next row).
pub const BAND_ROWS: usize = 2;

/// How the wrinkle columns of `results.md` are measured (see `eval::metrics::wrinkle_detail`).
const WRINKLE_NOTE: &str = "Wrinkle detail D = (X − S(X))·n: X minus its Catmull-Rom round trip S(X) through the LR grid, \
along the normal of S(X), over the interior (two outer rings left out). `wrinkle RMS` = RMS(D); `/ truth` = that over the \
HR truth's RMS(D); `corr` = ΣD·D_truth / √(ΣD² ΣD_truth²); `change / truth` = RMS(D(t+1) − D(t)) over the truth's.\n";

fn stem(p: &Path) -> String {
    p.file_stem().unwrap_or_default().to_string_lossy().into_owned()
}

fn load_linear(path: &Path) -> Result<LinearUpsampler> {
    LinearUpsampler::from_npz(&crate::io::read_npz(path)?, path)
}
