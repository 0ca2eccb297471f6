//! `anisocb upscale INPUT... --out DIR`: LR cloth animation in, HR animation out.

use super::setup::{load_model, set_threads};
use super::ui::progress;
use crate::cloth::run_io::read_run_at;
use crate::cloth::run_io::DOMAIN_MARGIN;
use crate::error::{Error, Result};
use crate::geom::geometry_image::images_to_sequence;
use crate::geom::obj::{list_obj_files, natural_cmp, read_obj_sequence, write_obj_grid, FaceStyle};
use crate::geom::{Domain, GridMesh};
use crate::io::atomic::{ensure_dir, remove_stale_temps};
use crate::io::json::{write_json, Layout, Object, Value};
use crate::io::write_npy;
use crate::sr::compose::DEFAULT_ETA;
use crate::sr::upscale::{upscale_images, upscale_meshes, UpscaleParams};
use crate::tensor::Tensor;
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(clap::Args, Debug)]
#[command(after_help = "Examples:
  anisocb upscale frames/ --out hr/                  # a directory of OBJ frames (natural order)
  anisocb upscale f_0001.obj f_0002.obj --out hr/    # explicit OBJ files
  anisocb upscale run/lr --out hr/                   # a simulator run dir (geometry.npy + domain.npy)
  anisocb upscale run/lr/geometry.npy --out hr/ --eta 1.0 --maps

Input meshes must be regular grids (quads or triangulated quads, any vertex order); the output has
2W x 2H vertices per frame over the same surface, written the way the input was (OBJ quads or
triangles with the same file names, or geometry.npy + domain.npy).")]
pub struct Args {
    /// OBJ files, a directory of OBJ files, a run directory with geometry.npy, or a geometry.npy.
    #[arg(required = true)]
    pub input: Vec<PathBuf>,
    /// Output directory (created if missing; existing frames with the same names are replaced).
    #[arg(long)]
    pub out: PathBuf,
    /// Wrinkle enhancement η ≥ 0 (Eq 12): 0 = plain predicted detail, larger = deeper wrinkles
    /// where EnhanceNet sees edges. Smooth cloth and the border are unaffected.
    #[arg(long, default_value_t = DEFAULT_ETA)]
    pub eta: f32,
    /// Temporal smoothing radius in frames of the predicted detail, in the cloth's own frame
    /// (1 = weights ¼ ½ ¼ over the previous, this and the next frame; 0 = every frame on its
    /// own). Removes frame-to-frame flicker of the detail; wrinkles that stay on the cloth are
    /// kept.
    #[arg(long, default_value_t = crate::sr::upscale::DEFAULT_TEMPORAL)]
    pub temporal: usize,
    /// Strain limit: iterations pulling the output's edge lengths toward those of the input
    /// frame (0 = off). About 10 removes swimming and frame-to-frame edge flicker on cloth that
    /// barely stretches (flags, drapes: also −6 % error); do not use it on cloth that stretches
    /// a lot (rubber, strongly twisted strips), where it makes the result worse.
    #[arg(long, default_value_t = crate::sr::upscale::DEFAULT_STRAIN_ITERS)]
    pub strain_iters: usize,
    /// Weights file (.npz bundle of the three nets) instead of the embedded ×2 model.
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// Frames per network pass (more = faster, more memory).
    #[arg(long, default_value_t = 8)]
    pub batch: usize,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Compute device: cpu or cuda.
    #[arg(long, default_value = "cpu")]
    pub device: String,
    /// Output format: auto (same as input), obj or npy.
    #[arg(long, default_value = "auto", value_parser = ["auto", "obj", "npy"])]
    pub format: String,
    /// Domain margin for OBJ input, as a fraction of the sequence's largest extent.
    #[arg(long, default_value_t = DOMAIN_MARGIN)]
    pub margin: f32,
    /// Also write the predicted boundary and wrinkle-edge maps (boundary.npy, enhance.npy).
    #[arg(long)]
    pub maps: bool,
}

/// The LR frames as the user gave them.
pub enum LrFrames {
    /// OBJ meshes.
    Meshes(Vec<GridMesh>),
    /// Geometry images (T, 3, H, W) of a run directory or a `.npy`.
    Images(Tensor),
}

/// An LR sequence, from whatever the user gave.
pub struct LrInput {
    pub frames: LrFrames,
    pub domain: Domain,
    /// Output file names for OBJ output (one per frame).
    pub names: Vec<String>,
    /// Face style of OBJ input (None for .npy input).
    pub style: Option<FaceStyle>,
    pub domain_note: String,
}

impl LrInput {
    /// (frames, columns, rows).
    pub fn size(&self) -> (usize, usize, usize) {
        match &self.frames {
            LrFrames::Meshes(m) => (m.len(), m[0].w, m[0].h),
            LrFrames::Images(t) => (t.shape[0], t.shape[3], t.shape[2]),
        }
    }
}

fn is_obj(p: &Path) -> bool {
    p.extension().is_some_and(|e| e.eq_ignore_ascii_case("obj"))
}

/// Read OBJ files, an OBJ directory, a run directory or a geometry.npy.
pub fn read_input(inputs: &[PathBuf], margin: f32) -> Result<LrInput> {
    let first = &inputs[0];
    let npy = if inputs.len() == 1 && first.is_dir() && first.join("geometry.npy").exists() {
        Some(first.join("geometry.npy"))
    } else if inputs.len() == 1 && first.extension().is_some_and(|e| e == "npy") {
        Some(first.clone())
    } else {
        None
    };
    if let Some(gp) = npy {
        let run = read_run_at(&gp)?;
        let names = (0..run.images.shape[0]).map(|k| format!("frame_{k:04}.obj")).collect();
        let note = format!("domain from {}", gp.with_file_name("domain.npy").display());
        return Ok(LrInput {
            frames: LrFrames::Images(run.images),
            domain: run.domain,
            names,
            style: None,
            domain_note: note,
        });
    }
    let mut files = Vec::new();
    for p in inputs {
        if p.is_dir() {
            files.extend(list_obj_files(p)?);
        } else if is_obj(p) {
            files.push(p.clone());
        } else if !p.exists() {
            return Err(Error::format(p, "no such file or directory"));
        } else {
            return Err(Error::format(p, "not an OBJ file, an OBJ directory, a run directory or a .npy"));
        }
    }
    if files.is_empty() {
        return Err(Error::format(first, "no .obj files found"));
    }
    files.sort_by(|a, b| natural_cmp(&a.to_string_lossy(), &b.to_string_lossy()));
    let (frames, style) = read_obj_sequence(&files)?;
    if !(margin.is_finite() && margin >= 0.0) {
        return Err(Error::config(format!("--margin must be ≥ 0, got {margin}")));
    }
    let domain = Domain::enclosing(&frames, margin);
    let names = files.iter().map(|p| p.file_name().unwrap().to_string_lossy().into_owned()).collect();
    let note = format!(
        "domain = bounding box of all frames + {:.0}% margin: bmin {:?}, bmax {:?} (m)",
        margin * 100.0,
        domain.bmin,
        domain.bmax
    );
    Ok(LrInput { frames: LrFrames::Meshes(frames), domain, names, style: Some(style), domain_note: note })
}

pub fn run(a: Args) -> Result<()> {
    set_threads(a.threads)?;
    let ops = crate::cuda::ops_for_device(&a.device)?;
    let model = load_model(a.weights.as_deref())?;
    let input = read_input(&a.input, a.margin)?;
    let (t, w, h) = input.size();
    let r = model.scale();
    ensure_dir(&a.out)?;
    let fmt = match (a.format.as_str(), input.style) {
        ("auto", Some(_)) | ("obj", _) => "obj",
        _ => "npy",
    };
    eprintln!("upscaling {t} frames {w}x{h} -> {}x{} ({}), η = {}", r * w, r * h, ops.name(), a.eta);
    eprintln!("{}", input.domain_note);
    let pb = progress(t as u64, "upscale");
    let start = Instant::now();
    let params = UpscaleParams {
        eta: a.eta,
        batch: a.batch,
        temporal: a.temporal,
        strain_iters: a.strain_iters,
        ..UpscaleParams::default()
    };
    let mut on_frames = |k: usize| pb.set_position(k as u64);
    let (up, hr_meshes) = match &input.frames {
        LrFrames::Meshes(m) => {
            let (meshes, up) =
                upscale_meshes(ops.as_ref(), &model, m, &input.domain, &params, &mut on_frames)?;
            (up, Some(meshes))
        }
        LrFrames::Images(img) => {
            (upscale_images(ops.as_ref(), &model, img, &input.domain, &params, &mut on_frames)?, None)
        }
    };
    let secs = start.elapsed().as_secs_f64();
    pb.finish_and_clear();
    let quads = input.style != Some(FaceStyle::Triangles);
    // A rerun after a kill: clear the temp files the killed run left (every file below is
    // written atomically, so the outputs themselves are either complete or absent).
    let mut outputs: Vec<PathBuf> =
        ["geometry.npy", "domain.npy", "boundary.npy", "enhance.npy", "upscale.json"]
            .iter()
            .map(|n| a.out.join(n))
            .collect();
    outputs.extend(input.names.iter().map(|n| a.out.join(n)));
    for p in &outputs {
        remove_stale_temps(p)?;
    }
    if fmt == "obj" {
        let meshes = hr_meshes.unwrap_or_else(|| images_to_sequence(&up.hr, &input.domain));
        for (name, m) in input.names.iter().zip(&meshes) {
            write_obj_grid(&a.out.join(name), m, quads)?;
        }
    } else {
        write_npy(&a.out.join("geometry.npy"), &up.hr)?;
        write_npy(&a.out.join("domain.npy"), &input.domain.to_tensor())?;
    }
    if a.maps {
        write_npy(&a.out.join("boundary.npy"), &up.boundary)?;
        write_npy(&a.out.join("enhance.npy"), &up.enhance)?;
    }
    let size = |w: usize, h: usize| vec![Value::num(w), Value::num(h)];
    let summary = Object::new()
        .num("frames", t)
        .val("lr", size(w, h))
        .val("hr", size(r * w, r * h))
        .num("eta", a.eta)
        .str("device", ops.name())
        .num("seconds", format!("{secs:.3}"))
        .num("ms_per_frame", format!("{:.3}", 1e3 * secs / t as f64))
        .val(
            "domain",
            Object::new()
                .val("bmin", Value::reals(&input.domain.bmin))
                .val("bmax", Value::reals(&input.domain.bmax)),
        );
    write_json(&a.out.join("upscale.json"), &summary.into(), Layout::Compact)?;
    println!(
        "upscaled {t} frames {w}x{h} -> {}x{} in {secs:.2} s ({:.1} ms/frame) -> {} ({fmt})",
        r * w,
        r * h,
        1e3 * secs / t as f64,
        a.out.display()
    );
    Ok(())
}
