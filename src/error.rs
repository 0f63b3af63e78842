//! One error type for the whole crate. A user mistake (`Input`) exits with status 2, a solve
//! that failed (`Solve`) with status 1; every message names the file, key or group at fault
//! and says what would fix it.

use std::path::Path;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Bad input: a scene, mesh or command-line value the user can fix. Exit status 2.
    #[error("{0}")]
    Input(String),
    /// A solve or run that failed although its input was accepted. Exit status 1.
    #[error("{0}")]
    Solve(String),
    /// SIGINT/SIGTERM (the signal's number) came during a run's or a resume's setup, which
    /// then stopped before it changed anything on disk. Exit status 128 + the signal.
    #[error(
        "interrupted by {} during setup, before the first step: nothing on disk was changed \
         (the output directory holds what it held before)",
        signal_name(*.0)
    )]
    Interrupted(i32),
    /// A run's setup failed or was stopped on another MPI rank of the run, which
    /// reported why: this rank ends with the same exit status, saying nothing.
    #[error("another rank ended the run's setup (exit status {0}) and said why")]
    Elsewhere(i32),
    /// An operating-system error while reading or writing a file. Exit status 1.
    #[error("{path}: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
}

impl Error {
    pub fn input(msg: impl Into<String>) -> Self {
        Error::Input(msg.into())
    }

    pub fn solve(msg: impl Into<String>) -> Self {
        Error::Solve(msg.into())
    }

    /// An HDF5 error while reading or writing `path` (an I/O error of that file).
    pub fn hdf5(path: &Path, e: hdf5_metno::Error) -> Self {
        Error::io(path, std::io::Error::other(format!("HDF5: {e}")))
    }

    /// Wraps an I/O error with the path it concerns.
    pub fn io(path: &Path, source: std::io::Error) -> Self {
        Error::Io {
            path: path.display().to_string(),
            source,
        }
    }

    /// The process exit status for this error (README.md, "Commands": 2 for bad input, 1 otherwise;
    /// 128 + the signal for a setup that a signal stopped, as a shell reports a process the
    /// signal ended).
    pub fn exit_code(&self) -> i32 {
        match self {
            Error::Input(_) => 2,
            Error::Interrupted(signal) => 128 + signal,
            Error::Elsewhere(code) => *code,
            Error::Solve(_) | Error::Io { .. } => 1,
        }
    }
}

/// "SIGINT" / "SIGTERM" / "SIGHUP" / "signal N".
pub fn signal_name(signal: i32) -> String {
    match signal {
        libc::SIGINT => "SIGINT".into(),
        libc::SIGTERM => "SIGTERM".into(),
        libc::SIGHUP => "SIGHUP".into(),
        s => format!("signal {s}"),
    }
}

pub type Result<T> = std::result::Result<T, Error>;
