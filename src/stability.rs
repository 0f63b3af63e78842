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
//! logarithmic scan). Without memory this is k ≤ 2/λ_B. For a kernel that is not a Prony
//! series the memory term's contribution is not included (the limit printed says so).

use crate::fem::{Discretization, Isotropic};
use crate::scene::Kernel;
use faer::Mat;

/// The largest stable step of the left endpoint scheme.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepLimit {
    /// The limit; None when no explicit term can go unstable (no elasticity, no memory).
    pub k_max: Option<f64>,
    /// Whether the memory term is included in `k_max` (Prony kernels or no memory).
    pub includes_memory: bool,
}

/// The two modal ratios (λ_B, λ_R) of the pointwise tensors against A in dimension d: the
/// deviatoric mode (C τ = 2a τ) and the volumetric one (C I = (2a + d b) I).
fn modes(a: Isotropic, b: Option<Isotropic>, r: Isotropic, d: usize) -> [(f64, f64); 2] {
    let b = b.unwrap_or(Isotropic { a: 0.0, b: 0.0 });
    let d = d as f64;
    let vol = |c: Isotropic| 2.0 * c.a + d * c.b;
    [(b.a / a.a, r.a / a.a), (vol(b) / vol(a), vol(r) / vol(a))]
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

/// The largest k for which every mode is stable.
pub fn step_limit(disc: &Discretization, kernel: Option<&Kernel>) -> StepLimit {
    let (prony, includes_memory): (Vec<(f64, f64)>, bool) = match kernel {
        None => (Vec::new(), true),
        Some(Kernel::Prony(t)) => (t.clone(), true),
        Some(_) => (Vec::new(), false),
    };
    if disc.b.is_none() && prony.is_empty() {
        return StepLimit {
            k_max: None,
            includes_memory,
        };
    }
    let tol = 1e-12;
    let stable = |k: f64| {
        modes(disc.a, disc.b, disc.r, disc.dim)
            .iter()
            .all(|&(lb, lr)| radius(k, lb, lr, &prony) <= 1.0 + tol)
    };
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
