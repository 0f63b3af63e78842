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
//! # Method (chosen by measurement, see docs/memory.md)
//!
//! A fixed geometric grid of rates b_j, `PER_DECADE` per decade from 40/k down to
//! 1e-8/T (T the last lag's time), plus the constant b = 0, and non-negative least squares
//! weights (Lawson–Hanson, in double-double arithmetic: `nnls`) on a sample of the lags:
//! every lag up to 64, then lags growing by 3 %, and the last. NNLS adds rates greedily and
//! stops once the error on the sample is `TARGET` of the tolerance, so the sum is as short
//! as the tolerance allows; the zero weights are dropped. If the certified error on all lags
//! is above the tolerance, the lags where the error peaks are added to the sample, the grid
//! is bisected around every active rate (the base grid stays), and the fit is repeated, at
//! most `ROUNDS` times and until two rounds in a row fail to halve the best error. A fit
//! of at most `POLISH_TERMS` terms that still misses has its rates freed
//! (Levenberg–Marquardt, `polish`): a single exponential e^{−bs} needs its own rate, which
//! no grid holds.
//!
//! Why a grid reaches 1e-13: for s^(−α) = Γ(α)^{−1} ∫ e^{−s eˣ + αx} dx the trapezoid rule
//! in x = ln b with 7 nodes per decade (step h = ln 10/7) has error ~e^{−π²/h} ≈ 1e-13
//! relative (Beylkin and Monzón 2005, 2010), and its weights are positive: the grid holds a
//! positive sum that good, and NNLS finds one at least as good on the sample. The grid
//! reaches 1e-8/T (not 1e-4/T) because the mass of a flat kernel's spectrum below it, folded
//! into the constant, errs by its curvature: (s + 1)^(−0.1) missed 1e-10 with the grid ending
//! at 1e-4/T. Why not that rule itself: it needs the kernel's inverse Laplace transform,
//! which an expression or a table does not give; NNLS needs only values and works for
//! tables, stretched exponentials and sums alike. Why double-double: in f64 the active set
//! method stops at 4e-11 on the same grids (the gradients that would still lower the error
//! drown in the weights' rounding, `nnls`). Positive weights keep r̃ completely monotone like
//! the kernels users have; signed weights are never used.
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

mod dd;
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

/// `[material.relaxation] tolerance` when the scene gives none: the fit meets it on
/// completely monotone kernels (power laws, stretched exponentials, their sums) over up to
/// 10^6 lags and more (docs/memory.md), with a margin of about 4.
pub const DEFAULT_TOLERANCE: f64 = 1e-12;

/// Refinement rounds after the first fit.
const ROUNDS: usize = 16;

/// Candidate rates beyond which refinement stops (each NNLS gradient is O(rows·rates)).
const MAX_RATES: usize = 400;

/// Rates per decade of the grid: the trapezoid rule in ln b at this density is good to
/// ~1e-13 on power laws (module doc).
const PER_DECADE: f64 = 7.0;

/// NNLS stops once its error on the sample is this fraction of the tolerance: between the
/// sampled lags the error was measured up to 3.8× larger (0.95(s + 1)^(−0.95), k = 1e-3).
const TARGET: f64 = 0.25;

/// The most terms of a fit whose rates are freed when the grid misses (each
/// Levenberg–Marquardt step is a dense solve in twice as many unknowns).
const POLISH_TERMS: usize = 8;

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
    let (mut terms, mut error) = attempt(lags, tolerance, scale);
    if error > tolerance && terms.len() <= POLISH_TERMS {
        (terms, error) = polished(lags, tolerance, scale, terms, error);
    }
    if error > tolerance {
        return Err(format!(
            "the best sum of exponentials with positive weights reaches a relative error of \
             {error:.2e} on the lags, above the tolerance {tolerance:e} (this method reaches \
             about 1e-13 on completely monotone kernels such as power laws and stretched \
             exponentials; a kinked table or a kernel that is not completely monotone stops \
             earlier): set [material.relaxation] tolerance ≥ {:.0e} to compress it, or \
             memory = \"exact\"",
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

/// NNLS on the grid, certificate, and refinement rounds (module doc); the best (terms,
/// certified error) seen.
fn attempt(lags: &Lags, tolerance: f64, scale: f64) -> (Vec<(f64, f64)>, f64) {
    let base = grid(lags.k, lags.last() as f64 * lags.k);
    let mut rows = sample(lags);
    let mut rates = base.clone();
    let mut best: Option<(Vec<(f64, f64)>, f64)> = None;
    let mut stalled = 0;
    for _ in 0..=ROUNDS {
        let target = TARGET * tolerance * scale;
        let weights = nnls(&design(lags, &rows, &rates), &values(lags, &rows), target);
        let terms: Vec<(f64, f64)> = weights
            .iter()
            .zip(&rates)
            .filter(|(a, _)| **a > 0.0)
            .map(|(&a, &b)| (a, b))
            .collect();
        let errors = deviation(lags, &terms);
        let error = errors.iter().fold(0.0f64, |m, e| m.max(*e)) / scale;
        match &best {
            Some((_, e)) if error >= 0.5 * e => stalled += 1,
            _ => stalled = 0,
        }
        if best.as_ref().is_none_or(|(_, e)| error < *e) {
            best = Some((terms, error));
        }
        if error <= tolerance || stalled == 2 {
            break;
        }
        rows = refined(&rows, &errors);
        rates = bisected(&rates, &weights, &base);
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
/// other rates matches e^{−bs} only to the order of the mixture's spread. The base grid
/// stays: a rate no round used may be needed once the others are placed (exp(−(s/τ)^0.9)
/// stopped at 5e-12 when the rates above 100/τ had been dropped).
fn bisected(rates: &[f64], weights: &[f64], base: &[f64]) -> Vec<f64> {
    let mut out = base.to_vec();
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

/// The rate grid: 40/k (e^{−40} at the first lag) down to 1e-8/T by the factor
/// 10^{−1/PER_DECADE}, then b = 0.
fn grid(k: f64, t: f64) -> Vec<f64> {
    let (hi, lo) = (40.0 / k, 1e-8 / t);
    let q = 10f64.powf(-1.0 / PER_DECADE);
    let count = ((hi / lo).log10() * PER_DECADE).ceil() as i32;
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
        let x = nnls(&design(&lags, &rows, &rates), &values(&lags, &rows), 0.0);
        assert!((x[0] - 3.0).abs() < 1e-10 && x[1] < 1e-12 && (x[2] - 0.5).abs() < 1e-10);
    }

    /// The CPU time of this thread: the wall time of a test depends on what else the machine
    /// runs (the tests run in parallel).
    fn cpu() -> f64 {
        let mut t = libc::timespec {
            tv_sec: 0,
            tv_nsec: 0,
        };
        // SAFETY: clock_gettime writes the timespec it is given.
        unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) };
        t.tv_sec as f64 + 1e-9 * t.tv_nsec as f64
    }

    /// r on the lags l·k, l = 1..10^6.
    fn million(k: f64, r: impl Fn(f64) -> f64) -> Lags {
        Lags {
            k,
            with_zero: false,
            r: (1..=1_000_000).map(|l| r(l as f64 * k)).collect(),
        }
    }

    /// Fits at the default tolerance 1e-12 within 30 s of CPU (generous: about 1 s here) and
    /// checks the certificate independently, with exp on every lag.
    fn fits_to_1e_12(name: &str, lags: &Lags) {
        let start = cpu();
        let fit = fit(lags, 1e-12).unwrap_or_else(|e| panic!("{name}: {e}"));
        let seconds = cpu() - start;
        let worst = lags
            .r
            .iter()
            .enumerate()
            .map(|(i, r)| {
                let l = lags.lag(i) as f64;
                let fitted: f64 = fit
                    .terms
                    .iter()
                    .map(|&(a, b)| a * (l * log_decay(b, lags.k)).exp())
                    .sum();
                (fitted - r).abs()
            })
            .fold(0.0f64, f64::max)
            / lags.scale();
        assert!(fit.error <= 1e-12, "{name}: {:e}", fit.error);
        assert!(worst <= 1.01e-12, "{name}: independent max error {worst:e}");
        assert!(fit.terms.len() <= 80, "{name}: {} terms", fit.terms.len());
        assert!(fit.terms.iter().all(|&(a, b)| a > 0.0 && b >= 0.0));
        assert!(seconds < 30.0, "{name}: {seconds} s of CPU");
        println!(
            "{name}: {} terms, certified {:.2e}, {seconds:.2} s of CPU",
            fit.terms.len(),
            fit.error
        );
    }

    #[test]
    fn power_laws_reach_1e_12_on_a_million_lags() {
        fits_to_1e_12("s^-0.3", &million(1.0, |s| s.powf(-0.3)));
        fits_to_1e_12(
            "0.2(s+0.01)^-0.5",
            &million(1e-4, |s| 0.2 * (s + 0.01).powf(-0.5)),
        );
        fits_to_1e_12("(s+1)^-0.1", &million(1.0 / 32.0, |s| (s + 1.0).powf(-0.1)));
        fits_to_1e_12(
            "(s+1e-3)^-0.9",
            &million(1.0 / 32.0, |s| (s + 1e-3).powf(-0.9)),
        );
    }

    #[test]
    fn stretched_exponentials_reach_1e_12_on_a_million_lags() {
        for (tau, beta) in [(0.5, 0.3), (100.0, 0.9)] {
            let lags = million(1.0 / 32.0, |s| (-(s / tau).powf(beta)).exp());
            fits_to_1e_12(&format!("exp(-(s/{tau})^{beta})"), &lags);
        }
    }

    #[test]
    fn a_sum_reaches_1e_12_on_a_million_lags() {
        let r = |s: f64| {
            0.2 * (s + 0.01).powf(-0.5) + (-(s / 3.0).powf(0.6)).exp() + 0.1 * (-0.5 * s).exp()
        };
        fits_to_1e_12("sum", &million(1.0 / 32.0, r));
    }

    #[test]
    fn a_table_reaches_1e_12_on_a_million_lags() {
        // Relaxation data at every lag, and r(0): the implicit variant reads it.
        let k = 1.0 / 32.0;
        let s: Vec<f64> = (0..=1_000_000).map(|l| l as f64 * k).collect();
        let r = s.iter().map(|s| 0.3 * (s + 0.005).powf(-0.7)).collect();
        let lags = Lags::new(&Kernel::Table(s, r), k, 1_000_000, true, "r").unwrap();
        fits_to_1e_12("table", &lags);
    }

    #[test]
    fn a_kinked_table_is_refused_in_seconds_naming_the_tolerance_that_compresses() {
        // s^(−1/2) through 200 points from 0.01 to 10^5: linear between them, so no positive
        // sum of exponentials follows it closer than the kinks allow (~1e-4).
        let s: Vec<f64> = (0..200)
            .map(|i| 10f64.powf(-2.0 + 7.0 * i as f64 / 199.0))
            .collect();
        let r = s.iter().map(|s| s.powf(-0.5)).collect();
        let lags = Lags::new(&Kernel::Table(s, r), 1.0 / 32.0, 1_000_000, false, "r").unwrap();
        let start = cpu();
        let why = fit(&lags, 1e-12).unwrap_err();
        let seconds = cpu() - start;
        assert!(why.contains("tolerance ≥ 1e-4"), "{why}");
        assert!(seconds < 20.0, "{seconds} s of CPU to refuse");
        println!("kinked table refused in {seconds:.2} s of CPU: {why}");
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
