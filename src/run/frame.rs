//! The frame of a solved step: the fields of docs/output.md computed from the
//! step's velocity w_n, displacement u_n, memory m_n and multipliers z_n, handed to the
//! series (`output`), which knows files, not the model.

use std::path::Path;
use std::sync::mpsc::Receiver;
use std::sync::Arc;

use crate::fem::Discretization;
use crate::mesh::Mesh;
use crate::output::{Geometry, Options, OwnedField, Resumed, Series};
use crate::scene::Model;
use crate::solver::Rows;
use crate::time_loop::Step;
use crate::Result;

/// The series of a run on `mesh` (discretized as `disc`) in `out`, its frames in a piece
/// per rank where `own` holds the ranks' layout (a run over several MPI ranks): a new one,
/// or for a resume from a checkpoint of step n ≥ 1 the existing one, verified and continued
/// after step n − 1 ([`Series::resume`]).
pub(super) fn open_series(
    out: &Path,
    (mesh, disc): (&Mesh, &Discretization),
    own: Option<&crate::ranks::Own>,
    run_id: &str,
    options: &Options,
    resumed: Option<&Resumed>,
) -> Result<Series> {
    let (cells, nodes_per_cell) = mesh.cell_nodes();
    let region = region(mesh);
    let pieces = pieces(disc, (&cells, nodes_per_cell), own, options);
    let geometry = Geometry {
        points: &mesh.nodes,
        cells: &cells,
        nodes_per_cell,
        region: &region,
        material_region: &disc.materials.region,
        pieces: &pieces,
    };
    match resumed {
        Some(r) if r.step > 0 => Series::resume(out, &geometry, run_id, options, r),
        _ => Series::create(out, &geometry, run_id, options),
    }
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
    let stress = series.options().wants("stress") || series.options().wants("von_mises");
    let (tx, rx) = std::sync::mpsc::sync_channel(1);
    series.write_with(step.n, step.t, move || {
        let (points, cells) = fields(
            &disc,
            model,
            &rows,
            &active,
            stress,
            [&w, &u, &z],
            m.as_deref(),
        );
        if let Some(vm) = cells.iter().find(|f| f.name == "von_mises") {
            let _ = tx.send(max_von_mises(&vm.values));
        }
        (points, cells)
    })?;
    Ok(stress.then_some(rx))
}

/// The largest von Mises stress of a step's cells (0 without cells), as history.csv
/// records it.
fn max_von_mises(von_mises: &[f64]) -> f64 {
    von_mises.iter().copied().fold(0.0, f64::max)
}

/// The fields of a step's frame (docs/output.md): point fields, then cell fields
/// (the stress and von Mises stress when `stress`), from `[w, u, z]` and m.
fn fields(
    disc: &Discretization,
    model: Model,
    rows: &Rows,
    active: &[bool],
    stress: bool,
    [w, u, z]: [&[f64]; 3],
    m: Option<&[f64]>,
) -> (Vec<OwnedField>, Vec<OwnedField>) {
    let nn = disc.nodes.len();
    // Nodal tractions from the multipliers: p = λ_i / ∫φ_i (contact pressure, ≥ 0) and the
    // friction traction γ_i / ∫φ_i: a scalar along τ_i in 2D, the tangential vector
    // Σ_k γ_ik τ_ik / ∫φ_i in 3D.
    let fc = if disc.dim == 2 { 1 } else { 3 };
    let mut pressure = vec![0.0; nn];
    let mut friction = vec![0.0; fc * nn];
    let mut state = vec![0.0; nn];
    for ((i, r), &on) in rows.rows.iter().enumerate().zip(active) {
        if i < rows.n_contact {
            pressure[r.node] = z[i] / r.area;
        } else if fc == 1 {
            friction[r.node] = z[i] / r.area;
        } else {
            let tau = disc.frames.to_space(r.node, r.dir);
            for (k, t) in tau.iter().enumerate() {
                friction[3 * r.node + k] += z[i] * t / r.area;
            }
        }
        if on {
            state[r.node] = 1.0;
        }
    }
    let field = |name: &str, components, values| OwnedField {
        name: name.to_string(),
        components,
        values,
    };
    let mut cell_data = Vec::new();
    if stress {
        let (stress, von_mises) = disc.stress(w, u, m, model);
        cell_data.push(field("stress", 6, stress));
        cell_data.push(field("von_mises", 1, von_mises));
    }
    let point_data = vec![
        field("displacement", 3, disc.nodal(u)),
        field("velocity", 3, disc.nodal(w)),
        field("contact_pressure", 1, pressure),
        field("friction_traction", fc, friction),
        field("contact_state", 1, state),
    ];
    (point_data, cell_data)
}
