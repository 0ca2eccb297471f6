//! `anisocb upscale INPUT... --out DIR`: LR cloth animation in, HR animation out.

use super::ui::progress;
use crate::cloth::run_io::DOMAIN_MARGIN;
use crate::error::{Error, Result};
use crate::geom::geometry_image::image_to_mesh;
use crate::geom::obj::{list_obj_files, natural_cmp, read_obj_sequence, write_obj_grid, FaceStyle};
use crate::geom::Domain;
use crate::io::atomic::{ensure_dir, remove_stale_temps};
use crate::io::npy::read_geometry_images;
use crate::io::{read_npy, write_atomic_bytes, write_npy};
use crate::nn::bundle::AnisoCb;
use crate::sr::compose::DEFAULT_ETA;
use crate::sr::upscale::{embedded_model, upscale_images, UpscaleParams};
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

/// An LR sequence, from whatever the user gave.
pub struct LrInput {
    pub images: Tensor,
    pub domain: Domain,
    /// Output file names for OBJ output (one per frame).
    pub names: Vec<String>,
    /// Face style of OBJ input (None for .npy input).
    pub style: Option<FaceStyle>,
    pub domain_note: String,
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
        let images = read_geometry_images(&gp)?;
        let dp = gp.with_file_name("domain.npy");
        if !dp.exists() {
            return Err(Error::format(
                &gp,
                format!("needs its domain beside it ({} with [bmin; bmax], shape [2, 3])", dp.display()),
            ));
        }
        let domain = Domain::from_tensor(&read_npy(&dp)?).map_err(|e| e.in_file(&dp))?;
        let t = images.shape[0];
        let names = (0..t).map(|k| format!("frame_{k:04}.obj")).collect();
        let note = format!("domain from {}", dp.display());
        return Ok(LrInput { images, domain, names, style: None, domain_note: note });
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
    let images = crate::geom::geometry_image::sequence_to_images(&frames, &domain);
    let names = files.iter().map(|p| p.file_name().unwrap().to_string_lossy().into_owned()).collect();
    let note = format!(
        "domain = bounding box of all frames + {:.0}% margin: bmin {:?}, bmax {:?} (m)",
        margin * 100.0,
        domain.bmin,
        domain.bmax
    );
    Ok(LrInput { images, domain, names, style: Some(style), domain_note: note })
}

/// The model to use: `--weights FILE` or the embedded one.
pub fn load_model(weights: Option<&Path>) -> Result<AnisoCb> {
    match weights {
        Some(p) => AnisoCb::load(p),
        None => embedded_model(),
    }
}

pub fn set_threads(threads: Option<usize>) -> Result<()> {
    if let Some(n) = threads {
        if n == 0 {
            return Err(Error::config("--threads must be ≥ 1"));
        }
        // Fails only if a pool was already set up in this process; the first setting wins.
        let _ = rayon::ThreadPoolBuilder::new().num_threads(n).build_global();
    }
    Ok(())
}

pub fn run(a: Args) -> Result<()> {
    set_threads(a.threads)?;
    let ops = crate::cuda::ops_for_device(&a.device)?;
    let model = load_model(a.weights.as_deref())?;
    let input = read_input(&a.input, a.margin)?;
    let (t, _, h, w) = input.images.dims4();
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
    let params = UpscaleParams { eta: a.eta, batch: a.batch, ..UpscaleParams::default() };
    let up =
        upscale_images(ops.as_ref(), &model, &input.images, &params, &mut |k| pb.set_position(k as u64))?;
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
        for (k, name) in input.names.iter().enumerate() {
            write_obj_grid(&a.out.join(name), &image_to_mesh(&up.hr, k, &input.domain), quads)?;
        }
    } else {
        write_npy(&a.out.join("geometry.npy"), &up.hr)?;
        write_npy(&a.out.join("domain.npy"), &input.domain.to_tensor())?;
    }
    if a.maps {
        write_npy(&a.out.join("boundary.npy"), &up.boundary)?;
        write_npy(&a.out.join("enhance.npy"), &up.enhance)?;
    }
    let summary = format!(
        "{{\"frames\": {t}, \"lr\": [{w}, {h}], \"hr\": [{}, {}], \"eta\": {}, \"device\": \"{}\", \
         \"seconds\": {secs:.3}, \"ms_per_frame\": {:.3}, \"domain\": {{\"bmin\": {:?}, \"bmax\": {:?}}}}}\n",
        r * w,
        r * h,
        a.eta,
        ops.name(),
        1e3 * secs / t as f64,
        input.domain.bmin,
        input.domain.bmax
    );
    write_atomic_bytes(&a.out.join("upscale.json"), summary.as_bytes())?;
    println!(
        "upscaled {t} frames {w}x{h} -> {}x{} in {secs:.2} s ({:.1} ms/frame) -> {} ({fmt})",
        r * w,
        r * h,
        1e3 * secs / t as f64,
        a.out.display()
    );
    Ok(())
}
