//! The iteration of the dual solve: semismooth Newton steps, their damping, the projected
//! Newton and projected gradient fallbacks with their Armijo searches.

use super::groups::{dot, norm, Coord, Set};
use super::newton::{axpy_columns, newton_step, Gradient, Operators, Scratch};
use super::DualSolver;
use crate::{Error, Result};

/// Vectors of a solve, kept between steps so that the iterations do not allocate them.
pub(super) struct Work {
    /// d = P K_A⁻¹ b.
    pub(super) d: Vec<f64>,
    /// g = D z − d at the iterate, and at the trial point.
    pub(super) grad: Vec<f64>,
    pub(super) trial: Vec<f64>,
    pub(super) grad_trial: Vec<f64>,
    /// The projected Newton direction.
    pub(super) p: Vec<f64>,
    /// The projected gradient trial point and its gradient.
    pub(super) alt: Vec<f64>,
    pub(super) grad_alt: Vec<f64>,
    pub(super) coords: Vec<Coord>,
    /// Per group: binding (moving along −g/δ) in the projected Newton step.
    pub(super) binding: Vec<bool>,
    /// z_u = B d, the unconstrained minimizer of q, when B = D⁻¹ is kept.
    pub(super) z_u: Vec<f64>,
    /// What the Newton steps need besides D: see `newton_step`.
    pub(super) newton: Scratch,
}

impl DualSolver {
    /// Minimizes ½ zᵀDz − dᵀz over Z (d in `work.d`), from z (the warm start); returns the
    /// number of iterations.
    pub(super) fn dual_solve(&mut self, z: &mut [f64]) -> Result<usize> {
        let DualSolver {
            d,
            inverse,
            settings,
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
        let tol = settings.tolerance * scale.max(f64::MIN_POSITIVE);
        if let Some(b) = inverse {
            // z_u = B d (B symmetric: column j of B is its row j).
            z_u.fill(0.0);
            axpy_columns(b, dvec.iter().copied().enumerate(), z_u);
        }
        let ops = Operators {
            d,
            dvec,
            woodbury: inverse.as_ref().map(|b| (b, &z_u[..])),
            settings,
            accuracy: settings.newton_accuracy * tol,
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
        // The factor of ε (`DualSettings::widen`).
        let mut widen = 1.0;
        // Whether the last iteration's Newton point was rejected (`DualSettings::eta`).
        let mut rejected = false;
        let residual = |z: &[f64], g: &[f64]| {
            groups
                .iter()
                .map(|grp| grp.residual(&z[grp.rows()], &g[grp.rows()], settings.rim))
                .fold(0.0f64, f64::max)
        };
        loop {
            let res = residual(z, g);
            if res <= tol {
                return Ok(iterations);
            }
            if iterations == settings.max_iterations {
                let limit = settings.max_iterations;
                return Err(Error::solve(format!(
                    "the dual semismooth Newton method did not converge in {limit} \
                     iterations (residual {res:e} relative to {scale:e}); \
                     try [solver] contact = \"clarabel\""
                )));
            }
            iterations += 1;
            // 1. The semismooth Newton step at v = z − g/(ηδ): z₀ (the fixed parts) in `trial`,
            // the columns of Q in `coords`; then trial = Π(z₀ + Q x).
            coords.clear();
            let eta = if rejected { 1.0 } else { settings.eta };
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
                if alpha <= settings.min_damping {
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
            // step z − Π(z − g/δ), widened after a short step (`DualSettings::widen`).
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
                alpha *= backtrack(dq, predicted, iterations <= settings.interpolated);
            }
            widen = if alpha < settings.pg_switch {
                (widen * settings.widen).min(settings.max_widen)
            } else {
                1.0
            };
            // 3. A projected Newton direction that needed a short step can stall on an
            // ill-conditioned D (thin slabs: flat tetrahedra), zigzagging at the edge of its
            // binding set. Then the projected gradient step z(β) = Π(z − β g/δ) with Armijo,
            // which decreases q in proportion to the residual, is taken when it does better.
            if alpha < settings.pg_switch {
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
                    beta *= backtrack(dq, predicted, iterations <= settings.interpolated);
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

/// The next trial of an Armijo search as a fraction of the last trial's step α: ½, or if
/// `interpolate` (the first `DualSettings::interpolated` iterations of a step) the minimizer
/// of the quadratic in α through q at the start, with slope −`predicted`/α there (the
/// first-order decrease the search compares with), and through the change `dq` of q at α
/// (Nocedal & Wright, Numerical Optimization, (3.58)), kept within [0.1, 0.5]; ½ if that
/// quadratic has no minimizer. q is quadratic, so along a stretch of the arc where the
/// projection leaves the same groups fixed this lands at the minimizer at once, where
/// halving takes several products with D.
fn backtrack(dq: f64, predicted: f64, interpolate: bool) -> f64 {
    let t = predicted / (2.0 * (dq + predicted));
    if interpolate && t > 0.0 {
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
