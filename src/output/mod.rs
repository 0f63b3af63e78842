//! Writers: the ParaView time series of a run (DESIGN.md, "Output of run").
//!
//! A run's directory holds `solution_NNNNNN.vtu` (one VTK XML UnstructuredGrid per output
//! step) and `solution.pvd` (the collection that makes ParaView open them as one time series).
//! [`Series`] owns both: [`Series::create`] takes the mesh once, [`Series::write`] writes one
//! [`Frame`] and rewrites the `.pvd`, so the directory is a valid series after every frame.
//! Every file goes through [`write_atomic`]: a crash never leaves a half-written file where a
//! good one was.
//!
//! Frames are encoded and written on a background thread ([`writer`]): the time loop hands
//! over a frame's values and goes on; it waits only when two frames are already queued. A
//! write that failed stops the run at the next [`Series::write`] or at [`Series::finish`],
//! naming the file.
//!
//! Field conventions (the caller's, checked only for sizes):
//! - vectors have 3 components, z = 0 in 2D;
//! - a symmetric tensor (`stress`) has 6 components in ParaView's order
//!   XX, YY, ZZ, XY, YZ, XZ; every 6-component field is written with these component names
//!   (`ComponentName0="XX"` …), so ParaView shows `stress_XY`;
//! - values are written as Float64 or Float32 ([`Precision`]), names exactly as given;
//! - [`FIELDS`] lists the fields a run writes; [`Options::fields`] selects some of them.
//!
//! Encoding: raw appended data, zlib-compressed by default (details in `vtu.rs`). The run id
//! given to [`Series::create`] is stored in every `.vtu` (FieldData `run_id`) and in the
//! `.pvd` (a comment), and [`Series::reopen`] refuses a directory of another run.

pub mod frame;
mod pvd;
pub mod read;
mod vtu;
mod writer;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::{Error, Result};

/// Name of the collection file in a run's directory.
pub const PVD_NAME: &str = "solution.pvd";

/// The fields a run writes (`[output] fields` chooses among them): point fields, cell fields,
/// and `region`, the gmsh physical tag of each cell.
pub const FIELDS: [&str; 8] = [
    "displacement",
    "velocity",
    "contact_pressure",
    "friction_traction",
    "contact_state",
    "stress",
    "von_mises",
    "region",
];

/// `[output] compression`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Compression {
    /// Raw appended data.
    None,
    /// VTK's zlib blocks (`vtkZLibDataCompressor`).
    #[default]
    Zlib,
}

/// `[output] precision` of the field values (coordinates stay Float64).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Precision {
    #[default]
    Float64,
    Float32,
}

/// How a series is written.
#[derive(Clone, Debug, Default)]
pub struct Options {
    pub compression: Compression,
    pub precision: Precision,
    /// The fields to write, names from [`FIELDS`]; `None` = all.
    pub fields: Option<Vec<String>>,
}

impl Options {
    /// Whether the field `name` is written.
    pub fn wants(&self, name: &str) -> bool {
        self.fields
            .as_ref()
            .is_none_or(|f| f.iter().any(|g| g == name))
    }
}

/// The mesh of a series. `points`: node coordinates (3 per node, z = 0 in 2D); `cells`:
/// `nodes_per_cell` node indices per cell, concatenated (3 → VTK_TRIANGLE, 4 → VTK_TETRA,
/// anything else is an input error); `region`: the gmsh physical tag of each cell, or empty
/// for none.
#[derive(Clone, Copy, Debug)]
pub struct Geometry<'a> {
    pub points: &'a [[f64; 3]],
    pub cells: &'a [usize],
    pub nodes_per_cell: usize,
    pub region: &'a [i32],
}

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
/// The geometry (points, connectivity, offsets, cell types, region) is encoded once, in
/// [`Series::create`]; a frame encodes only its fields.
pub struct Series {
    dir: PathBuf,
    run_id: String,
    options: Options,
    sizes: (usize, usize),
    /// `(time, file name relative to dir)`, in the order written; one entry per step.
    files: Vec<(f64, String)>,
    writer: writer::Writer,
}

impl Series {
    /// Starts a new series in `dir` (created if missing) for the run `run_id`.
    ///
    /// Existing `solution_*.vtu` files of an earlier run are left alone; `solution.pvd` is
    /// rewritten by the first [`Series::write`]. To continue an earlier series (resume), use
    /// [`Series::reopen`].
    pub fn create(
        dir: &Path,
        geometry: &Geometry,
        run_id: &str,
        options: &Options,
    ) -> Result<Series> {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        let mut g = *geometry;
        if !options.wants("region") {
            g.region = &[];
        }
        let grid = vtu::Grid::new(&g, run_id, options.compression)?;
        Ok(Series {
            dir: dir.to_path_buf(),
            run_id: run_id.to_string(),
            options: options.clone(),
            sizes: (grid.num_points(), grid.num_cells()),
            files: Vec::new(),
            writer: writer::Writer::new(grid),
        })
    }

    /// Continues the series in `dir` (for `resume`): reads `dir/solution.pvd` if there is one
    /// and keeps its frames of step ≤ `last_step` (later ones are about to be recomputed), so
    /// that the collection lists the whole run again. Without a `.pvd`, same as
    /// [`Series::create`]. A `.pvd` that this module did not write, or one of a run whose id
    /// is not `run_id`, is an input error.
    pub fn reopen(
        dir: &Path,
        geometry: &Geometry,
        run_id: &str,
        options: &Options,
        last_step: usize,
    ) -> Result<Series> {
        let pvd_path = dir.join(PVD_NAME);
        let text = match std::fs::read_to_string(&pvd_path) {
            Ok(text) => text,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Series::create(dir, geometry, run_id, options)
            }
            Err(e) => return Err(Error::io(&pvd_path, e)),
        };
        let bad = |msg: String| {
            Error::input(format!(
                "{}: {msg}; remove it or choose another output directory",
                pvd_path.display()
            ))
        };
        let entries = pvd::parse(&text).map_err(bad)?;
        match pvd::run_id(&text) {
            Some(id) if id == pvd::comment_safe(run_id) => {}
            stored => {
                return Err(Error::input(format!(
                    "{} holds frames of another run (run id {}, this run is {run_id}); \
                     choose another output directory (--out) or remove them",
                    dir.display(),
                    stored.unwrap_or("missing")
                )))
            }
        }
        let mut series = Series::create(dir, geometry, run_id, options)?;
        series.files = entries
            .into_iter()
            .filter(|(_, file)| step_of(file).is_some_and(|s| s <= last_step))
            .collect();
        Ok(series)
    }

    /// Hands `dir/solution_{step:06}.vtu` to the writer thread, which writes it (temporary
    /// file + rename), then `dir/solution.pvd` (likewise) listing every frame so far with its
    /// real time, so the directory is a valid series after every frame. Writing a step again
    /// replaces its file and its entry. Fields not chosen by [`Options::fields`] are left out.
    /// Returns the path of the `.vtu`.
    ///
    /// Errors: a field whose length is not `components` × (number of points or cells), a
    /// field with 0 components or a repeated or empty name, or a non-finite time →
    /// `Error::Input`; a failed write of an earlier frame → `Error::Io` naming its file.
    pub fn write(&mut self, frame: &Frame) -> Result<PathBuf> {
        if !frame.time.is_finite() {
            return Err(Error::input(format!(
                "output step {}: time {} is not a finite number",
                frame.step, frame.time
            )));
        }
        let name = vtu_name(frame.step);
        let path = self.dir.join(&name);
        let (points, cells) = self.sizes;
        let arrays = |fields: &[Field], count, what| {
            check_fields(fields, count, what)
                .map(|()| {
                    fields
                        .iter()
                        .filter(|f| self.options.wants(f.name))
                        .map(|f| self.array(f))
                        .collect::<Vec<_>>()
                })
                .map_err(|msg| {
                    Error::input(format!(
                        "{} (output step {}): {msg}",
                        path.display(),
                        frame.step
                    ))
                })
        };
        let point_data = arrays(&frame.point_data, points, "point")?;
        let cell_data = arrays(&frame.cell_data, cells, "cell")?;
        match self.files.iter_mut().find(|(_, f)| *f == name) {
            Some(entry) => entry.0 = frame.time,
            None => self.files.push((frame.time, name)),
        }
        self.writer.send(writer::Job {
            path: path.clone(),
            point_data,
            cell_data,
            pvd: (
                self.dir.join(PVD_NAME),
                pvd::render(&self.files, &self.run_id),
            ),
        })?;
        Ok(path)
    }

    /// Waits until every frame handed over is on disk; the first failed write is the error.
    pub fn finish(&mut self) -> Result<()> {
        self.writer.finish()
    }

    /// The little-endian bytes of a field in the chosen precision.
    fn array(&self, f: &Field) -> vtu::Array {
        let (ty, bytes) = match self.options.precision {
            Precision::Float64 => (
                "Float64",
                f.values.iter().flat_map(|x| x.to_le_bytes()).collect(),
            ),
            Precision::Float32 => (
                "Float32",
                f.values
                    .iter()
                    .flat_map(|&x| (x as f32).to_le_bytes())
                    .collect(),
            ),
        };
        vtu::Array {
            name: f.name.to_string(),
            ty,
            components: f.components,
            bytes,
        }
    }

    /// `(time, file name relative to the directory)` of every frame listed in the `.pvd`.
    pub fn files(&self) -> &[(f64, String)] {
        &self.files
    }

    /// The series' directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The options the series was created with.
    pub fn options(&self) -> &Options {
        &self.options
    }

    /// Number of points and cells of the mesh.
    pub fn sizes(&self) -> (usize, usize) {
        self.sizes
    }
}

/// Checks sizes and names of the fields of one kind (`what` = "point" or "cell").
fn check_fields(fields: &[Field], count: usize, what: &str) -> std::result::Result<(), String> {
    for (k, f) in fields.iter().enumerate() {
        if f.name.is_empty() {
            return Err(format!("{what} field #{k} has an empty name"));
        }
        if fields[..k].iter().any(|g| g.name == f.name) {
            return Err(format!("{what} field `{}` is given twice", f.name));
        }
        if f.components == 0 || f.values.len() != f.components * count {
            return Err(format!(
                "{what} field `{}` has {} values, expected {} components × {count} {what}s",
                f.name,
                f.values.len(),
                f.components
            ));
        }
    }
    Ok(())
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
