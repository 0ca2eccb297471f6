//! Training: the Adam optimizer, the dataset, the trainer loop.

pub mod adam;
pub mod data;
pub mod dataset;
pub mod trainer;
