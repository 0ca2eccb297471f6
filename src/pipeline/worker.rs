//! [`Worker`]: a rayon pool of its own with one job resident on it that runs its owner's
//! closures. `ThreadPool::install` from a thread outside the pool queues each closure on
//! rayon's injector (crossbeam-deque's `Injector`), which allocates a block every 63 jobs: with
//! two closures per frame that was the last heap allocation of an [`super::Upscaler`] frame
//! (tests/upscaler_allocations.rs). Handing a closure to the resident job over a bounded
//! channel allocates nothing once the channels have been used.

use std::any::Any;
use std::panic::{catch_unwind, resume_unwind, AssertUnwindSafe};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender};
use std::sync::Mutex;

/// A thread pool whose resident job runs [`Worker::run`]'s closures (see the module docs).
pub(crate) struct Worker {
    /// The threads (only the resident job queues work on them). Dropped first: rayon then
    /// ends each thread once the resident job has returned.
    _pool: rayon::ThreadPool,
    /// Closures to the resident job, and what became of each (a panic's payload) back. Behind
    /// a lock so that `run` takes `&self` and the owner stays `Sync`.
    jobs: Mutex<(SyncSender<Job>, Receiver<Outcome>)>,
}

/// A closure on the stack of a thread blocked in [`Worker::run`] until it has run.
struct Job(*mut (dyn FnMut() + Send + 'static));

// SAFETY: the closure is `Send`; `run` keeps it alive and unused until the job reports back.
unsafe impl Send for Job {}

/// `None`: the closure returned; `Some`: it panicked with this payload.
type Outcome = Option<Box<dyn Any + Send>>;

impl Worker {
    /// A pool of `threads` threads (≥ 1) with the resident job started on it.
    pub(crate) fn new(threads: usize) -> Result<Worker, rayon::ThreadPoolBuildError> {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
        let (job_tx, job_rx) = sync_channel::<Job>(1);
        let (done_tx, done_rx) = sync_channel::<Outcome>(1);
        // Ends when the Worker, and with it the job sender, is dropped.
        pool.spawn(move || {
            while let Ok(Job(f)) = job_rx.recv() {
                // SAFETY: `run` holds the closure alive, borrowed by nothing else, until it has
                // the outcome sent below.
                let outcome = catch_unwind(AssertUnwindSafe(|| unsafe { (*f)() }));
                if done_tx.send(outcome.err()).is_err() {
                    break;
                }
            }
        });
        Ok(Worker { _pool: pool, jobs: Mutex::new((job_tx, done_rx)) })
    }

    /// `f()` on the pool, as `ThreadPool::install` runs it (a panic in it is raised again
    /// here). Not to be called from inside another `run`'s closure on the same Worker (it would
    /// wait for itself).
    pub(crate) fn run<T: Send>(&self, f: impl FnOnce() -> T + Send) -> T {
        let (mut f, mut out) = (Some(f), None);
        let mut call = || out = f.take().map(|f| f());
        let call: *mut (dyn FnMut() + Send + '_) = &mut call;
        // SAFETY: only the lifetime is erased; the resident job calls the closure before it
        // sends the outcome, and this frame does not return (nor touch `out`) before that.
        let job = Job(unsafe {
            std::mem::transmute::<*mut (dyn FnMut() + Send + '_), *mut (dyn FnMut() + Send + 'static)>(call)
        });
        let outcome = {
            let jobs = self.jobs.lock().unwrap_or_else(|e| e.into_inner());
            jobs.0.send(job).expect("the resident job runs as long as its Worker");
            jobs.1.recv().expect("the resident job answers every closure")
        };
        if let Some(payload) = outcome {
            resume_unwind(payload);
        }
        out.expect("the resident job ran the closure")
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
