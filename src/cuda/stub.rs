//! The CUDA backend in a build without the `cuda` feature: same API, cannot be constructed.

use crate::error::{Error, Result};
use crate::ops::loss::DetailEnergy;
use crate::ops::{AdamParams, Interp, Ops, Padding};
use crate::tensor::Tensor;

/// Stand-in for the GPU backend. Uninhabited: [`Cuda::new`] always fails, so no method of it
/// can ever run.
#[derive(Debug)]
pub enum Cuda {}

impl Cuda {
    /// Always an [`Error::Device`]: this build has no GPU backend.
    pub fn new() -> Result<Cuda> {
        Err(Error::device(
            "built without the `cuda` feature: rebuild with `cargo build --release --features cuda` \
             (needs an NVIDIA driver at run time, no CUDA toolkit at build time)",
        ))
    }

    /// Same as [`Cuda::new`]; `ordinal` selects the GPU in a `cuda` build.
    pub fn with_ordinal(_ordinal: usize) -> Result<Cuda> {
        Cuda::new()
    }

    /// The GPU's name.
    pub fn device_name(&self) -> &str {
        match *self {}
    }

    /// Whether the tensor-core path runs here: never in this build.
    pub fn tensor_cores(&self) -> std::result::Result<(), String> {
        match *self {}
    }

    /// Turn the tensor-core path on or off: there is none in this build.
    pub fn use_tensor_cores(&self, _on: bool) {
        match *self {}
    }

    /// GeometryNet's loss on the device: there is none in this build.
    pub fn geometry_loss(
        &self,
        _: &Tensor,
        _: &Tensor,
        _: crate::nn::geometry_net::GeometryLoss,
    ) -> Option<(f32, Tensor)> {
        match *self {}
    }
}

/// Stand-in for the device-resident trainer: it holds a [`Cuda`], which cannot exist here.
pub struct DeviceTrainer<'a> {
    cuda: &'a Cuda,
}

impl<'a> DeviceTrainer<'a> {
    /// Never called: there is no [`Cuda`] to pass.
    pub fn new(cuda: &'a Cuda, _: &crate::nn::Trunk, _: &crate::train::adam::Adam) -> Result<Self> {
        Ok(DeviceTrainer { cuda })
    }
    pub fn step(&mut self, _: &Tensor, _: &Tensor, _: &Tensor, _: super::StepLoss) -> f32 {
        match *self.cuda {}
    }
    pub fn loss(&self, _: &Tensor, _: &Tensor, _: &Tensor, _: super::StepLoss) -> f32 {
        match *self.cuda {}
    }
    pub fn store(&self, _: &mut crate::nn::Trunk, _: &mut crate::train::adam::Adam) -> Result<()> {
        match *self.cuda {}
    }
}

impl Ops for Cuda {
    fn name(&self) -> &'static str {
        match *self {}
    }
    fn as_cuda(&self) -> Option<&Cuda> {
        match *self {}
    }
    fn conv2d(&self, _: &Tensor, _: &Tensor, _: Option<&Tensor>, _: Padding) -> Tensor {
        match *self {}
    }
    fn conv2d_backward(
        &self,
        _: &Tensor,
        _: &Tensor,
        _: &Tensor,
        _: Padding,
        _: Option<&mut Tensor>,
        _: &mut Tensor,
        _: Option<&mut Tensor>,
    ) {
        match *self {}
    }
    fn relu(&self, _: &Tensor) -> Tensor {
        match *self {}
    }
    fn relu_backward(&self, _: &Tensor, _: &Tensor, _: &mut Tensor) {
        match *self {}
    }
    fn add_assign(&self, _: &mut Tensor, _: &Tensor) {
        match *self {}
    }
    fn pixel_shuffle(&self, _: &Tensor, _: usize) -> Tensor {
        match *self {}
    }
    fn pixel_unshuffle(&self, _: &Tensor, _: usize) -> Tensor {
        match *self {}
    }
    fn resize(&self, _: &Tensor, _: usize, _: usize, _: Interp) -> Tensor {
        match *self {}
    }
    fn resize_backward(&self, _: &Tensor, _: Interp, _: &mut Tensor) {
        match *self {}
    }
    fn sigmoid(&self, _: &Tensor) -> Tensor {
        match *self {}
    }
    fn mse(&self, _: &Tensor, _: &Tensor) -> (f32, Tensor) {
        match *self {}
    }
    fn bce_with_logits(&self, _: &Tensor, _: &Tensor, _: f32) -> (f32, Tensor) {
        match *self {}
    }
    fn edge_mse(&self, _: &Tensor, _: &Tensor) -> (f32, Tensor) {
        match *self {}
    }
    fn edge_length_mse(&self, _: &Tensor, _: &Tensor) -> (f32, Tensor) {
        match *self {}
    }
    fn laplacian_mse(&self, _: &Tensor, _: &Tensor) -> (f32, Tensor) {
        match *self {}
    }
    fn detail_energy_mse(
        &self,
        _: &Tensor,
        _: &Tensor,
        _: usize,
        _: usize,
        _: DetailEnergy,
    ) -> (f32, Tensor) {
        match *self {}
    }
    fn adam_update(&self, _: &mut [f32], _: &[f32], _: &mut [f32], _: &mut [f32], _: u64, _: &AdamParams) {
        match *self {}
    }
}
