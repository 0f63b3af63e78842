//! The time loop of Problem 3.1: for n = 0, 1, …, N form b_n from the history and solve the
//! step problem for w_n, then advance u and m. A run is `TimeLoop::new` (setup: factor K_A
//! once, build the step solver) followed by `solve_step` / `advance` pairs; whoever drives
//! it (the `run` command, a test, an example) consumes each solved step.
//!
//! # The implicit variant (`[scheme] history = "implicit"`)
//!
//! The paper's scheme (3.1) treats the elastic and memory terms explicitly: they act on
//! u_n = u_0 + kΣ_{j<n} w_j, built from past velocities only. For 2θε' + Eε = f that is
//! forward Euler, stable only for k ≤ 4θ/E (see `stability`). The implicit variant evaluates
//! the elastic term at the end of the step, u_{n+1} = u_n + k w_n, and adds the newest memory
//! weight, the interval [t_n, t_{n+1}] weighted by r(0), to the memory sum:
//!
//!   (Aε(w_n) + Bε(u_n + k w_n) + ε(m_n) + k r(0) ε(k w_n), ε(v − w_n))
//!       + ∫_{Γ3,2} [F(v_ν − w_{n,ν}) + μF(|v_τ| − |w_{n,τ}|)] ≥ ⟨f_n, v − w_n⟩   ∀v ∈ K^h,
//!
//! i.e. the step problem with the constant matrix K_A + k K_B + k² r(0) K_R (factored once)
//! and the same right side b_n = f_n − K_B u_n − K_R m_n − g_F. The added terms are k(Bε(w_n))
//! and k² r(0) ε(w_n): O(k) perturbations of a first-order scheme, so the variant stays first
//! order in k. For the scalar model the step is ε_{n+1} = ε_n + k(f − Eε_n)/(2θ + kE) with
//! amplification 2θ/(2θ + kE) ∈ (0, 1]: unconditionally stable, and for θ → 0 it gives the
//! elastic response ε_{n+1} = f/E.

use crate::effects::{self, Effects};
use crate::fem::{mul_add, Discretization};
use crate::history::{History, Plan};
use crate::scene::{self, Scene};
use crate::solver::{Factor, Rows, StepReport, StepSolver};
use crate::stability::Verdict;
use crate::{Error, Result};

pub struct TimeLoop<'p> {
    pub scene: &'p Scene,
    pub disc: &'p Discretization,
    pub effects: Effects,
    pub factor: Factor,
    pub solver: StepSolver,
    pub rows: Rows,
    pub history: History,
    /// How the memory sum is computed (the compressed kernel's fit, if any).
    pub plan: Plan,
    /// w_n of the last solved step.
    pub w: Vec<f64>,
    /// Multipliers of the last solved step: λ on contact rows, γ on friction rows.
    pub z: Vec<f64>,
    /// m_n of the last solved step (empty without memory).
    pub m: Vec<f64>,
    b: Vec<f64>,
    /// max|u_n| at the last solved step and how many steps in a row it has doubled.
    last_u: f64,
    doublings: usize,
}

/// Consecutive doublings of max|u_n| taken as growth without bound (a factor 2^40 ≈ 10^12
/// in 40 steps: no load ramp does that, an unstable recursion does).
const DIVERGED_AFTER: usize = 40;

/// A solved step n: t_n, u_n (displacement), w_n (velocity), m_n, multipliers.
pub struct Step<'a> {
    pub n: usize,
    pub t: f64,
    pub u: &'a [f64],
    pub w: &'a [f64],
    pub m: Option<&'a [f64]>,
    pub z: &'a [f64],
    pub report: StepReport,
}

impl<'p> TimeLoop<'p> {
    pub fn new(scene: &'p Scene, disc: &'p Discretization) -> Result<Self> {
        let effects = Effects::new(scene, disc);
        let rows = Rows::new(&disc.contact, &disc.friction, disc.dim - 1);
        let plan = Plan::new(scene)?;
        let implicit = match scene.history {
            scene::History::Left => {
                // Refuses a step beyond the scheme's stability limit (exit 2).
                Verdict::new(scene, disc, &plan).check(scene)?;
                None
            }
            scene::History::Implicit => {
                Some(disc.implicit_matrix(scene.k(), plan.r0(scene.relaxation.as_ref())))
            }
        };
        let matrix = implicit.as_ref().unwrap_or(&disc.k_a);
        // The step matrix is factored once, with the constrained boundary dofs ordered last.
        let factor = Factor::new(matrix, &rows.dofs())?;
        let solver = effects::step_solver(&effects, scene, matrix, &factor, &rows)?;
        let n = disc.n_free;
        let history = History::new(n, scene.k(), &plan);
        let m = if history.has_memory() {
            vec![0.0; n]
        } else {
            Vec::new()
        };
        Ok(TimeLoop {
            scene,
            disc,
            effects,
            factor,
            solver,
            z: vec![0.0; rows.len()],
            rows,
            history,
            plan,
            w: vec![0.0; n],
            m,
            b: vec![0.0; n],
            last_u: 0.0,
            doublings: 0,
        })
    }

    /// The index n of the next step to solve.
    pub fn n(&self) -> usize {
        self.history.n
    }

    /// t_n = n k.
    pub fn time(&self) -> f64 {
        self.history.n as f64 * self.history.k
    }

    /// Solves (3.1) at the current n: b_n = f_n − K_B u_n − K_R m_n − g_F, then w_n.
    pub fn solve_step(&mut self) -> Result<Step<'_>> {
        let t = self.time();
        let h = &mut self.history;
        self.b.fill(0.0);
        self.disc
            .loads
            .add(t, &self.disc.free, self.scene, &mut self.b)?;
        if let Some(k_b) = &self.disc.k_b {
            mul_add(k_b, &h.u, -1.0, &mut self.b);
        }
        if h.memory_into(self.scene.relaxation.as_ref(), &mut self.m) {
            mul_add(&self.disc.k_r, &self.m, -1.0, &mut self.b);
        }
        for (b, g) in self.b.iter_mut().zip(&self.disc.g_f) {
            *b -= g;
        }
        let report =
            self.solver
                .solve(&self.factor, &self.rows, &self.b, &mut self.w, &mut self.z)?;
        // Divergence detector: a non-finite velocity, or max|u_n| doubling step after step.
        let u_max = h.u.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        self.doublings = if u_max > 2.0 * self.last_u && self.last_u > 0.0 {
            self.doublings + 1
        } else {
            0
        };
        self.last_u = u_max;
        if self.w.iter().any(|v| !v.is_finite()) || self.doublings >= DIVERGED_AFTER {
            return Err(Error::solve(format!(
                "the solution grows without bound at step {}, t = {t}: max|u| = {u_max:e} \
                 doubled {} steps in a row; the step k = {} is too large for the explicit \
                 scheme: use more time steps or [scheme] history = \"implicit\"",
                h.n, self.doublings, h.k
            )));
        }
        Ok(Step {
            n: h.n,
            t,
            u: &h.u,
            w: &self.w,
            m: if self.m.is_empty() {
                None
            } else {
                Some(&self.m)
            },
            z: &self.z,
            report,
        })
    }

    /// n → n + 1: u_{n+1} = u_n + k w_n and the memory update.
    pub fn advance(&mut self) {
        self.history.advance(&self.w);
    }
}
