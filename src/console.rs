//! The process's two text streams, written so that neither can end a run.
//!
//! A run outlives its terminal: an ssh session that drops, `run … | head -1` or a log on a
//! full disk close or fill stdout and stderr, and `println!` would then panic (exit 101)
//! at the next progress line, with no checkpoint and no summary.json. Everything the
//! program prints goes through [`outln!`](crate::outln) and [`errln!`](crate::errln) instead: a line that cannot be
//! written is dropped, the run goes on and ends as it would have (its files are its
//! results), and the first failure on stdout is kept for [`stdout_failure`].
//!
//! The commands that only print (`check`, `mesh-info`, `plot`'s report) behave as Unix
//! tools do: [`end_quietly_on_broken_pipe`] gives SIGPIPE back its default action (Rust
//! ignores it; [`outlive_broken_pipes`] ignores it again for runs and studies), so
//! `check X | head -1` ends silently the moment the reader goes, and a stdout that fails
//! otherwise (`> /dev/full`) is an error of the command (exit 1).

use std::fmt;
use std::io::Write;
use std::sync::OnceLock;

/// The first error writing stdout, if one happened.
static STDOUT_FAILED: OnceLock<String> = OnceLock::new();

/// Writes one line to stdout; a failure is remembered (see [`stdout_failure`]), not raised.
pub fn out(line: fmt::Arguments) {
    let mut stdout = std::io::stdout().lock();
    if let Err(e) = writeln!(stdout, "{line}").and_then(|()| stdout.flush()) {
        let _ = STDOUT_FAILED.set(e.to_string());
    }
}

/// Writes one line to stderr, in one write; a line that cannot be written is dropped.
/// Stderr is unbuffered, and a line formatted into it would go out in pieces, which the
/// MPI ranks of a run, writing to one terminal, would interleave mid-line.
pub fn err(line: fmt::Arguments) {
    let _ = std::io::stderr().write_all(format!("{line}\n").as_bytes());
}

/// Why stdout could not be written, if it could not.
pub fn stdout_failure() -> Option<&'static str> {
    STDOUT_FAILED.get().map(String::as_str)
}

/// From now on a write to a pipe whose reader has gone ends the process silently by
/// SIGPIPE (exit status 141 in a shell), as `cat` and `ls` do. For commands that only print.
pub fn end_quietly_on_broken_pipe() {
    // SAFETY: resets one signal's disposition to its default; no handler is involved.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

/// From now on a write to a pipe whose reader has gone fails with an error that
/// [`outln!`](crate::outln) and [`errln!`](crate::errln) drop (Rust's default for a process): for runs and studies.
pub fn outlive_broken_pipes() {
    // SAFETY: sets one signal's disposition to "ignore"; no handler is involved.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_IGN);
    }
}

/// `println!` that never panics: see the module doc.
#[macro_export]
macro_rules! outln {
    () => {
        $crate::console::out(format_args!(""))
    };
    ($($arg:tt)*) => {
        $crate::console::out(format_args!($($arg)*))
    };
}

/// `eprintln!` that never panics: see the module doc.
#[macro_export]
macro_rules! errln {
    () => {
        $crate::console::err(format_args!(""))
    };
    ($($arg:tt)*) => {
        $crate::console::err(format_args!($($arg)*))
    };
}
