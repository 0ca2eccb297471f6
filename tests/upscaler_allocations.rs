//! Heap allocations per frame of the [`Upscaler`] after warm-up, counted by the allocator in
//! tests/common/alloc.rs (every thread: the worker threads' allocations count too). One test
//! in its own binary, so the process-wide count is this test's alone.
//!
//! The target: after the first frames of a shot (the pools and the upscaler's buffers
//! warmed up), a frame through [`Upscaler::push_into`] — what the C ABI's `anisocb_push` runs —
//! allocates nothing, on one or two worker threads of its own (`with_threads`), with and
//! without temporal smoothing; [`Upscaler::push`] allocates exactly the mesh it returns. With
//! the `capi` feature (`make c-example` runs it) the same through `anisocb_push` itself, with
//! the default options (`threads = 0`: one thread per core, the upscaler's own).
//!
//! On rayon's global pool (a Rust [`Upscaler`] without `with_threads`) a frame hands its work
//! to the pool from outside, and crossbeam's injector then allocates a block every 63 such
//! jobs: about one allocation per 16 frames, which this test does not cover.

#[path = "common/alloc.rs"]
mod alloc;

use anisocb::geom::GridMesh;
use anisocb::nn::weights::embedded_model;
use anisocb::pipeline::Upscaler;
use anisocb::sr::params::UpscaleParams;

/// Frames of a shot after which nothing is allocated any more (measured: frames 0–3 allocate
/// with temporal 0, 0–5 with temporal 2, whose window of the nets' outputs grows to 2k + 1
/// frames first).
const WARM_UP: usize = 8;
const FRAMES: usize = 41;

/// Frame `t` of a 32 × 32 shot: a sheet with a travelling ripple.
fn frame(t: usize) -> GridMesh {
    let pos = (0..32 * 32)
        .map(|i| {
            let (x, y) = ((i % 32) as f32 * 0.03, (i / 32) as f32 * 0.03);
            [x, y, 0.02 * (x * 7.0 + t as f32 * 0.1).sin()]
        })
        .collect();
    GridMesh::new(32, 32, pos)
}

fn upscaler(temporal: usize, threads: usize) -> Upscaler {
    let params = UpscaleParams { temporal, ..UpscaleParams::default() };
    Upscaler::new(embedded_model().unwrap(), params).unwrap().with_threads(threads).unwrap()
}

/// Assert that no frame from [`WARM_UP`] on allocated; print the counts.
fn assert_none_after_warm_up(what: &str, counts: &[usize]) {
    println!("{what}: allocations per frame {counts:?}");
    assert!(
        counts[WARM_UP..].iter().all(|&n| n == 0),
        "{what}: frames {WARM_UP}.. allocate (32×32 → 64×64): {counts:?}"
    );
}

#[test]
fn upscaler_frames_allocate_nothing_after_warm_up() {
    let frames: Vec<GridMesh> = (0..FRAMES).map(frame).collect();
    // Two threads: which thread takes which part of a frame varies, so each thread's pools
    // may meet their largest request late (measured: nothing after frame 4 in 3 × 300 frames).
    for (temporal, threads) in [(0, 1), (2, 1), (2, 2)] {
        let mut up = upscaler(temporal, threads);
        let mut hr = vec![[0.0f32; 3]; 4 * 32 * 32];
        let counts: Vec<usize> = frames
            .iter()
            .enumerate()
            .map(|(t, f)| {
                let (out, n) = alloc::allocations(|| up.push_into(32, 32, &f.pos, &mut hr).unwrap());
                assert_eq!(out, t >= temporal);
                n
            })
            .collect();
        assert_none_after_warm_up(&format!("push_into, temporal {temporal}, {threads} thread(s)"), &counts);
    }

    // push: the returned mesh's positions, nothing else.
    let mut up = upscaler(2, 1);
    let counts: Vec<usize> = frames
        .iter()
        .map(|f| {
            let (out, n) = alloc::allocations(|| up.push(f).unwrap());
            drop(out);
            n
        })
        .collect();
    println!("push, temporal 2: allocations per frame {counts:?}");
    assert!(counts[WARM_UP..].iter().all(|&n| n == 1), "push allocates more than its mesh: {counts:?}");

    #[cfg(feature = "capi")]
    c_abi(&frames);
}

/// The same through the C ABI: `anisocb_new` with the default options (threads 0: one per
/// core) and temporal 2, `anisocb_push` frame by frame into one caller buffer.
#[cfg(feature = "capi")]
fn c_abi(frames: &[GridMesh]) {
    use anisocb::capi::*;
    let mut opts = std::mem::MaybeUninit::<AnisocbOptions>::uninit();
    let mut up = std::ptr::null_mut();
    let mut hr = vec![0.0f32; 3 * 4 * 32 * 32];
    // SAFETY: valid pointers and sizes throughout; the handle is freed at the end.
    unsafe {
        assert_eq!(anisocb_options_default(opts.as_mut_ptr()), ANISOCB_OK);
        let mut opts = opts.assume_init();
        opts.temporal = 2;
        assert_eq!(anisocb_new(&opts, &mut up), ANISOCB_OK);
        let counts: Vec<usize> = frames
            .iter()
            .enumerate()
            .map(|(t, f)| {
                let lr: &[f32] = bytemuck::cast_slice(&f.pos);
                let (status, n) =
                    alloc::allocations(|| anisocb_push(up, 32, 32, lr.as_ptr(), hr.as_mut_ptr(), hr.len()));
                assert_eq!(status, if t >= 2 { ANISOCB_OK } else { ANISOCB_PENDING });
                n
            })
            .collect();
        while anisocb_flush(up, hr.as_mut_ptr(), hr.len()) == ANISOCB_OK {}
        anisocb_free(up);
        assert_none_after_warm_up("anisocb_push, default threads, temporal 2", &counts);
    }
}
