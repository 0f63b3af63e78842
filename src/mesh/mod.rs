//! Mesh import: gmsh MSH 4.1 files (ASCII or binary) with physical groups.
//!
//! [`Mesh::read`] reads the file through `mshio` (see `msh.rs` for what `mshio` does and
//! what is added here) and the `$PhysicalNames` section with a small reader of its own
//! (`physical_names.rs`: `mshio` skips that section). It accepts 3-node triangles (gmsh type
//! 2), 2-node lines (type 1) and points (type 15); anything else is refused with a message
//! naming the type and how to remesh. Then:
//!
//! - triangles given clockwise are reoriented (counted in [`Mesh::flipped`]); triangles of
//!   zero area, and meshes that fold over themselves or have an edge shared by three or more
//!   triangles, are refused;
//! - nodes not used by any triangle are dropped and the others renumbered `0..` in file order;
//! - every physical curve group becomes a list of boundary facets oriented with the body on
//!   their left (an edge that is not on the boundary of the triangle mesh is refused), every
//!   physical surface group a list of triangle indices. Physical point and volume groups are
//!   ignored.
//!
//! Groups are found by name, by an ASCII alias of the name, or by integer tag
//! ([`Mesh::group`]).
//!
//! The mesh is 2D ([`Mesh::dim`] = 2); the data layout (`dim`, 3 coordinates per node,
//! `dim`-tagged groups) leaves room for tetrahedral meshes later.

mod msh;
mod physical_names;
mod quality;

use std::collections::{BTreeMap, HashMap, HashSet};
use std::path::{Path, PathBuf};

pub use quality::Quality;

use crate::{Error, Result};
use msh::RawMesh;
use physical_names::PhysicalName;
use quality::signed_area;

/// A P1 triangle mesh with its physical groups.
#[derive(Debug, Clone, PartialEq)]
pub struct Mesh {
    /// The file the mesh was read from (as given to [`Mesh::read`]).
    pub path: PathBuf,
    /// Spatial dimension: 2 (triangles in the xy-plane).
    pub dim: usize,
    /// Node coordinates; only nodes used by the triangles, numbered `0..` in file order;
    /// z = 0 in 2D.
    pub nodes: Vec<[f64; 3]>,
    /// Triangles as 0-based node indices, counter-clockwise (positive signed area).
    pub triangles: Vec<[usize; 3]>,
    /// All physical curve and surface groups, in file order (the order of `$PhysicalNames`,
    /// then unnamed groups in the order of `$Entities`).
    pub groups: Vec<Group>,
    /// How many triangles were clockwise in the file and got reoriented.
    pub flipped: usize,
}

/// A physical group of the mesh.
#[derive(Debug, Clone, PartialEq)]
pub struct Group {
    /// 1 = boundary curve group, 2 = surface group.
    pub dim: usize,
    /// The physical tag in the file.
    pub tag: i32,
    /// The name from `$PhysicalNames` (UTF-8, e.g. `"Γ3,1"`), if the group has one.
    pub name: Option<String>,
    /// For `dim == 1`: boundary edges `[a, b]`, each once, oriented so that the body lies on
    /// the left of a → b (outward normal `(dy, -dx) / len`). Empty for surface groups.
    pub facets: Vec<[usize; 2]>,
    /// For `dim == 2`: indices into [`Mesh::triangles`]. Empty for curve groups.
    pub cells: Vec<usize>,
}

impl Mesh {
    /// Reads a gmsh MSH 4.1 file (ASCII or binary). Every problem with the file (missing,
    /// wrong version, unsupported elements, truncated, degenerate or folded elements, boundary
    /// groups off the boundary) is an [`Error::Input`] naming the file and the culprit.
    pub fn read(path: &Path) -> Result<Mesh> {
        let bytes = std::fs::read(path).map_err(|e| read_error(path, &e))?;
        let raw = msh::read_raw(path, &bytes)?;
        let names = physical_names::read_physical_names(&bytes)
            .map_err(|m| Error::input(format!("mesh file '{}': {m}", path.display())))?;
        build(path, raw, &names)
    }

    /// A group by name, ASCII alias or integer tag.
    ///
    /// A key matches a group whose name equals it; failing that, one whose name equals it
    /// after normalizing both sides (`Γ`/`γ` → `gamma`, `,` → `_`, whitespace removed, ASCII
    /// case ignored: `Gamma3_1`, `gamma3,1` and `Γ3_1` all find `"Γ3,1"`); failing that, a key
    /// that is an integer matches the group with that tag. When the key matches groups of
    /// different dimensions, the boundary (dim-1) group wins. The error names the mesh file
    /// and the key, and lists the groups the file has.
    pub fn group(&self, key: &str) -> Result<&Group> {
        self.find_group(key, false)
    }

    /// Like [`Mesh::group`], but the group must be a boundary (dim-1, curve) group.
    /// An empty group (named in `$PhysicalNames` but carried by no curve) is refused: a
    /// boundary condition on it would silently do nothing.
    pub fn boundary_group(&self, key: &str) -> Result<&Group> {
        let g = self.find_group(key, true)?;
        if g.facets.is_empty() {
            return Err(Error::input(format!(
                "mesh '{}': physical group '{}' (tag {}) has no boundary edges: no curve of the \
                 mesh carries it; add the curves to the group in gmsh",
                self.path.display(),
                Self::display_name(g),
                g.tag
            )));
        }
        Ok(g)
    }

    /// Outward unit normal of the boundary facet `f = [a, b]` (body on the left of a → b):
    /// `(dy, -dx) / len`.
    pub fn facet_normal(&self, f: [usize; 2]) -> [f64; 2] {
        let (a, b) = (self.nodes[f[0]], self.nodes[f[1]]);
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let len = dx.hypot(dy);
        [dy / len, -dx / len]
    }

    /// Length of the facet `f`.
    pub fn facet_length(&self, f: [usize; 2]) -> f64 {
        let (a, b) = (self.nodes[f[0]], self.nodes[f[1]]);
        (b[0] - a[0]).hypot(b[1] - a[1])
    }

    /// The nodes of a group's facets (curve group) or cells (surface group), sorted, unique.
    pub fn group_nodes(&self, g: &Group) -> Vec<usize> {
        let mut nodes: Vec<usize> = g
            .facets
            .iter()
            .flatten()
            .copied()
            .chain(g.cells.iter().flat_map(|&c| self.triangles[c]))
            .collect();
        nodes.sort_unstable();
        nodes.dedup();
        nodes
    }

    /// Outward unit normal at each node of a boundary group: the length-weighted average of
    /// the group's own facet normals at that node, normalized; sorted by node. Also returns
    /// the largest angle in degrees between two facet normals of the group meeting at a node
    /// (0 for a straight boundary), so that callers can warn about kinks. Where the facet
    /// normals cancel (a boundary folding back by 180°), the normal of the node's first facet
    /// is used. A surface group has no facets: empty list, angle 0.
    pub fn nodal_normals(&self, g: &Group) -> (Vec<(usize, [f64; 2])>, f64) {
        /// Per node: Σ len·n, Σ len, and the facet normals.
        #[derive(Default)]
        struct Acc {
            sum: [f64; 2],
            total_len: f64,
            ns: Vec<[f64; 2]>,
        }
        let mut at: BTreeMap<usize, Acc> = BTreeMap::new();
        for &f in &g.facets {
            let n = self.facet_normal(f);
            let len = self.facet_length(f);
            for node in f {
                let e = at.entry(node).or_default();
                e.sum[0] += len * n[0];
                e.sum[1] += len * n[1];
                e.total_len += len;
                e.ns.push(n);
            }
        }
        let mut max_angle: f64 = 0.0;
        let normals = at
            .into_iter()
            .map(|(node, Acc { sum, total_len, ns })| {
                for (i, a) in ns.iter().enumerate() {
                    for b in &ns[i + 1..] {
                        let cross = a[0] * b[1] - a[1] * b[0];
                        let dot = a[0] * b[0] + a[1] * b[1];
                        max_angle = max_angle.max(cross.abs().atan2(dot).to_degrees());
                    }
                }
                let norm = sum[0].hypot(sum[1]);
                let n = if norm > 1e-12 * total_len {
                    [sum[0] / norm, sum[1] / norm]
                } else {
                    ns[0]
                };
                (node, n)
            })
            .collect();
        (normals, max_angle)
    }

    /// Element quality: smallest angle, largest aspect ratio, smallest and largest area.
    pub fn quality(&self) -> Quality {
        quality::quality(&self.nodes, &self.triangles)
    }

    /// The group's name if it has one, else its tag as a string.
    pub fn display_name(g: &Group) -> String {
        g.name.clone().unwrap_or_else(|| g.tag.to_string())
    }

    fn find_group(&self, key: &str, boundary: bool) -> Result<&Group> {
        let file = self.path.display();
        let normalized = normalize_name(key);
        let tag: Option<i32> = key.trim().parse().ok();
        let stages: [&dyn Fn(&Group) -> bool; 3] = [
            &|g| g.name.as_deref() == Some(key),
            &|g| g.name.as_deref().map(normalize_name).as_deref() == Some(normalized.as_str()),
            &|g| Some(g.tag) == tag,
        ];
        for matches in stages {
            let found: Vec<&Group> = self.groups.iter().filter(|&g| matches(g)).collect();
            if found.is_empty() {
                continue;
            }
            let curves: Vec<&Group> = found.iter().copied().filter(|g| g.dim == 1).collect();
            let chosen = if !curves.is_empty() {
                curves
            } else if boundary {
                let boundary_groups: Vec<String> = self
                    .groups
                    .iter()
                    .filter(|g| g.dim == 1)
                    .map(describe)
                    .collect();
                return Err(Error::input(format!(
                    "mesh '{file}': '{key}' names the physical group {}, which is a surface \
                     group, but a boundary (curve) group is needed here; the boundary groups \
                     are: {}",
                    describe(found[0]),
                    or_none(&boundary_groups)
                )));
            } else {
                found
            };
            if chosen.len() > 1 {
                let list: Vec<String> = chosen.iter().map(|g| describe(g)).collect();
                return Err(Error::input(format!(
                    "mesh '{file}': '{key}' matches several physical groups: {}; use the exact \
                     name (or rename the groups in gmsh so that they differ)",
                    list.join(", ")
                )));
            }
            return Ok(chosen[0]);
        }
        let list: Vec<String> = self.groups.iter().map(describe).collect();
        let hint = if self.groups.is_empty() {
            "define physical groups in gmsh (e.g. Physical Curve(\"Γ1\") = {...};) and save the \
             mesh again"
        } else {
            "rename the group in gmsh or use one of these names (ASCII aliases match too: Γ → \
             Gamma, ',' → '_', case ignored; so does the tag)"
        };
        Err(Error::input(format!(
            "mesh '{file}' has no physical group '{key}'; it has: {} — {hint}",
            or_none(&list)
        )))
    }
}

/// The name normalization used by [`Mesh::group`].
fn normalize_name(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 4);
    for ch in s.chars() {
        match ch {
            'Γ' | 'γ' => out.push_str("gamma"),
            ',' => out.push('_'),
            c if c.is_whitespace() => {}
            c => out.push(c.to_ascii_lowercase()),
        }
    }
    out
}

/// `"Γ1" (tag 1, curve, 8 edges)` or `tag 7 (surface, 12 triangles, no name)`.
fn describe(g: &Group) -> String {
    let size = match g.dim {
        1 => format!("curve, {} edges", g.facets.len()),
        _ => format!("surface, {} triangles", g.cells.len()),
    };
    match &g.name {
        Some(n) => format!("\"{n}\" (tag {}, {size})", g.tag),
        None => format!("tag {} ({size}, no name)", g.tag),
    }
}

fn or_none(list: &[String]) -> String {
    if list.is_empty() {
        "none".into()
    } else {
        list.join(", ")
    }
}

fn read_error(path: &Path, e: &std::io::Error) -> Error {
    let mut msg = e.to_string();
    if let Some(p) = msg.find(" (os error") {
        msg.truncate(p);
    }
    Error::input(format!("cannot read mesh file '{}': {msg}", path.display()))
}

fn fmt_point(p: [f64; 3]) -> String {
    format!("({}, {})", p[0], p[1])
}

/// Geometry, topology and groups from the raw file content.
fn build(path: &Path, raw: RawMesh, names: &[PhysicalName]) -> Result<Mesh> {
    let file = path.display();
    if raw.triangles.is_empty() {
        return Err(Error::input(format!(
            "mesh file '{file}' contains no triangles (gmsh element type 2); viscontact needs a \
             2D triangle mesh: mesh the surface with `gmsh -2` and put it in a physical surface \
             group (gmsh saves only elements of physical groups)"
        )));
    }

    // Renumber the nodes used by triangles, in file order.
    const UNUSED: usize = usize::MAX;
    let mut new_index = vec![UNUSED; raw.nodes.len()];
    for t in &raw.triangles {
        for &n in &t.nodes {
            new_index[n] = 0;
        }
    }
    let mut nodes = Vec::new();
    for (old, slot) in new_index.iter_mut().enumerate() {
        if *slot != UNUSED {
            *slot = nodes.len();
            nodes.push(raw.nodes[old]);
        }
    }

    // Planarity and the coordinate scale for the zero-area test.
    let scale = nodes
        .iter()
        .map(|p| p[0].abs().max(p[1].abs()))
        .fold(0.0_f64, f64::max);
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in &nodes {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let diag = (hi[0] - lo[0]).hypot(hi[1] - lo[1]);
    if let Some(p) = nodes.iter().find(|p| p.iter().any(|c| !c.is_finite())) {
        return Err(Error::input(format!(
            "mesh file '{file}' has a node with a non-finite coordinate ({}, {}, {}); the file \
             looks corrupt, regenerate it with gmsh",
            p[0], p[1], p[2]
        )));
    }
    if let Some(p) = nodes.iter().find(|p| p[2].abs() > 1e-12 * diag.max(scale)) {
        return Err(Error::input(format!(
            "mesh file '{file}' is not a 2D mesh in the xy-plane: node ({}, {}, {}) has z ≠ 0; \
             viscontact reads 2D meshes (z = 0)",
            p[0], p[1], p[2]
        )));
    }
    for p in &mut nodes {
        p[2] = 0.0;
    }

    // Orientation and degeneracy. A triangle is degenerate if the altitude onto its longest
    // edge is at most 1e-12 of that edge (its smallest angle is below ~1e-10 rad) or at most
    // 1e-13 of the largest coordinate (the precision at which coordinates are stored).
    let mut triangles = Vec::with_capacity(raw.triangles.len());
    let mut flipped = 0;
    let mut degenerate = Vec::new();
    for t in &raw.triangles {
        let mut tri = t.nodes.map(|n| new_index[n]);
        let [a, b, c] = tri.map(|n| nodes[n]);
        let area2 = 2.0 * signed_area(a, b, c);
        let lmax = [(a, b), (b, c), (c, a)]
            .iter()
            .map(|(p, q)| (q[0] - p[0]).hypot(q[1] - p[1]))
            .fold(0.0_f64, f64::max);
        if area2.abs() <= lmax * (1e-12 * lmax + 1e-13 * scale) {
            degenerate.push(t);
        } else if area2 < 0.0 {
            tri.swap(1, 2);
            flipped += 1;
        }
        triangles.push(tri);
    }
    if let Some(t) = degenerate.first() {
        let pts: Vec<String> = t.nodes.iter().map(|&n| fmt_point(raw.nodes[n])).collect();
        let more = match degenerate.len() {
            1 => String::new(),
            n => format!(" ({} more triangles are degenerate)", n - 1),
        };
        return Err(Error::input(format!(
            "mesh file '{file}': triangle {} (gmsh element tag) has zero area: its nodes {} are \
             collinear or coincide{more}; fix the geometry or remesh",
            t.tag,
            pts.join(", ")
        )));
    }

    // Edges: each is used by one triangle (boundary) or by two in opposite directions.
    struct EdgeUse {
        dir: [usize; 2],
        tri: usize,
        count: u32,
    }
    let mut edges: HashMap<[usize; 2], EdgeUse> = HashMap::with_capacity(triangles.len() * 2);
    let tri_tag = |k: usize| raw.triangles[k].tag;
    for (k, tri) in triangles.iter().enumerate() {
        for i in 0..3 {
            let dir = [tri[i], tri[(i + 1) % 3]];
            let key = [dir[0].min(dir[1]), dir[0].max(dir[1])];
            let e = edges.entry(key).or_insert(EdgeUse {
                dir,
                tri: k,
                count: 0,
            });
            e.count += 1;
            let edge_at = || format!("{}–{}", fmt_point(nodes[key[0]]), fmt_point(nodes[key[1]]));
            if e.count == 2 && e.dir == dir {
                return Err(Error::input(format!(
                    "mesh file '{file}' folds over itself: triangles {} and {} (gmsh element \
                     tags) overlap at the edge {}; an inverted element in the middle of the mesh \
                     cannot be repaired by reorienting it: fix the geometry or remesh",
                    tri_tag(e.tri),
                    tri_tag(k),
                    edge_at()
                )));
            }
            if e.count == 3 {
                return Err(Error::input(format!(
                    "mesh file '{file}': the edge {} is shared by three or more triangles (e.g. \
                     {} and {}, gmsh element tags); the mesh is not a valid 2D domain \
                     (overlapping surfaces?): fix the geometry or remesh",
                    edge_at(),
                    tri_tag(e.tri),
                    tri_tag(k)
                )));
            }
        }
    }

    // Groups: named ones in $PhysicalNames order, then unnamed ones from $Entities.
    let mut groups: Vec<Group> = Vec::new();
    let mut slot: HashMap<(i32, i32), usize> = HashMap::new();
    let mut add_group = |dim: i32, tag: i32, name: Option<String>| {
        if (dim == 1 || dim == 2) && !slot.contains_key(&(dim, tag)) {
            slot.insert((dim, tag), groups.len());
            groups.push(Group {
                dim: dim as usize,
                tag,
                name,
                facets: Vec::new(),
                cells: Vec::new(),
            });
        }
    };
    for n in names {
        add_group(n.dim, n.tag, Some(n.name.clone()));
    }
    for &(dim, tag) in &raw.physical_order {
        add_group(dim, tag, None);
    }
    let groups_of = |entity: (i32, i32)| -> Vec<usize> {
        let mut out: Vec<usize> = raw
            .physical
            .get(&entity)
            .into_iter()
            .flatten()
            .filter_map(|p| slot.get(&(entity.0, p.wrapping_abs())).copied())
            .collect();
        out.sort_unstable();
        out.dedup();
        out
    };

    for (k, t) in raw.triangles.iter().enumerate() {
        if t.entity.0 == 2 {
            for g in groups_of(t.entity) {
                groups[g].cells.push(k);
            }
        }
    }
    let mut seen: Vec<HashSet<[usize; 2]>> = vec![HashSet::new(); groups.len()];
    for line in raw.lines.iter().filter(|l| l.entity.0 == 1) {
        let member = groups_of(line.entity);
        if member.is_empty() {
            continue;
        }
        let [a, b] = line.nodes.map(|n| new_index[n]);
        let facet = if a == UNUSED || b == UNUSED {
            None
        } else {
            edges.get(&[a.min(b), a.max(b)]).map(|e| (e.dir, e.count))
        };
        let dir = match facet {
            Some((dir, 1)) => dir,
            other => {
                let g = &groups[member[0]];
                let group = match &g.name {
                    Some(n) => format!("\"{n}\" (tag {})", g.tag),
                    None => format!("with tag {} (no name)", g.tag),
                };
                let why = match other {
                    Some(_) => "it is shared by two triangles (an interior edge)",
                    None => "it is not an edge of any triangle",
                };
                let [p, q] = line.nodes.map(|n| fmt_point(raw.nodes[n]));
                return Err(Error::input(format!(
                    "mesh file '{file}': physical group {} contains the line {p}–{q} (gmsh \
                     element {}), which is not on the boundary of the triangle mesh: {why}; a \
                     boundary group must consist of boundary curves of the meshed surface",
                    group, line.tag
                )));
            }
        };
        for g in member {
            if seen[g].insert(dir) {
                groups[g].facets.push(dir);
            }
        }
    }

    Ok(Mesh {
        path: path.to_path_buf(),
        dim: 2,
        nodes,
        triangles,
        groups,
        flipped,
    })
}

#[cfg(test)]
mod tests {
    use super::normalize_name;

    #[test]
    fn aliases_normalize_alike() {
        let n = normalize_name("Γ3,1");
        for alias in ["Gamma3_1", "gamma3,1", "Γ3_1", "GAMMA 3,1", "γ3,1"] {
            assert_eq!(normalize_name(alias), n, "{alias}");
        }
        assert_ne!(normalize_name("Gamma3_2"), n);
    }
}
