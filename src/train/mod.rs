//! Training: the Adam optimizer, the dataset, the trainer loop.

pub mod adam;
pub mod dataset;
pub mod patches;
pub mod trainer;
