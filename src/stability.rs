//! Stability of the paper's (left endpoint) scheme, from the material data alone.
//!
//! Without contact the scheme is the linear recursion
//!
//!   K_A w_n = f_n − K_B u_n − K_R m_n,   u_{n+1} = u_n + k w_n,
//!   m^(i)_{n+1} = e^{−b_i k}(m^(i)_n + k u_n),  m_n = Σ a_i m^(i)_n   (Prony kernel),
//!
//! explicit in the elastic and memory terms: for the scalar model 2θε' + Eε = f it is forward
//! Euler, stable only for k ≤ 4θ/E. A, B and R are pointwise tensors of the isotropic form
//! Cτ = 2a dev τ + (a + b) tr τ I, so their stiffness matrices are combinations of the same
//! two matrices (deviatoric and volumetric energy) and the Rayleigh quotients of K_B and K_R
//! against K_A lie within the pointwise ratios of the two modes:
//!
//!   deviatoric: λ_B = a_B/a_A,                 λ_R = a_R/a_A
//!   trace:      λ_B = (a_B + b_B)/(a_A + b_A),  λ_R = (a_R + b_R)/(a_A + b_A).
//!
//! For each mode the recursion above is a (1 + p)×(1 + p) matrix in (u, m^(1..p)); the step
//! limit is the largest k below which its spectral radius stays ≤ 1 (found by bisection on a
//! logarithmic scan). Without memory this is k ≤ 2/λ_B. A body of several materials
//! (`[[material.region]]`) gets the modes of each: the Rayleigh quotients of K_B and K_R
//! against K_A lie within the pointwise ratios of all of them (each cell's energies are
//! those of its material), so every mode of every material must be stable; without memory
//! this is exactly k ≤ 2/max λ_B, with memory it is the one-material analysis applied to
//! each material, with the kernel of its memory group (a region's own, `[material]`'s, or
//! none). A compressed expression or table
//! kernel (`kernel_fit`) is a Prony series, and the run is exactly the scheme with it, so it
//! gets this exact limit too.
//!
//! # Kernels run by the direct sum (`memory = "exact"`, or a kernel that could not be fitted)
//!
//! Here the limit comes from the kernel on the run's own lags r_l = r(lk), l = 1..N. In each
//! mode the scheme is the scalar Volterra recursion
//!
//!   u_{n+1} = (1 − kλ_B) u_n − k² λ_R Σ_{l=1}^{n} r_l u_{n−l},
//!
//! linear and shift-invariant, so every run of the mode is a superposition of shifted copies
//! of its response h_n to u_0 = 1 (f = 0). [`amplification`] computes that response for
//! n ≤ N exactly as the scheme would (O(N²) per mode: negligible against the O(N² · dofs) of
//! the direct-sum run itself) and returns max_n |h_n|. The guard refuses the step when it
//! exceeds [`MAX_AMPLIFICATION`]. Why that is safe: for a kernel of positive type (every
//! completely monotone kernel, every kernel a Prony series can fit) the exact modal solution
//! obeys ½u(t)² = ½u_0² − λ_B∫u² − λ_R∫u (r∗u) ≤ ½u_0², so |h| ≤ 1 is what a faithful
//! discretization returns; an explicit step past its limit amplifies geometrically, reaching
//! any bound within the run (100·e^{−s} as an expression at k = 1/32: 1e33). Nothing is
//! assumed about the kernel's shape, and the check is on the run's actual N and k, so a
//! kernel that is stable only for a while is judged on the horizon it runs. A kernel that is
//! not of positive type may have a genuinely growing solution; the guard refuses it too,
//! and `[scheme] allow_unstable = true` runs it anyway.

use crate::fem::{Discretization, Isotropic};
use crate::history::{Plan, Plans};
use crate::kernel_fit::Lags;
use crate::scene::{self, Scene};
use crate::{Error, Result};
use faer::Mat;

/// The largest stable step of the left endpoint scheme.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepLimit {
    /// The limit; None when no explicit term can go unstable (no elasticity, no memory).
    pub k_max: Option<f64>,
    /// Whether the memory term is included in `k_max` (Prony kernels or no memory).
    pub includes_memory: bool,
}

/// The modal ratios (λ_B, λ_R) of the pointwise tensors against A in dimension d, two for
/// each material of the cells: the deviatoric mode (C τ = 2a τ) and the volumetric one
/// (C I = (2a + d b) I), with the material's memory group (λ_R = 0 without one).
fn modes(disc: &Discretization) -> Vec<(f64, f64, Option<usize>)> {
    let d = disc.dim as f64;
    let vol = |c: Isotropic| 2.0 * c.a + d * c.b;
    (disc.materials.distinct.iter())
        .flat_map(|s| {
            let (a, b) = (s.a, s.b_or_zero());
            let r = s.memory.map_or(Isotropic { a: 0.0, b: 0.0 }, |_| disc.r);
            [
                (b.a / a.a, r.a / a.a, s.memory),
                (vol(b) / vol(a), vol(r) / vol(a), s.memory),
            ]
        })
        .collect()
}

/// Spectral radius of the one-mode recursion at step k.
fn radius(k: f64, lambda_b: f64, lambda_r: f64, prony: &[(f64, f64)]) -> f64 {
    let p = prony.len();
    // w = −λ_B u − λ_R Σ a_i m_i;  u ← u + k w;  m_i ← e^{−b_i k}(m_i + k u).
    let m = Mat::<f64>::from_fn(1 + p, 1 + p, |i, j| match (i, j) {
        (0, 0) => 1.0 - k * lambda_b,
        (0, j) => -k * lambda_r * prony[j - 1].0,
        (i, 0) => (-prony[i - 1].1 * k).exp() * k,
        (i, j) if i == j => (-prony[i - 1].1 * k).exp(),
        _ => 0.0,
    });
    match m.eigenvalues() {
        Ok(ev) => ev.iter().map(|z| z.re.hypot(z.im)).fold(0.0, f64::max),
        Err(_) => f64::INFINITY,
    }
}

/// The largest k for which every mode is stable, each with the Prony series of its memory
/// group (`None`: no memory). `includes_memory` is false only for a kernel run by the direct
/// sum, whose memory term is judged by [`amplification`] instead.
pub fn step_limit(disc: &Discretization, plans: &Plans) -> StepLimit {
    let includes_memory = !matches!(plans.body, Plan::Exact { .. });
    let prony = |g: Option<usize>| match g.map(|g| plans.group(g)) {
        Some(Plan::Exact { .. }) | None => &[][..],
        Some(plan) => plan.prony().unwrap_or(&[]),
    };
    let modes: Vec<_> = (modes(disc).into_iter())
        .map(|(lb, lr, g)| (lb, lr, prony(g)))
        .collect();
    if !disc.materials.elastic() && modes.iter().all(|m| m.2.is_empty()) {
        return StepLimit {
            k_max: None,
            includes_memory,
        };
    }
    let tol = 1e-12;
    let stable =
        |k: f64| (modes.iter()).all(|&(lb, lr, prony)| radius(k, lb, lr, prony) <= 1.0 + tol);
    // Scan k upward by factors of 2 from a tiny step; bisect at the first unstable one.
    let mut lo = 1e-12;
    if !stable(lo) {
        return StepLimit {
            k_max: Some(0.0),
            includes_memory,
        };
    }
    let mut hi = lo;
    while stable(hi) {
        lo = hi;
        hi *= 2.0;
        if hi > 1e12 {
            return StepLimit {
                k_max: None,
                includes_memory,
            };
        }
    }
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if stable(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= 1e-14 * hi {
            break;
        }
    }
    StepLimit {
        k_max: Some(lo),
        includes_memory,
    }
}

/// The largest modal response max_n |h_n| that counts as stable (see the module doc).
pub const MAX_AMPLIFICATION: f64 = 10.0;

/// max over both modes and n ≤ N of |h_n|, the response of the direct-sum recursion to
/// u_0 = 1 on the run's lags (`lags.r` without r(0), which the left endpoint rule does not
/// read). Stops early once the response passes 10⁶·[`MAX_AMPLIFICATION`].
pub fn amplification(disc: &Discretization, lags: &Lags) -> f64 {
    let k = lags.k;
    let r = &lags.r[usize::from(lags.with_zero)..];
    let n_max = r.len();
    // rev[n_max − l] = r_l, so that Σ_{l=1}^{n} r_l u_{n−l} is a contiguous dot product.
    let rev: Vec<f64> = r.iter().rev().copied().collect();
    let mut peak: f64 = 1.0;
    for (lb, lr, _) in modes(disc) {
        let mut u = Vec::with_capacity(n_max + 1);
        u.push(1.0f64);
        for n in 0..n_max {
            let memory: f64 = rev[n_max - n..].iter().zip(&u).map(|(a, b)| a * b).sum();
            let next = (1.0 - k * lb) * u[n] - k * k * lr * memory;
            // A NaN (overflow) counts as unbounded growth.
            peak = if next.is_finite() {
                peak.max(next.abs())
            } else {
                f64::INFINITY
            };
            if peak > 1e6 * MAX_AMPLIFICATION {
                return peak;
            }
            u.push(next);
        }
    }
    peak
}

/// What the stability guard found for a left endpoint run.
#[derive(Clone, Copy, Debug)]
pub enum Verdict {
    /// The implicit variant: unconditionally stable.
    Implicit,
    /// A Prony (given or compressed) kernel, or none: the exact limit.
    Limit(StepLimit),
    /// A direct-sum kernel: the modal amplification on the run's lags, with the limit of the
    /// terms without memory.
    Amplification(f64, StepLimit),
}

impl Verdict {
    pub fn new(scene: &Scene, disc: &Discretization, plans: &Plans) -> Verdict {
        if scene.solver.history == scene::History::Implicit {
            return Verdict::Implicit;
        }
        let limit = step_limit(disc, plans);
        match &plans.body {
            Plan::Exact { lags, .. } => Verdict::Amplification(amplification(disc, lags), limit),
            _ => Verdict::Limit(limit),
        }
    }

    /// Refuses a step the scheme cannot take (exit 2), unless `[scheme] allow_unstable`.
    pub fn check(&self, scene: &Scene) -> Result<()> {
        if scene.solver.allow_unstable {
            return Ok(());
        }
        let k = scene.time.k();
        let advice = "set [scheme] history = \"implicit\" (unconditionally stable, first \
                      order); [scheme] allow_unstable = true runs it anyway";
        match *self {
            Verdict::Limit(StepLimit {
                k_max: Some(k_max), ..
            })
            | Verdict::Amplification(
                _,
                StepLimit {
                    k_max: Some(k_max), ..
                },
            ) if k > k_max => Err(Error::input(format!(
                "{}: the time step k = T/N = {k:e} exceeds the stability limit {k_max:e} of the \
                 paper's left endpoint scheme for this material (its elastic{} term is \
                 explicit). Either use time.steps ≥ {} or {advice}",
                scene.path.display(),
                if matches!(self, Verdict::Limit(_)) {
                    " and memory"
                } else {
                    ""
                },
                (scene.time.end / k_max).ceil() as u64
            ))),
            Verdict::Amplification(a, _) if a.is_nan() || a > MAX_AMPLIFICATION => {
                Err(Error::input(format!(
                    "{}: with the relaxation kernel run by the direct sum, the time step k = \
                     T/N = {k:e} is unstable for the paper's left endpoint scheme: the scheme's \
                     response to a unit state grows to {a:.1e} within the run's {} steps \
                     (stable: ≤ {MAX_AMPLIFICATION}). Use more time steps, or {advice}",
                    scene.path.display(),
                    scene.time.steps
                )))
            }
            _ => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn forward_euler_limit_without_memory() {
        // 2θε' + Eε: λ = E/(2θ), limit 2/λ = 4θ/E.
        let (theta, e) = (0.1, 0.5);
        let lb = e / (2.0 * theta);
        assert!(radius(4.0 * theta / e * 0.999, lb, 0.0, &[]) <= 1.0);
        assert!(radius(4.0 * theta / e * 1.001, lb, 0.0, &[]) > 1.0);
    }

    /// The scalar scheme itself, run for `n` steps from ε_0 = 1 with f = 0: max |ε_n|.
    fn simulate(k: f64, lb: f64, lr: f64, prony: &[(f64, f64)], n: usize) -> f64 {
        let (mut u, mut m) = (1.0f64, vec![0.0; prony.len()]);
        let mut peak: f64 = 1.0;
        for _ in 0..n {
            let w = -lb * u - lr * prony.iter().zip(&m).map(|(t, mi)| t.0 * mi).sum::<f64>();
            for (mi, t) in m.iter_mut().zip(prony) {
                *mi = (-t.1 * k).exp() * (*mi + k * u);
            }
            u += k * w;
            peak = peak.max(u.abs());
        }
        peak
    }

    #[test]
    fn limit_with_memory_separates_bounded_from_growing_runs() {
        for (lb, lr, prony) in [
            (2.5, 5.0, vec![(1.0, 10.0)]),
            (0.5, 20.0, vec![(1.0, 2.0), (3.0, 0.5)]),
            (0.0, 5.0, vec![(2.0, 1.0)]),
        ] {
            // Bisect on the radius as step_limit does.
            let (mut lo, mut hi) = (1e-9, 1e-9);
            while radius(hi, lb, lr, &prony) <= 1.0 + 1e-12 {
                lo = hi;
                hi *= 2.0;
            }
            for _ in 0..80 {
                let mid = 0.5 * (lo + hi);
                if radius(mid, lb, lr, &prony) <= 1.0 + 1e-12 {
                    lo = mid
                } else {
                    hi = mid
                }
            }
            let below = simulate(0.98 * lo, lb, lr, &prony, 20_000);
            assert!(below < 1e3, "{lb} {lr}: below {lo} the run grew to {below}");
            // Above the limit the run grows like ρ^n: run long enough for a factor 10^6.
            let k = 1.02 * lo;
            let rho = radius(k, lb, lr, &prony);
            let n = ((6.0 * 10f64.ln() / rho.ln()).ceil() as usize + 100).min(2_000_000);
            let above = simulate(k, lb, lr, &prony, n);
            assert!(
                above > 1e5,
                "{lb} {lr}: above {lo} (ρ = {rho}) the run stayed at {above}"
            );
        }
    }
}
