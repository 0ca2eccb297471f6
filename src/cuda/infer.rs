//! `kernels/infer.cu` on the device: the whole bundle's inference for a batch of frames and
//! its mirror views, device-resident ([`super::nets_views`]).
//!
//! ```text
//! x (N,3,H,W) fp32 ─ upload ─┬─ resize (config.upsample) ───────────────────────────► U (N,3,2H,2W)
//!                            └─ views_to_nhwc ─► (V·N,H,W,16) fp16, one input for all Z nets
//!   conv_in ─► blocks (conv1+ReLU, conv2 [+skip in the GeometryNets]) ─► upscale+shuffle ─►
//!   tail.0–2 (+ReLU) ─► tail.3 ─► (Z,V·N,3,2H,2W) fp32 ─ views_average ─► R, Γb, Γe ─ download
//! ```
//! Every layer is one `conv3x3_tc` launch for all nets (grid z = net) and all images of the
//! batch (V views × N frames): 14 conv launches a chunk with the shipped config. Weights are
//! packed once per bundle (fp16, channels padded to 16 with zeros, so padded channels stay 0
//! through bias-free zeros, ReLU and the shuffle) and kept while the same bundle runs.

use std::sync::Arc;

use cudarc::driver::{CudaContext, CudaFunction, CudaSlice, LaunchConfig, PushKernelArg};
use cudarc::nvrtc::{compile_ptx_with_opts, CompileOptions};

use super::device::{grid1, i32_of, Cuda, DResult, DevBuf};
use super::{MirrorView, INFER_KERNELS};
use crate::nn::bundle::PackedAnisoCb;
use crate::nn::config::KERNEL;
use crate::nn::layers::{layout, Layer};
use crate::nn::NetsOutput;
use crate::ops::{Interp, Padding};
use crate::tensor::Tensor;

/// The pixel tile (rows, columns) and the output channels of one `conv3x3_tc` block (`TC_TH`,
/// `TC_TW`, `TC_COUT` in infer.cu). Two tile rows a warp (`TC_MT` = 2) measured as fast as three
/// and four and faster than one on an H200 (0.51, 0.50, 0.51–0.74, 0.58 ms a frame).
const TC_TILE: (usize, usize) = (8, 16);
const TC_COUT: usize = 32;
/// Threads of a `conv3x3_tc` block (four warps, two tile rows each).
const TC_THREADS: u32 = 128;
/// Channels of the fp16 input images (xyz and 13 zeros).
const IN_CP: usize = 16;
/// fp16 values of one HR activation buffer [`Cuda::nets_views`] allows itself (256 MiB): larger
/// batches run in sub-batches.
const HR_BUDGET: usize = 128 << 20;
/// Channels of the last layer's fp32 output (GeometryNet's xyz; the map nets fill one).
const OUT_CO: usize = 3;

/// The kernels of `kernels/infer.cu`.
pub(crate) struct InferKernels {
    f32_to_f16: CudaFunction,
    views_to_nhwc: CudaFunction,
    conv3x3_tc: CudaFunction,
    views_average: CudaFunction,
}

impl InferKernels {
    /// Compiles infer.cu for compute_80 on a GPU of compute capability 8.0 or newer; else (or
    /// where NVRTC or the driver refuses it) the reason, which `bench` prints.
    pub(super) fn load(ctx: &Arc<CudaContext>) -> std::result::Result<InferKernels, String> {
        let (major, minor) = ctx.compute_capability().map_err(|e| format!("compute capability: {e:?}"))?;
        if major < 8 {
            return Err(format!(
                "compute capability {major}.{minor}: the tensor-core path needs 8.0 or newer"
            ));
        }
        let (file, src, _) = INFER_KERNELS;
        let opts = CompileOptions {
            arch: Some("compute_80"),
            name: Some(file.to_string()),
            fmad: Some(true),
            ..Default::default()
        };
        let ptx = compile_ptx_with_opts(src, opts).map_err(|e| format!("NVRTC: kernels/{file}: {e}"))?;
        let m = ctx.load_module(ptx).map_err(|e| format!("loading kernels/{file}: {e:?}"))?;
        let f = |n: &str| m.load_function(n).map_err(|e| format!("kernel `{n}`: {e:?}"));
        Ok(InferKernels {
            f32_to_f16: f("f32_to_f16")?,
            views_to_nhwc: f("views_to_nhwc")?,
            conv3x3_tc: f("conv3x3_tc")?,
            views_average: f("views_average")?,
        })
    }
}

/// How `conv3x3_tc` stores (its `mode`).
#[derive(Clone, Copy, PartialEq, Eq)]
enum Store {
    /// fp16 NHWC, same size.
    Same = 0,
    /// fp16 NHWC, pixel shuffle ×2.
    Shuffle = 1,
    /// fp32 NCHW, the nets' outputs.
    Out = 2,
}

/// One layer of every net: weights (Z, COP, 9·CI) fp16, bias (Z, COP) fp32.
struct TcLayer {
    w: CudaSlice<u16>,
    b: CudaSlice<f32>,
    ci: usize,
    cop: usize,
    store: Store,
}

/// A bundle's weights on the device, packed for `conv3x3_tc`.
pub(crate) struct DeviceBundle {
    /// [`PackedAnisoCb::checksum`] of the bundle these are.
    key: u64,
    /// Nets (GeometryNets, BoundaryNet, EnhanceNet) and how many are GeometryNets.
    nets: usize,
    ng: usize,
    blocks: usize,
    /// Padded trunk channels (a multiple of 16).
    cp: usize,
    pad: i32,
    upsample: Interp,
    /// In [`layout`] order.
    layers: Vec<TcLayer>,
}

impl DeviceBundle {
    /// `None` where the bundle does not fit the kernels: a scale other than 2, or nets of
    /// different configs.
    fn build(cuda: &Cuda, k: &InferKernels, nets: &PackedAnisoCb) -> Option<DResult<DeviceBundle>> {
        let trunks = nets.model().named_trunks();
        let cfg = trunks[0].1.config;
        if cfg.scale != 2 || trunks.iter().any(|(_, t)| t.config != cfg) {
            return None;
        }
        let cp = cfg.channels.next_multiple_of(16);
        let ng = trunks.iter().filter(|(_, t)| t.kind.residual()).count();
        let lay = layout(trunks[0].1.kind, cfg);
        let z = trunks.len();
        let build = || -> DResult<DeviceBundle> {
            let mut layers = Vec::with_capacity(lay.len());
            for &(l, _, _) in &lay {
                let (ci, cop, store) = match l {
                    Layer::ConvIn => (IN_CP, cp, Store::Same),
                    Layer::Upscale => (cp, 4 * cp, Store::Shuffle),
                    Layer::Tail(i) if i + 1 == crate::nn::config::TAIL_CONVS => (cp, 8, Store::Out),
                    _ => (cp, cp, Store::Same),
                };
                let (mut w, mut b) = (vec![0f32; z * cop * 9 * ci], vec![0f32; z * cop]);
                for (z, (_, t)) in trunks.iter().enumerate() {
                    let conv = t.conv(l);
                    let (o_n, i_n) = (conv.weight.shape[0], conv.weight.shape[1]);
                    for o in 0..o_n {
                        // The upscale conv's channel o = c·4 + s keeps its index among 4·cp.
                        b[z * cop + o] = conv.bias.data[o];
                        for i in 0..i_n {
                            for tap in 0..KERNEL * KERNEL {
                                w[(z * cop + o) * 9 * ci + tap * ci + i] =
                                    conv.weight.data[(o * i_n + i) * KERNEL * KERNEL + tap];
                            }
                        }
                    }
                }
                let w32 = cuda.up(&w)?;
                let mut w16 = cuda.stream.alloc_zeros::<u16>(w.len())?;
                let n = w.len() as i64;
                let mut l = cuda.stream.launch_builder(&k.f32_to_f16);
                l.arg(&w32).arg(&mut w16).arg(&n);
                // SAFETY: matches f32_to_f16; both buffers hold n values.
                unsafe { l.launch(grid1(w.len())) }?;
                layers.push(TcLayer { w: w16, b: cuda.up(&b)?, ci, cop, store });
            }
            Ok(DeviceBundle {
                key: nets.checksum(),
                nets: z,
                ng,
                blocks: cfg.blocks,
                cp,
                pad: match cfg.padding {
                    Padding::Zero => 0,
                    Padding::Replicate => 1,
                },
                upsample: cfg.upsample,
                layers,
            })
        };
        Some(build())
    }
}

impl Cuda {
    /// Whether [`Cuda::nets_views`] can run here, or why not.
    pub fn tensor_cores(&self) -> std::result::Result<(), String> {
        self.infer.as_ref().map(|_| ()).map_err(Clone::clone)
    }

    /// Let [`Cuda::nets_views`] run (the default where it can), or not: the nets then run op by
    /// op in fp32 (`--precision fp32`).
    pub fn use_tensor_cores(&self, on: bool) {
        self.tensor_cores_on.store(on, std::sync::atomic::Ordering::Relaxed);
    }

    /// [`super::nets_views`] on this GPU: `None` without infer.cu or for a bundle the kernels do
    /// not fit.
    pub fn nets_views(
        &self,
        nets: &PackedAnisoCb,
        x: &Tensor,
        views: &[MirrorView],
        enhance: bool,
    ) -> Option<NetsOutput> {
        if !self.tensor_cores_on.load(std::sync::atomic::Ordering::Relaxed) {
            return None;
        }
        let k = self.infer.as_ref().ok()?;
        let (n, c, h, w) = x.dims4();
        assert_eq!(c, 3, "nets_views: xyz images, got {c} channels");
        assert!(!views.is_empty() && views.len() <= 4, "nets_views: 1 to 4 views, got {}", views.len());
        let nan = |ch: usize| Tensor::full(&[n, ch, 2 * h, 2 * w], f32::NAN);
        let failed =
            || NetsOutput { interpolated: nan(3), residual: nan(3), boundary: nan(1), enhance: nan(1) };
        let bundle = {
            let mut slot = self.bundle.lock().unwrap_or_else(|p| p.into_inner());
            match slot.as_ref() {
                Some(b) if b.key == nets.checksum() => b.clone(),
                _ => {
                    let b = match DeviceBundle::build(self, k, nets)? {
                        Ok(b) => Arc::new(b),
                        Err(e) => return Some(self.run("nets_views (weights)", failed, || Err(e))),
                    };
                    *slot = Some(b.clone());
                    b
                }
            }
        };
        // Sub-batches of at most ≈ 256 MiB for each fp16 activation buffer at the HR size.
        let per = (HR_BUDGET / (h * w * bundle.nets * views.len() * 4 * bundle.cp)).max(1);
        Some(self.run("nets_views", failed, || {
            if n <= per {
                return self.nets_views_dev(k, &bundle, x, views, enhance);
            }
            let mut all = failed();
            for f0 in (0..n).step_by(per) {
                let m = per.min(n - f0);
                let o = self.nets_views_dev(k, &bundle, &x.slice_batch(f0, m), views, enhance)?;
                for (dst, src) in [
                    (&mut all.interpolated, &o.interpolated),
                    (&mut all.residual, &o.residual),
                    (&mut all.boundary, &o.boundary),
                    (&mut all.enhance, &o.enhance),
                ] {
                    let len = src.len();
                    dst.data[f0 * len / m..(f0 + m) * len / m].copy_from_slice(&src.data);
                }
            }
            Ok(all)
        }))
    }

    fn nets_views_dev(
        &self,
        k: &InferKernels,
        m: &DeviceBundle,
        x: &Tensor,
        views: &[MirrorView],
        enhance: bool,
    ) -> DResult<NetsOutput> {
        let (n, _, h, w) = x.dims4();
        let (hh, hw) = (2 * h, 2 * w);
        let v = views.len();
        let nb = v * n;
        let z = if enhance { m.nets } else { m.nets - 1 };
        let _ = i32_of(z * nb * hh * hw * 4 * m.cp, "nets_views activation size");
        assert!(z * nb <= 65_535, "nets_views: {z} nets x {nb} images exceed the grid's z extent");
        let flags: i32 = views.iter().enumerate().map(|(i, vw)| vw.flags() << (8 * i)).sum();

        let xd = self.upload(x)?;
        let u = self.resize_dev(&xd, hh, hw, m.upsample)?;
        // SAFETY (allocations below): every element is written by the kernel that fills it.
        let mut xv = unsafe { self.stream.alloc::<u16>(nb * h * w * IN_CP) }?;
        {
            let (vi, ni, hi, wi, cpi) = (v as i32, n as i32, h as i32, w as i32, IN_CP as i32);
            let mut l = self.stream.launch_builder(&k.views_to_nhwc);
            l.arg(&xd.buf).arg(&mut xv).arg(&vi).arg(&ni).arg(&hi).arg(&wi).arg(&cpi).arg(&flags);
            // SAFETY: matches views_to_nhwc; xv holds V·N·H·W·16 values.
            unsafe { l.launch(grid1(nb * h * w)) }?;
        }

        let at = |l: Layer| &m.layers[l.index(m.blocks)];
        let lr_act = |cp: usize| z * nb * h * w * cp;
        let conv =
            |layer: &TcLayer,
             x: &CudaSlice<u16>,
             xz: usize,
             skip: Option<&CudaSlice<u16>>,
             y: &mut CudaSlice<u16>,
             (hh_, ww_): (usize, usize),
             relu: bool|
             -> DResult<()> { self.tc_conv(k, m, layer, x, xz, skip, y, nb, hh_, ww_, relu, z) };

        let mut a = unsafe { self.stream.alloc::<u16>(lr_act(m.cp)) }?;
        conv(at(Layer::ConvIn), &xv, 0, None, &mut a, (h, w), false)?;
        let mut r1 = unsafe { self.stream.alloc::<u16>(lr_act(m.cp)) }?;
        let mut a2 = unsafe { self.stream.alloc::<u16>(lr_act(m.cp)) }?;
        let xz = nb * h * w * m.cp;
        for b in 0..m.blocks {
            conv(at(Layer::Conv1(b)), &a, xz, None, &mut r1, (h, w), true)?;
            conv(at(Layer::Conv2(b)), &r1, xz, Some(&a), &mut a2, (h, w), false)?;
            std::mem::swap(&mut a, &mut a2);
        }
        drop((r1, a2));
        let hr_len = z * nb * hh * hw * m.cp;
        let mut t0 = unsafe { self.stream.alloc::<u16>(hr_len) }?;
        let mut t1 = unsafe { self.stream.alloc::<u16>(hr_len) }?;
        conv(at(Layer::Upscale), &a, xz, None, &mut t0, (h, w), false)?;
        drop(a);
        let hz = nb * hh * hw * m.cp;
        let tails = crate::nn::config::TAIL_CONVS;
        for i in 0..tails - 1 {
            conv(at(Layer::Tail(i)), &t0, hz, None, &mut t1, (hh, hw), true)?;
            std::mem::swap(&mut t0, &mut t1);
        }
        drop(t1);
        let mut out = unsafe { self.stream.alloc::<f32>(z * nb * OUT_CO * hh * hw) }?;
        // The last layer writes fp32.
        self.tc_conv(k, m, at(Layer::Tail(tails - 1)), &t0, hz, None, &mut out, nb, hh, hw, false, z)?;
        drop(t0);

        let avg = |z0: usize, z1: usize, ch: usize, neg: bool, sig: bool| -> DResult<DevBuf> {
            let mut y = unsafe { self.stream.alloc::<f32>(n * ch * hh * hw) }?;
            let (z0i, z1i, vi, ni, coi, chi) =
                (z0 as i32, z1 as i32, v as i32, n as i32, OUT_CO as i32, ch as i32);
            let (hi, wi, negi, sigi) = (hh as i32, hw as i32, neg as i32, sig as i32);
            let mut l = self.stream.launch_builder(&k.views_average);
            l.arg(&out).arg(&mut y).arg(&z0i).arg(&z1i).arg(&vi).arg(&ni).arg(&coi).arg(&chi);
            l.arg(&hi).arg(&wi).arg(&flags).arg(&negi).arg(&sigi);
            // SAFETY: matches views_average; out holds Z·V·N·3·(2H)·(2W), y N·ch·(2H)·(2W) values.
            unsafe { l.launch(grid1(n * ch * hh * hw)) }?;
            Ok(DevBuf { shape: vec![n, ch, hh, hw], buf: y })
        };
        let r = avg(0, m.ng, 3, true, false)?;
        let gb = avg(m.ng, m.ng + 1, 1, false, true)?;
        let enhance = if enhance {
            self.download(&avg(m.ng + 1, m.ng + 2, 1, false, true)?)?
        } else {
            Tensor::zeros(&[n, 1, hh, hw])
        };
        Ok(NetsOutput {
            interpolated: self.download(&u)?,
            residual: self.download(&r)?,
            boundary: self.download(&gb)?,
            enhance,
        })
    }

    /// One `conv3x3_tc` launch over `nets` nets with `layer`'s store: into fp16 `y` (`Same`,
    /// `Shuffle`) or fp32 `y` (`Out`, the nets' outputs (nets, NB, 3, H, W)).
    #[allow(clippy::too_many_arguments)]
    fn tc_conv<T: cudarc::driver::DeviceRepr>(
        &self,
        k: &InferKernels,
        m: &DeviceBundle,
        layer: &TcLayer,
        x: &CudaSlice<u16>,
        xz: usize,
        skip: Option<&CudaSlice<u16>>,
        y: &mut CudaSlice<T>,
        nb: usize,
        h: usize,
        w: usize,
        relu: bool,
        nets: usize,
    ) -> DResult<()> {
        let dummy;
        let (sk, nskip) = match skip {
            Some(s) => (s, m.ng as i32),
            None => {
                dummy = self.stream.alloc_zeros::<u16>(2)?;
                (&dummy, 0)
            }
        };
        let mut l = self.stream.launch_builder(&k.conv3x3_tc);
        let xz = xz as i64;
        let (nbi, hi, wi, cii, copi) = (nb as i32, h as i32, w as i32, layer.ci as i32, layer.cop as i32);
        let (mode, relui, ngi) = (layer.store as i32, relu as i32, m.ng as i32);
        let (coi, cg, cm) = (OUT_CO as i32, 3i32, 1i32);
        l.arg(x).arg(&xz).arg(&layer.w).arg(&layer.b).arg(sk).arg(y);
        l.arg(&nbi).arg(&hi).arg(&wi).arg(&cii).arg(&copi).arg(&m.pad).arg(&mode).arg(&relui);
        l.arg(&nskip).arg(&ngi).arg(&coi).arg(&cg).arg(&cm);
        // SAFETY: matches conv3x3_tc; x holds nets·NB·H·W·CI values (or NB·H·W·CI with xz = 0),
        // y nets·NB·H·W·COP fp16 (Same), nets·NB·2H·2W·COP/4 fp16 (Shuffle) or nets·NB·3·H·W
        // fp32 (Out), as the caller allocated for the layer's store; skip is like y.
        unsafe { l.launch(tc_grid(nb, h, w, layer.cop, nets)) }?;
        Ok(())
    }
}

/// `conv3x3_tc`'s grid: pixel tiles of an image, output channel blocks, nets × images.
fn tc_grid(nb: usize, h: usize, w: usize, cop: usize, nets: usize) -> LaunchConfig {
    let tiles = h.div_ceil(TC_TILE.0) * w.div_ceil(TC_TILE.1);
    LaunchConfig {
        grid_dim: (tiles as u32, cop.div_ceil(TC_COUT) as u32, (nets * nb) as u32),
        block_dim: (TC_THREADS, 1, 1),
        shared_mem_bytes: 0,
    }
}
