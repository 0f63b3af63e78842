//! SIGINT and SIGTERM (what Ctrl-C and a batch scheduler's time limit send) end a run after
//! the step being solved: the run writes a checkpoint and summary.json (status
//! "interrupted") and the command exits 130 / 143, the shell's codes for death by these
//! signals. During setup (scene, mesh, discretization, ordering, factorization) they end
//! the command at the next stage boundary with the same codes, before the directory's
//! earlier run is touched.
//!
//! A second signal is for a step that takes too long to wait for (on several MPI ranks, the
//! first: `Interrupt::give_up_at_first`). While a dual method
//! solves a step that a stop could be made before (any step after the first one the
//! process solved), it gives that step up (`solver::abandon`, within one Newton iteration
//! or one product of the matrix-free conjugate gradients): the run stops as if the first
//! signal had come just before the step, with the checkpoint of the state at its start
//! (written now if the last one is older), summary.json and the same exit codes; the
//! resumed run solves the step from its start, bit for bit the uninterrupted one.
//!
//! No later signal ever costs more than the step in progress. Before the run is committed
//! (setup, while the directory still holds its earlier run unchanged: see below) a second
//! signal ends the process at once by the signal's default action, which changes nothing
//! on disk. Once it is committed, the directory holds this run alone and, until its first
//! checkpoint, nothing to resume: a second or third signal that cannot give the step up
//! (clarabel's steps, the first step, writing a frame or a checkpoint) is noted on stderr
//! and the run stops after the step in progress as the first asked. Killing it then would
//! lose what it computed: two Ctrl-C a few milliseconds apart used to end the process by
//! the signal after setup, with the earlier run removed and no checkpoint written. SIGKILL
//! still ends it at once; the directory then keeps its last checkpoint (written through a
//! temporary file and a rename, so it is never half-written), if one was written.
//!
//! SIGHUP, which a terminal that goes away sends (an ssh session that drops), is taken as
//! SIGTERM is: the run stops after its step with a checkpoint (exit 129). Under `nohup` it
//! is ignored and the run goes on; its lines to the lost terminal are dropped
//! (`crate::console`).
//!
//! # How the signals are received
//!
//! No handler is installed. [`Interrupt::on_signals`] blocks SIGINT, SIGTERM and SIGHUP in the
//! calling thread before any other thread exists, so every thread the process starts
//! inherits the mask, and one thread of ours takes them with `sigwait`. A library that
//! installs handlers of its own therefore never sees them: the bundled METIS calls
//! `signal(SIGTERM, …)` around every ordering and `longjmp`s out of its handler, which
//! turned a SIGTERM during setup into "METIS could not order K_A" (exit 1), and once into
//! a process hung on glibc's malloc lock. With the signal blocked everywhere, METIS's
//! handler is never run, and `sigwait` takes the signal whatever its disposition. Child
//! processes start with an empty mask (std's `Command` resets it).
//!
//! # Setup is atomic
//!
//! A new run replaces the directory's earlier run in one step, [`Interrupt::unless_signalled`]:
//! under a lock that the signal thread also takes before it records a signal, the run
//! checks that no signal came and then removes the earlier run, and is committed. A signal
//! therefore either came first (the run stops, the earlier run is intact) or after the
//! replacement (the run is past setup and stops after its first step, with a checkpoint to
//! resume from). A resume commits the same way before it first changes the directory.

use crate::error::signal_name;
use crate::solver::Abandon;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

/// The signal that asked a run to stop, if one came; shared with the signal thread.
#[derive(Clone, Debug, Default)]
pub struct Interrupt {
    signal: Arc<AtomicUsize>,
    /// Held while a signal is recorded and while setup commits (see the module doc).
    commit: Arc<Mutex<()>>,
    /// Setup has committed: the directory holds this run, and no signal may end the process.
    committed: Arc<AtomicBool>,
    /// What a second signal asks of the step being solved.
    abandon: Abandon,
    /// The first signal asks it too (a run on several MPI ranks: `give_up_at_first`).
    at_first: Arc<AtomicBool>,
}

impl Interrupt {
    /// Takes SIGINT, SIGTERM and SIGHUP from now on: the first sets this flag, a later one
    /// gives up the step being solved where it can be (`abandon`), else, before the run
    /// commits, kills the process as if nothing had taken them (see the module doc). Call
    /// it before the process starts any thread (the mask it sets is inherited by threads
    /// started later).
    pub fn on_signals() -> std::io::Result<Interrupt> {
        let set = stop_signals();
        // SAFETY: `set` is an initialized signal set; pthread_sigmask only reads it.
        let rc = unsafe { libc::pthread_sigmask(libc::SIG_BLOCK, &set, std::ptr::null_mut()) };
        if rc != 0 {
            return Err(std::io::Error::from_raw_os_error(rc));
        }
        let interrupt = Interrupt::default();
        let taker = interrupt.clone();
        std::thread::Builder::new()
            .name("signals".into())
            .spawn(move || taker.take_signals(set))?;
        Ok(interrupt)
    }

    /// The signal thread: waits for the stop signals; records the first; answers a later
    /// one by [`Interrupt::again`].
    fn take_signals(&self, set: libc::sigset_t) {
        let mut noted = false;
        loop {
            let mut sig: libc::c_int = 0;
            // SAFETY: `set` is initialized and `sig` a valid place for the result.
            if unsafe { libc::sigwait(&set, &mut sig) } != 0 {
                continue;
            }
            if self.signal().is_some() {
                self.again(sig, &mut noted);
                continue;
            }
            let _commit = self.commit.lock().unwrap_or_else(|p| p.into_inner());
            self.raise(sig);
            if self.at_first.load(Ordering::SeqCst) {
                self.abandon.request();
            }
        }
    }

    /// A signal after the first: gives up the step being solved where it can; else ends
    /// the process if the run has not committed (nothing on disk changes), else says once
    /// that the run stops after the step in progress.
    fn again(&self, sig: libc::c_int, noted: &mut bool) {
        if self.abandon.request() {
            crate::errln!("\n{}: giving up the step in progress", signal_name(sig));
            return;
        }
        // Under the commit lock: a commit in progress finishes first, and then counts.
        let _commit = self.commit.lock().unwrap_or_else(|p| p.into_inner());
        if !self.committed.load(Ordering::SeqCst) {
            die_by(sig);
        }
        if !std::mem::replace(noted, true) {
            crate::errln!(
                "\n{}: the step in progress cannot be given up; the run stops after it, \
                 with a checkpoint (SIGKILL would end it now, losing what it computed \
                 since its last checkpoint)",
                signal_name(sig)
            );
        }
    }

    /// A run on several MPI ranks: the first signal also gives up the step being solved
    /// where it can be (on every rank at once; the run then stops before it), for mpirun
    /// kills the ranks a second after it passes a Ctrl-C on (docs/cluster.md).
    pub fn give_up_at_first(&self) {
        self.at_first.store(true, Ordering::SeqCst);
    }

    /// A follower rank's (`crate::ranks`): committed from the start, so that no signal ends
    /// the process; a signal only asks the run to stop after a step, which rank 0 decides
    /// with the others, and before it commits, alone.
    pub fn follow(&self) {
        self.committed.store(true, Ordering::SeqCst);
    }

    /// Asks the run to stop as `signal` would (for library callers and tests, and for a
    /// signal that reached another rank of the run).
    pub fn raise(&self, signal: i32) {
        self.signal.store(signal as usize, Ordering::SeqCst);
    }

    /// The request a second signal makes of the step being solved.
    pub fn abandon(&self) -> &Abandon {
        &self.abandon
    }

    /// The signal that arrived, if any.
    pub fn signal(&self) -> Option<i32> {
        match self.signal.load(Ordering::SeqCst) {
            0 => None,
            s => Some(s as i32),
        }
    }

    /// A stage boundary of setup: [`crate::Error::Interrupted`] once a signal has come.
    pub fn between_setup_stages(&self) -> crate::Result<()> {
        match self.signal() {
            Some(s) => Err(crate::Error::Interrupted(s)),
            None => Ok(()),
        }
    }

    /// Runs `commit` unless a signal has come, and so that no signal is recorded while it
    /// runs: `Err(signal)` when one came first.
    /// From then on no signal ends the process (see the module doc).
    pub fn unless_signalled<T>(&self, commit: impl FnOnce() -> T) -> Result<T, i32> {
        let _commit = self.commit.lock().unwrap_or_else(|p| p.into_inner());
        match self.signal() {
            Some(s) => Err(s),
            None => {
                let done = commit();
                self.committed.store(true, Ordering::SeqCst);
                Ok(done)
            }
        }
    }
}

/// {SIGINT, SIGTERM, SIGHUP}.
fn stop_signals() -> libc::sigset_t {
    // SAFETY: sigemptyset initializes the set before sigaddset reads it.
    unsafe {
        let mut set = std::mem::zeroed::<libc::sigset_t>();
        libc::sigemptyset(&mut set);
        libc::sigaddset(&mut set, libc::SIGINT);
        libc::sigaddset(&mut set, libc::SIGTERM);
        libc::sigaddset(&mut set, libc::SIGHUP);
        set
    }
}

/// Ends the process by `sig`'s default action (the exit status a shell reports as 128 +
/// sig), from the signal thread.
fn die_by(sig: libc::c_int) -> ! {
    // SAFETY: plain libc calls on this thread's own mask and a signal number we received.
    unsafe {
        libc::signal(sig, libc::SIG_DFL);
        let mut only = std::mem::zeroed::<libc::sigset_t>();
        libc::sigemptyset(&mut only);
        libc::sigaddset(&mut only, sig);
        libc::pthread_sigmask(libc::SIG_UNBLOCK, &only, std::ptr::null_mut());
        libc::raise(sig);
    }
    // The default action of SIGINT/SIGTERM ends the process; should it ever return here:
    std::process::exit(128 + sig)
}
