//! An MSH file as read, before any geometry: the plain arrays a read fills ([`RawMesh`]),
//! the file's encoding ([`Format`]), its sections' markers and a scanner of the numbers in
//! a section, ASCII or binary ([`Scanner`]), which `msh.rs` (through mshio, and its own
//! scans of the node tags) and `elements.rs` (the `$Elements` section) read with.

use std::collections::HashMap;

/// The parsed content of an MSH file, before any geometric processing. Node indices are
/// positions in `nodes` (file order); tags are the file's tags.
#[derive(Debug, Default)]
pub(crate) struct RawMesh {
    pub nodes: Vec<[f64; 3]>,
    pub triangles: Vec<RawElement<3>>,
    pub tetrahedra: Vec<RawElement<4>>,
    pub lines: Vec<RawElement<2>>,
    /// Physical tags of each entity `(dim, entity tag)`, from `$Entities`.
    pub physical: HashMap<(i32, i32), Vec<i32>>,
    /// Every `(dim, physical tag)` that some entity lists, in file order (curves, then
    /// surfaces, then volumes; points are skipped).
    pub physical_order: Vec<(i32, i32)>,
}

#[derive(Debug, Clone, Copy)]
pub(crate) struct RawElement<const N: usize> {
    /// The element tag in the file (for messages).
    pub tag: u64,
    /// The nodes' positions in [`RawMesh::nodes`] ([`RawElement::nodes`]): 32 bytes a
    /// tetrahedron, where positions as `usize` took 48, and a read holds every cell as read
    /// beside the cells oriented (docs/performance.md, "Reading the mesh").
    pub at: [u32; N],
    /// `(dim, tag)` of the entity the element belongs to.
    pub entity: (i32, i32),
}

impl<const N: usize> RawElement<N> {
    /// The nodes' positions in [`RawMesh::nodes`].
    pub fn nodes(&self) -> [usize; N] {
        self.at.map(|n| n as usize)
    }
}

/// What a mesh keeps of its cells as read once their nodes are oriented: each one's tag
/// in the file (for messages) and entity, 16 bytes a cell where the cell as read held 32
/// (a tetrahedron), freed before the faces' passes (docs/performance.md, "Reading the
/// mesh").
pub(crate) struct CellsRead {
    pub tags: Vec<u64>,
    pub entities: Vec<(i32, i32)>,
}

impl CellsRead {
    /// The tags and entities of `cells`, which go.
    pub fn of<const N: usize>(cells: Vec<RawElement<N>>) -> CellsRead {
        CellsRead {
            tags: cells.iter().map(|c| c.tag).collect(),
            entities: cells.iter().map(|c| c.entity).collect(),
        }
    }
}

/// A mesh whose node indices do not fit 32 bits ([`RawElement::at`], `facets::Facets`),
/// or cell indices 29 (`facets::Facets`).
pub(crate) fn too_many_nodes(file: &impl std::fmt::Display) -> crate::Error {
    crate::Error::input(format!(
        "mesh file '{file}' has more than 2^32 nodes or 2^29 cells, more than viscontact \
         indexes: split the body or use a coarser mesh"
    ))
}

/// Encoding details from `$MeshFormat`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Format {
    pub binary: bool,
    pub size_t: usize,
    pub big_endian: bool,
}

/// Offset just past the line `name` (which must start a line and be alone on it), or `None`.
pub(crate) fn find_section(bytes: &[u8], name: &[u8]) -> Option<usize> {
    find_marker(bytes, name).map(|(_, past)| past)
}

/// The offsets of the marker `name` (which must start a line and be alone on it) and just
/// past its line, or `None`.
pub(crate) fn find_marker(bytes: &[u8], name: &[u8]) -> Option<(usize, usize)> {
    let mut from = 0;
    while from + name.len() <= bytes.len() {
        let hit = from + find_sub(&bytes[from..], name)?;
        // A marker may be indented and followed by blanks (mshio accepts both).
        let before = bytes[..hit]
            .iter()
            .rev()
            .find(|&&b| b != b' ' && b != b'\t');
        let at_line_start = before.is_none_or(|&b| b == b'\n');
        let after = &bytes[hit + name.len()..];
        let blanks = after
            .iter()
            .take_while(|&&b| b == b' ' || b == b'\t' || b == b'\r')
            .count();
        let eol = (after.get(blanks) == Some(&b'\n')).then_some(blanks + 1);
        if let (true, Some(eol)) = (at_line_start, eol) {
            return Some((hit, hit + name.len() + eol));
        }
        from = hit + 1;
    }
    None
}

fn find_sub(hay: &[u8], needle: &[u8]) -> Option<usize> {
    let first = *needle.first()?;
    let mut i = 0;
    while i + needle.len() <= hay.len() {
        let j = i + hay[i..=hay.len() - needle.len()]
            .iter()
            .position(|&b| b == first)?;
        if hay[j..].starts_with(needle) {
            return Some(j);
        }
        i = j + 1;
    }
    None
}

/// Reads size_t / int / double values of an MSH section, ASCII or binary.
pub(crate) struct Scanner<'a> {
    pub bytes: &'a [u8],
    pub pos: usize,
    pub fmt: Format,
}

impl Scanner<'_> {
    fn token(&mut self) -> Option<&str> {
        let b = self.bytes;
        while self.pos < b.len() && b[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        let start = self.pos;
        while self.pos < b.len() && !b[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        if start == self.pos {
            return None;
        }
        std::str::from_utf8(&b[start..self.pos]).ok()
    }

    fn fixed(&mut self, n: usize) -> Option<u64> {
        let raw = self.bytes.get(self.pos..self.pos + n)?;
        self.pos += n;
        let mut v: u64 = 0;
        if self.fmt.big_endian {
            for &byte in raw {
                v = (v << 8) | u64::from(byte);
            }
        } else {
            for &byte in raw.iter().rev() {
                v = (v << 8) | u64::from(byte);
            }
        }
        Some(v)
    }

    /// The position of the next value: past the blanks before it in an ASCII file.
    pub fn next_at(&mut self) -> usize {
        if !self.fmt.binary {
            let blanks = self.bytes[self.pos.min(self.bytes.len())..].iter();
            self.pos += blanks.take_while(|b| b.is_ascii_whitespace()).count();
        }
        self.pos
    }

    pub fn size_t(&mut self) -> Option<u64> {
        if self.fmt.binary {
            self.fixed(self.fmt.size_t)
        } else {
            self.token()?.parse().ok()
        }
    }

    pub fn int(&mut self) -> Option<i64> {
        if self.fmt.binary {
            self.fixed(4).map(|v| i64::from(v as u32 as i32))
        } else {
            self.token()?.parse().ok()
        }
    }

    pub fn skip_doubles(&mut self, n: u64) -> Option<()> {
        if self.fmt.binary {
            let len = usize::try_from(n.checked_mul(8)?).ok()?;
            let end = self.pos.checked_add(len)?;
            if end > self.bytes.len() {
                return None;
            }
            self.pos = end;
        } else {
            for _ in 0..n {
                self.token()?;
            }
        }
        Some(())
    }
}
