//! The training set: LR geometry images paired with HR ground truth and the two ground-truth
//! maps computed on it (DESIGN.md "Ground-truth boundary map", "Ground-truth enhance map").
//!
//! Input: simulated run pairs as written by `anisocb simulate --pair --out DIR`, i.e. `DIR/lr/`
//! and `DIR/hr/`, each with `geometry.npy` (T, 3, H, W) f32, `domain.npy` (2, 3) = [bmin; bmax]
//! and `meta.json` (its `scenario` and `seed` fields are read when present).
//!
//! Output (`data.npz`, a stored zip readable by `numpy.load`), N frames over all runs in
//! command-line order, frame order inside a run:
//! - `lr` (N, 3, H, W) f32 — LR geometry images, expressed in the HR run's domain;
//! - `hr` (N, 3, sH, sW) f32 — HR geometry images (s = upscale factor, 2 by default);
//! - `boundary` (N, 1, sH, sW) in {0, 1} — anisotropic-kernel boundary map of the HR mesh
//!   decoded from the HR image (Eq 2) with its domain; `d` = longest edge of that run's HR
//!   frame 0;
//! - `edges` (N, 1, sH, sW) in {0, 1} — per-channel Canny of the HR image, OR-combined;
//! - `domain` (N, 2, 3) f32 — [bmin; bmax] of the frame (HR domain);
//! - `frames.json` — per frame `{"run", "scenario", "seed", "frame"}`;
//! - `params.json` — γ, λ, radius factor, Canny σ/low/high, upscale factor, held-out names.
//!
//! If a run's LR and HR domains differ, the LR images are re-encoded into the HR domain
//! (decode with the LR domain, encode with the HR one) so that `lr`, `hr` and `domain` agree.

use crate::error::{Error, Result};
use crate::geom::anisotropy::{boundary_map, BoundaryParams};
use crate::geom::geometry_image::image_to_mesh;
use crate::geom::Domain;
use crate::imgproc::{enhance_map, CannyParams};
use crate::io::{read_npy, NpzEntries};
use crate::tensor::Tensor;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// Parameters of both ground-truth maps.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MapParams {
    pub boundary: BoundaryParams,
    pub canny: CannyParams,
}

/// One simulated LR/HR run pair, loaded.
#[derive(Clone, Debug)]
pub struct RunPair {
    /// The pair directory as given (shown in `frames.json`).
    pub name: String,
    pub scenario: String,
    pub seed: Option<u64>,
    /// (T, 3, H, W), already in `domain`.
    pub lr: Tensor,
    /// (T, 3, sH, sW).
    pub hr: Tensor,
    /// The HR run's domain.
    pub domain: Domain,
}

/// The pair directory of `dir`: `dir` itself when it holds `lr/` and `hr/`, its parent when
/// `dir` is one of them.
pub fn pair_dir(dir: &Path) -> Result<PathBuf> {
    let has =
        |d: &Path| d.join("lr").join("geometry.npy").is_file() && d.join("hr").join("geometry.npy").is_file();
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
        "not a simulated run pair: expected lr/geometry.npy and hr/geometry.npy (from `anisocb simulate --pair`)",
    ))
}

/// A string or number field of a flat JSON object, without a JSON parser: enough for the
/// `scenario` and `seed` of a run's `meta.json`.
pub fn json_field(text: &str, key: &str) -> Option<String> {
    let pat = format!("\"{key}\"");
    let at = text.find(&pat)? + pat.len();
    let rest = text[at..].trim_start().strip_prefix(':')?.trim_start();
    if let Some(s) = rest.strip_prefix('"') {
        let end = s.find('"')?;
        Some(s[..end].to_string())
    } else {
        let end = rest
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '.' || c == '-' || c == '+'))
            .unwrap_or(rest.len());
        (end > 0).then(|| rest[..end].to_string())
    }
}

fn load_half(dir: &Path) -> Result<(Tensor, Domain)> {
    let g = crate::io::npy::read_geometry_images(&dir.join("geometry.npy"))?;
    let dpath = dir.join("domain.npy");
    let dom = Domain::from_tensor(&read_npy(&dpath)?).map_err(|e| e.in_file(&dpath))?;
    Ok((g, dom))
}

/// Load one run pair (`dir` = the pair directory or its `lr/` or `hr/`).
pub fn load_run(dir: &Path) -> Result<RunPair> {
    let pd = pair_dir(dir)?;
    let (mut lr, lr_dom) = load_half(&pd.join("lr"))?;
    let (hr, domain) = load_half(&pd.join("hr"))?;
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
    let meta = std::fs::read_to_string(pd.join("hr").join("meta.json"))
        .or_else(|_| std::fs::read_to_string(pd.join("lr").join("meta.json")))
        .unwrap_or_default();
    let scenario = json_field(&meta, "scenario").unwrap_or_else(|| "unknown".into());
    let seed = json_field(&meta, "seed").and_then(|s| s.parse().ok());
    Ok(RunPair { name: pd.display().to_string(), scenario, seed, lr, hr, domain })
}

/// True if `run` matches one of the held-out names: its scenario, its directory name, its
/// path as given, or `seed=N`.
pub fn is_held_out(run: &RunPair, holdout: &[String]) -> bool {
    let leaf = Path::new(&run.name).file_name().and_then(|n| n.to_str()).unwrap_or("").to_string();
    holdout.iter().any(|h| {
        *h == run.scenario
            || *h == leaf
            || *h == run.name
            || run.seed.is_some_and(|s| *h == format!("seed={s}"))
    })
}

/// Per-frame ground truth of one HR frame.
pub struct FrameMaps {
    /// (1, sH, sW) in {0, 1}.
    pub boundary: Tensor,
    /// (1, sH, sW) in {0, 1}.
    pub edges: Tensor,
}

/// Both maps for frame `f` of an HR sequence `hr` (T, 3, H, W) in `domain`; `rest_edge` = d.
pub fn frame_maps(
    hr: &Tensor,
    f: usize,
    domain: &Domain,
    rest_edge: f32,
    p: &MapParams,
) -> Result<FrameMaps> {
    let (_, c, h, w) = hr.dims4();
    let mesh = image_to_mesh(hr, f, domain);
    let boundary = boundary_map(&mesh, rest_edge, &p.boundary)?.to_image();
    let img = Tensor { shape: vec![c, h, w], data: hr.data[f * c * h * w..(f + 1) * c * h * w].to_vec() };
    let edges = enhance_map(&img, &p.canny)?;
    Ok(FrameMaps { boundary, edges })
}

/// One entry of `frames.json`.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameInfo {
    pub run: String,
    pub scenario: String,
    pub seed: Option<u64>,
    pub frame: usize,
}

/// The assembled training set (layout in the module docs).
pub struct Dataset {
    pub lr: Tensor,
    pub hr: Tensor,
    pub boundary: Tensor,
    pub edges: Tensor,
    pub domain: Tensor,
    pub frames: Vec<FrameInfo>,
    pub params: MapParams,
    pub upscale: usize,
    pub holdout: Vec<String>,
}

/// Build the dataset from loaded runs (held-out runs already removed). `tick` is called once
/// per finished frame, from worker threads (for a progress bar). Parallel per frame;
/// the output does not depend on the thread count.
pub fn build(
    runs: &[RunPair],
    p: &MapParams,
    holdout: &[String],
    tick: &(dyn Fn() + Sync),
) -> Result<Dataset> {
    p.boundary.validate()?;
    p.canny.validate()?;
    let first = runs.first().ok_or_else(|| Error::config("no runs left to build a dataset from"))?;
    let (_, _, hl, wl) = first.lr.dims4();
    let (_, _, hh, wh) = first.hr.dims4();
    for r in runs {
        let (_, _, a, b) = r.lr.dims4();
        let (_, _, c, d) = r.hr.dims4();
        if (a, b, c, d) != (hl, wl, hh, wh) {
            return Err(Error::shape(format!(
                "run {} has LR {a}×{b} / HR {c}×{d}, but {} has LR {hl}×{wl} / HR {hh}×{wh}; one dataset needs one size",
                r.name, first.name
            )));
        }
    }
    // d per run: longest edge of HR frame 0 (the initial mesh).
    let rest: Vec<f32> = runs.iter().map(|r| image_to_mesh(&r.hr, 0, &r.domain).longest_edge()).collect();
    let jobs: Vec<(usize, usize)> =
        runs.iter().enumerate().flat_map(|(k, r)| (0..r.hr.shape[0]).map(move |f| (k, f))).collect();
    let maps: Vec<FrameMaps> = jobs
        .par_iter()
        .map(|&(k, f)| {
            let m = frame_maps(&runs[k].hr, f, &runs[k].domain, rest[k], p)
                .map_err(|e| Error::numeric(format!("run {} frame {f}: {e}", runs[k].name)))?;
            tick();
            Ok(m)
        })
        .collect::<Result<_>>()?;
    let n = jobs.len();
    let (lrs, hrs) = (3 * hl * wl, 3 * hh * wh);
    let mut ds = Dataset {
        lr: Tensor::zeros(&[n, 3, hl, wl]),
        hr: Tensor::zeros(&[n, 3, hh, wh]),
        boundary: Tensor::zeros(&[n, 1, hh, wh]),
        edges: Tensor::zeros(&[n, 1, hh, wh]),
        domain: Tensor::zeros(&[n, 2, 3]),
        frames: Vec::with_capacity(n),
        params: *p,
        upscale: hh / hl,
        holdout: holdout.to_vec(),
    };
    for (i, (&(k, f), m)) in jobs.iter().zip(&maps).enumerate() {
        let r = &runs[k];
        ds.lr.data[i * lrs..(i + 1) * lrs].copy_from_slice(&r.lr.data[f * lrs..(f + 1) * lrs]);
        ds.hr.data[i * hrs..(i + 1) * hrs].copy_from_slice(&r.hr.data[f * hrs..(f + 1) * hrs]);
        ds.boundary.data[i * hh * wh..(i + 1) * hh * wh].copy_from_slice(&m.boundary.data);
        ds.edges.data[i * hh * wh..(i + 1) * hh * wh].copy_from_slice(&m.edges.data);
        ds.domain.data[i * 6..(i + 1) * 6].copy_from_slice(&r.domain.to_tensor().data);
        ds.frames.push(FrameInfo {
            run: r.name.clone(),
            scenario: r.scenario.clone(),
            seed: r.seed,
            frame: f,
        });
    }
    Ok(ds)
}

fn json_str(s: &str) -> String {
    let mut o = String::from("\"");
    for ch in s.chars() {
        match ch {
            '"' => o.push_str("\\\""),
            '\\' => o.push_str("\\\\"),
            c if (c as u32) < 0x20 => o.push_str(&format!("\\u{:04x}", c as u32)),
            c => o.push(c),
        }
    }
    o.push('"');
    o
}

impl Dataset {
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    pub fn frames_json(&self) -> String {
        let rows: Vec<String> = self
            .frames
            .iter()
            .map(|f| {
                let seed = f.seed.map_or("null".to_string(), |s| s.to_string());
                format!(
                    "  {{\"run\": {}, \"scenario\": {}, \"seed\": {seed}, \"frame\": {}}}",
                    json_str(&f.run),
                    json_str(&f.scenario),
                    f.frame
                )
            })
            .collect();
        format!("[\n{}\n]\n", rows.join(",\n"))
    }

    pub fn params_json(&self) -> String {
        let (b, c) = (&self.params.boundary, &self.params.canny);
        let hold: Vec<String> = self.holdout.iter().map(|h| json_str(h)).collect();
        format!(
            "{{\n  \"gamma\": {},\n  \"lambda\": {},\n  \"radius_factor\": {},\n  \"canny_sigma\": {},\n  \
             \"canny_low\": {},\n  \"canny_high\": {},\n  \"upscale\": {},\n  \"holdout\": [{}]\n}}\n",
            b.gamma,
            b.lambda,
            b.radius_factor,
            c.sigma,
            c.low,
            c.high,
            self.upscale,
            hold.join(", ")
        )
    }

    pub fn to_npz(&self) -> NpzEntries {
        let mut e = NpzEntries::default();
        e.push_array("lr", self.lr.clone());
        e.push_array("hr", self.hr.clone());
        e.push_array("boundary", self.boundary.clone());
        e.push_array("edges", self.edges.clone());
        e.push_array("domain", self.domain.clone());
        e.push_file("frames.json", self.frames_json().into_bytes());
        e.push_file("params.json", self.params_json().into_bytes());
        e
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_field_reads_strings_and_numbers() {
        let t = r#"{"scenario": "flag", "seed":42, "dt": 0.005}"#;
        assert_eq!(json_field(t, "scenario").as_deref(), Some("flag"));
        assert_eq!(json_field(t, "seed").as_deref(), Some("42"));
        assert_eq!(json_field(t, "dt").as_deref(), Some("0.005"));
        assert_eq!(json_field(t, "missing"), None);
    }
}
