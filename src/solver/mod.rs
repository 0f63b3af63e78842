//! The per-step problem: (3.1) at step n is the convex program (docs/architecture.md)
//!
//!   minimize   ½ wᵀ K_A w − b_nᵀ w + Σ_{i∈Γ3,2} c_i |w_τ,i|
//!   subject to n_i·w_i ≤ 0   at every node i of Γ3,1,
//!   b_n = f_n − K_B u_n − K_R m_n − g_F,
//!
//! with w_τ,i = (τ_ik·w_i)_k the tangential velocity of node i in its tangent frame: τ_i·w_i
//! in 2D, (τ_i1·w_i, τ_i2·w_i) in 3D, so that |w_τ,i| is the Euclidean norm in the tangent
//! plane (a second-order cone, not a box).
//!
//! K_A never changes, so it is factored once per run (`Factor`). Which solver a run uses is
//! decided by its effects (Remark 2.5): no constraint rows → `Linear` (one solve with the
//! stored factor per step, no optimization solver built); otherwise, by `[solver] contact`
//! (resolved once per run into `choice::Descriptor`: `auto` picks by the predicted memory of
//! the dense dual and, with PETSc, of the factor), the condensed dual
//! semismooth Newton method (`dual`, with the dense m × m matrix D), the same dual with D
//! applied through solves with the factor (`matrix_free`, for contact boundaries whose D
//! does not fit), clarabel on the whole problem (`conic`, the cross-check), or, without
//! any factor, the primal active-set method on PETSc (`active_set`).
//!
//! # Solvers, statuses and how a new one plugs in
//!
//! The time loop calls `StepSolver::solve` once per step and gets a `StepReport`: a
//! `StepStatus` (solved, the iteration limit, an indefinite Newton matrix, clarabel's
//! failure), the iterations and the final residual. It adds what its own checks of the
//! answer find (not finite, growing without bound, n·w > 0 on Γ3,1) to the status and
//! hands the report to `StepReport::check`, the one place where a status becomes an error.
//!
//! A contact solver (`matrix_free` is one) is a type in its own module, built from the run's `Factor` and `Rows`, with its settings as a
//! struct with documented defaults and `validate` (as `dual::DualSettings`), and
//! `solve(&mut self, factor, rows, b, w, z) -> StepReport` that warm starts from z. It
//! becomes a variant of `StepSolver` (its `name`, its arm in `solve`), of `choice::Contact`
//! (its memory, cost and what it needs built: `Contact::ordered_last`, and its arm in
//! `choice::Descriptor::of_run`) and of the scene's `ContactSolver`, and `effects::step_solver`
//! builds it; an outcome no `StepStatus` covers is a new variant with
//! its message in `status.rs`. A solver whose steps can take minutes honours a request to
//! give a step up (`abandon`, `StepSolver::abandon_on`): it looks at the request between
//! its iterations and ends with `StepStatus::Abandoned`, writing no w. The time loop does
//! not change.
//!
//! The linear backend is a `Backend`: the stored Cholesky factor `Factor` (`solver.linear =
//! "cholesky"`, and `auto` within `choice::FACTOR_LIMIT`), or PETSc's Krylov method with
//! algebraic multigrid (`solver.linear = "petsc"`, `solver.contact = "active_set"`, or `auto`
//! beyond the limits in a build with the cargo feature `petsc`, src/petsc/). The time loop
//! builds the one `choice::Build` names, never both, and hands it to `solve`. With
//! the factor, `Linear` needs only its solves with K_A, `Conic` none; the dual condenses
//! through its structure (the forward and backward solves with the constrained dofs last,
//! the trailing block L_CC). PETSc serves `Linear` (`krylov_step`) and `ActiveSet`, whose
//! Newton systems are K_A's with constrained directions projected out; the scene refuses
//! the other contact solvers with PETSc and `active_set` with the factor.

mod abandon;
pub mod active_set;
pub mod choice;
pub mod conic;
pub mod dual;
pub mod factor;
pub mod matrix_free;
mod ordering;
mod status;

use crate::fem::NodalRow;
pub use abandon::{Abandon, Armed};
pub use factor::Factor;
pub use status::{StepAt, StepReport, StepStatus};

/// The constraint rows of a run: contact rows (multiplier λ_i ≥ 0) first, then friction
/// rows in blocks of `block` = d − 1 consecutive rows per node (the tangents τ_i1, …), whose
/// multipliers γ_i lie in the ball |γ_i| ≤ c_i: an interval in 2D, a disc in 3D (the
/// Coulomb cone's section at the given normal stress).
#[derive(Clone, Debug, Default)]
pub struct Rows {
    pub rows: Vec<NodalRow>,
    pub n_contact: usize,
    /// Friction rows per node: 1 in 2D, 2 in 3D.
    pub block: usize,
}

impl Rows {
    /// `friction` must list each node's tangent rows consecutively (`block` per node).
    pub fn new(contact: &[NodalRow], friction: &[NodalRow], block: usize) -> Self {
        debug_assert!(block >= 1 && friction.len().is_multiple_of(block));
        let mut rows = contact.to_vec();
        rows.extend_from_slice(friction);
        Rows {
            rows,
            n_contact: contact.len(),
            block,
        }
    }

    pub fn len(&self) -> usize {
        self.rows.len()
    }

    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// These rows on a vector held at the dofs `held` alone (increasing, among which every
    /// dof the rows touch is: a follower rank's w_n, `time_loop`): each
    /// dof's place there (`fem::place`).
    pub fn placed(mut self, held: &[usize]) -> Rows {
        for r in &mut self.rows {
            let mut dofs = [0; 3];
            for c in (0..r.dim).filter(|&c| r.dir[c] != 0.0) {
                dofs[c] = crate::fem::place(Some(held), r.dofs[c]);
            }
            r.dofs = dofs;
        }
        self
    }

    /// The number of friction nodes (blocks).
    pub fn n_friction_nodes(&self) -> usize {
        (self.rows.len() - self.n_contact) / self.block.max(1)
    }

    /// The row indices of friction block j.
    pub fn friction_block(&self, j: usize) -> std::ops::Range<usize> {
        let start = self.n_contact + j * self.block;
        start..start + self.block
    }

    /// Nodes whose contact row n_i and friction rows τ_ik are dependent or nearly so: the
    /// contact normal lies within 60° of the friction tangent space (|Π_τ n_i| > ½, where
    /// Π_τ projects onto span τ_ik). That happens where Γ3,1 meets Γ3,2 at a corner (a
    /// 90° corner makes n_i = ±τ_i exactly, so D = P K_A⁻¹ Pᵀ is singular). Where the two
    /// sides continue each other (the paper's x = 1) n_i ⊥ τ_i and the node is not listed.
    pub fn dependent_nodes(&self) -> Vec<usize> {
        let friction = self.friction_blocks_by_node();
        self.rows[..self.n_contact]
            .iter()
            .filter(|r| {
                friction.get(&r.node).is_some_and(|&j| {
                    let along: f64 = self.rows[self.friction_block(j)]
                        .iter()
                        .map(|t| {
                            t.dir
                                .iter()
                                .zip(&r.dir)
                                .map(|(a, b)| a * b)
                                .sum::<f64>()
                                .powi(2)
                        })
                        .sum();
                    along > 0.25
                })
            })
            .map(|r| r.node)
            .collect()
    }

    /// Node → index of its friction block.
    fn friction_blocks_by_node(&self) -> std::collections::HashMap<usize, usize> {
        (0..self.n_friction_nodes())
            .map(|j| (self.rows[self.friction_block(j).start].node, j))
            .collect()
    }

    /// At each node with a contact row and friction rows: (node, n_i·ν_i), the cosine between
    /// the contact normal n_i and the normal ν_i of the friction tangent space (ν_i = (τ_y,
    /// −τ_x) in 2D, τ_i1 × τ_i2 in 3D). The constraint force at the node, λ_i n_i + Σ_k γ_ik
    /// τ_ik, is split uniquely into λ_i and γ_i exactly when the d vectors n_i, τ_ik are
    /// independent, that is when n_i·ν_i ≠ 0; the split's sensitivity grows as 1/|n_i·ν_i|.
    pub fn corner_cosines(&self) -> Vec<(usize, f64)> {
        let friction = self.friction_blocks_by_node();
        self.rows[..self.n_contact]
            .iter()
            .filter_map(|r| {
                let t = &self.rows[self.friction_block(*friction.get(&r.node)?)];
                let nu = match t {
                    [t] => [t.dir[1], -t.dir[0], 0.0],
                    [t1, t2, ..] => crate::mesh::cross(t1.dir, t2.dir),
                    [] => return None,
                };
                Some((r.node, crate::mesh::dot(r.dir, nu)))
            })
            .collect()
    }

    /// Every dof a row touches, sorted: the block C ordered last in the factor.
    pub fn dofs(&self) -> Vec<usize> {
        let mut d: Vec<usize> = self
            .rows
            .iter()
            .flat_map(|r| r.entries().map(|(d, _)| d))
            .collect();
        d.sort_unstable();
        d.dedup();
        d
    }

    /// P in `factor`'s ordering: each row's entries (i, c), i the dof's position less
    /// `first`, its index in the vectors on C of the solvers that order C last from `first`
    /// (`dual`, `matrix_free`; 0 where the vectors hold every dof).
    pub(super) fn in_factor(&self, factor: &Factor, first: usize) -> Vec<Vec<(usize, f64)>> {
        self.rows
            .iter()
            .map(|r| {
                r.entries()
                    .map(|(d, c)| (factor.position(d) - first, c))
                    .collect()
            })
            .collect()
    }
}

/// Σ c x_i over a row's entries (i, c) (`Rows::in_factor`): (P x)_row.
fn gather(row: &[(usize, f64)], x: &[f64]) -> f64 {
    row.iter().map(|&(i, c)| c * x[i]).sum()
}

/// y = Pᵀ v: each row's entries (i, c) (`Rows::in_factor`) add c v_row to y_i.
fn scatter(p: &[Vec<(usize, f64)>], v: &[f64], y: &mut [f64]) {
    y.fill(0.0);
    for (row, &x) in p.iter().zip(v) {
        for &(i, c) in row {
            y[i] += c * x;
        }
    }
}

/// How a run solves its step matrix (K_A, or its implicit variant). One per run: the
/// factor's size in the enum costs nothing.
#[allow(clippy::large_enum_variant)]
pub enum Backend {
    /// Factored once, one solve with the factor per step (`Factor`).
    Cholesky(Factor),
    /// None: the step solver holds its own (clarabel).
    None,
    /// PETSc's KSP, set up once (`crate::petsc::Krylov`): linear runs and the active-set
    /// contact solver.
    #[cfg(feature = "petsc")]
    Petsc(crate::petsc::Krylov),
}

impl Backend {
    /// The stored factor, where the run has one.
    pub fn factor(&self) -> Option<&Factor> {
        match self {
            Backend::Cholesky(f) => Some(f),
            Backend::None => None,
            #[cfg(feature = "petsc")]
            Backend::Petsc(_) => None,
        }
    }

    /// The largest of every rank's `x` (collective over the ranks of a PETSc run); `x` on
    /// one process.
    pub fn largest(&self, x: f64) -> crate::Result<f64> {
        match self {
            #[cfg(feature = "petsc")]
            Backend::Petsc(krylov) => krylov.largest(x),
            _ => Ok(x),
        }
    }

    /// `v` at the unknowns this rank reads (`petsc::Reads`) ← their values from the ranks
    /// that hold their rows, `v` exact in this rank's own rows
    /// (`Discretization::keep_columns`); nothing on one process.
    pub fn share(&self, v: &mut [f64]) -> crate::Result<()> {
        match self {
            #[cfg(feature = "petsc")]
            Backend::Petsc(krylov) => krylov.share(v),
            _ => {
                let _ = v;
                Ok(())
            }
        }
    }

    /// `kept` ← w as `restore` takes it back after a step given up: on a rank of several
    /// whose w is exact where it reads it alone, its own rows (`petsc::Krylov::keep`);
    /// elsewhere every value.
    pub fn keep(&self, w: &[f64], kept: &mut Vec<f64>) {
        match self {
            #[cfg(feature = "petsc")]
            Backend::Petsc(krylov) => krylov.keep(w, kept),
            _ => {
                kept.clear();
                kept.extend_from_slice(w);
            }
        }
    }

    /// w ← w as `keep` kept it in `kept`, wherever it is exact (collective over the ranks
    /// of a PETSc run: the values a rank reads of the others' rows come from them).
    pub fn restore(&self, kept: &[f64], w: &mut [f64]) -> crate::Result<()> {
        match self {
            #[cfg(feature = "petsc")]
            Backend::Petsc(krylov) => krylov.restore(kept, w),
            _ => {
                w.copy_from_slice(kept);
                Ok(())
            }
        }
    }

    /// The `n` unknowns' values on one process, and on rank 0 of several, each rank giving
    /// `value` of its own rows' unknowns (collective; `petsc::Krylov::gather_at_first`):
    /// None on the other ranks.
    pub fn gather_at_first(
        &self,
        n: usize,
        value: &dyn Fn(usize) -> f64,
    ) -> crate::Result<Option<Vec<f64>>> {
        match self {
            #[cfg(feature = "petsc")]
            Backend::Petsc(krylov) => krylov.gather_at_first(n, value),
            _ => Ok(Some((0..n).map(value).collect())),
        }
    }

    /// A solved step's w at every unknown, where this rank's history holds every dof and a
    /// solve gave it its reads alone (`petsc::Krylov::complete`); nothing on one process.
    pub fn complete(&mut self, w: &mut [f64]) -> crate::Result<()> {
        match self {
            #[cfg(feature = "petsc")]
            Backend::Petsc(krylov) => krylov.complete(w),
            _ => {
                let _ = w;
                Ok(())
            }
        }
    }
}

/// w = K⁻¹ b for a linear step through PETSc (`Backend::Petsc`): the report with the Krylov
/// iterations, or `Stopped` with the KSP's reason.
#[cfg(feature = "petsc")]
fn krylov_step(
    krylov: &mut crate::petsc::Krylov,
    b: &[f64],
    w: &mut [f64],
) -> crate::Result<StepReport> {
    // A step given up leaves an iterate in w, which the time loop puts back.
    let s = krylov.solve(b, w)?;
    Ok(StepReport {
        status: match s.failed {
            _ if s.given_up => StepStatus::Abandoned,
            None => StepStatus::Solved,
            Some(reason) => StepStatus::Stopped {
                solver: "PETSc's Krylov solve of K_A (KSP)",
                reason,
                iterations: s.iterations,
                residual: s.residual,
                remedy: crate::petsc::REMEDY,
            },
        },
        iterations: s.iterations,
        residual: s.residual,
        krylov: s.iterations,
    })
}

/// The solver of a run, picked by its effects.
pub enum StepSolver {
    /// w = K_A⁻¹ b: no contact and no friction.
    Linear,
    /// Condensed onto the constrained boundary dofs; see `dual`.
    Dual(Box<dual::DualSolver>),
    /// The same dual without the m × m matrix, `matrix_free` or `sparse`; see
    /// `matrix_free`.
    MatrixFree(Box<matrix_free::MatrixFreeSolver>),
    /// The whole problem in clarabel; see `conic`.
    Conic(Box<conic::ConicSolver>),
    /// The primal active-set method on PETSc's Krylov solves; see `active_set`.
    ActiveSet(Box<active_set::ActiveSetSolver>),
}

impl StepSolver {
    /// The name recorded in summary.json.
    pub fn name(&self) -> &'static str {
        match self {
            StepSolver::Linear => "linear (stored Cholesky factor of K_A, one solve per step)",
            StepSolver::Dual(_) => {
                "dual active set (condensed on Γ3 rows, stored Cholesky factor of K_A)"
            }
            StepSolver::MatrixFree(d) if d.sparse() => {
                "sparse dual (condensed on Γ3 rows through whole solves with the stored \
                 Cholesky factor of K_A)"
            }
            StepSolver::MatrixFree(_) => {
                "matrix-free dual (condensed on Γ3 rows through the trailing block of the \
                 stored Cholesky factor of K_A)"
            }
            StepSolver::Conic(_) => "clarabel (interior point on the whole step problem)",
            StepSolver::ActiveSet(_) => {
                "active set (semismooth Newton on the primal system, PETSc's Krylov method \
                 with the multigrid of K_A)"
            }
        }
    }

    /// Gives up the dual methods' steps when `abandon` is requested (`abandon`); clarabel's
    /// and the linear steps are always finished (the PETSc steps, linear and active set,
    /// are given up by their Krylov solves: `TimeLoop::abandon_on`). Whether a step
    /// honours it.
    pub fn abandon_on(&mut self, abandon: Abandon) -> bool {
        match self {
            StepSolver::Dual(d) => d.abandon_on(abandon),
            StepSolver::MatrixFree(d) => d.abandon_on(abandon),
            StepSolver::Linear | StepSolver::Conic(_) | StepSolver::ActiveSet(_) => return false,
        }
        true
    }

    /// The scene key of the solver's iteration limit, where the scene can set it.
    pub fn limit_key(&self) -> Option<&'static str> {
        match self {
            StepSolver::ActiveSet(_) => Some("[solver.active_set] max_iterations"),
            _ => None,
        }
    }

    /// The `solver.contact` value to try when this solver's answer cannot be trusted.
    pub fn other(&self) -> &'static str {
        match self {
            StepSolver::Conic(_) | StepSolver::ActiveSet(_) => "dense",
            _ => "clarabel",
        }
    }

    /// Solves step n with the run's linear backend: `b` is b_n, `w` receives w_n (in: the
    /// previous step's w_{n−1}), `z` the multipliers (λ on contact rows, γ on friction rows;
    /// in: the previous step's z_{n−1}, used as a warm start with `before`, z_{n−2}, where
    /// the time loop has it: see `dual::iteration`). w and z are the step's solution only
    /// where the report's status is `Solved`. The time loop builds each solver with the
    /// backend it needs (`effects::step_solver`); a PETSc error is the run's error.
    pub fn solve(
        &mut self,
        backend: &mut Backend,
        rows: &Rows,
        b: &[f64],
        w: &mut [f64],
        z: &mut [f64],
        before: Option<&[f64]>,
    ) -> crate::Result<StepReport> {
        // Without the `petsc` feature the factor is the only backend.
        #[allow(clippy::infallible_destructuring_match)]
        let factor = match backend {
            Backend::Cholesky(factor) => factor,
            Backend::None => {
                return match self {
                    StepSolver::Conic(c) => Ok(c.solve(rows, b, w, z)),
                    _ => Err(crate::Error::solve(format!(
                        "the {} solver needs the stored factor of K_A",
                        self.name()
                    ))),
                }
            }
            #[cfg(feature = "petsc")]
            Backend::Petsc(krylov) => {
                return match self {
                    StepSolver::Linear => krylov_step(krylov, b, w),
                    StepSolver::ActiveSet(a) => a.solve(krylov, rows, b, w, z),
                    _ => Err(crate::Error::solve(format!(
                        "the {} solver needs the stored factor of K_A",
                        self.name()
                    ))),
                }
            }
        };
        Ok(match self {
            StepSolver::Linear => {
                w.copy_from_slice(b);
                factor.solve(w);
                StepReport::default()
            }
            StepSolver::Dual(d) => d.solve(factor, rows, b, w, z, before),
            StepSolver::MatrixFree(d) => d.solve(factor, rows, b, w, z, before),
            StepSolver::Conic(c) => c.solve(rows, b, w, z),
            StepSolver::ActiveSet(_) => {
                return Err(crate::Error::solve(
                    "the active-set contact solver needs the PETSc backend",
                ))
            }
        })
    }
}

/// KKT residual of a step solution, relative: the largest of
/// - on Γ3,1: contact violation n·w > 0, a negative λ, complementarity |λ n·w|;
/// - on Γ3,2: the bound violation |γ_i| − c_i > 0, and consistency: where the node slides
///   (w_τ,i ≠ 0), γ_i = c_i w_τ,i/|w_τ,i|, measured as |γ_i |w_τ,i| − c_i w_τ,i| (which is
///   |γ_i − c_i ŵ_τ,i|·|w_τ,i|, zero where the node sticks; in 2D, the distance of γ_i to the
///   bound c_i sign(τ_i·w_i) times |τ_i·w_i|);
///
/// each scaled to be dimensionless by the velocity scale `w_scale` and the multiplier scale
/// `z_scale`.
pub fn kkt_residual(rows: &Rows, w: &[f64], z: &[f64], w_scale: f64, z_scale: f64) -> f64 {
    let mut r: f64 = 0.0;
    let ws = w_scale.max(f64::MIN_POSITIVE);
    let zs = z_scale.max(f64::MIN_POSITIVE);
    for (row, &lambda) in rows.rows[..rows.n_contact].iter().zip(z) {
        let nw = row.apply(w);
        r = r
            .max((-lambda).max(0.0) / zs)
            .max(nw.max(0.0) / ws)
            .max((lambda * nw).abs() / (zs * ws));
    }
    for j in 0..rows.n_friction_nodes() {
        let block = rows.friction_block(j);
        let c = rows.rows[block.start].bound;
        let gamma = &z[block.clone()];
        let w_tau = |k: usize| rows.rows[block.start + k].apply(w);
        let norm_w = (0..block.len()).fold(0.0f64, |a, k| a.hypot(w_tau(k)));
        let norm_gamma = gamma.iter().fold(0.0f64, |a, g| a.hypot(*g));
        let mismatch = gamma
            .iter()
            .enumerate()
            .fold(0.0f64, |a, (k, g)| a.hypot(g * norm_w - c * w_tau(k)));
        r = r
            .max((norm_gamma - c).max(0.0) / zs)
            .max(mismatch / (zs * ws));
    }
    r
}

#[cfg(test)]
mod tests {
    //! Synthetic step problems without the mesh code: a grounded spring lattice (2D or 3D)
    //! whose top layer carries contact rows, friction blocks or both.
    use super::*;
    use crate::fem::Sparse;
    use crate::testing::SplitMix;
    use faer::sparse::{SparseColMat, Triplet};

    fn unit(v: [f64; 3]) -> [f64; 3] {
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        [v[0] / n, v[1] / n, v[2] / n]
    }

    fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    }

    /// A normal n tilted from the last axis and its unit tangents, orthonormal (d − 1 of them).
    fn frame(dim: usize, noise: &mut SplitMix) -> ([f64; 3], Vec<[f64; 3]>) {
        let (a, b) = (noise.range(-0.3, 0.3), noise.range(-0.3, 0.3));
        if dim == 2 {
            let n = unit([a, 1.0, 0.0]);
            (n, vec![[n[1], -n[0], 0.0]])
        } else {
            let n = unit([a, b, 1.0]);
            let phi = noise.range(0.0, std::f64::consts::TAU);
            let t1 = unit(cross(n, [phi.cos(), phi.sin(), 0.0]));
            (n, vec![t1, cross(n, t1)])
        }
    }

    fn row(node: usize, dim: usize, dir: [f64; 3], bound: f64) -> NodalRow {
        NodalRow {
            node,
            dofs: [dim * node, dim * node + 1, dim * node + dim - 1],
            dir,
            dim,
            bound,
            area: 1.0,
        }
    }

    /// A step problem: K (SPD), its rows and the load b.
    struct Problem {
        k: Sparse,
        rows: Rows,
        b: Vec<f64>,
        /// The top layer's tangential loads, turned by `turn` in the warm start test.
        tangential: Vec<(usize, Vec<f64>)>,
    }

    /// A lattice of side `side` (nodes) and `layers` layers in `dim` dimensions: springs
    /// k_e e eᵀ between all neighbours (diagonals too), the bottom layer grounded. On the top
    /// layer node t gets a contact row (t % 3 ≠ 1), a friction block (t % 3 ≠ 0) or both, and
    /// a load: a random normal part (pressing or pulling) and a random tangential part.
    fn lattice(dim: usize, side: usize, layers: usize, seed: u64) -> Problem {
        let mut noise = SplitMix(seed);
        let per_layer = if dim == 2 { side } else { side * side };
        let nn = per_layer * layers;
        let coords = |i: usize| -> [f64; 3] {
            let (l, r) = (i / per_layer, i % per_layer);
            let x = [(r % side) as f64, (r / side) as f64, l as f64];
            if dim == 2 {
                [x[0], x[2], 0.0]
            } else {
                x
            }
        };
        let n = dim * nn;
        let mut t = Vec::new();
        for i in 0..nn {
            let ground = if i < per_layer { 10.0 } else { 0.05 };
            for c in 0..dim {
                t.push(Triplet::new(dim * i + c, dim * i + c, ground));
            }
            for j in i + 1..nn {
                let (xi, xj) = (coords(i), coords(j));
                let e = [xj[0] - xi[0], xj[1] - xi[1], xj[2] - xi[2]];
                if e.iter().any(|v| v.abs() > 1.5) {
                    continue;
                }
                let len = (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt();
                let k = noise.range(0.5, 1.5) / len;
                let e = [e[0] / len, e[1] / len, e[2] / len];
                for a in 0..dim {
                    for b in 0..dim {
                        let v = k * e[a] * e[b];
                        t.push(Triplet::new(dim * i + a, dim * i + b, v));
                        t.push(Triplet::new(dim * j + a, dim * j + b, v));
                        t.push(Triplet::new(dim * i + a, dim * j + b, -v));
                        t.push(Triplet::new(dim * j + a, dim * i + b, -v));
                    }
                }
            }
        }
        let k = SparseColMat::try_new_from_triplets(n, n, &t).unwrap();
        let mut b: Vec<f64> = (0..n).map(|_| noise.range(-0.05, 0.05)).collect();
        let (mut contact, mut friction, mut tangential) = (Vec::new(), Vec::new(), Vec::new());
        for (top, node) in (nn - per_layer..nn).enumerate() {
            let (nrm, tangents) = frame(dim, &mut noise);
            let push = noise.range(-1.0, 1.0);
            let c = noise.range(0.3, 0.8);
            let mut load = vec![0.0; dim];
            for tau in &tangents {
                let s = noise.range(-1.5, 1.5);
                for (l, t) in load.iter_mut().zip(tau) {
                    *l += s * t;
                }
            }
            for (k, l) in load.iter().enumerate() {
                b[dim * node + k] += l + push * nrm[k];
            }
            tangential.push((node, load));
            if top % 3 != 1 {
                contact.push(row(node, dim, nrm, f64::INFINITY));
            }
            if top % 3 != 0 {
                friction.extend(tangents.iter().map(|&tau| row(node, dim, tau, c)));
            }
        }
        Problem {
            k,
            rows: Rows::new(&contact, &friction, dim - 1),
            b,
            tangential,
        }
    }

    /// The solvers of a problem: the dual (with its factor) and clarabel.
    struct Solvers {
        factor: Factor,
        dual: dual::DualSolver,
        conic: conic::ConicSolver,
    }

    impl Solvers {
        fn new(p: &Problem) -> Self {
            let factor = Factor::new(&p.k, &p.rows.dofs()).unwrap();
            let dual = dual::DualSolver::new(&factor, &p.rows);
            let conic = conic::ConicSolver::new(&p.k, &p.rows).unwrap();
            Solvers {
                factor,
                dual,
                conic,
            }
        }

        /// The dual solution (w, z) from the warm start z, and its iterations.
        fn dual(&mut self, p: &Problem, b: &[f64], z: &mut [f64]) -> (Vec<f64>, usize) {
            let mut w = vec![0.0; b.len()];
            let report = self.dual.solve(&self.factor, &p.rows, b, &mut w, z, None);
            assert_eq!(report.status, StepStatus::Solved);
            assert!(report.residual <= 1e-12, "{report:?}");
            (w, report.iterations)
        }

        fn conic(&mut self, p: &Problem, b: &[f64]) -> (Vec<f64>, Vec<f64>) {
            let (mut w, mut z) = (vec![0.0; b.len()], vec![0.0; p.rows.len()]);
            let report = self.conic.solve(&p.rows, b, &mut w, &mut z);
            assert_eq!(report.status, StepStatus::Solved);
            (w, z)
        }
    }

    fn max_abs(v: &[f64]) -> f64 {
        v.iter().fold(0.0f64, |a, x| a.max(x.abs()))
    }

    /// max|a − b| / max|a|.
    fn rel_diff(a: &[f64], b: &[f64]) -> f64 {
        let d: Vec<f64> = a.iter().zip(b).map(|(a, b)| a - b).collect();
        max_abs(&d) / max_abs(a)
    }

    fn kkt(rows: &Rows, w: &[f64], z: &[f64]) -> f64 {
        kkt_residual(rows, w, z, max_abs(w), max_abs(z))
    }

    /// Counts of (active contact, inactive contact, sticking, sliding friction nodes).
    fn states(rows: &Rows, w: &[f64], z: &[f64]) -> [usize; 4] {
        let mut s = [0; 4];
        let tol = 1e-8 * max_abs(w);
        for (row, &lambda) in rows.rows[..rows.n_contact].iter().zip(z) {
            s[if lambda > 0.0 { 0 } else { 1 }] += 1;
            assert!(
                lambda > 0.0 || row.apply(w) < -tol,
                "a degenerate contact row"
            );
        }
        for j in 0..rows.n_friction_nodes() {
            let block = rows.friction_block(j);
            let slip = block
                .clone()
                .fold(0.0f64, |a, i| a.hypot(rows.rows[i].apply(w)));
            s[if slip <= tol { 2 } else { 3 }] += 1;
        }
        s
    }

    /// Dual and clarabel agree, the dual's KKT residual is at rounding level, and the
    /// problem has every kind of row.
    fn cross_check(dim: usize, seed: u64) {
        let p = lattice(dim, if dim == 2 { 12 } else { 5 }, 3, seed);
        let mut s = Solvers::new(&p);
        let mut z = vec![0.0; p.rows.len()];
        let (w, iterations) = s.dual(&p, &p.b, &mut z);
        let (wc, zc) = s.conic(&p, &p.b);
        let (dw, dz, r) = (rel_diff(&w, &wc), rel_diff(&z, &zc), kkt(&p.rows, &w, &z));
        let st = states(&p.rows, &w, &z);
        eprintln!(
            "{dim}D: m = {}, iterations {iterations}, |Δw| {dw:.1e}, |Δz| {dz:.1e}, \
             KKT dual {r:.1e}, clarabel {:.1e}, states {st:?}",
            p.rows.len(),
            kkt(&p.rows, &wc, &zc)
        );
        assert!(dw <= 1e-7 && dz <= 1e-7, "{dw:e} {dz:e}");
        assert!(r <= 1e-10, "{r:e}");
        assert!(st.iter().all(|&c| c > 0), "{st:?}");
    }

    #[test]
    fn dual_and_clarabel_agree_in_3d() {
        for seed in [1, 2, 3] {
            cross_check(3, seed);
        }
    }

    #[test]
    fn dual_and_clarabel_agree_in_2d() {
        for seed in [1, 2, 3] {
            cross_check(2, seed);
        }
    }

    /// Four warm-started steps of two solvers (each with its multipliers), b turned and
    /// scaled from step to step (other sets): each step's w and z against clarabel's and
    /// the KKT test, and the two solvers' w against each other.
    fn over_steps<T>(
        p: &Problem,
        s: &mut Solvers,
        seed: u64,
        solvers: &mut [(T, Vec<f64>); 2],
        solve: impl Fn(&mut T, &Factor, &Rows, &[f64], &mut [f64], &mut [f64]) -> StepReport,
    ) {
        for step in 0..4 {
            let b: Vec<f64> =
                p.b.iter()
                    .enumerate()
                    .map(|(i, v)| {
                        v * (1.0 + 0.3 * step as f64) + 0.2 * step as f64 * p.b[(i + 7) % p.b.len()]
                    })
                    .collect();
            let (wc, zc) = s.conic(p, &b);
            let solved = solvers.each_mut().map(|(solver, z)| {
                let mut w = vec![0.0; b.len()];
                let report = solve(solver, &s.factor, &p.rows, &b, &mut w, z);
                assert_eq!(report.status, StepStatus::Solved);
                w
            });
            for (w, (_, z)) in solved.iter().zip(solvers.iter()) {
                let (dw, dz) = (rel_diff(&wc, w), rel_diff(&zc, z));
                assert!(
                    dw <= 1e-7 && dz <= 1e-7,
                    "seed {seed} step {step}: {dw:e} {dz:e}"
                );
                assert!(kkt(&p.rows, w, z) <= 1e-10);
            }
            let dw = rel_diff(&solved[1], &solved[0]);
            assert!(
                dw <= 1e-9,
                "seed {seed} step {step}: the two differ by {dw:e}"
            );
        }
    }

    /// The two forms of the dual's Newton systems (`dual::newton_step`) give the same
    /// solution, that of clarabel, over a sequence of warm-started steps; the Woodbury form
    /// is really taken when forced and never in the direct form.
    #[test]
    fn newton_forms_agree_in_3d() {
        use dual::{DualSettings, DualSolver, NewtonForm};
        for seed in [1, 2, 3] {
            let p = lattice(3, 6, 3, seed);
            let mut s = Solvers::new(&p);
            let mut forms = [NewtonForm::Woodbury, NewtonForm::Direct].map(|form| {
                (
                    DualSolver::with_settings(
                        &s.factor,
                        &p.rows,
                        DualSettings {
                            newton_form: form,
                            ..Default::default()
                        },
                    )
                    .unwrap(),
                    vec![0.0; p.rows.len()],
                )
            });
            over_steps(&p, &mut s, seed, &mut forms, |dual, f, rows, b, w, z| {
                dual.solve(f, rows, b, w, z, None)
            });
            let [woodbury, direct] = forms.map(|(dual, _)| dual.newton_counts());
            eprintln!("seed {seed}: Woodbury form {woodbury:?}, direct form {direct:?}");
            assert!(
                woodbury.woodbury > 0 && woodbury.fallbacks == 0,
                "{woodbury:?}"
            );
            assert!(direct.woodbury == 0 && direct.direct > 0, "{direct:?}");
        }
    }

    /// The two preconditioners `kinds` of a dual without D on the factor ordered with `last`
    /// last, over a sequence of warm-started steps of `lattice(3, 6, 3, seed)` for three
    /// seeds: each gives clarabel's solution and the two agree (`over_steps`); their counts.
    fn preconditioned(
        last: bool,
        kinds: [matrix_free::Preconditioner; 2],
    ) -> Vec<[matrix_free::MatrixFreeCounts; 2]> {
        use matrix_free::{MatrixFreeSettings, MatrixFreeSolver};
        [1, 2, 3]
            .map(|seed| {
                let p = lattice(3, 6, 3, seed);
                let mut s = Solvers::new(&p);
                if !last {
                    s.factor = Factor::new(&p.k, &[]).unwrap();
                }
                let mut solvers = kinds.map(|preconditioner| {
                    let settings = MatrixFreeSettings {
                        preconditioner,
                        ..Default::default()
                    };
                    let solver =
                        MatrixFreeSolver::with_settings(&s.factor, &p.k, &p.rows, settings);
                    (solver.unwrap(), vec![0.0; p.rows.len()])
                });
                over_steps(&p, &mut s, seed, &mut solvers, |mf, f, rows, b, w, z| {
                    mf.solve(f, rows, b, w, z, None)
                });
                let counts = solvers.map(|(solver, _)| solver.counts());
                eprintln!("seed {seed}: {kinds:?} {counts:?}");
                counts
            })
            .to_vec()
    }

    /// Conjugate gradient iterations per Newton system.
    fn per_system(c: matrix_free::MatrixFreeCounts) -> f64 {
        c.cg_iterations as f64 / c.newton as f64
    }

    /// The matrix-free dual (C last) with either preconditioner gives clarabel's solution;
    /// the Dirichlet one really applies S and needs fewer conjugate gradient iterations on
    /// this lattice.
    #[test]
    fn matrix_free_preconditioners_agree_with_clarabel_in_3d() {
        use matrix_free::Preconditioner::{Diagonal, Dirichlet};
        for [dirichlet, diagonal] in preconditioned(true, [Dirichlet, Diagonal]) {
            assert!(dirichlet.preconditioner > 0 && diagonal.preconditioner == 0);
            assert!(
                per_system(dirichlet) < per_system(diagonal),
                "{dirichlet:?} {diagonal:?}"
            );
        }
    }

    /// The sparse dual (the factor in its fill-reducing order, whole solves) with the lumped
    /// or the diagonal preconditioner gives clarabel's solution, and the lumped one really
    /// applies K_CC (on this small lattice it takes as many conjugate gradient iterations
    /// as the diagonal; on the plates of docs/performance.md fewer); the Dirichlet one,
    /// which needs C last, is refused on such a factor, and is what the defaults pick where
    /// C is last.
    #[test]
    fn sparse_preconditioners_agree_with_clarabel_in_3d() {
        use matrix_free::Preconditioner::{Diagonal, Dirichlet, Lumped};
        use matrix_free::{MatrixFreeSettings, MatrixFreeSolver};
        for [lumped, diagonal] in preconditioned(false, [Lumped, Diagonal]) {
            assert!(lumped.preconditioner > 0 && diagonal.preconditioner == 0);
        }
        let p = lattice(3, 6, 3, 1);
        let (ordered, sparse) = (
            Factor::new(&p.k, &p.rows.dofs()).unwrap(),
            Factor::new(&p.k, &[]).unwrap(),
        );
        assert_eq!(
            MatrixFreeSettings::for_factor(&ordered).preconditioner,
            Dirichlet
        );
        assert_eq!(
            MatrixFreeSettings::for_factor(&sparse).preconditioner,
            Lumped
        );
        let dirichlet = MatrixFreeSettings::for_factor(&ordered);
        let err = MatrixFreeSolver::with_settings(&sparse, &p.k, &p.rows, dirichlet);
        assert!(err.is_err());
    }

    /// A free node with K = k I, one friction block in the plane z = 0 (tangents turned by
    /// φ), and b = |b| b̂ at 30° with |b| > c: w = (|b| − c)/k b̂ and γ = c b̂. A box
    /// |γ_k| ≤ c would give γ = (c, c) in the frame and another direction of w.
    #[test]
    fn the_friction_disc_is_round() {
        let (k, c, bn) = (2.0, 0.5, 1.7);
        let t = [
            Triplet::new(0, 0, k),
            Triplet::new(1, 1, k),
            Triplet::new(2, 2, k),
        ];
        let kmat = SparseColMat::try_new_from_triplets(3, 3, &t).unwrap();
        let (s30, c30) = 30f64.to_radians().sin_cos();
        let b = [bn * c30, bn * s30, 0.0];
        for phi in [0.0, 0.4, 2.0] {
            let (s, co) = f64::sin_cos(phi);
            let tau = [[co, s, 0.0], [-s, co, 0.0]];
            let friction: Vec<NodalRow> = tau.iter().map(|&d| row(0, 3, d, c)).collect();
            let p = Problem {
                k: kmat.clone(),
                rows: Rows::new(&[], &friction, 2),
                b: b.to_vec(),
                tangential: Vec::new(),
            };
            let mut sol = Solvers::new(&p);
            let mut z = vec![0.0; 2];
            let (w, _) = sol.dual(&p, &b, &mut z);
            let (wc, zc) = sol.conic(&p, &b);
            let w_exact = [(bn - c) / k * c30, (bn - c) / k * s30, 0.0];
            let g_exact: Vec<f64> = tau.iter().map(|t| c * (t[0] * c30 + t[1] * s30)).collect();
            let (dw, dz) = (rel_diff(&w_exact, &w), rel_diff(&g_exact, &z));
            eprintln!(
                "φ = {phi}: dual |Δw| {dw:.1e} |Δγ| {dz:.1e}; clarabel |Δw| {:.1e} |Δγ| {:.1e}",
                rel_diff(&w_exact, &wc),
                rel_diff(&g_exact, &zc)
            );
            assert!(dw <= 1e-14 && dz <= 1e-14, "{dw:e} {dz:e}");
            assert!(rel_diff(&w_exact, &wc) <= 1e-8 && rel_diff(&g_exact, &zc) <= 1e-8);
        }
    }

    /// A dual solve that reaches its iteration limit reports it as a status with its
    /// residual, and the status becomes the run's error (exit 1) that names the limit.
    #[test]
    fn the_iteration_limit_is_a_status() {
        let p = lattice(3, 5, 3, 1);
        let factor = Factor::new(&p.k, &p.rows.dofs()).unwrap();
        let settings = dual::DualSettings {
            max_iterations: 1,
            ..Default::default()
        };
        let mut dual = dual::DualSolver::with_settings(&factor, &p.rows, settings).unwrap();
        let (mut w, mut z) = (vec![0.0; p.b.len()], vec![0.0; p.rows.len()]);
        let report = dual.solve(&factor, &p.rows, &p.b, &mut w, &mut z, None);
        let StepStatus::MaxIterations {
            limit, residual, ..
        } = report.status
        else {
            panic!("{report:?}");
        };
        assert_eq!((limit, report.iterations), (1, 1));
        assert!(residual > 0.0 && report.residual > 1e-12, "{report:?}");
        let at = StepAt {
            n: 3,
            t: 0.5,
            k: 0.125,
            other_solver: "clarabel",
            limit_key: None,
        };
        let err = report.check(&at).unwrap_err();
        assert_eq!(err.exit_code(), 1);
        assert!(
            err.to_string().contains("did not converge in 1 iterations"),
            "{err}"
        );
    }

    /// Turns every tangential load of the top layer by `angle` about the z axis
    /// (in 2D: scales it by cos(angle)).
    fn turned_load(p: &Problem, dim: usize, angle: f64) -> Vec<f64> {
        let mut b = p.b.clone();
        let (s, c) = angle.sin_cos();
        for (node, load) in &p.tangential {
            let turned = if dim == 2 {
                vec![c * load[0], c * load[1]]
            } else {
                vec![
                    c * load[0] - s * load[1],
                    s * load[0] + c * load[1],
                    load[2],
                ]
            };
            for k in 0..dim {
                b[dim * node + k] += turned[k] - load[k];
            }
        }
        b
    }

    /// A run of slowly turning loads: warm started from the previous multipliers, each step
    /// takes a few iterations and agrees with clarabel.
    #[test]
    fn warm_starts_keep_iterations_small() {
        for dim in [2, 3] {
            let p = lattice(dim, if dim == 2 { 16 } else { 6 }, 3, 7);
            let mut s = Solvers::new(&p);
            let mut z = vec![0.0; p.rows.len()];
            let (mut warm, mut cold) = (Vec::new(), Vec::new());
            for step in 0..24 {
                let b = turned_load(&p, dim, 0.05 * step as f64);
                let (w, it) = s.dual(&p, &b, &mut z);
                warm.push(it);
                cold.push(s.dual(&p, &b, &mut vec![0.0; p.rows.len()]).1);
                assert!(kkt(&p.rows, &w, &z) <= 1e-10);
                if step % 8 == 0 {
                    let (wc, zc) = s.conic(&p, &b);
                    assert!(rel_diff(&w, &wc) <= 1e-7 && rel_diff(&z, &zc) <= 1e-7);
                }
            }
            eprintln!("{dim}D m = {}: warm {warm:?}, cold {cold:?}", p.rows.len());
            assert!(warm[1..].iter().all(|&it| it <= 6), "{warm:?}");
        }
    }

    /// Loads changing at a constant rate, b_n = (1 + n/100) b: where the steps keep their
    /// active sets (which rows are free, at zero or on the rim), the 2D multipliers are
    /// affine in the loads, so from the second step on the warm start's extrapolation
    /// 2z_{n−1} − z_{n−2} is the solution and is taken: the step ends without an iteration,
    /// where a start from z_{n−1} alone iterates. In 3D a rim's direction turns with the
    /// loads, and the extrapolation is only closer: fewer iterations. Each step passes the
    /// KKT test, and its w agrees with clarabel's.
    #[test]
    fn extrapolated_warm_starts_follow_steady_loads() {
        for dim in [2, 3] {
            let p = lattice(dim, if dim == 2 { 16 } else { 6 }, 3, 7);
            let mut s = Solvers::new(&p);
            let mut z = vec![0.0; p.rows.len()];
            s.dual(&p, &p.b, &mut z);
            let (mut extrapolated, mut plain) = (0, 0);
            let mut before = z.clone();
            for step in 1..6 {
                let b: Vec<f64> =
                    p.b.iter()
                        .map(|v| v * (1.0 + step as f64 / 100.0))
                        .collect();
                let from_last = s.dual(&p, &b, &mut z.clone()).1;
                let last = z.clone();
                let mut w = vec![0.0; b.len()];
                let report = s
                    .dual
                    .solve(&s.factor, &p.rows, &b, &mut w, &mut z, Some(&before));
                before = last;
                assert_eq!(report.status, StepStatus::Solved);
                assert!(kkt(&p.rows, &w, &z) <= 1e-10);
                assert!(rel_diff(&w, &s.conic(&p, &b).0) <= 1e-7);
                eprintln!(
                    "{dim}D step {step}: {} iterations, {from_last} from z_(n-1)",
                    report.iterations
                );
                if step >= 2 {
                    extrapolated += report.iterations;
                    plain += from_last;
                }
            }
            assert!(plain > 0, "{dim}D");
            match dim {
                2 => assert_eq!(extrapolated, 0),
                _ => assert!(extrapolated < plain, "{extrapolated} against {plain}"),
            }
        }
    }

    /// The problem's rows and loads on a random banded SPD matrix K = BᵀB + 0.01 I (B banded,
    /// entries in [−1, 1]): D is far from an M-matrix, so the Newton step often fails to
    /// descend and the projected Newton steps carry the iteration.
    fn scrambled(mut p: Problem, seed: u64) -> Problem {
        let n = p.b.len();
        let band = 13;
        let mut noise = SplitMix(seed);
        let mut t: Vec<_> = (0..n).map(|i| Triplet::new(i, i, 0.01)).collect();
        for k in 0..n {
            let row: Vec<f64> = (0..band).map(|_| noise.range(-1.0, 1.0)).collect();
            let cols = || (k..n).zip(&row);
            for (i, x) in cols() {
                t.extend(cols().map(|(j, y)| Triplet::new(i, j, x * y)));
            }
        }
        p.k = SparseColMat::try_new_from_triplets(n, n, &t).unwrap();
        p
    }

    /// The globalization: on scrambled problems the method still converges to the KKT point,
    /// from zero and warm started after a load change. (Clarabel is checked more loosely here:
    /// K is badly conditioned, and clarabel's 3D accuracy degrades with it.)
    #[test]
    fn hard_problems_converge() {
        for dim in [2, 3] {
            let (mut cold, mut warm) = (Vec::new(), Vec::new());
            for seed in 0..6 {
                let p = scrambled(lattice(dim, if dim == 2 { 30 } else { 5 }, 3, seed), seed);
                let mut s = Solvers::new(&p);
                let mut z = vec![0.0; p.rows.len()];
                let (w, it) = s.dual(&p, &p.b, &mut z);
                cold.push(it);
                assert!(kkt(&p.rows, &w, &z) <= 1e-10);
                let (wc, zc) = s.conic(&p, &p.b);
                assert!(rel_diff(&w, &wc) <= 1e-6 && rel_diff(&z, &zc) <= 1e-6);
                let b = turned_load(&p, dim, 0.1);
                let (w, it) = s.dual(&p, &b, &mut z);
                warm.push(it);
                assert!(kkt(&p.rows, &w, &z) <= 1e-10);
            }
            eprintln!("{dim}D scrambled: cold {cold:?}, warm after a load change {warm:?}");
        }
    }
}
