//! Metrics of a predicted HR mesh sequence against the HR ground truth, per frame and
//! averaged. Both sides must be grids of the same size (the HR grid); vertex `v` of one is
//! compared with vertex `v` of the other. Lengths are in the meshes' units (metres); sums run
//! in f64. Notation: `p_v` predicted, `g_v` ground-truth position, `N` vertices, `T` frames.

pub use super::wrinkle::{
    grid_normals, lr_round_trip, wrinkle_detail, wrinkle_stats, WrinkleStats, WRINKLE_RING,
};
use crate::error::{Error, Result};
use crate::geom::mesh::{closed_loop_length, ring_vertices, vertex_normals};
use crate::geom::vec3::{cross, dot, norm, sub};
use crate::geom::GridMesh;
use crate::io::json::{Object, Value};
use crate::tensor::Tensor;
use rayon::prelude::*;

pub(crate) fn same_grid(a: &GridMesh, b: &GridMesh) -> Result<()> {
    if a.w != b.w || a.h != b.h || a.pos.len() != b.pos.len() {
        return Err(Error::shape(format!("metrics: grid {}x{} vs ground truth {}x{}", a.w, a.h, b.w, b.h)));
    }
    if a.w < 2 || a.h < 2 {
        return Err(Error::shape(format!("metrics: grid {}x{} has no triangles", a.w, a.h)));
    }
    Ok(())
}

#[inline]
fn d2(a: [f32; 3], b: [f32; 3]) -> f64 {
    (0..3).map(|k| (a[k] as f64 - b[k] as f64).powi(2)).sum()
}

/// Per-vertex error `e_v = |p_v − g_v|` (for heat maps).
pub fn vertex_errors(pred: &GridMesh, gt: &GridMesh) -> Result<Vec<f32>> {
    same_grid(pred, gt)?;
    Ok(pred.pos.iter().zip(&gt.pos).map(|(&p, &g)| d2(p, g).sqrt() as f32).collect())
}

/// Vertex RMSE: `√( (1/N) Σ_v |p_v − g_v|² )`.
pub fn vertex_rmse(pred: &GridMesh, gt: &GridMesh) -> Result<f32> {
    same_grid(pred, gt)?;
    let s: f64 = pred.pos.iter().zip(&gt.pos).map(|(&p, &g)| d2(p, g)).sum();
    Ok((s / pred.pos.len() as f64).sqrt() as f32)
}

/// The topological border of a `w × h` grid as a vertex mask (index `j·w + i`).
pub fn border_mask(w: usize, h: usize) -> Vec<bool> {
    border_band(w, h, 1)
}

/// Vertices within `rows` rows (or columns) of the grid's border: `rows = 1` is the border
/// itself ([`border_mask`]), 2 adds the next ring, where shrinkage and fold errors show first.
pub fn border_band(w: usize, h: usize, rows: usize) -> Vec<bool> {
    (0..w * h).map(|v| v % w < rows || v / w < rows || w - v % w <= rows || h - v / w <= rows).collect()
}

/// A boundary map ((H, W), (1, H, W) or (1, 1, H, W), pixel (j, i) = vertex (i, j), e.g. the
/// anisotropic ground-truth map of Eq 4–9) → vertex mask `map > threshold`.
pub fn mask_from_map(map: &Tensor, w: usize, h: usize, threshold: f32) -> Result<Vec<bool>> {
    let s = &map.shape;
    let ok = s.len() >= 2 && s[s.len() - 2] == h && s[s.len() - 1] == w && map.len() == w * h;
    if !ok {
        return Err(Error::shape(format!("boundary map {s:?} does not fit a {w}x{h} grid")));
    }
    Ok(map.data.iter().map(|&v| v > threshold).collect())
}

/// Boundary-vertex RMSE: `√( Σ_{v∈B} |p_v − g_v|² / |B| )` over the masked vertices `B`
/// (0 if `B` is empty).
pub fn masked_rmse(pred: &GridMesh, gt: &GridMesh, mask: &[bool]) -> Result<f32> {
    same_grid(pred, gt)?;
    if mask.len() != pred.pos.len() {
        return Err(Error::shape(format!("mask of {} for {} vertices", mask.len(), pred.pos.len())));
    }
    let (mut s, mut n) = (0.0f64, 0usize);
    for ((&m, &p), &g) in mask.iter().zip(&pred.pos).zip(&gt.pos) {
        if m {
            s += d2(p, g);
            n += 1;
        }
    }
    Ok(if n == 0 { 0.0 } else { (s / n as f64).sqrt() as f32 })
}

/// Balanced k-d tree over a point set (implicit: node = index range, split at its middle on
/// the range's widest axis). Built with `select_nth_unstable_by` and index tie-breaks, so the
/// layout is deterministic.
struct KdTree<'a> {
    pts: &'a [[f32; 3]],
    idx: Vec<usize>,
    /// Split axis of the node whose middle element sits at this position.
    axis: Vec<u8>,
}

const KD_LEAF: usize = 8;

impl<'a> KdTree<'a> {
    fn new(pts: &'a [[f32; 3]]) -> KdTree<'a> {
        let mut t = KdTree { pts, idx: (0..pts.len()).collect(), axis: vec![0; pts.len()] };
        let mut idx = std::mem::take(&mut t.idx);
        t.build(&mut idx, 0);
        t.idx = idx;
        t
    }

    fn build(&mut self, idx: &mut [usize], offset: usize) {
        if idx.len() <= KD_LEAF {
            return;
        }
        let pts = self.pts;
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for &i in idx.iter() {
            for k in 0..3 {
                lo[k] = lo[k].min(pts[i][k]);
                hi[k] = hi[k].max(pts[i][k]);
            }
        }
        let k =
            (0..3).max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b])).then(b.cmp(&a))).unwrap_or(0);
        let mid = idx.len() / 2;
        idx.select_nth_unstable_by(mid, |&a, &b| pts[a][k].total_cmp(&pts[b][k]).then(a.cmp(&b)));
        self.axis[offset + mid] = k as u8;
        let (left, rest) = idx.split_at_mut(mid);
        self.build(left, offset);
        self.build(&mut rest[1..], offset + mid + 1);
    }

    /// Squared distance from `q` to its nearest point, or any value ≤ `enough` as soon as one
    /// point that close is found (the early exit of the Hausdorff search). `hint` is a point
    /// index likely to be close (the same grid vertex), which bounds the search from the start.
    fn nearest_d2(&self, q: [f32; 3], enough: f64, hint: usize) -> f64 {
        let mut best = d2(q, self.pts[hint.min(self.pts.len() - 1)]);
        if best > enough {
            self.search(0, self.idx.len(), q, enough, &mut best);
        }
        best
    }

    /// Returns true once `best ≤ enough` (stop everything).
    fn search(&self, lo: usize, hi: usize, q: [f32; 3], enough: f64, best: &mut f64) -> bool {
        if hi - lo <= KD_LEAF {
            for &i in &self.idx[lo..hi] {
                *best = best.min(d2(q, self.pts[i]));
            }
            return *best <= enough;
        }
        let mid = lo + (hi - lo) / 2;
        let k = self.axis[mid] as usize;
        let p = self.pts[self.idx[mid]];
        *best = best.min(d2(q, p));
        if *best <= enough {
            return true;
        }
        let diff = q[k] as f64 - p[k] as f64;
        let (near, far) = if diff < 0.0 { ((lo, mid), (mid + 1, hi)) } else { ((mid + 1, hi), (lo, mid)) };
        if self.search(near.0, near.1, q, enough, best) {
            return true;
        }
        if diff * diff < *best {
            return self.search(far.0, far.1, q, enough, best);
        }
        false
    }
}

/// Directed vertex-to-vertex distance `max_{a∈A} min_{b∈B} |a − b|`, squared: nearest
/// neighbours through a uniform grid, with the early break of Taha & Hanbury (a point whose
/// nearest neighbour is closer than the running maximum cannot raise it). Exact.
fn directed_hausdorff(a: &[[f32; 3]], b: &[[f32; 3]]) -> f64 {
    let tree = KdTree::new(b);
    a.par_chunks(256)
        .enumerate()
        .map(|(ci, chunk)| {
            let mut cmax = 0.0f64;
            for (k, &p) in chunk.iter().enumerate() {
                cmax = cmax.max(tree.nearest_d2(p, cmax, ci * 256 + k));
            }
            cmax
        })
        .reduce(|| 0.0, f64::max)
}

/// Symmetric Hausdorff distance between the two vertex sets (vertex-to-vertex, so it
/// over-estimates the surface distance by at most about half an edge):
/// `max( max_a min_b |a − b|, max_b min_a |a − b| )`.
pub fn hausdorff(pred: &GridMesh, gt: &GridMesh) -> Result<f32> {
    same_grid(pred, gt)?;
    Ok(directed_hausdorff(&pred.pos, &gt.pos).max(directed_hausdorff(&gt.pos, &pred.pos)).sqrt() as f32)
}

/// Perimeter of the grid border: `Σ_k |b_{k+1} − b_k|` over the closed border ([`crate::geom::mesh::border_loop`]).
pub fn border_length(mesh: &GridMesh) -> f32 {
    closed_loop_length(ring_vertices(mesh.w, mesh.h, 0), |v| mesh.pos[v].map(f64::from)) as f32
}

/// Surface area: `Σ_t ½ |(b − a) × (c − a)|` over the grid's triangles.
pub fn surface_area(mesh: &GridMesh) -> f32 {
    let p = |v: usize| mesh.pos[v].map(|x| x as f64);
    let mut s = 0.0f64;
    for t in mesh.triangles() {
        let (a, b, c) = (p(t[0]), p(t[1]), p(t[2]));
        s += 0.5 * norm(cross(sub(b, a), sub(c, a)));
    }
    s as f32
}

/// Wrinkle fidelity: mean angle (degrees) between area-weighted vertex normals,
/// `(1/N) Σ_v ∠(n_v(p), n_v(g))`, the angle computed as `atan2(|a × b|, a · b)`.
pub fn normal_angle_deg(pred: &GridMesh, gt: &GridMesh) -> Result<f32> {
    same_grid(pred, gt)?;
    let (a, b) = (vertex_normals(pred), vertex_normals(gt));
    let s: f64 = a
        .iter()
        .zip(&b)
        .map(|(x, y)| {
            // atan2(|x × y|, x · y) = acos(x · y), accurate near 0° where acos is not.
            let (x, y) = (x.map(f64::from), y.map(f64::from));
            norm(cross(x, y)).atan2(dot(x, y)).to_degrees()
        })
        .sum();
    Ok((s / a.len() as f64) as f32)
}

/// Discrete mean curvature `H_v = |Σ_j (cot α_vj + cot β_vj)(p_j − p_v)| / (4 A_v)` (1/m;
/// Meyer et al. 2003, unsigned, with `A_v` one third of the adjacent triangles' area) at every
/// vertex; border vertices (no closed ring) get 0.
pub fn mean_curvature(mesh: &GridMesh) -> Vec<f32> {
    let p = crate::geom::laplacian::positions_f64(mesh);
    let n = p.len();
    let mut lap = vec![[0.0f64; 3]; n];
    let mut area = vec![0.0f64; n];
    for t in mesh.triangles() {
        let (a, b, c) = (p[t[0]], p[t[1]], p[t[2]]);
        let tri = 0.5 * norm(cross(sub(b, a), sub(c, a)));
        for k in 0..3 {
            // The angle at corner k weighs the opposite edge (i, j).
            let (o, i, j) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
            let cot = crate::geom::laplacian::cot_at(p[o], p[i], p[j]);
            for d in 0..3 {
                lap[i][d] += cot * (p[j][d] - p[i][d]);
                lap[j][d] += cot * (p[i][d] - p[j][d]);
            }
            area[t[k]] += tri / 3.0;
        }
    }
    (0..n)
        .map(|v| {
            if mesh.is_border(v % mesh.w, v / mesh.w) || area[v] <= 0.0 {
                return 0.0;
            }
            (norm(lap[v]) / (4.0 * area[v])) as f32
        })
        .collect()
}

/// Wrinkle fidelity, second form: mean absolute mean-curvature error over interior vertices
/// `I`, `(1/|I|) Σ_{v∈I} |H_v(p) − H_v(g)|` (1/m, see [`mean_curvature`]).
pub fn curvature_error(pred: &GridMesh, gt: &GridMesh) -> Result<f32> {
    same_grid(pred, gt)?;
    let (a, b) = (mean_curvature(pred), mean_curvature(gt));
    let (mut s, mut n) = (0.0f64, 0usize);
    for v in 0..a.len() {
        if !pred.is_border(v % pred.w, v / pred.w) {
            s += (a[v] as f64 - b[v] as f64).abs();
            n += 1;
        }
    }
    Ok(if n == 0 { 0.0 } else { (s / n as f64) as f32 })
}

/// Temporal flicker (STED-like velocity error). With per-frame velocities
/// `u_{t,v} = p_{t+1,v} − p_{t,v}` and `γ_{t,v} = g_{t+1,v} − g_{t,v}` (metres per frame):
/// per step `f_t = √( (1/N) Σ_v |u_{t,v} − γ_{t,v}|² )`, overall `√( (1/(T−1)) Σ_t f_t² )`.
/// A constant offset between prediction and truth flickers 0. Returns (per step, overall);
/// fewer than 2 frames give (empty, 0).
pub fn flicker(pred: &[GridMesh], gt: &[GridMesh]) -> Result<(Vec<f32>, f32)> {
    if pred.len() != gt.len() {
        return Err(Error::shape(format!(
            "flicker: {} predicted frames vs {} ground truth",
            pred.len(),
            gt.len()
        )));
    }
    for (p, g) in pred.iter().zip(gt) {
        same_grid(p, g)?;
    }
    let mut steps = Vec::with_capacity(pred.len().saturating_sub(1));
    let mut total = 0.0f64;
    for t in 0..pred.len().saturating_sub(1) {
        let mut s = 0.0f64;
        for v in 0..pred[t].pos.len() {
            for k in 0..3 {
                let u = pred[t + 1].pos[v][k] as f64 - pred[t].pos[v][k] as f64;
                let g = gt[t + 1].pos[v][k] as f64 - gt[t].pos[v][k] as f64;
                s += (u - g).powi(2);
            }
        }
        let ms = s / pred[t].pos.len() as f64;
        total += ms;
        steps.push(ms.sqrt() as f32);
    }
    let overall = if steps.is_empty() { 0.0 } else { (total / steps.len() as f64).sqrt() as f32 };
    Ok((steps, overall))
}

/// Lengths of the grid's row and column edges (row edges first, then column edges).
fn grid_edge_lengths(m: &GridMesh) -> Vec<f64> {
    let (w, h) = (m.w, m.h);
    let len = |a: usize, b: usize| {
        let d: [f64; 3] = std::array::from_fn(|k| m.pos[a][k] as f64 - m.pos[b][k] as f64);
        (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
    };
    let mut out = Vec::with_capacity(2 * w * h);
    for j in 0..h {
        for i in 0..w.saturating_sub(1) {
            out.push(len(j * w + i + 1, j * w + i));
        }
    }
    for j in 0..h.saturating_sub(1) {
        for i in 0..w {
            out.push(len((j + 1) * w + i, j * w + i));
        }
    }
    out
}

/// STED (Vasa & Skala 2011), on the grid's row and column edges, as two dimensionless numbers.
/// Spatial: per frame, the standard deviation over edges of the relative edge-length
/// deviation `(l_pred − l_gt)/l_gt` (a uniform scale costs nothing; uneven stretching, the
/// "swimming" a texture shows, does), averaged over frames. Temporal: with per-step relative
/// edge-length changes `δ = (l_{t+1} − l_t)/l_gt,t`, `√(mean over steps and edges of
/// (δ_pred − δ_gt)²)`: edges that lengthen and shorten from frame to frame where the truth's
/// do not (flicker of the surface itself, independent of where it is). Degenerate truth
/// edges (length ≤ 1e-9 m) are skipped.
pub fn sted(pred: &[GridMesh], gt: &[GridMesh]) -> Result<(f32, f32)> {
    if pred.len() != gt.len() || pred.is_empty() {
        return Err(Error::shape(format!(
            "sted: {} predicted frames vs {} ground truth",
            pred.len(),
            gt.len()
        )));
    }
    for (p, g) in pred.iter().zip(gt) {
        same_grid(p, g)?;
    }
    let lp: Vec<Vec<f64>> = pred.iter().map(grid_edge_lengths).collect();
    let lg: Vec<Vec<f64>> = gt.iter().map(grid_edge_lengths).collect();
    let mut spatial = 0.0f64;
    for (a, b) in lp.iter().zip(&lg) {
        let dev: Vec<f64> = a.iter().zip(b).filter(|(_, g)| **g > 1e-9).map(|(p, g)| (p - g) / g).collect();
        let n = dev.len().max(1) as f64;
        let mean = dev.iter().sum::<f64>() / n;
        spatial += (dev.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / n).sqrt();
    }
    spatial /= pred.len() as f64;
    let (mut s, mut n) = (0.0f64, 0usize);
    for t in 0..pred.len() - 1 {
        for e in 0..lg[t].len() {
            let g = lg[t][e];
            if g > 1e-9 {
                let dp = (lp[t + 1][e] - lp[t][e]) / g;
                let dg = (lg[t + 1][e] - lg[t][e]) / g;
                s += (dp - dg).powi(2);
                n += 1;
            }
        }
    }
    let temporal = if n == 0 { 0.0 } else { (s / n as f64).sqrt() };
    Ok((spatial as f32, temporal as f32))
}

/// The per-frame metrics of one predicted frame against its ground truth.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameMetrics {
    /// [`vertex_rmse`], metres.
    pub rmse: f32,
    /// [`masked_rmse`] over the boundary vertices, metres.
    pub boundary_rmse: f32,
    /// [`hausdorff`], metres.
    pub hausdorff: f32,
    /// `border_length(pred) / border_length(gt)` (1 = no shrinkage).
    pub boundary_length_ratio: f32,
    /// `surface_area(pred) / surface_area(gt)`.
    pub area_ratio: f32,
    /// [`normal_angle_deg`], degrees.
    pub normal_angle_deg: f32,
    /// [`curvature_error`], 1/m.
    pub curvature_err: f32,
}

impl FrameMetrics {
    /// Field names in the order of [`FrameMetrics::values`] (table headers, JSON keys).
    pub const NAMES: [&'static str; 7] = [
        "rmse",
        "boundary_rmse",
        "hausdorff",
        "boundary_length_ratio",
        "area_ratio",
        "normal_angle_deg",
        "curvature_err",
    ];

    pub fn values(&self) -> [f32; 7] {
        [
            self.rmse,
            self.boundary_rmse,
            self.hausdorff,
            self.boundary_length_ratio,
            self.area_ratio,
            self.normal_angle_deg,
            self.curvature_err,
        ]
    }

    fn from_values(v: [f32; 7]) -> FrameMetrics {
        FrameMetrics {
            rmse: v[0],
            boundary_rmse: v[1],
            hausdorff: v[2],
            boundary_length_ratio: v[3],
            area_ratio: v[4],
            normal_angle_deg: v[5],
            curvature_err: v[6],
        }
    }

    /// A JSON object with the [`FrameMetrics::NAMES`] keys (non-finite values as `null`).
    pub fn to_value(&self) -> Value {
        let o =
            Self::NAMES.iter().zip(self.values()).fold(Object::new(), |o, (k, v)| o.val(k, Value::finite(v)));
        o.into()
    }

    pub fn to_json(&self) -> String {
        self.to_value().to_json()
    }
}

/// Metrics of one frame; `boundary` is the vertex mask of [`masked_rmse`].
pub fn frame_metrics(pred: &GridMesh, gt: &GridMesh, boundary: &[bool]) -> Result<FrameMetrics> {
    same_grid(pred, gt)?;
    Ok(FrameMetrics {
        rmse: vertex_rmse(pred, gt)?,
        boundary_rmse: masked_rmse(pred, gt, boundary)?,
        hausdorff: hausdorff(pred, gt)?,
        boundary_length_ratio: border_length(pred) / border_length(gt).max(f32::MIN_POSITIVE),
        area_ratio: surface_area(pred) / surface_area(gt).max(f32::MIN_POSITIVE),
        normal_angle_deg: normal_angle_deg(pred, gt)?,
        curvature_err: curvature_error(pred, gt)?,
    })
}

/// Metrics of a whole sequence.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SequenceMetrics {
    pub per_frame: Vec<FrameMetrics>,
    /// Arithmetic mean over frames of each per-frame metric.
    pub mean: FrameMetrics,
    /// Per-frame maximum of each metric (for ratios: the value farthest from 1).
    pub worst: FrameMetrics,
    /// [`flicker`] per step (T − 1 values) and overall, metres per frame.
    pub flicker_per_step: Vec<f32>,
    pub flicker: f32,
    /// [`sted`]: spatial and temporal edge-length distortion (dimensionless).
    pub sted_spatial: f32,
    pub sted_temporal: f32,
    /// [`wrinkle_stats`]: set by callers that know the LR grid the method upscaled (`eval`);
    /// [`sequence_metrics`] leaves it `None`.
    pub wrinkle: Option<WrinkleStats>,
}

impl SequenceMetrics {
    /// Indices of the `k` frames with the largest vertex RMSE, worst first (ties: earlier frame).
    pub fn worst_frames(&self, k: usize) -> Vec<usize> {
        let mut idx: Vec<usize> = (0..self.per_frame.len()).collect();
        idx.sort_by(|&a, &b| self.per_frame[b].rmse.total_cmp(&self.per_frame[a].rmse).then(a.cmp(&b)));
        idx.truncate(k);
        idx
    }

    /// JSON: `{"mean": {...}, "worst": {...}, "flicker": x, "sted_spatial": x,
    /// "sted_temporal": x, ["wrinkle": {...},] "per_frame": [{...}, ...], "flicker_per_step": [...]}`
    /// (`wrinkle` only where it was computed).
    pub fn to_value(&self) -> Value {
        let mut o = Object::new()
            .val("mean", self.mean.to_value())
            .val("worst", self.worst.to_value())
            .val("flicker", Value::finite(self.flicker))
            .val("sted_spatial", Value::finite(self.sted_spatial))
            .val("sted_temporal", Value::finite(self.sted_temporal));
        if let Some(w) = &self.wrinkle {
            o = o.val("wrinkle", w.to_value());
        }
        o.val("per_frame", Value::Arr(self.per_frame.iter().map(FrameMetrics::to_value).collect()))
            .val(
                "flicker_per_step",
                Value::Arr(self.flicker_per_step.iter().map(|&v| Value::finite(v)).collect()),
            )
            .into()
    }

    pub fn to_json(&self) -> String {
        self.to_value().to_json()
    }
}

/// Metrics of a predicted sequence against the ground truth. `boundary` defaults to the
/// grid's topological border ([`border_mask`]); pass e.g. [`mask_from_map`] of the
/// anisotropic map for folded regions too.
pub fn sequence_metrics(
    pred: &[GridMesh],
    gt: &[GridMesh],
    boundary: Option<&[bool]>,
) -> Result<SequenceMetrics> {
    if pred.is_empty() || pred.len() != gt.len() {
        return Err(Error::shape(format!(
            "metrics: {} predicted frames vs {} ground truth",
            pred.len(),
            gt.len()
        )));
    }
    let default_mask;
    let mask = match boundary {
        Some(m) => m,
        None => {
            default_mask = border_mask(gt[0].w, gt[0].h);
            &default_mask
        }
    };
    let per_frame =
        pred.iter().zip(gt).map(|(p, g)| frame_metrics(p, g, mask)).collect::<Result<Vec<_>>>()?;
    let n = per_frame.len() as f64;
    let mut mean = [0.0f64; 7];
    let mut worst = [0.0f32; 7];
    for f in &per_frame {
        for (k, v) in f.values().into_iter().enumerate() {
            mean[k] += v as f64 / n;
            let is_ratio = k == 3 || k == 4;
            let far = if is_ratio {
                (v - 1.0).abs() > (worst[k] - 1.0).abs() || worst[k] == 0.0
            } else {
                v > worst[k]
            };
            if far {
                worst[k] = v;
            }
        }
    }
    let (flicker_per_step, flicker) = flicker(pred, gt)?;
    let (sted_spatial, sted_temporal) = sted(pred, gt)?;
    Ok(SequenceMetrics {
        per_frame,
        mean: FrameMetrics::from_values(mean.map(|v| v as f32)),
        worst: FrameMetrics::from_values(worst),
        flicker_per_step,
        flicker,
        sted_spatial,
        sted_temporal,
        wrinkle: None,
    })
}
