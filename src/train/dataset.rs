//! The training set: LR geometry images paired with HR ground truth and the two ground-truth
//! maps computed on it (docs/architecture.md "Ground-truth boundary map", "Ground-truth enhance map").
//!
//! Input: simulated run pairs as written by `anisocb simulate --pair --out DIR`, i.e. `DIR/lr/`
//! and `DIR/hr/`, each with `geometry.npy` (T, 3, H, W) f32, `domain.npy` (2, 3) = [bmin; bmax]
//! and `meta.json` (its `scenario` and `seed` fields are read when present), read by
//! [`crate::cloth::run_io::read_pair`].
//!
//! Output (`data.npz`, a stored zip readable by `numpy.load`), N frames over all runs in
//! command-line order, frame order inside a run:
//! - `lr` (N, 3, H, W) f32 — LR frames in the nets' input coordinates: the HR run's domain
//!   (Eq 1, `input_frame = domain`) or each frame's own cloth frame estimated from its LR
//!   frame (`input_frame = cloth-frame`, [`crate::geom::cloth_frame`]);
//! - `hr` (N, 3, sH, sW) f32 — HR frames in the same per-frame coordinates as `lr`
//!   (s = upscale factor, 2 by default);
//! - `boundary` (N, 1, sH, sW) in {0, 1} — anisotropic-kernel boundary map of the HR mesh
//!   decoded from the HR image (Eq 2) with its domain; `d` = longest edge of that run's HR
//!   frame 0; or, with `--boundary-benefit`, soft targets in [0, 1] saying where a trained
//!   GeometryNet's residual does not help ([`benefit_boundary`]);
//! - `edges` (N, 1, sH, sW) in {0, 1} — per-channel Canny of the HR image (in the nets'
//!   coordinates, so a cloth-frame map does not depend on where the cloth is), OR-combined;
//! - `domain` (N, 2, 3) f32 — [bmin; bmax] of the frame (HR domain);
//! - `frames.json` — per frame `{"run", "scenario", "seed", "frame"}`;
//! - `params.json` — γ, λ, radius factor, Canny σ/low/high, upscale factor, input frame,
//!   held-out names.
//!
//! If a run's LR and HR domains differ, `read_pair` has re-encoded the LR images into the HR
//! domain, so that `lr`, `hr` and `domain` agree.

use crate::cloth::run_io::RunPair;
use crate::error::{Error, Result};
use crate::eval::mesh::MeshRun;
use crate::geom::anisotropy::{boundary_map, BoundaryParams};
use crate::geom::cloth_frame::{map_frames, to_cloth_frames, InputFrame};
use crate::geom::geometry_image::image_to_mesh;
use crate::geom::layout::MeshLayout;
use crate::geom::surface::Surface;
use crate::geom::Domain;
use crate::imgproc::{enhance_map, CannyParams};
use crate::io::json::{Layout, Object, Value};
use crate::io::NpzEntries;
use crate::nn::bundle::AnisoCb;
use crate::nn::geometry_net::GeometryNet;
use crate::ops::loss::{detail_amplitude, DetailEnergy};
use crate::ops::resample::resize;
use crate::ops::{Interp, Ops};
use crate::sr::compose::compose;
use crate::sr::upscale::views_averaged;
use crate::tensor::Tensor;
use rayon::prelude::*;

/// Parameters of both ground-truth maps.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MapParams {
    pub boundary: BoundaryParams,
    pub canny: CannyParams,
}

/// True if `run` matches one of the held-out names: its scenario, its directory name, its
/// path as given, or `seed=N`. A window of a mesh run (`DIR@k`, [`mesh_run_windows`]) goes
/// with its run.
pub fn is_held_out(run: &RunPair, holdout: &[String]) -> bool {
    let leaf = run.label();
    let (leaf, name) = (window_of(&leaf), window_of(&run.name));
    holdout.iter().any(|h| {
        *h == run.scenario || h == leaf || h == name || run.seed.is_some_and(|s| *h == format!("seed={s}"))
    })
}

/// The run a window's name (`DIR@k`) belongs to.
fn window_of(name: &str) -> &str {
    name.rsplit_once('@').filter(|(_, k)| k.parse::<usize>().is_ok()).map_or(name, |(run, _)| run)
}

/// A mesh run (a garment pair from `simulate --scenario skirt --pair`, or any LR/HR pair of OBJ
/// sequences where HR is the LR mesh subdivided once) as run pairs of images the size of the
/// sheets' (issue 45, step 5): its geometry images laid out as `upscale` lays them out (the
/// first LR frame and the file's UVs), cut into windows of `n` × `n` LR pixels
/// ([`MeshLayout::training_windows`]). The HR image of a window is `U + D`: `U` the LR window
/// upsampled by `upsample` (the interpolation the nets will refine), `D` the HR run's detail
/// (its frame minus the LR frame's linear subdivision) rasterised in the charts, 0 outside
/// ([`crate::geom::layout::TrainingWindow::hr_detail`]): what `upscale` composes on a mesh.
/// Images in metres ([`Domain::UNIT`]); one pair per window, named `DIR@k`.
pub fn mesh_run_windows(
    dir: &std::path::Path,
    run: &MeshRun,
    n: usize,
    r: usize,
    upsample: Interp,
) -> Result<Vec<RunPair>> {
    let rest = &run.lr.frames[0];
    let surface = Surface::new(rest.len(), run.lr.faces.clone(), &dir.join("lr"))?;
    let uv = (!run.first.uv.is_empty() && run.first.face_uv.iter().all(|t| !t.is_empty()))
        .then_some((run.first.uv.as_slice(), run.first.face_uv.as_slice()));
    let layout = MeshLayout::new(surface, rest, uv).map_err(|e| e.in_file(dir.join("lr")))?;
    let meta = crate::io::json::read_json(&dir.join("scene.json")).unwrap_or(Value::Null);
    let scenario = meta.get("garment").and_then(|g| g.as_str()).unwrap_or("mesh").to_string();
    let seed = meta.get("seed").and_then(|s| s.as_f64()).map(|s| s as u64);
    let t = run.lr.frames.len();
    let detail: Vec<Vec<[f32; 3]>> = (0..t)
        .map(|f| {
            let s = layout.base(&run.lr.frames[f]);
            run.hr[f].iter().zip(&s).map(|(h, s)| [h[0] - s[0], h[1] - s[1], h[2] - s[2]]).collect()
        })
        .collect();
    let windows = layout.training_windows(rest, n, r);
    Ok(windows
        .iter()
        .enumerate()
        .map(|(k, win)| {
            let mut lr = Tensor::zeros(&[t, 3, n, n]);
            let (a, b) = (3 * n * n, 3 * r * r * n * n);
            for f in 0..t {
                win.lr_image(&run.lr.frames[f], &mut lr.data[f * a..(f + 1) * a]);
            }
            let mut hr = resize(&lr, r * n, r * n, upsample);
            let mut d = vec![0.0f32; b];
            for (frame, hr) in detail.iter().zip(hr.data.chunks_exact_mut(b)) {
                win.hr_detail(frame, &mut d);
                hr.iter_mut().zip(&d).for_each(|(u, d)| *u += d);
            }
            RunPair {
                name: format!("{}@{k}", dir.display()),
                scenario: scenario.clone(),
                seed,
                lr,
                hr,
                domain: Domain::UNIT,
                meta: meta.clone(),
            }
        })
        .collect())
}

/// Per-frame ground truth of one HR frame.
pub struct FrameMaps {
    /// (1, sH, sW) in {0, 1}.
    pub boundary: Tensor,
    /// (1, sH, sW) in {0, 1}.
    pub edges: Tensor,
}

/// Both maps for frame `f` of an HR sequence `hr` (T, 3, H, W) in `domain`; `rest_edge` = d.
/// `net_img` is the same HR frame (3, H, W) in the nets' coordinates (Canny runs on it).
pub fn frame_maps(
    hr: &Tensor,
    f: usize,
    domain: &Domain,
    net_img: &[f32],
    rest_edge: f32,
    p: &MapParams,
) -> Result<FrameMaps> {
    let (_, c, h, w) = hr.dims4();
    let mesh = image_to_mesh(hr, f, domain);
    let boundary = boundary_map(&mesh, rest_edge, &p.boundary)?.to_image();
    let img = Tensor { shape: [c, h, w].into(), data: net_img.to_vec() };
    let edges = enhance_map(&img, &p.canny)?;
    Ok(FrameMaps { boundary, edges })
}

/// Frame `f` of a run pair in the nets' coordinates: (LR (3, H, W), HR (3, sH, sW)), both
/// mapped by the transform estimated from the LR frame.
pub fn frame_in(run: &RunPair, f: usize, frame: InputFrame) -> (Vec<f32>, Vec<f32>) {
    let (lr, maps) = to_cloth_frames(frame, &run.lr.slice_batch(f, 1), &run.domain);
    let mut hr = run.hr.slice_batch(f, 1);
    map_frames(&mut hr, maps.iter().map(|m| &m.0), true);
    (lr.into_data(), hr.into_data())
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
    /// The coordinates `lr` and `hr` are in.
    pub input_frame: InputFrame,
    /// What `boundary` holds: "anisotropy" (Eq 4–9) or the benefit of a net's residual.
    pub boundary_source: String,
    /// What the edge target is (Canny edges of the HR frame, or the truth's wrinkle energy).
    pub edges_source: String,
    /// What `hr` holds: the HR runs, or a bundle's output distilled from them.
    pub hr_source: String,
    pub upscale: usize,
    pub holdout: Vec<String>,
}

/// Build the dataset from loaded runs (held-out runs already removed). `tick` is called once
/// per finished frame, from worker threads (for a progress bar). Parallel per frame;
/// the output does not depend on the thread count.
pub fn build(
    runs: &[RunPair],
    p: &MapParams,
    input_frame: InputFrame,
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
    let maps: Vec<(Vec<f32>, Vec<f32>, FrameMaps)> = jobs
        .par_iter()
        .map(|&(k, f)| {
            let (lr, hr) = frame_in(&runs[k], f, input_frame);
            let m = frame_maps(&runs[k].hr, f, &runs[k].domain, &hr, rest[k], p)
                .map_err(|e| Error::numeric(format!("run {} frame {f}: {e}", runs[k].name)))?;
            tick();
            Ok((lr, hr, m))
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
        input_frame,
        boundary_source: "anisotropy (Eq 4-9)".into(),
        edges_source: "Canny edges of the HR geometry image".into(),
        hr_source: "the HR runs".into(),
        upscale: hh / hl,
        holdout: holdout.to_vec(),
    };
    for (i, (&(k, f), (lr, hr, m))) in jobs.iter().zip(&maps).enumerate() {
        let r = &runs[k];
        ds.lr.data[i * lrs..(i + 1) * lrs].copy_from_slice(lr);
        ds.hr.data[i * hrs..(i + 1) * hrs].copy_from_slice(hr);
        ds.boundary.data[i * hh * wh..(i + 1) * hh * wh].copy_from_slice(&m.boundary.data);
        ds.edges.data[i * hh * wh..(i + 1) * hh * wh].copy_from_slice(&m.edges.data);
        ds.domain.data[i * 6..(i + 1) * 6].copy_from_slice(&r.domain.to_tensor().data);
        ds.frames.push(FrameInfo { run: r.label(), scenario: r.scenario.clone(), seed: r.seed, frame: f });
    }
    Ok(ds)
}

/// Replace the boundary target by where interpolation is safer than `net`'s residual: per HR
/// pixel, with `D = HR − U` and the residual `R` (both in the nets' frame), the gain
/// `g* = clamp(⟨D, R⟩ / |R|², 0, 1)` that brings `U + g·R` closest to HR, and the target
/// `1 − g*` (soft, for BCE): 0 where the residual is right, 1 where it points the wrong way.
/// The grid's border is judged like every other pixel: GeometryNet is trained on whole frames,
/// so its residual there is learned from real borders and `upscale` no longer pins the border
/// by default. Frames in batches of 32.
pub fn benefit_boundary(ds: &mut Dataset, ops: &dyn Ops, net: &GeometryNet) -> Result<()> {
    let n = ds.lr.shape[0];
    let (hh, wh) = (ds.hr.shape[2], ds.hr.shape[3]);
    let px = hh * wh;
    for n0 in (0..n).step_by(32) {
        let cnt = 32.min(n - n0);
        let (u, r) = net.forward(ops, &ds.lr.slice_batch(n0, cnt))?;
        for k in 0..cnt {
            let f = n0 + k;
            let hr = &ds.hr.data[f * 3 * px..(f + 1) * 3 * px];
            let (u, r) = (&u.data[k * 3 * px..(k + 1) * 3 * px], &r.data[k * 3 * px..(k + 1) * 3 * px]);
            let dst = &mut ds.boundary.data[f * px..(f + 1) * px];
            for (p, d) in dst.iter_mut().enumerate() {
                let (mut dr, mut rr) = (0.0f64, 0.0f64);
                for c in 0..3 {
                    let i = c * px + p;
                    dr += (hr[i] - u[i]) as f64 * r[i] as f64;
                    rr += r[i] as f64 * r[i] as f64;
                }
                let g = if rr > 0.0 { (dr / rr).clamp(0.0, 1.0) } else { 1.0 };
                *d = (1.0 - g) as f32;
            }
        }
    }
    ds.boundary_source = format!("benefit of the residual of {}", net.trunk.config);
    Ok(())
}

/// Replace the HR target by what `teacher` composes from each LR frame at η = 0 (Eq 12,
/// before the outline floor): `U + (1 − Γb) ⊙ R`, with R the mean of its GeometryNets and, with
/// `mirrors`, R and Γb averaged over the grid's four mirror views, as `upscale` runs it
/// ([`crate::sr::upscale::views_averaged`]). A GeometryNet trained on these targets learns in
/// one pass what the bundle computes in (GeometryNets + BoundaryNet) × views: distillation.
/// Frames in batches of 16, the teacher at fp32; `tick(frames done)` after each batch.
pub fn distil_targets(
    ds: &mut Dataset,
    ops: &dyn Ops,
    teacher: &AnisoCb,
    mirrors: bool,
    tick: &mut dyn FnMut(usize),
) -> Result<()> {
    if teacher.input_frame() != ds.input_frame {
        return Err(Error::config(format!(
            "the teacher's nets take {} input, the data set is in {}: build the data set with \
             --input-frame {}",
            teacher.input_frame().name(),
            ds.input_frame.name(),
            teacher.input_frame().name()
        )));
    }
    if teacher.scale() != ds.upscale {
        return Err(Error::config(format!(
            "the teacher upscales ×{}, the data set ×{}",
            teacher.scale(),
            ds.upscale
        )));
    }
    let n = ds.lr.shape[0];
    let px3 = ds.hr.len() / n.max(1);
    let nets = teacher.packed();
    for n0 in (0..n).step_by(16) {
        let cnt = 16.min(n - n0);
        let o = views_averaged(ops, &nets, &ds.lr.slice_batch(n0, cnt), mirrors, false)?;
        let t = compose(&o.interpolated, &o.residual, Some(&o.boundary), None, 0.0)?;
        ds.hr.data[n0 * px3..(n0 + cnt) * px3].copy_from_slice(&t.data);
        tick(n0 + cnt);
    }
    ds.hr_source = format!(
        "distilled: U + (1 - boundary) * residual of a bundle of {} GeometryNet(s) ({}), {}",
        1 + teacher.more_geometry.len(),
        teacher.geometry.trunk.config,
        if mirrors { "averaged over the 4 mirror views" } else { "one view" }
    );
    Ok(())
}

/// Replace the edge target (EnhanceNet's) by where the HR truth folds: per HR pixel, the
/// local amplitude `a` of the truth's detail beyond the LR grid (along the normal, over a
/// (2r+1)² window: [`detail_amplitude`], as the wrinkle-energy loss measures it), divided by
/// its `quantile` over the whole data set and clamped to [0, 1] (soft targets for BCE). η then
/// deepens the residual where EnhanceNet expects folds (Eq 12), not on the 0.5 % of pixels
/// Canny marks, where a net trained on them predicts almost nothing.
pub fn wrinkle_energy_edges(ds: &mut Dataset, p: DetailEnergy, quantile: f32) -> Result<()> {
    if !(quantile > 0.0 && quantile <= 1.0) {
        return Err(Error::config(format!(
            "wrinkle-energy edges: quantile must be in (0, 1], got {quantile}"
        )));
    }
    let (hl, wl) = (ds.lr.shape[2], ds.lr.shape[3]);
    // Building a target from the data set, not a net op: the CPU function, not the op table.
    let a = detail_amplitude(&ds.hr, hl, wl, p);
    let mut sorted = a.data.clone();
    sorted.sort_by(f32::total_cmp);
    let at = ((sorted.len() as f32 * quantile) as usize).min(sorted.len().saturating_sub(1));
    // a = √(E + ε²) ≥ ε: a quantile near ε is no detail at all.
    let scale = sorted.get(at).copied().filter(|v| *v > 10.0 * p.eps).ok_or_else(|| {
        Error::numeric("wrinkle-energy edges: the truth has no detail beyond the LR grid".to_string())
    })?;
    for (e, v) in ds.edges.data.iter_mut().zip(&a.data) {
        *e = (v / scale).clamp(0.0, 1.0);
    }
    ds.edges_source = format!(
        "wrinkle energy of the HR truth: local amplitude (radius {} px) / its {:.0} % quantile {scale:.3e}, clamped to 1",
        p.radius,
        100.0 * quantile
    );
    Ok(())
}

impl Dataset {
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// `frames.json`: one object per frame, one per line.
    pub fn frames_json(&self) -> String {
        let rows = self
            .frames
            .iter()
            .map(|f| {
                Object::new()
                    .str("run", &f.run)
                    .str("scenario", &f.scenario)
                    .val("seed", f.seed.map(Value::num))
                    .num("frame", f.frame)
                    .into()
            })
            .collect();
        Value::Arr(rows).to_json_with(Layout::Indented) + "\n"
    }

    /// `params.json`: the map parameters, the upscale factor and the held-out names.
    pub fn params_json(&self) -> String {
        let (b, c) = (&self.params.boundary, &self.params.canny);
        let hold = self.holdout.iter().map(|h| Value::from(h.as_str())).collect::<Vec<_>>();
        let o = Object::new()
            .num("gamma", b.gamma)
            .num("lambda", b.lambda)
            .num("radius_factor", b.radius_factor)
            .num("canny_sigma", c.sigma)
            .num("canny_low", c.low)
            .num("canny_high", c.high)
            .num("upscale", self.upscale)
            .str("input_frame", self.input_frame.name())
            .str("boundary", &self.boundary_source)
            .str("edges", &self.edges_source)
            .str("hr", &self.hr_source)
            .val("holdout", hold);
        Value::from(o).to_json_with(Layout::Indented) + "\n"
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
    use crate::nn::map_net::MapNet;
    use crate::nn::{NetConfig, NetKind};
    use crate::ops::Cpu;

    /// A tiny GeometryNet whose residual is the constant `bias` per channel.
    fn constant_residual(bias: [f32; 3]) -> GeometryNet {
        let mut net = GeometryNet::new(NetConfig::tiny(), 1);
        let last = net.trunk.tail.last_mut().unwrap();
        last.weight.data.iter_mut().for_each(|w| *w = 0.0);
        last.bias.data.copy_from_slice(&bias);
        net
    }

    fn dataset_with_hr(net: &GeometryNet, sign: f32) -> Dataset {
        let (n, h, w) = (2, 5, 6);
        let lr = Tensor {
            shape: [n, 3, h, w].into(),
            data: (0..n * 3 * h * w).map(|i| (i as f32 * 0.37).sin()).collect(),
        };
        let (u, r) = net.forward(&Cpu, &lr).unwrap();
        let mut hr = u.clone();
        for (x, r) in hr.data.iter_mut().zip(&r.data) {
            *x += sign * r;
        }
        let map = Tensor::zeros(&[n, 1, 2 * h, 2 * w]);
        Dataset {
            lr,
            hr,
            boundary: map.clone(),
            edges: map,
            domain: Tensor::zeros(&[n, 2, 3]),
            frames: Vec::new(),
            params: MapParams::default(),
            input_frame: InputFrame::Cloth,
            boundary_source: String::new(),
            edges_source: String::new(),
            hr_source: String::new(),
            upscale: 2,
            holdout: Vec::new(),
        }
    }

    #[test]
    fn benefit_boundary_is_zero_where_the_residual_is_right_and_one_where_it_is_wrong() {
        let net = constant_residual([0.01, -0.02, 0.005]);
        for (sign, inside) in [(1.0f32, 0.0f32), (-1.0, 1.0), (0.5, 0.5)] {
            let mut ds = dataset_with_hr(&net, sign);
            benefit_boundary(&mut ds, &Cpu, &net).unwrap();
            // The border too: it is judged like every other pixel.
            for (p, &v) in ds.boundary.data.iter().enumerate() {
                assert!((v - inside).abs() < 1e-4, "sign {sign}, pixel {p}: {v} vs {inside}");
            }
        }
    }

    /// A cloth-frame bundle of tiny random nets (two GeometryNets), BoundaryNet `boundary` if given.
    fn teacher(boundary: Option<f32>) -> AnisoCb {
        let config = NetConfig { input_frame: InputFrame::Cloth, ..NetConfig::tiny() };
        let mut b = AnisoCb::new(config, 3);
        b.more_geometry.push(GeometryNet::new(config, 4));
        if let Some(z) = boundary {
            b.boundary = MapNet::constant(NetKind::Boundary, config, z).unwrap();
        }
        b
    }

    #[test]
    fn distilled_targets_are_the_teachers_gated_mean_residual() {
        let t = teacher(Some(-0.7));
        let mut ds = dataset_with_hr(&constant_residual([0.0; 3]), 1.0);
        distil_targets(&mut ds, &Cpu, &t, false, &mut |_| {}).unwrap();
        let (u, r1) = t.geometry.forward(&Cpu, &ds.lr).unwrap();
        let (_, r2) = t.more_geometry[0].forward(&Cpu, &ds.lr).unwrap();
        let keep = 1.0 - 1.0 / (1.0 + 0.7f32.exp());
        for i in 0..u.len() {
            let want = u.data[i] + keep * 0.5 * (r1.data[i] + r2.data[i]);
            assert!((ds.hr.data[i] - want).abs() < 1e-6, "pixel {i}: {} vs {want}", ds.hr.data[i]);
        }
        assert!(ds.hr_source.starts_with("distilled"), "{}", ds.hr_source);
        // A teacher in another input frame is refused.
        let mut domain = dataset_with_hr(&constant_residual([0.0; 3]), 1.0);
        domain.input_frame = InputFrame::Domain;
        assert!(distil_targets(&mut domain, &Cpu, &t, false, &mut |_| {}).is_err());
    }

    /// The mirror-averaged teacher does not depend on which way the grid runs: the target of a
    /// mirrored frame is the mirrored target (what one pass of a student is trained to learn).
    #[test]
    fn mirror_averaged_targets_of_a_mirrored_frame_are_the_mirrored_targets() {
        use crate::geom::cloth_frame::mirror_net_images;
        let t = teacher(None);
        let mut ds = dataset_with_hr(&constant_residual([0.0; 3]), 1.0);
        let lr = ds.lr.clone();
        distil_targets(&mut ds, &Cpu, &t, true, &mut |_| {}).unwrap();
        for (rows, cols) in [(true, false), (false, true), (true, true)] {
            let mut m = dataset_with_hr(&constant_residual([0.0; 3]), 1.0);
            m.lr = mirror_net_images(&lr, rows, cols, InputFrame::Cloth, true);
            distil_targets(&mut m, &Cpu, &t, true, &mut |_| {}).unwrap();
            let want = mirror_net_images(&ds.hr, rows, cols, InputFrame::Cloth, true);
            let worst = m.hr.data.iter().zip(&want.data).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
            assert!(worst < 1e-5, "mirror ({rows}, {cols}): off by {worst}");
        }
        // One view alone is not mirror-symmetric (else the test above proves nothing).
        let mut one = dataset_with_hr(&constant_residual([0.0; 3]), 1.0);
        let mut flipped = dataset_with_hr(&constant_residual([0.0; 3]), 1.0);
        flipped.lr = mirror_net_images(&lr, true, false, InputFrame::Cloth, true);
        distil_targets(&mut one, &Cpu, &t, false, &mut |_| {}).unwrap();
        distil_targets(&mut flipped, &Cpu, &t, false, &mut |_| {}).unwrap();
        let want = mirror_net_images(&one.hr, true, false, InputFrame::Cloth, true);
        let worst = flipped.hr.data.iter().zip(&want.data).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        assert!(worst > 1e-4, "one view is already mirror-symmetric ({worst})");
    }

    /// A 16×16 HR sheet (8×8 LR) with folds of a 4-pixel wavelength (finer than the LR grid)
    /// across its left half, flat on the right.
    fn half_folded() -> Dataset {
        let (h, w) = (16, 16);
        let mut hr = Tensor::zeros(&[1, 3, h, w]);
        for y in 0..h {
            for x in 0..w {
                let p = y * w + x;
                hr.data[p] = x as f32 / 15.0;
                hr.data[h * w + p] = y as f32 / 15.0;
                hr.data[2 * h * w + p] =
                    if x < 8 { 0.01 * (x as f32 * std::f32::consts::FRAC_PI_2).sin() } else { 0.0 };
            }
        }
        let map = Tensor::zeros(&[1, 1, h, w]);
        let mut ds = dataset_with_hr(&constant_residual([0.0; 3]), 1.0);
        ds.lr = Tensor::zeros(&[1, 3, 8, 8]);
        ds.hr = hr;
        (ds.boundary, ds.edges) = (map.clone(), map);
        ds
    }

    #[test]
    fn wrinkle_energy_edges_mark_where_the_truth_folds() {
        let mut ds = half_folded();
        wrinkle_energy_edges(&mut ds, DetailEnergy::default(), 0.9).unwrap();
        let e = &ds.edges.data;
        assert!(e.iter().all(|v| (0.0..=1.0).contains(v)), "targets outside [0, 1]");
        let mean = |xs: std::ops::Range<usize>| {
            let v: Vec<f32> =
                (4..12).flat_map(|y| xs.clone().map(move |x| y * 16 + x)).map(|p| e[p]).collect();
            v.iter().sum::<f32>() / v.len() as f32
        };
        let (folded, flat) = (mean(1..5), mean(12..15));
        assert!(folded > 0.7 && flat < 0.2, "folded half {folded}, flat half {flat}");
        assert!(ds.edges_source.contains("wrinkle energy"), "{}", ds.edges_source);
        // A truth without any detail beyond the LR grid has nothing to mark.
        let mut flat_ds = half_folded();
        for z in &mut flat_ds.hr.data[2 * 256..] {
            *z = 0.0;
        }
        assert!(wrinkle_energy_edges(&mut flat_ds, DetailEnergy::default(), 0.9).is_err());
        assert!(wrinkle_energy_edges(&mut half_folded(), DetailEnergy::default(), 0.0).is_err());
    }
}
