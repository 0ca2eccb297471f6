//! A catalogue of hostile and broken `.npy`, `.npz` and weights files, each with the error it
//! must produce: bad headers, truncated or trailing data, unsupported dtypes, geometry images of
//! the wrong shape or with non-finite values, corrupt or overlapping zip entries, weights whose
//! nets or config do not match, and weights that run but give absurd output. Every error names
//! the file and the problem; nothing allocates beyond the size of the file it reads (checked
//! with a counting allocator).

#[path = "common/hostile.rs"]
mod hostile;
#[path = "common/tempdir.rs"]
mod tempdir;
use anisocb::io::{npz, read_npy, read_npz, write_npy, NpzEntries};
use anisocb::tensor::Tensor;
use hostile::{anisocb, expect_err, obj_shot, ramp, scratch, upscale_refused, write};
use std::path::Path;

#[path = "common/alloc.rs"]
mod alloc;
use alloc::largest_alloc;

// ---------------------------------------------------------------------------------------------
// Helpers.

/// A `.npy` v1.0 file with a hand-written header (padded like numpy's) and raw payload.
fn npy_raw(descr: &str, fortran: bool, shape: &str, payload: &[u8]) -> Vec<u8> {
    let mut text = format!(
        "{{'descr': '{descr}', 'fortran_order': {}, 'shape': {shape}, }}",
        if fortran { "True" } else { "False" }
    );
    while (10 + text.len() + 1) % 64 != 0 {
        text.push(' ');
    }
    text.push('\n');
    let mut v = b"\x93NUMPY\x01\x00".to_vec();
    v.extend_from_slice(&(text.len() as u16).to_le_bytes());
    v.extend_from_slice(text.as_bytes());
    v.extend_from_slice(payload);
    v
}

fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

// ---------------------------------------------------------------------------------------------
// .npy

#[test]
fn npy_catalogue_each_bad_file_gives_its_error() {
    let d = scratch("npy");
    let good = anisocb::io::npy_bytes(&ramp(&[2, 3, 4, 5]));
    let mut bad_version = good.clone();
    bad_version[6] = 9;
    let cases: Vec<(&str, Vec<u8>, &[&str])> = vec![
        ("empty.npy", vec![], &["empty file"]),
        ("garbage.npy", b"hello, I am not an array at all".to_vec(), &["not a .npy file"]),
        ("tiny.npy", b"\x93NUM".to_vec(), &["not a .npy file"]),
        ("header_cut.npy", good[..40].to_vec(), &["truncated: header claims"]),
        ("data_cut.npy", good[..good.len() - 4].to_vec(), &["truncated", "needs 480 bytes", "file has 476"]),
        (
            "only_header.npy",
            npy_raw("<f4", false, "(3,)", &[]),
            &["truncated", "needs 12 bytes", "file has 0"],
        ),
        (
            "trailing.npy",
            npy_raw("<f4", false, "(2,)", &f32_bytes(&[1.0, 2.0, 3.0])),
            &["4 unexpected bytes"],
        ),
        ("int.npy", npy_raw("<i4", false, "(2,)", &[0; 8]), &["unsupported dtype", "<i4", "float32"]),
        ("bigendian.npy", npy_raw(">f4", false, "(2,)", &[0; 8]), &["unsupported dtype", ">f4"]),
        ("f16.npy", npy_raw("<f2", false, "(2,)", &[0; 4]), &["unsupported dtype", "<f2"]),
        ("object.npy", npy_raw("|O", false, "(2,)", &[0; 16]), &["unsupported dtype"]),
        ("fortran.npy", npy_raw("<f4", true, "(2, 3)", &[0; 24]), &["Fortran-order", "ascontiguousarray"]),
        ("huge_shape.npy", npy_raw("<f4", false, "(1000000, 1000000)", &[0; 16]), &["too large"]),
        (
            "overflow_shape.npy",
            npy_raw("<f4", false, "(4294967296, 4294967296, 4294967296)", &[0; 16]),
            &["too large"],
        ),
        ("negative_shape.npy", npy_raw("<f4", false, "(-1, 3)", &[0; 16]), &["bad .npy header"]),
        ("bad_literal.npy", npy_raw("<f4", false, "(2, 3", &[0; 24]), &["bad .npy header"]),
        ("version.npy", bad_version, &["unsupported .npy format version 9.0"]),
    ];
    for (name, bytes, want) in cases {
        let p = write(&d, name, &bytes);
        let (r, big) = largest_alloc(|| read_npy(&p));
        expect_err(r, &p, want);
        assert!(
            big <= 64 * 1024 + 2 * bytes.len(),
            "{name}: allocated {big} bytes for a {}-byte file",
            bytes.len()
        );
    }
}

/// A header claiming 10⁸ floats (400 MB) on a 100-byte file is refused before any allocation
/// larger than the file: the size check runs before npyz's `into_vec`.
#[test]
fn npy_header_claiming_more_than_the_file_allocates_nothing_big() {
    let d = scratch("npy_claim");
    let bytes = npy_raw("<f4", false, "(100000, 1000)", &[0; 36]);
    let p = write(&d, "claims_400mb.npy", &bytes);
    let (r, big) = largest_alloc(|| read_npy(&p));
    expect_err(r, &p, &["truncated", "needs 400000000 bytes", "file has 36"]);
    assert!(big < 64 * 1024, "allocated {big} bytes");
}

/// npyz allocates the header length the file claims before reading it; a 4 GiB claim in a
/// 12-byte file must be refused first.
#[test]
fn npy_header_length_field_is_checked_before_npyz_allocates_it() {
    let d = scratch("npy_hlen");
    let mut bytes = b"\x93NUMPY\x02\x00".to_vec();
    bytes.extend_from_slice(&0xFFFF_FFF0u32.to_le_bytes());
    bytes.extend_from_slice(b"{'descr'");
    let p = write(&d, "hlen.npy", &bytes);
    let (r, big) = largest_alloc(|| read_npy(&p));
    expect_err(r, &p, &["header claims 4294967280 bytes", "limit"]);
    assert!(big < 64 * 1024, "allocated {big} bytes");
    // Within the limit but longer than the file.
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&5000u16.to_le_bytes());
    bytes.extend_from_slice(b"{'descr'");
    let p = write(&d, "hlen2.npy", &bytes);
    expect_err(read_npy(&p), &p, &["truncated: header claims 5010 bytes, file has 18"]);
}

/// npyz's header parser is recursive: 9 000 nested brackets would overflow the stack (an
/// abort, not an error) if they reached it.
#[test]
fn npy_deeply_nested_header_is_refused_not_a_stack_overflow() {
    let d = scratch("npy_nest");
    let text = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {}, }}\n", "[".repeat(9000));
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&(text.len() as u16).to_le_bytes());
    bytes.extend_from_slice(text.as_bytes());
    let p = write(&d, "nested.npy", &bytes);
    expect_err(read_npy(&p), &p, &["nested deeper"]);
}

#[test]
fn npy_missing_file_names_it() {
    let p = scratch("npy_missing").join("nope.npy");
    expect_err(read_npy(&p), &p, &["No such file"]);
}

#[test]
fn npy_float64_and_scalars_are_read() {
    let d = scratch("npy_ok");
    let p = write(
        &d,
        "f8.npy",
        &npy_raw("<f8", false, "(2,)", &[1.5f64.to_le_bytes(), 2.5f64.to_le_bytes()].concat()),
    );
    assert_eq!(read_npy(&p).unwrap().data, [1.5, 2.5]);
    let p = write(&d, "scalar.npy", &npy_raw("<f4", false, "()", &f32_bytes(&[7.0])));
    let t = read_npy(&p).unwrap();
    assert_eq!((t.shape.len(), t.data.as_slice()), (0, &[7.0f32][..]));
}

// ---------------------------------------------------------------------------------------------
// Geometry images (T, 3, H, W)

#[test]
fn geometry_images_catalogue() {
    use anisocb::io::npy::read_geometry_images;
    let d = scratch("gi");
    let mut nan = ramp(&[2, 3, 4, 5]);
    let i = nan.idx4(1, 2, 3, 4);
    nan.data[i] = f32::NAN;
    let mut inf = ramp(&[2, 3, 4, 5]);
    let i = inf.idx4(0, 1, 0, 2);
    inf.data[i] = f32::NEG_INFINITY;
    let cases: Vec<(&str, Tensor, &[&str])> = vec![
        ("rank3.npy", ramp(&[3, 4, 5]), &["(T, 3, H, W)", "rank 3", "(1, 3, H, W)"]),
        ("rank2.npy", ramp(&[4, 5]), &["rank 2"]),
        ("four_channels.npy", ramp(&[2, 4, 4, 5]), &["3 channels", "got 4"]),
        ("no_frames.npy", ramp(&[0, 3, 4, 5]), &["no frames"]),
        ("one_row.npy", ramp(&[2, 3, 1, 5]), &["at least 2×2", "1×5"]),
        ("nan.npy", nan, &["non-finite value NaN at frame 1, channel 2 (z), pixel (row 3, col 4)"]),
        ("inf.npy", inf, &["non-finite value -inf at frame 0, channel 1 (y), pixel (row 0, col 2)"]),
    ];
    for (name, t, want) in cases {
        let p = d.join(name);
        write_npy(&p, &t).unwrap();
        expect_err(read_geometry_images(&p), &p, want);
    }
    let p = d.join("ok.npy");
    write_npy(&p, &ramp(&[2, 3, 4, 5])).unwrap();
    assert_eq!(read_geometry_images(&p).unwrap().shape, [2, 3, 4, 5]);
}

// ---------------------------------------------------------------------------------------------
// .npz

fn sample_npz() -> Vec<u8> {
    let mut e = NpzEntries::default();
    e.push_array("conv_in.weight", ramp(&[4, 3, 3, 3]));
    e.push_array("conv_in.bias", ramp(&[4]));
    e.push_file("config.json", b"{\"width\": 4}".to_vec());
    npz::npz_bytes(&e).unwrap()
}

/// Offset of the central directory's first entry (from the end-of-directory record).
fn cd_offset(b: &[u8]) -> usize {
    let eocd = b.len() - 22;
    u32::from_le_bytes(b[eocd + 16..eocd + 20].try_into().unwrap()) as usize
}

#[test]
fn npz_catalogue_each_bad_file_gives_its_error() {
    let d = scratch("npz");
    let good = sample_npz();
    let cd = cd_offset(&good);
    let mut compressed = good.clone();
    compressed[cd + 10] = 8; // method: deflate
    let mut bad_crc = good.clone();
    bad_crc[cd + 16] ^= 0xFF;
    let mut bad_data = good.clone();
    bad_data[200] ^= 0x55; // inside the first array's data: the CRC catches it
    let mut bad_cd = good.clone();
    bad_cd[cd] = b'X';
    let mut bad_local = good.clone();
    bad_local[0..4].copy_from_slice(b"PKxx");
    let mut zip64 = good.clone();
    zip64[cd + 20..cd + 24].copy_from_slice(&u32::MAX.to_le_bytes());
    let mut far_cd = good.clone();
    let eocd = far_cd.len() - 22;
    far_cd[eocd + 16..eocd + 20].copy_from_slice(&0x7FFF_FFFFu32.to_le_bytes());
    let mut many = good.clone();
    many[eocd + 10..eocd + 12].copy_from_slice(&65535u16.to_le_bytes());
    let cases: Vec<(&str, Vec<u8>, &[&str])> = vec![
        ("empty.npz", vec![], &["empty file"]),
        ("garbage.npz", b"this is plainly not a zip archive, sorry".to_vec(), &["not an .npz (zip) file"]),
        ("half.npz", good[..good.len() / 2].to_vec(), &["no zip end-of-directory record"]),
        ("cut_tail.npz", good[..good.len() - 1].to_vec(), &["no zip end-of-directory record"]),
        ("compressed.npz", compressed, &["compressed", "numpy.savez"]),
        ("bad_crc.npz", bad_crc, &["CRC mismatch"]),
        ("bad_data.npz", bad_data, &["'conv_in.weight.npy'", "CRC mismatch"]),
        ("bad_cd.npz", bad_cd, &["corrupt zip central directory"]),
        ("bad_local.npz", bad_local, &["corrupt local header"]),
        ("zip64.npz", zip64, &["zip64"]),
        ("far_cd.npz", far_cd, &["truncated zip"]),
        ("many_entries.npz", many, &["corrupt zip central directory"]),
    ];
    for (name, bytes, want) in cases {
        let p = write(&d, name, &bytes);
        let (r, big) = largest_alloc(|| read_npz(&p));
        expect_err(r, &p, want);
        assert!(big <= 64 * 1024 + 2 * bytes.len(), "{name}: allocated {big} bytes");
    }
}

#[test]
fn npz_entry_with_broken_array_names_the_array() {
    let d = scratch("npz_arr");
    let mut e = NpzEntries::default();
    e.push_file("w.npy", npy_raw("<f4", false, "(1000, 1000)", &[0; 8]));
    let p = write(&d, "w.npz", &npz::npz_bytes(&e).unwrap());
    expect_err(read_npz(&p), &p, &["array 'w'", "truncated", "needs 4000000 bytes"]);
}

#[test]
fn npz_duplicate_entries_are_refused() {
    let d = scratch("npz_dup");
    let mut e = NpzEntries::default();
    e.push_array("a", ramp(&[2]));
    e.push_array("a", ramp(&[3]));
    let p = write(&d, "dup.npz", &npz::npz_bytes(&e).unwrap());
    expect_err(read_npz(&p), &p, &["duplicate entry 'a.npy'"]);
}

/// A central directory that lists one 40 kB array 1 000 times would make the reader build
/// 40 MB from a 90 kB file; entries must not overlap.
#[test]
fn npz_overlapping_entries_cannot_multiply_memory() {
    let d = scratch("npz_overlap");
    let mut e = NpzEntries::default();
    e.push_array("big", ramp(&[10_000]));
    let good = npz::npz_bytes(&e).unwrap();
    let cd = cd_offset(&good);
    let entry = good[cd..good.len() - 22].to_vec();
    let mut bomb = good[..cd].to_vec();
    for k in 0..1000u32 {
        let mut en = entry.clone();
        let name_at = en.len() - 7; // "big.npy": vary one letter to dodge the duplicate check
        en[name_at] = b'a' + (k % 26) as u8;
        en[name_at + 1] = b'a' + (k / 26 % 26) as u8;
        en[name_at + 2] = b'a' + (k / 676) as u8;
        bomb.extend_from_slice(&en);
    }
    let cd_len = (bomb.len() - cd) as u32;
    bomb.extend_from_slice(&0x0605_4b50u32.to_le_bytes());
    bomb.extend_from_slice(&[0u8; 4]);
    bomb.extend_from_slice(&1000u16.to_le_bytes());
    bomb.extend_from_slice(&1000u16.to_le_bytes());
    bomb.extend_from_slice(&cd_len.to_le_bytes());
    bomb.extend_from_slice(&(cd as u32).to_le_bytes());
    bomb.extend_from_slice(&0u16.to_le_bytes());
    let p = write(&d, "bomb.npz", &bomb);
    expect_err(read_npz(&p), &p, &["overlap"]);
}

/// numpy's own `np.savez` (zip64 extra fields in local headers) is read; the fixture comes
/// from tests/fixtures/gen_hostile.py.
#[test]
fn npz_written_by_numpy_is_read() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/hostile/numpy_savez.npz");
    let e = read_npz(&p).unwrap();
    assert_eq!(e.array("a").unwrap().shape, [2, 3]);
    assert_eq!(e.array("a").unwrap().data, [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]);
    assert_eq!(e.array("b").unwrap().data, [1.0, 1.0]);
}

// ---------------------------------------------------------------------------------------------
// Weights (.npz with config.json)

mod weights {
    use super::*;
    use anisocb::nn::weights::{load_any, load_net, push_trunk};
    use anisocb::nn::{NetConfig, NetKind, Trunk};

    fn tiny(kind: NetKind) -> NpzEntries {
        let mut e = NpzEntries::default();
        push_trunk(&mut e, &Trunk::init(kind, NetConfig::tiny(), 1), "");
        e
    }

    fn set_config(e: &mut NpzEntries, json: &str) {
        e.files.retain(|(n, _)| n != "config.json");
        e.push_file("config.json", json.as_bytes().to_vec());
    }

    #[test]
    fn weights_catalogue_each_bad_file_gives_its_error() {
        let d = scratch("weights");
        let expect = Some((NetKind::Geometry, NetConfig::tiny()));
        let good = tiny(NetKind::Geometry);
        let cfg = String::from_utf8(good.file("config.json").unwrap().to_vec()).unwrap();
        let mut missing = good.clone();
        missing.arrays.retain(|(n, _)| n != "conv_in.weight");
        let mut wrong_shape = good.clone();
        wrong_shape.arrays.iter_mut().find(|(n, _)| n == "conv_in.bias").unwrap().1 = ramp(&[5]);
        let mut extra = good.clone();
        extra.push_array("extra.weight", ramp(&[2]));
        let mut nan = good.clone();
        nan.arrays.iter_mut().find(|(n, _)| n == "conv_in.weight").unwrap().1.data[3] = f32::NAN;
        let mut no_config = good.clone();
        no_config.files.clear();
        let mut bad_json = good.clone();
        set_config(&mut bad_json, "{\"kind\": \"geometry\", ");
        let mut bad_padding = good.clone();
        set_config(&mut bad_padding, &cfg.replace("\"zero\"", "\"mirror\""));
        let mut zero_channels = good.clone();
        set_config(&mut zero_channels, &cfg.replace("\"channels\": 4", "\"channels\": 0"));
        // A few bytes claiming a 4096-wide, 1000-block net (1.2 TB of weights): refused before
        // the net is allocated.
        let mut huge = NpzEntries::default();
        huge.push_file(
            "config.json",
            cfg.replace("\"channels\": 4", "\"channels\": 4096")
                .replace("\"blocks\": 2", "\"blocks\": 1000")
                .into_bytes(),
        );
        assert!(cfg.contains("\"channels\": 4") && cfg.contains("\"blocks\": 2"), "{cfg}");
        type Case = (&'static str, NpzEntries, Option<(NetKind, NetConfig)>, &'static [&'static str]);
        let cases: Vec<Case> = vec![
            (
                "other_config.npz",
                good.clone(),
                Some((NetKind::Geometry, NetConfig::small())),
                &["do not match the expected net", "channels"],
            ),
            (
                "other_kind.npz",
                tiny(NetKind::Boundary),
                expect,
                &["do not match the expected net", "kind: boundary vs geometry"],
            ),
            ("missing.npz", missing, expect, &["missing 1: conv_in.weight"]),
            ("wrong_shape.npz", wrong_shape, expect, &["wrong shape 1: conv_in.bias is [5], expected [4]"]),
            ("extra.npz", extra, None, &["unexpected 1: extra.weight"]),
            ("nan.npz", nan, None, &["conv_in.weight: non-finite value NaN at index 3"]),
            ("no_config.npz", no_config, None, &["not an anisocb weights file"]),
            ("bad_json.npz", bad_json, None, &["config.json"]),
            ("bad_padding.npz", bad_padding, None, &["unknown padding 'mirror'"]),
            ("zero_channels.npz", zero_channels, None, &["unreasonable net config"]),
            ("huge.npz", huge, None, &["missing"]),
        ];
        for (name, e, exp, want) in cases {
            let p = d.join(name);
            anisocb::io::write_npz(&p, &e).unwrap();
            let len = std::fs::metadata(&p).unwrap().len() as usize;
            let (r, big) = largest_alloc(|| load_net(&p, exp));
            expect_err(r, &p, want);
            assert!(big <= (1 << 20) + 4 * len, "{name}: allocated {big} bytes for a {len}-byte file");
        }
        let p = write(&d, "empty.npz", &[]);
        expect_err(load_net(&p, expect), &p, &["empty file"]);
        let p = d.join("ok.npz");
        anisocb::io::write_npz(&p, &good).unwrap();
        load_net(&p, expect).unwrap();
    }

    #[test]
    fn bundle_missing_a_net_names_it() {
        let d = scratch("bundle");
        let mut e = NpzEntries::default();
        for k in [NetKind::Geometry, NetKind::Boundary] {
            push_trunk(&mut e, &Trunk::init(k, NetConfig::tiny(), 1), &format!("{}.", k.name()));
        }
        let p = d.join("two_of_three.npz");
        anisocb::io::write_npz(&p, &e).unwrap();
        expect_err(load_any(&p).map(|_| ()), &p, &["enhance.config.json"]);
    }
}

#[test]
fn upscale_refuses_finite_but_absurd_output_from_corrupt_weights() {
    let d = scratch("upscale_absurd_weights");
    let shot = obj_shot(&d, "shot", 2);
    let s = |p: &Path| p.to_str().unwrap().to_string();
    // The shipped model with its last GeometryNet layer's weights scaled: finite, and the
    // residual it adds is thousands of times the cloth. (Not a bias shift: the four mirror views
    // would cancel it.)
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("weights/anisocb-x2.npz");
    let mut e = read_npz(&shipped).unwrap();
    let mut shifted = 0;
    for (name, t) in e.arrays.iter_mut() {
        if name.starts_with("geometry") && name.ends_with("tail.3.weight") {
            t.data.iter_mut().for_each(|v| *v *= 1e6);
            shifted += 1;
        }
    }
    assert!(shifted > 0, "no GeometryNet output layer found");
    let bad = d.join("corrupt.npz");
    anisocb::io::write_npz(&bad, &e).unwrap();
    let out = d.join("out");
    upscale_refused(&[&s(&shot), "--out", &s(&out), "--weights", &s(&bad)], 1, &["frame 0", "corrupt"]);
    assert!(!out.join("frame_0.obj").exists());
    // The same shot with the shipped weights passes the check.
    let o = anisocb(&["upscale", &s(&shot), "--out", &s(&out), "--weights", &s(&shipped)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}
