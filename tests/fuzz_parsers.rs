//! A bounded, deterministic fuzz harness for every parser of outside files: valid seeds are
//! mutated (bit flips, interesting bytes, truncations, splices, chunk copies, huge integers
//! in binary fields and in header text) and fed to the parser, which must return `Ok` or
//! `Err` — never panic, never hang, never allocate far beyond the input's size.
//!
//! Budget per target: `ANISOCB_FUZZ_ITERS` executions (default 20 000) or `ANISOCB_FUZZ_SECS`
//! seconds (default 2), whichever comes first; `ANISOCB_FUZZ_SEED` changes the stream. For a
//! long run: `ANISOCB_FUZZ_ITERS=100000000 ANISOCB_FUZZ_SECS=300 cargo test --release --test
//! fuzz_parsers -- --nocapture`. A failing input is saved under the cargo target tmpdir and
//! reported with its iteration number.

use anisocb::io::npz::{npz_bytes, npz_from_bytes};
use anisocb::io::{npy_bytes, tensor_from_npy_bytes, NpzEntries};
use anisocb::rng::Rng;
use anisocb::tensor::Tensor;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::time::{Duration, Instant};

#[path = "common/alloc.rs"]
mod alloc;
use alloc::largest_alloc;

// ---------------------------------------------------------------------------------------------
// PRNG and mutator.

const INTERESTING: [u64; 12] =
    [0, 1, 2, 0x7F, 0x80, 0xFF, 0xFFFF, 0x7FFF_FFFF, 0xFFFF_FFFF, 1 << 31, 1 << 40, u64::MAX];

const HUGE_TEXT: [&str; 8] =
    ["99999999999999999999999", "4294967296", "1073741825", "-1", "0", "(", "[[[[[[[[[[[[[[", "'<f8'"];

/// One to four random mutations of `seed`, sometimes splicing in part of `other`.
fn mutate(rng: &mut Rng, seed: &[u8], other: &[u8]) -> Vec<u8> {
    let mut v = seed.to_vec();
    for _ in 0..1 + rng.below(4) {
        let len = v.len();
        match rng.below(10) {
            0 | 1 if len > 0 => {
                let i = rng.below(len);
                v[i] ^= 1 << rng.below(8);
            }
            2 if len > 0 => {
                let i = rng.below(len);
                v[i] = INTERESTING[rng.below(INTERESTING.len())] as u8;
            }
            3 if len >= 4 => {
                // a binary length/offset/count field set to an extreme value
                let i = rng.below(len - 3);
                let x = INTERESTING[rng.below(INTERESTING.len())] as u32;
                let b = if rng.below(2) == 0 { x.to_le_bytes() } else { x.to_be_bytes() };
                let w = if rng.below(2) == 0 { 2 } else { 4 };
                v[i..i + w].copy_from_slice(&b[..w]);
            }
            4 => v.truncate(rng.below(len + 1)),
            5 if !other.is_empty() => {
                // splice: our prefix + a random tail of the other seed
                let cut = rng.below(len + 1);
                let from = rng.below(other.len());
                v.truncate(cut);
                v.extend_from_slice(&other[from..]);
            }
            6 if len > 0 => {
                // copy a chunk elsewhere (duplicates headers, directory entries)
                let a = rng.below(len);
                let n = rng.below((len - a).min(256) + 1);
                let chunk = v[a..a + n].to_vec();
                let at = rng.below(v.len() + 1);
                v.splice(at..at, chunk);
            }
            7 => {
                // replace a run of digits (e.g. a shape in an .npy header) by something huge
                let digits: Vec<usize> = (0..len).filter(|&i| v[i].is_ascii_digit()).collect();
                if !digits.is_empty() {
                    let s = digits[rng.below(digits.len())];
                    let e = (s..len).find(|&i| !v[i].is_ascii_digit()).unwrap_or(len);
                    let t = HUGE_TEXT[rng.below(HUGE_TEXT.len())].as_bytes();
                    v.splice(s..e, t.iter().copied());
                }
            }
            8 => {
                let n = rng.below(64);
                for _ in 0..n {
                    v.push(rng.next_u64() as u8);
                }
            }
            _ if len > 1 => {
                let a = rng.below(len);
                let b = rng.below(len);
                v.swap(a, b);
            }
            _ => {}
        }
    }
    v
}

// ---------------------------------------------------------------------------------------------
// Harness.

fn env_or(name: &str, default: u64) -> u64 {
    std::env::var(name).ok().and_then(|s| s.parse().ok()).unwrap_or(default)
}

/// Fuzz `parse` from `seeds`. `parse` returns whether the input was accepted.
fn fuzz(target: &str, seeds: &[Vec<u8>], parse: impl Fn(&[u8]) -> bool) {
    let iters = env_or("ANISOCB_FUZZ_ITERS", 20_000);
    let secs = env_or("ANISOCB_FUZZ_SECS", 3);
    let base = env_or("ANISOCB_FUZZ_SEED", 0x5EED);
    let name_hash = target.bytes().fold(0u64, |h, b| h.wrapping_mul(31).wrapping_add(b as u64));
    let mut rng = Rng::new(base ^ name_hash);
    let start = Instant::now();
    let budget = Duration::from_secs(secs);
    let (mut runs, mut accepted, mut slowest) = (0u64, 0u64, Duration::ZERO);
    // Seeds themselves must parse.
    for (k, s) in seeds.iter().enumerate() {
        assert!(parse(s), "{target}: seed {k} is not accepted by its own parser");
    }
    while runs < iters && start.elapsed() < budget {
        let a = &seeds[rng.below(seeds.len())];
        let b = &seeds[rng.below(seeds.len())];
        let input = mutate(&mut rng, a, b);
        let t0 = Instant::now();
        let (r, big) = largest_alloc(|| catch_unwind(AssertUnwindSafe(|| parse(&input))));
        let dt = t0.elapsed();
        slowest = slowest.max(dt);
        let problem = match r {
            Err(_) => Some("panicked".to_string()),
            Ok(_) if big > (1 << 20) + 4 * input.len() => {
                Some(format!("allocated {big} bytes at once for a {}-byte input", input.len()))
            }
            Ok(_) if dt > Duration::from_secs(2) => Some(format!("took {dt:?} (hang?)")),
            Ok(ok) => {
                accepted += ok as u64;
                None
            }
        };
        if let Some(p) = problem {
            let path =
                std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("fuzz-{target}-{runs}.bin"));
            let _ = std::fs::write(&path, &input);
            panic!("{target}: input #{runs} {p}; saved to {}", path.display());
        }
        runs += 1;
    }
    eprintln!(
        "fuzz {target}: {runs} executions in {:.2?} ({accepted} accepted), slowest {slowest:?}",
        start.elapsed()
    );
}

fn ramp(shape: &[usize]) -> Tensor {
    let n: usize = shape.iter().product();
    Tensor::from_vec(shape, (0..n).map(|i| (i % 13) as f32 * 0.1 - 0.3).collect()).unwrap()
}

fn npy_seeds() -> Vec<Vec<u8>> {
    let mut v =
        vec![npy_bytes(&ramp(&[2, 3, 4, 5])), npy_bytes(&ramp(&[7])), npy_bytes(&ramp(&[1, 3, 2, 2]))];
    // float64, version 2.0 header, hand-written like numpy's
    let text = "{'descr': '<f8', 'fortran_order': False, 'shape': (3,), }";
    let mut f8 = b"\x93NUMPY\x02\x00".to_vec();
    let pad = 64 - (12 + text.len() + 1) % 64;
    f8.extend_from_slice(&((text.len() + pad + 1) as u32).to_le_bytes());
    f8.extend_from_slice(text.as_bytes());
    f8.extend(std::iter::repeat_n(b' ', pad));
    f8.push(b'\n');
    for x in [1.0f64, -2.0, 3.5] {
        f8.extend_from_slice(&x.to_le_bytes());
    }
    v.push(f8);
    v
}

fn npz_seeds() -> Vec<Vec<u8>> {
    let mut e = NpzEntries::default();
    e.push_array("conv_in.weight", ramp(&[4, 3, 3, 3]));
    e.push_array("conv_in.bias", ramp(&[4]));
    e.push_file("config.json", b"{\"width\": 4, \"blocks\": 1}".to_vec());
    let mut one = NpzEntries::default();
    one.push_array("x", ramp(&[2, 3]));
    let numpy = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/hostile/numpy_savez.npz"))
        .unwrap();
    vec![npz_bytes(&e).unwrap(), npz_bytes(&one).unwrap(), numpy]
}

#[test]
fn fuzz_npy_reader() {
    fuzz("npy", &npy_seeds(), |b| match tensor_from_npy_bytes(b) {
        Ok(t) => {
            let _ = anisocb::io::npy::check_geometry_images(&t);
            true
        }
        Err(_) => false,
    });
}

#[test]
fn fuzz_npz_reader() {
    fuzz("npz", &npz_seeds(), |b| npz_from_bytes(b).is_ok());
}

fn weights_seeds() -> Vec<Vec<u8>> {
    use anisocb::nn::weights::push_trunk;
    use anisocb::nn::{NetConfig, NetKind, Trunk};
    let mut one = NpzEntries::default();
    push_trunk(
        &mut one,
        &Trunk::init(NetKind::Geometry, NetConfig { channels: 2, blocks: 1, ..NetConfig::tiny() }, 3),
        "",
    );
    let mut bundle = NpzEntries::default();
    for k in NetKind::ALL {
        let cfg = NetConfig { channels: 2, blocks: 1, ..NetConfig::tiny() };
        push_trunk(&mut bundle, &Trunk::init(k, cfg, 3), &format!("{}.", k.name()));
    }
    vec![npz_bytes(&one).unwrap(), npz_bytes(&bundle).unwrap()]
}

#[test]
fn fuzz_weights_loader() {
    use anisocb::nn::weights::{bundle_from_npz, trunk_from_npz};
    let p = std::path::Path::new("fuzz.npz");
    fuzz("weights", &weights_seeds(), |b| match npz_from_bytes(b) {
        Ok(e) if e.file("geometry.config.json").is_some() => bundle_from_npz(&e, p).is_ok(),
        Ok(e) => trunk_from_npz(&e, "", p, None).is_ok(),
        Err(_) => false,
    });
}

#[test]
fn fuzz_config_json() {
    use anisocb::nn::{NetConfig, NetKind};
    let seeds: Vec<Vec<u8>> = NetKind::ALL
        .iter()
        .map(|&k| NetConfig::small().to_json(k).into_bytes())
        .chain([b"{\"a\": \"x\\\"y\\u0041\", \"b\": -1.5e3, \"c\": true}".to_vec()])
        .collect();
    fuzz("config_json", &seeds, |b| {
        let text = String::from_utf8_lossy(b);
        let parsed = anisocb::io::json::Object::parse(&text).is_ok();
        NetConfig::from_json(&text).is_ok() || parsed
    });
}

#[test]
fn fuzz_obj_reader() {
    use anisocb::geom::obj::{obj_text, obj_text_from_bytes, obj_to_grid, parse_obj};
    use anisocb::geom::GridMesh;
    let mut m = GridMesh::flat(4, 3, 1.0, 0.5);
    m.pos[5][2] = 0.1;
    let quads = obj_text(&m, true);
    // Also as other exporters write it: a byte-order mark, CR LF, CR alone.
    let seeds = vec![
        quads.clone().into_bytes(),
        obj_text(&m, false).into_bytes(),
        [&b"\xEF\xBB\xBF"[..], quads.as_bytes()].concat(),
        quads.replace('\n', "\r\n").into_bytes(),
        quads.replace('\n', "\r").into_bytes(),
    ];
    let p = std::path::Path::new("fuzz.obj");
    fuzz("obj", &seeds, |b| {
        let strict =
            obj_text_from_bytes(b, p).and_then(|t| parse_obj(&t, p)).and_then(|o| obj_to_grid(&o, p));
        let text = String::from_utf8_lossy(b);
        parse_obj(&text, p).and_then(|o| obj_to_grid(&o, p)).is_ok() || strict.is_ok()
    });
}

/// Point caches written by the crate's writer: a few shapes, and for MDD also Blender's
/// exporter's layout with its one uncounted rest frame.
fn point_cache_seeds(format: anisocb::io::CacheFormat) -> Vec<Vec<u8>> {
    use anisocb::io::point_cache::{write_frame, write_header};
    use anisocb::io::CacheHeader;
    let mut seeds = Vec::new();
    for (points, frames) in [(1, 1), (3, 4), (17, 2)] {
        let h = CacheHeader {
            start_frame: 1.0,
            sample_rate: 0.5,
            ..CacheHeader::new(format, points, frames, 24.0)
        };
        let mut v = Vec::new();
        write_header(&mut v, &h).unwrap();
        for f in 0..frames {
            let pts: Vec<[f32; 3]> = (0..points).map(|i| [i as f32, f as f32 * 0.5, -0.25]).collect();
            write_frame(&mut v, format, &pts).unwrap();
        }
        if format == anisocb::io::CacheFormat::Mdd && points == 3 {
            let rest = v[v.len() - 36..].to_vec();
            seeds.push([&v[..], &rest[..]].concat());
        }
        seeds.push(v);
    }
    seeds
}

/// Open from bytes, read every frame, then a middle range again.
fn read_point_cache(bytes: &[u8], name: &str) -> bool {
    use anisocb::io::PointCacheReader;
    let r = PointCacheReader::from_reader(std::io::Cursor::new(bytes), std::path::Path::new(name));
    r.and_then(|mut r| {
        let n = r.header().frames;
        r.read_frames(0..n)?;
        r.read_frames(n / 2..n)
    })
    .is_ok()
}

#[test]
fn fuzz_pc2_reader() {
    let seeds = point_cache_seeds(anisocb::io::CacheFormat::Pc2);
    fuzz("pc2", &seeds, |b| read_point_cache(b, "fuzz.pc2"));
}

#[test]
fn fuzz_mdd_reader() {
    let seeds = point_cache_seeds(anisocb::io::CacheFormat::Mdd);
    fuzz("mdd", &seeds, |b| read_point_cache(b, "fuzz.mdd"));
}
