//! `upscale --physics`: the nets' HR frames pass through [`Follower`] (an HR cloth
//! coarse-tracked to them) on their way to the outputs, in shot order.

use crate::cloth::follow::{FollowParams, Follower};
use crate::error::Result;
use crate::geom::geometry_image::image_to_mesh;
use crate::geom::Domain;
use crate::sr::stream::HrSink;
use crate::sr::upscale::Upscaled;
use std::ops::Range;

/// An [`HrSink`] that replaces each HR frame by the physics pass's cloth and hands it on.
pub struct PhysicsSink<'a> {
    pub inner: &'a mut dyn HrSink,
    /// The box the HR geometry images are encoded in.
    pub domain: Domain,
    pub params: FollowParams,
    /// The shot's LR grid (columns, rows): the coarse constraints' nodes.
    pub lr: (usize, usize),
    /// Started on the shot's first frame.
    follower: Option<Follower>,
}

impl<'a> PhysicsSink<'a> {
    pub fn new(inner: &'a mut dyn HrSink, domain: Domain, params: FollowParams, lr: (usize, usize)) -> Self {
        PhysicsSink { inner, domain, params, lr, follower: None }
    }
}

impl HrSink for PhysicsSink<'_> {
    fn write(&mut self, first: usize, up: &Upscaled, keep: Range<usize>) -> Result<()> {
        let mut out = up.clone();
        let hw = out.hr.shape[2] * out.hr.shape[3];
        for (k, f) in keep.clone().enumerate() {
            let target = image_to_mesh(&up.hr, f, &self.domain);
            let cloth = match &mut self.follower {
                None => {
                    self.follower = Some(Follower::new(&target, self.lr, &self.params)?);
                    target
                }
                Some(fo) => fo.step(&target, first + k)?,
            };
            // (3, rH, rW) of frame f, planar.
            let img = &mut out.hr.data[f * 3 * hw..(f + 1) * 3 * hw];
            for (v, p) in cloth.pos.iter().enumerate() {
                let c = self.domain.encode(*p);
                for (ch, x) in c.iter().enumerate() {
                    img[ch * hw + v] = *x;
                }
            }
        }
        self.inner.write(first, &out, keep)
    }
}
