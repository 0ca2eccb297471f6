//! Texture coordinates of the HR grid.

use crate::tensor::Tensor;

/// Texture coordinates of the HR grid (`r·w × r·h`, row-major) from the LR grid's `uv`
/// (`w × h`): bilinear with corners aligned, so the border, the corners and every LR vertex's
/// UV stay exactly where they were (no seam or texture edge moves), and a uniformly unwrapped
/// sheet gets the uniform UVs its HR truth has. Not a cubic: Keys' bicubic (a = −0.75) does
/// not reproduce a linear function (12 → 24 vertices puts u = 0.4825 where the uniform layout
/// has 0.4783, 0.4 % of the texture's width), and Catmull-Rom does only away from the clamped
/// border; either would squeeze and stretch the texture in a pattern tied to the grid.
pub fn upscale_uv(uv: &[[f32; 2]], w: usize, h: usize, r: usize) -> Vec<[f32; 2]> {
    let mut t = Tensor::zeros(&[1, 2, h, w]);
    for (v, p) in uv.iter().enumerate() {
        t.data[v] = p[0];
        t.data[h * w + v] = p[1];
    }
    // UV post-processing, not a net op: the scalar function, not the op table.
    let up = crate::ops::resample::resize_ref(&t, r * h, r * w, crate::ops::Interp::Bilinear);
    let px = r * r * h * w;
    (0..px).map(|v| [up.data[v], up.data[px + v]]).collect()
}
