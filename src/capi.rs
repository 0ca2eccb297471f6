//! The C ABI (feature `capi`; header `include/anisocb.h`, which documents each call): an opaque
//! [`Upscaler`] handle, status codes with a per-thread last-error message, caller-owned
//! buffers. No panic crosses the boundary: each call runs under `catch_unwind` and a panic
//! becomes `ANISOCB_ERR_PANIC`. Built as a static and a shared library by `make c-example`
//! (`cargo rustc --lib --crate-type staticlib,cdylib`).
//!
//! Keep this file and `include/anisocb.h` in step: the status values, the options struct's
//! field order and every signature are the contract.

use crate::cloth::collision::{Cuboid, Sphere};
use crate::cloth::follow::{FollowParams, PinnedEdges};
use crate::cloth::params::Material;
use crate::error::Error;
use crate::geom::layout::MAX_LR_VERTICES;
use crate::nn::bundle::AnisoCb;
use crate::nn::weights::embedded_model;
use crate::pipeline::Upscaler;
use crate::sr::params::UpscaleParams;
use std::cell::RefCell;
use std::ffi::{c_char, c_int, CStr, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;

/// `anisocb_status` (include/anisocb.h).
pub const ANISOCB_OK: c_int = 0;
pub const ANISOCB_PENDING: c_int = 1;
pub const ANISOCB_DONE: c_int = 2;
pub const ANISOCB_ERR_ARGUMENT: c_int = -1;
pub const ANISOCB_ERR_IO: c_int = -2;
pub const ANISOCB_ERR_FORMAT: c_int = -3;
pub const ANISOCB_ERR_SHAPE: c_int = -4;
pub const ANISOCB_ERR_CONFIG: c_int = -5;
pub const ANISOCB_ERR_NUMERIC: c_int = -6;
pub const ANISOCB_ERR_DEVICE: c_int = -7;
pub const ANISOCB_ERR_MEMORY: c_int = -8;
pub const ANISOCB_ERR_PANIC: c_int = -99;

/// `anisocb_options` (include/anisocb.h): `repr(C)`, field for field.
#[repr(C)]
pub struct AnisocbOptions {
    /// Worker threads of the upscaler's own, 0 = one per core (`available_parallelism`). Its
    /// own threads, not rayon's process-wide pool: a frame then allocates nothing.
    pub threads: u32,
    /// A weights bundle (.npz, UTF-8 path), or null for the embedded ×2 model.
    pub weights_path: *const c_char,
    pub eta: f32,
    pub temporal: u32,
    pub strain_iters: u32,
    /// 0 or 1.
    pub mirrors: c_int,
    pub keep_outline: c_int,
    pub pin_border: c_int,
    pub gate_coarse_only: c_int,
    /// 1: the physics pass (`upscale --physics`); the fields after it are its settings.
    pub physics: c_int,
    /// m/s² in the shot's axes.
    pub gravity: [f32; 3],
    /// The shot's frame rate.
    pub fps: f32,
    /// silk, cotton, denim or rubber (UTF-8); null: cotton.
    pub material: *const c_char,
    /// Held edges, as `--physics-pin` (UTF-8); null: none.
    pub physics_pin: *const c_char,
    /// `--physics-drift`: seconds; infinity: off.
    pub physics_drift: f32,
    /// `--physics-ground`: a floor's height (m) along −gravity; NaN: no floor.
    pub physics_ground: f32,
    /// `--physics-sphere` X, Y, Z, R (m); R = 0: none.
    pub physics_sphere: [f32; 4],
    /// `--physics-box` centre X, Y, Z and half extents (m); all half extents 0: none.
    pub physics_box: [f32; 6],
    /// The most MiB a shot's frames may take (`Upscaler::with_memory_limit`); 0: as much as the
    /// allocator gives. Either way a frame that needs more is `ANISOCB_ERR_MEMORY`, not an abort.
    pub memory_limit_mib: u64,
}

thread_local! {
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

fn set_error(msg: &str) {
    let c = CString::new(msg.replace('\0', " ")).unwrap_or_default();
    LAST_ERROR.with(|e| *e.borrow_mut() = c);
}

fn status_of(e: &Error) -> c_int {
    match e {
        Error::Io { .. } => ANISOCB_ERR_IO,
        Error::Format { .. } | Error::Malformed(_) => ANISOCB_ERR_FORMAT,
        Error::Shape(_) => ANISOCB_ERR_SHAPE,
        Error::Config(_) | Error::Invalid { .. } => ANISOCB_ERR_CONFIG,
        Error::Numeric(_) => ANISOCB_ERR_NUMERIC,
        Error::Device(_) => ANISOCB_ERR_DEVICE,
        Error::OutOfMemory(_) => ANISOCB_ERR_MEMORY,
    }
}

/// A failed call: its status and message.
struct Fail(c_int, String);

impl From<Error> for Fail {
    fn from(e: Error) -> Fail {
        Fail(status_of(&e), e.renamed(c_field).to_string())
    }
}

/// The `anisocb_options` field (include/anisocb.h) that sets the library's field `field`.
fn c_field(field: &'static str) -> &'static str {
    match field {
        "pins" => "physics_pin",
        "drift_seconds" => "physics_drift",
        "ground" => "physics_ground",
        "sphere" => "physics_sphere",
        "cuboid" => "physics_box",
        f => f,
    }
}

/// Run `f`, turning a failure into its status (message kept) and a panic into
/// `ANISOCB_ERR_PANIC`.
fn guard(f: impl FnOnce() -> Result<c_int, Fail>) -> c_int {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(Ok(status)) => status,
        Ok(Err(Fail(status, msg))) => {
            set_error(&msg);
            status
        }
        Err(p) => {
            let what = p
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| p.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown".into());
            set_error(&format!("internal error (a bug in anisocb, please report it): {what}"));
            ANISOCB_ERR_PANIC
        }
    }
}

/// A bad argument (null pointer, short buffer, non-UTF-8 path).
fn argument(msg: &str) -> Fail {
    Fail(ANISOCB_ERR_ARGUMENT, msg.to_string())
}

/// The message of the last failed call on this thread ("" if none); valid until the next call
/// on this thread.
#[no_mangle]
pub extern "C" fn anisocb_last_error() -> *const c_char {
    LAST_ERROR.with(|e| e.borrow().as_ptr())
}

/// The crate version, a static string.
#[no_mangle]
pub extern "C" fn anisocb_version() -> *const c_char {
    concat!(env!("CARGO_PKG_VERSION"), "\0").as_ptr().cast()
}

/// Fill `opts` with the command line's defaults.
///
/// # Safety
/// `opts` is null or points to writable memory for an `anisocb_options`.
#[no_mangle]
pub unsafe extern "C" fn anisocb_options_default(opts: *mut AnisocbOptions) -> c_int {
    guard(|| {
        let o = opts.as_mut().ok_or_else(|| argument("anisocb_options_default: opts is null"))?;
        let p = UpscaleParams::default();
        let f = FollowParams::default();
        *o = AnisocbOptions {
            threads: 0,
            weights_path: std::ptr::null(),
            eta: p.eta,
            temporal: p.temporal as u32,
            strain_iters: p.strain_iters as u32,
            mirrors: p.mirrors as c_int,
            keep_outline: p.keep_outline as c_int,
            pin_border: p.pin_border as c_int,
            gate_coarse_only: p.gate_coarse_only as c_int,
            physics: 0,
            gravity: f.gravity,
            fps: f.fps,
            material: std::ptr::null(),
            physics_pin: std::ptr::null(),
            physics_drift: f.drift_seconds,
            physics_ground: f32::NAN,
            physics_sphere: [0.0; 4],
            physics_box: [0.0; 6],
            memory_limit_mib: 0,
        };
        Ok(ANISOCB_OK)
    })
}

/// Make an upscaler (`opts` null: the defaults) into `*out`; free it with `anisocb_free`.
///
/// # Safety
/// `opts` is null or a valid `anisocb_options` whose `weights_path` is null or a NUL-terminated
/// string; `out` points to writable memory for a pointer.
#[no_mangle]
pub unsafe extern "C" fn anisocb_new(opts: *const AnisocbOptions, out: *mut *mut Upscaler) -> c_int {
    guard(|| {
        let out = out.as_mut().ok_or_else(|| argument("anisocb_new: out is null"))?;
        *out = std::ptr::null_mut();
        let mut params = UpscaleParams::default();
        let (mut threads, mut model, mut physics, mut memory_limit) = (0, None, None, 0);
        if let Some(o) = opts.as_ref() {
            params.eta = o.eta;
            params.temporal = o.temporal as usize;
            params.strain_iters = o.strain_iters as usize;
            params.mirrors = o.mirrors != 0;
            params.keep_outline = o.keep_outline != 0;
            params.pin_border = o.pin_border != 0;
            params.gate_coarse_only = o.gate_coarse_only != 0;
            threads = o.threads as usize;
            memory_limit = o.memory_limit_mib;
            if !o.weights_path.is_null() {
                let p = CStr::from_ptr(o.weights_path)
                    .to_str()
                    .map_err(|_| argument("anisocb_new: weights_path is not UTF-8"))?;
                model = Some(AnisoCb::load(Path::new(p))?);
            }
            if o.physics != 0 {
                let text = |p: *const c_char, what: &str| -> Result<Option<&str>, Fail> {
                    match p.is_null() {
                        true => Ok(None),
                        false => CStr::from_ptr(p)
                            .to_str()
                            .map(Some)
                            .map_err(|_| argument(&format!("anisocb_new: {what} is not UTF-8"))),
                    }
                };
                let mut f = FollowParams {
                    gravity: o.gravity,
                    fps: o.fps,
                    drift_seconds: o.physics_drift,
                    ground: (!o.physics_ground.is_nan()).then_some(o.physics_ground),
                    sphere: match o.physics_sphere {
                        [_, _, _, 0.0] => None,
                        [x, y, z, r] => Some(Sphere { center: [x, y, z], radius: r }),
                    },
                    cuboid: match o.physics_box {
                        [_, _, _, 0.0, 0.0, 0.0] => None,
                        [x, y, z, hx, hy, hz] => Some(Cuboid { center: [x, y, z], half: [hx, hy, hz] }),
                    },
                    ..FollowParams::default()
                };
                if let Some(m) = text(o.material, "material")? {
                    f.material = Material::from_name(m)?;
                }
                if let Some(e) = text(o.physics_pin, "physics_pin")? {
                    f.pins = PinnedEdges::parse(e)?;
                }
                physics = Some(f);
            }
        }
        let model = match model {
            Some(m) => m,
            None => embedded_model()?,
        };
        if threads == 0 {
            threads = std::thread::available_parallelism().map_or(1, |n| n.get().min(1024));
        }
        let mut up = Upscaler::new(model, params)?.with_threads(threads)?;
        if let Some(f) = physics {
            up = up.with_physics(f)?;
        }
        if memory_limit > 0 {
            up = up.with_memory_limit(
                usize::try_from(memory_limit).unwrap_or(usize::MAX).saturating_mul(1 << 20),
            );
        }
        *out = Box::into_raw(Box::new(up));
        Ok(ANISOCB_OK)
    })
}

/// Free an upscaler (null is ignored).
///
/// # Safety
/// `up` is null or came from `anisocb_new` and is not used afterwards.
#[no_mangle]
pub unsafe extern "C" fn anisocb_free(up: *mut Upscaler) {
    if !up.is_null() {
        let _ = catch_unwind(AssertUnwindSafe(|| drop(Box::from_raw(up))));
    }
}

/// The model's scale (2), or 0 for a null handle.
///
/// # Safety
/// `up` is null or a live handle.
#[no_mangle]
pub unsafe extern "C" fn anisocb_scale(up: *const Upscaler) -> u32 {
    up.as_ref().map_or(0, |u| u.scale() as u32)
}

/// Frames between a frame going in and its result coming out (the temporal radius).
///
/// # Safety
/// `up` is null or a live handle.
#[no_mangle]
pub unsafe extern "C" fn anisocb_latency(up: *const Upscaler) -> u32 {
    up.as_ref().map_or(0, |u| u.latency() as u32)
}

/// The caller's buffer `out` of `cap` floats as the `n` floats (3·rW·rH) of an HR frame.
unsafe fn hr_buffer<'a>(out: *mut f32, cap: usize, n: usize) -> Result<&'a mut [[f32; 3]], Fail> {
    if out.is_null() || cap < n {
        return Err(argument(&format!(
            "the output buffer holds {cap} floats; the HR frame needs {n} (3·rW·rH)"
        )));
    }
    Ok(bytemuck::cast_slice_mut(std::slice::from_raw_parts_mut(out, n)))
}

/// Give the next LR frame (`w`×`h` vertices, row-major, xyz interleaved: 3·w·h floats); the
/// next HR frame (3·rW·rH floats) is written to `hr` and `ANISOCB_OK` returned, or
/// `ANISOCB_PENDING` while its temporal context is not in yet.
///
/// # Safety
/// `up` is a live handle; `lr` points to 3·w·h floats; `hr` to `hr_cap` writable floats.
#[no_mangle]
pub unsafe extern "C" fn anisocb_push(
    up: *mut Upscaler,
    w: u32,
    h: u32,
    lr: *const f32,
    hr: *mut f32,
    hr_cap: usize,
) -> c_int {
    guard(|| {
        let up = up.as_mut().ok_or_else(|| argument("anisocb_push: null handle"))?;
        let (w, h) = (w as usize, h as usize);
        if lr.is_null() {
            return Err(argument("anisocb_push: lr is null"));
        }
        // The caller's sizes, checked before a slice is made of its pointers or anything is
        // allocated for them (a product that overflows is no frame a buffer can hold).
        if w.checked_mul(h).is_none_or(|n| n > MAX_LR_VERTICES) {
            return Err(argument(&format!(
                "anisocb_push: a {w}×{h} frame is larger than the {MAX_LR_VERTICES} vertices an LR \
                 frame may have"
            )));
        }
        let r = up.scale();
        let need = 3 * r * r * w * h;
        if hr.is_null() || hr_cap < need {
            return Err(argument(&format!(
                "anisocb_push: the output buffer holds {hr_cap} floats; a {w}×{h} frame needs {need}"
            )));
        }
        // Straight from the caller's buffers into the caller's buffer: no allocation per frame.
        let pos: &[[f32; 3]] = bytemuck::cast_slice(std::slice::from_raw_parts(lr, 3 * w * h));
        let out = hr_buffer(hr, hr_cap, need)?;
        Ok(if up.push_into(w, h, pos, out)? { ANISOCB_OK } else { ANISOCB_PENDING })
    })
}

/// Most faces [`anisocb_set_mesh`] takes (with at most 4 indices each).
const MAX_MESH_FACES: usize = 4 * MAX_LR_VERTICES;

/// Switch the upscaler to a mesh that is not a regular grid: `n_vertices` vertices at rest
/// (`rest`: 3·n_vertices floats, metres), `n_faces` faces of `face_sizes[i]` (3 or 4) vertex
/// indices each, concatenated in `indices` (0-based); optionally its UVs, `n_uv` coordinates
/// (`uv`: 2·n_uv floats) with each face corner's index into them in `uv_indices` (laid out like
/// `indices`), else (`uv` null) an ARAP layout. Between shots only.
///
/// # Safety
/// `up` is a live handle; `rest` points to 3·n_vertices floats, `face_sizes` to n_faces
/// values, `indices` (and `uv_indices` with `uv`) to their sum, `uv` to 2·n_uv floats or null.
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn anisocb_set_mesh(
    up: *mut Upscaler,
    n_vertices: u32,
    rest: *const f32,
    n_faces: u32,
    face_sizes: *const u32,
    indices: *const u32,
    n_uv: u32,
    uv: *const f32,
    uv_indices: *const u32,
) -> c_int {
    guard(|| {
        let up = up.as_mut().ok_or_else(|| argument("anisocb_set_mesh: null handle"))?;
        let (nv, nf) = (n_vertices as usize, n_faces as usize);
        if rest.is_null() || face_sizes.is_null() || indices.is_null() {
            return Err(argument("anisocb_set_mesh: rest, face_sizes and indices must not be null"));
        }
        if nv == 0 || nv > MAX_LR_VERTICES || nf == 0 || nf > MAX_MESH_FACES {
            return Err(argument(&format!(
                "anisocb_set_mesh: {nv} vertices and {nf} faces; a mesh has 1 to {MAX_LR_VERTICES} \
                 vertices and 1 to {MAX_MESH_FACES} faces"
            )));
        }
        let sizes = std::slice::from_raw_parts(face_sizes, nf);
        if let Some((i, k)) = sizes.iter().enumerate().find(|(_, &k)| k != 3 && k != 4) {
            return Err(argument(&format!(
                "anisocb_set_mesh: face {i} has {k} vertices; faces are triangles or quads (3 or 4)"
            )));
        }
        let total = sizes.iter().map(|&k| k as usize).sum();
        // The concatenated corners cut into faces.
        let split = |flat: &[u32]| {
            let mut at = 0;
            sizes
                .iter()
                .map(|&k| {
                    at += k as usize;
                    flat[at - k as usize..at].to_vec()
                })
                .collect::<Vec<_>>()
        };
        let faces = split(std::slice::from_raw_parts(indices, total));
        let rest: &[[f32; 3]] = bytemuck::cast_slice(std::slice::from_raw_parts(rest, 3 * nv));
        if uv.is_null() {
            up.set_mesh(faces, rest, None)?;
            return Ok(ANISOCB_OK);
        }
        let nu = n_uv as usize;
        if uv_indices.is_null() || nu == 0 || nu > MAX_MESH_FACES {
            return Err(argument(&format!(
                "anisocb_set_mesh: with uv, give 1 to {MAX_MESH_FACES} coordinates (n_uv = {nu}) and \
                 uv_indices (one per face corner); or pass uv = NULL for an ARAP layout"
            )));
        }
        let coords: &[[f32; 2]] = bytemuck::cast_slice(std::slice::from_raw_parts(uv, 2 * nu));
        let uv_faces = split(std::slice::from_raw_parts(uv_indices, total));
        if let Some((i, &k)) = uv_faces
            .iter()
            .enumerate()
            .find_map(|(i, f)| f.iter().find(|&&k| k as usize >= nu).map(|k| (i, k)))
        {
            return Err(argument(&format!(
                "anisocb_set_mesh: face {i} has UV index {k}, but there are {nu} UV coordinates (n_uv)"
            )));
        }
        up.set_mesh(faces, rest, Some((coords, &uv_faces)))?;
        Ok(ANISOCB_OK)
    })
}

/// The vertex count of the HR frames of the mesh set by [`anisocb_set_mesh`]; 0 without one.
///
/// # Safety
/// `up` is a live handle or null.
#[no_mangle]
pub unsafe extern "C" fn anisocb_hr_vertex_count(up: *const Upscaler) -> u32 {
    up.as_ref().and_then(|u| u.mesh_vertices()).map_or(0, |(_, hr)| hr as u32)
}

/// The HR mesh's faces: 4 per LR face, in its order (a triangle splits into 4 triangles, a
/// quad into 4 quads): their sizes into `face_sizes` (`sizes_cap` values) and their vertex
/// indices, concatenated, into `indices` (`indices_cap` values).
///
/// # Safety
/// `up` is a live handle; the buffers hold their caps' values.
#[no_mangle]
pub unsafe extern "C" fn anisocb_hr_faces(
    up: *const Upscaler,
    face_sizes: *mut u32,
    sizes_cap: usize,
    indices: *mut u32,
    indices_cap: usize,
) -> c_int {
    guard(|| {
        let up = up.as_ref().ok_or_else(|| argument("anisocb_hr_faces: null handle"))?;
        let faces =
            up.hr_faces().ok_or_else(|| argument("anisocb_hr_faces: no mesh: call anisocb_set_mesh"))?;
        let total: usize = faces.iter().map(Vec::len).sum();
        if face_sizes.is_null() || indices.is_null() || sizes_cap < faces.len() || indices_cap < total {
            return Err(argument(&format!(
                "anisocb_hr_faces: the HR mesh has {} faces and {total} indices; the buffers hold {sizes_cap} \
                 and {indices_cap}",
                faces.len()
            )));
        }
        let sizes = std::slice::from_raw_parts_mut(face_sizes, faces.len());
        let flat = std::slice::from_raw_parts_mut(indices, total);
        let mut at = 0;
        for (s, f) in sizes.iter_mut().zip(faces) {
            *s = f.len() as u32;
            flat[at..at + f.len()].copy_from_slice(f);
            at += f.len();
        }
        Ok(ANISOCB_OK)
    })
}

/// [`anisocb_push`] for the mesh set by [`anisocb_set_mesh`]: the next LR frame (3·n_vertices
/// floats, the mesh's vertex order) in; the next HR frame (3·anisocb_hr_vertex_count floats)
/// written to `hr` and `ANISOCB_OK`, or `ANISOCB_PENDING`.
///
/// # Safety
/// `up` is a live handle; `lr` points to 3·n_vertices floats; `hr` to `hr_cap` writable floats.
#[no_mangle]
pub unsafe extern "C" fn anisocb_push_mesh(
    up: *mut Upscaler,
    lr: *const f32,
    hr: *mut f32,
    hr_cap: usize,
) -> c_int {
    guard(|| {
        let up = up.as_mut().ok_or_else(|| argument("anisocb_push_mesh: null handle"))?;
        let (nv, nh) = up
            .mesh_vertices()
            .ok_or_else(|| argument("anisocb_push_mesh: no mesh: call anisocb_set_mesh first"))?;
        if lr.is_null() {
            return Err(argument("anisocb_push_mesh: lr is null"));
        }
        let out = hr_buffer(hr, hr_cap, 3 * nh)?;
        let pos: &[[f32; 3]] = bytemuck::cast_slice(std::slice::from_raw_parts(lr, 3 * nv));
        Ok(match up.push_mesh(pos)? {
            Some(v) => {
                out.copy_from_slice(&v);
                ANISOCB_OK
            }
            None => ANISOCB_PENDING,
        })
    })
}

/// At the end of a shot: writes the next held-back HR frame to `hr` and returns `ANISOCB_OK`,
/// or returns `ANISOCB_DONE` when none is left (the next push starts a new shot). Grids and
/// meshes alike.
///
/// # Safety
/// `up` is a live handle; `hr` points to `hr_cap` writable floats.
#[no_mangle]
pub unsafe extern "C" fn anisocb_flush(up: *mut Upscaler, hr: *mut f32, hr_cap: usize) -> c_int {
    guard(|| {
        let up = up.as_mut().ok_or_else(|| argument("anisocb_flush: null handle"))?;
        if let Some((_, nh)) = up.mesh_vertices() {
            if up.held_back() == 0 {
                up.flush_mesh_one()?;
                return Ok(ANISOCB_DONE);
            }
            let out = hr_buffer(hr, hr_cap, 3 * nh)?;
            return Ok(match up.flush_mesh_one()? {
                Some(v) => {
                    out.copy_from_slice(&v);
                    ANISOCB_OK
                }
                None => ANISOCB_DONE,
            });
        }
        let out = match up.grid() {
            Some((w, h)) if up.held_back() > 0 => hr_buffer(hr, hr_cap, 3 * up.scale().pow(2) * w * h)?,
            _ => &mut [],
        };
        Ok(if up.flush_into(out)? { ANISOCB_OK } else { ANISOCB_DONE })
    })
}
