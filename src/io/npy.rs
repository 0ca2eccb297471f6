//! `.npy` in and out, as f32 [`Tensor`]s. Reading checks the header's claimed size against the
//! bytes actually present before allocating, accepts f32/f64 little-endian C-order arrays, and
//! rejects NaN/Inf only where the caller asks (see [`Tensor::first_non_finite`]).

use crate::error::{Error, Result};
use crate::tensor::Tensor;
use npyz::WriterBuilder;
use std::path::Path;

/// Largest array we accept from disk, in elements (4 GiB of f32): a header claiming more is
/// rejected before anything is allocated.
pub const MAX_ELEMENTS: u64 = 1 << 30;

pub fn read_npy(path: &Path) -> Result<Tensor> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    tensor_from_npy_bytes(&bytes).map_err(|m| Error::format(path, m))
}

/// Parse `.npy` bytes; the error is a plain message that the caller attaches a file name to.
pub fn tensor_from_npy_bytes(bytes: &[u8]) -> std::result::Result<Tensor, String> {
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err("not a .npy file (missing \\x93NUMPY magic)".into());
    }
    let npy = npyz::NpyFile::new(bytes).map_err(|e| format!("bad .npy header: {e}"))?;
    let shape: Vec<u64> = npy.shape().to_vec();
    if npy.order() != npyz::Order::C {
        return Err("Fortran-order array; save it C-contiguous (np.ascontiguousarray)".into());
    }
    let n = shape.iter().try_fold(1u64, |a, &d| a.checked_mul(d));
    let n = match n {
        Some(n) if n <= MAX_ELEMENTS => n,
        _ => return Err(format!("shape {shape:?} is too large")),
    };
    let header_len = header_len(bytes).ok_or("bad .npy header length")?;
    let payload = (bytes.len() - header_len.min(bytes.len())) as u64;
    let dtype = npy.dtype();
    let item = match &dtype {
        npyz::DType::Plain(ts) => ts.size_field(),
        _ => return Err(format!("unsupported dtype {}; expected float32", dtype.descr())),
    };
    if payload < n * item {
        return Err(format!(
            "truncated: shape {shape:?} needs {} bytes of data, file has {payload}",
            n * item
        ));
    }
    let descr = dtype.descr();
    let data: Vec<f32> = match descr.as_str() {
        "'<f4'" => npy.into_vec::<f32>().map_err(|e| format!("reading data: {e}"))?,
        "'<f8'" => npy
            .into_vec::<f64>()
            .map_err(|e| format!("reading data: {e}"))?
            .into_iter()
            .map(|v| v as f32)
            .collect(),
        _ => return Err(format!("unsupported dtype {descr}; expected float32 ('<f4')")),
    };
    let shape: Vec<usize> = shape.iter().map(|&d| d as usize).collect();
    Tensor::from_vec(&shape, data).map_err(|e| e.to_string())
}

/// Total header length (magic + version + len field + header text), or None if malformed.
fn header_len(bytes: &[u8]) -> Option<usize> {
    match bytes.get(6)? {
        1 => Some(10 + u16::from_le_bytes([bytes[8], bytes[9]]) as usize),
        2 | 3 => {
            let b = bytes.get(8..12)?;
            Some(12 + u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
        }
        _ => None,
    }
}

/// Serialize a tensor as `.npy` (little-endian f32, C order).
pub fn npy_bytes(t: &Tensor) -> Vec<u8> {
    let mut out = Vec::with_capacity(128 + 4 * t.len());
    let shape: Vec<u64> = t.shape.iter().map(|&d| d as u64).collect();
    let mut w = npyz::WriteOptions::new()
        .default_dtype()
        .shape(&shape)
        .writer(&mut out)
        .begin_nd()
        .expect("writing to a Vec cannot fail");
    w.extend(t.data.iter().copied()).expect("writing to a Vec cannot fail");
    w.finish().expect("writing to a Vec cannot fail");
    out
}

/// Write a tensor as `.npy`, atomically.
pub fn write_npy(path: &Path, t: &Tensor) -> Result<()> {
    super::write_atomic_bytes(path, &npy_bytes(t))
}
