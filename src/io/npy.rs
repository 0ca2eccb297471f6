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

/// Longest header text we parse (numpy's own default `max_header_size`). The header is a Python
/// literal parsed by a recursive parser inside npyz, and npyz allocates the claimed header
/// length before reading it, so both its length and its nesting are checked here first.
pub const MAX_HEADER_BYTES: usize = 10_000;
/// Deepest bracket nesting accepted in a header (a float array's header nests 2 deep).
const MAX_HEADER_NESTING: usize = 8;

/// Parse `.npy` bytes; the error is a plain message that the caller attaches a file name to.
/// Nothing is allocated beyond what the bytes present can fill.
pub fn tensor_from_npy_bytes(bytes: &[u8]) -> std::result::Result<Tensor, String> {
    if bytes.is_empty() {
        return Err("empty file (0 bytes); expected a .npy array".into());
    }
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err("not a .npy file (missing \\x93NUMPY magic)".into());
    }
    let header_len = header_len(bytes).ok_or_else(|| {
        format!("unsupported .npy format version {}.{} (expected 1.0, 2.0 or 3.0)", bytes[6], bytes[7])
    })?;
    let text_len = header_len - if bytes[6] == 1 { 10 } else { 12 };
    if text_len > MAX_HEADER_BYTES {
        return Err(format!(
            "header claims {text_len} bytes, more than the {MAX_HEADER_BYTES}-byte limit (corrupt file?)"
        ));
    }
    if header_len > bytes.len() {
        return Err(format!("truncated: header claims {header_len} bytes, file has {}", bytes.len()));
    }
    check_header_nesting(&bytes[header_len - text_len..header_len])?;
    let npy = npyz::NpyFile::new(bytes).map_err(|e| format!("bad .npy header: {e}"))?;
    let shape: Vec<u64> = npy.shape().to_vec();
    let dtype = npy.dtype();
    let descr = dtype.descr();
    let item: u64 = match descr.as_str() {
        "'<f4'" => 4,
        "'<f8'" => 8,
        _ => return Err(format!("unsupported dtype {descr}; expected float32 ('<f4') or float64 ('<f8')")),
    };
    if npy.order() != npyz::Order::C {
        return Err("Fortran-order array; save it C-contiguous (np.ascontiguousarray)".into());
    }
    let n = shape.iter().try_fold(1u64, |a, &d| a.checked_mul(d));
    let n = match n {
        Some(n) if n <= MAX_ELEMENTS => n,
        _ => return Err(format!("shape {shape:?} is too large (limit {MAX_ELEMENTS} elements)")),
    };
    let payload = (bytes.len() - header_len) as u64;
    let need = n * item; // ≤ 2^33: cannot overflow
    if payload < need {
        return Err(format!("truncated: shape {shape:?} needs {need} bytes of data, file has {payload}"));
    }
    if payload > need {
        return Err(format!(
            "{} unexpected bytes after the data of shape {shape:?} (corrupt file or wrong header?)",
            payload - need
        ));
    }
    // Allocations below are bounded by `payload`, checked above.
    let data: Vec<f32> = if item == 4 && cfg!(target_endian = "little") {
        // '<f4' on a little-endian host: the payload is the f32 buffer itself; bytemuck copies
        // it out whatever its alignment in the file (same bits as decoding element by element).
        let mut v = vec![0.0f32; n as usize];
        bytemuck::cast_slice_mut::<f32, u8>(&mut v).copy_from_slice(&bytes[header_len..]);
        v
    } else if item == 4 {
        npy.into_vec::<f32>().map_err(|e| format!("reading data: {e}"))?
    } else {
        npy.into_vec::<f64>()
            .map_err(|e| format!("reading data: {e}"))?
            .into_iter()
            .map(|v| v as f32)
            .collect()
    };
    let shape: Vec<usize> = shape.iter().map(|&d| d as usize).collect();
    Tensor::from_vec(&shape, data).map_err(|e| e.to_string())
}

/// Reject headers nested deeper than [`MAX_HEADER_NESTING`] before npyz's recursive parser
/// sees them (10 000 `[` would overflow a thread's stack, an abort no caller can catch).
fn check_header_nesting(text: &[u8]) -> std::result::Result<(), String> {
    let mut depth = 0usize;
    for &c in text {
        match c {
            b'(' | b'[' | b'{' => {
                depth += 1;
                if depth > MAX_HEADER_NESTING {
                    return Err(format!("bad .npy header: nested deeper than {MAX_HEADER_NESTING} levels"));
                }
            }
            b')' | b']' | b'}' => depth = depth.saturating_sub(1),
            _ => {}
        }
    }
    Ok(())
}

/// Total header length (magic + version + len field + header text), or None if malformed.
fn header_len(bytes: &[u8]) -> Option<usize> {
    match bytes.get(6)? {
        1 => Some(10 + u16::from_le_bytes([*bytes.get(8)?, *bytes.get(9)?]) as usize),
        2 | 3 => {
            let b = bytes.get(8..12)?;
            Some(12 + u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
        }
        _ => None,
    }
}

/// Read a sequence of geometry images, `(T, 3, H, W)` (paper Eq 1), and check it is usable:
/// rank 4, 3 channels (x, y, z), at least one frame of at least 2×2 pixels, every value
/// finite. The first bad value is reported by frame, channel and pixel (row, col).
pub fn read_geometry_images(path: &Path) -> Result<Tensor> {
    let t = read_npy(path)?;
    check_geometry_images(&t).map_err(|m| Error::format(path, m))?;
    Ok(t)
}

/// The checks of [`read_geometry_images`] on a tensor already in memory.
pub fn check_geometry_images(t: &Tensor) -> std::result::Result<(), String> {
    if t.rank() != 4 {
        return Err(format!(
            "geometry images must have shape (T, 3, H, W), got rank {} shape {:?}{}",
            t.rank(),
            t.shape,
            if t.rank() == 3 { " (save a single frame as (1, 3, H, W))" } else { "" }
        ));
    }
    let (frames, c, h, w) = t.dims4();
    if c != 3 {
        return Err(format!("geometry images need 3 channels (x, y, z), got {c} (shape {:?})", t.shape));
    }
    if frames == 0 {
        return Err(format!("no frames (shape {:?})", t.shape));
    }
    if h < 2 || w < 2 {
        return Err(format!("a geometry image needs at least 2×2 pixels, got {h}×{w} (shape {:?})", t.shape));
    }
    if let Some((i, v)) = t.first_non_finite() {
        let (frame, rest) = (i / (3 * h * w), i % (3 * h * w));
        let (ch, px) = (rest / (h * w), rest % (h * w));
        return Err(format!(
            "non-finite value {v} at frame {frame}, channel {ch} ({}), pixel (row {}, col {})",
            ["x", "y", "z"][ch],
            px / w,
            px % w
        ));
    }
    Ok(())
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
