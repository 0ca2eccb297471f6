//! Geometry images (paper Eq 1, 2): pixel (row j, col i) holds vertex (i, j) with its
//! position normalised by a sequence-wide domain, `c = (p − bmin) / (bmax − bmin)` per axis
//! (x→R, y→G, z→B). Values stay f32 and may leave [0,1] slightly; they are clamped only when
//! written as an 8-bit picture.

use super::mesh::GridMesh;
use crate::error::{Error, Result};
use crate::ops::resample::resize;
use crate::ops::Interp;
use crate::tensor::Tensor;

/// The axis-aligned box (metres) that maps to [0,1]³.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Domain {
    pub bmin: [f32; 3],
    pub bmax: [f32; 3],
}

impl Domain {
    /// Bounding box of all frames, grown by `margin` (fraction of the largest extent) on every
    /// side; degenerate axes (a flat sheet) get the largest extent so no axis divides by ~0.
    pub fn enclosing(frames: &[GridMesh], margin: f32) -> Domain {
        let mut b = Bounds::default();
        for f in frames {
            b.add(f);
        }
        b.domain(margin)
    }

    /// The box [0, 1]³: geometry images in it hold positions in metres, unchanged (encoding and
    /// decoding are exact). Used where no sequence-wide box is wanted: a model in the cloth
    /// frame does not need one, and a frame's result then depends on that frame alone.
    pub const UNIT: Domain = Domain { bmin: [0.0; 3], bmax: [1.0; 3] };

    pub fn validate(&self) -> Result<()> {
        for k in 0..3 {
            if !(self.bmin[k].is_finite() && self.bmax[k].is_finite() && self.bmax[k] > self.bmin[k]) {
                return Err(Error::config(format!("domain axis {k} is empty or not finite: {self:?}")));
            }
            if !(self.bmax[k] - self.bmin[k]).is_finite() {
                return Err(Error::config(format!(
                    "the domain is not usable: axis {k} spans {:e} to {:e}, an extent beyond f32's \
                     range (±3.4e38) that no geometry image can be decoded with; the domain box \
                     must enclose the cloth in metres",
                    self.bmin[k], self.bmax[k]
                )));
            }
        }
        Ok(())
    }

    /// As a (2, 3) tensor [bmin; bmax], the form stored beside geometry images.
    pub fn to_tensor(&self) -> Tensor {
        let mut d = self.bmin.to_vec();
        d.extend_from_slice(&self.bmax);
        Tensor { shape: [2, 3].into(), data: d }
    }

    pub fn from_tensor(t: &Tensor) -> Result<Domain> {
        if t.shape != [2, 3] {
            return Err(Error::shape(format!("domain must have shape [2, 3], got {:?}", t.shape)));
        }
        let d = Domain { bmin: [t.data[0], t.data[1], t.data[2]], bmax: [t.data[3], t.data[4], t.data[5]] };
        d.validate()?;
        Ok(d)
    }

    #[inline]
    pub fn encode(&self, p: [f32; 3]) -> [f32; 3] {
        std::array::from_fn(|k| (p[k] - self.bmin[k]) / (self.bmax[k] - self.bmin[k]))
    }

    #[inline]
    pub fn decode(&self, c: [f32; 3]) -> [f32; 3] {
        std::array::from_fn(|k| self.bmin[k] + c[k] * (self.bmax[k] - self.bmin[k]))
    }
}

/// A running bounding box of frames (a shot read one frame at a time); see [`Domain::enclosing`].
#[derive(Clone, Copy, Debug)]
pub struct Bounds {
    pub lo: [f32; 3],
    pub hi: [f32; 3],
}

impl Default for Bounds {
    fn default() -> Self {
        Bounds { lo: [f32::INFINITY; 3], hi: [f32::NEG_INFINITY; 3] }
    }
}

impl Bounds {
    pub fn add(&mut self, f: &GridMesh) {
        let (a, b) = f.bounds();
        for k in 0..3 {
            self.lo[k] = self.lo[k].min(a[k]);
            self.hi[k] = self.hi[k].max(b[k]);
        }
    }

    /// The box grown by `margin` (fraction of the largest extent) on every side; degenerate
    /// axes (a flat sheet) get the largest extent so no axis divides by ~0.
    pub fn domain(&self, margin: f32) -> Domain {
        let (lo, hi) = (self.lo, self.hi);
        let ext = (0..3).map(|k| hi[k] - lo[k]).fold(0.0f32, f32::max).max(1e-6);
        let mut d = Domain { bmin: lo, bmax: hi };
        for k in 0..3 {
            let c = 0.5 * (lo[k] + hi[k]);
            let half = 0.5 * (hi[k] - lo[k]).max(ext * 0.5) + margin * ext;
            d.bmin[k] = c - half;
            d.bmax[k] = c + half;
        }
        d
    }
}

/// Eq 1: mesh → (3, H, W) image.
pub fn mesh_to_image(mesh: &GridMesh, domain: &Domain) -> Tensor {
    grid_to_image(mesh.w, mesh.h, &mesh.pos, domain)
}

/// Eq 1 for the `w` × `h` grid of positions `pos` (row-major) → (3, H, W) image.
pub fn grid_to_image(w: usize, h: usize, pos: &[[f32; 3]], domain: &Domain) -> Tensor {
    assert_eq!(pos.len(), w * h, "grid {w}x{h} needs {} vertices", w * h);
    let mut t = Tensor::zeros(&[3, h, w]);
    for (v, p) in pos.iter().enumerate() {
        let c = domain.encode(*p);
        for (k, ck) in c.iter().enumerate() {
            t.data[k * h * w + v] = *ck;
        }
    }
    t
}

/// Eq 2: (3, H, W) image (or one frame of a batch, `frame` of (T, 3, H, W)) → mesh.
pub fn image_to_mesh(img: &Tensor, frame: usize, domain: &Domain) -> GridMesh {
    let (w, h, at) = image_vertices(img, frame, domain);
    GridMesh::new(w, h, (0..w * h).map(at).collect())
}

/// [`image_to_mesh`] into `out` (W·H positions, row-major), without allocating.
pub fn image_to_grid(img: &Tensor, frame: usize, domain: &Domain, out: &mut [[f32; 3]]) {
    let (w, h, at) = image_vertices(img, frame, domain);
    assert_eq!(out.len(), w * h, "image_to_grid: {} positions for a {w}×{h} grid", out.len());
    out.iter_mut().enumerate().for_each(|(v, p)| *p = at(v));
}

/// Eq 2 vertex by vertex: (W, H, vertex → position) of frame `frame` of `img` ((3, H, W) or
/// (T, 3, H, W)).
pub fn image_vertices<'a>(
    img: &'a Tensor,
    frame: usize,
    domain: &'a Domain,
) -> (usize, usize, impl Fn(usize) -> [f32; 3] + 'a) {
    let (h, w) = (img.shape[img.rank() - 2], img.shape[img.rank() - 1]);
    let base = frame * 3 * h * w;
    (w, h, move |v: usize| domain.decode(std::array::from_fn(|k| img.data[base + k * h * w + v])))
}

/// (T, 3, H, W) → one mesh per frame (Eq 2): the inverse of [`sequence_to_images`].
pub fn images_to_sequence(images: &Tensor, domain: &Domain) -> Vec<GridMesh> {
    (0..images.shape[0]).map(|k| image_to_mesh(images, k, domain)).collect()
}

/// A sequence of meshes → (T, 3, H, W).
pub fn sequence_to_images(frames: &[GridMesh], domain: &Domain) -> Tensor {
    let (w, h) = (frames[0].w, frames[0].h);
    let mut data = Vec::with_capacity(frames.len() * 3 * h * w);
    for f in frames {
        data.extend_from_slice(&mesh_to_image(f, domain).data);
    }
    Tensor { shape: [frames.len(), 3, h, w].into(), data }
}

/// S(X) of the wrinkle-detail metric: `frame` resampled to the `lr_w × lr_h` grid and back to
/// its own size with Catmull-Rom (align corners, Keys a = −0.5, clamped indices; the ×2
/// pipeline's own interpolation, [`resize`]). What is left of X after passing through the LR grid: a smooth surface, since a Catmull-Rom interpolated grid round-trips to itself up to the
/// resampling not being a projection. Resampled in f32, positions unchanged otherwise (metres).
pub fn lr_round_trip(frame: &GridMesh, lr_w: usize, lr_h: usize) -> GridMesh {
    // (1, 3, H, W): the geometry image of the unit domain holds metres unchanged.
    let img = sequence_to_images(std::slice::from_ref(frame), &Domain::UNIT);
    // The metric's resampling, not a net op: the CPU function, not the op table.
    let lr = resize(&img, lr_h, lr_w, Interp::CatmullRom);
    image_to_mesh(&resize(&lr, frame.h, frame.w, Interp::CatmullRom), 0, &Domain::UNIT)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn geometry_image_round_trip_is_exact_to_f32_rounding() {
        let mut m = GridMesh::flat(7, 5, 1.3, 0.7);
        for (k, p) in m.pos.iter_mut().enumerate() {
            p[2] = (k as f32 * 0.37).sin() * 0.2;
        }
        let d = Domain::enclosing(std::slice::from_ref(&m), 0.05);
        let back = image_to_mesh(&mesh_to_image(&m, &d), 0, &d);
        for (a, b) in m.pos.iter().zip(&back.pos) {
            for k in 0..3 {
                assert!((a[k] - b[k]).abs() <= 4.0 * f32::EPSILON * (1.0 + a[k].abs()), "{a:?} vs {b:?}");
            }
        }
    }
}
