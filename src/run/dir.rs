//! A run's directory holds exactly one run.
//!
//! - One process owns a directory at a time: [`DirLock`] holds an advisory lock
//!   (`flock`, std's `File::try_lock`) on `DIR/.viscontact.lock`, which the kernel releases
//!   when the process ends however it ends; a second process is refused (exit 2) with the
//!   holder's pid, host and start time, which the holder writes into the file.
//! - Files are ours by name ([`ours`]): the series (with the directories of a `.pvtu`
//!   frame's pieces), summary.json, history.csv, the checkpoint files, the
//!   lock file, and the temporary files our writers use (`.NAME.tmp.PID.N` of
//!   `output::write_atomic`, `checkpoint.h5.tmp`, `checkpoint_history.h5.tmp`). Under the
//!   lock no other process is writing, so temporary files are leftovers of a killed process
//!   and are removed ([`remove_temporaries`]); everything else in the directory is the
//!   user's and never touched.
//! - A new run replaces the old one only once its setup succeeded ([`remove_run`]), before
//!   its first frame: a run that fails during setup leaves the old run as it was.
//! - `resume` continues only the run the directory holds ([`check_same_run`]): the run id
//!   of summary.json and of a checkpoint in the directory must be the checkpoint's.

use crate::{Error, Result};
use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

/// The lock file of a run directory.
pub const LOCK_NAME: &str = ".viscontact.lock";

/// The files a run writes into its directory (besides temporaries); anything else there is
/// the user's.
fn run_file(name: &str) -> bool {
    frame_step(name).is_some()
        || matches!(
            name,
            "solution.pvd"
                | "solution.vtkhdf"
                | "history.csv"
                | "summary.json"
                | "checkpoint.h5"
                | "checkpoint_history.h5"
        )
}

/// The step of a frame's entry in a run's directory: `solution_NNNNNN.vtu`,
/// `solution_NNNNNN.pvtu` or the directory `solution_NNNNNN` of its pieces (a run over MPI
/// ranks, docs/output.md).
fn frame_step(name: &str) -> Option<usize> {
    let rest = name.strip_prefix("solution_")?;
    let digits = (rest.strip_suffix(".vtu"))
        .or(rest.strip_suffix(".pvtu"))
        .unwrap_or(rest);
    let ok = digits.len() >= 6 && digits.bytes().all(|b| b.is_ascii_digit());
    ok.then(|| digits.parse().ok()).flatten()
}

/// Whether `name` is a frame's directory of pieces (`solution_NNNNNN`).
fn piece_dir(name: &str) -> bool {
    frame_step(name).is_some() && !name.contains('.')
}

/// A piece in the directory `dir` (`solution_NNNNNN`): `solution_NNNNNN_R.vtu`, or a
/// temporary file of one.
fn piece_file(dir: &str, name: &str) -> bool {
    let piece = |n: &str| {
        (n.strip_prefix(dir))
            .and_then(|r| r.strip_prefix('_'))
            .and_then(|r| r.strip_suffix(".vtu"))
            .is_some_and(|r| !r.is_empty() && r.bytes().all(|b| b.is_ascii_digit()))
    };
    piece(name) || temporary_of(name, piece)
}

/// Removes the entry `name` of `dir`, a file of ours or a directory of pieces: its pieces,
/// then the directory, which stays if it holds anything else (the user's).
fn remove_entry(dir: &Path, name: &str) -> std::io::Result<()> {
    let path = dir.join(name);
    if !(piece_dir(name) && path.is_dir()) {
        return std::fs::remove_file(path);
    }
    for piece in entries(&path, |n| piece_file(name, n)) {
        std::fs::remove_file(path.join(piece))?;
    }
    let _ = std::fs::remove_dir(path);
    Ok(())
}

/// A temporary file of our writers: `checkpoint.h5.tmp`, `checkpoint_history.h5.tmp`,
/// `checkpoint.h5.states.tmp` (a copy whose Prony states a checkpoint reads back:
/// `checkpoint::Writer`), or `.NAME.tmp.PID.N` (`output::write_atomic`) for a NAME of ours.
fn temporary(name: &str) -> bool {
    if let Some(base) = name.strip_suffix(".tmp") {
        return matches!(
            base,
            "checkpoint.h5" | "checkpoint_history.h5" | "checkpoint.h5.states"
        );
    }
    temporary_of(name, run_file)
}

/// `.NAME.tmp.PID.N` for a NAME that `ours` selects.
fn temporary_of(name: &str, ours: impl Fn(&str) -> bool) -> bool {
    let Some(rest) = name.strip_prefix('.') else {
        return false;
    };
    let mut parts = rest.rsplitn(3, '.');
    let (Some(n), Some(pid), Some(head)) = (parts.next(), parts.next(), parts.next()) else {
        return false;
    };
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    digits(n) && digits(pid) && head.strip_suffix(".tmp").is_some_and(ours)
}

/// Every file a run of viscontact writes into its directory.
pub fn ours(name: &str) -> bool {
    run_file(name) || temporary(name) || name == LOCK_NAME
}

/// Names of the directory's entries that `keep` selects (none if it does not exist).
fn entries(dir: &Path, keep: impl Fn(&str) -> bool) -> Vec<String> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut names: Vec<String> = entries
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| keep(n))
        .collect();
    names.sort();
    names
}

/// Refuses an output path that is an existing file, and a directory holding files
/// viscontact did not write unless `force`.
pub fn check_out_dir(out: &Path, force: bool) -> Result<()> {
    if out.exists() && !out.is_dir() {
        return Err(Error::input(format!(
            "output directory '{}' is an existing file, not a directory; choose another --out \
             (a directory, created if missing)",
            out.display()
        )));
    }
    let foreign = entries(out, |n| !ours(n));
    if foreign.is_empty() || force {
        return Ok(());
    }
    Err(Error::input(format!(
        "output directory '{}' holds files viscontact did not write ({}{}); choose another \
         --out, or pass --force to write beside them (they are never touched)",
        out.display(),
        foreign
            .iter()
            .take(3)
            .map(|n| format!("'{n}'"))
            .collect::<Vec<_>>()
            .join(", "),
        if foreign.len() > 3 { ", …" } else { "" }
    )))
}

/// A lock found held is tried again BUSY_RETRIES times, BUSY_WAIT apart, before the
/// directory counts as in use. A lock released by this process can stay held for a moment:
/// a child that another thread is starting shares the lock's open file until it has
/// executed its program (seen once in the test suite under a load of 14: a resume right
/// after a run in the same process was refused). A real owner is refused 0.5 s later.
const BUSY_RETRIES: usize = 10;
const BUSY_WAIT: std::time::Duration = std::time::Duration::from_millis(50);

/// Exclusive ownership of a run directory for the life of this value (or of the process).
///
/// Two locks, both `flock`, both released by the kernel however the process ends:
/// - on the directory itself, the guard: deleting `.viscontact.lock` while a run holds the
///   directory cannot let a second run in (it used to: both exited 0 and the directory held
///   frames of one run beside the .pvd and summary of the other);
/// - on `.viscontact.lock`, which says who holds the directory (and keeps out a viscontact
///   that only knows this lock). The lock file is removed when the owner is done, while
///   still locked; a process that opened the old file just before finds, once it holds the
///   lock, that the path names another file (or none) and tries again, so two owners never
///   hold locks on different files of one name. The directory's identity is checked the
///   same way.
#[derive(Debug)]
pub struct DirLock {
    file: File,
    /// Held open for its lock.
    _dir: File,
    path: PathBuf,
    /// The directory did not exist before this run created it.
    created: bool,
}

impl DirLock {
    /// Creates `dir` if missing and locks it for `command` ("run" or "resume"), or refuses
    /// (exit 2) naming the process that holds it.
    pub fn acquire(dir: &Path, command: &str) -> Result<DirLock> {
        let created = !dir.exists();
        std::fs::create_dir_all(dir).map_err(|e| {
            Error::input(format!(
                "output directory '{}' cannot be created ({e}); choose another --out",
                dir.display()
            ))
        })?;
        let path = dir.join(LOCK_NAME);
        let in_use = || {
            let holder = std::fs::read_to_string(&path).unwrap_or_default();
            let holder = holder.trim();
            Error::input(format!(
                "output directory '{}' is in use by another viscontact process ({}); wait \
                 until it ends, or choose another --out",
                dir.display(),
                if holder.is_empty() {
                    format!("which has not yet said who it is, or whose {LOCK_NAME} was deleted")
                } else {
                    holder.replace('\n', ", ")
                }
            ))
        };
        let locked = |p: &Path, open: &dyn Fn() -> std::io::Result<File>| {
            let mut busy = 0;
            loop {
                let file = open().map_err(|e| Error::io(p, e))?;
                match file.try_lock() {
                    Ok(()) if same_file(&file, p) => return Ok(file),
                    Ok(()) => {}
                    Err(std::fs::TryLockError::WouldBlock) if busy < BUSY_RETRIES => {
                        busy += 1;
                        std::thread::sleep(BUSY_WAIT);
                    }
                    Err(std::fs::TryLockError::WouldBlock) => return Err(in_use()),
                    Err(std::fs::TryLockError::Error(e)) => return Err(Error::io(p, e)),
                }
            }
        };
        let dir_file = locked(dir, &|| File::open(dir))?;
        let file = locked(&path, &|| {
            OpenOptions::new()
                .read(true)
                .write(true)
                .create(true)
                .truncate(false)
                .open(&path)
        })?;
        let mut lock = DirLock {
            file,
            _dir: dir_file,
            path,
            created,
        };
        lock.describe(command)
            .map_err(|e| Error::io(&lock.path, e))?;
        Ok(lock)
    }

    /// Writes who holds the lock: pid, host, start time, command.
    fn describe(&mut self, command: &str) -> std::io::Result<()> {
        let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
            .ok()
            .or_else(|| std::env::var("HOSTNAME").ok())
            .map(|h| h.trim().to_string())
            .filter(|h| !h.is_empty())
            .unwrap_or_else(|| "an unknown host".into());
        let text = format!(
            "pid {}\nhost {host}\nstarted {}\ncommand viscontact {command}\n",
            std::process::id(),
            humantime::format_rfc3339_seconds(std::time::SystemTime::now())
        );
        self.file.set_len(0)?;
        self.file.write_all(text.as_bytes())?;
        self.file.flush()
    }
}

impl Drop for DirLock {
    /// Removes the lock file (still locked), and the directory if this run created it and
    /// left nothing in it (its setup failed).
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
        if let (true, Some(dir)) = (self.created, self.path.parent()) {
            let _ = std::fs::remove_dir(dir);
        }
    }
}

/// Whether `path` names the open file `file` (not a file that replaced it, nor nothing).
fn same_file(file: &File, path: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (file.metadata(), std::fs::metadata(path)) {
        (Ok(a), Ok(b)) => a.ino() == b.ino() && a.dev() == b.dev(),
        _ => false,
    }
}

/// Removes what killed processes left half-written (only under the lock).
pub fn remove_temporaries(dir: &Path) {
    for name in entries(dir, temporary) {
        let _ = std::fs::remove_file(dir.join(name));
    }
    for pieces in entries(dir, piece_dir) {
        let path = dir.join(&pieces);
        for name in entries(&path, |n| temporary_of(n, |m| piece_file(&pieces, m))) {
            let _ = std::fs::remove_file(path.join(name));
        }
    }
}

/// Removes the run the directory holds (only under the lock, once the new run's setup
/// succeeded): its series, summary, checkpoints and leftovers. The user's files stay.
pub fn remove_run(dir: &Path) -> Result<()> {
    for name in entries(dir, |n| run_file(n) || temporary(n)) {
        remove_entry(dir, &name).map_err(|e| Error::io(&dir.join(&name), e))?;
    }
    Ok(())
}

/// The run id summary.json records, if it records one.
fn summary_run_id(dir: &Path) -> Option<String> {
    summary(dir)?.get("run_id")?.as_str().map(str::to_string)
}

/// `dir`'s summary.json, if it has one that reads.
fn summary(dir: &Path) -> Option<serde_json::Value> {
    let text = std::fs::read_to_string(dir.join("summary.json")).ok()?;
    serde_json::from_str(&text).ok()
}

/// Whether `dir`'s summary.json says that run `run_id` completed.
pub fn completed(dir: &Path, run_id: &str) -> bool {
    summary(dir).is_some_and(|v| v["run_id"] == run_id && v["status"] == "completed")
}

/// Refuses to resume run `run_id` (of `checkpoint`) into `dir` when `dir` holds another run:
/// a summary.json or a checkpoint.h5 of another run id, or, in a directory that is not the
/// checkpoint's own, frames or a history.csv whose run no file identifies.
pub fn check_same_run(dir: &Path, checkpoint: &Path, run_id: &str) -> Result<()> {
    let refuse = |what: String| {
        Err(Error::input(format!(
            "output directory '{}' holds another run than the checkpoint {} (run {run_id}): \
             {what}; resume into the checkpoint's own directory or an empty one",
            dir.display(),
            checkpoint.display()
        )))
    };
    let theirs = dir.join(crate::checkpoint::FILE_NAME);
    let (dir_c, theirs_c, cp_c) = (
        dir.canonicalize().ok(),
        theirs.canonicalize().ok(),
        checkpoint.canonicalize().ok(),
    );
    // The checkpoint being resumed names the run of its own directory's frames.
    let mut identified = cp_c
        .as_ref()
        .is_some_and(|c| c.parent() == dir_c.as_deref());
    let is_the_checkpoint = theirs_c.is_some() && theirs_c == cp_c;
    if let Some(other) = summary_run_id(dir) {
        if other != run_id {
            return refuse(format!("summary.json of run {other}"));
        }
        identified = true;
    }
    if theirs.exists() && !is_the_checkpoint {
        match crate::checkpoint::Checkpoint::read(&theirs) {
            Ok(cp) if cp.id.run_id == run_id => identified = true,
            Ok(cp) => return refuse(format!("checkpoint.h5 of run {}", cp.id.run_id)),
            Err(e) => return refuse(format!("a checkpoint.h5 that cannot be read: {e}")),
        }
    }
    // Frames, or a history.csv alone (named last: the series says more).
    let files = entries(dir, run_file);
    let named = (files.iter().find(|n| *n != "history.csv")).or(files.first());
    if let Some(name) = named.filter(|_| !identified) {
        return refuse(format!(
            "'{name}' and no summary.json or checkpoint.h5 naming its run"
        ));
    }
    Ok(())
}

/// Whether `dir` is the directory of `checkpoint` (both exist and are the same).
pub fn is_checkpoint_dir(dir: &Path, checkpoint: &Path) -> bool {
    let parent = checkpoint
        .canonicalize()
        .ok()
        .and_then(|c| c.parent().map(Path::to_path_buf));
    parent.is_some() && dir.canonicalize().ok() == parent
}

/// Whether `dir` holds any file of a series (`.vtu` frames, `solution.pvd`,
/// `solution.vtkhdf`).
pub fn holds_series(dir: &Path) -> bool {
    !entries(dir, |n| {
        run_file(n)
            && !matches!(
                n,
                "summary.json" | "history.csv" | "checkpoint.h5" | "checkpoint_history.h5"
            )
    })
    .is_empty()
}

/// After a resume: frames of steps ≥ `from` left by the interrupted run that the finished
/// series does not list (a run extended past its old end no longer has a frame at the old
/// end, or one at a step beyond the new end) are removed, so the directory holds what an
/// uninterrupted run would have written.
pub fn remove_stale_frames(series: &crate::output::Series, from: usize) {
    let dir = series.dir();
    for name in entries(dir, run_file) {
        let Some(step) = frame_step(&name).filter(|&s| s >= from) else {
            continue;
        };
        // A directory of pieces goes with its `.pvtu`.
        let file = match piece_dir(&name) {
            true => crate::output::pvtu_name(step),
            false => name.clone(),
        };
        if !series.files().iter().any(|(_, f)| *f == file) {
            let _ = remove_entry(dir, &name);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn our_names_and_theirs() {
        for name in [
            "solution.pvd",
            "solution.vtkhdf",
            "solution_000012.vtu",
            "solution_000012.pvtu",
            "solution_000012",
            ".solution_000012.pvtu.tmp.4242.7",
            "summary.json",
            "history.csv",
            "checkpoint.h5",
            "checkpoint_history.h5",
            "checkpoint.h5.tmp",
            "checkpoint_history.h5.tmp",
            "checkpoint.h5.states.tmp",
            ".solution_000012.vtu.tmp.4242.7",
            ".solution.pvd.tmp.1.0",
            ".summary.json.tmp.99.3",
            LOCK_NAME,
        ] {
            assert!(ours(name), "{name}");
        }
        for name in [
            "notes.txt",
            "solution_12.vtu",
            "solution_12",
            "solution_000012.txt",
            "solution.pvd.tmp",
            ".notes.txt.tmp.1.2",
            ".solution.pvd.tmp.x.2",
            ".solution.pvd.tmp.1.",
            "summary.json.bak",
            ".summary.json.tmp.1",
        ] {
            assert!(!ours(name), "{name}");
        }
        assert!(temporary(".solution_000001.vtu.tmp.12.0"));
        assert!(!temporary("solution_000001.vtu"));
        assert!(piece_dir("solution_000001") && !piece_dir("solution_000001.vtu"));
        for name in ["solution_000001_0.vtu", ".solution_000001_12.vtu.tmp.5.1"] {
            assert!(piece_file("solution_000001", name), "{name}");
        }
        for name in ["solution_000002_0.vtu", "solution_000001_.vtu", "notes.txt"] {
            assert!(!piece_file("solution_000001", name), "{name}");
        }
    }

    #[test]
    fn a_second_lock_is_refused_naming_the_holder_and_the_first_is_released() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("d");
        let first = DirLock::acquire(&dir, "run").unwrap();
        let err = DirLock::acquire(&dir, "resume").unwrap_err();
        assert_eq!(err.exit_code(), 2);
        let msg = err.to_string();
        for needle in [
            "in use by another viscontact process",
            &format!("pid {}", std::process::id()),
            "started 20",
            "command viscontact run",
        ] {
            assert!(msg.contains(needle), "{needle:?} not in: {msg}");
        }
        drop(first);
        assert!(
            !dir.exists(),
            "an empty directory the lock created is removed again"
        );
        std::fs::create_dir(&dir).unwrap();
        drop(DirLock::acquire(&dir, "run").unwrap());
        assert!(!dir.join(LOCK_NAME).exists());
        assert!(dir.exists(), "a directory the lock did not create stays");
    }

    #[test]
    fn a_deleted_lock_file_does_not_let_a_second_run_in() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("d");
        let first = DirLock::acquire(&dir, "run").unwrap();
        std::fs::remove_file(dir.join(LOCK_NAME)).unwrap();
        let err = DirLock::acquire(&dir, "run").unwrap_err();
        assert_eq!(err.exit_code(), 2);
        assert!(err.to_string().contains("was deleted"), "{err}");
        assert!(
            !dir.join(LOCK_NAME).exists(),
            "the refused process writes no lock file of its own"
        );
        drop(first);
        drop(DirLock::acquire(&dir, "run").unwrap());
    }
}
