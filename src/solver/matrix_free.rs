//! The contact solver with no m × m matrix, for contact boundaries whose condensed operator
//! D = P K_A⁻¹ Pᵀ does not fit in memory (`[solver] contact = "matrix_free"`).
//!
//! It solves the dual of `dual` — the same problem
//!
//!   minimize q(z) = ½ zᵀ D z − dᵀ z  over  z ∈ Z,   d = P K_A⁻¹ b,
//!
//! with the same multiplier groups, projections Π_j and stopping test (`dual::groups`, the
//! module doc of `dual`), but never forms D: a product is one solve with the stored factor
//! of K_A,
//!
//!   D v = P (K_A⁻¹ (Pᵀ v)),
//!
//! Pᵀ v scattered onto the constrained dofs C in the factor's ordering, a forward and a
//! backward pass, P gathered from C. Memory: the factor, three vectors of the dofs and a
//! few of the m rows, O(nnz(L) + m).
//!
//! The method. The semismooth Newton step of `dual` on z = Π(z − g/(ηδ)) (the same
//! prediction: free groups, contact rows at zero, discs on their rim with the tangent t̂ and
//! the curvature shift κ) is the SPD system (QᵀDQ + diag κ) x = −Qᵀ(D z₀ − d), solved here
//! by conjugate gradients, one product with D per iteration, preconditioned by the diagonal
//! δ_j + κ_j (`cg`); inexactly, to a residual at most min(½, r/max|d|) r for the step's
//! KKT residual r (an inexact Newton method: fast local convergence, no work wasted far from
//! the solution) and never below a tenth of the tolerance. The Newton point Π(z₀ + Q x) is
//! taken when it lowers q (or, at the rounding level of q, the KKT residual); otherwise the
//! projected gradient step Π(z − β g/δ) with the Armijo search, which always descends, so
//! the method converges from any start. δ is one number for all groups here: the mean of
//! diag D, estimated from products with fixed ±1 vectors (Hutchinson's trace estimate),
//! since the exact diagonal would cost m solves. The answer does not depend on δ.

use super::dual::groups::{self, Coord, Group};
use super::dual::iteration::{backtrack, change, prediction, project, residual, rounding};
use super::dual::DualSettings;
use super::{Factor, Rows, StepReport, StepStatus};
use crate::{Error, Result};

/// The settings of a `MatrixFreeSolver`; `validate` checks the ranges given with each field.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MatrixFreeSettings {
    /// The dual's settings that this method shares: `tolerance` (the same stopping test),
    /// `max_iterations` (Newton or projected gradient iterations per step), `eta`, `rim`
    /// and `dependent_shift`. Default `DualSettings::default()`.
    pub dual: DualSettings,
    /// Conjugate gradient iterations per Newton system at most; a system not solved by then
    /// gives its last iterate, which the descent test accepts or rejects. Default 400; ≥ 1.
    pub cg_max: usize,
    /// Products with ±1 vectors for the estimate of diag D's mean. Default 4; ≥ 1.
    pub probes: usize,
}

impl Default for MatrixFreeSettings {
    fn default() -> Self {
        MatrixFreeSettings {
            dual: DualSettings::default(),
            cg_max: 400,
            probes: 4,
        }
    }
}

impl MatrixFreeSettings {
    /// Checks every field against its range; the error names the first field out of it.
    pub fn validate(&self) -> Result<()> {
        self.dual.validate()?;
        for (field, ok) in [("cg_max", self.cg_max >= 1), ("probes", self.probes >= 1)] {
            if !ok {
                return Err(Error::input(format!(
                    "the matrix-free contact solver's setting `{field}` must be at least 1 \
                     ({self:?})"
                )));
            }
        }
        Ok(())
    }
}

/// The work of a solver so far (cumulative over its steps).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MatrixFreeCounts {
    /// Products with D (solves with the factor of K_A).
    pub products: usize,
    /// Newton systems, and their conjugate gradient iterations.
    pub newton: usize,
    pub cg_iterations: usize,
}

pub struct MatrixFreeSolver {
    settings: MatrixFreeSettings,
    /// The multiplier groups, in row order, with δ_j the estimated mean of diag D.
    groups: Vec<Group>,
    /// Each row's (position in the factor's ordering, coefficient) pairs.
    entries: Vec<Vec<(usize, f64)>>,
    /// K_A⁻¹ b of the step in the factor's ordering, and a vector for the products.
    x_b: Vec<f64>,
    y: Vec<f64>,
    counts: MatrixFreeCounts,
}

/// The m-vectors of a step's iteration.
struct Vectors {
    d: Vec<f64>,
    g: Vec<f64>,
    trial: Vec<f64>,
    g_trial: Vec<f64>,
    coords: Vec<Coord>,
}

impl MatrixFreeSolver {
    /// The solver with the default settings; `factor` must have been built with the rows'
    /// dofs ordered last.
    pub fn new(factor: &Factor, rows: &Rows) -> Self {
        Self::build(factor, rows, MatrixFreeSettings::default())
    }

    /// As `new`, with other settings, which are validated first.
    pub fn with_settings(
        factor: &Factor,
        rows: &Rows,
        settings: MatrixFreeSettings,
    ) -> Result<Self> {
        settings.validate()?;
        Ok(Self::build(factor, rows, settings))
    }

    fn build(factor: &Factor, rows: &Rows, settings: MatrixFreeSettings) -> Self {
        let entries = rows
            .rows
            .iter()
            .map(|r| r.entries().map(|(d, c)| (factor.position(d), c)).collect())
            .collect();
        let mut solver = MatrixFreeSolver {
            settings,
            groups: Vec::new(),
            entries,
            x_b: vec![0.0; factor.dim()],
            y: vec![0.0; factor.dim()],
            counts: MatrixFreeCounts::default(),
        };
        let delta = solver.mean_diagonal(factor);
        let diag = vec![delta; rows.len()];
        solver.groups = groups::groups(rows, &diag, settings.dual.dependent_shift);
        solver
    }

    /// The work so far.
    pub fn counts(&self) -> MatrixFreeCounts {
        self.counts
    }

    /// tr(D)/m estimated as the mean of vᵀDv/m over `probes` vectors of ±1 entries (a fixed
    /// pattern: the signs of a multiplicative hash of the row and the probe).
    fn mean_diagonal(&mut self, factor: &Factor) -> f64 {
        let m = self.entries.len();
        let (mut v, mut dv) = (vec![0.0; m], vec![0.0; m]);
        let mut sum = 0.0;
        for probe in 0..self.settings.probes {
            for (i, vi) in v.iter_mut().enumerate() {
                let h = ((i * 4 + probe) as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
                *vi = if h >> 63 == 0 { 1.0 } else { -1.0 };
            }
            self.product(factor, &v, &mut dv);
            sum += groups::dot(&v, &dv);
        }
        (sum / (self.settings.probes * m.max(1)) as f64).max(f64::MIN_POSITIVE)
    }

    /// out = D v = P K_A⁻¹ Pᵀ v (one forward and one backward pass with the factor).
    fn product(&mut self, factor: &Factor, v: &[f64], out: &mut [f64]) {
        self.solve_transpose(factor, v);
        for (row, o) in self.entries.iter().zip(out) {
            *o = gather(row, &self.y);
        }
        self.counts.products += 1;
    }

    /// y = K_A⁻¹ Pᵀ v in the factor's ordering.
    fn solve_transpose(&mut self, factor: &Factor, v: &[f64]) {
        self.y.fill(0.0);
        for (row, &x) in self.entries.iter().zip(v) {
            for &(pos, c) in row {
                self.y[pos] += c * x;
            }
        }
        factor.forward(&mut self.y);
        factor.backward(&mut self.y);
    }

    /// Solves step n as `StepSolver::solve` does: `b` is b_n, `w` receives w_n, `z` the
    /// multipliers (in: the previous step's, the warm start).
    pub fn solve(
        &mut self,
        factor: &Factor,
        rows: &Rows,
        b: &[f64],
        w: &mut [f64],
        z: &mut [f64],
    ) -> StepReport {
        let m = rows.len();
        debug_assert_eq!(z.len(), m);
        // x_b = K_A⁻¹ b, d = P x_b.
        factor.permute(b, &mut self.x_b);
        factor.forward(&mut self.x_b);
        factor.backward(&mut self.x_b);
        let mut v = Vectors {
            d: self.entries.iter().map(|r| gather(r, &self.x_b)).collect(),
            g: vec![0.0; m],
            trial: vec![0.0; m],
            g_trial: vec![0.0; m],
            coords: Vec::with_capacity(m),
        };
        let report = self.iterate(factor, z, &mut v);
        if report.status == StepStatus::Solved {
            // w = K_A⁻¹ (b − Pᵀ z) = x_b − K_A⁻¹ Pᵀ z.
            self.solve_transpose(factor, z);
            for (y, x) in self.y.iter_mut().zip(&self.x_b) {
                *y = x - *y;
            }
            factor.unpermute(&self.y, w);
        }
        report
    }

    /// The iterations from the warm start z (the module doc) until the stopping test of
    /// `dual` holds or the iteration limit is reached.
    fn iterate(&mut self, factor: &Factor, z: &mut [f64], v: &mut Vectors) -> StepReport {
        let settings = self.settings.dual;
        let scale = v.d.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        let tol = settings.tolerance * scale.max(f64::MIN_POSITIVE);
        project(&self.groups, z);
        self.gradient(factor, z, &v.d, &mut v.g);
        let mut iterations = 0;
        loop {
            let res = residual(&self.groups, z, &v.g, settings.rim);
            let status = if res <= tol {
                StepStatus::Solved
            } else if iterations == settings.max_iterations {
                StepStatus::MaxIterations {
                    limit: settings.max_iterations,
                    residual: res,
                    scale,
                }
            } else {
                iterations += 1;
                if !self.newton_point(factor, z, res, scale, tol, v) {
                    self.projected_gradient(factor, z, v);
                }
                z.copy_from_slice(&v.trial);
                v.g.copy_from_slice(&v.g_trial);
                continue;
            };
            return StepReport {
                status,
                iterations,
                residual: res / scale.max(f64::MIN_POSITIVE),
            };
        }
    }

    /// g = D z − d.
    fn gradient(&mut self, factor: &Factor, z: &[f64], d: &[f64], g: &mut [f64]) {
        self.product(factor, z, g);
        for (g, d) in g.iter_mut().zip(d) {
            *g -= d;
        }
    }

    /// The Newton point Π(z₀ + Q x) from z (KKT residual `res`) in `trial`, its gradient in
    /// `g_trial`; true if it lowers q, or at q's rounding level the residual.
    fn newton_point(
        &mut self,
        factor: &Factor,
        z: &[f64],
        res: f64,
        scale: f64,
        tol: f64,
        v: &mut Vectors,
    ) -> bool {
        let eta = self.settings.dual.eta;
        prediction(&self.groups, z, &v.g, eta, &mut v.trial, &mut v.coords);
        // The right side −Qᵀ(D z₀ − d).
        self.gradient(factor, &v.trial, &v.d, &mut v.g_trial);
        let rhs: Vec<f64> = v.coords.iter().map(|q| -q.dot(&v.g_trial)).collect();
        let forcing = (res / scale.max(f64::MIN_POSITIVE)).min(0.5);
        let x = self.cg(factor, &v.coords, &rhs, (forcing * res).max(0.1 * tol));
        for (q, xq) in v.coords.iter().zip(&x) {
            for (i, e) in q.entries() {
                v.trial[i] += e * xq;
            }
        }
        project(&self.groups, &mut v.trial);
        self.gradient(factor, &v.trial, &v.d, &mut v.g_trial);
        let dq = change(z, &v.trial, &v.g, &v.g_trial);
        let noise = rounding(z, &v.trial, &v.g, &v.g_trial);
        dq < -noise
            || (dq <= noise
                && residual(&self.groups, &v.trial, &v.g_trial, self.settings.dual.rim) < res)
    }

    /// x with (QᵀDQ + diag κ) x = rhs to max|residual| ≤ `accuracy` (or after `cg_max`
    /// iterations), by conjugate gradients preconditioned by diag(δ + κ).
    fn cg(&mut self, factor: &Factor, coords: &[Coord], rhs: &[f64], accuracy: f64) -> Vec<f64> {
        let nq = coords.len();
        let m = self.entries.len();
        let mut x = vec![0.0; nq];
        let mut r = rhs.to_vec();
        let delta = self.groups.first().map_or(1.0, |g| g.scale);
        let precondition = |r: &[f64]| -> Vec<f64> {
            coords
                .iter()
                .zip(r)
                .map(|(q, ri)| ri / (delta + q.shift))
                .collect()
        };
        let mut s = precondition(&r);
        let mut p = s.clone();
        let mut rs = groups::dot(&r, &s);
        let (mut full, mut dfull) = (vec![0.0; m], vec![0.0; m]);
        self.counts.newton += 1;
        for _ in 0..self.settings.cg_max {
            if r.iter().fold(0.0f64, |a, x| a.max(x.abs())) <= accuracy {
                break;
            }
            // h = (QᵀDQ + diag κ) p.
            full.fill(0.0);
            for (q, pq) in coords.iter().zip(&p) {
                for (i, e) in q.entries() {
                    full[i] += e * pq;
                }
            }
            self.product(factor, &full, &mut dfull);
            let h: Vec<f64> = coords
                .iter()
                .zip(&p)
                .map(|(q, pq)| q.dot(&dfull) + q.shift * pq)
                .collect();
            let alpha = rs / groups::dot(&p, &h);
            for k in 0..nq {
                x[k] += alpha * p[k];
                r[k] -= alpha * h[k];
            }
            s = precondition(&r);
            let rs_next = groups::dot(&r, &s);
            for k in 0..nq {
                p[k] = s[k] + rs_next / rs * p[k];
            }
            rs = rs_next;
            self.counts.cg_iterations += 1;
        }
        x
    }

    /// The projected gradient step z(β) = Π(z − β g/δ), β = 1 backtracked by Armijo (the
    /// same search as `dual`'s), into `trial` and `g_trial`.
    fn projected_gradient(&mut self, factor: &Factor, z: &[f64], v: &mut Vectors) {
        let mut beta = 1.0;
        loop {
            for grp in &self.groups {
                for i in grp.rows() {
                    v.trial[i] = z[i] - beta * v.g[i] / grp.scale;
                }
            }
            project(&self.groups, &mut v.trial);
            self.gradient(factor, &v.trial, &v.d, &mut v.g_trial);
            let predicted: f64 = (0..z.len()).map(|i| v.g[i] * (z[i] - v.trial[i])).sum();
            let dq = change(z, &v.trial, &v.g, &v.g_trial);
            if -dq >= 1e-4 * predicted || beta < 1e-12 {
                return;
            }
            beta *= backtrack(dq, predicted, false);
        }
    }
}

/// Σ c x_pos over a row's entries.
fn gather(row: &[(usize, f64)], x: &[f64]) -> f64 {
    row.iter().map(|&(pos, c)| c * x[pos]).sum()
}
