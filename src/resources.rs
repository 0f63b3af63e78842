//! What a run will hold in memory and write to disk, estimated before it starts from the
//! scene's sizes, and refused when this machine cannot hold it (`time.steps = 10^12` once
//! passed `check` and then aborted in an allocation, or grew a 631 GB history file).
//!
//! What grows with the number of steps N is counted, and the memory sum's states; the mesh,
//! the matrices and their factor are the same for N = 10 and N = 10^9 and are known to fit
//! once setup has built them. With d free dofs, n nodes and c cells:
//!
//! - memory: a general kernel's direct sum keeps u_0..u_N (8 d (N+1) bytes) and r at every
//!   lag (8 (N+1)), and a checkpoint holds a few of the rows no checkpoint holds yet once
//!   more as they stream to its writer (as the Prony states below do); every kernel keeps
//!   the per-step iteration counts (8 N). A
//!   compressed kernel (expr or table, `memory = "compressed"`) counts its fit, 16 bytes per
//!   lag up to max(N, horizon/k) (r and the certificate's deviation, `kernel_fit`), and the
//!   direct sum's rows only when its run may fall back to it (N ≤ `kernel_fit::EXACT_STEPS`;
//!   a longer one is refused instead). The Prony states are 8 d bytes a term, of which a
//!   checkpoint holds a few more at once as they stream to its writer (at most 16 MiB
//!   waiting and two more, `history::held_bytes`; `Held::gathered`): a scene's own
//!   series' from the start,
//!   every term's once the kernels' plans are known ([`Estimate::with_plans`]: after the
//!   sizes above passed, since a plan evaluates the kernel on every lag; a compressed
//!   kernel's fit too), and then the direct sum's rows only where it runs (`study`'s
//!   packing of cases plans before any fit). Over several MPI ranks
//!   ([`Estimate::largest_rank`]) rank 0 holds the memory at the dofs it reads alone and
//!   gathers it at each checkpoint a few vectors at a time (the Prony states, a direct
//!   sum's rows that no checkpoint holds yet);
//! - disk: a frame every `output.every` steps (`frame_bytes`: the values of the fields
//!   written, at `output.precision`, the points and the cells; zlib, the default, keeps the
//!   values that are in general nonzero and about a fifth of the rest, the zeros and the
//!   integers), and for a general kernel the history file (8 d (N+1) bytes);
//! - files: a `.vtu` series writes one file per frame and its `.pvd`, a `.vtkhdf` series one
//!   file; the run directory's own files (summary, lock, checkpoint, history file and their
//!   temporaries) are covered by a margin of 16 files.
//!
//! A run is refused when the memory estimate exceeds 80 % of the memory available
//! (`available_memory`: `VISCONTACT_MEMORY` where set, else `MemAvailable` of /proc/meminfo),
//! the disk estimate exceeds 80 % of the space free to this user on the output directory's
//! file system, or the file count exceeds 80 % of the inodes free to this user there
//! (statvfs): the margin covers what the estimate leaves out and the other programs of the
//! machine. A file system that reports no inodes at all (0 in total: some network and
//! overlay file systems) does not count them and is not refused for them.

use crate::fem::Discretization;
use crate::history::{held_bytes, Plans};
use crate::kernel::Kernel;
use crate::kernel_fit::EXACT_STEPS;
use crate::output::{Compression, Format, Precision};
use crate::scene::{Model, Scene};
use crate::{Error, Result};
use std::path::{Path, PathBuf};

/// The share of available memory, free disk or free inodes a run may plan to use.
pub const MARGIN: f64 = 0.8;

/// The files a run directory holds besides its series: summary.json, the lock, the
/// checkpoint and history files and their temporaries, with room to spare.
const SPARE_FILES: f64 = 16.0;

/// A run's estimated memory and disk use, in bytes, and the files it creates, for its steps
/// from `from` on: what its steps hold ([`Estimate::memory`], one process's) and the
/// bytes of its frames, besides which a direct sum writes its history file
/// ([`Estimate::disk`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Estimate {
    held: Held,
    frames: f64,
    pub files: f64,
}

/// The bytes of what a run's steps hold: the memory sum's at every dof and the rest.
#[derive(Clone, Debug, Default, PartialEq)]
struct Held {
    /// A direct sum's past rows, 8 d (N + 1).
    rows: f64,
    /// The Prony states, 8 d a term: of the scene's own series, then of every term the
    /// plans run (a compressed kernel's fit too).
    states: f64,
    /// What a checkpoint holds at once of the states and of a direct sum's rows, as they
    /// stream to its writer a vector at a time (`history::held_bytes`): a few, at most all.
    streamed: Streamed,
    /// What no rank count divides: r at every lag, the fit, the iteration counts.
    rest: f64,
    /// Whether checkpoints are written, which gather the memory.
    checkpoints: bool,
}

/// What a checkpoint holds at once of the memory it streams to its writer, in bytes.
#[derive(Clone, Debug, Default, PartialEq)]
struct Streamed {
    /// Of the Prony states.
    states: f64,
    /// Of a direct sum's rows that no checkpoint holds yet.
    rows: f64,
}

impl Held {
    /// What a checkpoint adds to the process that writes it, the memory gathered at every
    /// dof that streams to the writer at once (`checkpoint::Feed`); and the rest.
    fn gathered(&self) -> f64 {
        let checkpoint = if self.checkpoints { 1.0 } else { 0.0 };
        self.rest + checkpoint * (self.streamed.states + self.streamed.rows)
    }

    /// The key that lowers the most of what it holds.
    fn key(&self) -> &'static str {
        match (self.rows > 0.0, self.states > self.rest) {
            (true, _) => DIRECT_KEY,
            (false, true) => TERMS_KEY,
            (false, false) => STEPS_KEY,
        }
    }

    /// One process's: every dof's memory, and what a checkpoint gathers.
    fn one_process(&self) -> f64 {
        self.gathered() + self.rows + self.states
    }
}

/// The Prony terms that `scene` gives as series (`prony = [...]`), the body's and its
/// regions': known before any fit, which a compressed kernel's terms are not.
fn given_terms(scene: &Scene) -> usize {
    let body = scene.physics.relaxation.as_ref();
    let regions = scene.physics.region_kernels();
    let kernels = body
        .into_iter()
        .chain(regions.iter().filter_map(|(_, r)| r.kernel.as_ref()));
    kernels
        .map(|k| match k {
            Kernel::Prony(terms) => terms.len(),
            _ => 0,
        })
        .sum()
}

/// The key an estimate names when its memory does not fit.
const STEPS_KEY: &str = "time.steps";
const DIRECT_KEY: &str = "time.steps (a general kernel keeps every step's displacement; a \
                          Prony kernel, material.relaxation.prony, keeps O(1) per step)";
const TERMS_KEY: &str = "the kernels' terms (each Prony term keeps a value at every dof: a \
                         shorter series, or a compressed kernel's looser tolerance or horizon)";

impl Estimate {
    /// The memory one process's steps hold, in bytes.
    pub fn memory(&self) -> f64 {
        self.held.one_process()
    }

    /// The bytes written: the frames, and with checkpoints a direct sum's history file.
    pub fn disk(&self) -> f64 {
        self.frames
            + if self.held.checkpoints {
                self.held.rows
            } else {
                0.0
            }
    }

    /// The key to change when the memory does not fit (with why, for a general kernel).
    pub fn memory_key(&self) -> &'static str {
        self.held.key()
    }

    /// The estimate for a run of `scene` (its `time.steps` N) continuing from step `from`
    /// (0 for a new run; a resumed run writes only the rest), before its kernels' plans.
    pub fn new(scene: &Scene, disc: &Discretization, from: usize) -> Estimate {
        let steps = scene.time.steps as f64;
        let d = disc.n_free as f64;
        let general = matches!(
            scene.physics.relaxation,
            Some(Kernel::Expr(_) | Kernel::Table(..))
        );
        let compressed = general && scene.physics.compression.is_some();
        let direct = general && (!compressed || scene.time.steps <= EXACT_STEPS);
        let fit = match (compressed, scene.physics.horizon) {
            (false, _) => 0.0,
            (true, None) => 16.0 * (steps + 1.0),
            (true, Some(h)) => 16.0 * ((h / scene.time.k()).ceil().max(steps) + 1.0),
        };
        let held = Held {
            rows: if direct { 8.0 * d * (steps + 1.0) } else { 0.0 },
            states: 8.0 * d * given_terms(scene) as f64,
            streamed: Streamed {
                states: held_bytes(disc.n_free, given_terms(scene)),
                rows: if direct {
                    held_bytes(disc.n_free, scene.time.steps.saturating_add(1))
                } else {
                    0.0
                },
            },
            rest: if direct { 8.0 * (steps + 1.0) } else { 0.0 } + fit + 8.0 * steps,
            checkpoints: scene.checkpoint.enabled,
        };
        let remaining = (scene.time.steps.saturating_sub(from) + 1) as f64;
        let frames = (remaining / scene.output.every as f64).ceil() + 1.0;
        let frame = frame_bytes(scene, disc);
        let series = match scene.output.options.format {
            Format::Vtu => frames + 1.0,
            Format::Vtkhdf => 1.0,
        };
        Estimate {
            held,
            frames: frames * frame,
            files: series + SPARE_FILES,
        }
    }

    /// The estimate once the kernels' `plans` are known, for `disc`'s dofs: the direct
    /// sum's rows where it runs (not where a compressed kernel might have fallen back to
    /// it and did not), and the Prony states of every term.
    pub fn with_plans(mut self, plans: &Plans, disc: &Discretization) -> Estimate {
        let d = disc.n_free as f64;
        if !plans.direct() {
            (self.held.rows, self.held.streamed.rows) = (0.0, 0.0);
        }
        self.held.states = 8.0 * d * plans.terms() as f64;
        self.held.streamed.states = held_bytes(disc.n_free, plans.terms());
        self
    }

    /// What the steps hold on the largest of several ranks, rank 0, which holds the memory
    /// at a fraction of the dofs (those its steps and history.csv read, and its own rows;
    /// every dof where it holds them all: `ranks::Plan`) and gathers the rest at each
    /// checkpoint a few vectors at a time: (what no rank count lowers, the memory at every
    /// dof, of which it holds that fraction).
    pub fn largest_rank(&self) -> (f64, f64) {
        (self.held.gathered(), self.held.rows + self.held.states)
    }

    /// Refuses (exit 2, the estimate and what to change) a run this machine cannot hold:
    /// memory beyond 80 % of what is available, disk beyond 80 % of what is free where `out`
    /// (or its nearest existing parent) is. Unknown capacities (no /proc/meminfo) pass.
    pub fn check(&self, out: &Path) -> Result<()> {
        if let Some(avail) = available_memory()? {
            if self.memory() > MARGIN * avail {
                return Err(Error::input(format!(
                    "the run would need ≈ {} of memory for its steps but {} (a run may plan \
                     {:.0} % of it): lower {}",
                    human(self.memory()),
                    memory_phrase(avail),
                    100.0 * MARGIN,
                    self.memory_key()
                )));
            }
        }
        if let Some(fs) = FileSystem::of(out) {
            self.check_file_system(&fs)?;
        }
        Ok(())
    }

    /// Refuses (exit 2) a run whose frames and history exceed 80 % of the bytes free on `fs`,
    /// or whose files exceed 80 % of its free inodes (not counted where it reports none).
    fn check_file_system(&self, fs: &FileSystem) -> Result<()> {
        if self.disk() > MARGIN * fs.bytes_free {
            return Err(Error::input(format!(
                "the run would write ≈ {} but {} has {} free (a run may plan {:.0} % of \
                 it): lower time.steps, raise output.every, or give --out on a larger disk",
                human(self.disk()),
                fs.dir.display(),
                human(fs.bytes_free),
                100.0 * MARGIN
            )));
        }
        if fs.inodes_total > 0.0 && self.files > MARGIN * fs.inodes_free {
            return Err(Error::input(format!(
                "the run would create ≈ {:.0} files but {} has {:.0} free inodes (a run may \
                 plan {:.0} % of them): raise output.every, write output.format = \"vtkhdf\" \
                 (one file), or give --out on another file system",
                self.files,
                fs.dir.display(),
                fs.inodes_free,
                100.0 * MARGIN
            )));
        }
        Ok(())
    }
}

impl std::fmt::Display for Estimate {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        write!(
            f,
            "≈ {} of memory and {} of disk for the steps (what grows with them, and the \
             memory sum's values at every dof)",
            human(self.memory()),
            human(self.disk())
        )
    }
}

/// Memory a run holds besides what grows with its steps (the mesh, the matrices and, for a
/// study's small cases, the factor of K_A), which `check`'s estimate leaves out: counted for
/// each case that `study --jobs` packs, in the `--mem` of a study's job array and in that of
/// `run --emit slurm` (which adds the factor and the contact solver's matrices). Large 3D
/// meshes need more.
pub const SETUP_MEMORY: f64 = 1024.0 * 1024.0 * 1024.0;

pub fn human(bytes: f64) -> String {
    match bytes {
        b if b >= 1e12 => format!("{:.1} TB", b / 1e12),
        b if b >= 1e9 => format!("{:.1} GB", b / 1e9),
        b => format!("{:.1} MB", b / 1e6),
    }
}

/// The memory of the dense condensed dual (`solver::dual`) on m constraint rows touching c
/// dofs, in bytes: while it condenses, at most the trailing block L_CC (c²), G = L_CC⁻¹ E
/// (c m) and D (m²); then D, B = D⁻¹ in 3D (`block` = 2) and the Newton matrix with its
/// factor (up to m² each; the factor in f64, or in f32 from `DualSettings::single_min` rows
/// on, never both large at once); 8 bytes a value. G is not kept: a step applies it by
/// passes over L_CC (`Factor::trailing_forward`, `trailing_backward`).
pub fn dense_dual_bytes(m: usize, c: usize, block: usize) -> f64 {
    let (m, c) = (m as f64, c as f64);
    let inverse = if block == 2 { 1.0 } else { 0.0 };
    8.0 * (c * c + c * m + m * m).max((3.0 + inverse) * m * m)
}

/// The memory of the duals without D (`solver::matrix_free`) on m rows of a problem with n
/// dofs, in bytes: three n-vectors for its solves and about twenty m-vectors, besides the
/// factor of K_A that every solver holds.
pub fn matrix_free_bytes(m: usize, n: usize) -> f64 {
    8.0 * (3.0 * n as f64 + 20.0 * m as f64)
}

/// The memory of the active-set solver (`solver::active_set`) on m rows of a problem with n
/// dofs whose K_A stores `nnz` entries (both triangles), in bytes: one n-vector (the
/// Krylov's rows of a Newton system's right side and of (K + S)w: `petsc::Krylov`); per
/// row, a removed direction or a share of a slip block (three dofs and up to nine values),
/// and at most a node's dofs, b − f_slip, the right side and (K + S)w there (84 bytes); and
/// PETSc's part on one rank (`petsc_bytes`).
pub fn active_set_bytes(m: usize, n: usize, nnz: usize) -> f64 {
    8.0 * n as f64 + 168.0 * m as f64 + petsc_bytes(nnz, true, 1)
}

/// PETSc's part of a run through it on a rank that holds `entries` of K_A's, in bytes, on
/// one of `ranks` ranks, with the active set's Newton systems where `newton`: what the
/// rank holds at its peak beyond its own part (its setup's peak, less on several ranks what
/// of K_A, K_B and K_R it drops: `ranks::Plan`), fitted to the fine plate's
/// peaks (367 470 dofs, 16.0 M entries, a setup peak of 1.17 GB; docs/cluster.md,
/// "Planning"). Counted from the matrices alone, AIJ at 12 bytes an entry, it would be K_A
/// and GAMG's hierarchy (0.8 of it), 21.6 bytes an entry, and for the active set the
/// Newton matrix N and Q, the N its multigrid was built from, Q's hierarchy and K_A's
/// coarse operators (0.4), 50.4 bytes an entry (K_A's own hierarchy is never built there);
/// the runs' peaks held 48 and 75 bytes an entry on one rank (GAMG's setup and the Krylov
/// vectors besides) and 74 and 76 on the largest of two (the off-rank blocks, their column
/// maps and message buffers, GAMG's Galerkin products' data for reuse until the shim frees
/// it, and the rank's rows of K_A in PETSc's numbering, which it hands over instead of
/// keeping K_A's columns: `ranks::Own`; K_A's own matrix goes before GAMG's setup, and the
/// Newton matrix is made after it).
pub fn petsc_bytes(entries: usize, newton: bool, ranks: usize) -> f64 {
    let per_entry = match (newton, ranks) {
        (false, 1) => 48.0,
        (false, _) => 74.0,
        (true, 1) => 75.0,
        (true, _) => 76.0,
    };
    per_entry * entries as f64
}

/// Hands back to the system the heap pages of the blocks freed so far (glibc's
/// `malloc_trim`; nothing elsewhere). glibc keeps the pages of freed blocks below its mmap
/// threshold, so a rank's resident memory kept the matrices it had dropped (the whole
/// ones, for its own columns, or its columns of K_A, for PETSc's rows:
/// `Ranks::keep_own_columns`) and PETSc's setup transients: on two ranks of
/// the fine plate 0.60 GB a rank after the columns were kept (docs/cluster.md, "Memory
/// per rank"). Called where a setup stage has just freed much; it takes milliseconds.
pub fn return_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: malloc_trim releases only memory that the allocator holds free.
    unsafe {
        libc::malloc_trim(0);
    }
}

/// The most memory this process has held so far, in bytes: its resident peak (`VmHWM` of
/// /proc/self/status); None where the system does not say.
pub fn peak_memory() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024.0)
}

/// Refuses (exit 2) a Cholesky factor of K_A (`n` unknowns) whose values, `bytes` by its
/// symbolic analysis, exceed `MARGIN` of the memory available (unknown: it passes): the
/// allocation would otherwise fail (the process aborts) or the machine swap, after the
/// ordering's minutes. The remedy is the backend without a factor.
pub fn check_factor(bytes: f64, n: usize) -> Result<()> {
    match available_memory()? {
        Some(avail) if bytes > MARGIN * avail => Err(Error::input(format!(
            "the Cholesky factor of K_A ({n} unknowns) would need ≈ {} for its values alone \
             but {} (a run may plan {:.0} % of it): use a coarser mesh, or a build with PETSc \
             (cargo build --release --features petsc), which solves K_A without a factor: \
             [solver] linear = \"petsc\" (with contact, contact = \"active_set\")",
            human(bytes),
            memory_phrase(avail),
            100.0 * MARGIN
        ))),
        _ => Ok(()),
    }
}

/// What ordering c constrained dofs last adds to a run's peak memory, in bytes: their block of
/// L is the factor of the Schur complement on C, dense, and faer factors the root supernode
/// that holds it as a full square (8c²) before it is repacked, with its factorization's
/// workspace beside it. Measured above the fill-reducing order's peak: 13.8c² on the plate
/// of issue 29 at size 0.015 (c = 16 125: 8.12 GB against 4.52 GB), about 14c² at size 0.03
/// (c ≈ 4 300: 261 MB); 16c² bounds both.
pub fn trailing_bytes(c: usize) -> f64 {
    16.0 * (c as f64).powi(2)
}

/// The environment variable that gives the memory a run may plan with, in bytes, instead of
/// `MemAvailable`: a share of a machine that others use too, or a batch job's memory limit.
pub const MEMORY_ENV: &str = "VISCONTACT_MEMORY";

/// The memory available to a run, in bytes: `VISCONTACT_MEMORY` where set, else
/// `MemAvailable` of /proc/meminfo (None where neither says). A `VISCONTACT_MEMORY` that is
/// not a number of bytes > 0 is bad input.
pub fn available_memory() -> Result<Option<f64>> {
    match std::env::var(MEMORY_ENV) {
        Ok(text) => parse_bytes(&text).map(Some).ok_or_else(|| {
            Error::input(format!(
                "{MEMORY_ENV}={text:?}: expected the memory available to a run in bytes, a \
                 number > 0 (8e9 for 8 GB)"
            ))
        }),
        Err(std::env::VarError::NotPresent) => Ok(mem_available()),
        Err(std::env::VarError::NotUnicode(_)) => {
            Err(Error::input(format!("{MEMORY_ENV} is not valid UTF-8")))
        }
    }
}

/// "this machine has X available", or where `VISCONTACT_MEMORY` set the figure, that it did.
pub fn memory_phrase(avail: f64) -> String {
    if std::env::var_os(MEMORY_ENV).is_some() {
        format!("{MEMORY_ENV} makes {} available", human(avail))
    } else {
        format!("this machine has {} available", human(avail))
    }
}

/// A byte count as `VISCONTACT_MEMORY` writes it: a finite number > 0.
fn parse_bytes(text: &str) -> Option<f64> {
    text.trim()
        .parse()
        .ok()
        .filter(|b: &f64| b.is_finite() && *b > 0.0)
}

/// `MemAvailable` of /proc/meminfo, in bytes.
fn mem_available() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024.0)
}

/// What the file system of a directory has free to this user: bytes, and inodes out of its
/// total (0 where it does not count them).
#[derive(Clone, Debug, PartialEq)]
struct FileSystem {
    /// The directory asked about or its nearest existing parent.
    dir: PathBuf,
    bytes_free: f64,
    inodes_free: f64,
    inodes_total: f64,
}

impl FileSystem {
    /// statvfs of `dir` or of its nearest existing parent.
    fn of(dir: &Path) -> Option<FileSystem> {
        let abs = std::path::absolute(dir).ok()?;
        let existing = abs.ancestors().find(|p| p.exists())?.to_path_buf();
        let c = std::ffi::CString::new(existing.as_os_str().as_encoded_bytes()).ok()?;
        let mut s: libc::statvfs = unsafe { std::mem::zeroed() };
        // SAFETY: `c` is a NUL-terminated path and `s` a statvfs the call fills in.
        if unsafe { libc::statvfs(c.as_ptr(), &mut s) } != 0 {
            return None;
        }
        Some(FileSystem {
            dir: existing,
            bytes_free: s.f_bavail as f64 * s.f_frsize as f64,
            inodes_free: s.f_favail as f64,
            inodes_total: s.f_files as f64,
        })
    }
}

/// The share of the zeros and integers of a frame that zlib keeps, where it keeps the
/// values that are in general nonzero: measured on the examples, so that the estimate is
/// 1.0–1.3 times the frames written by the paper's example and the block, in float64 and
/// float32 (issue 49: the uncompressed size, 2.7 times the paper's, was estimated before).
const ZLIB_KEEPS: f64 = 0.2;

/// The bytes of one frame: (values in general nonzero, zeros and integers) of its points
/// (float64), its fields at `output.precision` (a 2D run's third components and the stress
/// its model keeps zero; the contact fields, zero off the contact boundary) and its cells
/// (connectivity, offsets and types; `region`); compressed as [`ZLIB_KEEPS`] says.
fn frame_bytes(scene: &Scene, disc: &Discretization) -> f64 {
    let o = &scene.output.options;
    let (n, c) = (disc.nodes.len() as f64, disc.n_cells() as f64);
    let dim = disc.dim as f64;
    let value = match o.precision {
        Precision::Float64 => 8.0,
        Precision::Float32 => 4.0,
    };
    let wants = |name: &str| if o.wants(name) { 1.0 } else { 0.0 };
    let stress = match (disc.dim, scene.mesh.model) {
        (2, Model::PlaneStress) => 3.0,
        (2, _) => 4.0,
        _ => 6.0,
    };
    let vectors = wants("displacement") + wants("velocity");
    let nonzero = 8.0 * dim * n
        + value * vectors * dim * n
        + value * c * (wants("stress") * stress + wants("von_mises"));
    let contact = wants("contact_pressure")
        + wants("contact_state")
        + wants("friction_traction") * if disc.dim == 2 { 1.0 } else { 3.0 };
    let rest = 8.0 * (3.0 - dim) * n
        + value * (vectors * (3.0 - dim) + contact) * n
        + value * wants("stress") * (6.0 - stress) * c
        + 4.0 * wants("region") * c
        + (8.0 * (dim + 1.0) + 8.0 + 1.0) * c;
    match o.compression {
        Compression::Zlib => nonzero + ZLIB_KEEPS * rest,
        Compression::None => nonzero + rest,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An estimate of `memory` bytes held by the steps (none of them the memory sum's),
    /// `disk` bytes of frames and `files` files.
    fn estimate(memory: f64, disk: f64, files: f64) -> Estimate {
        let held = Held {
            rest: memory,
            ..Held::default()
        };
        Estimate {
            held,
            frames: disk,
            files,
        }
    }

    #[test]
    fn an_impossible_estimate_is_refused_naming_the_key() {
        let e = estimate(1e30, 0.0, 1.0);
        if available_memory().unwrap().is_some() {
            let err = e.check(Path::new(".")).unwrap_err().to_string();
            assert!(
                err.contains("time.steps") && err.contains("memory"),
                "{err}"
            );
        }
        let e = estimate(0.0, 1e30, 1.0);
        let err = e.check(Path::new("no/such/dir")).unwrap_err().to_string();
        assert!(
            err.contains("output.every") && err.contains("free"),
            "{err}"
        );
        let fits = estimate(1.0, 1.0, 1.0);
        fits.check(Path::new(".")).unwrap();
    }

    #[test]
    fn a_memory_is_a_number_of_bytes_above_zero() {
        assert_eq!(parse_bytes("8e9"), Some(8e9));
        assert_eq!(parse_bytes(" 1048576 "), Some(1048576.0));
        for bad in ["", "8 GB", "0", "-1", "inf", "NaN"] {
            assert_eq!(parse_bytes(bad), None, "{bad:?}");
        }
    }

    #[test]
    fn a_series_of_more_files_than_free_inodes_is_refused_unless_inodes_are_not_counted() {
        let fs = |inodes_free: f64, inodes_total: f64| FileSystem {
            dir: PathBuf::from("/out"),
            bytes_free: 1e12,
            inodes_free,
            inodes_total,
        };
        let e = estimate(0.0, 1e6, 1001.0 + SPARE_FILES);
        let err = e
            .check_file_system(&fs(1000.0, 1e6))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("1017 files")
                && err.contains("/out has 1000 free inodes")
                && err.contains("output.every")
                && err.contains("output.format = \"vtkhdf\""),
            "{err}"
        );
        // 1017 files fit into 80 % of 1272 free inodes, not of 1270.
        e.check_file_system(&fs(1272.0, 1e6)).unwrap();
        assert!(e.check_file_system(&fs(1270.0, 1e6)).is_err());
        // A file system that counts no inodes (f_files = 0) reports none free either.
        e.check_file_system(&fs(0.0, 0.0)).unwrap();
    }
}
