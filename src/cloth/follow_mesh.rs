//! The physics pass on any mesh (issue 45, deliverable 4): [`super::follow::Follower`]'s
//! method on a mesh that is not a grid. An HR cloth of the mesh's subdivision
//! ([`Cloth::from_mesh`]) is coarse-tracked to the nets' HR frames at the LR mesh's scale —
//! one XPBD constraint per LR vertex on the average of the HR vertices its subdivision weights
//! reach ([`Restriction::of_subdivision`], the grid's tents on any mesh) — so folds finer than
//! the LR mesh form as they would in an HR run of the same cloth.
//!
//! Where the grid pass resamples through the LR grid (its `S`), a mesh has its own: the
//! linear subdivision of a frame's LR vertices, `S(x) = P·x[..n]` (HR vertices `0..n` are the
//! LR vertices). The settling, the rest sag, both outputs, the drift correction and the
//! colliders are the grid pass's, with this `S` and with the border taper counted in rings of
//! edges from the mesh's own border. Pins are not supported on meshes yet.

use super::collision::Colliders;
use super::follow::{FollowOutput, FollowParams, SETTLE_SECONDS};
use super::kinematics::Kinematics;
use super::params::SimParams;
use super::solver::{Cloth, Scene};
use super::tracking::{CoarseTrack, Restriction, TrackTargets};
use super::wind::Wind;
use crate::error::{Error, Result};
use crate::geom::surface::{edge_key, Subdivision};

/// One shot's physics pass on a mesh: the HR cloth and the last frame's coarse targets.
pub struct MeshFollower {
    cloth: Cloth,
    scene: Scene,
    sim: SimParams,
    strength: f32,
    damping: f32,
    track: CoarseTrack,
    /// The LR mesh's subdivision (the HR topology) and its LR vertex count.
    sub: Subdivision,
    lr: usize,
    /// Coarse targets (one per LR vertex, m) of the last frame given.
    from: Vec<[f32; 3]>,
    /// The part finer than the LR mesh of each vertex's offset at the end of the settling (m).
    rest_sag: Vec<[f32; 3]>,
    /// Per HR vertex, the share of the simulated detail `detail` output takes (0 on the
    /// border, ½ one edge in, 1 inside).
    taper: Vec<f32>,
    floor: Option<([f32; 3], f32)>,
    output: FollowOutput,
    drift_keep: f32,
    drift: Vec<[f32; 3]>,
}

impl MeshFollower {
    /// A cloth of `sub`'s HR mesh (`hr_faces`) whose rest shape is `first` (the shot's first HR
    /// frame), settled there; `lr` LR vertices.
    pub fn new(first: &[[f32; 3]], sub: Subdivision, lr: usize, p: &FollowParams) -> Result<MeshFollower> {
        p.validate()?;
        if !p.pins.is_empty() {
            return Err(Error::invalid(
                "pins",
                "held grid edges (top, left, …) name a grid's sides; a mesh that is not a grid has \
                 none: leave them out",
            ));
        }
        if first.len() != sub.hr_vertices() {
            return Err(Error::shape(format!(
                "the physics pass's mesh has {} HR vertices, the frame {}",
                sub.hr_vertices(),
                first.len()
            )));
        }
        check_frame(first, 0)?;
        let material = p.material;
        let cloth = Cloth::from_mesh(first, &sub.faces, &|_| material, Vec::new());
        let track = CoarseTrack::new(Restriction::of_subdivision(&sub, lr), &cloth.inv_mass);
        let colliders = Colliders { sphere: p.sphere, cuboid: p.cuboid, ground: None };
        let scene = Scene { kinematics: Kinematics::Static, wind: Wind::none(), colliders };
        let taper = border_taper(&sub.faces, first.len());
        let mut f = MeshFollower {
            cloth,
            scene,
            sim: p.sim_params(),
            strength: p.strength,
            damping: p.damping,
            track,
            sub,
            lr,
            from: Vec::new(),
            rest_sag: Vec::new(),
            taper,
            floor: p.ground.map(|h| {
                let n = p.gravity.iter().map(|g| g * g).sum::<f32>().sqrt();
                (p.gravity.map(|g| -g / n), h)
            }),
            output: p.output,
            drift_keep: (-1.0 / (p.fps * p.drift_seconds)).exp(),
            drift: Vec::new(),
        };
        f.settle(first);
        f.from = f.targets(first);
        Ok(f)
    }

    /// `S(x)`: the linear subdivision of `x`'s LR vertices (the part of `x` the LR mesh holds).
    fn coarse(&self, x: &[[f32; 3]]) -> Vec<[f32; 3]> {
        self.sub.apply(&x[..self.lr])
    }

    /// The coarse targets of an HR frame (one per LR vertex, m): the restriction of its `S`.
    fn targets(&self, frame: &[[f32; 3]]) -> Vec<[f32; 3]> {
        self.track.restriction.apply(&self.coarse(frame))
    }

    /// Settle on the first frame as the grid pass does ([`SETTLE_SECONDS`] held still,
    /// critically damped; start from the mean shape over the second half) and keep the rest
    /// sag finer than the LR mesh.
    fn settle(&mut self, first: &[[f32; 3]]) {
        let (time, t) = (self.cloth.time, self.targets(first));
        let frames = (SETTLE_SECONDS * self.sim.dt.recip()).ceil().max(2.0) as usize;
        let n = (frames - frames.div_ceil(2)) as f32;
        let mut mean = vec![[0.0f32; 3]; first.len()];
        for k in 0..frames {
            let tt = TrackTargets {
                from: &t,
                to: &t,
                strength: self.strength,
                damping: self.damping.max(1.0),
                coarse: Some(&self.track),
                pins: None,
            };
            self.cloth.step(&self.sim, &self.scene, Some(&tt));
            if 2 * k >= frames {
                for (m, x) in mean.iter_mut().zip(&self.cloth.x) {
                    (0..3).for_each(|i| m[i] += x[i] / n);
                }
            }
        }
        let d: Vec<[f32; 3]> =
            mean.iter().zip(first).map(|(x, f)| std::array::from_fn(|c| x[c] - f[c])).collect();
        let coarse = self.coarse(&d);
        self.rest_sag = d.iter().zip(&coarse).map(|(a, b)| std::array::from_fn(|c| a[c] - b[c])).collect();
        let c = &mut self.cloth;
        for (v, (x, m)) in c.x.iter_mut().zip(&mean).enumerate() {
            if c.inv_mass[v] > 0.0 {
                *x = *m;
            }
        }
        c.v.iter_mut().for_each(|v| *v = [0.0; 3]);
        c.time = time;
    }

    /// Simulate one frame toward `target` (the next HR frame, the mesh's HR vertices) and
    /// return the cloth there; `k` is the frame's number, for errors.
    pub fn step(&mut self, target: &[[f32; 3]], k: usize) -> Result<Vec<[f32; 3]>> {
        if target.len() != self.cloth.x.len() {
            return Err(Error::shape(format!(
                "frame {k} has {} HR vertices, the physics pass's cloth {}",
                target.len(),
                self.cloth.x.len()
            )));
        }
        check_frame(target, k)?;
        let to = self.targets(target);
        let tt = TrackTargets {
            from: &self.from,
            to: &to,
            strength: self.strength,
            damping: self.damping,
            coarse: Some(&self.track),
            pins: None,
        };
        self.cloth.step(&self.sim, &self.scene, Some(&tt));
        self.from = to;
        let mut out: Vec<[f32; 3]> = self
            .cloth
            .x
            .iter()
            .zip(&self.rest_sag)
            .map(|(x, s)| std::array::from_fn(|c| x[c] - s[c]))
            .collect();
        match self.output {
            FollowOutput::Detail => {
                let s = self.coarse(&out);
                for (((o, t), s), k) in out.iter_mut().zip(target).zip(&s).zip(&self.taper) {
                    *o = std::array::from_fn(|c| t[c] + k * (o[c] - s[c]));
                }
            }
            FollowOutput::Cloth if self.drift_keep < 1.0 => {
                let (st, so) = (self.coarse(target), self.coarse(&out));
                let now = st.iter().zip(&so).map(|(t, o)| std::array::from_fn(|c| t[c] - o[c]));
                if self.drift.is_empty() {
                    self.drift = now.collect();
                } else {
                    let keep = self.drift_keep;
                    for (d, n) in self.drift.iter_mut().zip(now) {
                        *d = std::array::from_fn(|c| keep * d[c] + (1.0 - keep) * n[c]);
                    }
                }
                for (o, d) in out.iter_mut().zip(&self.drift) {
                    (0..3).for_each(|c| o[c] += d[c]);
                }
            }
            FollowOutput::Cloth => {}
        }
        let c = &self.scene.colliders;
        if c.sphere.is_some() || c.cuboid.is_some() {
            let (before, free) = (out.clone(), vec![1.0; out.len()]);
            c.project(&mut out, &before, &free, 0.0, 0.0);
        }
        if let Some((up, h)) = self.floor {
            for o in &mut out {
                let below = h - (0..3).map(|c| o[c] * up[c]).sum::<f32>();
                if below > 0.0 {
                    (0..3).for_each(|c| o[c] += below * up[c]);
                }
            }
        }
        if out.iter().flatten().any(|c| !c.is_finite()) {
            return Err(Error::numeric(format!(
                "the physics pass blew up at frame {k} (non-finite position): is the shot in metres \
                 and --fps its frame rate?"
            )));
        }
        Ok(out)
    }
}

/// Per vertex of the mesh `faces` (`n` vertices): 0 on its border (a vertex of an edge in one
/// face), ½ one edge in, 1 further in: how much of the simulated detail [`FollowOutput::Detail`]
/// takes, as on a grid (the simulated hem, held by fewer constraints, crumples in its plane).
fn border_taper(faces: &[Vec<u32>], n: usize) -> Vec<f32> {
    let mut count: std::collections::HashMap<(u32, u32), u32> = std::collections::HashMap::new();
    for f in faces {
        for i in 0..f.len() {
            *count.entry(edge_key(f[i], f[(i + 1) % f.len()])).or_default() += 1;
        }
    }
    let mut ring = vec![u32::MAX; n];
    for (&(a, b), &c) in &count {
        if c == 1 {
            ring[a as usize] = 0;
            ring[b as usize] = 0;
        }
    }
    // One edge in from the border.
    for &(a, b) in count.keys() {
        let (ra, rb) = (ring[a as usize], ring[b as usize]);
        if ra == 0 && rb != 0 {
            ring[b as usize] = 1;
        }
        if rb == 0 && ra != 0 {
            ring[a as usize] = 1;
        }
    }
    ring.into_iter()
        .map(|r| match r {
            0 => 0.0,
            1 => 0.5,
            _ => 1.0,
        })
        .collect()
}

fn check_frame(x: &[[f32; 3]], k: usize) -> Result<()> {
    if x.iter().flatten().any(|c| !c.is_finite()) {
        return Err(Error::numeric(format!(
            "frame {k} has a non-finite position; the physics pass needs finite frames"
        )));
    }
    Ok(())
}
