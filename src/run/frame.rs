//! The frame of a solved step: the fields of docs/output.md computed from the
//! step's velocity w_n, displacement u_n, memory m_n and multipliers z_n, handed to the
//! series (`output`), which knows files, not the model.

use std::path::{Path, PathBuf};
use std::sync::mpsc::Receiver;
use std::sync::Arc;

use crate::fem::{Discretization, StressCells};
use crate::mesh::Mesh;
use crate::output::{Geometry, Options, OwnPiece, OwnedField, PieceMesh, Resumed, Series};
use crate::ranks::Ranks;
use crate::scene::{Model, Scene};
use crate::solver::Rows;
use crate::time_loop::{Solved, Step};
use crate::Result;

/// The series of a run of `scene` on `mesh` (discretized as `disc`) in `out`, its frames
/// in a piece per rank where `own` holds the ranks' layout (a run over several MPI ranks): a
/// new one, or for a resume from a checkpoint of step n ≥ 1 the existing one, verified and
/// continued after step n − 1 ([`Series::resume`]). Where the ranks write their own pieces,
/// also rank 0's piece of the frames.
pub(super) fn open_series(
    (out, run_id): (&Path, &str),
    (mesh, disc): (&Mesh, &Discretization),
    (own, ranks): (Option<&crate::ranks::Own>, Ranks),
    scene: &Scene,
    resumed: Option<&Resumed>,
) -> Result<(Series, Option<OwnFrames>)> {
    let options = &scene.output.options;
    with_geometry((mesh, disc), own, options, |geometry| {
        let series = match resumed {
            Some(r) if r.step > 0 => Series::resume(out, geometry, run_id, options, r),
            _ => Series::create(out, geometry, run_id, options),
        }?;
        let setup = piece_of(geometry, 0, options).map(|mesh| PieceSetup {
            mesh,
            materials: None,
        });
        let first = setup.map(|s| OwnFrames::new(s, (out, run_id), scene, ranks));
        Ok((series, first))
    })
}

/// A rank's piece of the frames as its setup leaves it: the piece's mesh (None where its
/// part has no cells) and, on a follower, whose discretization holds no cell, the
/// material of each of the piece's cells (rank 0 holds every cell's vertices and material).
pub(super) struct PieceSetup {
    mesh: Option<PieceMesh>,
    materials: Option<Vec<u32>>,
}

impl PieceSetup {
    /// The piece's points: the nodes of its cells, increasing.
    pub fn points(&self) -> &[usize] {
        self.mesh.as_ref().map_or(&[][..], PieceMesh::points)
    }

    /// The dofs of the piece's points: where its fields read u_n, w_n and m_n.
    pub fn dofs(&self, disc: &Discretization) -> Vec<usize> {
        dofs_of(disc, self.points())
    }
}

/// The free dofs of the nodes `points`: where a piece's fields read u_n, w_n and m_n.
pub(super) fn dofs_of(disc: &Discretization, points: &[usize]) -> Vec<usize> {
    let d = disc.dim;
    (points.iter())
        .flat_map(|&p| disc.free.of_node(d, p))
        .collect()
}

/// A follower's piece of the frames of `mesh` where the ranks write their own (`own`:
/// their layout; `.vtu` frames); None where the frames are not in pieces.
pub(super) fn piece_of_follower(
    (mesh, disc): (&Mesh, &Discretization),
    own: Option<&crate::ranks::Own>,
    options: &Options,
    rank: usize,
) -> Option<PieceSetup> {
    let mesh = with_geometry((mesh, disc), own, options, |g| piece_of(g, rank, options))?;
    let materials = mesh.as_ref().map(|p| materials_of(p, disc));
    Some(PieceSetup { mesh, materials })
}

/// The material of each of the piece `mesh`'s cells, from `disc`'s cells.
fn materials_of(mesh: &PieceMesh, disc: &Discretization) -> Vec<u32> {
    let of_cell = &disc.materials.of_cell;
    mesh.cells().iter().map(|&c| of_cell[c]).collect()
}

/// Rank `rank`'s piece of the frames' geometry `g`: its mesh, None inside where its part
/// has no cells; None where the frames are not in pieces.
fn piece_of(g: &Geometry, rank: usize, options: &Options) -> Option<Option<PieceMesh>> {
    (!g.pieces.is_empty()).then(|| PieceMesh::of_rank(g, rank, options))
}

/// `f` of the geometry of the frames of `mesh` (discretized as `disc`): each cell's piece
/// where the ranks write their own ([`pieces`]).
fn with_geometry<T>(
    (mesh, disc): (&Mesh, &Discretization),
    own: Option<&crate::ranks::Own>,
    options: &Options,
    f: impl FnOnce(&Geometry) -> T,
) -> T {
    let (cells, nodes_per_cell) = mesh.cell_nodes();
    let region = region(mesh);
    let pieces = pieces(disc, (&cells, nodes_per_cell), own, options);
    f(&Geometry {
        points: mesh.nodes.points(),
        cells: &cells,
        nodes_per_cell,
        region: &region,
        material_region: &disc.materials.region,
        pieces: &pieces,
        pieces_by_ranks: true,
    })
}

/// Each cell's piece where the frames of a run over several ranks (`own`: their layout,
/// whose partition the pieces follow) are `.vtu` files (a `.pvtu` a frame with a piece per
/// rank's part of the mesh, docs/output.md); else none, one file a frame. Only a build with
/// PETSc runs over several ranks.
fn pieces(
    disc: &Discretization,
    (cells, nodes_per_cell): (&[usize], usize),
    own: Option<&crate::ranks::Own>,
    options: &Options,
) -> Vec<u32> {
    #[cfg(feature = "petsc")]
    if let Some(own) = own.filter(|_| options.format == crate::output::Format::Vtu) {
        return own.layout.cell_pieces(disc, cells, nodes_per_cell);
    }
    let _ = (disc, cells, nodes_per_cell, own, options);
    Vec::new()
}

/// A rank's own piece of the frames of a run over several ranks whose frames are `.vtu`
/// files: at a frame's step every rank computes the fields of its piece's cells and
/// points alone and writes its piece, the ranks agree that every piece is on disk
/// ([`Ranks::written`], which also gives the largest von Mises stress of them all), and
/// rank 0's series then lists them in the frame's `.pvtu` (`Series::list_pieces`). At a
/// step whose frame does not give history.csv that stress, each rank computes it of its
/// piece's cells and the ranks take the largest ([`OwnFrames::solved`]). No rank computes
/// the whole mesh's fields, nor the stress of every cell.
///
/// The piece's encoded mesh is made at the first step, after PETSc's setup, where a rank
/// of a few peaks: until then the rank keeps the piece's mesh alone (its node numbers and
/// points), and a follower none of the cells that assembled its columns
/// (`Discretization::forget_cells`). A follower then keeps its piece's cells as their
/// vertices and makes each when it reads it, as rank 0 does its own (`fem::StressCells`).
pub(super) struct OwnFrames {
    piece: Piece,
    /// The series' directory and the run id, which the piece's file records.
    out: (PathBuf, String),
    every: usize,
    model: Model,
    options: Options,
    ranks: Ranks,
}

/// A rank's piece of the frames, before and after its first step.
enum Piece {
    /// This rank's part has no cells.
    None,
    /// Before the first step: the piece's mesh, and the material of each of its cells (a
    /// follower's, and rank 0's where it lets go of its cells: None where it holds every
    /// cell's vertices and material).
    Mesh(PieceMesh, Option<Vec<u32>>),
    /// The piece and (where its materials were given) its cells' vertices (dim + 1 a
    /// cell, each by its place among the piece's points), from which
    /// [`Discretization::stress`] makes each cell when it reads it, and their materials.
    Made(Box<OwnPiece>, Option<(Vec<usize>, Vec<u32>)>),
}

impl OwnFrames {
    /// This rank's frames of its piece `setup` in the series of `out`.
    pub fn new(
        setup: PieceSetup,
        (out, run_id): (&Path, &str),
        scene: &Scene,
        ranks: Ranks,
    ) -> OwnFrames {
        let PieceSetup { mesh, materials } = setup;
        OwnFrames {
            piece: mesh.map_or(Piece::None, |m| Piece::Mesh(m, materials)),
            out: (out.to_path_buf(), run_id.to_string()),
            every: scene.output.every,
            model: scene.mesh.model,
            options: scene.output.options.clone(),
            ranks,
        }
    }

    /// At solved step `s` (`active`: the run's state flags), writes this rank's piece of
    /// its frame where one is due ([`OwnFrames::write`]), and returns the frame's fields by
    /// name (None without a frame) and history.csv's largest von Mises stress of every
    /// rank's cells (collective on several): each rank's of its own piece's cells (the
    /// frame's, or computed for the row), and the largest of those in one reduction, the
    /// frame's or its own. The pieces split the cells, so that is a maximum over every
    /// cell, one process's bits, and no rank computes the stress of every cell at a step.
    pub fn solved(
        &mut self,
        disc: &Discretization,
        s: &Solved,
        active: &[bool],
    ) -> Result<(Option<Named>, f64)> {
        if due(self.every, s) {
            let (names, largest) = self.write(disc, &s.step, active)?;
            return Ok((Some(names), largest));
        }
        let mine = self.make().map(|()| self.piece_von_mises(disc, &s.step));
        Ok((None, self.ranks.written(mine)?))
    }

    /// Writes this rank's piece of step `step`'s frame (`active`: the run's state flags),
    /// and waits until every rank has written its own (collective). Returns the frame's
    /// fields by name and components (their values left out: what the `.pvtu` lists) and
    /// the largest von Mises stress of every rank's cells, of the frame's field or, where
    /// the frame has none, computed for history.csv.
    fn write(
        &mut self,
        disc: &Discretization,
        step: &Step,
        active: &[bool],
    ) -> Result<(Named, f64)> {
        let (names, mine) = match self.write_piece(disc, step, active) {
            Ok((names, vm)) => (names, Ok(vm)),
            Err(e) => (Named::default(), Err(e)),
        };
        Ok((names, self.ranks.written(mine)?))
    }

    /// [`OwnFrames::write`] on this rank alone: the fields' names and its cells' largest
    /// von Mises stress.
    fn write_piece(
        &mut self,
        disc: &Discretization,
        step: &Step,
        active: &[bool],
    ) -> Result<(Named, f64)> {
        self.make()?;
        let Some(cells) = self.stress_cells() else {
            return Ok((Named::default(), 0.0));
        };
        let [w, u, z] = [step.w, step.u, step.z];
        let cells = wants_stress(&self.options).then_some(cells);
        let at = match &self.piece {
            Piece::Made(piece, _) => piece.points(),
            _ => &[],
        };
        let fields = fields(
            disc,
            (self.model, Some(at)),
            step.rows,
            active,
            cells,
            [w, u, z],
            (step.m, [step.held, step.local]),
        );
        let (points, cells) = fields;
        let named = |fields: &[OwnedField]| -> Vec<OwnedField> {
            let named = |f: &OwnedField| OwnedField {
                name: f.name.clone(),
                components: f.components,
                values: Vec::new(),
            };
            fields.iter().map(named).collect()
        };
        let names = (named(&points), named(&cells));
        let vm = match cells.iter().find(|f| f.name == "von_mises") {
            Some(f) => max_von_mises(&f.values),
            None => self.piece_von_mises(disc, step),
        };
        if let Piece::Made(piece, _) = &mut self.piece {
            piece.write(step.n, points, cells)?;
        }
        Ok((names, vm))
    }

    /// The largest von Mises stress of this rank's piece's cells at step `step` (0 without
    /// cells), once made (`make`).
    fn piece_von_mises(&self, disc: &Discretization, step: &Step) -> f64 {
        let Some(cells) = self.stress_cells() else {
            return 0.0;
        };
        let held = (step.m, [step.held, step.local]);
        disc.max_von_mises([step.w, step.u], held, self.model, cells)
    }

    /// ‖u‖²_{L²} and |u|²_{H¹} over the piece's cells (`u` held at the dofs given alone
    /// where some are: `TimeLoop::u_held`), made or not: this rank's part of summary.json's
    /// norms ([`Discretization::norm_parts`]; zero where its part has no cells).
    pub fn norm_parts(&self, disc: &Discretization, u: (&[f64], Option<&[usize]>)) -> [f64; 2] {
        match &self.piece {
            Piece::None => [0.0; 2],
            Piece::Mesh(mesh, Some(materials)) => {
                let cells = StressCells::Of(mesh.connectivity(), materials, mesh.points());
                disc.norm_parts(u, cells)
            }
            Piece::Mesh(mesh, None) => disc.norm_parts(u, StressCells::Only(mesh.cells())),
            Piece::Made(..) => (self.stress_cells()).map_or([0.0; 2], |c| disc.norm_parts(u, c)),
        }
    }

    /// The piece's points, the nodes of its cells (increasing; none where its part has no
    /// cells).
    pub fn points(&self) -> &[usize] {
        match &self.piece {
            Piece::None => &[],
            Piece::Mesh(mesh, _) => mesh.points(),
            Piece::Made(piece, _) => piece.points(),
        }
    }

    /// On rank 0, whose discretization lets go of its cells' vertices
    /// (`run::first_lets_go_of_cells`): its piece keeps its own cells' materials, from which
    /// it makes them as a follower's does.
    pub fn keep_own_cells(&mut self, disc: &Discretization) {
        if let Piece::Mesh(mesh, materials @ None) = &mut self.piece {
            *materials = Some(materials_of(mesh, disc));
        }
    }

    /// The piece's cells as [`Discretization::stress`] reads them, once made (`make`): a
    /// follower's own, rank 0's among the discretization's; None on a follower whose part
    /// has no cells (rank 0 then lists none, and still writes the frame's `.pvtu`).
    fn stress_cells(&self) -> Option<StressCells<'_>> {
        match &self.piece {
            Piece::Made(piece, Some((cells, materials))) => {
                Some(StressCells::Of(cells, materials, piece.points()))
            }
            Piece::Made(piece, None) => Some(StressCells::Only(piece.cells())),
            _ if self.ranks.is_first() => Some(StressCells::Only(&[])),
            _ => None,
        }
    }

    /// Makes the piece (its mesh encoded), with its cells' vertices where it keeps them, at
    /// the first step.
    fn make(&mut self) -> Result<()> {
        self.piece = match std::mem::replace(&mut self.piece, Piece::None) {
            Piece::Mesh(mesh, materials) => {
                let cells = materials.map(|m| (mesh.connectivity().to_vec(), m));
                let (out, run_id) = &self.out;
                let piece = OwnPiece::new(out, mesh, run_id, &self.options)?;
                Piece::Made(Box::new(piece), cells)
            }
            made => made,
        };
        Ok(())
    }
}

/// A frame's point fields and cell fields by name and components, without values.
pub(super) type Named = (Vec<OwnedField>, Vec<OwnedField>);

/// Whether a run writes the frame of step `s`: at every `every`-th step and the last.
pub(super) fn due(every: usize, s: &Solved) -> bool {
    s.step.n.is_multiple_of(every) || s.last
}

/// The gmsh physical tag of each cell: the first group of the cells' dimension (in file
/// order) that holds it, 0 for a cell in none (gmsh tags are ≥ 1).
pub fn region(mesh: &Mesh) -> Vec<i32> {
    let mut tags = vec![0; mesh.n_cells()];
    for g in mesh.groups.iter().filter(|g| g.dim == mesh.dim).rev() {
        for &c in &g.cells {
            tags[c] = g.tag;
        }
    }
    tags
}

/// Hands the frame of step `step` to the writer thread; `active[i]` says whether
/// contact/friction row block `i` is active (the run's state flags). The time loop only
/// copies the step's state (w, u, m, z: a few hundred kB at h = 1/128); the fields are
/// computed on the writer thread, which shares `disc` and `rows`. Fields not chosen are
/// not computed. When the frame has the von Mises stress, its largest value is sent on the
/// receiver returned, once computed (history.csv's row takes it instead of computing the
/// stress again); a frame never made drops the sender.
pub(super) fn write_step(
    series: &mut Series,
    disc: &Arc<Discretization>,
    model: Model,
    rows: &Arc<Rows>,
    step: &Step,
    active: &[bool],
) -> Result<Option<Receiver<f64>>> {
    let (disc, rows) = (Arc::clone(disc), Arc::clone(rows));
    let (w, u, m, z) = (
        step.w.to_vec(),
        step.u.to_vec(),
        step.m.map(<[f64]>::to_vec),
        step.z.to_vec(),
    );
    let active = active.to_vec();
    let stress = wants_stress(series.options());
    let (tx, rx) = std::sync::mpsc::sync_channel(1);
    series.write_with(step.n, step.t, move || {
        let (points, cells) = fields(
            &disc,
            (model, None),
            &rows,
            &active,
            stress.then_some(StressCells::All),
            [&w, &u, &z],
            (m.as_deref(), [None; 2]),
        );
        if let Some(vm) = cells.iter().find(|f| f.name == "von_mises") {
            let _ = tx.send(max_von_mises(&vm.values));
        }
        (points, cells)
    })?;
    Ok(stress.then_some(rx))
}

/// Whether a frame has a field of the stresses (the stress or the von Mises stress).
fn wants_stress(options: &Options) -> bool {
    options.wants("stress") || options.wants("von_mises")
}

/// The largest von Mises stress of a step's cells (0 without cells), as history.csv
/// records it.
fn max_von_mises(von_mises: &[f64]) -> f64 {
    von_mises.iter().copied().fold(0.0, f64::max)
}

/// The fields of a step's frame (docs/output.md): point fields, then cell fields (the
/// stress and von Mises stress of the cells `cells` says, where it is Some), from
/// `[w, u, z]` and m. The point fields are of every node, or of the nodes `at` alone, in
/// their order (increasing: a rank's piece of the frame, whose other points are other
/// pieces'). w, and u and m, hold their values at the dofs `held` gives alone where it
/// gives some (a follower's, `Step::held` and `Step::local`: its piece's are among them).
fn fields(
    disc: &Discretization,
    (model, at): (Model, Option<&[usize]>),
    rows: &Rows,
    active: &[bool],
    cells: Option<StressCells>,
    [w, u, z]: [&[f64]; 3],
    (m, held): (Option<&[f64]>, [Option<&[usize]>; 2]),
) -> (Vec<OwnedField>, Vec<OwnedField>) {
    let count = at.map_or(disc.nodes.len(), <[usize]>::len);
    let point = |node: usize| match at {
        None => Some(node),
        Some(at) => at.binary_search(&node).ok(),
    };
    // Nodal tractions from the multipliers: p = λ_i / ∫φ_i (contact pressure, ≥ 0) and the
    // friction traction γ_i / ∫φ_i: a scalar along τ_i in 2D, the tangential vector
    // Σ_k γ_ik τ_ik / ∫φ_i in 3D.
    let fc = if disc.dim == 2 { 1 } else { 3 };
    let mut pressure = vec![0.0; count];
    let mut friction = vec![0.0; fc * count];
    let mut state = vec![0.0; count];
    for ((i, r), &on) in rows.rows.iter().enumerate().zip(active) {
        let Some(p) = point(r.node) else {
            continue;
        };
        if i < rows.n_contact {
            pressure[p] = z[i] / r.area;
        } else if fc == 1 {
            friction[p] = z[i] / r.area;
        } else {
            let tau = disc.frames.to_space(r.node, r.dir);
            for (k, t) in tau.iter().enumerate() {
                friction[3 * p + k] += z[i] * t / r.area;
            }
        }
        if on {
            state[p] = 1.0;
        }
    }
    let field = |name: &str, components, values| OwnedField {
        name: name.to_string(),
        components,
        values,
    };
    let mut cell_data = Vec::new();
    if let Some(only) = cells {
        let (stress, von_mises) = disc.stress([w, u], (m, held), model, only);
        cell_data.push(field("stress", 6, stress));
        cell_data.push(field("von_mises", 1, von_mises));
    }
    let nodal = |v, held| match at {
        None => disc.nodal(v),
        Some(at) => disc.nodal_at((v, held), at),
    };
    let point_data = vec![
        field("displacement", 3, nodal(u, held[1])),
        field("velocity", 3, nodal(w, held[0])),
        field("contact_pressure", 1, pressure),
        field("friction_traction", fc, friction),
        field("contact_state", 1, state),
    ];
    (point_data, cell_data)
}
