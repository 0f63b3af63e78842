//! 3D meshes: 4-node tetrahedra with physical surface (boundary) and volume groups.
//!
//! The same checks as for triangles, one dimension up: a tetrahedron of negative volume is
//! reoriented (counted in [`Mesh::flipped`]), a flat one is refused, and so is a mesh in which
//! a face is shared by two tetrahedra on the same side (a fold) or by three or more. Every
//! triangle of a physical surface group must be a boundary face of the tetrahedral mesh; it
//! is stored with the outward orientation of its tetrahedron.

use std::path::Path;

use super::facets::{survey, Survey};
use super::groups::{fill_groups, group_table, other_groups, Words};
use super::physical_names::PhysicalName;
use super::quality::Quality;
use super::raw::{too_many_nodes, CellsRead, RawMesh};
use super::{check_finite, fmt_point, renumber, Mesh, Places};
use crate::{Error, Result};

pub(crate) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub(crate) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub(crate) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(crate) fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

/// Six times the signed volume of (a, b, c, d): (b − a)·((c − a) × (d − a)).
pub(crate) fn volume6(p: [[f64; 3]; 4]) -> f64 {
    dot(sub(p[1], p[0]), cross(sub(p[2], p[0]), sub(p[3], p[0])))
}

/// The faces of a positively oriented tetrahedron, each ordered so that its right-hand
/// normal points out of the tetrahedron; face k is opposite vertex k.
pub(crate) const FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]];

/// How messages about the tetrahedral mesh name its parts.
const WORDS: Words = Words {
    element: "triangle",
    mesh: "tetrahedral mesh",
    cells: "tetrahedra",
    cell: "tetrahedron",
    facet: "face",
    a_facet: "a face",
    boundary: "surfaces of the meshed volume",
};

/// Geometry, topology and groups of a 3D mesh from the raw file content.
pub(crate) fn build(path: &Path, mut raw: RawMesh, names: &[PhysicalName]) -> Result<Mesh> {
    let file = path.display();
    let (new_index, nodes) = renumber(&raw.nodes, &raw.tetrahedra);
    check_finite(&file, &nodes)?;
    let scale = nodes
        .iter()
        .map(|p| p.iter().fold(0.0_f64, |a, c| a.max(c.abs())))
        .fold(0.0_f64, f64::max);
    let (tetrahedra, flipped) = orient_tetrahedra(&file, &raw, &new_index, &nodes, scale)?;
    let cells = CellsRead::of(std::mem::take(&mut raw.tetrahedra));
    let faces = face_uses(&file, &cells.tags, &tetrahedra, &nodes, &raw, &new_index)?;

    let lookup = |f: [usize; 3]| faces.lookup(f);
    let groups = fill_groups(
        &file,
        &raw,
        (&cells.entities, &raw.triangles),
        group_table(&raw, names, 3),
        &new_index,
        lookup,
        &WORDS,
        |g, f| g.faces.push(f),
    )?;

    Ok(Mesh {
        path: path.to_path_buf(),
        dim: 3,
        nodes: Places::every(nodes),
        triangles: Vec::new(),
        tetrahedra,
        groups,
        flipped,
        other_groups: other_groups(&raw, names, 3),
        cell_entity: cells.entities.iter().map(|e| e.1).collect(),
    })
}

/// The tetrahedra in the new numbering, positively oriented, and how many were reoriented;
/// a flat tetrahedron is refused.
///
/// A tetrahedron is flat if its height over the largest face is at most 1e-12 of its longest
/// edge, or at most 1e-13 of the largest coordinate `scale`.
fn orient_tetrahedra(
    file: &impl std::fmt::Display,
    raw: &RawMesh,
    new_index: &[usize],
    nodes: &[[f64; 3]],
    scale: f64,
) -> Result<(Vec<[usize; 4]>, usize)> {
    let mut tetrahedra = Vec::with_capacity(raw.tetrahedra.len());
    let mut flipped = 0;
    let mut flat = Vec::new();
    for t in &raw.tetrahedra {
        let mut tet = t.nodes().map(|n| new_index[n]);
        let p = tet.map(|n| nodes[n]);
        let v6 = volume6(p);
        let mut lmax: f64 = 0.0;
        let mut amax: f64 = 0.0;
        for i in 0..4 {
            for j in i + 1..4 {
                lmax = lmax.max(norm(sub(p[j], p[i])));
            }
            let [a, b, c] = FACES[i].map(|k| p[k]);
            amax = amax.max(norm(cross(sub(b, a), sub(c, a))));
        }
        // height = v6 / (2 · face area) = v6 / amax (amax is twice the largest face area).
        if v6.abs() <= amax * (1e-12 * lmax + 1e-13 * scale) {
            flat.push(t);
        } else if v6 < 0.0 {
            tet.swap(1, 2);
            flipped += 1;
        }
        tetrahedra.push(tet);
    }
    if let Some(t) = flat.first() {
        let pts: Vec<String> = t
            .nodes()
            .iter()
            .map(|&n| fmt_point(raw.nodes[n], 3))
            .collect();
        let more = match flat.len() {
            1 => String::new(),
            n => format!(" ({} more tetrahedra are flat)", n - 1),
        };
        return Err(Error::input(format!(
            "mesh file '{file}': tetrahedron {} (gmsh element tag) has zero volume: its nodes \
             {} are coplanar or coincide{more}; fix the geometry or remesh",
            t.tag,
            pts.join(", ")
        )));
    }
    Ok((tetrahedra, flipped))
}

/// The faces of the tetrahedra: each is used by one tetrahedron (boundary) or by two in
/// opposite orientations; a fold or a face of three tetrahedra is refused. Found are the
/// triangles of the file (`raw`'s, in the nodes' `new_index`), which the groups look up.
fn face_uses(
    file: &impl std::fmt::Display,
    tags: &[u64],
    tetrahedra: &[[usize; 4]],
    nodes: &[[f64; 3]],
    raw: &RawMesh,
    new_index: &[usize],
) -> Result<Survey<3>> {
    let uses = || {
        (tetrahedra.iter().enumerate())
            .flat_map(|(k, tet)| FACES.map(|local| (k, local.map(|i| tet[i]))))
    };
    let asked = (raw.triangles.iter()).map(|t| t.nodes().map(|n| new_index[n]));
    // The same face seen from the other side is an odd permutation: the same side, an even one.
    let same_side =
        |a: [u32; 3], b: [u32; 3]| (0..3).any(|r| [a[r], a[(r + 1) % 3], a[(r + 2) % 3]] == b);
    let faces = survey(uses, nodes.len(), asked, same_side).ok_or_else(|| too_many_nodes(file))?;
    let tet_tag = |k: usize| tags[k];
    let face_at = |f: [usize; 3]| {
        let pts: Vec<String> = f.iter().map(|&n| fmt_point(nodes[n], 3)).collect();
        pts.join("–")
    };
    match &faces.misuse {
        None => Ok(faces),
        Some(misuse) => Err(misuse.error(file, &WORDS, tet_tag, face_at)),
    }
}

/// Quality of a tetrahedral mesh: the smallest dihedral angle (70.53° for a regular
/// tetrahedron), the largest aspect ratio ℓ_max / (2√6 r) with r = 3V / (total face area) the
/// inradius (1 for a regular tetrahedron), the smallest and largest volume.
pub(crate) fn quality(nodes: &[[f64; 3]], tets: &[[usize; 4]]) -> Quality {
    let mut q = Quality {
        min_angle_deg: f64::INFINITY,
        max_aspect_ratio: 0.0,
        min_area: f64::INFINITY,
        max_area: 0.0,
    };
    for t in tets {
        let p = t.map(|i| nodes[i]);
        let vol = volume6(p).abs() / 6.0;
        // Face normals (outward, scaled by twice the face area).
        let n = FACES.map(|f| {
            let [a, b, c] = f.map(|k| p[k]);
            cross(sub(b, a), sub(c, a))
        });
        let area: f64 = n.iter().map(|v| 0.5 * norm(*v)).sum();
        let mut lmax: f64 = 0.0;
        for i in 0..4 {
            for j in i + 1..4 {
                lmax = lmax.max(norm(sub(p[j], p[i])));
                // The dihedral angle at the edge shared by faces i and j: π minus the angle
                // between their outward normals.
                let c = dot(n[i], n[j]) / (norm(n[i]) * norm(n[j]));
                let angle = std::f64::consts::PI - c.clamp(-1.0, 1.0).acos();
                q.min_angle_deg = q.min_angle_deg.min(angle.to_degrees());
            }
        }
        let r = 3.0 * vol / area;
        q.max_aspect_ratio = q.max_aspect_ratio.max(lmax / (2.0 * 6f64.sqrt() * r));
        q.min_area = q.min_area.min(vol);
        q.max_area = q.max_area.max(vol);
    }
    q
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regular_tetrahedron_quality_and_outward_faces() {
        let s = 1.0 / 2f64.sqrt();
        let nodes = [
            [1.0, 0.0, -s],
            [-1.0, 0.0, -s],
            [0.0, 1.0, s],
            [0.0, -1.0, s],
        ];
        let t = if volume6(nodes) > 0.0 {
            [0, 1, 2, 3]
        } else {
            [0, 2, 1, 3]
        };
        let q = quality(&nodes, &[t]);
        assert!((q.min_angle_deg - (1.0f64 / 3.0).acos().to_degrees()).abs() < 1e-12);
        assert!(
            (q.max_aspect_ratio - 1.0).abs() < 1e-12,
            "{}",
            q.max_aspect_ratio
        );
        // Each face's right-hand normal points away from the opposite vertex.
        let p = t.map(|i| nodes[i]);
        for (k, f) in FACES.iter().enumerate() {
            let [a, b, c] = f.map(|i| p[i]);
            assert!(dot(cross(sub(b, a), sub(c, a)), sub(a, p[k])) > 0.0);
        }
    }
}
