//! Where an upscale's LR frames come from: an OBJ sequence, a point cache with its rest mesh,
//! or a geometry.npy, opened and checked before a net runs ([`open_input`]), then read a range
//! of frames at a time as geometry images ([`Shot`], an [`LrSource`]).

use crate::error::{Error, Result};
use crate::geom::geometry_image::{image_to_mesh, mesh_to_image, Bounds};
use crate::geom::layout::MeshLayout;
use crate::geom::mesh::dist;
use crate::geom::obj::{
    list_obj_files, mesh_obj_text, natural_cmp, obj_text_with, obj_to_grid, parse_obj, read_obj_text,
    FaceStyle, ObjAttrs, ObjGrid, ObjMesh, ObjSequence,
};
use crate::geom::obj_sequence::MeshSequence;
use crate::geom::surface::{FaceUvsBuf, Subdivision, Surface};
use crate::geom::{Domain, GridMesh};
use crate::io::npy::NpyFrames;
use crate::io::point_cache::{CacheFormat, CacheHeader, PointCacheReader};
use crate::io::read_npy;
use crate::pipeline::stream::LrSource;
use crate::sr::uv::upscale_uv;
use crate::tensor::Tensor;
use std::cell::RefCell;
use std::collections::{BTreeMap, HashMap};
use std::ffi::OsString;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::rc::Rc;

/// The shot as the user gave it, read a range of frames at a time.
pub enum Shot {
    /// A geometry.npy (T, 3, H, W) with its domain.
    Npy { frames: NpyFrames, path: PathBuf },
    /// An OBJ sequence, encoded with `domain` as it is read; each frame's file attributes go to
    /// `attrs` until its HR frame is written, and notes on renumbered frames to `notes`.
    Obj { seq: Box<ObjSequence>, domain: Domain, attrs: FrameAttrs, notes: Notes },
    /// A point cache; `order[j*w + i]` is the cache point at grid vertex (i, j) (from the rest
    /// mesh `rest`, which every frame read is checked against: [`unlike_edges`]).
    Cache {
        cache: PointCacheReader,
        order: Vec<u32>,
        w: usize,
        h: usize,
        domain: Domain,
        rest: Box<GridMesh>,
    },
    /// An OBJ sequence of a mesh that is not a regular grid (issue 45): each frame laid out
    /// into the atlas image by `layout`; each frame's positions wait in `lr` until its HR
    /// frame is written (the HR mesh is their subdivision plus the nets' detail).
    Mesh { seq: Box<MeshSequence>, layout: Rc<MeshLayout>, domain: Domain, attrs: FrameAttrs, lr: LrFrames },
    /// A point cache of such a mesh, with its rest positions (every frame read is checked
    /// against them, as for a grid).
    MeshCache {
        cache: PointCacheReader,
        layout: Rc<MeshLayout>,
        domain: Domain,
        rest: Vec<[f32; 3]>,
        lr: LrFrames,
    },
}

impl Shot {
    /// (frames, columns, rows).
    pub fn size(&self) -> (usize, usize, usize) {
        match self {
            Shot::Npy { frames, .. } => (frames.frames(), frames.header.shape[3], frames.header.shape[2]),
            Shot::Obj { seq, .. } => (seq.len(), seq.first.mesh.w, seq.first.mesh.h),
            Shot::Cache { cache, w, h, .. } => (cache.header().frames, *w, *h),
            Shot::Mesh { seq, layout, .. } => (seq.len(), layout.atlas.w, layout.atlas.h),
            Shot::MeshCache { cache, layout, .. } => (cache.header().frames, layout.atlas.w, layout.atlas.h),
        }
    }

    /// The layout of a shot that is a mesh, not a grid, and its LR frames read so far.
    pub fn mesh(&self) -> Option<(&Rc<MeshLayout>, &LrFrames)> {
        match self {
            Shot::Mesh { layout, lr, .. } | Shot::MeshCache { layout, lr, .. } => Some((layout, lr)),
            _ => None,
        }
    }

    /// Encode OBJ and cache frames with `d` from now on (`.npy` frames come with theirs).
    pub fn set_domain(&mut self, d: Domain) {
        match self {
            Shot::Obj { domain, .. }
            | Shot::Cache { domain, .. }
            | Shot::Mesh { domain, .. }
            | Shot::MeshCache { domain, .. } => *domain = d,
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
            Shot::Obj { seq, domain, attrs, notes } => {
                let (w, h) = (seq.first.mesh.w, seq.first.mesh.h);
                let mut t = Tensor::zeros(&[range.len(), 3, h, w]);
                for (k, f) in range.enumerate() {
                    let (mesh, a) = seq.frame_and_attrs(f)?;
                    attrs.borrow_mut().insert(f, a);
                    put_frame(&mut t, k, &mesh, domain);
                }
                notes.borrow_mut().extend(seq.take_notes());
                Ok(t)
            }
            Shot::Cache { cache, order, w, h, domain, rest } => {
                let (w, h, n) = (*w, *h, cache.header().points);
                let pts = cache.read_frames(range.clone())?;
                let mut t = Tensor::zeros(&[range.len(), 3, h, w]);
                for (k, frame) in pts.chunks_exact(n).enumerate() {
                    let mesh = GridMesh::new(w, h, order.iter().map(|&v| frame[v as usize]).collect());
                    let (now, then) = (mesh.edge_lengths(), rest.edge_lengths());
                    check_cache_frame(&now, &then, range.start + k, cache.path())?;
                    put_frame(&mut t, k, &mesh, domain);
                }
                Ok(t)
            }
            Shot::Mesh { seq, layout, domain, attrs, lr } => {
                let (h, w) = layout.image_size();
                let mut t = Tensor::zeros(&[range.len(), 3, h, w]);
                for (k, f) in range.enumerate() {
                    let (pos, a) = seq.frame_and_attrs(f)?;
                    attrs.borrow_mut().insert(f, a);
                    put_image(&mut t, k, &layout.to_image(&pos, domain)?);
                    lr.borrow_mut().insert(f, pos);
                }
                Ok(t)
            }
            Shot::MeshCache { cache, layout, domain, rest, lr } => {
                let (h, w) = layout.image_size();
                let n = cache.header().points;
                let pts = cache.read_frames(range.clone())?;
                let mut t = Tensor::zeros(&[range.len(), 3, h, w]);
                let faces = &layout.surface.faces;
                let then = mesh_edge_lengths(rest, faces);
                for (k, frame) in pts.chunks_exact(n).enumerate() {
                    let now = mesh_edge_lengths(frame, faces);
                    check_cache_frame(&now, &then, range.start + k, cache.path())?;
                    put_image(&mut t, k, &layout.to_image(frame, domain)?);
                    lr.borrow_mut().insert(range.start + k, frame.to_vec());
                }
                Ok(t)
            }
        }
    }
}

/// LR positions of a mesh's frames read but not yet written, by frame.
pub type LrFrames = Rc<RefCell<BTreeMap<usize, Vec<[f32; 3]>>>>;

/// Frame `k` of the (n, 3, H, W) images `t`: the (1, 3, H, W) image `img`.
fn put_image(t: &mut Tensor, k: usize, img: &Tensor) {
    let n = img.len();
    t.data[k * n..(k + 1) * n].copy_from_slice(&img.data);
}

/// Lengths (metres) of each face's edges in face order (an edge shared by two faces twice).
fn mesh_edge_lengths(pos: &[[f32; 3]], faces: &[Vec<u32>]) -> Vec<f32> {
    let mut v = Vec::with_capacity(4 * faces.len());
    for f in faces {
        for i in 0..f.len() {
            v.push(dist(pos[f[i] as usize], pos[f[(i + 1) % f.len()] as usize]));
        }
    }
    v
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
fn npy_input(inputs: &[PathBuf]) -> Result<Option<PathBuf>> {
    let first = &inputs[0];
    Ok(if inputs.len() == 1 && first.is_dir() && first.join("geometry.npy").exists() {
        // A folder of OBJ frames with a stray geometry.npy: which one is the shot?
        if let Ok(objs) = list_obj_files(first) {
            return Err(Error::format(
                first,
                format!(
                    "holds both geometry.npy and {} OBJ frames ({} …): name the one to upscale, \
                     the .npy or the OBJ files",
                    objs.len(),
                    objs[0].file_name().unwrap_or_default().to_string_lossy()
                ),
            ));
        }
        Some(first.join("geometry.npy"))
    } else if inputs.len() == 1 && first.extension().is_some_and(|e| e == "npy") {
        Some(first.clone())
    } else {
        None
    })
}

/// Refuse a folder of OBJ frames that holds two shots: two or more numbered frames under
/// each of two name stems (`shotA_0001.obj` …, `shotB_0001.obj` …), which natural order would
/// play one after the other as one shot.
fn refuse_two_shots(dir: &Path, files: &[PathBuf]) -> Result<()> {
    let mut stems: Vec<(String, usize)> = Vec::new();
    for f in files {
        let Some(stem) = f.file_stem().and_then(|s| s.to_str()) else { continue };
        let head = stem.trim_end_matches(|c: char| c.is_ascii_digit());
        if head.len() == stem.len() {
            continue;
        }
        match stems.iter_mut().find(|s| s.0 == head) {
            Some(s) => s.1 += 1,
            None => stems.push((head.to_string(), 1)),
        }
    }
    let shots: Vec<_> = stems.iter().filter(|s| s.1 >= 2).collect();
    if let [a, b, ..] = shots.as_slice() {
        return Err(Error::format(
            dir,
            format!(
                "holds two shots: {}*.obj ({} frames) and {}*.obj ({} frames); give one shot's \
                 frames (its files, or a folder of its own)",
                a.0, a.1, b.0, b.1
            ),
        ));
    }
    Ok(())
}

/// The OBJ files of the input, in natural order.
fn obj_files(inputs: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    for p in inputs {
        if p.is_dir() {
            let listed = list_obj_files(p)?;
            refuse_two_shots(p, &listed)?;
            files.extend(listed);
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
pub fn frame_gaps(files: &[PathBuf]) -> Vec<String> {
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
                "{} and {} would both be written as {name} in the output folder, one shot overwriting the \
                 other; upscale each folder into its own output folder",
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

/// Per-frame OBJ attributes (`mtllib` …) of input frames read but not yet written, by frame.
pub type FrameAttrs = Rc<RefCell<BTreeMap<usize, ObjAttrs>>>;

/// Notes for the user gathered while frames are read (renumbered frames), to print.
pub type Notes = Rc<RefCell<Vec<String>>>;

/// The bounding box of a whole shot read in [`Domain::UNIT`] (images = metres), grown by
/// `margin` (a fraction of its extent): one reading pass, `chunk` frames at a time;
/// `on_frames(k)` gets the number of frames read so far.
pub fn shot_bounds(
    shot: &mut Shot,
    margin: f32,
    chunk: usize,
    on_frames: &mut dyn FnMut(usize),
) -> Result<Domain> {
    let t = shot.frames();
    let mut b = Bounds::default();
    let mut at = 0;
    while at < t {
        let n = chunk.max(1).min(t - at);
        let img = shot.read(at..at + n)?;
        for k in 0..n {
            b.add(&image_to_mesh(&img, k, &Domain::UNIT));
        }
        at += n;
        on_frames(at);
    }
    Ok(b.domain(margin))
}

/// What an OBJ-based input (an OBJ sequence, or a point cache's rest mesh) gives the output.
pub struct MeshOut {
    /// Output names per frame of the shot (OBJ output): an OBJ input's own file names, byte
    /// for byte.
    pub names: Vec<OsString>,
    pub style: FaceStyle,
    /// HR texture coordinates, if the input had usable ones.
    pub uv: Option<Vec<[f32; 2]>>,
    pub attrs: ObjAttrs,
    /// The HR mesh's faces, UVs and tags when the input is a mesh, not a grid.
    pub topo: Option<Rc<MeshTopo>>,
}

/// The subdivided mesh as written (any-mesh input): faces four per LR face, the UVs
/// subdivided with their own faces (seams stay seams), and the input's `g`/`usemtl`/`s` lines
/// before the same faces.
pub struct MeshTopo {
    pub faces: Vec<Vec<u32>>,
    /// HR texture coordinates and each HR face's indices into them.
    pub uv: Option<FaceUvsBuf>,
    pub tags: Vec<(usize, String)>,
}

impl MeshTopo {
    /// The HR topology of `m` (checked as `surface`, read from `file`); a note on UVs that
    /// cannot be kept goes to `messages`.
    pub fn of(m: &ObjMesh, sub: &Subdivision, file: &Path, messages: &mut Vec<String>) -> MeshTopo {
        let uv = if m.uv.is_empty() {
            None
        } else if let Some(f) = m.face_uv.iter().position(|t| t.is_empty()) {
            messages.push(format!(
                "note: {}: face {} has no texture coordinates; the output has no UVs",
                file.display(),
                f + 1
            ));
            None
        } else {
            let s = Subdivision::of(m.uv.len(), &m.face_uv);
            Some((s.apply(&m.uv), s.faces))
        };
        MeshTopo { faces: sub.faces.clone(), uv, tags: m.tags.clone() }
    }
}

impl MeshOut {
    /// What `g` (read from `file`) gives an HR output of scale `r` with frame `names`; a note on
    /// unusable UVs goes to `messages`.
    pub fn of(
        g: &ObjGrid,
        file: &Path,
        names: Vec<OsString>,
        r: usize,
        messages: &mut Vec<String>,
    ) -> MeshOut {
        if let Some(why) = &g.uv_note {
            messages.push(format!("note: {}: {why}", file.display()));
        }
        let uv = g.uv.as_ref().map(|uv| upscale_uv(uv, g.mesh.w, g.mesh.h, r));
        MeshOut { names, style: g.style, uv, attrs: g.attrs.clone(), topo: None }
    }

    /// What the mesh `m` (not a grid; HR topology `topo`) gives the output, frames `names`.
    pub fn of_mesh(m: &ObjMesh, topo: MeshTopo, names: Vec<OsString>) -> MeshOut {
        let style =
            if m.faces.iter().all(|f| f.len() == 3) { FaceStyle::Triangles } else { FaceStyle::Quads };
        MeshOut { names, style, uv: None, attrs: m.attrs.clone(), topo: Some(Rc::new(topo)) }
    }

    /// Plain quads named `frame_0000.obj` … for `t` frames (output of non-OBJ input).
    pub fn plain(t: usize) -> MeshOut {
        MeshOut {
            names: (0..t).map(|k| format!("frame_{k:04}.obj").into()).collect(),
            style: FaceStyle::Quads,
            uv: None,
            attrs: ObjAttrs::default(),
            topo: None,
        }
    }

    /// OBJ text of an HR frame with `attrs` (its input frame's; the rest mesh's for caches).
    pub fn obj_text(&self, mesh: &GridMesh, attrs: &ObjAttrs) -> String {
        obj_text_with(mesh, self.style != FaceStyle::Triangles, self.uv.as_deref(), attrs)
    }

    /// OBJ text of an HR frame of a mesh input (`pos`: its HR vertices) with `attrs`.
    pub fn mesh_text(&self, pos: &[[f32; 3]], attrs: &ObjAttrs) -> String {
        let t = self.topo.as_ref().expect("a mesh input");
        let uv = t.uv.as_ref().map(|(c, f)| (c.as_slice(), f.as_slice()));
        mesh_obj_text(pos, &t.faces, uv, attrs, &t.tags, 4)
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

/// Refuse frame `k` of the cache `path` (as a grid, `mesh`) whose points are in another order
/// than the rest mesh's (`rest`): frame 0 is checked when the cache is opened, every frame as
/// it is read, so a cache whose later frames were shuffled or mixed from another export is not
/// upscaled into a crumpled sheet.
fn check_cache_frame(now: &[f32], rest: &[f32], k: usize, path: &Path) -> Result<()> {
    let odd = unlike_edges(now, rest);
    if odd > MAX_UNLIKE_EDGES {
        return Err(Error::format(
            path,
            format!(
                "in frame {k} of the cache, {:.0} % of the edges are over {EDGE_RATIO}× longer or \
                 shorter than the same edges of the rest mesh (relative to the typical edge; cloth \
                 stretches by a few percent): this frame's points are not in the rest mesh's \
                 vertex order (a cache whose frames were mixed from another export); export the \
                 cache again from one object",
                100.0 * odd
            ),
        ));
    }
    Ok(())
}

/// The fraction of the edge lengths `a` whose ratio to the same edge's length in `b` is more
/// than [`EDGE_RATIO`] from the median ratio (edges of length 0 in `b` left out).
fn unlike_edges(a: &[f32], b: &[f32]) -> f64 {
    let mut ratio: Vec<f32> = a.iter().zip(b).filter(|e| *e.1 > 0.0).map(|(x, y)| x / y).collect();
    if ratio.is_empty() {
        return 0.0;
    }
    ratio.sort_by(f32::total_cmp);
    let m = ratio[ratio.len() / 2];
    let odd = ratio.iter().filter(|&&q| !(q <= m * EDGE_RATIO && q * EDGE_RATIO >= m)).count();
    odd as f64 / ratio.len() as f64
}

/// A point-cache input: the cache file, its header and its rest mesh.
pub struct CacheIn {
    pub path: PathBuf,
    pub header: CacheHeader,
    pub rest: PathBuf,
    /// The rest mesh as a grid (`None` for a mesh that is not one: the shot holds it).
    pub rest_grid: Option<ObjGrid>,
}

/// What the user gave, opened.
pub struct Input {
    /// The frames (OBJ and cache frames read in [`Domain::UNIT`] until the domain is settled).
    pub shot: Shot,
    /// The domain of `.npy` input.
    pub npy_domain: Option<Domain>,
    /// What OBJ-based input gives the output.
    pub mesh_out: Option<MeshOut>,
    pub cache_in: Option<CacheIn>,
    /// Every file the input is read from (kept safe from the output, [`super::output::refuse_out_over_input`]).
    pub files: Vec<PathBuf>,
}

/// The folder holding `file` as named (`.` for a bare name).
pub(crate) fn folder_of(file: &Path) -> &Path {
    file.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."))
}

/// Whether `a` and `b` are one file (the same inode: also through hard and symbolic links).
pub(crate) fn same_file(a: &Path, b: &Path) -> bool {
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

/// The point-cache format `path` is in, by its name (`.pc2`, `.mdd`) or, whatever its name, by
/// the PC2 signature at its start; None for anything else (an unreadable file included: its
/// reader says why).
fn point_cache_kind(path: &Path) -> Option<&'static str> {
    if let Some(f) = CacheFormat::from_path(path) {
        return Some(f.name());
    }
    // Only a regular file is opened here: opening a pipe would wait for its writer.
    if !std::fs::metadata(path).ok()?.is_file() {
        return None;
    }
    let mut head = [0u8; 12];
    let mut f = std::fs::File::open(path).ok()?;
    std::io::Read::read_exact(&mut f, &mut head).ok()?;
    (&head == b"POINTCACHE2\0").then_some(CacheFormat::Pc2.name())
}

/// Open what the user gave: OBJ files or folders, a run folder or geometry.npy, or one point
/// cache with its `rest` mesh; `r` is the model's scale (for the HR UVs). Everything that can be
/// checked before a net runs is checked here; `messages` gets the notes and warnings for the user (each line prefixed
/// `note:` or `warning:`), on what is suspicious but allowed.
pub fn open_input(
    inputs: &[PathBuf],
    rest: Option<&Path>,
    r: usize,
    messages: &mut Vec<String>,
) -> Result<Input> {
    if inputs.is_empty() {
        return Err(Error::config(
            "no input given: name OBJ files, a folder of them, a geometry.npy or a point cache",
        ));
    }
    let first = &inputs[0];
    if let Some(gp) = npy_input(inputs)? {
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
    if inputs.len() == 1 && CacheFormat::from_path(first).is_some() {
        let Some(rest) = rest else {
            return Err(Error::invalid(
                "rest",
                format!(
                "{}: a point cache holds positions only; give the mesh they move as its rest mesh: an OBJ \
                 exported from the same object, same vertex order",
                first.display()
            ),
            ));
        };
        if let Some(kind) = point_cache_kind(rest) {
            return Err(Error::invalid(
                "rest",
                format!(
                    "{}: this is a {kind} point cache, not a mesh; the rest mesh must be an OBJ \
                     file of the mesh the cache moves (exported from the same object, same vertex \
                     order), and the cache is the input",
                    rest.display()
                ),
            ));
        }
        let cache = PointCacheReader::open(first)?;
        let rest_mesh = parse_obj(&read_obj_text(rest)?, rest)?;
        if obj_to_grid(&rest_mesh, rest).is_err() {
            return open_mesh_cache(first, cache, rest, rest_mesh, messages);
        }
        let seq = ObjSequence::open(&[rest.to_path_buf()])?;
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
        let odd = unlike_edges(&frame0.edge_lengths(), &g.mesh.edge_lengths());
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
        let out =
            MeshOut::of(&g, rest, (0..t).map(|k| format!("frame_{k:04}.obj").into()).collect(), r, messages);
        let header = cache.header().clone();
        let (w, h, order) = (g.mesh.w, g.mesh.h, g.order.clone());
        let shot = Shot::Cache { cache, order, w, h, domain: Domain::UNIT, rest: Box::new(g.mesh.clone()) };
        let cin = CacheIn { path: first.clone(), header, rest: rest.to_path_buf(), rest_grid: Some(g) };
        let files = vec![first.clone(), rest.to_path_buf()];
        return Ok(Input { shot, npy_domain: None, mesh_out: Some(out), cache_in: Some(cin), files });
    }
    let caches: Vec<&PathBuf> = inputs.iter().filter(|p| CacheFormat::from_path(p).is_some()).collect();
    if !caches.is_empty() {
        return Err(Error::config(format!(
            "{} inputs given, {} of them point caches ({}): upscale one point cache per run, alone, \
             with its --rest mesh",
            inputs.len(),
            caches.len(),
            caches.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ")
        )));
    }
    if rest.is_some() {
        return Err(Error::invalid("rest", "a rest mesh is for point-cache input (.pc2 / .mdd) only"));
    }
    let files = obj_files(inputs)?;
    refuse_colliding_names(&files)?;
    messages.extend(frame_gaps(&files).into_iter().map(|g| format!("warning: {g}")));
    let first = parse_obj(&read_obj_text(&files[0])?, &files[0])?;
    if obj_to_grid(&first, &files[0]).is_err() {
        return open_mesh_sequence(files, first, messages);
    }
    let seq = ObjSequence::open(&files)?;
    let names = seq.files.iter().map(|p| p.file_name().unwrap_or_default().to_os_string()).collect();
    let out = MeshOut::of(&seq.first, &seq.files[0], names, r, messages);
    let files = seq.files.clone();
    let shot = Shot::Obj {
        seq: Box::new(seq),
        domain: Domain::UNIT,
        attrs: FrameAttrs::default(),
        notes: Notes::default(),
    };
    Ok(Input { shot, npy_domain: None, mesh_out: Some(out), cache_in: None, files })
}

/// The layout of a mesh that is not a grid (`m`, read from `file`), and a note on it.
fn lay_out(m: &ObjMesh, rest: &[[f32; 3]], file: &Path, messages: &mut Vec<String>) -> Result<MeshLayout> {
    let surface = Surface::new(m.pos.len(), m.faces.clone(), file)?;
    let uv = (!m.uv.is_empty() && m.face_uv.iter().all(|t| !t.is_empty()))
        .then_some((m.uv.as_slice(), m.face_uv.as_slice()));
    let layout = MeshLayout::new(surface, rest, uv).map_err(|e| e.in_file(file))?;
    let a = &layout.atlas;
    if let Some(why) = a.uv_note() {
        messages.push(format!(
            "note: {}: its UVs are not used to lay it out ({why}); flattened by ARAP instead",
            file.display()
        ));
    }
    messages.push(format!(
        "note: {}: a mesh of {} vertices and {} faces, not a regular grid: laid out as {} chart(s) \
         ({}) in a {}x{} geometry image at {:.1} mm a pixel (its mean edge length); the output is \
         its subdivision, {} vertices",
        file.display(),
        layout.lr_vertices(),
        layout.surface.faces.len(),
        a.charts,
        match a.source {
            crate::geom::atlas::ChartSource::Uv => "its UV islands",
            crate::geom::atlas::ChartSource::Arap => "flattened by ARAP",
        },
        a.w,
        a.h,
        1e3 * a.texel,
        layout.sub.hr_vertices()
    ));
    Ok(layout)
}

/// [`open_input`] for an OBJ sequence of a mesh that is not a grid, its first file parsed as
/// `first`.
fn open_mesh_sequence(files: Vec<PathBuf>, first: ObjMesh, messages: &mut Vec<String>) -> Result<Input> {
    let layout = lay_out(&first, &first.pos, &files[0], messages)?;
    let topo = MeshTopo::of(&first, &layout.sub, &files[0], messages);
    let names = files.iter().map(|p| p.file_name().unwrap_or_default().to_os_string()).collect();
    let out = MeshOut::of_mesh(&first, topo, names);
    let seq = MeshSequence::open(&files, first)?;
    let shot = Shot::Mesh {
        seq: Box::new(seq),
        layout: Rc::new(layout),
        domain: Domain::UNIT,
        attrs: FrameAttrs::default(),
        lr: LrFrames::default(),
    };
    Ok(Input { shot, npy_domain: None, mesh_out: Some(out), cache_in: None, files })
}

/// [`open_input`] for a point cache `path` whose rest mesh `rest` (parsed as `m`) is not a
/// grid: the cache's points are the mesh's vertices, checked on frame 0 as for a grid.
fn open_mesh_cache(
    path: &Path,
    mut cache: PointCacheReader,
    rest: &Path,
    m: ObjMesh,
    messages: &mut Vec<String>,
) -> Result<Input> {
    if cache.header().points != m.pos.len() {
        return Err(Error::format(
            path,
            format!(
                "the cache moves {} points but the rest mesh {} has {} vertices: export both from the same object",
                cache.header().points,
                rest.display(),
                m.pos.len()
            ),
        ));
    }
    let layout = lay_out(&m, &m.pos, rest, messages)?;
    let f0 = cache.read_frames(0..1)?;
    let (now, then) = (mesh_edge_lengths(&f0, &m.faces), mesh_edge_lengths(&m.pos, &m.faces));
    check_cache_frame(&now, &then, 0, path)?;
    let t = cache.header().frames;
    let topo = MeshTopo::of(&m, &layout.sub, rest, messages);
    let out = MeshOut::of_mesh(&m, topo, (0..t).map(|k| format!("frame_{k:04}.obj").into()).collect());
    let header = cache.header().clone();
    let shot = Shot::MeshCache {
        cache,
        layout: Rc::new(layout),
        domain: Domain::UNIT,
        rest: m.pos,
        lr: LrFrames::default(),
    };
    let cin = CacheIn { path: path.to_path_buf(), header, rest: rest.to_path_buf(), rest_grid: None };
    let files = vec![path.to_path_buf(), rest.to_path_buf()];
    Ok(Input { shot, npy_domain: None, mesh_out: Some(out), cache_in: Some(cin), files })
}
