//! 2D meshes: 3-node triangles in the xy-plane with physical curve (boundary) and surface
//! groups.
//!
//! A triangle given clockwise is reoriented (counted in [`Mesh::flipped`]), one of zero area
//! is refused, and so is a mesh in which an edge is shared by two triangles in the same
//! direction (a fold) or by three or more. Every line of a physical curve group must be a
//! boundary edge of the triangle mesh; it is stored with the body on its left.

use std::path::Path;

use super::facets::{survey, Survey};
use super::groups::{fill_groups, group_table, other_groups, Words};
use super::physical_names::PhysicalName;
use super::quality::signed_area;
use super::raw::{too_many_nodes, CellsRead, RawMesh};
use super::{check_finite, fmt_point, renumber, Mesh, Places};
use crate::{Error, Result};

/// How messages about the triangle mesh name its parts.
const WORDS: Words = Words {
    element: "line",
    mesh: "triangle mesh",
    cells: "triangles",
    cell: "triangle",
    facet: "edge",
    a_facet: "an edge",
    boundary: "curves of the meshed surface",
};

/// Geometry, topology and groups of a 2D mesh from the raw file content.
pub(crate) fn build(path: &Path, mut raw: RawMesh, names: &[PhysicalName]) -> Result<Mesh> {
    let file = path.display();
    if raw.triangles.is_empty() {
        return Err(Error::input(format!(
            "mesh file '{file}' contains no triangles (gmsh element type 2) and no tetrahedra \
             (type 4); viscontact needs a 2D triangle mesh (`gmsh -2`) or a 3D tetrahedral \
             mesh (`gmsh -3`) with the cells in a physical surface or volume group (gmsh saves \
             only elements of physical groups)"
        )));
    }
    let (new_index, mut nodes) = renumber(&raw.nodes, &raw.triangles);
    let scale = flatten_onto_xy_plane(&file, &mut nodes)?;
    let (triangles, flipped) = orient_triangles(&file, &raw, &new_index, &nodes, scale)?;
    let cells = CellsRead::of(std::mem::take(&mut raw.triangles));
    let edges = edge_uses(&file, &cells.tags, &triangles, &nodes, &raw, &new_index)?;

    let lookup = |f: [usize; 2]| edges.lookup(f);
    let groups = fill_groups(
        &file,
        &raw,
        (&cells.entities, &raw.lines),
        group_table(&raw, names, 2),
        &new_index,
        lookup,
        &WORDS,
        |g, f| g.facets.push(f),
    )?;

    Ok(Mesh {
        path: path.to_path_buf(),
        dim: 2,
        nodes: Places::every(nodes),
        triangles,
        tetrahedra: Vec::new(),
        groups,
        flipped,
        other_groups: other_groups(&raw, names, 2),
        cell_entity: cells.entities.iter().map(|e| e.1).collect(),
    })
}

/// Checks that the nodes are finite and lie in the xy-plane, and sets their z to 0: the
/// coordinate scale (the largest |x| or |y|) for the zero-area test.
fn flatten_onto_xy_plane(file: &impl std::fmt::Display, nodes: &mut [[f64; 3]]) -> Result<f64> {
    let scale = nodes
        .iter()
        .map(|p| p[0].abs().max(p[1].abs()))
        .fold(0.0_f64, f64::max);
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in nodes.iter() {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let diag = (hi[0] - lo[0]).hypot(hi[1] - lo[1]);
    check_finite(file, nodes)?;
    if let Some(p) = nodes.iter().find(|p| p[2].abs() > 1e-12 * diag.max(scale)) {
        return Err(Error::input(format!(
            "mesh file '{file}' is not a 2D mesh in the xy-plane: node {} has z ≠ 0; \
             viscontact reads 2D meshes (z = 0)",
            fmt_point(*p, 3)
        )));
    }
    for p in nodes.iter_mut() {
        p[2] = 0.0;
    }
    Ok(scale)
}

/// The triangles in the new numbering, counter-clockwise, and how many were reoriented;
/// a degenerate triangle is refused.
///
/// A triangle is degenerate if the altitude onto its longest edge is at most 1e-12 of that
/// edge (its smallest angle is below ~1e-10 rad) or at most 1e-13 of the largest coordinate
/// `scale` (the precision at which coordinates are stored).
fn orient_triangles(
    file: &impl std::fmt::Display,
    raw: &RawMesh,
    new_index: &[usize],
    nodes: &[[f64; 3]],
    scale: f64,
) -> Result<(Vec<[usize; 3]>, usize)> {
    let mut triangles = Vec::with_capacity(raw.triangles.len());
    let mut flipped = 0;
    let mut degenerate = Vec::new();
    for t in &raw.triangles {
        let mut tri = t.nodes().map(|n| new_index[n]);
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
        let pts: Vec<String> = t
            .nodes()
            .iter()
            .map(|&n| fmt_point(raw.nodes[n], 2))
            .collect();
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
    Ok((triangles, flipped))
}

/// The edges of the triangles: each is used by one triangle (boundary) or by two in
/// opposite directions; a fold or an edge of three triangles is refused. Found are the
/// lines of the file (`raw`'s, in the nodes' `new_index`), which the groups look up.
fn edge_uses(
    file: &impl std::fmt::Display,
    tags: &[u64],
    triangles: &[[usize; 3]],
    nodes: &[[f64; 3]],
    raw: &RawMesh,
    new_index: &[usize],
) -> Result<Survey<2>> {
    let uses = || {
        (triangles.iter().enumerate())
            .flat_map(|(k, tri)| [0, 1, 2].map(|i| (k, [tri[i], tri[(i + 1) % 3]])))
    };
    let asked = (raw.lines.iter()).map(|l| l.nodes().map(|n| new_index[n]));
    let edges =
        survey(uses, nodes.len(), asked, |a, b| a == b).ok_or_else(|| too_many_nodes(file))?;
    let tri_tag = |k: usize| tags[k];
    let edge_at =
        |[a, b]: [usize; 2]| format!("{}–{}", fmt_point(nodes[a], 2), fmt_point(nodes[b], 2));
    match &edges.misuse {
        None => Ok(edges),
        Some(misuse) => Err(misuse.error(file, &WORDS, tri_tag, edge_at)),
    }
}
