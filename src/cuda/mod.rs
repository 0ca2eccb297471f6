//! The GPU backend (cargo feature `cuda`) and the device switch used by the command line.
//!
//! [`ops_for_device`] turns a `--device cpu|cuda` option into an op table. With the feature,
//! [`Cuda`] implements [`Ops`] with kernels from `kernels/*.cu`, compiled at run time by NVRTC
//! from sources embedded in the binary; `cudarc` loads `libcuda`/`libnvrtc` dynamically, so the
//! crate builds on machines with no CUDA toolkit, and a machine with no driver or no GPU gets an
//! [`Error::Device`] saying what is missing, never a panic. Without the feature, [`Cuda`] is an
//! uninhabited stub with the same API whose constructor explains how to rebuild.
//!
//! Transfers: the [`Ops`] trait takes and returns host [`Tensor`]s, so every call uploads its
//! inputs and downloads its outputs (≈ 2 × 4 bytes per element over PCIe, which dominates for
//! small element-wise ops). The kernels themselves work on device buffers (`Cuda::*_dev`
//! methods on `DevBuf`): that is the seam for a device-resident training loop.
//!
//! Files: `device.rs` (context, kernel loading, `DevBuf`, transfers), one file per kernel
//! family mirroring `kernels/*.cu` (`conv2d.rs`, `elementwise.rs`, `pixel_shuffle.rs`,
//! `resample.rs`, `loss.rs`, `adam.rs`: the `Cuda::*_dev` methods), `table.rs` (the [`Ops`]
//! table over host tensors), `stub.rs` (the build without the feature).
//!
//! Checking without a GPU: `python3 kernels/emu/check_kernels.py` compiles the same kernel
//! sources with g++ (a CPU emulation of blocks, threads, shared memory and barriers), launches
//! them with this module's grid geometry and compares with NumPy references; the parity tests
//! in `tests/cuda_parity.rs` compare against the CPU engine where a GPU is present.

use crate::error::{Error, Result};
use crate::ops::{Cpu, Ops};

#[cfg(feature = "cuda")]
mod adam;
#[cfg(feature = "cuda")]
mod conv2d;
#[cfg(feature = "cuda")]
mod device;
#[cfg(feature = "cuda")]
mod elementwise;
#[cfg(feature = "cuda")]
mod infer;
#[cfg(feature = "cuda")]
mod loss;
#[cfg(feature = "cuda")]
mod pixel_shuffle;
#[cfg(feature = "cuda")]
mod resample;
#[cfg(feature = "cuda")]
mod table;
#[cfg(feature = "cuda")]
mod train;
#[cfg(feature = "cuda")]
pub use device::{Cuda, DevBuf};
#[cfg(feature = "cuda")]
pub use train::DeviceTrainer;

#[cfg(not(feature = "cuda"))]
mod stub;
#[cfg(not(feature = "cuda"))]
pub use stub::{Cuda, DeviceTrainer};

/// What a [`DeviceTrainer`] step minimises: GeometryNet's `U + R` against HR (Eq 3 and the
/// optional terms), or a map net's BCE (Eq 10, 11).
#[derive(Clone, Copy, Debug)]
pub enum StepLoss {
    Geometry(crate::nn::geometry_net::GeometryLoss),
    Map { pos_weight: f32 },
}

/// A [`DeviceTrainer`] for `trunk` with Adam's state `adam` where `ops` is the CUDA table, else
/// `None` (the trainer runs op by op on the table).
pub fn device_trainer<'a>(
    ops: &'a dyn Ops,
    trunk: &crate::nn::Trunk,
    adam: &crate::train::adam::Adam,
) -> Result<Option<DeviceTrainer<'a>>> {
    match ops.as_cuda() {
        Some(c) => DeviceTrainer::new(c, trunk, adam).map(Some),
        None => Ok(None),
    }
}

/// The embedded kernel sources, compiled by NVRTC when [`Cuda`] starts: (file under
/// `kernels/`, source, the `extern "C" __global__` kernels it defines). Sources are kept ASCII.
#[cfg_attr(not(feature = "cuda"), allow(dead_code))]
pub(crate) const KERNELS: [(&str, &str, &[&str]); 6] = [
    (
        "conv2d.cu",
        include_str!("../../kernels/conv2d.cu"),
        &[
            "conv2d_fwd",
            "conv2d_fwd_m32",
            "conv2d_wgrad",
            "conv2d_wgrad_m32",
            "conv2d_wgrad_reduce",
            "conv2d_dgrad_padded",
            "conv2d_dgrad_padded_m32",
            "conv2d_dgrad_fold",
            "conv2d_bias_grad",
        ],
    ),
    (
        "elementwise.cu",
        include_str!("../../kernels/elementwise.cu"),
        &["relu_fwd", "relu_bwd", "add_assign", "sigmoid_fwd"],
    ),
    (
        "pixel_shuffle.cu",
        include_str!("../../kernels/pixel_shuffle.cu"),
        &["pixel_shuffle", "pixel_unshuffle"],
    ),
    ("resample.cu", include_str!("../../kernels/resample.cu"), &["resize_fwd", "resize_bwd"]),
    ("loss.cu", include_str!("../../kernels/loss.cu"), &["mse_loss", "bce_logits_loss", "geometry_loss"]),
    ("adam.cu", include_str!("../../kernels/adam.cu"), &["adam_step", "adam_step_all"]),
];

/// `kernels/infer.cu`, the device-resident inference of a whole bundle ([`nets_views`]):
/// compiled apart from [`KERNELS`], for compute capability 8.0 and newer (tensor-core `mma.sync`).
#[cfg_attr(not(feature = "cuda"), allow(dead_code))]
pub(crate) const INFER_KERNELS: (&str, &str, &[&str]) = (
    "infer.cu",
    include_str!("../../kernels/infer.cu"),
    &["f32_to_f16", "views_to_nhwc", "conv3x3_tc", "views_average"],
);

/// One mirror view of a batch for [`nets_views`]: the grid's rows and/or columns flipped, and
/// the net coordinates the flip reverses (`v ↦ 1 − v` on the way in, `R ↦ −R` on the way out;
/// [`crate::geom::cloth_frame::mirror_net_images`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MirrorView {
    pub rows: bool,
    pub cols: bool,
    pub axes: [bool; 3],
}

impl MirrorView {
    /// The view's bits in `kernels/infer.cu`: 1 rows, 2 columns, 4 << axis for each reversed axis.
    #[cfg_attr(not(feature = "cuda"), allow(dead_code))]
    pub(crate) fn flags(self) -> i32 {
        let axes = self.axes.iter().enumerate().map(|(a, &on)| (on as i32) << (2 + a)).sum::<i32>();
        self.rows as i32 | (self.cols as i32) << 1 | axes
    }
}

/// The whole bundle's (`nets`, its weights kept on the GPU under its checksum while the same
/// bundle runs) inference on the batch `x` (N, 3, H, W), already in the nets' frame, for
/// each of `views` (the first is usually the identity), every output un-mirrored and averaged
/// over the views: what [`crate::sr::upscale`] computes op by op with `forward_with` on each
/// view. Runs where `ops` is a [`Cuda`] table whose GPU has tensor cores (compute capability
/// 8.0+) and the bundle fits the fused kernels (×2, every net of one config): one upload of the
/// batch, every net and view on the device in fp16 with fp32 accumulation, one download of U,
/// R, Γb and Γe. `None` where it cannot (the caller runs the op table instead). A driver failure
/// is recorded like any op's ([`Ops::take_error`]) and the outputs are NaN.
pub fn nets_views(
    ops: &dyn Ops,
    nets: &crate::nn::bundle::PackedAnisoCb,
    x: &crate::tensor::Tensor,
    views: &[MirrorView],
    enhance: bool,
) -> Option<crate::nn::NetsOutput> {
    #[cfg(feature = "cuda")]
    return ops.as_cuda()?.nets_views(nets, x, views, enhance);
    #[cfg(not(feature = "cuda"))]
    {
        let _ = (nets, x, views, enhance);
        ops.as_cuda().map(|c| match *c {})
    }
}

/// The devices [`ops_for_device`] knows, for option help texts.
pub const DEVICES: &[&str] = &["cpu", "cuda"];

/// Where the nets run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Device {
    /// The CPU op table ([`Cpu`]): the default everywhere.
    #[default]
    Cpu,
    /// The first GPU (feature `cuda`).
    Cuda,
}

impl Device {
    /// Its name in [`DEVICES`].
    pub fn name(self) -> &'static str {
        match self {
            Device::Cpu => "cpu",
            Device::Cuda => "cuda",
        }
    }

    /// `cpu` or `cuda` (`gpu` too), any case, spaces around ignored.
    pub fn parse(name: &str) -> Result<Device> {
        match name.trim().to_ascii_lowercase().as_str() {
            "cpu" => Ok(Device::Cpu),
            "cuda" | "gpu" => Ok(Device::Cuda),
            other => Err(Error::invalid(
                "device",
                format!("unknown device `{other}`: expected one of {}", DEVICES.join(", ")),
            )),
        }
    }

    /// Its op table. Errors: `cuda` in a build without the feature, without a driver, or
    /// without a device ([`Error::Device`], saying which and how to fix it).
    pub fn ops(self) -> Result<Box<dyn Ops>> {
        match self {
            Device::Cpu => Ok(Box::new(Cpu)),
            Device::Cuda => Ok(Box::new(Cuda::new()?)),
        }
    }
}

/// The op table for a device named `name` ([`Device::parse`], [`Device::ops`]).
pub fn ops_for_device(name: &str) -> Result<Box<dyn Ops>> {
    Device::parse(name)?.ops()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cpu_device_is_the_cpu_op_table() {
        assert_eq!(ops_for_device("cpu").unwrap().name(), Cpu.name());
        assert_eq!(ops_for_device(" CPU ").unwrap().name(), Cpu.name());
    }

    #[test]
    fn every_listed_kernel_is_defined_in_its_ascii_source() {
        for (file, src, names) in KERNELS {
            assert!(src.is_ascii(), "kernels/{file}: keep kernel sources ASCII for NVRTC");
            for name in names {
                let sig = format!("extern \"C\" __global__ void {name}(");
                assert_eq!(src.matches(&sig).count(), 1, "kernels/{file} should define `{name}` once");
            }
            let defined = src.matches("__global__ void").count();
            assert_eq!(defined, names.len(), "kernels/{file}: every kernel is listed in KERNELS");
        }
        let (file, src, names) = INFER_KERNELS;
        assert!(src.is_ascii(), "kernels/{file}: keep kernel sources ASCII for NVRTC");
        for name in names {
            let sig = format!("extern \"C\" __global__ void {name}(");
            assert_eq!(src.matches(&sig).count(), 1, "kernels/{file} should define `{name}` once");
        }
        assert_eq!(src.matches("__global__ void").count(), names.len(), "kernels/{file}: all listed");
    }

    #[test]
    fn unknown_device_is_an_invalid_device_option() {
        let e = ops_for_device("tpu").err().expect("tpu is not a device");
        assert!(matches!(e, Error::Invalid { field: "device", .. }), "{e}");
        assert!(e.to_string().contains("cpu, cuda"), "{e}");
    }
}
