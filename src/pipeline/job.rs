//! One upscale job on files, as `anisocb upscale` runs it: open and check the input, plan and
//! check every output, settle the domain, stream the shot through the nets chunk by chunk into
//! the outputs, and write the run's summary (`upscale.json`). The command line is a thin layer
//! over [`upscale_files`]; a Rust program calls it the same way and gets the same bytes.

use super::folder::{self, Ownership};
use super::input::{open_input, shot_bounds, CacheIn, FrameAttrs, Input, MeshOut, Shot};
use super::output::{refuse_duplicate_outputs, refuse_out_over_input, CacheSink, Decode, ObjSink, Outputs};
use super::physics::{MeshPhysicsPass, PhysicsSink};
use crate::cloth::follow::{FollowOutput, FollowParams};
use crate::cloth::run_io::DOMAIN_MARGIN;
use crate::error::{Error, Result};
use crate::geom::cloth_frame::InputFrame;
use crate::geom::Domain;
use crate::io::atomic::{remove_stale_temps, write_atomic_bytes, AtomicFile};
use crate::io::json::{write_json, Layout, Object, Value};
use crate::io::npy::NpyWriter;
use crate::io::point_cache::{write_header, CacheHeader};
use crate::io::write_npy;
use crate::nn::bundle::AnisoCb;
use crate::ops::Ops;
pub use crate::ops::Precision;
use crate::pipeline::stream::{upscale_stream, DEFAULT_CHUNK};
use crate::sr::params::UpscaleParams;
use crate::sr::upscale::upscale_meshes;
use std::cell::RefCell;
use std::ops::Range;
use std::path::PathBuf;
use std::rc::Rc;
use std::time::Instant;

/// The output format of a job.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputFormat {
    /// The input's: OBJ files for OBJ input, the same cache format for a point cache,
    /// geometry.npy for geometry.npy.
    Auto,
    /// One OBJ file per frame.
    Obj,
    /// geometry.npy (T, 3, 2H, 2W) + domain.npy.
    Npy,
}

/// Frames `start..end` of a shot (0-based, `end` exclusive; `None`: to the shot's end).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameSpan {
    pub start: usize,
    pub end: Option<usize>,
}

impl FrameSpan {
    /// `A:B` or `A:`.
    pub fn parse(spec: &str) -> Result<FrameSpan> {
        let bad = || Error::invalid("frames", format!("{spec}: expected A:B (0-based, B exclusive) or A:"));
        let (a, b) = spec.split_once(':').ok_or_else(bad)?;
        let start = a.trim().parse().map_err(|_| bad())?;
        let end = if b.trim().is_empty() { None } else { Some(b.trim().parse().map_err(|_| bad())?) };
        let span = FrameSpan { start, end };
        span.check()?;
        Ok(span)
    }

    /// Refuse a span that is empty whatever the shot (B ≤ A).
    fn check(self) -> Result<()> {
        match self.end {
            Some(b) if b <= self.start => Err(Error::invalid(
                "frames",
                format!("{}:{b} is empty: expected A:B with A < B (0-based, B exclusive)", self.start),
            )),
            _ => Ok(()),
        }
    }

    /// The frames of a shot of `t` frames.
    pub fn range(self, t: usize) -> Result<Range<usize>> {
        let end = self.end.unwrap_or(t);
        if self.start >= end || end > t {
            let b = self.end.map_or(String::new(), |b| b.to_string());
            return Err(Error::invalid(
                "frames",
                format!("{}:{b} is not in the shot: expected A:B or A: with 0 ≤ A < B ≤ {t}", self.start),
            ));
        }
        Ok(self.start..end)
    }
}

/// What to upscale, where to, and how: [`UpscaleJob::check`] makes it a [`CheckedJob`], which
/// [`upscale_files`] runs.
#[derive(Clone, Debug)]
pub struct UpscaleJob {
    /// OBJ files, folders of OBJ files, a run folder or geometry.npy, or one point cache
    /// (.pc2 / .mdd, with `rest`).
    pub inputs: Vec<PathBuf>,
    /// Output folder (created if missing); never the input's own folder.
    pub out: PathBuf,
    /// Rest mesh of a point-cache input.
    pub rest: Option<PathBuf>,
    pub format: OutputFormat,
    /// Frames of the shot, or all of them. A slice gives exactly the bytes the whole shot
    /// gives for its frames.
    pub frames: Option<FrameSpan>,
    /// Domain margin for OBJ and point-cache input, a fraction of the shot's largest extent
    /// (0 to [`MAX_MARGIN`]).
    pub margin: f32,
    /// Frames read, upscaled and written at a time (memory is bounded by it).
    pub chunk: usize,
    /// Also write the boundary and wrinkle-edge maps (boundary.npy, enhance.npy).
    pub maps: bool,
    pub params: UpscaleParams,
    /// The physics pass: the nets' frames pass through an HR cloth coarse-tracked to them
    /// ([`crate::cloth::follow`]); `None` = off (the default). Needs the shot from frame 0.
    pub physics: Option<FollowParams>,
    /// Write into a folder that holds files no earlier run of this shot wrote (replacing those
    /// this run writes), and remove another slice's files made with other settings, instead of
    /// refusing ([`super::folder`]).
    pub overwrite: bool,
}

impl UpscaleJob {
    /// A job with the command line's defaults: `inputs` into `out` in the input's format.
    pub fn new(inputs: Vec<PathBuf>, out: impl Into<PathBuf>) -> UpscaleJob {
        UpscaleJob {
            inputs,
            out: out.into(),
            rest: None,
            format: OutputFormat::Auto,
            frames: None,
            margin: DOMAIN_MARGIN,
            chunk: DEFAULT_CHUNK,
            maps: false,
            params: UpscaleParams::default(),
            physics: None,
            overwrite: false,
        }
    }

    /// Check every option once, before a file is read or a net runs: the job as a
    /// [`CheckedJob`], or the first field out of range ([`Error::Invalid`]).
    pub fn check(self) -> Result<CheckedJob> {
        self.params.validate()?;
        check_margin(self.margin)?;
        if let Some(p) = &self.physics {
            p.validate()?;
        }
        if self.chunk == 0 {
            return Err(Error::invalid(
                "chunk",
                "must be ≥ 1 frame (frames read, upscaled and written at a time)",
            ));
        }
        if let Some(span) = self.frames {
            span.check()?;
            if self.physics.is_some() && span.start > 0 {
                let end = span.end.map_or(String::new(), |b| b.to_string());
                return Err(Error::invalid(
                    "frames",
                    format!(
                        "the physics pass simulates the cloth from the shot's first frame: a slice \
                         with it must start at 0 (got {}:{end}); upscale 0:{end} instead",
                        span.start
                    ),
                ));
            }
        }
        Ok(CheckedJob(self))
    }
}

/// An [`UpscaleJob`] whose options passed [`UpscaleJob::check`]: what [`upscale_files`] runs.
#[derive(Clone, Debug)]
pub struct CheckedJob(UpscaleJob);

impl CheckedJob {
    /// The job with the nets' arithmetic resolved for the op table it runs on
    /// ([`Precision::resolve`]); the checks stand.
    pub fn with_precision(mut self, precision: Precision) -> CheckedJob {
        self.0.params.precision = precision;
        self
    }
}

impl std::ops::Deref for CheckedJob {
    type Target = UpscaleJob;
    fn deref(&self) -> &UpscaleJob {
        &self.0
    }
}

/// How a job tells its caller what happens (the command line: progress bars and stderr).
/// Every method does nothing by default ([`Quiet`]).
pub trait Report {
    /// A stage of `total` items begins (`"bounds"`: frames read for the domain; `"upscale"`).
    fn start(&mut self, _stage: &str, _total: usize) {}
    /// `done` items of the current stage are done.
    fn progress(&mut self, _done: usize) {}
    /// The current stage is over.
    fn end(&mut self) {}
    /// A line for the user: what runs, notes (`note: …`), warnings (`warning: …`).
    fn message(&mut self, _line: &str) {}
}

/// A [`Report`] that says nothing.
pub struct Quiet;
impl Report for Quiet {}

/// What a finished job did.
#[derive(Clone, Debug)]
pub struct Summary {
    /// Frames written.
    pub frames: usize,
    /// LR and HR grid sizes (columns, rows); for a mesh that is not a grid, its geometry
    /// images' (the atlas).
    pub lr: (usize, usize),
    pub hr: (usize, usize),
    /// LR and HR vertices of a mesh that is not a grid (`None` for a grid).
    pub mesh: Option<(usize, usize)>,
    pub seconds: f64,
    /// `obj`, `npy`, `pc2` or `mdd`.
    pub format: String,
}

/// Largest `--margin` (a fraction of the shot's extent): beyond it the shot fills a sliver of
/// the geometry image and f32 loses its detail (at 1e30 every pixel reads 0.5).
pub const MAX_MARGIN: f32 = 1.0;

/// Refuse a margin outside 0 ..= [`MAX_MARGIN`] (NaN included).
pub fn check_margin(margin: f32) -> Result<()> {
    if !(margin.is_finite() && (0.0..=MAX_MARGIN).contains(&margin)) {
        return Err(Error::invalid(
            "margin",
            format!(
                "must be a fraction of the shot's extent from 0 to {MAX_MARGIN}, got {margin} \
                 (the default {DOMAIN_MARGIN} suits any shot)"
            ),
        ));
    }
    Ok(())
}

/// Run `job` with the `model` on `ops` (see the module docs); its options were checked when it
/// became a [`CheckedJob`], and every file is written atomically.
pub fn upscale_files(
    ops: &dyn Ops,
    model: &AnisoCb,
    job: &CheckedJob,
    report: &mut dyn Report,
) -> Result<Summary> {
    let params = &job.params;
    let r = model.scale();
    let mut messages = Vec::new();
    let opened = open_input(&job.inputs, job.rest.as_deref(), r, &mut messages);
    for m in &messages {
        report.message(m);
    }
    let Input { mut shot, npy_domain, mesh_out, cache_in, files } = opened?;
    let (t, w, h) = shot.size();
    if shot.mesh().is_some() {
        refuse_for_mesh(job)?;
    } else if job.physics.as_ref().is_some_and(|p| !p.pin_vertices.is_empty()) {
        return Err(Error::invalid(
            "pin_vertices",
            "a grid is held by its edges (--physics-pin top, …), not by a vertex list; a vertex \
             list is for a mesh that is not a grid",
        ));
    }
    if let Some(p) = &job.physics {
        p.check_shot_frames(t)?;
    }
    let mesh_given = mesh_out.is_some();
    let mesh_out = mesh_out.unwrap_or_else(|| MeshOut::plain(t));
    let plan = Plan::new(job, t, mesh_given, &mesh_out, cache_in.as_ref(), &files)?;
    let (domain, domain_note) = settle_domain(model, job, &plan, npy_domain, &mut shot, report)?;
    let own = ownership(ops, model, job, &plan)?;
    let claim = folder::claim(&job.out, &own, job.overwrite)?;
    for n in &claim.removed {
        report.message(&format!("note: removed {n}, an earlier run's output that this run does not write"));
    }
    let range = plan.range.clone();
    let size = match shot.mesh() {
        Some((m, _)) => format!(
            "a mesh of {} vertices -> {} (geometry images {w}x{h} -> {}x{})",
            m.lr_vertices(),
            m.sub.hr_vertices(),
            r * w,
            r * h
        ),
        None => format!("{w}x{h} -> {}x{}", r * w, r * h),
    };
    report.message(&format!(
        "upscaling frames {}..{} of {t}, {size} ({}), η = {}",
        range.start,
        range.end,
        ops.name(),
        params.eta
    ));
    report.message(&domain_note);
    // A rerun after a kill: clear the temp files the killed run left (every file is written
    // atomically, so the outputs themselves are either complete or absent).
    for p in &plan.outputs {
        remove_stale_temps(p)?;
    }
    // Until the final summary replaces it, the folder says it is unfinished: whatever stops the
    // run (a kill, a bad frame) leaves this marker, never an earlier run's summary.
    let started = Object::new()
        .val("complete", Value::Bool(false))
        .num("frames", range.len())
        .val("range", vec![Value::num(range.start), Value::num(range.end)])
        .num("eta", params.eta)
        .str("note", "unfinished: this run was stopped part-way or failed; rerun the same command");
    let started = own.record(started);
    write_json(&plan.summary_path, &started.into(), Layout::Compact)?;
    let start = Instant::now();
    if let Some(c) = &cache_in {
        write_hr_rest_mesh(ops, model, job, c, &shot, &mesh_out, &domain)?;
    }
    let mut out = open_outputs(job, &plan, &shot, mesh_out, cache_in.as_ref(), domain, (r * w, r * h))?;
    let notes = match &shot {
        Shot::Obj { notes, .. } => notes.clone(),
        _ => Default::default(),
    };
    report.start("upscale", range.len());
    let mut on_frames = |k: usize| {
        for n in notes.borrow_mut().drain(..) {
            report.message(&format!("note: {n}"));
        }
        report.progress(k);
    };
    let mut physics;
    let sink: &mut dyn super::stream::HrSink = match &job.physics {
        // A mesh's pass runs on its HR vertices, in the sinks' decoding (`decode`).
        Some(p) if shot.mesh().is_none() => {
            physics = PhysicsSink::new(&mut out, domain, p.clone(), (w, h));
            &mut physics
        }
        _ => &mut out,
    };
    upscale_stream(ops, model, &mut shot, &domain, range.clone(), params, job.chunk, sink, &mut on_frames)?;
    out.finish()?;
    if plan.fmt == "npy" {
        write_npy(&plan.npy("domain"), &domain.to_tensor())?;
    }
    let secs = start.elapsed().as_secs_f64();
    report.end();
    let n = range.len();
    let size = |w: usize, h: usize| vec![Value::num(w), Value::num(h)];
    let summary = Object::new()
        .val("complete", Value::Bool(true))
        .num("frames", n)
        .val("range", vec![Value::num(range.start), Value::num(range.end)])
        .val("lr", size(w, h))
        .val("hr", size(r * w, r * h))
        .num("eta", params.eta)
        .str("device", ops.name())
        .num("seconds", format!("{secs:.3}"))
        .num("ms_per_frame", format!("{:.3}", 1e3 * secs / n as f64))
        .val("mesh", shot.mesh().map_or(Value::Null, |(m, _)| mesh_json(m).into()))
        .val(
            "domain",
            Object::new().val("bmin", Value::reals(&domain.bmin)).val("bmax", Value::reals(&domain.bmax)),
        );
    let summary = match &job.physics {
        Some(p) => summary.val("physics", physics_json(p)),
        None => summary,
    };
    write_json(&plan.summary_path, &own.record(summary).into(), Layout::Compact)?;
    drop(claim);
    let mesh = shot.mesh().map(|(m, _)| (m.lr_vertices(), m.sub.hr_vertices()));
    Ok(Summary { frames: n, lr: (w, h), hr: (r * w, r * h), mesh, seconds: secs, format: plan.fmt })
}

/// Refuse, for a mesh that is not a regular grid, what runs on grids only so far: held grid
/// edges in the physics pass, and geometry.npy output (atlas images, with no mesh to go back
/// to).
fn refuse_for_mesh(job: &UpscaleJob) -> Result<()> {
    if job.physics.as_ref().is_some_and(|p| !p.pins.is_empty()) {
        return Err(Error::invalid(
            "pins",
            "held grid edges (top, left, …) name a grid's sides, and this input is a mesh of \
             another outline: leave them out (pins on meshes are not supported yet)",
        ));
    }
    if job.format == OutputFormat::Npy {
        return Err(Error::invalid(
            "format",
            "geometry.npy output is a grid's images; this input is a mesh of another outline, whose \
             images are an atlas of its charts: write OBJ frames or a point cache",
        ));
    }
    Ok(())
}

/// How a mesh input was laid out, as the summary records it.
fn mesh_json(m: &crate::geom::layout::MeshLayout) -> Object {
    let a = &m.atlas;
    Object::new()
        .num("lr_vertices", m.lr_vertices())
        .num("hr_vertices", m.sub.hr_vertices())
        .num("faces", m.surface.faces.len())
        .num("charts", a.charts)
        .str(
            "charts_from",
            match a.source {
                crate::geom::atlas::ChartSource::Uv => "uv",
                crate::geom::atlas::ChartSource::Arap => "arap",
            },
        )
        .num("texel_m", format!("{:.6}", a.texel))
}

/// The physics pass's settings as the summary records them. The sphere, the box and the mesh
/// colliders only when given (a run without them records what it did before they were);
/// each mesh by its canonical path and a checksum of its content, so a rerun with another
/// collider, or the same file changed, is another run's output.
fn physics_json(p: &FollowParams) -> Object {
    let o = Object::new()
        .val("gravity_m_per_s2", Value::reals(&p.gravity))
        .num("fps", p.fps)
        .str("material", p.material.name)
        .num("strength_per_s2", p.strength)
        .num("damping", p.damping)
        .num("substeps_per_second", p.substeps_per_second)
        .str("output", if p.output == FollowOutput::Detail { "detail" } else { "cloth" })
        .val("drift_seconds", Value::finite(p.drift_seconds))
        .val("ground_m", p.ground.map_or(Value::Null, Value::finite))
        .str("pins", &p.pins.names());
    let o = if p.pin_vertices.is_empty() {
        o
    } else {
        o.val("pin_vertices", p.pin_vertices.iter().map(|&v| Value::num(v + 1)).collect::<Vec<_>>())
    };
    let o = match p.sphere {
        Some(s) => o.val("sphere_m", Value::reals(&[s.center[0], s.center[1], s.center[2], s.radius])),
        None => o,
    };
    let o = match p.cuboid {
        Some(b) => o.val("box_m", Value::reals(&[b.center, b.half].concat())),
        None => o,
    };
    if p.colliders.is_empty() {
        return o;
    }
    let meshes: Vec<Value> = p
        .colliders
        .iter()
        .map(|m| {
            let path = folder::canonical(&[m.source().to_path_buf()]).remove(0);
            Object::new()
                .str("path", &path)
                .num("frames", m.frames())
                .num("triangles", m.triangles())
                .val("closed", Value::Bool(m.is_closed()))
                .str("checksum", &format!("{:016x}", m.checksum()))
                .into()
        })
        .collect();
    o.val("colliders", meshes).num("collider_thickness_m", p.collider_thickness)
}

/// Who this run is for its output folder ([`folder::claim`]): its inputs, every setting that
/// decides the output's bytes (the weights by a checksum of their values), the files it writes.
fn ownership(ops: &dyn Ops, model: &AnisoCb, job: &UpscaleJob, plan: &Plan) -> Result<Ownership> {
    let p = &job.params;
    let mut inputs = job.inputs.clone();
    inputs.extend(job.rest.iter().cloned());
    let settings = Object::new()
        .num("eta", p.eta)
        .val("maps", Value::Bool(job.maps))
        .num("temporal", p.temporal)
        .num("strain_iters", p.strain_iters)
        .val("mirrors", Value::Bool(p.mirrors))
        .val("keep_outline", Value::Bool(p.keep_outline))
        .val("pin_border", Value::Bool(p.pin_border))
        .val("gate_coarse_only", Value::Bool(p.gate_coarse_only))
        .str("format", &plan.fmt)
        .num("margin", job.margin)
        .str("device", ops.name())
        .str("precision", p.precision.name())
        .str("weights", &format!("{:016x}", model.checksum()))
        .val("physics", job.physics.as_ref().map_or(Value::Null, |f| physics_json(f).into()));
    let name = |p: &PathBuf| p.file_name().unwrap_or_default().to_string_lossy().into_owned();
    Ok(Ownership {
        job: "upscale",
        noun: "shot",
        inputs: folder::canonical(&inputs),
        settings: settings.into(),
        summary: name(&plan.summary_path),
        files: plan.writes.iter().filter(|w| **w != plan.summary_path).map(name).collect(),
    })
}

/// What a job writes where, settled and checked before anything is written.
struct Plan {
    /// `obj`, `npy`, `pc2` or `mdd`.
    fmt: String,
    /// The frames upscaled.
    range: Range<usize>,
    /// `.A-B` for a `--frames` slice, else empty: in the `.npy`, cache and summary names.
    suffix: String,
    out: PathBuf,
    /// The HR point cache's name (point-cache input).
    cache_name: Option<String>,
    summary_path: PathBuf,
    /// Every file this run may write (their stale temps are cleared before it starts).
    outputs: Vec<PathBuf>,
    /// The files this run writes, its summary included.
    writes: Vec<PathBuf>,
}

impl Plan {
    /// The plan for `job` on a shot of `t` frames read from `files`; refuses an `--out` that
    /// would overwrite the input and two outputs of one name.
    fn new(
        job: &UpscaleJob,
        t: usize,
        mesh_given: bool,
        mesh_out: &MeshOut,
        cache_in: Option<&CacheIn>,
        files: &[PathBuf],
    ) -> Result<Plan> {
        let fmt = match (job.format, mesh_given, cache_in) {
            (OutputFormat::Auto, _, Some(c)) => c.header.format.name().to_lowercase(),
            (OutputFormat::Auto, true, None) | (OutputFormat::Obj, ..) => "obj".to_string(),
            _ => "npy".to_string(),
        };
        let range = job.frames.map_or(Ok(0..t), |s| s.range(t))?;
        // Outputs of a slice carry its range in their names (OBJ frames keep their own names).
        let suffix = if range.len() != t { format!(".{}-{}", range.start, range.end) } else { String::new() };
        let cache_name = cache_in.map(|c| {
            let stem = c.path.file_stem().unwrap_or_default().to_string_lossy().into_owned();
            format!("{stem}{suffix}.{}", c.header.format.name().to_lowercase())
        });
        let out = job.out.clone();
        let summary_path = out.join(format!("upscale{suffix}.json"));
        let mut plan = Plan {
            fmt,
            range,
            suffix,
            out,
            cache_name,
            summary_path,
            outputs: Vec::new(),
            writes: Vec::new(),
        };
        let (out, range) = (&plan.out, plan.range.clone());
        let frames = || mesh_out.names[range.clone()].iter().map(|n| out.join(n));
        let rest = || cache_in.and_then(|c| c.rest.file_name()).map(|n| out.join(n));
        // Every file this run may write.
        let mut outputs: Vec<PathBuf> =
            ["geometry", "domain", "boundary", "enhance"].map(|n| plan.npy(n)).into();
        outputs.push(plan.summary_path.clone());
        outputs.extend(frames());
        outputs.extend(plan.cache_name.iter().map(|n| out.join(n)));
        outputs.extend(rest());
        refuse_out_over_input(out, files, &outputs)?;
        // What this run writes, each once.
        let mut writes = vec![plan.summary_path.clone()];
        match plan.fmt.as_str() {
            "obj" => writes.extend(frames()),
            "npy" => writes.extend(["geometry", "domain"].map(|n| plan.npy(n))),
            _ => writes.extend(plan.cache_name.iter().map(|n| out.join(n))),
        }
        if job.maps {
            writes.extend(["boundary", "enhance"].map(|n| plan.npy(n)));
        }
        writes.extend(rest());
        refuse_duplicate_outputs(&writes)?;
        plan.outputs = outputs;
        plan.writes = writes;
        Ok(plan)
    }

    /// `OUT/stem[.A-B].npy`.
    fn npy(&self, stem: &str) -> PathBuf {
        self.out.join(format!("{stem}{}.npy", self.suffix))
    }
}

/// The domain and a note on where it came from: the file's for `.npy` input; none needed for
/// a model in the cloth frame writing meshes (each frame then depends on itself alone);
/// otherwise the whole shot's bounding box (not a `--frames` slice's, so slices agree), which
/// `shot` then encodes its frames with.
fn settle_domain(
    model: &AnisoCb,
    job: &UpscaleJob,
    plan: &Plan,
    npy_domain: Option<Domain>,
    shot: &mut Shot,
    report: &mut dyn Report,
) -> Result<(Domain, String)> {
    Ok(match npy_domain {
        Some(d) => (d, "domain from domain.npy beside the input".to_string()),
        None if model.input_frame() == InputFrame::Cloth && plan.fmt != "npy" => {
            (Domain::UNIT, "no domain needed: the model works in each frame's cloth frame".to_string())
        }
        None => {
            report.start("bounds", shot.size().0);
            let d = shot_bounds(shot, job.margin, job.chunk, &mut |k| report.progress(k))?;
            report.end();
            // The frames read for the bounds are read again to upscale.
            if let Some((_, lr)) = shot.mesh() {
                lr.borrow_mut().clear();
            }
            shot.set_domain(d);
            let note = format!(
                "domain = bounding box of all frames + {:.0}% margin: bmin {:?}, bmax {:?} (m)",
                job.margin * 100.0,
                d.bmin,
                d.bmax
            );
            (d, note)
        }
    })
}

/// A point cache plays on an HR rest mesh: the rest OBJ upscaled on its own, written beside
/// the HR cache under its own name.
fn write_hr_rest_mesh(
    ops: &dyn Ops,
    model: &AnisoCb,
    job: &UpscaleJob,
    c: &CacheIn,
    shot: &Shot,
    mesh_out: &MeshOut,
    domain: &Domain,
) -> Result<()> {
    let name = c.rest.file_name().unwrap_or_default();
    if let Shot::MeshCache { layout, rest, .. } = shot {
        let img = layout.to_image(rest, domain)?;
        let up = crate::sr::upscale::upscale_images(ops, model, &img, domain, &job.params, &mut |_| {})?;
        let hr = layout.hr_frame(&up.hr, &up.interpolated(), 0, domain, rest, up.keeps_outline());
        return write_atomic_bytes(&job.out.join(name), mesh_out.mesh_text(&hr, &mesh_out.attrs).as_bytes());
    }
    let Some(g) = &c.rest_grid else { unreachable!("a grid cache has its rest grid") };
    let rest = &g.mesh;
    let d = if *domain == Domain::UNIT {
        *domain
    } else {
        Domain::enclosing(std::slice::from_ref(rest), job.margin)
    };
    let (hr, _) = upscale_meshes(ops, model, std::slice::from_ref(rest), &d, &job.params, &mut |_| {})?;
    write_atomic_bytes(&job.out.join(name), mesh_out.obj_text(&hr[0], &mesh_out.attrs).as_bytes())
}

/// How `shot`'s HR images become vertices (through `job`'s physics pass for a mesh).
fn decode(shot: &Shot, job: &UpscaleJob) -> Decode {
    match shot.mesh() {
        Some((layout, lr)) => {
            let physics = job.physics.as_ref().map(|p| {
                let pass = MeshPhysicsPass::new(p.clone(), layout.sub.clone(), layout.lr_vertices());
                Rc::new(RefCell::new(pass))
            });
            Decode::Mesh(layout.clone(), lr.clone(), physics)
        }
        None => Decode::Grid,
    }
}

/// The sinks of `plan` for HR frames of `hr` = (columns, rows): OBJ frames, geometry.npy or
/// the HR point cache, and the maps with `--maps`.
fn open_outputs(
    job: &UpscaleJob,
    plan: &Plan,
    shot: &Shot,
    mesh_out: MeshOut,
    cache_in: Option<&CacheIn>,
    domain: Domain,
    (hw, hh): (usize, usize),
) -> Result<Outputs> {
    let n = plan.range.len();
    let maps = if job.maps {
        let shape = [n, 1, hh, hw];
        Some((
            NpyWriter::create(&plan.npy("boundary"), &shape)?,
            NpyWriter::create(&plan.npy("enhance"), &shape)?,
        ))
    } else {
        None
    };
    let mut out = Outputs { obj: None, cache: None, geometry: None, maps };
    match (plan.fmt.as_str(), cache_in) {
        ("obj", _) => {
            let attrs = match shot {
                Shot::Obj { attrs, .. } | Shot::Mesh { attrs, .. } => attrs.clone(),
                _ => FrameAttrs::default(),
            };
            out.obj = Some(ObjSink {
                dir: job.out.clone(),
                domain,
                mesh: mesh_out,
                attrs,
                decode: decode(shot, job),
            });
        }
        ("npy", _) => out.geometry = Some(NpyWriter::create(&plan.npy("geometry"), &[n, 3, hh, hw])?),
        (_, Some(c)) => {
            let path = job.out.join(plan.cache_name.as_deref().unwrap_or("cache"));
            let points = shot.mesh().map_or(hw * hh, |(m, _)| m.sub.hr_vertices());
            let mut header = CacheHeader::new(c.header.format, points, n, 1.0);
            // The slice's timing: PC2 start frame and sampling, MDD per-frame times.
            header.sample_rate = c.header.sample_rate;
            header.start_frame = c.header.start_frame + plan.range.start as f32 * c.header.sample_rate;
            if !c.header.times.is_empty() {
                header.times = c.header.times[plan.range.clone()].to_vec();
            }
            let mut file = AtomicFile::create(&path)?;
            write_header(file.writer(), &header).map_err(|e| Error::io(&path, e))?;
            let decode = decode(shot, job);
            out.cache =
                Some(CacheSink { file, format: header.format, domain, frames: n, written: 0, decode });
        }
        _ => unreachable!("fmt is obj, npy, or a cache format for cache input"),
    }
    Ok(out)
}
