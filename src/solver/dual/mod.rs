//! The fast step solver: the problem condensed onto its constraint rows.
//!
//! With P the m×n matrix of the nodal rows (n_iᵀ on Γ3,1; τ_iᵀ on Γ3,2 in 2D, the two unit
//! tangents τ_i1ᵀ, τ_i2ᵀ of node i in 3D), write w_τ,i = (τ_ik·w_i)_k for the tangential
//! velocity of a Γ3,2 node in its tangent frame (one number in 2D, two in 3D). The optimality
//! conditions of the step problem are
//!
//!   K_A w = b − Pᵀ z,   z_i = λ_i ≥ 0, λ_i n_i·w_i = 0, n_i·w_i ≤ 0       (Γ3,1)
//!                       z_i = γ_i ∈ c_i ∂|·|(w_τ,i)                         (Γ3,2)
//!
//! where γ_i is node i's block of multipliers: |γ_i| ≤ c_i, and γ_i = c_i w_τ,i/|w_τ,i| where
//! the node slides (w_τ,i ≠ 0). Eliminating w = K_A⁻¹(b − Pᵀz) leaves the dual
//!
//!   minimize q(z) = ½ zᵀ D z − dᵀ z  over  z ∈ Z,   D = P K_A⁻¹ Pᵀ,  d = P K_A⁻¹ b,
//!   Z = Π_i {λ_i ≥ 0} × Π_i {|γ_i| ≤ c_i}   (|·| Euclidean: an interval in 2D, a disc in 3D),
//!
//! whose gradient is g = D z − d = −P w.
//!
//! The factor of K_A orders the constrained dofs C last (`Factor`): P K_A Pᵀ = L Lᵀ with
//! trailing block L_CC, and P touches only C (E: its C-block, |C|×m). With G = L_CC⁻¹ E:
//! D = GᵀG (dense, once per run: `condense`), and for a step with forward solve L y = b,
//! d = Gᵀ y_C; the multipliers enter only through y_C ← y_C − G z; one backward solve
//! Lᵀ w = y gives w. G itself is not kept: Gᵀ y_C = Eᵀ L_CC⁻ᵀ y_C and G z = L_CC⁻¹ E z are
//! one pass each over L_CC, which the factor holds. So a step costs one solve with the
//! stored factor — the same as a step without contact — plus O(|C|²) for these passes and
//! the small problem below.
//!
//! # The dual solve
//!
//! The multipliers come in groups j — one per contact row, one per friction node — each with
//! its closed convex set Z_j and Euclidean projection Π_j:
//!
//!   Π_j(λ) = max(λ, 0),   Π_j(γ) = γ min(1, c_j/|γ|).
//!
//! z solves the dual iff z = Π(z − g/δ), δ_j > 0 a scale per group (the mean of diag D over
//! its rows), and as well iff z = Π(z − g/(ηδ)) for any η > 0. The method is a semismooth
//! Newton method on the second fixed-point equation with η = `DualSettings::eta` (why 64 and
//! not 1: see there), globalized by descent of q. It is warm started from the previous
//! step's multipliers z_{n−1} or their extrapolation 2z_{n−1} − z_{n−2}, both projected
//! onto Z, whichever has the lower q (`Iteration::start`).
//!
//! Newton step. At v = z − g/(ηδ) each group is
//!  - free (v_j ∈ Z_j; Π' = I): the Newton equations are g_j(z⁺) = 0;
//!  - at zero (contact, v_j < 0; Π' = 0): z⁺_j = 0;
//!  - on the rim (friction, |v_j| > c_j; Π' = ρ(I − v̂v̂ᵀ), ρ = c_j/|v_j|): the equations
//!    split into a radial part v̂·z⁺_j = c_j and a tangential part
//!    T(g_j(z⁺) + κ_j z⁺_j) = 0,  T = I − v̂v̂ᵀ,  κ_j = ηδ_j (|v_j| − c_j)/c_j ≥ 0.
//!    At the solution −g_j = w_τ,j = μ_j γ̂_j and κ_j = μ_j/c_j: the circle's curvature times
//!    the radial multiplier, the second-order term of the constraint |γ_j| ≤ c_j. In 2D
//!    T = 0 and the multiplier is simply fixed at ±c_j.
//!
//! In a step's first iteration, and after a damped Newton point (below), a 3D disc
//! multiplier that lies on its rim stays on it where v_j falls inside the disc, with
//! κ_j = max(μ_j, 0)/c_j (`DualSettings::held_rims`): the warm start's gradient is the new
//! loads', and at nodes that go on sliding it can point inward.
//!
//! With z⁺ = z₀ + Q x — z₀ holds the fixed parts (c_j v̂_j, zeros), the columns of Q are the
//! free rows' unit vectors and the rims' unit tangents — the step is one SPD system
//!
//!   (QᵀDQ + diag κ) x = −Qᵀ(D z₀ − d),
//!
//! solved by a dense Cholesky factorization — in 3D, where this is the bottleneck, by its
//! Woodbury form through B = D⁻¹ when that is cheaper (`newton_step`); z⁺ is projected
//! onto Z. In 2D this is the
//! primal-dual active set step (Hintermüller, Ito, Kunisch 2002): once the sets are right the
//! answer is exact up to rounding. In 3D it converges quadratically near the solution.
//!
//! Globalization. The Newton point is taken if it lowers q, else the damped point
//! Π(z + α(z⁺ − z)) if that lowers q by at least `damped_decrease` of its first-order
//! prediction, α backtracking by quadratic interpolation (`backtrack`) down to
//! `min_damping` (`DualSettings`); after a damped point the next prediction takes η = 1
//! and holds the rims (`far_after_damped`). Otherwise (a plain active set iteration can
//! cycle: D is not an M-matrix) the iteration takes a projected Newton step (Bertsekas
//! 1982), which always descends. A group is binding when it lies within ε of the boundary
//! in the direction the gradient pushes it (z_j − ε ĝ_j ∉ int Z_j, ε the length of the
//! projected gradient step); it moves along −g_j/δ_j, except a binding
//! disc multiplier pushed outward (μ_j = −g_j·ẑ_j > 0), which moves radially onto the rim
//! and along the rim as a Newton coordinate (tangent t̂ ⊥ ẑ, shift κ_j = μ_j/c_j as above).
//! The other (free) rows F and these tangents take the Newton step of the face,
//! (QᵀDQ + diag κ) x = −Qᵀg; then an Armijo search along the projection arc
//! z(α) = Π(z + α p), backtracking by quadratic interpolation. So the method converges
//! from any start; in 2D the fallback is Bertsekas' method for bound constraints as it
//! stands. Near the solution the decrease of q sinks below its rounding level (a disc
//! multiplier c v̂ has the norm c only to a few ulps, and g is large along it); there the
//! Newton point is taken when it lowers the residual below.
//!
//! Dependent rows. Where Γ3,1 meets Γ3,2 at a corner, a node carries a contact row along
//! its normal n_i and friction rows whose tangents span n_i (a 90° corner: τ_i = ±n_i), so
//! P has dependent rows and D is singular: w is unique (K_A is SPD), the split of the force
//! Pᵀz between λ_i and γ_i is not. The Newton matrices of such nodes' groups get the shift
//! ρ δ_j (ρ = `DualSettings::dependent_shift`) on their coordinates: (QᵀDQ + diag κ + ρ diag δ) x = −Qᵀg
//! is solvable whatever the sets are, and since Qᵀg lies in the range of QᵀDQ its solution
//! differs from an exact Newton step only by O(ρ) along the near-null directions: a
//! Levenberg–Marquardt step, which contracts the error in the range by ρδ/(ρδ + σ) per
//! iteration (σ the curvature there: σ/δ ≈ 1 − cos 0.1° = 1.5e-6 at an 89.9° corner, so
//! 7e-3 per iteration) and leaves the non-unique direction alone. ρ is not smaller because
//! the rounding of g along the null direction is amplified by 1/ρ in x: at ρ = 1e-10 those
//! steps wandered by 1e-6 |z| and the 3D edge case (tests/solutions/corner.rs) stalled at 5× the
//! tolerance. The stopping test below is the unregularized one, so the iteration still
//! ends at the exact KKT point; only which of the equivalent multipliers it reports depends
//! on the path. Nodes whose rows are far from dependent (the paper's x = 1, n_i ⊥ τ_i) get
//! no shift, so those runs are unchanged. (A pivoted factorization would also solve the
//! singular systems, but nearly dependent rows at 89.9° would still leave pivots at the
//! rounding level whose sign decides the outcome: the same mesh failed as ASCII and ran as
//! binary.)
//!
//! Stopping test: the part of g not balanced by the normal cone of Z at z, per group — for a
//! contact row |g| if λ > 0 and max(0, −g) if λ = 0 (n·w ≤ 0); for a friction node |g_j|
//! inside the disc, and on its rim |T g_j| + max(0, g_j·γ̂_j) (there −g_j = w_τ,j must be a
//! nonnegative multiple of γ_j: the node slides along its friction force, or sticks) — at
//! most `DualSettings::tolerance` · max|d|, in units of the velocities P w.

mod delassus;
pub(super) mod groups;
pub(super) mod iteration;
pub(super) mod newton;
mod settings;
#[cfg(test)]
mod tests;

use super::{gather, scatter, Abandon, Factor, Rows, StepReport, StepStatus};
use crate::threads::team::{blocks, Team};
use crate::Result;
use delassus::Delassus;
use faer::linalg::matmul::triangular::{self, BlockStructure};
use faer::linalg::solvers::DenseSolveCore;
use faer::linalg::triangular_inverse::invert_lower_triangular;
use faer::linalg::triangular_solve::solve_lower_triangular_in_place;
use faer::{Accum, Mat, Par, Side};
use groups::Group;
use iteration::Work;
pub(super) use settings::in_ranges;
pub use settings::{DualSettings, NewtonForm};

/// How many Newton systems a solver solved in each form (cumulative over its steps).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct NewtonCounts {
    pub direct: usize,
    pub woodbury: usize,
    /// Refinement passes of Woodbury solves.
    pub refinements: usize,
    /// Woodbury solves not accurate enough after refinement, solved directly instead.
    pub fallbacks: usize,
}

pub struct DualSolver {
    /// P on C (`Rows::in_factor`): E, the rows' C-block.
    p: Vec<Vec<(usize, f64)>>,
    /// D = GᵀG = P K_A⁻¹ Pᵀ (m×m).
    d: Delassus,
    /// B = D⁻¹ for the Woodbury form of the Newton steps, when it is used: D definite (no
    /// dependent rows) and the form allowed.
    inverse: Option<Mat<f64>>,
    settings: DualSettings,
    /// The multiplier groups, in row order; fixed per run.
    groups: Vec<Group>,
    work: Box<Work>,
    /// The step's forward-solved right side, in the factor's ordering, and a vector on C.
    y: Vec<f64>,
    y_c: Vec<f64>,
    /// A request to give the step up (`solver::abandon`); none by default.
    abandon: Abandon,
}

impl DualSolver {
    /// The solver with the default settings; `factor` must have been built with the rows'
    /// dofs ordered last.
    pub fn new(factor: &Factor, rows: &Rows) -> Self {
        Self::build(factor, rows, DualSettings::default())
    }

    /// As `new`, with other settings, which are validated first.
    pub fn with_settings(factor: &Factor, rows: &Rows, settings: DualSettings) -> Result<Self> {
        settings.validate()?;
        Ok(Self::build(factor, rows, settings))
    }

    fn build(factor: &Factor, rows: &Rows, settings: DualSettings) -> Self {
        let p = rows.in_factor(factor, factor.dim() - factor.last());
        let sel = selection(factor.last(), &p);
        let d = condense(factor, &p, sel.as_deref());
        let diag: Vec<f64> = (0..rows.len()).map(|i| d[(i, i)]).collect();
        let groups = groups::groups(rows, &diag, settings.dependent_shift);
        let m = rows.len();
        let work = Box::new(Work::new(m, groups.len(), &settings));
        // B = D⁻¹ (m³ flops once) where the Woodbury form may be used: 3D, where the rim
        // tangents of sliding nodes make U small, and D definite. In 2D the direct form stays:
        // its systems are at most one boundary line's rows.
        let woodbury = match settings.newton_form {
            NewtonForm::Direct => false,
            NewtonForm::Cheaper => rows.block == 2,
            NewtonForm::Woodbury => true,
        };
        let inverse = (woodbury && m > 0 && groups.iter().all(|g| g.shift == 0.0))
            .then(|| inverse(factor, sel.as_deref(), &d))
            .flatten();
        DualSolver {
            p,
            d: Delassus {
                mat: d,
                team: Team::default(),
                split_rows: settings.split_rows,
            },
            inverse,
            settings,
            groups,
            work,
            y: vec![0.0; factor.dim()],
            y_c: vec![0.0; factor.last()],
            abandon: Abandon::default(),
        }
    }

    /// Gives up a step when `abandon` is requested (`solver::abandon`).
    pub fn abandon_on(&mut self, abandon: Abandon) {
        self.abandon = abandon;
    }

    /// The Newton systems solved so far, by form.
    pub fn newton_counts(&self) -> NewtonCounts {
        self.work.newton.counts
    }

    pub fn solve(
        &mut self,
        factor: &Factor,
        rows: &Rows,
        b: &[f64],
        w: &mut [f64],
        z: &mut [f64],
        before: Option<&[f64]>,
    ) -> StepReport {
        debug_assert_eq!(z.len(), rows.len());
        let first = factor.dim() - factor.last();
        // Forward solve L y = b; d = Gᵀ y_C = Eᵀ L_CC⁻ᵀ y_C.
        factor.permute(b, &mut self.y);
        factor.forward(&mut self.y);
        self.y_c.copy_from_slice(&self.y[first..]);
        factor.trailing_backward(&mut self.y_c);
        for (row, d) in self.p.iter().zip(&mut self.work.d) {
            *d = gather(row, &self.y_c);
        }
        let report = self.dual_solve(z, before);
        if report.status != StepStatus::Solved {
            return report;
        }
        // y_C ← y_C − G z = y_C − L_CC⁻¹ E z, then the backward solve Lᵀ w = y.
        scatter(&self.p, z, &mut self.y_c);
        factor.trailing_forward(&mut self.y_c);
        for (y, t) in self.y[first..].iter_mut().zip(&self.y_c) {
            *y -= t;
        }
        factor.backward(&mut self.y);
        factor.unpermute(&self.y, w);
        report
    }
}

/// D = GᵀG = Eᵀ L_CC⁻ᵀ L_CC⁻¹ E (E the rows' C-block in the factor's ordering), on all
/// the process's threads: faer's parallel products and solves with more than one column
/// give the same bits for every thread count; with one column they split their sums by it
/// (`threads`), so a single row is condensed on one thread. Where E selects (`selection`)
/// by two triangles (`condense_selected`), else by a solve and a product (`condense_solved`).
fn condense(factor: &Factor, p: &[Vec<(usize, f64)>], sel: Option<&[(usize, f64)]>) -> Mat<f64> {
    let par = if p.len() >= 2 {
        crate::threads::par()
    } else {
        Par::Seq
    };
    match sel {
        Some(sel) => condense_selected(factor, sel, par),
        None => condense_solved(factor, p, par),
    }
}

/// `condense` where E = Π diag(s) selects (`selection`): D = Eᵀ L_CC⁻ᵀ L_CC⁻¹ E, a product
/// of two triangles. c³/3 flops for the inverse and c³/3 for the product, against c³ for
/// the solve with E and 2c³ for the full product GᵀG (the plate 0.03's setup 6.6 → 5.0 s:
/// docs/performance.md).
fn condense_selected(factor: &Factor, sel: &[(usize, f64)], par: Par) -> Mat<f64> {
    let c = factor.last();
    let l_cc = factor.trailing_block();
    let mut linv = Mat::<f64>::zeros(c, c);
    invert_lower_triangular(linv.as_mut(), l_cc.as_ref(), par);
    drop(l_cc);
    // L_CC⁻ᵀ L_CC⁻¹, its lower triangle.
    let mut inner = Mat::<f64>::zeros(c, c);
    triangular::matmul(
        inner.as_mut(),
        BlockStructure::TriangularLower,
        Accum::Replace,
        linv.transpose(),
        BlockStructure::TriangularUpper,
        linv.as_ref(),
        BlockStructure::TriangularLower,
        1.0,
        par,
    );
    drop(linv);
    selected(&inner, sel, |sa, sb| sa * sb)
}

/// `condense` for any E: G = L_CC⁻¹ E by a triangular solve with the m columns of E,
/// D = GᵀG.
fn condense_solved(factor: &Factor, p: &[Vec<(usize, f64)>], par: Par) -> Mat<f64> {
    let (c, m) = (factor.last(), p.len());
    let mut g = Mat::<f64>::zeros(c, m);
    for (r, row) in p.iter().enumerate() {
        for &(i, coef) in row {
            g[(i, r)] = coef;
        }
    }
    let l_cc = factor.trailing_block();
    solve_lower_triangular_in_place(l_cc.as_ref(), g.as_mut(), par);
    drop(l_cc);
    let mut d = Mat::<f64>::zeros(m, m);
    faer::linalg::matmul::matmul(
        d.as_mut(),
        Accum::Replace,
        g.transpose(),
        g.as_ref(),
        1.0,
        par,
    );
    d
}

/// B = D⁻¹ for the Woodbury form, None where D is not definite. Where E selects
/// (`selection`), D⁻¹ = E⁻¹ L_CC L_CCᵀ E⁻ᵀ: the Schur complement of K_A on C, a product
/// of two triangles (c³/3 flops, exact to rounding, where a Cholesky factorization and
/// inverse of D cost m³ and carry D's conditioning); else from D's Cholesky factor.
fn inverse(factor: &Factor, sel: Option<&[(usize, f64)]>, d: &Mat<f64>) -> Option<Mat<f64>> {
    let Some(sel) = sel else {
        return d.llt(Side::Lower).ok().map(|llt| llt.inverse());
    };
    let l_cc = factor.trailing_block();
    let mut schur = Mat::<f64>::zeros(l_cc.nrows(), l_cc.ncols());
    triangular::matmul(
        schur.as_mut(),
        BlockStructure::TriangularLower,
        Accum::Replace,
        l_cc.as_ref(),
        BlockStructure::TriangularLower,
        l_cc.transpose(),
        BlockStructure::TriangularUpper,
        1.0,
        crate::threads::par(),
    );
    drop(l_cc);
    Some(selected(&schur, sel, |sa, sb| 1.0 / (sa * sb)))
}

/// Where every row of P on C (`p`, C's c dofs) is one dof, a dof no other row has, and
/// every dof of C has a row (c = m): each row's (position in C, coefficient). E is then a
/// scaled permutation. So it is on a flat boundary along the coordinate axes, whose normal
/// and tangents (`fem::tangents`) are coordinate directions.
fn selection(c: usize, p: &[Vec<(usize, f64)>]) -> Option<Vec<(usize, f64)>> {
    if c != p.len() {
        return None;
    }
    let mut seen = vec![false; c];
    p.iter()
        .map(|row| match row[..] {
            [(i, coef)] => (!std::mem::replace(&mut seen[i], true)).then_some((i, coef)),
            _ => None,
        })
        .collect()
}

/// The symmetric m×m matrix with entries f(s_a, s_b) M_{p_a p_b} for the rows' (p, s) in
/// `sel`, from M's lower triangle.
fn selected(inner: &Mat<f64>, sel: &[(usize, f64)], f: impl Fn(f64, f64) -> f64) -> Mat<f64> {
    Mat::from_fn(sel.len(), sel.len(), |a, b| {
        let ((pa, sa), (pb, sb)) = (sel[a], sel[b]);
        f(sa, sb) * inner[(pa.max(pb), pa.min(pb))]
    })
}
