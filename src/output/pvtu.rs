//! A frame in pieces, for a run over MPI ranks: `solution_NNNNNN.pvtu`, VTK's parallel
//! UnstructuredGrid, listing one `.vtu` piece per rank in the directory `solution_NNNNNN/`
//! (`solution_NNNNNN/solution_NNNNNN_R.vtu`, the layout of VTK's own
//! `vtkXMLPUnstructuredGridWriter`):
//!
//! ```xml
//! <?xml version="1.0"?>
//! <!-- run_id: ID -->
//! <VTKFile type="PUnstructuredGrid" version="1.0" byte_order="LittleEndian" header_type="UInt64">
//!   <PUnstructuredGrid GhostLevel="0">
//!     <PPointData> <PDataArray type="Float64" Name="displacement" NumberOfComponents="3"/> …
//!     <PCellData> … <PPoints> …
//!     <Piece Source="solution_000001/solution_000001_0.vtu"/> …
//! ```
//!
//! Piece r holds the cells of rank r's part of the mesh (the part of METIS's partition that
//! the rank solves for, `petsc::Layout`: a cell goes with the lowest part among its nodes
//! that have unknowns) and the points those cells use, so a node on the border between two
//! parts is in both pieces, with the same values; there are no ghost cells. A part without
//! cells has no piece. Each piece is a `.vtu` of `vtu.rs` with the fields of a one-process
//! frame, its own mesh encoded once per run, and the point array `GlobalPointIds` (VTK's
//! global ids: each point's number in the whole mesh, from 0), by which this crate's reader
//! (`read.rs`) joins the pieces again, and VTK's filters that match shared points find them.
//!
//! A frame is written piece by piece, each through a temporary file and a rename, then the
//! `.pvtu`; a checkpoint records the CRC-32 of the `.pvtu`'s bytes followed by its pieces'
//! ([`crc32_of_frame`]), so resume verifies every piece. The same step's frame of the other
//! layout (a `.vtu` written before a resume on one rank, or the reverse) and pieces that the
//! `.pvtu` no longer lists (a resume on fewer ranks) are removed once the frame is written:
//! a step has one frame on disk.
//!
//! In a run, each rank writes its own piece ([`OwnPiece`], from the fields of its piece's
//! cells alone) and rank 0's series lists the pieces in the `.pvtu` once every rank's is on
//! disk (`Series::list_pieces`; the geometry's `pieces_by_ranks`); a series handed whole
//! frames (`Series::write`) writes every piece itself.

use std::borrow::Cow;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::vtu::{array_attrs, escape_attr, global_ids, Grid, Job, Vtu, GLOBAL_IDS};
use super::writer::{Sink, Written};
use super::{checked_arrays, pvd, vtu_name, write_atomic, Array, Compression, Geometry};
use super::{Options, OwnedField, Values};
use crate::mesh::{increasing, Points};
use crate::{Error, Result};

/// The `.pvtu` of step `step`: `solution_{step:06}.pvtu`.
pub fn pvtu_name(step: usize) -> String {
    format!("solution_{step:06}.pvtu")
}

/// The directory of step `step`'s pieces, and the name of piece `r` in it.
fn piece_name(step: usize, r: usize) -> (String, String) {
    let dir = format!("solution_{step:06}");
    let file = format!("{dir}_{r}.vtu");
    (dir, file)
}

/// A series' frames in `.vtu` files: one per frame, or (a run over MPI ranks) a `.pvtu`
/// per frame with a piece per rank ([`Pieces`]).
pub(super) enum Frames {
    One(Box<Grid>),
    Pieces(Pieces),
}

impl Sink for Frames {
    type Job = Job;

    /// The frame's file(s) (temporary file + rename) and its CRC-32 (read back: the file is
    /// in the page cache, and its block sizes were patched in after the blocks), then the
    /// `.pvd` (likewise).
    fn write(&mut self, job: Job) -> Result<Option<Written>> {
        let written = match job.vtu {
            Some(v) => {
                match self {
                    Frames::One(grid) => {
                        grid.write_frame(&v.path, &v.point_data, &v.cell_data)?;
                        let parent = v.path.parent().unwrap_or(Path::new("."));
                        remove_frame(parent, v.step);
                    }
                    Frames::Pieces(pieces) => pieces.write(&v)?,
                }
                let (crc32, bytes) =
                    crc32_of_frame(&v.path).map_err(|e| crate::Error::io(&v.path, e))?;
                Some(Written {
                    step: v.step,
                    crc32,
                    bytes,
                })
            }
            None => None,
        };
        if let Some((path, text)) = job.pvd {
            write_atomic(&path, text.as_bytes())?;
        }
        Ok(written)
    }

    fn prepare(&mut self) {
        match self {
            Frames::One(grid) => grid.prepare(),
            Frames::Pieces(pieces) => pieces.prepare(),
        }
    }

    /// Every file was closed when it was written.
    fn close(&mut self) -> Result<()> {
        Ok(())
    }
}

/// One piece: its mesh, and which of the whole mesh's points and cells it holds.
struct Piece {
    rank: usize,
    grid: Grid,
    points: Vec<usize>,
    cells: Vec<usize>,
}

/// The pieces of every frame of a series: written here from a frame's whole fields, or
/// (`Geometry::pieces_by_ranks`, a run) by each rank ([`OwnPiece`]) before the series
/// lists them (`Series::list_pieces`).
pub(super) struct Pieces {
    /// Each piece's mesh where this writes the pieces; empty where the ranks do.
    pieces: Vec<Piece>,
    /// The ranks whose pieces have cells, in order: those the `.pvtu` lists.
    ranks: Vec<usize>,
    run_id: String,
    /// The `<PCellData>` lines of the static cell arrays (`region`, `material_region`).
    statics: Vec<String>,
}

impl Pieces {
    /// Splits the geometry by `g.pieces` (a piece index for each cell) and encodes each
    /// piece's mesh ([`Grid::new`]).
    pub(super) fn new(g: &Geometry, run_id: &str, compression: Compression) -> Result<Pieces> {
        let npc = g.nodes_per_cell;
        let num_cells = g.cells.len() / npc.max(1);
        if g.pieces.len() != num_cells {
            return Err(Error::input(format!(
                "output: {} piece indices for {num_cells} cells",
                g.pieces.len()
            )));
        }
        let count = g.pieces.iter().map(|&p| p as usize + 1).max().unwrap_or(0);
        let mut cells_of = vec![Vec::new(); count];
        for (c, &p) in g.pieces.iter().enumerate() {
            cells_of[p as usize].push(c);
        }
        let ranks = (0..count).filter(|&r| !cells_of[r].is_empty()).collect();
        let mut pieces = Vec::new();
        for (rank, cells) in cells_of.into_iter().enumerate() {
            if !cells.is_empty() && !g.pieces_by_ranks {
                let mesh = PieceMesh::of(g, rank, cells);
                pieces.push(Piece::new(mesh, run_id, compression)?);
            }
        }
        let statics = g
            .cell_statics()
            .iter()
            .map(|(name, _)| format!("      <PDataArray {}/>\n", array_attrs("Int32", name, 1)))
            .collect();
        Ok(Pieces {
            pieces,
            ranks,
            run_id: run_id.to_string(),
            statics,
        })
    }

    /// Compresses every piece's mesh (once).
    pub(super) fn prepare(&mut self) {
        self.pieces.iter_mut().for_each(|p| p.grid.prepare());
    }

    /// Writes the frame `v` (`v.path` its `.pvtu`): every piece from the whole-mesh fields
    /// (unless the ranks wrote them: then `v`'s arrays only name the fields), then the
    /// `.pvtu`; removes what another layout or rank count left of this step.
    pub(super) fn write(&mut self, v: &Vtu) -> Result<()> {
        let parent = v.path.parent().unwrap_or(Path::new("."));
        let (dir_name, _) = piece_name(v.step, 0);
        for p in &mut self.pieces {
            p.write(parent, v.step, (&v.point_data, &v.cell_data), false)?;
        }
        let sources: Vec<String> = (self.ranks.iter())
            .map(|&r| format!("{dir_name}/{}", piece_name(v.step, r).1))
            .collect();
        let dir = parent.join(&dir_name);
        write_atomic(&v.path, self.xml(v, &sources).as_bytes())?;
        let _ = std::fs::remove_file(parent.join(vtu_name(v.step)));
        remove_pieces(&dir, v.step, |r| !self.ranks.contains(&r));
        Ok(())
    }

    /// The `.pvtu` of frame `v` whose pieces are `sources`.
    fn xml(&self, v: &Vtu, sources: &[String]) -> String {
        let mut s = format!(
            "<?xml version=\"1.0\"?>\n<!-- run_id: {} -->\n\
             <VTKFile type=\"PUnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" \
             header_type=\"UInt64\">\n  <PUnstructuredGrid GhostLevel=\"0\">\n",
            pvd::comment_safe(&self.run_id)
        );
        let arrays = |s: &mut String, arrays: &[Array]| {
            for a in arrays {
                let attrs = array_attrs(a.vtk_type(), &a.name, a.components);
                let _ = writeln!(s, "      <PDataArray {attrs}/>");
            }
        };
        let _ = writeln!(s, "    <PPointData{}>", global_ids(true));
        arrays(&mut s, &v.point_data);
        let _ = writeln!(
            s,
            "      <PDataArray {}/>",
            array_attrs("Int64", GLOBAL_IDS, 1)
        );
        s.push_str("    </PPointData>\n    <PCellData>\n");
        arrays(&mut s, &v.cell_data);
        self.statics.iter().for_each(|line| s.push_str(line));
        s.push_str("    </PCellData>\n    <PPoints>\n");
        let _ = writeln!(
            s,
            "      <PDataArray {}/>",
            array_attrs("Float64", "Points", 3)
        );
        s.push_str("    </PPoints>\n");
        for source in sources {
            let _ = writeln!(s, "    <Piece Source=\"{}\"/>", escape_attr(source));
        }
        s.push_str("  </PUnstructuredGrid>\n</VTKFile>\n");
        s
    }
}

/// The mesh of piece `rank`: its cells, the points they use (both as numbered in the whole
/// mesh, in its order) and its own numbering of them. Made during a rank's setup, while it
/// has the mesh; encoded once the run's steps begin ([`OwnPiece::new`]).
pub struct PieceMesh {
    rank: usize,
    points: Vec<usize>,
    cells: Vec<usize>,
    coords: Vec<[f64; 3]>,
    connectivity: Vec<usize>,
    nodes_per_cell: usize,
    region: Vec<i32>,
    material_region: Vec<i32>,
}

impl PieceMesh {
    /// The piece of `rank` in `g` (whose `pieces` give each cell's), or None where it has
    /// no cells (a part without cells has no piece).
    pub fn of_rank(g: &Geometry, rank: usize, options: &Options) -> Option<PieceMesh> {
        let g = g.chosen(options);
        let cells: Vec<usize> = (g.pieces.iter().enumerate())
            .filter(|&(_, &p)| p as usize == rank)
            .map(|(c, _)| c)
            .collect();
        (!cells.is_empty()).then(|| PieceMesh::of(&g, rank, cells))
    }

    /// Piece `rank` of `g`: the cells `cells` and the points they use.
    fn of(g: &Geometry, rank: usize, cells: Vec<usize>) -> PieceMesh {
        let npc = g.nodes_per_cell;
        let vertices = |c: usize| &g.cells[c * npc..(c + 1) * npc];
        // Its points, increasing, and each one's number in the piece by binary search: no
        // array of every node (a follower holds some nodes' places alone).
        let mut points = increasing(cells.iter().flat_map(|&c| vertices(c)).copied().collect());
        points.shrink_to_fit();
        let local = |i: &usize| points.binary_search(i).expect("a vertex of the piece");
        let subset = |a: &[i32]| -> Vec<i32> {
            match a.is_empty() {
                true => Vec::new(),
                false => cells.iter().map(|&c| a[c]).collect(),
            }
        };
        PieceMesh {
            rank,
            coords: points.iter().map(|&i| g.points[i]).collect(),
            connectivity: (cells.iter())
                .flat_map(|&c| vertices(c).iter().map(local))
                .collect(),
            nodes_per_cell: npc,
            region: subset(g.region),
            material_region: subset(g.material_region),
            points,
            cells,
        }
    }

    /// The piece's cells, numbered in the whole mesh, in its order.
    pub fn cells(&self) -> &[usize] {
        &self.cells
    }

    /// The piece's points, numbered in the whole mesh, in its order (increasing).
    pub fn points(&self) -> &[usize] {
        &self.points
    }

    /// The vertices of the piece's cells (`nodes_per_cell` a cell), each by its place
    /// among the piece's points.
    pub fn connectivity(&self) -> &[usize] {
        &self.connectivity
    }
}

impl Piece {
    /// The piece of `mesh`, its mesh encoded ([`Grid::new`]) with the global ids.
    fn new(mesh: PieceMesh, run_id: &str, compression: Compression) -> Result<Piece> {
        let grid = Grid::new(
            &Geometry {
                points: Points::Every(&mesh.coords),
                cells: &mesh.connectivity,
                nodes_per_cell: mesh.nodes_per_cell,
                region: &mesh.region,
                material_region: &mesh.material_region,
                pieces: &[],
                pieces_by_ranks: false,
            },
            run_id,
            compression,
        )?
        .with_global_ids(&mesh.points);
        Ok(Piece {
            rank: mesh.rank,
            grid,
            points: mesh.points,
            cells: mesh.cells,
        })
    }

    /// Writes the piece of step `step`'s frame (in its directory in `parent`, made if
    /// missing): `point_data` and `cell_data` of the whole mesh's points and cells, or
    /// (`own`) of the piece's alone, in its order.
    fn write(
        &mut self,
        parent: &Path,
        step: usize,
        (point_data, cell_data): (&[Array], &[Array]),
        own: bool,
    ) -> Result<()> {
        let (dir_name, file) = piece_name(step, self.rank);
        let dir = parent.join(dir_name);
        std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
        let piece = |data: &[Array], at: &[usize]| -> Vec<Array> {
            data.iter().map(|a| gather(a, at)).collect()
        };
        let (point_data, cell_data): (Cow<[Array]>, Cow<[Array]>) = match own {
            true => (Cow::Borrowed(point_data), Cow::Borrowed(cell_data)),
            false => (
                Cow::Owned(piece(point_data, &self.points)),
                Cow::Owned(piece(cell_data, &self.cells)),
            ),
        };
        self.grid
            .write_frame(&dir.join(file), &point_data, &cell_data)
    }
}

/// The piece of a run's frames that its own rank writes (a run over MPI ranks, `.vtu`
/// frames): each frame's piece file, before rank 0 lists the pieces in the frame's
/// `.pvtu` (`Series::list_pieces`), once every rank's is on disk.
pub struct OwnPiece {
    piece: Piece,
    dir: PathBuf,
    options: Options,
}

impl OwnPiece {
    /// The piece of `mesh` in the series of `dir`, its mesh encoded with the run id.
    pub fn new(dir: &Path, mesh: PieceMesh, run_id: &str, options: &Options) -> Result<OwnPiece> {
        Ok(OwnPiece {
            piece: Piece::new(mesh, run_id, options.compression)?,
            dir: dir.to_path_buf(),
            options: options.clone(),
        })
    }

    /// The piece's cells, numbered in the whole mesh, in its order.
    pub fn cells(&self) -> &[usize] {
        &self.piece.cells
    }

    /// The piece's points, numbered in the whole mesh, in its order (increasing).
    pub fn points(&self) -> &[usize] {
        &self.piece.points
    }

    /// Writes step `step`'s piece: `points` and `cells`, fields of the piece's points and
    /// cells in its order; those the options leave out are not written. A field of the
    /// wrong size is an input error naming the piece.
    pub fn write(
        &mut self,
        step: usize,
        points: Vec<OwnedField>,
        cells: Vec<OwnedField>,
    ) -> Result<()> {
        let (dir_name, file) = piece_name(step, self.piece.rank);
        let at = self.dir.join(dir_name).join(file);
        let sizes = (self.piece.points.len(), self.piece.cells.len());
        let (points, cells) = checked_arrays(&self.options, (&at, step), (points, cells), sizes)?;
        self.piece.write(&self.dir, step, (&points, &cells), true)
    }
}

/// The values of `a` at the tuples `at`.
fn gather(a: &Array, at: &[usize]) -> Array {
    let k = a.components;
    fn pick<T: Copy>(v: &[T], at: &[usize], k: usize) -> Vec<T> {
        at.iter()
            .flat_map(|&i| v[i * k..(i + 1) * k].iter().copied())
            .collect()
    }
    Array {
        name: a.name.clone(),
        components: k,
        values: match &a.values {
            Values::F64(v) => Values::F64(pick(v, at, k)),
            Values::F32(v) => Values::F32(pick(v, at, k)),
        },
    }
}

/// Removes the pieces of step `step` in `dir` whose rank `stale` selects, and `dir` if it is
/// then empty.
fn remove_pieces(dir: &Path, step: usize, stale: impl Fn(usize) -> bool) {
    let (dir_name, _) = piece_name(step, 0);
    let prefix = format!("{dir_name}_");
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let rank = name
            .strip_prefix(&prefix)
            .and_then(|r| r.strip_suffix(".vtu"))
            .and_then(|r| r.parse::<usize>().ok());
        if rank.is_some_and(&stale) {
            let _ = std::fs::remove_file(e.path());
        }
    }
    let _ = std::fs::remove_dir(dir);
}

/// Removes step `step`'s `.pvtu` in `parent` and its pieces (a `.vtu` frame replaced it).
pub(super) fn remove_frame(parent: &Path, step: usize) {
    let _ = std::fs::remove_file(parent.join(pvtu_name(step)));
    let (dir_name, _) = piece_name(step, 0);
    remove_pieces(&parent.join(dir_name), step, |_| true);
}

/// The pieces a `.pvtu` lists (`Source` attributes, relative to its directory), in order.
pub(super) fn sources(text: &str) -> Vec<String> {
    text.split("<Piece ")
        .skip(1)
        .filter_map(|rest| {
            let rest = &rest[rest.find("Source=\"")? + 8..];
            Some(pvd::unescape(&rest[..rest.find('"')?]))
        })
        .collect()
}

/// The CRC-32 and length of a frame's bytes: a `.vtu` file's, or a `.pvtu`'s followed by
/// those of the pieces it lists.
pub(super) fn crc32_of_frame(path: &Path) -> std::io::Result<(u32, u64)> {
    if path.extension().is_none_or(|e| e != "pvtu") {
        return super::crc32_of_file(path);
    }
    let text = std::fs::read(path)?;
    let (mut h, mut len) = (crc32fast::Hasher::new(), text.len() as u64);
    h.update(&text);
    let parent = path.parent().unwrap_or(Path::new("."));
    for source in sources(&String::from_utf8_lossy(&text)) {
        len += super::hash_file(&parent.join(source), &mut h)?;
    }
    Ok((h.finalize(), len))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sources_are_read_in_order() {
        let text = "<PUnstructuredGrid>\n<Piece Source=\"a/a_0.vtu\"/>\n<Piece \
                    Source=\"a/a_1.vtu\"/>\n";
        assert_eq!(sources(text), ["a/a_0.vtu", "a/a_1.vtu"]);
        assert_eq!(piece_name(7, 3).1, "solution_000007_3.vtu");
    }
}
