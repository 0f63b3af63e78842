//! Sum-of-exponentials compression of a relaxation kernel, with a certified error.
//!
//! The memory sum m_n = k Σ_{j<n} r((n − j)k) u_j of (3.1) reads r only on the lags
//! s_l = l·k, l = 1..N (and the implicit variant also r(0)). On exactly these points we fit
//!
//!   r̃(s) = Σ_i a_i e^{−b_i s},   a_i ≥ 0, b_i ≥ 0,
//!
//! and then run the exact O(1) Prony recursion of `history` with r̃. The fit is **certified**:
//! after fitting, r̃ − r is evaluated on every lag and the maximum, relative to max_l |r(s_l)|,
//! is the error reported; a fit whose certified error exceeds the tolerance is not used: a
//! run of at most [`EXACT_STEPS`] steps falls back to the direct sum and says why, a longer
//! one is refused (`history::Plan::new`), since the direct sum would cost O(N²·dofs) time
//! and 8·dofs·N bytes behind the user's back. A compressed run is therefore exactly the
//! scheme (3.1) with the kernel r̃, which agrees with r within ε·max|r| at every value the
//! scheme reads.
//!
//! # Method (chosen by measurement, see README "The cost of memory")
//!
//! A fixed geometric grid of rates b_j — 0.6 per decade per digit of the tolerance (then
//! 0.8, 1.0 if that fails) from 1e-4/T to 40/k, plus the constant b = 0 — and non-negative least squares weights (Lawson–Hanson) on a sample of the
//! lags: every lag up to 64, then lags growing by 3 %, and the last. NNLS picks a sparse set
//! of active rates; the zero weights are dropped. If the certified error on all lags is above
//! the tolerance, the lags where the error peaks are added to the sample, the grid is
//! bisected around every active rate, and the fit is repeated (at most `ROUNDS` times). Why this and not the
//! trapezoid rule on s^(−α) = Γ(α)^{−1} ∫ t^{α−1} e^{−ts} dt followed by a Prony reduction:
//! that rule needs the kernel's inverse Laplace transform, which an expression or a table does
//! not give; NNLS on a grid needs only values, works for tables and stretched exponentials
//! alike, and on s^(−α) with T/k = 10^6 and ε = 1e-10 it gives 40–60 terms in well under a
//! second (README). Positive weights keep r̃ completely monotone like the kernels users have,
//! and they make the fit numerically benign: the weighted sum has no cancellation, so a
//! backward-stable least squares solve (Householder QR) gives a residual near round-off
//! although the exponential columns are nearly dependent. Signed weights are never used.
//!
//! A kernel with positive weights and rates is positive, non-increasing and convex on the
//! lags. One that changes sign or grows is reported as unfittable before any fitting, with
//! the place it does so; one that is positive and non-increasing but still misses the
//! tolerance (a kinked table, a kernel that is not completely monotone) is reported with the
//! error the best fit reached, so that the user can choose a tolerance it meets.
//!
//! Each term's rate enters the Prony recursion through its one-step decay d_i = e^{−b_i k}
//! rounded to f64; the certificate evaluates Σ a_i d_i^l with that rounded d_i, i.e. the
//! kernel the recursion implements, not an idealization of it. Everything here is
//! sequential and deterministic: the same kernel, lags and tolerance give the same bits (a
//! resumed run recomputes the fit and the checkpoint check compares it bit for bit).

mod nnls;
mod polish;

use crate::kernel::Kernel;
use crate::{Error, Result};
use faer::Mat;
use nnls::nnls;
use polish::polish;
use std::time::Instant;

/// r on the lags the scheme reads: `r[0]` = r(0) when `with_zero`, then r(k), r(2k), …,
/// r(Nk). Lag l is evaluated at s = l·k exactly as the direct sum does.
#[derive(Clone, Debug)]
pub struct Lags {
    pub k: f64,
    pub with_zero: bool,
    pub r: Vec<f64>,
}

impl Lags {
    /// Evaluates the kernel on the lags; a non-finite value is bad input naming `key` (the
    /// scene key of the kernel), with the lag where it happens.
    pub fn new(kernel: &Kernel, k: f64, n: usize, with_zero: bool, key: &str) -> Result<Lags> {
        let first = usize::from(!with_zero);
        let mut r = Vec::with_capacity(n + 1 - first);
        for l in first..=n {
            let s = l as f64 * k;
            let v = kernel.eval(s);
            if !v.is_finite() {
                return Err(Error::input(format!(
                    "key '{key}': r(s) = {v} at s = {s} (lag {l} of the run's {n}, k = {k}); the \
                     memory sum reads r on s = {}k, 2k, …, T: give a kernel that is finite \
                     there{}",
                    if with_zero {
                        "0 (implicit variant), "
                    } else {
                        ""
                    },
                    if with_zero && l == 0 {
                        ", or use [scheme] history = \"left\" (it does not read r(0))"
                    } else {
                        ""
                    }
                )));
            }
            r.push(v);
        }
        Ok(Lags { k, with_zero, r })
    }

    /// Keeps the lags up to l = n.
    pub fn truncate(&mut self, n: usize) {
        self.r.truncate(n + usize::from(self.with_zero));
    }

    /// The last lag l.
    pub fn last(&self) -> usize {
        self.lag(self.r.len() - 1)
    }

    /// The lag index l of `r[i]`.
    fn lag(&self, i: usize) -> usize {
        i + usize::from(!self.with_zero)
    }

    /// max_l |r(s_l)|: the scale of the relative error.
    pub fn scale(&self) -> f64 {
        self.r.iter().fold(0.0, |m, v| m.max(v.abs()))
    }
}

/// A certified fit r̃(s) = Σ a_i e^{−b_i s}.
#[derive(Clone, Debug, PartialEq)]
pub struct Fit {
    /// (a_i, b_i), rates decreasing.
    pub terms: Vec<(f64, f64)>,
    /// The certified max_l |r̃(s_l) − r(s_l)| / max_l |r(s_l)| over every lag.
    pub error: f64,
    /// The last lag l it is certified on (N, or the horizon's steps).
    pub last_lag: usize,
    /// Wall time of the fit and its certificate.
    pub seconds: f64,
}

/// The most lags a fit is evaluated and certified on (max(N, horizon/k)): the fit keeps r
/// and its deviation on every lag, 16 bytes each (160 MB here), and each certificate is
/// O(lags · terms). A scene asking for more is refused when it is read (`scene.rs`).
pub const MAX_LAGS: usize = 10_000_000;

/// The most steps a compressed kernel whose fit misses its tolerance may run by the direct
/// sum instead: beyond, its O(N²·dofs) time and 8·dofs·N bytes are refused, not spent.
pub const EXACT_STEPS: usize = 10_000;

/// Refinement rounds after the first fit.
const ROUNDS: usize = 16;

/// Candidate rates beyond which refinement stops (each NNLS iteration is a dense solve).
const MAX_RATES: usize = 240;

/// Fits the lags within `tolerance` (relative to max|r|), or says why it cannot.
pub fn fit(lags: &Lags, tolerance: f64) -> std::result::Result<Fit, String> {
    let start = Instant::now();
    let scale = lags.scale();
    if scale == 0.0 {
        return Ok(Fit {
            terms: Vec::new(),
            error: 0.0,
            last_lag: lags.last(),
            seconds: start.elapsed().as_secs_f64(),
        });
    }
    shape(lags, tolerance * scale)?;
    // The starting grid density that succeeds depends on the kernel in no simple way
    // (denser grids are not always better: their columns are closer to dependent), so a few
    // are tried in a fixed order and the best fit is kept.
    let mut best: Option<(Vec<(f64, f64)>, f64)> = None;
    for per_digit in [0.6, 0.8, 1.0] {
        let (terms, error) = attempt(lags, tolerance, scale, per_digit);
        if best.as_ref().is_none_or(|(_, e)| error < *e) {
            best = Some((terms, error));
        }
        if error <= tolerance {
            break;
        }
    }
    let (mut terms, mut error) = best.expect("at least one round");
    if error > tolerance {
        (terms, error) = polished(lags, tolerance, scale, terms, error);
    }
    if error > tolerance {
        return Err(format!(
            "the best sum of exponentials with positive weights reaches a relative error of \
             {error:.2e} on the lags, above the tolerance {tolerance:e} (in double precision \
             this method reaches about 1e-11 on smooth completely monotone kernels; a kinked \
             table or a kernel that is not completely monotone stops earlier): set \
             [material.relaxation] tolerance ≥ {:.0e} to compress it, or memory = \"exact\"",
            10f64.powf(error.log10().ceil())
        ));
    }
    Ok(Fit {
        terms,
        error,
        last_lag: lags.last(),
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// One fit from a grid of `per_digit`·digits rates per decade: NNLS, certificate, and up to
/// `ROUNDS` refinements; the best (terms, certified error) seen.
fn attempt(lags: &Lags, tolerance: f64, scale: f64, per_digit: f64) -> (Vec<(f64, f64)>, f64) {
    let n = lags.last();
    let k = lags.k;
    let mut rows = sample(lags);
    let mut rates = grid(k, n as f64 * k, (-per_digit * tolerance.log10()).max(3.0));
    let mut best: Option<(Vec<(f64, f64)>, f64)> = None;
    for _ in 0..=ROUNDS {
        let weights = nnls(&design(lags, &rows, &rates), &values(lags, &rows));
        let terms: Vec<(f64, f64)> = weights
            .iter()
            .zip(&rates)
            .filter(|(a, _)| **a > 0.0)
            .map(|(&a, &b)| (a, b))
            .collect();
        let errors = deviation(lags, &terms);
        let error = errors.iter().fold(0.0f64, |m, e| m.max(*e)) / scale;
        if best.as_ref().is_none_or(|(_, e)| error < *e) {
            best = Some((terms, error));
        }
        if error <= tolerance {
            break;
        }
        rows = refined(&rows, &errors);
        rates = bisected(&rates, &weights);
        if rates.len() > MAX_RATES {
            break;
        }
    }
    best.expect("at least one round")
}

/// A fit that missed the tolerance on the grid, with its rates freed: Levenberg–Marquardt
/// ([`polish`]) on the sample, then on the sample plus the lags where the error peaks, up
/// to `ROUNDS` times; the best certified (terms, error). A grid cannot hold the rate of
/// e^{−s} exactly, and its neighbours approximate it only to ~1e-10 (measured: e^{−s},
/// 100 e^{−s} and e^{−s} + 0.1 e^{−0.01 s} missed 1e-10 before this step); freed rates reach
/// it to round-off.
fn polished(
    lags: &Lags,
    tolerance: f64,
    scale: f64,
    terms: Vec<(f64, f64)>,
    error: f64,
) -> (Vec<(f64, f64)>, f64) {
    let mut rows = sample(lags);
    let mut best = (terms, error);
    for _ in 0..ROUNDS {
        let terms = polish(lags, &rows, &best.0);
        let errors = deviation(lags, &terms);
        let error = errors.iter().fold(0.0f64, |m, e| m.max(*e)) / scale;
        if error >= best.1 {
            break;
        }
        best = (terms, error);
        if error <= tolerance {
            break;
        }
        rows = refined(&rows, &errors);
    }
    best
}

/// The shape no positive sum of exponentials can follow: a sign change or growth beyond the
/// tolerance `abs_tol` (absolute).
fn shape(lags: &Lags, abs_tol: f64) -> std::result::Result<(), String> {
    let s = |i: usize| lags.lag(i) as f64 * lags.k;
    if let Some(i) = lags.r.iter().position(|&v| v < -abs_tol) {
        return Err(format!(
            "r is negative at s = {} (r = {:e}): a sum of exponentials with positive weights \
             is positive",
            s(i),
            lags.r[i]
        ));
    }
    if let Some(i) = lags.r.windows(2).position(|w| w[1] > w[0] + abs_tol) {
        return Err(format!(
            "r grows from s = {} to s = {} ({:e} → {:e}): a sum of decaying exponentials \
             with positive weights never grows",
            s(i),
            s(i + 1),
            lags.r[i],
            lags.r[i + 1]
        ));
    }
    Ok(())
}

/// Indices into `lags.r` of the sample the least squares fit sees: r(0) if present, every
/// lag up to 64, then lags growing by a factor 1.03, and the last lag.
fn sample(lags: &Lags) -> Vec<usize> {
    let len = lags.r.len();
    let mut rows: Vec<usize> = (0..len.min(65)).collect();
    let mut x = rows.len() as f64;
    while (x as usize) < len {
        rows.push(x as usize);
        x *= 1.03;
    }
    rows.push(len - 1);
    rows.dedup();
    rows
}

/// The sample plus the lags where the error of the last fit peaks (its 64 largest local
/// maxima).
fn refined(rows: &[usize], errors: &[f64]) -> Vec<usize> {
    let mut peaks: Vec<usize> = (0..errors.len())
        .filter(|&i| {
            (i == 0 || errors[i] >= errors[i - 1])
                && (i + 1 == errors.len() || errors[i] >= errors[i + 1])
        })
        .collect();
    peaks.sort_by(|&a, &b| errors[b].total_cmp(&errors[a]).then(a.cmp(&b)));
    peaks.truncate(64);
    let mut out: Vec<usize> = rows.iter().copied().chain(peaks).collect();
    out.sort_unstable();
    out.dedup();
    out
}

/// The active rates, their neighbours and the geometric midpoints between them: a kernel
/// whose spectrum is concentrated (a single exponential, a stretched exponential with β
/// near one) needs rates closer to its own than any fixed grid holds, since a positive mixture of
/// other rates matches e^{−bs} only to the order of the mixture's spread. Rates far from
/// every active one are dropped, so the candidate set stays about 5× the active one.
fn bisected(rates: &[f64], weights: &[f64]) -> Vec<f64> {
    let mut out = Vec::new();
    for i in (0..rates.len()).filter(|&i| weights[i] > 0.0) {
        out.push(rates[i]);
        for j in [i.wrapping_sub(1), i + 1] {
            if let Some(&b) = rates.get(j) {
                out.push(b);
                out.push((b * rates[i]).sqrt());
            }
        }
    }
    out.sort_by(|a, b| b.total_cmp(a));
    out.dedup();
    out
}

/// The rate grid: 40/k down to 1e-4/T by the factor 10^{1/per_decade}, then b = 0.
fn grid(k: f64, t: f64, per_decade: f64) -> Vec<f64> {
    let (hi, lo) = (40.0 / k, 1e-4 / t);
    let q = 10f64.powf(-1.0 / per_decade);
    let count = ((hi / lo).log10() * per_decade).ceil() as i32;
    let mut rates: Vec<f64> = (0..=count).map(|j| hi * q.powi(j)).collect();
    rates.push(0.0);
    rates
}

/// One-step decay e^{−b k} as the Prony recursion rounds it, and its logarithm.
fn log_decay(b: f64, k: f64) -> f64 {
    (-b * k).exp().ln()
}

/// Column j holds d_j^l for the sampled lags l (d_j = e^{−b_j k} rounded as the recursion
/// uses it).
fn design(lags: &Lags, rows: &[usize], rates: &[f64]) -> Mat<f64> {
    Mat::from_fn(rows.len(), rates.len(), |i, j| {
        (lags.lag(rows[i]) as f64 * log_decay(rates[j], lags.k)).exp()
    })
}

fn values(lags: &Lags, rows: &[usize]) -> Vec<f64> {
    rows.iter().map(|&i| lags.r[i]).collect()
}

/// The certificate of `terms` on every lag: the relative error max_l |r̃(s_l) − r(s_l)| /
/// max_l |r(s_l)|, and the last lag index l* such that the error stays within `tolerance` on
/// every lag up to it (`None` when it fails already on the first).
pub fn certify(lags: &Lags, terms: &[(f64, f64)], tolerance: f64) -> (f64, Option<usize>) {
    let scale = lags.scale();
    if scale == 0.0 {
        return (0.0, lags.r.len().checked_sub(1).map(|i| lags.lag(i)));
    }
    let errors = deviation(lags, terms);
    let error = errors.iter().fold(0.0f64, |m, e| m.max(*e)) / scale;
    let within = errors
        .iter()
        .position(|e| e / scale > tolerance)
        .unwrap_or(errors.len());
    (error, within.checked_sub(1).map(|i| lags.lag(i)))
}

/// |r̃(s_l) − r(s_l)| on every lag, r̃(s_l) = Σ a_i d_i^l. d_i^l is recomputed by exp every
/// 32 lags and carried by multiplication in between (relative rounding ≤ 32 ulp of a
/// positive sum: far below any tolerance the fit is asked for).
pub fn deviation(lags: &Lags, terms: &[(f64, f64)]) -> Vec<f64> {
    let ln_d: Vec<f64> = terms.iter().map(|t| log_decay(t.1, lags.k)).collect();
    let d: Vec<f64> = ln_d.iter().map(|v| v.exp()).collect();
    let mut power = vec![0.0; terms.len()];
    let mut out = Vec::with_capacity(lags.r.len());
    for (i, r) in lags.r.iter().enumerate() {
        let l = lags.lag(i);
        if i % 32 == 0 {
            for (p, ld) in power.iter_mut().zip(&ln_d) {
                *p = (l as f64 * ld).exp();
            }
        } else {
            for (p, di) in power.iter_mut().zip(&d) {
                *p *= di;
            }
        }
        let fit: f64 = terms.iter().zip(&power).map(|(t, p)| t.0 * p).sum();
        out.push((fit - r).abs());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn power_law(alpha: f64, n: usize) -> Lags {
        Lags {
            k: 1.0,
            with_zero: false,
            r: (1..=n).map(|l| (l as f64).powf(-alpha)).collect(),
        }
    }

    #[test]
    fn nnls_recovers_a_positive_combination() {
        let rates = [2.0, 0.5, 0.1];
        let lags = Lags {
            k: 0.1,
            with_zero: true,
            r: (0..200)
                .map(|l| 3.0 * (-0.2 * l as f64).exp() + 0.5 * (-0.01 * l as f64).exp())
                .collect(),
        };
        let rows: Vec<usize> = (0..200).collect();
        let x = nnls(&design(&lags, &rows, &rates), &values(&lags, &rows));
        assert!((x[0] - 3.0).abs() < 1e-10 && x[1] < 1e-12 && (x[2] - 0.5).abs() < 1e-10);
    }

    #[test]
    fn power_laws_fit_within_tolerance_with_few_terms() {
        // The time limit is on the CPU time of this thread: the wall time of a test depends
        // on what else the machine runs (the tests run in parallel).
        let cpu = || {
            let mut t = libc::timespec {
                tv_sec: 0,
                tv_nsec: 0,
            };
            // SAFETY: clock_gettime writes the timespec it is given.
            unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) };
            t.tv_sec as f64 + 1e-9 * t.tv_nsec as f64
        };
        for alpha in [0.2, 0.5, 0.8] {
            let lags = power_law(alpha, 1_000_000);
            let start = cpu();
            let fit = fit(&lags, 1e-10).unwrap();
            let seconds = cpu() - start;
            let check = deviation(&lags, &fit.terms)
                .iter()
                .fold(0.0f64, |m, e| m.max(*e));
            assert!(fit.error <= 1e-10 && check == fit.error * lags.scale());
            assert!(fit.terms.len() <= 80, "{alpha}: {} terms", fit.terms.len());
            assert!(fit.terms.iter().all(|&(a, b)| a > 0.0 && b >= 0.0));
            assert!(seconds < 1.0, "{alpha}: {seconds} s of CPU");
        }
    }

    #[test]
    fn exponentials_off_the_grid_are_recovered_to_round_off() {
        let on_lags = |r: &dyn Fn(f64) -> f64| Lags {
            k: 1.0 / 32.0,
            with_zero: false,
            r: (1..=4096).map(|l| r(l as f64 / 32.0)).collect(),
        };
        let cases: [(&dyn Fn(f64) -> f64, usize); 3] = [
            (&|s: f64| (-s).exp(), 2),
            (&|s: f64| 100.0 * (-s).exp(), 2),
            (&|s: f64| (-s).exp() + 0.1 * (-0.01 * s).exp(), 4),
        ];
        for (i, (r, most)) in cases.into_iter().enumerate() {
            let fit = fit(&on_lags(r), 1e-12).unwrap();
            assert!(fit.terms.len() <= most, "case {i}: {:?}", fit.terms);
        }
        // Stretched exponentials exp(−(s/τ)^β) are completely monotone: they fit too.
        for (tau, beta) in [(0.5, 0.3), (2.0, 0.5)] {
            let lags = on_lags(&|s: f64| (-(s / tau).powf(beta)).exp());
            assert!(fit(&lags, 1e-10).unwrap().error <= 1e-10);
        }
    }

    #[test]
    fn shapes_no_positive_sum_follows_are_named() {
        let sign = Lags {
            k: 0.1,
            with_zero: false,
            r: (1..100).map(|l| (0.3 * l as f64).cos()).collect(),
        };
        assert!(fit(&sign, 1e-10).unwrap_err().contains("negative"));
        let bump = Lags {
            k: 0.1,
            with_zero: false,
            r: (1..100).map(|l| 2.0 + (0.3 * l as f64).cos()).collect(),
        };
        assert!(fit(&bump, 1e-10).unwrap_err().contains("grows"));
    }
}
