//! The GPU op table: `cudarc` (driver API, dynamically loaded) + NVRTC-compiled kernels.
//!
//! Every kernel is written out in `kernels/*.cu` with its shapes and index math; this file
//! only checks shapes (the GPU would read out of bounds silently), moves data, picks launch
//! geometry and launches. Results are deterministic: no kernel uses atomics, and every
//! reduction runs in a fixed order that depends only on the shapes.
//!
//! Errors: construction returns [`Error::Device`]. Once constructed, a driver failure inside an
//! op (out of memory, a lost device) panics with the driver's message, because the [`Ops`]
//! methods, like the CPU ones, have no error channel; shape mismatches panic like the CPU path.

use std::sync::{Arc, Mutex, MutexGuard};

use cudarc::driver::{
    CudaContext, CudaFunction, CudaModule, CudaSlice, CudaStream, DriverError, LaunchConfig, PushKernelArg,
};
use cudarc::nvrtc::{compile_ptx_with_opts, CompileOptions};

use super::taps::{axis_taps, transpose};
use super::KERNELS;
use crate::error::{Error, Result};
use crate::ops::{AdamParams, Interp, Ops, Padding};
use crate::tensor::Tensor;

type DResult<T> = std::result::Result<T, DriverError>;

/// Threads per block for the 1-D and tiled kernels (the tiled kernels require exactly 256).
const THREADS: u32 = 256;
/// Cap on blocks of the grid-stride kernels.
const MAX_BLOCKS: usize = 8192;
/// Output tile edge of the implicit-GEMM conv kernels, and their reduction slice.
const TILE: usize = 64;
const BK: usize = 16;
/// Blocks the weight-gradient kernel aims for (split over the pixel reduction).
const WGRAD_TARGET_BLOCKS: usize = 1024;

/// The loaded kernels, one field per `extern "C" __global__` function.
struct Kernels {
    conv2d_fwd: CudaFunction,
    conv2d_wgrad: CudaFunction,
    conv2d_wgrad_reduce: CudaFunction,
    conv2d_dgrad_padded: CudaFunction,
    conv2d_dgrad_fold: CudaFunction,
    conv2d_bias_grad: CudaFunction,
    relu_fwd: CudaFunction,
    relu_bwd: CudaFunction,
    add_assign: CudaFunction,
    sigmoid_fwd: CudaFunction,
    pixel_shuffle: CudaFunction,
    pixel_unshuffle: CudaFunction,
    resize_fwd: CudaFunction,
    resize_bwd: CudaFunction,
    mse_loss: CudaFunction,
    bce_logits_loss: CudaFunction,
    adam_step: CudaFunction,
}

/// A device buffer with its NCHW (or any) shape: the unit of a device-resident pipeline.
/// The buffer may be longer than the shape's element count (never shorter).
pub struct DevBuf {
    pub shape: Vec<usize>,
    pub buf: CudaSlice<f32>,
}

impl DevBuf {
    pub fn len(&self) -> usize {
        self.shape.iter().product()
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The CUDA op table (one GPU, one stream). Calls are serialized by an internal lock.
pub struct Cuda {
    ctx: Arc<CudaContext>,
    stream: Arc<CudaStream>,
    k: Kernels,
    device_name: String,
    lock: Mutex<()>,
}

impl std::fmt::Debug for Cuda {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Cuda({}, ordinal {})", self.device_name, self.ctx.ordinal())
    }
}

fn panic_text(p: Box<dyn std::any::Any + Send>) -> String {
    if let Some(s) = p.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = p.downcast_ref::<String>() {
        s.clone()
    } else {
        "unknown panic".to_string()
    }
}

fn driver_err(what: &str, e: DriverError) -> Error {
    Error::device(format!("{what}: {e:?}"))
}

/// Abort an op on a driver failure (the [`Ops`] methods have no error channel).
fn fail(op: &str, e: DriverError) -> ! {
    panic!("CUDA {op} failed: {e:?}")
}

/// Grid for a 1-D grid-stride kernel over `n` (> 0) items.
fn grid1(n: usize) -> LaunchConfig {
    let blocks = n.div_ceil(THREADS as usize).clamp(1, MAX_BLOCKS);
    LaunchConfig { grid_dim: (blocks as u32, 1, 1), block_dim: (THREADS, 1, 1), shared_mem_bytes: 0 }
}

fn i32_of(v: usize, what: &str) -> i32 {
    i32::try_from(v).unwrap_or_else(|_| panic!("CUDA: {what} = {v} exceeds the kernels' 32-bit index range"))
}

fn pad_mode(pad: Padding) -> i32 {
    match pad {
        Padding::Zero => 0,
        Padding::Replicate => 1,
    }
}

impl Cuda {
    /// The first GPU. See [`Cuda::with_ordinal`].
    pub fn new() -> Result<Cuda> {
        Cuda::with_ordinal(0)
    }

    /// GPU number `ordinal`: checks that the driver and NVRTC libraries can be loaded (cudarc
    /// would panic without them), initialises the driver, creates the context and compiles the
    /// embedded kernels. Every failure is an [`Error::Device`] naming what is missing.
    pub fn with_ordinal(ordinal: usize) -> Result<Cuda> {
        // SAFETY: these only try to dlopen the libraries by their usual names.
        if !unsafe { cudarc::driver::sys::is_culib_present() } {
            return Err(Error::device(
                "no CUDA driver (libcuda.so) found: install the NVIDIA driver (or add its directory \
                 to LD_LIBRARY_PATH), or use --device cpu",
            ));
        }
        if !unsafe { cudarc::nvrtc::sys::is_culib_present() } {
            return Err(Error::device(
                "no NVRTC runtime compiler (libnvrtc.so) found: install the CUDA NVRTC library \
                 (e.g. the cuda-nvrtc-12-x package) or add its directory to LD_LIBRARY_PATH, or use --device cpu",
            ));
        }
        // Belt and braces: cudarc panics where a library lacks a symbol it expects.
        std::panic::catch_unwind(move || Cuda::init(ordinal))
            .unwrap_or_else(|p| Err(Error::device(format!("CUDA initialisation failed: {}", panic_text(p)))))
    }

    fn init(ordinal: usize) -> Result<Cuda> {
        use cudarc::driver::result as dr;
        use cudarc::driver::sys::CUresult;
        match dr::init() {
            Ok(()) => {}
            Err(DriverError(CUresult::CUDA_ERROR_NO_DEVICE)) => {
                return Err(Error::device(
                    "no CUDA device: the driver is installed but finds no GPU; use --device cpu",
                ))
            }
            Err(e) => return Err(driver_err("cannot initialise the CUDA driver (cuInit)", e)),
        }
        let count = dr::device::get_count().map_err(|e| driver_err("cannot count CUDA devices", e))?;
        if count <= 0 {
            return Err(Error::device(
                "no CUDA device: the driver is installed but finds no GPU; use --device cpu",
            ));
        }
        if ordinal >= count as usize {
            return Err(Error::device(format!("no CUDA device {ordinal}: this machine has {count}")));
        }
        let ctx = CudaContext::new(ordinal).map_err(|e| driver_err("cannot create a CUDA context", e))?;
        let device_name = ctx.name().unwrap_or_else(|_| format!("CUDA device {ordinal}"));
        let stream = ctx.default_stream();

        let mut modules: Vec<Arc<CudaModule>> = Vec::with_capacity(KERNELS.len());
        for (file, src, _) in KERNELS {
            // fmad off: the element-wise kernels then round like the CPU path (the conv kernels
            // use explicit fmaf either way).
            let opts =
                CompileOptions { fmad: Some(false), name: Some(file.to_string()), ..Default::default() };
            let ptx = compile_ptx_with_opts(src, opts)
                .map_err(|e| Error::device(format!("NVRTC could not compile kernels/{file}: {e}")))?;
            let module = ctx.load_module(ptx).map_err(|e| {
                driver_err(
                    &format!("cannot load kernels/{file} (is libnvrtc newer than the driver supports?)"),
                    e,
                )
            })?;
            modules.push(module);
        }
        let f = |name: &str| -> Result<CudaFunction> {
            let m = KERNELS
                .iter()
                .position(|(_, _, names)| names.contains(&name))
                .ok_or_else(|| Error::device(format!("kernel `{name}` is not listed in cuda::KERNELS")))?;
            modules[m].load_function(name).map_err(|e| driver_err(&format!("kernel `{name}` missing"), e))
        };
        let k = Kernels {
            conv2d_fwd: f("conv2d_fwd")?,
            conv2d_wgrad: f("conv2d_wgrad")?,
            conv2d_wgrad_reduce: f("conv2d_wgrad_reduce")?,
            conv2d_dgrad_padded: f("conv2d_dgrad_padded")?,
            conv2d_dgrad_fold: f("conv2d_dgrad_fold")?,
            conv2d_bias_grad: f("conv2d_bias_grad")?,
            relu_fwd: f("relu_fwd")?,
            relu_bwd: f("relu_bwd")?,
            add_assign: f("add_assign")?,
            sigmoid_fwd: f("sigmoid_fwd")?,
            pixel_shuffle: f("pixel_shuffle")?,
            pixel_unshuffle: f("pixel_unshuffle")?,
            resize_fwd: f("resize_fwd")?,
            resize_bwd: f("resize_bwd")?,
            mse_loss: f("mse_loss")?,
            bce_logits_loss: f("bce_logits_loss")?,
            adam_step: f("adam_step")?,
        };
        Ok(Cuda { ctx, stream, k, device_name, lock: Mutex::new(()) })
    }

    /// The GPU's name as the driver reports it.
    pub fn device_name(&self) -> &str {
        &self.device_name
    }

    fn guard(&self) -> MutexGuard<'_, ()> {
        self.lock.lock().unwrap_or_else(|p| p.into_inner())
    }

    // ---- transfers (the seam: everything below works on device buffers) ----

    /// Copy host values to a new device buffer of at least one element (the driver rejects
    /// empty allocations).
    fn up<T: cudarc::driver::DeviceRepr + cudarc::driver::ValidAsZeroBits>(
        &self,
        v: &[T],
    ) -> DResult<CudaSlice<T>> {
        let mut d = self.stream.alloc_zeros::<T>(v.len().max(1))?;
        if !v.is_empty() {
            self.stream.memcpy_htod(v, &mut d)?;
        }
        Ok(d)
    }

    /// Copy the first `n` values of a device buffer to the host (waits for the stream).
    fn down<T: cudarc::driver::DeviceRepr + Default + Clone>(
        &self,
        d: &CudaSlice<T>,
        n: usize,
    ) -> DResult<Vec<T>> {
        let mut v = vec![T::default(); n];
        if n > 0 {
            self.stream.memcpy_dtoh(&d.slice(0..n), &mut v)?;
        }
        self.stream.synchronize()?;
        Ok(v)
    }

    /// Upload a tensor.
    pub fn upload(&self, t: &Tensor) -> DResult<DevBuf> {
        Ok(DevBuf { shape: t.shape.clone(), buf: self.up(&t.data)? })
    }

    /// Download a device buffer as a tensor.
    pub fn download(&self, d: &DevBuf) -> DResult<Tensor> {
        Ok(Tensor { shape: d.shape.clone(), data: self.down(&d.buf, d.len())? })
    }

    /// A zero-filled device buffer of `shape`.
    pub fn zeros(&self, shape: &[usize]) -> DResult<DevBuf> {
        let n: usize = shape.iter().product();
        Ok(DevBuf { shape: shape.to_vec(), buf: self.stream.alloc_zeros::<f32>(n.max(1))? })
    }

    // ---- device-resident ops ----

    /// y = conv2d(x, w, b); x (N, C, H, W), w (O, C, KH, KW), b (O) → (N, O, H, W).
    pub fn conv2d_dev(&self, x: &DevBuf, w: &DevBuf, b: Option<&DevBuf>, pad: Padding) -> DResult<DevBuf> {
        let [n, c, h, wd] = dims4(&x.shape, "conv2d x");
        let [o, c2, kh, kw] = dims4(&w.shape, "conv2d w");
        assert_eq!(c, c2, "conv2d: x has {c} channels, weight expects {c2}");
        assert!(kh % 2 == 1 && kw % 2 == 1, "conv2d: odd kernels only, got {kh}x{kw}");
        if let Some(b) = b {
            assert_eq!(b.len(), o, "conv2d: bias has {} values for {o} output channels", b.len());
        }
        let mut y = self.zeros(&[n, o, h, wd])?;
        let p = n * h * wd;
        if y.is_empty() {
            return Ok(y);
        }
        let _ = i32_of(n * c.max(o) * h * wd, "conv2d tensor size");
        let dummy;
        let bias = match b {
            Some(b) => &b.buf,
            None => {
                dummy = self.stream.alloc_zeros::<f32>(1)?;
                &dummy
            }
        };
        let (ni, ci, hi, wi, oi, khi, kwi) =
            (n as i32, c as i32, h as i32, wd as i32, o as i32, kh as i32, kw as i32);
        let (pm, hb) = (pad_mode(pad), b.is_some() as i32);
        let cfg = LaunchConfig {
            grid_dim: (p.div_ceil(TILE) as u32, o.div_ceil(TILE) as u32, 1),
            block_dim: (THREADS, 1, 1),
            shared_mem_bytes: 0,
        };
        let mut l = self.stream.launch_builder(&self.k.conv2d_fwd);
        l.arg(&x.buf).arg(&w.buf).arg(bias).arg(&mut y.buf);
        l.arg(&ni).arg(&ci).arg(&hi).arg(&wi).arg(&oi).arg(&khi).arg(&kwi).arg(&pm).arg(&hb);
        // SAFETY: argument list matches conv2d_fwd; buffers hold the sizes the shapes imply.
        unsafe { l.launch(cfg) }?;
        Ok(y)
    }

    /// Adds the conv2d gradients into `dx` (if given), `dw`, `db` (if given).
    #[allow(clippy::too_many_arguments)]
    pub fn conv2d_backward_dev(
        &self,
        x: &DevBuf,
        w: &DevBuf,
        dy: &DevBuf,
        pad: Padding,
        dx: Option<&mut DevBuf>,
        dw: &mut DevBuf,
        db: Option<&mut DevBuf>,
    ) -> DResult<()> {
        let [n, c, h, wd] = dims4(&x.shape, "conv2d_backward x");
        let [o, c2, kh, kw] = dims4(&w.shape, "conv2d_backward w");
        assert_eq!(c, c2, "conv2d_backward: x has {c} channels, weight expects {c2}");
        assert!(kh % 2 == 1 && kw % 2 == 1, "conv2d_backward: odd kernels only, got {kh}x{kw}");
        assert_eq!(dy.shape, [n, o, h, wd], "conv2d_backward: dy shape");
        assert_eq!(dw.shape, w.shape, "conv2d_backward: dw shape");
        if let Some(dx) = dx.as_deref() {
            assert_eq!(dx.shape, x.shape, "conv2d_backward: dx shape");
        }
        if let Some(db) = db.as_deref() {
            assert_eq!(db.len(), o, "conv2d_backward: db has {} values for {o} channels", db.len());
        }
        if dy.is_empty() {
            return Ok(()); // every gradient gets += 0
        }
        let (hp, wp) = (h + kh - 1, wd + kw - 1);
        let _ = i32_of(n * c.max(o) * hp * wp, "conv2d tensor size");
        let (ni, ci, hi, wi, oi, khi, kwi) =
            (n as i32, c as i32, h as i32, wd as i32, o as i32, kh as i32, kw as i32);
        let pm = pad_mode(pad);
        let p = n * h * wd;
        let kk = c * kh * kw;

        // Weight gradient: split-K partials, then an ordered sum into dw.
        if kk > 0 {
            let tiles = kk.div_ceil(TILE) * o.div_ceil(TILE);
            let want_z = WGRAD_TARGET_BLOCKS.div_ceil(tiles).max(1);
            let chunk = p.div_ceil(want_z).next_multiple_of(BK).max(16 * BK);
            let z = p.div_ceil(chunk);
            let mut part = self.stream.alloc_zeros::<f32>(z * o * kk)?;
            let (chunk_i, z_i, len) = (chunk as i32, z as i32, (o * kk) as i64);
            let cfg = LaunchConfig {
                grid_dim: (kk.div_ceil(TILE) as u32, o.div_ceil(TILE) as u32, z as u32),
                block_dim: (THREADS, 1, 1),
                shared_mem_bytes: 0,
            };
            let mut l = self.stream.launch_builder(&self.k.conv2d_wgrad);
            l.arg(&x.buf).arg(&dy.buf).arg(&mut part);
            l.arg(&ni).arg(&ci).arg(&hi).arg(&wi).arg(&oi).arg(&khi).arg(&kwi).arg(&pm).arg(&chunk_i);
            // SAFETY: matches conv2d_wgrad; part holds z·O·C·KH·KW values.
            unsafe { l.launch(cfg) }?;
            let mut l = self.stream.launch_builder(&self.k.conv2d_wgrad_reduce);
            l.arg(&part).arg(&mut dw.buf).arg(&z_i).arg(&len);
            // SAFETY: matches conv2d_wgrad_reduce; dw holds O·C·KH·KW values.
            unsafe { l.launch(grid1(o * kk)) }?;
        }

        // Input gradient: full correlation onto the padded grid, then fold onto dx.
        if let Some(dx) = dx {
            if c > 0 {
                let q = n * hp * wp;
                let mut dxp = self.stream.alloc_zeros::<f32>(n * c * hp * wp)?;
                let cfg = LaunchConfig {
                    grid_dim: (q.div_ceil(TILE) as u32, c.div_ceil(TILE) as u32, 1),
                    block_dim: (THREADS, 1, 1),
                    shared_mem_bytes: 0,
                };
                let mut l = self.stream.launch_builder(&self.k.conv2d_dgrad_padded);
                l.arg(&w.buf).arg(&dy.buf).arg(&mut dxp);
                l.arg(&ni).arg(&ci).arg(&hi).arg(&wi).arg(&oi).arg(&khi).arg(&kwi);
                // SAFETY: matches conv2d_dgrad_padded; dxp holds N·C·Hp·Wp values.
                unsafe { l.launch(cfg) }?;
                let nc = (n * c) as i32;
                let mut l = self.stream.launch_builder(&self.k.conv2d_dgrad_fold);
                l.arg(&dxp).arg(&mut dx.buf).arg(&nc).arg(&hi).arg(&wi).arg(&khi).arg(&kwi).arg(&pm);
                // SAFETY: matches conv2d_dgrad_fold; dx holds N·C·H·W values.
                unsafe { l.launch(grid1(n * c * h * wd)) }?;
            }
        }

        if let Some(db) = db {
            let hw = (h * wd) as i32;
            let cfg =
                LaunchConfig { grid_dim: (o as u32, 1, 1), block_dim: (THREADS, 1, 1), shared_mem_bytes: 0 };
            let mut l = self.stream.launch_builder(&self.k.conv2d_bias_grad);
            l.arg(&dy.buf).arg(&mut db.buf).arg(&ni).arg(&oi).arg(&hw);
            // SAFETY: matches conv2d_bias_grad (256 threads, one block per output channel).
            unsafe { l.launch(cfg) }?;
        }
        Ok(())
    }

    /// Launch a flat kernel `f(a, b, n)` (element-wise, `n` > 0 elements).
    fn flat2(&self, f: &CudaFunction, a: &CudaSlice<f32>, b: &mut CudaSlice<f32>, n: usize) -> DResult<()> {
        let nn = n as i64;
        let mut l = self.stream.launch_builder(f);
        l.arg(a).arg(b).arg(&nn);
        // SAFETY: (const float*, float*, long long) kernels; both buffers hold ≥ n values.
        unsafe { l.launch(grid1(n)) }?;
        Ok(())
    }

    pub fn relu_dev(&self, x: &DevBuf) -> DResult<DevBuf> {
        let mut y = self.zeros(&x.shape)?;
        if !x.is_empty() {
            self.flat2(&self.k.relu_fwd, &x.buf, &mut y.buf, x.len())?;
        }
        Ok(y)
    }

    pub fn sigmoid_dev(&self, x: &DevBuf) -> DResult<DevBuf> {
        let mut y = self.zeros(&x.shape)?;
        if !x.is_empty() {
            self.flat2(&self.k.sigmoid_fwd, &x.buf, &mut y.buf, x.len())?;
        }
        Ok(y)
    }

    /// dx += dy ⊙ [x > 0]
    pub fn relu_backward_dev(&self, x: &DevBuf, dy: &DevBuf, dx: &mut DevBuf) -> DResult<()> {
        assert_eq!(x.shape, dy.shape, "relu_backward: x and dy shapes differ");
        assert_eq!(x.shape, dx.shape, "relu_backward: x and dx shapes differ");
        let n = x.len();
        if n == 0 {
            return Ok(());
        }
        let nn = n as i64;
        let mut l = self.stream.launch_builder(&self.k.relu_bwd);
        l.arg(&x.buf).arg(&dy.buf).arg(&mut dx.buf).arg(&nn);
        // SAFETY: matches relu_bwd; all three buffers hold n values.
        unsafe { l.launch(grid1(n)) }?;
        Ok(())
    }

    /// a += b
    pub fn add_assign_dev(&self, a: &mut DevBuf, b: &DevBuf) -> DResult<()> {
        assert_eq!(a.shape, b.shape, "add_assign: shapes differ");
        let n = a.len();
        if n == 0 {
            return Ok(());
        }
        let nn = n as i64;
        let mut l = self.stream.launch_builder(&self.k.add_assign);
        l.arg(&mut a.buf).arg(&b.buf).arg(&nn);
        // SAFETY: matches add_assign; both buffers hold n values.
        unsafe { l.launch(grid1(n)) }?;
        Ok(())
    }

    /// (N, C·r², H, W) → (N, C, H·r, W·r)
    pub fn pixel_shuffle_dev(&self, x: &DevBuf, r: usize) -> DResult<DevBuf> {
        let [n, cr2, h, w] = dims4(&x.shape, "pixel_shuffle x");
        assert!(r >= 1 && cr2 % (r * r) == 0, "pixel_shuffle: {cr2} channels not divisible by r²={}", r * r);
        let c = cr2 / (r * r);
        let mut y = self.zeros(&[n, c, h * r, w * r])?;
        if y.is_empty() {
            return Ok(y);
        }
        let _ = i32_of(cr2 * h * r * w * r, "pixel_shuffle plane size");
        let (ni, ci, hi, wi, ri) = (n as i32, c as i32, h as i32, w as i32, r as i32);
        let cfg = grid1(y.len());
        let mut l = self.stream.launch_builder(&self.k.pixel_shuffle);
        l.arg(&x.buf).arg(&mut y.buf).arg(&ni).arg(&ci).arg(&hi).arg(&wi).arg(&ri);
        // SAFETY: matches pixel_shuffle (C = output channels).
        unsafe { l.launch(cfg) }?;
        Ok(y)
    }

    /// (N, C, H·r, W·r) → (N, C·r², H, W)
    pub fn pixel_unshuffle_dev(&self, x: &DevBuf, r: usize) -> DResult<DevBuf> {
        let [n, c, hr, wr] = dims4(&x.shape, "pixel_unshuffle x");
        assert!(r >= 1 && hr % r == 0 && wr % r == 0, "pixel_unshuffle: {hr}x{wr} not divisible by r={r}");
        let (h, w) = (hr / r, wr / r);
        let mut y = self.zeros(&[n, c * r * r, h, w])?;
        if y.is_empty() {
            return Ok(y);
        }
        let _ = i32_of(c * r * r * hr * wr, "pixel_unshuffle plane size");
        let (ni, ci, hi, wi, ri) = (n as i32, c as i32, h as i32, w as i32, r as i32);
        let cfg = grid1(y.len());
        let mut l = self.stream.launch_builder(&self.k.pixel_unshuffle);
        l.arg(&x.buf).arg(&mut y.buf).arg(&ni).arg(&ci).arg(&hi).arg(&wi).arg(&ri);
        // SAFETY: matches pixel_unshuffle (C = input channels, H, W = output size).
        unsafe { l.launch(cfg) }?;
        Ok(y)
    }

    /// (N, C, H, W) → (N, C, out_h, out_w), align corners.
    pub fn resize_dev(&self, x: &DevBuf, out_h: usize, out_w: usize, mode: Interp) -> DResult<DevBuf> {
        let [n, c, h, w] = dims4(&x.shape, "resize x");
        assert!(h > 0 && w > 0, "resize: empty input {:?}", x.shape);
        let mut y = self.zeros(&[n, c, out_h, out_w])?;
        if y.is_empty() {
            return Ok(y);
        }
        let _ = i32_of(h.max(out_h) * w.max(out_w), "resize plane size");
        let (ty, tx) = (axis_taps(h, out_h, mode), axis_taps(w, out_w, mode));
        let (ty_i, ty_w, tx_i, tx_w) =
            (self.up(&ty.idx)?, self.up(&ty.w)?, self.up(&tx.idx)?, self.up(&tx.w)?);
        let (nc, hi, wi, ohi, owi) = ((n * c) as i64, h as i32, w as i32, out_h as i32, out_w as i32);
        let (ky, kx) = (ty.k as i32, tx.k as i32);
        let cfg = grid1(y.len());
        let mut l = self.stream.launch_builder(&self.k.resize_fwd);
        l.arg(&x.buf).arg(&mut y.buf).arg(&nc).arg(&hi).arg(&wi).arg(&ohi).arg(&owi);
        l.arg(&ty_i).arg(&ty_w).arg(&ky).arg(&tx_i).arg(&tx_w).arg(&kx);
        // SAFETY: matches resize_fwd; taps hold out·k entries with indices < in.
        unsafe { l.launch(cfg) }?;
        Ok(y)
    }

    /// dx (N, C, H, W) += resizeᵀ(dy (N, C, out_h, out_w)).
    pub fn resize_backward_dev(&self, dy: &DevBuf, mode: Interp, dx: &mut DevBuf) -> DResult<()> {
        let [n, c, out_h, out_w] = dims4(&dy.shape, "resize_backward dy");
        let [n2, c2, h, w] = dims4(&dx.shape, "resize_backward dx");
        assert_eq!((n, c), (n2, c2), "resize_backward: dy {:?} vs dx {:?}", dy.shape, dx.shape);
        if dy.is_empty() || dx.is_empty() {
            return Ok(());
        }
        let _ = i32_of(h.max(out_h) * w.max(out_w) * 4, "resize plane size");
        let cy = transpose(&axis_taps(h, out_h, mode), h);
        let cx = transpose(&axis_taps(w, out_w, mode), w);
        let (cy_p, cy_o, cy_w) = (self.up(&cy.ptr)?, self.up(&cy.o)?, self.up(&cy.w)?);
        let (cx_p, cx_o, cx_w) = (self.up(&cx.ptr)?, self.up(&cx.o)?, self.up(&cx.w)?);
        let (nc, hi, wi, ohi, owi) = ((n * c) as i64, h as i32, w as i32, out_h as i32, out_w as i32);
        let cfg = grid1(dx.len());
        let mut l = self.stream.launch_builder(&self.k.resize_bwd);
        l.arg(&dy.buf).arg(&mut dx.buf).arg(&nc).arg(&hi).arg(&wi).arg(&ohi).arg(&owi);
        l.arg(&cy_p).arg(&cy_o).arg(&cy_w).arg(&cx_p).arg(&cx_o).arg(&cx_w);
        // SAFETY: matches resize_bwd; CSR pointers hold in + 1 entries, outputs < out.
        unsafe { l.launch(cfg) }?;
        Ok(())
    }

    /// A loss kernel `(pred, target, grad, part, n, nf, [pos_weight])`: (mean loss, gradient).
    fn loss_dev(
        &self,
        f: &CudaFunction,
        p: &DevBuf,
        t: &DevBuf,
        pos_weight: Option<f32>,
    ) -> DResult<(f32, DevBuf)> {
        let n = p.len();
        let mut g = self.zeros(&p.shape)?;
        if n == 0 {
            return Ok((0.0, g));
        }
        let cfg = grid1(n);
        let blocks = cfg.grid_dim.0 as usize;
        let mut part = self.stream.alloc_zeros::<f64>(blocks)?;
        let (nn, nf) = (n as i64, n as f32);
        let pw = pos_weight.unwrap_or(1.0);
        let mut l = self.stream.launch_builder(f);
        l.arg(&p.buf).arg(&t.buf).arg(&mut g.buf).arg(&mut part).arg(&nn).arg(&nf);
        if pos_weight.is_some() {
            l.arg(&pw);
        }
        // SAFETY: matches mse_loss / bce_logits_loss; part holds one double per block, 256 threads.
        unsafe { l.launch(cfg) }?;
        let sum: f64 = self.down(&part, blocks)?.iter().sum();
        Ok(((sum / n as f64) as f32, g))
    }

    pub fn mse_dev(&self, pred: &DevBuf, target: &DevBuf) -> DResult<(f32, DevBuf)> {
        assert_eq!(pred.shape, target.shape, "mse: prediction {:?} vs target {:?}", pred.shape, target.shape);
        self.loss_dev(&self.k.mse_loss, pred, target, None)
    }

    pub fn bce_with_logits_dev(
        &self,
        z: &DevBuf,
        target: &DevBuf,
        pos_weight: f32,
    ) -> DResult<(f32, DevBuf)> {
        assert_eq!(
            z.shape, target.shape,
            "bce_with_logits: prediction {:?} vs target {:?}",
            z.shape, target.shape
        );
        self.loss_dev(&self.k.bce_logits_loss, z, target, Some(pos_weight))
    }

    /// One Adam step on device buffers of `n` values each. `step` counts from 1.
    #[allow(clippy::too_many_arguments)]
    pub fn adam_update_dev(
        &self,
        p: &mut CudaSlice<f32>,
        g: &CudaSlice<f32>,
        m: &mut CudaSlice<f32>,
        v: &mut CudaSlice<f32>,
        n: usize,
        step: u64,
        hp: &AdamParams,
    ) -> DResult<()> {
        assert!(step >= 1, "adam_update: step counts from 1");
        assert!(
            p.len() >= n && g.len() >= n && m.len() >= n && v.len() >= n,
            "adam_update: buffers shorter than {n}"
        );
        if n == 0 {
            return Ok(());
        }
        // Bias corrections as the CPU path computes them: f64, rounded once.
        let t = step.min(i32::MAX as u64) as i32;
        let c1 = (1.0 - (hp.beta1 as f64).powi(t)) as f32;
        let c2 = (1.0 - (hp.beta2 as f64).powi(t)) as f32;
        let nn = n as i64;
        let mut l = self.stream.launch_builder(&self.k.adam_step);
        l.arg(p).arg(g).arg(m).arg(v).arg(&nn);
        l.arg(&hp.lr).arg(&hp.beta1).arg(&hp.beta2).arg(&hp.eps).arg(&c1).arg(&c2);
        // SAFETY: matches adam_step; all buffers hold ≥ n values.
        unsafe { l.launch(grid1(n)) }?;
        Ok(())
    }

    /// Run `f` under the lock; a driver failure aborts the op with the driver's message.
    fn run<T>(&self, op: &str, f: impl FnOnce() -> DResult<T>) -> T {
        let _g = self.guard();
        f().unwrap_or_else(|e| fail(op, e))
    }
}

fn dims4(shape: &[usize], what: &str) -> [usize; 4] {
    assert_eq!(shape.len(), 4, "{what}: expected (N, C, H, W), got shape {shape:?}");
    [shape[0], shape[1], shape[2], shape[3]]
}

/// Copy a device result into an existing host tensor (same length).
fn store(dst: &mut Tensor, src: Tensor) {
    debug_assert_eq!(dst.data.len(), src.data.len());
    dst.data = src.data;
}

/// The [`Ops`] table over host tensors: each call uploads its inputs, runs the kernels and
/// downloads its outputs (see the module docs for the transfer cost).
impl Ops for Cuda {
    fn name(&self) -> &'static str {
        "cuda"
    }

    fn conv2d(&self, x: &Tensor, w: &Tensor, b: Option<&Tensor>, pad: Padding) -> Tensor {
        self.run("conv2d", || {
            let (xd, wd) = (self.upload(x)?, self.upload(w)?);
            let bd = b.map(|b| self.upload(b)).transpose()?;
            let y = self.conv2d_dev(&xd, &wd, bd.as_ref(), pad)?;
            self.download(&y)
        })
    }

    fn conv2d_backward(
        &self,
        x: &Tensor,
        w: &Tensor,
        dy: &Tensor,
        pad: Padding,
        dx: Option<&mut Tensor>,
        dw: &mut Tensor,
        db: Option<&mut Tensor>,
    ) {
        self.run("conv2d_backward", || {
            let (xd, wd, dyd) = (self.upload(x)?, self.upload(w)?, self.upload(dy)?);
            let mut dwd = self.upload(dw)?;
            let mut dxd = dx.as_deref().map(|t| self.upload(t)).transpose()?;
            let mut dbd = db.as_deref().map(|t| self.upload(t)).transpose()?;
            self.conv2d_backward_dev(&xd, &wd, &dyd, pad, dxd.as_mut(), &mut dwd, dbd.as_mut())?;
            store(dw, self.download(&dwd)?);
            if let (Some(dx), Some(d)) = (dx, dxd) {
                store(dx, self.download(&d)?);
            }
            if let (Some(db), Some(d)) = (db, dbd) {
                store(db, self.download(&d)?);
            }
            Ok(())
        })
    }

    fn relu(&self, x: &Tensor) -> Tensor {
        self.run("relu", || self.download(&self.relu_dev(&self.upload(x)?)?))
    }

    fn relu_backward(&self, x: &Tensor, dy: &Tensor, dx: &mut Tensor) {
        self.run("relu_backward", || {
            let (xd, dyd, mut dxd) = (self.upload(x)?, self.upload(dy)?, self.upload(dx)?);
            self.relu_backward_dev(&xd, &dyd, &mut dxd)?;
            store(dx, self.download(&dxd)?);
            Ok(())
        })
    }

    fn add_assign(&self, a: &mut Tensor, b: &Tensor) {
        self.run("add_assign", || {
            let (mut ad, bd) = (self.upload(a)?, self.upload(b)?);
            self.add_assign_dev(&mut ad, &bd)?;
            store(a, self.download(&ad)?);
            Ok(())
        })
    }

    fn pixel_shuffle(&self, x: &Tensor, r: usize) -> Tensor {
        self.run("pixel_shuffle", || self.download(&self.pixel_shuffle_dev(&self.upload(x)?, r)?))
    }

    fn pixel_unshuffle(&self, x: &Tensor, r: usize) -> Tensor {
        self.run("pixel_unshuffle", || self.download(&self.pixel_unshuffle_dev(&self.upload(x)?, r)?))
    }

    fn resize(&self, x: &Tensor, out_h: usize, out_w: usize, mode: Interp) -> Tensor {
        self.run("resize", || self.download(&self.resize_dev(&self.upload(x)?, out_h, out_w, mode)?))
    }

    fn resize_backward(&self, dy: &Tensor, mode: Interp, dx: &mut Tensor) {
        self.run("resize_backward", || {
            let (dyd, mut dxd) = (self.upload(dy)?, self.upload(dx)?);
            self.resize_backward_dev(&dyd, mode, &mut dxd)?;
            store(dx, self.download(&dxd)?);
            Ok(())
        })
    }

    fn sigmoid(&self, x: &Tensor) -> Tensor {
        self.run("sigmoid", || self.download(&self.sigmoid_dev(&self.upload(x)?)?))
    }

    fn mse(&self, pred: &Tensor, target: &Tensor) -> (f32, Tensor) {
        self.run("mse", || {
            let (l, g) = self.mse_dev(&self.upload(pred)?, &self.upload(target)?)?;
            Ok((l, self.download(&g)?))
        })
    }

    fn bce_with_logits(&self, logits: &Tensor, target: &Tensor, pos_weight: f32) -> (f32, Tensor) {
        self.run("bce_with_logits", || {
            let (l, g) =
                self.bce_with_logits_dev(&self.upload(logits)?, &self.upload(target)?, pos_weight)?;
            Ok((l, self.download(&g)?))
        })
    }

    fn adam_update(
        &self,
        p: &mut [f32],
        g: &[f32],
        m: &mut [f32],
        v: &mut [f32],
        step: u64,
        hp: &AdamParams,
    ) {
        assert!(
            p.len() == g.len() && p.len() == m.len() && p.len() == v.len(),
            "adam_update: lengths p {} g {} m {} v {}",
            p.len(),
            g.len(),
            m.len(),
            v.len()
        );
        self.run("adam_update", || {
            let n = p.len();
            let (mut pd, gd, mut md, mut vd) = (self.up(p)?, self.up(g)?, self.up(m)?, self.up(v)?);
            self.adam_update_dev(&mut pd, &gd, &mut md, &mut vd, n, step, hp)?;
            p.copy_from_slice(&self.down(&pd, n)?);
            m.copy_from_slice(&self.down(&md, n)?);
            v.copy_from_slice(&self.down(&vd, n)?);
            Ok(())
        })
    }
}
