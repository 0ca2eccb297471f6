//! `anisocb eval`: anisocb against the methods a user would otherwise use, on held-out runs,
//! as numbers (markdown + JSON tables), per-frame plots and error renders; `--speed` adds the
//! study of (LR simulation + upscaling) vs HR simulation.

use super::setup::{load_model, set_threads};
use super::ui::{progress, save_png};
use crate::cloth::run_io::read_pair;
use crate::cloth::scenarios::{run_single, Scenario, ScenarioSpec};
use crate::error::{Error, Result};
use crate::eval::metrics::{border_mask, sequence_metrics, vertex_errors, SequenceMetrics};
use crate::eval::report::{metrics_table, Column};
use crate::geom::geometry_image::images_to_sequence;
use crate::geom::GridMesh;
use crate::io::atomic::ensure_dir;
use crate::io::json::{write_json, Layout, Object, Value};
use crate::io::write_atomic_bytes;
use crate::nn::bundle::AnisoCb;
use crate::nn::config::NetConfig;
use crate::nn::geometry_net::GeometryNet;
use crate::nn::weights::{load_any, Weights};
use crate::ops::Ops;
use crate::sr::compose::{compose, DEFAULT_ETA};
use crate::sr::upscale::{upscale_images, UpscaleParams};
use crate::tensor::Tensor;
use crate::viz::heat::{render_heat_row, scale_max, ScalarColors};
use crate::viz::image::vstack;
use crate::viz::plot::LinePlot;
use crate::viz::render::{Shading, Tile, View};
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(clap::Args, Debug)]
#[command(after_help = "Methods compared (all on the same held-out runs, against their HR run):
  bicubic            U, the LR geometry image interpolated x2 (align corners)
  prior              Chen et al. 2018 style: one residual SR net, replicate-padded, U + R (--prior FILE)
  anisocb -boundary  anisocb without BoundaryNet: U + (1 + eta Ge) R
  anisocb eta=E      anisocb in full, Eq 12, for each --eta value
  anisocb paper      the paper-size config (--paper FILE), eta = default

Example (the README's headline table):
  anisocb simulate --scenario flag-sphere --pair --seed 1000 --frames 120 --tracking 1000 --out runs/flag-sphere
  anisocb simulate --scenario twist-zero-g --res 32x32 --pair --seed 1000 --frames 120 --tracking 1000 --out runs/twist-zero-g
  anisocb eval --runs runs/* --prior weights/prior-x2.npz --out eval-out")]
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
    /// The prior-method baseline: a GeometryNet weights file trained with replicate padding.
    #[arg(long)]
    pub prior: Option<PathBuf>,
    /// A paper-size (C=64, 10 blocks) anisocb bundle to compare with the small one.
    #[arg(long)]
    pub paper: Option<PathBuf>,
    /// Enhancement factors η to evaluate, comma-separated.
    #[arg(long, value_delimiter = ',', default_values_t = vec![0.0, DEFAULT_ETA, 1.0])]
    pub eta: Vec<f32>,
    /// Worst frames rendered per scenario.
    #[arg(long, default_value_t = 2)]
    pub worst: usize,
    /// Also run the speed study (LR sim + upscale vs HR sim at 32, 64, 128 LR grids).
    #[arg(long)]
    pub speed: bool,
    /// Worker threads (default: all cores).
    #[arg(long)]
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

fn load_prior(path: &Path) -> Result<GeometryNet> {
    match load_any(path)? {
        Weights::Net(t) if t.kind == crate::nn::config::NetKind::Geometry => Ok(GeometryNet { trunk: *t }),
        Weights::Net(t) => {
            Err(Error::format(path, format!("expected a geometry net, got a {} net", t.kind.name())))
        }
        Weights::Bundle(b) => Ok(b.geometry),
    }
}

fn methods_for_run(
    ops: &dyn Ops,
    model: &AnisoCb,
    prior: Option<&GeometryNet>,
    paper: Option<&AnisoCb>,
    lr: &Tensor,
    domain: &crate::geom::Domain,
    etas: &[f32],
) -> Result<Vec<Method>> {
    let p = UpscaleParams::default();
    let up = upscale_images(ops, model, lr, &p, &mut |_| {})?;
    let mut out =
        vec![Method { name: "bicubic".into(), meshes: images_to_sequence(&up.interpolated, domain) }];
    if let Some(g) = prior {
        let mut r = Tensor::zeros(&up.residual.shape);
        let per = r.len() / r.shape[0];
        for k in 0..lr.shape[0] {
            let (_, rk) = g.forward(ops, &lr.slice_batch(k, 1))?;
            r.data[k * per..(k + 1) * per].copy_from_slice(&rk.data);
        }
        let hr = compose(&up.interpolated, &r, None, None, 0.0)?;
        out.push(Method { name: "prior (Chen 2018 style)".into(), meshes: images_to_sequence(&hr, domain) });
    }
    let no_b = compose(&up.interpolated, &up.residual, None, Some(&up.enhance), DEFAULT_ETA)?;
    out.push(Method {
        name: format!("anisocb -boundary, eta={DEFAULT_ETA}"),
        meshes: images_to_sequence(&no_b, domain),
    });
    for &eta in etas {
        out.push(Method {
            name: format!("anisocb, eta={eta}"),
            meshes: images_to_sequence(&up.with_eta(eta)?, domain),
        });
    }
    if let Some(pm) = paper {
        let pu = upscale_images(ops, pm, lr, &p, &mut |_| {})?;
        out.push(Method {
            name: format!("anisocb paper config, eta={DEFAULT_ETA}"),
            meshes: images_to_sequence(&pu.hr, domain),
        });
    }
    Ok(out)
}

/// Markdown: one table per scenario, methods as rows (lengths in mm).
pub fn results_markdown(cells: &[Cell]) -> String {
    let mut s = String::new();
    let mut scenarios: Vec<&str> = cells.iter().map(|c| c.scenario.as_str()).collect();
    scenarios.dedup();
    for sc in scenarios {
        let rows = cells.iter().filter(|c| c.scenario == sc).map(|c| (c.method.as_str(), &c.metrics));
        s.push_str(&format!("\n### {sc}\n\n{}", metrics_table(rows, &Column::ALL)));
    }
    s
}

pub fn run(a: Args) -> Result<()> {
    set_threads(a.threads)?;
    let ops = crate::cuda::ops_for_device(&a.device)?;
    let model = load_model(a.weights.as_deref())?;
    let prior = a.prior.as_deref().map(load_prior).transpose()?;
    let paper = a.paper.as_deref().map(AnisoCb::load).transpose()?;
    ensure_dir(&a.out)?;
    let mut cells = Vec::new();
    let pb = progress(a.runs.len() as u64, "eval");
    for dir in &a.runs {
        let pair = read_pair(dir)?;
        let (lr, domain) = (&pair.lr, &pair.domain);
        // Runs are labelled by their directory name (unique, and the user's own naming).
        let scenario = run_label(Path::new(&pair.name));
        let hr = images_to_sequence(&pair.hr, domain);
        let lr_m = images_to_sequence(lr, domain);
        let methods =
            methods_for_run(ops.as_ref(), &model, prior.as_ref(), paper.as_ref(), lr, domain, &a.eta)?;
        let mask = border_mask(hr[0].w, hr[0].h);
        let mut rows = Vec::new();
        for m in &methods {
            let metrics = sequence_metrics(&m.meshes, &hr, Some(&mask))?;
            rows.push(Cell { method: m.name.clone(), scenario: scenario.clone(), metrics });
        }
        write_plots(&a.out, &scenario, &rows)?;
        write_worst_renders(&a.out, &scenario, &lr_m, &methods, &hr, &rows, a.worst)?;
        cells.extend(rows);
        pb.inc(1);
    }
    pb.finish_and_clear();
    let md = format!(
        "# anisocb evaluation\n\nHeld-out runs: {}. Means over frames; boundary = the grid's border vertices.\n{}",
        a.runs.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", "),
        results_markdown(&cells)
    );
    write_atomic_bytes(&a.out.join("results.md"), md.as_bytes())?;
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
        "wrote {}/: results.md, results.json, <scenario>-rmse.png, <scenario>-worst.png",
        a.out.display()
    );
    Ok(())
}

fn run_label(dir: &Path) -> String {
    let name = dir.file_name().or_else(|| dir.parent().and_then(Path::file_name));
    name.map_or_else(|| "run".to_string(), |n| n.to_string_lossy().into_owned())
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
        .filter(|m| m.name == "bicubic" || m.name.starts_with("prior") || m.name == target)
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
            upscale_images(ops, m, &img.slice_batch(0, 1), &p, &mut |_| {})?; // warm-up
            let t = Instant::now();
            upscale_images(ops, m, &img, &p, &mut |_| {})?;
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
