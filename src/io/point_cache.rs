//! Point caches: per-frame vertex positions of a mesh whose connectivity lives elsewhere (a
//! rest OBJ), in the two formats animation tools exchange, read and written by hand.
//!
//! - **PC2** (3ds Max Point Cache, Blender's Mesh Cache modifier), little-endian. A 32-byte
//!   header — `char[12] "POINTCACHE2\0"`, `i32 version = 1`, `i32 points`, `f32 start_frame`,
//!   `f32 sample_rate`, `i32 frames` — then `frames × points × [f32; 3]`.
//! - **MDD** (LightWave Motion Designer, Blender), big-endian. `i32 frames`, `i32 points`,
//!   `frames × f32` times (seconds), then `frames × points × [f32; 3]`.
//!
//! These are the layouts Blender's `MOD_meshcache_pc2.cc` / `MOD_meshcache_mdd.cc` read and
//! the blender-addons exporters `io_export_pc2.py` / `io_shape_mdd/export_mdd.py` write.
//! Blender's MDD exporter writes one frame block more than its header counts (a "rest" copy of
//! the first frame ahead of the counted ones); Blender reads the counted blocks from the start
//! and never touches the last. So do we: exactly one extra frame block after an MDD payload is
//! accepted and ignored, any other trailing byte is refused.
//!
//! Reading checks every header field and the size the header implies against the file before
//! allocating anything, then reads only the frames asked for ([`PointCacheReader::read_frames`]
//! seeks to them), so memory is bounded by the range, not the file. Coordinates are checked
//! (finite) as they are read. Positions are in the file's units (Blender: metres).

use crate::error::{Error, Result};
use std::fs::File;
use std::io::{self, Read, Seek, SeekFrom, Write};
use std::ops::Range;
use std::path::{Path, PathBuf};

const PC2_MAGIC: &[u8; 12] = b"POINTCACHE2\0";
const PC2_HEADER_BYTES: u64 = 32;
/// Bytes of one point: x, y, z as f32.
const POINT_BYTES: u64 = 12;
const AXES: [&str; 3] = ["x", "y", "z"];

/// Which point-cache format a file is in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CacheFormat {
    /// `.pc2`: little-endian, `POINTCACHE2` signature, start frame and sampling in the header.
    Pc2,
    /// `.mdd`: big-endian, no signature, one time (s) per frame in the header.
    Mdd,
}

impl CacheFormat {
    /// The format a file name implies: `.pc2` or `.mdd`, in any letter case.
    pub fn from_path(path: &Path) -> Option<Self> {
        let ext = path.extension()?.to_str()?;
        if ext.eq_ignore_ascii_case("pc2") {
            Some(CacheFormat::Pc2)
        } else if ext.eq_ignore_ascii_case("mdd") {
            Some(CacheFormat::Mdd)
        } else {
            None
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            CacheFormat::Pc2 => "PC2",
            CacheFormat::Mdd => "MDD",
        }
    }

    fn decode(self, bits: u32) -> f32 {
        f32::from_bits(match self {
            CacheFormat::Pc2 => u32::from_le(bits),
            CacheFormat::Mdd => u32::from_be(bits),
        })
    }

    fn encode(self, x: f32) -> [u8; 4] {
        match self {
            CacheFormat::Pc2 => x.to_le_bytes(),
            CacheFormat::Mdd => x.to_be_bytes(),
        }
    }
}

/// What a point-cache header says. The payload is `frames × points` positions, frame-major.
#[derive(Clone, Debug, PartialEq)]
pub struct CacheHeader {
    pub format: CacheFormat,
    /// Vertices per frame (≥ 1; must match the rest mesh).
    pub points: usize,
    /// Frames (samples) in the file (≥ 1).
    pub frames: usize,
    /// PC2: scene frame of the first sample. MDD has none: 0 when read.
    pub start_frame: f32,
    /// PC2: scene frames between consecutive samples (Blender's `sampling`; 1 = one sample per
    /// frame, 0.5 = two), finite and > 0. Not a rate in Hz despite the name PC2 gives it. MDD
    /// has none: 1 when read.
    pub sample_rate: f32,
    /// MDD: the time of each frame in seconds (`frames` values, finite). PC2 has none: empty.
    pub times: Vec<f32>,
}

impl CacheHeader {
    /// A header for `frames` frames of `points` points sampled at `fps` frames per second:
    /// PC2 starts at frame 0 with one sample per frame; MDD frame `i` is at `i / fps` seconds.
    pub fn new(format: CacheFormat, points: usize, frames: usize, fps: f32) -> Self {
        let times = match format {
            CacheFormat::Pc2 => Vec::new(),
            CacheFormat::Mdd => (0..frames).map(|i| i as f32 / fps).collect(),
        };
        CacheHeader { format, points, frames, start_frame: 0.0, sample_rate: 1.0, times }
    }

    /// Byte offset of frame 0's first coordinate in the file: 32 for PC2, `8 + 4·frames` for
    /// MDD. Derived rather than stored, so it cannot disagree with `format` and `frames`.
    pub fn data_offset(&self) -> u64 {
        match self.format {
            CacheFormat::Pc2 => PC2_HEADER_BYTES,
            CacheFormat::Mdd => 8 + 4 * self.frames as u64,
        }
    }

    /// Bytes of one frame's coordinates.
    pub fn frame_bytes(&self) -> u64 {
        self.points as u64 * POINT_BYTES
    }

    /// The rules a header must follow to be written or accepted when read.
    fn check(&self) -> std::result::Result<(), String> {
        if self.points == 0 {
            return Err("zero points; a point cache needs at least one vertex per frame".into());
        }
        if self.frames == 0 {
            return Err("zero frames; a point cache needs at least one frame".into());
        }
        if self.points > i32::MAX as usize || self.frames > i32::MAX as usize {
            return Err(format!(
                "{} frames × {} points: the format stores counts as i32 (at most {})",
                self.frames,
                self.points,
                i32::MAX
            ));
        }
        match self.format {
            CacheFormat::Pc2 => {
                if !self.start_frame.is_finite() {
                    return Err(format!(
                        "start frame is {}; it must be a finite frame number",
                        self.start_frame
                    ));
                }
                if !(self.sample_rate.is_finite() && self.sample_rate > 0.0) {
                    return Err(format!(
                        "sample rate is {}; it must be a finite, positive number of frames per sample",
                        self.sample_rate
                    ));
                }
                // The scene frame of every sample, as a slice of the cache computes it (start +
                // k × rate, in f32): the last is the largest.
                let last = self.frames - 1;
                let at = self.start_frame + last as f32 * self.sample_rate;
                if !(at.is_finite() && (last as f32 * self.sample_rate).is_finite()) {
                    return Err(format!(
                        "start frame {:e} and sample rate {:e} put sample {last} at scene frame \
                         {at}, beyond f32's range (±3.4e38): the header's timing is corrupt; \
                         re-export the cache",
                        self.start_frame, self.sample_rate
                    ));
                }
            }
            CacheFormat::Mdd => {
                if self.times.len() != self.frames {
                    return Err(format!("{} frame times for {} frames", self.times.len(), self.frames));
                }
                if let Some(i) = self.times.iter().position(|t| !t.is_finite()) {
                    return Err(format!(
                        "time of frame {i} is {}; frame times must be finite seconds",
                        self.times[i]
                    ));
                }
            }
        }
        Ok(())
    }
}

/// Format and sizes of a file, checked against its length.
struct Layout {
    format: CacheFormat,
    points: usize,
    frames: usize,
    header_len: usize,
}

fn le_i32(b: &[u8], at: usize) -> i32 {
    i32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

fn be_i32(b: &[u8], at: usize) -> i32 {
    i32::from_be_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

fn f32_at(format: CacheFormat, b: &[u8], at: usize) -> f32 {
    format.decode(u32::from_ne_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]]))
}

/// Check the counts a header claims against the file length, with checked arithmetic, before
/// anything is allocated for them. Returns (points, frames, header length).
fn check_counts(
    format: CacheFormat,
    frames: i32,
    points: i32,
    file_len: u64,
) -> std::result::Result<(usize, usize, usize), String> {
    if frames < 0 {
        return Err(format!("negative frame count {frames} in the header (corrupt file?)"));
    }
    if points < 0 {
        return Err(format!("negative point count {points} in the header (corrupt file?)"));
    }
    if points == 0 {
        return Err("zero points; a point cache needs at least one vertex per frame".into());
    }
    if frames == 0 {
        return Err("zero frames; a point cache needs at least one frame".into());
    }
    let (f, p) = (frames as u64, points as u64);
    let header_len = match format {
        CacheFormat::Pc2 => PC2_HEADER_BYTES,
        CacheFormat::Mdd => 8 + 4 * f, // < 2^34: cannot overflow
    };
    let frame_bytes = p * POINT_BYTES;
    let Some(need) = f.checked_mul(frame_bytes).and_then(|n| n.checked_add(header_len)) else {
        return Err(format!(
            "header claims {frames} frames × {points} points, more than any file holds (corrupt header?)"
        ));
    };
    if need > file_len {
        return Err(format!(
            "truncated: header claims {frames} frames × {points} points ({need} bytes with the \
             header), file has {file_len} bytes (cut short, or a corrupt header); copy or export it again"
        ));
    }
    let excess = file_len - need;
    // Blender's MDD exporter writes one uncounted frame block; see the module docs.
    if excess != 0 && !(format == CacheFormat::Mdd && excess == frame_bytes) {
        return Err(format!(
            "{excess} unexpected bytes after the {frames} frames × {points} points the header \
             claims (corrupt file or wrong header?)"
        ));
    }
    Ok((points as usize, frames as usize, header_len as usize))
}

/// Recognise the format and check the header's counts against `file_len`.
fn layout(bytes: &[u8], file_len: u64, path: &Path) -> Result<Layout> {
    let err = |m: String| Error::format(path, m);
    if file_len == 0 || bytes.is_empty() {
        return Err(err("empty file (0 bytes); expected a PC2 or MDD point cache".into()));
    }
    let format = if bytes.starts_with(PC2_MAGIC) {
        CacheFormat::Pc2
    } else {
        match CacheFormat::from_path(path) {
            Some(CacheFormat::Pc2) => {
                return Err(err("not a PC2 point cache: the file does not start with the \
                                POINTCACHE2 signature (wrong file, or an .mdd named .pc2?)"
                    .into()))
            }
            Some(CacheFormat::Mdd) => CacheFormat::Mdd,
            None => {
                return Err(err("unknown point-cache format: expected a .pc2 file (POINTCACHE2 \
                                signature) or an .mdd file; rename it after its format"
                    .into()))
            }
        }
    };
    let (points, frames, header_len) = match format {
        CacheFormat::Pc2 => {
            if bytes.len() < PC2_HEADER_BYTES as usize {
                return Err(err(format!(
                    "truncated PC2 header: {} bytes, the header has {PC2_HEADER_BYTES}",
                    bytes.len()
                )));
            }
            let version = le_i32(bytes, 12);
            if version != 1 {
                return Err(err(if version.swap_bytes() == 1 {
                    "big-endian PC2 (its version field reads 1 only byte-swapped); PC2 is \
                     little-endian: export it again with a PC2 exporter"
                        .into()
                } else {
                    format!("unsupported PC2 version {version} (expected 1)")
                }));
            }
            check_counts(format, le_i32(bytes, 28), le_i32(bytes, 16), file_len).map_err(err)?
        }
        CacheFormat::Mdd => {
            if bytes.len() < 8 {
                return Err(err(format!("truncated MDD header: {} bytes, the counts need 8", bytes.len())));
            }
            match check_counts(format, be_i32(bytes, 0), be_i32(bytes, 4), file_len) {
                Ok(c) => c,
                Err(m) if check_counts(format, le_i32(bytes, 0), le_i32(bytes, 4), file_len).is_ok() => {
                    return Err(err(format!(
                        "little-endian MDD: its counts fit the file only byte-swapped \
                         (read big-endian: {m}); MDD is big-endian, as Blender and LightWave \
                         write it: export it again"
                    )))
                }
                Err(m) => return Err(err(m)),
            }
        }
    };
    Ok(Layout { format, points, frames, header_len })
}

/// Parse and validate a point-cache header. `bytes` is the start of the file — at least the
/// whole header (32 bytes for PC2, `8 + 4·frames` for MDD) or all of it — and `file_len` the
/// file's full length in bytes; `path` names the file in errors and, for files without the PC2
/// signature, picks the format by its extension. Every field is checked, and the payload the
/// counts imply must fill the file exactly (see the module docs for MDD's one extra frame), so
/// a header claiming 2³¹ points in a 100-byte file is refused before anything is allocated.
pub fn parse_header(bytes: &[u8], file_len: u64, path: &Path) -> Result<CacheHeader> {
    let l = layout(bytes, file_len, path)?;
    if bytes.len() < l.header_len {
        return Err(Error::format(
            path,
            format!("truncated header: {} bytes given, the header has {}", bytes.len(), l.header_len),
        ));
    }
    let mut h = CacheHeader {
        format: l.format,
        points: l.points,
        frames: l.frames,
        start_frame: 0.0,
        sample_rate: 1.0,
        times: Vec::new(),
    };
    match l.format {
        CacheFormat::Pc2 => {
            h.start_frame = f32_at(l.format, bytes, 20);
            h.sample_rate = f32_at(l.format, bytes, 24);
        }
        // Bounded by the file length, checked in `layout`.
        CacheFormat::Mdd => h.times = (0..l.frames).map(|i| f32_at(l.format, bytes, 8 + 4 * i)).collect(),
    }
    h.check().map_err(|m| Error::format(path, m))?;
    Ok(h)
}

/// Reads frames of a point cache on demand: [`open`](Self::open) reads and checks the header,
/// [`read_frames`](Self::read_frames) seeks to the frames asked for and reads only those.
pub struct PointCacheReader<R = File> {
    src: R,
    header: CacheHeader,
    path: PathBuf,
}

impl PointCacheReader<File> {
    /// Open a `.pc2` or `.mdd` file and check its header against its length.
    pub fn open(path: &Path) -> Result<Self> {
        let file = super::open_regular(path)?;
        Self::from_reader(file, path)
    }
}

impl<R: Read + Seek> PointCacheReader<R> {
    /// Read a point cache from any seekable source (a file, a `Cursor` over bytes); `path`
    /// names it in errors and, without the PC2 signature, picks the format by extension.
    pub fn from_reader(mut src: R, path: &Path) -> Result<Self> {
        let io_err = |e| Error::io(path, e);
        let file_len = src.seek(SeekFrom::End(0)).map_err(io_err)?;
        src.seek(SeekFrom::Start(0)).map_err(io_err)?;
        let mut head = vec![0u8; file_len.min(PC2_HEADER_BYTES) as usize];
        src.read_exact(&mut head).map_err(io_err)?;
        let l = layout(&head, file_len, path)?;
        if l.header_len > head.len() {
            // MDD frame times; `layout` checked they lie within the file.
            let have = head.len();
            head.resize(l.header_len, 0);
            src.read_exact(&mut head[have..]).map_err(io_err)?;
        }
        let header = parse_header(&head, file_len, path)?;
        Ok(PointCacheReader { src, header, path: path.to_path_buf() })
    }

    /// The file it reads.
    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn header(&self) -> &CacheHeader {
        &self.header
    }

    /// Positions of `frames` (a range of frame indices, `end ≤ header().frames`), frame-major:
    /// `(frames.len() × points)` entries of `[x, y, z]`, frame `frames.start` first. Only these
    /// frames are read from disk. A non-finite coordinate is refused, naming frame and point.
    pub fn read_frames(&mut self, frames: Range<usize>) -> Result<Vec<[f32; 3]>> {
        let h = &self.header;
        let path = &self.path;
        if frames.start > frames.end || frames.end > h.frames {
            return Err(Error::config(format!(
                "{}: frames {}..{} requested, the cache has frames 0..{}",
                path.display(),
                frames.start,
                frames.end,
                h.frames
            )));
        }
        // Within the file (checked when the header was read); only a 32-bit host can overflow.
        let n = (frames.end - frames.start).checked_mul(h.points).ok_or_else(|| {
            Error::config(format!(
                "{}: {} frames do not fit in memory; read fewer",
                path.display(),
                frames.len()
            ))
        })?;
        let mut out = vec![[0.0f32; 3]; n];
        if n == 0 {
            return Ok(out);
        }
        let offset = h.data_offset() + frames.start as u64 * h.frame_bytes();
        self.src.seek(SeekFrom::Start(offset)).map_err(|e| Error::io(path, e))?;
        self.src.read_exact(bytemuck::cast_slice_mut(&mut out)).map_err(|e| Error::io(path, e))?;
        let format = h.format;
        let coords: &mut [f32] = bytemuck::cast_slice_mut(&mut out);
        for x in coords.iter_mut() {
            *x = format.decode(x.to_bits());
        }
        if let Some(i) = coords.iter().position(|x| !x.is_finite()) {
            let (point, axis) = (i / 3, i % 3);
            return Err(Error::format(
                path,
                format!(
                    "non-finite coordinate {} at frame {}, point {} ({}); the cache is corrupt \
                     or its simulation blew up: export it again",
                    coords[i],
                    frames.start + point / h.points,
                    point % h.points,
                    AXES[axis]
                ),
            ));
        }
        Ok(out)
    }
}

fn invalid(msg: String) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidInput, msg)
}

/// Write the header of `h` in its format. PC2 writes `start_frame` and `sample_rate` and
/// ignores `times`; MDD writes `times` (one per frame, seconds) and ignores the other two.
/// A header that breaks the format's rules (zero counts, counts beyond i32, a non-finite or
/// non-positive sampling, non-finite times) is an `InvalidInput` error and nothing is written.
pub fn write_header(w: &mut dyn Write, h: &CacheHeader) -> io::Result<()> {
    h.check().map_err(invalid)?;
    let (points, frames) = (h.points as i32, h.frames as i32); // ≤ i32::MAX, checked above
    match h.format {
        CacheFormat::Pc2 => {
            let mut b = Vec::with_capacity(PC2_HEADER_BYTES as usize);
            b.extend_from_slice(PC2_MAGIC);
            b.extend_from_slice(&1i32.to_le_bytes());
            b.extend_from_slice(&points.to_le_bytes());
            b.extend_from_slice(&h.start_frame.to_le_bytes());
            b.extend_from_slice(&h.sample_rate.to_le_bytes());
            b.extend_from_slice(&frames.to_le_bytes());
            w.write_all(&b)
        }
        CacheFormat::Mdd => {
            let mut b = Vec::with_capacity(8 + 4 * h.frames);
            b.extend_from_slice(&frames.to_be_bytes());
            b.extend_from_slice(&points.to_be_bytes());
            for &t in &h.times {
                b.extend_from_slice(&t.to_be_bytes());
            }
            w.write_all(&b)
        }
    }
}

/// Write one frame's positions (`points` entries of `[x, y, z]`) in `format`'s byte order.
/// A non-finite coordinate is an `InvalidInput` error naming the point; what was written
/// before it stays written (use [`write_point_cache`] for all-or-nothing files).
pub fn write_frame(w: &mut dyn Write, format: CacheFormat, pts: &[[f32; 3]]) -> io::Result<()> {
    const CHUNK: usize = 256;
    let mut buf = [0u8; CHUNK * POINT_BYTES as usize];
    for (c, chunk) in pts.chunks(CHUNK).enumerate() {
        for (k, p) in chunk.iter().enumerate() {
            for (a, &x) in p.iter().enumerate() {
                if !x.is_finite() {
                    return Err(invalid(format!("point {} ({}) is {x}", c * CHUNK + k, AXES[a])));
                }
                buf[12 * k + 4 * a..12 * k + 4 * a + 4].copy_from_slice(&format.encode(x));
            }
        }
        w.write_all(&buf[..chunk.len() * POINT_BYTES as usize])?;
    }
    Ok(())
}

/// Write a whole point cache atomically (temp file + rename): `frames` holds
/// `header.frames × header.points` positions, frame-major. Refuses, writing nothing, a path
/// whose extension names the other format, a header that breaks the format's rules, the wrong
/// number of positions, or a non-finite coordinate (named by frame and point).
pub fn write_point_cache(path: &Path, header: &CacheHeader, frames: &[[f32; 3]]) -> Result<()> {
    if let Some(f) = CacheFormat::from_path(path).filter(|&f| f != header.format) {
        return Err(Error::config(format!(
            "{}: writing a {} cache to a .{} path; name it .{}",
            path.display(),
            header.format.name(),
            f.name().to_lowercase(),
            header.format.name().to_lowercase()
        )));
    }
    header.check().map_err(|m| Error::config(format!("{}: {m}", path.display())))?;
    let need = header.frames.checked_mul(header.points);
    if need != Some(frames.len()) {
        return Err(Error::shape(format!(
            "{}: {} positions given, the header needs {} frames × {} points",
            path.display(),
            frames.len(),
            header.frames,
            header.points
        )));
    }
    if let Some(i) = frames.iter().position(|p| p.iter().any(|x| !x.is_finite())) {
        return Err(Error::numeric(format!(
            "{}: non-finite position {:?} at frame {}, point {}; nothing written",
            path.display(),
            frames[i],
            i / header.points,
            i % header.points
        )));
    }
    super::write_atomic(path, |w| {
        write_header(w, header)?;
        for f in frames.chunks(header.points) {
            write_frame(w, header.format, f)?;
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_that_overflow_u64_are_refused_not_wrapped() {
        let m = check_counts(CacheFormat::Pc2, i32::MAX, i32::MAX, 100).unwrap_err();
        assert!(m.contains("more than any file holds"), "{m}");
    }

    #[test]
    fn exactly_one_extra_frame_is_accepted_for_mdd_only() {
        let need = 8 + 4 * 2 + 2 * 3 * 12;
        assert!(check_counts(CacheFormat::Mdd, 2, 3, need + 36).is_ok());
        assert!(check_counts(CacheFormat::Mdd, 2, 3, need + 72).is_err());
        assert!(check_counts(CacheFormat::Pc2, 2, 3, 32 + 72 + 36).is_err());
    }
}
