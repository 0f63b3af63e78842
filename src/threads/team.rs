//! The pieces of a memory-bound pass, on all the process's threads when that pays.
//!
//! One core does not saturate the memory bus: a pass over a matrix that does not fit in the
//! cache (a big factor's solve, the dense Delassus operator or G of a 3D contact surface)
//! runs faster cut in pieces on several threads, up to the bandwidth of the socket. More
//! threads pay only when cores are free for them: on a machine loaded to 3.5–4 with two
//! cores the threaded solves ran 0.78× as fast as on one thread. So a `Team` times both
//! ways, all its threads and one, takes the faster, and every `PROBE`th call the other one,
//! to follow the load. Callers cut their work so that the arithmetic does not depend on the
//! pieces' threads (nor, where they say so, on how many pieces there are).

use std::sync::{Mutex, OnceLock};
use std::time::Instant;

/// Every PROBE-th call takes the way that was slower lately.
const PROBE: usize = 16;

/// The threads that take all pieces but the first of every `Team`'s passes: one rayon pool
/// of `threads::count() − 1` workers, started by the first pass on several threads and
/// kept (the caller takes the first piece). A thread started per pass
/// (`std::thread::scope`) cost 55–72 µs here, two per time step; waking a worker costs a
/// fraction of that. None if the threads cannot be started: then the passes run on one.
fn workers() -> Option<&'static rayon::ThreadPool> {
    static WORKERS: OnceLock<Option<rayon::ThreadPool>> = OnceLock::new();
    WORKERS
        .get_or_init(|| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(crate::threads::count().saturating_sub(1).max(1))
                .thread_name(|i| format!("viscontact-team-{i}"))
                .build()
                .ok()
        })
        .as_ref()
}

/// Runs the pieces of one kind of pass, on the team's threads or one after the other.
pub struct Team {
    /// The threads a pass may use (`threads::count`); 1: never the workers.
    size: usize,
    ways: Mutex<Ways>,
}

/// The smoothed times (seconds) of the pass on all threads and on one, and its calls so far.
#[derive(Default)]
struct Ways {
    many: f64,
    one: f64,
    calls: usize,
}

impl Default for Team {
    fn default() -> Self {
        Team::of(crate::threads::count())
    }
}

impl Team {
    /// A team of `size` threads (at least one).
    pub fn of(size: usize) -> Self {
        Team {
            size: size.max(1),
            ways: Mutex::default(),
        }
    }

    /// The number of pieces for a pass that is `large`: the team's size, else one (a small
    /// pass takes less time than handing pieces of it to the workers).
    pub fn pieces(&self, large: bool) -> usize {
        if large {
            self.size
        } else {
            1
        }
    }

    /// As [`Team::each`] for a pass that is `large`, else one piece after the other here.
    pub fn each_if<T: Send>(&self, large: bool, pieces: Vec<T>, work: impl Fn(T) + Sync) {
        if large {
            self.each(pieces, work);
        } else {
            pieces.into_iter().for_each(work);
        }
    }

    /// Runs `work` on every piece: on the team's threads (the first piece on this one) when
    /// there are several pieces and threads and that was the faster way lately, else one
    /// piece after the other here.
    pub fn each<T: Send>(&self, pieces: Vec<T>, work: impl Fn(T) + Sync) {
        let workers = (self.size >= 2 && pieces.len() >= 2)
            .then(workers)
            .flatten();
        let Some(workers) = workers else {
            return pieces.into_iter().for_each(work);
        };
        let ways = || self.ways.lock().unwrap_or_else(|e| e.into_inner());
        let many = {
            let mut w = ways();
            w.calls += 1;
            (w.many <= w.one) != w.calls.is_multiple_of(PROBE)
        };
        let start = Instant::now();
        if many {
            let work = &work;
            let mut pieces = pieces.into_iter();
            let first = pieces.next();
            // The others on the workers, the first here; the scope waits for them (and
            // passes on a panic).
            workers.in_place_scope(|scope| {
                for piece in pieces {
                    scope.spawn(move |_| work(piece));
                }
                if let Some(piece) = first {
                    work(piece);
                }
            });
        } else {
            pieces.into_iter().for_each(work);
        }
        let took = start.elapsed().as_secs_f64();
        let mut w = ways();
        let slot = if many { &mut w.many } else { &mut w.one };
        *slot = if *slot == 0.0 {
            took
        } else {
            0.75 * *slot + 0.25 * took
        };
    }
}

/// `0..n` cut into `pieces` consecutive ranges of sizes differing by one at most.
pub fn blocks(n: usize, pieces: usize) -> impl Iterator<Item = std::ops::Range<usize>> {
    let pieces = pieces.clamp(1, n.max(1));
    (0..pieces).map(move |k| k * n / pieces..(k + 1) * n / pieces)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_cover_the_range_in_order() {
        for (n, pieces) in [(0, 3), (1, 4), (7, 3), (10, 1), (1000, 16)] {
            let got: Vec<_> = blocks(n, pieces).collect();
            assert_eq!(got.len(), pieces.clamp(1, n.max(1)));
            assert_eq!(got.first().unwrap().start, 0);
            assert_eq!(got.last().unwrap().end, n);
            assert!(got.windows(2).all(|w| w[0].end == w[1].start));
            assert!(got.iter().all(|r| r.len() + 1 >= n / pieces));
        }
    }

    /// Every piece runs once, on one thread or several.
    #[test]
    fn each_runs_every_piece_once() {
        for size in [1, 2, 3, 8] {
            let team = Team::of(size);
            for _ in 0..2 * PROBE {
                let mut out = vec![0usize; 37];
                let pieces: Vec<_> = out.chunks_mut(5).enumerate().collect();
                team.each(pieces, |(k, chunk)| {
                    chunk.iter_mut().for_each(|x| *x += k + 1)
                });
                assert!(out.iter().enumerate().all(|(i, &x)| x == i / 5 + 1));
            }
        }
    }
}
