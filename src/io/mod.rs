//! File formats and safe writing: `.npy` (via npyz), `.npz` (a stored zip of `.npy`), JSON,
//! PC2/MDD point caches, atomic temp+rename writes. Every reader checks sizes against the file
//! before allocating.

pub mod atomic;
pub mod json;
mod json_parse;
pub mod npy;
pub mod npz;
pub mod point_cache;
#[cfg(feature = "usd")]
pub mod usd;

pub use atomic::{write_atomic, write_atomic_bytes};

use crate::error::{Error, Result};
use std::fs::File;
use std::io::Read;
use std::path::Path;

/// Open `path` for reading if it is a regular file (symbolic links followed): a device
/// (`/dev/zero`), a pipe or a folder is refused with a message, instead of being read until
/// memory runs out or blocking forever.
pub fn open_regular(path: &Path) -> Result<File> {
    let file = File::open(path).map_err(|e| Error::io(path, e))?;
    let meta = file.metadata().map_err(|e| Error::io(path, e))?;
    if !meta.is_file() {
        let what = if meta.is_dir() { "a folder" } else { "not a regular file (a device, pipe or socket)" };
        return Err(Error::format(path, format!("{what}: give a file")));
    }
    Ok(file)
}

/// The bytes of the regular file `path` ([`open_regular`]), at most its length when opened
/// (a file that grows meanwhile is read to that length and refused).
pub fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    let file = open_regular(path)?;
    let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
    let mut bytes = Vec::new();
    file.take(len.saturating_add(1)).read_to_end(&mut bytes).map_err(|e| Error::io(path, e))?;
    if bytes.len() as u64 > len {
        return Err(Error::format(path, "the file grew while it was read: read it once it is complete"));
    }
    Ok(bytes)
}
pub use npy::{npy_bytes, read_npy, tensor_from_npy_bytes, write_npy};
pub use npz::{read_npz, write_npz, NpzEntries};
pub use point_cache::{CacheFormat, CacheHeader, PointCacheReader};
