//! `anisocb dataset`: LR/HR geometry images of simulated run pairs plus the HR ground-truth
//! boundary and edge maps, in one `.npz` (layout: [`crate::train::dataset`]), and a PNG
//! contact sheet to check the maps by eye.

use crate::cloth::run_io::{pair_dir, read_pair};
use crate::error::{Error, Result};
use crate::eval::mesh::MeshRun;
use crate::geom::anisotropy::BoundaryParams;
use crate::geom::cloth_frame::InputFrame;
use crate::imgproc::CannyParams;
use crate::io::read_npz;
use crate::pipeline::folder;
use crate::pipeline::input::same_file;
use crate::tensor::Tensor;
use crate::train::dataset::{benefit_boundary, build, is_held_out, mesh_run_windows, MapParams};
use std::path::{Path, PathBuf};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run pairs from `anisocb simulate --pair --out DIR` (DIR, or its lr/ or hr/ subdirectory):
    /// sheets, and garments (`--scenario skirt` …) or any pair of OBJ sequences whose HR mesh
    /// is the LR mesh subdivided once. A mesh run's geometry images (laid out as `upscale`
    /// lays them out) are cut into windows the size of the sheets' LR frames (32×32 without
    /// sheets), each a run of its own named DIR@k.
    #[arg(long, num_args = 1.., required = true, value_name = "DIR")]
    pub runs: Vec<PathBuf>,
    /// Output .npz (arrays lr, hr, boundary, edges, domain; frames.json, params.json), written
    /// atomically: new, or an earlier data set replaced; any other file there is refused (see
    /// --overwrite), as is a file of a run read. One run at a time writes it (a lock).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Replace --out (and --png) even where it is not a data set (a PNG image).
    #[arg(long)]
    pub overwrite: bool,
    /// Boundary threshold γ on σ3/σ1 [default: 0.05].
    #[arg(long)]
    pub gamma: Option<f64>,
    /// Laplacian smoothing step λ (0..1) [default: 0.5].
    #[arg(long)]
    pub lambda: Option<f64>,
    /// Canny Gaussian σ in pixels [default: 1.0].
    #[arg(long)]
    pub canny_sigma: Option<f32>,
    /// Canny low threshold on the gradient magnitude [default: 0.15].
    #[arg(long)]
    pub canny_low: Option<f32>,
    /// Canny high threshold on the gradient magnitude [default: 0.3].
    #[arg(long)]
    pub canny_high: Option<f32>,
    /// Leave out runs whose scenario, directory name or `seed=N` matches (for evaluation).
    #[arg(long, num_args = 1.., value_name = "NAME")]
    pub holdout: Vec<String>,
    /// Coordinates the nets will see: `cloth-frame` (each frame in its own frame, moving with
    /// the cloth: translation, rotation and scale removed) or `domain` (the paper's Eq 1 box of
    /// the whole sequence, kept for comparison).
    #[arg(long, default_value = "cloth-frame", value_name = "FRAME")]
    pub input_frame: String,
    /// Boundary target from the benefit of a trained GeometryNet's residual (weights .npz, a
    /// net or a bundle, trained in the same input frame) instead of the anisotropy map: soft
    /// targets 1 − clamp(⟨HR − U, R⟩ / |R|², 0, 1), i.e. 1 where interpolation is safer than
    /// the residual; the grid border stays 1.
    #[arg(long, value_name = "WEIGHTS")]
    pub boundary_benefit: Option<PathBuf>,
    /// HR target distilled from a bundle (weights .npz, trained in the same input frame): what
    /// it composes from each LR frame at η = 0, `U + (1 − Γb) ⊙ R`, its GeometryNets averaged
    /// and (with --distil-mirrors true) over the grid's four mirror views, as `upscale` runs
    /// it. A GeometryNet trained on it does in one pass what the bundle does in many.
    #[arg(long, value_name = "WEIGHTS")]
    pub distil: Option<PathBuf>,
    /// With --distil: average the teacher over the four mirror views (as `upscale --mirrors
    /// true`).
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set, value_name = "BOOL")]
    pub distil_mirrors: bool,
    /// EnhanceNet's target: `canny` (edges of the HR geometry image, the paper's) or
    /// `wrinkle-energy` (where the HR truth folds: the local amplitude of its detail beyond the
    /// LR grid over a 7×7 window, divided by its 90 % quantile, clamped to 1), so that η
    /// deepens the predicted folds where EnhanceNet expects the cloth to fold.
    #[arg(long, default_value = "canny", value_parser = ["canny", "wrinkle-energy"])]
    pub edges: String,
    /// Mesh runs only: the interpolation U their HR windows are built on (`U + detail`, what
    /// `upscale` composes on a mesh); give `train` the same --upsample.
    #[arg(long, default_value = "catmull-rom", value_name = "INTERP")]
    pub upsample: String,
    /// Contact sheet PNG [default: --out with extension .png].
    #[arg(long, value_name = "FILE")]
    pub png: Option<PathBuf>,
    /// Frames shown in the contact sheet.
    #[arg(long, default_value_t = 4)]
    pub sheet_frames: usize,
}

/// LR pixels of the square windows mesh runs are cut into when there is no grid run to match:
/// the sheets' training size (`make weights`).
const DEFAULT_WINDOW: usize = 32;

/// The HR run of a mesh run is its LR mesh subdivided once.
const UPSCALE: usize = 2;

/// `dataset --edges wrinkle-energy`: the quantile of the truth's local wrinkle amplitude that
/// maps to an edge target of 1 (the folds of the most folded tenth of the cloth count fully).
const WRINKLE_EDGE_QUANTILE: f32 = 0.9;

/// Refuse outputs that would replace a file of the run pair `pd` (its `lr/`, `hr/` or the pair
/// folder itself): a data set written over a run's `geometry.npy` destroys the run.
fn refuse_writing_into_run(pd: &Path, outputs: &[&PathBuf]) -> Result<()> {
    for o in outputs {
        let Some(dir) = o.parent().map(|p| if p.as_os_str().is_empty() { Path::new(".") } else { p }) else {
            continue;
        };
        let (Ok(dir), true) = (dir.canonicalize(), o.exists()) else { continue };
        for sub in [pd.to_path_buf(), pd.join("lr"), pd.join("hr")] {
            if sub.canonicalize().is_ok_and(|s| s == dir) {
                return Err(Error::config(format!(
                    "{} is a file of the run {}: writing the data set there would replace it; give \
                     another --out / --png",
                    o.display(),
                    pd.display()
                )));
            }
        }
    }
    Ok(())
}

pub fn run(a: Args) -> Result<()> {
    let bd = BoundaryParams::default();
    let cd = CannyParams::default();
    let params = MapParams {
        boundary: BoundaryParams {
            gamma: a.gamma.unwrap_or(bd.gamma),
            lambda: a.lambda.unwrap_or(bd.lambda),
            ..bd
        },
        canny: CannyParams {
            sigma: a.canny_sigma.unwrap_or(cd.sigma),
            low: a.canny_low.unwrap_or(cd.low),
            high: a.canny_high.unwrap_or(cd.high),
        },
    };
    params.boundary.validate()?;
    params.canny.validate()?;
    let input_frame = InputFrame::parse(&a.input_frame)?;
    let upsample = crate::nn::config::parse_upsample(&a.upsample)?;
    let png = a.png.clone().unwrap_or_else(|| a.out.with_extension("png"));
    for (path, ext, what) in [(&a.out, "npz", "--out"), (&png, "png", "--png")] {
        if !path.extension().is_some_and(|e| e.eq_ignore_ascii_case(ext)) {
            return Err(Error::config(format!("{what} {}: expected a .{ext} file name", path.display())));
        }
    }
    let mut seen = Vec::new();
    for dir in &a.runs {
        let pd = pair_dir(dir)?;
        if seen.contains(&pd) {
            continue; // `DIR/lr` and `DIR/hr` both given: one run
        }
        refuse_writing_into_run(&pd, &[&a.out, &png])?;
        seen.push(pd);
    }
    if let Some(w) = a.distil.as_ref().filter(|w| same_file(w, &a.out)) {
        return Err(Error::config(format!(
            "--out {} is the --distil weights {}: writing the data set would replace them; \
             choose another file",
            a.out.display(),
            w.display()
        )));
    }
    if let Some(w) = a.boundary_benefit.as_ref().filter(|w| same_file(w, &a.out)) {
        return Err(Error::config(format!(
            "--out {} is the --boundary-benefit weights {}: writing the data set would replace \
             them; choose another file",
            a.out.display(),
            w.display()
        )));
    }
    let is_data_set = |p: &Path| {
        read_npz(p).is_ok_and(|e| e.file("frames.json").is_some() && e.file("params.json").is_some())
    };
    let _out = folder::claim_file(&a.out, "a data set (.npz with frames.json)", is_data_set, a.overwrite)?;
    let is_png = |p: &Path| std::fs::read(p).is_ok_and(|b| b.starts_with(b"\x89PNG\r\n\x1a\n"));
    let _png = folder::claim_file(&png, "a PNG image", is_png, a.overwrite)?;
    // Grid runs as they are; mesh runs (OBJ sequences that are not a grid: garments) after
    // them, in windows of the grid runs' LR size.
    let (mut runs, mut meshes) = (Vec::new(), Vec::new());
    for pd in &seen {
        match read_pair(pd) {
            Ok(r) => runs.push(r),
            Err(grid) => match MeshRun::read(pd) {
                Ok(m) => meshes.push((pd, m)),
                // Neither: the grid reader's message, unless the run is plainly a mesh run.
                Err(mesh) => return Err(if pd.join("scene.json").exists() { mesh } else { grid }),
            },
        }
    }
    let window = match runs.first().map(|r| r.lr.dims4()) {
        _ if meshes.is_empty() => DEFAULT_WINDOW,
        Some((_, _, h, w)) if h == w => h,
        Some((_, _, h, w)) => {
            return Err(Error::config(format!(
                "the grid runs are {w}×{h}: mesh runs are cut into square windows of the grid runs' \
                 size; simulate square sheets (--res 32x32) or leave the mesh runs out"
            )))
        }
        None => DEFAULT_WINDOW,
    };
    for (pd, m) in &meshes {
        runs.extend(mesh_run_windows(pd, m, window, UPSCALE, upsample)?);
    }
    runs.retain(|r| {
        let out = is_held_out(r, &a.holdout);
        if out {
            eprintln!("held out: {} ({})", r.name, r.scenario);
        }
        !out
    });
    let total: u64 = runs.iter().map(|r| r.hr.shape[0] as u64).sum();
    let pb = super::ui::progress(total, "maps");
    let mut ds = build(&runs, &params, input_frame, &a.holdout, &|| pb.inc(1))?;
    pb.finish_and_clear();
    if a.edges == "wrinkle-energy" {
        crate::train::dataset::wrinkle_energy_edges(&mut ds, Default::default(), WRINKLE_EDGE_QUANTILE)?;
    }
    if let Some(w) = &a.boundary_benefit {
        let net = super::setup::load_geometry_net(w)?;
        if net.trunk.config.input_frame != input_frame {
            return Err(crate::Error::format(
                w,
                format!(
                    "this GeometryNet takes {} input but the dataset is built in the {} frame",
                    net.trunk.config.input_frame.name(),
                    input_frame.name()
                ),
            ));
        }
        benefit_boundary(&mut ds, &crate::ops::Cpu, &net)?;
    }
    if let Some(w) = &a.distil {
        let teacher = super::setup::load_model(Some(w))?;
        let pb = super::ui::progress(ds.len() as u64, "teacher");
        crate::train::dataset::distil_targets(
            &mut ds,
            &crate::ops::Cpu,
            &teacher,
            a.distil_mirrors,
            &mut |d| pb.set_position(d as u64),
        )
        .map_err(|e| e.in_file(w))?;
        pb.finish_and_clear();
    }
    crate::io::write_npz(&a.out, &ds.to_npz())?;
    super::ui::save_png(&png, &crate::viz::sheet::contact_sheet(&ds, a.sheet_frames)?)?;
    let pos = |t: &Tensor| t.data.iter().filter(|&&v| v > 0.5).count() as f64 / t.data.len().max(1) as f64;
    eprintln!(
        "wrote {} ({} frames from {} runs, LR {}×{} → HR {}×{}; boundary {:.1}% / edges {:.1}% of pixels), {}",
        a.out.display(),
        ds.len(),
        runs.len(),
        ds.lr.shape[2],
        ds.lr.shape[3],
        ds.hr.shape[2],
        ds.hr.shape[3],
        100.0 * pos(&ds.boundary),
        100.0 * pos(&ds.edges),
        png.display()
    );
    Ok(())
}
