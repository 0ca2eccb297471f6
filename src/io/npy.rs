//! `.npy` in and out, as f32 [`Tensor`]s. Reading checks the header's claimed size against the
//! bytes actually present before allocating, accepts f32/f64 little-endian C-order arrays, and
//! rejects NaN/Inf only where the caller asks (see [`Tensor::first_non_finite`]).

use super::atomic::AtomicFile;
use crate::error::{Error, Result};
use crate::tensor::{Tensor, MAX_RANK};
use npyz::WriterBuilder;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// Largest array we accept from disk, in elements (4 GiB of f32): a header claiming more is
/// rejected before anything is allocated.
pub const MAX_ELEMENTS: u64 = 1 << 30;

pub fn read_npy(path: &Path) -> Result<Tensor> {
    let bytes = super::read_bytes(path)?;
    tensor_from_npy_bytes(&bytes).map_err(|e| e.in_file(path))
}

/// Longest header text we parse (numpy's own default `max_header_size`). The header is a Python
/// literal parsed by a recursive parser inside npyz, and npyz allocates the claimed header
/// length before reading it, so both its length and its nesting are checked here first.
pub const MAX_HEADER_BYTES: usize = 10_000;
/// Deepest bracket nesting accepted in a header (a float array's header nests 2 deep).
const MAX_HEADER_NESTING: usize = 8;

/// What a `.npy` header says: the array's shape, bytes per element (4 = '<f4', 8 = '<f8'),
/// and where the data starts.
#[derive(Clone, Debug, PartialEq)]
pub struct NpyHeader {
    pub shape: Vec<usize>,
    pub item: usize,
    pub offset: usize,
}

impl NpyHeader {
    /// Elements in the array.
    pub fn len(&self) -> usize {
        self.shape.iter().product()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Parse and check the header at the start of `bytes` (which need hold only the header) of a
/// `.npy` file of `file_len` bytes: a float array in C order whose data fills the file
/// exactly. Nothing is allocated beyond the header text.
pub fn parse_npy_header(bytes: &[u8], file_len: u64) -> Result<NpyHeader> {
    parse_npy_header_str(bytes, file_len).map_err(Error::Malformed)
}

fn parse_npy_header_str(bytes: &[u8], file_len: u64) -> std::result::Result<NpyHeader, String> {
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
    if header_len as u64 > file_len || header_len > bytes.len() {
        return Err(format!("truncated: header claims {header_len} bytes, file has {file_len}"));
    }
    check_header_nesting(&bytes[header_len - text_len..header_len])?;
    let npy = npyz::NpyFile::new(&bytes[..header_len]).map_err(|e| format!("bad .npy header: {e}"))?;
    let shape: Vec<u64> = npy.shape().to_vec();
    let descr = npy.dtype().descr();
    let item: u64 = match descr.as_str() {
        "'<f4'" => 4,
        "'<f8'" => 8,
        _ => return Err(format!("unsupported dtype {descr}; expected float32 ('<f4') or float64 ('<f8')")),
    };
    if npy.order() != npyz::Order::C {
        return Err("Fortran-order array; save it C-contiguous (np.ascontiguousarray)".into());
    }
    if shape.len() > MAX_RANK {
        return Err(format!("shape {shape:?} has {} axes; at most {MAX_RANK} are read", shape.len()));
    }
    let n = shape.iter().try_fold(1u64, |a, &d| a.checked_mul(d));
    let n = match n {
        Some(n) if n <= MAX_ELEMENTS => n,
        _ => return Err(format!("shape {shape:?} is too large (limit {MAX_ELEMENTS} elements)")),
    };
    let payload = file_len - header_len as u64;
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
    Ok(NpyHeader {
        shape: shape.iter().map(|&d| d as usize).collect(),
        item: item as usize,
        offset: header_len,
    })
}

/// Decode little-endian f32 (`item` = 4) or f64 (8) data into f32s. Fails with the index and
/// value of the first f64 that is finite but beyond f32's range: it would become ±inf, and be
/// reported as a non-finite value the file does not hold.
fn decode_floats(bytes: &[u8], item: usize) -> std::result::Result<Vec<f32>, (usize, f64)> {
    if item == 8 {
        let mut out = Vec::with_capacity(bytes.len() / 8);
        for (i, b) in bytes.chunks_exact(8).enumerate() {
            let v = f64::from_le_bytes(b.try_into().unwrap_or([0; 8]));
            let x = v as f32;
            if v.is_finite() && !x.is_finite() {
                return Err((i, v));
            }
            out.push(x);
        }
        return Ok(out);
    }
    Ok(if item == 4 && cfg!(target_endian = "little") {
        // '<f4' on a little-endian host: the payload is the f32 buffer itself; bytemuck copies
        // it out whatever its alignment in the file (same bits as decoding element by element).
        let mut v = vec![0.0f32; bytes.len() / 4];
        bytemuck::cast_slice_mut::<f32, u8>(&mut v).copy_from_slice(bytes);
        v
    } else {
        bytes.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect()
    })
}

/// What [`decode_floats`]'s error means, for element `at` (a description of where it is).
fn out_of_f32_range(v: f64, at: &str) -> String {
    format!(
        "float64 value {v:e} at {at} is finite but beyond float32's range (±3.4e38), which \
         anisocb computes in; rescale the data (positions in metres) and save it again"
    )
}

/// Parse `.npy` bytes; the error is a plain message that the caller attaches a file name to.
/// Nothing is allocated beyond what the bytes present can fill.
pub fn tensor_from_npy_bytes(bytes: &[u8]) -> Result<Tensor> {
    tensor_from_npy_bytes_str(bytes).map_err(Error::Malformed)
}

pub(crate) fn tensor_from_npy_bytes_str(bytes: &[u8]) -> std::result::Result<Tensor, String> {
    let h = parse_npy_header_str(bytes, bytes.len() as u64)?;
    // Bounded by the payload present, checked by the header parse.
    let data = decode_floats(&bytes[h.offset..], h.item)
        .map_err(|(i, v)| out_of_f32_range(v, &format!("index {i}")))?;
    Tensor::from_vec(&h.shape, data).map_err(|e| e.to_string())
}

/// A `(T, …)` `.npy` read a range of the first axis at a time (seek + read: memory for the
/// range only), for shots longer than memory.
pub struct NpyFrames {
    path: PathBuf,
    file: File,
    pub header: NpyHeader,
}

impl NpyFrames {
    pub fn open(path: &Path) -> Result<NpyFrames> {
        let mut file = super::open_regular(path)?;
        let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
        let mut head = Vec::new();
        (&mut file)
            .take(12 + MAX_HEADER_BYTES as u64)
            .read_to_end(&mut head)
            .map_err(|e| Error::io(path, e))?;
        let header = parse_npy_header(&head, len).map_err(|e| e.in_file(path))?;
        if header.shape.is_empty() {
            return Err(Error::format(path, "a scalar, not a sequence of frames"));
        }
        Ok(NpyFrames { path: path.to_path_buf(), file, header })
    }

    /// Entries along the first axis.
    pub fn frames(&self) -> usize {
        self.header.shape[0]
    }

    /// Frames `range` as a tensor of shape (range.len(), …).
    pub fn read(&mut self, range: std::ops::Range<usize>) -> Result<Tensor> {
        if range.start > range.end || range.end > self.frames() {
            return Err(Error::config(format!(
                "{}: frames {range:?} asked, the file has {}",
                self.path.display(),
                self.frames()
            )));
        }
        let per = self.header.len() / self.frames().max(1);
        let at = self.header.offset as u64 + (range.start * per * self.header.item) as u64;
        let mut bytes = vec![0u8; range.len() * per * self.header.item];
        self.file.seek(SeekFrom::Start(at)).map_err(|e| Error::io(&self.path, e))?;
        self.file.read_exact(&mut bytes).map_err(|e| Error::io(&self.path, e))?;
        let mut shape = self.header.shape.clone();
        shape[0] = range.len();
        let data = decode_floats(&bytes, self.header.item).map_err(|(i, v)| {
            let at = format!("index {} (frame {})", range.start * per + i, range.start + i / per.max(1));
            Error::format(&self.path, out_of_f32_range(v, &at))
        })?;
        Tensor::from_vec(&shape, data)
    }
}

/// A `(T, …)` float32 `.npy` written a range of the first axis at a time, appearing atomically
/// when [`NpyWriter::finish`] has written all `T` (the same bytes [`npy_bytes`] gives).
pub struct NpyWriter {
    file: AtomicFile,
    shape: Vec<usize>,
    written: usize,
}

impl NpyWriter {
    pub fn create(path: &Path, shape: &[usize]) -> Result<NpyWriter> {
        let mut file = AtomicFile::create(path)?;
        let header = npy_header_bytes(shape);
        file.writer().write_all(&header).map_err(|e| Error::io(path, e))?;
        Ok(NpyWriter { file, shape: shape.to_vec(), written: 0 })
    }

    /// Append the next frames, `t` of shape (n, …) with the remaining dims of the file's.
    pub fn append(&mut self, t: &Tensor) -> Result<()> {
        let path = self.file.path().to_path_buf();
        if t.shape.len() != self.shape.len()
            || t.shape[1..] != self.shape[1..]
            || self.written + t.shape[0] > self.shape[0]
        {
            return Err(Error::shape(format!(
                "{}: cannot append {:?} to an array of shape {:?} holding {} entries",
                path.display(),
                t.shape,
                self.shape,
                self.written
            )));
        }
        let w = self.file.writer();
        for v in &t.data {
            w.write_all(&v.to_le_bytes()).map_err(|e| Error::io(&path, e))?;
        }
        self.written += t.shape[0];
        Ok(())
    }

    /// Check every entry was written, then move the file into place.
    pub fn finish(self) -> Result<()> {
        if self.written != self.shape[0] {
            return Err(Error::shape(format!(
                "{}: {} of {} entries written",
                self.file.path().display(),
                self.written,
                self.shape[0]
            )));
        }
        self.file.commit()
    }
}

/// The `.npy` header npyz writes for a float32 C-order array of `shape`.
fn npy_header_bytes(shape: &[usize]) -> Vec<u8> {
    let mut out = Vec::new();
    let dims: Vec<u64> = shape.iter().map(|&d| d as u64).collect();
    npyz::WriteOptions::<f32>::new()
        .default_dtype()
        .shape(&dims)
        .writer(&mut out)
        .write_header_only()
        .expect("writing to a Vec cannot fail");
    out
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
    check_geometry_images(&t).map_err(|e| e.in_file(path))?;
    Ok(t)
}

/// The checks of [`read_geometry_images`] on a tensor already in memory.
pub fn check_geometry_images(t: &Tensor) -> Result<()> {
    check_geometry_images_str(t).map_err(Error::Malformed)
}

fn check_geometry_images_str(t: &Tensor) -> std::result::Result<(), String> {
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
