//! Any mesh through the C ABI (feature `capi`): `anisocb_set_mesh`, `anisocb_hr_faces`,
//! `anisocb_push_mesh` and `anisocb_flush` give, frame for frame and bit for bit, what
//! [`Upscaler::with_mesh`] gives the Rust API; bad meshes and misuse are error codes with a
//! message naming the face or the call, never a crash.
#![cfg(feature = "capi")]

use anisocb::capi::*;
use anisocb::pipeline::Upscaler;
use std::ffi::CStr;
use std::mem::MaybeUninit;

/// A sleeve-like open tube of quads (`around` × `along` vertices, no grid: it has no corners)
/// with a triangle fan capping nothing, plus a flap of two triangles: a mixed mesh.
fn tube(around: usize, along: usize) -> (Vec<[f32; 3]>, Vec<Vec<u32>>) {
    let mut pos = Vec::new();
    for j in 0..along {
        for i in 0..around {
            let a = i as f32 / around as f32 * std::f32::consts::TAU;
            pos.push([0.1 * a.cos(), 0.1 * a.sin(), 0.03 * j as f32]);
        }
    }
    let at = |i: usize, j: usize| (j * around + i % around) as u32;
    let mut faces = Vec::new();
    for j in 0..along - 1 {
        for i in 0..around {
            if i % 3 == 0 {
                faces.push(vec![at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
                faces.push(vec![at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
            } else {
                faces.push(vec![at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)]);
            }
        }
    }
    (pos, faces)
}

/// Frame `t` of the tube swaying and bulging.
fn frame(rest: &[[f32; 3]], t: usize) -> Vec<f32> {
    let s = t as f32 * 0.3;
    rest.iter().flat_map(|p| [p[0] * (1.0 + 0.05 * (p[2] * 40.0 + s).sin()) + 0.01 * s, p[1], p[2]]).collect()
}

unsafe fn new_upscaler() -> *mut anisocb::pipeline::Upscaler {
    let mut opts = MaybeUninit::<AnisocbOptions>::uninit();
    assert_eq!(anisocb_options_default(opts.as_mut_ptr()), ANISOCB_OK);
    let mut opts = opts.assume_init();
    opts.threads = 1;
    let mut up = std::ptr::null_mut();
    assert_eq!(anisocb_new(&opts, &mut up), ANISOCB_OK);
    up
}

/// `anisocb_set_mesh` of `rest` and faces given as their sizes and concatenated indices, no UVs.
unsafe fn set_mesh(up: *mut Upscaler, rest: &[[f32; 3]], sizes: &[u32], flat: &[u32]) -> std::ffi::c_int {
    let rest_flat = rest.concat();
    let (null_uv, null_idx) = (std::ptr::null(), std::ptr::null());
    anisocb_set_mesh(
        up,
        rest.len() as u32,
        rest_flat.as_ptr(),
        sizes.len() as u32,
        sizes.as_ptr(),
        flat.as_ptr(),
        0,
        null_uv,
        null_idx,
    )
}

unsafe fn last_error() -> String {
    CStr::from_ptr(anisocb_last_error()).to_string_lossy().into_owned()
}

#[test]
fn a_mesh_through_the_c_abi_is_the_rust_apis_bit_for_bit() {
    let (rest, faces) = tube(16, 6);
    let frames = 7;
    // The Rust API.
    let mut rust =
        Upscaler::embedded().unwrap().with_threads(1).unwrap().with_mesh(faces.clone(), &rest, None).unwrap();
    let mut want = Vec::new();
    for t in 0..frames {
        let lr: Vec<[f32; 3]> = frame(&rest, t).chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        want.extend(rust.push_mesh(&lr).unwrap());
    }
    want.extend(rust.flush_mesh().unwrap());
    assert_eq!(want.len(), frames);
    unsafe {
        let up = new_upscaler();
        let sizes: Vec<u32> = faces.iter().map(|f| f.len() as u32).collect();
        let flat: Vec<u32> = faces.concat();
        let st = set_mesh(up, &rest, &sizes, &flat);
        assert_eq!(st, ANISOCB_OK, "{}", last_error());
        let nh = anisocb_hr_vertex_count(up) as usize;
        assert_eq!(nh, want[0].len(), "HR vertex count");
        // The HR faces: 4 per LR face, each of its LR face's size, the Rust API's.
        let hr_faces = rust.hr_faces().unwrap();
        let total: usize = hr_faces.iter().map(Vec::len).sum();
        let (mut hs, mut hi) = (vec![0u32; hr_faces.len()], vec![0u32; total]);
        assert_eq!(anisocb_hr_faces(up, hs.as_mut_ptr(), hs.len(), hi.as_mut_ptr(), hi.len()), ANISOCB_OK);
        assert_eq!(hs.len(), 4 * faces.len());
        assert_eq!(hi, hr_faces.concat());
        assert!(hs.iter().zip(faces.iter().flat_map(|f| [f.len(); 4])).all(|(&a, b)| a as usize == b));
        // A buffer too small for the faces is refused.
        assert_eq!(
            anisocb_hr_faces(up, hs.as_mut_ptr(), hs.len() - 1, hi.as_mut_ptr(), hi.len()),
            ANISOCB_ERR_ARGUMENT
        );
        assert!(last_error().contains("faces"), "{}", last_error());

        let mut got = Vec::new();
        let mut hr = vec![0.0f32; 3 * nh];
        for t in 0..frames {
            let lr = frame(&rest, t);
            match anisocb_push_mesh(up, lr.as_ptr(), hr.as_mut_ptr(), hr.len()) {
                ANISOCB_OK => got.push(hr.clone()),
                ANISOCB_PENDING => {}
                s => panic!("anisocb_push_mesh: status {s}: {}", last_error()),
            }
            // The mesh cannot change in the middle of a shot.
            if t == 1 {
                let sizes: Vec<u32> = faces.iter().map(|f| f.len() as u32).collect();
                let st = set_mesh(up, &rest, &sizes, &flat);
                assert_eq!(st, ANISOCB_ERR_CONFIG);
                assert!(last_error().contains("between shots"), "{}", last_error());
            }
        }
        // An HR buffer too small is refused, and takes nothing from the shot.
        let lr = frame(&rest, frames);
        assert_eq!(anisocb_push_mesh(up, lr.as_ptr(), hr.as_mut_ptr(), hr.len() - 1), ANISOCB_ERR_ARGUMENT);
        loop {
            match anisocb_flush(up, hr.as_mut_ptr(), hr.len()) {
                ANISOCB_OK => got.push(hr.clone()),
                ANISOCB_DONE => break,
                s => panic!("anisocb_flush: status {s}: {}", last_error()),
            }
        }
        assert_eq!(got.len(), frames, "every frame out once");
        for (t, (g, w)) in got.iter().zip(&want).enumerate() {
            let w: Vec<f32> = w.concat();
            assert!(
                g.iter().zip(&w).all(|(a, b)| a.to_bits() == b.to_bits()),
                "frame {t} differs from the Rust API's"
            );
        }
        // After the flush, the next shot may set another mesh.
        let (rest2, faces2) = tube(12, 5);
        let sizes2: Vec<u32> = faces2.iter().map(|f| f.len() as u32).collect();
        let st = set_mesh(up, &rest2, &sizes2, &faces2.concat());
        assert_eq!(st, ANISOCB_OK, "{}", last_error());
        anisocb_free(up);
    }
}

#[test]
fn bad_meshes_and_misuse_through_the_c_abi_are_error_codes_with_messages() {
    let (rest, faces) = tube(8, 4);
    let rest_flat: Vec<f32> = rest.concat();
    unsafe {
        let up = new_upscaler();
        let mut hr = vec![0.0f32; 3 * 1000];
        // Frames before a mesh.
        assert_eq!(
            anisocb_push_mesh(up, rest_flat.as_ptr(), hr.as_mut_ptr(), hr.len()),
            ANISOCB_ERR_ARGUMENT
        );
        assert!(last_error().contains("anisocb_set_mesh"), "{}", last_error());
        assert_eq!(anisocb_hr_vertex_count(up), 0);
        // A pentagon.
        let (sizes, idx) = (vec![5u32], vec![0u32, 1, 2, 3, 4]);
        assert_eq!(set_mesh(up, &rest, &sizes, &idx), ANISOCB_ERR_ARGUMENT);
        assert!(last_error().contains("face 0 has 5 vertices"), "{}", last_error());
        // A vertex index past the mesh's vertices.
        let mut flat: Vec<u32> = faces.concat();
        flat[5] = rest.len() as u32 + 7;
        let sizes: Vec<u32> = faces.iter().map(|f| f.len() as u32).collect();
        let st = set_mesh(up, &rest, &sizes, &flat);
        assert!(st < 0, "an index out of range was accepted");
        let msg = last_error();
        assert!(msg.contains(&(rest.len() + 7).to_string()) || msg.contains("face"), "{msg}");
        // Null pointers and no vertices.
        assert_eq!(
            anisocb_set_mesh(
                up,
                0,
                rest_flat.as_ptr(),
                1,
                sizes.as_ptr(),
                flat.as_ptr(),
                0,
                std::ptr::null(),
                std::ptr::null()
            ),
            ANISOCB_ERR_ARGUMENT
        );
        assert_eq!(
            anisocb_set_mesh(
                up,
                rest.len() as u32,
                std::ptr::null(),
                1,
                sizes.as_ptr(),
                flat.as_ptr(),
                0,
                std::ptr::null(),
                std::ptr::null()
            ),
            ANISOCB_ERR_ARGUMENT
        );
        // Still no mesh after the failures; a good one is then taken.
        assert_eq!(anisocb_hr_vertex_count(up), 0);
        let flat: Vec<u32> = faces.concat();
        let st = set_mesh(up, &rest, &sizes, &flat);
        assert_eq!(st, ANISOCB_OK, "{}", last_error());
        assert!(anisocb_hr_vertex_count(up) as usize > rest.len());
        // A frame holding a NaN.
        let mut bad = rest_flat.clone();
        bad[4] = f32::NAN;
        let n = 3 * anisocb_hr_vertex_count(up) as usize;
        let mut hr = vec![0.0f32; n];
        let st = anisocb_push_mesh(up, bad.as_ptr(), hr.as_mut_ptr(), hr.len());
        assert!(st < 0, "a NaN frame was accepted");
        assert!(!last_error().is_empty());
        anisocb_free(up);
    }
}

/// The tube's UVs unrolled: column i of row j at (i / around, j / (along − 1)), a seam where the
/// last column meets the first (its own coordinates at u = 1); per face, its corners' indices.
fn tube_uvs(around: usize, along: usize, faces: &[Vec<u32>]) -> (Vec<[f32; 2]>, Vec<Vec<u32>>) {
    let uv: Vec<[f32; 2]> = (0..along)
        .flat_map(|j| (0..=around).map(move |i| [i as f32 / around as f32, j as f32 / (along - 1) as f32]))
        .collect();
    let uv_faces = faces
        .iter()
        .map(|f| {
            // A face's corners as (column, row); a corner on column 0 of a face that also has the
            // last column takes the seam's copy (column `around`).
            let cols: Vec<usize> = f.iter().map(|&v| v as usize % around).collect();
            let wraps = cols.contains(&(around - 1)) && cols.contains(&0);
            f.iter()
                .zip(&cols)
                .map(|(&v, &c)| {
                    let (c, j) = (if wraps && c == 0 { around } else { c }, v as usize / around);
                    (j * (around + 1) + c) as u32
                })
                .collect()
        })
        .collect();
    (uv, uv_faces)
}

#[test]
fn a_mesh_with_uvs_through_the_c_abi_is_the_rust_apis_bit_for_bit() {
    let (around, along) = (16, 6);
    let (rest, faces) = tube(around, along);
    let (uv, uv_faces) = tube_uvs(around, along, &faces);
    let frames = 5;
    let mut rust = Upscaler::embedded()
        .unwrap()
        .with_threads(1)
        .unwrap()
        .with_mesh(faces.clone(), &rest, Some((&uv, &uv_faces)))
        .unwrap();
    let mut want = Vec::new();
    for t in 0..frames {
        let lr: Vec<[f32; 3]> = frame(&rest, t).chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        want.extend(rust.push_mesh(&lr).unwrap());
    }
    want.extend(rust.flush_mesh().unwrap());
    // The UVs are used: an ARAP layout of the same tube gives other HR vertices.
    let mut arap =
        Upscaler::embedded().unwrap().with_threads(1).unwrap().with_mesh(faces.clone(), &rest, None).unwrap();
    let lr: Vec<[f32; 3]> = frame(&rest, 0).chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    let mut by_arap = arap.push_mesh(&lr).unwrap().into_iter().collect::<Vec<_>>();
    by_arap.extend(arap.flush_mesh().unwrap());
    assert_ne!(by_arap[0], want[0], "the UV layout gave the ARAP layout's vertices");
    unsafe {
        let up = new_upscaler();
        let sizes: Vec<u32> = faces.iter().map(|f| f.len() as u32).collect();
        let (flat, uv_flat, uv_idx) = (faces.concat(), uv.concat(), uv_faces.concat());
        let rest_flat: Vec<f32> = rest.concat();
        let set = |uv_idx: &[u32]| {
            anisocb_set_mesh(
                up,
                rest.len() as u32,
                rest_flat.as_ptr(),
                sizes.len() as u32,
                sizes.as_ptr(),
                flat.as_ptr(),
                uv.len() as u32,
                uv_flat.as_ptr(),
                uv_idx.as_ptr(),
            )
        };
        // A UV index past the coordinates is refused, with a message.
        let mut bad = uv_idx.clone();
        bad[3] = uv.len() as u32 + 2;
        assert_eq!(set(&bad), ANISOCB_ERR_ARGUMENT, "a UV index out of range was accepted");
        assert!(last_error().contains(&format!("UV index {}", uv.len() + 2)), "{}", last_error());
        assert_eq!(set(&uv_idx), ANISOCB_OK, "{}", last_error());
        let nh = anisocb_hr_vertex_count(up) as usize;
        let mut hr = vec![0.0f32; 3 * nh];
        let mut got = Vec::new();
        for t in 0..frames {
            let lr = frame(&rest, t);
            if anisocb_push_mesh(up, lr.as_ptr(), hr.as_mut_ptr(), hr.len()) == ANISOCB_OK {
                got.push(hr.clone());
            }
        }
        while anisocb_flush(up, hr.as_mut_ptr(), hr.len()) == ANISOCB_OK {
            got.push(hr.clone());
        }
        assert_eq!(got.len(), frames);
        for (t, (g, w)) in got.iter().zip(&want).enumerate() {
            let w: Vec<f32> = w.concat();
            assert!(g.iter().zip(&w).all(|(a, b)| a.to_bits() == b.to_bits()), "frame {t} differs");
        }
        anisocb_free(up);
    }
}
