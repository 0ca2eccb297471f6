//! Training: the Adam optimizer, the dataset, the trainer loop.

pub mod adam;
