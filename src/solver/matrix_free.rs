//! The contact solvers with no m × m matrix, for contact boundaries whose condensed operator
//! D = P K_A⁻¹ Pᵀ does not fit in memory (`[solver] contact = "matrix_free"` and
//! `"sparse"`).
//!
//! Both solve the dual of `dual` — the same problem
//!
//!   minimize q(z) = ½ zᵀ D z − dᵀ z  over  z ∈ Z,   d = P K_A⁻¹ b,
//!
//! with the same multiplier groups, projections Π_j and stopping test (`dual::groups`, the
//! module doc of `dual`), but never form D: a product goes through the stored factor of
//! K_A, in one of two forms, decided by how the factor was ordered:
//!
//! - `matrix_free`: the constrained dofs C ordered last, so that
//!   D v = P (K_A⁻¹)_CC Pᵀ v = P L_CC⁻ᵀ L_CC⁻¹ Pᵀ v: Pᵀ v scattered onto C, one pass down
//!   and one up over the trailing block L_CC alone (`Factor::trailing_solve`: the rest of L
//!   does not touch C's part of the solution), P gathered from C. The Schur complement of
//!   K_A on C is dense, and so is L_CC: |C|(|C| + 1)/2 values held in the factor, which a
//!   product reads, as one with the dense D's lower triangle would.
//! - `sparse`: the factor in the fill-reducing order of a linear run, and
//!   D v = P L⁻ᵀ L⁻¹ Pᵀ v, a forward and backward solve per product, over the supernodes
//!   that hold dofs of C and their ancestors alone (`Factor::solve_within`: the others
//!   neither receive Pᵀ v nor hold a dof of the answer; 77–88 % of L's values on the
//!   plates). Memory: the factor of a linear run, two vectors of the dofs and a few of the
//!   m rows, O(nnz(L) + m); nothing dense.
//!
//! The method is the dense dual's iteration (`dual::iteration`: the semismooth Newton point,
//! its damping, the projected Newton step with its arc search, the projected gradient step,
//! the same stopping test), with D given by these products. Its Newton systems
//! (QᵀDQ + diag κ) x = −Qᵀ(D z₀ − d) are solved by conjugate gradients, one product with D
//! per iteration (`cg`), inexactly, to a residual at most min(f, r/max|d|) r for the
//! iterate's KKT residual r and f = `MatrixFreeSettings::forcing_max` (an inexact Newton
//! method: fast local convergence, no work wasted far from the solution) and never below a
//! tenth of the tolerance. They start
//! from the iterate z, x₀ = Qᵀ(z − z₀), not from x = 0: the Newton point's z₀ holds only
//! the fixed parts (zeros, points on rims), so from 0 CG would rebuild every free
//! multiplier, while from the iterate it only reduces the Newton residual there, which is
//! small near the answer (docs/performance.md: 29–49 % fewer products on the plates).
//! The preconditioner is Q_Fᵀ S Q_F on the coordinates F without a shift, with S an
//! approximation of D⁻¹ on C:
//!
//! - `Preconditioner::Dirichlet` (with the trailing block): S = P S_C Pᵀ = P L_CC L_CCᵀ Pᵀ,
//!   the Schur complement K_CC − K_CI K_II⁻¹ K_IC, the Dirichlet preconditioner of FETI
//!   (Farhat, Mandel, Roux 1994): on a flat contact boundary, where P only picks dofs of C,
//!   S = D⁻¹ exactly, and Q_Fᵀ S Q_F differs from (Q_Fᵀ D Q_F)⁻¹ only through the coupling
//!   of F to the fixed directions; it costs as much as a product with D.
//! - `Preconditioner::Lumped` (without it): S = P K_CC Pᵀ, C's block of K_A, FETI's lumped
//!   preconditioner, which drops K_CI K_II⁻¹ K_IC; a sparse product, nearly free.
//!
//! The rims' tangents (κ > 0) take diag(δ + κ): a sliding node's tangent is coupled to its
//! radial direction, which the step keeps fixed, so S is far from the inverse there. δ_j,
//! the groups' scale, is one number here: the mean of diag D, estimated from products with
//! fixed ±1 vectors (Hutchinson's trace estimate), since the exact diagonal would cost m
//! products. The answer does not depend on δ.

use super::dual::groups::{self, Coord, Group};
use super::dual::iteration::{Buffers, Iteration, Operator};
use super::dual::newton::{Gradient, Indefinite};
use super::dual::{self, DualSettings};
use super::factor::Reach;
use super::{gather, scatter, Abandon, Factor, Rows, StepReport, StepStatus};
use crate::fem::Sparse;
use crate::{Error, Result};
use std::cell::RefCell;

/// What preconditions the conjugate gradients of a Newton system (the module doc).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Preconditioner {
    /// diag(δ + κ).
    Diagonal,
    /// Q_Fᵀ S Q_F on the coordinates without a shift (F: free rows and free discs), S =
    /// P L_CC L_CCᵀ Pᵀ, and diag(δ + κ) on the rims' tangents (the module doc).
    Dirichlet,
    /// As `Dirichlet` with K_CC, C's block of K_A, in place of S_C = K_CC − K_CI K_II⁻¹ K_IC:
    /// FETI's lumped preconditioner, the one a factor without the trailing block allows.
    Lumped,
}

/// The settings of a `MatrixFreeSolver`; `validate` checks the ranges given with each field.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MatrixFreeSettings {
    /// The dual's settings: the iteration's (`tolerance`, `max_iterations`, `eta`, `rim`,
    /// the damping and search settings) and `dependent_shift`. Default
    /// `DualSettings::default()` but `far_after_damped` false: with it the same dual
    /// iterations took longer on the fine plate (docs/performance.md).
    pub dual: DualSettings,
    /// Conjugate gradient iterations per Newton system at most; a system not solved by then
    /// gives its last iterate, which the iteration's descent tests accept or reject.
    /// Default 400; ≥ 1.
    pub cg_max: usize,
    /// The largest forcing term of the inexact Newton method: a Newton system is solved to
    /// a residual of min(`forcing_max`, r/max|d|) · r for the iterate's KKT residual r.
    /// Loose solves mislead the next prediction where many groups change state: where a
    /// plate starts to slide, the usual Eisenstat–Walker cap of 0.5 took over twice the
    /// dual iterations of 0.01 (docs/performance.md). Default 0.01; in (0, 1).
    pub forcing_max: f64,
    /// Products with ±1 vectors for the estimate of diag D's mean. Default 4; ≥ 1.
    pub probes: usize,
    /// Default `Dirichlet`; `Lumped` on a factor without the trailing block
    /// (`for_factor`), which `Dirichlet` needs.
    pub preconditioner: Preconditioner,
}

impl Default for MatrixFreeSettings {
    fn default() -> Self {
        MatrixFreeSettings {
            dual: DualSettings {
                far_after_damped: false,
                ..DualSettings::default()
            },
            cg_max: 400,
            forcing_max: 0.01,
            probes: 4,
            preconditioner: Preconditioner::Dirichlet,
        }
    }
}

impl MatrixFreeSettings {
    /// The defaults for a solver on `factor`: `Dirichlet` where the factor orders C last
    /// (the trailing block S_C = L_CC L_CCᵀ is at hand), `Lumped` where it does not.
    pub fn for_factor(factor: &Factor) -> Self {
        let preconditioner = match factor.last() {
            0 => Preconditioner::Lumped,
            _ => Preconditioner::Dirichlet,
        };
        MatrixFreeSettings {
            preconditioner,
            ..Default::default()
        }
    }

    /// Checks every field against its range; the error names the first field out of it.
    pub fn validate(&self) -> Result<()> {
        self.dual.validate()?;
        let checks = [
            ("cg_max", self.cg_max >= 1, "at least 1"),
            ("probes", self.probes >= 1, "at least 1"),
            (
                "forcing_max",
                self.forcing_max > 0.0 && self.forcing_max < 1.0,
                "in (0, 1)",
            ),
        ];
        dual::in_ranges("matrix-free", &checks, self)
    }
}

/// The work of a solver so far (cumulative over its steps).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MatrixFreeCounts {
    /// Products with D (passes over L_CC, or solves), and with S or K_CC for the
    /// preconditioner.
    pub products: usize,
    pub preconditioner: usize,
    /// Newton systems, and their conjugate gradient iterations.
    pub newton: usize,
    pub cg_iterations: usize,
}

pub struct MatrixFreeSolver {
    /// What the products read (`Products`).
    operands: Operands,
    /// The multiplier groups, in row order, with δ_j the estimated mean of diag D.
    groups: Vec<Group>,
    /// C's first position in the factor's ordering, where the products go through its
    /// trailing block; 0 where they are solves (their vectors then hold every dof).
    first: usize,
    /// K_A⁻¹ b of the step in the factor's ordering, and a vector of the dofs.
    x_b: Vec<f64>,
    y: Vec<f64>,
    /// The iteration's vectors.
    buffers: Buffers,
}

/// The settings, P, the step's d and the products' vectors.
struct Operands {
    settings: MatrixFreeSettings,
    /// P: each row's (index, coefficient) pairs, the index a dof's position in the factor
    /// less `MatrixFreeSolver::first`: its entry in the products' vectors.
    p: Vec<Vec<(usize, f64)>>,
    /// K_CC by rows for `Preconditioner::Lumped` (else empty): (row's index, its entries
    /// (index, value)), indexed as P.
    kcc: Vec<(usize, Vec<(usize, f64)>)>,
    /// Where the factor has no trailing block, the products are solves within the reach
    /// of C's positions (`Factor::solve_within`); None: passes over the trailing block.
    reach: Option<Reach>,
    /// d = P K_A⁻¹ b.
    d: Vec<f64>,
    /// A request to give the step up (`solver::abandon`); none by default.
    abandon: Abandon,
    /// Vectors on C for the products, and the counts.
    work: RefCell<Work>,
}

/// The products' vectors (on C, or on every dof for solves), and the counts.
struct Work {
    y_c: Vec<f64>,
    s_c: Vec<f64>,
    counts: MatrixFreeCounts,
}

impl MatrixFreeSolver {
    /// The solver with the default settings for `factor` (`MatrixFreeSettings::for_factor`),
    /// which holds `matrix` with the rows' dofs ordered last (`matrix_free`) or in the
    /// fill-reducing order of a linear run (`sparse`).
    pub fn new(factor: &Factor, matrix: &Sparse, rows: &Rows) -> Self {
        Self::build(factor, matrix, rows, MatrixFreeSettings::for_factor(factor))
    }

    /// As `new`, with other settings, which are validated first.
    pub fn with_settings(
        factor: &Factor,
        matrix: &Sparse,
        rows: &Rows,
        settings: MatrixFreeSettings,
    ) -> Result<Self> {
        settings.validate()?;
        if factor.last() == 0 && settings.preconditioner == Preconditioner::Dirichlet {
            return Err(Error::input(
                "the matrix-free contact solver's Dirichlet preconditioner needs a factor with \
                 the constrained dofs ordered last (solver.contact = \"matrix_free\")",
            ));
        }
        Ok(Self::build(factor, matrix, rows, settings))
    }

    /// `factor` holds `matrix`; with C ordered last the products go through its trailing
    /// block, else through solves within the reach of C.
    fn build(factor: &Factor, matrix: &Sparse, rows: &Rows, settings: MatrixFreeSettings) -> Self {
        let solves = factor.last() == 0;
        let first = if solves {
            0
        } else {
            factor.dim() - factor.last()
        };
        let span = factor.dim() - first;
        let kcc = match settings.preconditioner {
            Preconditioner::Lumped => lumped(factor, matrix, &rows.dofs(), first),
            _ => Vec::new(),
        };
        let p = rows.in_factor(factor, first);
        let m = rows.len();
        let reach = solves.then(|| factor.reach(p.iter().flatten().map(|&(i, _)| i)));
        let operands = Operands {
            settings,
            p,
            kcc,
            reach,
            d: vec![0.0; m],
            abandon: Abandon::default(),
            work: RefCell::new(Work {
                y_c: vec![0.0; span],
                s_c: vec![0.0; span],
                counts: MatrixFreeCounts::default(),
            }),
        };
        let delta = Products::new(factor, &operands, 1.0).mean_diagonal(settings.probes);
        let groups = groups::groups(rows, &vec![delta; m], settings.dual.dependent_shift);
        MatrixFreeSolver {
            operands,
            buffers: Buffers::new(m, groups.len()),
            groups,
            first,
            x_b: vec![0.0; factor.dim()],
            y: vec![0.0; factor.dim()],
        }
    }

    /// Whether the products are solves with the factor (`sparse`; else passes over the
    /// trailing block, `matrix_free`).
    pub fn sparse(&self) -> bool {
        self.operands.reach.is_some()
    }

    /// Gives up a step when `abandon` is requested (`solver::abandon`).
    pub fn abandon_on(&mut self, abandon: Abandon) {
        self.operands.abandon = abandon;
    }

    /// The work so far.
    pub fn counts(&self) -> MatrixFreeCounts {
        self.operands.work.borrow().counts
    }

    /// Solves step n as `StepSolver::solve` does: `b` is b_n, `w` receives w_n, `z` the
    /// multipliers (in: the previous step's, with `before` the warm start).
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
        // x_b = K_A⁻¹ b, d = P x_b.
        factor.permute(b, &mut self.x_b);
        factor.forward(&mut self.x_b);
        factor.backward(&mut self.x_b);
        let x_c = &self.x_b[self.first..];
        let Operands { p, d, .. } = &mut self.operands;
        for (row, d) in p.iter().zip(d) {
            *d = gather(row, x_c);
        }
        let delta = self.groups.first().map_or(1.0, |g| g.scale);
        let ops = Products::new(factor, &self.operands, delta);
        let scale = ops.scale;
        let tol = self.operands.settings.dual.tolerance * scale.max(f64::MIN_POSITIVE);
        let report =
            Iteration::new(ops, &self.groups, scale, tol).run(z, before, &mut self.buffers);
        if report.status == StepStatus::Solved {
            // w = K_A⁻¹ (b − Pᵀ z) = x_b − K_A⁻¹ Pᵀ z.
            scatter(&self.operands.p, z, &mut self.y[self.first..]);
            self.y[..self.first].fill(0.0);
            factor.forward(&mut self.y);
            factor.backward(&mut self.y);
            for (y, x) in self.y.iter_mut().zip(&self.x_b) {
                *y = x - *y;
            }
            factor.unpermute(&self.y, w);
        }
        report
    }
}

/// D and S through the factor (the module doc): the `Operator` of the shared iteration.
struct Products<'a> {
    factor: &'a Factor,
    p: &'a [Vec<(usize, f64)>],
    kcc: &'a [(usize, Vec<(usize, f64)>)],
    reach: Option<&'a Reach>,
    d: &'a [f64],
    abandon: &'a Abandon,
    settings: &'a MatrixFreeSettings,
    /// max|d|, and δ.
    scale: f64,
    delta: f64,
    work: &'a RefCell<Work>,
}

impl<'a> Products<'a> {
    /// D through `factor` for the rows P of `operands`, with its step's d, and δ = `delta`.
    fn new(factor: &'a Factor, operands: &'a Operands, delta: f64) -> Self {
        Products {
            factor,
            p: &operands.p,
            kcc: &operands.kcc,
            reach: operands.reach.as_ref(),
            d: &operands.d,
            abandon: &operands.abandon,
            settings: &operands.settings,
            scale: operands.d.iter().fold(0.0f64, |a, x| a.max(x.abs())),
            delta,
            work: &operands.work,
        }
    }

    /// out = D v = P (K_A⁻¹)_CC Pᵀ v: one pass each way over L_CC, or a forward and
    /// backward solve over the supernodes that hold C and their ancestors.
    fn product(&self, v: &[f64], out: &mut [f64]) {
        let mut work = self.work.borrow_mut();
        scatter(self.p, v, &mut work.y_c);
        match self.reach {
            Some(reach) => self.factor.solve_within(reach, &mut work.y_c),
            None => self.factor.trailing_solve(&mut work.y_c),
        }
        for (row, o) in self.p.iter().zip(out) {
            *o = gather(row, &work.y_c);
        }
        work.counts.products += 1;
    }

    /// tr(D)/m estimated as the mean of vᵀDv/m over `probes` vectors of ±1 entries (a fixed
    /// pattern: the signs of a multiplicative hash of the row and the probe).
    fn mean_diagonal(&self, probes: usize) -> f64 {
        let m = self.p.len();
        let (mut v, mut dv) = (vec![0.0; m], vec![0.0; m]);
        let mut sum = 0.0;
        for probe in 0..probes {
            for (i, vi) in v.iter_mut().enumerate() {
                let h = ((i * 4 + probe) as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
                *vi = if h >> 63 == 0 { 1.0 } else { -1.0 };
            }
            self.product(&v, &mut dv);
            sum += groups::dot(&v, &dv);
        }
        (sum / (probes * m.max(1)) as f64).max(f64::MIN_POSITIVE)
    }

    /// The preconditioner of `cg` applied to r (`Preconditioner`).
    fn precondition(&self, coords: &[Coord], r: &[f64]) -> Vec<f64> {
        match self.settings.preconditioner {
            Preconditioner::Diagonal => coords
                .iter()
                .zip(r)
                .map(|(q, ri)| ri / (self.delta + q.shift))
                .collect(),
            Preconditioner::Dirichlet | Preconditioner::Lumped => {
                // Q_F r_F, with the rims' tangents (κ > 0) left out.
                let mut t = vec![0.0; self.p.len()];
                for (q, ri) in coords.iter().zip(r).filter(|(q, _)| q.shift == 0.0) {
                    for (i, e) in q.entries() {
                        t[i] += e * ri;
                    }
                }
                let mut work = self.work.borrow_mut();
                let Work { y_c, s_c, counts } = &mut *work;
                scatter(self.p, &t, y_c);
                if self.settings.preconditioner == Preconditioner::Lumped {
                    for (i, row) in self.kcc {
                        s_c[*i] = row.iter().map(|&(j, v)| v * y_c[j]).sum();
                    }
                } else {
                    self.factor.trailing_product(y_c, s_c);
                }
                counts.preconditioner += 1;
                for (row, ti) in self.p.iter().zip(&mut t) {
                    *ti = gather(row, s_c);
                }
                coords
                    .iter()
                    .zip(r)
                    .map(|(q, ri)| match q.shift > 0.0 {
                        true => ri / (self.delta + q.shift),
                        false => q.dot(&t),
                    })
                    .collect()
            }
        }
    }

    /// x with (QᵀDQ + diag κ) x = rhs to max|residual| ≤ `accuracy` (or after `cg_max`
    /// iterations, or at once when the step is given up: the iteration then ends before it
    /// uses x), by preconditioned conjugate gradients from x₀ (`r0` = rhs − H x₀).
    fn cg(&self, coords: &[Coord], x0: Vec<f64>, r0: Vec<f64>, accuracy: f64) -> Vec<f64> {
        let (nq, m) = (coords.len(), self.p.len());
        let (mut x, mut r) = (x0, r0);
        let mut s = self.precondition(coords, &r);
        let mut p = s.clone();
        let mut rs = groups::dot(&r, &s);
        let (mut full, mut dfull) = (vec![0.0; m], vec![0.0; m]);
        self.work.borrow_mut().counts.newton += 1;
        for _ in 0..self.settings.cg_max {
            if r.iter().fold(0.0f64, |a, x| a.max(x.abs())) <= accuracy || self.abandoned() {
                break;
            }
            // h = (QᵀDQ + diag κ) p.
            full.fill(0.0);
            add_columns(coords, &p, &mut full);
            self.product(&full, &mut dfull);
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
            s = self.precondition(coords, &r);
            let rs_next = groups::dot(&r, &s);
            for k in 0..nq {
                p[k] = s[k] + rs_next / rs * p[k];
            }
            rs = rs_next;
            self.work.borrow_mut().counts.cg_iterations += 1;
        }
        x
    }
}

impl Operator for Products<'_> {
    fn settings(&self) -> &DualSettings {
        &self.settings.dual
    }

    fn gradient(&self, z: &[f64], g: &mut [f64]) {
        self.product(z, g);
        for (g, d) in g.iter_mut().zip(self.d) {
            *g -= d;
        }
    }

    fn linear(&self) -> &[f64] {
        self.d
    }

    fn abandoned(&self) -> bool {
        self.abandon.requested()
    }

    fn newton_step(
        &self,
        _groups: &[Group],
        coords: &[Coord],
        z0: &[f64],
        grad: Gradient,
        out: &mut [f64],
        res: f64,
    ) -> std::result::Result<(), Indefinite> {
        if coords.is_empty() {
            return Ok(());
        }
        // CG starts from the iterate's own coordinates, x₀ = Qᵀ(z − z₀) (0 where the base
        // point z₀ is the iterate). The Newton point's z₀ holds only the fixed parts, so
        // from x = 0 CG would rebuild every free multiplier from zero; from x₀ it reduces
        // the Newton residual at the iterate, small near the answer. Its residual
        // r₀ = −Qᵀ(D(z₀ + Q x₀) − d) − diag κ x₀ costs the one product D z₀ − d costs.
        let (x0, r0) = match grad {
            Gradient::Known(g) => (
                vec![0.0; coords.len()],
                coords.iter().map(|q| -q.dot(g)).collect(),
            ),
            Gradient::Unknown { buffer, near } => {
                let x0: Vec<f64> = coords.iter().map(|q| q.dot(near) - q.dot(z0)).collect();
                let mut start = z0.to_vec();
                add_columns(coords, &x0, &mut start);
                self.gradient(&start, buffer);
                let r0 = coords
                    .iter()
                    .zip(&x0)
                    .map(|(q, x)| -q.dot(buffer) - q.shift * x)
                    .collect();
                (x0, r0)
            }
        };
        let scale = self.scale.max(f64::MIN_POSITIVE);
        let tol = self.settings.dual.tolerance * scale;
        let forcing = (res / scale).min(self.settings.forcing_max);
        let x = self.cg(coords, x0, r0, (forcing * res).max(0.1 * tol));
        add_columns(coords, &x, out);
        Ok(())
    }
}

/// out += Q x for the columns of Q given by `coords`.
fn add_columns(coords: &[Coord], x: &[f64], out: &mut [f64]) {
    for (q, xq) in coords.iter().zip(x) {
        for (i, e) in q.entries() {
            out[i] += e * xq;
        }
    }
}

/// K_CC by rows, C = `dofs` (sorted), each row's and column's index its position in the
/// factor less `first`: what the products' vectors on C hold.
fn lumped(
    factor: &Factor,
    matrix: &Sparse,
    dofs: &[usize],
    first: usize,
) -> Vec<(usize, Vec<(usize, f64)>)> {
    dofs.iter()
        .map(|&d| {
            // Column d of the symmetric K_A is its row d.
            let col = matrix.col_range(d);
            let entries = matrix.symbolic().row_idx()[col.clone()]
                .iter()
                .zip(&matrix.val()[col])
                .filter(|(r, _)| dofs.binary_search(r).is_ok())
                .map(|(&r, &v)| (factor.position(r) - first, v))
                .collect();
            (factor.position(d) - first, entries)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::MatrixFreeSettings;

    #[test]
    fn defaults_are_valid_and_ranges_are_checked() {
        MatrixFreeSettings::default().validate().unwrap();
        let bad = [
            (
                MatrixFreeSettings {
                    cg_max: 0,
                    ..Default::default()
                },
                "cg_max",
            ),
            (
                MatrixFreeSettings {
                    probes: 0,
                    ..Default::default()
                },
                "probes",
            ),
            (
                MatrixFreeSettings {
                    forcing_max: 1.0,
                    ..Default::default()
                },
                "forcing_max",
            ),
            (
                MatrixFreeSettings {
                    forcing_max: f64::NAN,
                    ..Default::default()
                },
                "forcing_max",
            ),
        ];
        for (s, field) in bad {
            let err = s.validate().unwrap_err().to_string();
            assert!(err.contains(&format!("`{field}`")), "{err}");
        }
    }
}
