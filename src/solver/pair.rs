//! Two halves of a memory-bound pass, on two threads when that pays.
//!
//! One core does not saturate the memory bus: a pass over a matrix that does not fit in the
//! cache (a big factor's solve, the dense Delassus operator of a 3D contact surface) runs
//! 1.5–1.8× faster split in two halves on two threads. A second thread pays only when a
//! core is free for it: on a machine loaded to 3.5–4 with two cores the threaded solves ran
//! 0.78× as fast as on one thread. So `Pair` times both ways and takes the faster, and every
//! `PROBE`th call the other one, to follow the load. Callers split their work so that the
//! arithmetic does not depend on the way.

use std::sync::{Mutex, OnceLock};
use std::time::Instant;

/// Every PROBE-th call takes the way that was slower lately.
const PROBE: usize = 16;

/// The thread that takes the second halves of every `Pair`: one rayon worker, started by the
/// first pass on two threads and kept. A thread started per pass (`std::thread::scope`) cost
/// 55–72 µs here, two per time step; waking the worker costs a fraction of that. None if
/// the thread cannot be started: then the passes run on one thread.
fn worker() -> Option<&'static rayon::ThreadPool> {
    static WORKER: OnceLock<Option<rayon::ThreadPool>> = OnceLock::new();
    WORKER
        .get_or_init(|| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .thread_name(|_| "viscontact-pair".to_string())
                .build()
                .ok()
        })
        .as_ref()
}

/// Runs pairs of closures of one kind of pass, on two threads or one after the other.
pub struct Pair {
    /// Whether a second thread may take the second half (the process has two threads or
    /// more, `threads::count`).
    threads: bool,
    ways: Mutex<Ways>,
}

/// The smoothed times (seconds) of the pass on two threads and on one, and its calls so far.
#[derive(Default)]
struct Ways {
    two: f64,
    one: f64,
    calls: usize,
}

impl Default for Pair {
    fn default() -> Self {
        Pair {
            threads: crate::threads::count() >= 2,
            ways: Mutex::default(),
        }
    }
}

impl Pair {
    /// A pair that never uses the worker thread.
    #[cfg(test)]
    pub fn one_thread() -> Self {
        Pair {
            threads: false,
            ways: Mutex::default(),
        }
    }

    /// As [`Pair::both`] for a pass that is `large`, else `a` then `b` on this thread (a small
    /// pass takes less time than handing half of it to the worker).
    pub fn both_if(&self, large: bool, a: impl FnOnce() + Send, b: impl FnOnce() + Send) {
        if large {
            self.both(a, b);
        } else {
            a();
            b();
        }
    }

    /// Runs `a` and `b`: on two threads when the process has two and that was the faster
    /// way lately, else one after the other.
    pub fn both(&self, a: impl FnOnce() + Send, b: impl FnOnce() + Send) {
        let Some(worker) = self.threads.then(worker).flatten() else {
            a();
            b();
            return;
        };
        let ways = || self.ways.lock().unwrap_or_else(|e| e.into_inner());
        let two = {
            let mut w = ways();
            w.calls += 1;
            (w.two <= w.one) != w.calls.is_multiple_of(PROBE)
        };
        let start = Instant::now();
        if two {
            // b on the worker, a here; the scope waits for b (and passes on a panic).
            worker.in_place_scope(|scope| {
                scope.spawn(|_| b());
                a();
            });
        } else {
            a();
            b();
        }
        let took = start.elapsed().as_secs_f64();
        let mut w = ways();
        let slot = if two { &mut w.two } else { &mut w.one };
        *slot = if *slot == 0.0 {
            took
        } else {
            0.75 * *slot + 0.25 * took
        };
    }
}
