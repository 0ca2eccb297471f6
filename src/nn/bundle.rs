//! The three networks together, as the upscale pipeline uses them.

use super::config::{NetConfig, NetKind};
use super::geometry_net::{check_input, GeometryNet};
use super::layers::Trunk;
use super::map_net::MapNet;
use crate::error::{Error, Result};
use crate::geom::cloth_frame::InputFrame;
use crate::ops::conv2d::PackedConv;
use crate::ops::Ops;
use crate::ops::Precision;
use crate::tensor::Tensor;
use std::sync::OnceLock;

/// The widest activation (bytes) of one CPU pass of the nets over several frames; more frames
/// run in further passes. Activations that stay near the cores' caches run faster: `upscale`
/// of a 64² flag took 0.86–0.91× the time in passes of 2 frames (4 MiB) as in passes of 8
/// (16 MiB), bf16 and fp32, while at 32² passes of 1 frame (0.5 MiB) took 1.16× the time of 8
/// (per-pass costs dominate there): docs/performance.md.
pub const CPU_PASS_BYTES: usize = 4 << 20;

/// GeometryNet, BoundaryNet and EnhanceNet. All three must share the upscale factor.
#[derive(Clone, Debug, PartialEq)]
pub struct AnisoCb {
    pub geometry: GeometryNet,
    /// Further GeometryNets of the same configuration (e.g. trained with other seeds): R is the
    /// mean of all GeometryNets' residuals, U the first's. Empty in a plain bundle.
    pub more_geometry: Vec<GeometryNet>,
    pub boundary: MapNet,
    pub enhance: MapNet,
}

/// What the nets say about one batch; every map is (N, ·, r·H, r·W).
#[derive(Clone, Debug)]
pub struct NetsOutput {
    /// U: the input interpolated (`config.upsample`, align corners), (N, 3, rH, rW).
    pub interpolated: Tensor,
    /// R: GeometryNet's residual, (N, 3, rH, rW).
    pub residual: Tensor,
    /// Γb = σ(BoundaryNet logits), (N, 1, rH, rW), in [0, 1].
    pub boundary: Tensor,
    /// Γe = σ(EnhanceNet logits), (N, 1, rH, rW), in [0, 1].
    pub enhance: Tensor,
}

impl AnisoCb {
    /// Fresh nets, all with `config`, initialised from `seed` (each net gets its own stream).
    pub fn new(config: NetConfig, seed: u64) -> Self {
        AnisoCb {
            geometry: GeometryNet::new(config, seed),
            more_geometry: Vec::new(),
            boundary: MapNet { trunk: Trunk::init(NetKind::Boundary, config, seed) },
            enhance: MapNet { trunk: Trunk::init(NetKind::Enhance, config, seed) },
        }
    }

    /// Assemble from three trunks (checks kinds and scales).
    pub fn from_trunks(geometry: Trunk, boundary: Trunk, enhance: Trunk) -> Result<Self> {
        for (t, k) in
            [(&geometry, NetKind::Geometry), (&boundary, NetKind::Boundary), (&enhance, NetKind::Enhance)]
        {
            if t.kind != k {
                return Err(Error::config(format!("expected a {} net, got {}", k.name(), t.kind.name())));
            }
        }
        if geometry.config.scale != boundary.config.scale || geometry.config.scale != enhance.config.scale {
            return Err(Error::config("the three nets have different upscale factors"));
        }
        let frames = [&geometry, &boundary, &enhance].map(|t| t.config.input_frame.name());
        if frames[1..].iter().any(|f| *f != frames[0]) {
            return Err(Error::config(format!(
                "the three nets were trained in different input frames (geometry, boundary, enhance: {})",
                frames.join(", ")
            )));
        }
        Ok(AnisoCb {
            geometry: GeometryNet { trunk: geometry },
            more_geometry: Vec::new(),
            boundary: MapNet { trunk: boundary },
            enhance: MapNet { trunk: enhance },
        })
    }

    /// Add GeometryNets whose residuals are averaged with the first's; each must have the
    /// first's configuration (size, scale, padding, interpolation, input frame).
    pub fn with_more_geometry(mut self, trunks: Vec<Trunk>) -> Result<Self> {
        for (k, t) in trunks.into_iter().enumerate() {
            if t.kind != NetKind::Geometry {
                return Err(Error::config(format!("GeometryNet {}: got a {} net", k + 2, t.kind.name())));
            }
            if t.config != self.geometry.trunk.config {
                return Err(Error::config(format!(
                    "GeometryNet {} ({}) differs from the first ({}): an ensemble needs one configuration",
                    k + 2,
                    t.config,
                    self.geometry.trunk.config
                )));
            }
            self.more_geometry.push(GeometryNet { trunk: t });
        }
        Ok(self)
    }

    /// FNV-1a over every net's name and weights' bits, in the bundle's order: two bundles that
    /// compute differently have different checksums (an output folder's summary records it).
    pub fn checksum(&self) -> u64 {
        let mut h = 0xcbf2_9ce4_8422_2325u64;
        let mut eat =
            |bytes: &[u8]| bytes.iter().for_each(|&b| h = (h ^ b as u64).wrapping_mul(0x0100_0000_01b3));
        for (name, trunk) in self.named_trunks() {
            eat(name.as_bytes());
            for (_, t) in trunk.params() {
                t.data.iter().for_each(|v| eat(&v.to_bits().to_le_bytes()));
            }
        }
        h
    }

    pub fn scale(&self) -> usize {
        self.geometry.trunk.config.scale
    }

    /// The coordinates the nets expect their input in (shared by all three).
    pub fn input_frame(&self) -> InputFrame {
        self.geometry.trunk.config.input_frame
    }

    /// Every net with its name in a weights file: `geometry`, `geometry1`, `geometry2`, …
    /// (the ensemble's further GeometryNets), `boundary`, `enhance`.
    pub fn named_trunks(&self) -> Vec<(String, &Trunk)> {
        let mut v = vec![(NetKind::Geometry.name().to_string(), &self.geometry.trunk)];
        v.extend(
            self.more_geometry.iter().enumerate().map(|(k, g)| (format!("geometry{}", k + 1), &g.trunk)),
        );
        v.push((NetKind::Boundary.name().to_string(), &self.boundary.trunk));
        v.push((NetKind::Enhance.name().to_string(), &self.enhance.trunk));
        v
    }

    /// lr (N, 3, H, W) → (U, R, Γb, Γe). Inference only: no activations are kept; run it in
    /// batches that fit memory (≈ 2·C·r²·H·W floats per sample at the widest layer).
    pub fn forward(&self, ops: &dyn Ops, lr: &Tensor) -> Result<NetsOutput> {
        self.forward_with(ops, lr, true)
    }

    /// [`AnisoCb::forward`], with EnhanceNet run only if `enhance` (else Γe = 0, which is all
    /// Eq 12 reads of it at η = 0): a third less work for the default η.
    pub fn forward_with(&self, ops: &dyn Ops, lr: &Tensor, enhance: bool) -> Result<NetsOutput> {
        self.run(ops, lr, enhance, None)
    }

    /// The bundle with every conv's weights packed once, for inference on many frames.
    pub fn packed(&self) -> PackedAnisoCb<'_> {
        self.packed_as(Precision::Fp32)
    }

    /// [`AnisoCb::packed`] for the kernels of `precision` ([`Precision::Bf16`]: the CPU's AMX
    /// tiles where it has them).
    pub fn packed_as(&self, precision: Precision) -> PackedAnisoCb<'_> {
        PackedAnisoCb {
            model: self,
            packed: Packing::Own(self.pack_all(precision)),
            checksum: Checksum::Own(OnceLock::new()),
        }
    }

    /// [`Trunk::pack`] of every net, in [`AnisoCb::named_trunks`] order: for an owner that
    /// keeps the bundle unchanged and runs it with [`AnisoCb::packed_with`] on every frame.
    pub(crate) fn pack_all(&self, precision: Precision) -> Vec<Vec<PackedConv>> {
        self.named_trunks().into_iter().map(|(_, t)| t.pack(precision)).collect()
    }

    /// The bundle with `packed` = [`AnisoCb::pack_all`] of this very bundle, weights unchanged
    /// since, and `checksum` empty or holding [`AnisoCb::checksum`] of it (the caller's promise;
    /// crate-only for that reason).
    pub(crate) fn packed_with<'a>(
        &'a self,
        packed: &'a [Vec<PackedConv>],
        checksum: &'a OnceLock<u64>,
    ) -> PackedAnisoCb<'a> {
        PackedAnisoCb { model: self, packed: Packing::Lent(packed), checksum: Checksum::Lent(checksum) }
    }

    /// `packed`: [`Trunk::pack`] of every net, in [`AnisoCb::named_trunks`] order. On the CPU
    /// the frames run [`AnisoCb::frames_per_pass`] at a time (the same bits: each frame's
    /// outputs depend on that frame alone).
    fn run(
        &self,
        ops: &dyn Ops,
        lr: &Tensor,
        enhance: bool,
        packed: Option<&[Vec<PackedConv>]>,
    ) -> Result<NetsOutput> {
        check_input(lr, "AnisoCb input")?;
        let (n, per) = (lr.shape[0], self.frames_per_pass(ops, lr));
        if n <= per {
            return self.run_pass(ops, lr, enhance, packed);
        }
        // Each pass's outputs copied into place in tensors of all n frames (one copy, no growth).
        let whole = |t: &Tensor| {
            let mut shape = t.shape.to_vec();
            shape[0] = n;
            Tensor::for_overwrite(&shape)
        };
        let mut out: Option<NetsOutput> = None;
        for n0 in (0..n).step_by(per) {
            let part = self.run_pass(ops, &lr.slice_batch(n0, per.min(n - n0)), enhance, packed)?;
            let o = out.get_or_insert_with(|| NetsOutput {
                interpolated: whole(&part.interpolated),
                residual: whole(&part.residual),
                boundary: whole(&part.boundary),
                enhance: whole(&part.enhance),
            });
            for (to, from) in [
                (&mut o.interpolated, &part.interpolated),
                (&mut o.residual, &part.residual),
                (&mut o.boundary, &part.boundary),
                (&mut o.enhance, &part.enhance),
            ] {
                let at = n0 * from.len() / from.shape[0];
                to.data[at..at + from.len()].copy_from_slice(&from.data);
            }
        }
        Ok(out.expect("n > per ≥ 1: at least one pass"))
    }

    /// Frames of `lr` (N, 3, H, W) one pass of the nets takes on the CPU: as many as keep the
    /// widest activation (C channels at r·H × r·W, f32) within [`CPU_PASS_BYTES`], at least one;
    /// all of them on a GPU.
    pub fn frames_per_pass(&self, ops: &dyn Ops, lr: &Tensor) -> usize {
        if ops.as_cuda().is_some() {
            return usize::MAX;
        }
        let (_, _, h, w) = lr.dims4();
        // The nets one by one (not `named_trunks`, whose names would allocate on every call).
        let more = self.more_geometry.iter().map(|g| &g.trunk);
        let nets = [&self.geometry.trunk, &self.boundary.trunk, &self.enhance.trunk].into_iter().chain(more);
        let c = nets.map(|t| t.config.channels).max().unwrap_or(1);
        let widest = c * self.scale() * self.scale() * h * w * std::mem::size_of::<f32>();
        (CPU_PASS_BYTES / widest.max(1)).max(1)
    }

    /// [`AnisoCb::run`] on every frame of `lr` at once.
    fn run_pass(
        &self,
        ops: &dyn Ops,
        lr: &Tensor,
        enhance: bool,
        packed: Option<&[Vec<PackedConv>]>,
    ) -> Result<NetsOutput> {
        let pk = |k: usize| packed.map(|p| p[k].as_slice());
        let ng = 1 + self.more_geometry.len();
        crate::ops::entered(ops, || {
            let (u, mut r) = self.geometry.forward_packed(ops, lr, pk(0))?;
            if ng > 1 {
                for (k, g) in self.more_geometry.iter().enumerate() {
                    ops.add_assign(&mut r, &g.forward_packed(ops, lr, pk(1 + k))?.1);
                }
                let s = 1.0 / ng as f32;
                r.data.iter_mut().for_each(|v| *v *= s);
            }
            let boundary = self.boundary.probabilities_packed(ops, lr, pk(ng))?;
            let enhance = if enhance {
                self.enhance.probabilities_packed(ops, lr, pk(ng + 1))?
            } else {
                Tensor::zeros(&boundary.shape)
            };
            Ok(NetsOutput { interpolated: u, residual: r, boundary, enhance })
        })
    }
}

/// An [`AnisoCb`] with every conv's weights packed once ([`AnisoCb::packed`]): the same
/// outputs, bit for bit, without repacking the weights for every batch and mirror view. It
/// borrows the bundle, so the weights cannot change under it.
pub struct PackedAnisoCb<'a> {
    model: &'a AnisoCb,
    /// [`Trunk::pack`] of every net, in [`AnisoCb::named_trunks`] order.
    packed: Packing<'a>,
    /// [`AnisoCb::checksum`] of the bundle, computed the first time it is asked for.
    checksum: Checksum<'a>,
}

/// A lazily computed checksum of its own, or one kept by the owner of the bundle.
enum Checksum<'a> {
    Own(OnceLock<u64>),
    Lent(&'a OnceLock<u64>),
}

/// Packed weights made for one [`PackedAnisoCb`], or kept by an owner of the bundle that runs
/// it on every frame ([`crate::pipeline::Upscaler`]: no packing, and no allocation, per frame).
enum Packing<'a> {
    Own(Vec<Vec<PackedConv>>),
    Lent(&'a [Vec<PackedConv>]),
}

impl PackedAnisoCb<'_> {
    /// [`AnisoCb::forward_with`].
    pub fn forward_with(&self, ops: &dyn Ops, lr: &Tensor, enhance: bool) -> Result<NetsOutput> {
        let packed = match &self.packed {
            Packing::Own(p) => p,
            Packing::Lent(p) => *p,
        };
        self.model.run(ops, lr, enhance, Some(packed))
    }

    /// The bundle.
    pub fn model(&self) -> &AnisoCb {
        self.model
    }

    /// [`AnisoCb::checksum`] of the bundle, computed once (the weights cannot change while it is
    /// borrowed): the key under which a device keeps its copy of the weights.
    pub fn checksum(&self) -> u64 {
        let cell = match &self.checksum {
            Checksum::Own(c) => c,
            Checksum::Lent(c) => *c,
        };
        *cell.get_or_init(|| self.model.checksum())
    }
}
