//! Training data: `data.npz` (built by `anisocb dataset`) in memory, a held-out validation
//! split, and seeded random patches.
//!
//! Layout of `data.npz`: arrays `lr` (N, 3, H, W), `hr` (N, 3, rH, rW), `boundary` (N, 1, rH, rW),
//! `edges` (N, 1, rH, rW), `domain` (N, 2, 3), and entries `frames.json`, `params.json`.
//!
//! Sampling is *stateless*: sample `k` of step `s` is drawn from a stream keyed by
//! `(seed, s·batch + k)`, and the frame order of each epoch is a seeded shuffle keyed by
//! `(seed, epoch)`. A run resumed at step `s` therefore draws exactly the batches an
//! uninterrupted run would, with nothing but `(seed, s)` saved.

use crate::error::{Error, Result};
use crate::geom::cloth_frame::{mirror_net_images, InputFrame, GRID_MIRRORS};
use crate::io::json::Value;
use crate::io::read_npz;
use crate::nn::geometry_net::interpolate;
use crate::nn::NetKind;
use crate::ops::{Interp, Ops};
use crate::rng::{mix_seed, Rng};
use crate::tensor::Tensor;
use std::path::Path;

/// All frames of a training set.
#[derive(Clone, Debug)]
pub struct TrainingData {
    /// LR geometry images (N, 3, H, W), in [0, 1].
    pub lr: Tensor,
    /// HR ground truth (N, 3, rH, rW).
    pub hr: Tensor,
    /// Ground-truth boundary maps (N, 1, rH, rW), 0/1.
    pub boundary: Tensor,
    /// Ground-truth enhance (edge) maps (N, 1, rH, rW), 0/1.
    pub edges: Tensor,
    /// Upscale factor r (from the shapes).
    pub scale: usize,
    /// The coordinates `lr` and `hr` are in (`params.json` key `input_frame`; a set without
    /// it was built in the paper's domain).
    pub input_frame: InputFrame,
}

impl TrainingData {
    /// Read and check `data.npz`; every problem names the file.
    pub fn load(path: &Path) -> Result<TrainingData> {
        let e = read_npz(path)?;
        let get = |n: &str| e.require(path, n).cloned();
        let mut d = TrainingData::new(get("lr")?, get("hr")?, get("boundary")?, get("edges")?)
            .map_err(|e| e.in_file(path))?;
        if let Some(bytes) = e.file("params.json") {
            let text =
                std::str::from_utf8(bytes).map_err(|_| Error::format(path, "params.json is not UTF-8"))?;
            let v = Value::parse_str(text).map_err(|m| Error::format(path, format!("params.json: {m}")))?;
            if let Some(f) = v.get("input_frame").and_then(Value::as_str) {
                d.input_frame = InputFrame::parse(f).map_err(|e| e.in_file(path))?;
            }
        }
        Ok(d)
    }

    /// Check shapes (`hr` is r× `lr`, maps have one channel) and values (finite).
    pub fn new(lr: Tensor, hr: Tensor, boundary: Tensor, edges: Tensor) -> Result<TrainingData> {
        let (n, c, h, w) = lr.expect_rank4("lr")?;
        if c != 3 || n == 0 || h == 0 || w == 0 {
            return Err(Error::shape(format!("lr: expected (N, 3, H, W), got {:?}", lr.shape)));
        }
        let (_, _, hh, _) = hr.expect_rank4("hr")?;
        let scale = hh / h;
        if scale == 0 || hr.shape != [n, 3, h * scale, w * scale] {
            return Err(Error::shape(format!(
                "hr: {:?} is not an integer upscale of lr {:?}",
                hr.shape, lr.shape
            )));
        }
        for (name, t) in [("boundary", &boundary), ("edges", &edges)] {
            if t.shape != [n, 1, h * scale, w * scale] {
                return Err(Error::shape(format!(
                    "{name}: expected {:?}, got {:?}",
                    [n, 1, h * scale, w * scale],
                    t.shape
                )));
            }
        }
        for (name, t) in [("lr", &lr), ("hr", &hr), ("boundary", &boundary), ("edges", &edges)] {
            if let Some((i, v)) = t.first_non_finite() {
                return Err(Error::numeric(format!("{name}: non-finite value {v} at index {i}")));
            }
        }
        Ok(TrainingData { lr, hr, boundary, edges, scale, input_frame: InputFrame::Domain })
    }

    pub fn len(&self) -> usize {
        self.lr.shape[0]
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// (H, W) of the LR frames.
    pub fn lr_size(&self) -> (usize, usize) {
        (self.lr.shape[2], self.lr.shape[3])
    }

    /// The target of `kind`: HR geometry, boundary map or edge map.
    pub fn target(&self, kind: NetKind) -> &Tensor {
        match kind {
            NetKind::Geometry => &self.hr,
            NetKind::Boundary => &self.boundary,
            NetKind::Enhance => &self.edges,
        }
    }

    /// FNV-1a hash of the shapes and bits of what training `kind` reads (the LR frames, and
    /// its target: HR for GeometryNet, the boundary or edge map for the map nets): a resumed run
    /// must see the same data, while a data set that differs only in another net's target
    /// (e.g. a benefit-based boundary map) resumes the nets it does not change.
    pub fn fingerprint(&self, kind: NetKind) -> u64 {
        let mut h = 0xcbf2_9ce4_8422_2325u64;
        let mut eat = |w: u64| {
            for b in w.to_le_bytes() {
                h = (h ^ b as u64).wrapping_mul(0x0100_0000_01b3);
            }
        };
        for t in [&self.lr, self.target(kind)] {
            t.shape.iter().for_each(|&d| eat(d as u64));
            t.data.chunks(2).for_each(|c| eat(c.iter().fold(0u64, |a, v| (a << 32) | v.to_bits() as u64)));
        }
        h
    }
}

/// Train / validation frame indices: the last `⌈val_frac·N⌉` frames are held out (a contiguous
/// block, so neighbouring, near-identical frames do not leak into validation); at least one
/// frame stays in training. `val_frac = 0` gives no validation.
pub fn split(n: usize, val_frac: f32) -> Result<(Vec<usize>, Vec<usize>)> {
    if !(0.0..1.0).contains(&val_frac) {
        return Err(Error::invalid("val_frac", format!("must be in [0, 1), got {val_frac}")));
    }
    // (−1e-6: 0.1f32 is 0.10000000149, and 10% of 800 frames should be 80, not 81.)
    let n_val = ((val_frac as f64 * n as f64 - 1e-6).ceil().max(0.0) as usize).min(n.saturating_sub(1));
    Ok(((0..n - n_val).collect(), (n - n_val..n).collect()))
}

/// A batch: LR patches, the matching crop of the whole-frame interpolation `U`, the target.
#[derive(Clone, Debug)]
pub struct Batch {
    /// (B, 3, ph, pw)
    pub lr: Tensor,
    /// (B, 3, r·ph, r·pw); only for GeometryNet (empty otherwise).
    pub u: Tensor,
    /// (B, 3 or 1, r·ph, r·pw)
    pub target: Tensor,
}

/// Copy the window (y0.., x0..) of size (h, w) of sample `n` of `src` (N, C, H, W) into `dst`
/// (B, C, h, w) at batch index `b`.
fn crop_into(src: &Tensor, n: usize, y0: usize, x0: usize, dst: &mut Tensor, b: usize) {
    let (_, c, sh, sw) = src.dims4();
    let (_, _, h, w) = dst.dims4();
    for ci in 0..c {
        for y in 0..h {
            let s = ((n * c + ci) * sh + y0 + y) * sw + x0;
            let d = ((b * c + ci) * h + y) * w;
            dst.data[d..d + w].copy_from_slice(&src.data[s..s + w]);
        }
    }
    debug_assert!(y0 + h <= sh && x0 + w <= sw);
}

/// Mirror sample `b` of `t` (B, C, H, W) in place by the grid mirror (`rows`, `cols`): pixels,
/// and for positions (C = 3) the coordinates ([`mirror_net_images`]). An empty `t` is left alone.
fn mirror_sample(t: &mut Tensor, b: usize, rows: bool, cols: bool, frame: InputFrame) {
    if t.data.is_empty() {
        return;
    }
    let one = t.slice_batch(b, 1);
    let m = if one.shape[1] == 3 {
        mirror_net_images(&one, rows, cols, frame, true)
    } else {
        one.flipped(rows, cols)
    };
    let per = m.len();
    t.data[b * per..(b + 1) * per].copy_from_slice(&m.data);
}

/// Seeded random patches from the training frames.
#[derive(Clone, Debug)]
pub struct PatchSampler {
    pub train: Vec<usize>,
    pub seed: u64,
    pub batch: usize,
    /// LR patch size (rows, cols); the HR patch is r× it at r× the offset.
    pub patch: (usize, usize),
    /// Mirror each sample at random into one of the grid's four mirror images
    /// ([`GRID_MIRRORS`]), LR, U and target together; in the cloth frame the positions get the
    /// mirrored grid's own frame ([`crate::geom::cloth_frame::mirrored_axes`]).
    pub mirror: bool,
    perm_cache: Option<(u64, Vec<usize>)>,
}

impl PatchSampler {
    /// `patch` is clamped to the frame size (the paper's flag is 32×10).
    pub fn new(
        data: &TrainingData,
        train: Vec<usize>,
        seed: u64,
        batch: usize,
        patch: usize,
    ) -> Result<Self> {
        if train.is_empty() || batch == 0 || patch == 0 {
            return Err(Error::config("need at least one training frame, batch ≥ 1 and patch ≥ 1"));
        }
        let (h, w) = data.lr_size();
        Ok(PatchSampler {
            train,
            seed,
            batch,
            patch: (patch.min(h), patch.min(w)),
            mirror: false,
            perm_cache: None,
        })
    }

    /// Frame of global sample `g`: epoch `g / n` visits the training frames in a seeded order.
    fn frame(&mut self, g: u64) -> usize {
        let n = self.train.len() as u64;
        let (epoch, pos) = (g / n, (g % n) as usize);
        if self.perm_cache.as_ref().map(|c| c.0) != Some(epoch) {
            let mut p = self.train.clone();
            Rng::new(mix_seed(&[self.seed, 1, epoch])).shuffle(&mut p);
            self.perm_cache = Some((epoch, p));
        }
        self.perm_cache.as_ref().unwrap().1[pos]
    }

    /// The batch of training step `step` (0-based). `u` is the whole-frame interpolation of
    /// `data.lr` (needed only for GeometryNet).
    pub fn batch(&mut self, data: &TrainingData, u: Option<&Tensor>, kind: NetKind, step: u64) -> Batch {
        let r = data.scale;
        let (ph, pw) = self.patch;
        let (h, w) = data.lr_size();
        let target_src = data.target(kind);
        let tc = target_src.shape[1];
        let bsz = self.batch;
        let mut lr = Tensor::zeros(&[bsz, 3, ph, pw]);
        let mut target = Tensor::zeros(&[bsz, tc, r * ph, r * pw]);
        let mut ub = match u {
            Some(_) => Tensor::zeros(&[bsz, 3, r * ph, r * pw]),
            None => Tensor::zeros(&[0]),
        };
        for b in 0..bsz {
            let g = step * bsz as u64 + b as u64;
            let n = self.frame(g);
            let mut rng = Rng::new(mix_seed(&[self.seed, 2, g]));
            let y0 = rng.below(h - ph + 1);
            let x0 = rng.below(w - pw + 1);
            crop_into(&data.lr, n, y0, x0, &mut lr, b);
            crop_into(target_src, n, r * y0, r * x0, &mut target, b);
            if let Some(u) = u {
                crop_into(u, n, r * y0, r * x0, &mut ub, b);
            }
            if self.mirror {
                let (rows, cols) = GRID_MIRRORS[rng.below(GRID_MIRRORS.len())];
                for t in [&mut lr, &mut target, &mut ub] {
                    mirror_sample(t, b, rows, cols, data.input_frame);
                }
            }
        }
        Batch { lr, u: ub, target }
    }

    /// The batches of `steps`, in order, cut on a thread of `scope` one batch ahead of the
    /// receiver (for a step that runs elsewhere, a GPU's: the host cuts the next batch while
    /// the device works). The same batches as [`PatchSampler::batch`] step by step; the thread
    /// ends at the last step or when the receiver is dropped.
    pub fn ahead<'s>(
        mut self,
        scope: &'s std::thread::Scope<'s, '_>,
        data: &'s TrainingData,
        u: Option<&'s Tensor>,
        kind: NetKind,
        steps: std::ops::Range<u64>,
    ) -> std::sync::mpsc::Receiver<Batch> {
        let (tx, rx) = std::sync::mpsc::sync_channel(1);
        scope.spawn(move || {
            for step in steps {
                if tx.send(self.batch(data, u, kind, step)).is_err() {
                    break;
                }
            }
        });
        rx
    }
}

/// Whole-frame interpolation `U` of every LR frame (N, 3, rH, rW) with `mode`, in chunks.
pub fn interpolate_all(ops: &dyn Ops, data: &TrainingData, mode: Interp) -> Tensor {
    let n = data.len();
    let mut parts = Vec::with_capacity(data.hr.len());
    for n0 in (0..n).step_by(64) {
        let cnt = 64.min(n - n0);
        parts.extend_from_slice(&interpolate(ops, &data.lr.slice_batch(n0, cnt), data.scale, mode).data);
    }
    Tensor { shape: data.hr.shape, data: parts }
}

/// Frames `idx` of `src` as one batch (N', C, H, W).
pub fn gather(src: &Tensor, idx: &[usize]) -> Tensor {
    let per: usize = src.shape[1..].iter().product();
    let mut shape = src.shape;
    shape[0] = idx.len();
    let mut data = Vec::with_capacity(idx.len() * per);
    for &i in idx {
        data.extend_from_slice(&src.data[i * per..(i + 1) * per]);
    }
    Tensor { shape, data }
}
