//! Checkpoints: everything a run needs to continue as if it had never stopped
//! (docs/restart.md), in `DIR/checkpoint.h5`, read back by `viscontact resume`.
//!
//! A checkpoint at step n is the state *before* step n is solved: steps 0..n−1 are done and
//! written, t_n = n k, and the history gives u_n and m_n exactly as the time loop holds them.
//! It saves
//!
//! - n, t_n and the step size k (the bits of k are kept: a resumed run never recomputes k);
//! - u_n with its Neumaier running sum and compensation (`history.rs`), bit for bit;
//! - the memory: each Prony term's (a_i, b_i, e^{−b_i k}, m^(i)_n), or for a general kernel
//!   the past displacements u_0..u_{n−1} (below);
//! - the velocity w_{n−1} and the multipliers z_{n−1} of the last solved step, and z_{n−2}
//!   of the step before (since format version 4): the step solver warm starts from z and
//!   its extrapolation 2z_{n−1} − z_{n−2} and recomputes its active set from them, so they
//!   are all it needs (the contact/stick flags are stored as well, for people);
//! - the per-step solver iteration counts and the running maxima of summary.json, so that
//!   the summary of a resumed run equals the uninterrupted one;
//! - the frames of the series written before step n: step, time, CRC-32 and length of each
//!   (`/series`, since format version 3), which resume verifies (`output/verify.rs`);
//! - the effective scene text (after `--set`), the scene's path, and fingerprints of the mesh
//!   (node coordinate bits + connectivity) and of its physical groups; a flattened copy of
//!   every physics key of the scene (`/physics`), to tell what differs.
//!
//! Every dataset carries `description` and `units` attributes (SI, as the scene's numbers
//! are meant: m, s, Pa); the root carries `format` = "viscontact checkpoint" and
//! `format_version`.
//!
//! # Crash safety
//!
//! `checkpoint.h5` is written whole to `checkpoint.h5.tmp`, fsync'ed, renamed over the old
//! one, and the directory fsync'ed: `kill -9` (or a failed write) at any moment leaves the
//! previous checkpoint intact.
//!
//! The past displacements of a general kernel grow by one row per step, so rewriting them in
//! every checkpoint would make checkpoint k cost O(k). They live instead in
//! `checkpoint_history.h5`, dataset `past_displacements` (capacity × free dofs, contiguous,
//! allocated at creation without fill), which is only ever appended to: a checkpoint writes
//! the rows new since the last one (positioned writes at their byte offsets, so no HDF5
//! metadata ever changes), fsyncs the file, and only then renames the new `checkpoint.h5`,
//! which records how many rows are valid (`/memory/history_rows` = n) and a running 64-bit
//! hash of them (`/memory/history_hash`). A torn append can only touch rows beyond the
//! recorded length, which resume ignores and overwrites. The capacity grows with the run by
//! powers of two (a new file, rows copied a chunk at a time, temp + rename;
//! `history_file.rs`), so the old
//! checkpoint stays valid against the new file. `checkpoint.h5` holds an HDF5 external link
//! `/memory/past_displacements` to it, so h5py opening the checkpoint finds the history there.
//!
//! # Integrity
//!
//! Both files begin with a 512-byte HDF5 user block (`seal.rs`) holding a CRC-32: of every
//! byte after it for `checkpoint.h5` (computed over the final bytes, also when a later
//! checkpoint is the template patched in place), of the header and the HDF5 metadata for the
//! history file, whose rows are covered by the running hash instead. Resume checks both
//! before libhdf5 parses anything and reads the history rows by offset, so a damaged file
//! is refused with exit 2 naming it, never parsed into a crash or a silent answer. Format
//! version 1 (no user block) cannot be verified and is refused.
//!
//! # Cost
//!
//! The run does not wait for the disk: [`Writer::write`] copies the state (O(dofs)) and a
//! background thread writes it. Checkpoints that fall due while the previous one is still
//! being written are coalesced (the newest state wins, history rows accumulate), so the
//! file on disk is always a complete, recent state and the run is never throttled by fsync.
//! The memory (the Prony states, 8 bytes a dof a term; a direct sum's rows since the last
//! checkpoint, 8 bytes a dof a step) is not copied whole: it goes to the writer a vector at
//! a time through a queue of 16 MiB ([`Feed`], `vectors.rs`), so the run waits for the
//! writer only where it is more than that, at most until the writer has taken the last
//! vector. The first checkpoint of a process goes through the HDF5 library; the later ones
//! copy the last file a chunk at a time with the variable datasets patched in place
//! (`Template`) instead of creating some fifty HDF5 objects. The end of a run (and
//! `--stop-after`) waits until the last checkpoint is on disk.

mod fingerprint;
pub(crate) mod h5;
mod history_file;
mod layout;
mod read;
mod resume;
mod seal;
mod snapshot;
mod template;
mod vectors;
mod writer;

pub use fingerprint::{groups_fingerprint, mesh_fingerprint, physics_signature, Hash64};
pub use writer::{Feed, Writer};

/// Recomputes the CRC-32 in the header of a checkpoint that was edited on purpose (with h5py,
/// say): resume refuses a checkpoint whose bytes changed in any other way.
pub fn reseal(path: &std::path::Path) -> crate::Result<()> {
    use std::io::Read;
    let mut head = Vec::new();
    let file = std::fs::File::open(path).map_err(|e| crate::Error::io(path, e))?;
    (file.take(seal::USERBLOCK as u64).read_to_end(&mut head))
        .map_err(|e| crate::Error::io(path, e))?;
    if !seal::looks_sealed(&head) {
        return Err(crate::Error::input(format!(
            "{}: not a checkpoint with a viscontact header",
            path.display()
        )));
    }
    seal::seal_checkpoint_file(path).map_err(|e| crate::Error::io(path, e))
}

use crate::fem::Discretization;
use crate::mesh::Mesh;
use crate::scene::Scene;
use std::path::PathBuf;

/// The root attribute `format` of every checkpoint.
pub const FORMAT: &str = "viscontact checkpoint";
/// The layout version written (root attribute `format_version`); files of a newer version
/// are refused.
pub const FORMAT_VERSION: u32 = 4;
/// Version 2 recorded no checksums of the series' frames (`/series`, version 3): it is still
/// resumed, with its series continued unverified.
pub const UNVERIFIED_VERSION: u32 = 2;
/// Versions before 4 recorded only the last step's multipliers, not those of the step
/// before (`/state/z_before`; read where such a file has it): they are still resumed, their
/// first step warm started from z alone, so they continue the run to the solver's
/// tolerance rather than bit for bit.
pub const Z_BEFORE_VERSION: u32 = 4;
/// The checkpoint's file name in a run directory.
pub const FILE_NAME: &str = "checkpoint.h5";
/// The append-only history file of a general (direct-sum) kernel, beside the checkpoint.
pub const HISTORY_FILE_NAME: &str = "checkpoint_history.h5";
pub(crate) const HISTORY_DATASET: &str = "past_displacements";

// ---------------------------------------------------------------------------------------
// What a run saves
// ---------------------------------------------------------------------------------------

/// The run-wide numbers of summary.json that depend on every step so far.
#[derive(Clone, Debug, PartialEq)]
pub struct RunLog {
    /// Step solver iterations of steps 0, 1, ….
    pub iterations: Vec<usize>,
    /// The largest n·w on Γ3,1 so far (−∞ before the first step or without contact rows).
    pub max_violation: f64,
    /// The largest relative KKT residual so far.
    pub max_kkt_residual: f64,
}

impl Default for RunLog {
    fn default() -> Self {
        RunLog {
            iterations: Vec::new(),
            max_violation: f64::NEG_INFINITY,
            max_kkt_residual: 0.0,
        }
    }
}

/// What identifies a run and its physics; constant while it runs.
#[derive(Clone, Debug)]
pub struct Identity {
    /// Unique per run (kept by resume): ties a history file to its checkpoints.
    pub run_id: String,
    pub scene_text: String,
    /// The scene's path as the run was given it (summary.json "scene").
    pub scene_path: String,
    /// The same, absolute: `mesh.file` is resolved against its directory on resume.
    pub scene_path_absolute: String,
    pub mesh_path: String,
    pub mesh_fingerprint: u64,
    pub groups_fingerprint: u64,
    pub nodes: usize,
    pub triangles: usize,
    pub physics: Vec<(String, String)>,
    /// Free dof index of node i's x and y velocity (2i, 2i+1), −1 on Γ1.
    pub dof_of: Vec<i64>,
}

impl Identity {
    /// The identity of a run of `scene`; `resumed` keeps the run id and the absolute scene
    /// path of the checkpoint a run continues.
    pub fn new(
        scene: &Scene,
        mesh: &Mesh,
        disc: &Discretization,
        resumed: Option<&Checkpoint>,
    ) -> Identity {
        let run_id = match resumed {
            Some(cp) => cp.id.run_id.clone(),
            None => new_run_id(),
        };
        let scene_path_absolute = std::fs::canonicalize(&scene.path)
            .map(|p| p.display().to_string())
            .ok()
            .or_else(|| resumed.map(|cp| cp.id.scene_path_absolute.clone()))
            .unwrap_or_else(|| scene.path.display().to_string());
        Identity {
            run_id,
            scene_text: scene.text.clone(),
            scene_path: scene.path.display().to_string(),
            scene_path_absolute,
            mesh_path: mesh.path.display().to_string(),
            mesh_fingerprint: mesh_fingerprint(mesh),
            groups_fingerprint: groups_fingerprint(mesh),
            nodes: mesh.nodes.len(),
            triangles: mesh.n_cells(),
            physics: physics_signature(&scene.text),
            dof_of: disc.free.signed().collect(),
        }
    }
}

fn new_run_id() -> String {
    let t = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos())
        .unwrap_or(0);
    format!("{t:x}-{:x}", std::process::id())
}

/// The memory as stored in a checkpoint.
#[derive(Clone, Debug)]
pub enum StoredMemory {
    None,
    /// The terms; their states m^(i)_n stay in the file until a resume reads each rank's
    /// part of them, a term at a time (`Checkpoint::saved`): no rank holds every term's
    /// whole state.
    Prony {
        a: Vec<f64>,
        decay: Vec<f64>,
        /// The memory group of each term (all 0 where the file has no `prony_group`).
        group: Vec<usize>,
        /// The dofs each state holds.
        width: usize,
    },
    /// Rows 0..rows of the history file and their running hash.
    Direct {
        file: String,
        rows: usize,
        hash: u64,
    },
}

/// A checkpoint read back.
#[derive(Clone, Debug)]
pub struct Checkpoint {
    pub path: PathBuf,
    pub version: u32,
    pub n: usize,
    pub time: f64,
    pub k: f64,
    pub id: Identity,
    /// The dofs of its vectors u_n, its compensated sum and w_n, which stay in the file
    /// until a resume reads each rank's part of them ([`Checkpoint::saved`]).
    pub n_dofs: usize,
    pub z: Vec<f64>,
    /// z_{n−2}; z itself for a checkpoint of format version < 4 (`Z_BEFORE_VERSION`).
    pub z_before: Vec<f64>,
    pub memory: StoredMemory,
    pub log: RunLog,
    /// The frames of steps < n the run wrote, with their checksums (`/series`); None for a
    /// checkpoint of format version 2.
    pub frames: Option<Vec<crate::output::FrameSum>>,
}
