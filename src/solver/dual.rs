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
//! its rows). The method is a semismooth Newton method on this fixed-point equation, warm
//! started from the previous step's multipliers, globalized by descent of q.
//!
//! Newton step. At v = z − g/δ each group is
//!  - free (v_j ∈ Z_j; Π' = I): the Newton equations are g_j(z⁺) = 0;
//!  - at zero (contact, v_j < 0; Π' = 0): z⁺_j = 0;
//!  - on the rim (friction, |v_j| > c_j; Π' = ρ(I − v̂v̂ᵀ), ρ = c_j/|v_j|): the equations
//!    split into a radial part v̂·z⁺_j = c_j and a tangential part
//!    T(g_j(z⁺) + κ_j z⁺_j) = 0,  T = I − v̂v̂ᵀ,  κ_j = δ_j (|v_j| − c_j)/c_j ≥ 0.
//!    At the solution −g_j = w_τ,j = μ_j γ̂_j and κ_j = μ_j/c_j: the circle's curvature times
//!    the radial multiplier, the second-order term of the constraint |γ_j| ≤ c_j. In 2D
//!    T = 0 and the multiplier is simply fixed at ±c_j.
//!
//! With z⁺ = z₀ + Q x — z₀ holds the fixed parts (c_j v̂_j, zeros), the columns of Q are the
//! free rows' unit vectors and the rims' unit tangents — the step is one SPD system
//!
//!   (QᵀDQ + diag κ) x = −Qᵀ(D z₀ − d),
//!
//! solved by a dense Cholesky factorization; z⁺ is projected onto Z. In 2D this is the
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
//! then an Armijo search along the projection arc z(α) = Π(z + α p). So the method converges
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

use super::{Factor, Rows, StepReport};
use crate::{Error, Result};
use faer::linalg::solvers::{Llt, Solve};
use faer::linalg::triangular_solve::solve_lower_triangular_in_place;
use faer::{Accum, Mat, Side};
use std::ops::Range;

/// Relative tolerance of the dual optimality conditions (in units of the velocities P w).
pub const TOLERANCE: f64 = 1e-12;
const MAX_ITERATIONS: usize = 500;
/// A projected Newton step shorter than this also tries the projected gradient step.
const PG_SWITCH: f64 = 1e-3;
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
    /// The step's last factorization of a Newton matrix; see `newton_step`.
    cache: Option<Cached>,
}

/// A Cholesky factor of QᵀDQ + diag κ and the coordinates (Q, κ) it was built from.
struct Cached {
    coords: Vec<Coord>,
    llt: Llt<f64>,
}

pub struct DualSolver {
    /// G = L_CC⁻¹ E (|C|×m).
    g: Mat<f64>,
    /// D = GᵀG = P K_A⁻¹ Pᵀ (m×m).
    d: Mat<f64>,
    /// The multiplier groups, in row order; fixed per run.
    groups: Vec<Group>,
    work: Box<Work>,
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
            cache: None,
        });
        DualSolver {
            g,
            d,
            groups,
            work,
            y: vec![0.0; n],
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
        debug_assert_eq!(z.len(), rows.len());
        let (n, c) = (factor.dim(), factor.last());
        // Forward solve L y = b; d = Gᵀ y_C.
        factor.permute(b, &mut self.y);
        factor.forward(&mut self.y);
        let y_c = &self.y[n - c..];
        for (r, dr) in self.work.d.iter_mut().enumerate() {
            *dr = dot(self.g.col(r).try_as_col_major().unwrap().as_slice(), y_c);
        }
        let iterations = self.dual_solve(z)?;
        // y_C ← y_C − G z, then the backward solve Lᵀ w = y.
        let y_c = &mut self.y[n - c..];
        for (r, &zr) in z.iter().enumerate() {
            if zr != 0.0 {
                for (yi, gi) in y_c.iter_mut().zip(self.g.col(r).iter()) {
                    *yi -= gi * zr;
                }
            }
        }
        factor.backward(&mut self.y);
        factor.unpermute(&self.y, w);
        Ok(StepReport { iterations })
    }

    /// Minimizes ½ zᵀDz − dᵀz over Z (d in `work.d`), from z (the warm start); returns the
    /// number of iterations.
    fn dual_solve(&mut self, z: &mut [f64]) -> Result<usize> {
        let DualSolver {
            d, groups, work, ..
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
            cache,
        } = &mut **work;
        // A factorization is reused within the step only, so that a run resumed from a
        // checkpoint (which starts with an empty cache) repeats the uninterrupted run bit
        // for bit.
        *cache = None;
        let scale = dvec.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let tol = TOLERANCE * scale.max(f64::MIN_POSITIVE);
        let project = |v: &mut [f64]| {
            for grp in groups.iter() {
                grp.project(&mut v[grp.rows()]);
            }
        };
        // Warm start: the previous multipliers, projected onto Z.
        project(z);
        gradient(d, z, dvec, g);
        let mut iterations = 0;
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
            // 1. The semismooth Newton step at v = z − g/δ: z₀ (the fixed parts) in `trial`,
            // the columns of Q in `coords`; then trial = Π(z₀ + Q x).
            coords.clear();
            for grp in groups.iter() {
                let r = grp.rows();
                for i in r.clone() {
                    trial[i] = z[i] - g[i] / grp.scale;
                }
                match grp.project(&mut trial[r.clone()]) {
                    None => {
                        trial[r.clone()].fill(0.0);
                        coords.extend(grp.free());
                    }
                    // On the rim of a disc: radial part fixed at c v̂, the tangent t̂ ⊥ v̂ free
                    // with κ = δ (|v| − c)/c = δ (1/ρ − 1). (ρ = 0: a contact row at 0.)
                    Some(rho) if rho > 0.0 => {
                        let shift = grp.scale * (1.0 / rho - 1.0);
                        coords.extend(grp.tangent(&trial[r], shift));
                    }
                    Some(_) => {}
                }
            }
            gradient(d, trial, dvec, g_trial);
            newton_step(d, coords, g_trial, trial, cache)?;
            // The Newton point z⁺ (kept in p), then damped: trial = Π(z + α(z⁺ − z)) for
            // α = 1, ½, ¼ (a damped trial costs one product with D, no factorization).
            p.copy_from_slice(trial);
            let mut alpha = 1.0;
            let accepted = loop {
                if alpha < 1.0 {
                    for i in 0..z.len() {
                        trial[i] = z[i] + alpha * (p[i] - z[i]);
                    }
                }
                project(trial);
                gradient(d, trial, dvec, g_trial);
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
            if accepted {
                z.copy_from_slice(trial);
                g.copy_from_slice(g_trial);
                continue;
            }
            // 2. Otherwise the projected Newton step. ε: the length of the projected gradient
            // step z − Π(z − g/δ).
            let mut eps: f64 = 0.0;
            for grp in groups.iter() {
                let r = grp.rows();
                for i in r.clone() {
                    trial[i] = z[i] - g[i] / grp.scale;
                }
                grp.project(&mut trial[r.clone()]);
                eps = eps.max(r.fold(0.0, |a, i| a.hypot(z[i] - trial[i])));
            }
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
            newton_step(d, coords, g, p, cache)?;
            // Armijo search along the projection arc z(α) = Π(z + α p).
            let mut alpha = 1.0;
            loop {
                for i in 0..z.len() {
                    trial[i] = z[i] + alpha * p[i];
                }
                project(trial);
                gradient(d, trial, dvec, g_trial);
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
                if -change(z, trial, g, g_trial) >= 1e-4 * predicted || alpha < 1e-12 {
                    break;
                }
                alpha *= 0.5;
            }
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
                    gradient(d, alt, dvec, g_alt);
                    let predicted: f64 = (0..z.len()).map(|i| g[i] * (z[i] - alt[i])).sum();
                    if -change(z, alt, g, g_alt) >= 1e-4 * predicted || beta < 1e-12 {
                        break;
                    }
                    beta *= 0.5;
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

/// g = D z − d (D symmetric: column j of D is its row j).
fn gradient(dmat: &Mat<f64>, z: &[f64], d: &[f64], g: &mut [f64]) {
    for (gi, di) in g.iter_mut().zip(d) {
        *gi = -di;
    }
    for (j, &zj) in z.iter().enumerate() {
        if zj != 0.0 {
            let col = dmat.col(j).try_as_col_major().unwrap().as_slice();
            for (gi, dij) in g.iter_mut().zip(col) {
                *gi += dij * zj;
            }
        }
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

/// out += Q x, where (QᵀDQ + diag κ) x = −Qᵀ grad and Q, κ are given by `coords`: the Newton
/// step on those coordinates.
///
/// The matrix H = QᵀDQ + diag κ is SPD; a dense Cholesky factorization costs nq³/3 and
/// dominates an iteration on large contact boundaries (nq ≈ 2000 in 3D). Consecutive
/// iterations of a step mostly keep the same coordinate structure (which rows are free, which
/// discs on their rim) and change only the rims' tangents and shifts slightly, so the step's
/// last factor, when its structure matches, preconditions conjugate gradients on the new H
/// (O(nq²) per iteration) to the accuracy of a direct solve; only a new structure, or CG not
/// converging in `PCG_MAX` iterations, costs a new factorization. For an unchanged H the
/// first preconditioned solve is already the direct solution.
fn newton_step(
    dmat: &Mat<f64>,
    coords: &[Coord],
    grad: &[f64],
    out: &mut [f64],
    cache: &mut Option<Cached>,
) -> Result<()> {
    let nq = coords.len();
    if nq == 0 {
        return Ok(());
    }
    // H = QᵀDQ + diag κ, column by column from D's contiguous columns.
    let mut h = Mat::<f64>::zeros(nq, nq);
    let mut dq = vec![0.0; dmat.nrows()];
    for (b, qb) in coords.iter().enumerate() {
        // dq = D q_b.
        dq.fill(0.0);
        for (j, y) in qb.entries() {
            let col = dmat.col(j).try_as_col_major().unwrap().as_slice();
            for (v, dij) in dq.iter_mut().zip(col) {
                *v += y * dij;
            }
        }
        let hb = h.col_mut(b).try_as_col_major_mut().unwrap().as_slice_mut();
        for (hab, qa) in hb.iter_mut().zip(coords) {
            *hab = qa.entries().map(|(i, x)| x * dq[i]).sum();
        }
        hb[b] += qb.shift;
    }
    let rhs = Mat::<f64>::from_fn(nq, 1, |a, _| {
        -coords[a].entries().map(|(i, x)| x * grad[i]).sum::<f64>()
    });
    let same_structure = cache.as_ref().is_some_and(|c| {
        c.coords.len() == nq
            && c.coords
                .iter()
                .zip(coords)
                .all(|(a, b)| a.start == b.start && a.len == b.len)
    });
    let solved = match cache.as_ref() {
        Some(c) if same_structure => pcg(&h, &rhs, &c.llt),
        _ => None,
    };
    let x = match solved {
        Some(x) => x,
        None => {
            let llt = h.llt(Side::Lower).map_err(|e| {
                Error::solve(format!(
                    "the condensed contact matrix is not positive definite ({e:?})"
                ))
            })?;
            let x = llt.solve(&rhs);
            *cache = Some(Cached {
                coords: coords.to_vec(),
                llt,
            });
            x
        }
    };
    for (a, q) in coords.iter().enumerate() {
        for (i, v) in q.entries() {
            out[i] += v * x[(a, 0)];
        }
    }
    Ok(())
}

/// Most conjugate gradient iterations with a reused factor before a new factorization.
const PCG_MAX: usize = 30;

/// Solves H x = rhs by conjugate gradients preconditioned with the factor `m` of a nearby
/// matrix, to a relative residual of 1e-14; None if that takes more than `PCG_MAX`
/// iterations.
fn pcg(h: &Mat<f64>, rhs: &Mat<f64>, m: &Llt<f64>) -> Option<Mat<f64>> {
    let target = 1e-14 * rhs.norm_l2();
    let mut x = m.solve(rhs);
    let mut r = rhs - h * &x;
    if r.norm_l2() <= target {
        return Some(x);
    }
    let mut z = m.solve(&r);
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
        z = m.solve(&r);
        let rz_new = (r.transpose() * &z)[(0, 0)];
        p = &z + (rz_new / rz) * &p;
        rz = rz_new;
    }
    None
}
