//! `anisocb upscale INPUT... --out DIR`: LR cloth animation in, HR animation out, streamed a
//! chunk of frames at a time (memory bounded by `--chunk`, not the shot), any `--frames`
//! slice giving the same bytes as the whole shot.

use super::setup::{load_model, set_threads};
use super::ui::progress;
use crate::cloth::run_io::DOMAIN_MARGIN;
use crate::error::{Error, Result};
use crate::geom::cloth_frame::InputFrame;
use crate::geom::geometry_image::{image_to_mesh, mesh_to_image, Bounds};
use crate::geom::obj::{list_obj_files, natural_cmp, obj_text_with, FaceStyle, ObjAttrs, ObjSequence};
use crate::geom::Domain;
use crate::io::atomic::{ensure_dir, remove_stale_temps, write_atomic_bytes};
use crate::io::json::{write_json, Layout, Object, Value};
use crate::io::npy::{NpyFrames, NpyWriter};
use crate::io::read_npy;
use crate::io::write_npy;
use crate::nn::bundle::AnisoCb;
use crate::sr::compose::DEFAULT_ETA;
use crate::sr::stream::{upscale_stream, HrSink, LrSource, DEFAULT_CHUNK};
use crate::sr::upscale::{upscale_uv, UpscaleParams, Upscaled};
use crate::tensor::Tensor;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(clap::Args, Debug)]
#[command(after_help = "Examples:
  anisocb upscale frames/ --out hr/                  # a directory of OBJ frames (natural order)
  anisocb upscale f_0001.obj f_0002.obj --out hr/    # explicit OBJ files
  anisocb upscale run/lr --out hr/                   # a simulator run dir (geometry.npy + domain.npy)
  anisocb upscale run/lr/geometry.npy --out hr/ --eta 1.0 --maps
  anisocb upscale frames/ --out hr/ --frames 0:100   # one slice of a shot (a render-farm task)

From Blender and back (OBJ sequence):
  1. File > Export > Wavefront (.obj): Animation on, Apply Modifiers on, UV Coordinates and
     Normals on, Materials on, Forward/Up as you like; export the cloth object to frames/.
  2. anisocb upscale frames/ --out hr/
  3. In Blender, import hr/ as an OBJ sequence (e.g. File > Import > Wavefront for one frame,
     or an OBJ-sequence add-on): UVs, material slot, object name and face style come back.

Input meshes must be regular grids (quads or triangulated quads, any vertex order); the output has
2W x 2H vertices per frame over the same surface, written the way the input was (OBJ quads or
triangles with the same file names, UVs interpolated (bilinear: seams stay put), normals recomputed,
mtllib/usemtl/o/g/s kept; or geometry.npy + domain.npy).")]
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
    /// Upscale only frames A to B−1 of the shot (0-based, `A:B`, `A:` = to the end). Slices
    /// upscaled separately give exactly the files (bytes) the whole shot gives, so a farm can
    /// split a shot by frame range; .npy output of a slice is named geometry.A-B.npy.
    #[arg(long, value_name = "A:B")]
    pub frames: Option<String>,
    /// Frames read, upscaled and written at a time: memory is bounded by this, not by the
    /// shot's length.
    #[arg(long, default_value_t = DEFAULT_CHUNK)]
    pub chunk: usize,
}

/// Parse `--frames A:B` against a shot of `t` frames.
pub fn parse_frames(spec: Option<&str>, t: usize) -> Result<Range<usize>> {
    let Some(spec) = spec else { return Ok(0..t) };
    let bad = || {
        Error::config(format!(
            "--frames {spec}: expected A:B (0-based, B exclusive) or A: with 0 ≤ A < B ≤ {t}"
        ))
    };
    let (a, b) = spec.split_once(':').ok_or_else(bad)?;
    let a: usize = a.trim().parse().map_err(|_| bad())?;
    let b: usize = if b.trim().is_empty() { t } else { b.trim().parse().map_err(|_| bad())? };
    if a >= b || b > t {
        return Err(bad());
    }
    Ok(a..b)
}

/// The shot as the user gave it, read a range of frames at a time.
enum Shot {
    /// A geometry.npy (T, 3, H, W) with its domain.
    Npy { frames: NpyFrames, path: PathBuf },
    /// An OBJ sequence, encoded with `domain` as it is read.
    Obj { seq: Box<ObjSequence>, domain: Domain },
}

impl Shot {
    /// (frames, columns, rows).
    fn size(&self) -> (usize, usize, usize) {
        match self {
            Shot::Npy { frames, .. } => (frames.frames(), frames.header.shape[3], frames.header.shape[2]),
            Shot::Obj { seq, .. } => (seq.len(), seq.first.mesh.w, seq.first.mesh.h),
        }
    }
}

impl LrSource for Shot {
    fn frames(&self) -> usize {
        self.size().0
    }

    fn read(&mut self, range: Range<usize>) -> Result<Tensor> {
        match self {
            Shot::Npy { frames, path } => {
                let t = frames.read(range.clone())?;
                if let Some((i, v)) = t.first_non_finite() {
                    let (_, _, h, w) = t.dims4();
                    return Err(Error::format(
                        &*path,
                        format!("non-finite value {v} in frame {}", range.start + i / (3 * h * w)),
                    ));
                }
                Ok(t)
            }
            Shot::Obj { seq, domain } => {
                let (w, h) = (seq.first.mesh.w, seq.first.mesh.h);
                let mut t = Tensor::zeros(&[range.len(), 3, h, w]);
                for (k, f) in range.enumerate() {
                    let img = mesh_to_image(&seq.frame(f)?, domain);
                    t.data[k * 3 * h * w..(k + 1) * 3 * h * w].copy_from_slice(&img.data);
                }
                Ok(t)
            }
        }
    }
}

fn is_obj(p: &Path) -> bool {
    p.extension().is_some_and(|e| e.eq_ignore_ascii_case("obj"))
}

/// The geometry.npy an input names, if it names one (a run directory or a `.npy`).
fn npy_input(inputs: &[PathBuf]) -> Option<PathBuf> {
    let first = &inputs[0];
    if inputs.len() == 1 && first.is_dir() && first.join("geometry.npy").exists() {
        Some(first.join("geometry.npy"))
    } else if inputs.len() == 1 && first.extension().is_some_and(|e| e == "npy") {
        Some(first.clone())
    } else {
        None
    }
}

/// The OBJ files of the input, in natural order.
fn obj_files(inputs: &[PathBuf]) -> Result<Vec<PathBuf>> {
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
        return Err(Error::format(&inputs[0], "no .obj files found"));
    }
    files.sort_by(|a, b| natural_cmp(&a.to_string_lossy(), &b.to_string_lossy()));
    Ok(files)
}

/// OBJ frames written one file per frame, the way the input was.
struct ObjSink {
    dir: PathBuf,
    names: Vec<String>,
    domain: Domain,
    quads: bool,
    /// HR texture coordinates, if the input had usable ones.
    uv: Option<Vec<[f32; 2]>>,
    attrs: ObjAttrs,
}

impl HrSink for ObjSink {
    fn write(&mut self, first: usize, up: &Upscaled, keep: Range<usize>) -> Result<()> {
        for (k, f) in keep.enumerate() {
            let mesh = image_to_mesh(&up.hr, f, &self.domain);
            let text = obj_text_with(&mesh, self.quads, self.uv.as_deref(), &self.attrs);
            write_atomic_bytes(&self.dir.join(&self.names[first + k]), text.as_bytes())?;
        }
        Ok(())
    }
}

/// Everything `upscale` writes: OBJ frames or geometry.npy, and the maps; the `.npy` files
/// are appended chunk by chunk, each appearing when complete ([`Outputs::finish`]).
struct Outputs {
    obj: Option<ObjSink>,
    geometry: Option<NpyWriter>,
    maps: Option<(NpyWriter, NpyWriter)>,
}

impl HrSink for Outputs {
    fn write(&mut self, first: usize, up: &Upscaled, keep: Range<usize>) -> Result<()> {
        let (a, n) = (keep.start, keep.len());
        if let Some(o) = &mut self.obj {
            o.write(first, up, keep)?;
        }
        if let Some(g) = &mut self.geometry {
            g.append(&up.hr.slice_batch(a, n))?;
        }
        if let Some((b, e)) = &mut self.maps {
            b.append(&up.boundary.slice_batch(a, n))?;
            e.append(&up.enhance.slice_batch(a, n))?;
        }
        Ok(())
    }
}

impl Outputs {
    fn finish(self) -> Result<()> {
        if let Some(g) = self.geometry {
            g.finish()?;
        }
        if let Some((b, e)) = self.maps {
            b.finish()?;
            e.finish()?;
        }
        Ok(())
    }
}

/// The domain OBJ frames are encoded with: none needed for a model in the cloth frame writing
/// OBJ ([`Domain::UNIT`]: each frame then depends on itself alone); otherwise the bounding box
/// of the whole shot (not of a `--frames` slice, so slices agree), from one reading pass.
fn obj_domain(seq: &ObjSequence, model: &AnisoCb, fmt: &str, margin: f32) -> Result<(Domain, String)> {
    if model.input_frame() == InputFrame::Cloth && fmt == "obj" {
        return Ok((Domain::UNIT, "no domain needed: the model works in each frame's cloth frame".into()));
    }
    if !(margin.is_finite() && margin >= 0.0) {
        return Err(Error::config(format!("--margin must be ≥ 0, got {margin}")));
    }
    let pb = progress(seq.len() as u64, "bounds");
    let mut b = Bounds::default();
    for k in 0..seq.len() {
        b.add(&seq.frame(k)?);
        pb.set_position(k as u64 + 1);
    }
    pb.finish_and_clear();
    let d = b.domain(margin);
    let note = format!(
        "domain = bounding box of all frames + {:.0}% margin: bmin {:?}, bmax {:?} (m)",
        margin * 100.0,
        d.bmin,
        d.bmax
    );
    Ok((d, note))
}

pub fn run(a: Args) -> Result<()> {
    set_threads(a.threads)?;
    let ops = crate::cuda::ops_for_device(&a.device)?;
    let model = load_model(a.weights.as_deref())?;
    let r = model.scale();
    // The shot, its domain, and (OBJ input) its files' names and attributes.
    let (mut shot, domain, domain_note, obj_in) = match npy_input(&a.input) {
        Some(gp) => {
            let dp = gp.with_file_name("domain.npy");
            let domain = Domain::from_tensor(&read_npy(&dp)?).map_err(|e| e.in_file(&dp))?;
            let frames = NpyFrames::open(&gp)?;
            let s = &frames.header.shape;
            if s.len() != 4 || s[1] != 3 || s[2] < 2 || s[3] < 2 || s[0] == 0 {
                return Err(Error::format(
                    &gp,
                    format!("geometry images must have shape (T, 3, H, W) with T ≥ 1, H, W ≥ 2; got {s:?}"),
                ));
            }
            (Shot::Npy { frames, path: gp.clone() }, domain, format!("domain from {}", dp.display()), None)
        }
        None => {
            let seq = ObjSequence::open(&obj_files(&a.input)?)?;
            let fmt = if a.format == "npy" { "npy" } else { "obj" };
            let (domain, note) = obj_domain(&seq, &model, fmt, a.margin)?;
            let names: Vec<String> =
                seq.files.iter().map(|p| p.file_name().unwrap().to_string_lossy().into_owned()).collect();
            let g = &seq.first;
            if let Some(why) = &g.uv_note {
                eprintln!("note: {}: {why}", seq.files[0].display());
            }
            let uv = g.uv.as_ref().map(|uv| upscale_uv(uv, g.mesh.w, g.mesh.h, r));
            let obj = (names, g.style, uv, g.attrs.clone());
            (Shot::Obj { seq: Box::new(seq), domain }, domain, note, Some(obj))
        }
    };
    let (t, w, h) = shot.size();
    let range = parse_frames(a.frames.as_deref(), t)?;
    let sliced = range.len() != t;
    let fmt = match (a.format.as_str(), &obj_in) {
        ("auto", Some(_)) | ("obj", _) => "obj",
        _ => "npy",
    };
    ensure_dir(&a.out)?;
    eprintln!(
        "upscaling frames {}..{} of {t}, {w}x{h} -> {}x{} ({}), η = {}",
        range.start,
        range.end,
        r * w,
        r * h,
        ops.name(),
        a.eta
    );
    eprintln!("{domain_note}");
    let suffix = if sliced { format!(".{}-{}", range.start, range.end) } else { String::new() };
    let npy_name = |stem: &str| format!("{stem}{suffix}.npy");
    let names: Vec<String> = match &obj_in {
        Some((names, ..)) => names.clone(),
        None => (0..t).map(|k| format!("frame_{k:04}.obj")).collect(),
    };
    // A rerun after a kill: clear the temp files the killed run left (every file below is
    // written atomically, so the outputs themselves are either complete or absent).
    let mut outputs: Vec<PathBuf> = ["geometry", "domain", "boundary", "enhance"]
        .iter()
        .map(|n| a.out.join(npy_name(n)))
        .chain([a.out.join(format!("upscale{suffix}.json"))])
        .collect();
    outputs.extend(names[range.clone()].iter().map(|n| a.out.join(n)));
    for p in &outputs {
        remove_stale_temps(p)?;
    }
    let params = UpscaleParams {
        eta: a.eta,
        batch: a.batch,
        temporal: a.temporal,
        strain_iters: a.strain_iters,
        ..UpscaleParams::default()
    };
    let pb = progress(range.len() as u64, "upscale");
    let mut on_frames = |k: usize| pb.set_position(k as u64);
    let start = Instant::now();
    let maps = if a.maps {
        let shape = [range.len(), 1, r * h, r * w];
        Some((
            NpyWriter::create(&a.out.join(npy_name("boundary")), &shape)?,
            NpyWriter::create(&a.out.join(npy_name("enhance")), &shape)?,
        ))
    } else {
        None
    };
    let mut out = Outputs { obj: None, geometry: None, maps };
    if fmt == "obj" {
        let (quads, uv, attrs) = match obj_in {
            Some((_, style, uv, attrs)) => (style != FaceStyle::Triangles, uv, attrs),
            None => (true, None, ObjAttrs::default()),
        };
        out.obj = Some(ObjSink { dir: a.out.clone(), names, domain, quads, uv, attrs });
    } else {
        let shape = [range.len(), 3, r * h, r * w];
        out.geometry = Some(NpyWriter::create(&a.out.join(npy_name("geometry")), &shape)?);
    }
    let chunk = a.chunk;
    upscale_stream(
        ops.as_ref(),
        &model,
        &mut shot,
        &domain,
        range.clone(),
        &params,
        chunk,
        &mut out,
        &mut on_frames,
    )?;
    out.finish()?;
    if fmt == "npy" {
        write_npy(&a.out.join(npy_name("domain")), &domain.to_tensor())?;
    }
    let secs = start.elapsed().as_secs_f64();
    pb.finish_and_clear();
    let n = range.len();
    let size = |w: usize, h: usize| vec![Value::num(w), Value::num(h)];
    let summary = Object::new()
        .num("frames", n)
        .val("range", vec![Value::num(range.start), Value::num(range.end)])
        .val("lr", size(w, h))
        .val("hr", size(r * w, r * h))
        .num("eta", a.eta)
        .str("device", ops.name())
        .num("seconds", format!("{secs:.3}"))
        .num("ms_per_frame", format!("{:.3}", 1e3 * secs / n as f64))
        .val(
            "domain",
            Object::new().val("bmin", Value::reals(&domain.bmin)).val("bmax", Value::reals(&domain.bmax)),
        );
    write_json(&a.out.join(format!("upscale{suffix}.json")), &summary.into(), Layout::Compact)?;
    println!(
        "upscaled {n} frames {w}x{h} -> {}x{} in {secs:.2} s ({:.1} ms/frame) -> {} ({fmt})",
        r * w,
        r * h,
        1e3 * secs / n as f64,
        a.out.display()
    );
    Ok(())
}
