//! SIGINT and SIGTERM (what Ctrl-C and a batch scheduler's time limit send) end a run after
//! the step being solved: the run writes a checkpoint and summary.json (status
//! "interrupted") and the command exits 130 / 143, the shell's codes for death by these
//! signals. A second signal ends the process at once, by the signal's default action, for a
//! run stuck in a long step; the checkpoint on disk is then the previous one (it is written
//! through a temporary file and a rename, so it is never half-written).

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;

/// The signal that asked a run to stop, if one came; shared with the signal handlers.
#[derive(Clone, Debug, Default)]
pub struct Interrupt {
    signal: Arc<AtomicUsize>,
}

impl Interrupt {
    /// Makes SIGINT and SIGTERM set this flag instead of killing the process; a second one
    /// of either kills it as if no handler were installed.
    pub fn on_signals() -> std::io::Result<Interrupt> {
        use signal_hook::consts::{SIGINT, SIGTERM};
        use signal_hook::flag;
        let interrupt = Interrupt::default();
        let armed = Arc::new(AtomicBool::new(false));
        for sig in [SIGINT, SIGTERM] {
            // Registered first, so it sees `armed` as the previous signal left it.
            flag::register_conditional_default(sig, armed.clone())?;
            flag::register(sig, armed.clone())?;
            flag::register_usize(sig, interrupt.signal.clone(), sig as usize)?;
        }
        Ok(interrupt)
    }

    /// Asks the run to stop as `signal` would (for library callers and tests).
    pub fn raise(&self, signal: i32) {
        self.signal.store(signal as usize, Ordering::SeqCst);
    }

    /// The signal that arrived, if any.
    pub fn signal(&self) -> Option<i32> {
        match self.signal.load(Ordering::SeqCst) {
            0 => None,
            s => Some(s as i32),
        }
    }
}

/// "SIGINT" / "SIGTERM" / "signal N".
pub fn signal_name(signal: i32) -> String {
    match signal {
        signal_hook::consts::SIGINT => "SIGINT".into(),
        signal_hook::consts::SIGTERM => "SIGTERM".into(),
        s => format!("signal {s}"),
    }
}
