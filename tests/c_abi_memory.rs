//! A frame that needs more memory than can be had is an error, not an abort of the process
//! (which, through the C ABI, would be the host application's): [`Upscaler`] asks for a shot's
//! memory fallibly before its first frame, and holds to a caller's limit.

use anisocb::error::Error;
use anisocb::nn::weights::embedded_model;
use anisocb::pipeline::Upscaler;
use anisocb::sr::params::UpscaleParams;

/// A flat `w` × `h` sheet, 1 cm between vertices.
fn sheet(w: usize, h: usize) -> Vec<[f32; 3]> {
    (0..w * h).map(|i| [(i % w) as f32 * 0.01, (i / w) as f32 * 0.01, 0.0]).collect()
}

#[test]
fn a_first_frame_over_the_memory_limit_is_an_out_of_memory_error_and_the_next_shot_runs() {
    let model = embedded_model().unwrap();
    let up = Upscaler::new(model, UpscaleParams::default()).unwrap();
    let need = up.frame_bytes(64, 64);
    // Measured: a 256 × 256 shot through `anisocb upscale` peaks at 7.2 KB per LR vertex; the
    // estimate must not be below what a frame really takes by much, nor absurdly above it.
    let per_vertex = up.frame_bytes(256, 256) / (256 * 256);
    assert!((6_000..=20_000).contains(&per_vertex), "{per_vertex} bytes per LR vertex");
    let mut up = up.with_memory_limit(need - 1);
    let mut hr = vec![[0.0f32; 3]; 4 * 64 * 64];
    match up.push_into(64, 64, &sheet(64, 64), &mut hr) {
        Err(Error::OutOfMemory(m)) => {
            assert!(m.contains("64×64") && m.contains("MiB") && m.contains("limit"), "{m}")
        }
        other => panic!("a frame over the limit was not refused as out of memory: {other:?}"),
    }
    // A smaller grid fits, and starts the shot (the refused frame left nothing behind).
    let mut hr = vec![[0.0f32; 3]; 4 * 32 * 32];
    assert!(up.push_into(32, 32, &sheet(32, 32), &mut hr).unwrap());
    assert!(hr.iter().all(|p| p.iter().all(|c| c.is_finite())));
}

#[cfg(feature = "capi")]
#[test]
fn anisocb_push_returns_an_error_code_when_a_frame_needs_more_memory_than_it_may_take() {
    use anisocb::capi::*;
    use std::ffi::CStr;
    use std::mem::MaybeUninit;
    unsafe {
        let mut opts = MaybeUninit::<AnisocbOptions>::uninit();
        assert_eq!(anisocb_options_default(opts.as_mut_ptr()), ANISOCB_OK);
        let mut opts = opts.assume_init();
        opts.threads = 1;
        // 1 MiB: a 64 × 64 frame needs about 34 MiB.
        opts.memory_limit_mib = 1;
        let mut up = std::ptr::null_mut();
        assert_eq!(anisocb_new(&opts, &mut up), ANISOCB_OK);
        let lr: Vec<f32> = sheet(64, 64).concat();
        let mut hr = vec![0.0f32; 3 * 4 * 64 * 64];
        let status = anisocb_push(up, 64, 64, lr.as_ptr(), hr.as_mut_ptr(), hr.len());
        let msg = CStr::from_ptr(anisocb_last_error()).to_string_lossy().into_owned();
        assert_eq!(status, ANISOCB_ERR_MEMORY, "{msg}");
        assert!(msg.contains("out of memory") && msg.contains("64×64"), "{msg}");
        anisocb_free(up);
    }
}
