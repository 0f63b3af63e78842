//! Reading a run's series back: `solution.pvd` and the `.vtu` files this module's writer
//! produces (`vtu.rs`): raw appended data, uncompressed or in VTK's zlib blocks, and the
//! inline base64 uncompressed arrays of earlier versions; header_type UInt64.
//! Float64/Float32, Int64/Int32, UInt64/UInt32/UInt8 arrays are read; other layouts (other
//! writers) are refused with a message saying so. `solution.vtkhdf` (`vtkhdf.rs`) is read
//! frame by frame through HDF5. Used by the `plot` command.

use super::{pvd, vtkhdf};
use crate::{Error, Result};
use std::path::{Path, PathBuf};

/// Where one frame of a series is.
#[derive(Clone, Debug, PartialEq)]
pub enum FrameRef {
    /// A `.vtu` file.
    Vtu(PathBuf),
    /// Frame `index` (0-based) of a `.vtkhdf` file.
    Vtkhdf { path: PathBuf, index: usize },
}

impl FrameRef {
    /// The file that holds the frame.
    pub fn path(&self) -> &Path {
        match self {
            FrameRef::Vtu(p) | FrameRef::Vtkhdf { path: p, .. } => p,
        }
    }
}

/// The frames `(time, where)` of a series: `path` is a `.pvd`, a `.vtkhdf`, or a run's
/// directory (its `solution.pvd`, else its `solution.vtkhdf`). Also returns the series
/// file read. A directory with neither file is an input error that names both.
pub fn read_series(path: &Path) -> Result<(PathBuf, Vec<(f64, FrameRef)>)> {
    let file = if path.is_dir() {
        let pvd = path.join(super::PVD_NAME);
        let h5 = path.join(super::VTKHDF_NAME);
        match (pvd.exists(), h5.exists()) {
            (true, _) => pvd,
            (false, true) => h5,
            (false, false) => {
                return Err(Error::input(format!(
                    "{} holds neither {} nor {}; give the output directory of a run \
                     (viscontact run … --out DIR)",
                    path.display(),
                    super::PVD_NAME,
                    super::VTKHDF_NAME
                )))
            }
        }
    } else {
        path.to_path_buf()
    };
    let frames = if file.extension().is_some_and(|e| e == "vtkhdf") {
        read_vtkhdf(&file)?
            .into_iter()
            .enumerate()
            .map(|(index, (_, t))| {
                let path = file.clone();
                (t, FrameRef::Vtkhdf { path, index })
            })
            .collect()
    } else {
        read_pvd(&file)?
            .into_iter()
            .map(|(t, p)| (t, FrameRef::Vtu(p)))
            .collect()
    };
    Ok((file, frames))
}

/// Reads one frame of a series.
pub fn read_frame(frame: &FrameRef) -> Result<Vtu> {
    match frame {
        FrameRef::Vtu(path) => read_vtu(path),
        FrameRef::Vtkhdf { path, index } => read_vtkhdf_frame(path, *index),
    }
}

/// The `(step, time)` of every complete frame of a `solution.vtkhdf` written by
/// [`super::Series`]. A file that cannot be read is an input error naming it.
pub fn read_vtkhdf(path: &Path) -> Result<Vec<(usize, f64)>> {
    if !path.exists() {
        return Err(Error::input(format!("{}: no such file", path.display())));
    }
    Ok(vtkhdf::Stored::read(path)?.frames)
}

/// One named data array with its number of components; values converted to f64.
#[derive(Clone, Debug)]
pub struct Array {
    pub name: String,
    pub components: usize,
    pub values: Vec<f64>,
}

/// The content of one `.vtu` file.
#[derive(Clone, Debug)]
pub struct Vtu {
    pub points: Vec<[f64; 3]>,
    /// Node indices of each cell.
    pub cells: Vec<Vec<usize>>,
    pub point_data: Vec<Array>,
    pub cell_data: Vec<Array>,
}

impl Vtu {
    pub fn point_field(&self, name: &str) -> Option<&Array> {
        self.point_data.iter().find(|a| a.name == name)
    }

    pub fn cell_field(&self, name: &str) -> Option<&Array> {
        self.cell_data.iter().find(|a| a.name == name)
    }
}

/// The `(time, path)` entries of a `.pvd`, paths resolved against its directory.
pub fn read_pvd(path: &Path) -> Result<Vec<(f64, PathBuf)>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let entries =
        pvd::parse(&text).map_err(|m| Error::input(format!("{}: {m}", path.display())))?;
    let dir = path.parent().unwrap_or(Path::new("."));
    Ok(entries.into_iter().map(|(t, f)| (t, dir.join(f))).collect())
}

/// Reads a `.vtu` file written by [`super::Series`], or a `.pvtu` and its pieces as the one
/// mesh they were cut from (its points in the mesh's order).
pub fn read_vtu(path: &Path) -> Result<Vtu> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    if path.extension().is_some_and(|e| e == "pvtu") {
        return read_pieces(path, &String::from_utf8_lossy(&bytes));
    }
    parse_vtu(&bytes).map_err(|m| Error::input(format!("{}: {m}", path.display())))
}

/// The pieces of the `.pvtu` at `path` (`text`), joined.
fn read_pieces(path: &Path, text: &str) -> Result<Vtu> {
    let parent = path.parent().unwrap_or(Path::new("."));
    let pieces = (super::pvtu::sources(text).into_iter())
        .map(|source| read_vtu(&parent.join(source)))
        .collect::<Result<Vec<Vtu>>>()?;
    join(pieces).map_err(|m| Error::input(format!("{}: {m}", path.display())))
}

/// Pieces as the one mesh they were cut from: each point where its global id
/// (`GlobalPointIds`) puts it, so that point fields are in the mesh's order, and the cells
/// piece after piece.
fn join(pieces: Vec<Vtu>) -> std::result::Result<Vtu, String> {
    let ids = |v: &Vtu| -> std::result::Result<Vec<usize>, String> {
        let ids = (v.point_field(super::vtu::GLOBAL_IDS))
            .ok_or_else(|| format!("a piece has no point array {}", super::vtu::GLOBAL_IDS))?;
        Ok(ids.values.iter().map(|&x| x as usize).collect())
    };
    let ids = pieces
        .iter()
        .map(ids)
        .collect::<std::result::Result<Vec<_>, _>>()?;
    let n = ids
        .iter()
        .flatten()
        .map(|&i| i + 1)
        .max()
        .ok_or("lists no pieces")?;
    let empty = |arrays: &[Array], count: usize| -> Vec<Array> {
        (arrays.iter().filter(|a| a.name != super::vtu::GLOBAL_IDS))
            .map(|a| Array {
                name: a.name.clone(),
                components: a.components,
                values: vec![f64::NAN; a.components * count],
            })
            .collect()
    };
    let mut whole = Vtu {
        points: vec![[f64::NAN; 3]; n],
        cells: Vec::new(),
        point_data: empty(&pieces[0].point_data, n),
        cell_data: empty(&pieces[0].cell_data, 0),
    };
    for (piece, ids) in pieces.into_iter().zip(ids) {
        ids.iter()
            .zip(&piece.points)
            .for_each(|(&i, &p)| whole.points[i] = p);
        let cells = piece.cells.iter();
        (whole.cells).extend(cells.map(|c| c.iter().map(|&k| ids[k]).collect()));
        for a in whole.point_data.iter_mut() {
            let k = a.components;
            let theirs = piece.point_field(&a.name).filter(|b| b.components == k);
            let theirs = theirs.ok_or_else(|| format!("a piece has no point field {}", a.name))?;
            for (j, &i) in ids.iter().enumerate() {
                a.values[i * k..(i + 1) * k].copy_from_slice(&theirs.values[j * k..(j + 1) * k]);
            }
        }
        for a in whole.cell_data.iter_mut() {
            let theirs = piece
                .cell_field(&a.name)
                .filter(|b| b.components == a.components);
            let theirs = theirs.ok_or_else(|| format!("a piece has no cell field {}", a.name))?;
            a.values.extend_from_slice(&theirs.values);
        }
    }
    match whole.points.iter().position(|p| p[0].is_nan()) {
        Some(i) => Err(format!("point {i} of the mesh is in none of its pieces")),
        None => Ok(whole),
    }
}

/// The bytes of the `_`-prefixed raw appended section, and whether they are zlib blocks.
struct Appended<'a> {
    data: &'a [u8],
    zlib: bool,
}

/// Parses the bytes of a `.vtu` file.
pub fn parse_vtu(bytes: &[u8]) -> std::result::Result<Vtu, String> {
    let tag = b"<AppendedData";
    let (head, data) = match bytes.windows(tag.len()).position(|w| w == tag) {
        Some(at) => {
            let rest = &bytes[at..];
            let us = rest
                .iter()
                .position(|&b| b == b'_')
                .ok_or("<AppendedData> without its '_' marker")?;
            (&bytes[..at], &rest[us + 1..])
        }
        None => (bytes, &[][..]),
    };
    let text = std::str::from_utf8(head).map_err(|_| "the XML part is not UTF-8".to_string())?;
    if !text.contains("type=\"UnstructuredGrid\"") {
        return Err("not a VTK UnstructuredGrid (.vtu) file".into());
    }
    let appended = Appended {
        data,
        zlib: text.contains("compressor=\"vtkZLibDataCompressor\""),
    };
    if !appended.zlib && text.contains("compressor=") {
        return Err("only vtkZLibDataCompressor compression is supported".into());
    }
    if !text.contains("header_type=\"UInt64\"") {
        return Err("only header_type=\"UInt64\" is supported".into());
    }
    // `<PointData>`, or with attributes (`<PointData GlobalIds="…">`).
    let section = |tag: &str| -> &str {
        let open = [format!("<{tag}>"), format!("<{tag} ")];
        let start = open.iter().filter_map(|o| text.find(o)).min();
        let start = start.and_then(|a| text[a..].find('>').map(|e| a + e + 1));
        match (start, text.find(&format!("</{tag}>"))) {
            (Some(a), Some(b)) if b >= a => &text[a..b],
            _ => "",
        }
    };
    let point_data = arrays(section("PointData"), &appended)?;
    let cell_data = arrays(section("CellData"), &appended)?;
    let points = arrays(section("Points"), &appended)?;
    let cells = arrays(section("Cells"), &appended)?;
    let pts = points
        .first()
        .ok_or_else(|| "no <Points> array".to_string())?;
    if pts.components != 3 || pts.values.len() % 3 != 0 {
        return Err("<Points> must have 3 components".into());
    }
    let points: Vec<[f64; 3]> = pts
        .values
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    let out_cells = cells_of(&cells, points.len())?;
    check_sizes(&point_data, points.len(), "point")?;
    check_sizes(&cell_data, out_cells.len(), "cell")?;
    Ok(Vtu {
        points,
        cells: out_cells,
        point_data,
        cell_data,
    })
}

/// The cells from the `<Cells>` arrays `connectivity` and `offsets`, each a list of point
/// indices below `n_points`.
fn cells_of(cells: &[Array], n_points: usize) -> std::result::Result<Vec<Vec<usize>>, String> {
    let get = |name: &str| {
        cells
            .iter()
            .find(|a| a.name == name)
            .ok_or_else(|| format!("<Cells> has no '{name}' array"))
    };
    let conn = get("connectivity")?;
    let offsets = get("offsets")?;
    let mut start = 0usize;
    let mut out_cells = Vec::with_capacity(offsets.values.len());
    for &o in &offsets.values {
        let end = o as usize;
        if end < start || end > conn.values.len() {
            return Err("bad cell offsets".into());
        }
        let c: Vec<usize> = conn.values[start..end]
            .iter()
            .map(|&i| i as usize)
            .collect();
        if c.iter().any(|&i| i >= n_points) {
            return Err("a cell refers to a missing point".into());
        }
        out_cells.push(c);
        start = end;
    }
    Ok(out_cells)
}

/// Refuses a `what` field (point or cell) whose values are not components × `count`.
fn check_sizes(list: &[Array], count: usize, what: &str) -> std::result::Result<(), String> {
    for a in list {
        if a.values.len() != a.components * count {
            return Err(format!(
                "{what} field '{}' has {} values for {count} {what}s × {} components",
                a.name,
                a.values.len(),
                a.components
            ));
        }
    }
    Ok(())
}

/// Every `<DataArray …>` in `s`: inline base64 (`format="binary"`, uncompressed) or
/// appended (`format="appended" offset="N"`).
fn arrays(s: &str, appended: &Appended) -> std::result::Result<Vec<Array>, String> {
    let mut out = Vec::new();
    let mut rest = s;
    while let Some(a) = rest.find("<DataArray") {
        let after = &rest[a + "<DataArray".len()..];
        let gt = after.find('>').ok_or("unterminated <DataArray>")?;
        let attrs = &after[..gt];
        let name = attr(attrs, "Name").unwrap_or("").to_string();
        let ty = attr(attrs, "type").ok_or("a <DataArray> has no type")?;
        let components: usize = attr(attrs, "NumberOfComponents")
            .unwrap_or("1")
            .parse()
            .map_err(|_| format!("array '{name}': bad NumberOfComponents"))?;
        let format = attr(attrs, "format").unwrap_or("");
        let body = &after[gt + 1..];
        let raw = match format {
            "appended" => {
                let offset: usize = attr(attrs, "offset")
                    .and_then(|o| o.parse().ok())
                    .ok_or_else(|| format!("array '{name}': no offset"))?;
                let data = appended
                    .data
                    .get(offset..)
                    .ok_or_else(|| format!("array '{name}': offset {offset} past the data"))?;
                rest = body;
                if appended.zlib {
                    inflate_blocks(data)
                } else {
                    counted(data)
                }
            }
            "binary" => {
                let end = body
                    .find("</DataArray>")
                    .ok_or_else(|| format!("array '{name}' is not closed"))?;
                rest = &body[end..];
                let bytes = base64_decode(body[..end].trim()).ok_or("bad base64")?;
                counted(&bytes)
            }
            _ => {
                return Err(format!(
                    "array '{name}': format=\"{format}\" is not supported (appended or binary)"
                ))
            }
        }
        .map_err(|m| format!("array '{name}': {m}"))?;
        let values = decode(ty, &raw)
            .ok_or_else(|| format!("array '{name}': type {ty} is not supported"))?;
        out.push(Array {
            name,
            components: components.max(1),
            values,
        });
    }
    Ok(out)
}

/// The UInt64 little-endian word `k` of `d`.
fn word(d: &[u8], k: usize) -> std::result::Result<usize, String> {
    d.get(8 * k..8 * k + 8)
        .map(|w| u64::from_le_bytes(w.try_into().expect("8 bytes")) as usize)
        .ok_or_else(|| "truncated header".to_string())
}

/// Uncompressed: a UInt64 byte count, then the bytes.
fn counted(d: &[u8]) -> std::result::Result<Vec<u8>, String> {
    let len = word(d, 0)?;
    d.get(8..8 + len)
        .map(<[u8]>::to_vec)
        .ok_or_else(|| format!("{len} bytes announced, fewer present"))
}

/// VTK's zlib blocks: number of blocks, block size, last partial block size (0 = full),
/// compressed sizes, then the blocks.
fn inflate_blocks(d: &[u8]) -> std::result::Result<Vec<u8>, String> {
    let (blocks, size, last) = (word(d, 0)?, word(d, 1)?, word(d, 2)?);
    let total = blocks
        .checked_mul(size)
        .map(|t| if last > 0 { t - size + last } else { t })
        .ok_or("bad block header")?;
    let mut out = Vec::with_capacity(total.min(1 << 30));
    let mut at = 8 * (3 + blocks);
    for b in 0..blocks {
        let n = word(d, 3 + b)?;
        let block = d.get(at..at + n).ok_or("a compressed block is cut short")?;
        std::io::Read::read_to_end(&mut flate2::read::ZlibDecoder::new(block), &mut out)
            .map_err(|e| format!("zlib: {e}"))?;
        at += n;
    }
    if out.len() != total {
        return Err(format!("{} bytes inflated, {total} announced", out.len()));
    }
    Ok(out)
}

fn decode(ty: &str, d: &[u8]) -> Option<Vec<f64>> {
    macro_rules! conv {
        ($t:ty, $n:expr) => {
            d.chunks_exact($n)
                .map(|c| <$t>::from_le_bytes(c.try_into().expect("chunk")) as f64)
                .collect()
        };
    }
    Some(match ty {
        "Float64" => conv!(f64, 8),
        "Float32" => conv!(f32, 4),
        "Int64" => conv!(i64, 8),
        "Int32" => conv!(i32, 4),
        "UInt64" => conv!(u64, 8),
        "UInt32" => conv!(u32, 4),
        "UInt8" => d.iter().map(|&b| b as f64).collect(),
        _ => return None,
    })
}

/// The value of attribute `name` in an element's attribute text.
fn attr<'a>(attrs: &'a str, name: &str) -> Option<&'a str> {
    let pat = format!(" {name}=\"");
    let i = attrs.find(&pat)? + pat.len();
    let j = attrs[i..].find('"')?;
    Some(&attrs[i..i + j])
}

/// Standard base64 (RFC 4648) with padding; None on a bad character.
fn base64_decode(s: &str) -> Option<Vec<u8>> {
    fn val(c: u8) -> Option<u32> {
        Some(match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => return None,
        } as u32)
    }
    let bytes: Vec<u8> = s.bytes().filter(|c| !c.is_ascii_whitespace()).collect();
    let mut out = Vec::with_capacity(bytes.len() / 4 * 3);
    for chunk in bytes.chunks(4) {
        let pad = chunk.iter().rev().take_while(|&&c| c == b'=').count();
        let mut n = 0u32;
        for (i, &c) in chunk.iter().enumerate() {
            let v = if i >= chunk.len() - pad { 0 } else { val(c)? };
            n |= v << (18 - 6 * i);
        }
        let take = chunk.len().saturating_sub(1).saturating_sub(pad);
        out.extend_from_slice(&[(n >> 16) as u8, (n >> 8) as u8, n as u8][..take]);
    }
    Some(out)
}

/// Frame `index` of a `solution.vtkhdf`, as [`Vtu`] (for `plot`).
fn read_vtkhdf_frame(path: &Path, index: usize) -> Result<Vtu> {
    read_frame_h5(path, index).map_err(|e| {
        Error::input(format!(
            "{}: frame {index} cannot be read ({e})",
            path.display()
        ))
    })
}

fn read_frame_h5(path: &Path, index: usize) -> hdf5_metno::Result<Vtu> {
    let file = vtkhdf::h5_open(path, hdf5_metno::OpenMode::Read)?;
    let root = file.group("VTKHDF")?;
    let points: Vec<f64> = root.dataset("Points")?.read_raw()?;
    let conn: Vec<i64> = root.dataset("Connectivity")?.read_raw()?;
    let offsets: Vec<i64> = root.dataset("Offsets")?.read_raw()?;
    let n = points.len() / 3;
    let mut cells = Vec::with_capacity(offsets.len().saturating_sub(1));
    for w in offsets.windows(2) {
        let (a, b) = (w[0] as usize, w[1] as usize);
        let cell = conn
            .get(a..b)
            .ok_or("Offsets point past Connectivity")?
            .iter()
            .map(|&i| i as usize)
            .collect::<Vec<_>>();
        if cell.iter().any(|&i| i >= n) {
            return Err("a cell refers to a missing point".into());
        }
        cells.push(cell);
    }
    let steps = root.group("Steps")?;
    let read = |data: &str, offsets: &str, rows: usize| -> hdf5_metno::Result<Vec<Array>> {
        let mut out = Vec::new();
        for ds in root.group(data)?.datasets()? {
            let full = ds.name();
            let name = full.rsplit('/').next().unwrap_or_default().to_string();
            let shape = ds.shape();
            let components = shape.get(1).copied().unwrap_or(1);
            let from = steps
                .group(offsets)?
                .dataset(&name)
                .and_then(|o| o.read_raw::<i64>())
                .ok()
                .and_then(|o| o.get(index).copied())
                .unwrap_or(0) as usize;
            if from + rows > shape[0] {
                return Err(format!("{full}: frame {index} lies past its end").into());
            }
            let values: Vec<f64> = if components == 1 {
                ds.read_slice_1d::<f64, _>(from..from + rows)?.to_vec()
            } else {
                ds.read_slice_2d::<f64, _>(ndarray::s![from..from + rows, ..])?
                    .iter()
                    .copied()
                    .collect()
            };
            out.push(Array {
                name,
                components,
                values,
            });
        }
        Ok(out)
    };
    let point_data = read("PointData", "PointDataOffsets", n)?;
    let cell_data = read("CellData", "CellDataOffsets", cells.len())?;
    Ok(Vtu {
        points: points.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect(),
        cells,
        point_data,
        cell_data,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_decodes_rfc_4648_vectors() {
        for (plain, enc) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64_decode(enc).unwrap(), plain.as_bytes(), "{enc}");
        }
        assert!(base64_decode("Zm9*").is_none());
    }

    #[test]
    fn series_round_trips_through_the_reader() {
        use super::super::{Compression, Field, Frame, Geometry, Options, Precision, Series};
        let points = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 1.0, 0.0],
        ];
        let cells = [0, 1, 2, 1, 3, 2];
        let u = [0.0, 0.0, 0.0, 0.1, 0.0, 0.0, 0.0, -0.2, 0.0, 0.3, 0.4, 0.0];
        let vm = [1.5, -2.25];
        for compression in [Compression::None, Compression::Zlib] {
            for precision in [Precision::Float64, Precision::Float32] {
                let dir = tempfile::tempdir().unwrap();
                let geometry = Geometry {
                    points: crate::mesh::Points::Every(&points),
                    cells: &cells,
                    nodes_per_cell: 3,
                    region: &[7, 9],
                    material_region: &[],
                    pieces: &[],
                    pieces_by_ranks: false,
                };
                let options = Options {
                    compression,
                    precision,
                    fields: None,
                    ..Options::default()
                };
                let mut s = Series::create(dir.path(), &geometry, "id", &options).unwrap();
                s.write(&Frame {
                    step: 3,
                    time: 0.75,
                    point_data: vec![Field {
                        name: "displacement",
                        components: 3,
                        values: &u,
                    }],
                    cell_data: vec![Field {
                        name: "von_mises",
                        components: 1,
                        values: &vm,
                    }],
                })
                .unwrap();
                s.finish().unwrap();
                let entries = read_pvd(&dir.path().join("solution.pvd")).unwrap();
                assert_eq!(entries.len(), 1);
                assert_eq!(entries[0].0, 0.75);
                let v = read_vtu(&entries[0].1).unwrap();
                assert_eq!(v.points, points);
                assert_eq!(v.cells, vec![vec![0, 1, 2], vec![1, 3, 2]]);
                let round = |x: &[f64]| -> Vec<f64> {
                    match precision {
                        Precision::Float64 => x.to_vec(),
                        Precision::Float32 => x.iter().map(|&v| v as f32 as f64).collect(),
                    }
                };
                assert_eq!(v.point_field("displacement").unwrap().values, round(&u));
                assert_eq!(v.cell_field("von_mises").unwrap().values, round(&vm));
                assert_eq!(v.cell_field("region").unwrap().values, [7.0, 9.0]);
            }
        }
    }
}
