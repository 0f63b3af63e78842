//! The material of each cell: `[material]`'s, or on the cells of a `[[material.region]]`'s
//! group the region's. A (4.1) and B (4.2) then vary from cell to cell, and so do the
//! element matrices of K_A and K_B, the stress and the stability limit. R = r·I: a region
//! with a kernel of its own puts its cells into a memory group of their own (group g ≥ 1,
//! `Physics::memory_group`), with its own K_R and memory state; the other cells are in the
//! body's group 0 (or in none, without relaxation).
//!
//! The cells are grouped by distinct material (A, B), not by region: regions whose
//! materials are equal, or equal to `[material]`'s, share one entry, so a scene whose
//! regions repeat `[material]` computes exactly what the scene without them computes, bit
//! for bit. An element may lie in one region only.

use super::element::Isotropic;
use crate::mesh::{fmt_point, Mesh};
use crate::scene::{Material, Model, Scene};
use crate::{Error, Result};

/// The pointwise tensors of one material: A, and B (None when E = 0 or elasticity is off),
/// and the memory group whose kernel r gives R = r·I (None without a relaxation term).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stiffness {
    pub a: Isotropic,
    pub b: Option<Isotropic>,
    pub memory: Option<usize>,
}

impl Stiffness {
    /// A and B of `m` under `model` (plane stress as (4.2); plane strain and 3D with the 3D
    /// Lamé coefficient), with the memory group `memory`.
    pub fn of(m: &Material, model: Model, memory: Option<usize>) -> Self {
        let b = (m.elasticity)
            .filter(|(e, _)| *e > 0.0)
            .map(|(e, nu)| match model {
                Model::PlaneStress => Isotropic::plane_stress(e, nu),
                Model::PlaneStrain | Model::ThreeD => Isotropic::lame(e, nu),
            });
        Stiffness {
            a: Isotropic::viscosity(m.theta, m.zeta),
            b,
            memory,
        }
    }

    /// B, or the zero tensor without elasticity.
    pub fn b_or_zero(&self) -> Isotropic {
        self.b.unwrap_or(Isotropic { a: 0.0, b: 0.0 })
    }
}

/// Which material each cell has.
#[derive(Default)]
pub struct CellMaterials {
    /// The distinct materials of the cells, in the order of their first cell.
    pub distinct: Vec<Stiffness>,
    /// Each cell's index into `distinct`.
    pub of_cell: Vec<u32>,
    /// Each cell's region: 0 outside every region, i for the i-th `[[material.region]]`
    /// entry (from 1); empty for a scene without regions.
    pub region: Vec<i32>,
}

impl CellMaterials {
    /// The materials of the cells of `mesh` (in the order of `Mesh::triangles` or
    /// `Mesh::tetrahedra`) under `scene`: each region's group resolved among the groups of
    /// the body's dimension; overlapping regions are refused.
    pub fn new(mesh: &Mesh, scene: &Scene) -> Result<Self> {
        let regions = &scene.physics.regions;
        let region = match regions.is_empty() {
            true => Vec::new(),
            false => region_of_cells(mesh, scene)?,
        };
        let by_entry = by_entry(scene);
        let mut distinct: Vec<Stiffness> = Vec::new();
        let of_cell = (0..mesh.n_cells())
            .map(|c| {
                let s = by_entry[region.get(c).map_or(0, |&r| r as usize)];
                let i = distinct.iter().position(|d| *d == s).unwrap_or_else(|| {
                    distinct.push(s);
                    distinct.len() - 1
                });
                i as u32
            })
            .collect();
        Ok(CellMaterials {
            distinct,
            of_cell,
            region,
        })
    }

    /// The entry of each distinct material: 0 for `[material]`, i for the i-th
    /// `[[material.region]]`, the first whose material it is. What rank 0 hands a follower
    /// of `distinct` ([`CellMaterials::of_part`]).
    pub fn distinct_entries(&self, scene: &Scene) -> Vec<u32> {
        let by_entry = by_entry(scene);
        let entry = |d: &Stiffness| by_entry.iter().position(|s| s == d).unwrap_or(0) as u32;
        self.distinct.iter().map(entry).collect()
    }

    /// The materials of a part of the cells, as rank 0 hands them to a follower with its
    /// part of the mesh (`Ranks::cells_of_first`): the whole mesh's distinct materials by
    /// their `entries` ([`CellMaterials::distinct_entries`]), made again from `scene`, the
    /// same bits, and each cell's index into them and its region. So every rank has the
    /// same distinct materials, whichever its part holds.
    pub fn of_part(scene: &Scene, entries: &[u32], of_cell: Vec<u32>, region: Vec<i32>) -> Self {
        let by_entry = by_entry(scene);
        let distinct = entries.iter().map(|&e| by_entry[e as usize]).collect();
        CellMaterials {
            distinct,
            of_cell,
            region,
        }
    }

    /// The material of cell `c`.
    pub fn of(&self, c: usize) -> Stiffness {
        self.distinct[self.of_cell[c] as usize]
    }

    /// Whether any cell has elasticity (K_B is assembled).
    pub fn elastic(&self) -> bool {
        self.distinct.iter().any(|s| s.b.is_some())
    }

    /// Whether any cell has a memory term (K_R is assembled).
    pub fn memory(&self) -> bool {
        self.distinct.iter().any(|s| s.memory.is_some())
    }

    /// The number of cells in region i (i = 1.. for the entries; 0 outside every region).
    pub fn count(&self, i: usize) -> usize {
        self.region.iter().filter(|&&r| r as usize == i).count()
    }
}

/// The material of `[material]` (first) and of each `[[material.region]]` entry.
fn by_entry(scene: &Scene) -> Vec<Stiffness> {
    let (model, physics) = (scene.mesh.model, &scene.physics);
    (physics.materials().enumerate())
        .map(|(i, m)| Stiffness::of(m, model, physics.memory_group(i.checked_sub(1))))
        .collect()
}

/// `check`'s lines on the regions (none for a scene without): each entry's group, its
/// element count and its material, then the elements outside every region and how many
/// distinct materials the cells hold.
pub fn summary(materials: &CellMaterials, scene: &Scene) -> Vec<String> {
    if materials.region.is_empty() {
        return Vec::new();
    }
    let cells = ["triangles", "tetrahedra"][scene.mesh.model.dim() - 2];
    let group = |i: usize| scene.physics.memory_group(Some(i)).unwrap_or(0);
    let regions = scene.physics.regions.iter().enumerate();
    let mut lines: Vec<String> = regions
        .map(|(i, r)| {
            let n = materials.count(i + 1);
            let kernel = match &r.relaxation {
                None => String::new(),
                Some(own) if own.kernel.is_none() => ", no relaxation".into(),
                Some(_) => format!(", its own kernel (memory group {})", group(i)),
            };
            format!(
                "{}: '{}', {n} {cells}, {}{kernel}",
                i + 1,
                r.on,
                describe(&r.material)
            )
        })
        .collect();
    lines.push(format!(
        "0: outside every region, {} {cells}, [material] {}; {} distinct materials",
        materials.count(0),
        describe(&scene.physics.material),
        materials.distinct.len()
    ));
    lines
}

/// "θ = …, ζ = …, E = …, ν = …" (or "no elasticity").
fn describe(m: &Material) -> String {
    let elasticity = match m.elasticity {
        Some((e, nu)) => format!("E = {e}, ν = {nu}"),
        None => "no elasticity".into(),
    };
    format!("θ = {}, ζ = {}, {elasticity}", m.theta, m.zeta)
}

/// The region of every cell (0 outside all): each entry's group, which must be one of the
/// body's dimension; a cell in two regions is refused, naming both and where.
fn region_of_cells(mesh: &Mesh, scene: &Scene) -> Result<Vec<i32>> {
    let file = scene.path.display();
    let mut region = vec![0i32; mesh.n_cells()];
    for (i, r) in scene.physics.regions.iter().enumerate() {
        let key = format!("material.region[{i}].on");
        let g = (mesh.cell_group(&r.on))
            .map_err(|e| Error::input(format!("{file}: key '{key}': {e}")))?;
        let shared: Vec<usize> = (g.cells.iter().copied())
            .filter(|&c| region[c] != 0)
            .collect();
        if let Some(&c) = shared.first() {
            let j = region[c] as usize - 1;
            let other = &scene.physics.regions[j].on;
            return Err(Error::input(format!(
                "{file}: keys 'material.region[{j}].on' and '{key}': the groups '{other}' and \
                 '{}' share {} elements (the first with its centroid at {}): an element takes \
                 the material of one region; make the groups disjoint in gmsh, or merge the \
                 two entries into one",
                r.on,
                shared.len(),
                fmt_point(centroid(mesh, c), mesh.dim)
            )));
        }
        for &c in &g.cells {
            region[c] = i as i32 + 1;
        }
    }
    Ok(region)
}

/// The centroid of cell `c`.
fn centroid(mesh: &Mesh, c: usize) -> [f64; 3] {
    let nodes: Vec<usize> = match mesh.dim {
        2 => mesh.triangles[c].to_vec(),
        _ => mesh.tetrahedra[c].to_vec(),
    };
    let mut p = [0.0; 3];
    for &n in &nodes {
        for (pk, xk) in p.iter_mut().zip(mesh.nodes[n]) {
            *pk += xk / nodes.len() as f64;
        }
    }
    p
}
