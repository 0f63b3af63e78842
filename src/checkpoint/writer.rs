//! The background writer: snapshots handed over by the run, coalesced, and written by a
//! thread (history rows, `checkpoint.h5.tmp`, fsync, rename).

use super::h5::{fsync_dir, fsync_file};
use super::history_file::{grown_capacity, HistoryFile};
use super::layout::{variable_data, write_checkpoint, Raw};
use super::seal;
use super::snapshot::{Snapshot, SnapshotMemory};
use super::template::Template;
use super::{Checkpoint, Identity, RunLog, StoredMemory, FILE_NAME, HISTORY_FILE_NAME};
use crate::history::{LoopState, SavedMemory};
use crate::output::FrameSum;
use crate::solver::Rows;
use crate::{Error, Result};
use std::path::{Path, PathBuf};

/// What the background writer and the run share.
#[derive(Default)]
pub(super) struct Mailbox {
    /// The newest snapshot not yet taken by the writer.
    pending: Option<Snapshot>,
    /// The writer is writing a snapshot.
    busy: bool,
    /// No more snapshots will come.
    closed: bool,
    /// The first failure of the writer; reported to the run at its next checkpoint.
    error: Option<Error>,
}

pub(super) struct Shared {
    mailbox: std::sync::Mutex<Mailbox>,
    changed: std::sync::Condvar,
}

/// Writes the checkpoints of one run into its directory, on a background thread.
///
/// [`Writer::write`] copies the state (O(dofs) plus the history rows new since the last
/// checkpoint) and returns; a thread writes it (history rows, `checkpoint.h5.tmp`, fsync,
/// rename), so the time loop does not wait for the disk. When checkpoints fall due faster
/// than the disk takes them, a snapshot still waiting is replaced by the newer one (its
/// history rows are kept): the checkpoint on disk is always a complete state of the run,
/// at most one write behind. [`Writer::finish`] waits until the last one is on disk.
pub struct Writer {
    path: PathBuf,
    shared: std::sync::Arc<Shared>,
    thread: Option<std::thread::JoinHandle<()>>,
}

/// The writer thread's side: the files.
pub(super) struct Disk {
    dir: PathBuf,
    id: Identity,
    /// The run's number of steps.
    steps: usize,
    history: Option<HistoryFile>,
    /// Where a resume into another directory (or whose history file could not be opened
    /// to append to) finds the checkpoint's past rows, their count and hash, copied into
    /// this run's file at its first checkpoint.
    earlier: Option<(PathBuf, usize, u64)>,
    row_node: Vec<u64>,
    /// The length of the last checkpoint written through HDF5 and where its variable data
    /// lie; later checkpoints copy the last file and patch them (see [`Template`]).
    template: Option<Template>,
}

impl Disk {
    /// The disk side of a run of `steps` steps into `dir`, no history file yet.
    fn new(dir: &Path, id: Identity, steps: usize, rows: &Rows) -> Disk {
        Disk {
            dir: dir.to_path_buf(),
            id,
            steps,
            history: None,
            earlier: None,
            row_node: rows.rows.iter().map(|r| r.node as u64).collect(),
            template: None,
        }
    }
}

impl Writer {
    /// A writer for a run of `steps` steps into `dir` whose Γ3 has `rows`.
    pub fn new(dir: &Path, id: Identity, steps: usize, rows: &Rows) -> Writer {
        Writer::start(Disk::new(dir, id, steps, rows))
    }

    /// A writer that continues `cp` in `dir` for a run of `steps` steps, the checkpoint's
    /// past rows of a direct sum sent already. The history file is appended to in place when
    /// it is the checkpoint's own (grown when full); otherwise the first checkpoint writes a
    /// new one, its first rows copied from the checkpoint's a chunk at a time (once): no
    /// rank holds every past row whole (`TimeLoop::gather_memory` sends the later ones).
    pub fn resume(dir: &Path, id: Identity, steps: usize, rows: &Rows, cp: &Checkpoint) -> Writer {
        let mut disk = Disk::new(dir, id, steps, rows);
        if let StoredMemory::Direct { rows, hash, .. } = &cp.memory {
            let same_dir = match (std::fs::canonicalize(dir), cp.dir().canonicalize()) {
                (Ok(a), Ok(b)) => a == b,
                _ => false,
            };
            let path = dir.join(HISTORY_FILE_NAME);
            if same_dir {
                disk.history = HistoryFile::open(&path, &disk.id, cp.u.len(), *rows, *hash).ok();
            }
            if disk.history.is_none() {
                disk.earlier = Some((cp.dir().join(HISTORY_FILE_NAME), *rows, *hash));
            }
        }
        Writer::start(disk)
    }

    fn start(mut disk: Disk) -> Writer {
        let shared = std::sync::Arc::new(Shared {
            mailbox: std::sync::Mutex::new(Mailbox::default()),
            changed: std::sync::Condvar::new(),
        });
        let path = disk.dir.join(FILE_NAME);
        let theirs = shared.clone();
        let thread = std::thread::Builder::new()
            .name("checkpoint writer".into())
            .spawn(move || loop {
                let snapshot = {
                    let mut mb = theirs.mailbox.lock().expect("checkpoint mailbox");
                    loop {
                        if let Some(s) = mb.pending.take() {
                            mb.busy = true;
                            break Some(s);
                        }
                        if mb.closed {
                            break None;
                        }
                        mb = theirs.changed.wait(mb).expect("checkpoint mailbox");
                    }
                };
                let Some(snapshot) = snapshot else { return };
                let result = disk.write(&snapshot);
                let mut mb = theirs.mailbox.lock().expect("checkpoint mailbox");
                mb.busy = false;
                if let Err(e) = result {
                    mb.error.get_or_insert(e);
                    mb.closed = true;
                    mb.pending = None;
                }
                theirs.changed.notify_all();
            })
            .expect("a thread for the checkpoint writer");
        Writer {
            path,
            shared,
            thread: Some(thread),
        }
    }

    /// `DIR/checkpoint.h5`.
    pub fn path(&self) -> PathBuf {
        self.path.clone()
    }

    /// Hands the checkpoint of the loop's `state` (at step n, before solving it) to the writer
    /// thread, with its memory as `TimeLoop::gather_memory` made it (of a direct sum, the
    /// rows after the last checkpoint's). `active`: the contact/stick flags of the last solved step's rows; `frames`:
    /// the frames of the series written so far (all on disk). Returns the error of an earlier
    /// checkpoint that failed.
    pub fn write(
        &mut self,
        state: LoopState,
        memory: SavedMemory,
        log: &RunLog,
        active: &[bool],
        frames: Vec<FrameSum>,
    ) -> Result<()> {
        let h = state.history;
        let memory = match memory {
            SavedMemory::None => SnapshotMemory::None,
            SavedMemory::Prony(terms) => SnapshotMemory::Prony(terms),
            // The past rows after the last checkpoint's, up to u_{n−1}.
            SavedMemory::Direct(rows) => {
                assert!(
                    rows.len() <= h.n && rows.iter().all(|r| r.len() == h.u.len()),
                    "the past rows after the last checkpoint's, each of every dof"
                );
                SnapshotMemory::Direct {
                    from: h.n - rows.len(),
                    rows,
                }
            }
        };
        let snapshot = Snapshot {
            n: h.n,
            k: h.k,
            u: h.u.clone(),
            u_sum: h.u_sum.clone(),
            u_comp: h.u_comp.clone(),
            w: state.w.to_vec(),
            z: state.z.to_vec(),
            z_before: state.z_before.to_vec(),
            active: active.to_vec(),
            memory,
            log: log.clone(),
            frames,
        };
        let mut mb = self.shared.mailbox.lock().expect("checkpoint mailbox");
        if let Some(e) = mb.error.take() {
            return Err(e);
        }
        match &mut mb.pending {
            Some(older) => older.absorb(snapshot),
            None => mb.pending = Some(snapshot),
        }
        self.shared.changed.notify_all();
        Ok(())
    }

    /// Waits until every checkpoint handed over so far is on disk (the writer stays open);
    /// returns the first failure.
    pub fn flush(&self) -> Result<()> {
        let mut mb = self.shared.mailbox.lock().expect("checkpoint mailbox");
        while mb.pending.is_some() || mb.busy {
            mb = self.shared.changed.wait(mb).expect("checkpoint mailbox");
        }
        match mb.error.take() {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }

    /// Waits until every checkpoint handed over is on disk; returns the first failure.
    pub fn finish(mut self) -> Result<()> {
        self.close()
    }

    fn close(&mut self) -> Result<()> {
        {
            let mut mb = self.shared.mailbox.lock().expect("checkpoint mailbox");
            mb.closed = true;
            self.shared.changed.notify_all();
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        let mut mb = self.shared.mailbox.lock().expect("checkpoint mailbox");
        match mb.error.take() {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }
}

impl Drop for Writer {
    /// A run that fails still lets the checkpoint being written reach the disk.
    fn drop(&mut self) {
        let _ = self.close();
    }
}

impl Disk {
    /// This run's first history file, holding rows `..from` (those of the checkpoint a
    /// resume continues: [`Writer::resume`]) and `rows` after them.
    fn new_history(&self, from: usize, rows: &[Vec<f64>], n_free: usize) -> Result<HistoryFile> {
        let path = self.dir.join(HISTORY_FILE_NAME);
        let earlier = match &self.earlier {
            Some((earlier, n, hash)) if *n == from && from > 0 => {
                Some(HistoryFile::open(earlier, &self.id, n_free, *n, *hash)?)
            }
            _ if from == 0 => None,
            _ => {
                return Err(Error::solve(format!(
                    "{}: history rows from {from} have no earlier rows to follow (internal error)",
                    path.display()
                )))
            }
        };
        let capacity = grown_capacity(0, from + rows.len(), self.steps);
        let id = (self.id.run_id.as_str(), n_free);
        HistoryFile::create_after(
            &path,
            id,
            capacity,
            earlier.as_ref().map(|e| (e, from)),
            rows,
        )
    }

    /// First the new history rows (fsync'ed), then `checkpoint.h5.tmp`, fsync, rename, fsync
    /// of the directory.
    fn write(&mut self, s: &Snapshot) -> Result<()> {
        if let SnapshotMemory::Direct { from, rows } = &s.memory {
            match &mut self.history {
                Some(h) => h.append(*from, rows, &self.id.run_id, self.steps)?,
                None => self.history = Some(self.new_history(*from, rows, s.u.len())?),
            }
        }
        let path = self.dir.join(FILE_NAME);
        let tmp = self.dir.join(format!("{FILE_NAME}.tmp"));
        let mut data = variable_data(s, self.steps);
        if let Some(h) = &self.history {
            data.push((
                "memory/history_hash",
                Raw::Bytes(h.hash.0.to_le_bytes().to_vec()),
            ));
        }
        let fast = match &self.template {
            Some(t) if t.fits(&data) => t.write(&path, &tmp, &data),
            _ => Ok(false),
        };
        let fast = fast.map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            Error::io(&path, e)
        })?;
        if !fast {
            write_checkpoint(
                &tmp,
                &self.id,
                &self.row_node,
                s,
                self.steps,
                self.history.as_ref(),
            )
            .map_err(|e| {
                let _ = std::fs::remove_file(&tmp);
                Error::hdf5(&path, e)
            })?;
            seal::seal_checkpoint_file(&tmp).map_err(|e| {
                let _ = std::fs::remove_file(&tmp);
                Error::io(&path, e)
            })?;
            self.template = Template::capture(&tmp, &data);
        }
        fsync_file(&tmp)?;
        std::fs::rename(&tmp, &path).map_err(|e| Error::io(&path, e))?;
        fsync_dir(&self.dir);
        Ok(())
    }
}
