//! PC2 and MDD point caches (io::point_cache): writer → reader round trips are bit-identical,
//! ranges read exactly their frames and only their bytes, and files spelled out byte by byte
//! here — independently of the writer — are read (and written) as the formats define them.
//! The broken-file catalogue lives in tests/hostile_point_cache.rs.

#[path = "common/tempdir.rs"]
mod tempdir;
use anisocb::io::point_cache::{
    parse_header, write_frame, write_header, write_point_cache, CacheFormat, CacheHeader, PointCacheReader,
};
use anisocb::rng::Rng;
use std::cell::Cell;
use std::io::{Cursor, Read, Seek, SeekFrom};
use std::path::Path;
use std::rc::Rc;
use tempdir::TempDir;

fn scratch(test: &str) -> TempDir {
    TempDir::new(&format!("point-cache-{test}"))
}

/// Finite f32s from random bit patterns: every exponent, subnormals, ±0.
fn random_positions(rng: &mut Rng, n: usize) -> Vec<[f32; 3]> {
    let mut coord = || loop {
        let x = f32::from_bits(rng.next_u64() as u32);
        if x.is_finite() {
            return x;
        }
    };
    (0..n).map(|_| [coord(), coord(), coord()]).collect()
}

fn bits(v: &[[f32; 3]]) -> Vec<[u32; 3]> {
    v.iter().map(|p| p.map(f32::to_bits)).collect()
}

fn read_all(path: &Path) -> (CacheHeader, Vec<[f32; 3]>) {
    let mut r = PointCacheReader::open(path).unwrap();
    let n = r.header().frames;
    let v = r.read_frames(0..n).unwrap();
    (r.header().clone(), v)
}

// ---------------------------------------------------------------------------------------------
// Round trips.

fn round_trip(format: CacheFormat, name: &str) {
    let d = scratch(name);
    let mut rng = Rng::new(7);
    let (points, frames) = (37, 11);
    let mut h = CacheHeader::new(format, points, frames, 24.0);
    match format {
        CacheFormat::Pc2 => (h.start_frame, h.sample_rate) = (-3.5, 0.25),
        CacheFormat::Mdd => h.times = (0..frames).map(|i| (i * i) as f32 * 0.013 - 0.2).collect(),
    }
    let pos = random_positions(&mut rng, points * frames);
    let p = d.join(name);
    write_point_cache(&p, &h, &pos).unwrap();
    let len = std::fs::metadata(&p).unwrap().len();
    assert_eq!(len, h.data_offset() + (frames * points * 12) as u64);
    let (back, got) = read_all(&p);
    assert_eq!(back, h);
    assert_eq!(bits(&got), bits(&pos), "positions differ after a round trip");
    assert_eq!(
        back.times.iter().map(|t| t.to_bits()).collect::<Vec<_>>(),
        h.times.iter().map(|t| t.to_bits()).collect::<Vec<_>>()
    );
}

#[test]
fn pc2_round_trip_is_bit_identical() {
    round_trip(CacheFormat::Pc2, "rt.pc2");
}

#[test]
fn mdd_round_trip_is_bit_identical() {
    round_trip(CacheFormat::Mdd, "rt.mdd");
}

/// Counts the bytes its reader hands out, so a test can see what was read from "disk".
struct CountingReader<R> {
    inner: R,
    read: Rc<Cell<u64>>,
}

impl<R: Read> Read for CountingReader<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.read.set(self.read.get() + n as u64);
        Ok(n)
    }
}

impl<R: Seek> Seek for CountingReader<R> {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        self.inner.seek(pos)
    }
}

#[test]
fn a_middle_range_reads_those_frames_and_only_their_bytes() {
    let mut rng = Rng::new(11);
    for format in [CacheFormat::Pc2, CacheFormat::Mdd] {
        let (points, frames) = (40, 50);
        let h = CacheHeader::new(format, points, frames, 30.0);
        let pos = random_positions(&mut rng, points * frames);
        let mut bytes = Vec::new();
        write_header(&mut bytes, &h).unwrap();
        for f in pos.chunks(points) {
            write_frame(&mut bytes, format, f).unwrap();
        }
        let count = Rc::new(Cell::new(0));
        let src = CountingReader { inner: Cursor::new(bytes), read: count.clone() };
        let name = if format == CacheFormat::Pc2 { "mem.pc2" } else { "mem.mdd" };
        let mut r = PointCacheReader::from_reader(src, Path::new(name)).unwrap();
        assert_eq!(count.get(), h.data_offset(), "{name}: the header read more than the header");
        count.set(0);
        let got = r.read_frames(20..23).unwrap();
        assert_eq!(count.get(), 3 * 40 * 12, "{name}: read bytes outside frames 20..23");
        assert_eq!(bits(&got), bits(&pos[20 * points..23 * points]), "{name}: wrong frames");
        // the last frame, an empty range, and ranges past the end
        assert_eq!(bits(&r.read_frames(49..50).unwrap()), bits(&pos[49 * points..]));
        assert!(r.read_frames(7..7).unwrap().is_empty());
        for bad in [49..51, 50..51] {
            let e = r.read_frames(bad.clone()).unwrap_err().to_string();
            assert!(e.contains(name) && e.contains("the cache has frames 0..50"), "{bad:?}: {e}");
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Files spelled out by hand: the layouts themselves, independent of the writer.

/// Frame 0: (1, 2, −1.5), (0.25, −0, 3); frame 1: (0.5, 4, −2), (10, 0.125, 100).
const PC2_HAND: [u8; 80] = [
    b'P', b'O', b'I', b'N', b'T', b'C', b'A', b'C', b'H', b'E', b'2', 0, // signature
    1, 0, 0, 0, // version 1 (i32 LE)
    2, 0, 0, 0, // 2 points
    0x00, 0x00, 0x80, 0x3F, // start frame 1.0 (f32 LE)
    0x00, 0x00, 0x00, 0x3F, // sampling 0.5
    2, 0, 0, 0, // 2 frames
    0x00, 0x00, 0x80, 0x3F, 0x00, 0x00, 0x00, 0x40, 0x00, 0x00, 0xC0, 0xBF, // (1, 2, -1.5)
    0x00, 0x00, 0x80, 0x3E, 0x00, 0x00, 0x00, 0x80, 0x00, 0x00, 0x40, 0x40, // (0.25, -0, 3)
    0x00, 0x00, 0x00, 0x3F, 0x00, 0x00, 0x80, 0x40, 0x00, 0x00, 0x00, 0xC0, // (0.5, 4, -2)
    0x00, 0x00, 0x20, 0x41, 0x00, 0x00, 0x00, 0x3E, 0x00, 0x00, 0xC8, 0x42, // (10, 0.125, 100)
];

/// Three frames of one point, at 0, 0.04 and 0.08 s: (1, 2, −1.5), (0.25, −0, 3), (10, 0.125, 100).
const MDD_HAND: [u8; 56] = [
    0, 0, 0, 3, // 3 frames (i32 BE)
    0, 0, 0, 1, // 1 point
    0x00, 0x00, 0x00, 0x00, // 0.0 s (f32 BE)
    0x3D, 0x23, 0xD7, 0x0A, // 0.04 s
    0x3D, 0xA3, 0xD7, 0x0A, // 0.08 s
    0x3F, 0x80, 0x00, 0x00, 0x40, 0x00, 0x00, 0x00, 0xBF, 0xC0, 0x00, 0x00, // (1, 2, -1.5)
    0x3E, 0x80, 0x00, 0x00, 0x80, 0x00, 0x00, 0x00, 0x40, 0x40, 0x00, 0x00, // (0.25, -0, 3)
    0x41, 0x20, 0x00, 0x00, 0x3E, 0x00, 0x00, 0x00, 0x42, 0xC8, 0x00, 0x00, // (10, 0.125, 100)
];

#[test]
fn hand_built_pc2_is_read_and_written_byte_for_byte() {
    let d = scratch("hand_pc2");
    let p = d.join("hand.pc2");
    std::fs::write(&p, PC2_HAND).unwrap();
    let (h, pos) = read_all(&p);
    assert_eq!((h.format, h.points, h.frames), (CacheFormat::Pc2, 2, 2));
    assert_eq!((h.start_frame, h.sample_rate, h.data_offset()), (1.0, 0.5, 32));
    assert!(h.times.is_empty());
    let want = [[1.0, 2.0, -1.5], [0.25, -0.0, 3.0], [0.5, 4.0, -2.0], [10.0, 0.125, 100.0]];
    assert_eq!(bits(&pos), bits(&want));
    let mut r = PointCacheReader::open(&p).unwrap();
    assert_eq!(bits(&r.read_frames(1..2).unwrap()), bits(&want[2..]));
    let q = d.join("again.pc2");
    write_point_cache(&q, &h, &want).unwrap();
    assert_eq!(std::fs::read(&q).unwrap(), PC2_HAND, "the writer does not reproduce the hand-built file");
}

#[test]
fn hand_built_mdd_is_read_and_written_byte_for_byte() {
    let d = scratch("hand_mdd");
    let p = d.join("hand.mdd");
    std::fs::write(&p, MDD_HAND).unwrap();
    let (h, pos) = read_all(&p);
    assert_eq!((h.format, h.points, h.frames), (CacheFormat::Mdd, 1, 3));
    assert_eq!(h.times, [0.0, 0.04, 0.08]);
    assert_eq!((h.start_frame, h.sample_rate, h.data_offset()), (0.0, 1.0, 20));
    let want = [[1.0, 2.0, -1.5], [0.25, -0.0, 3.0], [10.0, 0.125, 100.0]];
    assert_eq!(bits(&pos), bits(&want));
    let q = d.join("again.mdd");
    write_point_cache(&q, &h, &want).unwrap();
    assert_eq!(std::fs::read(&q).unwrap(), MDD_HAND, "the writer does not reproduce the hand-built file");
    // parse_header on the bytes alone agrees with the reader
    assert_eq!(parse_header(&MDD_HAND, MDD_HAND.len() as u64, &p).unwrap(), h);
}

/// Blender's io_shape_mdd exporter writes a "rest" copy of the first frame ahead of the frames
/// its header counts; like Blender we read the counted blocks from the start. A second extra
/// block is not that, and is refused.
#[test]
fn blender_mdd_with_one_uncounted_rest_frame_is_read() {
    let d = scratch("mdd_rest");
    let mut bytes = MDD_HAND.to_vec();
    bytes.extend_from_slice(&MDD_HAND[20..32]); // one more block of 1 point
    let p = d.join("blender.mdd");
    std::fs::write(&p, &bytes).unwrap();
    let (h, pos) = read_all(&p);
    assert_eq!(h.frames, 3);
    assert_eq!(bits(&pos[..1]), bits(&[[1.0, 2.0, -1.5]]));
    bytes.extend_from_slice(&MDD_HAND[20..32]);
    std::fs::write(&p, &bytes).unwrap();
    let e = PointCacheReader::open(&p).err().unwrap().to_string();
    assert!(e.contains("24 unexpected bytes"), "{e}");
}

/// Each 4-byte field after the PC2 signature, and every MDD field, byte-swapped: the file as
/// a tool with the other byte order would have written it.
fn swap_words(bytes: &[u8], from: usize) -> Vec<u8> {
    let mut v = bytes.to_vec();
    for w in v[from..].chunks_mut(4) {
        w.reverse();
    }
    v
}

#[test]
fn byte_swapped_files_are_refused_naming_the_byte_order() {
    let d = scratch("endian");
    let p = d.join("swapped.pc2");
    std::fs::write(&p, swap_words(&PC2_HAND, 12)).unwrap();
    let e = PointCacheReader::open(&p).err().unwrap().to_string();
    assert!(e.contains("swapped.pc2") && e.contains("big-endian PC2") && e.contains("little-endian"), "{e}");
    let p = d.join("swapped.mdd");
    std::fs::write(&p, swap_words(&MDD_HAND, 0)).unwrap();
    let e = PointCacheReader::open(&p).err().unwrap().to_string();
    assert!(e.contains("swapped.mdd") && e.contains("little-endian MDD") && e.contains("big-endian"), "{e}");
    // A larger MDD: its swapped counts are absurd, not merely off by a little.
    let h = CacheHeader::new(CacheFormat::Mdd, 300, 40, 25.0);
    let mut bytes = Vec::new();
    write_header(&mut bytes, &h).unwrap();
    for _ in 0..40 {
        write_frame(&mut bytes, CacheFormat::Mdd, &[[0.5, -1.0, 2.0]; 300]).unwrap();
    }
    let p = d.join("swapped_big.mdd");
    std::fs::write(&p, swap_words(&bytes, 0)).unwrap();
    let e = PointCacheReader::open(&p).err().unwrap().to_string();
    assert!(e.contains("little-endian MDD"), "{e}");
}

#[test]
fn format_comes_from_the_signature_then_the_extension() {
    for (name, want) in [
        ("a.pc2", Some(CacheFormat::Pc2)),
        ("a.PC2", Some(CacheFormat::Pc2)),
        ("dir.x/a.Mdd", Some(CacheFormat::Mdd)),
        ("a.mdd.bak", None),
        ("pc2", None),
        ("a.obj", None),
    ] {
        assert_eq!(CacheFormat::from_path(Path::new(name)), want, "{name}");
    }
    // A PC2 file is recognised by its signature whatever its name.
    let h = parse_header(&PC2_HAND, PC2_HAND.len() as u64, Path::new("cloth.cache")).unwrap();
    assert_eq!(h.format, CacheFormat::Pc2);
    let e = parse_header(&MDD_HAND, MDD_HAND.len() as u64, Path::new("cloth.cache")).unwrap_err();
    assert!(e.to_string().contains("unknown point-cache format"), "{e}");
}

#[test]
fn writer_refuses_what_the_reader_would_refuse_and_leaves_no_file() {
    let d = scratch("writer");
    let h = CacheHeader::new(CacheFormat::Pc2, 2, 2, 24.0);
    let pos = [[0.0f32; 3]; 4];
    let cases: Vec<(&str, CacheHeader, Vec<[f32; 3]>, &str)> = vec![
        ("wrong_ext.mdd", h.clone(), pos.to_vec(), "writing a PC2 cache to a .mdd path"),
        ("short.pc2", h.clone(), pos[..3].to_vec(), "3 positions given"),
        (
            "nan.pc2",
            h.clone(),
            vec![[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, f32::NAN, 0.0], [0.0; 3]],
            "frame 1, point 0",
        ),
        ("zero_points.pc2", CacheHeader::new(CacheFormat::Pc2, 0, 2, 24.0), vec![], "zero points"),
        ("rate.pc2", CacheHeader { sample_rate: 0.0, ..h.clone() }, pos.to_vec(), "sample rate is 0"),
        (
            "times.mdd",
            CacheHeader { times: vec![0.0], ..CacheHeader::new(CacheFormat::Mdd, 2, 2, 24.0) },
            pos.to_vec(),
            "1 frame times for 2 frames",
        ),
    ];
    for (name, h, pos, want) in cases {
        let p = d.join(name);
        let e = write_point_cache(&p, &h, &pos).unwrap_err().to_string();
        assert!(e.contains(name) && e.contains(want), "{name}: {e}");
        assert!(!p.exists(), "{name} was written");
    }
    assert_eq!(std::fs::read_dir(&d).unwrap().count(), 0, "temporary files left behind");
    let e = write_frame(&mut Vec::new(), CacheFormat::Mdd, &[[0.0, 0.0, f32::INFINITY]]).unwrap_err();
    assert_eq!(e.kind(), std::io::ErrorKind::InvalidInput);
    assert!(e.to_string().contains("point 0 (z) is inf"), "{e}");
}
