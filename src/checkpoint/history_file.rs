//! The append-only history file of a general kernel (`checkpoint_history.h5`): creation with
//! preallocated chunks, appends, and reading back with its hash checked.

use super::h5::{describe, fsync_dir, fsync_file, h5_file, h5err, str_attr, str_attr_of, OpenMode};
use super::{Hash64, Identity, FORMAT_VERSION, HISTORY_DATASET, HISTORY_FILE_NAME};
use crate::{Error, Result};
use hdf5_metno as hdf5;
use std::path::{Path, PathBuf};

/// The append-only history file of this run's directory.
pub(super) struct HistoryFile {
    pub(super) path: PathBuf,
    pub(super) capacity: usize,
    /// Rows written and fsync'ed (rows past the last checkpoint's count may be among them).
    pub(super) rows: usize,
    /// Running hash of rows 0..rows.
    pub(super) hash: Hash64,
}

impl HistoryFile {
    /// Creates the file with `capacity` preallocated rows holding `past` (temp + rename).
    pub(super) fn create(
        path: &Path,
        run_id: &str,
        n_free: usize,
        capacity: usize,
        past: &[Vec<f64>],
    ) -> Result<HistoryFile> {
        let capacity = capacity.max(past.len()).max(1);
        let tmp = path.with_file_name(format!("{HISTORY_FILE_NAME}.tmp"));
        let write = || -> hdf5::Result<()> {
            let f = h5_file(OpenMode::Create, &tmp)?;
            str_attr(&f, "format", "viscontact checkpoint history")?;
            f.new_attr::<u32>()
                .shape(())
                .create("format_version")?
                .write_scalar(&FORMAT_VERSION)?;
            str_attr(&f, "run_id", run_id)?;
            let ds = f
                .new_dataset_builder()
                .chunk((1, n_free.max(1)))
                .alloc_time(Some(hdf5::dataset::AllocTime::Early))
                .fill_time(hdf5::dataset::FillTime::Never)
                .empty::<f64>()
                .shape([(capacity, None), (n_free, Some(n_free))])
                .create(HISTORY_DATASET)?;
            describe(
                &ds,
                "past displacements u_0, u_1, … (row j = u_j in free-dof numbering, see \
                 /mesh/dof_of of checkpoint.h5); rows 0..history_rows-1 of the checkpoint's \
                 /memory are valid, later rows are unused preallocated space",
                "m",
            )?;
            for (j, row) in past.iter().enumerate() {
                ds.write_slice(&row[..], (j, ..))?;
            }
            Ok(())
        };
        write().map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            h5err(path, e)
        })?;
        fsync_file(&tmp)?;
        std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e))?;
        if let Some(dir) = path.parent() {
            fsync_dir(dir);
        }
        let mut hash = Hash64::default();
        for row in past {
            hash.f64s(row);
        }
        Ok(HistoryFile {
            path: path.to_path_buf(),
            capacity,
            rows: past.len(),
            hash,
        })
    }

    /// Writes rows `from..from + rows.len()` into their preallocated chunks and fsyncs.
    pub(super) fn append(&mut self, from: usize, rows: &[Vec<f64>]) -> Result<()> {
        if rows.is_empty() {
            return Ok(());
        }
        let end = from + rows.len();
        if from > self.rows || end > self.capacity {
            return Err(Error::solve(format!(
                "{}: history rows {from}..{end} do not fit the file ({} rows written, room \
                 for {}) (internal error)",
                self.path.display(),
                self.rows,
                self.capacity
            )));
        }
        let write = || -> hdf5::Result<()> {
            let f = h5_file(OpenMode::ReadWrite, &self.path)?;
            let ds = f.dataset(HISTORY_DATASET)?;
            for (j, row) in rows.iter().enumerate() {
                ds.write_slice(&row[..], (from + j, ..))?;
            }
            Ok(())
        };
        write().map_err(|e| h5err(&self.path, e))?;
        fsync_file(&self.path)?;
        // The hash covers rows 0..self.rows; rows before `self.rows` are not sent again.
        for row in &rows[self.rows - from..] {
            self.hash.f64s(row);
        }
        self.rows = end;
        Ok(())
    }
}

/// Rows 0..rows of a history file, checked against the checkpoint's run id and hash.
pub(super) fn read_history(
    path: &Path,
    rows: usize,
    hash: u64,
    n_free: usize,
    id: &Identity,
) -> Result<Vec<Vec<f64>>> {
    let shown = path.display();
    let refuse = |why: String| {
        Error::input(format!(
            "{shown}: {why}; this history file does not hold the checkpoint's past \
             displacements (it belongs to another run or was damaged), so the run cannot be \
             resumed from this checkpoint: start it again"
        ))
    };
    if !path.exists() {
        return Err(refuse("missing".into()));
    }
    let f =
        h5_file(OpenMode::Read, path).map_err(|e| refuse(format!("cannot open as HDF5 ({e})")))?;
    let run_id = str_attr_of(&f, "run_id").map_err(|e| refuse(format!("no run_id ({e})")))?;
    if run_id != id.run_id {
        return Err(refuse(format!(
            "written by run {run_id}, the checkpoint is of run {}",
            id.run_id
        )));
    }
    let ds = f
        .dataset(HISTORY_DATASET)
        .map_err(|e| refuse(format!("no dataset {HISTORY_DATASET} ({e})")))?;
    let shape = ds.shape();
    if shape.len() != 2 || shape[1] != n_free || shape[0] < rows {
        return Err(refuse(format!(
            "{HISTORY_DATASET} has shape {shape:?}, need at least [{rows}, {n_free}]"
        )));
    }
    let mut past = Vec::with_capacity(rows);
    let mut h = Hash64::default();
    for j in 0..rows {
        let row = ds
            .read_slice_1d::<f64, _>((j, ..))
            .map_err(|e| refuse(format!("row {j} unreadable ({e})")))?
            .to_vec();
        h.f64s(&row);
        past.push(row);
    }
    if h.0 != hash {
        return Err(refuse(format!(
            "rows 0..{rows} hash to {:#018x}, the checkpoint recorded {hash:#018x}",
            h.0
        )));
    }
    Ok(past)
}
