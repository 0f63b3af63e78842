//! A checkpoint's state in memory: copied out of the time loop by the run, folded with a newer
//! one while the writer thread is busy, laid out by `layout` and written by `writer`.

use super::vectors::Vectors;
use super::RunLog;
use crate::output::FrameSum;

/// The state saved at one checkpoint, copied out of the time loop (so that the run goes on
/// while a background thread writes it), but for the memory (the Prony states, a direct
/// sum's past rows), which reaches the writer a vector at a time as the run gathers it
/// (`Vectors`).
pub(super) struct Snapshot {
    pub(super) n: usize,
    pub(super) k: f64,
    pub(super) u: Vec<f64>,
    pub(super) u_sum: Vec<f64>,
    pub(super) u_comp: Vec<f64>,
    pub(super) w: Vec<f64>,
    pub(super) z: Vec<f64>,
    pub(super) z_before: Vec<f64>,
    pub(super) active: Vec<bool>,
    pub(super) memory: SnapshotMemory,
    pub(super) log: RunLog,
    /// The frames written before step n, with their checksums.
    pub(super) frames: Vec<FrameSum>,
}

pub(super) enum SnapshotMemory {
    None,
    /// The terms, and their states as the run sends them (`Vectors`).
    Prony {
        terms: Vec<Term>,
        states: Vectors,
    },
    /// The past displacements not yet sent to the writer, as the run sends them: rows
    /// `from..`, those of each checkpoint folded into this one after its own.
    Direct {
        from: usize,
        rows: Vec<Vectors>,
    },
}

/// A Prony term's weight, one-step decay and memory group (`history::PronyTerm` without
/// its state).
pub(super) struct Term {
    pub(super) a: f64,
    pub(super) decay: f64,
    pub(super) group: usize,
}

impl Snapshot {
    /// Folds a newer snapshot into this unwritten one: the newer state wins, history rows
    /// accumulate (the newer's after this one's, still to be taken in that order).
    pub(super) fn absorb(&mut self, mut newer: Snapshot) {
        if let (SnapshotMemory::Direct { from, rows }, SnapshotMemory::Direct { rows: more, .. }) =
            (&mut self.memory, &mut newer.memory)
        {
            rows.append(more);
            newer.memory = SnapshotMemory::Direct {
                from: *from,
                rows: std::mem::take(rows),
            };
        }
        *self = newer;
    }
}
