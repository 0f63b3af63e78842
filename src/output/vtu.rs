//! One `.vtu` file: a VTK XML UnstructuredGrid.
//!
//! # Encoding
//!
//! `format="binary"` (inline base64) with `header_type="UInt64"`, `byte_order="LittleEndian"`,
//! `version="1.0"`, no compression: each `DataArray` holds base64 of one stream made of a
//! UInt64 byte count followed by the values, exactly what vtkio 0.6 writes and what VTK itself
//! writes for uncompressed inline data. ParaView, meshio and vtkio read it. Field values are
//! Float64, coordinates Float64, `connectivity`/`offsets` Int64 (VTK's `vtkIdType`), `types`
//! UInt8 (5 = VTK_TRIANGLE, 10 = VTK_TETRA). Version 1.0 is the first that knows
//! `header_type` and the newest meshio 5 accepts. A 6-component field is a symmetric tensor
//! and gets VTK's component names XX, YY, ZZ, XY, YZ, XZ.
//!
//! # Why this module writes the XML itself instead of calling vtkio's writer
//!
//! The first version of this module wrote through `vtkio::Vtk::try_into_xml_format` and
//! vtkio's XML serializer. Measured in a release build on a 33k-node / 65k-triangle frame with
//! every field of DESIGN.md (12.7 MB): 70–100 ms per frame, 60 ms of it in vtkio's serializer
//! alone (quick-xml escapes every byte of the base64 text, and the output is copied several times
//! through growing buffers), against a budget of well under 50 ms. vtkio 0.6 also offers no
//! way around it:
//! - the encoded geometry cannot be kept between frames: the pieces of
//!   `vtkio::xml::Unstructured` are private and `vtkio::xml::EncodingInfo` has private fields
//!   and no constructor, so a prepared file cannot be given new point/cell data;
//! - its compressed output (`Compressor::ZLib`, `LZ4`, `LZMA`) is one compressed stream behind a
//!   single size word, not VTK's block header (number of blocks, block size, last block size,
//!   compressed size of each block), so neither ParaView nor meshio could read it anyway.
//!
//! So the geometry is encoded once, in [`Grid::new`], and a frame base64-encodes its fields
//! into a buffer kept between frames: about 8 ms per such frame in a release build (5 ms to
//! encode, 3 ms to write; `writing_a_33k_node_frame_is_fast` in tests/output_format.rs
//! prints it). The layout is vtkio's (connectivity Int64 where vtkio writes UInt64), and
//! the tests read every file back with vtkio (`vtkio::Vtk::import`, bit for bit), compare it
//! with what vtkio's own writer produces for the same data, and read it with meshio.

use std::io::Write as _;

use super::Field;
use crate::{Error, Result};

/// VTK cell type codes.
const VTK_TRIANGLE: u8 = 5;
const VTK_TETRA: u8 = 10;

/// The mesh of a series, encoded once, and the buffers reused by every frame.
pub(super) struct Grid {
    num_points: usize,
    num_cells: usize,
    /// The `<Points>` and `<Cells>` elements, ready to copy into every file.
    geometry: Vec<u8>,
    /// The file being written (kept to reuse its allocation).
    out: Vec<u8>,
    /// The little-endian bytes of one array before base64 (kept likewise).
    raw: Vec<u8>,
}

impl Grid {
    /// Checks and encodes the geometry. `cells` holds `nodes_per_cell` node indices per
    /// cell: 3 → VTK_TRIANGLE, 4 → VTK_TETRA.
    pub(super) fn new(points: &[[f64; 3]], cells: &[usize], nodes_per_cell: usize) -> Result<Grid> {
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
        let num_points = points.len();
        let num_cells = cells.len() / nodes_per_cell;
        if let Some(pos) = cells.iter().position(|&i| i >= num_points) {
            return Err(Error::input(format!(
                "output: cell {} refers to node {}, but the mesh has {num_points} nodes",
                pos / nodes_per_cell,
                cells[pos]
            )));
        }

        let mut geometry = Vec::new();
        let mut raw = Vec::new();
        geometry.extend_from_slice(b"      <Points>\n");
        raw_array(&mut raw, points.as_flattened(), |x| x.to_le_bytes());
        data_array(&mut geometry, &raw, "Float64", "Points", 3);
        geometry.extend_from_slice(b"      </Points>\n      <Cells>\n");
        raw_array(&mut raw, cells, |&i| (i as i64).to_le_bytes());
        data_array(&mut geometry, &raw, "Int64", "connectivity", 1);
        raw_array(&mut raw, 1..num_cells + 1, |c| {
            ((c * nodes_per_cell) as i64).to_le_bytes()
        });
        data_array(&mut geometry, &raw, "Int64", "offsets", 1);
        raw_array(&mut raw, 0..num_cells, |_| [cell_type]);
        data_array(&mut geometry, &raw, "UInt8", "types", 1);
        geometry.extend_from_slice(b"      </Cells>\n");

        Ok(Grid {
            num_points,
            num_cells,
            geometry,
            out: Vec::new(),
            raw,
        })
    }

    pub(super) fn num_points(&self) -> usize {
        self.num_points
    }

    pub(super) fn num_cells(&self) -> usize {
        self.num_cells
    }

    /// The whole `.vtu` file for these fields (valid until the next call). Errors say which
    /// field does not fit the mesh.
    pub(super) fn encode(
        &mut self,
        point_data: &[Field],
        cell_data: &[Field],
    ) -> std::result::Result<&[u8], String> {
        check_fields(point_data, self.num_points, "point")?;
        check_fields(cell_data, self.num_cells, "cell")?;

        let out = &mut self.out;
        out.clear();
        let values: usize = point_data
            .iter()
            .chain(cell_data)
            .map(|f| f.values.len())
            .sum();
        let fields = point_data.len() + cell_data.len();
        out.reserve(self.geometry.len() + (values * 8 + fields * 11) * 4 / 3 + fields * 200 + 512);

        // Writing into a Vec cannot fail.
        let _ = write!(
            out,
            "<?xml version=\"1.0\"?>\n\
             <VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" \
             header_type=\"UInt64\">\n  <UnstructuredGrid>\n    \
             <Piece NumberOfPoints=\"{}\" NumberOfCells=\"{}\">\n",
            self.num_points, self.num_cells
        );
        for (tag, fields) in [("PointData", point_data), ("CellData", cell_data)] {
            let _ = writeln!(out, "      <{tag}>");
            for f in fields {
                raw_array(&mut self.raw, f.values, |x| x.to_le_bytes());
                data_array(out, &self.raw, "Float64", f.name, f.components);
            }
            let _ = writeln!(out, "      </{tag}>");
        }
        out.extend_from_slice(&self.geometry);
        out.extend_from_slice(b"    </Piece>\n  </UnstructuredGrid>\n</VTKFile>\n");
        Ok(&self.out)
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

/// Fills `raw` with the UInt64 byte count of the array followed by its little-endian bytes.
fn raw_array<T, const N: usize>(
    raw: &mut Vec<u8>,
    items: impl IntoIterator<Item = T, IntoIter: ExactSizeIterator>,
    le_bytes: impl Fn(T) -> [u8; N],
) {
    let items = items.into_iter();
    let len = items.len() * N;
    raw.clear();
    raw.resize(8 + len, 0);
    raw[..8].copy_from_slice(&(len as u64).to_le_bytes());
    for (dst, item) in raw[8..].chunks_exact_mut(N).zip(items) {
        dst.copy_from_slice(&le_bytes(item));
    }
}

/// Component names of a symmetric tensor, in ParaView's order.
const SYMMETRIC_TENSOR: [&str; 6] = ["XX", "YY", "ZZ", "XY", "YZ", "XZ"];

/// Appends one `<DataArray format="binary">` holding base64 of `raw`. A 6-component array is
/// a symmetric tensor: its components are named XX, YY, ZZ, XY, YZ, XZ (`ComponentName0` …,
/// as VTK writes them), so ParaView shows `stress_XY` and not `stress_3`.
fn data_array(out: &mut Vec<u8>, raw: &[u8], ty: &str, name: &str, components: usize) {
    let _ = write!(
        out,
        "        <DataArray type=\"{ty}\" Name=\"{}\" NumberOfComponents=\"{components}\"",
        escape_attr(name)
    );
    if components == 6 {
        for (i, c) in SYMMETRIC_TENSOR.iter().enumerate() {
            let _ = write!(out, " ComponentName{i}=\"{c}\"");
        }
    }
    out.extend_from_slice(b" format=\"binary\">");
    base64_into(out, raw);
    out.extend_from_slice(b"</DataArray>\n");
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

const BASE64: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

/// Appends standard base64 (RFC 4648, with `=` padding) of `bytes` to `out`.
fn base64_into(out: &mut Vec<u8>, bytes: &[u8]) {
    let start = out.len();
    let len = bytes.len().div_ceil(3) * 4;
    out.resize(start + len, 0);
    let dst = &mut out[start..];
    let sextet = |n: u32, shift: u32| BASE64[((n >> shift) & 63) as usize];
    let mut chunks = bytes.chunks_exact(3);
    for (src, d) in (&mut chunks).zip(dst.chunks_exact_mut(4)) {
        let n = u32::from(src[0]) << 16 | u32::from(src[1]) << 8 | u32::from(src[2]);
        d.copy_from_slice(&[sextet(n, 18), sextet(n, 12), sextet(n, 6), sextet(n, 0)]);
    }
    let rest = chunks.remainder();
    if !rest.is_empty() {
        let b1 = rest.get(1).copied().unwrap_or(0);
        let n = u32::from(rest[0]) << 16 | u32::from(b1) << 8;
        let d = &mut dst[len - 4..];
        d[0] = sextet(n, 18);
        d[1] = sextet(n, 12);
        d[2] = if rest.len() == 2 { sextet(n, 6) } else { b'=' };
        d[3] = b'=';
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn b64(bytes: &[u8]) -> String {
        let mut out = Vec::new();
        base64_into(&mut out, bytes);
        String::from_utf8(out).unwrap()
    }

    #[test]
    fn base64_matches_rfc_4648_vectors() {
        let cases = [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ];
        for (plain, encoded) in cases {
            assert_eq!(b64(plain.as_bytes()), encoded);
        }
        assert_eq!(b64(&[0xfb, 0xff, 0xbf]), "+/+/");
    }

    #[test]
    fn raw_array_has_the_byte_count_first() {
        let mut raw = Vec::new();
        raw_array(&mut raw, [1.5f64, -2.0], |x| x.to_le_bytes());
        assert_eq!(raw.len(), 24);
        assert_eq!(u64::from_le_bytes(raw[..8].try_into().unwrap()), 16);
        assert_eq!(f64::from_le_bytes(raw[16..].try_into().unwrap()), -2.0);
    }

    #[test]
    fn names_are_escaped() {
        assert_eq!(escape_attr("σ_xx"), "σ_xx");
        assert_eq!(escape_attr("a<b&\"c\""), "a&lt;b&amp;&quot;c&quot;");
    }
}
