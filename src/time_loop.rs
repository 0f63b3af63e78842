//! The time loop of Problem 3.1: for n = 0, 1, …, N form b_n from the history and solve the
//! step problem for w_n, then advance u and m. A run is `TimeLoop::new` (setup: factor K_A
//! once, build the step solver) followed by `solve_step` / `advance` pairs; whoever drives
//! it (the `run` command, a test, an example) consumes each solved step.

use crate::effects::{self, Effects};
use crate::fem::{mul_add, Discretization};
use crate::history::History;
use crate::scene::Scene;
use crate::solver::{Factor, Rows, StepReport, StepSolver};
use crate::Result;

pub struct TimeLoop<'p> {
    pub scene: &'p Scene,
    pub disc: &'p Discretization,
    pub effects: Effects,
    pub factor: Factor,
    pub solver: StepSolver,
    pub rows: Rows,
    pub history: History,
    /// w_n of the last solved step.
    pub w: Vec<f64>,
    /// Multipliers of the last solved step: λ on contact rows, γ on friction rows.
    pub z: Vec<f64>,
    /// m_n of the last solved step (empty without memory).
    pub m: Vec<f64>,
    b: Vec<f64>,
}

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
        let rows = Rows::new(&disc.contact, &disc.friction);
        // K_A is factored once, with the constrained boundary dofs ordered last.
        let factor = Factor::new(&disc.k_a, &rows.dofs())?;
        let solver = effects::step_solver(&effects, scene, disc, &factor, &rows)?;
        let n = disc.n_free;
        let history = History::new(n, scene.k(), scene.relaxation.as_ref());
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
            w: vec![0.0; n],
            m,
            b: vec![0.0; n],
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
