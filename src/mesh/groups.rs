//! The physical groups of a mesh, for both dimensions: the table of the groups the file
//! declares, filled with the cells and boundary facets of their entities, and the groups
//! of other dimensions, which carry no condition.

use std::collections::{HashMap, HashSet};

use super::physical_names::PhysicalName;
use super::raw::{RawElement, RawMesh};
use super::{fmt_point, Group, UNUSED};
use crate::Result;

/// The words of `fill_groups`' messages for one dimension.
pub(super) struct Words {
    pub(super) element: &'static str,
    pub(super) mesh: &'static str,
    pub(super) cells: &'static str,
    pub(super) cell: &'static str,
    pub(super) facet: &'static str,
    pub(super) a_facet: &'static str,
    pub(super) boundary: &'static str,
}

/// Fills the groups of `group_table` (dimension D of the cells, D − 1 of the facets): each
/// cell element goes into the cell groups of its entity (`cells`: each one's entity), each
/// facet element (a line in 2D, a triangle in 3D) into the boundary groups of its entity,
/// once, as the oriented boundary facet that `lookup` finds for its nodes (`(oriented
/// nodes, number of cells using it)`). A facet element that is not a boundary facet of the
/// cells (an embedded curve or surface) marks its groups with a `defect`: refused where a
/// scene uses the group as a boundary.
#[allow(clippy::too_many_arguments)]
pub(super) fn fill_groups<const F: usize>(
    file: &impl std::fmt::Display,
    raw: &RawMesh,
    (cells, facets): (&[(i32, i32)], &[RawElement<F>]),
    (mut groups, groups_of): (Vec<Group>, impl Fn((i32, i32)) -> Vec<usize>),
    new_index: &[usize],
    lookup: impl Fn([usize; F]) -> Option<([usize; F], u32)>,
    words: &Words,
    store: impl Fn(&mut Group, [usize; F]),
) -> Result<Vec<Group>> {
    // A facet of F nodes bounds a cell of dimension F (an edge a triangle, a triangle a
    // tetrahedron).
    let (cell_dim, facet_dim) = (F as i32, F as i32 - 1);
    for (k, &entity) in cells.iter().enumerate() {
        if entity.0 == cell_dim {
            for g in groups_of(entity) {
                groups[g].cells.push(k);
            }
        }
    }
    let sorted = |mut f: [usize; F]| {
        f.sort_unstable();
        f
    };
    let mut seen: Vec<HashSet<[usize; F]>> = vec![HashSet::new(); groups.len()];
    let mut misfits = vec![Misfits::default(); groups.len()];
    for el in facets.iter().filter(|e| e.entity.0 == facet_dim) {
        let member = groups_of(el.entity);
        if member.is_empty() {
            continue;
        }
        let f = el.nodes().map(|n| new_index[n]);
        let found = if f.contains(&UNUSED) { None } else { lookup(f) };
        for &g in &member {
            misfits[g].elements += 1;
        }
        let dir = match found {
            Some((dir, 1)) => dir,
            other => {
                let pts: Vec<String> = el
                    .nodes()
                    .iter()
                    .map(|&n| fmt_point(raw.nodes[n], F))
                    .collect();
                let example = format!("{} (gmsh element {})", pts.join("–"), el.tag);
                for &g in &member {
                    let m = &mut misfits[g];
                    match other {
                        Some(_) => m.interior += 1,
                        None => m.off += 1,
                    }
                    m.example.get_or_insert_with(|| example.clone());
                }
                continue;
            }
        };
        for g in member {
            if seen[g].insert(sorted(dir)) {
                store(&mut groups[g], dir);
            }
        }
    }
    for (g, m) in groups.iter_mut().zip(&misfits) {
        if m.off + m.interior > 0 {
            g.defect = Some(m.message(file, g, words));
        }
    }
    Ok(groups)
}

/// The facet elements of one boundary group that are not boundary facets of the cells.
#[derive(Clone, Default)]
struct Misfits {
    /// All facet elements of the group.
    elements: usize,
    /// Facets of no cell (a curve or surface outside the meshed body's boundary).
    off: usize,
    /// Facets of two cells (an embedded curve or surface inside the body).
    interior: usize,
    /// The first misfit, as its corner points and gmsh element tag.
    example: Option<String>,
}

impl Misfits {
    /// The group's `defect`: it exists, how many of its elements are not boundary facets and
    /// why, an example, and the gmsh fix.
    fn message(&self, file: &impl std::fmt::Display, g: &Group, words: &Words) -> String {
        let Words {
            element,
            mesh,
            cells,
            cell,
            facet,
            a_facet,
            boundary,
        } = words;
        let group = match &g.name {
            Some(n) => format!("\"{n}\" (tag {})", g.tag),
            None => format!("with tag {} (no name)", g.tag),
        };
        let bad = self.off + self.interior;
        let how_many = match (bad == self.elements, bad) {
            (true, 1) => format!("it is not a boundary {facet} of the {mesh}"),
            (true, _) => format!("none of them is a boundary {facet} of the {mesh}"),
            (false, 1) => format!("1 of them is not a boundary {facet} of the {mesh}"),
            (false, _) => format!("{bad} of them are not boundary {facet}s of the {mesh}"),
        };
        let is = |n: usize| {
            if n == 1 {
                "1 is".to_string()
            } else {
                format!("{n} are")
            }
        };
        let mut why = Vec::new();
        if self.off > 0 {
            why.push(format!("{} not {a_facet} of any {cell}", is(self.off)));
        }
        if self.interior > 0 {
            why.push(format!(
                "{} an interior {facet} shared by two {cells} (an embedded {element})",
                is(self.interior)
            ));
        }
        let plural = if self.elements == 1 { "" } else { "s" };
        format!(
            "mesh file '{file}': physical group {group} exists, with {} {element} element{plural}, \
             but {how_many} (not on the boundary: {}; e.g. the {element} {}), so it cannot \
             carry a boundary condition: a boundary group must consist of boundary {boundary}. \
             In gmsh, make them part of that boundary (build the body from them, or fragment: \
             BooleanFragments in OpenCASCADE, Coherence in the built-in kernel) and mesh again",
            self.elements,
            why.join(", "),
            self.example.as_deref().unwrap_or("?")
        )
    }
}

/// The physical groups of the file whose dimension is neither `dim − 1` nor `dim`.
pub(super) fn other_groups(
    raw: &RawMesh,
    names: &[PhysicalName],
    dim: i32,
) -> Vec<(usize, i32, Option<String>)> {
    let mut out: Vec<(usize, i32, Option<String>)> = names
        .iter()
        .filter(|n| n.dim != dim && n.dim != dim - 1)
        .map(|n| (n.dim as usize, n.tag, Some(n.name.clone())))
        .collect();
    for &(d, tag) in &raw.physical_order {
        if d != dim && d != dim - 1 && !out.iter().any(|o| (o.0, o.1) == (d as usize, tag)) {
            out.push((d as usize, tag, None));
        }
    }
    out
}

/// The physical groups of dimensions `dim − 1` and `dim` (named ones in `$PhysicalNames`
/// order, then unnamed ones from `$Entities`), still empty, and a map from an entity
/// `(dim, tag)` to the indices of the groups it belongs to.
pub(super) fn group_table<'r>(
    raw: &'r RawMesh,
    names: &[PhysicalName],
    dim: i32,
) -> (Vec<Group>, impl Fn((i32, i32)) -> Vec<usize> + 'r) {
    let mut groups: Vec<Group> = Vec::new();
    let mut slot: HashMap<(i32, i32), usize> = HashMap::new();
    let mut add_group = |d: i32, tag: i32, name: Option<String>| {
        if (d == dim - 1 || d == dim) && !slot.contains_key(&(d, tag)) {
            slot.insert((d, tag), groups.len());
            groups.push(Group {
                dim: d as usize,
                tag,
                name,
                facets: Vec::new(),
                faces: Vec::new(),
                cells: Vec::new(),
                defect: None,
            });
        }
    };
    for n in names {
        add_group(n.dim, n.tag, Some(n.name.clone()));
    }
    for &(d, tag) in &raw.physical_order {
        add_group(d, tag, None);
    }
    let groups_of = move |entity: (i32, i32)| -> Vec<usize> {
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
    (groups, groups_of)
}
