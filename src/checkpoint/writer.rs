//! The background writer: snapshots handed over by the run, coalesced, and written by a
//! thread (history rows, `checkpoint.h5.tmp`, fsync, rename).

use super::h5::{fsync_dir, fsync_file};
use super::history_file::{grown_capacity, HistoryFile};
use super::layout::{variable_data, write_checkpoint, Raw, PRONY_STATE};
use super::seal;
use super::snapshot::{Snapshot, SnapshotMemory, Term};
use super::template::Template;
use super::vectors::Vectors;
use super::{Checkpoint, Identity, RunLog, StoredMemory, FILE_NAME, HISTORY_FILE_NAME};
use crate::history::{queue_len, LoopState, Memory};
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
/// [`Writer::write`] copies the state (O(dofs); the memory follows through its [`Feed`] a
/// vector at a time) and returns; a thread writes it (history rows, `checkpoint.h5.tmp`,
/// fsync, rename), so the time loop does not wait for the disk. When checkpoints fall due faster
/// than the disk takes them, a snapshot still waiting is replaced by the newer one (its
/// history rows are kept): the checkpoint on disk is always a complete state of the run,
/// at most one write behind. [`Writer::finish`] waits until the last one is on disk.
pub struct Writer {
    path: PathBuf,
    /// How many of a direct sum's past rows the checkpoints handed over hold (those of a
    /// resumed checkpoint among them): a checkpoint at step n is sent the rest, up to n.
    past_sent: usize,
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
        Writer::start(Disk::new(dir, id, steps, rows), 0)
    }

    /// A writer that continues `cp` in `dir` for a run of `steps` steps, the checkpoint's
    /// past rows of a direct sum sent already. The history file is appended to in place when
    /// it is the checkpoint's own (grown when full); otherwise the first checkpoint writes a
    /// new one, its first rows copied from the checkpoint's a chunk at a time (once): no
    /// rank holds every past row whole (`TimeLoop::gather_memory` sends the later ones).
    pub fn resume(dir: &Path, id: Identity, steps: usize, rows: &Rows, cp: &Checkpoint) -> Writer {
        let mut disk = Disk::new(dir, id, steps, rows);
        let mut past_sent = 0;
        if let StoredMemory::Direct { rows, hash, .. } = &cp.memory {
            past_sent = *rows;
            let same_dir = match (std::fs::canonicalize(dir), cp.dir().canonicalize()) {
                (Ok(a), Ok(b)) => a == b,
                _ => false,
            };
            let path = dir.join(HISTORY_FILE_NAME);
            if same_dir {
                disk.history = HistoryFile::open(&path, &disk.id, cp.n_dofs, *rows, *hash).ok();
            }
            if disk.history.is_none() {
                disk.earlier = Some((cp.dir().join(HISTORY_FILE_NAME), *rows, *hash));
            }
        }
        Writer::start(disk, past_sent)
    }

    fn start(mut disk: Disk, past_sent: usize) -> Writer {
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
            past_sent,
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
    /// makes it, one vector at a time (of a direct sum, the rows after the last checkpoint's,
    /// up to u_{n−1}).
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
        let (memory, queue) = match &h.memory {
            Memory::None => (SnapshotMemory::None, None),
            Memory::Prony(terms) => {
                let (tx, states) = Vectors::queue(state.u.len(), terms.len());
                let terms = (terms.iter())
                    .map(|t| Term {
                        a: t.a,
                        decay: t.decay,
                        group: t.group,
                    })
                    .collect();
                let count = states.count();
                (SnapshotMemory::Prony { terms, states }, Some((tx, count)))
            }
            Memory::Direct { .. } => {
                let from = std::mem::replace(&mut self.past_sent, h.n);
                let count = h.n.checked_sub(from).expect("no past row sent twice");
                let (tx, rows) = Vectors::queue(state.u.len(), count);
                let rows = vec![rows];
                (SnapshotMemory::Direct { from, rows }, Some((tx, count)))
            }
        };
        let whole = (queue.as_ref()).is_none_or(|(_, count)| *count <= queue_len(state.u.len()));
        let snapshot = Snapshot {
            n: h.n,
            k: h.k,
            u: state.u,
            u_sum: state.u_sum,
            u_comp: state.u_comp,
            w: state.w,
            z: state.z.to_vec(),
            z_before: state.z_before.to_vec(),
            active: active.to_vec(),
            memory,
            log: log.clone(),
            frames,
        };
        // Memory that the queue holds whole goes to the writer with the state once it is all
        // sent, so the writer is woken once (docs/restart.md, "Checkpoint cost"); more, the
        // writer takes as it comes, the run waiting for it.
        if whole {
            let at_end = Some((Box::new(snapshot), self.shared.clone()));
            return Feed(Fed::Queue { queue, at_end });
        }
        Feed(match post(&self.shared, snapshot) {
            Ok(()) => Fed::Queue {
                queue,
                at_end: None,
            },
            Err(e) => Fed::Refused(e),
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
/// of every dof (the Prony states, or a direct sum's past rows), go in one at a time
/// ([`Feed::send`]) as the run gathers them, on to the writer thread at once through a
/// queue of a few (`Vectors`), so that the process never holds them all twice.
pub struct Feed(Fed);

enum Fed {
    Queue {
        /// The memory's queue and how many vectors are still to come (None: no memory).
        queue: Option<(std::sync::mpsc::SyncSender<Vec<f64>>, usize)>,
        /// The snapshot, where it goes to the writer once every vector is sent.
        at_end: Option<(Box<Snapshot>, std::sync::Arc<Shared>)>,
    },
    /// An earlier checkpoint failed: the vectors are let go, the error told at the end.
    Refused(Error),
}

impl Feed {
    /// The memory's next vector.
    pub fn send(&mut self, v: Vec<f64>) {
        if let Fed::Queue {
            queue: Some((tx, left)),
            ..
        } = &mut self.0
        {
            *left = left
                .checked_sub(1)
                .expect("no more vectors than the memory holds");
            // A writer that failed has let the queue go; its error comes at the next
            // checkpoint.
            drop(tx.send(v));
        }
    }

    /// Every vector was sent: the checkpoint is the writer's. Returns the error of an
    /// earlier checkpoint that failed.
    pub fn end(self) -> Result<()> {
        match self.0 {
            Fed::Queue { queue, at_end } => {
                let left = queue.map_or(0, |(_, left)| left);
                assert_eq!(left, 0, "every vector of the memory sent");
                match at_end {
                    Some((snapshot, shared)) => post(&shared, *snapshot),
                    None => Ok(()),
                }
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
    fn new_history(&self, from: usize, rows: &Vectors, n_free: usize) -> Result<HistoryFile> {
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
        let capacity = grown_capacity(0, from + rows.count(), self.steps);
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
            let mut from = *from;
            for rows in rows {
                match &mut self.history {
                    Some(h) => h.append(from, rows, &self.id.run_id, self.steps)?,
                    None => self.history = Some(self.new_history(from, rows, s.u.len())?),
                }
                from += rows.count();
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
    use super::super::history_file::read_history;
    use super::*;
    use crate::history::{HeldAt, History, QUEUE_BYTES};

    /// A run's identity for checkpoints of `width` free dofs in 2D (and one or two held).
    fn identity(run_id: &str, width: usize) -> Identity {
        let held = [-1; 2][width % 2..].iter().copied();
        Identity {
            run_id: run_id.into(),
            scene_text: String::new(),
            scene_path: String::new(),
            scene_path_absolute: String::new(),
            mesh_path: String::new(),
            mesh_fingerprint: 0,
            groups_fingerprint: 0,
            nodes: width / 2 + 1,
            triangles: 1,
            physics: Vec::new(),
            dof_of: (0..width as i64).chain(held).collect(),
        }
    }

    /// The checkpoint of step n of `width` dofs, each vector of the state n.
    fn snapshot(n: usize, width: usize, memory: SnapshotMemory) -> Snapshot {
        let vector = |c: usize| vector_of(n, c, width);
        Snapshot {
            n,
            k: 0.1,
            u: vector(0),
            u_sum: vector(1),
            u_comp: vector(2),
            w: vector(3),
            z: Vec::new(),
            z_before: Vec::new(),
            active: Vec::new(),
            memory,
            log: RunLog {
                iterations: vec![1; n],
                ..RunLog::default()
            },
            frames: Vec::new(),
        }
    }

    /// Vector `c` (u_n, its sum, its compensation, w_n) of [`snapshot`]'s step `n`.
    fn vector_of(n: usize, c: usize, width: usize) -> Vec<f64> {
        (0..width)
            .map(|j| (n * 1000 + c * 100 + j) as f64)
            .collect()
    }

    /// The Prony states reach the file as they come, through HDF5 at the first checkpoint
    /// and the last file's copy at the later ones; where that copy finds the last file
    /// damaged once it has taken them, they are read back from the copy and the checkpoint
    /// is written through HDF5 with the same values, nothing left beside it.
    #[test]
    fn states_taken_by_a_copy_of_a_damaged_last_file_reach_the_checkpoint_through_hdf5() {
        let dir = tempfile::tempdir().unwrap();
        let (width, terms) = (5, 3);
        let id = identity("states", width);
        let mut disk = Disk::new(dir.path(), id, 10, &Rows::new(&[], &[], 1));
        let state = |n: usize, i: usize| -> Vec<f64> {
            (0..width)
                .map(|j| (n * 100 + i * 10 + j) as f64 / 7.0)
                .collect()
        };
        let write = |disk: &mut Disk, n: usize| {
            let (tx, states) = Vectors::queue(width, terms);
            (0..terms).for_each(|i| tx.send(state(n, i)).unwrap());
            let term = |i| Term {
                a: 1.0 + i as f64,
                decay: 0.5,
                group: 0,
            };
            let terms = (0..terms).map(term).collect();
            let snapshot = snapshot(n, width, SnapshotMemory::Prony { terms, states });
            disk.write(&snapshot).unwrap();
            let cp = Checkpoint::read(&disk.dir.join(FILE_NAME)).unwrap();
            assert!(
                matches!(cp.memory, StoredMemory::Prony { .. }),
                "a Prony checkpoint"
            );
            let m = cp.prony_states_at(None).unwrap();
            for (i, m) in m.iter().enumerate() {
                assert_eq!(m, &state(n, i), "step {n}, term {i}");
            }
            // A resume's part of them: at some dofs alone, read a term at a time, and u_n
            // and w_n at others.
            let mut cp = cp;
            let held = HeldAt {
                u: Some(&[0, 4]),
                memory: Some(&[1, 3]),
                w: Some(&[2]),
            };
            let saved = cp.saved(width, 0, held).unwrap();
            let h = &saved.history;
            for (c, v) in [&h.u, &h.u_sum, &h.u_comp].into_iter().enumerate() {
                let whole = vector_of(n, c, width);
                assert_eq!(v, &[whole[0], whole[4]], "step {n}, vector {c}");
            }
            assert_eq!(saved.w, [vector_of(n, 3, width)[2]], "step {n}: w_n");
            let crate::history::SavedMemory::Prony(part) = saved.history.memory else {
                panic!("a Prony memory")
            };
            assert_eq!(part.len(), m.len());
            for (i, t) in part.iter().enumerate() {
                let whole = state(n, i);
                assert_eq!(t.m, [whole[1], whole[3]], "step {n}, term {i}");
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

    /// Past row j of `width` values.
    fn past_row(width: usize, j: usize) -> Vec<f64> {
        (0..width).map(|i| (j * width + i) as f64 / 3.0).collect()
    }

    /// The checkpoint in `dir` holds `n` past rows, and its history file rows 0..n of
    /// [`past_row`], checked against its hash.
    fn assert_past_rows(dir: &Path, id: &Identity, n: usize) {
        let cp = Checkpoint::read(&dir.join(FILE_NAME)).unwrap();
        let StoredMemory::Direct { rows, hash, .. } = cp.memory else {
            panic!("a direct sum's checkpoint")
        };
        assert_eq!(rows, n);
        let width = id.dof_of.iter().filter(|&&d| d >= 0).count();
        let file = dir.join(HISTORY_FILE_NAME);
        let past = read_history(&file, (rows, hash), width, id, None).unwrap();
        for (j, row) in past.iter().enumerate() {
            assert!(row == &past_row(width, j), "row {j}");
        }
    }

    /// A direct sum's past rows reach the history file as the run sends them, more of them
    /// than the queue holds (the run waits for the writer), those of a checkpoint still
    /// waiting when a newer one came (`Snapshot::absorb`) first: the file holds every row
    /// in order, and the checkpoint their count and hash.
    #[test]
    fn past_rows_stream_into_the_history_file_in_order_after_a_folded_checkpoints() {
        let dir = tempfile::tempdir().unwrap();
        // Rows of half the queue's bytes: two wait in it, the others wait for the writer.
        let width = QUEUE_BYTES / 16;
        let id = || identity("rows", width);
        let mut disk = Disk::new(dir.path(), id(), 10, &Rows::new(&[], &[], 1));
        let direct = |from, rows| SnapshotMemory::Direct {
            from,
            rows: vec![rows],
        };
        // The checkpoint of step 2, its two rows sent, waits for the writer when step 6's
        // comes, whose rows the run sends as the writer takes them.
        let (tx, rows) = Vectors::queue(width, 2);
        (0..2).for_each(|j| tx.send(past_row(width, j)).unwrap());
        let mut waiting = snapshot(2, width, direct(0, rows));
        let (tx, rows) = Vectors::queue(width, 4);
        waiting.absorb(snapshot(6, width, direct(2, rows)));
        let run = std::thread::spawn(move || {
            (2..6).for_each(|j| tx.send(past_row(width, j)).unwrap());
        });
        disk.write(&waiting).unwrap();
        run.join().unwrap();
        assert_past_rows(dir.path(), &id(), 6);
    }

    /// Through the writer of a run: checkpoints whose new rows fill the queue and more
    /// (streamed as the writer takes them) and one whose row fits it (sent with the state
    /// at the end) leave the history file holding every row in order; the writer counts the
    /// rows it was sent, so each checkpoint sends those after the last one's alone.
    #[test]
    fn a_runs_checkpoints_send_each_past_row_once_streamed_or_whole() {
        let dir = tempfile::tempdir().unwrap();
        let width = QUEUE_BYTES / 16;
        let id = || identity("run", width);
        let mut writer = Writer::new(dir.path(), id(), 10, &Rows::new(&[], &[], 1));
        let mut history = History {
            k: 0.1,
            n: 0,
            u: vec![0.0; width],
            u_comp: vec![0.0; width],
            u_sum: vec![0.0; width],
            memory: Memory::Direct {
                r_lag: Vec::new(),
                past: Vec::new(),
            },
            holds: crate::history::Holds::Every,
        };
        let mut sent = 0;
        for n in [3, 4, 7] {
            while history.n < n {
                if let Memory::Direct { past, .. } = &mut history.memory {
                    past.push(past_row(width, history.n));
                }
                history.n += 1;
            }
            let state = LoopState {
                history: &history,
                u: history.u.clone(),
                u_sum: history.u_sum.clone(),
                u_comp: history.u_comp.clone(),
                w: history.u.clone(),
                z: &[],
                z_before: &[],
            };
            let log = RunLog {
                iterations: vec![1; n],
                ..RunLog::default()
            };
            let mut feed = writer.write(state, &log, &[], Vec::new());
            (sent..n).for_each(|j| feed.send(past_row(width, j)));
            feed.end().unwrap();
            sent = n;
            writer.flush().unwrap();
        }
        writer.finish().unwrap();
        assert_past_rows(dir.path(), &id(), 7);
    }
}
