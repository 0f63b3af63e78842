//! Reading a gmsh MSH 4.1 file (ASCII or binary) into plain arrays, through `mshio`.
//!
//! What `mshio` 0.4 does and does not do, and what this module adds:
//!
//! - It parses `$MeshFormat`, `$Entities`, `$Nodes` and `$Elements` and silently skips every
//!   other `$Section ... $EndSection` (`$PhysicalNames` included; see `physical_names`).
//! - It accepts only version 4.1 but says just "unsupported format version"; the header is
//!   checked here first so that an MSH 2.2 file gets a message saying how to convert it.
//! - It can panic instead of returning an error on some malformed headers (an unsupported
//!   binary `size_t` width hits `unimplemented!`; a `$Nodes`/`$Elements` header announcing 0
//!   entries with a nonzero minimum tag underflows `num - 1`). Those headers are validated here
//!   before `mshio` sees the file.
//! - It keeps node tags only when they are sparse (`max - min + 1 > count`); for dense tags it
//!   drops them, which is correct only if they appear in increasing order. The node tags are
//!   therefore read here by a small scan of the `$Nodes` section, so nodes are always mapped
//!   by their real tags.
//! - Its `Display` for parse errors appends a hex dump of the whole rest of the file; the
//!   message is built here from the error backtrace instead, with the byte offset / line.
//! - It does not check that elements refer to existing nodes; this module does.
//! - It holds every element as a `Vec` of its node tags, all of them at once: mshio is
//!   handed the file without its `$Elements` section, which `elements.rs` reads (its
//!   module says what that saved). What a read fills, and the scanner of a section's
//!   numbers that both use, are `raw.rs`'s.

use std::collections::HashMap;
use std::path::Path;

use mshio::{ElementType, MshParserError};

use super::elements::{Section, Unread};
use super::raw::{find_section, too_many_nodes, Format, RawMesh, Scanner};
use crate::Error;

/// Checks the `$MeshFormat` header: an MSH file, version 4.1, ASCII or binary with a
/// supported `size_t` width.
pub(crate) fn check_format(path: &Path, bytes: &[u8]) -> crate::Result<Format> {
    let file = path.display();
    let not_msh = || {
        Error::input(format!(
            "mesh file '{file}' is not a gmsh MSH file (it does not start with a $MeshFormat \
             section); export the mesh from gmsh in MSH 4.1 format (`gmsh -2 GEO -format msh41`)"
        ))
    };
    if !bytes.starts_with(b"$MeshFormat") {
        return Err(not_msh());
    }
    let start = find_section(bytes, b"$MeshFormat").ok_or_else(not_msh)?;
    let line_end = bytes[start..]
        .iter()
        .position(|&b| b == b'\n')
        .map_or(bytes.len(), |p| start + p);
    let line = String::from_utf8_lossy(&bytes[start..line_end]);
    let fields: Vec<&str> = line.split_whitespace().collect();
    if fields.len() < 3 {
        return Err(Error::input(format!(
            "mesh file '{file}' has a malformed $MeshFormat line '{}' (expected 'version \
             file-type data-size'); the file looks truncated or corrupt",
            line.trim()
        )));
    }
    if fields[0] != "4.1" {
        let stem = path
            .file_stem()
            .map_or("mesh".into(), |s| s.to_string_lossy().into_owned());
        let new = path.with_file_name(format!("{stem}_msh41.msh"));
        let (from, to) = (shell_quote(path), shell_quote(&new));
        return Err(Error::input(format!(
            "mesh file '{file}' is in MSH format version {}; viscontact reads MSH 4.1 (ASCII or \
             binary): convert it with `gmsh {from} -save -format msh41 -o {to}`",
            fields[0]
        )));
    }
    let binary = match fields[1] {
        "0" => false,
        "1" => true,
        other => {
            return Err(Error::input(format!(
                "mesh file '{file}': unknown file-type '{other}' in $MeshFormat (0 = ASCII, \
                 1 = binary); the file looks corrupt"
            )))
        }
    };
    let size_t: usize = match fields[2].parse() {
        Ok(s @ (4 | 8)) => s,
        _ => {
            return Err(Error::input(format!(
                "mesh file '{file}': unsupported data-size '{}' in $MeshFormat (gmsh writes 8); \
                 the file looks corrupt",
                fields[2]
            )))
        }
    };
    let mut big_endian = false;
    if binary {
        // The line after the header line holds the integer 1 in binary, to detect endianness.
        let one = bytes.get(line_end + 1..line_end + 5);
        match one {
            Some([1, 0, 0, 0]) => big_endian = false,
            Some([0, 0, 0, 1]) => big_endian = true,
            _ => {
                return Err(Error::input(format!(
                    "mesh file '{file}': binary $MeshFormat without a valid endianness marker; \
                     the file looks truncated or corrupt"
                )))
            }
        }
    }
    Ok(Format {
        binary,
        size_t,
        big_endian,
    })
}

/// A path as a shell word (single-quoted if it has characters a shell would interpret).
fn shell_quote(p: &Path) -> String {
    let s = p.display().to_string();
    let plain = |c: char| c.is_ascii_alphanumeric() || "_-./+,:@%".contains(c);
    if !s.is_empty() && s.chars().all(plain) {
        s
    } else {
        format!("'{}'", s.replace('\'', r"'\''"))
    }
}

/// The four numbers heading each `$Nodes` or `$Elements` section:
/// `numEntityBlocks numItems minTag maxTag` (unreadable headers are left out).
fn section_headers(bytes: &[u8], fmt: Format, name: &[u8]) -> Vec<[u64; 4]> {
    let mut out = Vec::new();
    let mut from = 0;
    while let Some(pos) = find_section(&bytes[from..], name).map(|p| from + p) {
        let mut s = Scanner { bytes, pos, fmt };
        if let (Some(a), Some(b), Some(c), Some(d)) =
            (s.size_t(), s.size_t(), s.size_t(), s.size_t())
        {
            out.push([a, b, c, d]);
        }
        from = pos;
    }
    out
}

/// Node tags of each node block of `$Nodes`, in file order. `None` if the section cannot be
/// scanned (mshio parsed it, so this does not happen for a consistent file).
pub(super) fn scan_node_tags(bytes: &[u8], fmt: Format) -> Option<Vec<Vec<u64>>> {
    Some(
        scan_node_blocks(bytes, fmt)?
            .into_iter()
            .map(|(t, _)| t)
            .collect(),
    )
}

/// Each node block of `$Nodes`: its node tags and whether it stores parametric coordinates.
fn scan_node_blocks(bytes: &[u8], fmt: Format) -> Option<Vec<(Vec<u64>, bool)>> {
    let pos = find_section(bytes, b"$Nodes")?;
    let mut s = Scanner { bytes, pos, fmt };
    let blocks = s.size_t()?;
    let _count = s.size_t()?;
    let _min = s.size_t()?;
    let _max = s.size_t()?;
    let mut out = Vec::new();
    for _ in 0..blocks {
        let entity_dim = s.int()?;
        let _entity_tag = s.int()?;
        let parametric = s.int()?;
        let n = s.size_t()?;
        let mut tags = Vec::with_capacity(usize::try_from(n).ok()?.min(bytes.len()));
        for _ in 0..n {
            tags.push(s.size_t()?);
        }
        let per_node = 3 + if parametric != 0 {
            entity_dim.max(0) as u64
        } else {
            0
        };
        s.skip_doubles(n.checked_mul(per_node)?)?;
        out.push((tags, parametric != 0));
    }
    Some(out)
}

/// Turns an mshio parse error into an input error naming the file, the place and the problem.
/// `given`: the bytes mshio read, the file's without the `$Elements` section `cut` (if any).
fn parse_error(
    path: &Path,
    (bytes, given, cut): (&[u8], &[u8], Option<&Section>),
    fmt: Format,
    e: &MshParserError<&[u8]>,
) -> Error {
    let trace = e.filtered_backtrace();
    let at = trace.first().and_then(|(rest, _)| {
        let offset = (rest.as_ptr() as usize).wrapping_sub(given.as_ptr() as usize);
        (offset <= given.len()).then(|| cut.map_or(offset, |c| c.in_file(offset)))
    });
    // The backtrace runs from the innermost error outwards; print it outermost first.
    let chain: Vec<String> = trace
        .iter()
        .rev()
        .map(|(_, k)| {
            k.context()
                .map_or_else(|| k.to_string(), str::to_string)
                .trim_end_matches('.')
                .to_string()
        })
        .collect();
    let what = if chain.is_empty() {
        "unknown error".to_string()
    } else {
        chain.join(" > ")
    };
    stopped(path, bytes, fmt, at, &what)
}

/// The input error of a file that cannot be parsed: where (the byte offset `at` in the
/// file, shown as a line in an ASCII file) and what was being read.
fn stopped(path: &Path, bytes: &[u8], fmt: Format, at: Option<usize>, what: &str) -> Error {
    let place = match at {
        Some(offset) if fmt.binary => format!(" at byte {offset}"),
        Some(offset) => {
            let line = bytes[..offset].iter().filter(|&&b| b == b'\n').count() + 1;
            format!(" at line {line}")
        }
        None => String::new(),
    };
    let ending = if ends_with_end_tag(bytes) {
        "looks corrupt"
    } else {
        "looks truncated (its last line is not an $End... line)"
    };
    Error::input(format!(
        "mesh file '{}' cannot be read: it {ending}; the MSH parser stopped{place}: {what}; \
         regenerate the file with gmsh",
        path.display()
    ))
}

fn ends_with_end_tag(bytes: &[u8]) -> bool {
    let trimmed = bytes.trim_ascii_end();
    let last_line = trimmed
        .iter()
        .rposition(|&b| b == b'\n')
        .map_or(trimmed, |p| &trimmed[p + 1..]);
    last_line.starts_with(b"$End")
}

/// A short description of a gmsh element type and a hint how to avoid it.
fn describe_element_type(t: ElementType) -> (String, &'static str) {
    let code = t as i32;
    let nodes = t.nodes().unwrap_or(0);
    let (family, kind) = match code {
        1 | 8 | 26 | 27 | 28 | 62..=70 => ("lines", 1),
        2 | 9 | 20..=25 | 42..=46 | 52..=57 => ("triangles", 2),
        3 | 10 | 16 | 36..=41 | 47..=51 | 58..=61 => ("quadrangles", 2),
        4 | 11 | 29..=31 | 71..=79 => ("tetrahedra", 3),
        5 | 12 | 17 | 92 | 93 => ("hexahedra", 3),
        6 | 13 | 18 => ("prisms", 3),
        7 | 14 | 19 => ("pyramids", 3),
        _ => ("elements", 0),
    };
    let order = match code {
        8 | 9 | 10 | 11 | 12 | 13 | 14 | 16 | 17 | 18 | 19 => " (quadratic)",
        1..=7 | 15 => "",
        _ => " (high-order)",
    };
    let text = format!("{nodes}-node{order} {family} (gmsh element type {code})");
    let hint = match (kind, order.is_empty()) {
        (3, false) => {
            "viscontact uses P1 tetrahedra in 3D: remesh with `gmsh -3 -order 1` (or \
             Mesh.ElementOrder = 1)"
        }
        (3, true) => {
            "viscontact reads 3D meshes of 4-node tetrahedra only: remesh the volume without \
             recombination or extrusion into prisms (Mesh.RecombineAll = 0, no Recombine in \
             Extrude)"
        }
        (_, false) => {
            "viscontact uses P1 triangles: remesh with `gmsh -2 -order 1` (or Mesh.ElementOrder = 1)"
        }
        _ if family == "quadrangles" => {
            "viscontact uses 3-node triangles: remesh without recombination (remove `Recombine \
             Surface` / set Mesh.RecombineAll = 0)"
        }
        _ => {
            "viscontact reads 4-node tetrahedra, 3-node triangles, 2-node lines and points only"
        }
    };
    (text, hint)
}

/// Reads the file content `bytes` of `path` into a [`RawMesh`]: mshio parses the file
/// without its `$Elements` section, which `elements.rs` reads (its module says why).
pub(crate) fn read_raw(path: &Path, bytes: &[u8]) -> crate::Result<RawMesh> {
    let fmt = check_format(path, bytes)?;
    check_section_headers(path, bytes, fmt)?;
    check_options_mshio_reads(path, bytes, fmt)?;
    let section = Section::find(bytes, fmt).map_err(|e| unread(path, bytes, fmt, e))?;
    let rest = section.as_ref().map(|s| s.without(bytes));
    let given = rest.as_deref().unwrap_or(bytes);
    let msh = mshio::parse_msh_bytes(given)
        .map_err(|e| parse_error(path, (bytes, given, section.as_ref()), fmt, &e))?;
    drop(rest);
    let data = msh.data;
    if data.elements.is_some() {
        return Err(corrupt(
            path,
            "it has more than one $Elements section".into(),
        ));
    }

    let mut raw = RawMesh::default();
    if let Some(ent) = &data.entities {
        add_entities(&mut raw, ent);
    }
    let nodes = data.nodes.ok_or_else(|| {
        Error::input(format!(
            "mesh file '{}' has no $Nodes section; it looks truncated, regenerate it with gmsh",
            path.display()
        ))
    })?;
    let index = add_nodes(path, bytes, fmt, &nodes, &mut raw)?;
    drop(nodes);
    let section = section.ok_or_else(|| {
        Error::input(format!(
            "mesh file '{}' has no $Elements section; it looks truncated, regenerate it with \
             gmsh",
            path.display()
        ))
    })?;
    check_element_types(path, section.blocks.iter().map(|b| b.kind))?;
    let missing = |elem, tag| {
        corrupt(
            path,
            format!("element {elem} refers to node {tag}, which is not in the $Nodes section"),
        )
    };
    section.read(bytes, fmt, &index, missing, &mut raw)?;
    if data.entities.is_some() {
        check_element_entities(path, &section, &raw)?;
    }
    Ok(raw)
}

/// The input error of an `$Elements` section that cannot be walked.
fn unread(path: &Path, bytes: &[u8], fmt: Format, e: Unread) -> Error {
    match e {
        Unread::Stop { at, what } => stopped(path, bytes, fmt, Some(at), &what),
        Unread::Unskippable(kind) => match check_element_types(path, [kind].into_iter()) {
            Err(e) => e,
            Ok(()) => stopped(path, bytes, fmt, None, "element section"),
        },
    }
}

/// The error for a file whose sections contradict each other.
fn corrupt(path: &Path, what: String) -> Error {
    Error::input(format!(
        "mesh file '{}' is inconsistent: {what}; the file looks corrupt, regenerate it with gmsh",
        path.display()
    ))
}

/// Refuses `$Nodes` and `$Elements` headers that would make mshio panic (or mean an empty
/// mesh).
fn check_section_headers(path: &Path, bytes: &[u8], fmt: Format) -> crate::Result<()> {
    for (name, what) in [(&b"$Nodes"[..], "nodes"), (&b"$Elements"[..], "elements")] {
        for [_, count, min, max] in section_headers(bytes, fmt, name) {
            if count == 0 || min == 0 || max < min {
                let problem = if count == 0 {
                    format!(
                        "has no {what} (its {} section is empty)",
                        name.escape_ascii()
                    )
                } else {
                    format!(
                        "has an invalid {} header (tags {min}..{max}); it looks corrupt",
                        name.escape_ascii()
                    )
                };
                return Err(Error::input(format!(
                    "mesh file '{}' {problem}; mesh the geometry with `gmsh -2` and save it \
                     with its physical groups",
                    path.display()
                )));
            }
        }
    }
    Ok(())
}

/// Refuses two legal gmsh options that mshio cannot read, saying which option to change.
fn check_options_mshio_reads(path: &Path, bytes: &[u8], fmt: Format) -> crate::Result<()> {
    let file = path.display();
    if find_section(bytes, b"$PartitionedEntities").is_some() {
        return Err(Error::input(format!(
            "mesh file '{file}' was saved partitioned (`gmsh -part N`, or Mesh.NbPartitions > \
             0); viscontact reads a whole mesh: save it again without partitioning (drop \
             `-part`, or `-setnumber Mesh.NbPartitions 0`)"
        )));
    }
    if scan_node_blocks(bytes, fmt).is_some_and(|b| b.iter().any(|(_, param)| *param)) {
        return Err(Error::input(format!(
            "mesh file '{file}' stores parametric node coordinates (saved with \
             Mesh.SaveParametric = 1), which the MSH reader (mshio) does not support: save it \
             again with `-setnumber Mesh.SaveParametric 0` (the default)"
        )));
    }
    Ok(())
}

/// Records the physical tags of every entity, and each `(dim, physical tag)` in file order.
fn add_entities(raw: &mut RawMesh, ent: &mshio::Entities<i32, f64>) {
    let mut seen = std::collections::HashSet::new();
    let mut add = |dim: i32, tag: i32, phys: &[i32]| {
        raw.physical.insert((dim, tag), phys.to_vec());
        for &p in phys {
            // gmsh may write negative physical tags for entities of reversed orientation
            let p = p.wrapping_abs();
            if dim > 0 && seen.insert((dim, p)) {
                raw.physical_order.push((dim, p));
            }
        }
    };
    for p in &ent.points {
        add(0, p.tag, &p.physical_tags);
    }
    for c in &ent.curves {
        add(1, c.tag, &c.physical_tags);
    }
    for s in &ent.surfaces {
        add(2, s.tag, &s.physical_tags);
    }
    for v in &ent.volumes {
        add(3, v.tag, &v.physical_tags);
    }
}

/// Appends the nodes to `raw`, mapped by their real tags (scanned here, see the module
/// docs): the index of each tag in `raw.nodes`.
fn add_nodes(
    path: &Path,
    bytes: &[u8],
    fmt: Format,
    nodes: &mshio::Nodes<u64, i32, f64>,
    raw: &mut RawMesh,
) -> crate::Result<HashMap<u64, u32>> {
    let tags = scan_node_tags(bytes, fmt).ok_or_else(|| {
        corrupt(
            path,
            "the $Nodes section cannot be scanned for node tags".into(),
        )
    })?;
    if tags.len() != nodes.node_blocks.len() {
        return Err(corrupt(
            path,
            format!(
                "$Nodes has {} blocks but {} were scanned",
                nodes.node_blocks.len(),
                tags.len()
            ),
        ));
    }
    let mut index: HashMap<u64, u32> = HashMap::new();
    for (block, tags) in nodes.node_blocks.iter().zip(&tags) {
        if block.nodes.len() != tags.len() {
            return Err(corrupt(
                path,
                "a $Nodes block has a wrong number of node tags".into(),
            ));
        }
        for (node, &tag) in block.nodes.iter().zip(tags) {
            let at = u32::try_from(raw.nodes.len()).map_err(|_| too_many_nodes(&path.display()))?;
            if index.insert(tag, at).is_some() {
                return Err(corrupt(
                    path,
                    format!("node tag {tag} appears twice in $Nodes"),
                ));
            }
            raw.nodes.push([node.x, node.y, node.z]);
        }
    }
    Ok(index)
}

/// Refuses every element type but P1 tetrahedra and triangles, 2-node lines and points,
/// naming the types found and how to remesh.
fn check_element_types(path: &Path, kinds: impl Iterator<Item = ElementType>) -> crate::Result<()> {
    let mut unsupported: Vec<ElementType> = Vec::new();
    for t in kinds {
        if !matches!(
            t,
            ElementType::Pnt | ElementType::Lin2 | ElementType::Tri3 | ElementType::Tet4
        ) && !unsupported.contains(&t)
        {
            unsupported.push(t);
        }
    }
    if unsupported.is_empty() {
        return Ok(());
    }
    // Report the highest-dimensional elements first: they are the cells and decide the
    // remedy (in a 3D file the triangles are only boundary faces).
    let rank = |t: ElementType| {
        let text = describe_element_type(t).0;
        let has = |fams: &[&str]| fams.iter().any(|f| text.contains(f));
        if has(&["tetrahedra", "hexahedra", "prisms", "pyramids"]) {
            0
        } else if has(&["triangles", "quadrangles"]) {
            1
        } else {
            2
        }
    };
    unsupported.sort_by_key(|&t| rank(t));
    let top = rank(unsupported[0]);
    let texts: Vec<String> = unsupported
        .iter()
        .map(|&t| describe_element_type(t).0)
        .collect();
    let mut hints: Vec<&str> = Vec::new();
    for &t in unsupported.iter().filter(|&&t| rank(t) == top) {
        let h = describe_element_type(t).1;
        if !hints.contains(&h) {
            hints.push(h);
        }
    }
    Err(Error::input(format!(
        "mesh file '{}' contains {}; {}",
        path.display(),
        texts.join(" and "),
        hints.join("; ")
    )))
}

/// Refuses an element block (other than points) whose entity `$Entities` does not list.
fn check_element_entities(path: &Path, section: &Section, raw: &RawMesh) -> crate::Result<()> {
    for b in &section.blocks {
        let key = b.entity;
        if b.kind != ElementType::Pnt && !raw.physical.contains_key(&key) {
            return Err(corrupt(
                path,
                format!(
                    "an element block belongs to entity (dim {}, tag {}), which is not in \
                     $Entities",
                    key.0, key.1
                ),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_sections_only_at_line_starts() {
        let b = b"$MeshFormat\n4.1 0 8\n$EndMeshFormat\nx$Nodes\n$Nodes\r\n1 2";
        assert_eq!(find_section(b, b"$MeshFormat"), Some(12));
        let p = find_section(b, b"$Nodes").unwrap();
        assert_eq!(&b[p..], b"1 2");
        assert_eq!(find_section(b, b"$Elements"), None);
    }

    #[test]
    fn dense_but_unordered_node_tags_are_mapped_by_tag() {
        // Tags 1..3 are dense but written as 2, 3, 1: mshio drops them, the scan keeps them.
        let src = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 3 1 3\n2 1 0 3\n2\n3\n1\n\
                   1 0 0\n0 1 0\n0 0 0\n$EndNodes\n$Elements\n1 1 1 1\n2 1 2 1\n1 1 2 3\n\
                   $EndElements\n";
        let raw = read_raw(Path::new("t.msh"), src.as_bytes()).unwrap();
        let t = raw.triangles[0].nodes();
        assert_eq!(raw.nodes[t[0]], [0.0, 0.0, 0.0]);
        assert_eq!(raw.nodes[t[1]], [1.0, 0.0, 0.0]);
        assert_eq!(raw.nodes[t[2]], [0.0, 1.0, 0.0]);
    }

    #[test]
    fn empty_node_section_is_an_error_not_a_panic() {
        let src = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n0 0 1 1\n$EndNodes\n";
        let e = read_raw(Path::new("t.msh"), src.as_bytes()).unwrap_err();
        assert!(e.to_string().contains("has no nodes"), "{e}");
    }
}

#[cfg(test)]
mod elements_tests {
    use std::path::{Path, PathBuf};

    use super::super::raw::{RawElement, RawMesh};
    use super::{check_format, find_section, read_raw, scan_node_tags};
    use mshio::ElementType;

    /// Every mesh file of the repository under `dir`.
    fn meshes(dir: &Path, out: &mut Vec<PathBuf>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                meshes(&path, out);
            } else if path.extension().is_some_and(|e| e == "msh") {
                out.push(path);
            }
        }
    }

    /// (element tag, node tags, entity) of each element, from the reader's lists.
    fn ours<const N: usize>(
        list: &[RawElement<N>],
        tags: &[u64],
    ) -> Vec<(u64, Vec<u64>, (i32, i32))> {
        let node_tags = |e: &RawElement<N>| e.nodes().iter().map(|&i| tags[i]).collect();
        list.iter()
            .map(|e| (e.tag, node_tags(e), e.entity))
            .collect()
    }

    /// The same of mshio's whole parse, for one element type.
    fn mshio_s(
        elements: &mshio::Elements<u64, i32>,
        kind: ElementType,
    ) -> Vec<(u64, Vec<u64>, (i32, i32))> {
        let blocks = elements
            .element_blocks
            .iter()
            .filter(|b| b.element_type == kind);
        let each = |b: &mshio::ElementBlock<u64, i32>| {
            let entity = (b.entity_dim, b.entity_tag);
            b.elements
                .iter()
                .map(move |e| (e.element_tag, e.nodes.clone(), entity))
                .collect::<Vec<_>>()
        };
        blocks.flat_map(each).collect()
    }

    #[test]
    fn the_elements_of_every_mesh_of_the_repository_are_mshio_s() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let mut files = Vec::new();
        meshes(&root.join("meshes"), &mut files);
        meshes(&root.join("tests/data"), &mut files);
        let mut compared = 0;
        for path in files {
            let bytes = std::fs::read(&path).unwrap();
            let (Ok(raw), Ok(whole)) = (read_raw(&path, &bytes), mshio::parse_msh_bytes(&bytes))
            else {
                continue;
            };
            let fmt = check_format(&path, &bytes).unwrap();
            let tags: Vec<u64> = scan_node_tags(&bytes, fmt).unwrap().concat();
            let elements = whole.data.elements.unwrap();
            let file = path.display();
            assert_eq!(
                ours(&raw.lines, &tags),
                mshio_s(&elements, ElementType::Lin2),
                "{file}"
            );
            assert_eq!(
                ours(&raw.triangles, &tags),
                mshio_s(&elements, ElementType::Tri3),
                "{file}"
            );
            assert_eq!(
                ours(&raw.tetrahedra, &tags),
                mshio_s(&elements, ElementType::Tet4),
                "{file}"
            );
            compared += 1;
        }
        assert!(compared >= 40, "{compared} files compared");
    }

    const HEAD: &str = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n";
    const NODES: &str =
        "$Nodes\n1 4 1 4\n2 1 0 4\n1\n2\n3\n4\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n$EndNodes\n";

    fn read(elements: &str) -> crate::Result<RawMesh> {
        let text = format!("{HEAD}{NODES}{elements}");
        read_raw(Path::new("t.msh"), text.as_bytes())
    }

    #[test]
    fn points_are_skipped_and_lines_and_triangles_read_in_their_blocks() {
        let raw = read(
            "$Elements\n3 4 1 4\n0 1 15 1\n1 1\n1 1 1 1\n2 1 2\n2 1 2 2\n3 1 2 3\n4 2 4 3\n\
             $EndElements\n",
        )
        .unwrap();
        assert_eq!(raw.lines.len(), 1);
        assert_eq!(raw.lines[0].nodes(), [0, 1]);
        assert_eq!(
            raw.triangles.iter().map(|t| t.tag).collect::<Vec<_>>(),
            [3, 4]
        );
        assert_eq!(raw.triangles[1].nodes(), [1, 3, 2]);
        assert_eq!(raw.triangles[1].entity, (2, 1));
        assert_eq!(raw.triangles.capacity(), 2);
    }

    #[test]
    fn a_cut_or_unclosed_section_says_where_it_stopped() {
        let cut = "truncated";
        let cases = [
            (
                "$Elements\n1 2 1 2\n2 1 2 2\n1 1 2 3\n2 2 3\n",
                [cut, "line 20", "element definition (2 of 2)"],
            ),
            (
                "$Elements\n1 1 1 1\n2 1 2 1\n1 1 2 3\n",
                [cut, "line 20", "> $EndElements"],
            ),
            (
                "$Elements\n1 1 1 1\n2 1 2\n",
                [cut, "line 19", "number of elements in element block"],
            ),
            (
                "$Elements\n1 1 1 1\n2 1 999 1\n1 1\n$EndElements\n",
                [
                    "corrupt",
                    "line 18",
                    "element type > unknown element type 999",
                ],
            ),
        ];
        for (elements, needles) in cases {
            let e = read(elements).unwrap_err().to_string();
            for needle in needles.iter().chain(&["cannot be read", "regenerate"]) {
                assert!(e.contains(needle), "{needle}: {e}");
            }
        }
    }

    #[test]
    fn an_unskippable_or_unread_type_is_refused_by_name() {
        // Quadrangles are skipped by their node count, and named with their remedy.
        let e = read("$Elements\n2 2 1 2\n2 1 3 1\n1 1 2 4 3\n2 1 2 1\n2 1 2 3\n$EndElements\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("4-node quadrangles") && e.contains("recombination"),
            "{e}"
        );
    }

    #[test]
    fn a_second_section_and_a_parse_error_after_the_section_are_placed_in_the_file() {
        let one = "$Elements\n1 1 1 1\n2 1 2 1\n1 1 2 3\n$EndElements\n";
        let e = read(&format!("{one}{one}")).unwrap_err().to_string();
        assert!(e.contains("more than one $Elements"), "{e}");
        // Line 21 of the file, after the five lines that mshio does not see.
        let e = read(&format!("{one}garbage\n")).unwrap_err().to_string();
        assert!(e.contains("line 21"), "{e}");
    }

    #[test]
    fn a_binary_section_cut_in_an_element_names_it() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("meshes/paper/rect_016_binary.msh");
        let bytes = std::fs::read(&path).unwrap();
        let end = find_section(&bytes, b"$EndElements").unwrap();
        let e = read_raw(&path, &bytes[..end - 30]).unwrap_err().to_string();
        for needle in [
            "cannot be read",
            "truncated",
            "at byte",
            "element definition",
        ] {
            assert!(e.contains(needle), "{needle}: {e}");
        }
    }

    /// The mesh of [`read`]'s points with two triangles and a line, in binary with
    /// `size_t` of `width` bytes in either byte order.
    fn binary(width: usize, big: bool) -> Vec<u8> {
        let bytes = |v: u64, n: usize| {
            let le = v.to_le_bytes()[..n].to_vec();
            if big {
                le.into_iter().rev().collect()
            } else {
                le
            }
        };
        let size_t = |v: u64| bytes(v, width);
        let int = |v: i32| bytes(u64::from(v as u32), 4);
        let real = |v: f64| bytes(v.to_bits(), 8);
        let mut b = format!("$MeshFormat\n4.1 1 {width}\n").into_bytes();
        b.extend(int(1));
        b.extend(b"\n$EndMeshFormat\n$Nodes\n");
        [1, 4, 1, 4].into_iter().for_each(|v| b.extend(size_t(v)));
        [2, 1, 0].into_iter().for_each(|v| b.extend(int(v)));
        b.extend(size_t(4));
        (1..=4).for_each(|t| b.extend(size_t(t)));
        for p in [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]] {
            [p[0], p[1], 0.0]
                .into_iter()
                .for_each(|x| b.extend(real(x)));
        }
        b.extend(b"\n$EndNodes\n$Elements\n");
        [2, 3, 1, 3].into_iter().for_each(|v| b.extend(size_t(v)));
        let blocks: [(i32, i32, &[&[u64]]); 2] = [
            (1, 1, &[&[1, 1, 2]]),
            (2, 2, &[&[2, 1, 2, 3], &[3, 2, 4, 3]]),
        ];
        for (dim, kind, elements) in blocks {
            [dim, 1, kind].into_iter().for_each(|v| b.extend(int(v)));
            b.extend(size_t(elements.len() as u64));
            elements
                .iter()
                .flat_map(|e| e.iter())
                .for_each(|&v| b.extend(size_t(v)));
        }
        b.extend(b"\n$EndElements\n");
        b
    }

    #[test]
    fn binary_files_of_either_byte_order_and_size_t_read_as_the_ascii_one() {
        let ascii =
            read("$Elements\n2 3 1 3\n1 1 1 1\n1 1 2\n2 1 2 2\n2 1 2 3\n3 2 4 3\n$EndElements\n")
                .unwrap();
        let tags = [1, 2, 3, 4];
        for (width, big) in [(8, false), (8, true), (4, false), (4, true)] {
            let raw = read_raw(Path::new("t.msh"), &binary(width, big)).unwrap();
            let case = format!("size_t {width}, big-endian {big}");
            assert_eq!(raw.nodes, ascii.nodes, "{case}");
            assert_eq!(ours(&raw.lines, &tags), ours(&ascii.lines, &tags), "{case}");
            assert_eq!(
                ours(&raw.triangles, &tags),
                ours(&ascii.triangles, &tags),
                "{case}"
            );
            assert_eq!(raw.triangles.len(), 2, "{case}");
        }
    }
}
