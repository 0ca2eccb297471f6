//! The run directory: written by `simulate` and `demo`, read (one reader, [`read_run`], and
//! [`read_pair`] on top of it) by `dataset`, `eval` and `upscale`:
//!
//! ```text
//! DIR/geometry.npy   (T, 3, H, W) f32 geometry images (Eq 1) of frames 0..T
//! DIR/domain.npy     (2, 3) f32 [bmin; bmax] (m), the sequence-wide domain (Eq 1, 2)
//! DIR/meta.json      scenario, resolution, frames, seed, dt, substeps, material, tracking … (readable;
//!                    optional for readers)
//! DIR/obj/frame_0000.obj …   optional, quads
//! DIR/preview.png    a few frames' geometry images side by side (written by the CLI,
//!                    `viz::sheet::frame_strip`)
//! ```
//!
//! A pair is `DIR/lr/…` and `DIR/hr/…`, sharing one domain (the union of both runs' bounds with
//! a small margin) so their images are directly comparable. All writes are atomic.

use super::scenarios::ScenarioSpec;
use crate::error::{Error, Result};
use crate::geom::geometry_image::sequence_to_images;
use crate::geom::obj::{list_obj_files, read_obj_sequence};
use crate::geom::{Domain, GridMesh};
use crate::io::json::{read_json, write_json, Layout, Object, Value};
use crate::io::npy::read_geometry_images;
use crate::io::{atomic::ensure_dir, read_npy, write_npy};
use crate::tensor::Tensor;
use std::path::{Path, PathBuf};

/// Margin (fraction of the largest extent) added around the runs' bounds to form the domain.
pub const DOMAIN_MARGIN: f32 = 0.05;

/// The files [`write_run`] writes in a run directory (besides `obj/` frames).
pub const RUN_FILES: [&str; 3] = ["geometry.npy", "domain.npy", "meta.json"];

/// The name of frame `k`'s OBJ file in a run directory's `obj/`.
pub fn obj_frame_name(k: usize) -> String {
    format!("frame_{k:04}.obj")
}

/// Write one run: geometry images, domain, metadata and (with `obj`) the frames as quad OBJ.
/// Returns the (T, 3, H, W) images it wrote.
pub fn write_run(
    dir: &Path,
    frames: &[GridMesh],
    domain: &Domain,
    meta: &Value,
    obj: bool,
) -> Result<Tensor> {
    if frames.is_empty() {
        return Err(Error::shape("write_run: no frames"));
    }
    domain.validate()?;
    ensure_dir(dir)?;
    let images = sequence_to_images(frames, domain);
    write_npy(&dir.join("geometry.npy"), &images)?;
    write_npy(&dir.join("domain.npy"), &domain.to_tensor())?;
    write_json(&dir.join("meta.json"), meta, Layout::Indented)?;
    if obj {
        let od = dir.join("obj");
        ensure_dir(&od)?;
        for (k, f) in frames.iter().enumerate() {
            crate::geom::obj::write_obj_grid(&od.join(obj_frame_name(k)), f, true)?;
        }
    }
    Ok(images)
}

/// A run directory read back (or a pair's half).
#[derive(Clone, Debug)]
pub struct Run {
    /// (T, 3, H, W) geometry images (Eq 1).
    pub images: Tensor,
    /// The sequence-wide domain the images are normalised by.
    pub domain: Domain,
    /// `meta.json`, where the directory has one.
    pub meta: Option<Value>,
}

/// Read a run directory: `dir/geometry.npy`, `dir/domain.npy`, and `dir/meta.json` if present.
pub fn read_run(dir: &Path) -> Result<Run> {
    read_run_at(&dir.join("geometry.npy"))
}

/// Read the geometry images at `geometry` (any `.npy` name) with the `domain.npy` beside it,
/// and the `meta.json` beside it if there is one. Every check of
/// [`crate::io::npy::read_geometry_images`] applies; errors name the file.
pub fn read_run_at(geometry: &Path) -> Result<Run> {
    let images = read_geometry_images(geometry)?;
    let dp = geometry.with_file_name("domain.npy");
    if !dp.exists() {
        return Err(Error::format(
            geometry,
            format!("needs its domain beside it ({} with [bmin; bmax], shape [2, 3])", dp.display()),
        ));
    }
    let domain = Domain::from_tensor(&read_npy(&dp)?).map_err(|e| e.in_file(&dp))?;
    let mp = geometry.with_file_name("meta.json");
    let meta = if mp.exists() { Some(read_json(&mp)?) } else { None };
    Ok(Run { images, domain, meta })
}

/// A run directory, or a directory of OBJ frames (domain: bounding box + 5 % margin).
fn read_run_or_obj(dir: &Path) -> Result<Run> {
    if dir.join("geometry.npy").is_file() {
        return read_run(dir);
    }
    let (frames, _) = read_obj_sequence(&list_obj_files(dir)?)?;
    let domain = Domain::enclosing(&frames, 0.05);
    Ok(Run { images: sequence_to_images(&frames, &domain), domain, meta: None })
}

/// One LR/HR run pair, loaded.
#[derive(Clone, Debug)]
pub struct RunPair {
    /// The pair directory as given.
    pub name: String,
    /// From `meta.json` (HR, else LR); "unknown" without one.
    pub scenario: String,
    pub seed: Option<u64>,
    /// (T, 3, H, W), in `domain`.
    pub lr: Tensor,
    /// (T, 3, sH, sW).
    pub hr: Tensor,
    /// The HR run's domain.
    pub domain: Domain,
    /// `meta.json` (HR, else LR; `Null` without one).
    pub meta: Value,
}

impl RunPair {
    /// The pair directory's own name (its last path component, `run` if it has none): what
    /// datasets and reports record, so no machine path ends up in them.
    pub fn label(&self) -> String {
        pair_label(Path::new(&self.name))
    }
}

/// The label of the pair directory `dir` ([`RunPair::label`]), before reading it.
pub fn pair_label(dir: &Path) -> String {
    let name = dir.file_name().or_else(|| dir.parent().and_then(Path::file_name));
    name.map_or_else(|| "run".to_string(), |n| n.to_string_lossy().into_owned())
}

/// True if `d` holds a run: `geometry.npy`, or at least one `.obj` file (an exported sequence).
fn holds_run(d: &Path) -> bool {
    d.join("geometry.npy").is_file()
        || std::fs::read_dir(d).is_ok_and(|mut it| {
            it.any(|e| e.is_ok_and(|e| e.path().extension().is_some_and(|x| x.eq_ignore_ascii_case("obj"))))
        })
}

/// The pair directory of `dir`: `dir` itself when it holds `lr/` and `hr/`, its parent when
/// `dir` is one of them.
pub fn pair_dir(dir: &Path) -> Result<PathBuf> {
    let has = |d: &Path| holds_run(&d.join("lr")) && holds_run(&d.join("hr"));
    if has(dir) {
        return Ok(dir.to_path_buf());
    }
    let leaf = dir.file_name().and_then(|n| n.to_str());
    if matches!(leaf, Some("lr" | "hr")) {
        if let Some(parent) = dir.parent() {
            if has(parent) {
                return Ok(parent.to_path_buf());
            }
        }
    }
    Err(Error::format(
        dir,
        "not a run pair: expected lr/ and hr/, each with geometry.npy (from `anisocb simulate --pair`) or an OBJ sequence (e.g. exported from Blender)",
    ))
}

/// Read a run pair (`dir` = the pair directory or its `lr/` or `hr/`). If the LR and HR
/// domains differ (pairs not written by [`write_pair`]), the LR images are re-encoded into the
/// HR domain (decode with the LR domain, encode with the HR one), so `lr`, `hr` and `domain`
/// agree.
///
/// An `lr/` or `hr/` with OBJ files instead of `geometry.npy` is read as an OBJ sequence (frames
/// in natural name order, grids recovered from connectivity); its domain is its bounding box
/// plus the simulator's 5 % margin.
pub fn read_pair(dir: &Path) -> Result<RunPair> {
    let pd = pair_dir(dir)?;
    let Run { images: mut lr, domain: lr_dom, meta: lr_meta } = read_run_or_obj(&pd.join("lr"))?;
    let Run { images: hr, domain, meta: hr_meta } = read_run_or_obj(&pd.join("hr"))?;
    let (tl, _, hl, wl) = lr.dims4();
    let (th, _, hh, wh) = hr.dims4();
    if tl != th {
        return Err(Error::format(&pd, format!("LR has {tl} frames but HR has {th}")));
    }
    if hh % hl != 0 || wh % wl != 0 || hh / hl != wh / wl || hh / hl < 1 {
        return Err(Error::format(
            &pd,
            format!("HR size {hh}×{wh} is not an integer multiple of LR size {hl}×{wl} on both axes"),
        ));
    }
    if lr_dom != domain {
        for px in 0..tl * hl * wl {
            let (f, v) = (px / (hl * wl), px % (hl * wl));
            let base = f * 3 * hl * wl + v;
            let c = [lr.data[base], lr.data[base + hl * wl], lr.data[base + 2 * hl * wl]];
            let e = domain.encode(lr_dom.decode(c));
            for (k, ek) in e.iter().enumerate() {
                lr.data[base + k * hl * wl] = *ek;
            }
        }
    }
    let meta = hr_meta.or(lr_meta).unwrap_or(Value::Null);
    let scenario = meta.get("scenario").and_then(Value::as_str).unwrap_or("unknown").to_string();
    let seed = meta.get("seed").and_then(Value::as_u64);
    Ok(RunPair { name: pd.display().to_string(), scenario, seed, lr, hr, domain, meta })
}

/// Human-readable metadata of one run (`role`: "single", "lr" or "hr") at `w × h`.
pub fn meta_json(spec: &ScenarioSpec, role: &str, w: usize, h: usize, domain: &Domain) -> Value {
    let p = &spec.params;
    // A varied run (`--vary`) may simulate another material than the spec's.
    let m = &super::scenarios::Variation::from_seed(spec.vary).material.unwrap_or(spec.material);
    let (sx, sy) = spec.size();
    let material: Value = if spec.scenario == super::Scenario::TwistMaterials {
        "bands along u: silk | rubber | denim".into()
    } else {
        Object::new()
            .str("name", m.name)
            .val("density_kg_per_m2", Value::real(m.density))
            .val("stretch_compliance_m_per_n", Value::real(m.stretch_compliance))
            .val("shear_compliance_m_per_n", Value::real(m.shear_compliance))
            .val("bend_stiffness_n_m", Value::real(m.bend_stiffness))
            .into()
    };
    let tracking = if role == "hr" { spec.tracking } else { 0.0 };
    let tethers: Value =
        if p.tethers { Object::new().val("slack", Value::real(p.tether_slack)).into() } else { false.into() };
    Object::new()
        .str("format", "anisocb-run/1")
        .str(
            "layout",
            "geometry.npy (T, 3, H, W) f32, pixel (row j, col i) = vertex (i, j), c = (p - bmin) / (bmax - bmin); \
             domain.npy (2, 3) [bmin; bmax] in metres",
        )
        .str("scenario", spec.scenario.name())
        .str("description", spec.scenario.description())
        .str("role", role)
        .val("resolution", vec![Value::num(w), Value::num(h)])
        .val("lr_resolution", vec![Value::num(spec.w), Value::num(spec.h)])
        .num("scale", spec.scale)
        .num("frames", spec.frames)
        .num("seed", spec.seed)
        .num("vary", spec.vary)
        .val("rest_size_m", Value::reals(&[sx, sy]))
        .val("dt_s", Value::real(p.dt))
        .num("substeps", p.substeps)
        .num("iterations", p.iterations)
        .val("tethers", tethers)
        .val("gravity_m_per_s2", Value::reals(&p.gravity))
        .val("damping_per_s", Value::real(p.damping))
        .val("collision_margin_m", Value::real(p.collision_margin))
        .val("friction", Value::real(p.friction))
        .val("drag_kg_per_m2_s", Value::real(p.drag))
        .val("material", material)
        .str("bending", "isometric (Bergou et al. 2006)")
        .val("tracking_per_s2", Value::real(tracking))
        .str("tracking_mode", if tracking > 0.0 { spec.tracking_mode.name() } else { "none" })
        .val("hr_jitter_m", Value::real(if role == "hr" { spec.hr_jitter } else { 0.0 }))
        .num("hr_restart_frame", if role == "hr" { spec.hr_restart } else { 0 })
        .val("hr_blind", Value::Bool(role == "hr" && spec.hr_blind))
        .val(
            "domain",
            Object::new().val("bmin", Value::reals(&domain.bmin)).val("bmax", Value::reals(&domain.bmax)),
        )
        .str("generator", &format!("anisocb {}", env!("CARGO_PKG_VERSION")))
        .into()
}

/// Write a single run to `dir`; returns its images.
pub fn write_single(dir: &Path, spec: &ScenarioSpec, frames: &[GridMesh], obj: bool) -> Result<Tensor> {
    let domain = Domain::enclosing(frames, DOMAIN_MARGIN);
    write_run(dir, frames, &domain, &meta_json(spec, "single", spec.w, spec.h, &domain), obj)
}

/// Write a pair to `dir/lr` and `dir/hr` with one shared domain; returns what
/// [`read_pair`] would read back.
pub fn write_pair(
    dir: &Path,
    spec: &ScenarioSpec,
    lr: &[GridMesh],
    hr: &[GridMesh],
    obj: bool,
) -> Result<RunPair> {
    let all: Vec<GridMesh> = lr.iter().chain(hr.iter()).cloned().collect();
    let domain = Domain::enclosing(&all, DOMAIN_MARGIN);
    let (hw, hh) = (hr[0].w, hr[0].h);
    let lr = write_run(&dir.join("lr"), lr, &domain, &meta_json(spec, "lr", spec.w, spec.h, &domain), obj)?;
    let hs = spec.for_scale(spec.scale);
    let meta = meta_json(&hs, "hr", hw, hh, &domain);
    let hr = write_run(&dir.join("hr"), hr, &domain, &meta, obj)?;
    Ok(RunPair {
        name: dir.display().to_string(),
        scenario: spec.scenario.name().to_string(),
        seed: Some(spec.seed),
        lr,
        hr,
        domain,
        meta,
    })
}

/// Write a garment run (`simulate` with a garment) to `dir` in the layout `eval --meshes` and
/// `upscale` read (OBJ frames, Y up, metres):
///
/// ```text
/// DIR/lr/cloth_0000.obj …        the LR run, with the pattern's UVs
/// DIR/hr/cloth_0000.obj …        (a pair) the HR run: the LR mesh subdivided once, UVs subdivided
/// DIR/collider/body_0000.obj …   the body, one closed mesh per frame (`upscale --collider`)
/// DIR/pins.txt                   the LR vertices sewn to the body, from 1, if any (`--physics-pin-vertices`)
/// DIR/scene.json                 garment, frames, fps, seed, material, tracking …
/// ```
pub fn write_garment_run(
    dir: &Path,
    spec: &super::garments::GarmentSpec,
    run: &super::garments::GarmentRun,
) -> Result<()> {
    use crate::geom::obj::{mesh_obj_text, ObjAttrs};
    use crate::geom::surface::Subdivision;
    use crate::io::atomic::write_atomic_bytes;
    let m = &run.mesh;
    let attrs = ObjAttrs { object: Some(spec.garment.name().to_string()), ..Default::default() };
    let write_frames = |sub: &str,
                        stem: &str,
                        faces: &[Vec<u32>],
                        uv: Option<crate::geom::surface::FaceUvs>,
                        frames: &[Vec<[f32; 3]>]| {
        let d = dir.join(sub);
        ensure_dir(&d)?;
        for (k, f) in frames.iter().enumerate() {
            let text = mesh_obj_text(f, faces, uv, &attrs, &[], 1);
            write_atomic_bytes(&d.join(format!("{stem}_{k:04}.obj")), text.as_bytes())?;
        }
        Ok::<(), Error>(())
    };
    write_frames("lr", "cloth", &m.faces, Some((&m.uv, &m.face_uv)), &run.lr)?;
    if !run.hr.is_empty() {
        let s = Subdivision::of(m.uv.len(), &m.face_uv);
        let uv = s.apply(&m.uv);
        write_frames("hr", "cloth", &run.sub.faces, Some((&uv, &s.faces)), &run.hr)?;
    }
    let body_attrs = ObjAttrs { object: Some("body".to_string()), ..Default::default() };
    let cd = dir.join("collider");
    ensure_dir(&cd)?;
    for (k, f) in run.body.iter().enumerate() {
        let text = mesh_obj_text(f, &run.body_faces, None, &body_attrs, &[], 1);
        write_atomic_bytes(&cd.join(format!("body_{k:04}.obj")), text.as_bytes())?;
    }
    let mut pins: Vec<u32> = m.pins.iter().map(|p| p.0 + 1).collect();
    pins.sort_unstable();
    if !pins.is_empty() {
        let list: Vec<String> = pins.iter().map(|v| v.to_string()).collect();
        let text = format!(
            "# LR vertices sewn to the body, numbered from 1 (upscale --physics-pin-vertices)\n{}\n",
            list.join(" ")
        );
        write_atomic_bytes(&dir.join("pins.txt"), text.as_bytes())?;
    }
    let p = &spec.params;
    let mat = &run.material;
    let meta: Value = Object::new()
        .str("format", "anisocb-garment-run/1")
        .str("scene", spec.garment.name())
        .str("garment", spec.garment.name())
        .num("frames", spec.frames)
        .val("fps", Value::real(1.0 / p.dt))
        .num("seed", spec.seed)
        .num("vary", spec.vary)
        .str("up_axis", "Y")
        .str("units", "m")
        .val("lr", Object::new().num("vertices", m.pos.len()).num("faces", m.faces.len()))
        .val(
            "hr",
            Object::new()
                .num("vertices", run.sub.hr_vertices())
                .num("faces", run.sub.faces.len())
                .str("mesh", "the LR mesh subdivided once (midpoints, quad centres), HR vertices 0..N_LR-1 are the LR vertices")
                .val("tracking_per_s2", Value::real(if run.hr.is_empty() { 0.0 } else { spec.tracking }))
                .str("tracking_mode", "coarse: one constraint per LR vertex")
                .val("hr_jitter_m", Value::real(if run.hr.is_empty() { 0.0 } else { spec.hr_jitter })),
        )
        .num("pinned", m.pins.len())
        .val("collider_thickness_m", Value::real(spec.thickness))
        .val("dt_s", Value::real(p.dt))
        .num("substeps_lr", p.substeps)
        .num("substeps_hr", 2 * p.substeps)
        .val("gravity_m_per_s2", Value::reals(&p.gravity))
        .val(
            "material",
            Object::new()
                .str("name", mat.name)
                .val("density_kg_per_m2", Value::real(mat.density))
                .val("stretch_compliance_m_per_n", Value::real(mat.stretch_compliance))
                .val("bend_stiffness_n_m", Value::real(mat.bend_stiffness)),
        )
        .str("bending", "isometric (Bergou et al. 2006) on the triangles (a quad split along 0-2)")
        .str("generator", &format!("anisocb {}", env!("CARGO_PKG_VERSION")))
        .into();
    write_json(&dir.join("scene.json"), &meta, Layout::Indented)
}
