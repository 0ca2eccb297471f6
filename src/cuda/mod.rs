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

use crate::error::{Error, Result};
use crate::ops::{Cpu, Ops};

pub mod taps;

#[cfg(feature = "cuda")]
mod device;
#[cfg(feature = "cuda")]
pub use device::{Cuda, DevBuf};

#[cfg(not(feature = "cuda"))]
mod stub;
#[cfg(not(feature = "cuda"))]
pub use stub::Cuda;

/// The devices [`ops_for_device`] knows, for option help texts.
pub const DEVICES: &[&str] = &["cpu", "cuda"];

/// The op table for a `--device` option value: `"cpu"` (the default everywhere) or `"cuda"`
/// (first GPU). Errors: an unknown name ([`Error::Config`]); `cuda` in a build without the
/// feature, without a driver, or without a device ([`Error::Device`], saying which and how to
/// fix it).
pub fn ops_for_device(name: &str) -> Result<Box<dyn Ops>> {
    match name.trim().to_ascii_lowercase().as_str() {
        "cpu" => Ok(Box::new(Cpu)),
        "cuda" | "gpu" => Ok(Box::new(Cuda::new()?)),
        other => {
            Err(Error::config(format!("unknown device `{other}`: expected one of {}", DEVICES.join(", "))))
        }
    }
}

/// Whether [`Cuda::new`] would succeed here (builds the backend once to find out).
pub fn cuda_available() -> bool {
    Cuda::new().is_ok()
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
    fn unknown_device_is_a_config_error() {
        let e = ops_for_device("tpu").err().expect("tpu is not a device");
        assert!(matches!(e, Error::Config(_)), "{e}");
        assert!(e.to_string().contains("cpu, cuda"), "{e}");
    }
}
