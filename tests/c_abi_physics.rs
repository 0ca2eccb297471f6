//! The C ABI's physics options (`anisocb_options.physics` …, include/anisocb.h): a bad
//! material or held-edge list is refused at `anisocb_new` with `ANISOCB_ERR_CONFIG` and a
//! message naming the option; a good one runs the pass (frames differ from the plain
//! upscaler's after the first). Bit-equality with `upscale --physics` is `make c-example`'s.
#![cfg(feature = "capi")]

use anisocb::capi::*;
use std::ffi::{CStr, CString};

/// `anisocb_new` with the default options changed by `edit`: its status and the last error.
fn new_with(edit: impl FnOnce(&mut AnisocbOptions)) -> (i32, String, *mut anisocb::pipeline::Upscaler) {
    let mut opts = std::mem::MaybeUninit::<AnisocbOptions>::uninit();
    let mut up = std::ptr::null_mut();
    // SAFETY: valid pointers; the options' strings outlive the call.
    unsafe {
        assert_eq!(anisocb_options_default(opts.as_mut_ptr()), ANISOCB_OK);
        let mut opts = opts.assume_init();
        edit(&mut opts);
        let status = anisocb_new(&opts, &mut up);
        (status, CStr::from_ptr(anisocb_last_error()).to_string_lossy().into_owned(), up)
    }
}

/// Frame `t` of a 16 × 16 sheet being pushed together along x (a fold the LR grid cannot hold).
fn frame(t: usize) -> Vec<f32> {
    (0..16 * 16)
        .flat_map(|v| {
            let squeeze = 1.0 - 0.01 * t as f32;
            [(v % 16) as f32 * 0.08 * squeeze, 1.0, (v / 16) as f32 * 0.08]
        })
        .collect()
}

/// Push `n` frames, returning the HR frames handed out.
fn run(up: *mut anisocb::pipeline::Upscaler, n: usize) -> Vec<Vec<f32>> {
    let mut out = Vec::new();
    for t in 0..n {
        let mut hr = vec![0.0f32; 3 * 32 * 32];
        // SAFETY: `up` is a live handle; the buffers have the sizes given.
        let s = unsafe { anisocb_push(up, 16, 16, frame(t).as_ptr(), hr.as_mut_ptr(), hr.len()) };
        assert_eq!(s, ANISOCB_OK, "frame {t}");
        out.push(hr);
    }
    out
}

#[test]
fn c_abi_physics_options_are_checked_and_run_the_pass() {
    let bad = CString::new("velvet").unwrap();
    let (s, msg, up) = new_with(|o| (o.physics, o.material) = (1, bad.as_ptr()));
    assert!(s == ANISOCB_ERR_CONFIG && up.is_null() && msg.contains("velvet"), "{s}: {msg}");
    let bad = CString::new("top,middle").unwrap();
    let (s, msg, _) = new_with(|o| (o.physics, o.physics_pin) = (1, bad.as_ptr()));
    assert!(s == ANISOCB_ERR_CONFIG && msg.contains("middle"), "{s}: {msg}");
    let (s, msg, _) = new_with(|o| (o.physics, o.fps) = (1, 0.0));
    assert!(s == ANISOCB_ERR_CONFIG && msg.contains("option fps:"), "{s}: {msg}");
    let (s, msg, _) = new_with(|o| (o.physics, o.physics_drift) = (1, -1.0));
    assert!(s == ANISOCB_ERR_CONFIG && msg.contains("physics_drift"), "{s}: {msg}");
    let (s, msg, _) = new_with(|o| (o.physics, o.gravity, o.physics_ground) = (1, [0.0; 3], 0.0));
    assert!(s == ANISOCB_ERR_CONFIG && msg.contains("physics_ground"), "{s}: {msg}");
    let (s, msg, _) = new_with(|o| (o.physics, o.physics_sphere) = (1, [0.0, 0.0, 0.0, -1.0]));
    assert!(s == ANISOCB_ERR_CONFIG && msg.contains("physics_sphere"), "{s}: {msg}");
    let (s, msg, _) = new_with(|o| (o.physics, o.physics_box) = (1, [0.0, 0.0, 0.0, 1.0, f32::NAN, 1.0]));
    assert!(s == ANISOCB_ERR_CONFIG && msg.contains("physics_box"), "{s}: {msg}");

    let silk = CString::new("silk").unwrap();
    let (s, msg, phys) = new_with(|o| (o.physics, o.material, o.threads) = (1, silk.as_ptr(), 1));
    assert_eq!(s, ANISOCB_OK, "{msg}");
    let (_, _, plain) = new_with(|o| o.threads = 1);
    let (a, b) = (run(phys, 12), run(plain, 12));
    assert_eq!(a[0], b[0], "the first frame is the nets' with or without the pass");
    assert_ne!(a[11], b[11], "the physics pass changed nothing");
    assert!(a.iter().flatten().all(|x| x.is_finite()));
    // A floor just under the sheet (y = 1 m): no output vertex below it after the first frame.
    let (s, msg, floor) = new_with(|o| (o.physics, o.threads, o.physics_ground) = (1, 1, 0.9995));
    assert_eq!(s, ANISOCB_OK, "{msg}");
    let below = |frames: &[Vec<f32>]| frames[1..].iter().flat_map(|hr| hr.chunks(3)).any(|p| p[1] < 0.9995);
    assert!(below(&a), "without a floor the folds should dip below y = 0.9995 m");
    let f = run(floor, 12);
    assert!(!below(&f), "a vertex went below the floor");
    // SAFETY: the handle came from anisocb_new and is not used afterwards.
    unsafe { anisocb_free(floor) };
    // SAFETY: both handles came from anisocb_new and are not used afterwards.
    unsafe {
        anisocb_free(phys);
        anisocb_free(plain);
    }
}

#[test]
fn c_abi_push_refuses_frame_sizes_no_buffer_can_hold_before_touching_the_pointers() {
    let (s, msg, up) = new_with(|o| o.threads = 1);
    assert_eq!(s, ANISOCB_OK, "{msg}");
    let lr = [0.0f32; 12];
    let mut hr = [0.0f32; 48];
    // u32::MAX² · 12 floats overflows a 64-bit size; 4097 × 4097 is past the LR limit. Both
    // are refused from the sizes alone (the 12-float buffers would otherwise be overrun).
    for (w, h) in [(u32::MAX, u32::MAX), (4097, 4097)] {
        // SAFETY: a live handle; the call must not read or write past the buffers' 12 / 48 floats.
        let s = unsafe { anisocb_push(up, w, h, lr.as_ptr(), hr.as_mut_ptr(), usize::MAX) };
        let msg = unsafe { CStr::from_ptr(anisocb_last_error()) }.to_string_lossy().into_owned();
        assert!(s == ANISOCB_ERR_ARGUMENT && msg.contains("larger than"), "{w}×{h}: {s}: {msg}");
    }
    unsafe { anisocb_free(up) };
}
