//! Writers: the ParaView time series of a run (DESIGN.md, "Output of run").
//!
//! A run's directory holds `solution_NNNNNN.vtu` (one VTK XML UnstructuredGrid per output
//! step) and `solution.pvd` (the collection that makes ParaView open them as one time series).
//! [`Series`] owns both: [`Series::create`] takes the mesh once, [`Series::write`] writes one
//! [`Frame`] and rewrites the `.pvd`, so the directory is a valid series after every frame.
//! Every file goes through [`write_atomic`]: a crash never leaves a half-written file where a
//! good one was.
//!
//! Field conventions (the caller's, checked only for sizes):
//! - vectors have 3 components, z = 0 in 2D;
//! - a symmetric tensor (`stress`) has 6 components in ParaView's order
//!   XX, YY, ZZ, XY, YZ, XZ; every 6-component field is written with these component names
//!   (`ComponentName0="XX"` …), so ParaView shows `stress_XY`;
//! - all values are written as Float64, names exactly as given.
//!
//! Encoding: inline base64 binary, header_type UInt64, little endian, uncompressed: the layout
//! vtkio writes, which ParaView, meshio and vtkio read. The XML is written by this module, not
//! by vtkio's writer, which is too slow and cannot reuse the geometry (details in `vtu.rs`).

mod pvd;
pub mod read;
mod vtu;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::{Error, Result};

/// Name of the collection file in a run's directory.
pub const PVD_NAME: &str = "solution.pvd";

/// The `.vtu` file name of output step `step`: `solution_{step:06}.vtu`.
pub fn vtu_name(step: usize) -> String {
    format!("solution_{step:06}.vtu")
}

/// A named field: `components` values per point (or per cell), row-major.
#[derive(Clone, Copy, Debug)]
pub struct Field<'a> {
    pub name: &'a str,
    pub components: usize,
    pub values: &'a [f64],
}

/// One output step.
#[derive(Clone, Debug)]
pub struct Frame<'a> {
    pub step: usize,
    pub time: f64,
    pub point_data: Vec<Field<'a>>,
    pub cell_data: Vec<Field<'a>>,
}

/// A ParaView time series in a directory: `solution_NNNNNN.vtu` per frame + `solution.pvd`.
///
/// The geometry (points, connectivity, offsets, cell types) is encoded once, in
/// [`Series::create`]; a frame encodes only its fields.
pub struct Series {
    dir: PathBuf,
    grid: vtu::Grid,
    /// `(time, file name relative to dir)`, in the order written; one entry per step.
    files: Vec<(f64, String)>,
}

impl Series {
    /// Starts a new series in `dir` (created if missing).
    ///
    /// `points`: node coordinates (3 per node, z = 0 in 2D); `cells`: `nodes_per_cell` node
    /// indices per cell, concatenated. `nodes_per_cell` = 3 writes VTK_TRIANGLE (5),
    /// 4 writes VTK_TETRA (10); anything else is an input error.
    ///
    /// Existing `solution_*.vtu` files of an earlier run are left alone; `solution.pvd` is
    /// rewritten by the first [`Series::write`]. To continue an earlier series (resume), use
    /// [`Series::reopen`].
    pub fn create(
        dir: &Path,
        points: &[[f64; 3]],
        cells: &[usize],
        nodes_per_cell: usize,
    ) -> Result<Series> {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        let grid = vtu::Grid::new(points, cells, nodes_per_cell)?;
        Ok(Series {
            dir: dir.to_path_buf(),
            grid,
            files: Vec::new(),
        })
    }

    /// Continues the series in `dir` (for `resume`): reads `dir/solution.pvd` if there is one
    /// and keeps its frames of step ≤ `last_step` (later ones are about to be recomputed), so
    /// that the collection lists the whole run again. Without a `.pvd`, same as
    /// [`Series::create`]. A `.pvd` that this module did not write is an input error.
    pub fn reopen(
        dir: &Path,
        points: &[[f64; 3]],
        cells: &[usize],
        nodes_per_cell: usize,
        last_step: usize,
    ) -> Result<Series> {
        let mut series = Series::create(dir, points, cells, nodes_per_cell)?;
        let pvd_path = dir.join(PVD_NAME);
        let text = match std::fs::read_to_string(&pvd_path) {
            Ok(text) => text,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(series),
            Err(e) => return Err(Error::io(&pvd_path, e)),
        };
        let entries = pvd::parse(&text).map_err(|msg| {
            Error::input(format!(
                "{}: {msg}; remove it or choose another output directory",
                pvd_path.display()
            ))
        })?;
        series.files = entries
            .into_iter()
            .filter(|(_, file)| step_of(file).is_some_and(|s| s <= last_step))
            .collect();
        Ok(series)
    }

    /// Writes `dir/solution_{step:06}.vtu` (through a temporary file + rename), then rewrites
    /// `dir/solution.pvd` (temp + rename) so the `.pvd` is valid after every frame, listing
    /// every frame so far with its real time. Writing a step again replaces its file and its
    /// entry. Returns the path of the `.vtu`.
    ///
    /// Errors: a field whose length is not `components` × (number of points or cells), a
    /// field with 0 components or a repeated or empty name, or a non-finite time →
    /// `Error::Input`; any file-system failure → `Error::Io` naming the file.
    pub fn write(&mut self, frame: &Frame) -> Result<PathBuf> {
        if !frame.time.is_finite() {
            return Err(Error::input(format!(
                "output step {}: time {} is not a finite number",
                frame.step, frame.time
            )));
        }
        let name = vtu_name(frame.step);
        let path = self.dir.join(&name);
        let bytes = self
            .grid
            .encode(&frame.point_data, &frame.cell_data)
            .map_err(|msg| {
                Error::input(format!(
                    "{} (output step {}): {msg}",
                    path.display(),
                    frame.step
                ))
            })?;
        write_atomic(&path, bytes)?;

        match self.files.iter_mut().find(|(_, f)| *f == name) {
            Some(entry) => entry.0 = frame.time,
            None => self.files.push((frame.time, name)),
        }
        let pvd_path = self.dir.join(PVD_NAME);
        write_atomic(&pvd_path, pvd::render(&self.files).as_bytes())?;
        Ok(path)
    }

    /// `(time, file name relative to the directory)` of every frame listed in the `.pvd`.
    pub fn files(&self) -> &[(f64, String)] {
        &self.files
    }

    /// The series' directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Number of points and cells of the mesh.
    pub fn sizes(&self) -> (usize, usize) {
        (self.grid.num_points(), self.grid.num_cells())
    }
}

/// The step number encoded in a `solution_NNNNNN.vtu` name.
fn step_of(file: &str) -> Option<usize> {
    file.strip_prefix("solution_")?
        .strip_suffix(".vtu")?
        .parse()
        .ok()
}

/// Writes bytes to `path` through a temporary file in the same directory and a rename, so a
/// crash never leaves a half-written file where a good one was.
///
/// The temporary file (`.NAME.tmp.PID.N` beside `path`) is removed again on failure. The data
/// are not fsync'ed: the rename makes a process crash safe, which is what a run needs; the
/// output of a run is reproducible and a power failure is out of scope. Errors name `path`.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let file_name = path.file_name().ok_or_else(|| {
        Error::io(
            path,
            std::io::Error::new(std::io::ErrorKind::InvalidInput, "not a file path"),
        )
    })?;
    let tmp_name = format!(
        ".{}.tmp.{}.{}",
        file_name.to_string_lossy(),
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    );
    let tmp = path.with_file_name(tmp_name);
    let result = (|| {
        let mut file = std::fs::File::create(&tmp)?;
        file.write_all(bytes)?;
        file.flush()?;
        drop(file);
        std::fs::rename(&tmp, path)
    })();
    result.map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        Error::io(path, e)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn step_of_parses_only_our_names() {
        assert_eq!(step_of("solution_000012.vtu"), Some(12));
        assert_eq!(step_of("solution_1234567.vtu"), Some(1234567));
        assert_eq!(step_of("other_000012.vtu"), None);
        assert_eq!(step_of("solution_x.vtu"), None);
    }

    #[test]
    fn write_atomic_replaces_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.txt");
        write_atomic(&path, b"one").unwrap();
        write_atomic(&path, b"two").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"two");
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(names.len(), 1);
    }

    #[test]
    fn write_atomic_error_names_the_path() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("missing").join("a.txt");
        let err = write_atomic(&path, b"x").unwrap_err();
        assert!(matches!(err, Error::Io { .. }));
        assert!(
            err.to_string().contains(&path.display().to_string()),
            "{err}"
        );
    }
}
