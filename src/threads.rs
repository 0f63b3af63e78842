//! The threads of the process: one count, decided once before any work starts.
//!
//! The count is `--threads N` (`run`, `resume`, `study`), else the environment variable
//! `VISCONTACT_THREADS`, else the cores the process may use
//! (`std::thread::available_parallelism`, which on Linux obeys the CPU affinity that
//! `taskset` or Slurm's `--cpus-per-task` set, and a cgroup's CPU quota). Everything that
//! hands work to other threads asks here:
//! - rayon's global pool, on which faer's parallel kernels run, holds that many threads;
//! - faer's parallelism is `Par::rayon(N)`, no more than the cores the process may use,
//!   `Par::Seq` for one thread ([`par`]);
//! - the step's passes (`team::Team`) cut their work in as many pieces and run
//!   them on that many threads (the factor's solves on 16 at most).
//!
//! Where an MPI launcher started several processes of a run on one node (docs/cluster.md),
//! the default is each one's share of the cores.
//!
//! With one thread nothing runs on a second thread. Results do not depend on the count:
//! the step's arithmetic is decided by the matrix (the factor's two groups of subtrees,
//! the two column parts of D), never by the thread count or by timing; where the pieces
//! follow the thread count, each row's arithmetic is the same in any piece (the blocks of
//! G's and the Newton matrices' rows or columns; the factor's subtrees, whose updates of
//! other rows are recorded and applied in the serial order: `solver::factor`).
//! faer's sparse Cholesky factorization and its dense kernels on matrices of several
//! columns (factorizations, triangular solves, products, inverses) give the same bits for
//! every `Par` (this module's tests, and `solver::factor`'s for the sparse factorization);
//! its products and solves of a single vector do not (they split their sums by the thread
//! count), so they always run with `Par::Seq`.

pub mod team;

use crate::{Error, Result};
use faer::Par;
use std::num::NonZeroUsize;
use std::sync::OnceLock;

/// The environment variable read when `--threads` is not given.
pub const ENV: &str = "VISCONTACT_THREADS";

/// The count, once [`init`] or [`count`] has decided it.
static COUNT: OnceLock<usize> = OnceLock::new();

/// The most threads a run may ask for, as a multiple of the cores the process may use.
/// Results are the same for every count, so more threads than cores only slow a run
/// (`--threads 5000` turned a 0.25 s run into 9.6 s, and a billion spawned threads for 11
/// minutes before the process aborted); a few times the cores is still a count someone
/// may try on purpose (with a warning), far more is a typo.
pub const MAX_PER_CORE: usize = 4;

/// Decides the process's thread count (`flag`, else `VISCONTACT_THREADS`, else the cores it
/// may use), sizes rayon's global pool and faer's parallelism by it, and returns it. Call it
/// once, before any work: a second call, or one after [`count`], keeps the first count.
/// A `VISCONTACT_THREADS` that is not a whole number ≥ 1, or a count above
/// [`MAX_PER_CORE`] times the cores, is bad input; a count above the cores is warned of.
pub fn init(flag: Option<NonZeroUsize>) -> Result<usize> {
    let (n, source) = match flag {
        Some(n) => (n.get(), format!("--threads {n}")),
        None => match std::env::var(ENV) {
            Ok(text) => (
                parse(&text).ok_or_else(|| {
                    Error::input(format!(
                        "{ENV}={text:?}: expected the number of threads, a whole number ≥ 1 \
                         written without spaces"
                    ))
                })?,
                format!("{ENV}={text}"),
            ),
            Err(std::env::VarError::NotPresent) => (default_count(), String::new()),
            Err(std::env::VarError::NotUnicode(_)) => {
                return Err(Error::input(format!("{ENV} is not valid UTF-8")));
            }
        },
    };
    check(n, available(), &source)?;
    let n = *COUNT.get_or_init(|| n);
    // Fails only if the pool was started already (a second call): it keeps its size then.
    let _ = rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .thread_name(|i| format!("viscontact-{i}"))
        .build_global();
    faer::set_global_parallelism(par());
    Ok(n)
}

/// The count where none is asked for: the cores this process may use, shared among the
/// run's processes on this node (`mpirun -n 2` on two cores: one thread each).
fn default_count() -> usize {
    (available() / ranks_on_this_node()).max(1)
}

/// How many processes an MPI launcher started on this process's node (Open MPI's variable,
/// MPICH's), 1 without one.
fn ranks_on_this_node() -> usize {
    ["OMPI_COMM_WORLD_LOCAL_SIZE", "MPI_LOCALNRANKS"]
        .into_iter()
        .find_map(|var| std::env::var(var).ok()?.trim().parse::<usize>().ok())
        .filter(|&n| n >= 1)
        .unwrap_or(1)
}

/// Refuses `n` threads (asked for by `source`) above [`MAX_PER_CORE`] × `cores`, and warns
/// of more than `cores`.
fn check(n: usize, cores: usize, source: &str) -> Result<()> {
    let most = MAX_PER_CORE * cores;
    let cores_text = format!(
        "this process may use {cores} core{}",
        if cores == 1 { "" } else { "s" }
    );
    if n > most {
        return Err(Error::input(format!(
            "{source}: {cores_text}, and at most {most} threads ({MAX_PER_CORE} a core) are \
             accepted; results are the same for every count, so give {cores} (or leave the \
             count out to use the cores)"
        )));
    }
    if n > cores {
        crate::errln!(
            "warning: {source}: {cores_text}; threads beyond the cores only slow the steps \
             (the results are the same)"
        );
    }
    Ok(())
}

/// A thread count as `VISCONTACT_THREADS` writes it: a whole number ≥ 1.
fn parse(text: &str) -> Option<usize> {
    text.parse().ok().filter(|&n| n >= 1)
}

/// The cores the process may use (1 if the system cannot say), asked once: the answer
/// reads the CPU affinity and the cgroup's files, and [`par`] asks for every Newton
/// factorization.
fn available() -> usize {
    static CORES: OnceLock<usize> = OnceLock::new();
    *CORES.get_or_init(|| std::thread::available_parallelism().map_or(1, NonZeroUsize::get))
}

/// The process's thread count: [`init`]'s, or the cores it may use where nothing called
/// `init` (the library used from a test or a benchmark).
pub fn count() -> usize {
    *COUNT.get_or_init(available)
}

/// faer's parallelism for work that is large enough to share: all [`count`] threads, but
/// no more than the cores the process may use. faer's parallel kernels wait for each other
/// spinning, so more of them than cores is ruinous (eight on two cores made a setup seven
/// times as long as two: docs/performance.md, "Threads"), where the step's passes
/// (`team::Team`) merely lose their threaded way. Their bits do not depend on the
/// parallelism (this module's tests), so the cap changes no result.
pub fn par() -> Par {
    match count().min(available()) {
        1 => Par::Seq,
        n => Par::rayon(n),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::SplitMix;
    use faer::linalg::cholesky::llt;
    use faer::linalg::matmul::matmul;
    use faer::linalg::triangular_solve::solve_lower_triangular_in_place;
    use faer::{Accum, Mat};

    #[test]
    fn counts_are_whole_numbers_from_one() {
        assert_eq!(parse("3"), Some(3));
        assert_eq!(parse("16"), Some(16));
        for bad in ["0", "-1", "", "two", "1.5", " 2", "16\n"] {
            assert_eq!(parse(bad), None, "{bad}");
        }
        assert!(available() >= 1);
        // However many threads the process runs, faer's kernels use no more than its cores.
        assert!(par().degree() <= available());
    }

    #[test]
    fn counts_far_above_the_cores_are_refused() {
        assert!(check(2, 2, "--threads 2").is_ok());
        assert!(check(8, 2, "--threads 8").is_ok());
        let e = check(9, 2, "--threads 9").unwrap_err().to_string();
        assert!(e.contains("--threads 9") && e.contains("2 cores"), "{e}");
        assert!(check(1_000_000_000, 16, "VISCONTACT_THREADS=1000000000").is_err());
    }

    /// A matrix of uniform entries in [−1, 1) from `seed`.
    fn random(rows: usize, cols: usize, seed: u64) -> Mat<f64> {
        let mut rng = SplitMix(seed);
        Mat::from_fn(rows, cols, |_, _| rng.range(-1.0, 1.0))
    }

    /// The dense kernels the dual runs on all threads (G = L⁻¹E, D = GᵀG, the Cholesky
    /// factorization of a Newton matrix, the inverse of D) give the same bits on one thread
    /// and on 2, 3 or 4: with more than one column their parallel versions split the output,
    /// never a sum. (A product or solve of a single vector splits its sum by the thread
    /// count: the dual runs those on one thread.) Sizes past faer's thresholds for going
    /// parallel, with sums long enough that another order would show.
    #[test]
    fn faer_dense_kernels_are_identical_for_every_par() {
        let (n, m) = (1100, 300);
        let a = random(n, n, 1);
        let run = |par: Par| {
            // An SPD matrix A Aᵀ/n + I, its factor, a solve with it, and GᵀG.
            let mut spd = Mat::<f64>::identity(n, n);
            matmul(
                spd.as_mut(),
                Accum::Add,
                a.as_ref(),
                a.transpose(),
                1.0 / n as f64,
                par,
            );
            let mut l = spd.clone();
            let mut mem = faer::dyn_stack::MemBuffer::new(
                llt::factor::cholesky_in_place_scratch::<f64>(n, par, Default::default()),
            );
            llt::factor::cholesky_in_place(
                l.as_mut(),
                Default::default(),
                par,
                faer::dyn_stack::MemStack::new(&mut mem),
                Default::default(),
            )
            .unwrap();
            let mut g = random(n, m, 2);
            solve_lower_triangular_in_place(l.as_ref(), g.as_mut(), par);
            let mut d = Mat::<f64>::zeros(m, m);
            matmul(
                d.as_mut(),
                Accum::Replace,
                g.transpose(),
                g.as_ref(),
                1.0,
                par,
            );
            let bits = |v: &Mat<f64>| {
                (0..v.ncols())
                    .flat_map(|j| (0..v.nrows()).map(move |i| v[(i, j)].to_bits()))
                    .collect::<Vec<_>>()
            };
            let mut inv = Mat::<f64>::zeros(n, n);
            llt::inverse::inverse(
                inv.as_mut(),
                l.as_ref(),
                par,
                faer::dyn_stack::MemStack::new(&mut faer::dyn_stack::MemBuffer::new(
                    llt::inverse::inverse_scratch::<f64>(n, par),
                )),
            );
            [&spd, &l, &g, &d, &inv].map(bits)
        };
        let one = run(Par::Seq);
        for threads in [2, 3, 4] {
            let many = run(Par::rayon(threads));
            for (what, (a, b)) in ["A", "L", "G", "D", "A⁻¹"]
                .iter()
                .zip(one.iter().zip(&many))
            {
                assert!(a == b, "{what} differs with {threads} threads");
            }
        }
    }
}
