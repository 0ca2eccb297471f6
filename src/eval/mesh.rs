//! `anisocb eval --meshes`: any-mesh cloth (issue 45) against its HR run, for the methods a user
//! has — the linear subdivision, the smooth subdivision (Loop on triangles, Catmull–Clark on
//! quads), the curved subdivision (the base anisocb's nets add their detail to, so the nets' own
//! part shows as the difference of two rows) and anisocb — with the metrics of a mesh run:
//!
//! - vertex RMSE and the largest vertex error (the Hausdorff distance of corresponding
//!   vertices), mm;
//! - velocity error: RMS of (Δx_pred − Δx_true) between consecutive frames, mm/frame (the
//!   temporal term of STED);
//! - normal angle: mean angle between the vertex normals, degrees;
//! - wrinkle detail: the part of a frame X its LR vertices cannot hold — X minus the linear
//!   subdivision of X's own LR vertices, along that smooth surface's normal — as an RMS (mm),
//!   its ratio to the truth's, and its frame-to-frame change (flicker, mm) and that ratio;
//! - penetration: the share of vertices inside the collider (a closed mesh), and the deepest.
//!
//! The HR run is the LR mesh subdivided once and simulated on its own (Blender's cloth, or any
//! tool): its vertices are put in anisocb's HR numbering by matching its first frame to the
//! linear subdivision of the LR run's first frame.

use crate::cloth::follow::FollowParams;
use crate::error::{Error, Result};
use crate::geom::layout::MeshLayout;
use crate::geom::obj::{list_obj_files, mesh_normals, parse_obj, read_obj_text, ObjMesh};
use crate::geom::surface::{Subdivision, Surface};
use crate::geom::vec3::{cross, dot, sub};
use crate::nn::bundle::AnisoCb;
use crate::ops::Ops;
use crate::pipeline::physics::MeshPhysicsPass;
use crate::sr::params::UpscaleParams;
use crate::sr::upscale::upscale_mesh_frames;
use std::path::{Path, PathBuf};

/// Frames of one mesh (fixed topology), metres.
pub struct MeshFrames {
    pub faces: Vec<Vec<u32>>,
    pub frames: Vec<Vec<[f32; 3]>>,
}

/// A held-out mesh run: `DIR/lr/*.obj`, `DIR/hr/*.obj` (the LR mesh subdivided once,
/// simulated), optional `DIR/collider/*.obj`, frame by frame, optional `DIR/pins.txt` (the LR
/// vertices held by the body, numbered from 1) and `DIR/scene.json` (its `fps`).
pub struct MeshRun {
    pub name: String,
    pub lr: MeshFrames,
    /// The HR run in anisocb's HR numbering ([`Subdivision`] of `lr`'s faces).
    pub hr: Vec<Vec<[f32; 3]>>,
    pub collider: Option<MeshFrames>,
    /// Its folder, for the physics pass's mesh collider.
    pub collider_dir: Option<PathBuf>,
    /// The LR mesh's UVs and such, for the layout.
    pub first: ObjMesh,
    /// Frames per second (`DIR/scene.json`'s `fps`, else 24), for the physics pass.
    pub fps: f32,
    /// The LR vertices held by the body (`DIR/pins.txt`, numbered from 1 there; 0-based
    /// here), for the physics pass.
    pub pins: Vec<u32>,
    /// The cloth's material when `DIR/scene.json` names one of anisocb's (`material.name`, as
    /// `simulate` writes for a garment), for the physics pass: what an artist gives as
    /// `--material`. None: the pass's own (Blender's scenes name none).
    pub material: Option<crate::cloth::Material>,
}

/// The OBJ frames of folder `dir` (fixed topology).
pub fn read_mesh_frames(dir: &Path) -> Result<(MeshFrames, ObjMesh)> {
    let files = list_obj_files(dir)?;
    let mut frames = Vec::with_capacity(files.len());
    let mut first: Option<ObjMesh> = None;
    for (k, f) in files.iter().enumerate() {
        let m = parse_obj(&read_obj_text(f)?, f)?;
        if let Some(m0) = &first {
            if m.faces != m0.faces || m.pos.len() != m0.pos.len() {
                return Err(Error::format(
                    f,
                    format!("frame {k} has another topology than {}", files[0].display()),
                ));
            }
        }
        frames.push(m.pos.clone());
        first.get_or_insert(m);
    }
    let first = first.expect("list_obj_files gives at least one file");
    Ok((MeshFrames { faces: first.faces.clone(), frames }, first))
}

impl MeshRun {
    /// The name of the run in `dir` (its folder's name), before reading it.
    pub fn name_of(dir: &Path) -> String {
        dir.file_name().unwrap_or_default().to_string_lossy().into_owned()
    }

    /// Read `dir` (see [`MeshRun`]).
    pub fn read(dir: &Path) -> Result<MeshRun> {
        let (lr, first) = read_mesh_frames(&dir.join("lr"))?;
        let (hr_raw, _) = read_mesh_frames(&dir.join("hr"))?;
        let cdir = dir.join("collider");
        let collider = if cdir.is_dir() { Some(read_mesh_frames(&cdir)?.0) } else { None };
        let collider_dir = collider.is_some().then_some(cdir);
        let t = lr.frames.len().min(hr_raw.frames.len());
        let sub = Subdivision::of(lr.frames[0].len(), &lr.faces);
        let order = match_vertices(&sub.apply(&lr.frames[0]), &hr_raw.frames[0], &dir.join("hr"))?;
        let hr = hr_raw.frames[..t].iter().map(|f| order.iter().map(|&v| f[v]).collect()).collect();
        let name = MeshRun::name_of(dir);
        let lr = MeshFrames { faces: lr.faces, frames: lr.frames[..t].to_vec() };
        let scene = dir.join("scene.json");
        let meta = if scene.exists() { Some(crate::io::json::read_json(&scene)?) } else { None };
        let fps = meta.as_ref().and_then(|m| m.get("fps")?.as_f64()).map_or(24.0, |f| f as f32);
        let material = meta
            .as_ref()
            .and_then(|m| m.get("material")?.get("name")?.as_str().map(str::to_string))
            .and_then(|n| crate::cloth::Material::from_name(&n).ok());
        let pins_file = dir.join("pins.txt");
        let pins =
            if pins_file.exists() { crate::geom::obj::read_vertex_list(&pins_file)? } else { Vec::new() };
        Ok(MeshRun { name, lr, hr, collider, collider_dir, first, fps, pins, material })
    }
}

/// For each point of `ours`, the index of the point of `theirs` at the same place (the HR
/// run's first frame against the LR run's first frame subdivided): one to one, each within a
/// quarter of the typical spacing, or an error that says the HR run is not the LR mesh
/// subdivided once.
fn match_vertices(ours: &[[f32; 3]], theirs: &[[f32; 3]], path: &Path) -> Result<Vec<usize>> {
    if ours.len() != theirs.len() {
        return Err(Error::format(
            path,
            format!(
                "the HR run has {} vertices; the LR mesh subdivided once has {}: the HR run must be \
                 the LR mesh subdivided once (simple subdivision) before the simulation",
                theirs.len(),
                ours.len()
            ),
        ));
    }
    // A hash grid of cell `h` (the mean nearest spacing, estimated from the bounding box).
    let (lo, hi) = crate::geom::mesh::bounds(theirs);
    let ext = (0..3).map(|k| hi[k] - lo[k]).fold(0.0f32, f32::max).max(1e-6);
    let h = ext / (theirs.len() as f32).sqrt().max(1.0);
    let cell = |p: [f32; 3]| -> [i64; 3] { std::array::from_fn(|k| ((p[k] - lo[k]) / h).floor() as i64) };
    let mut grid: std::collections::HashMap<[i64; 3], Vec<usize>> = std::collections::HashMap::new();
    for (i, p) in theirs.iter().enumerate() {
        grid.entry(cell(*p)).or_default().push(i);
    }
    let mut used = vec![false; theirs.len()];
    let mut order = Vec::with_capacity(ours.len());
    for (v, p) in ours.iter().enumerate() {
        let c = cell(*p);
        let mut best = (f32::INFINITY, usize::MAX);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    for &i in grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]).map_or(&[][..], |v| v.as_slice()) {
                        let d = crate::geom::mesh::dist(*p, theirs[i]);
                        if d < best.0 {
                            best = (d, i);
                        }
                    }
                }
            }
        }
        if best.1 == usize::MAX || best.0 > 0.25 * h || std::mem::replace(&mut used[best.1], true) {
            return Err(Error::format(
                path,
                format!(
                    "no vertex of the HR run's first frame matches vertex {v} of the LR mesh \
                     subdivided once (nearest {:.2} mm away): the HR run must start as the LR mesh \
                     subdivided once (simple subdivision), from the same first frame",
                    1e3 * best.0
                ),
            ));
        }
        order.push(best.1);
    }
    Ok(order)
}

/// One method's scores on a run (see the module docs; lengths in metres).
#[derive(Clone, Debug, PartialEq)]
pub struct MeshScores {
    pub method: String,
    pub rmse: f32,
    pub max_error: f32,
    pub velocity_error: f32,
    pub normal_deg: f32,
    pub detail: f32,
    pub flicker: f32,
    /// Share of vertex-frames inside the collider, and the deepest (metres); 0 without one.
    pub inside: f32,
    pub depth: f32,
    /// The border's length (the HR mesh's edges in one face) over the truth's, mean over
    /// frames: a border that shrinks or frills shows here.
    pub border_ratio: f32,
}

/// The wrinkle detail of every vertex of an HR frame `x` (its LR vertices are `x[..lr]`):
/// `(x − S)·n` with `S` the linear subdivision of `x[..lr]` and `n` its normals.
pub fn mesh_detail(sub: &Subdivision, lr: usize, x: &[[f32; 3]]) -> Vec<f32> {
    let s = sub.apply(&x[..lr]);
    let n = mesh_normals(&s, &sub.faces);
    x.iter().zip(&s).zip(&n).map(|((p, q), n)| dot(sub3(*p, *q), *n)).collect()
}

fn sub3(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    sub(a, b)
}

/// Score `pred` (frames in anisocb's HR numbering) against the run's truth.
pub fn score(method: &str, pred: &[Vec<[f32; 3]>], run: &MeshRun, sub: &Subdivision) -> MeshScores {
    let lr = run.lr.frames[0].len();
    let border = border_edges(&sub.faces);
    let length = |x: &[[f32; 3]]| -> f64 {
        border.iter().map(|&(a, b)| crate::geom::mesh::dist(x[a as usize], x[b as usize]) as f64).sum()
    };
    let ratios: Vec<f64> =
        pred.iter().zip(&run.hr).map(|(p, y)| length(p) / length(y).max(f64::MIN_POSITIVE)).collect();
    let (mut se, mut n, mut max_error) = (0.0f64, 0usize, 0.0f32);
    let (mut ve, mut vn) = (0.0f64, 0usize);
    let (mut ang, mut an) = (0.0f64, 0usize);
    let (mut det, mut dn) = (0.0f64, 0usize);
    let (mut fl, mut fn_) = (0.0f64, 0usize);
    let mut prev_detail: Option<Vec<f32>> = None;
    for (t, (p, y)) in pred.iter().zip(&run.hr).enumerate() {
        for (a, b) in p.iter().zip(y) {
            let e = crate::geom::mesh::dist(*a, *b);
            se += (e as f64).powi(2);
            max_error = max_error.max(e);
            n += 1;
        }
        if t > 0 {
            for ((a, a0), (b, b0)) in p.iter().zip(&pred[t - 1]).zip(y.iter().zip(&run.hr[t - 1])) {
                let dv = sub3(sub3(*a, *a0), sub3(*b, *b0));
                ve += dot(dv, dv) as f64;
                vn += 1;
            }
        }
        let (np, ny) = (mesh_normals(p, &sub.faces), mesh_normals(y, &sub.faces));
        for (a, b) in np.iter().zip(&ny) {
            ang += (dot(*a, *b).clamp(-1.0, 1.0) as f64).acos().to_degrees();
            an += 1;
        }
        let d = mesh_detail(sub, lr, p);
        for v in &d[lr..] {
            det += (*v as f64).powi(2);
            dn += 1;
        }
        if let Some(d0) = &prev_detail {
            for (a, b) in d[lr..].iter().zip(&d0[lr..]) {
                fl += ((a - b) as f64).powi(2);
                fn_ += 1;
            }
        }
        prev_detail = Some(d);
    }
    let (inside, depth) = run.collider.as_ref().map_or((0.0, 0.0), |c| penetration(pred, c));
    let rms = |s: f64, n: usize| (s / n.max(1) as f64).sqrt() as f32;
    MeshScores {
        method: method.to_string(),
        rmse: rms(se, n),
        max_error,
        velocity_error: rms(ve, vn),
        normal_deg: (ang / an.max(1) as f64) as f32,
        detail: rms(det, dn),
        flicker: rms(fl, fn_),
        inside,
        depth,
        border_ratio: (ratios.iter().sum::<f64>() / ratios.len().max(1) as f64) as f32,
    }
}

/// The edges of `faces` that are in one face only (the mesh's border), each once.
fn border_edges(faces: &[Vec<u32>]) -> Vec<(u32, u32)> {
    let mut count: std::collections::BTreeMap<(u32, u32), u32> = std::collections::BTreeMap::new();
    for f in faces {
        for i in 0..f.len() {
            *count.entry(crate::geom::surface::edge_key(f[i], f[(i + 1) % f.len()])).or_default() += 1;
        }
    }
    count.into_iter().filter(|e| e.1 == 1).map(|e| e.0).collect()
}

/// Share of the vertex-frames of `frames` inside the collider (a closed mesh, frame by frame;
/// ray parity), and the deepest of them below its surface (metres).
pub fn penetration(frames: &[Vec<[f32; 3]>], collider: &MeshFrames) -> (f32, f32) {
    let tris: Vec<[u32; 3]> =
        collider.faces.iter().flat_map(|f| (1..f.len() - 1).map(move |k| [f[0], f[k], f[k + 1]])).collect();
    let (mut inside, mut total, mut deepest) = (0usize, 0usize, 0.0f32);
    for (t, x) in frames.iter().enumerate() {
        let c = &collider.frames[t.min(collider.frames.len() - 1)];
        for p in x {
            total += 1;
            // An odd number of crossings along a slightly tilted ray: inside. A ray through an
            // edge or a corner counts the crossing twice (or not at all), so a point the first
            // ray calls inside is inside only if one of two more rays agrees (two of three).
            let odd = |dir: [f32; 3]| {
                tris.iter().filter(|tr| ray_hits(*p, dir, tr.map(|v| c[v as usize]))).count() % 2 == 1
            };
            let inside_here = odd([1.0, 0.000_37, 0.000_91])
                && [[0.000_53, 1.0, -0.000_29], [-0.000_71, 0.000_43, 1.0]]
                    .iter()
                    .filter(|d| odd(**d))
                    .count()
                    >= 1;
            if inside_here {
                inside += 1;
                let d = tris
                    .iter()
                    .map(|tr| point_triangle_distance(*p, tr.map(|v| c[v as usize])))
                    .fold(f32::INFINITY, f32::min);
                deepest = deepest.max(d);
            }
        }
    }
    (inside as f32 / total.max(1) as f32, deepest)
}

/// Whether the ray `o + s·d` (s > 0) crosses triangle `t` (Möller–Trumbore).
fn ray_hits(o: [f32; 3], d: [f32; 3], t: [[f32; 3]; 3]) -> bool {
    let (e1, e2) = (sub(t[1], t[0]), sub(t[2], t[0]));
    let p = cross(d, e2);
    let det = dot(e1, p);
    if det.abs() < 1e-12 {
        return false;
    }
    let s = sub(o, t[0]);
    let u = dot(s, p) / det;
    if !(0.0..=1.0).contains(&u) {
        return false;
    }
    let q = cross(s, e1);
    let v = dot(d, q) / det;
    if v < 0.0 || u + v > 1.0 {
        return false;
    }
    dot(e2, q) / det > 0.0
}

/// Distance from `p` to triangle `t` (Ericson, Real-Time Collision Detection 5.1.5).
pub fn point_triangle_distance(p: [f32; 3], t: [[f32; 3]; 3]) -> f32 {
    let [a, b, c] = t;
    let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(p, a));
    let (d1, d2) = (dot(ab, ap), dot(ac, ap));
    let at = |q: [f32; 3]| crate::geom::mesh::dist(p, q);
    let lerp =
        |x: [f32; 3], y: [f32; 3], s: f32| -> [f32; 3] { std::array::from_fn(|k| x[k] + s * (y[k] - x[k])) };
    if d1 <= 0.0 && d2 <= 0.0 {
        return at(a);
    }
    let bp = sub(p, b);
    let (d3, d4) = (dot(ab, bp), dot(ac, bp));
    if d3 >= 0.0 && d4 <= d3 {
        return at(b);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return at(lerp(a, b, d1 / (d1 - d3)));
    }
    let cp = sub(p, c);
    let (d5, d6) = (dot(ab, cp), dot(ac, cp));
    if d6 >= 0.0 && d5 <= d6 {
        return at(c);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return at(lerp(a, c, d2 / (d2 - d6)));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return at(lerp(b, c, (d4 - d3) / ((d4 - d3) + (d5 - d6))));
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    at(std::array::from_fn(|k| a[k] + ab[k] * v + ac[k] * w))
}

/// What [`evaluate_mesh_run`] gives: each method's scores and frames (HR numbering), and the
/// HR faces they share.
pub struct MeshRunEval {
    pub scores: Vec<MeshScores>,
    pub frames: Vec<(String, Vec<Vec<[f32; 3]>>)>,
    pub hr_faces: Vec<Vec<u32>>,
}

/// Every method on `run`: the linear, smooth and curved subdivisions and anisocb (`model`,
/// `params`), with `physics` also anisocb's frames through the physics pass (at the run's frame
/// rate, its collider a mesh collider), and the truth scored against itself (its detail and
/// flicker are the yardsticks).
pub fn evaluate_mesh_run(
    ops: &dyn Ops,
    model: &AnisoCb,
    params: &UpscaleParams,
    run: &MeshRun,
    physics: Option<&FollowParams>,
) -> Result<MeshRunEval> {
    let path = PathBuf::from(&run.name);
    let surface = Surface::new(run.lr.frames[0].len(), run.lr.faces.clone(), &path)?;
    let uv = (!run.first.uv.is_empty() && run.first.face_uv.iter().all(|t| !t.is_empty()))
        .then_some((run.first.uv.as_slice(), run.first.face_uv.as_slice()));
    let layout = MeshLayout::new(surface, &run.lr.frames[0], uv)?;
    let sub = &layout.sub;
    let mut frames: Vec<(String, Vec<Vec<[f32; 3]>>)> =
        vec![("linear subdivision".to_string(), run.lr.frames.iter().map(|f| sub.apply(f)).collect())];
    let smooth: Option<Vec<Vec<[f32; 3]>>> =
        run.lr.frames.iter().map(|f| sub.apply_smooth(&run.lr.faces, f)).collect();
    if let Some(s) = smooth {
        let name =
            if run.lr.faces.iter().all(|f| f.len() == 3) { "Loop subdivision" } else { "Catmull-Clark" };
        frames.push((name.to_string(), s));
    }
    frames.push(("curved subdivision".to_string(), run.lr.frames.iter().map(|f| layout.base(f)).collect()));
    let ours = upscale_mesh_frames(ops, model, &layout, &run.lr.frames, params)?;
    if let Some(p) = physics {
        // The run's collider (every body of the scene, frame by frame) as a mesh collider.
        let colliders = match &run.collider_dir {
            Some(d) => vec![std::sync::Arc::new(crate::cloth::mesh_collider::ColliderMesh::read(d)?)],
            None => Vec::new(),
        };
        let material = run.material.unwrap_or(p.material);
        let p =
            FollowParams { fps: run.fps, colliders, pin_vertices: run.pins.clone(), material, ..p.clone() };
        let mut pass = MeshPhysicsPass::new(p, sub.clone(), run.lr.frames[0].len());
        let cloth =
            ours.iter().enumerate().map(|(k, f)| pass.apply(f.clone(), k)).collect::<Result<Vec<_>>>()?;
        frames.push(("anisocb --physics".to_string(), cloth));
    }
    frames.push(("anisocb".to_string(), ours));
    frames.push(("HR run (truth)".to_string(), run.hr.clone()));
    let scores = frames.iter().map(|(name, f)| score(name, f, run, sub)).collect();
    Ok(MeshRunEval { scores, frames, hr_faces: sub.faces.clone() })
}

/// Triangles of faces of 3 or 4 vertices (a quad by 0-1-2, 0-2-3), for drawing.
pub fn triangles(faces: &[Vec<u32>]) -> Vec<[usize; 3]> {
    faces
        .iter()
        .flat_map(|f| (1..f.len() - 1).map(move |k| [f[0] as usize, f[k] as usize, f[k + 1] as usize]))
        .collect()
}

/// The markdown table of the runs' scores.
pub fn mesh_markdown(runs: &[(String, Vec<MeshScores>)]) -> String {
    let mut s = String::from(
        "| run | method | RMSE mm | max mm | velocity err mm/frame | normal ° | border ÷ truth | detail mm (÷ truth) | flicker mm (÷ truth) | inside % | deepest mm |\n\
         |---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for (name, rows) in runs {
        let truth = rows.iter().find(|r| r.method.starts_with("HR run"));
        for r in rows {
            let ratio = |x: f32, t: Option<f32>| {
                t.filter(|t| *t > 0.0).map_or(String::new(), |t| format!(" ({:.2})", x / t))
            };
            s += &format!(
                "| {name} | {} | {:.2} | {:.2} | {:.3} | {:.2} | {:.4} | {:.3}{} | {:.3}{} | {:.2} | {:.2} |\n",
                r.method,
                1e3 * r.rmse,
                1e3 * r.max_error,
                1e3 * r.velocity_error,
                r.normal_deg,
                r.border_ratio,
                1e3 * r.detail,
                ratio(r.detail, truth.map(|t| t.detail)),
                1e3 * r.flicker,
                ratio(r.flicker, truth.map(|t| t.flicker)),
                100.0 * r.inside,
                1e3 * r.depth
            );
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_point_inside_a_closed_box_is_found_with_its_depth() {
        // A unit cube of 12 triangles.
        let p: Vec<[f32; 3]> =
            (0..8).map(|i| [(i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32]).collect();
        let faces = vec![
            vec![0, 1, 3, 2],
            vec![4, 6, 7, 5],
            vec![0, 4, 5, 1],
            vec![2, 3, 7, 6],
            vec![0, 2, 6, 4],
            vec![1, 5, 7, 3],
        ];
        let box_ = MeshFrames { faces, frames: vec![p] };
        let frames = vec![vec![[0.5, 0.5, 0.3], [1.5, 0.5, 0.5], [0.5, -0.2, 0.5], [0.9, 0.5, 0.5]]];
        let (share, depth) = penetration(&frames, &box_);
        assert_eq!(share, 0.5);
        assert!((depth - 0.3).abs() < 1e-6, "{depth}");
    }

    #[test]
    fn the_detail_of_a_frame_is_what_its_lr_vertices_cannot_hold() {
        let faces = vec![vec![0, 1, 2, 3]];
        let lr: Vec<[f32; 3]> = vec![[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]];
        let s = Subdivision::of(4, &faces);
        let mut x = s.apply(&lr);
        assert!(mesh_detail(&s, 4, &x).iter().all(|d| *d == 0.0));
        x[8][2] += 0.01; // the centre lifted 1 cm
        let d = mesh_detail(&s, 4, &x);
        assert!((d[8].abs() - 0.01).abs() < 1e-6 && d[..8].iter().all(|v| *v == 0.0), "{d:?}");
    }
}
