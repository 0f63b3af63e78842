//! The background writer: snapshots handed over by the run, coalesced, and written by a
//! thread (history rows, `checkpoint.h5.tmp`, fsync, rename).

use super::h5::{fsync_dir, fsync_file};
use super::history_file::{grown_capacity, HistoryFile};
use super::layout::{variable_data, write_checkpoint, Raw, PRONY_STATE};
use super::seal;
use super::snapshot::{Snapshot, SnapshotMemory, Term};
use super::states::States;
use super::template::Template;
use super::{Checkpoint, Identity, RunLog, StoredMemory, FILE_NAME, HISTORY_FILE_NAME};
use crate::history::{LoopState, Memory};
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

    /// Hands the checkpoint of the loop's `state` (at step n, before solving it) to the
    /// writer thread, whose memory follows through the [`Feed`] as `TimeLoop::gather_memory`
    /// makes it, one vector at a time (of a direct sum, the rows after the last checkpoint's).
    /// `active`: the contact/stick flags of the last solved step's rows; `frames`: the frames
    /// of the series written so far (all on disk). [`Feed::end`] returns the error of an
    /// earlier checkpoint that failed.
    pub fn write(
        &mut self,
        state: LoopState,
        log: &RunLog,
        active: &[bool],
        frames: Vec<FrameSum>,
    ) -> Feed {
        if let Err(e) = self.writing() {
            return Feed(Fed::Refused(e));
        }
        let h = state.history;
        let (memory, tx) = match &h.memory {
            Memory::None => (SnapshotMemory::None, None),
            Memory::Prony(terms) => {
                let (tx, states) = States::queue(h.u.len(), terms.len());
                let terms = (terms.iter())
                    .map(|t| Term {
                        a: t.a,
                        decay: t.decay,
                        group: t.group,
                    })
                    .collect();
                (SnapshotMemory::Prony { terms, states }, Some(tx))
            }
            Memory::Direct { .. } => {
                let (from, rows) = (h.n, Vec::new());
                (SnapshotMemory::Direct { from, rows }, None)
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
        let shared = self.shared.clone();
        Feed(match tx {
            // The writer may take the states as they come.
            Some(tx) => match post(&shared, snapshot) {
                Ok(()) => Fed::States(tx),
                Err(e) => Fed::Refused(e),
            },
            None => Fed::Rows(Box::new(snapshot), shared),
        })
    }

    /// Ok where the writer takes checkpoints: the error of an earlier one that failed.
    fn writing(&self) -> Result<()> {
        let mut mb = self.shared.mailbox.lock().expect("checkpoint mailbox");
        refused(&mut mb)
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

/// The error of an earlier checkpoint that failed, or that the writer stopped after one.
fn refused(mb: &mut Mailbox) -> Result<()> {
    match (mb.error.take(), mb.closed) {
        (Some(e), _) => Err(e),
        (None, true) => Err(Error::solve(
            "the checkpoint writer stopped after an earlier checkpoint failed",
        )),
        (None, false) => Ok(()),
    }
}

/// Hands `snapshot` to the writer thread, folded into one still waiting.
fn post(shared: &Shared, snapshot: Snapshot) -> Result<()> {
    let mut mb = shared.mailbox.lock().expect("checkpoint mailbox");
    refused(&mut mb)?;
    match &mut mb.pending {
        Some(older) => older.absorb(snapshot),
        None => mb.pending = Some(snapshot),
    }
    shared.changed.notify_all();
    Ok(())
}

/// A checkpoint being handed to the writer ([`Writer::write`]): its memory's vectors, each
/// of every dof, go in one at a time ([`Feed::send`]) as the run gathers them. The Prony
/// states go on to the writer thread at once, through a queue of a few (`States`), so that
/// the process never holds them all twice; a direct sum's rows, which the writer appends to
/// the history file before the checkpoint, go with the state at [`Feed::end`].
pub struct Feed(Fed);

enum Fed {
    States(std::sync::mpsc::SyncSender<Vec<f64>>),
    Rows(Box<Snapshot>, std::sync::Arc<Shared>),
    /// An earlier checkpoint failed: the vectors are let go, the error told at the end.
    Refused(Error),
}

impl Feed {
    /// The memory's next vector.
    pub fn send(&mut self, v: Vec<f64>) {
        match &mut self.0 {
            // A writer that failed has let the queue go; its error comes at the next
            // checkpoint.
            Fed::States(tx) => drop(tx.send(v)),
            Fed::Rows(snapshot, _) => {
                if let SnapshotMemory::Direct { rows, .. } = &mut snapshot.memory {
                    rows.push(v);
                }
            }
            Fed::Refused(_) => {}
        }
    }

    /// Every vector was sent: the checkpoint is the writer's. Returns the error of an
    /// earlier checkpoint that failed.
    pub fn end(self) -> Result<()> {
        match self.0 {
            Fed::States(_) => Ok(()),
            Fed::Rows(mut snapshot, shared) => {
                if let SnapshotMemory::Direct { from, rows } = &mut snapshot.memory {
                    // The past rows after the last checkpoint's, up to u_{n−1}.
                    assert!(
                        rows.len() <= snapshot.n
                            && rows.iter().all(|r| r.len() == snapshot.u.len()),
                        "the past rows after the last checkpoint's, each of every dof"
                    );
                    *from = snapshot.n - rows.len();
                }
                post(&shared, *snapshot)
            }
            Fed::Refused(e) => Err(e),
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

    /// Where a copy of the last checkpoint took the Prony states into `tmp` and then found
    /// the last file damaged (`Template::write`): `tmp` moved aside, the states to be read
    /// back from it; the path it was moved to.
    fn states_taken(
        &self,
        s: &Snapshot,
        data: &[(&str, Raw)],
        tmp: &Path,
    ) -> Result<Option<PathBuf>> {
        let (SnapshotMemory::Prony { states, .. }, Some(template)) = (&s.memory, &self.template)
        else {
            return Ok(None);
        };
        if states.untouched() {
            return Ok(None);
        }
        let at = data.iter().position(|(name, _)| *name == PRONY_STATE);
        let offset = at.map(|i| template.offset(i)).expect("the states' dataset");
        let taken = tmp.with_extension("states.tmp");
        std::fs::rename(tmp, &taken).map_err(|e| Error::io(tmp, e))?;
        let file = std::fs::File::open(&taken).map_err(|e| Error::io(&taken, e))?;
        states.reread(file, offset as u64);
        Ok(Some(taken))
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
            let taken = self.states_taken(s, &data, &tmp)?;
            let written = write_checkpoint(
                &tmp,
                &self.id,
                &self.row_node,
                s,
                self.steps,
                self.history.as_ref(),
            );
            if let Some(taken) = taken {
                let _ = std::fs::remove_file(taken);
            }
            written.map_err(|e| {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The Prony states reach the file as they come, through HDF5 at the first checkpoint
    /// and the last file's copy at the later ones; where that copy finds the last file
    /// damaged once it has taken them, they are read back from the copy and the checkpoint
    /// is written through HDF5 with the same values, nothing left beside it.
    #[test]
    fn states_taken_by_a_copy_of_a_damaged_last_file_reach_the_checkpoint_through_hdf5() {
        let dir = tempfile::tempdir().unwrap();
        let (width, terms) = (5, 3);
        let id = Identity {
            run_id: "states".into(),
            scene_text: String::new(),
            scene_path: String::new(),
            scene_path_absolute: String::new(),
            mesh_path: String::new(),
            mesh_fingerprint: 0,
            groups_fingerprint: 0,
            nodes: 3,
            triangles: 1,
            physics: Vec::new(),
            dof_of: (0..width as i64).chain([-1]).collect(),
        };
        let mut disk = Disk::new(dir.path(), id, 10, &Rows::new(&[], &[], 1));
        let state = |n: usize, i: usize| -> Vec<f64> {
            (0..width)
                .map(|j| (n * 100 + i * 10 + j) as f64 / 7.0)
                .collect()
        };
        let write = |disk: &mut Disk, n: usize| {
            let (tx, states) = States::queue(width, terms);
            (0..terms).for_each(|i| tx.send(state(n, i)).unwrap());
            let term = |i| Term {
                a: 1.0 + i as f64,
                decay: 0.5,
                group: 0,
            };
            let vector = vec![n as f64; width];
            let snapshot = Snapshot {
                n,
                k: 0.1,
                u: vector.clone(),
                u_sum: vector.clone(),
                u_comp: vector.clone(),
                w: vector,
                z: Vec::new(),
                z_before: Vec::new(),
                active: Vec::new(),
                memory: SnapshotMemory::Prony {
                    terms: (0..terms).map(term).collect(),
                    states,
                },
                log: RunLog {
                    iterations: vec![1; n],
                    ..RunLog::default()
                },
                frames: Vec::new(),
            };
            disk.write(&snapshot).unwrap();
            let cp = Checkpoint::read(&disk.dir.join(FILE_NAME)).unwrap();
            let StoredMemory::Prony { m, .. } = cp.memory else {
                panic!("a Prony checkpoint")
            };
            for (i, m) in m.iter().enumerate() {
                assert_eq!(m, &state(n, i), "step {n}, term {i}");
            }
        };
        write(&mut disk, 1);
        assert!(disk.template.is_some(), "the first file is the template");
        write(&mut disk, 2);
        let path = disk.dir.join(FILE_NAME);
        let mut bytes = std::fs::read(&path).unwrap();
        let at = bytes.len() - 1;
        bytes[at] ^= 1;
        std::fs::write(&path, bytes).unwrap();
        write(&mut disk, 3);
        let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(left.len(), 1, "checkpoint.h5 alone: {left:?}");
    }
}
