//! How a step's solve ended: the solvers report a `StepStatus` with their iterations and
//! final residual (`StepReport`), the time loop adds what its checks of the answer found,
//! and `StepReport::check` turns every status but `Solved` into the run's error, here and
//! nowhere else, each message naming the step and what to try.

use crate::{Error, Result};

/// The outcome of a step: the contact solve's, then the time loop's checks of its answer.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum StepStatus {
    /// Solved to the solver's tolerance and trusted.
    #[default]
    Solved,
    /// The dual method reached its iteration limit with the stopping test's residual
    /// `residual` against the scale `scale` = max|d| it is relative to.
    MaxIterations {
        limit: usize,
        residual: f64,
        scale: f64,
    },
    /// A Newton matrix of the dual method was not positive definite to working precision.
    NewtonIndefinite,
    /// Given up on request before it was solved (`solver::abandon`); z holds an iterate.
    Abandoned,
    /// The step's solver (or the linear solver under it) stopped without an answer, in its
    /// own words: `solver` says which and what it solved, `reason` is its status by name
    /// (clarabel's `SolverStatus`, PETSc's `KSPConvergedReason`), after `iterations`, with
    /// its final residual; `remedy` says what to try.
    Stopped {
        solver: &'static str,
        reason: &'static str,
        iterations: usize,
        residual: f64,
        remedy: &'static str,
    },
    /// u_n or w_n has an entry that is not finite.
    NotFinite { u_max: f64, w_max: f64 },
    /// max|u_n| grew `factor` times its size per unit load at t = `since` (the time loop's
    /// divergence detector).
    Diverged { u_max: f64, factor: f64, since: f64 },
    /// n·w > 0 on Γ3,1 by `amount` at `node`, beyond the tolerance relative to the larger
    /// of max|w_n| and the mean velocity max|u_n|/t_n.
    Violation {
        amount: f64,
        node: usize,
        w_max: f64,
        mean_velocity: f64,
    },
}

/// What a step's solve did.
#[derive(Clone, Copy, Debug, Default)]
pub struct StepReport {
    pub status: StepStatus,
    /// Newton iterations (dual) or interior-point iterations (clarabel); 0 for linear with
    /// the stored factor, the Krylov iterations for linear through PETSc.
    pub iterations: usize,
    /// The solver's final residual, relative: the dual's stopping test over max|d|,
    /// clarabel's larger of its primal and dual residuals, the active-set solver's KKT
    /// residual; 0 for linear.
    pub residual: f64,
    /// The Krylov iterations of the active-set solver's Newton systems (0 for the others).
    pub krylov: usize,
}

/// Where a step stands, for the messages: step n at t_n, the time step k, and the
/// `[solver] contact` choice to suggest when the answer is not trusted.
pub struct StepAt {
    pub n: usize,
    pub t: f64,
    pub k: f64,
    pub other_solver: &'static str,
    /// The scene key that sets the solver's iteration limit, where it has one.
    pub limit_key: Option<&'static str>,
}

impl StepReport {
    /// Ok for a solved step; otherwise the run's error (exit 1), which says what to try.
    pub fn check(&self, at: &StepAt) -> Result<()> {
        let StepAt { n, t, k, .. } = *at;
        let msg = match self.status {
            StepStatus::Solved => return Ok(()),
            StepStatus::MaxIterations {
                limit,
                residual,
                scale,
            } => format!(
                "the contact solver's semismooth Newton method did not converge in {limit} \
                 iterations (residual {residual:e} relative to {scale:e}); {}try [solver] \
                 contact = \"{}\"",
                at.limit_key
                    .map_or(String::new(), |key| format!("raise {key}, or ")),
                at.other_solver
            ),
            StepStatus::Abandoned => {
                format!("step {n} at t = {t} was given up before it was solved")
            }
            StepStatus::NewtonIndefinite => "the fast contact solver's Newton matrix (the \
                 constraint rows condensed through K_A⁻¹) is not positive definite to working \
                 precision, so a Newton step cannot be solved; set `[solver] contact = \
                 \"clarabel\"` to solve the step problem without it, and report the scene"
                .to_string(),
            StepStatus::Stopped {
                solver,
                reason,
                iterations,
                residual,
                remedy,
            } => format!(
                "{solver} stopped without an answer at step {n}, t = {t}: {reason} after \
                 {iterations} iterations (residual {residual:e}); {remedy}"
            ),
            StepStatus::NotFinite { u_max, w_max } => format!(
                "the solution is not finite at step {n}, t = {t} (max|u_n| = {u_max:e}, \
                 max|w_n| = {w_max:e}); {}",
                remedy(k)
            ),
            StepStatus::Diverged {
                u_max,
                factor,
                since,
            } => format!(
                "the solution grows without bound at step {n}, t = {t}: max|u| = {u_max:e}, \
                 {factor:.1e} times its size per unit load at t = {since}; {}",
                remedy(k)
            ),
            StepStatus::Violation {
                amount,
                node,
                w_max,
                mean_velocity,
            } => format!(
                "the contact solver's answer violates n·w ≤ 0 on Γ3,1 by {amount:e} (max|w| = \
                 {w_max:e}, max|u|/t = {mean_velocity:e}) at node {node} at step {n}, t = {t}; \
                 the results cannot be trusted: try [solver] contact = \"{}\"",
                at.other_solver
            ),
        };
        Err(Error::solve(msg))
    }
}

/// What to do about a run that blows up.
fn remedy(k: f64) -> String {
    format!(
        "the step k = {k} may be too large for the explicit scheme (use more time steps or \
         [scheme] history = \"implicit\"), or the data make the problem unstable (a \
         relaxation kernel that amplifies, loads that grow without bound)"
    )
}
