//! The three networks of AnisoCBConvNet, written against the op table [`crate::ops::Ops`].
//!
//! - [`config`]: [`NetKind`], [`NetConfig`] and its presets (`paper`, `small`, `tiny`).
//! - [`layers`]: [`layers::Conv`] and the shared [`layers::Trunk`] (forward with or without a
//!   tape of activations, backward that adds into gradients).
//! - [`geometry_net`]: GeometryNet (residual trunk predicting `R` over the cubic interpolation `U`, MSE).
//! - [`map_net`]: BoundaryNet / EnhanceNet (plain trunk, one logit channel, sigmoid-BCE).
//! - [`bundle`]: [`bundle::AnisoCb`], the three nets together, `forward → (U, R, Γb, Γe)`.
//! - [`weights`]: `.npz` in and out with PyTorch-style names (see `weights/README.md`).
//! - [`audit`]: every layer's activation as `.npy`, named after the layer.

pub mod audit;
pub mod bundle;
pub mod config;
pub mod geometry_net;
pub mod layers;
pub mod map_net;
pub mod weights;

pub use bundle::{AnisoCb, NetsOutput};
pub use config::{NetConfig, NetKind};
pub use geometry_net::GeometryNet;
pub use layers::{Conv, Tape, Trunk};
pub use map_net::MapNet;
