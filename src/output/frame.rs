//! The frame of a solved step: the fields of DESIGN.md "Output of run" computed from the
//! step's velocity w_n, displacement u_n, memory m_n and multipliers z_n.

use std::path::Path;

use super::{Field, Frame, Geometry, Options, Series};
use crate::fem::Discretization;
use crate::mesh::Mesh;
use crate::scene::Scene;
use crate::solver::Rows;
use crate::time_loop::Step;
use crate::Result;

/// The series of a run on `mesh` in `out`: a new one, or for a resume from a checkpoint of
/// step n ≥ 1 the existing one continued after step `keep_until` = n − 1
/// ([`Series::reopen`]).
pub fn open_series(
    out: &Path,
    mesh: &Mesh,
    run_id: &str,
    options: &Options,
    keep_until: Option<usize>,
) -> Result<Series> {
    let (cells, nodes_per_cell) = mesh.cell_nodes();
    let region = region(mesh);
    let geometry = Geometry {
        points: &mesh.nodes,
        cells: &cells,
        nodes_per_cell,
        region: &region,
    };
    match keep_until {
        None => Series::create(out, &geometry, run_id, options),
        Some(step) => Series::reopen(out, &geometry, run_id, options, step),
    }
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

impl Series {
    /// Writes the frame of step `step`; `active[i]` says whether contact/friction row block
    /// `i` is active (the run's state flags). Fields not chosen are not computed.
    pub fn write_step(
        &mut self,
        disc: &Discretization,
        scene: &Scene,
        rows: &Rows,
        step: &Step,
        active: &[bool],
    ) -> Result<()> {
        let nn = disc.nodes.len();
        let u = disc.nodal(step.u);
        let w = disc.nodal(step.w);
        let (stress, von_mises) =
            if self.options().wants("stress") || self.options().wants("von_mises") {
                disc.stress(step.w, step.u, step.m, scene.model)
            } else {
                (Vec::new(), Vec::new())
            };
        // Nodal tractions from the multipliers: p = λ_i / ∫φ_i (contact pressure, ≥ 0) and
        // the friction traction γ_i / ∫φ_i: a scalar along τ_i in 2D, the tangential vector
        // Σ_k γ_ik τ_ik / ∫φ_i in 3D.
        let fc = if disc.dim == 2 { 1 } else { 3 };
        let mut pressure = vec![0.0; nn];
        let mut friction = vec![0.0; fc * nn];
        let mut state = vec![0.0; nn];
        for ((i, r), &on) in rows.rows.iter().enumerate().zip(active) {
            if i < rows.n_contact {
                pressure[r.node] = step.z[i] / r.area;
            } else if fc == 1 {
                friction[r.node] = step.z[i] / r.area;
            } else {
                for (k, t) in r.dir.iter().enumerate() {
                    friction[3 * r.node + k] += step.z[i] * t / r.area;
                }
            }
            if on {
                state[r.node] = 1.0;
            }
        }
        let field = |name, components, values| Field {
            name,
            components,
            values,
        };
        let mut cell_data = Vec::new();
        if !stress.is_empty() {
            cell_data.push(field("stress", 6, &stress[..]));
            cell_data.push(field("von_mises", 1, &von_mises[..]));
        }
        self.write(&Frame {
            step: step.n,
            time: step.t,
            point_data: vec![
                field("displacement", 3, &u),
                field("velocity", 3, &w),
                field("contact_pressure", 1, &pressure),
                field("friction_traction", fc, &friction),
                field("contact_state", 1, &state),
            ],
            cell_data,
        })?;
        Ok(())
    }
}
