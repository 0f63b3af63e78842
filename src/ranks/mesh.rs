//! The mesh rank 0 reads, handed to the other ranks: a follower never reads the mesh file.
//!
//! Rank 0 reads and checks the file (`Mesh::read`). Once the ranks agree that every setup
//! so far succeeded ([`Ranks::agree`]), it broadcasts the mesh in two parts: its [`Shape`]
//! (its arrays' lengths, the groups' tags and names, the file's path) as JSON, and then
//! each array's bytes as they lie in memory, into arrays of that shape on the others
//! ([`Ranks::mesh_of_first`]). So a follower holds the mesh alone, never the file's bytes
//! nor the reader's arrays, where reading a mesh peaks, and the mesh is the same bits on
//! every rank. The bytes are the ranks' own layout in memory: the ranks of a run are one build on one
//! architecture, as MPI runs of one program are.

use std::os::unix::ffi::{OsStrExt, OsStringExt};
use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::{mpi, Ranks};
use crate::mesh::{Group, Mesh};
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

    /// A mesh of this shape, its arrays zero, to receive them.
    fn empty(self) -> Mesh {
        Mesh {
            path: PathBuf::from(std::ffi::OsString::from_vec(self.path)),
            dim: self.dim,
            nodes: vec![[0.0; 3]; self.nodes],
            triangles: vec![[0; 3]; self.triangles],
            tetrahedra: vec![[0; 4]; self.tetrahedra],
            groups: self.groups.into_iter().map(GroupShape::empty).collect(),
            flipped: self.flipped,
            other_groups: self.other_groups,
            cell_entity: vec![0; self.cell_entity],
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

    fn empty(self) -> Group {
        Group {
            dim: self.dim,
            tag: self.tag,
            name: self.name,
            facets: vec![[0; 2]; self.facets],
            faces: vec![[0; 3]; self.faces],
            cells: vec![0; self.cells],
            defect: self.defect,
        }
    }
}

/// The mesh's arrays as bytes, in the order in which they are sent.
fn arrays(mesh: &mut Mesh) -> Vec<&mut [u8]> {
    use bytemuck::cast_slice_mut as bytes;
    let mut out: Vec<&mut [u8]> = vec![
        bytes(&mut mesh.nodes),
        bytes(&mut mesh.triangles),
        bytes(&mut mesh.tetrahedra),
        bytes(&mut mesh.cell_entity),
    ];
    for g in &mut mesh.groups {
        out.extend([
            bytes(&mut g.facets),
            bytes(&mut g.faces),
            bytes(&mut g.cells),
        ]);
    }
    out
}

impl Ranks {
    /// The mesh rank 0 read (`mine`: `Some` on rank 0, `None` on a follower) on every rank
    /// (collective on several: every rank calls it, once the ranks agreed on their setup
    /// so far).
    pub fn mesh_of_first(&self, mine: Option<Mesh>) -> Result<Mesh> {
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
        let mut mesh = mine.unwrap_or_else(|| shape.empty());
        for array in arrays(&mut mesh) {
            mpi::from_rank0_bytes(array)?;
        }
        Ok(mesh)
    }

    /// Every rank's setup up to its mesh (`read`: the mesh on rank 0, `None` on a
    /// follower) agreed ([`Ranks::agree`]), and then the mesh that rank 0 read on every
    /// rank ([`Ranks::mesh_of_first`]).
    pub fn with_mesh_of_first<T>(&self, read: Result<(T, Option<Mesh>)>) -> Result<(T, Mesh)> {
        let (t, mine) = self.agree(read)?;
        let mesh = self.mesh_of_first(mine)?;
        // Rank 0's reading freed the file's bytes and the reader's arrays: they go back to
        // the system before the assembly, its peak (docs/cluster.md, "Memory per rank").
        crate::resources::return_freed_memory();
        Ok((t, mesh))
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
            let mut received = serde_json::from_str::<Shape>(&json).unwrap().empty();
            assert_ne!(received, sent, "{file}: the empty mesh is not the mesh yet");
            for (to, from) in arrays(&mut received).into_iter().zip(arrays(&mut sent)) {
                to.copy_from_slice(from);
            }
            assert_eq!(received, sent, "{file}");
        }
    }
}
