//! The time loop of Problem 3.1: for n = 0, 1, …, N form b_n from the history and solve the
//! step problem for w_n, then advance u and m. A run is `TimeLoop::new` (setup: the linear
//! backend of K_A, `solver::Backend` — factor it once, or where the run's solver
//! (`solver::choice::Descriptor`) says PETSc set up its Krylov method instead — and the step
//! solver) followed by [`TimeLoop::run`], the one driver of the steps:
//! it hands each solved step to an [`Observer`] (the `run` command's consumers, a study, a
//! test, a benchmark) and asks it whether to stop. [`TimeLoop::state`] and
//! [`TimeLoop::restore`] are the only way a checkpoint sees the loop.
//!
//! A step being solved can be given up ([`TimeLoop::abandon_on`], `solver::abandon`): the
//! loop then stands where it stood before the step, as after a stop after the previous one.
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

use std::borrow::Cow;

use crate::effects::{self, Effects};
use crate::fem::{
    constraints, leading_block, mul_add, mul_add_rows, Discretization, RowsPair, Sparse,
    SymmetricPair,
};
use crate::history::{HeldAt, History, Holds, LoopState, Plans, SavedLoop};
use crate::ranks::Own;
use crate::scene::{self, Scene};
use crate::solver::choice::{Build, Descriptor};
use crate::solver::{Abandon, Backend, Factor, Rows, StepAt, StepReport, StepSolver, StepStatus};
use crate::stability::Verdict;
use crate::{Error, Result};

pub struct TimeLoop<'p> {
    scene: &'p Scene,
    disc: &'p Discretization,
    effects: Effects,
    backend: Backend,
    solver: StepSolver,
    /// The run's solver as resolved from the scene (`solver::choice`).
    descriptor: Descriptor,
    rows: Rows,
    history: History,
    /// How the memory sums are computed (the compressed kernels' fits, if any).
    plans: Plans,
    /// w_n of the last solved step, and its unknowns kept while a step that can be given up
    /// is solved into w (a solver may leave an iterate there). On one of several MPI ranks
    /// whose history holds some dofs alone (`Holds::Local`), w_n and b_n are held at the
    /// dofs `held` alone; it keeps its own rows alone, the others coming back from the
    /// ranks that hold them (`Backend::keep`).
    w: Vec<f64>,
    w_start: Vec<f64>,
    /// Multipliers of the last solved step z_{n−1}: λ on contact rows, γ on friction rows;
    /// and of the step before it, z_{n−2} (z_{n−1} itself before a second step), for the
    /// warm start's extrapolation (`StepSolver::solve`); `spare` keeps z_{n−1} while step
    /// n is solved into z.
    z: Vec<f64>,
    z_before: Vec<f64>,
    spare: Vec<f64>,
    /// m_n of the last solved step, each memory group's after the other's (empty without
    /// memory).
    m: Vec<f64>,
    b: Vec<f64>,
    growth: Growth,
    /// K_B and the body's K_R (when both are used and share their pattern): K_B u_n + K_R
    /// m_n in one pass over their lower triangles.
    paired: Option<SymmetricPair>,
    /// On one of several MPI ranks, its rows of K_B and K_R^(0) where it makes them after
    /// PETSc's setup (`Discretization::own_pair_made`); else `disc.own_pair`'s are read.
    own_pair: Option<RowsPair>,
    /// On a follower rank whose history holds some dofs alone (`Holds::Local`), the dofs
    /// at which w_n and b_n are held, increasing (`held_at`): the history's, its own rows
    /// and Γ3's unknowns. `rows` numbers Γ3's dofs by their places there (`fem::place`),
    /// and PETSc reads and writes the solution there (`petsc::Reads::held`).
    held: Option<Vec<usize>>,
    /// On one of several MPI ranks, the places of its own rows (`Discretization::own`) in
    /// w and b, and g_F's dofs' there (all of `disc.g_f`'s elsewhere).
    own: Option<Cow<'p, [usize]>>,
    g_f: Cow<'p, [(usize, f64)]>,
    /// The step matrix on all n_dofs when there are prescribed dofs: its free-by-prescribed
    /// block moves their velocities to the right side (`fem::constraints`).
    lift: Option<Sparse>,
    /// The request that gives up a step, where the step solver honours one.
    abandon: Option<Abandon>,
    /// How many of a direct sum's past rows the checkpoints hold
    /// ([`TimeLoop::gather_memory`]).
    past_saved: usize,
    /// Whether the state at t_n follows a step this loop solved, so that a stop can save it
    /// (the last step's flags are the consumers'). Only then is a step given up: a new run
    /// would have nothing to resume from, and a resumed one, written into another directory,
    /// no checkpoint there.
    can_stop: bool,
}

/// The divergence detector. A stable run's displacement is bounded by its loads: with
/// q_n = max|u_n| / max_{j≤n} max|f_j − g_F| (the response per unit of the largest load so
/// far), creep under a constant load makes q grow like t_n, so q_n / q_j stays of the order
/// of n/j. An unstable recursion (the explicit scheme above its step limit, a kernel that
/// amplifies) grows geometrically, erratically or not. The run is stopped once q_n exceeds
/// `DIVERGED` times P_{j−1} = max_{i<j} q_i for j the largest power of two ≤ n/2: growth by 10^12
/// within the last three quarters of the run, which no load explains (the loads are divided
/// out) and which an amplification of 2 per step reaches in 40 steps, of 1.1 in 400, even
/// when it is interrupted by steps that shrink (56 doublings in 98 steps, never 40 in a
/// row, went unnoticed by a count of consecutive doublings). P is kept at powers of two
/// only: O(log n) memory.
#[derive(Default)]
struct Growth {
    /// max_{j≤n} max|f_j − g_F|.
    load: f64,
    /// max_{i≤n} q_i.
    running: f64,
    /// P_{j−1} at j = 1, 2, 4, 8, …
    at_powers: Vec<f64>,
}

/// The growth of q that stops a run (≈ 2^40).
const DIVERGED: f64 = 1e12;

impl Growth {
    /// Records step n; returns q_n / P_j when that exceeds `DIVERGED`.
    fn record(&mut self, n: usize, u_max: f64, load_max: f64) -> Option<f64> {
        self.load = self.load.max(load_max);
        let q = if self.load > 0.0 {
            u_max / self.load
        } else {
            0.0
        };
        if n.is_power_of_two() {
            self.at_powers.push(self.running);
        }
        self.running = self.running.max(q);
        // Index i of `at_powers` holds P_{j−1} for j = 2^i (pushed at n = j before q_j).
        let reference = (n / 2)
            .checked_ilog2()
            .and_then(|i| self.at_powers.get(i as usize).copied())
            .filter(|&p| p > 0.0)?;
        (q > DIVERGED * reference).then_some(q / reference)
    }
}

/// A solved step's n·w on Γ3,1 may exceed 0 by this much relative to the run's velocity
/// scale, the larger of max|w_n| and the mean velocity max|u_n|/t_n (the solvers stop at
/// 1e-12 relative KKT residuals); more means the solve cannot be trusted. max|w_n| alone is
/// not a scale late in a long creep: w_n tends to 0 while the round-off of the solve stays
/// that of the loads and of u_n (a run of 10^5 steps was stopped at step 82 581 by n·w =
/// 1.3e-15 with max|w_n| = 1.3e-7 and max|u_n|/t_n = 1.3e-5).
const VIOLATION_TOLERANCE: f64 = 1e-8;

/// A solved step n: t_n, u_n (displacement), w_n (velocity), m_n, the multipliers and the
/// rows of Γ3 they belong to.
pub struct Step<'a> {
    pub n: usize,
    pub t: f64,
    /// u_n, at the dofs `local` where there are some (else every dof).
    pub u: &'a [f64],
    /// w_n, at the dofs `held` where there are some (else every dof), exact where the
    /// loop's w is (on a follower rank, not everywhere), and max|w_n| over every dof.
    pub w: &'a [f64],
    pub w_max: f64,
    /// m_n of each memory group after the other's, at u_n's dofs.
    pub m: Option<&'a [f64]>,
    /// On a follower rank whose history holds some dofs alone (`Holds::Local`), those,
    /// and the dofs at which w_n and `rows` are held (`TimeLoop::held`).
    pub local: Option<&'a [usize]>,
    pub held: Option<&'a [usize]>,
    pub z: &'a [f64],
    /// The rows of Γ3, on w's places (`Rows::placed` where `local` is given).
    pub rows: &'a Rows,
    pub report: StepReport,
}

/// A solved step as [`TimeLoop::run`] hands it to its observer.
pub struct Solved<'s> {
    pub step: Step<'s>,
    /// n = the last step of the run: the loop ends with it.
    pub last: bool,
    /// The loop stops after this step ([`Observer::stop_after`]); a resume continues it.
    pub stop: bool,
}

/// Whoever consumes the solved steps of [`TimeLoop::run`]. A closure `FnMut(&Solved) ->
/// Result<()>` is an observer that never stops the loop early.
pub trait Observer {
    /// Whether the loop stops after step n, asked once step n is solved (`--stop-after`, a
    /// signal). Not asked of the last step.
    fn stop_after(&mut self, n: usize) -> bool {
        let _ = n;
        false
    }

    /// Step n is solved.
    fn solved(&mut self, s: &Solved) -> Result<()>;

    /// Step n was given up ([`TimeLoop::abandon_on`]): the loop stands at t_n as before it,
    /// `tl.state()` and `tl.gather_memory()` make what a checkpoint saves of the ranks'
    /// parts (every rank calling both), and the run stops.
    fn abandoned(&mut self, tl: &mut TimeLoop) -> Result<()> {
        let _ = tl;
        Ok(())
    }

    /// The loop advanced to t_{n+1}: `tl.state()` and `tl.gather_memory()` make what a
    /// checkpoint of step n + 1 saves (every rank calling both).
    fn advanced(&mut self, tl: &mut TimeLoop) -> Result<()> {
        let _ = tl;
        Ok(())
    }
}

impl<F: FnMut(&Solved) -> Result<()>> Observer for F {
    fn solved(&mut self, s: &Solved) -> Result<()> {
        self(s)
    }
}

/// How [`TimeLoop::run`] ended, when no step failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RunEnd {
    /// The last step was solved.
    Completed,
    /// After a step the observer stopped at, or within a step given up; the loop stands at
    /// the step that comes next.
    Stopped,
}

impl<'p> TimeLoop<'p> {
    pub fn new(scene: &'p Scene, disc: &'p Discretization) -> Result<Self> {
        Self::with_plan(scene, disc, Plans::new(scene)?)
    }

    /// A time loop with its memory plans in hand (a resumed run's, `Plans::resumed`), checked
    /// by [`refusals`] before anything is factored.
    pub fn with_plan(scene: &'p Scene, disc: &'p Discretization, plans: Plans) -> Result<Self> {
        Self::with_solver(scene, disc, plans, Descriptor::of_run(scene, disc)?, None)
    }

    /// A time loop with its memory plans and its solver in hand: `descriptor` is the scene's
    /// `[solver]` resolved on `disc` (`Descriptor::of_run`), which a run has already checked
    /// against the memory available. On one of several MPI ranks, `own` is what
    /// `Ranks::keep_own_columns` made for PETSc: the layout over the ranks, and the rank's
    /// rows of K_A where they were taken out of `disc`.
    pub fn with_solver(
        scene: &'p Scene,
        disc: &'p Discretization,
        plans: Plans,
        descriptor: Descriptor,
        mut own: Option<Own>,
    ) -> Result<Self> {
        refusals(scene, disc, &plans)?;
        let holds = own.as_mut().map(|own| std::mem::take(&mut own.holds));
        let effects = Effects::new(scene, disc);
        let rows = Rows::new(&disc.contact, &disc.friction, disc.dim - 1);
        let local = holds.as_ref().and_then(Holds::local);
        let held = local.map(|local| held_at(local, &rows, disc.own.as_deref()));
        let implicit = match scene.solver.history {
            scene::History::Left => None,
            scene::History::Implicit => {
                Some(disc.implicit_matrix(scene.time.k(), &plans.r0(scene)))
            }
        };
        // With prescribed dofs the factored matrix is the free block of the whole one.
        let (implicit, lift) = match (implicit, &disc.k_a_all) {
            (Some(all), Some(_)) => (Some(leading_block(&all, disc.n_free)), Some(all)),
            (None, Some(all)) => (None, Some(all.clone())),
            (implicit, None) => (implicit, None),
        };
        let matrix = implicit.as_ref().unwrap_or(&disc.k_a);
        // The step matrix is factored once, with the constrained boundary dofs ordered last
        // where the contact solver works on its trailing block, or handed to PETSc.
        let backend = match descriptor.build() {
            Build::Krylov { newton } => {
                let reads = (&rows, held.as_deref());
                petsc_backend(scene, (matrix, own), disc, *newton, reads)?
            }
            Build::Factor { last } => Backend::Cholesky(Factor::new(matrix, last)?),
            Build::Nothing => Backend::None,
        };
        let rows = match &held {
            Some(held) => rows.placed(held),
            None => rows,
        };
        let solver = effects::step_solver(
            (&effects, disc, held.as_deref()),
            &descriptor,
            matrix,
            &backend,
            &rows,
        )?;
        // After PETSc's setup, where a rank of several peaks: its rows of K_B and K_R^(0).
        let own_pair = disc.own_pair_made(local);
        let (own, g_f) = own_placed(disc, held.as_deref());
        let n = held.as_ref().map_or(disc.n_dofs, Vec::len);
        let holds = holds.unwrap_or_default();
        let history = History::holding(disc.n_dofs, scene.time.k(), &plans, holds);
        let paired = disc
            .k_b
            .as_ref()
            .filter(|_| history.has_memory() && disc.own.is_none())
            .and_then(|k_b| SymmetricPair::new(k_b, disc.k_r.first()?));
        let m = if history.has_memory() {
            vec![0.0; plans.groups() * history.u.len()]
        } else {
            Vec::new()
        };
        Ok(TimeLoop {
            scene,
            disc,
            effects,
            backend,
            solver,
            descriptor,
            z: vec![0.0; rows.len()],
            z_before: vec![0.0; rows.len()],
            spare: vec![0.0; rows.len()],
            rows,
            history,
            plans,
            w: vec![0.0; n],
            w_start: Vec::new(),
            m,
            b: vec![0.0; n],
            growth: Growth::default(),
            paired,
            own_pair,
            held,
            own,
            g_f,
            lift,
            abandon: None,
            past_saved: 0,
            can_stop: false,
        })
    }

    /// Solves the steps from the current n to `last` (inclusive), each handed to `observer`:
    /// solve step n; unless it is the last or the observer stops after it, advance to
    /// t_{n+1} and tell the observer. The only caller of the step function.
    pub fn run(&mut self, last: usize, observer: &mut impl Observer) -> Result<RunEnd> {
        loop {
            let n = self.n();
            let is_last = n >= last;
            let Some(step) = self.solve_step()? else {
                observer.abandoned(self)?;
                return Ok(RunEnd::Stopped);
            };
            // Asked after the solve: a signal that came while the last step was solved lets
            // the run complete (nothing would be left to resume).
            let stop = !is_last && observer.stop_after(n);
            let solved = Solved {
                step,
                last: is_last,
                stop,
            };
            observer.solved(&solved)?;
            if is_last {
                return Ok(RunEnd::Completed);
            }
            self.advance();
            self.can_stop = true;
            observer.advanced(self)?;
            if stop {
                return Ok(RunEnd::Stopped);
            }
        }
    }

    /// What a checkpoint saves of the loop at t_n, before step n is solved, but for the
    /// memory ([`TimeLoop::gather_memory`]'s): on one process and on rank 0 of several,
    /// None on the others. Each vector is made there of each rank's values at its own rows
    /// (`TimeLoop::gathered`): rank 0 may hold some dofs alone, as a follower does.
    /// Collective: every rank calls it at every checkpoint, before `gather_memory`.
    pub fn state(&self) -> Result<Option<LoopState<'_>>> {
        let local = self.history.holds.local();
        let [u, u_sum, u_comp] = [&self.history.u, &self.history.u_sum, &self.history.u_comp];
        let gathered = [
            (u, local),
            (u_sum, local),
            (u_comp, local),
            (&self.w, self.held.as_deref()),
        ];
        let mut whole = Vec::with_capacity(4);
        for (v, at) in gathered {
            whole.extend(self.gathered(v, at)?);
        }
        // All four on rank 0 and one process, none on the other ranks.
        let Ok([u, u_sum, u_comp, w]) = <[Vec<f64>; 4]>::try_from(whole) else {
            return Ok(None);
        };
        Ok(Some(LoopState {
            history: &self.history,
            u,
            u_sum,
            u_comp,
            w,
            z: &self.z,
            z_before: &self.z_before,
        }))
    }

    /// `v`, held at the dofs `at` (None: every one), at every dof on one process and on
    /// rank 0 of several, None on the others (collective: every rank calls it): the
    /// unknowns' values each rank's own rows give (`Backend::gather_at_first`), with the
    /// bits of one process's, then the prescribed dofs' (n_free.., which a rank that holds
    /// them holds whole).
    fn gathered(&self, v: &[f64], at: Option<&[usize]>) -> Result<Option<Vec<f64>>> {
        let value = |i: usize| v[crate::fem::place(at, i)];
        let (n_free, n_dofs) = (self.disc.n_free, self.disc.n_dofs);
        let whole = self.backend.gather_at_first(n_free, &value)?;
        Ok(whole.map(|mut whole| {
            whole.extend((n_free..n_dofs).map(value));
            whole
        }))
    }

    /// The memory at t_n as a checkpoint saves it, every dof's, one vector at a time into
    /// `each` (collective: every rank calls it at every checkpoint, which rank 0's schedule
    /// shares with the others: `run`): called on one process and on rank 0 of several,
    /// each vector made there of each rank's values at its own rows, never on the other
    /// ranks. Of a direct sum, the past rows that no checkpoint holds yet, which every rank
    /// counts alike (`History::gathered`).
    pub fn gather_memory(&mut self, each: &mut dyn FnMut(Vec<f64>)) -> Result<()> {
        let whole = |v: &[f64], at: Option<&[usize]>| self.gathered(v, at);
        self.history.gathered(self.past_saved, whole, each)?;
        if let crate::history::Memory::Direct { past, .. } = &self.history.memory {
            self.past_saved = past.len();
        }
        Ok(())
    }

    /// Where the loop holds u_n, the memory (the Prony states or a direct sum's past rows)
    /// and w_n: a resume reads them there alone (`Checkpoint::saved`).
    pub fn held_at(&self) -> HeldAt<'_> {
        HeldAt {
            w: self.held.as_deref(),
            ..self.history.held_at()
        }
    }

    /// Takes back the state a checkpoint saved (a resume), into this loop built from the
    /// same scene, its vectors at the dofs this loop holds them ([`TimeLoop::held_at`]);
    /// the sizes were checked by the checkpoint, the memory's kind and terms are checked
    /// here. Its every past row is the checkpoint's.
    pub fn restore(&mut self, saved: SavedLoop) -> Result<()> {
        if saved.w.len() != self.w.len() {
            let why = "the checkpoint's w_n was read at other dofs than this rank holds";
            return Err(crate::Error::input(why));
        }
        self.history.restore(saved.history)?;
        self.past_saved = self.history.n;
        self.w = saved.w;
        self.z = saved.z;
        self.z_before = saved.z_before;
        Ok(())
    }

    /// From now on a request on `abandon` gives up the step being solved, where the step
    /// solver honours it (the dual methods, the active set, a linear step's PETSc Krylov
    /// solve) and the loop's state before the step is one a
    /// stop leaves (after a step solved by this loop): `run` then tells its
    /// observer ([`Observer::abandoned`]) and ends with [`RunEnd::Stopped`] at that step.
    pub fn abandon_on(&mut self, abandon: &Abandon) {
        let honoured = match (&mut self.solver, &mut self.backend) {
            // A step through PETSc (linear, or the active set's Newton systems): its Krylov
            // solves ask the request, at every iteration on every rank.
            #[cfg(feature = "petsc")]
            (StepSolver::Linear | StepSolver::ActiveSet(_), Backend::Petsc(krylov)) => {
                let request = abandon.clone();
                krylov.give_up_when(move || request.requested());
                true
            }
            (solver, _) => solver.abandon_on(abandon.clone()),
        };
        self.abandon = honoured.then(|| abandon.clone());
    }

    /// The rows of Γ3: contact rows, then friction rows.
    pub fn rows(&self) -> &Rows {
        &self.rows
    }

    /// The effects of Remark 2.5 the run keeps.
    pub fn effects(&self) -> &Effects {
        &self.effects
    }

    /// The contact solver of the steps.
    pub fn solver(&self) -> &StepSolver {
        &self.solver
    }

    /// The run's solver as resolved from the scene: its plan, memory and what was built.
    pub fn descriptor(&self) -> &Descriptor {
        &self.descriptor
    }

    /// The factor of the step matrix (K_A, or its implicit variant), where the run has one
    /// (not with `solver.linear = "petsc"`).
    pub fn factor(&self) -> Option<&Factor> {
        self.backend.factor()
    }

    /// The name of the step solver recorded in summary.json: the contact solver's, or for
    /// a linear run through PETSc the KSP and PC it runs.
    pub fn solver_name(&self) -> String {
        match &self.backend {
            Backend::Cholesky(_) | Backend::None => self.solver.name().to_string(),
            #[cfg(feature = "petsc")]
            Backend::Petsc(k) => match self.solver {
                StepSolver::ActiveSet(_) => format!(
                    "active set (semismooth Newton on the primal system; PETSc KSP {} with the \
                     PC {} of K_A, projected)",
                    k.ksp_type, k.pc_type
                ),
                _ => format!(
                    "linear (PETSc KSP {} with PC {} on K_A, one Krylov solve per step)",
                    k.ksp_type, k.pc_type
                ),
            },
        }
    }

    /// PETSc's KSP, where the run solves through it.
    #[cfg(feature = "petsc")]
    pub fn krylov(&self) -> Option<&crate::petsc::Krylov> {
        match &self.backend {
            Backend::Petsc(k) => Some(k),
            Backend::Cholesky(_) | Backend::None => None,
        }
    }

    /// How the memory sums are computed.
    pub fn plans(&self) -> &Plans {
        &self.plans
    }

    /// The index n of the next step to solve.
    pub fn n(&self) -> usize {
        self.history.n
    }

    /// u_n of the current n (after the last step of a completed run: u_N), at every dof
    /// but on a follower rank that holds some alone (`Step::local`).
    pub fn u(&self) -> &[f64] {
        &self.history.u
    }

    /// [`TimeLoop::u`] and the dofs it holds its values at where not every one
    /// (`Step::local`).
    pub fn u_held(&self) -> (&[f64], Option<&[usize]>) {
        (&self.history.u, self.history.holds.local())
    }

    /// The step size k.
    pub fn k(&self) -> f64 {
        self.history.k
    }

    /// t_n = n k.
    pub fn time(&self) -> f64 {
        self.history.n as f64 * self.history.k
    }

    /// Solves (3.1) at the current n: b_n = f_n − K_B u_n − K_R m_n − g_F, then w_n.
    /// Step n, or None when it was given up (the loop's state is then as before it).
    fn solve_step(&mut self) -> Result<Option<Step<'_>>> {
        let t = self.time();
        let load_max = self.right_side(t)?;
        self.spare.copy_from_slice(&self.z);
        let armed = (self.abandon.as_ref())
            .filter(|_| self.can_stop)
            .map(Abandon::arm);
        let nf = self.unknowns();
        if armed.is_some() {
            self.backend.keep(&self.w[..nf], &mut self.w_start);
        }
        let mut report = self.solver.solve(
            &mut self.backend,
            &self.rows,
            &self.b[..nf],
            &mut self.w[..nf],
            &mut self.z,
            Some(&self.z_before),
        )?;
        drop(armed);
        if report.status == StepStatus::Abandoned {
            // w and z may hold the step's iterate: both go back to the step before.
            self.backend.restore(&self.w_start, &mut self.w[..nf])?;
            self.z.copy_from_slice(&self.spare);
            return Ok(None);
        }
        std::mem::swap(&mut self.z_before, &mut self.spare);
        self.backend.complete(&mut self.w[..nf])?;
        let mut w_max = f64::NAN;
        if report.status == StepStatus::Solved {
            w_max = self.w_max()?;
            report.status = self.trust(t, load_max, w_max)?;
        }
        let h = &self.history;
        report.check(&StepAt {
            n: h.n,
            t,
            k: h.k,
            other_solver: self.solver.other(),
            limit_key: self.solver.limit_key(),
        })?;
        Ok(Some(Step {
            n: h.n,
            t,
            u: &h.u,
            w: &self.w,
            w_max,
            m: if self.m.is_empty() {
                None
            } else {
                Some(&self.m)
            },
            local: h.holds.local(),
            held: self.held.as_deref(),
            z: &self.z,
            rows: &self.rows,
            report,
        }))
    }

    /// b_n = f_n − K_B u_n − K_R m_n − g_F into `b` (m_n into `m` on the way), and with
    /// prescribed dofs their velocities w_p = (g(t_{n+1}) − u_{n,p})/k into `w` and
    /// b_f −= M_fp w_p (`fem::constraints`); returns max|f_n − g_F|, the step's load for
    /// the divergence detector.
    fn right_side(&mut self, t: f64) -> Result<f64> {
        let disc = self.disc;
        let h = &self.history;
        if !disc.prescribed.is_empty() {
            let next = (h.n + 1) as f64 * h.k;
            let g = constraints::values(&disc.prescribed, &disc.nodes, self.scene, next)?;
            for (p, g) in disc.prescribed.iter().zip(g) {
                self.w[p.dof] = (g - h.u[p.dof]) / h.k;
            }
        }
        self.b.fill(0.0);
        let added = self.disc.loads.add(
            t,
            (&self.disc.free, &self.disc.frames),
            self.scene,
            (&mut self.b, self.held.as_deref()),
        );
        let load_max = self.load_max(added, t)?;
        let h = &mut self.history;
        let memory = h.memory_into(self.scene.physics.relaxation.as_ref(), &mut self.m);
        // −K_B u_n − Σ_g K_R^(g) m^(g)_n, the body's group with K_B in one pass where paired.
        let n = h.u.len();
        let mut groups = (self.disc.k_r.iter()).zip(self.m.chunks_exact(n.max(1)));
        // A rank of several holds its own columns (`Discretization::keep_columns`): its
        // rows of the products, gathered below.
        let own = self.own.as_deref();
        let product = |k: &Sparse, x: &[f64], b: &mut [f64]| match own {
            Some(own) => mul_add_rows(k, own, x, -1.0, b),
            None => mul_add(k, x, -1.0, b),
        };
        let own_pair = self.own_pair.as_ref().or(disc.own_pair.as_ref());
        match (&mut self.paired, own_pair, &disc.k_b) {
            (Some(pair), _, _) if memory => {
                let (_, m0) = groups.next().expect("group 0");
                pair.mul_add(&h.u, m0, -1.0, &mut self.b)
            }
            (_, Some(rows), _) => {
                let own = own.unwrap_or_default();
                let m0 = groups.next().map(|(_, m0)| m0);
                rows.mul_add(own, &h.u, m0, -1.0, &mut self.b)
            }
            (_, _, Some(k_b)) => product(k_b, &h.u, &mut self.b),
            (_, _, None) => {}
        }
        for (k_r, m) in groups {
            product(k_r, m, &mut self.b);
        }
        for &(i, g) in self.g_f.iter() {
            self.b[i] -= g;
        }
        if let Some(lift) = &self.lift {
            constraints::lift(lift, disc.n_free, &self.w, &mut self.b);
        }
        self.backend.share(&mut self.b)?;
        Ok(load_max)
    }

    /// max|f_n − g_F| (g_F is empty without friction) of f_n in `b`, `added` as
    /// `Loads::add` left it. On one of several MPI ranks, f_n is exact in its own rows alone
    /// (a rank keeps their loads alone: `Loads::is_part`): each rank takes the largest
    /// of its own rows, and the ranks the largest of those (a maximum: one process's
    /// bits), and a load that is not finite fails the step on every rank, rank 0 (which
    /// sees every value) saying where, the others quietly.
    fn load_max(&mut self, added: Result<()>, t: f64) -> Result<f64> {
        let Some(own) = &self.own else {
            added?;
            return Ok(less_g_f(&mut self.b, &self.g_f, max_abs));
        };
        let failed = self.backend.largest(f64::from(u8::from(added.is_err())))?;
        if failed > 0.0 {
            // Rank 0 sees every value (`Loads::sees_every_value`) and names the first, as
            // one process does; a follower is quiet.
            if !self.disc.loads.sees_every_value() {
                return Err(Error::Elsewhere(1));
            }
            let first = self.disc.visit_every_load(t, self.scene, |_, _, _| {});
            return Err(first.and(added).err().unwrap_or_else(|| {
                Error::solve(format!(
                    "a load is not finite at t = {t} on another rank; the run stops here"
                ))
            }));
        }
        let mine = less_g_f(&mut self.b, &self.g_f, |b| max_abs_at(b, own));
        self.backend.largest(mine)
    }

    /// Whether a step the solver calls solved is trusted: finite, bounded by its loads
    /// (`Growth`) and keeping n·w ≤ 0 on Γ3,1 to the solver's tolerance.
    fn trust(&mut self, t: f64, load_max: f64, w_max: f64) -> Result<StepStatus> {
        let u_max = self.u_max()?;
        let h = &self.history;
        let mean_velocity = u_max / t.max(h.k);
        if !(u_max.is_finite() && w_max.is_finite()) {
            return Ok(StepStatus::NotFinite { u_max, w_max });
        }
        if let Some(factor) = self.growth.record(h.n, u_max, load_max) {
            let since = ((h.n / 2).max(1).ilog2() as f64).exp2() * h.k;
            return Ok(StepStatus::Diverged {
                u_max,
                factor,
                since,
            });
        }
        let (amount, node) = self.rows.rows[..self.rows.n_contact]
            .iter()
            .map(|r| (r.apply(&self.w), r.node))
            .fold((f64::NEG_INFINITY, 0), |a, b| if b.0 > a.0 { b } else { a });
        Ok(if amount > VIOLATION_TOLERANCE * w_max.max(mean_velocity) {
            StepStatus::Violation {
                amount,
                node,
                w_max,
                mean_velocity,
            }
        } else {
            StepStatus::Solved
        })
    }

    /// max|u_n|: on several MPI ranks, the ranks' largest (`largest`), since a rank may
    /// hold some dofs alone.
    fn u_max(&self) -> Result<f64> {
        self.largest(max_abs(&self.history.u))
    }

    /// max|w_n|. On several MPI ranks, the largest of each rank's own rows' and the
    /// prescribed dofs' (which every rank holds): w_n is exact there, not everywhere on a
    /// follower; as `u_max` says.
    fn w_max(&self) -> Result<f64> {
        let Some(own) = &self.own else {
            return Ok(max_abs(&self.w));
        };
        let (own_max, prescribed) = (
            max_abs_at(&self.w, own),
            max_abs(&self.w[self.unknowns()..]),
        );
        self.largest(match own_max.is_nan() || prescribed.is_nan() {
            true => f64::NAN,
            false => own_max.max(prescribed),
        })
    }

    /// The largest of the ranks' `mine` (a maximum: one process's bits); a rank whose
    /// `mine` is NaN keeps its NaN, and the others see +∞: not finite either.
    fn largest(&self, mine: f64) -> Result<f64> {
        if self.disc.own.is_none() {
            return Ok(mine);
        }
        let all = self
            .backend
            .largest(if mine.is_nan() { f64::INFINITY } else { mine })?;
        Ok(if mine.is_nan() { mine } else { all })
    }

    /// The count of unknowns among w's values: n_free, or on a follower that holds some
    /// dofs alone (`held`: no prescribed dofs), every value w holds.
    fn unknowns(&self) -> usize {
        match self.held {
            Some(_) => self.w.len(),
            None => self.disc.n_free,
        }
    }

    /// n → n + 1: u_{n+1} = u_n + k w_n and the memory update.
    fn advance(&mut self) {
        self.history.advance(&self.w, self.held.as_deref());
    }
}

/// A rank's own rows (`Discretization::own`) and g_F's terms, at their places in vectors
/// held at the dofs `held` alone where given (`fem::place`); g_F's terms at other dofs
/// are dropped: they are others' rows, whose b_n comes from those ranks. Borrowed where
/// the vectors are whole (rank 0 and one process: no copy).
fn own_placed<'a>(disc: &'a Discretization, held: Option<&[usize]>) -> OwnPlaced<'a> {
    let own = disc.own.as_deref();
    let Some(held) = held else {
        return (own.map(Cow::Borrowed), Cow::Borrowed(&disc.g_f));
    };
    let placed = |i: usize| crate::fem::place(Some(held), i);
    let own = own.map(|own| own.iter().map(|&i| placed(i)).collect());
    let g_f = (disc.g_f.iter())
        .filter_map(|&(i, g)| Some((crate::fem::place_if_held(Some(held), i)?, g)))
        .collect();
    (own, g_f)
}

/// A rank's own rows and g_F's terms, placed ([`own_placed`]).
type OwnPlaced<'a> = (Option<Cow<'a, [usize]>>, Cow<'a, [(usize, f64)]>);

/// The dofs at which a follower whose history holds the dofs `local` alone holds w_n and
/// b_n, increasing: those (which its rows of K_B and K_R and its piece read), its own rows
/// (which it solves for) and Γ3's unknowns (which every rank's active set reads). Its
/// history does not hold Γ3's unknowns: measured, that cost more than w_n and b_n of the
/// whole had (docs/cluster.md, "Memory per rank", 38.).
fn held_at(local: &[usize], rows: &Rows, own: Option<&[usize]>) -> Vec<usize> {
    let mut held = rows.dofs();
    held.extend(local.iter().chain(own.unwrap_or_default()));
    held.sort_unstable();
    held.dedup();
    held
}

/// The PETSc backend of the step matrix (`Build::Krylov`): its KSP with the scene's options. A
/// build without the feature never gets here (the scene refused the keys, and `auto` picks
/// PETSc only in a build with it).
fn petsc_backend(
    scene: &Scene,
    (matrix, own): (&crate::fem::Sparse, Option<Own>),
    disc: &Discretization,
    newton: bool,
    (rows, held): (&Rows, Option<&[usize]>),
) -> Result<Backend> {
    #[cfg(feature = "petsc")]
    {
        let settings = crate::petsc::KrylovSettings {
            options: scene.solver.petsc_options.clone(),
            rtol: crate::petsc::DEFAULT_RTOL,
            newton,
        };
        let own = own.map(|o| (o.layout, o.rows));
        // What this rank reads of a solution besides its own rows: where it holds its
        // vectors at some dofs alone, those (Γ3's among them); else Γ3's unknowns, and
        // every one once a step is solved.
        let gamma3 = match held {
            Some(_) => Vec::new(),
            None => rows.dofs(),
        };
        let reads = crate::petsc::Reads {
            dofs: held.unwrap_or(&gamma3),
            held: held.is_some(),
        };
        let krylov = crate::petsc::Krylov::new(matrix, own, disc, &settings, reads)?;
        // GAMG's setup freed what its products held meanwhile.
        crate::resources::return_freed_memory();
        Ok(Backend::Petsc(krylov))
    }
    #[cfg(not(feature = "petsc"))]
    {
        let _ = (matrix, own, disc, newton, rows, held);
        Err(crate::Error::input(format!(
            "{}: solver.linear = \"petsc\" needs a build with the petsc feature",
            scene.path.display()
        )))
    }
}

/// `f(b)` with b − g_F in b at g_F's dofs for the while (f_n − g_F of f_n in b), b's own
/// values put back there after it.
fn less_g_f<T>(b: &mut [f64], g_f: &[(usize, f64)], f: impl FnOnce(&[f64]) -> T) -> T {
    let kept: Vec<f64> = (g_f.iter())
        .map(|&(i, g)| {
            let f = b[i];
            b[i] = f - g;
            f
        })
        .collect();
    let out = f(b);
    g_f.iter().zip(kept).for_each(|(&(i, _), v)| b[i] = v);
    out
}

/// max|v_i| over i in `at`, NaN if any is NaN.
fn max_abs_at(v: &[f64], at: &[usize]) -> f64 {
    let mut nan = false;
    let largest = at.iter().fold(0.0f64, |m, &i| {
        let x = v[i].abs();
        nan |= x.is_nan();
        if x > m {
            x
        } else {
            m
        }
    });
    if nan {
        f64::NAN
    } else {
        largest
    }
}

/// max|v_i|, NaN if any v_i is NaN (`f64::max` would skip it). Eight running maxima: one
/// would wait on its comparisons (a third of a step's checks at h = 1/128).
fn max_abs(a: &[f64]) -> f64 {
    let mut m = [0.0f64; 8];
    let mut nan = false;
    let mut take = |lanes: &mut [f64; 8], x: [f64; 8]| {
        for (l, x) in lanes.iter_mut().zip(x) {
            let x = x.abs();
            nan |= x.is_nan();
            *l = if x > *l { x } else { *l };
        }
    };
    let chunks = a.chunks_exact(8);
    let tail = chunks.remainder();
    for c in chunks {
        take(&mut m, std::array::from_fn(|k| c[k]));
    }
    take(
        &mut m,
        std::array::from_fn(|k| tail.get(k).map_or(0.0, |x| *x)),
    );
    if nan {
        f64::NAN
    } else {
        m.into_iter().fold(0.0, f64::max)
    }
}

/// What a run refuses before it factors anything (exit 2), for the memory plan it will run
/// (`Plan::new`, which already refused a kernel that is not finite on the run's lags, or a
/// resumed run's `Plan::resumed`): a left endpoint step above the stability limit of the
/// kernel as it will run (`Verdict`), loads that are not finite at t = 0, prescribed
/// displacements that are not finite at t = k. `viscontact check`
/// calls it with the plan it prints, so that `check` fails wherever `run` would.
pub fn refusals(scene: &Scene, disc: &Discretization, plans: &Plans) -> Result<()> {
    if scene.solver.history == scene::History::Left {
        Verdict::new(scene, disc, plans).check(scene)?;
    }
    constraints::values(&disc.prescribed, &disc.nodes, scene, scene.time.k())?;
    disc.loads_at_start(scene)
}

#[cfg(test)]
mod tests {
    use super::{less_g_f, max_abs, Growth};

    /// The first step at which `Growth` stops a sequence of (max|u_n|, max load) pairs.
    fn stopped_at(seq: impl Iterator<Item = (f64, f64)>) -> Option<usize> {
        let mut g = Growth::default();
        seq.enumerate()
            .find_map(|(n, (u, l))| g.record(n, u, l).map(|_| n))
    }

    #[test]
    fn erratic_geometric_growth_is_stopped() {
        // ×4 at about 56 of 98 steps and ×½ at the others, never 40 growing steps in a row.
        let mut u = 0.0;
        let mut rng = crate::testing::SplitMix(7);
        let seq = (0..98).map(move |n| {
            let grows = rng.unit() < 56.0 / 98.0;
            u = if n == 1 {
                1e-3
            } else if grows {
                4.0 * u
            } else {
                0.5 * u
            };
            (u, 1.0)
        });
        assert!(stopped_at(seq).is_some());
        // Steady ×5 (the explicit scheme at three times its limit): within 40 steps.
        let seq = (0..200).map(|n| (if n == 0 { 0.0 } else { 5f64.powi(n) }, 1.0));
        assert!(stopped_at(seq).unwrap() < 40);
    }

    #[test]
    fn growth_that_the_loads_explain_is_not_stopped() {
        // Creep under a constant load, a load t^6 ramped from 0 (u ∝ t^7), an exponential
        // load e^{50t} (u ∝ e^{50t}), over 10^5 steps of k = 1e-5.
        let k = 1e-5;
        let t = |n: usize| n as f64 * k;
        let creep = (0..100_000).map(|n| (t(n), 1.0));
        assert_eq!(stopped_at(creep), None);
        let ramp = (0..100_000).map(|n| (t(n).powi(7), t(n).powi(6)));
        assert_eq!(stopped_at(ramp), None);
        let exponential = (0..100_000).map(|n| ((50.0 * t(n)).exp() - 1.0, (50.0 * t(n)).exp()));
        assert_eq!(stopped_at(exponential), None);
    }

    #[test]
    fn max_abs_keeps_nan() {
        assert!(max_abs(&[1.0, f64::NAN, 2.0]).is_nan());
        assert!(max_abs(&[f64::NAN, 2.0]).is_nan());
        assert_eq!(max_abs(&[1.0, -3.0]), 3.0);
        assert_eq!(max_abs(&[]), 0.0);
        // Past the eight lanes, in the lanes and in the tail.
        let mut v: Vec<f64> = (0..21).map(|i| i as f64 - 10.0).collect();
        assert_eq!(max_abs(&v), 10.0);
        v[17] = -30.0;
        assert_eq!(max_abs(&v), 30.0);
        v[19] = f64::NAN;
        assert!(max_abs(&v).is_nan());
        v[19] = 0.0;
        v[3] = f64::INFINITY;
        assert_eq!(max_abs(&v), f64::INFINITY);
    }

    /// max|f − g_F| with g_F at its dofs alone, f itself back after it, to the bit.
    #[test]
    fn g_f_is_taken_from_f_at_its_dofs_for_the_while() {
        let f: Vec<f64> = (0..21).map(|i| i as f64 - 10.0).collect();
        let g_f = [(3, -50.0), (20, 0.3)];
        let mut b = f.clone();
        assert_eq!(less_g_f(&mut b, &g_f, max_abs), 43.0);
        assert_eq!(b, f);
        b[20] = f64::NAN;
        assert!(less_g_f(&mut b, &g_f, max_abs).is_nan());
    }
}
