//! The mesh rank 0 reads, handed to the other ranks: a follower never reads the mesh file.
//!
//! Rank 0 reads and checks the file (`Mesh::read`). Once the ranks agree that every setup
//! so far succeeded ([`Ranks::agree`]), it broadcasts the mesh in two parts: its [`Shape`]
//! (its arrays' lengths, the groups' tags and names, the file's path) as JSON, and then
//! each array's bytes as they lie in memory, into arrays of that shape on the others
//! ([`Ranks::mesh_of_first`]), the nodes' places on their own. So a follower holds the
//! mesh alone, never the file's bytes nor the reader's arrays, where reading a mesh peaks,
//! and the mesh is the same bits on every rank. The bytes are the ranks' own layout in
//! memory: the ranks of a run are one build on one architecture, as MPI runs of one
//! program are.
//!
//! Where the run's setup spreads (several ranks, PETSc: [`Ranks::spreads_setup`]), the
//! followers get the mesh without its cells (its groups' facets, the places of their
//! nodes and the centroid of every node), and, once rank 0 has partitioned the nodes, each
//! its part of the cells alone (`Ranks::cells_of_first`): those its assembly reads, with
//! one of its own nodes (`petsc::Layout::cell_parts`), in the whole's order, so that each
//! entry it assembles sums the same terms in the same order; their vertices' places;
//! their gmsh entities, materials and regions, which rank 0 makes of the whole mesh; and
//! each group's cells among them. A cell with nodes in several parts goes to each rank
//! that reads it. So no follower holds the whole mesh's cells, nor every node's place
//! (`mesh::Places`), whose bytes every follower had received and held through its setup.

use std::os::unix::ffi::{OsStrExt, OsStringExt};
use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::{mpi, Ranks};
#[cfg(feature = "petsc")]
use crate::fem::{CellMaterials, Discretization};
use crate::mesh::{increasing, Group, Mesh, Places};
#[cfg(feature = "petsc")]
use crate::scene::Scene;
use crate::{Error, Result};

/// What a rank needs to receive a mesh's arrays: their lengths, and the small fields.
#[derive(Serialize, Deserialize)]
struct Shape {
    /// The path's bytes (a path need not be UTF-8).
    path: Vec<u8>,
    dim: usize,
    nodes: usize,
    triangles: usize,
    tetrahedra: usize,
    cell_entity: usize,
    flipped: usize,
    groups: Vec<GroupShape>,
    other_groups: Vec<(usize, i32, Option<String>)>,
}

#[derive(Serialize, Deserialize)]
struct GroupShape {
    dim: usize,
    tag: i32,
    name: Option<String>,
    defect: Option<String>,
    facets: usize,
    faces: usize,
    cells: usize,
}

impl Shape {
    fn of(mesh: &Mesh) -> Shape {
        // Every field named, so that a field added to the mesh is not forgotten here.
        let Mesh {
            path,
            dim,
            nodes,
            triangles,
            tetrahedra,
            groups,
            flipped,
            other_groups,
            cell_entity,
        } = mesh;
        Shape {
            path: path.as_os_str().as_bytes().to_vec(),
            dim: *dim,
            nodes: nodes.len(),
            triangles: triangles.len(),
            tetrahedra: tetrahedra.len(),
            cell_entity: cell_entity.len(),
            flipped: *flipped,
            groups: groups.iter().map(GroupShape::of).collect(),
            other_groups: other_groups.clone(),
        }
    }

    /// A mesh of this shape, its arrays zero, to receive them; without its cells where
    /// `cells` is false (a follower's part comes later: `Ranks::cells_of_first`).
    fn empty(self, cells: bool) -> Mesh {
        let n = |len: usize| if cells { len } else { 0 };
        Mesh {
            path: PathBuf::from(std::ffi::OsString::from_vec(self.path)),
            dim: self.dim,
            nodes: Places::default(),
            triangles: vec![[0; 3]; n(self.triangles)],
            tetrahedra: vec![[0; 4]; n(self.tetrahedra)],
            groups: (self.groups.into_iter())
                .map(|g| GroupShape::empty(g, cells))
                .collect(),
            flipped: self.flipped,
            other_groups: self.other_groups,
            cell_entity: vec![0; n(self.cell_entity)],
        }
    }
}

impl GroupShape {
    fn of(group: &Group) -> GroupShape {
        let Group {
            dim,
            tag,
            name,
            facets,
            faces,
            cells,
            defect,
        } = group;
        GroupShape {
            dim: *dim,
            tag: *tag,
            name: name.clone(),
            defect: defect.clone(),
            facets: facets.len(),
            faces: faces.len(),
            cells: cells.len(),
        }
    }

    fn empty(self, cells: bool) -> Group {
        Group {
            dim: self.dim,
            tag: self.tag,
            name: self.name,
            facets: vec![[0; 2]; self.facets],
            faces: vec![[0; 3]; self.faces],
            cells: vec![0; if cells { self.cells } else { 0 }],
            defect: self.defect,
        }
    }
}

/// The mesh's arrays as bytes, in the order in which they are sent; those of its cells
/// (the cells, their entities and the cell groups') only where `cells`.
fn arrays(mesh: &mut Mesh, cells: bool) -> Vec<&mut [u8]> {
    use bytemuck::cast_slice_mut as bytes;
    let mut out: Vec<&mut [u8]> = Vec::new();
    if cells {
        out.extend([
            bytes(&mut mesh.triangles),
            bytes(&mut mesh.tetrahedra),
            bytes(&mut mesh.cell_entity),
        ]);
    }
    for g in &mut mesh.groups {
        out.extend([bytes(&mut g.facets), bytes(&mut g.faces)]);
        if cells {
            out.push(bytes(&mut g.cells));
        }
    }
    out
}

/// Every node's place of rank 0's `mesh` (`first`; on the others, none yet), on
/// every rank (collective; `n` nodes).
fn every_place_of_first(mesh: &mut Mesh, (n, first): (usize, bool)) -> Result<()> {
    let mut all = match first {
        true => std::mem::take(&mut mesh.nodes).into_all(),
        false => vec![[0.0; 3]; n],
    };
    mpi::from_rank0_bytes(bytemuck::cast_slice_mut(&mut all))?;
    mesh.nodes = Places::every(all);
    Ok(())
}

/// Of the places of rank 0's `mesh` (`first`), on a follower, which has its groups and
/// none yet, those of its groups' nodes and the centroid of every node (collective; `n`
/// nodes): what its setup reads of them before its part of the cells comes, with their
/// nodes' places (`Ranks::cells_of_first`).
fn group_places_of_first(mesh: &mut Mesh, (n, first): (usize, bool)) -> Result<()> {
    let nodes = group_nodes(mesh);
    let (mut places, mut centre) = match first {
        true => (
            nodes.iter().map(|&p| mesh.nodes[p as usize]).collect(),
            mesh.nodes.centre(),
        ),
        false => (vec![[0.0; 3]; nodes.len()], [0.0; 3]),
    };
    mpi::from_rank0_bytes(bytemuck::cast_slice_mut(&mut places))?;
    mpi::from_rank0_bytes(bytemuck::cast_slice_mut(&mut centre))?;
    if !first {
        mesh.nodes = Places::held(n, (nodes, places), centre);
    }
    Ok(())
}

/// The nodes of `mesh`'s boundary groups' facets, increasing: those whose places the
/// setup of a run reads (its conditions', Γ3's, the tractions').
fn group_nodes(mesh: &Mesh) -> Vec<u32> {
    let facets = mesh.groups.iter().flat_map(|g| {
        let edges = g.facets.iter().flatten();
        edges.chain(g.faces.iter().flatten())
    });
    increasing(facets.map(|&p| p as u32).collect())
}

impl Ranks {
    /// The mesh rank 0 read (`mine`: `Some` on rank 0, `None` on a follower) on every rank
    /// (collective on several: every rank calls it, once the ranks agreed on their setup
    /// so far); on a follower without its cells where `cells` is false.
    pub fn mesh_of_first(&self, mine: Option<Mesh>, cells: bool) -> Result<Mesh> {
        let failed = |e: &dyn std::fmt::Display| Error::solve(format!("the mesh of rank 0: {e}"));
        if self.size == 1 {
            return mine.ok_or_else(|| failed(&"one rank, and it read none"));
        }
        let shape = match &mine {
            Some(mesh) => serde_json::to_string(&Shape::of(mesh)).map_err(|e| failed(&e))?,
            None => String::new(),
        };
        let shape: Shape =
            serde_json::from_str(&self.first_says_text(&shape)?).map_err(|e| failed(&e))?;
        let n = (shape.nodes, self.is_first());
        let mut mesh = mine.unwrap_or_else(|| shape.empty(cells));
        for array in arrays(&mut mesh, cells) {
            mpi::from_rank0_bytes(array)?;
        }
        match cells {
            true => every_place_of_first(&mut mesh, n)?,
            false => group_places_of_first(&mut mesh, n)?,
        }
        Ok(mesh)
    }

    /// Every rank's setup up to its mesh (`read`: the mesh on rank 0, `None` on a
    /// follower) agreed ([`Ranks::agree`]), and then the mesh that rank 0 read on every
    /// rank ([`Ranks::mesh_of_first`]): on a follower of a run whose setup spreads
    /// ([`Ranks::spreads_setup`], of the scene that `scene` reads of what it read) without
    /// its cells, which come with the partition (`Ranks::cells_of_first`).
    pub fn with_mesh_of_first<T>(
        &self,
        read: Result<(T, Option<Mesh>)>,
        scene: impl FnOnce(&T) -> &crate::scene::Scene,
    ) -> Result<(T, Mesh)> {
        let (t, mine) = self.agree(read)?;
        let mesh = self.mesh_of_first(mine, !self.spreads_setup(scene(&t)))?;
        // Rank 0's reading freed the file's bytes and the reader's arrays: they go back to
        // the system before the assembly, its peak (docs/cluster.md, "Memory per rank").
        crate::resources::return_freed_memory();
        Ok((t, mesh))
    }
}

/// What rank 0 hands each follower of the mesh's cells with the partition: per rank (rank
/// 0's empty), the vertices of its part's cells (dim + 1 a cell), their gmsh entities,
/// their materials (`CellMaterials::of_cell`), their regions (none without
/// `[[material.region]]`), and of each group of the mesh, in order, the count and the
/// indices in the part of its cells, and the places of its cells' vertices (in increasing
/// node order, each as six words); then the distinct materials' entries
/// (`CellMaterials::distinct_entries`), the same for every rank.
#[cfg(feature = "petsc")]
struct Parts {
    vertices: Vec<Vec<u32>>,
    entities: Vec<Vec<u32>>,
    of_cell: Vec<Vec<u32>>,
    region: Vec<Vec<u32>>,
    groups: Vec<Vec<u32>>,
    places: Vec<Vec<u32>>,
    entries: Vec<u32>,
}

#[cfg(feature = "petsc")]
impl Parts {
    /// Each follower's part of `mesh` (its cells: `layout.cell_parts`) with what it needs of
    /// them, `materials` those of the whole mesh's cells.
    fn of(
        mesh: &Mesh,
        (disc, layout): (&Discretization, &crate::petsc::Layout),
        (materials, scene): (&CellMaterials, &Scene),
    ) -> Result<Parts> {
        if u32::try_from(mesh.n_cells()).is_err() {
            return Err(Error::input(format!(
                "mesh '{}': more cells than a run over several MPI ranks numbers (2^32)",
                mesh.path.display()
            )));
        }
        let ids = layout.cell_parts(disc, crate::fem::CellSource::Made(mesh));
        // Cell c's vertices, read in place (no copy of the whole mesh's cells).
        let (cells, dim) = crate::fem::mesh_cells(mesh);
        let vertices = |c: usize| &cells[c * (dim + 1)..(c + 1) * (dim + 1)];
        // Of each part, `f`'s values of each of its cells, in order.
        let each = |f: &dyn Fn(usize, &mut Vec<u32>)| -> Vec<Vec<u32>> {
            let part = |ids: &Vec<u32>| {
                let mut values = Vec::new();
                ids.iter().for_each(|&c| f(c as usize, &mut values));
                values
            };
            ids.iter().map(part).collect()
        };
        let region = &materials.region;
        let vertices = each(&|c, v| v.extend(vertices(c).iter().map(|&p| p as u32)));
        let places_of = |part: &Vec<u32>| -> Vec<u32> {
            let at = |p: &u32| mesh.nodes[*p as usize];
            bytemuck::cast_slice(&increasing(part.clone()).iter().map(at).collect::<Vec<_>>())
                .to_vec()
        };
        let parts = Parts {
            places: vertices.iter().map(places_of).collect(),
            vertices,
            entities: each(&|c, v| v.push(mesh.cell_entity[c] as u32)),
            of_cell: each(&|c, v| v.push(materials.of_cell[c])),
            region: each(&|c, v| v.extend(region.get(c).map(|&r| r as u32))),
            groups: groups_of_parts(mesh, &ids),
            entries: materials.distinct_entries(scene),
        };
        // MPI counts a part's values in an int (`petsc::scatter_from_first`).
        let counted = |p: &Vec<u32>| i32::try_from(p.len()).is_ok();
        let mut values = (parts.vertices.iter().chain(&parts.groups)).chain(&parts.places);
        if !values.all(counted) {
            return Err(Error::input(format!(
                "mesh '{}': a rank's part of the mesh holds more than 2^31 values; run it on \
                 more ranks",
                mesh.path.display()
            )));
        }
        Ok(parts)
    }
}

/// Of each group of `mesh` (in order), in each part (`ids`: the cells of each, increasing),
/// the count and the indices in the part of the group's cells: in one pass over each
/// part's cells, which groups hold a cell read from a table of every cell's groups.
#[cfg(feature = "petsc")]
fn groups_of_parts(mesh: &Mesh, ids: &[Vec<u32>]) -> Vec<Vec<u32>> {
    let mut start = vec![0usize; mesh.n_cells() + 1];
    let held = || {
        mesh.groups
            .iter()
            .enumerate()
            .flat_map(|(g, group)| group.cells.iter().map(move |&c| (g, c)))
    };
    held().for_each(|(_, c)| start[c + 1] += 1);
    (1..start.len()).for_each(|c| start[c] += start[c - 1]);
    let (mut of_cell, mut at) = (vec![0u32; start[mesh.n_cells()]], start.clone());
    for (g, c) in held() {
        of_cell[at[c]] = g as u32;
        at[c] += 1;
    }
    let part = |ids: &Vec<u32>| {
        let mut groups = vec![Vec::new(); mesh.groups.len()];
        for (k, &c) in ids.iter().enumerate() {
            let c = c as usize;
            of_cell[start[c]..start[c + 1]]
                .iter()
                .for_each(|&g| groups[g as usize].push(k as u32));
        }
        groups
            .into_iter()
            .flat_map(|g| std::iter::once(g.len() as u32).chain(g))
            .collect()
    };
    ids.iter().map(part).collect()
}

#[cfg(feature = "petsc")]
impl Ranks {
    /// The materials of this rank's cells, of a run whose setup spreads
    /// ([`Ranks::spreads_setup`]), once rank 0 has partitioned the nodes (`layout`;
    /// collective): rank 0 makes the whole mesh's (an error of them goes to the others as
    /// its exit status) and hands each follower its part of the mesh's cells
    /// (`Parts`), which the follower's `mesh`, received without its cells
    /// ([`Ranks::with_mesh_of_first`]), now holds, numbered in the whole's order. So no
    /// follower holds the whole mesh's cells, nor checks the regions of a part. Where
    /// `layout` was sent without the rows' order (not `every_row`), each follower gets the
    /// rows of its part's unknowns and Γ3's alone too (`Layout::keep_rows_of_first`).
    pub fn cells_of_first(
        &self,
        mesh: &mut Mesh,
        scene: &Scene,
        (disc, layout, every_row): (&Discretization, &mut crate::petsc::Layout, bool),
    ) -> Result<CellMaterials> {
        let made = self.is_first().then(|| -> Result<_> {
            let materials = CellMaterials::new(mesh, scene)?;
            let parts = Parts::of(mesh, (disc, &*layout), (&materials, scene))?;
            Ok((materials, parts))
        });
        let code = match &made {
            Some(Err(e)) => e.exit_code(),
            _ => 0,
        };
        if let code @ 1.. = self.first_says(code)? {
            return Err(match made {
                Some(Err(e)) => e,
                _ => Error::Elsewhere(code),
            });
        }
        let (materials, parts) = match made {
            Some(made) => {
                let (materials, parts) = made?;
                (Some(materials), Some(parts))
            }
            None => (None, None),
        };
        let field = |f: fn(&Parts) -> &[Vec<u32>]| mpi::scatter_from_first(parts.as_ref().map(f));
        let (vertices, entities) = (field(|p| &p.vertices)?, field(|p| &p.entities)?);
        let (of_cell, region) = (field(|p| &p.of_cell)?, field(|p| &p.region)?);
        let (groups, places) = (field(|p| &p.groups)?, field(|p| &p.places)?);
        // A follower's part's nodes, sorted once for its rows and its places.
        let nodes = match self.is_first() {
            true => Vec::new(),
            false => increasing(vertices.clone()),
        };
        if !every_row {
            let of_part = |vertices: &[u32]| crate::petsc::part_unknowns(disc, vertices);
            let mine = match self.is_first() {
                true => Vec::new(),
                false => of_part(&nodes),
            };
            let kept_of = |r: usize| of_part(&parts.as_ref().expect("rank 0's").vertices[r]);
            layout.keep_rows_of_first((self.is_first(), mine), kept_of)?;
        }
        let mut entries = parts.map_or(Vec::new(), |p| p.entries);
        let count = self.first_says(entries.len() as i32)?;
        entries.resize(count as usize, 0);
        mpi::from_rank0_bytes(bytemuck::cast_slice_mut(&mut entries))?;
        if let Some(materials) = materials {
            return Ok(materials);
        }
        mesh.nodes = (mesh.nodes).joined(&nodes, &bytemuck::pod_collect_to_vec(&places));
        hold_part(mesh, (vertices, entities), groups);
        let region = region.into_iter().map(|r| r as i32).collect();
        Ok(CellMaterials::of_part(scene, &entries, of_cell, region))
    }
}

/// A follower's `mesh`, received without its cells, with its part's: their vertices and
/// entities, and of each group the cells it holds among them (`groups`: count, indices).
#[cfg(feature = "petsc")]
fn hold_part(mesh: &mut Mesh, (vertices, entities): (Vec<u32>, Vec<u32>), groups: Vec<u32>) {
    fn cells<const N: usize>(vertices: &[u32]) -> Vec<[usize; N]> {
        let cell = |c: &[u32]| std::array::from_fn(|i| c[i] as usize);
        vertices.chunks_exact(N).map(cell).collect()
    }
    match mesh.dim {
        2 => mesh.triangles = cells(&vertices),
        _ => mesh.tetrahedra = cells(&vertices),
    }
    mesh.cell_entity = entities.into_iter().map(|e| e as i32).collect();
    let mut at = 0;
    for g in &mut mesh.groups {
        let count = groups[at] as usize;
        g.cells = groups[at + 1..at + 1 + count]
            .iter()
            .map(|&k| k as usize)
            .collect();
        at += 1 + count;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A mesh through its shape's JSON and its arrays' bytes is the same mesh, every field
    /// (what a follower receives, without MPI).
    #[test]
    fn a_mesh_through_its_shape_and_bytes_is_the_same_mesh() {
        let files = [
            "meshes/paper/rect_008.msh",
            "meshes/bimaterial/bimaterial.msh",
            "meshes/3d/block_008.msh",
        ];
        for file in files {
            let mut sent = Mesh::read(std::path::Path::new(file)).unwrap();
            let json = serde_json::to_string(&Shape::of(&sent)).unwrap();
            let mut received = serde_json::from_str::<Shape>(&json).unwrap().empty(true);
            assert_ne!(received, sent, "{file}: the empty mesh is not the mesh yet");
            for (to, from) in arrays(&mut received, true)
                .into_iter()
                .zip(arrays(&mut sent, true))
            {
                to.copy_from_slice(from);
            }
            // The places go on their own (`every_place_of_first`, `group_places_of_first`):
            // a follower finds the groups' nodes whose places it receives as rank 0 does.
            assert_eq!(group_nodes(&received), group_nodes(&sent), "{file}");
            assert_ne!(received, sent, "{file}: the mesh without its places");
            received.nodes = Places::every(sent.nodes.all().to_vec());
            assert_eq!(received, sent, "{file}");
        }
    }
}
