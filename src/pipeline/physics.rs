//! The physics pass (`upscale --physics`, [`crate::pipeline::Upscaler::with_physics`]): the
//! nets' HR frames pass through [`Follower`] (an HR cloth coarse-tracked to them) on their way
//! out, in shot order.

use crate::cloth::follow::{FollowParams, Follower};
use crate::error::{Error, Result};
use crate::geom::geometry_image::image_to_mesh;
use crate::geom::mesh::{bounds, dist};
use crate::geom::surface::Subdivision;
use crate::geom::Domain;
use crate::pipeline::stream::HrSink;
use crate::sr::upscale::Upscaled;
use crate::tensor::Tensor;
use std::ops::Range;

/// One shot's physics pass over HR geometry images: the cloth starts on the shot's first frame
/// and each later frame is replaced by where the cloth is then.
pub struct PhysicsPass {
    pub params: FollowParams,
    /// Started on the shot's first frame.
    follower: Option<Follower>,
}

impl PhysicsPass {
    /// A pass with `params`, checked by the caller ([`FollowParams::validate`]; the job's
    /// check, [`crate::pipeline::Upscaler::with_physics`]) and again by [`Follower::new`] on
    /// the shot's first frame.
    pub fn new(params: FollowParams) -> PhysicsPass {
        PhysicsPass { params, follower: None }
    }

    /// Replace frame `f` of `hr` ((N, 3, rH, rW) geometry images encoded with `domain`) by the
    /// pass's cloth; `k` is the frame's number in the shot, `lr` the shot's LR grid (columns,
    /// rows). The first call starts the cloth on that frame (which it gives back as it was).
    pub fn apply(
        &mut self,
        hr: &mut Tensor,
        f: usize,
        k: usize,
        domain: &Domain,
        lr: (usize, usize),
    ) -> Result<()> {
        let hw = hr.shape[2] * hr.shape[3];
        let target = image_to_mesh(hr, f, domain);
        let cloth = match &mut self.follower {
            None => {
                self.follower = Some(Follower::new(&target, lr, &self.params)?);
                target
            }
            Some(fo) => {
                let cloth = fo.step(&target, k)?;
                check_follows(&cloth.pos, &target.pos, k)?;
                cloth
            }
        };
        // (3, rH, rW) of frame f, planar.
        let img = &mut hr.data[f * 3 * hw..(f + 1) * 3 * hw];
        for (v, p) in cloth.pos.iter().enumerate() {
            let c = domain.encode(*p);
            for (ch, x) in c.iter().enumerate() {
                img[ch * hw + v] = *x;
            }
        }
        Ok(())
    }

    /// Forget the shot: the next frame starts a new cloth.
    pub fn reset(&mut self) {
        self.follower = None;
    }
}

/// One shot's physics pass on a mesh that is not a grid ([`Follower::new_mesh`]): the HR frames'
/// vertices go in in shot order, the cloth's come out.
pub struct MeshPhysicsPass {
    pub params: FollowParams,
    sub: Subdivision,
    lr: usize,
    follower: Option<Follower>,
}

impl MeshPhysicsPass {
    /// A pass with `params` on the subdivision `sub` of a mesh of `lr` vertices.
    pub fn new(params: FollowParams, sub: Subdivision, lr: usize) -> MeshPhysicsPass {
        MeshPhysicsPass { params, sub, lr, follower: None }
    }

    /// Forget the shot: the next frame starts a new cloth.
    pub fn reset(&mut self) {
        self.follower = None;
    }

    /// The pass's cloth for frame `k` of the shot whose HR vertices the nets gave as `hr`; the
    /// first call starts the cloth on it (and gives it back as it was).
    pub fn apply(&mut self, hr: Vec<[f32; 3]>, k: usize) -> Result<Vec<[f32; 3]>> {
        match &mut self.follower {
            None => {
                self.follower = Some(Follower::new_mesh(&hr, self.sub.clone(), self.lr, &self.params)?);
                Ok(hr)
            }
            Some(fo) => {
                let cloth = fo.step_mesh(&hr, k)?;
                check_follows(&cloth, &hr, k)?;
                Ok(cloth)
            }
        }
    }
}

/// Largest distance, as a fraction of the frame's size (its bounding box's diagonal), by
/// which the pass's cloth may lie from the frame it follows. The pass adds folds of
/// millimetres to centimetres and its drift correction keeps it on the shot: on our
/// simulator's drop, drape, flag, twist and flag-sphere runs (60 frames, 32², their held edges
/// pinned) the largest vertex distance stayed below 8 % of the cloth's size (the drop's
/// landing; the others below 3 %). A cloth a fifth of its size away did not follow the shot: a jump it cannot take
/// (two shots in one folder, a snap of metres), or a shot read with the wrong units, gravity
/// axis or frame rate.
pub const MAX_FOLLOW_FRACTION: f32 = 0.2;

/// Largest mean offset of the pass's cloth from the frame, as a fraction of the frame's size:
/// a cloth that trails the shot as a whole (a shot too fast for the pass to follow). Our
/// simulator's runs stayed below 1 % (drop 0.96 %, drape 0.26 %, flag 0.11 %).
pub const MAX_TRAIL_FRACTION: f32 = 0.05;

/// Refuse frame `k` of the pass's `cloth` if a vertex lies further than
/// [`MAX_FOLLOW_FRACTION`] of the frame's size from `target`, the frame it follows, or the
/// cloth as a whole further than [`MAX_TRAIL_FRACTION`].
fn check_follows(cloth: &[[f32; 3]], target: &[[f32; 3]], k: usize) -> Result<()> {
    let (lo, hi) = bounds(target);
    let size = dist(lo, hi);
    let far = cloth.iter().zip(target).map(|(a, b)| dist(*a, *b)).fold(0.0f32, f32::max);
    // The mean offset: a cloth that trails the shot as a whole.
    let n = cloth.len().max(1) as f32;
    let mut mean = [0.0f32; 3];
    for (a, b) in cloth.iter().zip(target) {
        (0..3).for_each(|i| mean[i] += (a[i] - b[i]) / n);
    }
    let trail = dist(mean, [0.0; 3]);
    if far > MAX_FOLLOW_FRACTION * size || trail > MAX_TRAIL_FRACTION * size {
        let far = far.max(trail);
        return Err(Error::numeric(format!(
            "frame {k}: the physics pass's cloth lies {far:.3} m from the frame ({:.0} % of the \
             cloth's {size:.2} m): it cannot follow the shot there. Check that the shot is in \
             metres, that gravity points down along its axes (y-up: 0,-9.81,0; z-up: 0,0,-9.81), \
             that the frame rate is the shot's, and that the input holds one shot (a jump of \
             metres between frames)",
            100.0 * far / size
        )));
    }
    Ok(())
}

/// An [`HrSink`] that replaces each HR frame by the physics pass's cloth and hands it on.
pub struct PhysicsSink<'a> {
    pub inner: &'a mut dyn HrSink,
    /// The box the HR geometry images are encoded in.
    pub domain: Domain,
    pub pass: PhysicsPass,
    /// The shot's LR grid (columns, rows): the coarse constraints' nodes.
    pub lr: (usize, usize),
}

impl<'a> PhysicsSink<'a> {
    pub fn new(inner: &'a mut dyn HrSink, domain: Domain, params: FollowParams, lr: (usize, usize)) -> Self {
        PhysicsSink { inner, domain, pass: PhysicsPass::new(params), lr }
    }
}

impl HrSink for PhysicsSink<'_> {
    fn write(&mut self, first: usize, up: &Upscaled, keep: Range<usize>) -> Result<()> {
        let mut out = up.clone();
        for (k, f) in keep.clone().enumerate() {
            self.pass.apply(&mut out.hr, f, first + k, &self.domain, self.lr)?;
        }
        self.inner.write(first, &out, keep)
    }
}
