//! Writers: the ParaView time series of a run (docs/output.md).
//!
//! Two formats (`[output] format`, [`Format`]):
//! - `"vtu"` (the default): `solution_NNNNNN.vtu` (one VTK XML UnstructuredGrid per output
//!   step) and `solution.pvd` (the collection that makes ParaView open them as one time
//!   series). [`Series::write`] writes one [`Frame`]; the `.pvd` is rewritten with the first
//!   frame, then at most every [`PVD_EVERY`] and by [`Series::finish`] (which the run calls
//!   before every checkpoint and at its end), so the directory is always a valid series of
//!   the frames so far, and a resume finds every frame before its checkpoint listed. Every
//!   file goes through [`write_atomic`]: a crash never leaves a half-written file where a
//!   good one was.
//! - `"vtkhdf"`: one file `solution.vtkhdf`, a temporal VTKHDF 2.x UnstructuredGrid (the
//!   mesh once, each frame's fields appended, the times in `Steps/Values`; layout and crash
//!   behaviour in `vtkhdf.rs`), flushed after every frame.
//!
//! Besides the series, [`Lines`] (`lines.rs`) grows a text file by lines made on the same
//! kind of thread (the run's `history.csv`).
//!
//! [`Series`] owns either: [`Series::create`] takes the mesh once; the checks of a frame, the
//! choice of fields and precision and the writer thread are shared, only the sink differs.
//!
//! Frames are encoded and written on a background thread (`writer`): the time loop hands
//! over a frame's values and goes on; it waits only when two frames are already queued. A
//! run's frames are computed there too ([`Series::write_with`], `frame.rs`): the time loop
//! copies the step's state (w, u, m, z), the thread makes the fields (nodal values, stress,
//! contact tractions). A write that failed stops the run at the next [`Series::write`] or at
//! [`Series::finish`], naming the file.
//!
//! Field conventions (the caller's, checked only for sizes):
//! - vectors have 3 components, z = 0 in 2D;
//! - a symmetric tensor (`stress`) has 6 components in ParaView's order
//!   XX, YY, ZZ, XY, YZ, XZ; every 6-component field is written with these component names
//!   (`ComponentName0="XX"` …), so ParaView shows `stress_XY`;
//! - values are written as Float64 or Float32 ([`Precision`]), names exactly as given;
//! - [`FIELDS`] lists the fields a run writes; [`Options::fields`] selects some of them.
//!
//! Encoding: `.vtu` raw appended data, zlib-compressed by default (details in `vtu.rs`);
//! `.vtkhdf` HDF5 deflate chunks, or none. The run id given to
//! [`Series::create`] is stored in every `.vtu` and in `solution.vtkhdf` (FieldData
//! `run_id`) and in the `.pvd` (a comment), and [`Series::reopen`] refuses a series of
//! another run.

mod lines;
mod pvd;
mod pvtu;
pub mod read;
mod verify;
mod vtkhdf;
mod vtu;
mod writer;
pub mod zlib;

use std::borrow::Cow;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use crate::mesh::Points;
use crate::{Error, Result};
pub use lines::Lines;
pub use verify::{FrameSum, Resumed};

/// Name of the collection file in a run's directory.
pub const PVD_NAME: &str = "solution.pvd";

/// Name of the one-file series (`format = "vtkhdf"`) in a run's directory.
pub const VTKHDF_NAME: &str = "solution.vtkhdf";

/// The `.pvd` is rewritten at most this often (and when the series finishes): it lists every
/// frame, so rewriting it per frame made a run's output cost grow with the square of its
/// frames (10⁵ frames: 7 MB of XML per frame).
pub const PVD_EVERY: Duration = Duration::from_secs(1);

/// VTK cell type codes.
const VTK_TRIANGLE: u8 = 5;
const VTK_TETRA: u8 = 10;

/// The fields a run writes (`[output] fields` chooses among them): point fields, cell fields,
/// and the static cell arrays ([`STATIC_CELL_FIELDS`]): `region`, the gmsh physical tag of
/// each cell, and `material_region`, its `[[material.region]]` entry (written only by a scene
/// with regions).
pub const FIELDS: [&str; 9] = [
    "displacement",
    "velocity",
    "contact_pressure",
    "friction_traction",
    "contact_state",
    "stress",
    "von_mises",
    "region",
    "material_region",
];

/// The cell arrays of the mesh rather than of a frame (Int32, written once), in the order
/// of the files.
pub const STATIC_CELL_FIELDS: [&str; 2] = ["region", "material_region"];

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

/// `[output] format`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Format {
    /// `solution_NNNNNN.vtu` per frame + `solution.pvd`.
    #[default]
    Vtu,
    /// One temporal VTKHDF file, `solution.vtkhdf`.
    Vtkhdf,
}

/// How a series is written.
#[derive(Clone, Debug, Default)]
pub struct Options {
    pub format: Format,
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
/// for none; `material_region`: each cell's `[[material.region]]` entry (0 outside every
/// region, i for the i-th entry), or empty for none; `pieces`: each cell's piece, for a run
/// over MPI ranks whose `.vtu` frames are a `.pvtu` with a piece per rank (`pvtu.rs`), or
/// empty for one file a frame.
#[derive(Clone, Copy, Debug)]
pub struct Geometry<'a> {
    /// The nodes' places: every node's, or on a follower rank of several those it holds.
    pub points: Points<'a>,
    pub cells: &'a [usize],
    pub nodes_per_cell: usize,
    pub region: &'a [i32],
    pub material_region: &'a [i32],
    pub pieces: &'a [u32],
    /// With `pieces`: each rank writes its own piece of a frame ([`OwnPiece`]), and the
    /// series only lists them in the frame's `.pvtu` ([`Series::list_pieces`]); else the
    /// series writes every piece from the frame's whole fields.
    pub pieces_by_ranks: bool,
}

impl<'a> Geometry<'a> {
    /// The static cell arrays that are not empty, by name ([`STATIC_CELL_FIELDS`]' order).
    pub(super) fn cell_statics(&self) -> Vec<(&'static str, &'a [i32])> {
        let arrays = [self.region, self.material_region];
        STATIC_CELL_FIELDS
            .into_iter()
            .zip(arrays)
            .filter(|(_, a)| !a.is_empty())
            .collect()
    }

    /// The geometry with the static cell arrays that `options` does not choose left empty.
    pub(super) fn chosen(mut self, options: &Options) -> Self {
        if !options.wants("region") {
            self.region = &[];
        }
        if !options.wants("material_region") {
            self.material_region = &[];
        }
        self
    }

    /// Checks the mesh and returns its VTK cell type: 3 nodes per cell → VTK_TRIANGLE, 4 →
    /// VTK_TETRA, anything else, node indices out of range or a region tag count that is not
    /// the cell count → `Error::Input`.
    fn cell_type(&self) -> Result<u8> {
        let (cells, nodes_per_cell) = (self.cells, self.nodes_per_cell);
        let cell_type = match nodes_per_cell {
            3 => VTK_TRIANGLE,
            4 => VTK_TETRA,
            n => {
                return Err(Error::input(format!(
                    "output: {n} nodes per cell is not supported (3 = triangle, 4 = tetrahedron)"
                )))
            }
        };
        if !cells.len().is_multiple_of(nodes_per_cell) {
            return Err(Error::input(format!(
                "output: {} cell node indices is not a multiple of {nodes_per_cell} nodes per cell",
                cells.len()
            )));
        }
        let num_points = self.points.whole().len();
        let num_cells = cells.len() / nodes_per_cell;
        if let Some(pos) = cells.iter().position(|&i| i >= num_points) {
            return Err(Error::input(format!(
                "output: cell {} refers to node {}, but the mesh has {num_points} nodes",
                pos / nodes_per_cell,
                cells[pos]
            )));
        }
        for (name, values) in self.cell_statics() {
            if values.len() != num_cells {
                return Err(Error::input(format!(
                    "output: {} {name} values for {num_cells} cells",
                    values.len()
                )));
            }
        }
        Ok(cell_type)
    }
}

/// The values of one array of a frame in the chosen precision.
#[derive(Clone, Debug)]
pub(super) enum Values {
    F64(Vec<f64>),
    F32(Vec<f32>),
}

/// One array of a frame, as the writer thread gets it.
#[derive(Clone, Debug)]
pub(super) struct Array {
    pub name: String,
    pub components: usize,
    pub values: Values,
}

impl Array {
    /// VTK's XML name of the value type.
    fn vtk_type(&self) -> &'static str {
        match self.values {
            Values::F64(_) => "Float64",
            Values::F32(_) => "Float32",
        }
    }

    /// The values' little-endian bytes: the values' own memory on a little-endian machine
    /// (a frame's 3 MB are not copied once more), a copy elsewhere.
    fn le_bytes(&self) -> Cow<'_, [u8]> {
        if cfg!(target_endian = "little") {
            return match &self.values {
                Values::F64(v) => Cow::Borrowed(bytemuck::cast_slice(v)),
                Values::F32(v) => Cow::Borrowed(bytemuck::cast_slice(v)),
            };
        }
        Cow::Owned(match &self.values {
            Values::F64(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            Values::F32(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
        })
    }
}

/// The `.vtu` file name of output step `step`: `solution_{step:06}.vtu`.
pub fn vtu_name(step: usize) -> String {
    format!("solution_{step:06}.vtu")
}

pub use pvtu::{pvtu_name, OwnPiece, PieceMesh};

/// A named field: `components` values per point (or per cell), row-major.
#[derive(Clone, Copy, Debug)]
pub struct Field<'a> {
    pub name: &'a str,
    pub components: usize,
    pub values: &'a [f64],
}

/// A field that owns its values (see [`Series::write_with`]).
#[derive(Clone, Debug)]
pub struct OwnedField {
    pub name: String,
    pub components: usize,
    pub values: Vec<f64>,
}

impl OwnedField {
    /// The array of the field in the chosen precision (Float64 keeps the values).
    fn array(self, precision: Precision) -> Array {
        Array {
            name: self.name,
            components: self.components,
            values: match precision {
                Precision::Float64 => Values::F64(self.values),
                Precision::Float32 => Values::F32(self.values.iter().map(|&x| x as f32).collect()),
            },
        }
    }
}

/// One output step.
#[derive(Clone, Debug)]
pub struct Frame<'a> {
    pub step: usize,
    pub time: f64,
    pub point_data: Vec<Field<'a>>,
    pub cell_data: Vec<Field<'a>>,
}

/// A ParaView time series in a directory: `solution_NNNNNN.vtu` per frame + `solution.pvd`,
/// or `solution.vtkhdf` ([`Options::format`]).
///
/// The geometry (points, connectivity, offsets, cell types, region) is encoded once, in
/// [`Series::create`]; a frame encodes only its fields.
pub struct Series {
    dir: PathBuf,
    run_id: String,
    options: Options,
    sizes: (usize, usize),
    /// `(time, file name relative to dir)`, in the order written; one entry per frame (for
    /// `vtkhdf`, every frame's file is `solution.vtkhdf`).
    files: Vec<(f64, String)>,
    /// `vtu`: when the `.pvd` was last handed to the writer, and whether frames came since.
    pvd_written: Option<Instant>,
    pvd_stale: bool,
    sink: Sink,
    /// CRC-32 and length of the frame of each step written (or kept and verified), for the
    /// checkpoints (`verify.rs`).
    sums: std::collections::HashMap<usize, (u32, u64)>,
}

/// The writer thread of each format.
enum Sink {
    Vtu {
        /// Whether a frame is a `.pvtu` in pieces (else one `.vtu`).
        pieces: bool,
        writer: writer::Writer<pvtu::Frames>,
    },
    Vtkhdf {
        /// The step of each frame in `files`.
        steps: Vec<usize>,
        writer: writer::Writer<vtkhdf::Sink>,
    },
}

impl Series {
    /// Starts a new series in `dir` (created if missing) for the run `run_id`. Nothing is
    /// written before the first frame.
    ///
    /// Existing `solution_*.vtu` files of an earlier run are left alone; `solution.pvd` is
    /// rewritten by the first [`Series::write`]; an existing `solution.vtkhdf` is replaced by
    /// the first frame. To continue an earlier series (resume), use [`Series::reopen`].
    pub fn create(
        dir: &Path,
        geometry: &Geometry,
        run_id: &str,
        options: &Options,
    ) -> Result<Series> {
        Series::start(dir, geometry, run_id, options, Vec::new())
    }

    /// A series whose first frames are `kept` (`vtkhdf`: `(step, time)` of the frames
    /// `solution.vtkhdf` holds and keeps).
    fn start(
        dir: &Path,
        geometry: &Geometry,
        run_id: &str,
        options: &Options,
        kept: Vec<(usize, f64)>,
    ) -> Result<Series> {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        let g = geometry.chosen(options);
        let sizes = (
            g.points.whole().len(),
            g.cells.len() / g.nodes_per_cell.max(1),
        );
        let (sink, files) = match options.format {
            Format::Vtu => {
                let pieces = !g.pieces.is_empty();
                let frames = match pieces {
                    false => pvtu::Frames::One(Box::new(vtu::Grid::new(
                        &g,
                        run_id,
                        options.compression,
                    )?)),
                    true => {
                        pvtu::Frames::Pieces(pvtu::Pieces::new(&g, run_id, options.compression)?)
                    }
                };
                let writer = writer::Writer::new(frames);
                (Sink::Vtu { pieces, writer }, Vec::new())
            }
            Format::Vtkhdf => (
                Sink::Vtkhdf {
                    steps: kept.iter().map(|&(s, _)| s).collect(),
                    writer: writer::Writer::new(vtkhdf::Sink::new(
                        &dir.join(VTKHDF_NAME),
                        &g,
                        run_id,
                        options.compression,
                    )?),
                },
                kept.iter()
                    .map(|&(_, t)| (t, VTKHDF_NAME.to_string()))
                    .collect(),
            ),
        };
        Ok(Series {
            dir: dir.to_path_buf(),
            run_id: run_id.to_string(),
            options: options.clone(),
            sizes,
            files,
            pvd_written: None,
            pvd_stale: false,
            sink,
            sums: Default::default(),
        })
    }

    /// Continues the series in `dir` (for `resume`) and keeps its frames of step ≤
    /// `last_step` (later ones are about to be recomputed), so that it holds the whole run
    /// again: `.vtu` reads `dir/solution.pvd`, `vtkhdf` reads `dir/solution.vtkhdf` (and its
    /// first new frame cuts the file back to the frames kept). Without that file, same as
    /// [`Series::create`]. A file that this module did not write, one that cannot be read,
    /// one of a run whose id is not `run_id`, or (`vtkhdf`) one of another precision is an
    /// input error that names it; nothing is changed on disk then.
    pub fn reopen(
        dir: &Path,
        geometry: &Geometry,
        run_id: &str,
        options: &Options,
        last_step: usize,
    ) -> Result<Series> {
        if options.format == Format::Vtkhdf {
            let path = dir.join(VTKHDF_NAME);
            if !path.exists() {
                return Series::create(dir, geometry, run_id, options);
            }
            let stored = vtkhdf::Stored::read(&path)?;
            if stored.run_id != run_id {
                return Err(other_run(&path, &stored.run_id, run_id));
            }
            stored.check(&path, geometry, options.precision)?;
            let kept = stored
                .frames
                .into_iter()
                .filter(|&(s, _)| s <= last_step)
                .collect();
            let mut series = Series::start(dir, geometry, run_id, options, kept)?;
            series.checksum_kept(geometry)?;
            return Ok(series);
        }
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
            stored => return Err(other_run(dir, stored.unwrap_or("missing"), run_id)),
        }
        let mut series = Series::create(dir, geometry, run_id, options)?;
        series.files = entries
            .into_iter()
            .filter(|(_, file)| step_of(file).is_some_and(|s| s <= last_step))
            .collect();
        series.checksum_kept(geometry)?;
        Ok(series)
    }

    /// Hands the frame to the writer thread and returns the path of the file it goes to.
    ///
    /// `vtu`: the thread writes `dir/solution_{step:06}.vtu` (temporary file + rename), then,
    /// at the first frame and once [`PVD_EVERY`] passed since the last time,
    /// `dir/solution.pvd` (likewise) listing every frame so far with its real time (the
    /// frames after it are listed by the next one or by [`Series::finish`]). Writing a step
    /// again replaces its file and its entry.
    ///
    /// `vtkhdf`: the thread appends the frame to `dir/solution.vtkhdf` (creating it at the
    /// first frame) and flushes the file. A frame of step s first drops the frames of steps
    /// ≥ s, so the steps in the file always increase.
    ///
    /// Fields not chosen by [`Options::fields`] are left out.
    ///
    /// Errors: a field whose length is not `components` × (number of points or cells), a
    /// field with 0 components or a repeated or empty name, or a non-finite time →
    /// `Error::Input`; a failed write of an earlier frame → that error, naming its file.
    pub fn write(&mut self, frame: &Frame) -> Result<PathBuf> {
        let name = self.file_name(frame.step, frame.time)?;
        let path = self.dir.join(&name);
        let (points, cells) = self.sizes;
        let owned = |fields: &[Field], count, what| {
            check_fields(
                fields
                    .iter()
                    .map(|f| (f.name, f.components, f.values.len())),
                count,
                what,
            )
            .map_err(|msg| frame_error(&path, frame.step, msg))?;
            Ok::<_, Error>(
                fields
                    .iter()
                    .filter(|f| self.options.wants(f.name))
                    .map(|f| OwnedField {
                        name: f.name.to_string(),
                        components: f.components,
                        values: f.values.to_vec(),
                    })
                    .collect::<Vec<_>>(),
            )
        };
        let fields = (
            owned(&frame.point_data, points, "point")?,
            owned(&frame.cell_data, cells, "cell")?,
        );
        self.send(frame.step, frame.time, (name, self.sizes), move || fields)
    }

    /// As [`Series::write`], for fields that `make` computes on the writer thread: (point
    /// fields, cell fields). A run's frames go this way, so that the time loop only copies
    /// the state of a step. The fields' sizes are checked on the thread: a wrong one is the
    /// error of the next write or of [`Series::finish`].
    pub fn write_with(
        &mut self,
        step: usize,
        time: f64,
        make: impl FnOnce() -> (Vec<OwnedField>, Vec<OwnedField>) + Send + 'static,
    ) -> Result<PathBuf> {
        let name = self.file_name(step, time)?;
        self.send(step, time, (name, self.sizes), make)
    }

    /// Lists step `step`'s frame, whose pieces every rank has written ([`OwnPiece`]), in its
    /// `.pvtu` (a series whose geometry has `pieces_by_ranks`); `fields` are the frame's
    /// (point fields, cell fields) by name and components, without values.
    pub fn list_pieces(
        &mut self,
        step: usize,
        time: f64,
        fields: (Vec<OwnedField>, Vec<OwnedField>),
    ) -> Result<PathBuf> {
        let name = self.file_name(step, time)?;
        // Fields of no point and no cell: the sizes that the writer thread checks.
        self.send(step, time, (name, (0, 0)), move || fields)
    }

    /// The file (in the series' directory) of step `step`'s frame; a non-finite time is an
    /// input error.
    fn file_name(&self, step: usize, time: f64) -> Result<String> {
        if !time.is_finite() {
            return Err(Error::input(format!(
                "output step {step}: time {time} is not a finite number"
            )));
        }
        Ok(match self.sink {
            Sink::Vtu { pieces: false, .. } => vtu_name(step),
            Sink::Vtu { pieces: true, .. } => pvtu_name(step),
            Sink::Vtkhdf { .. } => VTKHDF_NAME.to_string(),
        })
    }

    /// Lists the frame (its file `name`) and queues it: the thread makes its fields, checks
    /// them against `sizes` (points, cells) and keeps those chosen, in the chosen precision.
    fn send(
        &mut self,
        step: usize,
        time: f64,
        (name, sizes): (String, (usize, usize)),
        make: impl FnOnce() -> (Vec<OwnedField>, Vec<OwnedField>) + Send + 'static,
    ) -> Result<PathBuf> {
        let path = self.dir.join(&name);
        let arrays = arrays(self.options.clone(), sizes, path.clone(), step, make);
        match &mut self.sink {
            Sink::Vtu { writer, .. } => {
                relist(&mut self.files, step, time, name);
                let due = self.pvd_written.is_none_or(|t| t.elapsed() >= PVD_EVERY);
                self.pvd_stale = !due;
                if due {
                    self.pvd_written = Some(Instant::now());
                }
                let pvd = due.then(|| collection(&self.dir, &self.files, &self.run_id));
                let file = path.clone();
                writer.send(Box::new(move || {
                    let (point_data, cell_data) = arrays()?;
                    Ok(vtu::Job {
                        vtu: Some(vtu::Vtu {
                            step,
                            path: file,
                            point_data,
                            cell_data,
                        }),
                        pvd,
                    })
                }))?;
            }
            Sink::Vtkhdf { steps, writer } => {
                let index = steps.iter().take_while(|&&s| s < step).count();
                steps.truncate(index);
                steps.push(step);
                self.files.truncate(index);
                self.files.push((time, name));
                writer.send(Box::new(move || {
                    let (point_data, cell_data) = arrays()?;
                    Ok(vtkhdf::Job {
                        index,
                        step,
                        time,
                        point_data,
                        cell_data,
                    })
                }))?;
            }
        }
        Ok(path)
    }

    /// Waits until every frame handed over is on disk, and the `.pvd` lists them; the first
    /// failed write is the error.
    pub fn finish(&mut self) -> Result<()> {
        if self.pvd_stale {
            self.pvd_stale = false;
            self.pvd_written = Some(Instant::now());
            let pvd = Some(collection(&self.dir, &self.files, &self.run_id));
            if let Sink::Vtu { writer, .. } = &mut self.sink {
                writer.send(Box::new(move || Ok(vtu::Job { vtu: None, pvd })))?;
            }
        }
        let (finished, written) = match &mut self.sink {
            Sink::Vtu { writer, .. } => (writer.finish(), writer.take_written()),
            Sink::Vtkhdf { writer, .. } => (writer.finish(), writer.take_written()),
        };
        for w in written {
            self.sums.insert(w.step, (w.crc32, w.bytes));
        }
        finished
    }

    /// The checksums of the frames the series lists, in order (complete after
    /// [`Series::finish`]: what a checkpoint records, `verify.rs`).
    pub fn checksums(&self) -> Vec<FrameSum> {
        let steps: Vec<Option<usize>> = match &self.sink {
            Sink::Vtu { .. } => self.files.iter().map(|(_, f)| step_of(f)).collect(),
            Sink::Vtkhdf { steps, .. } => steps.iter().map(|&s| Some(s)).collect(),
        };
        steps
            .into_iter()
            .zip(&self.files)
            .filter_map(|(step, &(time, _))| {
                let step = step?;
                let &(crc32, bytes) = self.sums.get(&step)?;
                Some(FrameSum {
                    step,
                    time,
                    crc32,
                    bytes,
                })
            })
            .collect()
    }

    /// Takes the checksums of frames kept from an earlier run of the series.
    fn remember(&mut self, frames: &[FrameSum]) {
        for f in frames {
            self.sums.insert(f.step, (f.crc32, f.bytes));
        }
    }

    /// `(time, file name relative to the directory)` of every frame of the series.
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

impl Drop for Series {
    /// A series dropped without [`Series::finish`] (a run that failed elsewhere) still lists
    /// its frames in the `.pvd`; errors are moot then.
    fn drop(&mut self) {
        let _ = self.finish();
    }
}

/// The `.pvd` of `dir` listing `files`, path and text.
fn collection(dir: &Path, files: &[(f64, String)], run_id: &str) -> (PathBuf, String) {
    (dir.join(PVD_NAME), pvd::render(files, run_id))
}

/// The error for a series of another run in `at` (a directory or a file).
fn other_run(at: &Path, stored: &str, run_id: &str) -> Error {
    Error::input(format!(
        "{} holds frames of another run (run id {stored}, this run is {run_id}); choose \
         another output directory (--out) or remove them",
        at.display()
    ))
}

/// The point and cell arrays of a frame as `make` gives its fields (`sizes`: the points and
/// cells they must cover), checked and narrowed to what `options` asks for; run on the
/// writer's thread.
fn arrays(
    options: Options,
    sizes: (usize, usize),
    at: PathBuf,
    step: usize,
    make: impl FnOnce() -> (Vec<OwnedField>, Vec<OwnedField>) + Send + 'static,
) -> impl FnOnce() -> Result<(Vec<Array>, Vec<Array>)> + Send + 'static {
    move || checked_arrays(&options, (&at, step), make(), sizes)
}

/// The arrays of a frame's fields (`fields`: point fields, cell fields; `sizes`: the
/// points and cells they must cover), checked and narrowed to what `options` asks for; an
/// error names the frame's file `at` and its step.
pub(super) fn checked_arrays(
    options: &Options,
    (at, step): (&Path, usize),
    (points, cells): (Vec<OwnedField>, Vec<OwnedField>),
    sizes: (usize, usize),
) -> Result<(Vec<Array>, Vec<Array>)> {
    let checked = |fields: Vec<OwnedField>, count, what| {
        let sizes = fields
            .iter()
            .map(|f| (&f.name[..], f.components, f.values.len()));
        check_fields(sizes, count, what).map_err(|msg| frame_error(at, step, msg))?;
        Ok::<_, Error>(
            fields
                .into_iter()
                .filter(|f| options.wants(&f.name))
                .map(|f| f.array(options.precision))
                .collect::<Vec<_>>(),
        )
    };
    Ok((
        checked(points, sizes.0, "point")?,
        checked(cells, sizes.1, "cell")?,
    ))
}

/// Lists the .vtu of `step` in the series: a new entry, or (where a step is written again)
/// the old one's time replaced.
fn relist(files: &mut Vec<(f64, String)>, step: usize, time: f64, name: String) {
    // Steps normally increase: only an older step can already be listed.
    let newer = files.last().is_none_or(|(_, f)| step_of(f) < Some(step));
    let listed = if newer {
        None
    } else {
        files.iter_mut().find(|(_, f)| *f == name)
    };
    match listed {
        Some(entry) => entry.0 = time,
        None => files.push((time, name)),
    }
}

/// Checks sizes and names of the fields of one kind (`what` = "point" or "cell"), given as
/// (name, components, number of values).
fn check_fields<'f>(
    fields: impl Iterator<Item = (&'f str, usize, usize)>,
    count: usize,
    what: &str,
) -> std::result::Result<(), String> {
    let mut names = Vec::new();
    for (k, (name, components, len)) in fields.enumerate() {
        if name.is_empty() {
            return Err(format!("{what} field #{k} has an empty name"));
        }
        if names.contains(&name) {
            return Err(format!("{what} field `{name}` is given twice"));
        }
        names.push(name);
        if components == 0 || len != components * count {
            return Err(format!(
                "{what} field `{name}` has {len} values, expected {components} components × \
                 {count} {what}s"
            ));
        }
    }
    Ok(())
}

/// The input error of a frame's field.
fn frame_error(path: &Path, step: usize, msg: String) -> Error {
    Error::input(format!("{} (output step {step}): {msg}", path.display()))
}

/// The step number encoded in a `solution_NNNNNN.vtu` or `solution_NNNNNN.pvtu` name.
fn step_of(file: &str) -> Option<usize> {
    let rest = file.strip_prefix("solution_")?;
    let digits = rest.strip_suffix(".vtu").or(rest.strip_suffix(".pvtu"))?;
    digits.parse().ok()
}

/// The frame file of step `step` in `dir`: its `.pvtu` where there is one (a run over MPI
/// ranks), else its `.vtu`.
fn frame_file(dir: &Path, step: usize) -> String {
    match dir.join(pvtu_name(step)).exists() {
        true => pvtu_name(step),
        false => vtu_name(step),
    }
}

/// The CRC-32 and length of the file at `path`, read in blocks.
pub(crate) fn crc32_of_file(path: &Path) -> std::io::Result<(u32, u64)> {
    let mut h = crc32fast::Hasher::new();
    let len = hash_file(path, &mut h)?;
    Ok((h.finalize(), len))
}

/// Feeds the file at `path` to `h`, in blocks; returns its length.
fn hash_file(path: &Path, h: &mut crc32fast::Hasher) -> std::io::Result<u64> {
    use std::io::Read;
    let mut file = std::fs::File::open(path)?;
    let mut buf = vec![0u8; 1 << 18];
    let mut len = 0u64;
    loop {
        match file.read(&mut buf) {
            Ok(0) => return Ok(len),
            Ok(k) => {
                h.update(&buf[..k]);
                len += k as u64;
            }
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
}

/// Writes bytes to `path` through a temporary file in the same directory and a rename, so a
/// crash never leaves a half-written file where a good one was.
///
/// The temporary file (`.NAME.tmp.PID.N` beside `path`) is removed again on failure. The data
/// are not fsync'ed: the rename makes a process crash safe, which is what a run needs; the
/// output of a run is reproducible and a power failure is out of scope. Errors name `path`.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic_with(path, |file| file.write_all(bytes))
}

/// [`write_atomic`] of what `write` writes into the (empty) temporary file.
fn write_atomic_with(
    path: &Path,
    write: impl FnOnce(&mut std::fs::File) -> std::io::Result<()>,
) -> Result<()> {
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
        write(&mut file)?;
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
        assert_eq!(step_of("solution_000012.pvtu"), Some(12));
        assert_eq!(step_of("solution_000012/solution_000012_0.vtu"), None);
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
