//! The physics pass (`upscale --physics`, [`crate::pipeline::Upscaler::with_physics`]): the
//! nets' HR frames pass through [`Follower`] (an HR cloth coarse-tracked to them) on their way
//! out, in shot order.

use crate::cloth::follow::{FollowParams, Follower};
use crate::error::Result;
use crate::geom::geometry_image::image_to_mesh;
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
            Some(fo) => fo.step(&target, k)?,
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
