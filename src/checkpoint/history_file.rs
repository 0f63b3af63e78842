//! The append-only history file of a general kernel (`checkpoint_history.h5`): creation,
//! appends, growth, and reading back with every byte that resume uses checked.
//!
//! The rows live in one contiguous dataset of `capacity` rows allocated at creation (no
//! fill), so row j is the raw f64s at `rows_offset + j · row_bytes` and an append is a plain
//! positioned write into space that already exists: no HDF5 metadata changes after creation.
//! The file's user block (`seal.rs`) records the run id, `rows_offset`, the capacity and a
//! CRC-32 of every byte outside the rows block (the HDF5 metadata, fixed at creation); the
//! rows themselves are covered by the running hash the checkpoint records for its
//! `history_rows`. Resume therefore checks the whole file it relies on without letting
//! libhdf5 parse it, and reads the rows by their offsets.
//!
//! A run that needs more rows than the file holds gets a new file of twice the capacity (at
//! most the run's steps + 1), the rows copied, written through a temporary file and a rename:
//! the file grows with the run instead of being allocated for all N steps up front (N = 10^12
//! once asked for a 631 GB sparse file), and the copies cost O(1) per row amortized. The old
//! checkpoint stays valid against the new file (same rows, same hash, same run id).

use super::h5::{describe, fsync_dir, fsync_file, h5_create_sealed, str_attr};
use super::seal;
use super::vectors::{from_le, RowSource};
use super::{Hash64, Identity, HISTORY_DATASET, HISTORY_FILE_NAME};

/// The history file's layout version (unchanged since checkpoint format version 2).
const FORMAT_VERSION: u32 = 2;
use crate::{Error, Result};
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

/// First line of the history file's user block.
const MAGIC: &str = "viscontact checkpoint history";
/// Rows of a history file's first allocation (or the run's steps + 1, if fewer).
const FIRST_CAPACITY: usize = 64;
/// The most bytes of rows a write, a read or a grown copy holds at once: a copy of the
/// whole past had doubled the writer's memory at each growth (several GB on a large run).
const CHUNK_BYTES: usize = if cfg!(test) { 24 } else { 8 << 20 };

/// The append-only history file of this run's directory.
pub(super) struct HistoryFile {
    pub(super) path: PathBuf,
    pub(super) capacity: usize,
    /// Rows written and fsync'ed (rows past the last checkpoint's count may be among them).
    pub(super) rows: usize,
    /// Running hash of rows 0..rows.
    pub(super) hash: Hash64,
    /// Byte offset of row 0 and bytes per row.
    offset: u64,
    row_bytes: u64,
}

/// What a history file's user block says, checked.
struct Header {
    run_id: String,
    offset: u64,
    capacity: usize,
    row_bytes: u64,
}

/// The capacity for `needed` rows of a run of `steps` steps, growing from `old`: at least
/// doubled and a power of two (at least 64), so that growths are few however the
/// checkpoints fall, at most `steps` + 1 rows (all a run can need).
pub(super) fn grown_capacity(old: usize, needed: usize, steps: usize) -> usize {
    let doubled = (2 * old)
        .max(needed.next_power_of_two())
        .max(FIRST_CAPACITY);
    needed.max(doubled.min(steps.saturating_add(1)))
}

impl HistoryFile {
    /// Creates the file with room for `capacity` rows (temp + rename): its first rows
    /// copied from rows 0..n of `kept` (`Some((old, n))`: the file this one grows from, or
    /// a resumed run's earlier one) a chunk at a time, then `past`.
    pub(super) fn create_after(
        path: &Path,
        (run_id, n_free): (&str, usize),
        capacity: usize,
        kept: Option<(&HistoryFile, usize)>,
        past: &(impl RowSource + ?Sized),
    ) -> Result<HistoryFile> {
        let copied = kept.map_or(0, |(_, n)| n);
        let capacity = capacity.max(copied + past.count()).max(1);
        let tmp = path.with_file_name(format!("{HISTORY_FILE_NAME}.tmp"));
        let write = || -> hdf5_metno::Result<u64> {
            let f = h5_create_sealed(&tmp)?;
            str_attr(&f, "format", MAGIC)?;
            f.new_attr::<u32>()
                .shape(())
                .create("format_version")?
                .write_scalar(&FORMAT_VERSION)?;
            str_attr(&f, "run_id", run_id)?;
            let ds = f
                .new_dataset_builder()
                .alloc_time(Some(hdf5_metno::dataset::AllocTime::Early))
                .fill_time(hdf5_metno::dataset::FillTime::Never)
                .empty::<f64>()
                .shape([capacity, n_free])
                .create(HISTORY_DATASET)?;
            describe(
                &ds,
                "past displacements u_0, u_1, … (row j = u_j in free-dof numbering, see \
                 /mesh/dof_of of checkpoint.h5); rows 0..history_rows-1 of the checkpoint's \
                 /memory are valid, later rows are unused preallocated space",
                "m",
            )?;
            let offset = ds
                .offset()
                .ok_or("the history dataset has no file offset")?;
            f.close()?;
            Ok(offset)
        };
        let failed = |e: Error| {
            let _ = std::fs::remove_file(&tmp);
            e
        };
        let offset = write().map_err(|e| failed(Error::hdf5(path, e)))?;
        let mut file = HistoryFile {
            path: tmp.clone(),
            capacity,
            rows: 0,
            hash: Hash64::default(),
            offset,
            row_bytes: 8 * n_free as u64,
        };
        let mut fill = || -> Result<()> {
            if let Some((old, n)) = kept {
                for start in (0..n).step_by(old.rows_per_chunk()) {
                    file.push(&old.read_rows(start..n.min(start + old.rows_per_chunk()))?[..])?;
                }
                // All of its rows copied: the same hash, or the file changed since it was
                // checked (a resume's read, the last append).
                if n == old.rows && file.hash.0 != old.hash.0 {
                    return Err(Error::solve(format!(
                        "{}: rows 0..{n} hash to {:#018x} where {:#018x} was recorded: the \
                         file changed while the run read it; the run's last checkpoint is kept",
                        old.path.display(),
                        file.hash.0,
                        old.hash.0
                    )));
                }
            }
            file.push(past)?;
            file.seal(run_id)?;
            fsync_file(&tmp)
        };
        fill().map_err(failed)?;
        std::fs::rename(&tmp, path).map_err(|e| failed(Error::io(path, e)))?;
        if let Some(dir) = path.parent() {
            fsync_dir(dir);
        }
        file.path = path.to_path_buf();
        Ok(file)
    }

    /// Writes `rows` after the rows this file holds, and hashes them.
    fn push(&mut self, rows: &(impl RowSource + ?Sized)) -> Result<()> {
        let mut hash = self.hash;
        self.write_rows(self.rows, rows, |_, row| hash.f64s(row))?;
        self.hash = hash;
        self.rows += rows.count();
        Ok(())
    }

    /// The history file of a checkpoint in `dir`, whose rows 0..rows hash to `hash` (resume
    /// checked them), to be appended to.
    pub(super) fn open(
        path: &Path,
        id: &Identity,
        n_free: usize,
        rows: usize,
        hash: u64,
    ) -> Result<HistoryFile> {
        let h = Header::read(path, id, n_free, rows)?;
        Ok(HistoryFile {
            path: path.to_path_buf(),
            capacity: h.capacity,
            rows,
            hash: Hash64(hash),
            offset: h.offset,
            row_bytes: h.row_bytes,
        })
    }

    /// Writes rows `from..from + rows.len()` into a file of this capacity, then fsyncs it;
    /// past the capacity, a grown copy replaces the file (`run_id`, `steps` size it).
    pub(super) fn append(
        &mut self,
        from: usize,
        rows: &(impl RowSource + ?Sized),
        run_id: &str,
        steps: usize,
    ) -> Result<()> {
        if rows.count() == 0 {
            return Ok(());
        }
        let end = from + rows.count();
        if from > self.rows {
            return Err(Error::solve(format!(
                "{}: history rows from {from} leave a gap after row {} (internal error)",
                self.path.display(),
                self.rows,
            )));
        }
        if end > self.capacity {
            // Rows 0..from copied a chunk at a time: never every row in memory at once.
            let capacity = grown_capacity(self.capacity, end, steps);
            let sizes = (run_id, self.n_free());
            *self =
                HistoryFile::create_after(&self.path, sizes, capacity, Some((self, from)), rows)?;
            return Ok(());
        }
        // The hash covers rows 0..self.rows; rows before `self.rows` are not hashed again.
        let (mut hash, known) = (self.hash, self.rows - from);
        self.write_rows(from, rows, |i, row| {
            if i >= known {
                hash.f64s(row)
            }
        })?;
        fsync_file(&self.path)?;
        (self.hash, self.rows) = (hash, end);
        Ok(())
    }

    fn n_free(&self) -> usize {
        (self.row_bytes / 8) as usize
    }

    /// Rows a chunk of at most [`CHUNK_BYTES`] holds (at least one).
    fn rows_per_chunk(&self) -> usize {
        (CHUNK_BYTES / self.row_bytes.max(1) as usize).max(1)
    }

    /// Positioned writes of rows `from..` into the rows block, a chunk at a time, each row
    /// `i` of `rows` shown to `seen` as it passes.
    fn write_rows(
        &self,
        from: usize,
        rows: &(impl RowSource + ?Sized),
        mut seen: impl FnMut(usize, &[f64]),
    ) -> Result<()> {
        let io = |e| Error::io(&self.path, e);
        let f = (std::fs::OpenOptions::new().write(true))
            .open(&self.path)
            .map_err(io)?;
        let per = self.rows_per_chunk();
        let mut bytes = Vec::new();
        for start in (0..rows.count()).step_by(per) {
            bytes.clear();
            for i in start..rows.count().min(start + per) {
                rows.row(i, &mut |row| {
                    bytes.extend(row.iter().flat_map(|x| x.to_le_bytes()));
                    seen(i, row);
                })
                .map_err(io)?;
            }
            let at = self.offset + (from + start) as u64 * self.row_bytes;
            f.write_all_at(&bytes, at).map_err(io)?;
        }
        Ok(())
    }

    /// Rows `range`, read back by offset a chunk at a time.
    fn read_rows(&self, range: std::ops::Range<usize>) -> Result<Vec<Vec<f64>>> {
        let mut rows = Vec::with_capacity(range.len());
        self.each_row(range, |row| rows.push(row.to_vec()))?;
        Ok(rows)
    }

    /// Each of rows `range` in turn, read back by offset a chunk at a time.
    fn each_row(&self, range: std::ops::Range<usize>, mut f: impl FnMut(&[f64])) -> Result<()> {
        let row = self.row_bytes as usize;
        if row == 0 {
            range.for_each(|_| f(&[]));
            return Ok(());
        }
        let file = std::fs::File::open(&self.path).map_err(|e| Error::io(&self.path, e))?;
        let per = self.rows_per_chunk();
        let mut bytes = vec![0u8; per.min(range.len()) * row];
        let mut values = Vec::with_capacity(bytes.len() / 8);
        for start in range.clone().step_by(per) {
            let bytes = &mut bytes[..(range.end - start).min(per) * row];
            file.read_exact_at(bytes, self.offset + start as u64 * self.row_bytes)
                .map_err(|e| Error::io(&self.path, e))?;
            values.clear();
            from_le(bytes, &mut values);
            values.chunks(row / 8).for_each(&mut f);
        }
        Ok(())
    }

    /// Writes the user block: run id, layout and the CRC of every byte outside the rows.
    fn seal(&self, run_id: &str) -> Result<()> {
        let io = |e: std::io::Error| Error::io(&self.path, e);
        let f = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(&self.path)
            .map_err(io)?;
        let len = f.metadata().map_err(io)?.len();
        let end = self.offset + self.capacity as u64 * self.row_bytes;
        if self.offset < seal::USERBLOCK as u64 || end > len {
            return Err(Error::solve(format!(
                "{}: the rows block lies outside the file (internal error)",
                self.path.display()
            )));
        }
        let read = |from: u64, to: u64| -> Result<Vec<u8>> {
            let mut b = vec![0u8; (to - from) as usize];
            f.read_exact_at(&mut b, from).map_err(io)?;
            Ok(b)
        };
        let (before, after) = (read(seal::USERBLOCK as u64, self.offset)?, read(end, len)?);
        let fields = format!(
            "{MAGIC}\nrun_id {run_id}\nrows_offset {}\ncapacity {}\nrow_bytes {}\nlength \
             {len}\n",
            self.offset, self.capacity, self.row_bytes
        );
        f.write_all_at(&seal::block(&fields, &[&before, &after]), 0)
            .map_err(io)
    }
}

impl Header {
    /// Reads and checks the user block and every byte outside the rows block; refuses a file
    /// of another run, of other sizes, or damaged.
    fn read(path: &Path, id: &Identity, n_free: usize, rows: usize) -> Result<Header> {
        let io = |e: std::io::Error| refuse(path, format!("unreadable ({e})"));
        let damaged = |what: &str| refuse(path, format!("damaged: {what}"));
        let f = std::fs::File::open(path).map_err(io)?;
        let len = f.metadata().map_err(io)?.len();
        let read = |from: u64, to: u64| -> Result<Vec<u8>> {
            let mut b = vec![0u8; to.saturating_sub(from) as usize];
            f.read_exact_at(&mut b, from).map_err(io)?;
            Ok(b)
        };
        let block = read(0, (seal::USERBLOCK as u64).min(len))?;
        let (fields, crc) = seal::parse(&block, MAGIC)
            .ok_or_else(|| damaged("its 512-byte header is not a viscontact history header"))?;
        let num = |key: &str| -> Result<u64> {
            seal::field(fields, key)
                .and_then(|v| v.parse().ok())
                .ok_or_else(|| damaged(&format!("no {key} in its header")))
        };
        let h = Header {
            run_id: seal::field(fields, "run_id").unwrap_or("").to_string(),
            offset: num("rows_offset")?,
            capacity: num("capacity")? as usize,
            row_bytes: num("row_bytes")?,
        };
        let length = num("length")?;
        if length != len {
            return Err(damaged(&format!(
                "{len} bytes long, its header says {length} (truncated?)"
            )));
        }
        let end = h
            .row_bytes
            .checked_mul(h.capacity as u64)
            .and_then(|b| b.checked_add(h.offset))
            .filter(|&end| h.offset >= seal::USERBLOCK as u64 && end <= len)
            .ok_or_else(|| damaged("its rows block lies outside the file"))?;
        let (before, after) = (read(seal::USERBLOCK as u64, h.offset)?, read(end, len)?);
        if seal::crc(fields, &[&before, &after]) != crc {
            return Err(damaged(
                "its HDF5 metadata or header do not match their CRC-32 (bytes changed since \
                 viscontact wrote them)",
            ));
        }
        if h.run_id != id.run_id {
            return Err(refuse(
                path,
                format!(
                    "written by run {}, the checkpoint is of run {}; it belongs to another run",
                    h.run_id, id.run_id
                ),
            ));
        }
        if h.row_bytes != 8 * n_free as u64 || h.capacity < rows {
            return Err(refuse(
                path,
                format!(
                    "it holds {} rows of {} values, need {rows} rows of {n_free}",
                    h.capacity,
                    h.row_bytes / 8
                ),
            ));
        }
        Ok(h)
    }
}

fn refuse(path: &Path, why: String) -> Error {
    Error::input(format!(
        "{}: {why}; this history file does not hold the checkpoint's past displacements, so \
         the run cannot be resumed from this checkpoint: restore an intact copy of the run \
         directory or start the run again",
        path.display()
    ))
}

/// Rows 0..rows of a history file, checked: its header and metadata (CRC-32), its run id and
/// sizes, and the rows' running hash against the checkpoint's; each row whole, or its values
/// at the dofs `keep` alone (a rank of several: never every row whole in memory).
pub(super) fn read_history(
    path: &Path,
    (rows, hash): (usize, u64),
    n_free: usize,
    id: &Identity,
    keep: Option<&[usize]>,
) -> Result<Vec<Vec<f64>>> {
    if !path.exists() {
        return Err(refuse(path, "missing".into()));
    }
    let file = HistoryFile::open(path, id, n_free, rows, hash)?;
    let mut past = Vec::with_capacity(rows);
    let mut h = Hash64::default();
    file.each_row(0..rows, |row| {
        h.f64s(row);
        past.push(crate::history::at(keep, row));
    })?;
    if h.0 != hash {
        return Err(refuse(
            path,
            format!(
                "damaged: rows 0..{rows} hash to {:#018x}, the checkpoint recorded {hash:#018x}",
                h.0
            ),
        ));
    }
    Ok(past)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_grown_file_copies_its_rows_a_chunk_at_a_time() {
        // One value a row: a chunk holds 3 rows in tests (`CHUNK_BYTES`), so the copy and
        // the reads end in a part of a chunk.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(HISTORY_FILE_NAME);
        let rows: Vec<Vec<f64>> = (0..8).map(|j| vec![j as f64 + 0.25 - 1e-300]).collect();
        let mut file = HistoryFile::create_after(&path, ("run", 1), 4, None, &rows[..3]).unwrap();
        file.append(3, &rows[3..4], "run", 100).unwrap();
        assert_eq!((file.capacity, file.rows), (4, 4));
        // Row 2 sent again, as a checkpoint's rows can be, and the file grows.
        file.append(2, &rows[2..], "run", 100).unwrap();
        assert_eq!((file.capacity, file.rows), (64, 8));
        assert_eq!(file.read_rows(0..8).unwrap(), rows);
        assert_eq!(file.read_rows(4..7).unwrap(), rows[4..7]);
        let mut each = Vec::new();
        file.each_row(1..8, |row| each.push(row.to_vec())).unwrap();
        assert_eq!(each, rows[1..]);
        let mut hash = Hash64::default();
        rows.iter().for_each(|row| hash.f64s(row));
        assert_eq!(file.hash.0, hash.0);
        assert!(!dir.path().join(format!("{HISTORY_FILE_NAME}.tmp")).exists());
    }
}
