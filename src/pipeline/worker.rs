//! [`Worker`]: a rayon pool of its own with one job resident on it that runs its owner's
//! closures. `ThreadPool::install` from a thread outside the pool queues each closure on
//! rayon's injector (crossbeam-deque's `Injector`), which allocates a block every 63 jobs: with
//! two closures per frame that was the last heap allocation of an [`super::Upscaler`] frame
//! (tests/upscaler_allocations.rs). The resident job takes closures through a mutex-guarded
//! slot and a condition variable, which never allocate (`std::sync::mpsc` channels did, the
//! first time a thread blocked on one: at a frame that depended on timing).

use std::any::Any;
use std::panic::{catch_unwind, resume_unwind, AssertUnwindSafe};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};

/// A thread pool whose resident job runs [`Worker::run`]'s closures (see the module docs).
pub(crate) struct Worker {
    /// The threads (only the resident job queues work on them). Dropped after `Drop::drop`
    /// has closed the slot: rayon then ends each thread once the resident job has returned.
    _pool: rayon::ThreadPool,
    /// The slot the resident job waits on.
    shared: Arc<Shared>,
    /// Held for a whole [`Worker::run`]: one closure in the slot at a time.
    calls: Mutex<()>,
}

/// A closure on the stack of a thread blocked in [`Worker::run`] until it has run.
struct Job(*mut (dyn FnMut() + Send + 'static));

// SAFETY: the closure is `Send`; `run` keeps it alive and unused until the job reports back.
unsafe impl Send for Job {}

/// `None`: the closure returned; `Some`: it panicked with this payload.
type Outcome = Option<Box<dyn Any + Send>>;

#[derive(Default)]
struct Slot {
    job: Option<Job>,
    outcome: Option<Outcome>,
    /// The Worker is gone: the resident job returns.
    closed: bool,
}

#[derive(Default)]
struct Shared {
    slot: Mutex<Slot>,
    changed: Condvar,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Slot> {
        // Nothing panics while holding it (closures run unlocked): a poisoned lock is still valid.
        self.slot.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Wait until `ready(slot)`.
    fn wait_for<'a>(
        &self,
        mut s: MutexGuard<'a, Slot>,
        ready: impl Fn(&Slot) -> bool,
    ) -> MutexGuard<'a, Slot> {
        while !ready(&s) {
            s = self.changed.wait(s).unwrap_or_else(|e| e.into_inner());
        }
        s
    }
}

impl Worker {
    /// A pool of `threads` threads (≥ 1) with the resident job started on it.
    pub(crate) fn new(threads: usize) -> Result<Worker, rayon::ThreadPoolBuildError> {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
        let shared = Arc::new(Shared::default());
        let sh = Arc::clone(&shared);
        pool.spawn(move || loop {
            let mut s = sh.wait_for(sh.lock(), |s| s.job.is_some() || s.closed);
            let Some(Job(f)) = s.job.take() else { return };
            drop(s);
            // SAFETY: `run` holds the closure alive, borrowed by nothing else, until it has
            // the outcome set below.
            let outcome = catch_unwind(AssertUnwindSafe(|| unsafe { (*f)() }));
            sh.lock().outcome = Some(outcome.err());
            sh.changed.notify_all();
        });
        Ok(Worker { _pool: pool, shared, calls: Mutex::new(()) })
    }

    /// `f()` on the pool, as `ThreadPool::install` runs it (a panic in it is raised again
    /// here). Not to be called from inside another `run`'s closure on the same Worker (it would
    /// wait for itself).
    pub(crate) fn run<T: Send>(&self, f: impl FnOnce() -> T + Send) -> T {
        let (mut f, mut out) = (Some(f), None);
        let mut call = || out = f.take().map(|f| f());
        let call: *mut (dyn FnMut() + Send + '_) = &mut call;
        // SAFETY: only the lifetime is erased; the resident job calls the closure before it
        // sets the outcome, and this frame does not return (nor touch `out`) before that.
        let job = Job(unsafe {
            std::mem::transmute::<*mut (dyn FnMut() + Send + '_), *mut (dyn FnMut() + Send + 'static)>(call)
        });
        let outcome = {
            let _one = self.calls.lock().unwrap_or_else(|e| e.into_inner());
            let mut s = self.shared.lock();
            s.job = Some(job);
            self.shared.changed.notify_all();
            let mut s = self.shared.wait_for(s, |s| s.outcome.is_some());
            s.outcome.take().expect("waited for it")
        };
        if let Some(payload) = outcome {
            resume_unwind(payload);
        }
        out.expect("the resident job ran the closure")
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.shared.lock().closed = true;
        self.shared.changed.notify_all();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_closures_on_its_own_threads_and_raises_their_panics_here() {
        let w = Worker::new(2).unwrap();
        let v = [1, 2, 3];
        assert_eq!(w.run(|| (rayon::current_num_threads(), v.iter().sum::<i32>())), (2, 6));
        let p = catch_unwind(AssertUnwindSafe(|| w.run(|| panic!("boom"))));
        assert_eq!(p.unwrap_err().downcast_ref::<&str>(), Some(&"boom"));
        // Still serving after a panic.
        assert!(w.run(|| rayon::current_thread_index().is_some()));
    }
}
