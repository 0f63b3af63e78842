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
//! 10 = VTK_TETRA), the cell field `region` Int32 (gmsh physical tag). The run id is a
//! `FieldData` array `run_id`: UInt8, the bytes of the string, ascii — a VTK `String` array
//! would say it better, but meshio refuses that type, and ParaView shows the UInt8 array too.
//! A 6-component field is a symmetric tensor and gets VTK's component names XX, YY, ZZ, XY,
//! YZ, XZ.
//!
//! The static arrays (points, connectivity, offsets, types, region) are encoded and
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

use std::path::PathBuf;

use super::writer::Sink;
use super::{write_atomic, write_atomic_parts, zlib, Array, Compression, Geometry};
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
    pub path: PathBuf,
    pub point_data: Vec<Array>,
    pub cell_data: Vec<Array>,
}

/// Appends the header and data of one array holding `raw` to `out` in the appended layout
/// (see the module doc); `deflate` makes a zlib stream of a block (`zlib::compress` for
/// fields, `zlib::compress_once` for the mesh).
fn append(
    compression: Compression,
    out: &mut Vec<u8>,
    raw: &[u8],
    deflate: fn(&[u8], &mut Vec<u8>),
) {
    match compression {
        Compression::None => {
            out.extend_from_slice(&(raw.len() as u64).to_le_bytes());
            out.extend_from_slice(raw);
        }
        Compression::Zlib => {
            let blocks = raw.len().div_ceil(BLOCK);
            let header = out.len();
            for word in [blocks, BLOCK, raw.len() % BLOCK] {
                out.extend_from_slice(&(word as u64).to_le_bytes());
            }
            out.resize(out.len() + 8 * blocks, 0);
            for (b, chunk) in raw.chunks(BLOCK).enumerate() {
                let start = out.len();
                deflate(chunk, out);
                let size = (out.len() - start) as u64;
                let at = header + 24 + 8 * b;
                out[at..at + 8].copy_from_slice(&size.to_le_bytes());
            }
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
    region: Option<Static>,
    /// Appended bytes of the static arrays: empty until [`Sink::prepare`] compresses them
    /// (every array has a header, so they are never empty after it).
    statics: Vec<u8>,
    /// The file being written (kept to reuse its allocation).
    out: Vec<u8>,
    appended: Vec<u8>,
}

fn le<T, const N: usize>(items: impl Iterator<Item = T>, f: impl Fn(T) -> [u8; N]) -> Vec<u8> {
    items.flat_map(f).collect()
}

impl Grid {
    /// Checks ([`Geometry::cell_type`]) and encodes the geometry.
    pub(super) fn new(g: &Geometry, run_id: &str, compression: Compression) -> Result<Grid> {
        let cell_type = g.cell_type()?;
        let (points, cells, nodes_per_cell) = (g.points, g.cells, g.nodes_per_cell);
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
        let region = (!g.region.is_empty()).then(|| {
            add(
                "region",
                "Int32",
                1,
                le(g.region.iter(), |t| t.to_le_bytes()),
            )
        });

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
            region,
            statics: Vec::new(),
            out: Vec::new(),
            appended: Vec::new(),
        })
    }

    /// The whole `.vtu` file for these fields in four parts (valid until the next call): the
    /// XML up to the appended data, the mesh, the fields, the end. Sizes were checked by the
    /// caller.
    pub(super) fn encode(&mut self, point_data: &[Array], cell_data: &[Array]) -> [&[u8]; 4] {
        self.prepare();
        let (out, appended) = (&mut self.out, &mut self.appended);
        out.clear();
        appended.clear();
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
        // The appended data hold the static arrays, then the fields in reverse document
        // order: meshio's raw appended reader walks the arrays by offset and looks each one
        // up by its offset attribute after rewriting those of the arrays before it, so the
        // array it looks for must come first in the document among equal offsets.
        let base = self.statics.len();
        let arrays: Vec<&Array> = point_data.iter().chain(cell_data).collect();
        let mut offsets = vec![0; arrays.len()];
        for (k, a) in arrays.iter().enumerate().rev() {
            offsets[k] = base + appended.len();
            append(self.compression, appended, &a.le_bytes(), zlib::compress);
        }
        for (k, a) in arrays.iter().enumerate() {
            if k == 0 {
                out.extend_from_slice(b"      <PointData>\n");
            }
            if k == point_data.len() {
                out.extend_from_slice(b"      </PointData>\n      <CellData>\n");
            }
            let _ = writeln!(
                out,
                "{} offset=\"{}\"/>",
                array_open(a.vtk_type(), &a.name, a.components),
                offsets[k]
            );
        }
        if arrays.is_empty() {
            out.extend_from_slice(b"      <PointData>\n");
        }
        if point_data.len() == arrays.len() {
            out.extend_from_slice(b"      </PointData>\n      <CellData>\n");
        }
        let put = |s: &Static, out: &mut Vec<u8>| {
            let _ = writeln!(out, "{} offset=\"{}\"/>", s.open, s.at);
        };
        if let Some(r) = &self.region {
            put(r, out);
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
        [
            &self.out,
            &self.statics,
            &self.appended,
            b"\n  </AppendedData>\n</VTKFile>\n",
        ]
    }
}

impl Sink for Grid {
    type Job = Job;

    /// The `.vtu` (temporary file + rename), then the `.pvd` (likewise).
    fn write(&mut self, job: Job) -> Result<()> {
        if let Some(v) = job.vtu {
            write_atomic_parts(&v.path, &self.encode(&v.point_data, &v.cell_data))?;
        }
        match job.pvd {
            Some((path, text)) => write_atomic(&path, text.as_bytes()),
            None => Ok(()),
        }
    }

    /// Compresses the static arrays (once; zlib's search at level 6 takes about 20 ms at
    /// h = 1/128, which the writer thread spends beside the run's setup).
    fn prepare(&mut self) {
        if !self.statics.is_empty() {
            return;
        }
        // In reverse document order (see `encode`): types, offsets, connectivity, points,
        // region.
        let [conn, offsets, types] = &mut self.cells;
        let order = [types, offsets, conn, &mut self.points]
            .into_iter()
            .chain(self.region.as_mut());
        for s in order {
            s.at = self.statics.len();
            append(
                self.compression,
                &mut self.statics,
                &std::mem::take(&mut s.raw),
                zlib::compress_once,
            );
        }
    }

    /// Every file was closed when it was written.
    fn close(&mut self) -> Result<()> {
        Ok(())
    }
}

/// Component names of a symmetric tensor, in ParaView's order.
const SYMMETRIC_TENSOR: [&str; 6] = ["XX", "YY", "ZZ", "XY", "YZ", "XZ"];

/// `<DataArray type=… Name=… NumberOfComponents=… format="appended"`, without the offset. A
/// 6-component array is a symmetric tensor: its components are named XX, YY, ZZ, XY, YZ, XZ
/// (`ComponentName0` …, as VTK writes them), so ParaView shows `stress_XY`.
fn array_open(ty: &str, name: &str, components: usize) -> String {
    let mut s = format!(
        "        <DataArray type=\"{ty}\" Name=\"{}\" NumberOfComponents=\"{components}\"",
        escape_attr(name)
    );
    if components == 6 {
        for (i, c) in SYMMETRIC_TENSOR.iter().enumerate() {
            s.push_str(&format!(" ComponentName{i}=\"{c}\""));
        }
    }
    s.push_str(" format=\"appended\"");
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
        append(Compression::Zlib, &mut out, &raw, zlib::compress);
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

    #[test]
    fn names_are_escaped() {
        assert_eq!(escape_attr("σ_xx"), "σ_xx");
        assert_eq!(escape_attr("a<b&\"c\""), "a&lt;b&amp;&quot;c&quot;");
    }
}
