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
//! trailing block L_CC, and P touches only C (E: its C-block, |C|×m). With G = L_CC⁻¹ E
//! (dense, once per run): D = GᵀG, and for a step with forward solve L y = b,
//! d = Gᵀ y_C; the multipliers enter only through y_C ← y_C − G z; one backward solve
//! Lᵀ w = y gives w. So a step costs one solve with the stored factor — the same as a step
//! without contact — plus O(|C|·m) for G and the small problem below.
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
//! Newton method on the second fixed-point equation with η = `ETA` (why 64 and not 1: see
//! there), warm started from the previous step's multipliers, globalized by descent of q.
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
//! Π(z + α(z⁺ − z)), α = ½ or ¼, if that does. Otherwise (a plain active set iteration can
//! cycle: D is not an M-matrix) the iteration takes a projected Newton step (Bertsekas
//! 1982), which always descends. A group is binding when it lies within ε of the boundary in
//! the direction the gradient pushes it (z_j − ε ĝ_j ∉ int Z_j, ε the length of the
//! projected gradient step); it moves along −g_j/δ_j, except a binding disc multiplier
//! pushed outward (μ_j = −g_j·ẑ_j > 0), which moves radially onto the rim and along the rim
//! as a Newton coordinate (tangent t̂ ⊥ ẑ, shift κ_j = μ_j/c_j as above). The other (free)
//! rows F and these tangents take the Newton step of the face, (QᵀDQ + diag κ) x = −Qᵀg;
//! then an Armijo search along the projection arc z(α) = Π(z + α p), backtracking by
//! quadratic interpolation (`backtrack`). So the method converges
//! from any start; in 2D the fallback is Bertsekas' method for bound constraints as it
//! stands. Near the solution the decrease of q sinks below its rounding level (a disc
//! multiplier c v̂ has the norm c only to a few ulps, and g is large along it); there the
//! Newton point is taken when it lowers the residual below.
//!
//! Dependent rows. Where Γ3,1 meets Γ3,2 at a corner, a node carries a contact row along
//! its normal n_i and friction rows whose tangents span n_i (a 90° corner: τ_i = ±n_i), so
//! P has dependent rows and D is singular: w is unique (K_A is SPD), the split of the force
//! Pᵀz between λ_i and γ_i is not. The Newton matrices of such nodes' groups get the shift
//! ρ δ_j (ρ = `DEPENDENT_SHIFT`) on their coordinates: (QᵀDQ + diag κ + ρ diag δ) x = −Qᵀg
//! is solvable whatever the sets are, and since Qᵀg lies in the range of QᵀDQ its solution
//! differs from an exact Newton step only by O(ρ) along the near-null directions: a
//! Levenberg–Marquardt step, which contracts the error in the range by ρδ/(ρδ + σ) per
//! iteration (σ the curvature there: σ/δ ≈ 1 − cos 0.1° = 1.5e-6 at an 89.9° corner, so
//! 7e-3 per iteration) and leaves the non-unique direction alone. ρ is not smaller because
//! the rounding of g along the null direction is amplified by 1/ρ in x: at ρ = 1e-10 those
//! steps wandered by 1e-6 |z| and the 3D edge case (tests/corner.rs) stalled at 5× the
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
//! most TOLERANCE · max|d|, in units of the velocities P w.

use super::pair::Pair;
use super::{Factor, Rows, StepReport};
use crate::{Error, Result};
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt;
use faer::linalg::solvers::DenseSolveCore;
use faer::linalg::triangular_solve::solve_lower_triangular_in_place;
use faer::{Accum, Mat, MatMut, Par, Side};
use std::ops::Range;

/// Relative tolerance of the dual optimality conditions (in units of the velocities P w).
pub const TOLERANCE: f64 = 1e-12;
/// A step's iterations at most. Thin plates take many (flat tetrahedra make D
/// ill-conditioned): slabs 1/500 and 1/1000 of their width thick need up to 776 in a step
/// (`WIDEN`), and converge to the same multipliers whatever the limit; reaching it is a
/// failed solve (exit 1), so the limit only bounds how long a failing step takes.
const MAX_ITERATIONS: usize = 2000;
/// A projected Newton step shorter than this also tries the projected gradient step.
const PG_SWITCH: f64 = 1e-3;
/// The backtracking of the Armijo searches interpolates (`backtrack`) in the first this many
/// iterations of a step and halves after them. Interpolation lands near the minimizer of q
/// along the arc, and on the thin slab's ill-conditioned D (tests/robustness.rs) such steps
/// zigzag at the edge of the binding set as exact line searches do: interpolating
/// throughout stalled it (residual 4e-3 after 500 iterations), and so did halving only
/// after 50 (the iterate was already caught), while after 10, 20 or 30 it converged. The
/// 3D block's steps take at most 35 iterations and mostly far fewer.
const INTERPOLATED: usize = 20;
/// After a projected Newton step shorter than `PG_SWITCH`, the next one takes a binding set
/// this many times wider (ε ← WIDEN·ε, up to `MAX_WIDEN`, back to 1 after a longer step or
/// an accepted Newton step). A short step means that free groups near the boundary left Z
/// at once along the face's Newton direction; with ε the length of the projected gradient
/// step alone (Bertsekas' choice), the thin slabs' steps zigzagged at α ≈ 1e-4 for hundreds
/// of iterations. Measured on slabs of thickness t (meshes/3d/slab.geo, n = 16, the paper's
/// scene over 32 and 64 steps), the most iterations of a step: t = 0.012 300 → 202 and
/// 261 → 171, t = 0.008 482 → 190 and 451 → 271; at t = 0.004 and 0.002 the runs failed at
/// the old limit of 500 (without a limit two of them needed 2 811 and 2 345) and now take
/// 229–776; u_N is the same to 1e-13. A factor of 10 did about as well (at most 1 513).
/// Runs whose projected Newton steps are never that short are unchanged bit for bit (the
/// paper's scenes, the bracket, the plate with a hole, the block, the slabs t ≥ 0.04).
const WIDEN: f64 = 3.0;
const MAX_WIDEN: f64 = 1e8;
/// η: the semismooth Newton step's fixed-point map is z = Π(z − g/(ηδ)) (module doc).
/// Which groups the step takes as free, at zero or on the rim depends on η: with η large a
/// group at the boundary of Z_j leaves it in the step's prediction v = z − g/(ηδ) only if
/// its gradient pulls it inward, and a free group is predicted outside Z_j only when it is
/// close to the boundary. With η = 1 the prediction reached far from z: in the loading steps
/// of the 3D block (gmsh's unstructured tetrahedra, 728 friction nodes, of which ~450 stick
/// at the solution) it put all 728 on their rims iteration after iteration, the Newton
/// points were rejected and each iteration paid a second factorization for the projected
/// Newton step (159 such fallbacks; up to 37 iterations in a step). With η large the
/// prediction follows the iterate, and on a rim the shift κ = ηδ(|v| − c)/c tends to μ/c,
/// its value at the solution. Measured (iterations over the run, projected Newton
/// fallbacks): that block, 100 steps, η = 1: 728 and 159; 4: 658 and 23; 16: 621 and 0;
/// 64: 578 and 0; 256 and 4096: 583 and 0 (wall 21.3 → 15.0 s); the paper scene at 1/128:
/// 330 and 36 → 259 and 0. The answer does not depend on η (the same fixed point; u_N within
/// 1.5e-15).
///
/// After a rejected Newton point the next iteration predicts with η = 1: on the thin slabs
/// (meshes/3d/slab.geo, D ill-conditioned, most iterations are projected Newton steps) η =
/// 64 throughout raised the most iterations of a step from 792 to 1 608 (t = 0.002, 64
/// steps; the limit is `MAX_ITERATIONS`), where the far prediction after a rejection keeps
/// them at 414 (and 912 against 928 over 32 steps; t = 0.004: 407 and 417 against 871 and
/// 228). Runs whose Newton points are accepted, like the block's, are unchanged by it.
const ETA: f64 = 64.0;
/// The shortest damped Newton step tried before the projected Newton step.
const MIN_DAMPING: f64 = 0.25;
/// |γ_j| ≥ RIM · c_j counts as on the rim: a projected disc multiplier c v̂ has norm c only
/// up to a few roundings.
const RIM: f64 = 1.0 - 8.0 * f64::EPSILON;
/// ρ: the relative Newton shift of the groups at nodes with dependent rows (see the module
/// doc): far above the rounding level of the factorizations and of g, far below the
/// curvature of independent rows.
const DEPENDENT_SHIFT: f64 = 1e-8;

/// The set Z_j of a group of multipliers.
#[derive(Clone, Copy, Debug)]
enum Set {
    /// λ ≥ 0: a contact row.
    HalfLine,
    /// |γ| ≤ c: a friction node's block (an interval in 2D, a disc in 3D).
    Ball(f64),
}

/// One group of multipliers: a contact row or a friction node's block of rows.
#[derive(Clone, Copy, Debug)]
struct Group {
    start: usize,
    len: usize,
    set: Set,
    /// δ_j: the mean of diag(D) over the group's rows.
    scale: f64,
    /// The Newton shift ρ δ_j of a group at a node with dependent rows, else 0.
    shift: f64,
}

fn norm(v: &[f64]) -> f64 {
    v.iter().fold(0.0f64, |a, x| a.hypot(*x))
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(a, b)| a * b).sum()
}

impl Group {
    fn rows(&self) -> Range<usize> {
        self.start..self.start + self.len
    }

    /// Projects v (the group's entries) onto Z_j in place. Returns None if v was in Z_j,
    /// otherwise Some(ρ): 0 for a contact row set to 0, c/|v| for a friction block scaled
    /// onto the rim.
    fn project(&self, v: &mut [f64]) -> Option<f64> {
        match self.set {
            Set::HalfLine => (v[0] < 0.0).then(|| {
                v[0] = 0.0;
                0.0
            }),
            Set::Ball(c) => {
                let nv = norm(v);
                (nv > c).then(|| {
                    // v/|v| first: exactly ±1 in 2D, so the 2D multiplier is exactly ±c.
                    for x in v.iter_mut() {
                        *x = *x / nv * c;
                    }
                    c / nv
                })
            }
        }
    }

    /// True when v lies on the boundary of Z_j or outside.
    fn not_interior(&self, v: &[f64]) -> bool {
        match self.set {
            Set::HalfLine => v[0] <= 0.0,
            Set::Ball(c) => norm(v) >= c,
        }
    }

    /// The unit tangent t̂ ⊥ n of a disc block (the rim's direction at n ≠ 0) as a Newton
    /// coordinate with diagonal shift κ; None for 1-row groups (their rim is two points).
    fn tangent(&self, n: &[f64], kappa: f64) -> Option<Coord> {
        (self.len == 2).then(|| {
            let nn = norm(n);
            Coord {
                start: self.start,
                len: 2,
                dir: [-n[1] / nn, n[0] / nn],
                shift: kappa + self.shift,
            }
        })
    }

    /// The group's rows as free Newton coordinates.
    fn free(&self) -> impl Iterator<Item = Coord> + '_ {
        self.rows().map(|i| Coord {
            start: i,
            len: 1,
            dir: [1.0, 0.0],
            shift: self.shift,
        })
    }

    /// The group's part of the optimality residual (see the module doc); z in Z_j.
    fn residual(&self, z: &[f64], g: &[f64]) -> f64 {
        match self.set {
            Set::HalfLine if z[0] > 0.0 => g[0].abs(),
            Set::HalfLine => (-g[0]).max(0.0),
            Set::Ball(c) => {
                let nz = norm(z);
                if nz < RIM * c {
                    norm(g)
                } else if nz == 0.0 {
                    0.0 // c = 0: Z_j = {0}, every g is balanced
                } else {
                    // g·γ̂ and |T g| = |g − (g·γ̂) γ̂|, computed without cancellation.
                    let gn = dot(g, z) / nz;
                    let tangential = g
                        .iter()
                        .zip(z)
                        .fold(0.0f64, |a, (g, z)| a.hypot(g - gn * z / nz));
                    tangential + gn.max(0.0)
                }
            }
        }
    }
}

/// A column of Q in the Newton systems: a unit vector in the rows of one group (a free
/// multiplier, or the tangent of a disc multiplier on its rim) and its diagonal shift κ.
#[derive(Clone, Copy, Debug)]
struct Coord {
    start: usize,
    len: usize,
    dir: [f64; 2],
    shift: f64,
}

impl Coord {
    fn entries(&self) -> impl Iterator<Item = (usize, f64)> + '_ {
        (self.start..self.start + self.len).zip(self.dir.iter().copied())
    }

    /// qᵀ v.
    fn dot(&self, v: &[f64]) -> f64 {
        self.entries().map(|(i, x)| x * v[i]).sum()
    }
}

/// Vectors of a solve, kept between steps so that the iterations do not allocate them.
struct Work {
    /// d = P K_A⁻¹ b.
    d: Vec<f64>,
    /// g = D z − d at the iterate, and at the trial point.
    grad: Vec<f64>,
    trial: Vec<f64>,
    grad_trial: Vec<f64>,
    /// The projected Newton direction.
    p: Vec<f64>,
    /// The projected gradient trial point and its gradient.
    alt: Vec<f64>,
    grad_alt: Vec<f64>,
    coords: Vec<Coord>,
    /// Per group: binding (moving along −g/δ) in the projected Newton step.
    binding: Vec<bool>,
    /// z_u = B d, the unconstrained minimizer of q, when B = D⁻¹ is kept.
    z_u: Vec<f64>,
    /// What the Newton steps need besides D: see `newton_step`.
    newton: Scratch,
}

/// The buffers of `newton_step`, and its counts.
struct Scratch {
    /// The columns of U (the Woodbury form's coordinates).
    u: Vec<Coord>,
    /// A Newton point, and the gradient there.
    point: Vec<f64>,
    grad: Vec<f64>,
    /// m-vectors of the Woodbury form: its right side s and B-products.
    sv: Vec<f64>,
    bv: Vec<f64>,
    /// The Newton matrix, and the step's last factorization of one. Both buffers are kept
    /// across iterations, so the iterations allocate no matrix (at nq = 1350 each is
    /// 14.6 MB; fresh ones cost the 3D block's run 4% of its samples in zeroing pages).
    h: Mat<f64>,
    factor: NewtonFactor,
    /// Building a Newton matrix, split over two threads where that pays.
    gram_pair: Pair,
    counts: NewtonCounts,
}

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

/// Which matrix a cached factor belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Form {
    /// H = QᵀDQ + diag κ.
    Direct,
    /// H_U = UᵀBU + diag(0 on N, 1/κ on R).
    Woodbury,
}

/// A Cholesky factor of a Newton matrix, its form and the coordinates it was built from.
struct NewtonFactor {
    /// L in the lower triangle (the upper one holds what the matrix had there).
    l: Mat<f64>,
    /// The form of the matrix factored in `l`; None while `l` holds no valid factor.
    form: Option<Form>,
    coords: Vec<Coord>,
}

/// Which form the Newton systems are solved in (see `newton_step`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NewtonForm {
    /// In 3D, whichever form the flop estimate finds cheaper, iteration by iteration; in 2D
    /// the direct form (the default).
    Cheaper,
    /// Always the direct form.
    Direct,
    /// The Woodbury form whenever B exists (tests).
    Woodbury,
}

pub struct DualSolver {
    /// G = L_CC⁻¹ E (|C|×m).
    g: Mat<f64>,
    /// The passes over G (d = Gᵀ y_C and y_C − G z: 27 MB each on the 3D block at h = 1/24),
    /// split over two threads where that pays.
    g_pair: Pair,
    /// D = GᵀG = P K_A⁻¹ Pᵀ (m×m).
    d: Delassus,
    /// B = D⁻¹ for the Woodbury form of the Newton steps, when it is used: D definite (no
    /// dependent rows) and the form allowed.
    inverse: Option<Mat<f64>>,
    form: NewtonForm,
    /// The multiplier groups, in row order; fixed per run.
    groups: Vec<Group>,
    work: Box<Work>,
    /// The step's forward-solved right side, in the factor's ordering.
    y: Vec<f64>,
}

impl DualSolver {
    /// `factor` must have been built with the rows' dofs ordered last.
    pub fn new(factor: &Factor, rows: &Rows) -> Self {
        Self::with_form(factor, rows, NewtonForm::Cheaper)
    }

    /// As `new`, with the form of the Newton systems chosen.
    pub fn with_form(factor: &Factor, rows: &Rows, form: NewtonForm) -> Self {
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
        debug_assert!(rows.block <= 2, "friction blocks span a tangent plane");
        let contact = (0..rows.n_contact).map(|i| (i..i + 1, Set::HalfLine));
        let dependent = rows.dependent_nodes();
        let friction = (0..rows.n_friction_nodes()).map(|j| {
            let r = rows.friction_block(j);
            let c = rows.rows[r.start].bound;
            (r, Set::Ball(c))
        });
        let groups = contact
            .chain(friction)
            .map(|(r, set)| {
                let scale = r.clone().map(|i| d[(i, i)]).sum::<f64>() / r.len() as f64;
                let at_dependent = dependent.contains(&rows.rows[r.start].node);
                Group {
                    start: r.start,
                    len: r.len(),
                    set,
                    scale,
                    shift: if at_dependent {
                        DEPENDENT_SHIFT * scale
                    } else {
                        0.0
                    },
                }
            })
            .collect::<Vec<_>>();
        let work = Box::new(Work {
            d: vec![0.0; m],
            grad: vec![0.0; m],
            trial: vec![0.0; m],
            grad_trial: vec![0.0; m],
            p: vec![0.0; m],
            alt: vec![0.0; m],
            grad_alt: vec![0.0; m],
            coords: Vec::with_capacity(m),
            binding: vec![false; groups.len()],
            z_u: vec![0.0; m],
            newton: Scratch {
                u: Vec::with_capacity(m),
                point: vec![0.0; m],
                grad: vec![0.0; m],
                sv: vec![0.0; m],
                bv: vec![0.0; m],
                h: Mat::new(),
                factor: NewtonFactor {
                    l: Mat::new(),
                    form: None,
                    coords: Vec::with_capacity(m),
                },
                gram_pair: Pair::default(),
                counts: NewtonCounts::default(),
            },
        });
        // B = D⁻¹ (m³ flops once) where the Woodbury form may be used: 3D, where the rim
        // tangents of sliding nodes make U small, and D definite. In 2D the direct form stays:
        // its systems are at most one boundary line's rows.
        let woodbury = match form {
            NewtonForm::Direct => false,
            NewtonForm::Cheaper => rows.block == 2,
            NewtonForm::Woodbury => true,
        };
        let inverse = (woodbury && m > 0 && groups.iter().all(|g| g.shift == 0.0))
            .then(|| d.llt(Side::Lower).ok().map(|llt| llt.inverse()))
            .flatten();
        DualSolver {
            g,
            g_pair: Pair::default(),
            d: Delassus {
                mat: d,
                pair: Pair::default(),
            },
            inverse,
            form,
            groups,
            work,
            y: vec![0.0; n],
        }
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
    ) -> Result<StepReport> {
        debug_assert_eq!(z.len(), rows.len());
        let (n, c) = (factor.dim(), factor.last());
        // Forward solve L y = b; d = Gᵀ y_C.
        factor.permute(b, &mut self.y);
        factor.forward(&mut self.y);
        let y_c = &self.y[n - c..];
        let g = &self.g;
        // The two halves of d on two threads (each entry is one dot product either way).
        let d_of = |rows: Range<usize>, d: &mut [f64]| {
            for (r, dr) in rows.zip(d) {
                *dr = dot(column(g, r), y_c);
            }
        };
        let m = z.len();
        let (d0, d1) = self.work.d.split_at_mut(m / 2);
        let large = m >= SPLIT_ROWS;
        self.g_pair
            .both_if(large, || d_of(0..m / 2, d0), || d_of(m / 2..m, d1));
        let iterations = self.dual_solve(z)?;
        // y_C ← y_C − G z (the two halves of y_C on two threads, each row's sum in column
        // order either way), then the backward solve Lᵀ w = y.
        let g = &self.g;
        let (y0, y1) = self.y[n - c..].split_at_mut(c / 2);
        let update = |rows: Range<usize>, y: &mut [f64]| {
            for (r, &zr) in z.iter().enumerate() {
                if zr != 0.0 {
                    for (yi, gi) in y.iter_mut().zip(&column(g, r)[rows.clone()]) {
                        *yi -= gi * zr;
                    }
                }
            }
        };
        self.g_pair
            .both_if(large, || update(0..c / 2, y0), || update(c / 2..c, y1));
        factor.backward(&mut self.y);
        factor.unpermute(&self.y, w);
        Ok(StepReport { iterations })
    }

    /// Minimizes ½ zᵀDz − dᵀz over Z (d in `work.d`), from z (the warm start); returns the
    /// number of iterations.
    fn dual_solve(&mut self, z: &mut [f64]) -> Result<usize> {
        let DualSolver {
            d,
            inverse,
            form,
            groups,
            work,
            ..
        } = self;
        let Work {
            d: dvec,
            grad: g,
            trial,
            grad_trial: g_trial,
            p,
            alt,
            grad_alt: g_alt,
            coords,
            binding,
            z_u,
            newton,
        } = &mut **work;
        // A factorization is reused within the step only, so that a run resumed from a
        // checkpoint (which starts with no factor) repeats the uninterrupted run bit
        // for bit.
        newton.factor.form = None;
        let scale = dvec.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let tol = TOLERANCE * scale.max(f64::MIN_POSITIVE);
        if let Some(b) = inverse {
            // z_u = B d (B symmetric: column j of B is its row j).
            z_u.fill(0.0);
            axpy_columns(b, dvec.iter().copied().enumerate(), z_u);
        }
        let ops = Operators {
            d,
            dvec,
            woodbury: inverse.as_ref().map(|b| (b, &z_u[..])),
            form: *form,
            accuracy: NEWTON_ACCURACY * tol,
        };
        let project = |v: &mut [f64]| {
            for grp in groups.iter() {
                grp.project(&mut v[grp.rows()]);
            }
        };
        // Warm start: the previous multipliers, projected onto Z.
        project(z);
        d.gradient(z, dvec, g);
        let mut iterations = 0;
        // The factor of ε (`WIDEN`).
        let mut widen = 1.0;
        // Whether the last iteration's Newton point was rejected (`ETA`).
        let mut rejected = false;
        let residual = |z: &[f64], g: &[f64]| {
            groups
                .iter()
                .map(|grp| grp.residual(&z[grp.rows()], &g[grp.rows()]))
                .fold(0.0f64, f64::max)
        };
        loop {
            let res = residual(z, g);
            if res <= tol {
                return Ok(iterations);
            }
            if iterations == MAX_ITERATIONS {
                return Err(Error::solve(format!(
                    "the dual semismooth Newton method did not converge in {MAX_ITERATIONS} \
                     iterations (residual {res:e} relative to {scale:e}); \
                     try [solver] contact = \"clarabel\""
                )));
            }
            iterations += 1;
            // 1. The semismooth Newton step at v = z − g/(ηδ): z₀ (the fixed parts) in `trial`,
            // the columns of Q in `coords`; then trial = Π(z₀ + Q x).
            coords.clear();
            let eta = if rejected { 1.0 } else { ETA };
            for grp in groups.iter() {
                let r = grp.rows();
                let eta_delta = eta * grp.scale;
                for i in r.clone() {
                    trial[i] = z[i] - g[i] / eta_delta;
                }
                match grp.project(&mut trial[r.clone()]) {
                    None => {
                        trial[r.clone()].fill(0.0);
                        coords.extend(grp.free());
                    }
                    // On the rim of a disc: radial part fixed at c v̂, the tangent t̂ ⊥ v̂ free
                    // with κ = ηδ (|v| − c)/c = ηδ (1/ρ − 1). (ρ = 0: a contact row at 0.)
                    Some(rho) if rho > 0.0 => {
                        let shift = eta_delta * (1.0 / rho - 1.0);
                        coords.extend(grp.tangent(&trial[r], shift));
                    }
                    Some(_) => {}
                }
            }
            p.copy_from_slice(trial);
            newton_step(
                &ops,
                groups,
                coords,
                trial,
                Gradient::Unknown(g_trial),
                p,
                newton,
            )?;
            // The Newton point z⁺ (in p), then damped: trial = Π(z + α(z⁺ − z)) for
            // α = 1, ½, ¼ (a damped trial costs one product with D, no factorization).
            let mut alpha = 1.0;
            let accepted = loop {
                if alpha < 1.0 {
                    for i in 0..z.len() {
                        trial[i] = z[i] + alpha * (p[i] - z[i]);
                    }
                } else {
                    trial.copy_from_slice(p);
                }
                project(trial);
                d.gradient(trial, dvec, g_trial);
                // Near the solution the change of q sinks below its rounding level (a
                // multiplier on a disc's rim has the norm c only to a few ulps, and g is large
                // along it); there the residual decides.
                let (dq, noise) = (change(z, trial, g, g_trial), rounding(z, trial, g, g_trial));
                if dq < -noise || (alpha == 1.0 && dq <= noise && residual(trial, g_trial) < res) {
                    break true;
                }
                if alpha <= MIN_DAMPING {
                    break false;
                }
                alpha *= 0.5;
            };
            rejected = !accepted;
            if accepted {
                widen = 1.0;
                z.copy_from_slice(trial);
                g.copy_from_slice(g_trial);
                continue;
            }
            // 2. Otherwise the projected Newton step. ε: the length of the projected gradient
            // step z − Π(z − g/δ), widened after a short step (`WIDEN`).
            let mut eps: f64 = 0.0;
            for grp in groups.iter() {
                let r = grp.rows();
                for i in r.clone() {
                    trial[i] = z[i] - g[i] / grp.scale;
                }
                grp.project(&mut trial[r.clone()]);
                eps = eps.max(r.fold(0.0, |a, i| a.hypot(z[i] - trial[i])));
            }
            eps *= widen;
            coords.clear();
            for (grp, bind) in groups.iter().zip(binding.iter_mut()) {
                let r = grp.rows();
                let gn = norm(&g[r.clone()]);
                *bind = gn > 0.0 && {
                    for i in r.clone() {
                        trial[i] = z[i] - eps * g[i] / gn;
                    }
                    grp.not_interior(&trial[r.clone()])
                };
                // A binding disc multiplier pushed outward (μ = −g·ẑ > 0) goes to the rim
                // radially and along it by Newton, with the curvature shift κ = μ/c.
                let to_rim = match grp.set {
                    Set::Ball(c) if *bind && grp.len == 2 => {
                        let nz = norm(&z[r.clone()]);
                        let mu = -dot(&g[r.clone()], &z[r.clone()]) / nz;
                        (mu > 0.0).then_some((c, nz, mu))
                    }
                    _ => None,
                };
                if let Some((c, nz, mu)) = to_rim {
                    for i in r.clone() {
                        p[i] = (c / nz - 1.0) * z[i];
                    }
                    coords.extend(grp.tangent(&z[r], mu / c));
                } else if *bind {
                    for i in r {
                        p[i] = -g[i] / grp.scale;
                    }
                } else {
                    p[r.clone()].fill(0.0);
                    coords.extend(grp.free());
                }
            }
            newton_step(&ops, groups, coords, z, Gradient::Known(g), p, newton)?;
            // Armijo search along the projection arc z(α) = Π(z + α p).
            let mut alpha = 1.0;
            loop {
                for i in 0..z.len() {
                    trial[i] = z[i] + alpha * p[i];
                }
                project(trial);
                d.gradient(trial, dvec, g_trial);
                let predicted: f64 = groups
                    .iter()
                    .zip(binding.iter())
                    .map(|(grp, &bind)| {
                        grp.rows()
                            .map(|i| {
                                if bind {
                                    g[i] * (z[i] - trial[i])
                                } else {
                                    -alpha * g[i] * p[i]
                                }
                            })
                            .sum::<f64>()
                    })
                    .sum();
                let dq = change(z, trial, g, g_trial);
                if -dq >= 1e-4 * predicted || alpha < 1e-12 {
                    break;
                }
                alpha *= backtrack(dq, predicted, iterations);
            }
            widen = if alpha < PG_SWITCH {
                (widen * WIDEN).min(MAX_WIDEN)
            } else {
                1.0
            };
            // 3. A projected Newton direction that needed a short step can stall on an
            // ill-conditioned D (thin slabs: flat tetrahedra), zigzagging at the edge of its
            // binding set. Then the projected gradient step z(β) = Π(z − β g/δ) with Armijo,
            // which decreases q in proportion to the residual, is taken when it does better.
            if alpha < PG_SWITCH {
                let mut beta = 1.0;
                loop {
                    for grp in groups.iter() {
                        for i in grp.rows() {
                            alt[i] = z[i] - beta * g[i] / grp.scale;
                        }
                    }
                    project(alt);
                    d.gradient(alt, dvec, g_alt);
                    let predicted: f64 = (0..z.len()).map(|i| g[i] * (z[i] - alt[i])).sum();
                    let dq = change(z, alt, g, g_alt);
                    if -dq >= 1e-4 * predicted || beta < 1e-12 {
                        break;
                    }
                    beta *= backtrack(dq, predicted, iterations);
                }
                if change(z, alt, g, g_alt) < change(z, trial, g, g_trial) {
                    trial.copy_from_slice(alt);
                    g_trial.copy_from_slice(g_alt);
                }
            }
            z.copy_from_slice(trial);
            g.copy_from_slice(g_trial);
        }
    }
}

/// D, with its products split over two threads where it is large (`Pair`).
struct Delassus {
    mat: Mat<f64>,
    pair: Pair,
}

/// Below this many rows (columns of a Newton matrix) a pass over D, G or the Newton matrix
/// takes less time than handing half of it to `Pair`'s worker thread.
const SPLIT_ROWS: usize = 512;

impl Delassus {
    /// g = D z − d from the lower triangle of D alone: the entry D_ij below the diagonal of
    /// column j serves both (D z)_i (with z_j) and (D z)_j (with z_i), so a product reads half
    /// of D (the multipliers are almost all non-zero: 97% on the 3D block, so skipping zero
    /// columns of the whole D read more). The columns are split into [0, c) and [c, m) with
    /// about as many entries each, c = m(1 − 1/√2); the second part's sums (rows ≥ c) are
    /// added to the first's at the end, so the arithmetic is the same on one thread or two.
    fn gradient(&self, z: &[f64], d: &[f64], g: &mut [f64]) {
        let m = g.len();
        let c = m - (m as f64 / std::f64::consts::SQRT_2) as usize;
        // The columns `cols`' share of D z, accumulated into y (rows first.. of D z).
        let part = |cols: Range<usize>, y: &mut [f64], first: usize| {
            for j in cols {
                let col = &column(&self.mat, j)[j..];
                let (y_j, y_below) = y[j - first..].split_first_mut().unwrap();
                let below = axpy_dot(&col[1..], z[j], &z[j + 1..], y_below);
                *y_j += col[0] * z[j] + below;
            }
        };
        for (gi, di) in g.iter_mut().zip(d) {
            *gi = -di;
        }
        let mut tail = vec![0.0; m - c];
        let (head, t) = (&mut *g, &mut tail);
        self.pair
            .both_if(m >= SPLIT_ROWS, || part(0..c, head, 0), || part(c..m, t, c));
        for (gi, ti) in g[c..].iter_mut().zip(&tail) {
            *gi += ti;
        }
    }
}

/// Column j of a dense matrix (faer's owned matrices are column-major).
fn column(mat: &Mat<f64>, j: usize) -> &[f64] {
    mat.col(j).try_as_col_major().unwrap().as_slice()
}

/// y += x a, and returns a·v (in four partial sums, so that it vectorizes): the two uses of
/// a column of a symmetric matrix's lower triangle, in one pass over it.
fn axpy_dot(a: &[f64], x: f64, v: &[f64], y: &mut [f64]) -> f64 {
    let n = a.len() / 4 * 4;
    let mut acc = [0.0; 4];
    for ((a, v), y) in a[..n]
        .chunks_exact(4)
        .zip(v[..n].chunks_exact(4))
        .zip(y[..n].chunks_exact_mut(4))
    {
        for k in 0..4 {
            y[k] += x * a[k];
            acc[k] += a[k] * v[k];
        }
    }
    let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    for i in n..a.len() {
        y[i] += x * a[i];
        s += a[i] * v[i];
    }
    s
}

/// The next trial of an Armijo search in the step's iteration `iteration`, as a fraction of
/// the last trial's step α: after `INTERPOLATED` iterations ½, before them the minimizer
/// of the quadratic in α through q at the start, with slope −`predicted`/α there (the
/// first-order decrease the search compares with), and through the change `dq` of q at α
/// (Nocedal & Wright, Numerical Optimization, (3.58)), kept within [0.1, 0.5]; ½ if that
/// quadratic has no minimizer. q is quadratic, so along a stretch of the arc where the
/// projection leaves the same groups fixed this lands at the minimizer at once: on the 3D
/// block h = 1/24 halving took 7.2 trials (products with D) per projected Newton step, and
/// the steps' products fell from 3966 to 2479, their iterations from 796 to 688 (see
/// `INTERPOLATED` for why it halves later).
fn backtrack(dq: f64, predicted: f64, iteration: usize) -> f64 {
    let t = predicted / (2.0 * (dq + predicted));
    if iteration <= INTERPOLATED && t > 0.0 {
        t.clamp(0.1, 0.5)
    } else {
        0.5
    }
}

/// q(t) − q(z) = (t − z)·(g(z) + g(t))/2 for the quadratic q: exact up to the rounding of
/// the gradients, where the difference of two objective values would lose it to cancellation.
fn change(z: &[f64], t: &[f64], g: &[f64], g_t: &[f64]) -> f64 {
    0.5 * z
        .iter()
        .zip(t)
        .zip(g.iter().zip(g_t))
        .map(|((z, t), (g, g_t))| (t - z) * (g + g_t))
        .sum::<f64>()
}

/// The rounding level of `change`: 8 ε Σ (|z_i| + |t_i|)(|g_i| + |g_t,i|), for errors of
/// relative size ε in z and t.
fn rounding(z: &[f64], t: &[f64], g: &[f64], g_t: &[f64]) -> f64 {
    8.0 * f64::EPSILON
        * z.iter()
            .zip(t)
            .zip(g.iter().zip(g_t))
            .map(|((z, t), (g, g_t))| (z.abs() + t.abs()) * (g.abs() + g_t.abs()))
            .sum::<f64>()
}

/// A Woodbury solve is accepted when its Newton equations hold to this fraction of the
/// dual's tolerance (so its inexactness cannot reach the stopping test); it is refined at
/// most `REFINEMENTS` times, then the system is solved in the direct form.
const NEWTON_ACCURACY: f64 = 1e-2;
const REFINEMENTS: usize = 2;

/// What the Newton steps are solved with.
struct Operators<'a> {
    d: &'a Delassus,
    /// d = P K_A⁻¹ b.
    dvec: &'a [f64],
    /// B = D⁻¹ and z_u = B d, when the Woodbury form is available.
    woodbury: Option<(&'a Mat<f64>, &'a [f64])>,
    form: NewtonForm,
    /// The Newton residual a Woodbury solve must reach (absolute).
    accuracy: f64,
}

/// The gradient D z₀ − d at a Newton step's base point, if known; else a buffer for it.
enum Gradient<'a> {
    Known(&'a [f64]),
    Unknown(&'a mut [f64]),
}

/// out += Q x, where (QᵀDQ + diag κ) x = −Qᵀ(D z₀ − d) and Q, κ are given by `coords`: the
/// Newton step from z₀ on those coordinates.
///
/// Direct form. The matrix H = QᵀDQ + diag κ is SPD; a dense Cholesky factorization costs
/// nq³/3 and dominates an iteration on large contact boundaries (nq ≈ 1350 of m = 1850
/// rows on the 3D block at h = 1/24).
///
/// Woodbury form. Let N be the directions the step keeps fixed (a contact row at zero, the
/// radial direction v̂ of a disc on its rim: the complement of Q, column by column within
/// each group) and R the columns of Q with κ > 0 (the rims' tangents). The step is the
/// point z⁺ = z₀ + Q x with Nᵀ z⁺ = Nᵀ z₀ and Qᵀ(D z⁺ − d) + K x = 0; with ν = K_R x_R,
/// D z⁺ − d + R ν lies in the span of N, so with B = D⁻¹, z_u = B d and U = [N R]:
///
///   z⁺ = z_u − B U c,   (UᵀBU + diag(0 on N, 1/κ on R)) c = Uᵀ(z_u − z₀),   x = Qᵀ(z⁺ − z₀).
///
/// Its matrix has |U| = (m − nq) + |R| rows — in 3D the rims' tangents, which make nq
/// large, leave U small (820 against 1350 on average on the block) — and the step costs
/// |U|³/3 + one pass over |U| columns of B. Rounding: z⁺ is a difference of terms that
/// grow with the conditioning of D, so the Newton residual Qᵀ(D z⁺ − d) + K x is checked
/// (one product with D, which the direct form spends on D z₀ − d) and refined by the same
/// formula (x' = Qᵀ(s − B U c'), s = B Q r, for the residual r). The form is chosen per
/// system by its flop estimate.
///
/// Either form's factor is reused within a step: consecutive iterations mostly keep the
/// same coordinate structure (which rows are free, which discs on their rim) and change
/// only the rims' tangents and shifts slightly, so the step's last factor, when its
/// structure matches, preconditions conjugate gradients on the new matrix (O(nq²) per
/// iteration) to the accuracy of a direct solve; only a new structure, or CG not converging
/// in `PCG_MAX` iterations, costs a new factorization. For an unchanged matrix the first
/// preconditioned solve is already the direct solution.
fn newton_step(
    ops: &Operators,
    groups: &[Group],
    coords: &[Coord],
    z0: &[f64],
    grad: Gradient,
    out: &mut [f64],
    s: &mut Scratch,
) -> Result<()> {
    let nq = coords.len();
    if nq == 0 {
        return Ok(());
    }
    if let Some((b, z_u)) = ops.woodbury {
        complement(groups, coords, &mut s.u);
        if ops.form == NewtonForm::Woodbury || woodbury_cost(nq, s.u.len()) < direct_cost(nq) {
            if let Some(x) = woodbury_step(ops, b, z_u, coords, z0, s)? {
                s.counts.woodbury += 1;
                add_columns(coords, &x, out);
                return Ok(());
            }
            s.counts.fallbacks += 1;
        }
    }
    s.counts.direct += 1;
    let grad = match grad {
        Gradient::Known(g) => g,
        Gradient::Unknown(buf) => {
            ops.d.gradient(z0, ops.dvec, buf);
            &*buf
        }
    };
    gram(&ops.d.mat, coords, &mut s.h, &s.gram_pair);
    let rhs = Mat::<f64>::from_fn(nq, 1, |a, _| -coords[a].dot(grad));
    let x = solve_cached(Form::Direct, &rhs, coords, &s.h, &mut s.factor)?;
    add_columns(coords, &x, out);
    Ok(())
}

/// The Woodbury form of `newton_step`: x, or None if it is not accurate to
/// `ops.accuracy` after `REFINEMENTS` refinements.
fn woodbury_step(
    ops: &Operators,
    b: &Mat<f64>,
    z_u: &[f64],
    coords: &[Coord],
    z0: &[f64],
    s: &mut Scratch,
) -> Result<Option<Mat<f64>>> {
    gram(b, &s.u, &mut s.h, &s.gram_pair);
    let mut x = Mat::<f64>::zeros(coords.len(), 1);
    // In y = z − z₀: y⁺ = s − B U c, (UᵀBU + diag) c = Uᵀ s, x = Qᵀ y⁺, with s = z_u − z₀;
    // a refinement solves for the residual r the same way with s = −B Q r.
    for ((t, zu), z) in s.sv.iter_mut().zip(z_u).zip(z0) {
        *t = zu - z;
    }
    for refinement in 0..=REFINEMENTS {
        s.bv.copy_from_slice(&s.sv);
        if !s.u.is_empty() {
            let rhs = Mat::<f64>::from_fn(s.u.len(), 1, |a, _| s.u[a].dot(&s.sv));
            let c = solve_cached(Form::Woodbury, &rhs, &s.u, &s.h, &mut s.factor)?;
            axpy_columns(b, scaled_entries(&s.u, |a| -c[(a, 0)]), &mut s.bv);
        }
        let Scratch {
            point,
            grad,
            sv,
            bv,
            counts,
            ..
        } = &mut *s;
        for (a, q) in coords.iter().enumerate() {
            x[(a, 0)] += q.dot(bv);
        }
        // The Newton residual r = Qᵀ(D (z₀ + Q x) − d) + K x.
        point.copy_from_slice(z0);
        add_columns(coords, &x, point);
        ops.d.gradient(point, ops.dvec, grad);
        let r = Mat::<f64>::from_fn(coords.len(), 1, |a, _| {
            coords[a].dot(grad) + coords[a].shift * x[(a, 0)]
        });
        if r.norm_max() <= ops.accuracy {
            return Ok(Some(x));
        }
        if refinement == REFINEMENTS {
            break;
        }
        counts.refinements += 1;
        sv.fill(0.0);
        axpy_columns(b, scaled_entries(coords, |a| -r[(a, 0)]), sv);
    }
    Ok(None)
}

/// The entries (i, f(a) v) of the columns a of Q (or U) scaled by f(a).
fn scaled_entries<'a>(
    coords: &'a [Coord],
    f: impl Fn(usize) -> f64 + 'a,
) -> impl Iterator<Item = (usize, f64)> + 'a {
    coords.iter().enumerate().flat_map(move |(a, q)| {
        let fa = f(a);
        q.entries().map(move |(i, v)| (i, fa * v))
    })
}

/// out += Σ y_j M e_j over the pairs (j, y_j): columns of M scaled and summed.
fn axpy_columns(mat: &Mat<f64>, pairs: impl Iterator<Item = (usize, f64)>, out: &mut [f64]) {
    for (j, y) in pairs {
        if y != 0.0 {
            for (o, mij) in out.iter_mut().zip(column(mat, j)) {
                *o += y * mij;
            }
        }
    }
}

/// out += Q x.
fn add_columns(coords: &[Coord], x: &Mat<f64>, out: &mut [f64]) {
    for (a, q) in coords.iter().enumerate() {
        for (i, v) in q.entries() {
            out[i] += v * x[(a, 0)];
        }
    }
}

/// The columns of U for the columns Q of a Newton step (`newton_step`), group by group:
/// the directions of each group that Q leaves out (shift 0), then its columns with κ > 0
/// (shift 1/κ). `coords` lists each group's columns together, in group order.
fn complement(groups: &[Group], coords: &[Coord], u: &mut Vec<Coord>) {
    u.clear();
    let mut k = 0;
    for grp in groups {
        let first = k;
        while k < coords.len() && grp.rows().contains(&coords[k].start) {
            k += 1;
        }
        let own = &coords[first..k];
        match own {
            [] => u.extend(grp.free().map(|c| Coord { shift: 0.0, ..c })),
            // A disc on its rim: the radial direction, normal to the tangent t̂.
            [t] if t.len == 2 => u.push(Coord {
                dir: [t.dir[1], -t.dir[0]],
                shift: 0.0,
                ..*t
            }),
            _ => debug_assert_eq!(own.len(), grp.len, "a group is all free"),
        }
        u.extend(own.iter().filter(|q| q.shift > 0.0).map(|q| Coord {
            shift: 1.0 / q.shift,
            ..*q
        }));
    }
    debug_assert_eq!(k, coords.len());
}

/// Flops of a Newton system in the direct form: the factorization (building H and the
/// product D z₀ are about the same in both forms).
fn direct_cost(nq: usize) -> f64 {
    (nq as f64).powi(3) / 3.0
}

/// Flops of the Woodbury form: the factorization and the pass over |U| columns of B.
fn woodbury_cost(nq: usize, nu: usize) -> f64 {
    let (nq, nu) = (nq as f64, nu as f64);
    nu.powi(3) / 3.0 + 2.0 * nu * (nq + nu)
}

/// h = CᵀMC + diag(shift) for the columns C given by `coords`, column by column from M's
/// contiguous columns (M symmetric). Every entry is written: h's buffer is reused as it is.
fn gram(mat: &Mat<f64>, coords: &[Coord], h: &mut Mat<f64>, pair: &Pair) {
    let n = coords.len();
    h.resize_with(n, n, |_, _| 0.0);
    // The columns `cols` of h, in `part` (each column alike on either thread).
    let fill = |cols: Range<usize>, mut part: MatMut<f64>| {
        for (k, b) in cols.enumerate() {
            let qb = &coords[b];
            // (M q_b)_i = Σ_j y_j M_ij, gathered at the rows of the other columns only.
            let mut cols = qb.entries().map(|(j, y)| (column(mat, j), y));
            let (c0, y0) = cols.next().expect("a column has an entry");
            let second = cols.next();
            let mq = |i: usize| match second {
                None => 0.0 + y0 * c0[i],
                Some((c1, y1)) => 0.0 + y0 * c0[i] + y1 * c1[i],
            };
            let hb = part
                .as_mut()
                .col_mut(k)
                .try_as_col_major_mut()
                .unwrap()
                .as_slice_mut();
            for (hab, qa) in hb.iter_mut().zip(coords) {
                *hab = qa.entries().map(|(i, x)| x * mq(i)).sum();
            }
            hb[b] += qb.shift;
        }
    };
    let (h0, h1) = h.as_mut().split_at_col_mut(n / 2);
    pair.both_if(
        n >= SPLIT_ROWS,
        || fill(0..n / 2, h0),
        || fill(n / 2..n, h1),
    );
}

/// Solves H x = rhs by the step's last factor `f` (conjugate gradients preconditioned with
/// it, when it was built for the same form and structure) or a new factorization, which
/// then replaces it in its buffer.
///
/// (A single-precision factorization refined by the same conjugate gradients was tried:
/// twice as fast to factor, but its two to three CG iterations of O(nq²) each cost about
/// as much again, and the 3D block ran 8% slower side by side.)
fn solve_cached(
    form: Form,
    rhs: &Mat<f64>,
    coords: &[Coord],
    h: &Mat<f64>,
    f: &mut NewtonFactor,
) -> Result<Mat<f64>> {
    let same_structure = f.form == Some(form)
        && f.coords.len() == coords.len()
        && f.coords
            .iter()
            .zip(coords)
            .all(|(a, b)| a.start == b.start && a.len == b.len);
    if same_structure {
        if let Some(x) = pcg(h, rhs, &f.l) {
            return Ok(x);
        }
    }
    f.form = None;
    f.l.resize_with(h.nrows(), h.ncols(), |_, _| 0.0);
    f.l.copy_from_triangular_lower(h);
    let par = dense_par(f.l.nrows());
    let mut mem = MemBuffer::new(llt::factor::cholesky_in_place_scratch::<f64>(
        f.l.nrows(),
        par,
        Default::default(),
    ));
    llt::factor::cholesky_in_place(
        f.l.as_mut(),
        Default::default(),
        par,
        MemStack::new(&mut mem),
        Default::default(),
    )
    .map_err(|_| {
        Error::solve(
            "the fast contact solver's Newton matrix (the constraint rows condensed through \
             K_A⁻¹) is not positive definite to working precision, so a Newton step cannot \
             be solved; set `[solver] contact = \"clarabel\"` to solve the step problem \
             without it, and report the scene",
        )
    })?;
    f.form = Some(form);
    f.coords.clear();
    f.coords.extend_from_slice(coords);
    Ok(llt_solve(&f.l, rhs))
}

/// The parallelism of dense work on an n × n Newton matrix: one thread below `PAR_MIN`,
/// faer's global parallelism (all cores) above. Handing a small factorization to the
/// thread pool costs more than it saves: a Cholesky factorization took, one thread against
/// two (medians of 15 in one process, this 2-core machine), 0.031 against 0.069 ms at
/// n = 128, 1.16 against 1.62 ms at 512, 7.9 against 7.6 ms at 1024, 64 against 37 ms at
/// 2048; in the 2D paper scene at 1/128 (2.7 factorizations of n ≈ 100 per step) the
/// factorizations took 0.085 instead of 0.32 ms per step.
fn dense_par(n: usize) -> Par {
    if n < PAR_MIN {
        Par::Seq
    } else {
        faer::get_global_parallelism()
    }
}

/// See `dense_par`.
const PAR_MIN: usize = 1024;

/// x = (L Lᵀ)⁻¹ rhs for L in the lower triangle of `l`.
fn llt_solve(l: &Mat<f64>, rhs: &Mat<f64>) -> Mat<f64> {
    let mut x = rhs.clone();
    llt::solve::solve_in_place_with_conj(
        l.as_ref(),
        faer::Conj::No,
        x.as_mut(),
        dense_par(l.nrows()),
        MemStack::new(&mut MemBuffer::new(StackReq::EMPTY)),
    );
    x
}

/// Most conjugate gradient iterations with a reused factor before a new factorization.
const PCG_MAX: usize = 30;

/// Solves H x = rhs by conjugate gradients preconditioned with the factor `l` of a nearby
/// matrix, to a relative residual of 1e-14; None if that takes more than `PCG_MAX`
/// iterations.
fn pcg(h: &Mat<f64>, rhs: &Mat<f64>, l: &Mat<f64>) -> Option<Mat<f64>> {
    let target = 1e-14 * rhs.norm_l2();
    let mut x = llt_solve(l, rhs);
    let mut r = rhs - h * &x;
    if r.norm_l2() <= target {
        return Some(x);
    }
    let mut z = llt_solve(l, &r);
    let mut p = z.clone();
    let mut rz = (r.transpose() * &z)[(0, 0)];
    for _ in 0..PCG_MAX {
        let hp = h * &p;
        let php = (p.transpose() * &hp)[(0, 0)];
        if php.is_nan() || php <= 0.0 {
            return None;
        }
        let alpha = rz / php;
        x += alpha * &p;
        r -= alpha * &hp;
        if r.norm_l2() <= target {
            return Some(x);
        }
        z = llt_solve(l, &r);
        let rz_new = (r.transpose() * &z)[(0, 0)];
        p = &z + (rz_new / rz) * &p;
        rz = rz_new;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::{gram, Coord, Delassus, Pair};
    use faer::Mat;

    /// A symmetric m×m matrix with entries of both signs.
    fn symmetric(m: usize) -> Mat<f64> {
        let entry = |i: usize, j: usize| (((i * 7 + j * 13) % 17) as f64 - 8.0) / 3.0;
        Mat::from_fn(m, m, |i, j| {
            entry(i.max(j), i.min(j)) + f64::from(u8::from(i == j))
        })
    }

    /// D z − d from the lower triangle equals the full product to rounding, below and above
    /// the size where it splits over two threads, and is the same bit for bit on one thread
    /// or two.
    #[test]
    fn gradient_from_the_lower_triangle() {
        for m in [1, 5, 37, 700] {
            // z with zeros among its entries.
            let mat = symmetric(m);
            let z: Vec<f64> = (0..m)
                .map(|i| if i % 5 == 3 { 0.0 } else { (i as f64).sin() })
                .collect();
            let d: Vec<f64> = (0..m).map(|i| (i as f64 * 0.3).cos()).collect();
            let expected: Vec<f64> = (0..m)
                .map(|i| (0..m).map(|j| mat[(i, j)] * z[j]).sum::<f64>() - d[i])
                .collect();
            let scale = m as f64 * 3.0;
            let mut got = [vec![0.0; m], vec![0.0; m]];
            for (pair, g) in [Pair::default(), Pair::one_thread()]
                .into_iter()
                .zip(&mut got)
            {
                let op = Delassus {
                    mat: mat.clone(),
                    pair,
                };
                op.gradient(&z, &d, g);
            }
            for (a, b) in got[0].iter().zip(&expected) {
                assert!((a - b).abs() <= 1e-14 * scale, "m = {m}: {a} against {b}");
            }
            assert!(
                got[0]
                    .iter()
                    .zip(&got[1])
                    .all(|(a, b)| a.to_bits() == b.to_bits()),
                "m = {m}: two threads and one differ"
            );
        }
    }

    /// The Newton matrix CᵀMC + diag(shift) equals its dense product, for single rows and
    /// two-row (disc) coordinates, and is the same bit for bit on one thread or two.
    #[test]
    fn gram_is_the_dense_product() {
        for (m, n) in [(9, 4), (1400, 700)] {
            let mat = symmetric(m);
            // Coordinates: a single row, or a unit direction in a pair of rows.
            let coords: Vec<Coord> = (0..n)
                .map(|a| {
                    let angle = a as f64;
                    if a % 3 == 0 {
                        Coord {
                            start: 2 * a,
                            len: 1,
                            dir: [1.0, 0.0],
                            shift: 0.5,
                        }
                    } else {
                        Coord {
                            start: 2 * a,
                            len: 2,
                            dir: [angle.cos(), angle.sin()],
                            shift: 0.0,
                        }
                    }
                })
                .collect();
            // The dense oracle: C (m×n) column by column, then CᵀMC.
            let c = Mat::from_fn(m, n, |i, a| {
                coords[a]
                    .entries()
                    .find(|&(r, _)| r == i)
                    .map_or(0.0, |(_, x)| x)
            });
            let dense = c.transpose() * &mat * &c;
            let mut got = [Mat::new(), Mat::new()];
            for (pair, h) in [Pair::default(), Pair::one_thread()]
                .into_iter()
                .zip(&mut got)
            {
                gram(&mat, &coords, h, &pair);
            }
            for a in 0..n {
                for b in 0..n {
                    let mut expected = dense[(a, b)];
                    if a == b {
                        expected += coords[a].shift;
                    }
                    let h = got[0][(a, b)];
                    assert!(
                        (h - expected).abs() <= 1e-12,
                        "n = {n}: ({a}, {b}) {h} against {expected}"
                    );
                    assert_eq!(
                        h.to_bits(),
                        got[1][(a, b)].to_bits(),
                        "n = {n}: one thread and two differ"
                    );
                }
            }
        }
    }
}
