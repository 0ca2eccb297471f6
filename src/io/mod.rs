//! File formats and safe writing: `.npy` (via npyz), `.npz` (a stored zip of `.npy`), JSON,
//! PC2/MDD point caches, atomic temp+rename writes. Every reader checks sizes against the file
//! before allocating.

pub mod atomic;
pub mod json;
mod json_parse;
pub mod npy;
pub mod npz;
pub mod point_cache;

pub use atomic::{write_atomic, write_atomic_bytes};
pub use npy::{npy_bytes, read_npy, tensor_from_npy_bytes, write_npy};
pub use npz::{read_npz, write_npz, NpzEntries};
pub use point_cache::{CacheFormat, CacheHeader, PointCacheReader};
