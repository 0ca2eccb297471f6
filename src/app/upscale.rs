//! `anisocb upscale INPUT... --out DIR`: LR cloth animation in, HR animation out, streamed a
//! chunk of frames at a time (memory bounded by `--chunk`, not the shot), any `--frames`
//! slice giving the same bytes as the whole shot. The work is [`crate::pipeline::upscale_files`];
//! this file maps the options onto it and draws the progress.

use super::setup::{load_model, parse_threads, set_threads};
use super::ui::progress;
use crate::cloth::collision::{Cuboid, Sphere};
use crate::cloth::follow::{FollowOutput, FollowParams, PinnedEdges};
use crate::cloth::mesh_collider::{ColliderMesh, COLLIDER_THICKNESS};
use crate::cloth::run_io::DOMAIN_MARGIN;
use crate::cloth::Material;
use crate::cuda::Device;
use crate::error::Error;
use crate::error::Result;
use crate::pipeline::job::{CheckedJob, FrameSpan, Precision};
use crate::pipeline::stream::DEFAULT_CHUNK;
use crate::pipeline::{upscale_files, OutputFormat, Report, UpscaleJob};
use crate::sr::compose::DEFAULT_ETA;
use crate::sr::params::UpscaleParams;
use indicatif::ProgressBar;
use std::path::PathBuf;
use std::sync::Arc;

#[derive(clap::Args, Debug)]
#[command(after_help = "Examples:
  anisocb upscale frames/ --out hr/                  # a directory of OBJ frames (natural order)
  anisocb upscale f_0001.obj f_0002.obj --out hr/    # explicit OBJ files
  anisocb upscale run/lr --out hr/                   # a simulator run dir (geometry.npy + domain.npy)
  anisocb upscale run/lr/geometry.npy --out hr/ --eta 1.0 --maps
  anisocb upscale frames/ --out hr/ --frames 0:100   # one slice of a shot (a render-farm task)
  anisocb upscale frames/ --out hr/ --physics --gravity 0,0,-9.81 --fps 24   # folds by simulation
  anisocb upscale frames/ --out hr/ --physics --collider body/ --collider chair.obj   # on meshes

From Blender and back (OBJ sequence):
  1. File > Export > Wavefront (.obj): Animation on, Apply Modifiers on, UV Coordinates and
     Normals on, Materials on, Forward/Up as you like; export the cloth object to frames/.
  2. anisocb upscale frames/ --out hr/
  3. In Blender, import hr/ as an OBJ sequence (e.g. File > Import > Wavefront for one frame,
     or an OBJ-sequence add-on): UVs, material slot, object name and face style come back.

Any cloth mesh: a regular grid (quads or triangulated quads, any vertex order) becomes a grid of
2W x 2H vertices over the same surface; any other mesh of triangles and quads (a skirt, a sleeve, a
round tablecloth, a garment of several panels, with holes, seams, unwelded) becomes its own
subdivision, every face split in four (edge midpoints, a centre per quad), its pieces laid out as
charts of a geometry image (its UV islands when they are a usable layout, else ARAP flattening)
for the nets. The output is written the way the input was: OBJ with the same file names, faces in
the same order and winding, UVs subdivided (seams stay seams), normals recomputed,
mtllib/usemtl/o/g/s kept face by face; or a point cache; geometry.npy + domain.npy for grids.
Every frame of a shot must have the first frame's topology. --physics runs on any mesh;
--physics-pin (held grid edges) only on grids.

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
    /// Output directory: created if missing, or empty, or one that earlier runs of the same
    /// shot (same inputs) own — their summaries list every file they wrote; another shot's
    /// files there are refused (see --overwrite). Never the input's own folder: the input is
    /// never overwritten. One run at a time writes each summary of it (a lock).
    #[arg(help_heading = "Input and output", long)]
    pub out: PathBuf,
    /// Write into --out even though it holds files no run of this shot wrote (those this run
    /// writes are replaced, the rest left), or another slice's frames made with other settings
    /// (removed).
    #[arg(help_heading = "Input and output", long)]
    pub overwrite: bool,
    /// Wrinkle enhancement η from -1 to 10 (Eq 12): 0 = plain predicted detail (the default,
    /// chosen on validation runs; EnhanceNet is then not run), larger = deeper wrinkles where
    /// EnhanceNet sees edges (up to 1 + η times the predicted detail), below 0 = softer (-1
    /// removes them there). With the wrinkle model and --gate-coarse-only it scales the folds
    /// finer than the LR grid (docs/research/wrinkles.md). Smooth cloth and the border are unaffected.
    #[arg(help_heading = "Detail", long, default_value_t = DEFAULT_ETA, allow_negative_numbers = true)]
    pub eta: f32,
    /// Temporal smoothing radius in frames of the predicted detail and of the boundary and
    /// wrinkle maps that gate it, in the cloth's own frame (1 = weights ¼ ½ ¼ over the
    /// previous, this and the next frame; 0 = every frame on its own, the default). Off by
    /// default because mirror averaging already removes the detail's frame-to-frame noise and
    /// smoothing then measured worse (most on cloth that keeps turning); it can still calm a
    /// one-pass (`--mirrors false`) result. At most 64.
    #[arg(help_heading = "Detail", long, default_value_t = crate::sr::params::DEFAULT_TEMPORAL)]
    pub temporal: usize,
    /// Strain limit: iterations pulling the output's edge lengths toward those of the input
    /// frame (0 = off). About 10 removes swimming and frame-to-frame edge flicker on cloth that
    /// barely stretches (flags, drapes: also −6 % error); do not use it on cloth that stretches
    /// a lot (rubber, strongly twisted strips), where it makes the result worse.
    #[arg(help_heading = "Detail", long, default_value_t = crate::sr::params::DEFAULT_STRAIN_ITERS)]
    pub strain_iters: usize,
    /// Average the nets over the grid's four mirror images (as given, flipped left-right,
    /// top-bottom, both; each in its own cloth frame): the detail no longer depends on which
    /// way the grid runs, and what one view invents is averaged out (smoother shading, less
    /// flicker). 4× the network time; `--mirrors false` for one pass.
    #[arg(help_heading = "Detail", long, default_value_t = crate::sr::params::DEFAULT_MIRRORS, action = clap::ArgAction::Set)]
    pub mirrors: bool,
    /// Outline floor: the output's border is never shorter than the LR frame's own border
    /// polyline; where the nets' correction would shorten it, its part along the surface
    /// normal (what flattens a hem's folds) is scaled down on the two outermost rings of
    /// vertices just enough. For draped cloth from other tools (Blender tablecloths), whose
    /// hanging hems fold more than the training cloth's and whose outline the nets then
    /// shorten by up to 0.7 %. On by default (chosen on validation scenes); `false` saves
    /// 1–2 % vertex error on cloth whose true outline is shorter than the LR one (strongly
    /// twisted strips) and gives the nets' border as it is.
    #[arg(help_heading = "Detail", long, default_value_t = crate::sr::params::DEFAULT_KEEP_OUTLINE, action = clap::ArgAction::Set)]
    pub keep_outline: bool,
    /// BoundaryNet gates only the coarse part of the predicted detail (what the LR grid can
    /// hold); folds finer than the LR grid are kept as GeometryNet predicts them. For the
    /// wrinkle model (docs/research/wrinkles.md), whose BoundaryNet would otherwise flatten them.
    #[arg(help_heading = "Detail", long)]
    pub gate_coarse_only: bool,
    /// Keep the outermost ring of vertices exactly where the interpolated input puts them
    /// (the outline is then the LR outline's interpolation, whatever the nets predict there).
    /// Off by default: the nets correct the border too, which measured closer to the truth.
    #[arg(help_heading = "Detail", long)]
    pub pin_border: bool,
    /// Weights file (.npz bundle of the three nets) instead of the embedded ×2 model.
    #[arg(help_heading = "Model and engine", long)]
    pub weights: Option<PathBuf>,
    /// Frames handed to the nets at a time (the streaming chunk). On a GPU the chunk is one
    /// batch (more = faster, more memory); on the CPU the nets run it in passes that stay near
    /// the caches (2 frames at 64², 8 at 32²).
    #[arg(help_heading = "Model and engine", long, default_value_t = 8)]
    pub batch: usize,
    /// Worker threads, 1 to 1024 (default: all cores).
    #[arg(help_heading = "Model and engine", long, value_parser = parse_threads)]
    pub threads: Option<usize>,
    /// Compute device: cpu or cuda.
    #[arg(help_heading = "Model and engine", long, default_value = "cpu")]
    pub device: String,
    /// The nets' arithmetic: auto (fp16 on a GPU with tensor cores, fp32 on another GPU, bf16
    /// on a CPU with AMX tiles, else fp32-fast), fp32 (the audited path, the same bits on every
    /// machine; on a GPU the op-by-op kernels), fp32-fast (CPU: f32 with the trunks' 3×3 convs
    /// by Winograd F(4×4, 3×3), about 1.4× faster, vertices within 0.0002 mm of fp32's), bf16
    /// (the CPU's AMX tiles: bf16 products summed in f32, the nets' first and last convs in
    /// fp32; vertices within about 0.1 mm of fp32's, and a moved, turned or scaled copy of a
    /// shot agrees with the shot moved alike to about 1.5·10⁻³ LR edge lengths, where fp32 and
    /// fp32-fast agree to 6·10⁻⁵) or fp16 (--device cuda only).
    #[arg(help_heading = "Model and engine", long, default_value = "auto", value_parser = ["auto", "fp32", "fp32-fast", "bf16", "fp16"])]
    pub precision: String,
    /// Output format: auto (same as input), obj or npy.
    #[arg(help_heading = "Input and output", long, default_value = "auto", value_parser = ["auto", "obj", "npy"])]
    pub format: String,
    /// Domain margin for OBJ and point-cache input, as a fraction of the sequence's largest
    /// extent, from 0 to 1.
    #[arg(help_heading = "Model and engine", long, default_value_t = DOMAIN_MARGIN, allow_negative_numbers = true)]
    pub margin: f32,
    /// Also write the predicted boundary and wrinkle-edge maps (boundary.npy, enhance.npy).
    #[arg(help_heading = "Input and output", long)]
    pub maps: bool,
    /// Rest mesh of a point-cache input (.pc2/.mdd): the OBJ whose vertices the cache moves,
    /// in the same order (export both from the same object). Its connectivity, UVs and
    /// material are used; the output gets an HR rest OBJ of the same name beside the HR cache.
    #[arg(help_heading = "Input and output", long, value_name = "OBJ")]
    pub rest: Option<PathBuf>,
    /// Upscale only frames A to B−1 of the shot (0-based, `A:B`, `A:` = to the end). Slices
    /// upscaled separately give exactly the files (bytes) the whole shot gives, so a farm can
    /// split a shot by frame range; .npy output of a slice is named geometry.A-B.npy.
    #[arg(help_heading = "Input and output", long, value_name = "A:B")]
    pub frames: Option<String>,
    /// Frames read, upscaled and written at a time: memory is bounded by this, not by the
    /// shot's length.
    #[arg(help_heading = "Model and engine", long, default_value_t = DEFAULT_CHUNK)]
    pub chunk: usize,
    /// Physics pass (opt-in): an HR cloth simulated alongside the shot, held to the nets' frames
    /// at the LR grid's scale only, so folds finer than the LR grid form where an HR simulation
    /// forms them (docs/research/wrinkles.md, "The physics pass"). Reads the shot as metres; set
    /// --gravity, --fps and --material to match it, and --physics-pin where the cloth is held.
    /// Needs the whole shot from frame 0.
    #[arg(help_heading = "Physics pass (--physics)", long)]
    pub physics: bool,
    /// With --physics: gravity in the shot's axes, m/s² (y-up OBJ: 0,-9.81,0; a z-up scene:
    /// 0,0,-9.81).
    #[arg(
        help_heading = "Physics pass (--physics)",
        long,
        value_name = "X,Y,Z",
        default_value = "0,-9.81,0",
        allow_hyphen_values = true
    )]
    pub gravity: String,
    /// With --physics: the shot's frame rate (frames per second).
    #[arg(help_heading = "Physics pass (--physics)", long, default_value_t = 30.0)]
    pub fps: f32,
    /// With --physics: settings chosen for a kind of shot. `blender`: cloth simulated by
    /// Blender, = --material silk --physics-damping 1 (chosen on the five Blender validation
    /// scenes: Blender's sheets fold finer than cotton and its cloth is damped more than ours).
    /// A --material or --physics-damping given as well wins over the preset's.
    #[arg(help_heading = "Physics pass (--physics)", long, value_parser = ["blender"])]
    pub preset: Option<String>,
    /// With --physics: the cloth's material (silk, cotton, denim, rubber); its bending
    /// stiffness sets how fine the folds are. Default cotton (silk with --preset blender).
    #[arg(help_heading = "Physics pass (--physics)", long)]
    pub material: Option<String>,
    /// With --physics: what the pass hands on: `cloth` = the simulated cloth itself, its slow
    /// drift from the shot taken out (--physics-drift; the default: its folds stay put and it
    /// filters the nets' frame-to-frame jitter), `detail` = the nets' frame plus the simulated
    /// cloth's folds finer than the LR grid (the nets' coarse shape, jitter included).
    #[arg(help_heading = "Physics pass (--physics)", long, default_value = "cloth", value_parser = ["cloth", "detail"])]
    pub physics_output: String,
    /// With --physics and `cloth` output: time constant (s) over which the cloth's coarse
    /// drift from the shot (the part the pass's springs, without the shot's wind and
    /// colliders, leave) is taken out; 0 = every frame in full, inf = never.
    #[arg(help_heading = "Physics pass (--physics)", long, value_name = "SECONDS", default_value_t = crate::cloth::follow::DRIFT_SECONDS)]
    pub physics_drift: f32,
    /// With --physics: the height (m, along −gravity: `y` in a y-up shot) of a floor under the
    /// cloth; no output vertex goes below it. The pass does not see the shot's colliders, so
    /// without it folds may dip into the floor by centimetres.
    #[arg(
        help_heading = "Physics pass (--physics)",
        long,
        value_name = "HEIGHT",
        allow_hyphen_values = true
    )]
    pub physics_ground: Option<f32>,
    /// With --physics: a static sphere in the shot, X,Y,Z,R (m, the shot's axes): the pass's
    /// cloth collides with it and the output stays out of it.
    #[arg(
        help_heading = "Physics pass (--physics)",
        long,
        value_name = "X,Y,Z,R",
        allow_hyphen_values = true
    )]
    pub physics_sphere: Option<String>,
    /// With --physics: a static box in the shot, aligned with its axes, X,Y,Z,HX,HY,HZ (centre
    /// and half extents, m): a table top is its upper face.
    #[arg(
        help_heading = "Physics pass (--physics)",
        long,
        value_name = "X,Y,Z,HX,HY,HZ",
        allow_hyphen_values = true
    )]
    pub physics_box: Option<String>,
    /// With --physics: how hard the simulated cloth is held to the shot at the LR grid's scale
    /// (1/s², the square of the attachment's angular frequency; higher = closer to the shot,
    /// folds finer than the LR grid stay free either way).
    #[arg(help_heading = "Physics pass (--physics)", long, default_value_t = crate::cloth::follow::FollowParams::default().strength)]
    pub physics_strength: f32,
    /// With --physics: damping of that attachment as a fraction of critical. Default 0 = none,
    /// as the training truth's runs (chosen on our simulator's runs); 1 with --preset blender,
    /// whose more damped cloth the undamped pass follows with a ring after it lands.
    #[arg(help_heading = "Physics pass (--physics)", long)]
    pub physics_damping: Option<f32>,
    /// With --physics: edges of the grid the shot's cloth is held by (pinned, hooked, in a
    /// hand), comma-separated: top, bottom, left, right (row 0 of the input is `top`, column 0
    /// `left`), corners, or none. Those vertices follow the shot exactly and pull the cloth
    /// into the folds the hold makes; a flag is `top`, a towel held at both ends `left,right`.
    #[arg(help_heading = "Physics pass (--physics)", long, default_value = "none", value_name = "EDGES")]
    pub physics_pin: String,
    /// With --physics, on a mesh that is not a grid: a text file of the vertices the shot's
    /// cloth is held by (a skirt's waist, a cape's shoulders), numbered from 1 as in the OBJ
    /// file, separated by spaces, commas or new lines (`#` starts a comment). They, and the HR
    /// vertices between held ones, follow the shot exactly.
    #[arg(help_heading = "Physics pass (--physics)", long, value_name = "FILE")]
    pub physics_pin_vertices: Option<PathBuf>,
    /// With --physics, on a mesh that is not a grid: hold the vertices of the faces in this OBJ
    /// group (`g NAME` in the first frame, or in --rest for a point cache): a pin group exported
    /// from Blender, Maya or Houdini. Adds to --physics-pin-vertices.
    #[arg(help_heading = "Physics pass (--physics)", long, value_name = "NAME")]
    pub physics_pin_group: Option<String>,
    /// With --physics: XPBD substeps per second of shot time (at least one per frame). More
    /// makes the cloth stiffer against stretching and costs time in proportion.
    #[arg(help_heading = "Physics pass (--physics)", long, default_value_t = crate::cloth::follow::FollowParams::default().substeps_per_second)]
    pub physics_substeps: f32,
    /// With --physics: a triangle mesh the cloth lies on (a body, a chair, a floor), in the
    /// shot's axes and metres: an OBJ file (static), or a folder of OBJ frames in natural order,
    /// one per frame of the shot (animated; the substeps blend between frames). Faces of 3 or 4
    /// corners. A closed mesh has an inside at any depth; an open one is one-sided, its faces'
    /// front (counter-clockwise) outside. The pass's cloth collides with it, never passes
    /// through it, and no output vertex is left inside it. Repeat for several.
    #[arg(help_heading = "Physics pass (--physics)", long, value_name = "PATH")]
    pub collider: Vec<PathBuf>,
    /// With --physics: the gap (m) the cloth keeps from the --collider meshes [default: 0.005].
    #[arg(help_heading = "Physics pass (--physics)", long, value_name = "M")]
    pub collider_thickness: Option<f32>,
}

/// Progress bars and messages on stderr.
#[derive(Default)]
struct Stderr {
    bar: Option<ProgressBar>,
}

impl Report for Stderr {
    fn start(&mut self, stage: &str, total: usize) {
        self.bar = Some(progress(total as u64, stage));
    }
    fn progress(&mut self, done: usize) {
        if let Some(b) = &self.bar {
            b.set_position(done as u64);
        }
    }
    fn end(&mut self) {
        if let Some(b) = self.bar.take() {
            b.finish_and_clear();
        }
    }
    fn message(&mut self, line: &str) {
        match &self.bar {
            Some(b) => b.suspend(|| eprintln!("{line}")),
            None => eprintln!("{line}"),
        }
    }
}

/// The options as a typed job, checked once ([`UpscaleJob::check`]).
fn job(a: &Args) -> Result<CheckedJob> {
    if !a.physics {
        if let Some(c) = a.collider.first() {
            return Err(Error::config(format!(
                "--collider {}: colliders are the physics pass's: add --physics",
                c.display()
            )));
        }
        if a.collider_thickness.is_some() {
            return Err(Error::config(
                "--collider-thickness sets the physics pass's gap to its colliders: add --physics",
            ));
        }
    }
    let physics = match (a.physics, &a.preset) {
        (false, Some(p)) => {
            return Err(Error::config(format!(
                "--preset {p} sets the physics pass's material and damping: add --physics"
            )))
        }
        (false, None) => None,
        (true, preset) => {
            let base = match preset.as_deref() {
                Some("blender") => FollowParams::blender_shot(),
                _ => FollowParams::default(),
            };
            Some(FollowParams {
                gravity: parse_gravity(&a.gravity)?,
                fps: a.fps,
                material: a.material.as_deref().map_or(Ok(base.material), Material::from_name)?,
                strength: a.physics_strength,
                damping: a.physics_damping.unwrap_or(base.damping),
                output: if a.physics_output == "cloth" { FollowOutput::Cloth } else { FollowOutput::Detail },
                drift_seconds: a.physics_drift,
                ground: a.physics_ground,
                sphere: a
                    .physics_sphere
                    .as_deref()
                    .map(|s| numbers::<4>(s, "--physics-sphere", "X,Y,Z,R in metres"))
                    .transpose()?
                    .map(|[x, y, z, r]| Sphere { center: [x, y, z], radius: r }),
                cuboid: a
                    .physics_box
                    .as_deref()
                    .map(|s| numbers::<6>(s, "--physics-box", "X,Y,Z,HX,HY,HZ in metres"))
                    .transpose()?
                    .map(|[x, y, z, hx, hy, hz]| Cuboid { center: [x, y, z], half: [hx, hy, hz] }),
                pins: PinnedEdges::parse(&a.physics_pin)?,
                substeps_per_second: a.physics_substeps,
                colliders: a
                    .collider
                    .iter()
                    .map(|p| ColliderMesh::read(p).map(Arc::new))
                    .collect::<Result<_>>()?,
                collider_thickness: a.collider_thickness.unwrap_or(COLLIDER_THICKNESS),
                pin_vertices: pin_vertices(a)?,
            })
        }
    };
    UpscaleJob {
        inputs: a.input.clone(),
        out: a.out.clone(),
        rest: a.rest.clone(),
        format: match a.format.as_str() {
            "obj" => OutputFormat::Obj,
            "npy" => OutputFormat::Npy,
            _ => OutputFormat::Auto,
        },
        frames: a.frames.as_deref().map(FrameSpan::parse).transpose()?,
        margin: a.margin,
        chunk: a.chunk,
        maps: a.maps,
        params: UpscaleParams {
            eta: a.eta,
            enhance_map: a.maps,
            batch: a.batch,
            temporal: a.temporal,
            strain_iters: a.strain_iters,
            pin_border: a.pin_border,
            mirrors: a.mirrors,
            keep_outline: a.keep_outline,
            gate_coarse_only: a.gate_coarse_only,
            // Resolved for the device once it is open (`CheckedJob::with_precision`).
            precision: Precision::Fp32,
        },
        physics,
        overwrite: a.overwrite,
    }
    .check()
}

pub fn run(a: Args) -> Result<()> {
    #[cfg(feature = "usd")]
    if a.input.len() == 1 && crate::io::usd::is_usd(&a.input[0]) {
        return run_usd(a);
    }
    // Every option checked before a file is read or a net runs.
    let job = job(&a)?;
    let device = Device::parse(&a.device)?;
    set_threads(a.threads)?;
    let ops = device.ops()?;
    let job = job.with_precision(Precision::resolve(&a.precision, ops.as_ref())?);
    let model = load_model(a.weights.as_deref())?;
    let done = upscale_files(ops.as_ref(), &model, &job, &mut Stderr::default())?;
    let (n, secs) = (done.frames, done.seconds);
    let size = match done.mesh {
        Some((lr, hr)) => format!("of a mesh, {lr} -> {hr} vertices,"),
        None => format!("{}x{} -> {}x{}", done.lr.0, done.lr.1, done.hr.0, done.hr.1),
    };
    println!(
        "upscaled {n} frames {size} in {secs:.2} s ({:.1} ms/frame) -> {} ({})",
        1e3 * secs / n as f64,
        job.out.display(),
        done.format
    );
    Ok(())
}

/// `upscale shot.usd[a|c] --out DIR`: the USD's animated mesh written as an OBJ sequence in
/// DIR/.anisocb-usd/lr, upscaled as any mesh into DIR/.anisocb-usd/hr, and written back as
/// DIR/STEM.usda (same prim path, transforms, time codes; UVs subdivided) with the run's summary.
#[cfg(feature = "usd")]
fn run_usd(mut a: Args) -> Result<()> {
    use crate::io::usd::UsdShot;
    let src = a.input[0].clone();
    if a.format != "auto" || a.rest.is_some() {
        return Err(Error::format(&src, "USD input takes neither --format nor --rest (the output is .usda)"));
    }
    let shot = UsdShot::read(&src)?;
    for n in &shot.notes {
        eprintln!("note: {n}");
    }
    let out = a.out.clone();
    // One work folder per --frames slice: a farm's slices may share the output folder.
    let work = out.join(match &a.frames {
        Some(f) => format!(".anisocb-usd.{}", f.replace(|c: char| !c.is_ascii_alphanumeric(), "-")),
        None => ".anisocb-usd".into(),
    });
    let (lr, hr) = (work.join("lr"), work.join("hr"));
    if work.exists() {
        std::fs::remove_dir_all(&work).map_err(|e| Error::io(&work, e))?;
    }
    crate::io::atomic::ensure_dir(&lr)?;
    shot.write_obj_frames(&lr)?;
    a.input = vec![lr];
    a.out = hr.clone();
    run(a)?;
    let stem = src.file_stem().unwrap_or_default().to_string_lossy().into_owned();
    let dst = usd_result(&hr, &out, &stem, &shot)?;
    std::fs::remove_dir_all(&work).map_err(|e| Error::io(&work, e))?;
    println!("wrote {} ({})", dst.display(), shot.prim);
    Ok(())
}

/// Write the HR frames in `hr` (the OBJ run of a USD shot) as `out/STEM.usda`
/// (`STEM.A-B.usda` for a --frames slice, so that the slices of a farm do not overwrite each
/// other), then the run's summary beside it (`upscale.json`, `upscale.A-B.json`): written
/// after the `.usda`, a summary saying `"complete": true` means the USD file is whole. Its
/// `files` names the `.usda`, `usd` the source file and the prim. Returns the `.usda`'s path.
#[cfg(feature = "usd")]
fn usd_result(
    hr: &std::path::Path,
    out: &std::path::Path,
    stem: &str,
    shot: &crate::io::usd::UsdShot,
) -> Result<std::path::PathBuf> {
    use crate::io::json::{read_json, write_json, Layout, Object, Value};
    let mut summaries = Vec::new();
    for e in std::fs::read_dir(hr).map_err(|e| Error::io(hr, e))? {
        let name = e.map_err(|e| Error::io(hr, e))?.file_name().to_string_lossy().into_owned();
        if let Some(tag) = name.strip_prefix("upscale").and_then(|t| t.strip_suffix(".json")) {
            summaries.push((name.clone(), tag.to_string()));
        }
    }
    let [(summary, tag)] = summaries.as_slice() else {
        return Err(Error::format(hr, format!("expected one run summary here, found {}", summaries.len())));
    };
    let dst = out.join(format!("{stem}{tag}.usda"));
    shot.write_hr(hr, &dst)?;
    let Value::Obj(o) = read_json(&hr.join(summary))? else {
        return Err(Error::format(hr.join(summary), "not a JSON object"));
    };
    let mut members: Vec<(String, Value)> =
        o.0.into_iter().filter(|(k, _)| k != "files" && k != "usd").collect();
    let name = dst.file_name().unwrap_or_default().to_string_lossy().into_owned();
    members.push(("files".into(), Value::Arr(vec![Value::from(name.as_str())])));
    let usd = Object::new().str("source", &shot.file.to_string_lossy()).str("prim", &shot.prim);
    members.push(("usd".into(), Value::from(usd)));
    write_json(&out.join(summary), &Value::Obj(Object(members)), Layout::Indented)?;
    Ok(dst)
}

/// The held vertices of `--physics-pin-vertices` and `--physics-pin-group` (0-based, each once).
fn pin_vertices(a: &Args) -> Result<Vec<u32>> {
    let mut out =
        a.physics_pin_vertices.as_deref().map_or(Ok(Vec::new()), crate::geom::obj::read_vertex_list)?;
    if let Some(name) = &a.physics_pin_group {
        // The mesh that names the groups: the point cache's rest OBJ, or the shot's first frame.
        let first = match (&a.rest, a.input.first()) {
            (Some(rest), _) => rest.clone(),
            (None, Some(p)) if p.is_dir() => crate::geom::obj::list_obj_files(p)?.remove(0),
            (None, Some(p)) => p.clone(),
            (None, None) => return Err(Error::config("--physics-pin-group needs an input")),
        };
        let m = crate::geom::obj::parse_obj(&crate::geom::obj::read_obj_text(&first)?, &first)?;
        for v in crate::geom::obj::group_vertices(&m, name, &first)? {
            if !out.contains(&v) {
                out.push(v);
            }
        }
    }
    Ok(out)
}

/// `--gravity X,Y,Z` (m/s²).
/// `N` comma-separated numbers for option `what` (`form` says which).
fn numbers<const N: usize>(s: &str, what: &str, form: &str) -> Result<[f32; N]> {
    let v: Vec<f32> = s.split(',').filter_map(|c| c.trim().parse().ok()).collect();
    <[f32; N]>::try_from(v.as_slice())
        .ok()
        .filter(|_| s.split(',').count() == N)
        .ok_or_else(|| Error::config(format!("{what} {s}: expected {N} numbers {form}")))
}

fn parse_gravity(s: &str) -> Result<[f32; 3]> {
    numbers::<3>(s, "--gravity", "X,Y,Z in m/s² (y-up: 0,-9.81,0; z-up: 0,0,-9.81)")
}
