//! The fast step solver: the problem condensed onto its constraint rows.
//!
//! With P the m×n matrix of the nodal rows (n_iᵀ on Γ3,1, τ_iᵀ on Γ3,2), the optimality
//! conditions of the step problem are
//!
//!   K_A w = b − Pᵀ z,   z_i = λ_i ≥ 0, λ_i n_i·w_i = 0, n_i·w_i ≤ 0       (Γ3,1)
//!                       z_i = γ_i ∈ c_i ∂|·|(τ_i·w_i)                       (Γ3,2)
//!
//! Eliminating w = K_A⁻¹(b − Pᵀz) leaves the box-constrained dual
//!
//!   minimize ½ zᵀ D z − dᵀ z  over  λ ≥ 0, |γ_i| ≤ c_i,   D = P K_A⁻¹ Pᵀ,  d = P K_A⁻¹ b,
//!
//! whose gradient is g = D z − d = −P w.
//!
//! The factor of K_A orders the constrained dofs C last (`Factor`): P K_A Pᵀ = L Lᵀ with
//! trailing block L_CC, and P touches only C (E: its C-block, |C|×m). With G = L_CC⁻¹ E
//! (dense, once per run): D = GᵀG, and for a step with forward solve L y = b,
//! d = Gᵀ y_C; the multipliers enter only through y_C ← y_C − G z; one backward solve
//! Lᵀ w = y gives w. So a step costs one solve with the stored factor — the same as a step
//! without contact — plus O(|C|·m) for G and the small problem below.
//!
//! The dual is solved exactly by an active-set Newton method — Bertsekas' projected Newton
//! method for bound constraints, with an Armijo search along the projection arc, warm
//! started from the previous step's multipliers. Multipliers at a bound whose gradient
//! points outward are held there; the others solve a dense linear system with D, so once the
//! active set is right the answer is exact up to rounding. (A plain primal-dual active set
//! iteration cycles on this problem: D is not an M-matrix; the line search makes the method
//! globally convergent.)

use super::{Factor, Rows, StepReport};
use crate::{Error, Result};
use faer::linalg::solvers::Solve;
use faer::linalg::triangular_solve::solve_lower_triangular_in_place;
use faer::{Accum, Mat, MatMut, Side};

/// Relative tolerance of the dual optimality conditions (in units of the velocities P w).
pub const TOLERANCE: f64 = 1e-12;
const MAX_ITERATIONS: usize = 500;

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Set {
    Lower,
    Upper,
    Free,
}

pub struct DualSolver {
    /// G = L_CC⁻¹ E (|C|×m).
    g: Mat<f64>,
    /// D = GᵀG = P K_A⁻¹ Pᵀ (m×m).
    d: Mat<f64>,
    /// diag(D) (scales the active-set test) and the multipliers' bounds, fixed per run.
    diag: Vec<f64>,
    bounds: Vec<(f64, f64)>,
    set: Vec<Set>,
    /// The step's forward-solved right side, in the factor's ordering.
    y: Vec<f64>,
}

impl DualSolver {
    /// `factor` must have been built with the rows' dofs ordered last.
    pub fn new(factor: &Factor, rows: &Rows) -> Self {
        let (n, c, m) = (factor.dim(), factor.last(), rows.len());
        let first = n - c;
        let mut g = Mat::<f64>::zeros(c, m);
        for (r, row) in rows.rows.iter().enumerate() {
            for (dof, coef) in row.entries() {
                let pos = factor.position(dof);
                debug_assert!(pos >= first, "constrained dofs are ordered last");
                g[(pos - first, r)] = coef;
            }
        }
        let l_cc = factor.trailing_block();
        solve_lower_triangular_in_place(l_cc.as_ref(), g.as_mut(), faer::get_global_parallelism());
        let mut d = Mat::<f64>::zeros(m, m);
        faer::linalg::matmul::matmul(
            d.as_mut(),
            Accum::Replace,
            g.transpose(),
            g.as_ref(),
            1.0,
            faer::get_global_parallelism(),
        );
        DualSolver {
            g,
            diag: (0..m).map(|i| d[(i, i)]).collect(),
            bounds: (0..m).map(|i| rows.bounds(i)).collect(),
            d,
            set: vec![Set::Free; m],
            y: vec![0.0; n],
        }
    }

    /// Solves D_FF x = rhs on the free multipliers F (dense Cholesky).
    fn face_solve(&self, free: &[usize], rhs: Vec<f64>) -> Result<Vec<f64>> {
        let nf = free.len();
        if nf == 0 {
            return Ok(Vec::new());
        }
        let a = Mat::<f64>::from_fn(nf, nf, |r, c| self.d[(free[r], free[c])]);
        let b = Mat::<f64>::from_fn(nf, 1, |r, _| rhs[r]);
        let llt = a.llt(Side::Lower).map_err(|e| {
            Error::solve(format!(
                "the condensed contact matrix is not positive definite ({e:?})"
            ))
        })?;
        let sol = llt.solve(&b);
        Ok((0..nf).map(|r| sol[(r, 0)]).collect())
    }

    fn gradient(&self, z: &[f64], dvec: &[f64], g: &mut [f64]) {
        let m = z.len();
        for i in 0..m {
            let mut s = -dvec[i];
            for (j, zj) in z.iter().enumerate() {
                if *zj != 0.0 {
                    s += self.d[(i, j)] * zj;
                }
            }
            g[i] = s;
        }
    }

    pub fn solve(
        &mut self,
        factor: &Factor,
        rows: &Rows,
        b: &[f64],
        w: &mut [f64],
        z: &mut [f64],
    ) -> Result<StepReport> {
        let m = rows.len();
        let (n, c) = (factor.dim(), factor.last());
        // Forward solve L y = b; d = Gᵀ y_C.
        factor.permute(b, &mut self.y);
        factor.forward(MatMut::from_column_major_slice_mut(&mut self.y, n, 1));
        let y_c = &self.y[n - c..];
        let dvec: Vec<f64> = (0..m)
            .map(|r| {
                let col = self.g.col(r);
                (0..c).map(|i| col[i] * y_c[i]).sum()
            })
            .collect();
        let scale = dvec.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let tol = TOLERANCE * scale.max(f64::MIN_POSITIVE);
        let (diag, bounds) = (&self.diag, &self.bounds);
        let project = |i: usize, v: f64| v.clamp(bounds[i].0, bounds[i].1);
        // Warm start: the previous multipliers, projected into the box.
        for (i, zi) in z.iter_mut().enumerate() {
            *zi = project(i, *zi);
        }
        let mut g = vec![0.0; m];
        self.gradient(z, &dvec, &mut g);
        let mut q = objective(z, &g, &dvec);
        let mut iterations = 0;
        let (mut trial, mut g_trial, mut p) = (vec![0.0; m], vec![0.0; m], vec![0.0; m]);
        loop {
            let residual = dual_residual(rows, z, &g);
            if residual <= tol {
                break;
            }
            if iterations == MAX_ITERATIONS {
                return Err(Error::solve(format!(
                    "the dual active-set method did not converge in {MAX_ITERATIONS} \
                     iterations (residual {residual:e} relative to {scale:e}); \
                     try [solver] contact = \"clarabel\""
                )));
            }
            iterations += 1;
            // 1. The primal-dual active set step (semismooth Newton on z = proj(z − g/diag D)):
            // fix the multipliers the test puts at a bound, solve D_FF z_F = d_F − D_FA z_A for
            // the others, project. Taken only if it lowers the dual objective; it changes many
            // sets at once and usually finishes in a few iterations.
            for i in 0..m {
                let (lo, hi) = bounds[i];
                let v = z[i] - g[i] / diag[i];
                (self.set[i], trial[i]) = if v < lo {
                    (Set::Lower, lo)
                } else if v > hi {
                    (Set::Upper, hi)
                } else {
                    (Set::Free, 0.0)
                };
            }
            let free: Vec<usize> = (0..m).filter(|&i| self.set[i] == Set::Free).collect();
            let rhs: Vec<f64> = free
                .iter()
                .map(|&i| {
                    dvec[i]
                        - (0..m)
                            .filter(|&j| self.set[j] != Set::Free)
                            .map(|j| self.d[(i, j)] * trial[j])
                            .sum::<f64>()
                })
                .collect();
            for (&i, v) in free.iter().zip(self.face_solve(&free, rhs)?) {
                trial[i] = project(i, v);
            }
            self.gradient(&trial, &dvec, &mut g_trial);
            let q_trial = objective(&trial, &g_trial, &dvec);
            if q_trial < q {
                z.copy_from_slice(&trial);
                g.copy_from_slice(&g_trial);
                q = q_trial;
                continue;
            }
            // 2. Otherwise a projected Newton step (Bertsekas 1982), which always descends:
            // multipliers within ε of a bound whose gradient pushes them outward are held
            // there (binding); the others take the Newton step of the face, D_FF p_F = −g_F.
            let eps = (0..m)
                .map(|i| (z[i] - project(i, z[i] - g[i] / diag[i])).abs())
                .fold(0.0f64, f64::max);
            for i in 0..m {
                let (lo, hi) = bounds[i];
                self.set[i] = if z[i] <= lo + eps && g[i] > 0.0 {
                    Set::Lower
                } else if z[i] >= hi - eps && g[i] < 0.0 {
                    Set::Upper
                } else {
                    Set::Free
                };
            }
            let free: Vec<usize> = (0..m).filter(|&i| self.set[i] == Set::Free).collect();
            for i in 0..m {
                p[i] = -g[i] / diag[i];
            }
            let rhs: Vec<f64> = free.iter().map(|&i| -g[i]).collect();
            for (&i, v) in free.iter().zip(self.face_solve(&free, rhs)?) {
                p[i] = v;
            }
            // Armijo search along the projection arc z(α) = proj(z + α p).
            let mut alpha = 1.0;
            loop {
                for i in 0..m {
                    trial[i] = project(i, z[i] + alpha * p[i]);
                }
                self.gradient(&trial, &dvec, &mut g_trial);
                let q_trial = objective(&trial, &g_trial, &dvec);
                let predicted: f64 = (0..m)
                    .map(|i| match self.set[i] {
                        Set::Free => -alpha * g[i] * p[i],
                        _ => g[i] * (z[i] - trial[i]),
                    })
                    .sum();
                if q - q_trial >= 1e-4 * predicted || alpha < 1e-12 {
                    break;
                }
                alpha *= 0.5;
            }
            z.copy_from_slice(&trial);
            g.copy_from_slice(&g_trial);
            q = objective(z, &g, &dvec);
        }
        // y_C ← y_C − G z, then the backward solve Lᵀ w = y.
        let y_c = &mut self.y[n - c..];
        for (r, &zr) in z.iter().enumerate() {
            if zr != 0.0 {
                for (yi, gi) in y_c.iter_mut().zip(self.g.col(r).iter()) {
                    *yi -= gi * zr;
                }
            }
        }
        factor.backward(MatMut::from_column_major_slice_mut(&mut self.y, n, 1));
        factor.unpermute(&self.y, w);
        Ok(StepReport { iterations })
    }
}

/// The dual objective ½ zᵀDz − dᵀz = ½ zᵀ(g − d) with g = Dz − d.
fn objective(z: &[f64], g: &[f64], d: &[f64]) -> f64 {
    0.5 * z
        .iter()
        .zip(g.iter().zip(d))
        .map(|(z, (g, d))| z * (g - d))
        .sum::<f64>()
}

/// Violation of the dual optimality conditions (z in the box assumed): g_i ≤ 0 wherever
/// z_i > lo_i and g_i ≥ 0 wherever z_i < hi_i (g = −P w: so n·w ≤ 0 on free contact rows).
fn dual_residual(rows: &Rows, z: &[f64], g: &[f64]) -> f64 {
    let mut r: f64 = 0.0;
    for i in 0..z.len() {
        let (lo, hi) = rows.bounds(i);
        if z[i] < lo || z[i] > hi {
            return f64::INFINITY;
        }
        if z[i] > lo {
            r = r.max(g[i]);
        }
        if z[i] < hi {
            r = r.max(-g[i]);
        }
    }
    r
}
