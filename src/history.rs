//! The two history sums of (3.1), by the left endpoint rule:
//!
//!   u_n = u_0 + k Σ_{j<n} w_j                    (displacement, "first sum")
//!   m_n = k Σ_{j<n} r(t_n − t_j) u_j             (memory, "second sum"; R(s) = r(s)·I)
//!
//! u_n is accumulated with Neumaier's compensated summation, so that it does not drift over
//! 10^5..10^6 steps. For a Prony kernel r(s) = Σ a_i e^{−b_i s} each term keeps its own state
//! m^(i)_n = k Σ_{j<n} e^{−b_i (t_n − t_j)} u_j, updated exactly in O(1) per step by
//! m^(i)_{n+1} = e^{−b_i k} (m^(i)_n + k u_n); m_n = Σ a_i m^(i)_n. Any other kernel (an
//! expression or a table) is by default compressed to a certified sum of exponentials
//! (`kernel_fit`) and then runs the same recursion; with `memory = "exact"`, or when it
//! cannot be fitted within its tolerance and the run has at most `kernel_fit::EXACT_STEPS`
//! steps, it keeps u_0..u_{n−1} and evaluates the direct sum, O(n) per step. A longer run
//! whose kernel misses its tolerance is refused (bad input naming the tolerance the fit
//! reached), never silently run in O(N²). t_n − t_j is taken as (n − j)·k exactly.

use crate::kernel::Kernel;
use crate::kernel_fit::{self, Fit, Lags};
use crate::scene::{self, Scene};
use crate::Result;

/// One Prony term a e^{−b s}: its weight, its one-step decay e^{−b k}, its state m^(i)_n.
#[derive(Clone, Debug)]
pub struct PronyTerm {
    pub a: f64,
    pub decay: f64,
    pub m: Vec<f64>,
}

/// The memory state of the scheme.
#[derive(Clone, Debug)]
pub enum Memory {
    /// No relaxation term (Remark 2.5: no memory state at all).
    None,
    Prony(Vec<PronyTerm>),
    /// r(l·k) for l = 1, 2, … (grown as needed) and the past displacements u_0..u_{n−1}.
    Direct {
        r_lag: Vec<f64>,
        past: Vec<Vec<f64>>,
    },
}

/// The memory a checkpoint holds, as [`Plan::resumed`] needs it.
pub enum Stored {
    /// The Prony terms (a_i, b_i) the run's recursion used.
    Terms(Vec<(f64, f64)>),
    /// The past displacements of the direct sum (or no memory at all).
    Direct,
}

/// How a run computes its memory sum, decided at setup from the scene (before any step).
#[derive(Clone, Debug)]
pub enum Plan {
    None,
    /// The scene's own Prony series.
    Prony(Vec<(f64, f64)>),
    /// An expression or table compressed to a certified Prony series.
    Compressed(Fit),
    /// The direct sum over r on the lags; `fallback` says why compression was not used when
    /// it was asked for (None: `memory = "exact"`).
    Exact {
        lags: Lags,
        fallback: Option<String>,
    },
}

impl Plan {
    /// Evaluates an expression or table kernel on every lag the run reads (r(k)..r(Nk), and
    /// r(0) for the implicit variant; a compressed kernel up to its horizon) — a non-finite
    /// value is bad input naming the key — and fits it when the scene asks for compression.
    pub fn new(scene: &Scene) -> Result<Plan> {
        let Some((lags, tolerance)) = Self::lags(scene)? else {
            return Ok(Self::fixed(scene));
        };
        Ok(match tolerance {
            None => Self::exact(lags, scene, None),
            Some(tolerance) => match kernel_fit::fit(&lags, tolerance) {
                Ok(fit) => Plan::Compressed(fit),
                Err(why) if scene.time.steps > kernel_fit::EXACT_STEPS => {
                    return Err(crate::Error::input(format!(
                        "{}: key 'material.relaxation.tolerance': the kernel cannot be \
                         compressed within {tolerance:e}: {why}. It is not run by the direct \
                         sum instead: its time.steps = {} exceed {} (the direct sum keeps \
                         every step's displacement, 8·dofs·N bytes, and takes O(N²·dofs) \
                         time); memory = \"exact\" runs it anyway",
                        scene.path.display(),
                        scene.time.steps,
                        kernel_fit::EXACT_STEPS
                    )))
                }
                Err(why) => Self::exact(lags, scene, Some(why)),
            },
        })
    }

    /// The plan of a run resumed from a checkpoint whose memory is `stored`: the memory the
    /// run started with, whatever the end time now. A compressed run continues with its own
    /// fit (the term states belong to it; nothing is stored to refit from), certified again on
    /// every lag up to the scene's end — the same lags without `--set time.end`, more with it.
    /// Where the fit leaves the tolerance on the new lags the resume is refused, naming the
    /// latest end time it still covers. A run that kept its past displacements continues the
    /// direct sum.
    pub fn resumed(scene: &Scene, stored: Stored) -> Result<Plan> {
        let Some((lags, tolerance)) = Self::lags(scene)? else {
            return Ok(Self::fixed(scene));
        };
        Ok(match (tolerance, stored) {
            (Some(tolerance), Stored::Terms(terms)) => {
                let start = std::time::Instant::now();
                let (error, within) = kernel_fit::certify(&lags, &terms, tolerance);
                if error > tolerance {
                    let t_ok = within.map_or(0.0, |l| l as f64 * lags.k);
                    return Err(crate::Error::input(format!(
                        "cannot continue this compressed run to T = {}: its kernel fit ({} \
                         terms, fitted on the lags of the run as it started) is off by {error:.2e} \
                         (relative) on the lags up to T, above the tolerance {tolerance:e}, and \
                         the checkpoint keeps no past displacements to fit again from. The fit \
                         holds up to t = {t_ok}: resume with --set time.end ≤ {t_ok}, or run \
                         the scene again from the start with [material.relaxation] horizon = \
                         {} (the latest end time its fit must cover)",
                        scene.time.end,
                        terms.len(),
                        scene.time.end
                    )));
                }
                Plan::Compressed(Fit {
                    terms,
                    error,
                    last_lag: lags.last(),
                    seconds: start.elapsed().as_secs_f64(),
                })
            }
            (Some(_), Stored::Direct) => Self::exact(
                lags,
                scene,
                Some(
                    "the run used the direct sum from its start (its kernel was not fitted \
                     within the tolerance then); it continues with the stored past \
                     displacements"
                        .into(),
                ),
            ),
            // memory = "exact"; a checkpoint whose memory kind differs is refused when it
            // is restored.
            _ => Self::exact(lags, scene, None),
        })
    }

    /// The direct sum on the run's own lags (`lags` may reach further, to a fit's horizon).
    fn exact(mut lags: Lags, scene: &Scene, fallback: Option<String>) -> Plan {
        lags.truncate(scene.time.steps);
        Plan::Exact { lags, fallback }
    }

    /// The plan of a scene without relaxation or with its own Prony series.
    fn fixed(scene: &Scene) -> Plan {
        match &scene.physics.relaxation {
            Some(Kernel::Prony(terms)) => Plan::Prony(terms.clone()),
            _ => Plan::None,
        }
    }

    /// For an expression or table kernel: r on every lag the run reads, and the tolerance of
    /// its compression (None: `memory = "exact"`); None for the other kernels.
    fn lags(scene: &Scene) -> Result<Option<(Lags, Option<f64>)>> {
        let kernel = match &scene.physics.relaxation {
            None | Some(Kernel::Prony(_)) => return Ok(None),
            Some(kernel) => kernel,
        };
        let key = match kernel {
            Kernel::Table(..) => "material.relaxation.table",
            _ => "material.relaxation.expr",
        };
        let implicit = scene.solver.history == scene::History::Implicit;
        // A compressed kernel is fitted up to its horizon, which a resume may extend the run
        // to (the scene checks horizon ≥ time.end).
        let steps = match (scene.physics.compression, scene.physics.horizon) {
            (Some(_), Some(h)) => scene
                .time
                .steps
                .max((h / scene.time.k() - 1e-9).ceil() as usize),
            _ => scene.time.steps,
        };
        let lags = Lags::new(kernel, scene.time.k(), steps, implicit, key)
            .map_err(|e| crate::Error::input(format!("{}: {e}", scene.path.display())))?;
        Ok(Some((lags, scene.physics.compression)))
    }

    /// The Prony series the recursion runs, if any.
    pub fn prony(&self) -> Option<&[(f64, f64)]> {
        match self {
            Plan::Prony(terms) => Some(terms),
            Plan::Compressed(fit) => Some(&fit.terms),
            _ => None,
        }
    }

    /// r(0) as the run uses it (the implicit variant's newest memory weight).
    pub fn r0(&self, kernel: Option<&Kernel>) -> Option<f64> {
        match self {
            Plan::None => None,
            Plan::Compressed(fit) => Some(fit.terms.iter().map(|t| t.0).sum()),
            _ => kernel.map(|k| k.eval(0.0)),
        }
    }
}

/// A time loop at t_n, before step n is solved: its history and the last solved step's w
/// and multipliers (the next solve's warm start). What a checkpoint saves
/// (`TimeLoop::state`); everything else of the loop is rebuilt from the scene.
pub struct LoopState<'a> {
    pub history: &'a History,
    pub w: &'a [f64],
    /// The multipliers of the last solved step and of the step before it.
    pub z: &'a [f64],
    pub z_before: &'a [f64],
}

/// A [`LoopState`] as a checkpoint gives it back (`TimeLoop::restore`).
pub struct SavedLoop {
    pub history: SavedHistory,
    pub w: Vec<f64>,
    pub z: Vec<f64>,
    pub z_before: Vec<f64>,
}

/// A history as a checkpoint saved it, for [`History::restore`].
pub struct SavedHistory {
    pub n: usize,
    pub k: f64,
    pub u: Vec<f64>,
    pub u_sum: Vec<f64>,
    pub u_comp: Vec<f64>,
    pub memory: SavedMemory,
}

/// The memory state a checkpoint saved.
pub enum SavedMemory {
    None,
    /// The Prony terms with their weights, one-step decays and states.
    Prony(Vec<PronyTerm>),
    /// The past displacements u_0..u_{n−1} of the direct sum.
    Direct(Vec<Vec<f64>>),
}

/// Why a checkpoint's stored memory (`what` it is) cannot continue this scene's.
pub fn memory_mismatch(what: &str) -> String {
    format!(
        "the stored memory is {what}, which the scene's relaxation kernel does not match: \
         the checkpoint does not belong to this scene"
    )
}

/// The state carried from step to step: n, u_n (compensated) and the memory.
#[derive(Clone, Debug)]
pub struct History {
    pub k: f64,
    /// The current step index n: `u` holds u_n and `memory` gives m_n.
    pub n: usize,
    /// u_n = sum + compensation.
    pub u: Vec<f64>,
    /// Neumaier compensation of the running sum (the rounding error not yet in `u_sum`).
    pub u_comp: Vec<f64>,
    pub u_sum: Vec<f64>,
    pub memory: Memory,
}

impl History {
    /// The state at n = 0: u_0 = 0 (the paper's example; the initial displacement is zero)
    /// and m_0 = 0.
    pub fn new(n_free: usize, k: f64, plan: &Plan) -> Self {
        let memory = match plan {
            Plan::None => Memory::None,
            Plan::Prony(terms) | Plan::Compressed(Fit { terms, .. }) => Memory::Prony(
                terms
                    .iter()
                    .map(|&(a, b)| PronyTerm {
                        a,
                        decay: (-b * k).exp(),
                        m: vec![0.0; n_free],
                    })
                    .collect(),
            ),
            Plan::Exact { .. } => Memory::Direct {
                r_lag: Vec::new(),
                past: Vec::new(),
            },
        };
        History {
            k,
            n: 0,
            u: vec![0.0; n_free],
            u_comp: vec![0.0; n_free],
            u_sum: vec![0.0; n_free],
            memory,
        }
    }

    pub fn has_memory(&self) -> bool {
        !matches!(self.memory, Memory::None)
    }

    /// m_n into `out` (overwritten). Returns false (and leaves `out` alone) without memory.
    pub fn memory_into(&mut self, kernel: Option<&Kernel>, out: &mut [f64]) -> bool {
        match &mut self.memory {
            Memory::None => false,
            Memory::Prony(terms) => {
                out.fill(0.0);
                for term in terms.iter() {
                    for (o, m) in out.iter_mut().zip(&term.m) {
                        *o += term.a * m;
                    }
                }
                true
            }
            Memory::Direct { r_lag, past } => {
                let kernel = kernel.expect("a direct-sum memory has a kernel");
                let n = self.n;
                while r_lag.len() < n {
                    let l = r_lag.len() + 1;
                    r_lag.push(kernel.eval(l as f64 * self.k));
                }
                out.fill(0.0);
                // m_n = k Σ_{j<n} r((n − j) k) u_j
                for (j, uj) in past.iter().enumerate() {
                    let c = self.k * r_lag[n - j - 1];
                    for (o, u) in out.iter_mut().zip(uj) {
                        *o += c * u;
                    }
                }
                true
            }
        }
    }

    /// Takes back a saved history into this one, freshly built from the same scene (a
    /// resume): the memory must be of the kind this one plans, with the same Prony weights
    /// and, up to the rounding of e^{−b k}, the same decays.
    pub fn restore(&mut self, saved: SavedHistory) -> Result<()> {
        let mismatch = |what: &str| crate::Error::input(memory_mismatch(what));
        match (&mut self.memory, saved.memory) {
            (Memory::None, SavedMemory::None) => {}
            (Memory::Prony(terms), SavedMemory::Prony(stored)) => {
                if terms.len() != stored.len() {
                    return Err(mismatch(&format!("{} Prony terms", stored.len())));
                }
                for (i, (t, s)) in terms.iter_mut().zip(stored).enumerate() {
                    // decay = exp(−b k) is recomputed by History::new from the scene's b and
                    // the same k: equal bits unless the kernel changed.
                    let expected = (t.decay.ln() / self.k) * saved.k;
                    if t.a.to_bits() != s.a.to_bits()
                        || (expected.exp() - s.decay).abs() > 1e-12 * s.decay.abs()
                    {
                        return Err(mismatch(&format!(
                            "term {i}: a = {}, exp(-b k) = {}",
                            s.a, s.decay
                        )));
                    }
                    if s.m.len() != t.m.len() {
                        return Err(mismatch(&format!("term {i} of the wrong size")));
                    }
                    *t = s;
                }
            }
            (Memory::Direct { past, r_lag }, SavedMemory::Direct(rows)) => {
                *past = rows;
                r_lag.clear();
            }
            (_, SavedMemory::None) => return Err(mismatch("absent (no relaxation)")),
            (_, SavedMemory::Prony(_)) => return Err(mismatch("a Prony series")),
            (_, SavedMemory::Direct(_)) => return Err(mismatch("a general kernel's direct sum")),
        }
        self.k = saved.k;
        self.n = saved.n;
        self.u = saved.u;
        self.u_sum = saved.u_sum;
        self.u_comp = saved.u_comp;
        Ok(())
    }

    /// n → n + 1 with the velocity w_n: u_{n+1} = u_n + k w_n, and the memory update.
    pub fn advance(&mut self, w: &[f64]) {
        let k = self.k;
        // The memory of step n + 1 uses u_n, so update it before u.
        match &mut self.memory {
            Memory::None => {}
            Memory::Prony(terms) => {
                for term in terms.iter_mut() {
                    // m^(i)_{n+1} = e^{−b_i k} (m^(i)_n + k u_n)
                    for (m, u) in term.m.iter_mut().zip(&self.u) {
                        *m = term.decay * (*m + k * u);
                    }
                }
            }
            Memory::Direct { past, .. } => past.push(self.u.clone()),
        }
        let state = self
            .u
            .iter_mut()
            .zip(self.u_sum.iter_mut().zip(&mut self.u_comp));
        for ((u, (sum, comp)), wi) in state.zip(w) {
            // Neumaier: add k w_i to (sum, comp) without losing the low-order bits.
            let x = k * wi;
            let t = *sum + x;
            *comp += if sum.abs() >= x.abs() {
                (*sum - t) + x
            } else {
                (x - t) + *sum
            };
            *sum = t;
            *u = t + *comp;
        }
        self.n += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prony_recursion_equals_direct_sum() {
        let k = 0.01;
        let prony = Kernel::Prony(vec![(1.0, 10.0), (0.5, 3.0)]);
        let table_like = Kernel::Expr(Box::new(
            crate::expr::Expr::parse("exp(-10*s) + 0.5*exp(-3*s)", &["s"], "r").unwrap(),
        ));
        let mut hp = History::new(3, k, &Plan::Prony(vec![(1.0, 10.0), (0.5, 3.0)]));
        let exact = Plan::Exact {
            lags: Lags::new(&table_like, k, 200, false, "r").unwrap(),
            fallback: None,
        };
        let mut hd = History::new(3, k, &exact);
        let (mut mp, mut md) = (vec![0.0; 3], vec![0.0; 3]);
        for n in 0..200 {
            let w = [(n as f64 * 0.1).sin(), 1.0, -0.5 * n as f64];
            assert!(hp.memory_into(Some(&prony), &mut mp));
            assert!(hd.memory_into(Some(&table_like), &mut md));
            for i in 0..3 {
                let scale = md[i].abs().max(1e-300);
                assert!(
                    (mp[i] - md[i]).abs() <= 1e-12 * scale.max(1e-12),
                    "n={n} {mp:?} {md:?}"
                );
            }
            hp.advance(&w);
            hd.advance(&w);
        }
    }

    #[test]
    fn compensated_sum_is_exact_for_constant_velocity() {
        // k = 0.1 is not a binary fraction: plain summation of 10^5 terms drifts visibly.
        let (k, n) = (0.1, 100_000);
        let mut h = History::new(1, k, &Plan::None);
        let mut plain = 0.0f64;
        for _ in 0..n {
            h.advance(&[1.0]);
            plain += k;
        }
        let exact = 10_000.0;
        assert!(
            (h.u[0] - exact).abs() <= 2.0 * f64::EPSILON * exact,
            "{}",
            h.u[0]
        );
        assert!(
            (plain - exact).abs() > 1e3 * f64::EPSILON * exact,
            "{plain}"
        );
    }
}
