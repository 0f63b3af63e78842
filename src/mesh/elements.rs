//! The `$Elements` section of an MSH 4.1 file, read here and not by `mshio`.
//!
//! mshio keeps each element as its tag and a `Vec` of its node tags, a heap allocation an
//! element, and holds all of them before it returns: on the fine plate (684 k tetrahedra,
//! a 33 MB binary file) 64 MB of the 140 MB of heap at which reading the mesh peaks, and
//! rank 0 of a run over MPI ranks, which reads the mesh for all of them, peaked there
//! (docs/performance.md, "Reading the mesh"). So `msh.rs` hands mshio the file without
//! this section ([`Section::without`]), and this module walks the section twice, with the
//! scanner that reads the node tags: once for its blocks' heads (entity, type, count, where
//! the elements start: [`Section::find`]; a block of a type that is not read is skipped by
//! the type's node count, which mshio's `ElementType` knows), and once for the elements of
//! the types that are read, lines, triangles and tetrahedra, each into `RawMesh`'s lists
//! at their exact size ([`Section::read`]). What mshio checked of the section is checked
//! here too: every number where the format puts one, a known element type, the closing
//! `$EndElements`; a file that fails says where, as mshio's errors do
//! (`msh::stopped`).

use std::collections::HashMap;

use mshio::ElementType;
use num_traits::FromPrimitive;

use super::raw::{find_marker, Format, RawElement, RawMesh, Scanner};

/// One element block's head.
pub(super) struct Block {
    /// `(dim, tag)` of the entity its elements belong to.
    pub entity: (i32, i32),
    pub kind: ElementType,
    count: u64,
    /// Where its first element starts in the file.
    data: usize,
}

/// The `$Elements` section of a file: its blocks, and where it lies.
pub(super) struct Section {
    pub blocks: Vec<Block>,
    /// From its `$Elements` marker to just past its `$EndElements` marker.
    pub span: std::ops::Range<usize>,
}

/// Why a file's `$Elements` cannot be walked: it cannot be parsed (`Stop`: the byte
/// offset in the file and what was being read, outermost first, `element section >
/// element entity block (2 of 6) > …`), or it holds an element type without a fixed node
/// count, which no reader here can skip.
pub(super) enum Unread {
    Stop { at: usize, what: String },
    Unskippable(ElementType),
}

impl Unread {
    /// The section stops at `at`, in what `what` names within it.
    fn stop(at: usize, what: &str) -> Unread {
        let what = format!("element section > {what}");
        Unread::Stop { at, what }
    }
}

impl Section {
    /// The file's first `$Elements` section, walked for its blocks' heads; `None` where the
    /// file has none.
    pub fn find(bytes: &[u8], fmt: Format) -> Result<Option<Section>, Unread> {
        let Some((start, pos)) = find_marker(bytes, b"$Elements") else {
            return Ok(None);
        };
        let mut s = Scanner { bytes, pos, fmt };
        let stop = Unread::stop;
        let head = "element section header > number of element entity blocks";
        let n_blocks = s.size_t().ok_or_else(|| stop(s.pos, head))?;
        for what in [
            "total number of elements",
            "min element tag",
            "max element tag",
        ] {
            s.size_t()
                .ok_or_else(|| stop(s.pos, &format!("element section header > {what}")))?;
        }
        let mut blocks = Vec::new();
        for i in 1..=n_blocks {
            let within = |what: &str| format!("element entity block ({i} of {n_blocks}) > {what}");
            let block = block_head(&mut s, &within)?;
            let nodes = block
                .kind
                .nodes()
                .map_err(|()| Unread::Unskippable(block.kind))?;
            skip_elements(&mut s, block.count, nodes).map_err(|(at, j)| {
                stop(
                    at,
                    &within(&format!("element definition ({j} of {})", block.count)),
                )
            })?;
            blocks.push(block);
        }
        let at = s.next_at();
        let end = end_marker(bytes, at).ok_or_else(|| stop(at, "$EndElements"))?;
        Ok(Some(Section {
            blocks,
            span: start..end,
        }))
    }

    /// The file without this section, for mshio.
    pub fn without(&self, bytes: &[u8]) -> Vec<u8> {
        [&bytes[..self.span.start], &bytes[self.span.end..]].concat()
    }

    /// The offset in the file of `at`, an offset in [`Section::without`]'s bytes.
    pub fn in_file(&self, at: usize) -> usize {
        match at < self.span.start {
            true => at,
            false => at + self.span.len(),
        }
    }

    /// The lines, triangles and tetrahedra into `raw`, each list at its exact size, their
    /// nodes as positions in `raw.nodes` by `index` (node tag → position); an element that
    /// refers to a node `index` lacks is `missing(element tag, node tag)`'s error.
    pub fn read<E>(
        &self,
        bytes: &[u8],
        fmt: Format,
        index: &HashMap<u64, u32>,
        missing: impl Fn(u64, u64) -> E,
        raw: &mut RawMesh,
    ) -> Result<(), E> {
        let count = |kind| {
            self.blocks
                .iter()
                .filter(|b| b.kind == kind)
                .map(|b| b.count)
                .sum::<u64>()
        };
        // Each count was walked in the file, so it is no more than the file's bytes.
        let exact = |kind| usize::try_from(count(kind)).unwrap_or(0);
        raw.lines.reserve_exact(exact(ElementType::Lin2));
        raw.triangles.reserve_exact(exact(ElementType::Tri3));
        raw.tetrahedra.reserve_exact(exact(ElementType::Tet4));
        let node_of =
            |elem: u64, tag: u64| index.get(&tag).copied().ok_or_else(|| missing(elem, tag));
        for b in &self.blocks {
            let s = Scanner {
                bytes,
                pos: b.data,
                fmt,
            };
            match b.kind {
                ElementType::Lin2 => block(s, b, &node_of, &mut raw.lines)?,
                ElementType::Tri3 => block(s, b, &node_of, &mut raw.triangles)?,
                ElementType::Tet4 => block(s, b, &node_of, &mut raw.tetrahedra)?,
                _ => {}
            }
        }
        Ok(())
    }
}

/// A block's head at `s`: entity dimension and tag, element type, element count.
fn block_head(s: &mut Scanner, within: &dyn Fn(&str) -> String) -> Result<Block, Unread> {
    let stop = |at, what: &str| Unread::stop(at, &within(what));
    let int = |s: &mut Scanner, what: &str| {
        let at = s.next_at();
        s.int()
            .and_then(|v| i32::try_from(v).ok())
            .ok_or_else(|| stop(at, what))
    };
    let entity = (int(s, "entity dimension")?, int(s, "entity tag")?);
    let at = s.next_at();
    let code = int(s, "element type")?;
    let kind = ElementType::from_i32(code)
        .ok_or_else(|| stop(at, &format!("element type > unknown element type {code}")))?;
    let at = s.next_at();
    let count = s
        .size_t()
        .ok_or_else(|| stop(at, "number of elements in element block"))?;
    Ok(Block {
        entity,
        kind,
        count,
        data: s.pos,
    })
}

/// Past `count` elements of `nodes` nodes each at `s`: every number there, or the offset
/// and the number (from 1) of the first element that is not whole.
fn skip_elements(s: &mut Scanner, count: u64, nodes: usize) -> Result<(), (usize, u64)> {
    let per = 1 + nodes as u64;
    if s.fmt.binary {
        let len = count
            .checked_mul(per)
            .and_then(|v| v.checked_mul(s.fmt.size_t as u64));
        let end = len
            .and_then(|l| usize::try_from(l).ok())
            .and_then(|l| s.pos.checked_add(l));
        if let Some(end) = end.filter(|&e| e <= s.bytes.len()) {
            s.pos = end;
            return Ok(());
        }
        let whole = (s.bytes.len() - s.pos) as u64 / (per * s.fmt.size_t as u64);
        return Err((s.pos + (whole * per) as usize * s.fmt.size_t, whole + 1));
    }
    for j in 1..=count {
        let at = s.next_at();
        for _ in 0..per {
            s.size_t().ok_or((at, j))?;
        }
    }
    Ok(())
}

/// The elements of block `b` at `s` onto `list`, their N nodes as positions by `node_of`.
fn block<const N: usize, E>(
    mut s: Scanner,
    b: &Block,
    node_of: &impl Fn(u64, u64) -> Result<u32, E>,
    list: &mut Vec<RawElement<N>>,
) -> Result<(), E> {
    for _ in 0..b.count {
        // `Section::find` read every number of the block, so none is missing here.
        let tag = s.size_t().unwrap_or(0);
        let mut at = [0; N];
        for slot in &mut at {
            *slot = node_of(tag, s.size_t().unwrap_or(0))?;
        }
        let entity = b.entity;
        list.push(RawElement { tag, at, entity });
    }
    Ok(())
}

/// Just past the `$EndElements` marker that follows blanks at `pos`, if it does.
fn end_marker(bytes: &[u8], pos: usize) -> Option<usize> {
    let blanks = bytes
        .get(pos..)?
        .iter()
        .take_while(|b| b" \t\r\n".contains(b))
        .count();
    let at = pos + blanks;
    bytes[at..]
        .starts_with(b"$EndElements")
        .then_some(at + b"$EndElements".len())
}
