//! The run directory, read by the dataset builder and the demo:
//!
//! ```text
//! DIR/geometry.npy   (T, 3, H, W) f32 geometry images (Eq 1) of frames 0..T
//! DIR/domain.npy     (2, 3) f32 [bmin; bmax] (m), the sequence-wide domain (Eq 1, 2)
//! DIR/meta.json      scenario, resolution, frames, seed, dt, substeps, material, tracking … (readable)
//! DIR/obj/frame_0000.obj …   optional, quads
//! DIR/preview.png    a few frames' geometry images side by side (written by the CLI)
//! ```
//!
//! A pair is `DIR/lr/…` and `DIR/hr/…`, sharing one domain (the union of both runs' bounds with
//! a small margin) so their images are directly comparable. All writes are atomic.

use super::scenarios::ScenarioSpec;
use crate::error::{Error, Result};
use crate::geom::geometry_image::sequence_to_images;
use crate::geom::{Domain, GridMesh};
use crate::io::{atomic::ensure_dir, read_npy, write_atomic_bytes, write_npy};
use crate::tensor::Tensor;
use std::path::Path;

/// Margin (fraction of the largest extent) added around the runs' bounds to form the domain.
pub const DOMAIN_MARGIN: f32 = 0.05;

/// Write one run: geometry images, domain, metadata and (with `obj`) the frames as quad OBJ.
/// Returns the (T, 3, H, W) images it wrote.
pub fn write_run(
    dir: &Path,
    frames: &[GridMesh],
    domain: &Domain,
    meta_json: &str,
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
    write_atomic_bytes(&dir.join("meta.json"), meta_json.as_bytes())?;
    if obj {
        let od = dir.join("obj");
        ensure_dir(&od)?;
        for (k, f) in frames.iter().enumerate() {
            crate::geom::obj::write_obj_grid(&od.join(format!("frame_{k:04}.obj")), f, true)?;
        }
    }
    Ok(images)
}

/// Read a run directory: images (T, 3, H, W), domain, and the metadata text.
pub fn read_run(dir: &Path) -> Result<(Tensor, Domain, String)> {
    let gp = dir.join("geometry.npy");
    let images = read_npy(&gp)?;
    if images.rank() != 4 || images.shape[1] != 3 {
        return Err(Error::format(
            &gp,
            format!("expected (T, 3, H, W) geometry images, got shape {:?}", images.shape),
        ));
    }
    if let Some((i, v)) = images.first_non_finite() {
        return Err(Error::format(&gp, format!("non-finite value {v} at flat index {i}")));
    }
    let dp = dir.join("domain.npy");
    let domain = Domain::from_tensor(&read_npy(&dp)?).map_err(|e| e.in_file(&dp))?;
    let mp = dir.join("meta.json");
    let meta = std::fs::read_to_string(&mp).map_err(|e| Error::io(&mp, e))?;
    Ok((images, domain, meta))
}

fn arr(v: &[f32]) -> String {
    let s: Vec<String> = v.iter().map(|x| format!("{x:?}")).collect();
    format!("[{}]", s.join(", "))
}

/// Human-readable metadata of one run (`role`: "single", "lr" or "hr") at `w × h`.
pub fn meta_json(spec: &ScenarioSpec, role: &str, w: usize, h: usize, domain: &Domain) -> String {
    let p = &spec.params;
    let m = &spec.material;
    let (sx, sy) = spec.size();
    let material = if spec.scenario == super::Scenario::TwistMaterials {
        "\"bands along u: silk | rubber | denim\"".to_string()
    } else {
        format!(
            "{{\"name\": \"{}\", \"density_kg_per_m2\": {:?}, \"stretch_compliance_m_per_n\": {:?}, \
\"shear_compliance_m_per_n\": {:?}, \"bend_stiffness_n_m\": {:?}}}",
            m.name, m.density, m.stretch_compliance, m.shear_compliance, m.bend_stiffness
        )
    };
    let tracking = if role == "hr" { spec.tracking } else { 0.0 };
    format!(
        "{{
  \"format\": \"anisocb-run/1\",
  \"layout\": \"geometry.npy (T, 3, H, W) f32, pixel (row j, col i) = vertex (i, j), c = (p - bmin) / (bmax - bmin); domain.npy (2, 3) [bmin; bmax] in metres\",
  \"scenario\": \"{}\",
  \"description\": \"{}\",
  \"role\": \"{}\",
  \"resolution\": [{}, {}],
  \"lr_resolution\": [{}, {}],
  \"scale\": {},
  \"frames\": {},
  \"seed\": {},
  \"rest_size_m\": {},
  \"dt_s\": {:?},
  \"substeps\": {},
  \"iterations\": {},
  \"tethers\": {},
  \"gravity_m_per_s2\": {},
  \"damping_per_s\": {:?},
  \"collision_margin_m\": {:?},
  \"friction\": {:?},
  \"drag_kg_per_m2_s\": {:?},
  \"material\": {},
  \"bending\": \"isometric (Bergou et al. 2006)\",
  \"tracking_per_s2\": {:?},
  \"domain\": {{\"bmin\": {}, \"bmax\": {}}},
  \"generator\": \"anisocb {}\"
}}
",
        spec.scenario.name(),
        spec.scenario.description(),
        role,
        w,
        h,
        spec.w,
        spec.h,
        spec.scale,
        spec.frames,
        spec.seed,
        arr(&[sx, sy]),
        p.dt,
        p.substeps,
        p.iterations,
        if p.tethers { format!("{{\"slack\": {:?}}}", p.tether_slack) } else { "false".into() },
        arr(&p.gravity),
        p.damping,
        p.collision_margin,
        p.friction,
        p.drag,
        material,
        tracking,
        arr(&domain.bmin),
        arr(&domain.bmax),
        env!("CARGO_PKG_VERSION"),
    )
}

/// Write a single run to `dir`; returns its images.
pub fn write_single(dir: &Path, spec: &ScenarioSpec, frames: &[GridMesh], obj: bool) -> Result<Tensor> {
    let domain = Domain::enclosing(frames, DOMAIN_MARGIN);
    write_run(dir, frames, &domain, &meta_json(spec, "single", spec.w, spec.h, &domain), obj)
}

/// Write a pair to `dir/lr` and `dir/hr` with one shared domain; returns (LR, HR) images.
pub fn write_pair(
    dir: &Path,
    spec: &ScenarioSpec,
    lr: &[GridMesh],
    hr: &[GridMesh],
    obj: bool,
) -> Result<(Tensor, Tensor)> {
    let all: Vec<GridMesh> = lr.iter().chain(hr.iter()).cloned().collect();
    let domain = Domain::enclosing(&all, DOMAIN_MARGIN);
    let (hw, hh) = (hr[0].w, hr[0].h);
    let a = write_run(&dir.join("lr"), lr, &domain, &meta_json(spec, "lr", spec.w, spec.h, &domain), obj)?;
    let hs = spec.for_scale(spec.scale);
    let b = write_run(&dir.join("hr"), hr, &domain, &meta_json(&hs, "hr", hw, hh, &domain), obj)?;
    Ok((a, b))
}

/// An 8-bit RGB strip of `n` evenly spaced frames of (T, 3, H, W) images, each upscaled by
/// nearest neighbour so it is at least `min_height` pixels tall, separated by 4 grey columns.
/// Returns (width, height, rgb bytes).
pub fn preview_rgb(images: &Tensor, n: usize, min_height: usize) -> (usize, usize, Vec<u8>) {
    let (t, _, h, w) = images.dims4();
    let n = n.clamp(1, t);
    let s = min_height.div_ceil(h).max(1);
    let gap = 4;
    let (ch, cw) = (h * s, w * s);
    let width = n * cw + (n - 1) * gap;
    let mut rgb = vec![96u8; width * ch * 3];
    for f in 0..n {
        let k = if n == 1 { 0 } else { f * (t - 1) / (n - 1) };
        let x0 = f * (cw + gap);
        for y in 0..ch {
            for x in 0..cw {
                let (j, i) = (y / s, x / s);
                for c in 0..3 {
                    let v = images.data[images.idx4(k, c, j, i)];
                    rgb[(y * width + x0 + x) * 3 + c] = (v.clamp(0.0, 1.0) * 255.0).round() as u8;
                }
            }
        }
    }
    (width, ch, rgb)
}
