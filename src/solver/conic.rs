//! The cross-check step solver: the whole step problem handed to clarabel (interior point).
//! Friction |τ_i·w_i| is lifted with one variable s_i per friction row:
//!
//!   minimize ½ wᵀ K_A w − bᵀ w + Σ c_i s_i
//!   subject to n_i·w ≤ 0 (Γ3,1),  τ_i·w − s_i ≤ 0,  −τ_i·w − s_i ≤ 0 (Γ3,2),
//!
//! all rows in one nonnegative cone. The problem structure is built once; each step only
//! replaces q = (−b, c) (`update_q`). Clarabel's duals give λ_i = z_i on contact rows and
//! γ_i = z⁺_i − z⁻_i on friction rows (K_A w = b − Pᵀ(λ, γ)).

use super::{Rows, StepReport};
use crate::fem::Sparse;
use crate::{Error, Result};
use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, NonnegativeConeT, SolverStatus,
};

/// Tolerances asked of clarabel (its defaults, 1e-8, are absolute in the objective and too
/// loose for the tiny objective values of the paper's scene).
const TOLERANCE: f64 = 1e-12;

pub struct ConicSolver {
    solver: DefaultSolver<f64>,
    n: usize,
    q: Vec<f64>,
}

impl ConicSolver {
    pub fn new(k_a: &Sparse, rows: &Rows) -> Result<Self> {
        let n = k_a.nrows();
        let nf = rows.len() - rows.n_contact;
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
        // A: one row per contact node, two per friction node.
        let (mut ii, mut jj, mut vv) = (Vec::new(), Vec::new(), Vec::new());
        let mut r = 0;
        for (i, row) in rows.rows.iter().enumerate() {
            if i < rows.n_contact {
                for (dof, coef) in row.entries() {
                    ii.push(r);
                    jj.push(dof);
                    vv.push(coef);
                }
                r += 1;
            } else {
                let s = n + i - rows.n_contact;
                for sign in [1.0, -1.0] {
                    for (dof, coef) in row.entries() {
                        ii.push(r);
                        jj.push(dof);
                        vv.push(sign * coef);
                    }
                    ii.push(r);
                    jj.push(s);
                    vv.push(-1.0);
                    r += 1;
                }
            }
        }
        let a = CscMatrix::new_from_triplets(r, nx, ii, jj, vv);
        let b = vec![0.0; r];
        let cones = [NonnegativeConeT(r)];
        let settings = DefaultSettingsBuilder::default()
            .verbose(false)
            .presolve_enable(false)
            .tol_gap_abs(1e-16)
            .tol_gap_rel(TOLERANCE)
            .tol_feas(TOLERANCE)
            .tol_ktratio(1e-8)
            .max_iter(300)
            .build()
            .map_err(|e| Error::solve(format!("clarabel settings: {e:?}")))?;
        let mut q = vec![0.0; nx];
        for (i, row) in rows.rows.iter().enumerate().skip(rows.n_contact) {
            q[n + i - rows.n_contact] = row.bound;
        }
        let solver = DefaultSolver::new(&p, &q, &a, &b, &cones, settings)
            .map_err(|e| Error::solve(format!("clarabel setup failed: {e:?}")))?;
        Ok(ConicSolver { solver, n, q })
    }

    pub fn solve(
        &mut self,
        rows: &Rows,
        b: &[f64],
        w: &mut [f64],
        z: &mut [f64],
    ) -> Result<StepReport> {
        // The step problem is positively homogeneous in (b, c): solve it for (b, c)/σ with
        // σ = max|b| so that clarabel's tolerances see O(1) data, then scale back.
        let sigma = b.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let sigma = if sigma > 0.0 { sigma } else { 1.0 };
        for (q, bi) in self.q.iter_mut().zip(b) {
            *q = -bi / sigma;
        }
        for (i, row) in rows.rows.iter().enumerate().skip(rows.n_contact) {
            self.q[self.n + i - rows.n_contact] = row.bound / sigma;
        }
        self.solver
            .update_q(&self.q)
            .map_err(|e| Error::solve(format!("clarabel update failed: {e:?}")))?;
        self.solver.solve();
        let sol = &self.solver.solution;
        if !matches!(
            sol.status,
            SolverStatus::Solved | SolverStatus::AlmostSolved
        ) {
            return Err(Error::solve(format!(
                "clarabel did not solve the step problem: status {:?} after {} iterations",
                sol.status, sol.iterations
            )));
        }
        for (wi, x) in w.iter_mut().zip(&sol.x[..self.n]) {
            *wi = sigma * x;
        }
        let mut r = 0;
        for (i, zi) in z.iter_mut().enumerate() {
            if i < rows.n_contact {
                *zi = sigma * sol.z[r];
                r += 1;
            } else {
                *zi = sigma * (sol.z[r] - sol.z[r + 1]);
                r += 2;
            }
        }
        Ok(StepReport {
            iterations: sol.iterations as usize,
        })
    }
}
