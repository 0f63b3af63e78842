//! The writer thread of a series: encodes frames (compression is the expensive part) and
//! writes them, off the time loop.
//!
//! The queue holds [`QUEUE`] frames: the time loop waits only when the disk or the
//! compressor falls that far behind, which bounds the memory held by frames in flight. The
//! thread stops at its first failed write; its error (naming the file) is what the next
//! [`Writer::send`] or [`Writer::finish`] returns, so a run never ends well with a frame
//! missing. The pattern is the checkpoint writer's (src/checkpoint.rs), without its
//! replacement of waiting snapshots: every frame is kept.

use std::path::PathBuf;
use std::sync::mpsc::{sync_channel, SyncSender};
use std::thread::JoinHandle;

use super::{vtu, write_atomic};
use crate::{Error, Result};

/// Frames waiting for the writer thread at most, besides the one it works on.
const QUEUE: usize = 2;

/// One frame to write: the `.vtu` and then the `.pvd` that lists it.
pub(super) struct Job {
    pub path: PathBuf,
    pub point_data: Vec<vtu::Array>,
    pub cell_data: Vec<vtu::Array>,
    /// The collection file and its new text.
    pub pvd: (PathBuf, String),
}

/// The thread hands the encoded mesh back when it ends, so that a finished series can be
/// written to again (the thread is started on demand).
type Thread = JoinHandle<(vtu::Grid, Result<()>)>;

pub(super) struct Writer {
    /// The mesh while no thread runs.
    grid: Option<vtu::Grid>,
    tx: Option<SyncSender<Job>>,
    thread: Option<Thread>,
}

impl Writer {
    pub(super) fn new(grid: vtu::Grid) -> Writer {
        Writer {
            grid: Some(grid),
            tx: None,
            thread: None,
        }
    }

    /// Queues a frame (waits while the queue is full). Errors: the failed write of an
    /// earlier frame.
    pub(super) fn send(&mut self, job: Job) -> Result<()> {
        if let Some(mut grid) = self.grid.take() {
            let (tx, rx) = sync_channel::<Job>(QUEUE);
            self.tx = Some(tx);
            self.thread = Some(std::thread::spawn(move || {
                let result = rx.iter().try_for_each(|job| {
                    write_atomic(&job.path, grid.encode(&job.point_data, &job.cell_data))?;
                    write_atomic(&job.pvd.0, job.pvd.1.as_bytes())
                });
                (grid, result)
            }));
        }
        let sent = self.tx.as_ref().is_some_and(|tx| tx.send(job).is_ok());
        if sent {
            return Ok(());
        }
        // The thread stopped at an error, which finish returns.
        self.finish()?;
        Err(Error::solve("output: the writer thread stopped"))
    }

    /// Waits until every queued frame is written; the first failed write is the error.
    pub(super) fn finish(&mut self) -> Result<()> {
        self.tx = None;
        let Some(thread) = self.thread.take() else {
            return Ok(());
        };
        match thread.join() {
            Ok((grid, result)) => {
                self.grid = Some(grid);
                result
            }
            Err(_) => Err(Error::solve("output: the writer thread panicked")),
        }
    }
}

impl Drop for Writer {
    /// A series dropped without [`Writer::finish`] (a run that failed elsewhere) still
    /// completes its queued frames; their errors are moot then.
    fn drop(&mut self) {
        let _ = self.finish();
    }
}
