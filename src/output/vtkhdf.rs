//! `solution.vtkhdf`: the whole series of a run in one temporal VTKHDF file
//! (`[output] format = "vtkhdf"`), which VTK ≥ 9.3 (`vtkHDFReader`) and ParaView ≥ 5.12 open
//! as a time series.
//!
//! # Layout (VTKHDF 2.2, temporal UnstructuredGrid, one part, static mesh)
//!
//! ```text
//! /VTKHDF                      attrs Version = [2, 2] (int64), Type = "UnstructuredGrid"
//!   NumberOfPoints [1]         int64   N
//!   NumberOfCells [1]          int64   C
//!   NumberOfConnectivityIds [1] int64  C·p (p = 3 triangle, 4 tetrahedron)
//!   Points [N, 3]              float64
//!   Connectivity [C·p]         int64
//!   Offsets [C + 1]            int64   0, p, 2p, …
//!   Types [C]                  uint8   5 = VTK_TRIANGLE, 10 = VTK_TETRA
//!   PointData/<field> [S·N, c] values of every frame, frame after frame (c = 1: [S·N])
//!   CellData/<field> [S·C, c]  likewise; CellData/region [C] int32 (gmsh tag) is static,
//!                              and so is CellData/material_region [C] int32 (a scene
//!                              with regions: the `[[material.region]]` entry)
//!   FieldData/run_id [1, len]  uint8, the bytes of the run id (one tuple: VTK reads one
//!                              tuple of a field data array a step)
//!   Steps                      attr NSteps = S (int64)
//!     Values [S]               float64 the time of each frame
//!     PartOffsets, NumberOfParts, PointOffsets, CellOffsets, ConnectivityIdOffsets [S]
//!                              int64 0, 1, 0, 0, 0: every frame has the one mesh above
//!     FieldDataOffsets/run_id [S]   int64 0: every frame has the one run id
//!     PointDataOffsets/<field> [S]  int64 k·N for frame k
//!     CellDataOffsets/<field> [S]   int64 k·C for frame k (the static ones: 0)
//! /viscontact/step [S]         int64 the step number n of each frame (outside /VTKHDF,
//!                              which the format leaves to the writer)
//! ```
//!
//! Field values are float64 or float32 (`precision`). Every dataset that grows is chunked
//! along its first dimension and has no limit there; a field's chunk is exactly one frame
//! (N or C rows), so appending a frame writes new chunks and never rewrites an old one. With
//! `compression = "zlib"` (the default) the fields and the mesh carry HDF5's deflate filter:
//! the mesh is compressed by HDF5 (level 1, once), each field chunk by `zlib.rs` (as the
//! .vtu frames) and handed over finished; `"none"` stores them raw. The small `Steps` arrays
//! are never compressed (1024 entries a chunk). No shuffle filter: on the 40 frames of
//! examples/paper.toml at h = 1/64 (31.3 MB of raw field values) deflate alone gave 16.1 MB,
//! shuffle + deflate 16.8 MB in a third more time (only von_mises shrank with it).
//!
//! # File format
//!
//! Every object is in the format of HDF5 1.10, in which all metadata carry a checksum
//! (Jenkins' lookup3): object headers of version 2 and chunk indexes of layout version 4, a
//! single chunk's address in the layout message (the mesh arrays) or an extensible array
//! (every growing dataset). The superblock is of version 2, also checksummed. So a flipped
//! bit in the metadata is an error of HDF5 when `resume` reads the file (`output::verify`),
//! not a file that it continues and that other HDF5 versions then fail on; in the format of
//! HDF5 1.8 the chunk index is a B-tree of version 1, without a checksum.
//!
//! Bounds: the file is created with low = 1.8, high = 1.10 (which gives superblock 2), and
//! then every object with low = high = 1.10 (`H5Fset_libver_bounds`). Not low = 1.10 at
//! creation: that gives superblock 3, which carries a mark "open for writing" while the file
//! is open, and HDF5 refuses to open a marked file, even to read it (short of SWMR): ParaView
//! could not show the series of a running run, and the file of a killed run could not be
//! opened again until `h5clear -s` unmarked it. High = 1.10 rather than the linked library's
//! latest: the file is the same whichever HDF5 viscontact is built with. Reading it takes
//! HDF5 ≥ 1.10 (1.8 cannot read layout version 4); `vtkHDFReader` (VTK ≥ 9.3, ParaView ≥
//! 5.12) and h5py ship a newer one. A file written by viscontact before this format has the
//! B-tree 1 chunk index; it is read and continued as it is.
//!
//! # Writing, flushing, and what a crash leaves
//!
//! The file is created at the first frame (a run whose setup fails leaves the old one as it
//! was). Each frame extends the field arrays by one chunk, appends one entry to each `Steps`
//! array and to `/viscontact/step`, sets `NSteps`, and then flushes the file (`H5Fflush`):
//! after every frame the file on disk is a complete series of the frames so far. Between
//! flushes HDF5 keeps the file's metadata in memory (a frame changes a few kB of it, far
//! below the metadata cache), and the new chunks go to space past the end the file on disk
//! records; a process killed there (kill -9, out of memory) leaves the file as the last flush
//! wrote it, which HDF5 opens with every frame flushed before. A kill during the flush itself
//! (well under a millisecond of each frame) can leave some of the frame's metadata written
//! and some not: chunk indexes that point past the end of allocated space the superblock
//! records (written last), which every open mends (`cover_written_space`). Each piece of
//! metadata is written whole, with its checksum, and what the frames before the checkpoint
//! need was flushed before it: runs killed just before one of their writes to the file (each
//! write of the flushes that add index blocks, a sample of the others) all resumed
//! (docs/restart.md). Should HDF5 still refuse a file, `resume` never overwrites it: it stops
//! (exit 2) naming the file, and moving the file aside lets the resumed run write a new one
//! from the checkpoint's step on.
//!
//! The number of frames a file holds is the smallest count that every array agrees on
//! (`NSteps`, `Values`, every offset array, every field's rows ÷ N or C), so a frame whose
//! arrays were not all extended is not counted. `resume` keeps the frames up to the
//! checkpoint's step; its first new frame cuts every array back to them and appends.

use std::borrow::Cow;
use std::path::{Path, PathBuf};

use hdf5::file::LibraryVersion::{self, V110, V18};
use hdf5::types::FixedAscii;
use hdf5::{Dataset, Extent, Group, H5Type, OpenMode, SimpleExtents};
use hdf5_metno as hdf5;
use hdf5_metno_sys as hdf5_sys;

use super::writer::Written;
use super::{zlib, Array, Compression, Geometry, Precision, Values, STATIC_CELL_FIELDS};
use crate::{Error, Result};

/// Level of HDF5's deflate filter: it compresses the mesh (once); the fields' chunks come
/// compressed from `zlib.rs`, and the filter only says how to read them.
const DEFLATE_LEVEL: u8 = 1;

/// Entries per chunk of the `Steps` arrays.
const STEPS_CHUNK: usize = 1024;

/// The `Steps` arrays that say every frame has the one mesh, with their value per frame.
const MESH_OFFSETS: [(&str, i64); 5] = [
    ("PartOffsets", 0),
    ("NumberOfParts", 1),
    ("PointOffsets", 0),
    ("CellOffsets", 0),
    ("ConnectivityIdOffsets", 0),
];

/// One frame for the writer thread: frame number `index` of the file (the frames from
/// `index` on are dropped first).
pub(super) struct Job {
    pub index: usize,
    pub step: usize,
    pub time: f64,
    pub point_data: Vec<Array>,
    pub cell_data: Vec<Array>,
}

/// The writer thread's side of `solution.vtkhdf`: the mesh to write at the first frame, and
/// the file while the thread runs.
pub(super) struct Sink {
    path: PathBuf,
    points: Vec<[f64; 3]>,
    cells: Vec<usize>,
    nodes_per_cell: usize,
    cell_type: u8,
    /// The static cell fields (`output::STATIC_CELL_FIELDS`) the geometry has.
    cell_arrays: Vec<(&'static str, Vec<i32>)>,
    run_id: String,
    compression: Compression,
    open: Option<Open>,
}

/// The open file and the number of frames it holds.
struct Open {
    file: hdf5::File,
    frames: usize,
}

pub(super) fn h5_open(path: &Path, mode: OpenMode) -> hdf5::Result<hdf5::File> {
    // File locking off, as for checkpoints (checkpoint/h5.rs): a child process inherits
    // HDF5's flock and would keep the file locked for as long as it lives. The format of a
    // new file: module doc, "File format".
    let file = hdf5::File::with_options()
        .with_fapl(|p| match mode {
            OpenMode::Create => p.file_locking(false).libver_bounds(V18, V110),
            _ => p.file_locking(false),
        })
        .open_as(path, mode)?;
    match mode {
        OpenMode::Create => create_objects_as(&file, V110),
        _ => cover_written_space(&file),
    }?;
    Ok(file)
}

extern "C" {
    /// HDF5 ≥ 1.10.2 (`H5Fpublic.h`), not bound by hdf5-metno-sys: sets the file's end of
    /// allocated space to the larger of it and the file's size, plus `increment`.
    fn H5Fincrement_filesize(
        file_id: hdf5_sys::h5i::hid_t,
        increment: hdf5_sys::h5::hsize_t,
    ) -> hdf5_sys::h5::herr_t;

    /// HDF5 ≥ 1.10.2 (`H5Fpublic.h`), not bound by hdf5-metno-sys: the format versions of
    /// the objects created in the open file from now on.
    fn H5Fset_libver_bounds(
        file_id: hdf5_sys::h5i::hid_t,
        low: hdf5_sys::h5f::H5F_libver_t,
        high: hdf5_sys::h5f::H5F_libver_t,
    ) -> hdf5_sys::h5::herr_t;
}

/// The objects created in `file` from now on take the format of library `version` exactly
/// (as low and high bound); the superblock keeps the version it was created with.
fn create_objects_as(file: &hdf5::File, version: LibraryVersion) -> hdf5::Result<()> {
    // SAFETY: `file` is an open file; the call holds hdf5-metno's library lock like every
    // other HDF5 call of the process.
    let status = hdf5::sync::sync(|| unsafe {
        H5Fset_libver_bounds(file.id(), version.into(), version.into())
    });
    match status < 0 {
        true => Err("H5Fset_libver_bounds failed".into()),
        false => Ok(()),
    }
}

/// Lets HDF5 read everything the file holds, as `h5clear --increment=0` would. A flush
/// writes the superblock, which records where the file's allocated space ends, after the
/// other metadata; a process killed within a flush can leave chunk indexes on disk that
/// point at chunks past that recorded end (written before the flush), and HDF5 then refuses
/// to read them ("addr overflow") although every byte is in the file. The recorded end is
/// moved to the file's size: in memory only for a file opened to read, written with the next
/// flush for one opened to append. Whether the frames so read are intact is then for the
/// checkpoint's checksums to say (`output::verify`).
fn cover_written_space(file: &hdf5::File) -> hdf5::Result<()> {
    // SAFETY: `file` is an open file; the call holds hdf5-metno's library lock like every
    // other HDF5 call of the process.
    let status = hdf5::sync::sync(|| unsafe { H5Fincrement_filesize(file.id(), 0) });
    match status < 0 {
        true => Err("H5Fincrement_filesize failed".into()),
        false => Ok(()),
    }
}

impl Sink {
    pub(super) fn new(
        path: &Path,
        g: &Geometry,
        run_id: &str,
        compression: Compression,
    ) -> Result<Sink> {
        Ok(Sink {
            path: path.to_path_buf(),
            cell_type: g.cell_type()?,
            points: g.points.whole().to_vec(),
            cells: g.cells.to_vec(),
            nodes_per_cell: g.nodes_per_cell,
            cell_arrays: (g.cell_statics().into_iter())
                .map(|(name, values)| (name, values.to_vec()))
                .collect(),
            run_id: run_id.to_string(),
            compression,
            open: None,
        })
    }

    fn num_points(&self) -> usize {
        self.points.len()
    }

    fn num_cells(&self) -> usize {
        self.cells.len() / self.nodes_per_cell
    }

    /// A new file with the mesh and the datasets of the fields of `job` (none of them
    /// holding a frame yet).
    fn create(&self, job: &Job) -> hdf5::Result<hdf5::File> {
        let file = h5_open(&self.path, OpenMode::Create)?;
        let root = file.create_group("VTKHDF")?;
        root.new_attr::<i64>()
            .shape(2)
            .create("Version")?
            .write_raw(&[2i64, 2])?;
        let ty = FixedAscii::<16>::from_ascii(b"UnstructuredGrid").expect("16 ASCII bytes");
        root.new_attr::<FixedAscii<16>>()
            .shape(())
            .create("Type")?
            .write_scalar(&ty)?;
        let (n, c, p) = (self.num_points(), self.num_cells(), self.nodes_per_cell);
        for (name, value) in [
            ("NumberOfPoints", n),
            ("NumberOfCells", c),
            ("NumberOfConnectivityIds", c * p),
        ] {
            root.new_dataset::<i64>()
                .shape(1)
                .create(name)?
                .write_raw(&[value as i64])?;
        }
        let points = ndarray::ArrayView2::from_shape((n, 3), self.points.as_flattened())
            .expect("3 coordinates a point");
        self.fixed::<f64>(&root, "Points", &[n, 3])?.write(points)?;
        let conn: Vec<i64> = self.cells.iter().map(|&i| i as i64).collect();
        self.fixed::<i64>(&root, "Connectivity", &[c * p])?
            .write_raw(&conn)?;
        let offsets: Vec<i64> = (0..=c).map(|k| (k * p) as i64).collect();
        self.fixed::<i64>(&root, "Offsets", &[c + 1])?
            .write_raw(&offsets)?;
        self.fixed::<u8>(&root, "Types", &[c])?
            .write_raw(&vec![self.cell_type; c])?;
        let field_data = root.create_group("FieldData")?;
        self.fixed::<u8>(&field_data, "run_id", &[1, self.run_id.len()])?
            .write_raw(self.run_id.as_bytes())?;

        let steps = root.create_group("Steps")?;
        steps
            .new_attr::<i64>()
            .shape(())
            .create("NSteps")?
            .write_scalar(&0i64)?;
        growing::<f64>(&steps, "Values")?;
        for (name, _) in MESH_OFFSETS {
            growing::<i64>(&steps, name)?;
        }
        growing::<i64>(&steps.create_group("FieldDataOffsets")?, "run_id")?;
        let point_offsets = steps.create_group("PointDataOffsets")?;
        let cell_offsets = steps.create_group("CellDataOffsets")?;
        let point_data = root.create_group("PointData")?;
        let cell_data = root.create_group("CellData")?;
        for (data, offsets, arrays, rows) in [
            (&point_data, &point_offsets, &job.point_data, n),
            (&cell_data, &cell_offsets, &job.cell_data, c),
        ] {
            for a in arrays {
                self.field(data, a, rows)?;
                growing::<i64>(offsets, &a.name)?;
            }
        }
        for (name, values) in &self.cell_arrays {
            self.fixed::<i32>(&cell_data, name, &[c])?
                .write_raw(values)?;
            growing::<i64>(&cell_offsets, name)?;
        }
        growing::<i64>(&file.create_group("viscontact")?, "step")?;
        Ok(file)
    }

    /// A dataset of fixed `shape`, compressed (one chunk) unless `compression = "none"`.
    fn fixed<T: H5Type>(&self, g: &Group, name: &str, shape: &[usize]) -> hdf5::Result<Dataset> {
        let b = g.new_dataset::<T>().shape(shape);
        if self.compression == Compression::Zlib && shape.iter().all(|&d| d > 0) {
            b.chunk(shape).deflate(DEFLATE_LEVEL).create(name)
        } else {
            b.create(name)
        }
    }

    /// The growing dataset of field `a`: `rows` rows (one chunk) a frame.
    fn field(&self, g: &Group, a: &Array, rows: usize) -> hdf5::Result<Dataset> {
        let (shape, chunk) = if a.components == 1 {
            (vec![Extent::resizable(0)], vec![rows.max(1)])
        } else {
            (
                vec![Extent::resizable(0), Extent::fixed(a.components)],
                vec![rows.max(1), a.components],
            )
        };
        let b = match a.values {
            Values::F64(_) => g.new_dataset::<f64>(),
            Values::F32(_) => g.new_dataset::<f32>(),
        }
        .shape(SimpleExtents::from_vec(shape))
        .chunk(chunk);
        match self.compression {
            Compression::Zlib => b.deflate(DEFLATE_LEVEL).create(a.name.as_str()),
            Compression::None => b.create(a.name.as_str()),
        }
    }

    /// The file, open, holding exactly `index` frames: created at frame 0, else opened (if
    /// the thread just started) and cut back to `index` frames.
    fn file_at(&mut self, job: &Job) -> Result<&hdf5::File> {
        let h5 = |e| Error::hdf5(&self.path, e);
        if job.index == 0 {
            self.open = None;
            let file = self.create(job).map_err(h5)?;
            self.open = Some(Open { file, frames: 0 });
        } else if self.open.is_none() {
            let file = h5_open(&self.path, OpenMode::ReadWrite).map_err(h5)?;
            // The fields are the run's, the same in every frame: checked once, when an
            // existing file is opened, before anything in it is cut.
            let root = file.group("VTKHDF").map_err(h5)?;
            for (group, arrays) in [("PointData", &job.point_data), ("CellData", &job.cell_data)] {
                self.check_fields(&root.group(group).map_err(h5)?, arrays)?;
            }
            let frames = frames_in(&file, self.num_points(), self.num_cells()).map_err(h5)?;
            self.open = Some(Open { file, frames });
        }
        let open = self.open.as_mut().expect("opened above");
        if job.index > open.frames {
            return Err(Error::solve(format!(
                "{}: frame {} written after only {} frames",
                self.path.display(),
                job.index,
                open.frames
            )));
        }
        if job.index < open.frames {
            let (n, c) = (self.points.len(), self.cells.len() / self.nodes_per_cell);
            truncate(&open.file, job.index, n, c).map_err(|e| Error::hdf5(&self.path, e))?;
            open.frames = job.index;
        }
        Ok(&open.file)
    }

    /// Appends the frame to the open file that holds `job.index` frames, then flushes.
    fn append(&self, file: &hdf5::File, job: &Job) -> Result<()> {
        let h5 = |e| Error::hdf5(&self.path, e);
        let root = file.group("VTKHDF").map_err(h5)?;
        let steps = root.group("Steps").map_err(h5)?;
        let k = job.index;
        let none = Vec::new();
        let deflate = self.compression == Compression::Zlib;
        for (data, offsets, arrays, rows, statics) in [
            (
                "PointData",
                "PointDataOffsets",
                &job.point_data,
                self.num_points(),
                &none,
            ),
            (
                "CellData",
                "CellDataOffsets",
                &job.cell_data,
                self.num_cells(),
                &self.cell_arrays,
            ),
        ] {
            let data = root.group(data).map_err(h5)?;
            let offsets = steps.group(offsets).map_err(h5)?;
            (|| {
                for a in arrays {
                    let ds = data.dataset(&a.name)?;
                    write_rows(&ds, a, k * rows, rows, deflate)?;
                    push(&offsets.dataset(&a.name)?, k, (k * rows) as i64)?;
                }
                for (name, _) in statics {
                    // A static cell field: every frame reads it from its start.
                    push(&offsets.dataset(name)?, k, 0i64)?;
                }
                Ok(())
            })()
            .map_err(h5)?;
        }
        let push_at =
            |g: &Group, name: &str, v: i64| g.dataset(name).and_then(|ds| push(&ds, k, v));
        (|| {
            for (name, v) in MESH_OFFSETS {
                push_at(&steps, name, v)?;
            }
            push(&steps.dataset("Values")?, k, job.time)?;
            push_at(&steps.group("FieldDataOffsets")?, "run_id", 0)?;
            push_at(&file.group("viscontact")?, "step", job.step as i64)?;
            steps.attr("NSteps")?.write_scalar(&((k + 1) as i64))?;
            file.flush()
        })()
        .map_err(h5)
    }

    /// The growing datasets of `data` must be the fields of the frame, with their
    /// components and precision: a resumed run must write what the file holds.
    fn check_fields(&self, data: &Group, arrays: &[Array]) -> Result<()> {
        let h5 = |e| Error::hdf5(&self.path, e);
        let mut stored = Vec::new();
        for ds in data.datasets().map_err(h5)? {
            if ds.is_resizable() {
                let name = ds.name();
                let name = name.rsplit('/').next().unwrap_or_default().to_string();
                let shape = ds.shape();
                let f32 = ds.dtype().map_err(h5)?.size() == 4;
                stored.push((name, shape.get(1).copied().unwrap_or(1), f32));
            }
        }
        stored.sort();
        let mut wanted: Vec<_> = arrays
            .iter()
            .map(|a| {
                let f32 = matches!(a.values, Values::F32(_));
                (a.name.clone(), a.components, f32)
            })
            .collect();
        wanted.sort();
        if stored == wanted {
            return Ok(());
        }
        let describe = |v: &[(String, usize, bool)]| {
            v.iter()
                .map(|(n, c, f32)| {
                    format!("{n} ({c} × {})", if *f32 { "float32" } else { "float64" })
                })
                .collect::<Vec<_>>()
                .join(", ")
        };
        Err(Error::input(format!(
            "{} holds the fields {} in '{}', but this run writes {}; resume with the [output] \
             fields and precision of the run that wrote it, or move the file aside",
            self.path.display(),
            describe(&stored),
            data.name(),
            describe(&wanted)
        )))
    }
}

impl super::writer::Sink for Sink {
    type Job = Job;

    /// Appends the frame; its CRC-32 is that of its field values ([`frame_crc`]).
    fn write(&mut self, job: Job) -> Result<Option<Written>> {
        self.file_at(&job)?;
        let open = self.open.as_ref().expect("file_at opened it");
        self.append(&open.file, &job)?;
        self.open.as_mut().expect("open").frames = job.index + 1;
        fn bytes(arrays: &[Array]) -> Vec<(String, Cow<'_, [u8]>)> {
            arrays
                .iter()
                .map(|a| (a.name.clone(), a.le_bytes()))
                .collect()
        }
        let (crc32, bytes) = frame_crc(bytes(&job.point_data), bytes(&job.cell_data));
        Ok(Some(Written {
            step: job.step,
            crc32,
            bytes,
        }))
    }

    /// Closes the file (every frame was flushed when it was written).
    fn close(&mut self) -> Result<()> {
        match self.open.take() {
            Some(open) => open.file.close().map_err(|e| Error::hdf5(&self.path, e)),
            None => Ok(()),
        }
    }
}

/// CRC-32 and length of a frame's field values as stored: the little-endian bytes of its
/// point fields in name order, then of its cell fields likewise (the static `region` is
/// the mesh's, not a frame's).
fn frame_crc(
    mut point: Vec<(String, Cow<'_, [u8]>)>,
    mut cell: Vec<(String, Cow<'_, [u8]>)>,
) -> (u32, u64) {
    point.sort_by(|a, b| a.0.cmp(&b.0));
    cell.sort_by(|a, b| a.0.cmp(&b.0));
    let mut h = crc32fast::Hasher::new();
    let mut len = 0;
    for (_, bytes) in point.iter().chain(&cell) {
        h.update(bytes);
        len += bytes.len() as u64;
    }
    (h.finalize(), len)
}

/// A 1-D dataset of `T` that grows by one entry a frame, uncompressed.
fn growing<T: H5Type>(g: &Group, name: &str) -> hdf5::Result<Dataset> {
    g.new_dataset::<T>()
        .shape(SimpleExtents::from_vec(vec![Extent::resizable(0)]))
        .chunk(STEPS_CHUNK)
        .create(name)
}

/// Sets entry `at` of a growing 1-D dataset to `v`, extending it to `at + 1` entries.
fn push<T: H5Type>(ds: &Dataset, at: usize, v: T) -> hdf5::Result<()> {
    ds.resize(at + 1)?;
    ds.write_slice(&[v], at..at + 1)
}

/// Writes the values of `a` as rows `from..from + rows` of its growing dataset: one chunk.
/// `deflate`: the dataset has HDF5's deflate filter; the chunk is compressed here, by
/// `zlib.rs` (as the .vtu frames) and written as it is (`H5Dwrite_chunk`); readers inflate
/// it with the filter. With HDF5's own deflate (the system zlib) the 200 frames of
/// examples/paper.toml at h = 1/64 cost 3.5 s more CPU than raw ones (4.59 s against 1.05 s
/// user time), and the run took 7.1 s instead of 4.3 s.
fn write_rows(
    ds: &Dataset,
    a: &Array,
    from: usize,
    rows: usize,
    deflate: bool,
) -> hdf5::Result<()> {
    let c = a.components;
    if c == 1 {
        ds.resize(from + rows)?;
    } else {
        ds.resize((from + rows, c))?;
    }
    // The chunk's bytes are the values' little-endian bytes: the dataset's native type on
    // a little-endian machine.
    if deflate && cfg!(target_endian = "little") {
        let mut chunk = Vec::new();
        zlib::compress(&a.le_bytes(), &mut chunk);
        let offset: Vec<hdf5_sys::h5::hsize_t> = if c == 1 {
            vec![from as _]
        } else {
            vec![from as _, 0]
        };
        // SAFETY: `ds` is an open dataset, `offset` has its rank and lies at a chunk
        // boundary inside it (resized above), `chunk` holds `chunk.len()` bytes; the call
        // holds hdf5-metno's library lock like every other HDF5 call of the process.
        let status = hdf5::sync::sync(|| unsafe {
            hdf5_sys::h5d::H5Dwrite_chunk(
                ds.id(),
                hdf5_sys::h5p::H5P_DEFAULT,
                0,
                offset.as_ptr(),
                chunk.len(),
                chunk.as_ptr().cast(),
            )
        });
        return if status < 0 {
            Err(format!("H5Dwrite_chunk of {} failed", a.name).into())
        } else {
            Ok(())
        };
    }
    if c == 1 {
        return match &a.values {
            Values::F64(v) => ds.write_slice(v.as_slice(), from..from + rows),
            Values::F32(v) => ds.write_slice(v.as_slice(), from..from + rows),
        };
    }
    let sel = ndarray::s![from..from + rows, ..];
    let shape = (rows, c);
    match &a.values {
        Values::F64(v) => ds.write_slice(view(v, shape), sel),
        Values::F32(v) => ds.write_slice(view(v, shape), sel),
    }
}

fn view<T>(v: &[T], shape: (usize, usize)) -> ndarray::ArrayView2<'_, T> {
    ndarray::ArrayView2::from_shape(shape, v).expect("sizes checked by Series::write")
}

/// Cuts every growing array back to `frames` frames (N points, C cells).
fn truncate(file: &hdf5::File, frames: usize, n: usize, c: usize) -> hdf5::Result<()> {
    let root = file.group("VTKHDF")?;
    let steps = root.group("Steps")?;
    for (data, offsets, rows) in [
        ("PointData", "PointDataOffsets", n),
        ("CellData", "CellDataOffsets", c),
    ] {
        for ds in root.group(data)?.datasets()? {
            if ds.is_resizable() {
                let mut shape = ds.shape();
                shape[0] = frames * rows;
                ds.resize(shape)?;
            }
        }
        for ds in steps.group(offsets)?.datasets()? {
            ds.resize(frames)?;
        }
    }
    for ds in steps
        .datasets()?
        .into_iter()
        .chain(steps.group("FieldDataOffsets")?.datasets()?)
    {
        ds.resize(frames)?;
    }
    file.group("viscontact")?.dataset("step")?.resize(frames)?;
    steps.attr("NSteps")?.write_scalar(&(frames as i64))
}

/// The number of complete frames: the smallest count every array agrees on.
fn frames_in(file: &hdf5::File, n: usize, c: usize) -> hdf5::Result<usize> {
    let root = file.group("VTKHDF")?;
    let steps = root.group("Steps")?;
    let nsteps: i64 = steps.attr("NSteps")?.read_scalar()?;
    let mut frames = usize::try_from(nsteps).unwrap_or(0);
    frames = frames.min(file.group("viscontact")?.dataset("step")?.shape()[0]);
    for ds in steps
        .datasets()?
        .into_iter()
        .chain(steps.group("FieldDataOffsets")?.datasets()?)
    {
        frames = frames.min(ds.shape()[0]);
    }
    for (data, offsets, rows) in [
        ("PointData", "PointDataOffsets", n),
        ("CellData", "CellDataOffsets", c),
    ] {
        for ds in root.group(data)?.datasets()? {
            if ds.is_resizable() {
                frames = frames.min(ds.shape()[0] / rows.max(1));
            }
        }
        for ds in steps.group(offsets)?.datasets()? {
            frames = frames.min(ds.shape()[0]);
        }
    }
    Ok(frames)
}

/// What a `solution.vtkhdf` holds, read back (for `resume` and `plot`).
#[derive(Clone, Debug)]
pub(super) struct Stored {
    pub run_id: String,
    /// `(step, time)` of each complete frame.
    pub frames: Vec<(usize, f64)>,
    pub num_points: usize,
    pub num_cells: usize,
    /// Whether the fields are float32.
    pub float32: bool,
}

impl Stored {
    /// Reads the file's frames and run id. A file that HDF5 cannot open or that is not a
    /// VTKHDF file of this module is an input error naming it and what to do; nothing is
    /// changed.
    pub(super) fn read(path: &Path) -> Result<Stored> {
        Stored::read_h5(path).map_err(|e| {
            Error::input(format!(
                "{}: cannot be read as a VTKHDF series written by viscontact ({e}); it may have \
                 been damaged by a crash while a frame was flushed. It was left as it is: move \
                 it aside to keep it (a resumed run then writes a new one from the \
                 checkpoint's step on), or run the scene again",
                path.display()
            ))
        })
    }

    fn read_h5(path: &Path) -> hdf5::Result<Stored> {
        let file = h5_open(path, OpenMode::Read)?;
        let root = file.group("VTKHDF")?;
        let ty: FixedAscii<16> = root.attr("Type")?.read_scalar()?;
        if ty.as_str() != "UnstructuredGrid" {
            return Err(format!("Type is {:?}, not UnstructuredGrid", ty.as_str()).into());
        }
        let count = |name: &str| -> hdf5::Result<usize> {
            Ok(root
                .dataset(name)?
                .read_raw::<i64>()?
                .first()
                .copied()
                .unwrap_or(0) as usize)
        };
        let (n, c) = (count("NumberOfPoints")?, count("NumberOfCells")?);
        let frames = frames_in(&file, n, c)?;
        let run_id = root
            .group("FieldData")?
            .dataset("run_id")?
            .read_raw::<u8>()?;
        let steps = file
            .group("viscontact")?
            .dataset("step")?
            .read_raw::<i64>()?;
        let times = root.group("Steps")?.dataset("Values")?.read_raw::<f64>()?;
        let float32 = root
            .group("PointData")?
            .datasets()?
            .into_iter()
            .chain(root.group("CellData")?.datasets()?)
            .filter(|ds| ds.is_resizable())
            .try_fold(false, |_, ds| ds.dtype().map(|t| t.size() == 4))?;
        Ok(Stored {
            run_id: String::from_utf8_lossy(&run_id).into_owned(),
            frames: steps
                .iter()
                .zip(&times)
                .take(frames)
                .map(|(&s, &t)| (s as usize, t))
                .collect(),
            num_points: n,
            num_cells: c,
            float32,
        })
    }

    /// A resumed run must write into the file the mesh and precision it holds.
    pub(super) fn check(&self, path: &Path, g: &Geometry, precision: Precision) -> Result<()> {
        let (n, c) = (
            g.points.whole().len(),
            g.cells.len() / g.nodes_per_cell.max(1),
        );
        if (self.num_points, self.num_cells) != (n, c) {
            return Err(Error::input(format!(
                "{} holds a mesh of {} points and {} cells, this run's has {n} and {c}; move \
                 the file aside or choose another output directory (--out)",
                path.display(),
                self.num_points,
                self.num_cells
            )));
        }
        let float32 = precision == Precision::Float32;
        if !self.frames.is_empty() && self.float32 != float32 {
            let name = |f32: bool| if f32 { "float32" } else { "float64" };
            return Err(Error::input(format!(
                "{} holds {} fields, but output.precision is \"{}\"; resume with \
                 --set output.precision='\"{}\"', or move the file aside",
                path.display(),
                name(self.float32),
                name(float32),
                name(self.float32)
            )));
        }
        Ok(())
    }
}

/// What frames `0..limit` of a `solution.vtkhdf` hold, read back in full and checked entry by
/// entry against what [`Sink`] writes for the mesh `g` and run `run_id`: the file's format
/// (superblock version ≥ 2, whose superblock and object headers are checksummed; module
/// doc, "File format"), the run id, the mesh arrays bit for bit, every `Steps` array, and
/// the CRC-32 of each frame's field values ([`frame_crc`], read through HDF5, so every chunk
/// is inflated). Fewer frames than `limit`
/// are returned when the file holds fewer; anything else wrong is the error (what, where).
/// `checksummed`: require the checksummed format (a file an older viscontact wrote has
/// none; it is read as it is only for an unverified resume).
pub(super) fn stored_sums(
    path: &Path,
    g: &Geometry,
    run_id: &str,
    limit: usize,
    checksummed: bool,
) -> std::result::Result<Vec<super::FrameSum>, String> {
    let mut head = [0u8; 9];
    std::fs::File::open(path)
        .and_then(|mut f| std::io::Read::read_exact(&mut f, &mut head))
        .map_err(|e| format!("cannot be read ({e})"))?;
    if checksummed && (head[..8] != *b"\x89HDF\r\n\x1a\n" || head[8] < 2) {
        return Err("its HDF5 superblock is damaged or of a format without checksums".into());
    }
    let file = h5_open(path, OpenMode::Read).map_err(|e| e.to_string())?;
    visit_every_object(&file).map_err(|e| e.to_string())?;
    check_static(&file, g, run_id)?;
    let (n, c) = (
        g.points.whole().len(),
        g.cells.len() / g.nodes_per_cell.max(1),
    );
    let frames = frames_in(&file, n, c)
        .map_err(|e| e.to_string())?
        .min(limit);
    check_steps(&file, frames, n, c)?;
    let read = || -> hdf5::Result<Vec<super::FrameSum>> {
        let root = file.group("VTKHDF")?;
        let steps = file
            .group("viscontact")?
            .dataset("step")?
            .read_raw::<i64>()?;
        let times = root.group("Steps")?.dataset("Values")?.read_raw::<f64>()?;
        let fields = |group: &str| -> hdf5::Result<Vec<(String, Dataset)>> {
            let mut v = Vec::new();
            for ds in root.group(group)?.datasets()? {
                if ds.is_resizable() {
                    let name = ds.name().rsplit('/').next().unwrap_or_default().to_string();
                    v.push((name, ds));
                }
            }
            Ok(v)
        };
        let (point, cell) = (fields("PointData")?, fields("CellData")?);
        let mut sums = Vec::with_capacity(frames);
        for k in 0..frames {
            let rows = |v: &[(String, Dataset)], r| -> hdf5::Result<Vec<_>> {
                v.iter()
                    .map(|(name, ds)| Ok((name.clone(), Cow::Owned(rows_le(ds, k * r, r)?))))
                    .collect()
            };
            let (crc32, bytes) = frame_crc(rows(&point, n)?, rows(&cell, c)?);
            sums.push(super::FrameSum {
                step: steps[k] as usize,
                time: times[k],
                crc32,
                bytes,
            });
        }
        Ok(sums)
    };
    read().map_err(|e| e.to_string())
}

/// Reads the metadata of every object in `file` as h5py's `visititems` does: each object
/// header, and the B-trees, heaps and free-space headers that hold a group's links or index
/// a dataset's chunks (`H5Ovisit` with every field of the object info). HDF5 checks each
/// one's checksum as it reads it; reading the frames alone would not touch all of them (a
/// flipped bit in the free-space header of a group's link heap passed resume and then made
/// h5py's `visititems` fail).
fn visit_every_object(file: &hdf5::File) -> hdf5::Result<()> {
    use hdf5_sys::h5::{H5_index_t, H5_iter_order_t};
    use hdf5_sys::h5o::{H5O_info1_t, H5Ovisit2, H5O_INFO_ALL};
    extern "C" fn each(
        _: hdf5_sys::h5i::hid_t,
        _: *const std::ffi::c_char,
        _: *const H5O_info1_t,
        _: *mut std::ffi::c_void,
    ) -> hdf5_sys::h5::herr_t {
        0
    }
    // SAFETY: `file` is an open file and `each` ignores its arguments; the call holds
    // hdf5-metno's library lock like every other HDF5 call of the process. `h5check` turns
    // a failure into HDF5's own message (what was damaged), as hdf5-metno's calls do.
    hdf5::sync::sync(|| {
        hdf5::h5check(unsafe {
            H5Ovisit2(
                file.id(),
                H5_index_t::H5_INDEX_NAME,
                H5_iter_order_t::H5_ITER_NATIVE,
                Some(each),
                std::ptr::null_mut(),
                H5O_INFO_ALL,
            )
        })
    })
    .map(|_| ())
}

/// Rows `from..from + rows` of a field dataset, as the little-endian bytes of its type.
fn rows_le(ds: &Dataset, from: usize, rows: usize) -> hdf5::Result<Vec<u8>> {
    fn read<T: H5Type + Copy, const B: usize>(
        ds: &Dataset,
        from: usize,
        rows: usize,
        le: fn(T) -> [u8; B],
    ) -> hdf5::Result<Vec<u8>> {
        let values: Vec<T> = if ds.ndim() == 1 {
            ds.read_slice_1d::<T, _>(from..from + rows)?.to_vec()
        } else {
            ds.read_slice_2d::<T, _>(ndarray::s![from..from + rows, ..])?
                .iter()
                .copied()
                .collect()
        };
        Ok(values.into_iter().flat_map(le).collect())
    }
    match ds.dtype()?.size() {
        4 => read(ds, from, rows, f32::to_le_bytes),
        _ => read(ds, from, rows, f64::to_le_bytes),
    }
}

/// The mesh arrays and the run id hold exactly what [`Sink::create`] writes for `g`.
fn check_static(file: &hdf5::File, g: &Geometry, run_id: &str) -> std::result::Result<(), String> {
    let (n, c, p) = (
        g.points.whole().len(),
        g.cells.len() / g.nodes_per_cell.max(1),
        g.nodes_per_cell,
    );
    let cell_type = g.cell_type().map_err(|e| e.to_string())?;
    let read = || -> hdf5::Result<Vec<(&'static str, bool)>> {
        let root = file.group("VTKHDF")?;
        let i64s = |name: &str| root.dataset(name).and_then(|d| d.read_raw::<i64>());
        let points = root.dataset("Points")?.read_raw::<f64>()?;
        let mut statics = Vec::new();
        for (name, values) in g.cell_statics() {
            let stored = root
                .dataset(&format!("CellData/{name}"))?
                .read_raw::<i32>()?;
            statics.push((name, stored == values));
        }
        let mut checks = vec![
            ("NumberOfPoints", i64s("NumberOfPoints")? == [n as i64]),
            ("NumberOfCells", i64s("NumberOfCells")? == [c as i64]),
            (
                "NumberOfConnectivityIds",
                i64s("NumberOfConnectivityIds")? == [(c * p) as i64],
            ),
            (
                "Points",
                points.len() == 3 * n
                    && points
                        .iter()
                        .zip(g.points.whole().as_flattened())
                        .all(|(a, b)| a.to_bits() == b.to_bits()),
            ),
            (
                "Connectivity",
                i64s("Connectivity")?
                    .iter()
                    .map(|&i| i as usize)
                    .eq(g.cells.iter().copied()),
            ),
            (
                "Offsets",
                i64s("Offsets")?
                    .iter()
                    .map(|&o| o as usize)
                    .eq((0..=c).map(|k| k * p)),
            ),
            (
                "Types",
                root.dataset("Types")?.read_raw::<u8>()? == vec![cell_type; c],
            ),
            (
                "FieldData/run_id",
                root.dataset("FieldData/run_id")?.read_raw::<u8>()? == run_id.as_bytes(),
            ),
        ];
        let cell_data = |name| match name {
            "region" => "CellData/region",
            _ => "CellData/material_region",
        };
        checks.extend(statics.into_iter().map(|(name, ok)| (cell_data(name), ok)));
        Ok(checks)
    };
    let checks = read().map_err(|e| e.to_string())?;
    match checks.iter().find(|(_, ok)| !ok) {
        Some((name, _)) => Err(format!(
            "/VTKHDF/{name} differs from what this run wrote (damaged, or the file of another \
             run or mesh)"
        )),
        None => Ok(()),
    }
}

/// Every `Steps` entry of frames `0..frames` is what [`Sink::append`] writes (N points, C
/// cells): the mesh offsets, the field offsets k·N and k·C (the static cell fields: 0), the
/// run id's 0.
fn check_steps(
    file: &hdf5::File,
    frames: usize,
    n: usize,
    c: usize,
) -> std::result::Result<(), String> {
    let read = || -> hdf5::Result<Option<String>> {
        let steps = file.group("VTKHDF/Steps")?;
        // (array, value at frame 0, increment per frame)
        let mut expected: Vec<(String, i64, i64)> = Vec::new();
        for (name, v) in MESH_OFFSETS {
            expected.push((name.to_string(), v, 0));
        }
        expected.push(("FieldDataOffsets/run_id".into(), 0, 0));
        for (group, rows) in [("PointDataOffsets", n), ("CellDataOffsets", c)] {
            for ds in steps.group(group)?.datasets()? {
                let name = ds.name().rsplit('/').next().unwrap_or_default().to_string();
                let rows = match STATIC_CELL_FIELDS.contains(&name.as_str()) {
                    true => 0,
                    false => rows,
                };
                expected.push((format!("{group}/{name}"), 0, rows as i64));
            }
        }
        for (name, base, step) in &expected {
            let want = |k: usize| base + k as i64 * step;
            let got = steps.dataset(name)?.read_slice_1d::<i64, _>(0..frames)?;
            if let Some(k) = (0..frames).find(|&k| got[k] != want(k)) {
                return Ok(Some(format!(
                    "/VTKHDF/Steps/{name}[{k}] is {}, this run wrote {}",
                    got[k],
                    want(k)
                )));
            }
        }
        Ok(None)
    };
    match read().map_err(|e| e.to_string())? {
        Some(why) => Err(why),
        None => Ok(()),
    }
}
