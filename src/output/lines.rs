//! A text file that grows by lines made and written on a thread of their own (the run's
//! `history.csv`): the time loop hands over the making of a line (what is costly in it, a
//! field's maximum over the cells, say) and goes on. Each line is written with one `write`
//! as soon as it is made, so a killed process leaves the lines made before it, at most the
//! last one cut short. The thread is the series' (`writer`): [`Lines::finish`] waits until
//! every line handed over is written (a checkpoint waits for it), and a failed write is
//! the error of the next [`Lines::send`] or [`Lines::finish`], naming the file.

use super::writer::{Make, Sink, Writer, Written};
use crate::{Error, Result};
use std::fs::File;
use std::io::Write;
use std::path::PathBuf;

/// The file the lines are appended to.
struct LineSink {
    file: File,
    path: PathBuf,
}

impl Sink for LineSink {
    type Job = String;

    fn write(&mut self, line: String) -> Result<Option<Written>> {
        (self.file.write_all(line.as_bytes())).map_err(|e| Error::io(&self.path, e))?;
        Ok(None)
    }

    fn close(&mut self) -> Result<()> {
        Ok(())
    }
}

/// Lines appended to `path` by a writer thread.
pub struct Lines {
    writer: Writer<LineSink>,
}

impl Lines {
    /// Appends to `file` (open at its end), which is `path`.
    pub fn new(file: File, path: PathBuf) -> Lines {
        Lines {
            writer: Writer::new(LineSink { file, path }),
        }
    }

    /// Queues a line: the thread calls `make` and writes what it returns.
    pub fn send(&mut self, make: impl FnOnce() -> Result<String> + Send + 'static) -> Result<()> {
        let make: Make<String> = Box::new(make);
        self.writer.send(make)
    }

    /// Waits until every line handed over is written.
    pub fn finish(&mut self) -> Result<()> {
        self.writer.finish()
    }
}
