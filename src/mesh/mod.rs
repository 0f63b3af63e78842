//! Mesh import: gmsh MSH 4.1 files (ASCII or binary) with physical groups.
//!
//! [`Mesh::read`] reads the file through `mshio` (see `msh.rs` for what `mshio` does and
//! what is added here) and the `$PhysicalNames` section with a small reader of its own
//! (`physical_names.rs`: `mshio` skips that section). It accepts 4-node tetrahedra (gmsh
//! type 4), 3-node triangles (type 2), 2-node lines (type 1) and points (type 15); anything
//! else is refused with a message naming the type and how to remesh. A file with tetrahedra
//! is a 3D mesh (its triangles are boundary faces), one without is a 2D mesh in the
//! xy-plane. For a 2D mesh (`plane.rs`):
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
//! A 3D mesh is read the same way one dimension up (`solid.rs`): tetrahedra of negative
//! volume are reoriented, flat ones, folds and faces shared by three tetrahedra are refused;
//! every physical surface group becomes a list of boundary faces (triangles oriented with the
//! outward normal by the right-hand rule), every physical volume group a list of tetrahedra;
//! curve groups are ignored.
//!
//! Groups are found by name, by an ASCII alias of the name, or by integer tag
//! ([`Mesh::group`]). The code downstream sees the boundary of either dimension through
//! [`Mesh::boundary_facets`]: edges in 2D, triangles in 3D, with normal and measure.

mod elements;
mod facets;
mod groups;
mod msh;
mod parts;
mod physical_names;
mod places;
mod plane;
mod quality;
mod raw;
mod solid;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

pub use parts::{Coincident, Part, COINCIDENT_TOLERANCE};
pub use places::{increasing, Places, Points};
pub use quality::Quality;
pub(crate) use solid::{cross, dot, norm, sub};

use crate::{Error, Result};

/// A P1 simplex mesh (triangles in 2D, tetrahedra in 3D) with its physical groups.
#[derive(Debug, Clone, PartialEq)]
pub struct Mesh {
    /// The file the mesh was read from (as given to [`Mesh::read`]).
    pub path: PathBuf,
    /// Spatial dimension: 2 (triangles in the xy-plane) or 3 (tetrahedra).
    pub dim: usize,
    /// Node coordinates; only nodes used by the cells, numbered `0..` in file order;
    /// z = 0 in 2D. On a follower rank of a run whose setup spreads, those of its groups'
    /// nodes and its part's cells alone ([`Places`]).
    pub nodes: Places,
    /// 2D: the cells, as 0-based node indices, counter-clockwise (positive signed area).
    /// Empty in 3D.
    pub triangles: Vec<[usize; 3]>,
    /// 3D: the cells, positively oriented ((b−a)·((c−a)×(d−a)) > 0). Empty in 2D.
    pub tetrahedra: Vec<[usize; 4]>,
    /// All physical groups of dimension `dim − 1` (boundary) and `dim` (cells), in file
    /// order (the order of `$PhysicalNames`, then unnamed groups in the order of
    /// `$Entities`).
    pub groups: Vec<Group>,
    /// How many cells had negative orientation in the file and got reoriented.
    pub flipped: usize,
    /// Physical groups of the other dimensions (points; curves in 3D), which carry no
    /// condition: (dimension, tag, name). Kept to say so when a scene names one.
    pub other_groups: Vec<(usize, i32, Option<String>)>,
    /// The gmsh entity (surface in 2D, volume in 3D) of each cell.
    pub cell_entity: Vec<i32>,
}

/// A boundary facet of either dimension: an edge in 2D, a triangle in 3D, its nodes ordered
/// so that the normal points out of the body.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Facet {
    nodes: [usize; 3],
    count: usize,
    /// Outward unit normal ν.
    pub normal: [f64; 3],
    /// Length (2D) or area (3D).
    pub measure: f64,
}

impl Facet {
    /// The facet's 2 (2D) or 3 (3D) nodes.
    pub fn nodes(&self) -> &[usize] {
        &self.nodes[..self.count]
    }

    /// Quadrature on the facet, exact for cubic polynomials (a quadratic traction times P1):
    /// 2-point Gauss on an edge, the 6-point degree-4 Dunavant rule on a triangle. Each point
    /// as (x, weight, φ of the facet's nodes at x; unused entries 0).
    pub fn quadrature(&self, mesh: &Mesh) -> Vec<([f64; 3], f64, [f64; 3])> {
        facet_rule(
            self.nodes.map(|n| mesh.nodes[n]),
            self.count,
            self.weights(),
        )
    }

    /// The weights of the orbits of [`Facet::quadrature`]'s rule: an edge's two points
    /// |e|/2 each, a triangle's two orbits w_o |T|.
    pub fn weights(&self) -> [f64; 2] {
        match self.count {
            2 => [0.5 * self.measure; 2],
            _ => DUNAVANT.map(|(_, _, w)| w * self.measure),
        }
    }
}

/// Dunavant (1985), degree 4: two orbits of 3 points, (a, b, w): barycentric coordinates
/// (b, a, a) and their permutations, weight w |T|.
const DUNAVANT: [(f64, f64, f64); 2] = [
    (
        0.445_948_490_915_965,
        0.108_103_018_168_070,
        0.223_381_589_678_011,
    ),
    (
        0.091_576_213_509_771,
        0.816_847_572_980_459,
        0.109_951_743_655_322,
    ),
];

/// The points of [`Facet::quadrature`] on a facet of `count` nodes at the places `p` (a
/// triangle's three; an edge's first two), its orbits' weights `weights` ([`Facet::weights`]),
/// as (x, weight, φ of the facet's nodes at x): the same bits from the facet's nodes and
/// weights alone, which a load that keeps those of every facet of a boundary remakes
/// its points from (`fem::loads`).
pub fn facet_rule(
    p: [[f64; 3]; 3],
    count: usize,
    weights: [f64; 2],
) -> Vec<([f64; 3], f64, [f64; 3])> {
    let at = |bary: [f64; 3], weight: f64| {
        let mut x = [0.0; 3];
        for (k, xk) in x.iter_mut().enumerate() {
            *xk = (0..count).map(|i| bary[i] * p[i][k]).sum();
        }
        (x, weight, bary)
    };
    if count == 2 {
        // s ∈ (0, 1) along a → b; φ_a = 1 − s, φ_b = s.
        let g = 0.5 / 3f64.sqrt();
        let edge = |s: f64| {
            let x = [0, 1, 2].map(|k| p[0][k] + s * (p[1][k] - p[0][k]));
            (x, weights[0], [1.0 - s, s, 0.0])
        };
        return vec![edge(0.5 - g), edge(0.5 + g)];
    }
    let mut out = Vec::with_capacity(6);
    for ((a, b, _), weight) in DUNAVANT.into_iter().zip(weights) {
        for bary in [[b, a, a], [a, b, a], [a, a, b]] {
            out.push(at(bary, weight));
        }
    }
    out
}

/// A physical group of the mesh.
#[derive(Debug, Clone, PartialEq)]
pub struct Group {
    /// 1 = curve, 2 = surface, 3 = volume. Boundary groups have dimension `Mesh::dim − 1`.
    pub dim: usize,
    /// The physical tag in the file.
    pub tag: i32,
    /// The name from `$PhysicalNames` (UTF-8, e.g. `"Γ3,1"`), if the group has one.
    pub name: Option<String>,
    /// 2D curve groups: boundary edges `[a, b]`, each once, oriented so that the body lies on
    /// the left of a → b (outward normal `(dy, -dx) / len`). Empty otherwise.
    pub facets: Vec<[usize; 2]>,
    /// 3D surface groups: boundary triangles `[a, b, c]`, each once, oriented so that
    /// (b − a) × (c − a) points out of the body. Empty otherwise.
    pub faces: Vec<[usize; 3]>,
    /// Cell groups: indices into [`Mesh::triangles`] (2D) or [`Mesh::tetrahedra`] (3D).
    pub cells: Vec<usize>,
    /// Why the group cannot carry a boundary condition (it holds elements inside the body:
    /// an embedded curve or surface), if so. Only a group the scene uses as a boundary group
    /// is refused for it; `mesh-info` shows it as a warning.
    pub defect: Option<String>,
}

impl Group {
    /// The number of boundary facets (edges or faces).
    pub fn n_facets(&self) -> usize {
        self.facets.len() + self.faces.len()
    }
}

impl Mesh {
    /// Reads a gmsh MSH 4.1 file (ASCII or binary). Every problem with the file (missing,
    /// wrong version, unsupported elements, truncated, degenerate or folded elements, boundary
    /// groups off the boundary) is an [`Error::Input`] naming the file and the culprit.
    pub fn read(path: &Path) -> Result<Mesh> {
        let bytes = crate::input_file::read_input_file(path, "mesh file", None)?;
        let raw = msh::read_raw(path, &bytes)?;
        let names = physical_names::read_physical_names(&bytes)
            .map_err(|m| Error::input(format!("mesh file '{}': {m}", path.display())))?;
        // The file's bytes go before the facets are sorted, where reading a mesh peaks.
        drop(bytes);
        if raw.tetrahedra.is_empty() {
            plane::build(path, raw, &names)
        } else {
            solid::build(path, raw, &names)
        }
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
        self.find_group(key, Want::Any)
    }

    /// Like [`Mesh::group`], but the group must hold cells of the body: a surface group in
    /// 2D, a volume group in 3D (a material region). An empty one is refused.
    pub fn cell_group(&self, key: &str) -> Result<&Group> {
        let g = self.find_group(key, Want::Cells)?;
        if g.cells.is_empty() {
            let cells = ["triangles", "tetrahedra"][self.dim - 2];
            return Err(Error::input(format!(
                "mesh '{}': physical group '{}' (tag {}) has no {cells}: no element of the \
                 mesh carries it; add the body's elements to the group in gmsh",
                self.path.display(),
                Self::display_name(g),
                g.tag
            )));
        }
        Ok(g)
    }

    /// Like [`Mesh::group`], but the group must be a boundary group: a curve group in 2D, a
    /// surface group in 3D. An empty group (named in `$PhysicalNames` but carried by no
    /// boundary entity) is refused: a boundary condition on it would silently do nothing.
    pub fn boundary_group(&self, key: &str) -> Result<&Group> {
        let g = self.find_group(key, Want::Boundary)?;
        if let Some(why) = &g.defect {
            return Err(Error::input(why.clone()));
        }
        if g.n_facets() == 0 {
            let (what, entity) = match self.dim {
                2 => ("boundary edges", "curve"),
                _ => ("boundary faces", "surface"),
            };
            return Err(Error::input(format!(
                "mesh '{}': physical group '{}' (tag {}) has no {what}: no {entity} of the \
                 mesh carries it; add the {entity}s to the group in gmsh",
                self.path.display(),
                Self::display_name(g),
                g.tag
            )));
        }
        Ok(g)
    }

    /// Outward unit normal of the 2D boundary edge `f = [a, b]` (body on the left of a → b):
    /// `(dy, -dx) / len`.
    pub fn facet_normal(&self, f: [usize; 2]) -> [f64; 2] {
        let (a, b) = (self.nodes[f[0]], self.nodes[f[1]]);
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let len = dx.hypot(dy);
        [dy / len, -dx / len]
    }

    /// Length of the 2D boundary edge `f`.
    pub fn facet_length(&self, f: [usize; 2]) -> f64 {
        let (a, b) = (self.nodes[f[0]], self.nodes[f[1]]);
        (b[0] - a[0]).hypot(b[1] - a[1])
    }

    /// The boundary facets of a group, edges (2D) or triangles (3D), with outward normal and
    /// measure. Empty for a cell group.
    pub fn boundary_facets(&self, g: &Group) -> Vec<Facet> {
        let edges = g.facets.iter().map(|&f| {
            let n = self.facet_normal(f);
            Facet {
                nodes: [f[0], f[1], f[1]],
                count: 2,
                normal: [n[0], n[1], 0.0],
                measure: self.facet_length(f),
            }
        });
        let faces = g.faces.iter().map(|&f| {
            let [a, b, c] = f.map(|i| self.nodes[i]);
            let cross = cross(sub(b, a), sub(c, a));
            let norm = norm(cross);
            Facet {
                nodes: f,
                count: 3,
                normal: cross.map(|x| x / norm),
                measure: 0.5 * norm,
            }
        });
        edges.chain(faces).collect()
    }

    /// The cells as one flat list of node indices, and the number of nodes per cell.
    pub fn cell_nodes(&self) -> (Vec<usize>, usize) {
        match self.dim {
            2 => (self.triangles.iter().flatten().copied().collect(), 3),
            _ => (self.tetrahedra.iter().flatten().copied().collect(), 4),
        }
    }

    /// The number of cells (triangles or tetrahedra).
    pub fn n_cells(&self) -> usize {
        self.triangles.len() + self.tetrahedra.len()
    }

    /// The nodes of a group's facets or cells, sorted, unique: marked, then listed (a
    /// volume's cells list each node a dozen times or more, which a sort would hold).
    pub fn group_nodes(&self, g: &Group) -> Vec<usize> {
        let cells = g.cells.iter().flat_map(|&c| match self.dim {
            2 => &self.triangles[c][..],
            _ => &self.tetrahedra[c][..],
        });
        let facets = g.facets.iter().flatten().chain(g.faces.iter().flatten());
        let nodes = facets.chain(cells);
        let mut marked = vec![false; nodes.clone().max().map_or(0, |&n| n + 1)];
        for &n in nodes {
            marked[n] = true;
        }
        (0..marked.len()).filter(|&n| marked[n]).collect()
    }

    /// Outward unit normal at each node of a boundary group: the measure-weighted average of
    /// the group's own facet normals at that node, normalized; sorted by node. Also returns
    /// the largest angle in degrees between two facet normals of the group meeting at a node
    /// (0 for a flat boundary), so that callers can warn about kinks. Where the facet
    /// normals cancel (a boundary folding back by 180°), the normal of the node's first facet
    /// is used. A cell group has no facets: empty list, angle 0.
    pub fn nodal_normals(&self, g: &Group) -> (Vec<(usize, [f64; 3])>, f64) {
        /// Per node: Σ measure·n, Σ measure, and the facet normals.
        #[derive(Default)]
        struct Acc {
            sum: [f64; 3],
            total: f64,
            ns: Vec<[f64; 3]>,
        }
        let mut at: BTreeMap<usize, Acc> = BTreeMap::new();
        for f in self.boundary_facets(g) {
            for &node in f.nodes() {
                let e = at.entry(node).or_default();
                for k in 0..3 {
                    e.sum[k] += f.measure * f.normal[k];
                }
                e.total += f.measure;
                e.ns.push(f.normal);
            }
        }
        let mut max_angle: f64 = 0.0;
        let normals = at
            .into_iter()
            .map(|(node, Acc { sum, total, ns })| {
                for (i, a) in ns.iter().enumerate() {
                    for b in &ns[i + 1..] {
                        let cross = norm(cross(*a, *b));
                        let dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
                        max_angle = max_angle.max(cross.atan2(dot).to_degrees());
                    }
                }
                let norm = norm(sum);
                let n = if norm > 1e-12 * total {
                    sum.map(|x| x / norm)
                } else {
                    ns[0]
                };
                (node, n)
            })
            .collect();
        (normals, max_angle)
    }

    /// Element quality: smallest angle, largest aspect ratio, smallest and largest area
    /// (2D) or volume (3D; the angle is the smallest dihedral angle).
    pub fn quality(&self) -> Quality {
        match self.dim {
            2 => quality::quality(self.nodes.all(), &self.triangles),
            _ => solid::quality(self.nodes.all(), &self.tetrahedra),
        }
    }

    /// The group's name if it has one, else its tag as a string.
    pub fn display_name(g: &Group) -> String {
        g.name.clone().unwrap_or_else(|| g.tag.to_string())
    }

    fn find_group(&self, key: &str, want: Want) -> Result<&Group> {
        let matcher = GroupKey::new(key);
        for stage in 0..3 {
            let found: Vec<&Group> = (self.groups.iter())
                .filter(|g| matcher.matches(stage, g.name.as_deref(), g.tag))
                .collect();
            if !found.is_empty() {
                return self.choose(found, key, want);
            }
        }
        Err(self.missing(key, &matcher, want))
    }

    /// The one group of `found` (the groups a name or tag matched) that `key` names: for
    /// cells one of the body's dimension, else one on the boundary where there is, else
    /// (unless `want` requires one) any.
    fn choose<'g>(&self, found: Vec<&'g Group>, key: &str, want: Want) -> Result<&'g Group> {
        let file = self.path.display();
        if want == Want::Cells {
            return self.choose_cells(found, key);
        }
        let bdim = self.dim - 1;
        let on_boundary: Vec<&Group> = found.iter().copied().filter(|g| g.dim == bdim).collect();
        let chosen = if !on_boundary.is_empty() {
            on_boundary
        } else if want == Want::Boundary {
            let boundary_groups = self.described(bdim);
            let (is, needed) = match self.dim {
                2 => ("a surface", "a boundary (curve)"),
                _ => ("a volume", "a boundary (surface)"),
            };
            return Err(Error::input(format!(
                "mesh '{file}': '{key}' names the physical group {}, which is {is} \
                 group, but {needed} group is needed here; the boundary groups \
                 are: {}",
                describe(found[0]),
                or_none(&boundary_groups)
            )));
        } else {
            found
        };
        self.only(chosen, key)
    }

    /// The groups of dimension `dim`, described for a message.
    fn described(&self, dim: usize) -> Vec<String> {
        (self.groups.iter())
            .filter(|g| g.dim == dim)
            .map(describe)
            .collect()
    }

    /// The one group of `found` of the body's dimension.
    fn choose_cells<'g>(&self, found: Vec<&'g Group>, key: &str) -> Result<&'g Group> {
        let of_body: Vec<&Group> = found
            .iter()
            .copied()
            .filter(|g| g.dim == self.dim)
            .collect();
        if of_body.is_empty() {
            let cell_groups = self.described(self.dim);
            let (is, needed) = match self.dim {
                2 => ("a curve", "a surface"),
                _ => ("a surface", "a volume"),
            };
            return Err(Error::input(format!(
                "mesh '{}': '{key}' names the physical group {}, which is {is} group, but \
                 {needed} group of the body's elements is needed here; those groups are: {}",
                self.path.display(),
                describe(found[0]),
                or_none(&cell_groups)
            )));
        }
        self.only(of_body, key)
    }

    /// The group when `chosen` holds one; else the error that `key` is ambiguous.
    fn only<'g>(&self, chosen: Vec<&'g Group>, key: &str) -> Result<&'g Group> {
        let file = self.path.display();
        if chosen.len() > 1 {
            let list: Vec<String> = chosen.iter().map(|g| describe(g)).collect();
            return Err(Error::input(format!(
                "mesh '{file}': '{key}' matches several physical groups: {}; use the exact \
                 name (or rename the groups in gmsh so that they differ)",
                list.join(", ")
            )));
        }
        Ok(chosen[0])
    }

    /// Why no physical group matches `key`: it names a group of another dimension, or none.
    fn missing(&self, key: &str, matcher: &GroupKey, want: Want) -> Error {
        let file = self.path.display();
        let elsewhere = (self.other_groups.iter()).find(|(_, tag, name)| {
            (0..3).any(|stage| matcher.matches(stage, name.as_deref(), *tag))
        });
        if let Some((dim, tag, _)) = elsewhere {
            let kind = ["point", "curve", "surface", "volume"][(*dim).min(3)];
            let (boundary, cells) = match self.dim {
                2 => ("curve", "surface"),
                _ => ("surface", "volume"),
            };
            let fix = match want {
                Want::Cells => format!("a material region is a physical {cells}"),
                _ => format!("put the boundary {boundary}s into the group in gmsh"),
            };
            return Error::input(format!(
                "mesh '{file}': '{key}' is a physical {kind} (tag {tag}); a boundary condition \
                 acts on a physical {boundary} and the body is a physical {cells} in a {}D \
                 mesh: {fix}",
                self.dim
            ));
        }
        let list: Vec<String> = self.groups.iter().map(describe).collect();
        let hint = if self.groups.is_empty() {
            "define physical groups in gmsh (e.g. Physical Curve(\"Γ1\") = {...};) and save the \
             mesh again"
        } else {
            "rename the group in gmsh or use one of these names (ASCII aliases match too: Γ → \
             Gamma, ',' → '_', case ignored; so does the tag)"
        };
        Error::input(format!(
            "mesh '{file}' has no physical group '{key}'; it has: {} — {hint}",
            or_none(&list)
        ))
    }
}

/// What kind of group a lookup needs.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Want {
    /// Any group (a boundary one wins where a key matches several dimensions).
    Any,
    /// A group of the boundary's dimension.
    Boundary,
    /// A group of the body's dimension.
    Cells,
}

/// A group as a scene names it, matched in three stages: the exact name, the name
/// normalized (`normalize_name`), the tag.
struct GroupKey<'k> {
    exact: &'k str,
    normalized: String,
    tag: Option<i32>,
}

impl<'k> GroupKey<'k> {
    fn new(key: &'k str) -> Self {
        GroupKey {
            exact: key,
            normalized: normalize_name(key),
            tag: key.trim().parse().ok(),
        }
    }

    /// Whether a group of this name and tag matches at `stage` (0, 1 or 2).
    fn matches(&self, stage: usize, name: Option<&str>, tag: i32) -> bool {
        match stage {
            0 => name == Some(self.exact),
            1 => name.map(normalize_name).as_deref() == Some(self.normalized.as_str()),
            _ => Some(tag) == self.tag,
        }
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
        2 if g.cells.is_empty() && !g.faces.is_empty() => {
            format!("surface, {} faces", g.faces.len())
        }
        2 => format!("surface, {} triangles", g.cells.len()),
        _ => format!("volume, {} tetrahedra", g.cells.len()),
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

/// A number for a message: 6 significant digits, trailing zeros dropped (`0.5`, `1.98097`,
/// `6.12323e-17`, `1.5e+06`): like C's `%g`. Every message that prints a coordinate uses it.
pub fn fmt_num(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{}", x + 0.0);
    }
    let exp = x.abs().log10().floor() as i32;
    // Rounding to 6 digits may carry into the next power of ten (999999.7 → 1e+06).
    let rounded: f64 = format!("{x:.5e}").parse().unwrap_or(x);
    let exp = exp.max(rounded.abs().log10().floor() as i32);
    let trim = |s: String| match s.contains('.') {
        true => s.trim_end_matches('0').trim_end_matches('.').to_string(),
        false => s,
    };
    if (-4..6).contains(&exp) {
        trim(format!("{:.*}", (5 - exp) as usize, x))
    } else {
        let s = format!("{x:.5e}");
        let (mantissa, e) = s.split_once('e').unwrap_or((&s, "0"));
        let e: i32 = e.parse().unwrap_or(0);
        format!(
            "{}e{}{:02}",
            trim(mantissa.to_string()),
            if e < 0 { '-' } else { '+' },
            e.abs()
        )
    }
}

/// A point for a message: `(x, y)` in 2D, `(x, y, z)` in 3D, each by [`fmt_num`].
pub fn fmt_point(p: [f64; 3], dim: usize) -> String {
    let c: Vec<String> = p[..dim.clamp(1, 3)].iter().map(|&x| fmt_num(x)).collect();
    format!("({})", c.join(", "))
}

// What the 2D and 3D builders (`plane.rs`, `solid.rs`) share besides the groups.

/// The index of a node no cell uses.
const UNUSED: usize = usize::MAX;

/// The nodes used by `cells`, renumbered `0..` in file order: (old → new index, with
/// `usize::MAX` for unused nodes; the coordinates of the used ones).
fn renumber<const N: usize>(
    raw_nodes: &[[f64; 3]],
    cells: &[raw::RawElement<N>],
) -> (Vec<usize>, Vec<[f64; 3]>) {
    let mut new_index = vec![UNUSED; raw_nodes.len()];
    for t in cells {
        for n in t.nodes() {
            new_index[n] = 0;
        }
    }
    let mut nodes = Vec::new();
    for (old, slot) in new_index.iter_mut().enumerate() {
        if *slot != UNUSED {
            *slot = nodes.len();
            nodes.push(raw_nodes[old]);
        }
    }
    (new_index, nodes)
}

fn check_finite(file: &impl std::fmt::Display, nodes: &[[f64; 3]]) -> Result<()> {
    match nodes.iter().find(|p| p.iter().any(|c| !c.is_finite())) {
        Some(p) => Err(Error::input(format!(
            "mesh file '{file}' has a node with a non-finite coordinate {}; the file \
             looks corrupt, regenerate it with gmsh",
            fmt_point(*p, 3)
        ))),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::{fmt_num, fmt_point, normalize_name};

    #[test]
    fn numbers_in_messages_have_six_significant_digits() {
        for (x, text) in [
            (6.123233995736766e-17, "6.12323e-17"),
            (0.5, "0.5"),
            (1.980969883096585, "1.98097"),
            (2.0, "2"),
            (-0.75, "-0.75"),
            (-0.0, "0"),
            (123456.7, "123457"),
            (999999.7, "1e+06"),
            (1.5e6, "1.5e+06"),
            (0.0001234, "0.0001234"),
            (1e-5, "1e-05"),
            (0.1 + 0.2, "0.3"),
            (f64::NAN, "NaN"),
        ] {
            assert_eq!(fmt_num(x), text, "{x:e}");
        }
        assert_eq!(fmt_point([1.0, 0.5, 7.0], 2), "(1, 0.5)");
        assert_eq!(fmt_point([1.0, 0.5, 1.0 / 3.0], 3), "(1, 0.5, 0.333333)");
    }

    #[test]
    fn aliases_normalize_alike() {
        let n = normalize_name("Γ3,1");
        for alias in ["Gamma3_1", "gamma3,1", "Γ3_1", "GAMMA 3,1", "γ3,1"] {
            assert_eq!(normalize_name(alias), n, "{alias}");
        }
        assert_ne!(normalize_name("Gamma3_2"), n);
    }
}
