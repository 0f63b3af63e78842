//! The memory of a checkpoint as it reaches the writer: one vector of every dof at a time
//! (a Prony term's state, a direct sum's past row), from the run through a bounded queue, so
//! that the process that writes checkpoints holds a few of them at once, never all (the
//! states of 40 terms are 40 vectors of every dof, and a direct sum's rows since the last
//! checkpoint one a step, which rank 0 of several gathers from the ranks' parts:
//! `TimeLoop::gather_memory`).
//!
//! The run sends each vector as it is gathered; the writer takes them in the file's order:
//! a direct sum's rows into the history file (`HistoryFile::append`, through [`RowSource`]),
//! the Prony states into the rows of `/memory/prony_state`, where a later checkpoint's copy
//! of the last file reaches them (`Template::write`) or the HDF5 library writes them row by
//! row. Where the copy found the last file damaged once it had taken the states, they are
//! read back from the copy (`Disk::write`). Small vectors fit the queue whole, and the run
//! never waits for the writer; larger ones wait for it a vector at a time.

use crate::history::queue_len;
use std::cell::RefCell;
use std::fs::File;
use std::io;
use std::os::unix::fs::FileExt;
use std::sync::mpsc::{sync_channel, Receiver, SyncSender};

/// `count` vectors of `width` values each, taken in order.
pub(super) struct Vectors {
    width: usize,
    count: usize,
    reading: RefCell<Reading>,
}

struct Reading {
    source: Source,
    /// How many vectors were taken; `row` is the last of them.
    taken: usize,
    row: Vec<f64>,
    /// The CRC-32 of the bytes of the vectors taken from the queue (`Template::capture`
    /// compares it with the file's), None once any was read back from a file.
    crc: Option<crc32fast::Hasher>,
}

enum Source {
    Queue(Receiver<Vec<f64>>),
    /// A file holding the vectors' bytes from `offset` on.
    File(File, u64),
}

impl Vectors {
    /// The vectors and the end of their queue, which the run sends them into.
    pub(super) fn queue(width: usize, count: usize) -> (SyncSender<Vec<f64>>, Vectors) {
        let (tx, rx) = sync_channel(queue_len(width));
        let reading = Reading {
            source: Source::Queue(rx),
            taken: 0,
            row: Vec::new(),
            crc: Some(crc32fast::Hasher::new()),
        };
        let states = Vectors {
            width,
            count,
            reading: RefCell::new(reading),
        };
        (tx, states)
    }

    pub(super) fn count(&self) -> usize {
        self.count
    }

    pub(super) fn width(&self) -> usize {
        self.width
    }

    /// Their bytes' count.
    pub(super) fn len(&self) -> usize {
        8 * self.width * self.count
    }

    /// Whether none was taken yet.
    pub(super) fn untouched(&self) -> bool {
        self.reading.borrow().taken == 0
    }

    /// The CRC-32 of their bytes, where every one came from the queue.
    pub(super) fn crc(&self) -> Option<u32> {
        let reading = self.reading.borrow();
        let whole = reading.taken == self.count;
        reading.crc.clone().filter(|_| whole).map(|c| c.finalize())
    }

    /// Takes them again from the start, from `file`, which holds their bytes from `offset`.
    pub(super) fn reread(&self, file: File, offset: u64) {
        let mut reading = self.reading.borrow_mut();
        reading.source = Source::File(file, offset);
        reading.taken = 0;
        reading.crc = None;
    }

    /// `f` of vector `i`, taken in order: `i` is the last vector taken or a later one.
    pub(super) fn with_row<R>(&self, i: usize, f: impl FnOnce(&[f64]) -> R) -> io::Result<R> {
        let mut reading = self.reading.borrow_mut();
        if i + 1 < reading.taken || i >= self.count {
            return Err(io::Error::other(format!(
                "vector {i} of a checkpoint's memory asked out of order (internal error)"
            )));
        }
        while reading.taken <= i {
            reading.next(self.width)?;
        }
        Ok(f(&reading.row))
    }

    /// Their bytes from byte `from` on into `out`, as many as it holds (in order, as
    /// [`Vectors::with_row`]).
    pub(super) fn write_range(&self, from: usize, out: &mut [u8]) -> io::Result<()> {
        let row_bytes = 8 * self.width;
        let mut done = 0;
        while done < out.len() {
            let at = from + done;
            let (i, within) = (at / row_bytes, at % row_bytes);
            let n = (row_bytes - within).min(out.len() - done);
            self.with_row(i, |row| le_range(row, within, &mut out[done..done + n]))?;
            done += n;
        }
        Ok(())
    }
}

impl Reading {
    /// Takes the next vector.
    fn next(&mut self, width: usize) -> io::Result<()> {
        match &self.source {
            Source::Queue(rx) => {
                self.row = rx.recv().map_err(|_| {
                    io::Error::other("the run stopped sending the memory of a checkpoint")
                })?;
                if self.row.len() != width {
                    return Err(io::Error::other(format!(
                        "a vector of {} values in a checkpoint's memory of {width} a vector \
                         (internal error)",
                        self.row.len()
                    )));
                }
                if let Some(crc) = &mut self.crc {
                    if cfg!(target_endian = "little") {
                        crc.update(bytemuck::cast_slice(&self.row));
                    } else {
                        self.row.iter().for_each(|x| crc.update(&x.to_le_bytes()));
                    }
                }
            }
            Source::File(file, offset) => {
                let mut bytes = vec![0u8; 8 * width];
                file.read_exact_at(&mut bytes, offset + (self.taken * 8 * width) as u64)?;
                self.row.clear();
                from_le(&bytes, &mut self.row);
            }
        }
        self.taken += 1;
        Ok(())
    }
}

/// Rows taken in order, each once: a direct sum's past rows as the history file takes them
/// (`HistoryFile::append`), from the run's queue ([`Vectors`]) or from memory.
pub(super) trait RowSource {
    /// How many.
    fn count(&self) -> usize;
    /// `f` of row `i`, asked in increasing order.
    fn row(&self, i: usize, f: &mut dyn FnMut(&[f64])) -> io::Result<()>;
}

impl RowSource for [Vec<f64>] {
    fn count(&self) -> usize {
        self.len()
    }

    fn row(&self, i: usize, f: &mut dyn FnMut(&[f64])) -> io::Result<()> {
        f(&self[i]);
        Ok(())
    }
}

impl RowSource for Vectors {
    fn count(&self) -> usize {
        self.count
    }

    fn row(&self, i: usize, f: &mut dyn FnMut(&[f64])) -> io::Result<()> {
        self.with_row(i, |row| f(row))
    }
}

/// The little-endian bytes of `v` from byte `from` on into `out`, as many as it holds.
pub(super) fn le_range(v: &[f64], from: usize, out: &mut [u8]) {
    if cfg!(target_endian = "little") {
        let bytes: &[u8] = bytemuck::cast_slice(v);
        return out.copy_from_slice(&bytes[from..from + out.len()]);
    }
    for (i, b) in out.iter_mut().enumerate() {
        let at = from + i;
        *b = v[at / 8].to_le_bytes()[at % 8];
    }
}

/// The values whose little-endian bytes are `bytes`, appended to `out` (`le_range`'s
/// inverse).
pub(super) fn from_le(bytes: &[u8], out: &mut Vec<f64>) {
    let value = |b: &[u8]| f64::from_le_bytes(b.try_into().expect("8 bytes"));
    out.extend(bytes.chunks_exact(8).map(value));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::history::{held_bytes, QUEUE_BYTES};

    /// The queue holds what `held_bytes` counts less the two in hand: every state where
    /// they are small, one where a state alone is more than the queue's bytes.
    #[test]
    fn the_queue_holds_what_the_estimate_counts() {
        for (width, count) in [(10, 7), (QUEUE_BYTES / 8 / 3, 40), (QUEUE_BYTES, 40)] {
            let (tx, _states) = Vectors::queue(width, count);
            let queued = (0..count)
                .take_while(|_| tx.try_send(Vec::new()).is_ok())
                .count();
            let held = held_bytes(width, count) / (8 * width) as f64;
            assert_eq!(held, (queued + 2).min(count) as f64, "width {width}");
            assert!(queued >= 1);
        }
        assert_eq!(held_bytes(QUEUE_BYTES, 40), 3.0 * 8.0 * QUEUE_BYTES as f64);
    }
}
