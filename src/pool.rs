//! A small per-thread pool of f32 buffers, shared by [`crate::Tensor`] and the conv kernels'
//! scratch space. Freeing a large buffer lets the allocator hand its pages back to the kernel
//! (glibc trims a thread's heap with `madvise`), and the next buffer of that size then pays a
//! page fault per 4 KiB page before the arithmetic starts: on one 32×32 frame through the three
//! small nets that cost about a third of the time (benches/peers.rs `nets`, 2-core machine).
//! Buffers dropped on a thread are kept there for the next allocation of a similar size.

use std::cell::RefCell;

thread_local! {
    static POOL: RefCell<Vec<Vec<f32>>> = const { RefCell::new(Vec::new()) };
}

/// Buffers kept per thread.
const KEEP: usize = 8;
/// Smallest buffer worth keeping (floats): the allocator serves small ones from its own lists.
const MIN_LEN: usize = 4096;
/// Largest buffer kept (floats, 64 MiB) and most floats kept per thread (256 MiB).
const MAX_LEN: usize = 1 << 24;
const MAX_TOTAL: usize = 1 << 26;

/// A buffer with room for `len` floats, as it was left (its length and values are stale): the
/// smallest pooled one that fits, else the largest one (to be grown), else a new one.
pub fn take(len: usize) -> Vec<f32> {
    if len < MIN_LEN {
        return Vec::new();
    }
    let v = POOL.with(|p| {
        let mut p = p.borrow_mut();
        let best = (0..p.len()).filter(|&i| p[i].capacity() >= len).min_by_key(|&i| p[i].capacity());
        let pick = best.or_else(|| (0..p.len()).max_by_key(|&i| p[i].capacity()));
        pick.map(|i| p.swap_remove(i))
    });
    v.unwrap_or_default()
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

/// Return a buffer to this thread's pool (oldest buffers leave first when it is full).
pub fn give(v: Vec<f32>) {
    let cap = v.capacity();
    if !(MIN_LEN..=MAX_LEN).contains(&cap) {
        return;
    }
    // try_with: a tensor dropped while the thread's locals are torn down is simply freed.
    let _ = POOL.try_with(|p| {
        let mut p = p.borrow_mut();
        p.push(v);
        while p.len() > KEEP || p.iter().map(Vec::capacity).sum::<usize>() > MAX_TOTAL {
            p.remove(0);
        }
    });
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
    }
}
