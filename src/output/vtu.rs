//! One `.vtu` file: a VTK XML UnstructuredGrid with its arrays in raw appended data.
//!
//! # Encoding
//!
//! `<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian"
//! header_type="UInt64" [compressor="vtkZLibDataCompressor"]>`; every `DataArray` is
//! `format="appended"` with its `offset` into the `<AppendedData encoding="raw">` section
//! that follows the `_`, the layout VTK's own `vtkXMLUnstructuredGridWriter` writes by default
//! and ParaView, VTK's readers and meshio read:
//! - uncompressed (`compression = "none"`): a UInt64 byte count, then the little-endian values;
//! - zlib (`compression = "zlib"`, the default): VTK's block header — UInt64 number of blocks,
//!   block size (32768 bytes, VTK's default), size of the last block if partial (0 if full),
//!   the compressed size of each block — then each block as one zlib stream.
//!
//! Field values are Float64 or Float32 (`output.precision`), coordinates always Float64 (the
//! mesh is exact in the file, and it costs once per frame after compression of a few
//! percent), `connectivity`/`offsets` Int64 (`vtkIdType`), `types` UInt8 (5 = VTK_TRIANGLE,
//! 10 = VTK_TETRA), the cell fields `region` Int32 (gmsh physical tag) and, for a scene with
//! regions, `material_region` Int32 (the `[[material.region]]` entry). The run id is a
//! `FieldData` array `run_id`: UInt8, the bytes of the string, ascii — a VTK `String` array
//! would say it better, but meshio refuses that type, and ParaView shows the UInt8 array too.
//! A 6-component field is a symmetric tensor and gets VTK's component names XX, YY, ZZ, XY,
//! YZ, XZ.
//!
//! The static arrays (points, connectivity, offsets, types, the static cell fields) are encoded and
//! compressed once, in [`Grid::new`]; a frame compresses only its fields and copies the
//! static bytes behind them.
//!
//! # Why this module writes the XML itself instead of calling vtkio's writer
//!
//! vtkio 0.6 cannot keep an encoded geometry between frames (the pieces of
//! `vtkio::xml::Unstructured` are private), its serializer took 60 ms of a 70–100 ms frame at
//! 33k nodes (quick-xml escapes every byte of base64 text), and its compressed output is one
//! stream behind a single size word, not VTK's block header, so neither ParaView nor meshio
//! could read it; its reader also cannot read raw appended data (its XML parser stops at a
//! `<` byte in the binary). The tests read every file back with VTK's own reader (Python
//! `vtk`), meshio and this crate's reader (`read.rs`).

use std::io::Write as _;

use std::path::{Path, PathBuf};

use super::{write_atomic_with, zlib, Array, Compression, Geometry};
use crate::Result;

/// Uncompressed bytes per zlib block: VTK's default (vtkDataCompressor block size).
const BLOCK: usize = 32768;

/// Work for the writer thread: a `.vtu` to write, then (when due) the `.pvd` that lists it.
pub(super) struct Job {
    pub vtu: Option<Vtu>,
    /// The collection file and its new text.
    pub pvd: Option<(PathBuf, String)>,
}

/// One frame's file and fields.
pub(super) struct Vtu {
    pub step: usize,
    pub path: PathBuf,
    pub point_data: Vec<Array>,
    pub cell_data: Vec<Array>,
}

/// Where the appended data go: memory (the static arrays, encoded once per run) or a frame's
/// file ([`FileTail`]). Positions count from the start of the appended data.
trait Appended {
    /// Appends `bytes`.
    fn put(&mut self, bytes: &[u8]) -> std::io::Result<()>;
    /// Appends the zlib stream of `block` made by `deflate`.
    fn deflate(&mut self, block: &[u8], deflate: fn(&[u8], &mut Vec<u8>)) -> std::io::Result<()>;
    /// The position of the end.
    fn len(&self) -> u64;
    /// Overwrites what was appended at `at`.
    fn patch(&mut self, at: u64, bytes: &[u8]) -> std::io::Result<()>;
}

impl Appended for Vec<u8> {
    fn put(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.extend_from_slice(bytes);
        Ok(())
    }

    fn deflate(&mut self, block: &[u8], deflate: fn(&[u8], &mut Vec<u8>)) -> std::io::Result<()> {
        deflate(block, self);
        Ok(())
    }

    fn len(&self) -> u64 {
        Vec::len(self) as u64
    }

    fn patch(&mut self, at: u64, bytes: &[u8]) -> std::io::Result<()> {
        self[at as usize..at as usize + bytes.len()].copy_from_slice(bytes);
        Ok(())
    }
}

/// Appends the header and data of one array holding `raw` to `out` in the appended layout
/// (see the module doc); `deflate` makes a zlib stream of a block (`zlib::compress` for
/// fields, `zlib::compress_once` for the mesh). The block sizes are patched in after the
/// blocks.
fn append(
    compression: Compression,
    out: &mut impl Appended,
    raw: &[u8],
    deflate: fn(&[u8], &mut Vec<u8>),
) -> std::io::Result<()> {
    match compression {
        Compression::None => {
            out.put(&(raw.len() as u64).to_le_bytes())?;
            out.put(raw)
        }
        Compression::Zlib => {
            let blocks = raw.len().div_ceil(BLOCK);
            let words = |w: &[usize]| w.iter().flat_map(|&w| (w as u64).to_le_bytes()).collect();
            let header: Vec<u8> = words(&[blocks, BLOCK, raw.len() % BLOCK]);
            out.put(&header)?;
            let sizes_at = out.len();
            out.put(&vec![0; 8 * blocks])?;
            let mut sizes = Vec::with_capacity(blocks);
            for chunk in raw.chunks(BLOCK) {
                let start = out.len();
                out.deflate(chunk, deflate)?;
                sizes.push((out.len() - start) as usize);
            }
            out.patch(sizes_at, &words(&sizes))
        }
    }
}

/// The appended data of a frame's file after its static arrays, through a buffer that goes
/// to the file whenever it holds [`FileTail::FLUSH`] bytes: a frame's compressed fields
/// (1.85 MB at h = 1/128) never sit in memory whole. The writer thread shares the last-level cache with the time loop, whose
/// factor about fills it at h = 1/128, and each byte it touches evicts one of the factor's.
struct FileTail<'a> {
    file: &'a std::fs::File,
    buf: &'a mut Vec<u8>,
    /// The file offset of the appended data, and how many of their bytes are in the file.
    base: u64,
    flushed: u64,
}

impl FileTail<'_> {
    /// Bytes kept before they go to the file.
    const FLUSH: usize = 1 << 17;

    fn flush(&mut self) -> std::io::Result<()> {
        std::io::Write::write_all(&mut self.file, self.buf)?;
        self.flushed += self.buf.len() as u64;
        self.buf.clear();
        Ok(())
    }

    fn flush_if_full(&mut self) -> std::io::Result<()> {
        if self.buf.len() >= Self::FLUSH {
            self.flush()?;
        }
        Ok(())
    }
}

impl Appended for FileTail<'_> {
    fn put(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        if bytes.len() < Self::FLUSH {
            self.buf.extend_from_slice(bytes);
            return self.flush_if_full();
        }
        // Raw values go to the file from where they are.
        self.flush()?;
        std::io::Write::write_all(&mut self.file, bytes)?;
        self.flushed += bytes.len() as u64;
        Ok(())
    }

    fn deflate(&mut self, block: &[u8], deflate: fn(&[u8], &mut Vec<u8>)) -> std::io::Result<()> {
        deflate(block, self.buf);
        self.flush_if_full()
    }

    fn len(&self) -> u64 {
        self.flushed + self.buf.len() as u64
    }

    /// Overwritten in the buffer if it is still there, else in the file with a positioned
    /// write (the file's own position stays at its end). A flush takes the whole buffer, so
    /// what one `put` appended is all in one of them.
    fn patch(&mut self, at: u64, bytes: &[u8]) -> std::io::Result<()> {
        match at.checked_sub(self.flushed) {
            Some(from) => {
                let from = from as usize;
                self.buf[from..from + bytes.len()].copy_from_slice(bytes);
                Ok(())
            }
            None => std::os::unix::fs::FileExt::write_all_at(self.file, bytes, self.base + at),
        }
    }
}

/// Where in the static bytes an array lies, and its element attributes.
struct Static {
    /// The `<DataArray …` text up to (not including) ` offset=`.
    open: String,
    /// Offset into [`Grid::statics`].
    at: usize,
    /// The array's bytes until [`Sink::prepare`] appends them to the statics.
    raw: Vec<u8>,
}

/// The mesh of a series, encoded once, and the state reused by every frame.
pub(super) struct Grid {
    num_points: usize,
    num_cells: usize,
    compression: Compression,
    /// `<FieldData>` with the run id.
    field_data: String,
    points: Static,
    cells: [Static; 3],
    /// The static cell fields (`region`, `material_region`) the geometry has.
    cell_arrays: Vec<Static>,
    /// A piece's [`GLOBAL_IDS`] (`pvtu.rs`), or none.
    ids: Option<Static>,
    /// Appended bytes of the static arrays: empty until [`Sink::prepare`] compresses them
    /// (every array has a header, so they are never empty after it).
    statics: Vec<u8>,
    /// The file being written (kept to reuse its allocation).
    out: Vec<u8>,
    /// The buffer of [`FileTail`] (kept likewise).
    buf: Vec<u8>,
}

fn le<T, const N: usize>(items: impl Iterator<Item = T>, f: impl Fn(T) -> [u8; N]) -> Vec<u8> {
    items.flat_map(f).collect()
}

impl Grid {
    /// Checks ([`Geometry::cell_type`]) and encodes the geometry.
    pub(super) fn new(g: &Geometry, run_id: &str, compression: Compression) -> Result<Grid> {
        let cell_type = g.cell_type()?;
        let (points, cells, nodes_per_cell) = (g.points.whole(), g.cells, g.nodes_per_cell);
        let num_points = points.len();
        let num_cells = cells.len() / nodes_per_cell;

        let add = |name: &str, ty: &str, components: usize, raw: Vec<u8>| Static {
            open: array_open(ty, name, components),
            at: 0,
            raw,
        };
        let types = add("types", "UInt8", 1, vec![cell_type; num_cells]);
        let offsets = add(
            "offsets",
            "Int64",
            1,
            le(1..num_cells + 1, |c| {
                ((c * nodes_per_cell) as i64).to_le_bytes()
            }),
        );
        let conn = add(
            "connectivity",
            "Int64",
            1,
            le(cells.iter(), |&i| (i as i64).to_le_bytes()),
        );
        let points_s = add(
            "Points",
            "Float64",
            3,
            le(points.as_flattened().iter(), |x| x.to_le_bytes()),
        );
        let cell_arrays = (g.cell_statics().into_iter())
            .map(|(name, values)| add(name, "Int32", 1, le(values.iter(), |t| t.to_le_bytes())))
            .collect();

        let id: Vec<String> = run_id.bytes().map(|b| b.to_string()).collect();
        let field_data = format!(
            "    <FieldData>\n      <DataArray type=\"UInt8\" Name=\"run_id\" \
             NumberOfTuples=\"{}\" format=\"ascii\">{}</DataArray>\n    </FieldData>\n",
            id.len(),
            id.join(" ")
        );
        Ok(Grid {
            num_points,
            num_cells,
            compression,
            field_data,
            points: points_s,
            cells: [conn, offsets, types],
            cell_arrays,
            ids: None,
            statics: Vec::new(),
            out: Vec::new(),
            buf: Vec::new(),
        })
    }

    /// The grid of a piece of a larger mesh whose point i is the mesh's point `ids[i]`: the
    /// static point array [`GLOBAL_IDS`], VTK's global ids of the points.
    pub(super) fn with_global_ids(mut self, ids: &[usize]) -> Grid {
        let raw = le(ids.iter(), |&i| (i as i64).to_le_bytes());
        self.ids = Some(Static {
            open: array_open("Int64", GLOBAL_IDS, 1),
            at: 0,
            raw,
        });
        self
    }

    /// Writes the `.vtu` of these fields to `path` ([`write_atomic_with`]): the XML up to the
    /// appended data, the mesh, the fields as they are compressed ([`FileTail`]), the end,
    /// and the XML once more with the fields' offsets, which are known only then (they are
    /// padded to a fixed width, so the XML keeps its length). Sizes were checked by the
    /// caller.
    pub(super) fn write_frame(
        &mut self,
        path: &Path,
        point_data: &[Array],
        cell_data: &[Array],
    ) -> Result<()> {
        self.prepare();
        let (mut out, mut buf) = (std::mem::take(&mut self.out), std::mem::take(&mut self.buf));
        // The appended data hold the static arrays, then the fields in reverse document
        // order: meshio's raw appended reader walks the arrays by offset and looks each one
        // up by its offset attribute after rewriting those of the arrays before it, so the
        // array it looks for must come first in the document among equal offsets.
        let arrays: Vec<&Array> = point_data.iter().chain(cell_data).collect();
        let mut offsets = vec![0; arrays.len()];
        let written = write_atomic_with(path, |file| {
            out.clear();
            self.xml(&arrays, point_data.len(), &offsets, &mut out);
            file.write_all(&out)?;
            file.write_all(&self.statics)?;
            buf.clear();
            let mut tail = FileTail {
                file,
                buf: &mut buf,
                base: out.len() as u64,
                flushed: self.statics.len() as u64,
            };
            for (k, a) in arrays.iter().enumerate().rev() {
                offsets[k] = tail.len();
                append(self.compression, &mut tail, &a.le_bytes(), zlib::compress)?;
            }
            tail.put(b"\n  </AppendedData>\n</VTKFile>\n")?;
            tail.flush()?;
            let length = out.len();
            out.clear();
            self.xml(&arrays, point_data.len(), &offsets, &mut out);
            debug_assert_eq!(out.len(), length, "the XML changed its length");
            std::os::unix::fs::FileExt::write_all_at(&*file, &out, 0)
        });
        (self.out, self.buf) = (out, buf);
        written
    }

    /// The XML of a frame up to its appended data, `offsets` those of `arrays` (the first
    /// `n_point` of them point fields).
    fn xml(&self, arrays: &[&Array], n_point: usize, offsets: &[u64], out: &mut Vec<u8>) {
        let compressor = match self.compression {
            Compression::None => "",
            Compression::Zlib => " compressor=\"vtkZLibDataCompressor\"",
        };
        // Writing into a Vec cannot fail.
        let _ = write!(
            out,
            "<?xml version=\"1.0\"?>\n\
             <VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" \
             header_type=\"UInt64\"{compressor}>\n  <UnstructuredGrid>\n{}    \
             <Piece NumberOfPoints=\"{}\" NumberOfCells=\"{}\">\n",
            self.field_data, self.num_points, self.num_cells
        );
        let field = |(a, offset): (&&Array, &u64), out: &mut Vec<u8>| {
            // Blanks before `/>` keep the width of any u64 offset.
            let offset = offset.to_string();
            let _ = writeln!(
                out,
                "{} offset=\"{offset}\"{:pad$}/>",
                array_open(a.vtk_type(), &a.name, a.components),
                "",
                pad = 20 - offset.len()
            );
        };
        let put = |s: &Static, out: &mut Vec<u8>| {
            let _ = writeln!(out, "{} offset=\"{}\"/>", s.open, s.at);
        };
        let _ = writeln!(out, "      <PointData{}>", global_ids(self.ids.is_some()));
        let fields = arrays.iter().zip(offsets);
        fields.clone().take(n_point).for_each(|f| field(f, out));
        self.ids.iter().for_each(|s| put(s, out));
        out.extend_from_slice(b"      </PointData>\n      <CellData>\n");
        fields.skip(n_point).for_each(|f| field(f, out));
        for s in &self.cell_arrays {
            put(s, out);
        }
        out.extend_from_slice(b"      </CellData>\n      <Points>\n");
        put(&self.points, out);
        out.extend_from_slice(b"      </Points>\n      <Cells>\n");
        for s in &self.cells {
            put(s, out);
        }
        out.extend_from_slice(
            b"      </Cells>\n    </Piece>\n  </UnstructuredGrid>\n  <AppendedData encoding=\"raw\">\n   _",
        );
    }

    /// Compresses the static arrays (once; zlib's search at level 6 takes about 20 ms at
    /// h = 1/128, which the writer thread spends beside the run's setup).
    pub(super) fn prepare(&mut self) {
        if !self.statics.is_empty() {
            return;
        }
        // In reverse document order (see `write_frame`): types, offsets, connectivity, points,
        // then the static cell fields.
        let [conn, offsets, types] = &mut self.cells;
        let order = [types, offsets, conn, &mut self.points]
            .into_iter()
            .chain(self.cell_arrays.iter_mut())
            .chain(self.ids.iter_mut());
        for s in order {
            s.at = self.statics.len();
            append(
                self.compression,
                &mut self.statics,
                &std::mem::take(&mut s.raw),
                zlib::compress_once,
            )
            .expect("appending to memory cannot fail");
        }
    }
}

/// The point array of a piece (`pvtu.rs`) that numbers its points in the whole mesh (Int64,
/// from 0), VTK's global ids: `vtkGenerateGlobalIds`' name, flagged by the `GlobalIds`
/// attribute of `<PointData>`.
pub const GLOBAL_IDS: &str = "GlobalPointIds";

/// The attribute of `<PointData>` (or `<PPointData>`) that flags [`GLOBAL_IDS`], if `has`.
pub(super) fn global_ids(has: bool) -> String {
    match has {
        true => format!(" GlobalIds=\"{GLOBAL_IDS}\""),
        false => String::new(),
    }
}

/// Component names of a symmetric tensor, in ParaView's order.
const SYMMETRIC_TENSOR: [&str; 6] = ["XX", "YY", "ZZ", "XY", "YZ", "XZ"];

/// `<DataArray type=… Name=… NumberOfComponents=… format="appended"`, without the offset. A
/// 6-component array is a symmetric tensor: its components are named XX, YY, ZZ, XY, YZ, XZ
/// (`ComponentName0` …, as VTK writes them), so ParaView shows `stress_XY`.
fn array_open(ty: &str, name: &str, components: usize) -> String {
    format!(
        "        <DataArray {} format=\"appended\"",
        array_attrs(ty, name, components)
    )
}

/// `type=… Name=… NumberOfComponents=…` and the component names of a symmetric tensor: the
/// attributes of a `DataArray`, and of a `.pvtu`'s `PDataArray` (`pvtu.rs`).
pub(super) fn array_attrs(ty: &str, name: &str, components: usize) -> String {
    let mut s = format!(
        "type=\"{ty}\" Name=\"{}\" NumberOfComponents=\"{components}\"",
        escape_attr(name)
    );
    if components == 6 {
        for (i, c) in SYMMETRIC_TENSOR.iter().enumerate() {
            s.push_str(&format!(" ComponentName{i}=\"{c}\""));
        }
    }
    s
}

/// `s` with the five XML special characters escaped, for an attribute value.
pub(super) fn escape_attr(s: &str) -> std::borrow::Cow<'_, str> {
    if !s.contains(['&', '<', '>', '"', '\'']) {
        return s.into();
    }
    let mut out = String::with_capacity(s.len() + 8);
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            c => out.push(c),
        }
    }
    out.into()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zlib_blocks_follow_vtk_header() {
        let raw: Vec<u8> = (0..(BLOCK * 2 + 100)).map(|i| (i % 7) as u8).collect();
        let mut out = Vec::new();
        append(Compression::Zlib, &mut out, &raw, zlib::compress).unwrap();
        let word = |k: usize| u64::from_le_bytes(out[8 * k..8 * k + 8].try_into().unwrap());
        assert_eq!(word(0), 3);
        assert_eq!(word(1), BLOCK as u64);
        assert_eq!(word(2), 100);
        let sizes: u64 = (3..6).map(word).sum();
        assert_eq!(out.len() as u64, 48 + sizes);
        let mut back = Vec::new();
        let mut at = 48;
        for k in 3..6 {
            let n = word(k) as usize;
            let mut d = flate2::read::ZlibDecoder::new(&out[at..at + n]);
            std::io::Read::read_to_end(&mut d, &mut back).unwrap();
            at += n;
        }
        assert_eq!(back, raw);
    }

    /// An array streamed to a file through a buffer that is flushed before its block sizes
    /// are known (they are patched in the file) is the array appended in memory.
    #[test]
    fn file_tail_writes_what_memory_holds() {
        // Bytes without repeats: every block is stored, 5 blocks exceed FileTail::FLUSH.
        let raw: Vec<u8> = (0u64..(5 * BLOCK as u64 + 3) / 8 + 1)
            .flat_map(|i| i.wrapping_mul(0x9e37_79b9_7f4a_7c15).to_le_bytes())
            .collect();
        assert!(raw.len() > FileTail::FLUSH);
        for compression in [Compression::Zlib, Compression::None] {
            let mut memory = b"static".to_vec();
            append(compression, &mut memory, &raw, zlib::compress).unwrap();
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("a");
            let mut file = std::fs::File::create(&path).unwrap();
            file.write_all(b"xmlstatic").unwrap();
            let mut buf = Vec::new();
            let mut tail = FileTail {
                file: &file,
                buf: &mut buf,
                base: 3,
                flushed: 6,
            };
            append(compression, &mut tail, &raw, zlib::compress).unwrap();
            assert!(tail.flushed > 6, "the buffer was flushed");
            tail.flush().unwrap();
            drop(file);
            assert_eq!(std::fs::read(&path).unwrap()[3..], memory[..]);
        }
    }

    #[test]
    fn names_are_escaped() {
        assert_eq!(escape_attr("σ_xx"), "σ_xx");
        assert_eq!(escape_attr("a<b&\"c\""), "a&lt;b&amp;&quot;c&quot;");
    }
}
