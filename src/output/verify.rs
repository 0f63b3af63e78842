//! Resume verifies the series it continues (user documentation: docs/restart.md, "What
//! resume verifies").
//!
//! # What a checkpoint records
//!
//! The frame writer thread reports, for each frame it wrote, the CRC-32 and length of the
//! bytes that make the frame: the whole `solution_NNNNNN.vtu` file (read back once written,
//! from the page cache), or for `solution.vtkhdf` the frame's field values as stored (the
//! little-endian bytes of its point fields in name order, then of its cell fields). A
//! checkpoint is handed to its writer only after the series' writer thread has finished
//! every frame before it (`run::consumers`), and the checksums come back with that thread
//! ([`super::Series::finish`]); so the checkpoint of step n records `(step, time, CRC-32,
//! length)` of exactly the frames of steps < n that the run wrote, in order (format version 3,
//! `/series`).
//!
//! # What resume checks, before anything is written
//!
//! Every recorded frame must be there and carry those bytes: `.vtu` files are read whole;
//! `solution.vtkhdf` is opened read only (its superblock, object headers and chunk indexes
//! carry checksums, `vtkhdf.rs` "File format", so damaged metadata is an error of the
//! library, not a crash or a silent answer), its mesh arrays and run id are
//! compared bit for bit, every `Steps` entry is checked, and every recorded frame is read
//! back (each chunk inflated) and its CRC-32 compared. A frame of another run differs in its
//! bytes (the run id is part of them). Anything missing or different is an input error that
//! lists the frames and says what to do; nothing on disk has changed then.
//!
//! The `.pvd` is derived data: it is rebuilt from the recorded frames at the first new frame,
//! whatever the file on disk says (or if it is missing).
//!
//! A series cannot be repaired: a frame is recomputed only by rerunning from a state before
//! it, and checkpoints are not kept per frame. The error says so, and offers the two ways on:
//! `--out NEW` (a directory without a series continues from the checkpoint without the old
//! frames) or running the scene again.
//!
//! A checkpoint of format version 2 records no frames: its series is continued as before,
//! from the `.pvd` or the `.vtkhdf` on disk, unverified (the caller warns), and the frames
//! it keeps are checksummed from disk so that later checkpoints record them.

use std::path::Path;

use super::pvtu::crc32_of_frame;
use super::{frame_file, step_of, vtkhdf, Format, Geometry, Options, Series};
use super::{Precision, VTKHDF_NAME};
use crate::{Error, Result};

/// What a checkpoint records of a frame written before it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameSum {
    pub step: usize,
    pub time: f64,
    /// CRC-32 of the frame's bytes (see the module doc).
    pub crc32: u32,
    /// How many bytes the CRC covers.
    pub bytes: u64,
}

impl FrameSum {
    /// The same frame with the same bytes (times compared bit for bit).
    fn same(&self, other: &FrameSum) -> bool {
        self.step == other.step
            && self.time.to_bits() == other.time.to_bits()
            && (self.crc32, self.bytes) == (other.crc32, other.bytes)
    }
}

/// What a resumed series continues.
#[derive(Clone, Copy, Debug)]
pub struct Resumed<'a> {
    /// The checkpoint (named in errors).
    pub checkpoint: &'a Path,
    /// Its step n: the frames of steps < n are kept, the rest recomputed.
    pub step: usize,
    /// The frames it recorded; None for a checkpoint of format version 2 (unverified).
    pub frames: Option<&'a [FrameSum]>,
}

/// What is wrong with a recorded frame.
enum Flaw {
    Missing,
    Damaged,
    OtherRun(String),
}

impl Series {
    /// Continues the series in `dir` after verifying every frame `resumed` recorded (see the
    /// module doc); refuses (input error, nothing changed) a series that is not intact. A
    /// checkpoint that records no frames (format version 2) continues it unverified
    /// ([`Series::reopen`]).
    pub fn resume(
        dir: &Path,
        geometry: &Geometry,
        run_id: &str,
        options: &Options,
        resumed: &Resumed,
    ) -> Result<Series> {
        let Some(recorded) = resumed.frames else {
            let last_step = resumed.step.saturating_sub(1);
            return Series::reopen(dir, geometry, run_id, options, last_step);
        };
        let kept: Vec<FrameSum> = recorded
            .iter()
            .copied()
            .filter(|f| f.step < resumed.step)
            .collect();
        let g = geometry.chosen(options);
        let mut series = match options.format {
            Format::Vtu => {
                check_vtus(dir, run_id, &kept, resumed)?;
                let mut s = Series::create(dir, geometry, run_id, options)?;
                s.files = kept
                    .iter()
                    .map(|f| (f.time, frame_file(dir, f.step)))
                    .collect();
                s
            }
            Format::Vtkhdf => {
                check_vtkhdf(dir, &g, run_id, options.precision, &kept, resumed)?;
                let frames = kept.iter().map(|f| (f.step, f.time)).collect();
                Series::start(dir, geometry, run_id, options, frames)?
            }
        };
        series.remember(&kept);
        Ok(series)
    }

    /// Checksums of the frames an unverified resume keeps (format-2 checkpoints), from disk,
    /// so that later checkpoints record them; frames that cannot be read are left out (and so
    /// dropped from the series by the next resume).
    pub(super) fn checksum_kept(&mut self, g: &Geometry) -> Result<()> {
        let g = g.chosen(&self.options);
        let sums: Vec<FrameSum> = match self.options.format {
            Format::Vtu => self
                .files
                .iter()
                .filter_map(|(time, file)| {
                    let (crc32, bytes) = crc32_of_frame(&self.dir.join(file)).ok()?;
                    Some(FrameSum {
                        step: step_of(file)?,
                        time: *time,
                        crc32,
                        bytes,
                    })
                })
                .collect(),
            Format::Vtkhdf => {
                let path = self.dir.join(VTKHDF_NAME);
                vtkhdf::stored_sums(&path, &g, &self.run_id, self.files.len(), false)
                    .map_err(|why| damaged_file(&path, &why, None))?
            }
        };
        self.remember(&sums);
        Ok(())
    }
}

/// The error for a `solution.vtkhdf` that cannot be continued; `step`: the checkpoint's, when
/// it recorded the frames (then they cannot be recomputed).
fn damaged_file(path: &Path, why: &str, step: Option<usize>) -> Error {
    let next = match step {
        Some(n) => format!(
            "its frames cannot be recomputed from this checkpoint (step {n}; checkpoints are \
             not kept per frame): restore the file from a copy, resume into a new directory \
             with --out NEW to continue from step {n} without them, or run the scene again"
        ),
        None => "move the file aside to keep it (a resumed run then writes a new one from the \
                 checkpoint's step on), or run the scene again"
            .into(),
    };
    Error::input(format!(
        "{}: cannot be read as the series this run wrote: {why}. Nothing was changed; {next}",
        path.display()
    ))
}

/// Every kept `.vtu` (or `.pvtu` and its pieces) is there with the recorded bytes.
fn check_vtus(dir: &Path, run_id: &str, kept: &[FrameSum], resumed: &Resumed) -> Result<()> {
    let mut flaws = Vec::new();
    for f in kept {
        let path = dir.join(frame_file(dir, f.step));
        let flaw = match crc32_of_frame(&path) {
            Ok((crc32, bytes)) if (crc32, bytes) == (f.crc32, f.bytes) => continue,
            Ok(_) => match vtu_run_id(&path) {
                Some(id) if id != run_id => Flaw::OtherRun(id),
                _ => Flaw::Damaged,
            },
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Flaw::Missing,
            Err(_) => Flaw::Damaged,
        };
        flaws.push((f.step, flaw));
    }
    match flaws.is_empty() {
        true => Ok(()),
        false => Err(not_intact(dir, &flaws, kept.len(), resumed)),
    }
}

/// The run id in the `<FieldData>` of a `.vtu` (in its first 4 kB), or in the comment of a
/// `.pvtu`, if it has one.
fn vtu_run_id(path: &Path) -> Option<String> {
    use std::io::Read;
    let mut head = vec![0u8; 4096];
    let len = std::fs::File::open(path).ok()?.read(&mut head).ok()?;
    let text = String::from_utf8_lossy(&head[..len]);
    if path.extension().is_some_and(|e| e == "pvtu") {
        return super::pvd::run_id(&text).map(str::to_string);
    }
    let at = text.find("Name=\"run_id\"")?;
    let values = &text[at..];
    let values = &values[values.find('>')? + 1..];
    let values = &values[..values.find('<')?];
    let bytes: Option<Vec<u8>> = values.split_whitespace().map(|b| b.parse().ok()).collect();
    String::from_utf8(bytes?).ok()
}

/// `solution.vtkhdf` holds the kept frames with the recorded bytes.
fn check_vtkhdf(
    dir: &Path,
    g: &Geometry,
    run_id: &str,
    precision: Precision,
    kept: &[FrameSum],
    resumed: &Resumed,
) -> Result<()> {
    let path = dir.join(VTKHDF_NAME);
    if kept.is_empty() {
        return Ok(());
    }
    if !path.exists() {
        let flaws: Vec<_> = kept.iter().map(|f| (f.step, Flaw::Missing)).collect();
        return Err(not_intact(&path, &flaws, kept.len(), resumed));
    }
    let stored = vtkhdf::stored_sums(&path, g, run_id, kept.len(), true)
        .map_err(|why| damaged_file(&path, &why, Some(resumed.step)))?;
    vtkhdf::Stored::read(&path)?.check(&path, g, precision)?;
    let flaws: Vec<_> = kept
        .iter()
        .enumerate()
        .filter_map(|(k, f)| match stored.get(k) {
            None => Some((f.step, Flaw::Missing)),
            Some(s) if s.same(f) => None,
            Some(_) => Some((f.step, Flaw::Damaged)),
        })
        .collect();
    match flaws.is_empty() {
        true => Ok(()),
        false => Err(not_intact(&path, &flaws, kept.len(), resumed)),
    }
}

/// Steps as ranges of consecutive recorded frames: `51–150, 160`.
fn ranges(steps: &[usize], recorded: &[usize]) -> String {
    let index = |s: usize| recorded.iter().position(|&r| r == s).unwrap_or(0);
    let mut out: Vec<String> = Vec::new();
    let mut i = 0;
    while i < steps.len() {
        let mut j = i;
        while j + 1 < steps.len() && index(steps[j + 1]) == index(steps[j]) + 1 {
            j += 1;
        }
        out.push(match i == j {
            true => steps[i].to_string(),
            false => format!("{}–{}", steps[i], steps[j]),
        });
        i = j + 1;
    }
    out.join(", ")
}

/// The error for a series with flawed frames (at `at`, a directory or the `.vtkhdf`).
fn not_intact(at: &Path, flaws: &[(usize, Flaw)], recorded: usize, r: &Resumed) -> Error {
    let all: Vec<usize> = r.frames.unwrap_or(&[]).iter().map(|f| f.step).collect();
    let what = |f: &Flaw| match f {
        Flaw::Missing => "missing".to_string(),
        Flaw::Damaged => {
            "damaged (their bytes differ from the CRC-32 the checkpoint recorded)".to_string()
        }
        Flaw::OtherRun(id) => format!("of another run (run id {id})"),
    };
    let mut kinds: Vec<String> = flaws.iter().map(|(_, f)| what(f)).collect();
    kinds.dedup();
    let parts: Vec<String> = kinds
        .iter()
        .map(|kind| {
            let steps: Vec<usize> = flaws
                .iter()
                .filter(|(_, f)| what(f) == *kind)
                .map(|(s, _)| *s)
                .collect();
            let files = match at.is_dir() {
                true if steps.len() == 1 => format!(" ({})", frame_file(at, steps[0])),
                true => format!(" ({}, …)", frame_file(at, steps[0])),
                false => String::new(),
            };
            format!(
                "{} {kind}: step{} {}{files}",
                count(steps.len()),
                if steps.len() == 1 { "" } else { "s" },
                ranges(&steps, &all)
            )
        })
        .collect();
    let n = r.step;
    Error::input(format!(
        "{}: cannot resume {}: the series it continues is not intact ({} of the {recorded} \
         frames it recorded): {}. Nothing was changed. These frames cannot be recomputed from \
         this checkpoint (step {n}; checkpoints are not kept per frame): restore them from a \
         copy, resume into a new directory with --out NEW to continue from step {n} without \
         them, or run the scene again",
        at.display(),
        r.checkpoint.display(),
        flaws.len(),
        parts.join("; ")
    ))
}

fn count(n: usize) -> String {
    match n {
        1 => "1 frame".into(),
        n => format!("{n} frames"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_follow_the_recorded_frames() {
        let recorded = [0, 10, 20, 30, 40, 50];
        assert_eq!(ranges(&[10, 20, 30, 50], &recorded), "10–30, 50");
        assert_eq!(ranges(&[0], &recorded), "0");
        let every: Vec<usize> = (0..151).collect();
        let missing: Vec<usize> = (51..151).collect();
        assert_eq!(ranges(&missing, &every), "51–150");
    }
}
