//! Effects: Remark 2.5 of the paper as a rule — simulate only what the scene calls for.
//! No Γ3,1 (or contact disabled) → no constraint; no Γ3,2, friction disabled or μF = 0 → no
//! friction term; no relaxation → no memory state; neither contact nor friction → every step
//! is one solve with the stored factorization and no optimization solver is built.

use crate::fem::{Discretization, Gamma3, Sparse};
use crate::mesh::{fmt_num, fmt_point};
use crate::scene::Scene;
use crate::solver::active_set::ActiveSetSolver;
use crate::solver::choice::{Contact, Descriptor};
use crate::solver::matrix_free::MatrixFreeSolver;
use crate::solver::{conic::ConicSolver, dual::DualSolver, Backend, Rows, StepSolver};
use crate::{Error, Result};

/// Which terms of (3.1) a run carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Effects {
    /// Aε(w): always (θ > 0).
    pub viscosity: bool,
    /// Bε(u_n): E > 0 and not disabled.
    pub elasticity: bool,
    /// kΣ R(t_n − t_j) ε(u_j): a relaxation kernel is given.
    pub memory: bool,
    /// Unilateral constraint n·w ≤ 0 at the Γ3,1 nodes.
    pub contact: bool,
    /// Coulomb friction μF|w_τ| at the Γ3,2 nodes.
    pub friction: bool,
    /// The given normal stress F on Γ3,2 (the load g_F).
    pub normal_stress: bool,
    pub tractions: bool,
    pub body_force: bool,
}

impl Effects {
    pub fn new(scene: &Scene, disc: &Discretization) -> Self {
        Effects {
            viscosity: true,
            elasticity: disc.k_b.is_some(),
            memory: (disc.materials.distinct.iter()).any(|s| s.memory.is_some()),
            contact: !disc.contact.is_empty(),
            friction: !disc.friction.is_empty(),
            normal_stress: !disc.g_f.is_empty(),
            tractions: !scene.physics.tractions.is_empty(),
            body_force: !scene.physics.body_forces.is_empty(),
        }
    }

    /// The names listed in summary.json and by `check`.
    pub fn names(&self) -> Vec<&'static str> {
        [
            (self.viscosity, "viscosity"),
            (self.elasticity, "elasticity"),
            (self.memory, "memory"),
            (self.contact, "contact"),
            (self.friction, "friction"),
            (self.normal_stress, "normal_stress"),
            (self.tractions, "tractions"),
            (self.body_force, "body_force"),
        ]
        .iter()
        .filter(|(on, _)| *on)
        .map(|(_, n)| *n)
        .collect()
    }

    /// True when a step is a plain linear solve.
    pub fn linear(&self) -> bool {
        !self.contact && !self.friction
    }
}

/// |n·ν| at or below which Γ3,1 and Γ3,2 meet at a right angle: the nodal normals come from
/// coordinates rounded to ~1e-16 relative, so a right angle gives |n·ν| ~ 1e-15.
pub const RIGHT_ANGLE_COSINE: f64 = 1e-9;

/// Things a user should know about a scene that runs: nearly incompressible plane strain or
/// 3D (P1 elements lock); a contact or friction boundary that is not straight at a node (the
/// nodal normal there is an average of the facet normals); nodes where Γ3,1 meets Γ3,2 at a
/// right angle, the only place where the split of the constraint force into contact
/// pressure and friction traction is not unique (see `Rows::corner_cosines`); a contact
/// solver without D, whose sliding steps can take many minutes (`ContactPlan::slow_warning`
/// of `solver`, the run's resolved solver). `check` prints them, `run` and `resume` print
/// them before the first step and write them into summary.json.
pub fn warnings(scene: &Scene, disc: &Discretization, solver: &Descriptor) -> Vec<String> {
    let mut w = Vec::new();
    use crate::scene::Model;
    // The largest Poisson ratio of the body's materials.
    let nu = (scene.physics.materials())
        .filter_map(|m| m.elasticity.map(|(_, nu)| nu))
        .reduce(f64::max);
    if let (Model::PlaneStrain | Model::ThreeD, Some(nu)) = (scene.mesh.model, nu) {
        if nu > 0.45 {
            let (model, elements, remedy) = match scene.mesh.model {
                Model::PlaneStrain => ("plane strain", "triangles", "a smaller ν or plane stress"),
                _ => ("3D", "tetrahedra", "a smaller ν"),
            };
            w.push(format!(
                "{model} with Poisson ratio {nu}: P1 {elements} lock for nearly \
                 incompressible materials, so displacements come out too small; use {remedy}"
            ));
        }
    }
    for (kink, group, what) in [
        (
            disc.contact_kink_deg,
            &scene.mesh.groups.contact,
            "n·w ≤ 0 is only approximately the contact of each facet",
        ),
        (
            disc.friction_kink_deg,
            &scene.mesh.groups.friction,
            "the slip |w_τ| is only approximately the slip along each facet",
        ),
    ] {
        if kink > 1.0 {
            w.push(format!(
                "the boundary '{group}' bends by up to {kink:.2}° at a node; the nodal normal \
                 there averages the facet normals, so {what}"
            ));
        }
    }
    for &condition in &disc.idle_groups {
        let (group, meaning) = match condition {
            Gamma3::Contact => (
                &scene.mesh.groups.contact,
                "no non-penetration: the body passes freely through the foundation there",
            ),
            Gamma3::Friction => (
                &scene.mesh.groups.friction,
                "neither the given normal stress F nor friction acts there",
            ),
        };
        let what = condition.name();
        w.push(format!(
            "the mesh has the {what} group '{group}' (mesh.groups.{what}), but the scene has \
             no [{what}] table (or it is disabled), so that boundary is free: {meaning}; add \
             [{what}] to the scene to impose it"
        ));
    }
    let rows = Rows::new(&disc.contact, &disc.friction, disc.dim - 1);
    let right = rows
        .corner_cosines()
        .into_iter()
        .filter(|(_, cos)| cos.abs() <= RIGHT_ANGLE_COSINE)
        .collect::<Vec<_>>();
    if let Some(&(first, cos)) = right.first() {
        w.push(format!(
            "{} node(s) where '{}' meets '{}' at a right angle (the first at {}; n·ν = {} for \
             the contact normal n and the friction boundary's normal ν): n lies in the \
             friction's tangent space, so the constraint force λ n + γ·τ there does not tell \
             contact pressure λ from friction traction γ, and their split is not unique (the \
             velocity and the force are); where the two meet at any other angle it is unique",
            right.len(),
            scene.mesh.groups.contact,
            scene.mesh.groups.friction,
            fmt_point(disc.nodes[first], disc.dim),
            fmt_num(cos)
        ));
    }
    w.extend(solver.contact().and_then(|plan| plan.slow_warning()));
    let active_set = solver.contact_solver() == Some(Contact::ActiveSet);
    if scene.solver.active_set != Default::default() && !active_set {
        w.push(format!(
            "[solver.active_set] is set, but this run's steps are solved {}: its keys are \
             not used",
            match solver.contact_solver() {
                Some(c) => format!("by the {} contact solver", c.key()),
                None => "as linear systems (no contact or friction rows)".to_string(),
            }
        ));
    }
    w
}

/// Builds the step solver (Remark 2.5): `Linear` without constraint rows, otherwise the
/// contact solver that `solver` names (`solver::choice::Descriptor`, the scene's keys
/// resolved): the dense dual, a dual without D or clarabel on the stored factor, or the
/// active-set solver on PETSc. `matrix` is the step matrix (K_A, or K_A + k K_B + k² r(0)
/// K_R for the implicit variant) that `backend` holds, as `solver.build()` says, over
/// `disc`'s columns (a rank's own alone on several: `Discretization::own`); `rows` and
/// the step's vectors are held at the dofs `held` alone where given (a follower's,
/// `time_loop`).
pub fn step_solver(
    (effects, disc, held): (&Effects, &Discretization, Option<&[usize]>),
    solver: &Descriptor,
    matrix: &Sparse,
    backend: &Backend,
    rows: &Rows,
) -> Result<StepSolver> {
    let Some(contact) = solver.contact_solver().filter(|_| !effects.linear()) else {
        return Ok(StepSolver::Linear);
    };
    let factor = || {
        backend.factor().ok_or_else(|| {
            Error::solve(format!(
                "the {} contact solver needs the stored factor of K_A",
                contact.key()
            ))
        })
    };
    Ok(match contact {
        Contact::Dense => StepSolver::Dual(Box::new(DualSolver::new(factor()?, rows))),
        Contact::MatrixFree | Contact::Sparse => {
            StepSolver::MatrixFree(Box::new(MatrixFreeSolver::new(factor()?, matrix, rows)))
        }
        Contact::Clarabel => StepSolver::Conic(Box::new(ConicSolver::new(matrix, rows)?)),
        Contact::ActiveSet => {
            // On one of several MPI ranks, `matrix` holds the diagonal of its own rows alone:
            // Γ3's others come from the ranks that hold them (collective on several).
            let mut diagonal = disc.diagonal_of(matrix, held);
            backend.share(&mut diagonal)?;
            let solver = ActiveSetSolver::new(rows, &diagonal, solver.active_set());
            StepSolver::ActiveSet(Box::new(solver))
        }
    })
}
