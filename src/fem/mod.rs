//! Discretization: P1 triangles (2D) or tetrahedra (3D), the dofs of V^h (d per node; the
//! dofs held at zero by a Dirichlet condition eliminated, prescribed ones numbered after the
//! free ones: `constraints`), the stiffness matrices K_A, K_B, K_R, the load vector ⟨f_n, ·⟩,
//! the given-normal-stress load g_F and the nodal constraint rows on Γ3,1 (n_i·w_i ≤ 0) and
//! Γ3,2 (weight c_i of |w_τ,i|, with w_τ,i in the tangent line (2D) or plane (3D)). A and
//! B are those of each cell's material (`materials`: `[material]`, or a region's).

pub mod constraints;
pub mod element;
pub mod loads;
pub mod materials;
mod pair;
pub mod reactions;

use crate::expr::Point;
use crate::mesh::{cross, increasing, norm, Group, Mesh};
pub use crate::mesh::{Places, Points};
use crate::scene::{Friction, MeshChoice, Model, Scene};
use crate::{Error, Result};
pub use constraints::{DofIndices, Frames, Numbering, Prescribed};
pub use element::{Cell, Isotropic};
use faer::sparse::{SparseColMat, SymbolicSparseColMat};
pub use loads::{Keep, Loads};
pub use materials::{CellMaterials, Stiffness};
pub use pair::{RowsPair, SymmetricPair};
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::path::Path;

/// Sparse symmetric matrix (both triangles stored), columns compressed.
pub type Sparse = SparseColMat<usize, f64>;

/// y += alpha · A x for a matrix in free-dof numbering.
pub fn mul_add(a: &Sparse, x: &[f64], alpha: f64, y: &mut [f64]) {
    let a = a.as_ref();
    let (cp, ri, v) = (a.symbolic().col_ptr(), a.symbolic().row_idx(), a.val());
    for j in 0..a.ncols() {
        let xj = alpha * x[j];
        if xj != 0.0 {
            for p in cp[j]..cp[j + 1] {
                y[ri[p]] += v[p] * xj;
            }
        }
    }
}

/// One nodal row of the constraint operator P: the functional w ↦ dir·w_i at a node.
/// `dim` components are used (2 in 2D, 3 in 3D); unused entries are 0.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NodalRow {
    pub node: usize,
    /// Free indices of the node's x, y (and z) dofs.
    pub dofs: [usize; 3],
    /// n_i on Γ3,1 (constraint n_i·w_i ≤ 0); a unit tangent τ_i on Γ3,2 (in 3D each friction
    /// node has two rows, τ_i1 and τ_i2, spanning its tangent plane: w_τ,i = Σ_k (τ_ik·w_i) τ_ik).
    pub dir: [f64; 3],
    /// The number of components: the spatial dimension.
    pub dim: usize,
    /// Γ3,2: c_i = ∫ μF φ_i da, the bound of the friction multiplier. Γ3,1: +∞.
    pub bound: f64,
    /// ∫ φ_i da over the group: turns the nodal multiplier into a traction.
    pub area: f64,
}

impl NodalRow {
    /// The (free dof, coefficient) pairs of the row with a nonzero coefficient: the dofs it
    /// touches (a flat boundary's normal touches one dof of a node, its tangents two; so
    /// the block C ordered last in the factor holds only these).
    pub fn entries(&self) -> impl Iterator<Item = (usize, f64)> + '_ {
        self.dofs[..self.dim]
            .iter()
            .copied()
            .zip(self.dir[..self.dim].iter().copied())
            .filter(|&(_, c)| c != 0.0)
    }

    pub fn apply(&self, w: &[f64]) -> f64 {
        self.entries().map(|(d, c)| c * w[d]).sum()
    }

    /// w += z · Pᵀ_row.
    pub fn add_transpose(&self, z: f64, w: &mut [f64]) {
        for (d, c) in self.entries() {
            w[d] += z * c;
        }
    }
}

/// A vector's values at the dofs where it is not zero, increasing: one that lives on a
/// boundary.
pub type DofValues = Vec<(usize, f64)>;

/// Everything the time loop needs from space: matrices, loads, boundary operators.
pub struct Discretization {
    /// Spatial dimension d (2 or 3): d dofs per node.
    pub dim: usize,
    /// Every node's place; on a follower rank of several, past its setup, those it reads
    /// alone ([`Discretization::keep_places`]).
    pub nodes: Places,
    /// The triangles (2D) or tetrahedra (3D) on one process; none on a rank of several
    /// ([`Discretization::assembled`], [`Discretization::forget_cells`]), which reads
    /// them through [`Discretization::cell_source`].
    pub cells: Vec<Cell>,
    /// On rank 0 of several, each cell's dim + 1 vertices ([`Hold::Vertices`]); else none.
    vertices: Vec<u32>,
    /// The mesh's cells, counted before any rank lets go of them (summary.json's
    /// `elements`).
    pub cells_in_mesh: usize,
    /// Global dof d·node + component → index: free dofs 0..n_free, prescribed dofs
    /// n_free..n_dofs; none where a condition holds the dof at zero (Γ1).
    pub free: DofIndices,
    /// The unknowns of the step problem.
    pub n_free: usize,
    /// The length of the vectors the loop keeps: n_free plus the prescribed dofs.
    pub n_dofs: usize,
    /// The prescribed dofs (`[[dirichlet]]` values not identically zero), in index order.
    pub prescribed: Vec<Prescribed>,
    /// Every held global dof (clamped, held at zero or prescribed), increasing, with the
    /// condition that holds it (`Numbering::held_by`).
    pub held: Vec<(usize, constraints::Source)>,
    /// The nodes whose dofs are components in a frame of their own (an inclined `normal`
    /// condition holds them; `constraints::Frames`): every vector and row is in these
    /// components there, [`Discretization::nodal`] turns them back into x, y, z.
    pub frames: Frames,
    /// Each cell's A (4.1) and B (4.2); R's constant part I (the same in every cell).
    pub materials: CellMaterials,
    pub r: Isotropic,
    /// K_A on the free dofs (n_free); K_B on all n_dofs (the free and the prescribed); K_R
    /// of each memory group g, on the cells of group g (`Stiffness::memory`), on all n_dofs
    /// (none where no cell has a memory term). All share one pattern.
    pub k_a: Sparse,
    pub k_b: Option<Sparse>,
    pub k_r: Vec<Sparse>,
    /// K_A on all n_dofs, when there are prescribed dofs (its free-by-prescribed block moves
    /// their velocities to the right side).
    pub k_a_all: Option<Sparse>,
    pub loads: Loads,
    /// g_F_i = ∫_{Γ3,2} F φ_i ν da at the dofs i where it is not zero, increasing (it lives
    /// on Γ3,2: a vector of the whole would cost every rank 8 bytes a dof); empty when F =
    /// 0 or no friction group.
    pub g_f: DofValues,
    /// Rows n_i on Γ3,1 (empty when contact is off).
    pub contact: Vec<NodalRow>,
    /// Rows τ_i (2D) or τ_i1, τ_i2 (3D, consecutive) at the Γ3,2 nodes with c_i > 0 (empty
    /// when friction is off or μF = 0).
    pub friction: Vec<NodalRow>,
    /// The largest kink (degrees) between facet normals at a node of Γ3,1 (0 when contact
    /// is off).
    pub contact_kink_deg: f64,
    /// The same for Γ3,2 (0 when friction is off).
    pub friction_kink_deg: f64,
    /// The conditions ("contact", "friction") whose group the mesh has but the scene
    /// leaves off: that boundary then carries no condition at all (`effects::warnings`).
    pub idle_groups: Vec<Gamma3>,
    /// On one of several MPI ranks, the unknowns whose columns of K_A, K_B and K_R this rank
    /// keeps whole ([`Discretization::keep_columns`]), in increasing order: the matrices'
    /// columns are then these alone, column k the unknown `own[k]` (`own_columns`); None:
    /// every column (one process).
    pub own: Option<Vec<usize>>,
    /// On one of several MPI ranks, K_B and K_R^(0) as the rank's rows of both, paired
    /// ([`Discretization::pair_own_rows`]); `k_b` and `k_r[0]` then hold no entry.
    pub own_pair: Option<RowsPair>,
    /// On one of several MPI ranks that pairs its rows of K_B and K_R^(0) after PETSc's
    /// setup ([`PairWhen::AfterKrylov`]): the cells it assembles them from
    /// ([`Discretization::own_pair_made`]); `k_b` and `k_r[0]` hold no entry meanwhile.
    pair_cells: Option<PairCells>,
    /// The cells as [`Discretization::stress`] reads them on one process, once it is called
    /// (a rank of several reads `cells`).
    stress_cells: std::sync::OnceLock<PackedCells>,
}

fn group<'m>(mesh: &'m Mesh, scene: &Scene, key: &str, value: &str) -> Result<&'m Group> {
    mesh.boundary_group(value)
        .map_err(|e| Error::input(format!("{}: key '{key}': {e}", scene.path.display())))
}

/// Which cells [`Discretization::stress`] covers.
#[derive(Clone, Copy, Debug)]
pub enum StressCells<'a> {
    /// Every cell of the discretization, in its order.
    All,
    /// The cells of these indices, in their order (rank 0's piece of a frame).
    Only(&'a [usize]),
    /// The cells of these vertices (dim + 1 a cell, each by its place in the third list)
    /// with these materials (`CellMaterials::of_cell`'s), apart from the discretization's
    /// (a rank's piece of the frames), and their nodes, increasing: each made from the
    /// nodes' places when it is read, as the discretization made its own, so the same
    /// bits. A node's values are found at its place in the list, not searched.
    Of(&'a [usize], &'a [u32], &'a [usize]),
}

/// Node `p` of `mesh` in the 32 bits a rank of several numbers its nodes in.
fn node_u32(p: usize, mesh: &Mesh) -> Result<u32> {
    u32::try_from(p).map_err(|_| {
        Error::input(format!(
            "mesh '{}': more nodes than a run over several MPI ranks numbers (2^32)",
            mesh.path.display()
        ))
    })
}

/// The mesh's triangles (2D) or tetrahedra (3D) as cells.
fn cells(mesh: &Mesh) -> Vec<Cell> {
    let (nodes, dim) = mesh_cells(mesh);
    cells_of(dim, nodes, mesh.nodes.points()).collect()
}

/// The mesh's cells' vertices (dim + 1 a cell), flattened, and the dimension.
pub(crate) fn mesh_cells(mesh: &Mesh) -> (&[usize], usize) {
    match mesh.dim {
        2 => (mesh.triangles.as_flattened(), 2),
        _ => (mesh.tetrahedra.as_flattened(), 3),
    }
}

/// The cells of dimension `dim` whose nodes are `nodes` (dim + 1 a cell), at `points`,
/// made one at a time.
fn cells_of<'a>(
    dim: usize,
    nodes: &'a [usize],
    points: Points<'a>,
) -> impl Iterator<Item = Cell> + 'a {
    (nodes.chunks_exact(dim + 1)).map(move |v| make_cell(dim, corners(v, |i| i), points))
}

/// The cell of dimension `dim` with the vertices `v` (the first dim + 1), at `points`.
fn make_cell(dim: usize, v: [usize; 4], points: Points) -> Cell {
    match dim {
        2 => {
            let t = [v[0], v[1], v[2]];
            Cell::triangle(t, t.map(|i| [points[i][0], points[i][1]]))
        }
        _ => Cell::tetrahedron(v, v.map(|i| points[i])),
    }
}

/// A cell's dim + 1 vertices `v` (node numbers as `index` reads them) as four, a
/// triangle's last repeated (unused).
fn corners<T: Copy>(v: &[T], index: impl Fn(T) -> usize) -> [usize; 4] {
    std::array::from_fn(|i| index(v[i.min(v.len() - 1)]))
}

/// The cells of a discretization in the mesh's order, as it reads them: held
/// ([`Discretization::cells`]: one process), or each made when it is read, the same bits,
/// from the mesh (a rank of several during its setup: [`Discretization::assembled`]) or
/// from the cells' vertices that rank 0 of several holds (16 bytes a tetrahedron where a
/// cell takes 144), so that no rank of several holds the whole mesh's cells.
#[derive(Clone, Copy)]
pub enum CellSource<'a> {
    Held(&'a [Cell]),
    Made(&'a Mesh),
    /// Each cell's dim + 1 vertices, at `points`.
    Vertices {
        vertices: &'a [u32],
        points: Points<'a>,
        dim: usize,
    },
}

impl<'a> CellSource<'a> {
    /// The cells as the setup of a discretization that holds what `hold` says reads them:
    /// `cells` where it holds them, else each made from `mesh`.
    fn setup(hold: Hold, cells: &'a [Cell], mesh: &'a Mesh) -> CellSource<'a> {
        match hold {
            Hold::Cells => CellSource::Held(cells),
            _ => CellSource::Made(mesh),
        }
    }

    /// Hands each cell to `f` with its index, in order.
    pub fn each(self, f: impl FnMut(usize, &Cell)) {
        self.each_where(|_| true, f)
    }

    /// [`CellSource::each`] of the cells whose vertices `visit` accepts alone; no other is
    /// made.
    pub fn each_where(self, visit: impl Fn(&[usize]) -> bool, mut f: impl FnMut(usize, &Cell)) {
        if let CellSource::Held(cells) = self {
            let visited = cells
                .iter()
                .enumerate()
                .filter(|(_, t)| visit(t.vertices()));
            return visited.for_each(|(c, t)| f(c, t));
        }
        let (points, dim) = self.points();
        let mut c = 0;
        self.each_vertices(|v| {
            if visit(v) {
                f(c, &make_cell(dim, corners(v, |i| i), points));
            }
            c += 1;
        });
    }

    /// Hands each cell's vertices to `f`, in order (no cell is made).
    pub fn each_vertices(self, mut f: impl FnMut(&[usize])) {
        match self {
            CellSource::Held(cells) => cells.iter().for_each(|t| f(t.vertices())),
            CellSource::Made(mesh) => {
                let (nodes, dim) = mesh_cells(mesh);
                nodes.chunks_exact(dim + 1).for_each(f)
            }
            CellSource::Vertices { vertices, dim, .. } => {
                for v in vertices.chunks_exact(dim + 1) {
                    f(&corners(v, |i| i as usize)[..=dim]);
                }
            }
        }
    }

    /// Cell `c`.
    pub fn get(self, c: usize) -> Cell {
        if let CellSource::Held(cells) = self {
            return cells[c];
        }
        let (points, dim) = self.points();
        make_cell(dim, self.vertices(c), points)
    }

    /// The vertices of cell `c` (its first dim + 1 entries; no cell is made).
    fn vertices(self, c: usize) -> [usize; 4] {
        let dim = self.points().1;
        let at = c * (dim + 1)..(c + 1) * (dim + 1);
        match self {
            CellSource::Held(cells) => cells[c].nodes,
            CellSource::Made(mesh) => corners(&mesh_cells(mesh).0[at], |i| i),
            CellSource::Vertices { vertices, .. } => corners(&vertices[at], |i| i as usize),
        }
    }

    /// The number of cells.
    pub fn count(self) -> usize {
        match self {
            CellSource::Held(cells) => cells.len(),
            CellSource::Made(mesh) => mesh.n_cells(),
            CellSource::Vertices { vertices, dim, .. } => vertices.len() / (dim + 1),
        }
    }

    /// The points the vertices number and the dimension (none for held cells).
    fn points(self) -> (Points<'a>, usize) {
        match self {
            CellSource::Held(cells) => (Points::Every(&[]), cells.first().map_or(0, |t| t.dim)),
            CellSource::Made(mesh) => (mesh.nodes.points(), mesh.dim),
            CellSource::Vertices { points, dim, .. } => (points, dim),
        }
    }
}

/// When a rank of several whose rows of K_A go to PETSc makes its rows of K_B and K_R^(0)
/// ([`Discretization::assembled`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PairWhen {
    /// With K_A, in its setup (`Discretization::pair_own_rows` pairs them).
    Setup,
    /// After PETSc's setup ([`Discretization::own_pair_made`]), where a scene has
    /// elasticity and one memory group: GAMG's setup, where a rank of a few peaks, then does not
    /// hold them (20 bytes an entry of its rows). Elsewhere as `Setup`.
    AfterKrylov,
}

/// The cells from which a rank makes its rows of K_B and K_R^(0) after PETSc's setup
/// ([`PairWhen::AfterKrylov`]): those with one of its own nodes, as vertices and
/// materials, and the rows' entries.
struct PairCells {
    vertices: Vec<u32>,
    materials: CellMaterials,
    entries: usize,
}

/// The pieces in which [`Discretization::own_pair_made`] assembles a rank's rows, so that
/// what the assembly holds besides the rows (32 bytes an entry of a piece) stays a small
/// part of them.
const PAIR_PIECES: usize = 8;

/// What of its cells a discretization holds past its setup.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Hold {
    /// Every cell (one process).
    Cells,
    /// Each cell's vertices, from which it makes a cell when it reads it (rank 0 of
    /// several during its setup, and past it where it reads every cell: the stresses of
    /// every cell where the frames are not in pieces, a body force's resultant in
    /// history.csv: `ranks::first_keeps_vertices`).
    Vertices,
    /// None (a follower rank of several).
    Nothing,
}

/// Makes the nodal constraint rows of Γ3 from the dof numbering: a node whose every
/// component is held by a Dirichlet condition has none (the condition wins); at a node with
/// some held components a row must not act on them.
struct RowMaker<'f> {
    numbering: &'f Numbering,
    dim: usize,
}

/// A row that acts on a held component: the component.
struct Acts(usize);

impl RowMaker<'_> {
    /// Whether every component of `node` is held.
    fn held(&self, node: usize) -> bool {
        let d = self.dim;
        (d * node..d * (node + 1)).all(|g| self.numbering.free.is_held(g))
    }

    /// The spatial direction `dir` at `node` in the node's dof components (its frame's,
    /// where it has one).
    fn in_dofs(&self, node: usize, dir: [f64; 3]) -> [f64; 3] {
        self.numbering.frames.to_dofs(node, dir)
    }

    /// The row `dir` at `node` (None when the node is held), in the node's dof components,
    /// its coefficients on held components zero (placeholder dof 0: `NodalRow::entries`
    /// skips them); `Acts` when `dir` has a component along a held one. A held component
    /// multiplies a dof that is zero, so dropping it changes nothing; the bound 1e-9 only
    /// tells a row that lies in the held plane, up to the round-off of facet normals and of
    /// a frame, from one that contradicts the condition.
    fn row(
        &self,
        node: usize,
        dir: [f64; 3],
        bound: f64,
        area: f64,
    ) -> std::result::Result<Option<NodalRow>, Acts> {
        if self.held(node) {
            return Ok(None);
        }
        let d = self.dim;
        let mut dir = self.in_dofs(node, dir);
        let mut dofs = [0; 3];
        for c in 0..d {
            match self.numbering.free.unknown(d * node + c) {
                Some(i) => dofs[c] = i,
                _ if dir[c].abs() <= 1e-9 => dir[c] = 0.0,
                _ => return Err(Acts(c)),
            }
        }
        Ok(Some(NodalRow {
            node,
            dofs,
            dir,
            dim: d,
            bound,
            area,
        }))
    }
}

/// A condition of Γ3, by its scene table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Gamma3 {
    /// `[contact]` on Γ3,1.
    Contact,
    /// `[friction]` on Γ3,2.
    Friction,
}

impl Gamma3 {
    /// The name of its table and of its `mesh.groups` key.
    pub fn name(self) -> &'static str {
        match self {
            Gamma3::Contact => "contact",
            Gamma3::Friction => "friction",
        }
    }
}

/// The conditions whose group the mesh has while the scene leaves them off.
fn idle_groups(mesh: &Mesh, scene: &Scene) -> Vec<Gamma3> {
    let groups = &scene.mesh.groups;
    [
        (Gamma3::Contact, &groups.contact, scene.physics.contact),
        (
            Gamma3::Friction,
            &groups.friction,
            scene.physics.friction.is_some(),
        ),
    ]
    .into_iter()
    .filter(|(_, name, on)| !on && mesh.boundary_group(name).is_ok())
    .map(|(condition, _, _)| condition)
    .collect()
}

/// A Γ3 row at `node` that acts on a component a Dirichlet condition holds.
fn acts_on_held(mesh: &Mesh, scene: &Scene, role: &str, node: usize, c: usize, why: &str) -> Error {
    Error::input(format!(
        "{}: key 'mesh.groups.{role}': the node at {} of the {role} group lies on a Dirichlet \
         condition ({}) that holds its {} component, {why}; keep the {role} group off the \
         condition's group (in gmsh, a separate physical group), or hold only components \
         tangent to the {role} surface",
        scene.path.display(),
        fmt_at(mesh.nodes[node], scene.mesh.model),
        constraints::conditions(scene),
        ["x", "y", "z"][c],
    ))
}

/// Γ3,1: one row n_i per free node, and the largest kink of the normals (empty and 0 when
/// contact is off); a group with every node clamped is refused.
fn contact_rows(mesh: &Mesh, scene: &Scene, rows: &RowMaker) -> Result<(Vec<NodalRow>, f64)> {
    let mut contact = Vec::new();
    let mut contact_kink = 0.0;
    if scene.physics.contact {
        let g = group(
            mesh,
            scene,
            "mesh.groups.contact",
            &scene.mesh.groups.contact,
        )?;
        let (normals, k) = mesh.nodal_normals(g);
        contact_kink = k;
        let area = lumped_area(mesh, g);
        for (node, n) in normals {
            match rows.row(node, n, f64::INFINITY, area(node)) {
                Ok(row) => contact.extend(row),
                Err(Acts(c)) => {
                    let why = "along the contact normal: the two conditions contradict";
                    return Err(acts_on_held(mesh, scene, "contact", node, c, why));
                }
            }
        }
        if contact.is_empty() {
            return Err(on_fixed(
                scene,
                "contact",
                &scene.mesh.groups.contact,
                "[contact]",
            ));
        }
    }
    Ok((contact, contact_kink))
}

/// Γ3,2: g_F where it is not zero, the friction rows τ_i with c_i = ∫ μF φ_i da, and the
/// largest kink of the normals; a group with every node clamped is refused.
fn friction_rows(
    mesh: &Mesh,
    scene: &Scene,
    fr: &Friction,
    rows: &RowMaker,
) -> Result<(DofValues, Vec<NodalRow>, f64)> {
    let g = group(
        mesh,
        scene,
        "mesh.groups.friction",
        &scene.mesh.groups.friction,
    )?;
    if scene.physics.contact {
        let c = group(
            mesh,
            scene,
            "mesh.groups.contact",
            &scene.mesh.groups.contact,
        )?;
        check_overlap(mesh, scene, c, g)?;
    }
    let dofs = (&rows.numbering.free, &rows.numbering.frames);
    let (gf, c) = friction_integrals(mesh, scene, fr, g, dofs)?;
    let g_f = gf.into_iter().filter(|&(_, v)| v != 0.0).collect();
    let c = |node: usize| c.get(&node).copied().unwrap_or(0.0);
    let (normals, k) = mesh.nodal_normals(g);
    if normals.iter().all(|&(node, _)| rows.held(node)) {
        return Err(on_fixed(
            scene,
            "friction",
            &scene.mesh.groups.friction,
            "[friction]",
        ));
    }
    let area = lumped_area(mesh, g);
    let mut friction = Vec::new();
    // μF may vanish on parts of Γ3,2: nodes with c_i = 0 carry no friction.
    for (node, n) in normals.into_iter().filter(|&(node, _)| c(node) > 0.0) {
        let ts = tangents(n, rows.dim);
        let made: std::result::Result<Vec<_>, Acts> = ts
            .iter()
            .map(|&t| rows.row(node, t, c(node), area(node)))
            .collect();
        match made {
            Ok(r) => friction.extend(r.into_iter().flatten()),
            // 2D: the tangent is the held component, so the node cannot slide.
            Err(Acts(_)) if rows.dim == 2 && is_axis(rows.in_dofs(node, ts[0])) => {}
            Err(Acts(comp)) => {
                let why = match rows.dim {
                    2 => "and the tangent is inclined to it",
                    _ => {
                        "in the friction's tangent plane: friction at a node with a held \
                          tangent component is supported in 2D only for now"
                    }
                };
                return Err(acts_on_held(mesh, scene, "friction", node, comp, why));
            }
        }
    }
    Ok((g_f, friction, k))
}

/// By facet quadrature over the friction group `g`: g_F_i = ∫ F φ_i ν da (`n_dofs`
/// entries, i = `free`[global dof], in the nodes' `frames`) and c_i = ∫ μF φ_i da per
/// node.
fn friction_integrals(
    mesh: &Mesh,
    scene: &Scene,
    fr: &Friction,
    g: &Group,
    (free, frames): (&DofIndices, &Frames),
) -> Result<(BTreeMap<usize, f64>, BTreeMap<usize, f64>)> {
    let d = mesh.dim;
    // At Γ3,2's dofs and nodes alone, not a slot of every one (8 bytes a dof and a node of
    // the whole on every rank); each sums its terms in the same order.
    let (mut gf, mut c) = (BTreeMap::new(), BTreeMap::new());
    for f in mesh.boundary_facets(g) {
        for (p, w, phi) in f.quadrature(mesh) {
            let pt = Point {
                x: p[0],
                y: p[1],
                z: p[2],
                ..Default::default()
            };
            let big_f = fr.normal_stress.eval(&pt);
            let mu = fr.coefficient.eval(&pt);
            check_data(big_f, "friction.normal_stress", scene, p, true)?;
            check_data(mu, "friction.coefficient", scene, p, true)?;
            for (&node, ph) in f.nodes().iter().zip(phi) {
                for comp in 0..d {
                    let v = w * ph * big_f * f.normal[comp];
                    frames.spread(d, d * node + comp, v, |g, v| {
                        if let Some(dof) = free.get(g) {
                            *gf.entry(dof).or_insert(0.0) += v;
                        }
                    });
                }
                *c.entry(node).or_insert(0.0) += w * ph * mu * big_f;
            }
        }
    }
    Ok((gf, c))
}

impl Discretization {
    /// The discretization of `scene` on `mesh`: the free dofs (Γ1 clamped), the cells, the
    /// stiffness matrices, the loads and the constraint rows on Γ3,1 and Γ3,2.
    pub fn new(mesh: &Mesh, scene: &Scene) -> Result<Self> {
        let disc = Self::numbered(mesh, scene, Hold::Cells)?;
        let materials = CellMaterials::new(mesh, scene)?;
        disc.assembled(
            mesh,
            scene,
            (Hold::Cells, PairWhen::Setup),
            (materials, None),
        )
    }

    /// A discretization's first stage: its unknowns, Γ3's rows, the cells it holds as
    /// `hold` says (and where it holds every cell, the loads), its matrices still empty and
    /// its cells without their materials. What reads it then reads its unknowns and the
    /// mesh's cells: of them a rank of several makes METIS's partition (`Ranks::discretize`),
    /// before [`Discretization::assembled`]. It reads of the mesh its nodes and groups, and
    /// its cells where it holds them or their vertices: a follower of several (`Hold::Nothing`)
    /// has none yet, and leaves the checks of the body's parts to rank 0
    /// (`Numbering::new`).
    pub fn numbered(mesh: &Mesh, scene: &Scene, hold: Hold) -> Result<Self> {
        check_model(mesh, scene)?;
        let d = mesh.dim;
        let numbering = Numbering::new(mesh, scene, hold != Hold::Nothing)?;
        let (n_free, n_dofs) = (numbering.n_free, numbering.n_dofs);
        let cells = match hold {
            Hold::Cells => cells(mesh),
            _ => Vec::new(),
        };
        // A rank of several makes its loads once its own rows are known (`assembled`).
        let loads = match hold {
            Hold::Cells => Loads::new(mesh, scene, CellSource::Held(&cells), Keep::Every)?,
            _ => Loads::none(d),
        };
        let rows = RowMaker {
            numbering: &numbering,
            dim: d,
        };
        let (contact, contact_kink) = contact_rows(mesh, scene, &rows)?;
        let (g_f, friction, friction_kink) = match &scene.physics.friction {
            Some(fr) => friction_rows(mesh, scene, fr, &rows)?,
            None => (Vec::new(), Vec::new(), 0.0),
        };
        Ok(Discretization {
            dim: d,
            // A follower keeps the places it reads once its own rows are known
            // (`keep_places`), and holds no copy of every node's before.
            nodes: match hold {
                Hold::Nothing => mesh.nodes.some(&[]),
                _ => mesh.nodes.clone(),
            },
            cells,
            n_free,
            n_dofs,
            prescribed: numbering.prescribed.clone(),
            held: numbering.held_by,
            free: numbering.free,
            frames: numbering.frames,
            k_a_all: None,
            materials: CellMaterials::default(),
            r: Isotropic::identity(),
            k_a: Sparse::new(
                SymbolicSparseColMat::new_checked(0, 0, vec![0], None, vec![]),
                vec![],
            ),
            k_b: None,
            k_r: Vec::new(),
            loads,
            g_f,
            contact,
            friction,
            contact_kink_deg: contact_kink,
            friction_kink_deg: friction_kink,
            idle_groups: idle_groups(mesh, scene),
            own: None,
            own_pair: None,
            pair_cells: None,
            stress_cells: std::sync::OnceLock::new(),
            vertices: Vec::new(),
            cells_in_mesh: mesh.n_cells(),
        })
    }

    /// A discretization's second stage, after [`Discretization::numbered`]: its cells'
    /// `materials` (those of `mesh`'s cells, in their order) and its matrices, of K_A, K_B
    /// and K_R only the columns of the unknowns that `own` names (increasing), as
    /// [`Discretization::keep_columns`] leaves them, bit for bit, but without the whole
    /// matrices ever in memory, and from the cells that reach those entries alone: on one
    /// of several MPI ranks (`Ranks::discretize`). None keeps every column; so does a scene
    /// with prescribed dofs, as `keep_columns` does. The discretization holds what `hold`
    /// says of the cells; where that is not every cell (a rank of several) its setup makes
    /// each from the mesh when it reads it ([`CellSource::Made`]). `pair` says when it
    /// makes its rows of K_B and K_R^(0).
    pub fn assembled(
        mut self,
        mesh: &Mesh,
        scene: &Scene,
        (hold, pair): (Hold, PairWhen),
        (materials, own): (CellMaterials, Option<Vec<usize>>),
    ) -> Result<Self> {
        self.materials = materials;
        let own = own.filter(|_| self.keeps_own_columns());
        if hold != Hold::Cells {
            // Those of its own rows alone (`Discretization::keep_own_loads`).
            let reaches = own.as_deref().map(|own| self.reaching(own));
            let keep = match (reaches.as_deref(), hold) {
                (None, _) => Keep::Every,
                (Some(r), Hold::Vertices) => Keep::ReachingAndTractions(r),
                (Some(r), _) => Keep::Reaching(r),
            };
            let cells = CellSource::setup(hold, &self.cells, mesh);
            self.loads = Loads::new(mesh, scene, cells, keep)?;
        }
        // Without a memory term in any cell K_R would be zero: none is assembled.
        let groups = match self.materials.memory() {
            true => scene.physics.memory_groups(),
            false => 0,
        };
        // The implicit variant's step matrix is made of the three matrices' columns.
        let left = scene.solver.history == crate::scene::History::Left;
        let later =
            pair == PairWhen::AfterKrylov && left && groups == 1 && self.materials.elastic();
        let terms = match (later, own.as_deref()) {
            (true, Some(own)) => {
                let cells = CellSource::setup(hold, &self.cells, mesh);
                self.pair_cells = Some(self.cells_with_own_nodes(cells, own, mesh)?);
                (false, 0)
            }
            _ => (self.materials.elastic(), groups),
        };
        let cells = CellSource::setup(hold, &self.cells, mesh);
        let (k_a_all, k_b, k_r) = self.assemble(cells, terms, own.as_deref());
        (self.k_a, self.k_a_all) = match self.n_dofs > self.n_free {
            true => (leading_block(&k_a_all, self.n_free), Some(k_a_all)),
            false => (k_a_all, None),
        };
        (self.k_b, self.k_r, self.own) = (k_b, k_r, own);
        self.pair_put_off();
        if hold == Hold::Vertices {
            let (nodes, _) = mesh_cells(mesh);
            // At their exact size (a collected Result grows by doubling): they stay.
            self.vertices = Vec::with_capacity(nodes.len());
            for &v in nodes {
                self.vertices.push(node_u32(v, mesh)?);
            }
        }
        Ok(self)
    }

    /// Whether a rank of several keeps of K_A, K_B and K_R its own unknowns' columns alone:
    /// not where there are prescribed dofs, whose columns the time loop reads whole.
    pub fn keeps_own_columns(&self) -> bool {
        self.n_dofs == self.n_free
    }

    /// K_A on all n_dofs, K_B and K_R (`assemble`) of the cells `cells`, the columns of the
    /// unknowns `own` alone (None: every column).
    fn assemble(
        &self,
        cells: CellSource,
        terms: (bool, usize),
        own: Option<&[usize]>,
    ) -> (Sparse, Option<Sparse>, Vec<Sparse>) {
        let dofs = (&self.free, &self.frames, self.n_dofs);
        let (materials, r) = (&self.materials, self.r);
        assemble(cells, self.dim, dofs, (materials, r), terms, own)
    }

    /// The unknowns at which the active set reads the step matrix's diagonal (its ρ): those
    /// of Γ3's rows, increasing (a list of Γ3's, not a flag of every dof).
    fn diagonal_read(&self) -> Vec<usize> {
        let rows = self.contact.iter().chain(&self.friction);
        increasing(rows.flat_map(|row| row.entries().map(|(d, _)| d)).collect())
    }

    /// Keeps of K_A, K_B and K_R the columns of the unknowns `own` (increasing) alone, as
    /// their only columns (column k the unknown `own[k]`: no rank holds a column start of
    /// the whole problem, 8 bytes a dof a matrix): a rank of several, which holds those
    /// unknowns' rows in PETSc (`petsc::Layout`), needs no more of them. A symmetric
    /// matrix's column is its row, so each rank computes its own entries of a product
    /// ([`mul_add_rows`]) and the ranks gather the rest; so too the step matrix's diagonal
    /// at Γ3's unknowns, which the active set's ρ reads (`effects::step_solver`). Where K_A
    /// has a block on prescribed dofs (`k_a_all`), which moves their velocities to every
    /// row's right side, the matrices stay whole.
    pub fn keep_columns(&mut self, own: Vec<usize>) {
        if self.k_a_all.is_some() {
            return;
        }
        let trim = |a: &mut Sparse| *a = own_columns(a, &own, |_, _| true);
        trim(&mut self.k_a);
        self.k_b.iter_mut().for_each(trim);
        self.k_r.iter_mut().for_each(trim);
        self.own = Some(own);
    }

    /// On one of several MPI ranks that keeps its own columns, K_B and K_R^(0) as its rows of
    /// both in one [`RowsPair`] (20 bytes an entry where the two took 32), each then with no
    /// entry (b_n's products read the pair alone); nothing without K_B or where the columns
    /// are whole. Only where K_A is the step matrix: the implicit variant's is made of all
    /// three matrices' columns.
    pub fn pair_own_rows(&mut self) {
        if self.pair_cells.is_some() {
            return; // `own_pair_made` pairs them after PETSc's setup.
        }
        let (Some(own), Some(k_b), Some(k_r)) = (&self.own, &mut self.k_b, self.k_r.first_mut())
        else {
            return;
        };
        let Some(pair) = RowsPair::new(k_b, k_r, 0..own.len()) else {
            return;
        };
        for m in [k_b, k_r] {
            *m = own_columns(m, own, |_, _| false);
        }
        self.own_pair = Some(pair);
    }

    /// Where the rank makes its rows of K_B and K_R^(0) after PETSc's setup
    /// ([`Discretization::own_pair_made`]): the two meanwhile present with no entry, as after
    /// [`Discretization::pair_own_rows`], and the rows' entries counted on K_A's own
    /// columns (one pattern).
    fn pair_put_off(&mut self) {
        let Some(cells) = &mut self.pair_cells else {
            return;
        };
        let size = (self.k_a.nrows(), self.k_a.ncols());
        let empty = || entries_kept(&self.k_a, size, |_, _| false);
        (self.k_b, self.k_r) = (Some(empty()), vec![empty()]);
        cells.entries = self.k_a.compute_nnz();
    }

    /// The cells of `cells` (`mesh`'s) with one of the nodes of the unknowns `own`, as
    /// [`PairCells`] (their entries counted once K_A is assembled).
    fn cells_with_own_nodes(
        &self,
        cells: CellSource,
        own: &[usize],
        mesh: &Mesh,
    ) -> Result<PairCells> {
        node_u32(mesh.nodes.len().saturating_sub(1), mesh)?; // so every node fits in 32 bits
        let reaches = self.reaching(own);
        let (mut vertices, mut of_cell, mut c) = (Vec::new(), Vec::new(), 0);
        cells.each_vertices(|v| {
            if v.iter().any(|p| reaches.binary_search(p).is_ok()) {
                vertices.extend(v.iter().map(|&p| p as u32));
                of_cell.push(self.materials.of_cell[c]);
            }
            c += 1;
        });
        let materials = CellMaterials {
            distinct: self.materials.distinct.clone(),
            of_cell,
            region: Vec::new(),
        };
        Ok(PairCells {
            vertices,
            materials,
            entries: 0,
        })
    }

    /// On one of several MPI ranks that pairs its rows of K_B and K_R^(0) after PETSc's
    /// setup ([`PairWhen::AfterKrylov`]), those rows, the bits that
    /// [`Discretization::pair_own_rows`] would have kept: assembled from its cells with one
    /// of its own nodes, `PAIR_PIECES` pieces of its rows at a time, each piece's
    /// entries summing the same terms in the same order as the whole's; their columns
    /// numbered by their places in `local` where given (a follower's history's dofs:
    /// [`Discretization::number_rows_over`]). None elsewhere.
    pub fn own_pair_made(&self, local: Option<&[usize]>) -> Option<RowsPair> {
        let (cells, own) = (self.pair_cells.as_ref()?, self.own.as_deref()?);
        let source = CellSource::Vertices {
            vertices: &cells.vertices,
            points: self.nodes.points(),
            dim: self.dim,
        };
        let dofs = (&self.free, &self.frames, self.n_dofs);
        let mut pair = RowsPair::with_capacity(own.len(), cells.entries);
        for piece in own.chunks(own.len().div_ceil(PAIR_PIECES).max(1)) {
            let materials = (&cells.materials, self.r);
            let (_, k_b, k_r) = assemble(source, self.dim, dofs, materials, (true, 1), Some(piece));
            let columns = 0..piece.len();
            pair.extend(&RowsPair::new(k_b.as_ref()?, k_r.first()?, columns)?);
        }
        if let Some(local) = local {
            pair.number_columns(|i| local.binary_search(&i).expect("a column in the reach"));
        }
        Some(pair)
    }

    /// On one of several MPI ranks that keeps its own columns, the dofs whose memory m_n
    /// its rows of Σ_g K_R^(g) m^(g)_n read, in increasing order: the rows of its columns of
    /// every K_R^(g) (of K_R^(0), those it pairs with K_B). They are the nodes that share a
    /// cell with memory with one of its own nodes, so every node of its piece of a frame
    /// whose cell's stress reads m (each cell of the piece has one of the rank's nodes:
    /// `output::pvtu`). None where it holds the matrices whole.
    pub fn memory_reach(&self) -> Option<Vec<usize>> {
        self.reach(&self.k_r, [])
    }

    /// [`Discretization::memory_reach`] with the rows of the rank's columns of K_B too and
    /// the dofs `also`: what a follower's history holds where its matrices number their rows
    /// over them (`Holds::Local`, [`Discretization::number_rows_over`]).
    pub fn local_reach(&self, also: impl IntoIterator<Item = usize>) -> Option<Vec<usize>> {
        self.reach(self.k_b.iter().chain(&self.k_r), also)
    }

    /// The rows of the rank's columns of `matrices` and of its pair of rows, and `also`, in
    /// increasing order; None where the rank holds the matrices whole.
    fn reach<'a>(
        &self,
        matrices: impl IntoIterator<Item = &'a Sparse>,
        also: impl IntoIterator<Item = usize>,
    ) -> Option<Vec<usize>> {
        let own = self.own.as_ref()?;
        // A set of the rank's own and its neighbours' dofs, not a flag of every dof.
        let mut read = std::collections::HashSet::new();
        for a in matrices {
            let (cp, ri) = (a.symbolic().col_ptr(), a.symbolic().row_idx());
            read.extend(&ri[..cp[own.len()]]);
        }
        if let Some(pair) = &self.own_pair {
            read.extend(pair.columns());
        }
        // The columns of the rows `own_pair_made` will make: its cells' unknowns.
        for &p in self.pair_cells.iter().flat_map(|c| &c.vertices) {
            read.extend(self.free.of_node(self.dim, p as usize));
        }
        read.extend(also);
        Some(increasing(read.into_iter().collect()))
    }

    /// On a follower rank whose history holds the dofs `local` alone (`Holds::Local`, made
    /// of [`Discretization::local_reach`]): its columns of K_B and of every K_R^(g), and its
    /// pair of rows, number their rows by their places in `local`, so that their products
    /// (`mul_add_rows`, `RowsPair::mul_add`) read u_n and m_n where the history holds them.
    /// The products' own rows keep the whole numbering.
    pub fn number_rows_over(&mut self, local: &[usize]) {
        if self.own.is_none() {
            return;
        }
        let place = |i: usize| {
            (local.binary_search(&i)).expect("a row of the rank's columns is in its reach")
        };
        for a in self.k_b.iter_mut().chain(&mut self.k_r) {
            let size = (local.len(), a.ncols());
            *a = entries_placed(a, size, |_, _| true, place);
        }
        if let Some(pair) = &mut self.own_pair {
            pair.number_columns(place);
        }
    }

    /// The loads at t = 0, refused (bad input) where a value is not finite: before any
    /// step, and on several MPI ranks by rank 0, which sees every value
    /// ([`Discretization::visit_every_load`]), before the ranks agree on their setup (a
    /// follower's own loads alone may not hold the value).
    pub fn loads_at_start(&self, scene: &Scene) -> Result<()> {
        self.visit_every_load(0.0, scene, |_, _, _| {})
    }

    /// Every term of the loads at t ([`Loads::visit`]), in one process's order, where
    /// these are one process's or rank 0's of several, which makes a body force's points
    /// that it does not keep again from its cells ([`Loads::visit_every`]).
    pub fn visit_every_load(
        &self,
        t: f64,
        scene: &Scene,
        put: impl FnMut(usize, usize, f64),
    ) -> Result<()> {
        let cells = (self.cell_source(), self.nodes.points());
        self.loads.visit_every((t, scene), cells, put)
    }

    /// On one of several MPI ranks that keeps its own columns, the loads' quadrature points
    /// that reach its own unknowns alone (`Loads::keep_reaching`; on rank 0, `first`,
    /// every traction's facets too, and it makes the others again, a traction's from
    /// those, a body force's from its cells, where it reads them:
    /// [`Discretization::visit_every_load`]): its rows of f_n keep their bits, the
    /// others' rows come from their ranks with b_n's exchange, and a rank holds a body
    /// force's points, four a tetrahedron, for its cells alone. Nothing where the setup
    /// made them so already ([`Discretization::assembled`]).
    pub fn keep_own_loads(&mut self, first: bool) {
        if let Some(own) = self.own.as_ref().filter(|_| !self.loads.is_part()) {
            let reaches = self.reaching(own);
            self.loads.keep_reaching(&reaches, first);
        }
    }

    /// The nodes of the unknowns `own`, increasing (a list of the rank's nodes, not a
    /// flag of every node).
    fn reaching(&self, own: &[usize]) -> Vec<usize> {
        increasing(column_nodes(&self.free, self.dim, Some(own), 0))
    }

    /// K_A's diagonal at the unknowns of Γ3's rows alone, where its rows went to the linear
    /// backend (on one of several MPI ranks: `Ranks::keep_own_columns`, which kept its own
    /// columns alone, so Γ3's own unknowns'): what the active set's ρ reads of it
    /// (`NodalRow::entries`), the others' from their ranks (`effects::step_solver`).
    pub fn keep_diagonal_of_k_a(&mut self) {
        let read = self.diagonal_read();
        let own = self.own.as_deref().expect("a rank's own columns");
        self.k_a = own_columns(&self.k_a, own, |i, j| {
            i == j && read.binary_search(&i).is_ok()
        });
    }

    /// The diagonal of `a`, the step matrix or K_A: its columns, placed at their unknowns
    /// where they are a rank's own alone ([`Discretization::own`]; 0 at the others), in a
    /// vector held at the dofs `held` alone where given ([`place`]).
    pub fn diagonal_of(&self, a: &Sparse, held: Option<&[usize]>) -> Vec<f64> {
        let Some(own) = self.own.as_deref() else {
            return diagonal(a);
        };
        let mut out = vec![0.0; held.map_or(a.nrows(), <[usize]>::len)];
        let (cp, ri, v) = (a.symbolic().col_ptr(), a.symbolic().row_idx(), a.val());
        for (k, &j) in own.iter().enumerate() {
            if let Some(p) = (cp[k]..cp[k + 1]).find(|&p| ri[p] == j) {
                out[place(held, j)] = v[p];
            }
        }
        out
    }

    /// Expands a free-dof vector to 3-component nodal vectors (0 on Γ1; z = 0 in 2D).
    pub fn nodal(&self, v: &[f64]) -> Vec<f64> {
        nodal_vectors::<3>(self, v).into_flattened()
    }

    /// [`Discretization::nodal`] at the nodes `at` alone, in their order (a rank's piece of
    /// a frame), of `v` held at the dofs `held` alone where given (`place`).
    pub fn nodal_at(&self, (v, held): (&[f64], Option<&[usize]>), at: &[usize]) -> Vec<f64> {
        let at = at.iter().map(|&i| nodal_vector::<3>(self, (v, held), i));
        at.collect::<Vec<_>>().into_flattened()
    }

    /// Per-cell stress σ_n = A ε(w_n) + B ε(u_n) + ε(m_n) (2.1 discretized; R = r·I, so the
    /// memory term is ε of m_n = kΣ r(t_n − t_j) u_j) as 6 components XX YY ZZ XY YZ XZ, and
    /// the von Mises stress, of the cells `cells` says (a rank's piece of a frame, or all). Plane stress has σ_zz = 0; plane strain σ_zz =
    /// b_A tr ε(w) + b_B tr ε(u) (the out-of-plane strain is zero).
    ///
    /// Each of A, B, R has the form C τ = 2a τ + b tr(τ) I, and ε is linear, so with the
    /// nodal combinations p = Σ_C a_C v_C and q = Σ_C b_C v_C (v_A = w, v_B = u, v_R = m)
    /// σ = Σ_i (∇φ_i ⊗ p_i + p_i ⊗ ∇φ_i) + (Σ_i ∇φ_i · q_i) I over the cell's vertices i:
    /// one pass over the cells instead of three strains each (a frame at every step pays
    /// this on the frame writer's thread, beside the time loop). A and B are the cell's own:
    /// the nodal p, q are made once per distinct material, and a cell reads its material's.
    /// `m` holds the memory of every memory group, group g's after the others' before (the
    /// cell's material names its group, `Stiffness::memory`). `held` gives the dofs at
    /// which w, and u and each group's m, hold their values alone where they do not hold
    /// every one (`place`: a follower rank's, `time_loop::Step`).
    pub fn stress(
        &self,
        [w, u]: [&[f64]; 2],
        (m, held): (Option<&[f64]>, [Option<&[usize]>; 2]),
        model: Model,
        cells: StressCells,
    ) -> (Vec<f64>, Vec<f64>) {
        let n_cells = match cells {
            StressCells::All => self.n_cells(),
            StressCells::Only(only) => only.len(),
            StressCells::Of(_, materials, _) => materials.len(),
        };
        let (mut s6, mut vm) = (Vec::with_capacity(6 * n_cells), Vec::with_capacity(n_cells));
        self.each_stress([w, u], (m, held), (model, cells), |s, v| {
            s6.extend(s);
            vm.push(v);
        });
        (s6, vm)
    }

    /// The largest von Mises stress of the cells `cells` of [`Discretization::stress`] (0
    /// without cells), the same number, without its arrays: history.csv's at a step
    /// without a frame (7 doubles a cell less), of every cell or of a rank's piece.
    pub fn max_von_mises(
        &self,
        [w, u]: [&[f64]; 2],
        m: (Option<&[f64]>, [Option<&[usize]>; 2]),
        model: Model,
        cells: StressCells,
    ) -> f64 {
        let mut max = 0.0;
        self.each_stress([w, u], m, (model, cells), |_, v| max = f64::max(max, v));
        max
    }

    /// Hands each cell's σ (XX YY ZZ XY YZ XZ) and von Mises stress to `sink`, in the cells'
    /// order, or of the cells `cells` says in theirs ([`Discretization::stress`]).
    fn each_stress(
        &self,
        wu: [&[f64]; 2],
        m: (Option<&[f64]>, [Option<&[usize]>; 2]),
        (model, only): (Model, StressCells),
        sink: impl FnMut([f64; 6], f64),
    ) {
        let how = (model == Model::PlaneStress, only);
        match self.dim {
            2 => self.stresses::<2, 3>(wu, m, how, sink),
            _ => self.stresses::<3, 4>(wu, m, how, sink),
        }
    }

    /// [`Discretization::stress`] for cells of dimension D with N = D + 1 vertices: the
    /// nodal p and q of w, u, m, then σ = Σ_i (∇φ_i ⊗ p_i + p_i ⊗ ∇φ_i) + (Σ_i ∇φ_i · q_i) I
    /// of every cell (XX YY ZZ XY YZ XZ, σ_zz = 0 under plane stress) and its von Mises
    /// stress. The z entries of ∇φ_i and of p_i, q_i are zero in 2D, so only D × D products
    /// are formed.
    fn stresses<const D: usize, const N: usize>(
        &self,
        [w, u]: [&[f64]; 2],
        (m, [w_held, held]): (Option<&[f64]>, [Option<&[usize]>; 2]),
        (plane_stress, only): (bool, StressCells),
        mut sink: impl FnMut([f64; 6], f64),
    ) {
        let (r, n) = (self.r, held.map_or(self.n_dofs, <[usize]>::len));
        // [p_n, q_n] of every node (D components: 32 bytes a node in 2D), or of the nodes of
        // a piece's cells alone (`at`, increasing), for each distinct material, its memory m
        // from its group's part of `m`.
        let at = self.nodes_of(only);
        let pq_of = |s: &Stiffness| -> Vec<[[f64; D]; 2]> {
            let (a, b) = (s.a, s.b_or_zero());
            let pq_at = |node: usize| {
                let [mut p, mut q] = [[0.0; D]; 2];
                for (c, (p, q)) in p.iter_mut().zip(&mut q).enumerate() {
                    if let Some(dof) = self.free.get(D * node + c) {
                        let at = place(held, dof);
                        let m = (m.zip(s.memory)).map_or(0.0, |(m, g)| m[g * n + at]);
                        let (w, u) = (w[place(w_held, dof)], u[at]);
                        *p = a.a * w + b.a * u + r.a * m;
                        *q = a.b * w + b.b * u + r.b * m;
                    }
                }
                // p and q are linear in the nodal vectors: turned into x, y, z alike.
                [p, q].map(|v| self.frames.to_space(node, v))
            };
            match &at {
                None => (0..self.nodes.len()).map(pq_at).collect(),
                Some(at) => at.iter().map(|&node| pq_at(node)).collect(),
            }
        };
        let pqs: Vec<Vec<[[f64; D]; 2]>> = self.materials.distinct.iter().map(pq_of).collect();
        // The nodes the cells name: every node, the piece's (`Of`: already their places
        // among its points), or those `at` lists.
        let index = |node: usize| match (&at, only) {
            (None, _) | (_, StressCells::Of(..)) => node,
            (Some(at), _) => at.partition_point(|&a| a < node),
        };
        let mut cell = |nodes: [usize; N], grad: &[[f64; D]; N], material: u32| {
            let pq = &pqs[material as usize];
            let mut g_p = [[0.0; 3]; 3]; // Σ_i ∇φ_i ⊗ p_i
            let mut tr = 0.0;
            for (g, n) in grad.iter().zip(nodes) {
                let [p, q] = &pq[index(n)];
                for a in 0..D {
                    for b in 0..D {
                        g_p[a][b] += g[a] * p[b];
                    }
                    tr += g[a] * q[a];
                }
            }
            let sym = |a: usize, b: usize| g_p[a][b] + g_p[b][a];
            let zz = if plane_stress { 0.0 } else { sym(2, 2) + tr };
            let s = [
                sym(0, 0) + tr,
                sym(1, 1) + tr,
                zz,
                sym(0, 1),
                sym(1, 2),
                sym(0, 2),
            ];
            let (dx, dy, dz) = (s[0] - s[1], s[1] - s[2], s[2] - s[0]);
            let shear = s[3] * s[3] + s[4] * s[4] + s[5] * s[5];
            sink(
                s,
                (0.5 * (dx * dx + dy * dy + dz * dz) + 3.0 * shear).sqrt(),
            );
        };
        let materials = &self.materials.of_cell;
        let each = |one: &mut dyn FnMut(usize)| match only {
            StressCells::Only(cells) => cells.iter().for_each(|&c| one(c)),
            _ => (0..self.n_cells()).for_each(one),
        };
        let mut of_cell = |t: &Cell, material: u32| {
            let grad = std::array::from_fn(|i| std::array::from_fn(|a| t.grad[i][a]));
            cell(std::array::from_fn(|i| t.nodes[i]), &grad, material);
        };
        // Rank 0 of several makes each cell from its vertices (16 bytes a tetrahedron) as it
        // reads it, on the thread that writes history.csv, beside PETSc's solves; packing
        // them, as one process does beside its factor, would hold 112 bytes a tetrahedron.
        // It holds the vertices whether or not it keeps its own columns (with prescribed
        // dofs every rank keeps the matrices whole); any rank of several reads its cells so,
        // a follower its piece's (a cell held would take 144 bytes).
        if let StressCells::Of(vertices, materials, nodes) = only {
            for ((v, t), &material) in self.piece_cells(vertices, nodes).zip(materials) {
                let grad = std::array::from_fn(|i| std::array::from_fn(|a| t.grad[i][a]));
                cell(std::array::from_fn(|i| v[i]), &grad, material);
            }
        } else if self.own.is_some() || !self.vertices.is_empty() {
            let cells = self.cell_source();
            each(&mut |c| of_cell(&cells.get(c), materials[c]));
        } else {
            let packed = self
                .stress_cells
                .get_or_init(|| PackedCells::new(&self.cells));
            let (grads, _) = packed.grad.as_chunks::<D>();
            let (grads, _) = grads.as_chunks::<N>();
            let (cells, _) = packed.nodes.as_chunks::<N>();
            each(&mut |c| cell(cells[c].map(|n| n as usize), &grads[c], materials[c]));
        }
    }

    /// The nodes of the cells `only` says, increasing, where they are a piece's (None: every
    /// node's, of every cell): the nodes whose p and q [`Discretization::stress`] makes. A
    /// follower's piece names them (no flag of every node there); rank 0 marks its own.
    fn nodes_of<'a>(&self, only: StressCells<'a>) -> Option<Cow<'a, [usize]>> {
        match only {
            StressCells::All => return None,
            StressCells::Of(_, _, nodes) => return Some(Cow::Borrowed(nodes)),
            StressCells::Only(_) => {}
        }
        let mut used = vec![false; self.nodes.len()];
        let mut mark = |vertices: &[usize]| vertices.iter().for_each(|&v| used[v] = true);
        match only {
            StressCells::Only(cells) => {
                let source = self.cell_source();
                cells
                    .iter()
                    .for_each(|&c| mark(&source.vertices(c)[..=self.dim]));
            }
            StressCells::Of(..) | StressCells::All => {}
        }
        let mut nodes = Vec::with_capacity(used.iter().filter(|&&u| u).count());
        nodes.extend((0..used.len()).filter(|&v| used[v]));
        Some(Cow::Owned(nodes))
    }

    /// K_A + k K_B + k² Σ_g r_g(0) K_R^(g) on all n_dofs: the step matrix of the implicit
    /// variant, r_g(0) of each memory group with a kernel (None: a group without) in `r0`
    /// (they share one sparsity pattern, so this adds their value arrays).
    pub fn implicit_matrix(&self, k: f64, r0: &[Option<f64>]) -> Sparse {
        let mut m = self.k_a_all.as_ref().unwrap_or(&self.k_a).clone();
        let mut add = |other: &Sparse, c: f64| {
            debug_assert_eq!(other.symbolic().row_idx(), m.symbolic().row_idx());
            for (v, o) in m.val_mut().iter_mut().zip(other.val()) {
                *v += c * o;
            }
        };
        if let Some(k_b) = &self.k_b {
            add(k_b, k);
        }
        for (k_r, r0) in self.k_r.iter().zip(r0) {
            if let Some(r0) = r0 {
                add(k_r, k * k * r0);
            }
        }
        m
    }

    /// ‖v‖_{L²(Ω)} and |v|_{H¹(Ω)} of a P1 field (free-dof vector), computed exactly.
    pub fn norms(&self, v: &[f64]) -> (f64, f64) {
        let [l2, h1] = self.norm_parts((v, None), StressCells::All);
        (l2.sqrt(), h1.sqrt())
    }

    /// The cells of a piece (`StressCells::Of`: `vertices` dim + 1 a cell, each by its
    /// place in `nodes`), each with its vertices' places, made from the nodes' places as
    /// the discretization made its own.
    fn piece_cells<'a>(
        &'a self,
        vertices: &'a [usize],
        nodes: &'a [usize],
    ) -> impl Iterator<Item = (&'a [usize], Cell)> + 'a {
        let points = self.nodes.points();
        (vertices.chunks_exact(self.dim + 1))
            .map(move |v| (v, make_cell(self.dim, corners(v, |i| nodes[i]), points)))
    }

    /// ‖v‖²_{L²} and |v|²_{H¹} over the cells `cells` says alone (a rank's piece of the
    /// frames), of `v` held at the dofs `held` alone where given ([`place`]): the pieces
    /// split the cells, so the ranks' parts sum to the squares of
    /// [`Discretization::norms`] (to its last digits: the sum's order is the ranks').
    pub fn norm_parts(
        &self,
        (v, held): (&[f64], Option<&[usize]>),
        cells: StressCells,
    ) -> [f64; 2] {
        let at = self.nodes_of(cells);
        let values: Vec<[f64; 3]> = match &at {
            None => nodal_vectors(self, v),
            Some(at) => at
                .iter()
                .map(|&i| nodal_vector(self, (v, held), i))
                .collect(),
        };
        let value = |node: usize| match &at {
            None => values[node],
            Some(at) => values[at.partition_point(|&a| a < node)],
        };
        let mut sums = [0.0; 2];
        let mut add = |t: &Cell| add_norms(t, |k| value(t.nodes[k]), &mut sums);
        match cells {
            StressCells::Of(vertices, _, nodes) => {
                for (v, t) in self.piece_cells(vertices, nodes) {
                    add_norms(&t, |k| values[v[k]], &mut sums);
                }
            }
            StressCells::Only(only) => {
                let source = self.cell_source();
                only.iter().for_each(|&c| add(&source.get(c)));
            }
            StressCells::All => self.cell_source().each(|_, t| add(t)),
        }
        sums
    }

    /// Lets go of the cells (where it held them: `solver.linear = "auto"`), of their
    /// vertices (rank 0's) and of each cell's material and region (`materials.distinct`
    /// stays): on a rank of several other than rank 0, nothing reads them once the
    /// matrices are assembled and the rank's layout is made, nor on rank 0 where it does
    /// not read every cell (`ranks::first_keeps_vertices`); a rank's piece of the frames
    /// makes its own cells from their vertices (`StressCells::Of`), and summary.json's
    /// norms are the pieces' sums ([`Discretization::norm_parts`]). With them goes the
    /// index of every dof, which the assembly of every cell read
    /// (`DofIndices::forget_whole`: a dof's is then found by searching the held dofs).
    /// [`Discretization::stress`] and
    /// [`Discretization::norms`] would see an empty mesh afterwards.
    pub fn forget_cells(&mut self) {
        self.free.forget_whole();
        self.cells = Vec::new();
        self.vertices = Vec::new();
        self.materials.of_cell = Vec::new();
        self.materials.region = Vec::new();
    }

    /// On a follower rank of several that keeps its own columns, past its setup: the
    /// places of the nodes it still reads alone ([`Places`]), those of its own unknowns
    /// (GAMG's rigid-body modes), of its rows of K_B and K_R^(0) made after PETSc's setup
    /// (their cells' vertices), of Γ3's rows, of the prescribed dofs (their values at each
    /// step), of the traction facets it keeps (rank 0's: history.csv's resultants make
    /// their points again) and `also` (its piece's points; on rank 0 history.csv's held
    /// nodes too, whose moments read them), of every node's places `all` (the mesh's), not
    /// every node's; every node's where it keeps every column (`own` is None), whose GAMG
    /// reads every node's. Rank 0 keeps them so where it lets go of its cells' vertices
    /// (`run`).
    pub fn keep_places(&mut self, all: &Places, also: &[usize]) {
        let Some(own) = &self.own else {
            self.nodes = all.clone();
            return;
        };
        let mut read = self.reaching(own);
        let cells = self.pair_cells.iter().flat_map(|c| &c.vertices);
        read.extend(cells.map(|&p| p as usize));
        read.extend(self.contact.iter().chain(&self.friction).map(|r| r.node));
        read.extend(self.prescribed.iter().map(|p| p.node));
        read.extend(self.loads.facet_nodes());
        read.extend(also);
        self.nodes = all.some(&increasing(read));
    }

    /// Its cells: those it holds ([`Discretization::cells`]), or on rank 0 of several
    /// each made from its vertices when it is read; none on a follower rank of several.
    pub fn cell_source(&self) -> CellSource<'_> {
        match self.vertices.is_empty() {
            true => CellSource::Held(&self.cells),
            false => CellSource::Vertices {
                vertices: &self.vertices,
                points: self.nodes.points(),
                dim: self.dim,
            },
        }
    }

    /// The number of cells of the mesh (those it holds, or their vertices).
    pub fn n_cells(&self) -> usize {
        self.cell_source().count()
    }
}

/// The `size` (rows, columns) leading block of `a` with its entries (i, j) where `keep(i,
/// j)`, in their order.
fn entries_kept(a: &Sparse, size: (usize, usize), keep: impl Fn(usize, usize) -> bool) -> Sparse {
    entries_placed(a, size, |i, j| i < size.0 && keep(i, j), |i| i)
}

/// The matrix of `a`'s rows and its columns `own` (increasing) alone, column k its
/// column `own[k]` (a rank's own columns: [`Discretization::own`]), with a's entries (i, j)
/// where `keep(i, j)`, in their order. Column k of `a` is read where `a` has as many
/// columns as `own` (its own columns already), column `own[k]` otherwise.
fn own_columns(a: &Sparse, own: &[usize], keep: impl Fn(usize, usize) -> bool) -> Sparse {
    let compact = a.ncols() == own.len();
    let column = |k: usize| if compact { k } else { own[k] };
    let a = a.as_ref();
    let (cp, ri, v) = (a.symbolic().col_ptr(), a.symbolic().row_idx(), a.val());
    let keep = &keep;
    let kept = |k: usize| (cp[column(k)]..cp[column(k) + 1]).filter(move |&p| keep(ri[p], own[k]));
    // At their exact size: they stay for the run.
    let entries = (0..own.len()).map(|k| kept(k).count()).sum();
    let mut col_ptr = Vec::with_capacity(own.len() + 1);
    let (mut row_idx, mut val) = (Vec::with_capacity(entries), Vec::with_capacity(entries));
    col_ptr.push(0);
    for k in 0..own.len() {
        for p in kept(k) {
            row_idx.push(ri[p]);
            val.push(v[p]);
        }
        col_ptr.push(row_idx.len());
    }
    let pattern = SymbolicSparseColMat::new_checked(a.nrows(), own.len(), col_ptr, None, row_idx);
    SparseColMat::new(pattern, val)
}

/// The matrix of `size` (rows, columns) made of `a`'s entries (i, j) where `keep(i, j)`, in
/// their order, each in row `place(i)` (increasing in i) of column j.
fn entries_placed(
    a: &Sparse,
    size: (usize, usize),
    keep: impl Fn(usize, usize) -> bool,
    place: impl Fn(usize) -> usize,
) -> Sparse {
    let a = a.as_ref();
    let (cp, ri, v) = (a.symbolic().col_ptr(), a.symbolic().row_idx(), a.val());
    let keep = &keep;
    let kept = |j: usize| (cp[j]..cp[j + 1]).filter(move |&p| keep(ri[p], j));
    // At their exact size: they stay for the run.
    let entries = (0..size.1).map(|j| kept(j).count()).sum();
    let mut col_ptr = Vec::with_capacity(size.1 + 1);
    let (mut row_idx, mut val) = (Vec::with_capacity(entries), Vec::with_capacity(entries));
    col_ptr.push(0);
    for j in 0..size.1 {
        for p in kept(j) {
            row_idx.push(place(ri[p]));
            val.push(v[p]);
        }
        col_ptr.push(row_idx.len());
    }
    let pattern = SymbolicSparseColMat::new_checked(size.0, size.1, col_ptr, None, row_idx);
    SparseColMat::new(pattern, val)
}

/// y_i += α (A x)_i for the unknowns i in `own`, whose columns the symmetric `a` keeps
/// whole and alone, column k the unknown `own[k]` (`Discretization::keep_columns`): its row.
pub fn mul_add_rows(a: &Sparse, own: &[usize], x: &[f64], alpha: f64, y: &mut [f64]) {
    let a = a.as_ref();
    let (cp, ri, v) = (a.symbolic().col_ptr(), a.symbolic().row_idx(), a.val());
    for (k, &i) in own.iter().enumerate() {
        let range = cp[k]..cp[k + 1];
        let row: f64 = (ri[range.clone()].iter().zip(&v[range]))
            .map(|(&j, a)| a * x[j])
            .sum();
        y[i] += alpha * row;
    }
}

/// The diagonal of the square matrix `a`.
pub fn diagonal(a: &Sparse) -> Vec<f64> {
    let a = a.as_ref();
    let (cp, ri, v) = (a.symbolic().col_ptr(), a.symbolic().row_idx(), a.val());
    (0..a.ncols())
        .map(|j| {
            (cp[j]..cp[j + 1])
                .find(|&k| ri[k] == j)
                .map_or(0.0, |k| v[k])
        })
        .collect()
}

/// The block of `a` on its first `n` rows and columns (a's rows increase in each column).
pub fn leading_block(a: &Sparse, n: usize) -> Sparse {
    entries_kept(a, (n, n), |_, _| true)
}

/// What [`Discretization::stress`] reads of the cells, packed: the d + 1 vertices (u32) and
/// the d components of each ∇φ_i, 60 bytes a triangle and 112 a tetrahedron where a [`Cell`]
/// takes 144. A frame at every step computes the stress on the writer thread beside the
/// time loop, whose solves read a factor that about fills the last-level cache at h = 1/128
/// (21 MB of 32): each byte the writer reads evicts one of the factor's. Built by the first
/// frame that writes the stress, on one process.
struct PackedCells {
    nodes: Vec<u32>,
    grad: Vec<f64>,
}

impl PackedCells {
    fn new(cells: &[Cell]) -> Self {
        let (mut nodes, mut grad) = (Vec::new(), Vec::new());
        for t in cells {
            for (g, &n) in t.grad[..=t.dim].iter().zip(&t.nodes[..=t.dim]) {
                nodes.push(n as u32);
                grad.extend_from_slice(&g[..t.dim]);
            }
        }
        PackedCells { nodes, grad }
    }
}

/// The first N components at every node of a free-dof vector (0 on Γ1 and beyond d), in
/// x, y, z (turned out of a node's frame where it has one).
pub fn nodal_vectors<const N: usize>(disc: &Discretization, v: &[f64]) -> Vec<[f64; N]> {
    (0..disc.nodes.len())
        .map(|i| nodal_vector(disc, (v, None), i))
        .collect()
}

/// The place of `dof`'s value in a vector held at the dofs `held` alone (increasing, among
/// which `dof` is: a follower rank's u_n and m_n, `history::Holds::Local`, and its w_n and
/// b_n, `time_loop`), or `dof` itself in a whole vector.
pub fn place(held: Option<&[usize]>, dof: usize) -> usize {
    place_if_held(held, dof).expect("a rank reads its vectors where it holds them")
}

/// [`place`], or None where `dof` is not among the dofs `held` (another rank's row, whose
/// terms that rank adds).
pub fn place_if_held(held: Option<&[usize]>, dof: usize) -> Option<usize> {
    held.map_or(Some(dof), |held| held.binary_search(&dof).ok())
}

/// [`nodal_vectors`] at node i, of `v` held at the dofs `held` alone where given
/// ([`place`]).
fn nodal_vector<const N: usize>(
    disc: &Discretization,
    (v, held): (&[f64], Option<&[usize]>),
    i: usize,
) -> [f64; N] {
    let d = disc.dim;
    let mut out = [0.0; N];
    for (k, o) in out.iter_mut().enumerate().take(d) {
        *o = (disc.free.get(d * i + k)).map_or(0.0, |dof| v[place(held, dof)]);
    }
    disc.frames.to_space(i, out)
}

/// ‖v‖_{L²} and |v|_{H¹} of a P1 vector field given by its nodal values, computed exactly:
/// per simplex of dimension d, ∫(Σ v_i φ_i)² = |T|/((d+1)(d+2)) (Σ v_i² + (Σ v_i)²), and the
/// gradient is constant.
pub fn p1_norms<const N: usize>(cells: &[Cell], v: &[[f64; N]]) -> (f64, f64) {
    let mut sums = [0.0; 2];
    (cells.iter()).for_each(|t| add_norms(t, |k| v[t.nodes[k]], &mut sums));
    (sums[0].sqrt(), sums[1].sqrt())
}

/// Adds cell `t`'s ∫(Σ v_i φ_i)² and ∫|∇(Σ v_i φ_i)|² to `sums`, a component at a time, of
/// the values `value(k)` at its k-th vertex.
fn add_norms<const N: usize>(t: &Cell, value: impl Fn(usize) -> [f64; N], sums: &mut [f64; 2]) {
    let count = t.dim + 1;
    let v: [[f64; N]; 4] = std::array::from_fn(|k| if k < count { value(k) } else { [0.0; N] });
    let v = &v[..count];
    let denom = ((t.dim + 1) * (t.dim + 2)) as f64;
    for c in 0..N {
        let s: f64 = v.iter().map(|v| v[c]).sum();
        let q: f64 = v.iter().map(|v| v[c] * v[c]).sum();
        sums[0] += t.measure / denom * (q + s * s);
        for k in 0..t.dim {
            let g: f64 = v.iter().enumerate().map(|(i, v)| t.grad[i][k] * v[c]).sum();
            sums[1] += t.measure * g * g;
        }
    }
}

/// ∫_g φ_i da at each node (zero off the group): a facet's measure shared equally by its
/// nodes, held at the group's nodes alone.
fn lumped_area(mesh: &Mesh, g: &Group) -> impl Fn(usize) -> f64 {
    let mut area = BTreeMap::new();
    for f in mesh.boundary_facets(g) {
        let share = f.measure / f.nodes().len() as f64;
        for &n in f.nodes() {
            *area.entry(n).or_insert(0.0) += share;
        }
    }
    move |node| area.get(&node).copied().unwrap_or(0.0)
}

/// Whether a unit direction is a coordinate axis (one nonzero component).
fn is_axis(dir: [f64; 3]) -> bool {
    dir.iter().filter(|c| c.abs() > 1e-12).count() == 1
}

/// Unit tangents at a boundary node with unit normal n: τ = (−n_y, n_x) in 2D; in 3D an
/// orthonormal pair τ_1 = e × n / |e × n| (e the coordinate axis least aligned with n),
/// τ_2 = n × τ_1. Any orthonormal pair gives the same |w_τ| (the friction is isotropic).
fn tangents(n: [f64; 3], d: usize) -> Vec<[f64; 3]> {
    if d == 2 {
        return vec![[-n[1], n[0], 0.0]];
    }
    let k = (0..3)
        .min_by(|&i, &j| n[i].abs().total_cmp(&n[j].abs()))
        .unwrap_or(0);
    let mut e = [0.0; 3];
    e[k] = 1.0;
    let t1 = cross(e, n);
    let len = norm(t1);
    let t1 = t1.map(|x| x / len);
    vec![t1, cross(n, t1)]
}

/// The scene's model must match the mesh's dimension.
/// A constraint group all of whose nodes are clamped: its condition would vanish silently.
fn on_fixed(scene: &Scene, role: &str, value: &str, table: &str) -> Error {
    Error::input(format!(
        "{}: key 'mesh.groups.{role}': every node of the group '{value}' lies on {}, so its \
         condition would have no effect; name the right group, or remove {table} (or set \
         enabled = false)",
        scene.path.display(),
        constraints::conditions(scene)
    ))
}

fn check_model(mesh: &Mesh, scene: &Scene) -> Result<()> {
    model_fits(mesh, scene.mesh.model, &scene.path)
}

/// For a scene that failed its checks, given its `[mesh]` as read: the mesh.model error if
/// the model does not fit the mesh. A 3D mesh run with a 2D model fails first on its
/// three-component loads; the model is what to fix, so that is reported.
pub fn model_mismatch(scene_path: &Path, mesh: &MeshChoice) -> Option<Error> {
    let read = Mesh::read(&mesh.file).ok()?;
    model_fits(&read, mesh.model, scene_path).err()
}

fn model_fits(mesh: &Mesh, model: Model, scene_path: &Path) -> Result<()> {
    let model_3d = model == Model::ThreeD;
    if model_3d == (mesh.dim == 3) {
        return Ok(());
    }
    let (has, fix) = if mesh.dim == 3 {
        ("tetrahedra (a 3D mesh)", "set mesh.model = \"3d\"")
    } else {
        (
            "triangles (a 2D mesh)",
            "set mesh.model = \"plane_stress\" or \"plane_strain\", or mesh the volume with \
             `gmsh -3`",
        )
    };
    Err(Error::input(format!(
        "{}: key 'mesh.model': the mesh '{}' has {has} but the model is \"{}\"; {fix}",
        scene_path.display(),
        mesh.path.display(),
        model.name()
    )))
}

/// Refuses NaN/∞ (and negative values where `nonnegative`) in data evaluated on the mesh.
pub(crate) fn check_data(
    v: f64,
    key: &str,
    scene: &Scene,
    p: [f64; 3],
    nonnegative: bool,
) -> Result<()> {
    if !v.is_finite() || (nonnegative && v < 0.0) {
        return Err(Error::input(format!(
            "{}: key '{key}' evaluates to {v} at {}; it must be finite{}",
            scene.path.display(),
            fmt_at(p, scene.mesh.model),
            if nonnegative { " and ≥ 0" } else { "" }
        )));
    }
    Ok(())
}

/// "(x, y) = (…, …)" in 2D, "(x, y, z) = (…, …, …)" in 3D, for messages.
pub(crate) fn fmt_at(p: [f64; 3], model: Model) -> String {
    match model {
        Model::ThreeD => format!("(x, y, z) = {}", crate::mesh::fmt_point(p, 3)),
        _ => format!("(x, y) = {}", crate::mesh::fmt_point(p, 2)),
    }
}

/// Refuses a contact group and a friction group that share a boundary facet (an edge in 2D,
/// a face in 3D): that facet would carry both conditions. Sharing nodes (where the two meet)
/// is normal.
fn check_overlap(mesh: &Mesh, scene: &Scene, contact: &Group, friction: &Group) -> Result<()> {
    let of_contact: std::collections::HashSet<Vec<usize>> = mesh
        .boundary_facets(contact)
        .iter()
        .map(loads::sorted)
        .collect();
    let shared: Vec<crate::mesh::Facet> = mesh
        .boundary_facets(friction)
        .into_iter()
        .filter(|f| of_contact.contains(&loads::sorted(f)))
        .collect();
    let Some(first) = shared.first() else {
        return Ok(());
    };
    let (facets, entity) = match mesh.dim {
        2 => ("edges", "curve"),
        _ => ("faces", "surface"),
    };
    let corners: Vec<String> = first
        .nodes()
        .iter()
        .map(|&n| crate::mesh::fmt_point(mesh.nodes[n], mesh.dim))
        .collect();
    Err(Error::input(format!(
        "{}: keys 'mesh.groups.contact' and 'mesh.groups.friction': the contact group '{}' and \
         the friction group '{}' of mesh '{}' share {} {facets} (the first {}): a boundary \
         {entity} carries either unilateral contact or the given normal stress with friction, \
         not both; put each {entity} into one of the two groups in gmsh (sharing the nodes \
         where they meet is fine), or disable one of [contact], [friction]",
        scene.path.display(),
        scene.mesh.groups.contact,
        scene.mesh.groups.friction,
        mesh.path.display(),
        shared.len(),
        corners.join("–")
    )))
}

/// Assembles K_A, K_B, K_R over all cells, each with its material (K_B where `elastic`, K_R
/// of the first `groups` memory groups), on the dofs with an index (`free`: the free and
/// the prescribed ones, n in all; rows and columns of dofs held at zero dropped; a node
/// with a frame in its frame's components, `Cell::parts_in`); the three share one sparsity
/// pattern ([`pattern`]). The element matrices are added at their positions (found by
/// bisection in the column): no triplets. Where `own` is given (a rank of several: its own
/// unknowns, increasing), their columns alone, column k the unknown own[k] (no column start
/// of the whole problem, 8 bytes a dof a matrix), from the cells that reach them alone
/// (those with a node of the rank's own): a rank's setup then makes and visits its part of
/// the mesh, not the whole. It finds an unknown among its own and a node among theirs by
/// binary search, holding no flag of every dof or node. Each entry held sums the same
/// terms in the same order.
fn assemble(
    cells: CellSource,
    d: usize,
    (free, frames, n): (&DofIndices, &Frames, usize),
    (materials, r): (&CellMaterials, Isotropic),
    (elastic, groups): (bool, usize),
    own: Option<&[usize]>,
) -> (Sparse, Option<Sparse>, Vec<Sparse>) {
    // The column of unknown j, where it has one.
    let column_of = |j: usize| match own {
        None => Some(j),
        Some(own) => own.binary_search(&j).ok(),
    };
    let node_of = column_nodes(free, d, own, n);
    // With `own`, the nodes of its unknowns, increasing.
    let mine = own.map(|_| increasing(node_of.clone()));
    let mine = mine.as_deref();
    let (col_ptr, row_idx) = pattern(cells, d, free, (&node_of, mine));
    drop(node_of);
    let reaches = |v: &[usize]| mine.is_none_or(|m| v.iter().any(|p| m.binary_search(p).is_ok()));
    let nnz = row_idx.len();
    let (mut va, mut vb, mut vr) = (
        vec![0.0; nnz],
        vec![0.0; if elastic { nnz } else { 0 }],
        vec![vec![0.0; nnz]; groups],
    );
    // The entries of the three matrices from the same two factors (`Cell::parts`), without
    // building three element matrices per cell.
    cells.each_where(reaches, |c, t| {
        let Stiffness { a, b, memory } = materials.of(c);
        let nodes = t.vertices();
        let frame = |i: usize| frames.of(nodes[i]);
        // The index of each of the cell's dofs and its column, found once a cell (a
        // follower searches the held dofs for it: `DofIndices`), not at each entry.
        let index_of = |j: usize, k: usize| match nodes.get(j) {
            Some(&p) if k < d => free.get(d * p + k),
            _ => None,
        };
        let index: [[Option<usize>; 3]; 4] =
            std::array::from_fn(|j| std::array::from_fn(|k| index_of(j, k)));
        let columns = index.map(|node| node.map(|i| i.and_then(&column_of)));
        for (j, cols) in columns.iter().enumerate().take(nodes.len()) {
            for (i, rows) in index.iter().enumerate().take(nodes.len()) {
                for (be, &col) in cols.iter().enumerate().take(d) {
                    let Some(col) = col else {
                        continue;
                    };
                    let column = &row_idx[col_ptr[col]..col_ptr[col + 1]];
                    for (al, &row) in rows.iter().enumerate().take(d) {
                        let Some(row) = row else {
                            continue;
                        };
                        let at = col_ptr[col] + column.partition_point(|&x| x < row);
                        let parts = t.parts_in([i, j], [al, be], [frame(i), frame(j)]);
                        va[at] += t.entry(a, parts);
                        if let Some(b) = b.filter(|_| elastic) {
                            vb[at] += t.entry(b, parts);
                        }
                        if let Some(g) = memory.filter(|&g| g < groups) {
                            vr[g][at] += t.entry(r, parts);
                        }
                    }
                }
            }
        }
    });
    // Each matrix owns its pattern: the last takes this one, so that no spare copy of it
    // stands beside them at the setup's peak.
    let columns = col_ptr.len() - 1;
    let pattern = SymbolicSparseColMat::new_checked(n, columns, col_ptr, None, row_idx);
    let k_b = elastic.then(|| SparseColMat::new(pattern.clone(), vb));
    let k_r = (vr.into_iter())
        .map(|v| SparseColMat::new(pattern.clone(), v))
        .collect();
    (SparseColMat::new(pattern, va), k_b, k_r)
}

/// The node of each of [`assemble`]'s columns: column k's unknown is own[k], or k of the
/// n indices without `own`.
fn column_nodes(free: &DofIndices, d: usize, own: Option<&[usize]>, n: usize) -> Vec<usize> {
    let node = |j: usize| free.global(j) / d;
    match own {
        Some(own) => own.iter().map(|&j| node(j)).collect(),
        None => (0..n).map(node).collect(),
    }
}

/// The sparsity pattern of [`assemble`]'s matrices, column pointers and row indices,
/// built from the cells' vertices: node q couples with node p when a cell holds both. The
/// column of index j, a component of node p, lists the indices of the components of p's
/// neighbours q, increasing; column k's node is node_of[k] ([`column_nodes`]). Only the
/// nodes with a column list their neighbours: every node, or those `mine` names
/// (increasing; a rank of several: its own nodes, not the whole mesh's, each list at its
/// place there), and the row indices are allocated once, at their exact count.
fn pattern(
    cells: CellSource,
    d: usize,
    free: &DofIndices,
    (node_of, mine): (&[usize], Option<&[usize]>),
) -> (Vec<usize>, Vec<usize>) {
    let dofs = |p: usize| free.of_node(d, p);
    let has_dofs = |p: usize| dofs(p).next().is_some();
    // The place of node p's list, where it has one.
    let list_of = |p: usize| match mine {
        None => dofs(p).next().map(|_| p),
        Some(mine) => mine.binary_search(&p).ok(),
    };
    let mut neighbours: Vec<Vec<u32>> = vec![Vec::new(); mine.map_or(free.dofs() / d, <[_]>::len)];
    cells.each_vertices(|vertices| {
        let has: [bool; 4] = std::array::from_fn(|i| vertices.get(i).is_some_and(|&q| has_dofs(q)));
        for list in vertices.iter().filter_map(|&p| list_of(p)) {
            let with_dofs = vertices.iter().zip(has).filter(|&(_, has)| has);
            neighbours[list].extend(with_dofs.map(|(&q, _)| q as u32));
        }
    });
    for list in neighbours.iter_mut() {
        list.sort_unstable();
        list.dedup();
    }
    let list = |p: usize| &neighbours[list_of(p).expect("a column's node has a list")];
    // Column k, of node p, lists p's neighbours' unknowns: the same for each of p's columns,
    // which follow each other (a node's unknowns are consecutive but where some are
    // prescribed), so they are found once for a run of them (a follower searches the held
    // dofs for each: `DofIndices`).
    let runs = || {
        node_of
            .chunk_by(|p, q| p == q)
            .map(|run| (run[0], run.len()))
    };
    let count = |p: usize| -> usize { (list(p).iter()).map(|&q| dofs(q as usize).count()).sum() };
    let mut row_idx = Vec::with_capacity(runs().map(|(p, len)| len * count(p)).sum());
    let mut col_ptr = Vec::with_capacity(node_of.len() + 1);
    col_ptr.push(0);
    for (p, len) in runs() {
        let start = row_idx.len();
        (list(p).iter()).for_each(|&q| row_idx.extend(dofs(q as usize)));
        row_idx[start..].sort_unstable();
        let end = row_idx.len();
        col_ptr.push(end);
        for _ in 1..len {
            row_idx.extend_from_within(start..end);
            col_ptr.push(row_idx.len());
        }
    }
    (col_ptr, row_idx)
}
