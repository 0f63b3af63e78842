//! Giving up a step while it is being solved. On the 3D boundaries where a step takes
//! minutes (the fine plate's onset of sliding: 7–27 minutes a step with the sparse dual),
//! stopping "after the current step" is no stop at all. An [`Abandon`] is the request,
//! shared between whoever makes it (the run's signal thread: a second SIGINT/SIGTERM, see
//! `run::interrupt`) and the solver of the step; the dual iterations (dense, sparse,
//! matrix-free) look at it before every iteration and the conjugate gradients of the
//! matrix-free Newton systems before every product, and end with `StepStatus::Abandoned`;
//! so do PETSc's Krylov solves (a linear step's, the active set's Newton systems'), at
//! every iteration. The time loop then puts back the w and the multipliers the step started
//! from: the loop stands where it stood before the step, exactly as a stop after the
//! previous step leaves it, so a checkpoint of it resumes bit for bit (the step is solved
//! again from its start). Clarabel's interior-point iterations are not interrupted.
//!
//! The time loop arms the request only around solves that can be given up (`arm`): a
//! request that comes while nothing is armed is refused, and the signal thread then does
//! what it did before (ends the process). One granted stays; it counts for every solve
//! armed later and for none that is not (a library caller may make it before a run: the
//! first step the loop can stop before is then given up).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// A request to give up the step being solved; clones share it.
#[derive(Clone, Debug, Default)]
pub struct Abandon {
    shared: Arc<Flags>,
}

#[derive(Debug, Default)]
struct Flags {
    /// A solve that honours the request is running.
    armed: AtomicBool,
    requested: AtomicBool,
}

impl Abandon {
    /// Requests that the step being solved be given up. Granted (true) when a solve that
    /// honours it is running and no request was made before: the caller decides what to do
    /// when it is not.
    pub fn request(&self) -> bool {
        let f = &self.shared;
        f.armed.load(Ordering::SeqCst) && !f.requested.swap(true, Ordering::SeqCst)
    }

    /// Whether the solve should end now: a request was granted and the solve is armed.
    pub fn requested(&self) -> bool {
        let f = &self.shared;
        f.armed.load(Ordering::SeqCst) && f.requested.load(Ordering::SeqCst)
    }

    /// Marks a solve that honours requests as running until the guard is dropped.
    pub fn arm(&self) -> Armed<'_> {
        self.shared.armed.store(true, Ordering::SeqCst);
        Armed(self)
    }
}

/// While it lives, [`Abandon::request`] is granted.
pub struct Armed<'a>(&'a Abandon);

impl Drop for Armed<'_> {
    fn drop(&mut self) {
        self.0.shared.armed.store(false, Ordering::SeqCst);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_request_is_granted_once_and_only_while_armed() {
        let a = Abandon::default();
        assert!(!a.request(), "nothing armed");
        assert!(!a.requested());
        {
            let _armed = a.arm();
            assert!(a.clone().request(), "armed: granted, through a clone");
            assert!(a.requested());
            assert!(!a.request(), "a second request is refused");
        }
        assert!(!a.request(), "disarmed");
        assert!(!a.requested(), "a request counts only while armed");
        let _armed = a.arm();
        assert!(a.requested(), "and for every solve armed later");
    }
}
