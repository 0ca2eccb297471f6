//! A catalogue of hostile and broken point caches (io::point_cache): PC2 little-endian with a
//! signature, MDD big-endian without. Bad headers, counts, rates and times, truncated or
//! trailing data, non-finite coordinates, headers claiming 2³¹ points, and a cache whose points
//! are not in the rest mesh's vertex order, each with the error it must produce. Every error
//! names the file and the problem; nothing allocates beyond the size of the file it reads
//! (checked with a counting allocator). Round trips of good caches are in tests/point_cache.rs.

#[path = "common/hostile.rs"]
mod hostile;
#[path = "common/tempdir.rs"]
mod tempdir;
use hostile::{anisocb, expect_err, grid_obj, grid_xyz, mdd_raw, pc2_raw, scratch, upscale_refused, write};
use std::path::Path;

#[path = "common/alloc.rs"]
mod alloc;
use alloc::largest_alloc;

// ---------------------------------------------------------------------------------------------
// Helpers.

/// Open and read every frame: what a caller does with a cache.
fn read_cache(p: &Path) -> anisocb::Result<Vec<[f32; 3]>> {
    let mut r = anisocb::io::PointCacheReader::open(p)?;
    let n = r.header().frames;
    r.read_frames(0..n)
}

/// 3 frames × 2 points with one coordinate replaced.
fn xyz_with(at: usize, x: f32) -> Vec<f32> {
    let mut v: Vec<f32> = (0..18).map(|i| i as f32 * 0.25 - 1.0).collect();
    v[at] = x;
    v
}

// ---------------------------------------------------------------------------------------------
// Broken files

#[test]
fn pc2_catalogue_each_bad_file_gives_its_error() {
    let d = scratch("pc2");
    const SIG: &[u8; 12] = b"POINTCACHE2\0";
    let ok = xyz_with(0, 0.0);
    let good = pc2_raw(SIG, 1, 2, 1.0, 1.0, 3, &ok);
    let big_endian: Vec<u8> = {
        let mut v = good.clone();
        v[12..].chunks_mut(4).for_each(|w| w.reverse());
        v
    };
    let cases: Vec<(&str, Vec<u8>, &[&str])> = vec![
        ("empty.pc2", vec![], &["empty file"]),
        ("short.pc2", good[..14].to_vec(), &["truncated PC2 header: 14 bytes"]),
        ("signature.pc2", pc2_raw(b"POINTCACHE3\0", 1, 2, 1.0, 1.0, 3, &ok), &["POINTCACHE2 signature"]),
        ("text.pc2", b"hello, I am not a point cache at all".to_vec(), &["POINTCACHE2 signature"]),
        ("version.pc2", pc2_raw(SIG, 2, 2, 1.0, 1.0, 3, &ok), &["unsupported PC2 version 2 (expected 1)"]),
        ("big_endian.pc2", big_endian, &["big-endian PC2", "little-endian"]),
        ("negative_points.pc2", pc2_raw(SIG, 1, -5, 1.0, 1.0, 3, &ok), &["negative point count -5"]),
        ("zero_points.pc2", pc2_raw(SIG, 1, 0, 1.0, 1.0, 3, &[]), &["zero points"]),
        ("negative_frames.pc2", pc2_raw(SIG, 1, 2, 1.0, 1.0, -1, &ok), &["negative frame count -1"]),
        ("zero_frames.pc2", pc2_raw(SIG, 1, 2, 1.0, 1.0, 0, &[]), &["zero frames"]),
        (
            "truncated.pc2",
            good[..good.len() - 4].to_vec(),
            &["truncated: header claims 3 frames × 2 points (104 bytes with the header), file has 100 bytes"],
        ),
        (
            "trailing.pc2",
            [&good[..], &[0; 4]].concat(),
            &["4 unexpected bytes after the 3 frames × 2 points"],
        ),
        ("extra_frame.pc2", [&good[..], &[0; 24]].concat(), &["24 unexpected bytes"]),
        ("nan_start.pc2", pc2_raw(SIG, 1, 2, f32::NAN, 1.0, 3, &ok), &["start frame is NaN"]),
        ("negative_rate.pc2", pc2_raw(SIG, 1, 2, 1.0, -1.0, 3, &ok), &["sample rate is -1", "positive"]),
        ("zero_rate.pc2", pc2_raw(SIG, 1, 2, 1.0, 0.0, 3, &ok), &["sample rate is 0"]),
        ("inf_rate.pc2", pc2_raw(SIG, 1, 2, 1.0, f32::INFINITY, 3, &ok), &["sample rate is inf"]),
        (
            "nan_coordinate.pc2",
            pc2_raw(SIG, 1, 2, 1.0, 1.0, 3, &xyz_with(10, f32::NAN)),
            &["non-finite coordinate NaN at frame 1, point 1 (y)"],
        ),
        (
            "inf_coordinate.pc2",
            pc2_raw(SIG, 1, 2, 1.0, 1.0, 3, &xyz_with(2, f32::NEG_INFINITY)),
            &["non-finite coordinate -inf at frame 0, point 0 (z)"],
        ),
        (
            "huge_points.pc2",
            pc2_raw(SIG, 1, i32::MAX, 1.0, 1.0, 3, &ok),
            &["truncated: header claims 3 frames × 2147483647 points"],
        ),
        (
            "overflowing_counts.pc2",
            pc2_raw(SIG, 1, i32::MAX, 1.0, 1.0, i32::MAX, &ok),
            &["more than any file holds"],
        ),
        ("unknown.cache", mdd_raw(1, 1, &[0.0], &[0.0; 3]), &["unknown point-cache format", ".pc2", ".mdd"]),
    ];
    cache_catalogue(&d, cases, "ok.pc2", &good);
}

#[test]
fn mdd_catalogue_each_bad_file_gives_its_error() {
    let d = scratch("mdd");
    let ok = xyz_with(0, 0.0);
    let t = [0.0, 0.04, 0.08];
    let good = mdd_raw(3, 2, &t, &ok);
    let little_endian: Vec<u8> = {
        let mut v = good.clone();
        v.chunks_mut(4).for_each(|w| w.reverse());
        v
    };
    let cases: Vec<(&str, Vec<u8>, &[&str])> = vec![
        ("empty.mdd", vec![], &["empty file"]),
        ("short.mdd", good[..5].to_vec(), &["truncated MDD header: 5 bytes"]),
        ("negative_frames.mdd", mdd_raw(-3, 2, &t, &ok), &["negative frame count -3"]),
        ("negative_points.mdd", mdd_raw(3, -2, &t, &ok), &["negative point count -2"]),
        ("zero_points.mdd", mdd_raw(3, 0, &t, &[]), &["zero points"]),
        ("zero_frames.mdd", mdd_raw(0, 2, &[], &[]), &["zero frames"]),
        ("little_endian.mdd", little_endian, &["little-endian MDD", "big-endian"]),
        (
            "truncated.mdd",
            good[..good.len() - 1].to_vec(),
            &["truncated: header claims 3 frames × 2 points (92 bytes with the header), file has 91 bytes"],
        ),
        ("times_only.mdd", mdd_raw(3, 2, &t, &[]), &["truncated", "file has 20 bytes"]),
        (
            "trailing.mdd",
            [&good[..], &[0; 4]].concat(),
            &["4 unexpected bytes after the 3 frames × 2 points"],
        ),
        ("two_extra_frames.mdd", [&good[..], &[0; 48]].concat(), &["48 unexpected bytes"]),
        ("nan_time.mdd", mdd_raw(3, 2, &[0.0, f32::NAN, 0.08], &ok), &["time of frame 1 is NaN"]),
        ("inf_time.mdd", mdd_raw(3, 2, &[0.0, 0.04, f32::INFINITY], &ok), &["time of frame 2 is inf"]),
        (
            "nan_coordinate.mdd",
            mdd_raw(3, 2, &t, &xyz_with(12, f32::NAN)),
            &["non-finite coordinate NaN at frame 2, point 0 (x)"],
        ),
        (
            "huge_frames.mdd",
            mdd_raw(i32::MAX, 2, &t, &ok),
            &["truncated: header claims 2147483647 frames × 2 points"],
        ),
        ("overflowing_counts.mdd", mdd_raw(i32::MAX, i32::MAX, &t, &ok), &["more than any file holds"]),
        ("mdd_named.pc2", mdd_raw(3, 2, &t, &ok), &["POINTCACHE2 signature", "an .mdd named .pc2?"]),
    ];
    cache_catalogue(&d, cases, "ok.mdd", &good);
}

/// Each bad point cache gives its error without allocating much beyond its size; the good
/// one (6 positions) reads.
fn cache_catalogue(d: &Path, cases: Vec<(&str, Vec<u8>, &[&str])>, good_name: &str, good: &[u8]) {
    for (name, bytes, want) in cases {
        let p = write(d, name, &bytes);
        let (r, big) = largest_alloc(|| read_cache(&p));
        expect_err(r, &p, want);
        assert!(
            big <= 64 * 1024 + 2 * bytes.len(),
            "{name}: allocated {big} bytes for a {}-byte file",
            bytes.len()
        );
    }
    let p = write(d, good_name, good);
    assert_eq!(read_cache(&p).unwrap().len(), 6);
}

/// A header claiming 2³¹ points or frames (as i32: 2³¹ − 1, or 2³¹ read as a negative count) in
/// a 100-byte file is refused before anything near the claim is allocated.
#[test]
fn point_cache_header_claiming_2_31_points_allocates_nothing_big() {
    let d = scratch("cache_claim");
    let pad = |mut v: Vec<u8>| {
        v.resize(100, 0);
        v
    };
    for (k, claim) in [0x7FFF_FFFFu32, 0x8000_0000].into_iter().enumerate() {
        let c = claim as i32;
        let files = [
            ("points.pc2", pad(pc2_raw(b"POINTCACHE2\0", 1, c, 0.0, 1.0, 1, &[]))),
            ("frames.pc2", pad(pc2_raw(b"POINTCACHE2\0", 1, 1, 0.0, 1.0, c, &[]))),
            ("points.mdd", pad(mdd_raw(1, c, &[0.0], &[]))),
            ("frames.mdd", pad(mdd_raw(c, 1, &[0.0], &[]))),
        ];
        for (name, bytes) in files {
            let p = write(&d, &format!("{k}_{name}"), &bytes);
            let (r, big) = largest_alloc(|| read_cache(&p));
            let msg = expect_err(r, &p, &[]);
            assert!(msg.contains("truncated") || msg.contains("negative"), "{name}: {msg}");
            assert!(big < 64 * 1024, "{name}: allocated {big} bytes");
        }
    }
}

// ---------------------------------------------------------------------------------------------
// `anisocb upscale` on a cache that does not fit its rest mesh.

#[test]
fn upscale_refuses_a_point_cache_whose_points_are_not_in_the_rest_meshs_order() {
    let d = scratch("upscale_cache_order");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let rest = write(&d, "rest.obj", grid_obj(8, 8).as_bytes());
    let xyz = grid_xyz(8, 8, 2);
    // Shuffled (vertex k takes point 37k mod 64), and merely scaled ×3 (an object scaled in the
    // scene: the same order, accepted).
    let shuffled: Vec<f32> = (0..128)
        .flat_map(|k| {
            let (f, v) = (k / 64, (k % 64) * 37 % 64);
            xyz[(f * 64 + v) * 3..(f * 64 + v) * 3 + 3].to_vec()
        })
        .collect();
    let scaled: Vec<f32> = xyz.iter().map(|v| 3.0 * v).collect();
    let bad = write(&d, "shuffled.pc2", &pc2_raw(b"POINTCACHE2\0", 1, 64, 0.0, 1.0, 2, &shuffled));
    let good = write(&d, "scaled.pc2", &pc2_raw(b"POINTCACHE2\0", 1, 64, 0.0, 1.0, 2, &scaled));
    upscale_refused(
        &[&s(&bad), "--rest", &s(&rest), "--out", &s(&d.join("o1"))],
        1,
        &["shuffled.pc2", "not in the rest mesh's vertex order"],
    );
    let o = anisocb(&["upscale", &s(&good), "--rest", &s(&rest), "--out", &s(&d.join("o2"))]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn upscale_refuses_a_point_cache_whose_later_frames_are_shuffled_naming_the_frame() {
    let d = scratch("upscale_cache_later_order");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let rest = write(&d, "rest.obj", grid_obj(8, 8).as_bytes());
    let xyz = grid_xyz(8, 8, 4);
    // Frames 0 and 1 in the rest mesh's order; frames 2 and 3 shuffled (vertex k takes point
    // 37k mod 64: a cache mixed from another export).
    let mixed: Vec<f32> = (0..256)
        .flat_map(|k| {
            let (f, v) = (k / 64, k % 64);
            let v = if f >= 2 { v * 37 % 64 } else { v };
            xyz[(f * 64 + v) * 3..(f * 64 + v) * 3 + 3].to_vec()
        })
        .collect();
    let bad = write(&d, "mixed.pc2", &pc2_raw(b"POINTCACHE2\0", 1, 64, 0.0, 1.0, 4, &mixed));
    upscale_refused(
        &[&s(&bad), "--rest", &s(&rest), "--out", &s(&d.join("o"))],
        1,
        &["mixed.pc2", "frame 2", "not in the rest mesh's vertex order"],
    );
}
