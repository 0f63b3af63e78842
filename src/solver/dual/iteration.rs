//! The iteration of the dual solve (the module doc's method), as a loop over its phases:
//! the stopping test, the semismooth Newton point and its damping (`newton_point`), else the
//! projected Newton step with its Armijo search along the projection arc
//! (`projected_newton`), and after a short one the projected gradient step
//! (`projected_gradient`).

use super::groups::{dot, norm, Coord, Group, Set};
use super::newton::{newton_step, Gradient, Indefinite, Operators, Scratch};
use super::{DualSettings, DualSolver};
use crate::solver::{Abandon, StepReport, StepStatus};
use std::cell::{OnceCell, RefCell};

/// What the iteration needs of D: the gradient and the Newton steps. The dense dual's
/// `Operators` (D stored, Newton systems by Cholesky) and the matrix-free dual's products
/// through the factor (`solver::matrix_free`) share the iteration below.
pub(in crate::solver) trait Operator {
    fn settings(&self) -> &DualSettings;

    /// g = D z − d.
    fn gradient(&self, z: &[f64], g: &mut [f64]);

    /// d, the linear term of q.
    fn linear(&self) -> &[f64];

    /// Whether the step is to be given up (`solver::abandon`).
    fn abandoned(&self) -> bool;

    /// out += Q x, the Newton step from z₀ on the coordinates `coords` (`newton_step`);
    /// `res` is the KKT residual at the iterate, for a solver that solves inexactly.
    fn newton_step(
        &self,
        groups: &[Group],
        coords: &[Coord],
        z0: &[f64],
        grad: Gradient,
        out: &mut [f64],
        res: f64,
    ) -> Result<(), Indefinite>;
}

/// The dense dual's operator: D, and the Newton systems' buffers and factor.
struct Dense<'a> {
    ops: Operators<'a>,
    newton: RefCell<&'a mut Scratch>,
    abandon: &'a Abandon,
}

impl Operator for Dense<'_> {
    fn settings(&self) -> &DualSettings {
        self.ops.settings
    }

    fn gradient(&self, z: &[f64], g: &mut [f64]) {
        self.ops.d.gradient(z, self.ops.dvec, g);
    }

    fn linear(&self) -> &[f64] {
        self.ops.dvec
    }

    fn abandoned(&self) -> bool {
        self.abandon.requested()
    }

    fn newton_step(
        &self,
        groups: &[Group],
        coords: &[Coord],
        z0: &[f64],
        grad: Gradient,
        out: &mut [f64],
        _res: f64,
    ) -> Result<(), Indefinite> {
        let mut newton = self.newton.borrow_mut();
        newton_step(&self.ops, groups, coords, z0, grad, out, &mut newton)
    }
}

/// Vectors of a solve, kept between steps so that the iterations do not allocate them.
pub(super) struct Work {
    /// d = P K_A⁻¹ b.
    pub(super) d: Vec<f64>,
    /// z_u = B d, the unconstrained minimizer of q, when B = D⁻¹ is kept and a step takes
    /// the Woodbury form (`newton::unconstrained`): a pass over B, which the plates'
    /// steps, all in the direct form, do not pay.
    pub(super) z_u: OnceCell<Vec<f64>>,
    pub(super) buffers: Buffers,
    /// What the Newton steps need besides D: see `newton_step`.
    pub(super) newton: Scratch,
}

/// The vectors the phases of an iteration fill.
pub(in crate::solver) struct Buffers {
    /// g = D z − d at the iterate, and at the trial point.
    pub(super) grad: Vec<f64>,
    pub(super) trial: Vec<f64>,
    pub(super) grad_trial: Vec<f64>,
    /// The Newton point, or the projected Newton direction.
    pub(super) p: Vec<f64>,
    /// The projected gradient trial point and its gradient.
    pub(super) alt: Vec<f64>,
    pub(super) grad_alt: Vec<f64>,
    pub(super) coords: Vec<Coord>,
    /// Per group: binding (moving along −g/δ) in the projected Newton step.
    pub(super) binding: Vec<bool>,
}

impl Buffers {
    /// The buffers of a solve of m multipliers in `groups` groups.
    pub(in crate::solver) fn new(m: usize, groups: usize) -> Buffers {
        Buffers {
            grad: vec![0.0; m],
            trial: vec![0.0; m],
            grad_trial: vec![0.0; m],
            p: vec![0.0; m],
            alt: vec![0.0; m],
            grad_alt: vec![0.0; m],
            coords: Vec::with_capacity(m),
            binding: vec![false; groups],
        }
    }
}

impl Work {
    /// The buffers of a solve of m multipliers in `groups` groups.
    pub(super) fn new(m: usize, groups: usize, settings: &DualSettings) -> Work {
        Work {
            d: vec![0.0; m],
            z_u: OnceCell::new(),
            buffers: Buffers::new(m, groups),
            newton: Scratch::new(m, settings),
        }
    }
}

impl DualSolver {
    /// Minimizes ½ zᵀDz − dᵀz over Z (d in `work.d`), warm started from z and `before`
    /// (`Iteration::run`). Each iteration leaves its next iterate in `trial`.
    pub(super) fn dual_solve(&mut self, z: &mut [f64], before: Option<&[f64]>) -> StepReport {
        let DualSolver {
            d,
            inverse,
            settings,
            groups,
            work,
            abandon,
            ..
        } = self;
        let Work {
            d: dvec,
            z_u,
            buffers: b,
            newton,
        } = &mut **work;
        // A factorization is reused within the step only, so that a run resumed from a
        // checkpoint (which starts with no factor) repeats the uninterrupted run bit
        // for bit.
        newton.factor.form = None;
        let scale = dvec.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let tol = settings.tolerance * scale.max(f64::MIN_POSITIVE);
        // z_u = B d belongs to the step's d: computed again if a system of this step wants it.
        z_u.take();
        let ops = Dense {
            ops: Operators {
                d,
                dvec,
                woodbury: inverse.as_ref().map(|b| (b, &*z_u)),
                settings,
                accuracy: settings.newton_accuracy * tol,
            },
            newton: RefCell::new(newton),
            abandon,
        };
        Iteration::new(ops, groups, scale, tol).run(z, before, b)
    }
}

/// What one iteration hands to the next.
struct Carried {
    /// The factor of ε (`DualSettings::widen`).
    widen: f64,
    /// How the last iteration's Newton point went.
    newton: Taken,
}

/// How much of a Newton step the iteration took (`Iteration::newton_point`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Taken {
    /// The Newton point itself: the next iteration predicts with η = `DualSettings::eta`.
    Full,
    /// A damped point Π(z + α(z⁺ − z)), α < 1: the prediction was wrong for the groups the
    /// step overshot, so the next one reaches far (η = 1) and holds the rims
    /// (`DualSettings::far_after_damped`).
    Damped,
    /// Neither: the projected Newton step was taken; the next prediction reaches far.
    Rejected,
}

/// What stays fixed over a step's iterations.
pub(in crate::solver) struct Iteration<'a, O: Operator> {
    ops: O,
    groups: &'a [Group],
    /// max|d|, and the residual at which the iteration stops.
    scale: f64,
    tol: f64,
}

impl<'a, O: Operator> Iteration<'a, O> {
    /// The iteration of a step with D given by `ops`, max|d| = `scale`, stopping at the
    /// residual `tol`.
    pub(in crate::solver) fn new(ops: O, groups: &'a [Group], scale: f64, tol: f64) -> Self {
        Iteration {
            ops,
            groups,
            scale,
            tol,
        }
    }

    /// The iterations from the warm start (`start`: z holds the last step's multipliers,
    /// `before` those of the step before it) until the residual is at most `tol`, the
    /// iteration limit is reached, a Newton matrix is indefinite or the step is given up
    /// (z then holds an iterate, which the time loop replaces).
    pub(in crate::solver) fn run(
        &self,
        z: &mut [f64],
        before: Option<&[f64]>,
        b: &mut Buffers,
    ) -> StepReport {
        let max_iterations = self.ops.settings().max_iterations;
        self.start(z, before, b);
        let mut carried = Carried {
            widen: 1.0,
            newton: Taken::Full,
        };
        let mut iterations = 0;
        loop {
            let res = self.residual(z, &b.grad);
            let status = if res <= self.tol {
                Some(StepStatus::Solved)
            } else if self.ops.abandoned() {
                Some(StepStatus::Abandoned)
            } else if iterations == max_iterations {
                Some(StepStatus::MaxIterations {
                    limit: max_iterations,
                    residual: res,
                    scale: self.scale,
                })
            } else {
                iterations += 1;
                let step = self.iteration(z, res, iterations, &mut carried, b);
                step.err().map(|Indefinite| StepStatus::NewtonIndefinite)
            };
            if let Some(status) = status {
                return StepReport {
                    status,
                    iterations,
                    residual: res / self.scale.max(f64::MIN_POSITIVE),
                    krylov: 0,
                };
            }
            z.copy_from_slice(&b.trial);
            b.grad.copy_from_slice(&b.grad_trial);
        }
    }

    /// Iteration number `iteration` from z (residual `res`): the semismooth Newton point if
    /// it is accepted, else the projected Newton step, and after a short one the projected
    /// gradient step if that does better. The next iterate is left in `trial`.
    fn iteration(
        &self,
        z: &[f64],
        res: f64,
        iteration: usize,
        carried: &mut Carried,
        b: &mut Buffers,
    ) -> Result<(), Indefinite> {
        let settings = self.ops.settings();
        let far = match carried.newton {
            Taken::Full => false,
            Taken::Damped => settings.far_after_damped,
            Taken::Rejected => true,
        };
        let eta = if far { 1.0 } else { settings.eta };
        let held = iteration <= settings.held_rims || (far && carried.newton == Taken::Damped);
        let hold = held.then_some(settings.rim);
        carried.newton = self.newton_point(z, eta, hold, res, b)?;
        let interpolate = iteration <= settings.interpolated;
        carried.widen = if carried.newton != Taken::Rejected || self.ops.abandoned() {
            // A step given up ends at the next test (`run`), whatever `trial` holds.
            1.0
        } else if self.projected_newton(z, res, carried.widen, interpolate, b)? < settings.pg_switch
        {
            self.projected_gradient(z, interpolate, b);
            (carried.widen * settings.widen).min(settings.max_widen)
        } else {
            1.0
        };
        Ok(())
    }

    /// The warm start, left in z with its gradient in `grad`: of the last step's multipliers
    /// z_{n−1} and their linear extrapolation in time 2z_{n−1} − z_{n−2} (`before` holds
    /// z_{n−2}), each projected onto Z, the one with the lower q. Where the loads change
    /// smoothly so do the multipliers, and the extrapolation starts the Newton iteration
    /// closer (docs/performance.md: a third fewer iterations on the plates lying on their
    /// foundation); where a step changed course — a node began to slide, a load
    /// turned — it can start farther, and q, which every iterate lowers, chooses. The
    /// choice costs one gradient per step.
    fn start(&self, z: &mut [f64], before: Option<&[f64]>, b: &mut Buffers) {
        // Where z_{n−2} = z_{n−1} (the first step) both starts are the same.
        let before = before.filter(|zb| *zb != &z[..]);
        if let Some(zb) = before {
            for ((t, zi), zb) in b.trial.iter_mut().zip(&*z).zip(zb) {
                *t = 2.0 * zi - zb;
            }
        }
        self.project(z);
        self.gradient(z, &mut b.grad);
        if before.is_some() {
            self.project(&mut b.trial);
            self.gradient(&b.trial, &mut b.grad_trial);
            if self.q(&b.trial, &b.grad_trial) < self.q(z, &b.grad) {
                z.copy_from_slice(&b.trial);
                b.grad.copy_from_slice(&b.grad_trial);
            }
        }
    }

    /// q(z) = ½ zᵀDz − dᵀz = ½ zᵀ(g − d), from its gradient g at z.
    fn q(&self, z: &[f64], g: &[f64]) -> f64 {
        let d = self.ops.linear();
        0.5 * z
            .iter()
            .zip(g)
            .zip(d)
            .map(|((z, g), d)| z * (g - d))
            .sum::<f64>()
    }

    /// v ← Π(v), group by group.
    fn project(&self, v: &mut [f64]) {
        project(self.groups, v);
    }

    /// g = D z − d.
    fn gradient(&self, z: &[f64], g: &mut [f64]) {
        self.ops.gradient(z, g);
    }

    /// The stopping test's residual at z (the module doc).
    fn residual(&self, z: &[f64], g: &[f64]) -> f64 {
        residual(self.groups, z, g, self.ops.settings().rim)
    }

    /// The semismooth Newton step at v = z − g/(ηδ): z₀ (the fixed parts) in `trial`, the
    /// columns of Q in `coords`, the Newton point z⁺ in `p`; then damped, trial =
    /// Π(z + α(z⁺ − z)) from α = 1 down to `min_damping`, each α the last one times
    /// `backtrack`'s interpolated fraction (a damped trial costs one product with D, no
    /// factorization). The Newton point is accepted where it lowers q, a damped trial where
    /// it lowers q by at least `damped_decrease` of its first-order prediction g·(z − trial),
    /// so that it lands near the minimizer along the path, not past it. Returns which trial
    /// was taken, if any; it is in `trial`, its gradient in `grad_trial`. `res` is the
    /// residual at z.
    fn newton_point(
        &self,
        z: &[f64],
        eta: f64,
        hold: Option<f64>,
        res: f64,
        b: &mut Buffers,
    ) -> Result<Taken, Indefinite> {
        self.prediction(z, eta, hold, b);
        let Buffers {
            grad: g,
            trial,
            grad_trial: g_trial,
            p,
            coords,
            ..
        } = b;
        p.copy_from_slice(trial);
        self.ops.newton_step(
            self.groups,
            coords,
            trial,
            Gradient::Unknown {
                buffer: g_trial,
                near: z,
            },
            p,
            res,
        )?;
        let settings = self.ops.settings();
        let mut alpha = 1.0;
        Ok(loop {
            if alpha < 1.0 {
                for i in 0..z.len() {
                    trial[i] = z[i] + alpha * (p[i] - z[i]);
                }
            } else {
                trial.copy_from_slice(p);
            }
            self.project(trial);
            self.gradient(trial, g_trial);
            // Near the solution the change of q sinks below its rounding level (a
            // multiplier on a disc's rim has the norm c only to a few ulps, and g is large
            // along it); there the residual decides.
            let (dq, noise) = (change(z, trial, g, g_trial), rounding(z, trial, g, g_trial));
            let predicted = first_order(z, trial, g);
            let accepted = if alpha == 1.0 {
                dq < -noise || (dq <= noise && self.residual(trial, g_trial) < res)
            } else {
                dq < -noise && -dq >= settings.damped_decrease * predicted
            };
            if accepted {
                break if alpha == 1.0 {
                    Taken::Full
                } else {
                    Taken::Damped
                };
            }
            if alpha <= settings.min_damping {
                break Taken::Rejected;
            }
            // Along a direction that does not descend, halving.
            let fraction = if predicted > 0.0 {
                backtrack(dq, predicted, true)
            } else {
                0.5
            };
            alpha = (alpha * fraction).max(settings.min_damping);
        })
    }

    /// The Newton step's prediction (`prediction`) at z from `grad` into `trial` and
    /// `coords`.
    fn prediction(&self, z: &[f64], eta: f64, hold: Option<f64>, b: &mut Buffers) {
        prediction(
            self.groups,
            z,
            &b.grad,
            eta,
            hold,
            &mut b.trial,
            &mut b.coords,
        );
    }

    /// The projected Newton step (Bertsekas 1982) from z: the binding groups move along
    /// −g/δ (`binding_set`), the others take the face's Newton step; then the Armijo search
    /// along the projection arc. Leaves the point in `trial` and returns its step α.
    fn projected_newton(
        &self,
        z: &[f64],
        res: f64,
        widen: f64,
        interpolate: bool,
        b: &mut Buffers,
    ) -> Result<f64, Indefinite> {
        self.binding_set(z, widen, b);
        let Buffers {
            grad: g, p, coords, ..
        } = b;
        self.ops
            .newton_step(self.groups, coords, z, Gradient::Known(g), p, res)?;
        Ok(self.arc_search(z, interpolate, b))
    }

    /// ε, the length of the projected gradient step z − Π(z − g/δ) (in `trial`), times
    /// `widen`.
    fn binding_width(&self, z: &[f64], widen: f64, b: &mut Buffers) -> f64 {
        let mut eps: f64 = 0.0;
        for grp in self.groups {
            let r = grp.rows();
            for i in r.clone() {
                b.trial[i] = z[i] - b.grad[i] / grp.scale;
            }
            grp.project(&mut b.trial[r.clone()]);
            eps = eps.max(r.fold(0.0, |a, i| a.hypot(z[i] - b.trial[i])));
        }
        eps * widen
    }

    /// The binding groups (within ε of the boundary in the direction the gradient pushes
    /// them) and the projected Newton direction: `p` on the binding groups, the free
    /// groups' rows and the rims' tangents in `coords`.
    fn binding_set(&self, z: &[f64], widen: f64, b: &mut Buffers) {
        let eps = self.binding_width(z, widen, b);
        let Buffers {
            grad: g,
            trial,
            p,
            coords,
            binding,
            ..
        } = b;
        coords.clear();
        for (grp, bind) in self.groups.iter().zip(binding.iter_mut()) {
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
    }

    /// The Armijo search along the projection arc z(α) = Π(z + α p): the point in `trial`,
    /// its gradient in `grad_trial`; returns α.
    fn arc_search(&self, z: &[f64], interpolate: bool, b: &mut Buffers) -> f64 {
        let Buffers {
            grad: g,
            trial,
            grad_trial: g_trial,
            p,
            binding,
            ..
        } = b;
        let mut alpha = 1.0;
        loop {
            for i in 0..z.len() {
                trial[i] = z[i] + alpha * p[i];
            }
            self.project(trial);
            self.gradient(trial, g_trial);
            let predicted: f64 = self
                .groups
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
                return alpha;
            }
            alpha *= backtrack(dq, predicted, interpolate);
        }
    }

    /// A projected Newton direction that needed a short step can stall on an
    /// ill-conditioned D (thin slabs: flat tetrahedra), zigzagging at the edge of its
    /// binding set. Then the projected gradient step z(β) = Π(z − β g/δ) with Armijo, which
    /// decreases q in proportion to the residual, replaces `trial` when it does better.
    fn projected_gradient(&self, z: &[f64], interpolate: bool, b: &mut Buffers) {
        let Buffers {
            grad: g,
            trial,
            grad_trial: g_trial,
            alt,
            grad_alt: g_alt,
            ..
        } = b;
        let mut beta = 1.0;
        loop {
            for grp in self.groups {
                for i in grp.rows() {
                    alt[i] = z[i] - beta * g[i] / grp.scale;
                }
            }
            self.project(alt);
            self.gradient(alt, g_alt);
            let predicted = first_order(z, alt, g);
            let dq = change(z, alt, g, g_alt);
            if -dq >= 1e-4 * predicted || beta < 1e-12 {
                break;
            }
            beta *= backtrack(dq, predicted, interpolate);
        }
        if change(z, alt, g, g_alt) < change(z, trial, g, g_trial) {
            trial.copy_from_slice(alt);
            g_trial.copy_from_slice(g_alt);
        }
    }
}

/// v ← Π(v), group by group.
pub(in crate::solver) fn project(groups: &[Group], v: &mut [f64]) {
    for grp in groups {
        grp.project(&mut v[grp.rows()]);
    }
}

/// The stopping test's residual at z (the module doc), a disc multiplier on its rim where
/// |γ_j| ≥ `rim` c_j.
pub(in crate::solver) fn residual(groups: &[Group], z: &[f64], g: &[f64], rim: f64) -> f64 {
    groups
        .iter()
        .map(|grp| grp.residual(&z[grp.rows()], &g[grp.rows()], rim))
        .fold(0.0f64, f64::max)
}

/// The Newton step's prediction v = z − g/(ηδ), group by group: free (z₀ = 0, its rows in
/// Q), at zero (z₀ = 0), or on the rim of a disc (z₀ = c v̂ fixed, the tangent t̂ ⊥ v̂ in Q
/// with κ = ηδ (|v| − c)/c = ηδ (1/ρ − 1)); z₀ in `trial`, the columns of Q in `coords`.
/// With `hold` = Some(rim), a disc multiplier on its rim at z that v would free stays on
/// it (`Group::held_on_rim`, `DualSettings::held_rims`).
pub(in crate::solver) fn prediction(
    groups: &[Group],
    z: &[f64],
    g: &[f64],
    eta: f64,
    hold: Option<f64>,
    trial: &mut [f64],
    coords: &mut Vec<Coord>,
) {
    coords.clear();
    for grp in groups {
        let r = grp.rows();
        let eta_delta = eta * grp.scale;
        for i in r.clone() {
            trial[i] = z[i] - g[i] / eta_delta;
        }
        match grp.project(&mut trial[r.clone()]) {
            None => {
                let held = hold.and_then(|rim| grp.held_on_rim(&z[r.clone()], &g[r.clone()], rim));
                if let Some((z0, kappa)) = held {
                    trial[r].copy_from_slice(&z0);
                    coords.extend(grp.tangent(&z0, kappa));
                } else {
                    trial[r].fill(0.0);
                    coords.extend(grp.free());
                }
            }
            // ρ = 0: a contact row at 0.
            Some(rho) if rho > 0.0 => {
                let shift = eta_delta * (1.0 / rho - 1.0);
                coords.extend(grp.tangent(&trial[r], shift));
            }
            Some(_) => {}
        }
    }
}

/// The next trial of an Armijo search as a fraction of the last trial's step α: ½, or if
/// `interpolate` (the first `DualSettings::interpolated` iterations of a step) the minimizer
/// of the quadratic in α through q at the start, with slope −`predicted`/α there (the
/// first-order decrease the search compares with), and through the change `dq` of q at α
/// (Nocedal & Wright, Numerical Optimization, (3.58)), kept within [0.1, 0.5]; ½ if that
/// quadratic has no minimizer. q is quadratic, so along a stretch of the arc where the
/// projection leaves the same groups fixed this lands at the minimizer at once, where
/// halving takes several products with D.
pub(in crate::solver) fn backtrack(dq: f64, predicted: f64, interpolate: bool) -> f64 {
    let t = predicted / (2.0 * (dq + predicted));
    if interpolate && t > 0.0 {
        t.clamp(0.1, 0.5)
    } else {
        0.5
    }
}

/// g·(z − t): the decrease of q from z to t to first order (g the gradient at z).
fn first_order(z: &[f64], t: &[f64], g: &[f64]) -> f64 {
    (0..z.len()).map(|i| g[i] * (z[i] - t[i])).sum()
}

/// q(t) − q(z) = (t − z)·(g(z) + g(t))/2 for the quadratic q: exact up to the rounding of
/// the gradients, where the difference of two objective values would lose it to cancellation.
pub(in crate::solver) fn change(z: &[f64], t: &[f64], g: &[f64], g_t: &[f64]) -> f64 {
    0.5 * z
        .iter()
        .zip(t)
        .zip(g.iter().zip(g_t))
        .map(|((z, t), (g, g_t))| (t - z) * (g + g_t))
        .sum::<f64>()
}

/// The rounding level of `change`: 8 ε Σ (|z_i| + |t_i|)(|g_i| + |g_t,i|), for errors of
/// relative size ε in z and t.
pub(in crate::solver) fn rounding(z: &[f64], t: &[f64], g: &[f64], g_t: &[f64]) -> f64 {
    8.0 * f64::EPSILON
        * z.iter()
            .zip(t)
            .zip(g.iter().zip(g_t))
            .map(|((z, t), (g, g_t))| (z.abs() + t.abs()) * (g.abs() + g_t.abs()))
            .sum::<f64>()
}
