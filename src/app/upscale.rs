//! `anisocb upscale INPUT... --out DIR`: LR cloth animation in, HR animation out, streamed a
//! chunk of frames at a time (memory bounded by `--chunk`, not the shot), any `--frames`
//! slice giving the same bytes as the whole shot.

use super::setup::{load_model, parse_threads, set_threads};
use super::ui::progress;
use crate::cloth::run_io::DOMAIN_MARGIN;
use crate::error::{Error, Result};
use crate::geom::cloth_frame::InputFrame;
use crate::geom::geometry_image::{image_to_mesh, mesh_to_image, Bounds};
use crate::geom::obj::{
    list_obj_files, natural_cmp, obj_text_with, FaceStyle, ObjAttrs, ObjGrid, ObjSequence,
};
use crate::geom::{Domain, GridMesh};
use crate::io::atomic::{ensure_dir, remove_stale_temps, write_atomic_bytes, AtomicFile};
use crate::io::json::{write_json, Layout, Object, Value};
use crate::io::npy::{NpyFrames, NpyWriter};
use crate::io::point_cache::{write_frame, write_header, CacheFormat, CacheHeader, PointCacheReader};
use crate::io::read_npy;
use crate::io::write_npy;
use crate::sr::compose::DEFAULT_ETA;
use crate::sr::stream::{upscale_stream, HrSink, LrSource, DEFAULT_CHUNK};
use crate::sr::upscale::{upscale_meshes, upscale_uv, UpscaleParams, Upscaled};
use crate::tensor::Tensor;
use std::cell::RefCell;
use std::collections::{BTreeMap, HashMap};
use std::ffi::OsString;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::rc::Rc;
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
mtllib/usemtl/o/g/s kept; or geometry.npy + domain.npy).

Finished or not: OUT/upscale.json (upscale.A-B.json for a --frames slice) is written first, before
any frame, with \"complete\": false, and replaced by the run's summary with \"complete\": true only
after every frame is written. A folder whose upscale.json is missing or says \"complete\": false was
stopped part-way (killed, or an input frame failed): its frames may mix this run's with an earlier
one's. Run the same command again to complete it; the input is never overwritten.")]
pub struct Args {
    /// OBJ files, a directory of OBJ files, a run directory with geometry.npy, a geometry.npy,
    /// or a point cache (.pc2 / .mdd, with --rest).
    #[arg(required = true)]
    pub input: Vec<PathBuf>,
    /// Output directory (created if missing; existing frames with the same names are replaced).
    /// Never the input's own folder: the input is never overwritten.
    #[arg(long)]
    pub out: PathBuf,
    /// Wrinkle enhancement η from -1 to 10 (Eq 12): 0 = plain predicted detail (the default,
    /// chosen on validation runs; EnhanceNet is then not run), larger = deeper wrinkles where
    /// EnhanceNet sees edges (up to 1 + η times the predicted detail), below 0 = softer (-1
    /// removes them there). With the wrinkle model and --gate-coarse-only it scales the folds
    /// finer than the LR grid (docs/wrinkles.md). Smooth cloth and the border are unaffected.
    #[arg(long, default_value_t = DEFAULT_ETA, allow_negative_numbers = true)]
    pub eta: f32,
    /// Temporal smoothing radius in frames of the predicted detail and of the boundary and
    /// wrinkle maps that gate it, in the cloth's own frame (1 = weights ¼ ½ ¼ over the
    /// previous, this and the next frame; 0 = every frame on its own, the default). Off by
    /// default because mirror averaging already removes the detail's frame-to-frame noise and
    /// smoothing then measured worse (most on cloth that keeps turning); it can still calm a
    /// one-pass (`--mirrors false`) result. At most 64.
    #[arg(long, default_value_t = crate::sr::upscale::DEFAULT_TEMPORAL)]
    pub temporal: usize,
    /// Strain limit: iterations pulling the output's edge lengths toward those of the input
    /// frame (0 = off). About 10 removes swimming and frame-to-frame edge flicker on cloth that
    /// barely stretches (flags, drapes: also −6 % error); do not use it on cloth that stretches
    /// a lot (rubber, strongly twisted strips), where it makes the result worse.
    #[arg(long, default_value_t = crate::sr::upscale::DEFAULT_STRAIN_ITERS)]
    pub strain_iters: usize,
    /// Average the nets over the grid's four mirror images (as given, flipped left-right,
    /// top-bottom, both; each in its own cloth frame): the detail no longer depends on which
    /// way the grid runs, and what one view invents is averaged out (smoother shading, less
    /// flicker). 4× the network time; `--mirrors false` for one pass.
    #[arg(long, default_value_t = crate::sr::upscale::DEFAULT_MIRRORS, action = clap::ArgAction::Set)]
    pub mirrors: bool,
    /// Outline floor: the output's border is never shorter than the LR frame's own border
    /// polyline; where the nets' correction would shorten it, its part along the surface
    /// normal (what flattens a hem's folds) is scaled down on the two outermost rings of
    /// vertices just enough. For draped cloth from other tools (Blender tablecloths), whose
    /// hanging hems fold more than the training cloth's and whose outline the nets then
    /// shorten by up to 0.7 %. On by default (chosen on validation scenes); `false` saves
    /// 1–2 % vertex error on cloth whose true outline is shorter than the LR one (strongly
    /// twisted strips) and gives the nets' border as it is.
    #[arg(long, default_value_t = crate::sr::upscale::DEFAULT_KEEP_OUTLINE, action = clap::ArgAction::Set)]
    pub keep_outline: bool,
    /// BoundaryNet gates only the coarse part of the predicted detail (what the LR grid can
    /// hold); folds finer than the LR grid are kept as GeometryNet predicts them. For the
    /// wrinkle model (docs/wrinkles.md), whose BoundaryNet would otherwise flatten them.
    #[arg(long)]
    pub gate_coarse_only: bool,
    /// Keep the outermost ring of vertices exactly where the interpolated input puts them
    /// (the outline is then the LR outline's interpolation, whatever the nets predict there).
    /// Off by default: the nets correct the border too, which measured closer to the truth.
    #[arg(long)]
    pub pin_border: bool,
    /// Weights file (.npz bundle of the three nets) instead of the embedded ×2 model.
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// Frames per network pass (more = faster, more memory).
    #[arg(long, default_value_t = 8)]
    pub batch: usize,
    /// Worker threads, 1 to 1024 (default: all cores).
    #[arg(long, value_parser = parse_threads)]
    pub threads: Option<usize>,
    /// Compute device: cpu or cuda.
    #[arg(long, default_value = "cpu")]
    pub device: String,
    /// Output format: auto (same as input), obj or npy.
    #[arg(long, default_value = "auto", value_parser = ["auto", "obj", "npy"])]
    pub format: String,
    /// Domain margin for OBJ and point-cache input, as a fraction of the sequence's largest
    /// extent, from 0 to 1.
    #[arg(long, default_value_t = DOMAIN_MARGIN)]
    pub margin: f32,
    /// Also write the predicted boundary and wrinkle-edge maps (boundary.npy, enhance.npy).
    #[arg(long)]
    pub maps: bool,
    /// Rest mesh of a point-cache input (.pc2/.mdd): the OBJ whose vertices the cache moves,
    /// in the same order (export both from the same object). Its connectivity, UVs and
    /// material are used; the output gets an HR rest OBJ of the same name beside the HR cache.
    #[arg(long, value_name = "OBJ")]
    pub rest: Option<PathBuf>,
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

/// Largest `--margin` (a fraction of the shot's extent): beyond it the shot fills a sliver of
/// the geometry image and f32 loses its detail (at 1e30 every pixel reads 0.5).
pub const MAX_MARGIN: f32 = 1.0;

/// Refuse `--margin` outside 0 ..= [`MAX_MARGIN`] (NaN included).
fn check_margin(margin: f32) -> Result<()> {
    if !(margin.is_finite() && (0.0..=MAX_MARGIN).contains(&margin)) {
        return Err(Error::config(format!(
            "--margin must be a fraction of the shot's extent from 0 to {MAX_MARGIN}, got {margin} \
             (the default {DOMAIN_MARGIN} suits any shot)"
        )));
    }
    Ok(())
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
    /// An OBJ sequence, encoded with `domain` as it is read; each frame's file attributes go to
    /// `attrs` until its HR frame is written.
    Obj { seq: Box<ObjSequence>, domain: Domain, attrs: FrameAttrs },
    /// A point cache; `order[j*w + i]` is the cache point at grid vertex (i, j) (from the rest
    /// mesh).
    Cache { cache: PointCacheReader, order: Vec<u32>, w: usize, h: usize, domain: Domain },
}

impl Shot {
    /// (frames, columns, rows).
    fn size(&self) -> (usize, usize, usize) {
        match self {
            Shot::Npy { frames, .. } => (frames.frames(), frames.header.shape[3], frames.header.shape[2]),
            Shot::Obj { seq, .. } => (seq.len(), seq.first.mesh.w, seq.first.mesh.h),
            Shot::Cache { cache, w, h, .. } => (cache.header().frames, *w, *h),
        }
    }

    /// Encode OBJ and cache frames with `d` from now on (`.npy` frames come with theirs).
    fn set_domain(&mut self, d: Domain) {
        match self {
            Shot::Obj { domain, .. } | Shot::Cache { domain, .. } => *domain = d,
            Shot::Npy { .. } => {}
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
            Shot::Obj { seq, domain, attrs } => {
                let (w, h) = (seq.first.mesh.w, seq.first.mesh.h);
                let mut t = Tensor::zeros(&[range.len(), 3, h, w]);
                for (k, f) in range.enumerate() {
                    let (mesh, a) = seq.frame_and_attrs(f)?;
                    attrs.borrow_mut().insert(f, a);
                    put_frame(&mut t, k, &mesh, domain);
                }
                for note in seq.take_notes() {
                    eprintln!("note: {note}");
                }
                Ok(t)
            }
            Shot::Cache { cache, order, w, h, domain } => {
                let (w, h, n) = (*w, *h, cache.header().points);
                let pts = cache.read_frames(range.clone())?;
                let mut t = Tensor::zeros(&[range.len(), 3, h, w]);
                for (k, frame) in pts.chunks_exact(n).enumerate() {
                    let mesh = GridMesh::new(w, h, order.iter().map(|&v| frame[v as usize]).collect());
                    put_frame(&mut t, k, &mesh, domain);
                }
                Ok(t)
            }
        }
    }
}

/// Frame `k` of the (n, 3, H, W) images `t`: `mesh` encoded with `domain` (Eq 1).
fn put_frame(t: &mut Tensor, k: usize, mesh: &GridMesh, domain: &Domain) {
    let n = 3 * mesh.w * mesh.h;
    t.data[k * n..(k + 1) * n].copy_from_slice(&mesh_to_image(mesh, domain).data);
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

/// Notes on gaps in the frame numbers of `files` (sorted): `cloth_0011.obj` then
/// `cloth_0015.obj` where the shot otherwise steps by 1 means three frames were not exported
/// (playback of the output jumps there). The step is the most common difference between
/// consecutive numbers (a shot exported every other frame steps by 2); names without a
/// trailing number, or with different stems, say nothing.
fn frame_gaps(files: &[PathBuf]) -> Vec<String> {
    let split = |p: &PathBuf| -> Option<(String, u64)> {
        let stem = p.file_stem()?.to_str()?;
        let digits = stem.len() - stem.bytes().rev().take_while(u8::is_ascii_digit).count();
        let n = stem[digits..].parse().ok()?;
        Some((format!("{}/{}", folder_of(p).display(), &stem[..digits]), n))
    };
    let Some(nums) = files.iter().map(split).collect::<Option<Vec<_>>>() else { return Vec::new() };
    let pairs: Vec<(usize, u64)> = (1..nums.len())
        .filter(|&k| nums[k].0 == nums[k - 1].0 && nums[k].1 > nums[k - 1].1)
        .map(|k| (k, nums[k].1 - nums[k - 1].1))
        .collect();
    let mut counts: Vec<(u64, usize)> = Vec::new();
    for &(_, d) in &pairs {
        match counts.iter_mut().find(|c| c.0 == d) {
            Some(c) => c.1 += 1,
            None => counts.push((d, 1)),
        }
    }
    let Some(&(step, _)) = counts.iter().max_by_key(|c| (c.1, std::cmp::Reverse(c.0))) else {
        return Vec::new();
    };
    pairs
        .iter()
        .filter(|&&(_, d)| d > step && d % step == 0)
        .map(|&(k, d)| {
            format!(
                "{} frame number(s) missing between {} and {}: the output has no frames there \
                 either (playback jumps)",
                d / step - 1,
                files[k - 1].display(),
                files[k].display()
            )
        })
        .collect()
}

/// Refuse OBJ frames that would be written to one output file, before anything is read or
/// written: a file given twice, the same name in two folders (two shots would merge into
/// one, one overwriting the other), or names that differ only in bytes that are not UTF-8
/// (`caf\xE9.obj`, `caf\xE8.obj`: they read alike and have no reliable frame order).
fn refuse_colliding_names(files: &[PathBuf]) -> Result<()> {
    let mut seen: HashMap<String, &PathBuf> = HashMap::new();
    for f in files {
        let name = f.file_name().unwrap_or_default().to_string_lossy().into_owned();
        let Some(prev) = seen.insert(name.clone(), f) else { continue };
        let msg = if same_file(prev, f) {
            format!("{} is given twice; give each frame once", f.display())
        } else if prev.file_name() == f.file_name() {
            format!(
                "{} and {} would both be written as {name} in --out, one shot overwriting the other; \
                 upscale each folder into its own --out",
                prev.display(),
                f.display()
            )
        } else {
            format!(
                "{prev:?} and {f:?} have names that differ only in bytes that are not UTF-8 text (both \
                 read {name:?}), so their frame order is ambiguous; rename them (e.g. frame_0001.obj)"
            )
        };
        return Err(Error::config(msg));
    }
    Ok(())
}

/// Refuse two outputs of one run with the same path (a point cache's rest mesh named like an
/// output frame, …): the later would silently replace the earlier.
fn refuse_duplicate_outputs(outputs: &[PathBuf]) -> Result<()> {
    let mut seen = std::collections::HashSet::new();
    match outputs.iter().find(|p| !seen.insert(*p)) {
        Some(p) => Err(Error::config(format!(
            "{} would be written twice by this run (an input's name clashes with an output's); \
             rename the input",
            p.display()
        ))),
        None => Ok(()),
    }
}

/// Per-frame OBJ attributes (`mtllib` …) of input frames read but not yet written, by frame.
type FrameAttrs = Rc<RefCell<BTreeMap<usize, ObjAttrs>>>;

/// OBJ frames written one file per frame, the way the input was: each with its own input
/// frame's attributes (from `attrs`; the first frame's for non-OBJ input).
struct ObjSink {
    dir: PathBuf,
    domain: Domain,
    mesh: MeshOut,
    attrs: FrameAttrs,
}

impl HrSink for ObjSink {
    fn write(&mut self, first: usize, up: &Upscaled, keep: Range<usize>) -> Result<()> {
        for (k, f) in keep.enumerate() {
            let hr = image_to_mesh(&up.hr, f, &self.domain);
            let attrs =
                self.attrs.borrow_mut().remove(&(first + k)).unwrap_or_else(|| self.mesh.attrs.clone());
            let text = self.mesh.obj_text(&hr, &attrs);
            write_atomic_bytes(&self.dir.join(&self.mesh.names[first + k]), text.as_bytes())?;
        }
        Ok(())
    }
}

/// An HR point cache, frames appended in order, appearing when complete.
struct CacheSink {
    file: AtomicFile,
    format: CacheFormat,
    domain: Domain,
    frames: usize,
    written: usize,
}

impl HrSink for CacheSink {
    fn write(&mut self, _first: usize, up: &Upscaled, keep: Range<usize>) -> Result<()> {
        for f in keep {
            let mesh = image_to_mesh(&up.hr, f, &self.domain);
            let path = self.file.path().to_path_buf();
            write_frame(self.file.writer(), self.format, &mesh.pos).map_err(|e| Error::io(path, e))?;
            self.written += 1;
        }
        Ok(())
    }
}

impl CacheSink {
    fn finish(self) -> Result<()> {
        if self.written != self.frames {
            return Err(Error::shape(format!(
                "{}: {} of {} frames written",
                self.file.path().display(),
                self.written,
                self.frames
            )));
        }
        self.file.commit()
    }
}

/// Everything `upscale` writes: OBJ frames or geometry.npy, and the maps; the `.npy` files
/// are appended chunk by chunk, each appearing when complete ([`Outputs::finish`]).
struct Outputs {
    obj: Option<ObjSink>,
    cache: Option<CacheSink>,
    geometry: Option<NpyWriter>,
    maps: Option<(NpyWriter, NpyWriter)>,
}

impl HrSink for Outputs {
    fn write(&mut self, first: usize, up: &Upscaled, keep: Range<usize>) -> Result<()> {
        let (a, n) = (keep.start, keep.len());
        if let Some(o) = &mut self.obj {
            o.write(first, up, keep.clone())?;
        }
        if let Some(c) = &mut self.cache {
            c.write(first, up, keep.clone())?;
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
        if let Some(c) = self.cache {
            c.finish()?;
        }
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

/// The bounding box of a whole shot read in [`Domain::UNIT`] (images = metres), grown by
/// `margin`: one reading pass, a chunk at a time.
fn shot_bounds(shot: &mut Shot, margin: f32, chunk: usize) -> Result<Domain> {
    check_margin(margin)?;
    let t = shot.frames();
    let pb = progress(t as u64, "bounds");
    let mut b = Bounds::default();
    let mut at = 0;
    while at < t {
        let n = chunk.max(1).min(t - at);
        let img = shot.read(at..at + n)?;
        for k in 0..n {
            b.add(&image_to_mesh(&img, k, &Domain::UNIT));
        }
        at += n;
        pb.set_position(at as u64);
    }
    pb.finish_and_clear();
    Ok(b.domain(margin))
}

/// What an OBJ-based input (an OBJ sequence, or a point cache's rest mesh) gives the output.
struct MeshOut {
    /// Output names per frame of the shot (OBJ output): an OBJ input's own file names, byte
    /// for byte.
    names: Vec<OsString>,
    style: FaceStyle,
    /// HR texture coordinates, if the input had usable ones.
    uv: Option<Vec<[f32; 2]>>,
    attrs: ObjAttrs,
}

impl MeshOut {
    fn of(g: &ObjGrid, file: &Path, names: Vec<OsString>, r: usize) -> MeshOut {
        if let Some(why) = &g.uv_note {
            eprintln!("note: {}: {why}", file.display());
        }
        let uv = g.uv.as_ref().map(|uv| upscale_uv(uv, g.mesh.w, g.mesh.h, r));
        MeshOut { names, style: g.style, uv, attrs: g.attrs.clone() }
    }

    /// OBJ text of an HR frame with `attrs` (its input frame's; the rest mesh's for caches).
    fn obj_text(&self, mesh: &GridMesh, attrs: &ObjAttrs) -> String {
        obj_text_with(mesh, self.style != FaceStyle::Triangles, self.uv.as_deref(), attrs)
    }
}

/// [`unlike_edges`]: an edge is unlike its rest edge when their length ratio is more than
/// this far (either way) from the median ratio (a cache may scale the whole object).
const EDGE_RATIO: f32 = 1.5;

/// Largest fraction of unlike edges a point cache's frame 0 may have against its rest mesh:
/// cloth stretches by a few percent; a cache whose points are in another order than the rest
/// mesh's vertices has most of its edges unlike (edges 3.6× longer on average for a shuffled
/// sheet).
const MAX_UNLIKE_EDGES: f64 = 0.1;

/// The fraction of `a`'s edges whose length ratio to the same edge of `b` is more than
/// [`EDGE_RATIO`] from the median ratio (edges of length 0 in `b` left out).
fn unlike_edges(a: &GridMesh, b: &GridMesh) -> f64 {
    let mut ratio: Vec<f32> =
        a.edge_lengths().iter().zip(b.edge_lengths()).filter(|e| e.1 > 0.0).map(|(x, y)| x / y).collect();
    if ratio.is_empty() {
        return 0.0;
    }
    ratio.sort_by(f32::total_cmp);
    let m = ratio[ratio.len() / 2];
    let odd = ratio.iter().filter(|&&q| !(q <= m * EDGE_RATIO && q * EDGE_RATIO >= m)).count();
    odd as f64 / ratio.len() as f64
}

/// A point-cache input: the cache file, its header and its rest mesh.
struct CacheIn {
    path: PathBuf,
    header: CacheHeader,
    rest: PathBuf,
    rest_grid: ObjGrid,
}

/// What the user gave, opened.
struct Input {
    /// The frames (OBJ and cache frames read in [`Domain::UNIT`] until the domain is settled).
    shot: Shot,
    /// The domain of `.npy` input.
    npy_domain: Option<Domain>,
    /// What OBJ-based input gives the output.
    mesh_out: Option<MeshOut>,
    cache_in: Option<CacheIn>,
    /// Every file the input is read from (kept safe from the output, [`refuse_out_over_input`]).
    files: Vec<PathBuf>,
}

/// The folder holding `file` as named (`.` for a bare name).
fn folder_of(file: &Path) -> &Path {
    file.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."))
}

/// Whether `a` and `b` are one file (the same inode: also through hard and symbolic links).
fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        match (std::fs::metadata(a), std::fs::metadata(b)) {
            (Ok(x), Ok(y)) => x.dev() == y.dev() && x.ino() == y.ino(),
            _ => false,
        }
    }
    #[cfg(not(unix))]
    {
        matches!((a.canonicalize(), b.canonicalize()), (Ok(x), Ok(y)) if x == y)
    }
}

/// Refuse, before anything is written, an `--out` that would overwrite the input: the folder
/// of an input file, however it is spelled (`..`, a link to it, or the folder a linked input
/// file really lives in: the HR files would replace the LR ones, and the same command run
/// again would upscale its own output), or a folder where an output file already is one of
/// the input files under another name (a hard link).
fn refuse_out_over_input(out: &Path, inputs: &[PathBuf], outputs: &[PathBuf]) -> Result<()> {
    // A folder that does not exist yet holds no input.
    let Ok(out_c) = out.canonicalize() else { return Ok(()) };
    for f in inputs {
        let real_folder = f.canonicalize().ok().and_then(|c| c.parent().map(Path::to_path_buf));
        if [folder_of(f).canonicalize().ok(), real_folder].iter().flatten().any(|d| *d == out_c) {
            return Err(Error::config(format!(
                "--out {} is the folder of the input {}: the HR files would replace the input's; \
                 give a new folder as --out (the input is left as it is)",
                out.display(),
                f.display()
            )));
        }
        if let Some(o) = outputs.iter().find(|o| same_file(o, f)) {
            return Err(Error::config(format!(
                "--out {}: {} is the input {} under another name (a link), and would be \
                 overwritten; give a new folder as --out",
                out.display(),
                o.display(),
                f.display()
            )));
        }
    }
    Ok(())
}

fn open_input(a: &Args, r: usize) -> Result<Input> {
    let first = &a.input[0];
    if let Some(gp) = npy_input(&a.input) {
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
        let files = vec![gp.clone(), dp];
        let shot = Shot::Npy { frames, path: gp };
        return Ok(Input { shot, npy_domain: Some(domain), mesh_out: None, cache_in: None, files });
    }
    if a.input.len() == 1 && CacheFormat::from_path(first).is_some() {
        let Some(rest) = &a.rest else {
            return Err(Error::config(format!(
                "{}: a point cache holds positions only; give the mesh they move with --rest MESH.obj \
                 (exported from the same object, same vertex order)",
                first.display()
            )));
        };
        let cache = PointCacheReader::open(first)?;
        let seq = ObjSequence::open(std::slice::from_ref(rest))?;
        let g = seq.first;
        let nv = g.mesh.w * g.mesh.h;
        if cache.header().points != nv {
            return Err(Error::format(
                first,
                format!(
                    "the cache moves {} points but the rest mesh {} has {nv} vertices: export both from the same object",
                    cache.header().points,
                    rest.display()
                ),
            ));
        }
        // Points in another order than the rest mesh's vertices (another export, another
        // object) make a crumpled sheet whose edges have nothing to do with the rest mesh's.
        let mut cache = cache;
        let f0 = cache.read_frames(0..1)?;
        let frame0 = GridMesh::new(g.mesh.w, g.mesh.h, g.order.iter().map(|&v| f0[v as usize]).collect());
        let odd = unlike_edges(&frame0, &g.mesh);
        if odd > MAX_UNLIKE_EDGES {
            return Err(Error::format(
                first,
                format!(
                    "in frame 0 of the cache, {:.0} % of the edges are over {EDGE_RATIO}× longer or \
                     shorter than the same edges of the rest mesh {} (relative to the typical edge; \
                     cloth stretches by a few percent): the cache's points are not in the rest \
                     mesh's vertex order, or belong to another object; export both from the same \
                     object",
                    100.0 * odd,
                    rest.display()
                ),
            ));
        }
        let t = cache.header().frames;
        let out = MeshOut::of(&g, rest, (0..t).map(|k| format!("frame_{k:04}.obj").into()).collect(), r);
        let header = cache.header().clone();
        let (w, h, order) = (g.mesh.w, g.mesh.h, g.order.clone());
        let shot = Shot::Cache { cache, order, w, h, domain: Domain::UNIT };
        let cin = CacheIn { path: first.clone(), header, rest: rest.clone(), rest_grid: g };
        let files = vec![first.clone(), rest.clone()];
        return Ok(Input { shot, npy_domain: None, mesh_out: Some(out), cache_in: Some(cin), files });
    }
    let caches: Vec<&PathBuf> = a.input.iter().filter(|p| CacheFormat::from_path(p).is_some()).collect();
    if !caches.is_empty() {
        return Err(Error::config(format!(
            "{} inputs given, {} of them point caches ({}): upscale one point cache per run, alone, \
             with its --rest mesh",
            a.input.len(),
            caches.len(),
            caches.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ")
        )));
    }
    if a.rest.is_some() {
        return Err(Error::config("--rest is for point-cache input (.pc2 / .mdd) only"));
    }
    let files = obj_files(&a.input)?;
    refuse_colliding_names(&files)?;
    for gap in frame_gaps(&files) {
        eprintln!("warning: {gap}");
    }
    let seq = ObjSequence::open(&files)?;
    let names = seq.files.iter().map(|p| p.file_name().unwrap_or_default().to_os_string()).collect();
    let out = MeshOut::of(&seq.first, &seq.files[0], names, r);
    let files = seq.files.clone();
    let shot = Shot::Obj { seq: Box::new(seq), domain: Domain::UNIT, attrs: FrameAttrs::default() };
    Ok(Input { shot, npy_domain: None, mesh_out: Some(out), cache_in: None, files })
}

pub fn run(a: Args) -> Result<()> {
    // Every option checked before a file is read or a net runs.
    let params = UpscaleParams {
        eta: a.eta,
        enhance_map: a.maps,
        batch: a.batch,
        temporal: a.temporal,
        strain_iters: a.strain_iters,
        pin_border: a.pin_border,
        mirrors: a.mirrors,
        keep_outline: a.keep_outline,
        gate_coarse_only: a.gate_coarse_only,
    };
    params.validate()?;
    check_margin(a.margin)?;
    if a.chunk == 0 {
        return Err(Error::config("--chunk must be ≥ 1 frame (frames read, upscaled and written at a time)"));
    }
    set_threads(a.threads)?;
    let ops = crate::cuda::ops_for_device(&a.device)?;
    let model = load_model(a.weights.as_deref())?;
    let r = model.scale();
    let Input { mut shot, npy_domain, mesh_out, cache_in, files } = open_input(&a, r)?;
    let fmt = match (a.format.as_str(), &mesh_out, &cache_in) {
        ("auto", _, Some(c)) => c.header.format.name().to_lowercase(),
        ("auto", Some(_), None) | ("obj", ..) => "obj".to_string(),
        _ => "npy".to_string(),
    };
    let fmt = fmt.as_str();
    let (t, w, h) = shot.size();
    let range = parse_frames(a.frames.as_deref(), t)?;
    let sliced = range.len() != t;
    // Outputs of a slice carry its range in their names (OBJ frames keep their own names).
    let suffix = if sliced { format!(".{}-{}", range.start, range.end) } else { String::new() };
    let npy_name = |stem: &str| format!("{stem}{suffix}.npy");
    let mesh_out = mesh_out.unwrap_or_else(|| MeshOut {
        names: (0..t).map(|k| format!("frame_{k:04}.obj").into()).collect(),
        style: FaceStyle::Quads,
        uv: None,
        attrs: ObjAttrs::default(),
    });
    let cache_name = cache_in.as_ref().map(|c| {
        let stem = c.path.file_stem().unwrap_or_default().to_string_lossy().into_owned();
        format!("{stem}{suffix}.{}", c.header.format.name().to_lowercase())
    });
    // Every file this run may write.
    let mut outputs: Vec<PathBuf> = ["geometry", "domain", "boundary", "enhance"]
        .iter()
        .map(|n| a.out.join(npy_name(n)))
        .chain([a.out.join(format!("upscale{suffix}.json"))])
        .collect();
    outputs.extend(mesh_out.names[range.clone()].iter().map(|n| a.out.join(n)));
    outputs.extend(cache_name.iter().map(|n| a.out.join(n)));
    outputs.extend(cache_in.iter().filter_map(|c| c.rest.file_name()).map(|n| a.out.join(n)));
    refuse_out_over_input(&a.out, &files, &outputs)?;
    // What this run writes, each once.
    let mut writes = vec![a.out.join(format!("upscale{suffix}.json"))];
    match (fmt, &cache_name) {
        ("obj", _) => writes.extend(mesh_out.names[range.clone()].iter().map(|n| a.out.join(n))),
        ("npy", _) => writes.extend(["geometry", "domain"].map(|n| a.out.join(npy_name(n)))),
        (_, name) => writes.extend(name.iter().map(|n| a.out.join(n))),
    }
    if a.maps {
        writes.extend(["boundary", "enhance"].map(|n| a.out.join(npy_name(n))));
    }
    writes.extend(cache_in.iter().filter_map(|c| c.rest.file_name()).map(|n| a.out.join(n)));
    refuse_duplicate_outputs(&writes)?;
    // The domain: the file's for .npy input; none needed for a model in the cloth frame writing
    // meshes (each frame then depends on itself alone); otherwise the whole shot's bounding
    // box (not a --frames slice's, so slices agree).
    let (domain, domain_note) = match npy_domain {
        Some(d) => (d, "domain from domain.npy beside the input".to_string()),
        None if model.input_frame() == InputFrame::Cloth && fmt != "npy" => {
            (Domain::UNIT, "no domain needed: the model works in each frame's cloth frame".to_string())
        }
        None => {
            let d = shot_bounds(&mut shot, a.margin, a.chunk)?;
            shot.set_domain(d);
            let note = format!(
                "domain = bounding box of all frames + {:.0}% margin: bmin {:?}, bmax {:?} (m)",
                a.margin * 100.0,
                d.bmin,
                d.bmax
            );
            (d, note)
        }
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
    // A rerun after a kill: clear the temp files the killed run left (every file is written
    // atomically, so the outputs themselves are either complete or absent).
    for p in &outputs {
        remove_stale_temps(p)?;
    }
    // Until the final summary replaces it, the folder says it is unfinished: whatever stops the
    // run (a kill, a bad frame) leaves this marker, never an earlier run's summary.
    let summary_path = a.out.join(format!("upscale{suffix}.json"));
    let started = Object::new()
        .val("complete", Value::Bool(false))
        .num("frames", range.len())
        .val("range", vec![Value::num(range.start), Value::num(range.end)])
        .num("eta", a.eta)
        .str("note", "unfinished: this run was stopped part-way or failed; rerun the same command");
    write_json(&summary_path, &started.into(), Layout::Compact)?;
    let start = Instant::now();
    // A point cache plays on an HR rest mesh: the rest OBJ upscaled on its own.
    if let Some(c) = &cache_in {
        let rest = &c.rest_grid.mesh;
        let d = if domain == Domain::UNIT {
            domain
        } else {
            Domain::enclosing(std::slice::from_ref(rest), a.margin)
        };
        let (hr, _) =
            upscale_meshes(ops.as_ref(), &model, std::slice::from_ref(rest), &d, &params, &mut |_| {})?;
        let name = c.rest.file_name().unwrap_or_default();
        write_atomic_bytes(&a.out.join(name), mesh_out.obj_text(&hr[0], &mesh_out.attrs).as_bytes())?;
    }
    let maps = if a.maps {
        let shape = [range.len(), 1, r * h, r * w];
        Some((
            NpyWriter::create(&a.out.join(npy_name("boundary")), &shape)?,
            NpyWriter::create(&a.out.join(npy_name("enhance")), &shape)?,
        ))
    } else {
        None
    };
    let mut out = Outputs { obj: None, cache: None, geometry: None, maps };
    match (fmt, &cache_in) {
        ("obj", _) => {
            let attrs = match &shot {
                Shot::Obj { attrs, .. } => attrs.clone(),
                _ => FrameAttrs::default(),
            };
            out.obj = Some(ObjSink { dir: a.out.clone(), domain, mesh: mesh_out, attrs });
        }
        ("npy", _) => {
            let shape = [range.len(), 3, r * h, r * w];
            out.geometry = Some(NpyWriter::create(&a.out.join(npy_name("geometry")), &shape)?);
        }
        (_, Some(c)) => {
            let path = a.out.join(cache_name.as_deref().unwrap_or("cache"));
            let mut header = CacheHeader::new(c.header.format, r * r * w * h, range.len(), 1.0);
            // The slice's timing: PC2 start frame and sampling, MDD per-frame times.
            header.sample_rate = c.header.sample_rate;
            header.start_frame = c.header.start_frame + range.start as f32 * c.header.sample_rate;
            if !c.header.times.is_empty() {
                header.times = c.header.times[range.clone()].to_vec();
            }
            let mut file = AtomicFile::create(&path)?;
            write_header(file.writer(), &header).map_err(|e| Error::io(&path, e))?;
            out.cache =
                Some(CacheSink { file, format: header.format, domain, frames: range.len(), written: 0 });
        }
        _ => unreachable!("fmt is obj, npy, or a cache format for cache input"),
    }
    let pb = progress(range.len() as u64, "upscale");
    let mut on_frames = |k: usize| pb.set_position(k as u64);
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
        .val("complete", Value::Bool(true))
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
    write_json(&summary_path, &summary.into(), Layout::Compact)?;
    println!(
        "upscaled {n} frames {w}x{h} -> {}x{} in {secs:.2} s ({:.1} ms/frame) -> {} ({fmt})",
        r * w,
        r * h,
        1e3 * secs / n as f64,
        a.out.display()
    );
    Ok(())
}
