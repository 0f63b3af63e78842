//! The cross-check step solver: the whole step problem handed to clarabel (interior point).
//! Friction |w_τ,j| is lifted with one variable s_j per friction node j (a block of `block`
//! rows τ_jk):
//!
//!   minimize ½ wᵀ K_A w − bᵀ w + Σ_j c_j s_j
//!   subject to n_i·w ≤ 0 (Γ3,1),   (s_j, τ_j1·w, …) ∈ SOC (Γ3,2),
//!
//! SOC = {(s, v) : |v| ≤ s} the second-order cone of dimension block + 1 (in 2D, SOC(2) is
//! |τ_j·w| ≤ s_j, the two inequalities ±τ_j·w ≤ s_j). Contact rows form one nonnegative cone.
//! The problem structure is built once; each step only replaces q = (−b, c) (`update_q`).
//!
//! Clarabel solves Ax + σ = 0, σ ∈ K (x = (w, s)), with duals y ∈ K* and
//! Px + q + Aᵀy = 0. The contact rows of A are n_iᵀ (σ_i = −n_i·w ≥ 0), the rows of friction
//! node j are (−e_{s_j}, τ_j1ᵀ, …) (σ = (s_j, −w_τ,j) ∈ SOC: the cone is symmetric under
//! v ↦ −v). So K_A w − b + Σ_i y_i n_i + Σ_jk y_jk τ_jk = 0, and with the convention
//! K_A w = b − Pᵀ(λ, γ) of `dual`: λ_i = y_i, γ_j = the tail (y_j1, …) of node j's SOC dual,
//! whose head is y_j0 = c_j (the s_j column of the stationarity), so |γ_j| ≤ c_j.

use super::{Rows, StepReport, StepStatus};
use crate::fem::Sparse;
use crate::{Error, Result};
use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, NonnegativeConeT, SecondOrderConeT,
    SolverStatus,
};

/// Tolerances asked of clarabel (its defaults, 1e-8, are absolute in the objective and too
/// loose for the tiny objective values of the paper's scene). The duality gap drives the
/// accuracy of w and γ: on the second-order cones of 3D friction the error of clarabel's
/// solution behaves like the square root of the relative gap (measured: gap 1e-12 → 2e-7,
/// 1e-14 → 5e-8 against the dual solver), while its primal residual stalls near 1e-10 as
/// the cones' scaling degenerates. So the gap is asked tight and the residual loose enough
/// that the tight gap is reached (in 2D both settle at 1e-11 or better).
const TOL_GAP: f64 = 1e-14;
const TOL_FEAS: f64 = 1e-9;

pub struct ConicSolver {
    solver: DefaultSolver<f64>,
    n: usize,
    q: Vec<f64>,
}

impl ConicSolver {
    pub fn new(k_a: &Sparse, rows: &Rows) -> Result<Self> {
        let n = k_a.nrows();
        let nf = rows.n_friction_nodes();
        let nx = n + nf;
        // P: the upper triangle of K_A, zero block for s.
        let a = k_a.as_ref();
        let (cp, ri, v) = (a.symbolic().col_ptr(), a.symbolic().row_idx(), a.val());
        let (mut colptr, mut rowval, mut nzval) = (vec![0usize], Vec::new(), Vec::new());
        for j in 0..n {
            for p in cp[j]..cp[j + 1] {
                if ri[p] <= j {
                    rowval.push(ri[p]);
                    nzval.push(v[p]);
                }
            }
            colptr.push(rowval.len());
        }
        colptr.resize(nx + 1, rowval.len());
        let p = CscMatrix::new(nx, nx, colptr, rowval, nzval);
        // A: the contact rows n_iᵀ, then per friction node the rows (−e_s, τ_j1ᵀ, …).
        let mut t: Vec<(usize, usize, f64)> = Vec::new();
        for (r, row) in rows.rows[..rows.n_contact].iter().enumerate() {
            t.extend(row.entries().map(|(dof, coef)| (r, dof, coef)));
        }
        let mut cones = vec![NonnegativeConeT(rows.n_contact)];
        let mut r = rows.n_contact;
        for j in 0..nf {
            t.push((r, n + j, -1.0));
            for row in &rows.rows[rows.friction_block(j)] {
                r += 1;
                t.extend(row.entries().map(|(dof, coef)| (r, dof, coef)));
            }
            r += 1;
            cones.push(SecondOrderConeT(rows.block + 1));
        }
        let a = CscMatrix::new_from_triplets(
            r,
            nx,
            t.iter().map(|e| e.0).collect(),
            t.iter().map(|e| e.1).collect(),
            t.iter().map(|e| e.2).collect(),
        );
        let b = vec![0.0; r];
        let settings = DefaultSettingsBuilder::default()
            .verbose(false)
            .presolve_enable(false)
            .tol_gap_abs(1e-16)
            .tol_gap_rel(TOL_GAP)
            .tol_feas(TOL_FEAS)
            .tol_ktratio(1e-8)
            .max_iter(300)
            .build()
            .map_err(|e| Error::solve(format!("clarabel settings: {e:?}")))?;
        // q = (−b, c) is set by each step's `solve`.
        let q = vec![0.0; nx];
        let solver = DefaultSolver::new(&p, &q, &a, &b, &cones, settings)
            .map_err(|e| Error::solve(format!("clarabel setup failed: {e:?}")))?;
        Ok(ConicSolver { solver, n, q })
    }

    pub fn solve(&mut self, rows: &Rows, b: &[f64], w: &mut [f64], z: &mut [f64]) -> StepReport {
        // The step problem is positively homogeneous in (b, c): solve it for (b, c)/σ with
        // σ = max|b| so that clarabel's tolerances see O(1) data, then scale back.
        let sigma = b.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let sigma = if sigma > 0.0 { sigma } else { 1.0 };
        for (q, bi) in self.q.iter_mut().zip(b) {
            *q = -bi / sigma;
        }
        for j in 0..rows.n_friction_nodes() {
            let c = rows.rows[rows.friction_block(j).start].bound;
            self.q[self.n + j] = c / sigma;
        }
        self.solver
            .update_q(&self.q)
            .expect("q keeps the length it was built with, and presolve is off");
        self.solver.solve();
        let sol = &self.solver.solution;
        let mut report = StepReport {
            status: StepStatus::Solved,
            iterations: sol.iterations as usize,
            residual: sol.r_prim.max(sol.r_dual),
            krylov: 0,
        };
        if !matches!(
            sol.status,
            SolverStatus::Solved | SolverStatus::AlmostSolved
        ) {
            report.status = StepStatus::Stopped {
                solver: "clarabel's interior point solve of the step problem",
                reason: status_name(sol.status),
                iterations: report.iterations,
                residual: report.residual,
                remedy: "try [solver] contact = \"dense\", or \"sparse\" where its memory \
                         would not fit",
            };
            return report;
        }
        for (wi, x) in w.iter_mut().zip(&sol.x[..self.n]) {
            *wi = sigma * x;
        }
        // λ: the nonnegative cone's duals; γ_j: the tails of the SOC duals (the module doc).
        let (lambda, gamma) = z.split_at_mut(rows.n_contact);
        for (zi, y) in lambda.iter_mut().zip(&sol.z) {
            *zi = sigma * y;
        }
        let soc = sol.z[rows.n_contact..].chunks_exact(rows.block + 1);
        for (g, y) in gamma.chunks_exact_mut(rows.block.max(1)).zip(soc) {
            for (gk, yk) in g.iter_mut().zip(&y[1..]) {
                *gk = sigma * yk;
            }
        }
        report
    }
}

/// Clarabel's status by its name.
fn status_name(status: SolverStatus) -> &'static str {
    match status {
        SolverStatus::Unsolved => "Unsolved",
        SolverStatus::Solved => "Solved",
        SolverStatus::PrimalInfeasible => "PrimalInfeasible",
        SolverStatus::DualInfeasible => "DualInfeasible",
        SolverStatus::AlmostSolved => "AlmostSolved",
        SolverStatus::AlmostPrimalInfeasible => "AlmostPrimalInfeasible",
        SolverStatus::AlmostDualInfeasible => "AlmostDualInfeasible",
        SolverStatus::MaxIterations => "MaxIterations",
        SolverStatus::MaxTime => "MaxTime",
        SolverStatus::NumericalError => "NumericalError",
        SolverStatus::InsufficientProgress => "InsufficientProgress",
        SolverStatus::CallbackTerminated => "CallbackTerminated",
    }
}
