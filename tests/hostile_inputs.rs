//! A catalogue of hostile and broken inputs, each with the error it must produce. Every error
//! names the file and the problem; nothing allocates beyond the size of the file it reads
//! (checked with a counting allocator); nothing is left half-written.

#[path = "common/tempdir.rs"]
mod tempdir;
use anisocb::io::{npz, read_npy, read_npz, write_npy, NpzEntries};
use anisocb::tensor::Tensor;
use std::path::{Path, PathBuf};
use tempdir::TempDir;

#[path = "common/alloc.rs"]
mod alloc;
use alloc::largest_alloc;

// ---------------------------------------------------------------------------------------------
// Helpers.

fn scratch(test: &str) -> TempDir {
    TempDir::new(&format!("hostile-{test}"))
}

/// Assert `r` failed with a message naming `path` and containing every piece of `want`.
#[track_caller]
fn expect_err<T: std::fmt::Debug>(r: anisocb::Result<T>, path: &Path, want: &[&str]) -> String {
    let msg = r.expect_err("hostile input was accepted").to_string();
    assert!(msg.contains(&path.display().to_string()), "error does not name {}: {msg}", path.display());
    for w in want {
        assert!(msg.contains(w), "error lacks {w:?}: {msg}");
    }
    msg
}

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

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

fn ramp(shape: &[usize]) -> Tensor {
    let n: usize = shape.iter().product();
    Tensor::from_vec(shape, (0..n).map(|i| (i % 17) as f32 / 17.0).collect()).unwrap()
}

fn file_names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
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
// Output locations that cannot be written.

#[test]
fn writing_under_a_regular_file_fails_naming_the_path_and_leaves_nothing() {
    let d = scratch("unwritable");
    let file = write(&d, "a_file", b"I am a file, not a directory");
    let target = file.join("out.npy");
    expect_err(write_npy(&target, &ramp(&[2])), &target, &["Not a directory"]);
    let sub = file.join("sub");
    expect_err(
        anisocb::io::atomic::ensure_dir(&sub),
        &sub,
        &["cannot create output directory", "output folder"],
    );
    expect_err(anisocb::io::atomic::ensure_dir(&file), &file, &["not a directory"]);
    assert_eq!(file_names(&d), ["a_file"]);
    assert_eq!(std::fs::read(&file).unwrap(), b"I am a file, not a directory");
}

#[test]
fn writing_into_a_missing_directory_fails_naming_the_path() {
    let d = scratch("missing_dir");
    let target = d.join("no/such/dir/x.npz");
    expect_err(anisocb::io::write_npz(&target, &NpzEntries::default()), &target, &["No such file"]);
    assert!(file_names(&d).is_empty());
}

// ---------------------------------------------------------------------------------------------
// The CLI: bad input → non-zero exit, a message naming the file, nothing half-written.

fn anisocb(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_anisocb")).args(args).output().unwrap()
}

/// `anisocb train --data DATA --config tiny --steps 2 EXTRA... --out OUT`.
fn train_tiny(data: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    let (data, out) = (data.to_str().unwrap(), out.to_str().unwrap());
    let mut args = vec!["train", "--data", data, "--config", "tiny", "--steps", "2"];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["--out", out]);
    anisocb(&args)
}

#[test]
fn cli_usage_errors_exit_2() {
    let o = anisocb(&["no-such-command"]);
    assert_eq!(o.status.code(), Some(2), "{o:?}");
    let o = anisocb(&["--help"]);
    assert_eq!(o.status.code(), Some(0), "{o:?}");
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

/// `anisocb train` on bad input: exit 1, the file and the problem on stderr, no output left.
#[test]
fn cli_train_refuses_bad_inputs_and_writes_nothing() {
    let d = scratch("cli_train");
    let garbage = write(&d, "garbage.npz", b"definitely not a zip file, just some words here");
    let empty = write(&d, "empty.npz", &[]);
    let mut e = NpzEntries::default();
    e.push_array("lr", ramp(&[2, 3, 4, 4]));
    let partial = d.join("partial.npz");
    anisocb::io::write_npz(&partial, &e).unwrap();
    let blocker = write(&d, "a_file", b"x");
    let missing = d.join("missing.npz");
    let cases: Vec<(&Path, PathBuf, &[&str])> = vec![
        (&garbage, d.join("out1"), &["garbage.npz", "not an .npz (zip) file"]),
        (&empty, d.join("out2"), &["empty.npz", "empty file"]),
        (&partial, d.join("out3"), &["partial.npz", "missing array 'hr'"]),
        (&missing, d.join("out4"), &["missing.npz", "No such file"]),
    ];
    for (data, out, want) in cases {
        let o = train_tiny(data, &out, &[]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{err}");
        for w in want {
            assert!(err.contains(w), "stderr lacks {w:?}: {err}");
        }
        assert!(!out.exists() || file_names(&out).is_empty(), "{:?} left {:?}", out, file_names(&out));
    }
    // A good data set but an --out below a regular file.
    let mut good = NpzEntries::default();
    good.push_array("lr", ramp(&[2, 3, 4, 4]));
    good.push_array("hr", ramp(&[2, 3, 8, 8]));
    good.push_array("boundary", ramp(&[2, 1, 8, 8]));
    good.push_array("edges", ramp(&[2, 1, 8, 8]));
    let data = d.join("data.npz");
    anisocb::io::write_npz(&data, &good).unwrap();
    let out = blocker.join("run");
    let o = train_tiny(&data, &out, &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains(&out.display().to_string()) && err.contains("cannot create output directory"),
        "{err}"
    );
    assert_eq!(std::fs::read(&blocker).unwrap(), b"x");
    // --resume from a corrupt checkpoint names it and keeps it.
    let out = d.join("resume");
    std::fs::create_dir_all(&out).unwrap();
    let ckpt = write(&out, "checkpoint.npz", b"PK\x03\x04 truncated checkpoint");
    let o = train_tiny(&data, &out, &["--resume"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains(&ckpt.display().to_string()), "{err}");
    assert_eq!(file_names(&out), ["checkpoint.npz"]);
    // --steps 0 would write untrained weights.
    let out = d.join("zero_steps");
    let (ds, os) = (data.to_str().unwrap(), out.to_str().unwrap());
    let o = anisocb(&["train", "--data", ds, "--config", "tiny", "--steps", "0", "--out", os]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("--steps 0") && err.contains("untrained"), "{err}");
    assert!(!out.exists(), "{:?}", file_names(&out));
}

#[test]
fn dataset_refuses_an_out_that_would_replace_a_runs_files() {
    let d = scratch("dataset_out");
    let run = d.join("run");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let o = anisocb(&[
        "simulate",
        "--scenario",
        "drop",
        "--res",
        "8x8",
        "--frames",
        "3",
        "--pair",
        "--out",
        &s(&run),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let geometry = run.join("lr").join("geometry.npy");
    let before = std::fs::read(&geometry).unwrap();
    let dataset = |out: &Path, extra: &[&str]| {
        let mut args = vec!["dataset".to_string(), "--runs".into(), s(&run), "--out".into(), s(out)];
        args.extend(extra.iter().map(|a| a.to_string()));
        anisocb(&args.iter().map(String::as_str).collect::<Vec<_>>())
    };
    // The run's own geometry.npy as --out, an existing file of the run renamed .npz, a .png
    // over a run file.
    let inside = write(&run.join("hr"), "old.npz", b"kept");
    let png_over = run.join("lr").join("geometry.png");
    std::fs::write(&png_over, b"kept").unwrap();
    for (out, extra, want) in [
        (geometry.clone(), vec![], "expected a .npz"),
        (inside.clone(), vec![], "is a file of the run"),
        (d.join("ok.npz"), vec!["--png".to_string(), s(&png_over)], "is a file of the run"),
    ] {
        let o = dataset(&out, &extra.iter().map(String::as_str).collect::<Vec<_>>());
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{out:?}: {err}");
        assert!(err.contains(want), "{out:?}: {err}");
    }
    assert_eq!(std::fs::read(&geometry).unwrap(), before);
    assert_eq!(std::fs::read(&inside).unwrap(), b"kept");
    assert_eq!(std::fs::read(&png_over).unwrap(), b"kept");
    assert!(!d.join("ok.npz").exists());
    // A new file beside the runs is fine.
    let o = dataset(&d.join("data.npz"), &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

// ---------------------------------------------------------------------------------------------
// OBJ grids (geom::obj)

/// OBJ text of a w×h grid of quads (vertex (i, j) at j*w+i, 1-based in faces).
fn grid_obj(w: usize, h: usize) -> String {
    let mut s = String::new();
    for j in 0..h {
        for i in 0..w {
            s +=
                &format!("v {} {} {}\n", i as f32 * 0.1, j as f32 * 0.1, ((i + j) as f32 * 0.3).sin() * 0.05);
        }
    }
    for j in 0..h - 1 {
        for i in 0..w - 1 {
            let v = j * w + i + 1;
            s += &format!("f {} {} {} {}\n", v, v + 1, v + 1 + w, v + w);
        }
    }
    s
}

#[test]
fn obj_catalogue_each_bad_file_gives_its_error() {
    use anisocb::geom::obj::read_obj_grid;
    let d = scratch("obj");
    let good = grid_obj(3, 3);
    let lines: Vec<&str> = good.lines().collect();
    let without_vertex_5: String =
        lines.iter().enumerate().filter(|(k, _)| *k != 4).map(|(_, l)| format!("{l}\n")).collect();
    let cases: Vec<(&str, Vec<u8>, &[&str])> = vec![
        ("empty.obj", vec![], &["no faces"]),
        ("only_comments.obj", b"# nothing here\n\n".to_vec(), &["no faces"]),
        ("binary.obj", vec![0xFF, 0xFE, 0x00, 0x80, 0x81], &["UTF-8"]),
        (
            "nan.obj",
            good.replacen("v 0.1 0 0", "v nan 0 0", 1).into_bytes(),
            &["line 2", "non-finite coordinate 'nan'"],
        ),
        ("inf.obj", good.replacen("v 0.1 0 0", "v 0.1 inf 0", 1).into_bytes(), &["line 2", "non-finite"]),
        ("overflow.obj", good.replacen("v 0.1 0 0", "v 1e39 0 0", 1).into_bytes(), &["line 2", "non-finite"]),
        (
            "bad_number.obj",
            good.replacen("v 0.1 0 0", "v 0.1 zero 0", 1).into_bytes(),
            &["line 2", "bad coordinate 'zero'"],
        ),
        (
            "two_coords.obj",
            good.replacen("v 0.1 0 0", "v 0.1 0", 1).into_bytes(),
            &["line 2", "3 coordinates"],
        ),
        ("absent_vertex.obj", format!("{good}f 1 2 99 4\n").into_bytes(), &["vertex 99", "9 vertices"]),
        ("index_zero.obj", good.replacen("f 1 2", "f 0 2", 1).into_bytes(), &["vertex 0"]),
        ("missing_vertex.obj", without_vertex_5.into_bytes(), &["vertex 9", "8 vertices"]),
        ("bad_index.obj", good.replacen("f 1 2", "f one 2", 1).into_bytes(), &["bad face index 'one'"]),
        (
            "relative_too_far.obj",
            good.replacen("f 1 2", "f -99 2", 1).into_bytes(),
            &["vertex -99", "9 vertices"],
        ),
        (
            "nan_uv.obj",
            format!("vt 0.5 nan\n{good}").into_bytes(),
            &["line 1", "bad texture coordinate 'nan'"],
        ),
        ("one_uv_coord.obj", format!("vt 0.5\n{good}").into_bytes(), &["line 1", "needs u and v"]),
        (
            "absent_uv.obj",
            format!("vt 0 0\n{}", good.replacen("f 1 2", "f 1/7 2", 1)).into_bytes(),
            &["texture coordinate 7", "1 texture coordinates"],
        ),
        ("bad_uv_index.obj", good.replacen("f 1 2", "f 1/x 2", 1).into_bytes(), &["bad face index '1/x'"]),
        (
            "duplicate_vertex.obj",
            format!("v 0 0 0\n{good}").replace("f ", "f_").replace("f_", "f ").into_bytes(),
            &["not a regular grid"],
        ),
        (
            "unused_vertex.obj",
            format!("{good}v 5 5 5\n").into_bytes(),
            &["not a regular grid", "vertex 10 is not used"],
        ),
        ("pentagon.obj", format!("{good}f 1 2 3 6 5\n").into_bytes(), &["not a regular grid", "5 vertices"]),
        ("mixed.obj", format!("{good}f 1 2 5\n").into_bytes(), &["not a regular grid", "mixes"]),
        (
            "odd_triangles.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n".into(),
            &["not a regular grid", "cannot pair"],
        ),
        (
            "cube.obj",
            "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n\
             f 1 2 3 4\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n"
                .into(),
            &["not a regular grid", "corner"],
        ),
        (
            // an L shape: a 3×3 grid of cells missing one corner cell
            "l_shape.obj",
            {
                let g = grid_obj(4, 4);
                g.lines()
                    .filter(|l| *l != "f 11 12 16 15")
                    .map(|l| format!("{l}\n"))
                    .collect::<String>()
                    .into_bytes()
            },
            &["not a regular grid"],
        ),
        (
            "shared_edge.obj",
            format!("{good}v 0 0 1\nv 0.1 0 1\nf 1 2 11 10\n").into_bytes(),
            &["not a regular grid"],
        ),
        (
            "repeated_vertex.obj",
            good.replacen("f 1 2 5 4", "f 1 2 2 4", 1).into_bytes(),
            &["not a regular grid"],
        ),
    ];
    for (name, bytes, want) in cases {
        let p = write(&d, name, &bytes);
        let (r, big) = largest_alloc(|| read_obj_grid(&p));
        expect_err(r, &p, want);
        assert!(big <= 64 * 1024 + 64 * bytes.len(), "{name}: allocated {big} bytes");
    }
    let p = write(&d, "ok.obj", good.as_bytes());
    let m = read_obj_grid(&p).unwrap();
    assert_eq!((m.w, m.h), (3, 3));
    // What some exporters write, read as the plain file: a byte-order mark, CR LF, CR alone.
    let bom = [&b"\xEF\xBB\xBF"[..], good.as_bytes()].concat();
    for (name, bytes) in [
        ("bom.obj", bom),
        ("crlf.obj", good.replace('\n', "\r\n").into_bytes()),
        ("cr.obj", good.replace('\n', "\r").into_bytes()),
    ] {
        assert_eq!(read_obj_grid(&write(&d, name, &bytes)).unwrap(), m, "{name}");
    }
    // A Latin-1 byte in a comment: named with its line.
    let latin1 = [b"v 0 0 0\nv 1 0 0\n# caf".as_slice(), &[0xE9], b"\n", good.as_bytes()].concat();
    let p = write(&d, "latin1.obj", &latin1);
    expect_err(read_obj_grid(&p), &p, &["line 3", "0xE9", "not UTF-8"]);
}

#[test]
fn obj_sequences_with_differing_grids_or_no_files_are_refused() {
    use anisocb::geom::obj::{list_obj_files, read_obj_sequence};
    let d = scratch("obj_seq");
    let a = write(&d, "frame_1.obj", grid_obj(3, 3).as_bytes());
    let b = write(&d, "frame_2.obj", grid_obj(4, 3).as_bytes());
    expect_err(read_obj_sequence(&[a.clone(), b.clone()]).map(|_| ()), &b, &["4x3", "first frame is 3x3"]);
    let c = write(&d, "frame_3.obj", grid_obj(3, 3).replacen("v 0.1 0 0", "v nan 0 0", 1).as_bytes());
    expect_err(read_obj_sequence(&[a.clone(), c.clone()]).map(|_| ()), &c, &["non-finite"]);
    let empty = d.join("empty_dir");
    std::fs::create_dir_all(&empty).unwrap();
    expect_err(list_obj_files(&empty), &empty, &["no .obj files"]);
    let missing = d.join("nope.obj");
    expect_err(read_obj_sequence(&[a, missing.clone()]).map(|_| ()), &missing, &["No such file"]);
}

// ---------------------------------------------------------------------------------------------
// Point caches (io::point_cache): PC2 little-endian with a signature, MDD big-endian without.

/// A PC2 file with the given header fields (little-endian) and coordinates.
fn pc2_raw(
    magic: &[u8; 12],
    version: i32,
    points: i32,
    start: f32,
    rate: f32,
    frames: i32,
    xyz: &[f32],
) -> Vec<u8> {
    let mut v = magic.to_vec();
    for w in [version.to_le_bytes(), points.to_le_bytes(), start.to_le_bytes(), rate.to_le_bytes()] {
        v.extend_from_slice(&w);
    }
    v.extend_from_slice(&frames.to_le_bytes());
    v.extend(xyz.iter().flat_map(|x| x.to_le_bytes()));
    v
}

/// An MDD file with the given counts, times and coordinates (big-endian).
fn mdd_raw(frames: i32, points: i32, times: &[f32], xyz: &[f32]) -> Vec<u8> {
    let mut v = frames.to_be_bytes().to_vec();
    v.extend_from_slice(&points.to_be_bytes());
    v.extend(times.iter().chain(xyz).flat_map(|x| x.to_be_bytes()));
    v
}

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
// `anisocb upscale`: options and output folders that could hang a run, lose a frame or
// overwrite the input. Each refusal exits 1 (2 for what clap refuses), names what is wrong and
// writes nothing.

/// A folder `name` under `d` holding `n` frames `frame_K.obj` of a 4×4 grid.
fn obj_shot(d: &Path, name: &str, n: usize) -> PathBuf {
    let dir = d.join(name);
    std::fs::create_dir_all(&dir).unwrap();
    for k in 0..n {
        write(&dir, &format!("frame_{k}.obj"), grid_obj(4, 4).as_bytes());
    }
    dir
}

/// Every file under `dir` with its bytes, to prove a refused run touched nothing.
fn snapshot(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut v = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            v.extend(snapshot(&p));
        } else {
            v.push((p.clone(), std::fs::read(&p).unwrap()));
        }
    }
    v.sort();
    v
}

/// Run `anisocb upscale ARGS`; assert it exited `code` with every piece of `want` in stderr.
#[track_caller]
fn upscale_refused(args: &[&str], code: i32, want: &[&str]) -> String {
    let mut all = vec!["upscale"];
    all.extend_from_slice(args);
    let o = anisocb(&all);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(code), "{args:?} was not refused with {code}: {err}");
    for w in want {
        assert!(err.contains(w), "{args:?}: message lacks {w:?}: {err}");
    }
    err
}

#[test]
fn upscale_refuses_absurd_option_values_and_physics_settings_before_reading_or_writing() {
    let d = scratch("upscale_values");
    let shot = obj_shot(&d, "shot", 2);
    let (inp, out) = (shot.to_str().unwrap(), d.join("out"));
    let o = out.to_str().unwrap();
    let cases: &[(&[&str], &[&str])] = &[
        (&["--eta", "1e30"], &["--eta", "from -1 to 10", "1000000000000000000000000000000"]),
        (&["--eta=-1.5"], &["--eta", "from -1 to 10"]),
        (&["--eta", "NaN"], &["--eta", "NaN"]),
        (&["--eta", "inf"], &["--eta", "inf"]),
        (&["--margin", "1e30"], &["--margin", "from 0 to 1"]),
        (&["--margin=-0.1"], &["--margin", "from 0 to 1"]),
        (&["--margin", "NaN"], &["--margin"]),
        (&["--temporal", "65"], &["--temporal", "at most 64", "65"]),
        (&["--temporal", "1000000"], &["--temporal", "at most 64"]),
        (&["--batch", "0"], &["--batch", "1 to 1024"]),
        (&["--batch", "100000000"], &["--batch", "1 to 1024"]),
        (&["--strain-iters", "1000000000"], &["--strain-iters", "at most 1000"]),
        (&["--chunk", "0"], &["--chunk", "must be ≥ 1"]),
        (&["--physics", "--physics-pin", "top,middle"], &["--physics-pin", "middle", "corners"]),
        (&["--physics", "--material", "velvet"], &["velvet", "silk"]),
        (&["--physics", "--fps", "0"], &["--fps", "1 to 1000"]),
        (&["--physics", "--physics-substeps", "NaN"], &["--physics-substeps"]),
        (&["--physics", "--gravity", "0,nan,0"], &["--gravity"]),
        (&["--physics", "--physics-drift", "NaN"], &["--physics-drift", "seconds"]),
        (&["--physics", "--physics-sphere", "1,2,3"], &["--physics-sphere", "4 numbers"]),
        (&["--physics", "--physics-box", "0,0.4,0,0.5,-0.4,0.5"], &["--physics-box", "half extents"]),
    ];
    for (extra, want) in cases {
        let mut args = vec![inp, "--out", o];
        args.extend_from_slice(extra);
        upscale_refused(&args, 1, want);
        assert!(!out.exists(), "{extra:?}: --out was created by a refused run");
    }
    // The checks come before the input is even opened: a missing input gets the option's error.
    upscale_refused(&["no/such/dir", "--out", o, "--eta", "1e30"], 1, &["--eta"]);
}

#[test]
fn upscale_refuses_thread_counts_that_would_hang() {
    let d = scratch("upscale_threads");
    let shot = obj_shot(&d, "shot", 1);
    let (inp, out) = (shot.to_str().unwrap(), d.join("out"));
    let o = out.to_str().unwrap();
    // Parsed before the worker pool is built, so clap refuses them (usage error, exit 2).
    upscale_refused(&[inp, "--out", o, "--threads", "100000"], 2, &["--threads", "more than 1024"]);
    upscale_refused(&[inp, "--out", o, "--threads", "0"], 2, &["--threads must be ≥ 1"]);
    upscale_refused(&[inp, "--out", o, "--threads=-3"], 2, &["--threads", "whole number"]);
    assert!(!out.exists());
    // demo and eval take the same bound.
    for cmd in ["demo", "eval"] {
        let r = anisocb(&[cmd, "--threads", "100000"]);
        let err = String::from_utf8_lossy(&r.stderr);
        assert_eq!(r.status.code(), Some(2), "{cmd}: {err}");
        assert!(err.contains("more than 1024"), "{cmd}: {err}");
    }
}

/// Binomial weights of the largest accepted radius, and of radii far beyond it (a library
/// caller is not bound by the CLI's check), stay finite: a constant sequence stays constant.
#[test]
fn temporal_smoothing_weights_do_not_overflow_at_any_radius() {
    use anisocb::sr::params::{UpscaleParams, MAX_TEMPORAL};
    use anisocb::sr::temporal::smooth_in_time;
    let x = Tensor::from_vec(&[5, 1, 1, 2], vec![0.25; 10]).unwrap();
    for k in [1, MAX_TEMPORAL, 600, 2000] {
        let y = smooth_in_time(&x, k);
        assert!(y.data.iter().all(|v| (v - 0.25).abs() < 1e-6), "radius {k}: {:?}", y.data);
    }
    let p = UpscaleParams { temporal: MAX_TEMPORAL + 1, ..UpscaleParams::default() };
    assert!(p.validate().unwrap_err().to_string().contains("at most 64"));
    assert!(UpscaleParams { temporal: MAX_TEMPORAL, ..UpscaleParams::default() }.validate().is_ok());
}

/// The vertices of [`grid_obj`]`(w, h)`, `frames` times, as a point cache's xyz.
fn grid_xyz(w: usize, h: usize, frames: usize) -> Vec<f32> {
    let mut v = Vec::new();
    for _ in 0..frames {
        for j in 0..h {
            for i in 0..w {
                v.extend([i as f32 * 0.1, j as f32 * 0.1, ((i + j) as f32 * 0.3).sin() * 0.05]);
            }
        }
    }
    v
}

#[test]
fn upscale_refuses_an_out_that_would_overwrite_the_input() {
    let d = scratch("upscale_out_is_input");
    let shot = obj_shot(&d, "shot", 2);
    let run = d.join("run");
    std::fs::create_dir_all(&run).unwrap();
    write_npy(&run.join("geometry.npy"), &ramp(&[2, 3, 4, 4])).unwrap();
    write_npy(&run.join("domain.npy"), &anisocb::geom::Domain::UNIT.to_tensor()).unwrap();
    let cache = d.join("cache");
    std::fs::create_dir_all(&cache).unwrap();
    write(&cache, "cloth.pc2", &pc2_raw(b"POINTCACHE2\0", 1, 16, 0.0, 1.0, 2, &grid_xyz(4, 4, 2)));
    write(&cache, "rest.obj", grid_obj(4, 4).as_bytes());
    let link = d.join("link_to_shot");
    std::os::unix::fs::symlink(&shot, &link).unwrap();
    let before = snapshot(&d);
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let (frame0, pc2, rest) = (shot.join("frame_0.obj"), cache.join("cloth.pc2"), cache.join("rest.obj"));
    let cases: Vec<(Vec<String>, String, PathBuf)> = vec![
        // OBJ folder into itself, however --out is spelled.
        (vec![s(&shot)], s(&shot), frame0.clone()),
        (vec![s(&shot)], format!("{}/.", s(&shot)), frame0.clone()),
        (vec![s(&shot)], format!("{}/../shot/", s(&shot)), frame0.clone()),
        (vec![s(&shot)], s(&link), frame0.clone()),
        (vec![s(&link)], s(&shot), link.join("frame_0.obj")),
        (vec![s(&frame0), s(&shot.join("frame_1.obj"))], s(&shot), frame0.clone()),
        // A run folder (geometry.npy + domain.npy), also as --format obj.
        (vec![s(&run)], s(&run), run.join("geometry.npy")),
        (vec![s(&run.join("geometry.npy"))], format!("{}/../run", s(&run)), run.join("geometry.npy")),
        (vec![s(&run), "--format".into(), "obj".into()], s(&run), run.join("geometry.npy")),
        // A point cache and its rest mesh.
        (vec![s(&pc2), "--rest".into(), s(&rest)], s(&cache), pc2.clone()),
    ];
    for (input, out, named) in &cases {
        let mut args: Vec<&str> = input.iter().map(String::as_str).collect();
        args.extend(["--out", out]);
        let err = upscale_refused(&args, 1, &["--out", out, &named.display().to_string(), "new folder"]);
        assert!(err.contains("is the folder of the input"), "{err}");
        assert!(snapshot(&d) == before, "{args:?}: a refused run changed a file");
    }
    // A rest mesh kept with the HR output: the cache is elsewhere, the rest mesh is in --out.
    let other = d.join("other");
    std::fs::create_dir_all(&other).unwrap();
    std::fs::rename(&pc2, other.join("cloth.pc2")).unwrap();
    let pc2 = other.join("cloth.pc2");
    let before = snapshot(&d);
    upscale_refused(&[&s(&pc2), "--rest", &s(&rest), "--out", &s(&cache)], 1, &[&s(&rest)]);
    assert!(snapshot(&d) == before);
    // An --out holding a hard link to an input frame under the output's name.
    let linked = d.join("linked");
    std::fs::create_dir_all(&linked).unwrap();
    std::fs::hard_link(&frame0, linked.join("frame_0.obj")).unwrap();
    let before = snapshot(&d);
    let err = upscale_refused(&[&s(&shot), "--out", &s(&linked)], 1, &[&s(&frame0), "a link"]);
    assert!(err.contains(&s(&linked.join("frame_0.obj"))), "{err}");
    assert!(snapshot(&d) == before);
    // A new folder works; the same command on its output then refuses to upscale it in place.
    let hr = d.join("hr");
    let o = anisocb(&["upscale", &s(&shot), "--out", &s(&hr)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let before = snapshot(&d);
    upscale_refused(&[&s(&hr), "--out", &s(&hr)], 1, &["is the folder of the input"]);
    assert!(snapshot(&d) == before);
}

#[test]
fn upscale_refuses_inputs_whose_output_names_collide_and_writes_nothing() {
    use std::os::unix::ffi::OsStrExt;
    let d = scratch("upscale_collide");
    let (a, b) = (obj_shot(&d, "shotA", 2), obj_shot(&d, "shotB", 2));
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let out = d.join("out");
    // Two folders with the same frame names: both named, nothing written.
    upscale_refused(
        &[&s(&a), &s(&b), "--out", &s(&out)],
        1,
        &[&s(&a.join("frame_0.obj")), &s(&b.join("frame_0.obj")), "its own output folder"],
    );
    assert!(!out.exists(), "a refused run created --out");
    // The same folder or file given twice.
    upscale_refused(&[&s(&a), &s(&a), "--out", &s(&out)], 1, &["given twice"]);
    upscale_refused(
        &[&s(&a), &s(&a.join("frame_1.obj")), "--out", &s(&out)],
        1,
        &["frame_1.obj is given twice"],
    );
    // Names that differ only in bytes that are not UTF-8 (both would read "caf\u{FFFD}.obj").
    let latin = d.join("latin1");
    std::fs::create_dir_all(&latin).unwrap();
    for name in [&b"caf\xe9.obj"[..], b"caf\xe8.obj"] {
        std::fs::write(latin.join(std::ffi::OsStr::from_bytes(name)), grid_obj(4, 4)).unwrap();
    }
    upscale_refused(&[&s(&latin), "--out", &s(&out)], 1, &["caf\\xE9.obj", "caf\\xE8.obj", "not UTF-8"]);
    assert!(!out.exists(), "a refused run created --out");
    // One such name alone is kept byte for byte, not renamed to the lossy "caf\u{FFFD}.obj".
    std::fs::remove_file(latin.join(std::ffi::OsStr::from_bytes(b"caf\xe8.obj"))).unwrap();
    let o = anisocb(&["upscale", &s(&latin), "--out", &s(&out)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.join(std::ffi::OsStr::from_bytes(b"caf\xe9.obj")).is_file(), "{:?}", file_names(&out));
    // A point cache's rest mesh named like an output frame of the cache (--format obj).
    let cache = d.join("cache");
    std::fs::create_dir_all(&cache).unwrap();
    let pc2 = write(&cache, "cloth.pc2", &pc2_raw(b"POINTCACHE2\0", 1, 16, 0.0, 1.0, 2, &grid_xyz(4, 4, 2)));
    let rest = write(&cache, "frame_0000.obj", grid_obj(4, 4).as_bytes());
    let out2 = d.join("out2");
    upscale_refused(
        &[&s(&pc2), "--rest", &s(&rest), "--format", "obj", "--out", &s(&out2)],
        1,
        &[&s(&out2.join("frame_0000.obj")), "written twice"],
    );
    assert!(!out2.exists(), "a refused run created --out");
}

#[test]
fn upscale_stopped_part_way_leaves_upscale_json_marked_incomplete() {
    let d = scratch("upscale_incomplete");
    let good = obj_shot(&d, "good", 4);
    let frame2 = std::fs::read(good.join("frame_2.obj")).unwrap();
    let nan = grid_obj(4, 4).replacen("v 0.1 0 0", "v nan 0 0", 1);
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let out = d.join("out");
    let summary = || std::fs::read_to_string(out.join("upscale.json")).unwrap();
    let o = anisocb(&["upscale", &s(&good), "--out", &s(&out)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(summary().contains("\"complete\": true"), "{}", summary());
    // A rerun with another η that fails on frame 2 (broken since) after writing frames 0 and
    // 1: the folder now mixes both runs' frames, and its summary must say so, not keep the
    // first run's.
    write(&good, "frame_2.obj", nan.as_bytes());
    let o = anisocb(&["upscale", &s(&good), "--out", &s(&out), "--eta", "1", "--chunk", "1"]);
    assert_eq!(o.status.code(), Some(1), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stderr).contains("frame_2.obj"));
    let text = summary();
    assert!(text.contains("\"complete\": false") && !text.contains("\"complete\": true"), "{text}");
    assert!(text.contains("rerun"), "{text}");
    // Completing the run marks the folder finished again.
    write(&good, "frame_2.obj", &frame2);
    let o = anisocb(&["upscale", &s(&good), "--out", &s(&out), "--eta", "1"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(summary().contains("\"complete\": true"), "{}", summary());
    // And --help says how to tell the two apart.
    let help = String::from_utf8_lossy(&anisocb(&["upscale", "--help"]).stdout).into_owned();
    assert!(help.contains("\"complete\": false") && help.contains("\"complete\": true"), "{help}");
}

/// OBJ text of the `w × h` grid `pos` (row-major) numbered by `s`: file vertex n is vertex n
/// of the renumbered grid. `faces`: "remap" keeps the grid's own faces, renamed (so the face
/// list differs from an unnumbered file's), "template" writes the renumbered grid's faces
/// from the usual template (identical to an unnumbered file's unless `s` transposes).
fn renumbered_obj(
    w: usize,
    h: usize,
    pos: &[[f32; 3]],
    s: anisocb::geom::mesh::GridSymmetry,
    faces: &str,
) -> String {
    let src = s.source_index(w, h);
    let mut text = String::new();
    for &k in &src {
        text += &format!("v {} {} {}\n", pos[k][0], pos[k][1], pos[k][2]);
    }
    let mut file_of = vec![0; w * h];
    for (n, &k) in src.iter().enumerate() {
        file_of[k] = n + 1;
    }
    let (tw, th) = if faces == "template" { s.dims(w, h) } else { (w, h) };
    for j in 0..th - 1 {
        for i in 0..tw - 1 {
            let q = [j * tw + i, j * tw + i + 1, (j + 1) * tw + i + 1, (j + 1) * tw + i];
            let f = q.map(|v| if faces == "template" { v + 1 } else { file_of[v] });
            text += &format!("f {} {} {} {}\n", f[0], f[1], f[2], f[3]);
        }
    }
    text
}

/// Frame `t` of a 7 × 5 sheet sliding and rippling.
fn moving_sheet(t: usize) -> Vec<[f32; 3]> {
    let mut p = Vec::new();
    for j in 0..5 {
        for i in 0..7 {
            let (x, y) = (i as f32 * 0.1, j as f32 * 0.1);
            p.push([
                x + 0.005 * t as f32,
                y,
                ((i as f32 + 1.7 * j as f32) * 0.3 + 0.2 * t as f32).sin() * 0.05,
            ]);
        }
    }
    p
}

#[test]
fn upscale_puts_renumbered_frames_back_in_the_first_frames_vertex_order() {
    use anisocb::geom::mesh::GridSymmetry;
    let all = GridSymmetry::all();
    // The 8 renumberings of a 7 × 5 grid are 8 different permutations.
    let maps: Vec<Vec<usize>> = all.iter().map(|s| s.source_index(7, 5)).collect();
    for (a, m) in maps.iter().enumerate() {
        let mut sorted = m.clone();
        sorted.sort();
        assert_eq!(sorted, (0..35).collect::<Vec<_>>(), "{:?} is not a permutation", all[a]);
        assert!(maps[..a].iter().all(|o| o != m), "{:?} repeats another symmetry", all[a]);
    }
    let [id, mi, mj, both, tr, ..] = all;
    assert_eq!(
        (mi.mirror_i, mj.mirror_j, both.mirror_i && both.mirror_j, tr.transpose),
        (true, true, true, true)
    );
    let d = scratch("upscale_renumbered");
    let (plain, renum) = (d.join("plain"), d.join("renumbered"));
    for dir in [&plain, &renum, &d.join("folded")] {
        std::fs::create_dir_all(dir).unwrap();
    }
    // Frame 1: rows reversed, faces renamed; 2: transposed (a 5 × 7 grid in the file);
    // 3 and 4: turned 180° with the unnumbered file's very faces (only the positions say so);
    // 5: the first frame's order again, also with the same faces.
    let numbering = [
        (id, "template"),
        (mj, "remap"),
        (tr, "template"),
        (both, "template"),
        (both, "template"),
        (id, "template"),
    ];
    for (t, (s, faces)) in numbering.into_iter().enumerate() {
        let p = moving_sheet(t);
        write(&plain, &format!("frame_{t}.obj"), renumbered_obj(7, 5, &p, id, "template").as_bytes());
        write(&renum, &format!("frame_{t}.obj"), renumbered_obj(7, 5, &p, s, faces).as_bytes());
    }
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let run = |input: &Path, out: &Path, extra: &[&str]| {
        let mut args = vec!["upscale".to_string(), s(input), "--out".into(), s(out)];
        args.extend(extra.iter().map(|a| a.to_string()));
        let o = anisocb(&args.iter().map(String::as_str).collect::<Vec<_>>());
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stderr).into_owned()
    };
    run(&plain, &d.join("out_plain"), &[]);
    let err = run(&renum, &d.join("out_renum"), &[]);
    // Every frame comes out exactly as if it had been exported in the first frame's order.
    for t in 0..6 {
        let f = format!("frame_{t}.obj");
        let (a, b) = (
            std::fs::read(d.join("out_plain").join(&f)).unwrap(),
            std::fs::read(d.join("out_renum").join(&f)).unwrap(),
        );
        assert!(a == b, "{f}: output differs from the unnumbered shot's");
    }
    // The user is told which frames were renumbered, and only those.
    for (t, said) in [(1, true), (2, true), (3, true), (4, false), (5, true)] {
        let f = s(&renum.join(format!("frame_{t}.obj")));
        assert_eq!(
            err.contains(&format!("note: {f}: vertices numbered differently")),
            said,
            "frame {t}: {err}"
        );
    }
    // A farm slice starting inside the renumbered frames gives the full run's bytes.
    run(&renum, &d.join("out_slice"), &["--frames", "4:6"]);
    for t in 4..6 {
        let f = format!("frame_{t}.obj");
        assert!(
            std::fs::read(d.join("out_slice").join(&f)).unwrap()
                == std::fs::read(d.join("out_plain").join(&f)).unwrap(),
            "{f}"
        );
    }
    // A renumbered frame folded exactly onto itself fits two orientations equally: refused,
    // naming the frame, with nothing claimed finished.
    let folded = d.join("folded");
    let p0 = moving_sheet(0);
    let p1: Vec<[f32; 3]> = (0..35)
        .map(|k| {
            let (i, j) = (k % 7, k / 7);
            let (a, b) = (p0[k], p0[j * 7 + 6 - i]);
            [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0, (a[2] + b[2]) / 2.0]
        })
        .collect();
    write(&folded, "frame_0.obj", renumbered_obj(7, 5, &p0, id, "template").as_bytes());
    let bad = write(&folded, "frame_1.obj", renumbered_obj(7, 5, &p1, mj, "remap").as_bytes());
    let out = d.join("out_folded");
    upscale_refused(
        &[&s(&folded), "--out", &s(&out)],
        1,
        &[&s(&bad), "two orientations", "same vertex order"],
    );
    let summary = std::fs::read_to_string(out.join("upscale.json")).unwrap_or_default();
    assert!(!summary.contains("\"complete\": true"), "{summary}");
}

/// A 64 × 64 point cache of `frames` frames and its rest mesh in `dir` (a run of seconds).
fn long_cache(dir: &Path, frames: usize) -> (PathBuf, PathBuf) {
    std::fs::create_dir_all(dir).unwrap();
    let pc2 = write(
        dir,
        "cloth.pc2",
        &pc2_raw(b"POINTCACHE2\0", 1, 4096, 0.0, 1.0, frames as i32, &grid_xyz(64, 64, frames)),
    );
    (pc2, write(dir, "rest.obj", grid_obj(64, 64).as_bytes()))
}

/// Start `anisocb upscale CACHE --rest REST --out OUT` and wait until its streamed cache's
/// temporary file exists (the run is then under way, writing).
fn start_cache_upscale(pc2: &Path, rest: &Path, out: &Path) -> std::process::Child {
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let child = std::process::Command::new(env!("CARGO_BIN_EXE_anisocb"))
        .args(["upscale", &s(pc2), "--rest", &s(rest), "--out", &s(out), "--chunk", "1", "--threads", "1"])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = std::time::Instant::now();
    while !temp_files(out).iter().any(|f| f.starts_with(".cloth.pc2.tmp.")) {
        assert!(t0.elapsed().as_secs() < 60, "the run never started writing: {:?}", file_names(out));
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    child
}

/// Hidden temporary files in `dir` (none if it does not exist).
fn temp_files(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .map(|r| {
            r.flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.contains(".tmp."))
                .collect()
        })
        .unwrap_or_default()
}

#[test]
fn upscale_interrupted_by_sigint_or_sigterm_removes_its_temp_files() {
    let d = scratch("upscale_signal");
    let (pc2, rest) = long_cache(&d.join("in"), 60);
    for sig in ["-INT", "-TERM"] {
        let out = d.join(format!("out{sig}"));
        let child = start_cache_upscale(&pc2, &rest, &out);
        let k = std::process::Command::new("kill").args([sig, &child.id().to_string()]).status().unwrap();
        assert!(k.success());
        let o = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(130), "{sig}: {err}");
        assert!(err.contains("interrupted"), "{sig}: {err}");
        assert!(temp_files(&out).is_empty(), "{sig} left {:?}", temp_files(&out));
        let summary = std::fs::read_to_string(out.join("upscale.json")).unwrap();
        assert!(summary.contains("\"complete\": false"), "{sig}: {summary}");
    }
}

#[test]
fn a_second_run_into_an_out_being_written_is_refused_and_the_first_finishes_untouched() {
    let d = scratch("upscale_concurrent");
    let (pc2, rest) = long_cache(&d.join("in"), 30);
    let out = d.join("out");
    let first = start_cache_upscale(&pc2, &rest, &out);
    // Wait until the first run holds its folder (its summary says it started).
    let t0 = std::time::Instant::now();
    while !out.join("upscale.json").exists() && t0.elapsed().as_secs() < 60 {
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    // The second run (the same shot, or another with the same output names) is refused while
    // the first writes: the folder would mix the two. It touches none of the first's files.
    let (pc2b, restb) = long_cache(&d.join("in2"), 2);
    let s = |p: &Path| p.to_str().unwrap().to_string();
    for (c, r) in [(&pc2, &rest), (&pc2b, &restb)] {
        let o = anisocb(&["upscale", &s(c), "--rest", &s(r), "--out", &s(&out)]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(err.contains("being written by another run") && err.contains("process"), "{err}");
    }
    let o = first.wait_with_output().unwrap();
    assert!(o.status.success(), "the first run failed: {}", String::from_utf8_lossy(&o.stderr));
    assert!(temp_files(&out).is_empty(), "{:?}", temp_files(&out));
}

#[test]
fn upscale_messages_say_what_is_wrong_with_what_was_given() {
    let d = scratch("upscale_messages");
    let shot = obj_shot(&d, "shot", 2);
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let out = s(&d.join("out"));
    // A single net where a bundle is needed: called a single net, with the way to bundle it.
    let single = Path::new(env!("CARGO_MANIFEST_DIR")).join("weights/domain-x2.npz");
    upscale_refused(
        &[&s(&shot), "--out", &out, "--weights", &s(&single)],
        1,
        &["single geometry net", "anisocb bundle"],
    );
    // Two point caches at once: both named, one per run.
    let xyz = grid_xyz(4, 4, 2);
    let a = write(&d, "a.pc2", &pc2_raw(b"POINTCACHE2\0", 1, 16, 0.0, 1.0, 2, &xyz));
    let b = write(&d, "b.pc2", &pc2_raw(b"POINTCACHE2\0", 1, 16, 0.0, 1.0, 2, &xyz));
    let rest = write(&d, "rest.obj", grid_obj(4, 4).as_bytes());
    upscale_refused(
        &[&s(&a), &s(&b), "--rest", &s(&rest), "--out", &out],
        1,
        &["2 of them point caches", "a.pc2", "b.pc2", "one point cache per run"],
    );
    // A cache without its rest mesh: the message reads as one sentence.
    let err = upscale_refused(
        &[&s(&a), "--out", &out],
        1,
        &["--rest", "rest mesh: an OBJ exported from the same object"],
    );
    assert!(!err.contains("  "), "stray spaces: {err:?}");
}

#[test]
fn upscale_warns_of_gaps_in_the_frame_numbers() {
    let d = scratch("upscale_gaps");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let run = |dir: &Path| {
        let o = anisocb(&["upscale", &s(dir), "--out", &s(&dir.with_extension("out"))]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stderr).into_owned()
    };
    let gap = d.join("gap");
    let every_other = d.join("every_other");
    for (dir, frames) in [(&gap, [0, 1, 2, 5]), (&every_other, [0, 2, 4, 6])] {
        std::fs::create_dir_all(dir).unwrap();
        for k in frames {
            write(dir, &format!("cloth_{k:04}.obj"), grid_obj(4, 4).as_bytes());
        }
    }
    let err = run(&gap);
    let want = format!(
        "warning: 2 frame number(s) missing between {} and {}",
        s(&gap.join("cloth_0002.obj")),
        s(&gap.join("cloth_0005.obj"))
    );
    assert!(err.contains(&want), "{err}");
    // A shot exported every other frame has no gap.
    assert!(!run(&every_other).contains("missing"));
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
