//! A small process-wide pool of f32 buffers for [`crate::Tensor`] (the conv kernels keep their
//! scratch space in a per-thread pool of their own, `ops::conv2d::Scratch`). Freeing a large
//! buffer lets glibc hand its pages back to the kernel (munmap above its mmap threshold, madvise
//! when it trims a heap), and the next buffer of that size then pays a page fault per 4 KiB page
//! before the arithmetic starts: on one 32×32 frame through the three small nets that was about
//! a third of the time (benches/peers.rs `nets`: 6.5 → 4.4 ms with the pool, 2-core machine).
//! One pool for every thread: activations are made on rayon's workers and often dropped on the
//! caller's thread.
//!
//! Buffers under [`MIN_LEN`] floats (LR-sized images, padded biases, small grids' activations)
//! are kept too, on a list of their own that never pushes a large buffer out: with them a
//! frame of [`crate::pipeline::Upscaler`] allocates nothing once the pools hold its working set.

use std::sync::{Mutex, MutexGuard};

static POOL: Mutex<Vec<Vec<f32>>> = Mutex::new(Vec::new());
static SMALL: Mutex<Vec<Vec<f32>>> = Mutex::new(Vec::new());

/// Buffers kept: a training step's tape (a few dozen activations) fits.
const KEEP: usize = 64;
/// Small buffers kept (under [`MIN_LEN`] floats each: at most 1 MiB in all).
const KEEP_SMALL: usize = 64;
/// Smallest buffer kept on the main list (floats); smaller ones go on the small list.
const MIN_LEN: usize = 4096;
/// Largest buffer kept (floats, 64 MiB) and most floats kept in all (512 MiB; [`release`]
/// hands them back).
const MAX_LEN: usize = 1 << 24;
const MAX_TOTAL: usize = 1 << 27;

/// The list for buffers of `len` floats.
fn pool(len: usize) -> MutexGuard<'static, Vec<Vec<f32>>> {
    let list = if len < MIN_LEN { &SMALL } else { &POOL };
    // A panic while holding the lock leaves a valid list of buffers: keep using it.
    list.lock().unwrap_or_else(|e| e.into_inner())
}

/// A buffer with room for `len` floats, as it was left (its length and values are stale): the
/// smallest pooled one with room for `len` and at most twice that, else a new one. (Growing a
/// pooled buffer would copy its stale contents; handing a small request a large buffer would
/// leave the next large request without one.)
pub fn take(len: usize) -> Vec<f32> {
    if len == 0 {
        return Vec::new();
    }
    let mut p = pool(len);
    let fits = |v: &Vec<f32>| (len..=2 * len).contains(&v.capacity());
    let best = (0..p.len()).filter(|&i| fits(&p[i])).min_by_key(|&i| p[i].capacity());
    best.map(|i| p.swap_remove(i)).unwrap_or_else(|| Vec::with_capacity(len))
}

/// `len` zeros.
pub fn zeroed(len: usize) -> Vec<f32> {
    filled(len, 0.0)
}

/// `len` copies of `v`.
pub fn filled(len: usize, v: f32) -> Vec<f32> {
    let mut b = take(len);
    b.clear();
    b.resize(len, v);
    b
}

/// `len` floats with unspecified values (stale ones from the pool, zeros where it grew): for
/// callers that write every element before reading it.
pub fn overwritten(len: usize) -> Vec<f32> {
    let mut b = take(len);
    b.resize(len, 0.0);
    b
}

/// Return a buffer to the pool (the oldest buffers leave first when it is full).
pub fn give(v: Vec<f32>) {
    if !(1..=MAX_LEN).contains(&v.capacity()) {
        return;
    }
    let keep = if v.capacity() < MIN_LEN { KEEP_SMALL } else { KEEP };
    let evicted: Vec<Vec<f32>> = {
        let mut p = pool(v.capacity());
        p.push(v);
        let mut total: usize = p.iter().map(Vec::capacity).sum();
        let mut cut = 0;
        while p.len() - cut > keep || total > MAX_TOTAL {
            total -= p[cut].capacity();
            cut += 1;
        }
        p.drain(..cut).collect()
    };
    drop(evicted); // freed outside the lock
}

/// Free every pooled buffer (for a caller that is done computing and wants its memory back).
pub fn release() {
    let all = [std::mem::take(&mut *pool(0)), std::mem::take(&mut *pool(MIN_LEN))];
    drop(all);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pooled_buffers_come_back_zeroed_or_filled() {
        let mut a = zeroed(5000);
        a.iter_mut().for_each(|v| *v = 7.0);
        give(a);
        let b = zeroed(4500);
        assert_eq!((b.len(), b.iter().all(|&v| v == 0.0)), (4500, true));
        give(b);
        let c = filled(6000, 2.5);
        assert_eq!((c.len(), c.iter().all(|&v| v == 2.5)), (6000, true));
        // Small buffers come back from their own list, zeroed all the same.
        let mut d = zeroed(300);
        d.iter_mut().for_each(|v| *v = 7.0);
        give(d);
        let e = zeroed(250);
        assert_eq!((e.len(), e.iter().all(|&v| v == 0.0)), (250, true));
    }
}
