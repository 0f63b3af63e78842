//! The per-step problem: (3.1) at step n is the convex program (DESIGN.md)
//!
//!   minimize   ½ wᵀ K_A w − b_nᵀ w + Σ_{i∈Γ3,2} c_i |τ_i·w_i|
//!   subject to n_i·w_i ≤ 0   at every node i of Γ3,1,
//!   b_n = f_n − K_B u_n − K_R m_n − g_F.
//!
//! K_A never changes, so it is factored once per run (`Factor`). Which solver a run uses is
//! decided by its effects (Remark 2.5): no constraint rows → `Linear` (one solve with the
//! stored factor per step, no optimization solver built); otherwise the condensed dual
//! active-set method (`dual`, default) or clarabel on the whole problem (`conic`, the
//! cross-check).

pub mod conic;
pub mod dual;
pub mod factor;

use crate::fem::NodalRow;
use crate::Result;
pub use factor::Factor;

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
        debug_assert!(block >= 1 && friction.len() % block == 0);
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

    /// The number of friction nodes (blocks).
    pub fn n_friction_nodes(&self) -> usize {
        (self.rows.len() - self.n_contact) / self.block.max(1)
    }

    /// The row indices of friction block j.
    pub fn friction_block(&self, j: usize) -> std::ops::Range<usize> {
        let start = self.n_contact + j * self.block;
        start..start + self.block
    }

    /// Every dof of every constrained node, sorted: the block C ordered last in the factor.
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

    /// Bounds of the multiplier of row i: [0, ∞) for contact, [−c_i, c_i] for friction
    /// (per component; in 3D the binding constraint is the disc of the row's block).
    pub fn bounds(&self, i: usize) -> (f64, f64) {
        if i < self.n_contact {
            (0.0, f64::INFINITY)
        } else {
            (-self.rows[i].bound, self.rows[i].bound)
        }
    }
}

/// What a step's solve did.
#[derive(Clone, Copy, Debug, Default)]
pub struct StepReport {
    /// Active-set iterations (dual) or interior-point iterations (clarabel); 0 for linear.
    pub iterations: usize,
}

/// The solver of a run, picked by its effects.
pub enum StepSolver {
    /// w = K_A⁻¹ b: no contact and no friction.
    Linear,
    /// Condensed onto the constrained boundary dofs; see `dual`.
    Dual(dual::DualSolver),
    /// The whole problem in clarabel; see `conic`.
    Conic(Box<conic::ConicSolver>),
}

impl StepSolver {
    /// The name recorded in summary.json.
    pub fn name(&self) -> &'static str {
        match self {
            StepSolver::Linear => "linear (stored Cholesky factor of K_A, one solve per step)",
            StepSolver::Dual(_) => {
                "dual active set (condensed on Γ3 rows, stored Cholesky factor of K_A)"
            }
            StepSolver::Conic(_) => "clarabel (interior point on the whole step problem)",
        }
    }

    /// Solves step n: `b` is b_n, `w` receives w_n, `z` the multipliers (λ on contact rows,
    /// γ on friction rows; in: the previous step's, used as a warm start).
    pub fn solve(
        &mut self,
        factor: &Factor,
        rows: &Rows,
        b: &[f64],
        w: &mut [f64],
        z: &mut [f64],
    ) -> Result<StepReport> {
        match self {
            StepSolver::Linear => {
                w.copy_from_slice(b);
                factor.solve(w);
                Ok(StepReport::default())
            }
            StepSolver::Dual(d) => d.solve(factor, rows, b, w, z),
            StepSolver::Conic(c) => c.solve(rows, b, w, z),
        }
    }
}

/// KKT residual of a step solution, relative: the largest of contact violation n·w > 0,
/// complementarity |λ n·w|, multiplier bound violations, and friction consistency
/// (|γ| < c ⇒ τ·w = 0; τ·w ≠ 0 ⇒ γ = c sign(τ·w)), each scaled to be dimensionless.
pub fn kkt_residual(rows: &Rows, w: &[f64], z: &[f64], w_scale: f64, z_scale: f64) -> f64 {
    let mut r: f64 = 0.0;
    let ws = w_scale.max(f64::MIN_POSITIVE);
    let zs = z_scale.max(f64::MIN_POSITIVE);
    for (i, row) in rows.rows.iter().enumerate() {
        let pw = row.apply(w);
        let (lo, hi) = rows.bounds(i);
        r = r.max((lo - z[i]).max(z[i] - hi).max(0.0) / zs);
        if i < rows.n_contact {
            r = r.max(pw.max(0.0) / ws);
            r = r.max((z[i] * pw).abs() / (zs * ws));
        } else {
            // γ_i − c sign(τ·w) = 0 where sliding; the distance to the bound times |τ·w|.
            let slack = if pw > 0.0 { hi - z[i] } else { z[i] - lo };
            r = r.max((slack.abs() * pw.abs()) / (zs * ws));
        }
    }
    r
}
