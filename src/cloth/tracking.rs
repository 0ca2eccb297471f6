//! "Tracking" (docs/architecture.md, "Training data and tracking"): a high-resolution run is softly attached to its
//! low-resolution twin, so the pair differs by detail, not by chaos.
//!
//! - [`TrackingMode::Coarse`] (default): one constraint per LR node on a weighted average of
//!   the HR vertices around it ([`Restriction`]), `C_I = Σ_k w_Ik x_k − t_I` with `t_I` the same
//!   average of the LR surface, projected as a zero-length XPBD spring of stiffness
//!   `m_I · strength` (`m_I` the node's share of the cloth's mass). Only the part of the HR
//!   motion the LR grid can represent is held; folds finer than the LR grid form freely.
//! - [`TrackingMode::Vertex`]: every HR vertex is pulled toward the LR surface at its rest
//!   (u, v), stiffness `m · strength`. It also flattens the HR run's own fine folds (a 1 cm
//!   fold at 1000 1/s² feels about g pulling it flat), which is why it is no longer the default.
//!
//! `strength` is in 1/s², the square of the attachment's natural angular frequency, so it is
//! independent of the resolution.

use crate::geom::mesh::{rest_uv, GridMesh};

/// Bilinear interpolation of the `lr` grid at the rest (u, v) of every vertex of a `w × h`
/// grid (corners aligned); returns `w·h` target positions (m).
pub fn bilinear_targets(lr: &GridMesh, w: usize, h: usize) -> Vec<[f32; 3]> {
    let mut out = Vec::with_capacity(w * h);
    for j in 0..h {
        for i in 0..w {
            let (u, v) = rest_uv(i, j, w, h);
            out.push(sample(lr, u, v));
        }
    }
    out
}

/// Bilinear sample of a grid at rest parameter (u, v) ∈ [0,1]².
pub fn sample(g: &GridMesh, u: f32, v: f32) -> [f32; 3] {
    let fx = u * (g.w.max(1) - 1) as f32;
    let fy = v * (g.h.max(1) - 1) as f32;
    let i0 = (fx.floor() as usize).min(g.w.saturating_sub(2));
    let j0 = (fy.floor() as usize).min(g.h.saturating_sub(2));
    let i1 = (i0 + 1).min(g.w - 1);
    let j1 = (j0 + 1).min(g.h - 1);
    let (a, b) = (fx - i0 as f32, fy - j0 as f32);
    let p00 = g.pos[g.idx(i0, j0)];
    let p10 = g.pos[g.idx(i1, j0)];
    let p01 = g.pos[g.idx(i0, j1)];
    let p11 = g.pos[g.idx(i1, j1)];
    std::array::from_fn(|k| {
        (1.0 - b) * ((1.0 - a) * p00[k] + a * p10[k]) + b * ((1.0 - a) * p01[k] + a * p11[k])
    })
}

/// Targets for one frame step: positions at the start and end of the frame; a substep at
/// fraction `s ∈ (0, 1]` of the frame uses their linear blend.
pub struct TrackTargets<'a> {
    /// One target per HR vertex (`coarse` = None) or per LR node of `coarse` (m).
    pub from: &'a [[f32; 3]],
    pub to: &'a [[f32; 3]],
    /// Attachment strength (1/s²); 0 = off.
    pub strength: f32,
    /// Damping of the coarse constraints as a fraction of critical (1 = critically damped
    /// attachment; 0 = none, the training runs'): XPBD constraint damping (Macklin et al. 2016,
    /// Eq 26) on the constraint's velocity relative to its moving target.
    pub damping: f32,
    pub coarse: Option<&'a CoarseTrack>,
    /// Where the cloth's pins go instead of their [`super::kinematics::Kinematics`]: pin `k`
    /// moves linearly from `from[k]` to `to[k]` over the frame (m). The physics pass's pins
    /// follow the shot; the training runs' follow their scenario (None).
    pub pins: Option<PinPath<'a>>,
}

/// Start and end positions of every pin over one frame (m), in the cloth's pin order.
#[derive(Clone, Copy, Debug)]
pub struct PinPath<'a> {
    pub from: &'a [[f32; 3]],
    pub to: &'a [[f32; 3]],
}

/// How a high-resolution run is tied to its low-resolution twin.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TrackingMode {
    /// Only the HR cloth's coarse view follows the LR run: one averaged XPBD constraint per LR
    /// node ([`Restriction`]), so folds finer than the LR grid form freely (TRACKS, Bergou et
    /// al. 2007; Rémillard & Kry 2013). The default.
    Coarse,
    /// Every HR vertex is pulled toward the LR surface at its rest (u, v): the HR run keeps the
    /// LR run's shape and loses its own fine folds (the training truth before coarse tracking).
    Vertex,
}

impl TrackingMode {
    pub fn name(self) -> &'static str {
        match self {
            TrackingMode::Coarse => "coarse",
            TrackingMode::Vertex => "vertex",
        }
    }

    pub fn from_name(s: &str) -> crate::error::Result<TrackingMode> {
        match s {
            "coarse" => Ok(TrackingMode::Coarse),
            "vertex" => Ok(TrackingMode::Vertex),
            _ => Err(crate::error::Error::config(format!(
                "unknown tracking mode '{s}'; choose coarse (LR-scale averages, folds free) or vertex (every HR vertex)"
            ))),
        }
    }
}

/// The restriction of an HR grid to the nodes of an LR grid over the same rest rectangle
/// (corners aligned): node I's coarse position is `Σ_k w_Ik x_k`, with `w_Ik` the bilinear
/// tent of node I (1 at the node, 0 one LR cell away, in rest (u, v)) at HR vertex k,
/// normalised to sum 1 (the transpose of bilinear prolongation, row-normalised).
///
/// Why this filter: its response to a fold of wavelength λ is sinc²(Δ/λ) for the LR spacing Δ,
/// 0 at λ = Δ (a fold two HR cells wide) and 0.41 at the LR grid's Nyquist wavelength 2Δ, 0.81
/// at 4Δ: the constraint holds the shapes the LR grid can carry and barely sees the folds it
/// cannot.
#[derive(Clone, Debug)]
pub struct Restriction {
    /// LR grid (vertices) and HR grid (vertices).
    pub lr: (usize, usize),
    pub hr: (usize, usize),
    /// CSR: node I = `j·lr_w + i` averages HR vertices `idx[ptr[I]..ptr[I + 1]]` with weights
    /// `w[..]` (row-major order within the node).
    ptr: Vec<usize>,
    idx: Vec<u32>,
    w: Vec<f32>,
}

impl Restriction {
    /// The tents of an `lr_w × lr_h` grid over an `hr_w × hr_h` grid (both ≥ 2 per side).
    pub fn new(lr_w: usize, lr_h: usize, hr_w: usize, hr_h: usize) -> Restriction {
        let tent = |x: f32| (1.0 - x.abs()).max(0.0);
        let (du, dv) = (1.0 / (lr_w.max(2) - 1) as f32, 1.0 / (lr_h.max(2) - 1) as f32);
        let (mut ptr, mut idx, mut w) = (vec![0usize], Vec::new(), Vec::new());
        for jl in 0..lr_h {
            for il in 0..lr_w {
                let (ui, vi) = rest_uv(il, jl, lr_w, lr_h);
                let start = w.len();
                for j in 0..hr_h {
                    let wv = tent((rest_uv(0, j, hr_w, hr_h).1 - vi) / dv);
                    if wv == 0.0 {
                        continue;
                    }
                    for i in 0..hr_w {
                        let wt = wv * tent((rest_uv(i, 0, hr_w, hr_h).0 - ui) / du);
                        if wt > 0.0 {
                            idx.push((j * hr_w + i) as u32);
                            w.push(wt);
                        }
                    }
                }
                let sum: f32 = w[start..].iter().sum();
                w[start..].iter_mut().for_each(|x| *x /= sum);
                ptr.push(w.len());
            }
        }
        Restriction { lr: (lr_w, lr_h), hr: (hr_w, hr_h), ptr, idx, w }
    }

    /// The restriction of a mesh's linear subdivision `sub` to its `lr` vertices (any mesh,
    /// issue 45): node I averages the HR vertices with the weights the subdivision gives I in
    /// them (1 at I, ½ at the midpoint of each of its edges, ¼ at the centre of each of its
    /// quads), normalised: the transpose of the prolongation, row-normalised, as on a grid.
    /// Its `lr` and `hr` are `(vertices, 1)`; [`Restriction::targets`] is for grids, a mesh's
    /// targets are `apply(sub.apply(lr))`.
    pub fn of_subdivision(sub: &crate::geom::surface::Subdivision, lr: usize) -> Restriction {
        let mut rows: Vec<Vec<(u32, f32)>> = vec![Vec::new(); lr];
        for (k, w) in sub.weights().into_iter().enumerate() {
            for (i, wi) in w {
                rows[i as usize].push((k as u32, wi));
            }
        }
        let (mut ptr, mut idx, mut w) = (vec![0usize], Vec::new(), Vec::new());
        for row in rows {
            let sum: f32 = row.iter().map(|r| r.1).sum();
            for (k, wk) in row {
                idx.push(k);
                w.push(if sum > 0.0 { wk / sum } else { 0.0 });
            }
            ptr.push(idx.len());
        }
        Restriction { lr: (lr, 1), hr: (sub.hr_vertices(), 1), ptr, idx, w }
    }

    /// Number of LR nodes.
    pub fn nodes(&self) -> usize {
        self.ptr.len() - 1
    }

    /// Node `n`'s (HR vertex, weight) pairs.
    pub fn node(&self, n: usize) -> impl Iterator<Item = (usize, f32)> + '_ {
        let r = self.ptr[n]..self.ptr[n + 1];
        self.idx[r.clone()].iter().map(|&k| k as usize).zip(self.w[r].iter().copied())
    }

    /// The coarse positions `Σ_k w_Ik x_k` of HR positions `x` (one per LR node, m).
    pub fn apply(&self, x: &[[f32; 3]]) -> Vec<[f32; 3]> {
        (0..self.nodes())
            .map(|n| {
                let mut s = [0.0f32; 3];
                for (k, wk) in self.node(n) {
                    for c in 0..3 {
                        s[c] += wk * x[k][c];
                    }
                }
                s
            })
            .collect()
    }

    /// Coarse targets of one LR frame: the same restriction of the LR surface sampled
    /// bilinearly at the HR vertices' rest (u, v), so a flat or evenly curved HR cloth lying on
    /// the LR surface meets its targets exactly, whatever the filter's own smoothing.
    pub fn targets(&self, lr: &GridMesh) -> Vec<[f32; 3]> {
        self.apply(&bilinear_targets(lr, self.hr.0, self.hr.1))
    }
}

/// A [`Restriction`] with what the solver needs per node: `Σ_k w_k² / m_k` (1/kg) and the
/// node's share of the cloth's mass (kg), each HR vertex's mass split over the nodes whose
/// tents cover it in proportion to their weights. Pinned vertices (inverse mass 0) do not move
/// and carry no share.
#[derive(Clone, Debug)]
pub struct CoarseTrack {
    pub restriction: Restriction,
    pub w2_inv_mass: Vec<f32>,
    pub node_mass: Vec<f32>,
}

impl CoarseTrack {
    pub fn new(restriction: Restriction, inv_mass: &[f32]) -> CoarseTrack {
        let mut cover = vec![0.0f32; inv_mass.len()];
        for n in 0..restriction.nodes() {
            for (k, wk) in restriction.node(n) {
                cover[k] += wk;
            }
        }
        let (mut w2_inv_mass, mut node_mass) = (Vec::new(), Vec::new());
        for n in 0..restriction.nodes() {
            let (mut s, mut m) = (0.0f32, 0.0f32);
            for (k, wk) in restriction.node(n) {
                if inv_mass[k] > 0.0 {
                    s += wk * wk * inv_mass[k];
                    m += wk / cover[k] / inv_mass[k];
                }
            }
            w2_inv_mass.push(s);
            node_mass.push(m);
        }
        CoarseTrack { restriction, w2_inv_mass, node_mass }
    }
}
