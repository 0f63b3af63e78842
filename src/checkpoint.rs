//! Checkpoints: everything a run needs to continue as if it had never stopped (DESIGN.md
//! "Checkpoint (HDF5)"), in `DIR/checkpoint.h5`, read back by `viscontact resume`.
//!
//! A checkpoint at step n is the state *before* step n is solved: steps 0..n−1 are done and
//! written, t_n = n k, and the history gives u_n and m_n exactly as the time loop holds them.
//! It saves
//!
//! - n, t_n and the step size k (the bits of k are kept: a resumed run never recomputes k);
//! - u_n with its Neumaier running sum and compensation (`history.rs`), bit for bit;
//! - the memory: each Prony term's (a_i, b_i, e^{−b_i k}, m^(i)_n), or for a general kernel
//!   the past displacements u_0..u_{n−1} (below);
//! - the velocity w_{n−1} and the multipliers z_{n−1} of the last solved step: the step
//!   solver warm starts from z and recomputes its active set from it, so z is all it needs
//!   (the contact/stick flags are stored as well, for people);
//! - the per-step solver iteration counts and the running maxima of summary.json, so that
//!   the summary of a resumed run equals the uninterrupted one;
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
//! `checkpoint_history.h5`, dataset `past_displacements` (rows × free dofs, chunked one row
//! per chunk, maxshape unlimited in rows), which is only ever appended to: a checkpoint
//! writes the rows new since the last one, fsyncs the file, and only then renames the new
//! `checkpoint.h5`, which records how many rows are valid (`/memory/history_rows` = n) and a
//! running 64-bit hash of them (`/memory/history_hash`). Two details keep the appends safe
//! against a kill in the middle:
//!
//! - the file is created (through a temporary file and a rename) with all chunks of its
//!   capacity allocated up front (`H5D_ALLOC_TIME_EARLY`, no fill), so an append writes raw
//!   data into chunks that already exist and changes no HDF5 metadata (no chunk-index node
//!   is split or rewritten); one row per chunk, so a torn write can only touch rows beyond
//!   the recorded length, which resume ignores and overwrites;
//! - resume reads the valid rows back and checks their hash, so a history file that does
//!   not belong to the checkpoint (another run wrote it, or it was damaged) is refused, never
//!   silently used.
//!
//! The capacity is the run's number of steps; a resume that extends the run past it (or
//! writes into another directory) copies the valid rows into a new, larger file, once,
//! through a temporary file and a rename. The dataset's shape is its capacity; rows past
//! `history_rows` are unused. `checkpoint.h5` holds an HDF5 external link
//! `/memory/past_displacements` to it, so h5py opening the checkpoint finds the history there.
//!
//! # Cost
//!
//! The run does not wait for the disk: [`Writer::write`] copies the state (O(dofs), plus the
//! new history rows) and a background thread writes it. Checkpoints that fall due while the
//! previous one is still being written are coalesced (the newest state wins, history rows
//! accumulate), so the file on disk is always a complete, recent state and the run is never
//! throttled by fsync. The first checkpoint of a process goes through the HDF5 library; the
//! later ones reuse its bytes with the variable datasets patched in place (`Template`), a
//! memory copy instead of creating some fifty HDF5 objects. The end of a run (and
//! `--stop-after`) waits until the last checkpoint is on disk.

use crate::fem::Discretization;
use crate::history::{Memory, PronyTerm};
use crate::mesh::Mesh;
use crate::scene::{self, Scene};
use crate::time_loop::TimeLoop;
use crate::{Error, Result};
use hdf5::types::VarLenUnicode;
use hdf5_metno as hdf5;
use std::path::{Path, PathBuf};
use std::str::FromStr;

/// The root attribute `format` of every checkpoint.
pub const FORMAT: &str = "viscontact checkpoint";
/// The layout version written (root attribute `format_version`); files of a newer version
/// are refused.
pub const FORMAT_VERSION: u32 = 1;
/// The checkpoint's file name in a run directory.
pub const FILE_NAME: &str = "checkpoint.h5";
/// The append-only history file of a general (direct-sum) kernel, beside the checkpoint.
pub const HISTORY_FILE_NAME: &str = "checkpoint_history.h5";
const HISTORY_DATASET: &str = "past_displacements";

// ---------------------------------------------------------------------------------------
// Fingerprints
// ---------------------------------------------------------------------------------------

/// A 64-bit running hash over 64-bit words (FNV-1a style multiply, with an xor-shift so that
/// high bits feed back into low ones). Not cryptographic: it tells a changed mesh or a
/// foreign history file from the right one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Hash64(pub u64);

impl Default for Hash64 {
    fn default() -> Self {
        Hash64(0xcbf2_9ce4_8422_2325)
    }
}

impl Hash64 {
    pub fn word(&mut self, w: u64) {
        let h = (self.0 ^ w).wrapping_mul(0x0000_0100_0000_01b3);
        self.0 = h ^ (h >> 32);
    }

    /// The bits of every value (so −0.0 ≠ 0.0 and NaNs are told apart).
    pub fn f64s(&mut self, v: &[f64]) {
        for x in v {
            self.word(x.to_bits());
        }
    }

    pub fn str(&mut self, s: &str) {
        self.word(s.len() as u64);
        for chunk in s.as_bytes().chunks(8) {
            let mut b = [0u8; 8];
            b[..chunk.len()].copy_from_slice(chunk);
            self.word(u64::from_le_bytes(b));
        }
    }
}

/// Hash of the node coordinates (their bits) and the triangles' connectivity.
pub fn mesh_fingerprint(mesh: &Mesh) -> u64 {
    let mut h = Hash64::default();
    h.word(mesh.nodes.len() as u64);
    for p in &mesh.nodes {
        h.f64s(p);
    }
    h.word(mesh.triangles.len() as u64);
    for t in &mesh.triangles {
        for &i in t {
            h.word(i as u64);
        }
    }
    // 3D meshes only, so that 2D fingerprints stay what they were.
    if !mesh.tetrahedra.is_empty() {
        h.word(mesh.tetrahedra.len() as u64);
        for t in &mesh.tetrahedra {
            for &i in t {
                h.word(i as u64);
            }
        }
    }
    h.0
}

/// Hash of the physical groups: name, tag, dimension, facets and cells of each.
pub fn groups_fingerprint(mesh: &Mesh) -> u64 {
    let mut h = Hash64::default();
    h.word(mesh.groups.len() as u64);
    for g in &mesh.groups {
        h.word(g.dim as u64);
        h.word(g.tag as i64 as u64);
        h.str(g.name.as_deref().unwrap_or(""));
        h.word(g.facets.len() as u64);
        for f in &g.facets {
            h.word(f[0] as u64);
            h.word(f[1] as u64);
        }
        if !g.faces.is_empty() {
            h.word(g.faces.len() as u64);
            for f in &g.faces {
                for &i in f {
                    h.word(i as u64);
                }
            }
        }
        h.word(g.cells.len() as u64);
        for &c in &g.cells {
            h.word(c as u64);
        }
    }
    h.0
}

/// The physics of a scene as `(dotted key, TOML value)` pairs: every key except the ones a
/// resume may change (`name`, `time.*`, `output.*`, `checkpoint.*`). The step size is
/// compared on its own (`step_size`).
pub fn physics_signature(scene_text: &str) -> Vec<(String, String)> {
    fn flatten(prefix: &str, v: &toml::Value, out: &mut Vec<(String, String)>) {
        match v {
            toml::Value::Table(t) => {
                for (k, v) in t {
                    let key = if prefix.is_empty() {
                        k.clone()
                    } else {
                        format!("{prefix}.{k}")
                    };
                    if matches!(key.as_str(), "name" | "time" | "output" | "checkpoint") {
                        continue;
                    }
                    flatten(&key, v, out);
                }
            }
            toml::Value::Array(a) if a.iter().any(|x| x.is_table()) => {
                for (i, x) in a.iter().enumerate() {
                    flatten(&format!("{prefix}[{i}]"), x, out);
                }
            }
            other => out.push((prefix.to_string(), other.to_string())),
        }
    }
    let mut out = Vec::new();
    if let Ok(root) = scene_text.parse::<toml::Table>() {
        flatten("", &toml::Value::Table(root), &mut out);
    }
    out.sort();
    out
}

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
            dof_of: disc
                .free
                .iter()
                .map(|d| d.map_or(-1, |i| i as i64))
                .collect(),
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

// ---------------------------------------------------------------------------------------
// Writing
// ---------------------------------------------------------------------------------------

use hdf5::file::OpenMode;

/// Opens or creates an HDF5 file with HDF5's file locking off. Our files are never shared by
/// two writers (a checkpoint is written to a private temporary file and renamed), and the
/// lock (flock) is inherited by child processes that a program spawns while a file is open,
/// which then makes opening the file fail elsewhere for as long as the child lives.
fn h5_file<P: AsRef<Path>>(mode: OpenMode, path: P) -> hdf5::Result<hdf5::File> {
    hdf5::File::with_options()
        .with_fapl(|p| p.file_locking(false))
        .open_as(path, mode)
}

fn h5err(path: &Path, e: hdf5::Error) -> Error {
    Error::io(path, std::io::Error::other(format!("HDF5: {e}")))
}

fn fsync_file(path: &Path) -> Result<()> {
    std::fs::File::open(path)
        .and_then(|f| f.sync_all())
        .map_err(|e| Error::io(path, e))
}

/// fsync of a directory makes a rename in it durable; failure (some file systems cannot) is
/// not an error: the rename itself is what makes a crash of the process safe.
fn fsync_dir(dir: &Path) {
    if let Ok(d) = std::fs::File::open(dir) {
        let _ = d.sync_all();
    }
}

fn vlu(s: &str) -> VarLenUnicode {
    // Strings we write never hold NUL; replace any to keep the attribute writable.
    VarLenUnicode::from_str(&s.replace('\0', " ")).expect("no NUL in the string")
}

fn str_attr(loc: &hdf5::Location, name: &str, value: &str) -> hdf5::Result<()> {
    loc.new_attr::<VarLenUnicode>()
        .shape(())
        .create(name)?
        .write_scalar(&vlu(value))
}

fn describe(ds: &hdf5::Dataset, description: &str, units: &str) -> hdf5::Result<()> {
    str_attr(ds, "description", description)?;
    str_attr(ds, "units", units)
}

fn scalar<T: hdf5::H5Type>(
    g: &hdf5::Group,
    name: &str,
    value: T,
    description: &str,
    units: &str,
) -> hdf5::Result<()> {
    let ds = g.new_dataset::<T>().shape(()).create(name)?;
    ds.write_scalar(&value)?;
    describe(&ds, description, units)
}

fn vector<T: hdf5::H5Type>(
    g: &hdf5::Group,
    name: &str,
    shape: &[usize],
    values: &[T],
    description: &str,
    units: &str,
) -> hdf5::Result<()> {
    let ds = g.new_dataset::<T>().shape(shape).create(name)?;
    if !values.is_empty() {
        ds.write_raw(values)?;
    }
    describe(&ds, description, units)
}

fn string_dataset(g: &hdf5::Group, name: &str, value: &str, description: &str) -> hdf5::Result<()> {
    let ds = g.new_dataset::<VarLenUnicode>().shape(()).create(name)?;
    ds.write_scalar(&vlu(value))?;
    describe(&ds, description, "")
}

/// The append-only history file of this run's directory.
struct HistoryFile {
    path: PathBuf,
    capacity: usize,
    /// Rows written and fsync'ed (rows past the last checkpoint's count may be among them).
    rows: usize,
    /// Running hash of rows 0..rows.
    hash: Hash64,
}

impl HistoryFile {
    /// Creates the file with `capacity` preallocated rows holding `past` (temp + rename).
    fn create(
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
    fn append(&mut self, from: usize, rows: &[Vec<f64>]) -> Result<()> {
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

/// The state saved at one checkpoint, copied out of the time loop (so that the run goes on
/// while a background thread writes it).
struct Snapshot {
    n: usize,
    k: f64,
    u: Vec<f64>,
    u_sum: Vec<f64>,
    u_comp: Vec<f64>,
    w: Vec<f64>,
    z: Vec<f64>,
    active: Vec<bool>,
    memory: SnapshotMemory,
    log: RunLog,
}

enum SnapshotMemory {
    None,
    Prony(Vec<PronyTerm>),
    /// The past displacements not yet sent to the writer: rows `from..from + rows.len()`.
    Direct {
        from: usize,
        rows: Vec<Vec<f64>>,
    },
}

impl Snapshot {
    /// Folds a newer snapshot into this unwritten one: the newer state wins, history rows
    /// accumulate.
    fn absorb(&mut self, newer: Snapshot) {
        let older_rows = match &mut self.memory {
            SnapshotMemory::Direct { rows, .. } => Some(std::mem::take(rows)),
            _ => None,
        };
        let from = match &self.memory {
            SnapshotMemory::Direct { from, .. } => *from,
            _ => 0,
        };
        *self = match (older_rows, newer) {
            (
                Some(mut rows),
                Snapshot {
                    memory: SnapshotMemory::Direct { rows: more, .. },
                    n,
                    k,
                    u,
                    u_sum,
                    u_comp,
                    w,
                    z,
                    active,
                    log,
                },
            ) => {
                rows.extend(more);
                Snapshot {
                    n,
                    k,
                    u,
                    u_sum,
                    u_comp,
                    w,
                    z,
                    active,
                    memory: SnapshotMemory::Direct { from, rows },
                    log,
                }
            }
            (_, newer) => newer,
        };
    }
}

/// What the background writer and the run share.
#[derive(Default)]
struct Mailbox {
    /// The newest snapshot not yet taken by the writer.
    pending: Option<Snapshot>,
    /// The writer is writing a snapshot.
    busy: bool,
    /// No more snapshots will come.
    closed: bool,
    /// The first failure of the writer; reported to the run at its next checkpoint.
    error: Option<Error>,
}

struct Shared {
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
    /// History rows already handed to the writer thread.
    rows_sent: usize,
    shared: std::sync::Arc<Shared>,
    thread: Option<std::thread::JoinHandle<()>>,
}

/// The writer thread's side: the files.
struct Disk {
    dir: PathBuf,
    id: Identity,
    /// Rows to preallocate in a new history file (the run's number of steps).
    capacity: usize,
    history: Option<HistoryFile>,
    row_node: Vec<u64>,
    /// The bytes of the last checkpoint written through HDF5 and where its variable data
    /// lie; later checkpoints patch them (see [`Template`]).
    template: Option<Template>,
}

/// The first checkpoint of a run is written through the HDF5 library; every later one has
/// the same structure and differs only in the raw data of its variable datasets (contiguous
/// layout, fixed sizes: `/run/iterations` has one entry per step of the whole run, −1 for
/// steps not yet solved). So the file's bytes are kept with the offsets of those datasets
/// (H5Dget_offset), and a later checkpoint is the same bytes with the new values written at
/// those offsets: a valid HDF5 file (raw data carries no checksum) at the cost of a memory
/// copy instead of creating some fifty HDF5 objects. Whatever does not fit (a dataset
/// without an offset, a size that changed) falls back to the library.
struct Template {
    bytes: Vec<u8>,
    /// (offset, length) of each entry of [`variable_data`], in its order.
    regions: Vec<(usize, usize)>,
}

/// The datasets whose values change from one checkpoint to the next, in file byte order
/// (little endian, as the datasets are declared).
fn variable_data(s: &Snapshot, steps: usize) -> Vec<(&'static str, Vec<u8>)> {
    fn f64s(v: &[f64]) -> Vec<u8> {
        v.iter().flat_map(|x| x.to_le_bytes()).collect()
    }
    let mut out = vec![
        ("step", (s.n as u64).to_le_bytes().to_vec()),
        ("time", (s.n as f64 * s.k).to_le_bytes().to_vec()),
        ("state/u", f64s(&s.u)),
        ("state/u_sum", f64s(&s.u_sum)),
        ("state/u_comp", f64s(&s.u_comp)),
        ("state/w", f64s(&s.w)),
        ("state/z", f64s(&s.z)),
        ("state/active", s.active.iter().map(|&a| a as u8).collect()),
        (
            "run/iterations",
            iterations(&s.log, steps)
                .iter()
                .flat_map(|x| x.to_le_bytes())
                .collect(),
        ),
        (
            "run/max_violation",
            s.log.max_violation.to_le_bytes().to_vec(),
        ),
        (
            "run/max_kkt_residual",
            s.log.max_kkt_residual.to_le_bytes().to_vec(),
        ),
    ];
    match &s.memory {
        SnapshotMemory::None => {}
        SnapshotMemory::Prony(terms) => {
            let m: Vec<f64> = terms.iter().flat_map(|t| t.m.iter().copied()).collect();
            out.push(("memory/prony_state", f64s(&m)));
        }
        SnapshotMemory::Direct { .. } => {
            out.push(("memory/history_rows", (s.n as u64).to_le_bytes().to_vec()));
        }
    }
    out
}

/// Iterations of steps 0..n, then −1 up to the run's `steps` + 1 entries.
fn iterations(log: &RunLog, steps: usize) -> Vec<i32> {
    let mut v: Vec<i32> = log
        .iterations
        .iter()
        .map(|&i| i.min(i32::MAX as usize) as i32)
        .collect();
    v.resize(v.len().max(steps + 1), -1);
    v
}

impl Template {
    /// Reads back the file just written and finds its variable datasets; None when one is
    /// not contiguous with exactly the expected size.
    fn capture(path: &Path, data: &[(&'static str, Vec<u8>)]) -> Option<Template> {
        let regions = {
            let f = h5_file(OpenMode::Read, path).ok()?;
            let mut regions = Vec::with_capacity(data.len());
            for (name, bytes) in data {
                let ds = f.dataset(name).ok()?;
                if bytes.is_empty() {
                    regions.push((0, 0));
                    continue;
                }
                let offset = ds.offset()? as usize;
                if ds.storage_size() as usize != bytes.len() {
                    return None;
                }
                regions.push((offset, bytes.len()));
            }
            regions
        };
        let bytes = std::fs::read(path).ok()?;
        for ((offset, len), (_, data)) in regions.iter().zip(data) {
            if offset + len > bytes.len() || bytes[*offset..offset + len] != data[..] {
                return None;
            }
        }
        Some(Template { bytes, regions })
    }

    /// The file bytes for `data`; None when the sizes no longer match.
    fn patch(&mut self, data: &[(&'static str, Vec<u8>)]) -> Option<&[u8]> {
        if data.len() != self.regions.len() {
            return None;
        }
        for ((_, len), (_, d)) in self.regions.iter().zip(data) {
            if *len != d.len() {
                return None;
            }
        }
        for ((offset, len), (_, d)) in self.regions.iter().zip(data) {
            self.bytes[*offset..offset + len].copy_from_slice(d);
        }
        Some(&self.bytes)
    }
}

impl Disk {
    /// The disk side of a run of `steps` steps into `dir`, no history file yet.
    fn new(dir: &Path, id: Identity, steps: usize, tl: &TimeLoop) -> Disk {
        Disk {
            dir: dir.to_path_buf(),
            id,
            capacity: steps,
            history: None,
            row_node: tl.rows.rows.iter().map(|r| r.node as u64).collect(),
            template: None,
        }
    }
}

impl Writer {
    /// A writer for a run of `steps` steps into `dir`; `tl` gives the sizes.
    pub fn new(dir: &Path, id: Identity, steps: usize, tl: &TimeLoop) -> Writer {
        Writer::start(Disk::new(dir, id, steps, tl), 0)
    }

    /// A writer that continues `cp` in `dir` for a run of `steps` steps. The history file is
    /// appended to in place when it is the checkpoint's own and has room; otherwise the first
    /// checkpoint writes a new one with all rows (once).
    pub fn resume(
        dir: &Path,
        id: Identity,
        steps: usize,
        tl: &TimeLoop,
        cp: &Checkpoint,
    ) -> Writer {
        let mut disk = Disk::new(dir, id, steps, tl);
        let mut rows_sent = 0;
        if let StoredMemory::Direct {
            rows,
            hash,
            capacity,
            ..
        } = &cp.memory
        {
            let same_dir = match (std::fs::canonicalize(dir), cp.dir().canonicalize()) {
                (Ok(a), Ok(b)) => a == b,
                _ => false,
            };
            if same_dir && *capacity >= steps {
                disk.history = Some(HistoryFile {
                    path: dir.join(HISTORY_FILE_NAME),
                    capacity: *capacity,
                    rows: *rows,
                    hash: Hash64(*hash),
                });
                rows_sent = *rows;
            }
        }
        Writer::start(disk, rows_sent)
    }

    fn start(mut disk: Disk, rows_sent: usize) -> Writer {
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
            rows_sent,
            shared,
            thread: Some(thread),
        }
    }

    /// `DIR/checkpoint.h5`.
    pub fn path(&self) -> PathBuf {
        self.path.clone()
    }

    /// Hands the checkpoint of `tl` (at step n = `tl.n()`, before solving it) to the writer
    /// thread. `active`: the contact/stick flags of the last solved step's rows. Returns the
    /// error of an earlier checkpoint that failed.
    pub fn write(&mut self, tl: &TimeLoop, log: &RunLog, active: &[bool]) -> Result<()> {
        let h = &tl.history;
        let memory = match &h.memory {
            Memory::None => SnapshotMemory::None,
            Memory::Prony(terms) => SnapshotMemory::Prony(terms.clone()),
            Memory::Direct { past, .. } => {
                let from = self.rows_sent;
                self.rows_sent = past.len();
                SnapshotMemory::Direct {
                    from,
                    rows: past[from..].to_vec(),
                }
            }
        };
        let snapshot = Snapshot {
            n: h.n,
            k: h.k,
            u: h.u.clone(),
            u_sum: h.u_sum.clone(),
            u_comp: h.u_comp.clone(),
            w: tl.w.clone(),
            z: tl.z.clone(),
            active: active.to_vec(),
            memory,
            log: log.clone(),
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
    /// First the new history rows (fsync'ed), then `checkpoint.h5.tmp`, fsync, rename, fsync
    /// of the directory.
    fn write(&mut self, s: &Snapshot) -> Result<()> {
        if let SnapshotMemory::Direct { from, rows } = &s.memory {
            match &mut self.history {
                Some(h) => h.append(*from, rows)?,
                None => {
                    assert_eq!(*from, 0, "a new history file starts at row 0");
                    self.history = Some(HistoryFile::create(
                        &self.dir.join(HISTORY_FILE_NAME),
                        &self.id.run_id,
                        s.u.len(),
                        self.capacity,
                        rows,
                    )?)
                }
            }
        }
        let path = self.dir.join(FILE_NAME);
        let tmp = self.dir.join(format!("{FILE_NAME}.tmp"));
        let data = variable_data(s, self.capacity);
        let history_hash = self.history.as_ref().map(|h| h.hash.0);
        let fast = match (&mut self.template, history_hash) {
            (Some(t), hash) => {
                let mut data = data.clone();
                if let Some(h) = hash {
                    data.push(("memory/history_hash", h.to_le_bytes().to_vec()));
                }
                t.patch(&data).map(|bytes| {
                    std::fs::write(&tmp, bytes).map_err(|e| {
                        let _ = std::fs::remove_file(&tmp);
                        Error::io(&path, e)
                    })
                })
            }
            (None, _) => None,
        };
        match fast {
            Some(result) => result?,
            None => {
                write_checkpoint(
                    &tmp,
                    &self.id,
                    &self.row_node,
                    s,
                    self.capacity,
                    self.history.as_ref(),
                )
                .map_err(|e| {
                    let _ = std::fs::remove_file(&tmp);
                    h5err(&path, e)
                })?;
                let mut data = data;
                if let Some(h) = history_hash {
                    data.push(("memory/history_hash", h.to_le_bytes().to_vec()));
                }
                self.template = Template::capture(&tmp, &data);
            }
        }
        fsync_file(&tmp)?;
        std::fs::rename(&tmp, &path).map_err(|e| Error::io(&path, e))?;
        fsync_dir(&self.dir);
        Ok(())
    }
}

fn write_checkpoint(
    path: &Path,
    id: &Identity,
    row_node: &[u64],
    s: &Snapshot,
    steps: usize,
    history: Option<&HistoryFile>,
) -> hdf5::Result<()> {
    let n_free = s.u.len();
    let f = h5_file(OpenMode::Create, path)?;
    str_attr(&f, "format", FORMAT)?;
    f.new_attr::<u32>()
        .shape(())
        .create("format_version")?
        .write_scalar(&FORMAT_VERSION)?;
    str_attr(
        &f,
        "writer",
        concat!("viscontact ", env!("CARGO_PKG_VERSION")),
    )?;
    str_attr(
        &f,
        "description",
        "restart state of a viscontact run (Problem 3.1 of Xu et al. 2021) before step \
         `step` is solved; continue it with `viscontact resume THIS_FILE`",
    )?;
    str_attr(&f, "run_id", &id.run_id)?;

    scalar(
        &f,
        "step",
        s.n as u64,
        "n: the next step to solve; steps 0..n-1 are done",
        "1",
    )?;
    scalar(&f, "time", s.n as f64 * s.k, "t_n = n k", "s")?;
    scalar(&f, "step_size", s.k, "k = T/N, the time step", "s")?;

    let state = f.create_group("state")?;
    let nf = [n_free];
    vector(
        &state,
        "u",
        &nf,
        &s.u,
        "u_n = u_0 + k Σ_{j<n} w_j, displacement at t_n (free dofs, see /mesh/dof_of) \
         = u_sum + u_comp",
        "m",
    )?;
    vector(
        &state,
        "u_sum",
        &nf,
        &s.u_sum,
        "running sum of k w_j (Neumaier compensated summation)",
        "m",
    )?;
    vector(
        &state,
        "u_comp",
        &nf,
        &s.u_comp,
        "Neumaier compensation: rounding error not yet in u_sum",
        "m",
    )?;
    vector(
        &state,
        "w",
        &nf,
        &s.w,
        "w_{n-1}: velocity of the last solved step (free dofs)",
        "m/s",
    )?;
    vector(
        &state,
        "z",
        &[s.z.len()],
        &s.z,
        "multipliers of the last solved step: λ_i ≥ 0 on the Γ3,1 contact rows, then γ_i \
         (|γ_i| ≤ μF∫φ_i) on the Γ3,2 friction rows (nodal forces); the warm start of step n",
        "N/m",
    )?;
    let flags: Vec<u8> = s.active.iter().map(|&a| a as u8).collect();
    vector(
        &state,
        "active",
        &[flags.len()],
        &flags,
        "per row of z: 1 = contact active (Γ3,1) or sticking (Γ3,2) at the last solved step, \
         0 = free or slipping; recomputed by the solver from z, stored for inspection",
        "1",
    )?;
    vector(
        &state,
        "row_node",
        &[row_node.len()],
        row_node,
        "mesh node of each row of z (contact rows first, then friction rows)",
        "1",
    )?;

    let memory = f.create_group("memory")?;
    match &s.memory {
        SnapshotMemory::None => str_attr(&memory, "kind", "none")?,
        SnapshotMemory::Prony(terms) => {
            str_attr(&memory, "kind", "prony")?;
            let a: Vec<f64> = terms.iter().map(|t| t.a).collect();
            let decay: Vec<f64> = terms.iter().map(|t| t.decay).collect();
            let b: Vec<f64> = terms.iter().map(|t| -t.decay.ln() / s.k).collect();
            let m: Vec<f64> = terms.iter().flat_map(|t| t.m.iter().copied()).collect();
            let nt = [terms.len()];
            vector(
                &memory,
                "prony_a",
                &nt,
                &a,
                "weights a_i of r(s) = Σ a_i exp(-b_i s)",
                "Pa/s",
            )?;
            vector(
                &memory,
                "prony_b",
                &nt,
                &b,
                "rates b_i of r(s) = Σ a_i exp(-b_i s) (recovered from prony_decay; \
                 informational)",
                "1/s",
            )?;
            vector(
                &memory,
                "prony_decay",
                &nt,
                &decay,
                "one-step decay exp(-b_i k) of each term (exactly as used)",
                "1",
            )?;
            vector(
                &memory,
                "prony_state",
                &[terms.len(), n_free],
                &m,
                "m^(i)_n = k Σ_{j<n} exp(-b_i (t_n - t_j)) u_j, one row per term; \
                 m_n = Σ a_i m^(i)_n",
                "m s",
            )?;
        }
        SnapshotMemory::Direct { .. } => {
            str_attr(&memory, "kind", "direct")?;
            let hist = history.expect("a direct-sum memory has a history file");
            scalar(
                &memory,
                "history_rows",
                s.n as u64,
                "valid rows of past_displacements: u_0..u_{n-1} (= step)",
                "1",
            )?;
            scalar(
                &memory,
                "history_hash",
                hist.hash.0,
                "64-bit running hash of the bits of rows 0..history_rows-1 of \
                 past_displacements (src/checkpoint.rs Hash64); resume checks it",
                "1",
            )?;
            memory
                .new_attr::<u64>()
                .shape(())
                .create("history_capacity")?
                .write_scalar(&(hist.capacity as u64))?;
            str_attr(&memory, "history_file", HISTORY_FILE_NAME)?;
            str_attr(
                &memory,
                "description",
                "general kernel: m_n = k Σ_{j<n} r((n-j)k) u_j by the direct sum; \
                 u_0..u_{n-1} are rows 0..history_rows-1 of past_displacements (an external \
                 link to history_file, appended to at each checkpoint); history_hash is a \
                 64-bit running hash of those rows' bits",
            )?;
            memory.link_external(HISTORY_FILE_NAME, HISTORY_DATASET, "past_displacements")?;
        }
    }

    let run = f.create_group("run")?;
    let iterations = iterations(&s.log, steps);
    vector(
        &run,
        "iterations",
        &[iterations.len()],
        &iterations,
        "step solver iterations of each step 0..N of the run (summary.json \
         iterations.per_step); -1 for the steps n..N not solved yet",
        "1",
    )?;
    scalar(
        &run,
        "max_violation",
        s.log.max_violation,
        "largest n·w over the Γ3,1 nodes and steps 0..n-1 (-inf: none yet)",
        "m/s",
    )?;
    scalar(
        &run,
        "max_kkt_residual",
        s.log.max_kkt_residual,
        "largest relative KKT residual over steps 0..n-1",
        "1",
    )?;

    let sc = f.create_group("scene")?;
    string_dataset(
        &sc,
        "text",
        &id.scene_text,
        "the scene file (TOML) that ran, after --set overrides",
    )?;
    str_attr(&sc, "path", &id.scene_path)?;
    str_attr(&sc, "absolute_path", &id.scene_path_absolute)?;
    str_attr(
        &sc,
        "description",
        "mesh.file in text is relative to the directory of absolute_path",
    )?;

    let mesh = f.create_group("mesh")?;
    str_attr(&mesh, "file", &id.mesh_path)?;
    mesh.new_attr::<u64>()
        .shape(())
        .create("nodes")?
        .write_scalar(&(id.nodes as u64))?;
    mesh.new_attr::<u64>()
        .shape(())
        .create("triangles")?
        .write_scalar(&(id.triangles as u64))?;
    scalar(
        &mesh,
        "fingerprint",
        id.mesh_fingerprint,
        "64-bit hash of the node coordinates' bits and the triangles' node indices \
         (src/checkpoint.rs mesh_fingerprint)",
        "1",
    )?;
    scalar(
        &mesh,
        "groups_fingerprint",
        id.groups_fingerprint,
        "64-bit hash of the physical groups: name, tag, dimension, facets, cells",
        "1",
    )?;
    vector(
        &mesh,
        "dof_of",
        &[id.nodes, id.dof_of.len() / id.nodes.max(1)],
        &id.dof_of,
        "free dof index of each node's x, y (and z in 3D) component (row = node), -1 on Γ1 \
         (w = 0)",
        "1",
    )?;

    let physics = f.create_group("physics")?;
    str_attr(
        &physics,
        "description",
        "every physics key of the scene (all but name, time, output, checkpoint) as \
         'dotted.key' = TOML value; resume refuses a scene that differs",
    )?;
    for (k, v) in &id.physics {
        str_attr(&physics, k, v)?;
    }
    f.close()?;
    Ok(())
}

// ---------------------------------------------------------------------------------------
// Reading
// ---------------------------------------------------------------------------------------

/// The memory as stored in a checkpoint.
#[derive(Clone, Debug)]
pub enum StoredMemory {
    None,
    Prony {
        a: Vec<f64>,
        decay: Vec<f64>,
        /// m^(i)_n per term.
        m: Vec<Vec<f64>>,
    },
    /// Rows 0..rows of the history file, their running hash, the file's capacity.
    Direct {
        file: String,
        rows: usize,
        hash: u64,
        capacity: usize,
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
    pub u: Vec<f64>,
    pub u_sum: Vec<f64>,
    pub u_comp: Vec<f64>,
    pub w: Vec<f64>,
    pub z: Vec<f64>,
    pub memory: StoredMemory,
    pub log: RunLog,
}

/// The 8-byte HDF5 signature; HDF5 looks for it at 0, 512, 1024, 2048, ….
const HDF5_SIGNATURE: &[u8; 8] = b"\x89HDF\r\n\x1a\n";

fn has_hdf5_signature(path: &Path) -> std::io::Result<bool> {
    use std::io::{Read, Seek, SeekFrom};
    let mut f = std::fs::File::open(path)?;
    let len = f.metadata()?.len();
    let mut at = 0u64;
    while at + 8 <= len {
        let mut buf = [0u8; 8];
        f.seek(SeekFrom::Start(at))?;
        f.read_exact(&mut buf)?;
        if &buf == HDF5_SIGNATURE {
            return Ok(true);
        }
        at = if at == 0 { 512 } else { at * 2 };
    }
    Ok(false)
}

impl Checkpoint {
    /// The directory the checkpoint is in.
    pub fn dir(&self) -> PathBuf {
        match self.path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        }
    }

    /// Reads and checks a checkpoint file. Refuses (input errors naming the file): a missing
    /// file, a file that is not HDF5, a truncated or damaged one, an HDF5 file that is not a
    /// viscontact checkpoint, a newer format version.
    pub fn read(path: &Path) -> Result<Checkpoint> {
        let shown = path.display();
        match has_hdf5_signature(path) {
            Ok(true) => {}
            Ok(false) => {
                return Err(Error::input(format!(
                    "{shown}: not an HDF5 file, so not a viscontact checkpoint; give the \
                     checkpoint.h5 of a run directory"
                )))
            }
            Err(e) => {
                return Err(Error::input(format!(
                    "cannot read checkpoint '{shown}': {e}; give the checkpoint.h5 of a run \
                     directory"
                )))
            }
        }
        let f = h5_file(OpenMode::Read, path).map_err(|e| {
            Error::input(format!(
                "{shown}: cannot open as HDF5 ({e}): the file is truncated or damaged; resume \
                 from an intact checkpoint (a run writes checkpoint.h5 whole and renames it, \
                 so the one a run left is intact unless something else changed it)"
            ))
        })?;
        let format = f
            .attr("format")
            .and_then(|a| a.read_scalar::<VarLenUnicode>())
            .map(|s| s.as_str().to_string())
            .ok();
        if format.as_deref() != Some(FORMAT) {
            return Err(Error::input(format!(
                "{shown}: an HDF5 file but not a viscontact checkpoint (its root attribute \
                 'format' is {}, expected \"{FORMAT}\"); give the checkpoint.h5 that \
                 `viscontact run` wrote",
                format.map_or("missing".to_string(), |s| format!("{s:?}"))
            )));
        }
        let version = f
            .attr("format_version")
            .and_then(|a| a.read_scalar::<u32>())
            .map_err(|e| {
                Error::input(format!(
                    "{shown}: damaged checkpoint: attribute 'format_version' unreadable ({e})"
                ))
            })?;
        if version > FORMAT_VERSION {
            return Err(Error::input(format!(
                "{shown}: checkpoint format version {version} is newer than this viscontact \
                 reads (≤ {FORMAT_VERSION}); resume it with the viscontact version that \
                 wrote it ({})",
                str_attr_of(&f, "writer").unwrap_or_else(|_| "unknown".into())
            )));
        }
        read_body(&f, path, version).map_err(|e| {
            Error::input(format!(
                "{shown}: damaged checkpoint ({e}); resume from an intact checkpoint or start \
                 the run again"
            ))
        })
    }
}

fn str_attr_of(loc: &hdf5::Location, name: &str) -> hdf5::Result<String> {
    Ok(loc
        .attr(name)?
        .read_scalar::<VarLenUnicode>()?
        .as_str()
        .to_string())
}

fn read_body(f: &hdf5::File, path: &Path, version: u32) -> hdf5::Result<Checkpoint> {
    let ds = |name: &str| f.dataset(name);
    let vec = |name: &str| -> hdf5::Result<Vec<f64>> { ds(name)?.read_raw::<f64>() };
    let n = ds("step")?.read_scalar::<u64>()? as usize;
    let time = ds("time")?.read_scalar::<f64>()?;
    let k = ds("step_size")?.read_scalar::<f64>()?;
    let mem = f.group("memory")?;
    let kind = str_attr_of(&mem, "kind")?;
    let memory = match kind.as_str() {
        "none" => StoredMemory::None,
        "prony" => {
            let a = vec("memory/prony_a")?;
            let decay = vec("memory/prony_decay")?;
            let state = ds("memory/prony_state")?;
            let flat = state.read_raw::<f64>()?;
            let shape = state.shape();
            if shape.len() != 2 || shape[0] != a.len() || decay.len() != a.len() {
                return Err("memory/prony_* have inconsistent shapes".into());
            }
            let m = if shape[1] == 0 {
                vec![Vec::new(); shape[0]]
            } else {
                flat.chunks(shape[1]).map(|c| c.to_vec()).collect()
            };
            StoredMemory::Prony { a, decay, m }
        }
        "direct" => StoredMemory::Direct {
            file: str_attr_of(&mem, "history_file")?,
            rows: mem.dataset("history_rows")?.read_scalar::<u64>()? as usize,
            hash: mem.dataset("history_hash")?.read_scalar::<u64>()?,
            capacity: mem.attr("history_capacity")?.read_scalar::<u64>()? as usize,
        },
        other => return Err(format!("/memory kind {other:?} is unknown").into()),
    };
    let run = f.group("run")?;
    let log = RunLog {
        iterations: {
            let all = run.dataset("iterations")?.read_raw::<i32>()?;
            if all.len() < n || all[..n].iter().any(|&i| i < 0) {
                return Err(format!("/run/iterations lacks the counts of steps 0..{n}").into());
            }
            all[..n].iter().map(|&i| i as usize).collect()
        },
        max_violation: run.dataset("max_violation")?.read_scalar::<f64>()?,
        max_kkt_residual: run.dataset("max_kkt_residual")?.read_scalar::<f64>()?,
    };
    let sc = f.group("scene")?;
    let mesh = f.group("mesh")?;
    let physics_group = f.group("physics")?;
    let mut physics = Vec::new();
    for name in physics_group.attr_names()? {
        if name != "description" {
            physics.push((name.clone(), str_attr_of(&physics_group, &name)?));
        }
    }
    physics.sort();
    let id = Identity {
        run_id: str_attr_of(f, "run_id")?,
        scene_text: sc
            .dataset("text")?
            .read_scalar::<VarLenUnicode>()?
            .as_str()
            .to_string(),
        scene_path: str_attr_of(&sc, "path")?,
        scene_path_absolute: str_attr_of(&sc, "absolute_path")?,
        mesh_path: str_attr_of(&mesh, "file")?,
        mesh_fingerprint: mesh.dataset("fingerprint")?.read_scalar::<u64>()?,
        groups_fingerprint: mesh.dataset("groups_fingerprint")?.read_scalar::<u64>()?,
        nodes: mesh.attr("nodes")?.read_scalar::<u64>()? as usize,
        triangles: mesh.attr("triangles")?.read_scalar::<u64>()? as usize,
        physics,
        dof_of: mesh.dataset("dof_of")?.read_raw::<i64>()?,
    };
    let cp = Checkpoint {
        path: path.to_path_buf(),
        version,
        n,
        time,
        k,
        id,
        u: vec("state/u")?,
        u_sum: vec("state/u_sum")?,
        u_comp: vec("state/u_comp")?,
        w: vec("state/w")?,
        z: vec("state/z")?,
        memory,
        log,
    };
    if cp.log.iterations.len() != cp.n {
        return Err(format!(
            "/run/iterations has {} entries for step {}",
            cp.log.iterations.len(),
            cp.n
        )
        .into());
    }
    if !(cp.k > 0.0 && cp.k.is_finite()) {
        return Err(format!("step_size {} is not a positive number", cp.k).into());
    }
    Ok(cp)
}

// ---------------------------------------------------------------------------------------
// Resuming
// ---------------------------------------------------------------------------------------

/// Keys a resume may override: the end time (the step size stays), output and checkpoints.
fn overridable(key: &str) -> bool {
    key == "time.end" || key.starts_with("output.") || key.starts_with("checkpoint.")
}

impl Checkpoint {
    /// The scene of a resumed run: the stored scene text with `overrides` applied. Only
    /// `time.end`, `output.*` and `checkpoint.*` may be overridden; `time.end = T2` keeps the
    /// step size k and sets `time.steps` = T2/k, which must be an integer (within 1e-9) not
    /// below the checkpoint's step. `mesh.file` is resolved against the stored scene path.
    pub fn scene(&self, overrides: &[String]) -> Result<Scene> {
        let shown = self.path.display();
        let mut all = Vec::new();
        for o in overrides {
            let (key, value) = o.split_once('=').ok_or_else(|| {
                Error::input(format!(
                    "--set {o:?}: expected KEY=VALUE, e.g. --set time.end=2.0"
                ))
            })?;
            let key = key.trim();
            if !overridable(key) {
                return Err(Error::input(format!(
                    "--set {key}: a resume continues the physics of {shown} and may only \
                     change time.end, output.* and checkpoint.*; to change {key}, start a new \
                     run with `viscontact run`"
                )));
            }
            if key == "time.end" {
                let end: f64 = value.trim().parse().map_err(|_| {
                    Error::input(format!(
                        "--set time.end={}: not a number; give the new end time T2 in seconds",
                        value.trim()
                    ))
                })?;
                let ratio = end / self.k;
                let steps = ratio.round();
                if !(ratio.is_finite() && (ratio - steps).abs() <= 1e-9 * steps.max(1.0)) {
                    return Err(Error::input(format!(
                        "--set time.end={end}: T2/k = {ratio} is not a whole number of steps of \
                         the run's step size k = {} ({shown}); choose T2 = N·k, e.g. {}",
                        self.k,
                        (ratio.ceil().max(1.0)) * self.k
                    )));
                }
                let steps = steps as usize;
                if steps < self.n {
                    return Err(Error::input(format!(
                        "--set time.end={end}: ends before the checkpoint's time t = {} (step \
                         {}) of {shown}; choose T2 ≥ {}",
                        self.time, self.n, self.time
                    )));
                }
                all.push(format!("time.end={end:?}"));
                all.push(format!("time.steps={steps}"));
            } else {
                all.push(o.clone());
            }
        }
        let scene_path = self.scene_path();
        let (text, file) = scene::parse_scene_text(&scene_path, self.id.scene_text.clone(), &all)
            .map_err(|e| Error::input(format!("{shown}: the stored scene: {e}")))?;
        let scene = Scene::from_file(&scene_path, text, file)
            .map_err(|e| Error::input(format!("{shown}: the stored scene: {e}")))?;
        if scene.steps < self.n {
            return Err(Error::input(format!(
                "{shown}: the stored scene has {} steps but the checkpoint is at step {}: \
                 the file is inconsistent",
                scene.steps, self.n
            )));
        }
        Ok(scene)
    }

    /// The scene path to use: the path as the run was given it when that still names the
    /// same file from here (so summary.json says the same), else the absolute one.
    fn scene_path(&self) -> PathBuf {
        let given = PathBuf::from(&self.id.scene_path);
        match std::fs::canonicalize(&given) {
            Ok(p) if p.display().to_string() == self.id.scene_path_absolute => given,
            _ => PathBuf::from(&self.id.scene_path_absolute),
        }
    }

    /// Refuses a mesh, physics or step size that differ from the checkpoint's, naming what.
    pub fn check(&self, scene: &Scene, mesh: &Mesh, disc: &Discretization) -> Result<()> {
        let shown = self.path.display();
        let mut diffs = Vec::new();
        if mesh_fingerprint(mesh) != self.id.mesh_fingerprint {
            diffs.push(format!(
                "the mesh {} is not the one the run used (now {} nodes, {} cells; the run \
                 had {} nodes, {} cells; node coordinates or connectivity differ): restore \
                 that mesh file",
                mesh.path.display(),
                mesh.nodes.len(),
                mesh.n_cells(),
                self.id.nodes,
                self.id.triangles
            ));
        } else if groups_fingerprint(mesh) != self.id.groups_fingerprint {
            diffs.push(format!(
                "the physical groups of the mesh {} differ from the run's: restore that mesh \
                 file",
                mesh.path.display()
            ));
        }
        let now = physics_signature(&scene.text);
        let stored = &self.id.physics;
        for (k, v) in stored {
            match now.iter().find(|(k2, _)| k2 == k) {
                Some((_, v2)) if v2 == v => {}
                Some((_, v2)) => diffs.push(format!("{k}: the run had {v}, the scene says {v2}")),
                None => diffs.push(format!("{k}: the run had {v}, the scene has no such key")),
            }
        }
        for (k, v) in &now {
            if !stored.iter().any(|(k2, _)| k2 == k) {
                diffs.push(format!("{k}: the run had no such key, the scene says {v}"));
            }
        }
        let k_scene = scene.k();
        if (k_scene - self.k).abs() > 1e-9 * self.k {
            diffs.push(format!(
                "step size: the run had k = {}, the scene gives k = {} / {} = {k_scene}",
                self.k, scene.end, scene.steps
            ));
        }
        let dof_of: Vec<i64> = disc
            .free
            .iter()
            .map(|d| d.map_or(-1, |i| i as i64))
            .collect();
        if diffs.is_empty() && dof_of != self.id.dof_of {
            diffs.push(
                "the clamped dofs (Γ1) differ from the run's: check mesh.groups.fixed".into(),
            );
        }
        if diffs.is_empty() {
            return Ok(());
        }
        Err(Error::input(format!(
            "{shown}: cannot resume, the checkpoint does not match its scene:\n  - {}",
            diffs.join("\n  - ")
        )))
    }

    /// Puts the saved state into a freshly built time loop (of the scene from
    /// [`Checkpoint::scene`]): n, k, u with its compensation, the memory, w and z. For a
    /// general kernel the past displacements are read from the history file and their hash
    /// checked.
    pub fn restore(&self, tl: &mut TimeLoop) -> Result<()> {
        let shown = self.path.display();
        let n_free = tl.disc.n_free;
        let sizes = [
            ("state/u", self.u.len(), n_free),
            ("state/u_sum", self.u_sum.len(), n_free),
            ("state/u_comp", self.u_comp.len(), n_free),
            ("state/w", self.w.len(), n_free),
            ("state/z", self.z.len(), tl.rows.len()),
        ];
        for (name, have, want) in sizes {
            if have != want {
                return Err(Error::input(format!(
                    "{shown}: {name} has {have} values but the scene's discretization needs \
                     {want}: the checkpoint does not belong to this scene and mesh"
                )));
            }
        }
        let h = &mut tl.history;
        let mismatch = |what: &str| {
            Error::input(format!(
                "{shown}: the stored memory is {what}, which the scene's relaxation kernel \
                 does not match: the checkpoint does not belong to this scene"
            ))
        };
        match (&mut h.memory, &self.memory) {
            (Memory::None, StoredMemory::None) => {}
            (Memory::Prony(terms), StoredMemory::Prony { a, decay, m }) => {
                if terms.len() != a.len() {
                    return Err(mismatch(&format!("{} Prony terms", a.len())));
                }
                for (i, t) in terms.iter_mut().enumerate() {
                    // decay = exp(−b k) is recomputed by History::new from the scene's b and
                    // the same k: equal bits unless the kernel changed.
                    let expected = (t.decay.ln() / h.k) * self.k;
                    if t.a.to_bits() != a[i].to_bits()
                        || (expected.exp() - decay[i]).abs() > 1e-12 * decay[i].abs()
                    {
                        return Err(mismatch(&format!(
                            "term {i}: a = {}, exp(-b k) = {}",
                            a[i], decay[i]
                        )));
                    }
                    if m[i].len() != n_free {
                        return Err(mismatch(&format!("term {i} of the wrong size")));
                    }
                    *t = PronyTerm {
                        a: a[i],
                        decay: decay[i],
                        m: m[i].clone(),
                    };
                }
            }
            (
                Memory::Direct { past, r_lag },
                StoredMemory::Direct {
                    file, rows, hash, ..
                },
            ) => {
                if *rows != self.n {
                    return Err(mismatch(&format!("{rows} history rows at step {}", self.n)));
                }
                *past = read_history(&self.dir().join(file), *rows, *hash, n_free, &self.id)?;
                r_lag.clear();
            }
            (_, StoredMemory::None) => return Err(mismatch("absent (no relaxation)")),
            (_, StoredMemory::Prony { .. }) => return Err(mismatch("a Prony series")),
            (_, StoredMemory::Direct { .. }) => {
                return Err(mismatch("a general kernel's direct sum"))
            }
        }
        h.k = self.k;
        h.n = self.n;
        h.u.clone_from(&self.u);
        h.u_sum.clone_from(&self.u_sum);
        h.u_comp.clone_from(&self.u_comp);
        tl.w.clone_from(&self.w);
        tl.z.clone_from(&self.z);
        Ok(())
    }
}

/// Rows 0..rows of a history file, checked against the checkpoint's run id and hash.
fn read_history(
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn physics_signature_skips_resumable_keys() {
        let text = "name = \"a\"\n[time]\nend = 1.0\nsteps = 4\n[output]\nevery = 2\n\
                    [material.viscosity]\ntheta = 0.1\n[[load.traction]]\non = \"top\"\n\
                    value = [\"0\", \"1\"]\n";
        let sig = physics_signature(text);
        assert_eq!(
            sig,
            vec![
                ("load.traction[0].on".to_string(), "\"top\"".to_string()),
                (
                    "load.traction[0].value".to_string(),
                    "[\"0\", \"1\"]".to_string()
                ),
                ("material.viscosity.theta".to_string(), "0.1".to_string()),
            ]
        );
    }

    #[test]
    fn hash_tells_bits_apart() {
        let (mut a, mut b) = (Hash64::default(), Hash64::default());
        a.f64s(&[0.0, 1.0]);
        b.f64s(&[-0.0, 1.0]);
        assert_ne!(a, b);
        let mut c = Hash64::default();
        c.f64s(&[0.0]);
        c.f64s(&[1.0]);
        assert_eq!(
            a, c,
            "a running hash does not depend on how rows are grouped"
        );
    }
}
