//! "Tracking" (DESIGN.md, training data): a high-resolution run is softly attached to its
//! low-resolution twin interpolated at each HR vertex's rest (u, v), so the pair differs by
//! detail, not by chaos. The attachment is a zero-length XPBD spring of stiffness
//! `m · strength` per vertex (`strength` in 1/s², the square of the attachment's natural
//! angular frequency), so it is independent of the resolution.

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
    pub from: &'a [[f32; 3]],
    pub to: &'a [[f32; 3]],
    /// Attachment strength (1/s²); 0 = off.
    pub strength: f32,
}
