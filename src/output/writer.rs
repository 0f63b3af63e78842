//! The writer thread of a series: computes frames' fields from a step's state, encodes them
//! (compression is the expensive part) and writes them, off the time loop.
//!
//! The queue holds [`QUEUE`] frames: the time loop waits only when the disk or the
//! compressor falls that far behind, which bounds the memory held by frames in flight. The
//! thread stops at its first failed write; its error (naming the file) is what the next
//! [`Writer::send`] or [`Writer::finish`] returns, so a run never ends well with a frame
//! missing. The pattern is the checkpoint writer's (src/checkpoint/writer.rs), without its
//! replacement of waiting snapshots: every frame is kept.
//!
//! What a frame becomes on disk is the [`Sink`]'s business: `.vtu` + `.pvd` (`vtu.rs`; in
//! pieces, `pvtu.rs`) or one more step of `solution.vtkhdf` (`vtkhdf.rs`). A sink reports the CRC-32 of each frame
//! it wrote ([`Written`]); the series collects them when the thread ends
//! ([`Writer::finish`]), which is also what a checkpoint waits for, so a checkpoint records
//! the checksums of exactly the frames written before it (`docs/restart.md`).

use std::sync::mpsc::{sync_channel, SyncSender};
use std::thread::JoinHandle;

use crate::{Error, Result};

/// A frame on disk: its step, the CRC-32 and length of the bytes it is checked by (the whole
/// `.vtu` file; for `solution.vtkhdf` the frame's field values as stored).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Written {
    pub step: usize,
    pub crc32: u32,
    pub bytes: u64,
}

/// Frames waiting for the writer thread at most, besides the one it works on.
const QUEUE: usize = 2;

/// Where the frames of a series go.
pub(super) trait Sink: Send + 'static {
    /// One frame, ready to be written.
    type Job: Send + 'static;
    /// What can be done before the first frame (the thread starts with the series).
    fn prepare(&mut self) {}
    /// Writes one frame (and says what it wrote, if a frame); an error names the file.
    fn write(&mut self, job: Self::Job) -> Result<Option<Written>>;
    /// The thread ends (the queue was drained by [`Writer::finish`]): let go of open files.
    fn close(&mut self) -> Result<()>;
}

/// A frame as the time loop hands it over: what makes the sink's job on the writer thread
/// (a step's fields are computed there, from copies of its state).
pub(super) type Make<J> = Box<dyn FnOnce() -> Result<J> + Send>;

/// The thread hands the sink back when it ends, so that a finished series can be written to
/// again (the thread is started on demand).
type Thread<S> = JoinHandle<(Box<S>, Vec<Written>, Result<()>)>;

pub(super) struct Writer<S: Sink> {
    /// The sink while no thread runs (boxed: a sink holds the mesh).
    sink: Option<Box<S>>,
    tx: Option<SyncSender<Make<S::Job>>>,
    thread: Option<Thread<S>>,
    /// The frames written by threads that ended, in order, until [`Writer::take_written`].
    written: Vec<Written>,
}

impl<S: Sink> Writer<S> {
    /// The writer of `sink`; its thread starts at once with [`Sink::prepare`].
    pub(super) fn new(sink: S) -> Writer<S> {
        let mut writer = Writer {
            sink: Some(Box::new(sink)),
            tx: None,
            thread: None,
            written: Vec::new(),
        };
        writer.start();
        writer
    }

    /// Starts the thread unless it runs.
    fn start(&mut self) {
        if let Some(mut sink) = self.sink.take() {
            let (tx, rx) = sync_channel::<Make<S::Job>>(QUEUE);
            self.tx = Some(tx);
            self.thread = Some(std::thread::spawn(move || {
                sink.prepare();
                let mut written = Vec::new();
                let result = rx.iter().try_for_each(|make| {
                    written.extend(sink.write(make()?)?);
                    Ok(())
                });
                let closed = sink.close();
                (sink, written, result.and(closed))
            }));
        }
    }

    /// Queues a frame (waits while the queue is full); the thread calls `make` and writes
    /// its job. Errors: the failed write of an earlier frame.
    pub(super) fn send(&mut self, make: Make<S::Job>) -> Result<()> {
        self.start();
        let sent = self.tx.as_ref().is_some_and(|tx| tx.send(make).is_ok());
        if sent {
            return Ok(());
        }
        // The thread stopped at an error, which finish returns.
        self.finish()?;
        Err(Error::solve("output: the writer thread stopped"))
    }

    /// Waits until every queued frame is written and the sink closed its files; the first
    /// failed write is the error.
    pub(super) fn finish(&mut self) -> Result<()> {
        self.tx = None;
        let Some(thread) = self.thread.take() else {
            return Ok(());
        };
        match thread.join() {
            Ok((sink, written, result)) => {
                self.sink = Some(sink);
                self.written.extend(written);
                result
            }
            Err(_) => Err(Error::solve("output: the writer thread panicked")),
        }
    }
}

impl<S: Sink> Writer<S> {
    /// The frames written since the last call, in the order written (complete once
    /// [`Writer::finish`] returned).
    pub(super) fn take_written(&mut self) -> Vec<Written> {
        std::mem::take(&mut self.written)
    }
}

impl<S: Sink> Drop for Writer<S> {
    /// A series dropped without [`Writer::finish`] (a run that failed elsewhere) still
    /// completes its queued frames; their errors are moot then.
    fn drop(&mut self) {
        let _ = self.finish();
    }
}
