//! The GPU backend's core: `cudarc` (driver API, dynamically loaded), the context, the
//! NVRTC-compiled kernels, device buffers and transfers. The ops themselves sit in one file
//! per kernel family, mirroring `kernels/*.cu`: [`super::conv2d`], [`super::elementwise`],
//! [`super::pixel_shuffle`], [`super::resample`], [`super::loss`], [`super::adam`]; the
//! [`Ops`](crate::ops::Ops) table over host tensors is in [`super::table`].
//!
//! Every kernel is written out in `kernels/*.cu` with its shapes and index math; the Rust side
//! only checks shapes (the GPU would read out of bounds silently), moves data, picks launch
//! geometry and launches. Results are deterministic: no kernel uses atomics, and every
//! reduction runs in a fixed order that depends only on the shapes.
//!
//! Errors: construction returns [`Error::Device`]. Once constructed, a driver failure inside an
//! op (out of memory, a lost device) is recorded with the driver's message, that op and every
//! later one return NaN results without touching the device, and
//! [`Ops::take_error`](crate::ops::Ops::take_error) hands the failure to the caller, which
//! checks it at batch boundaries and returns [`Error::Device`]: the [`Ops`](crate::ops::Ops)
//! methods, like the CPU ones, have no error channel of their own. Shape mismatches panic like
//! the CPU path (a bug, not a device failure).

use std::sync::{Arc, Mutex, MutexGuard};

use cudarc::driver::{
    CudaContext, CudaFunction, CudaModule, CudaSlice, CudaStream, DriverError, LaunchConfig, PinnedHostSlice,
};
use cudarc::nvrtc::{compile_ptx_with_opts, CompileOptions};

use super::infer::{DeviceBundle, InferKernels};
use super::KERNELS;
use crate::error::{Error, Result};
use crate::tensor::Tensor;

pub(super) type DResult<T> = std::result::Result<T, DriverError>;

/// Threads per block for the 1-D and tiled kernels (the tiled kernels require exactly 256).
pub(super) const THREADS: u32 = 256;
/// Cap on blocks of the grid-stride kernels.
const MAX_BLOCKS: usize = 8192;

/// The loaded kernels, one field per `extern "C" __global__` function.
pub(super) struct Kernels {
    /// The implicit-GEMM conv kernels in their two tile heights: `[64 rows, 32 rows]`.
    pub(super) conv2d_fwd: [CudaFunction; 2],
    pub(super) conv2d_wgrad: [CudaFunction; 2],
    pub(super) conv2d_wgrad_reduce: CudaFunction,
    pub(super) conv2d_dgrad_padded: [CudaFunction; 2],
    pub(super) conv2d_dgrad_fold: CudaFunction,
    pub(super) conv2d_bias_grad: CudaFunction,
    pub(super) relu_fwd: CudaFunction,
    pub(super) relu_bwd: CudaFunction,
    pub(super) add_assign: CudaFunction,
    pub(super) sigmoid_fwd: CudaFunction,
    pub(super) pixel_shuffle: CudaFunction,
    pub(super) pixel_unshuffle: CudaFunction,
    pub(super) resize_fwd: CudaFunction,
    pub(super) resize_bwd: CudaFunction,
    pub(super) mse_loss: CudaFunction,
    pub(super) bce_logits_loss: CudaFunction,
    pub(super) geometry_loss: CudaFunction,
    pub(super) adam_step: CudaFunction,
    pub(super) adam_step_all: CudaFunction,
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
    pub(super) stream: Arc<CudaStream>,
    pub(super) k: Kernels,
    device_name: String,
    /// Serialises the ops; holds the first driver failure (sticky until taken).
    lock: Mutex<Option<String>>,
    /// `kernels/infer.cu` (tensor cores, compute capability 8.0 or newer), or why it is missing.
    pub(super) infer: std::result::Result<InferKernels, String>,
    /// The last bundle [`Cuda::nets_views`] ran, its weights on the device.
    pub(super) bundle: Mutex<Option<Arc<DeviceBundle>>>,
    /// Whether [`Cuda::nets_views`] may run (`--precision fp32` turns it off).
    pub(super) tensor_cores_on: std::sync::atomic::AtomicBool,
    /// `ANISOCB_CUDA_PROFILE=1`: the time between [`Cuda::mark`]s, by bucket.
    profile: Option<Mutex<Profile>>,
}

/// Wall time charged to named buckets by [`Cuda::mark`] (a developer's tool: each mark waits
/// for the stream, so a profiled run is slower than a plain one).
struct Profile {
    last: std::time::Instant,
    /// (bucket, seconds, marks), in order of first appearance.
    rows: Vec<(String, f64, u64)>,
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

/// Grid for a 1-D grid-stride kernel over `n` (> 0) items.
pub(super) fn grid1(n: usize) -> LaunchConfig {
    let blocks = n.div_ceil(THREADS as usize).clamp(1, MAX_BLOCKS);
    LaunchConfig { grid_dim: (blocks as u32, 1, 1), block_dim: (THREADS, 1, 1), shared_mem_bytes: 0 }
}

pub(super) fn i32_of(v: usize, what: &str) -> i32 {
    i32::try_from(v).unwrap_or_else(|_| panic!("CUDA: {what} = {v} exceeds the kernels' 32-bit index range"))
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
                    "no CUDA device: the driver is installed but finds no GPU; run on the cpu device",
                ))
            }
            Err(e) => return Err(driver_err("cannot initialise the CUDA driver (cuInit)", e)),
        }
        let count = dr::device::get_count().map_err(|e| driver_err("cannot count CUDA devices", e))?;
        if count <= 0 {
            return Err(Error::device(
                "no CUDA device: the driver is installed but finds no GPU; run on the cpu device",
            ));
        }
        if ordinal >= count as usize {
            return Err(Error::device(format!("no CUDA device {ordinal}: this machine has {count}")));
        }
        let ctx = CudaContext::new(ordinal).map_err(|e| driver_err("cannot create a CUDA context", e))?;
        let device_name = ctx.name().unwrap_or_else(|_| format!("CUDA device {ordinal}"));
        let stream = ctx.default_stream();
        keep_freed_memory_pooled(&ctx);

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
            conv2d_fwd: [f("conv2d_fwd")?, f("conv2d_fwd_m32")?],
            conv2d_wgrad: [f("conv2d_wgrad")?, f("conv2d_wgrad_m32")?],
            conv2d_wgrad_reduce: f("conv2d_wgrad_reduce")?,
            conv2d_dgrad_padded: [f("conv2d_dgrad_padded")?, f("conv2d_dgrad_padded_m32")?],
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
            geometry_loss: f("geometry_loss")?,
            adam_step: f("adam_step")?,
            adam_step_all: f("adam_step_all")?,
        };
        let infer = InferKernels::load(&ctx);
        Ok(Cuda {
            ctx,
            stream,
            k,
            device_name,
            lock: Mutex::new(None),
            infer,
            bundle: Mutex::new(None),
            tensor_cores_on: std::sync::atomic::AtomicBool::new(true),
            profile: std::env::var_os("ANISOCB_CUDA_PROFILE")
                .is_some_and(|v| v == "1")
                .then(|| Mutex::new(Profile { last: std::time::Instant::now(), rows: Vec::new() })),
        })
    }

    /// With `ANISOCB_CUDA_PROFILE=1`: waits for the stream, then charges the wall time since
    /// the previous mark to `bucket()`. Otherwise nothing (the closure is not called).
    pub(super) fn mark(&self, bucket: impl FnOnce() -> String) {
        let Some(p) = &self.profile else { return };
        let _ = self.stream.synchronize();
        let mut p = p.lock().unwrap_or_else(|e| e.into_inner());
        let now = std::time::Instant::now();
        let dt = (now - p.last).as_secs_f64();
        p.last = now;
        let name = bucket();
        match p.rows.iter_mut().find(|r| r.0 == name) {
            Some(r) => {
                r.1 += dt;
                r.2 += 1;
            }
            None => p.rows.push((name, dt, 1)),
        }
    }

    /// The profile so far as a table on stderr, then cleared (nothing without a profile).
    pub(super) fn report_profile(&self, title: &str) {
        let Some(p) = &self.profile else { return };
        let mut p = p.lock().unwrap_or_else(|e| e.into_inner());
        let total: f64 = p.rows.iter().map(|r| r.1).sum();
        eprintln!("\nCUDA profile: {title} ({:.1} ms in all)", total * 1e3);
        for (name, s, k) in &p.rows {
            eprintln!("{:>9.3} ms {:>5.1} % {:>7} × {name}", s * 1e3, 100.0 * s / total.max(1e-12), k);
        }
        p.rows.clear();
    }

    /// The GPU's name as the driver reports it.
    pub fn device_name(&self) -> &str {
        &self.device_name
    }

    fn guard(&self) -> MutexGuard<'_, Option<String>> {
        self.lock.lock().unwrap_or_else(|p| p.into_inner())
    }

    // ---- transfers (the seam: everything below works on device buffers) ----

    /// Copy host values to a new device buffer of at least one element (the driver rejects
    /// empty allocations).
    pub(super) fn up<T: cudarc::driver::DeviceRepr + cudarc::driver::ValidAsZeroBits>(
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
    pub(super) fn down<T: cudarc::driver::DeviceRepr + Default + Clone>(
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
        Ok(DevBuf { shape: t.shape.to_vec(), buf: self.up(&t.data)? })
    }

    /// Upload a tensor through a page-locked staging buffer, `slot` (allocated on first use and
    /// whenever the tensor's length changes): the copy is queued behind the stream's work, where
    /// an upload from pageable memory first waits for the stream to drain. Writing into `slot`
    /// waits for its previous copy to leave (cudarc records an event on the slice).
    pub(super) fn upload_staged(
        &self,
        t: &Tensor,
        slot: &mut Option<PinnedHostSlice<f32>>,
    ) -> DResult<DevBuf> {
        let n = t.data.len();
        if n == 0 {
            return self.upload(t);
        }
        if slot.as_ref().is_none_or(|p| p.len() != n) {
            // SAFETY: the memory starts unset; all n values are written below before the copy.
            *slot = Some(unsafe { self.ctx.alloc_pinned::<f32>(n) }?);
        }
        let p = slot.as_mut().expect("allocated above");
        p.as_mut_slice()?.copy_from_slice(&t.data);
        let mut d = self.stream.alloc_zeros::<f32>(n)?;
        self.stream.memcpy_htod(p, &mut d)?;
        Ok(DevBuf { shape: t.shape.to_vec(), buf: d })
    }

    /// Download a device buffer as a tensor.
    pub fn download(&self, d: &DevBuf) -> DResult<Tensor> {
        Ok(Tensor { shape: d.shape.as_slice().into(), data: self.down(&d.buf, d.len())? })
    }

    /// A zero-filled device buffer of `shape`.
    pub fn zeros(&self, shape: &[usize]) -> DResult<DevBuf> {
        let n: usize = shape.iter().product();
        Ok(DevBuf { shape: shape.to_vec(), buf: self.stream.alloc_zeros::<f32>(n.max(1))? })
    }

    /// Run `f` under the lock. A driver failure is recorded (the first one is kept) and the op
    /// returns `failed()` (NaN results); after a failure no op touches the device again.
    pub(super) fn run<T>(&self, op: &str, failed: impl FnOnce() -> T, f: impl FnOnce() -> DResult<T>) -> T {
        let mut g = self.guard();
        if g.is_some() {
            return failed();
        }
        f().unwrap_or_else(|e| {
            *g = Some(format!("CUDA {op} failed: {e:?}"));
            failed()
        })
    }

    /// The recorded driver failure, if any (see the module docs).
    pub(super) fn take_failure(&self) -> Option<Error> {
        self.guard().take().map(Error::device)
    }
}

/// Buffers come from the device's stream-ordered pool (`cuMemAllocAsync`), which by default
/// hands freed memory back to the driver at every synchronisation (release threshold 0): then
/// every training step, which waits for its loss, maps its hundred-odd buffers afresh. With no
/// threshold the pool keeps what it has (up to the run's high-water mark) for the next step.
/// Best effort: without a default pool nothing changes but the speed.
fn keep_freed_memory_pooled(ctx: &CudaContext) {
    use cudarc::driver::sys;
    let mut pool: sys::CUmemoryPool = std::ptr::null_mut();
    // SAFETY: plain driver calls on this context's device; `max` outlives the call that reads it.
    unsafe {
        if sys::cuDeviceGetDefaultMemPool(&mut pool, ctx.cu_device()) == sys::CUresult::CUDA_SUCCESS {
            let mut max = u64::MAX;
            let attr = sys::CUmemPool_attribute::CU_MEMPOOL_ATTR_RELEASE_THRESHOLD;
            let _ = sys::cuMemPoolSetAttribute(pool, attr, (&mut max as *mut u64).cast());
        }
    }
}

pub(super) fn dims4(shape: &[usize], what: &str) -> [usize; 4] {
    assert_eq!(shape.len(), 4, "{what}: expected (N, C, H, W), got shape {shape:?}");
    [shape[0], shape[1], shape[2], shape[3]]
}

/// Copy a device result into an existing host tensor (same length).
pub(super) fn store(dst: &mut Tensor, src: Tensor) {
    debug_assert_eq!(dst.data.len(), src.data.len());
    dst.data = src.into_data();
}
