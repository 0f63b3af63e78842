//! The consumers of a run's stream of solved steps (STYLE.md, scikit-fem's time loop as an
//! iterator): the loop in `run::drive` solves step n, hands it to each consumer, advances to
//! t_{n+1} and tells the consumers that need the new state. Each consumer is a small type
//! that knows one job:
//!
//! - [`Statistics`]: the run-wide numbers of summary.json (iterations, the largest n·w on
//!   Γ3,1, the largest KKT residual, the contact state at the last step);
//! - [`Frames`]: the ParaView series, a frame every `output.every` steps and at the end;
//! - [`Checkpoints`]: `checkpoint.h5` at every `checkpoint.every`-th step, before the last
//!   step and where the run stops;
//! - [`Progress`]: the progress bar on a terminal.

use crate::checkpoint::{self, RunLog};
use crate::fem::Discretization;
use crate::output::{Field, Frame, Series};
use crate::scene::Scene;
use crate::solver::{kkt_residual, Rows};
use crate::time_loop::{Step, TimeLoop};
use crate::Result;

/// A solved step n as the consumers see it.
pub(super) struct Solved<'s> {
    pub step: Step<'s>,
    pub rows: &'s Rows,
    /// n = N: the run ends with this step.
    pub last: bool,
    /// The run stops after this step (`--stop-after`) and continues by resume.
    pub stop: bool,
}

/// Everything that consumes the solved steps, in the order they see them.
pub(super) struct Consumers<'a> {
    pub statistics: Statistics,
    pub frames: Frames<'a>,
    pub checkpoints: Checkpoints,
    pub progress: Progress,
}

impl Consumers<'_> {
    /// Step n is solved.
    pub fn solved(&mut self, s: &Solved) -> Result<()> {
        self.statistics.solved(s);
        self.frames.solved(s)?;
        self.checkpoints.solved(s);
        self.progress.solved(s);
        Ok(())
    }

    /// The loop advanced to t_{n+1}.
    pub fn advanced(&mut self, tl: &TimeLoop) -> Result<()> {
        self.checkpoints.advanced(tl, &self.statistics.log)
    }
}

/// The run-wide numbers of summary.json that depend on every step so far.
pub(super) struct Statistics {
    /// What a checkpoint saves of them (iterations, running maxima).
    pub log: RunLog,
    /// Γ3,1 nodes with an active constraint and sticking Γ3,2 nodes at the last step solved.
    pub active: usize,
    pub stick: usize,
}

impl Statistics {
    pub fn new(log: RunLog) -> Statistics {
        Statistics {
            log,
            active: 0,
            stick: 0,
        }
    }

    fn solved(&mut self, s: &Solved) {
        let log = &mut self.log;
        log.iterations.push(s.step.report.iterations);
        let (viol, kkt) = step_checks(s.rows, &s.step);
        log.max_violation = log.max_violation.max(viol);
        log.max_kkt_residual = log.max_kkt_residual.max(kkt);
        if s.last {
            (self.active, self.stick) = state_counts(s.rows, &s.step);
        }
    }
}

/// The ParaView series: a frame at every `output.every`-th step and at the last.
pub(super) struct Frames<'a> {
    pub series: Series,
    pub disc: &'a Discretization,
    pub scene: &'a Scene,
}

impl Frames<'_> {
    fn solved(&mut self, s: &Solved) -> Result<()> {
        if s.step.n.is_multiple_of(self.scene.output_every) || s.last {
            write_frame(&mut self.series, self.disc, self.scene, s.rows, &s.step)?;
        }
        Ok(())
    }
}

/// `checkpoint.h5`: the state at t_{n+1} after step n at every `checkpoint.every`-th step,
/// before the last step and where the run stops (`[checkpoint] enabled = false`: never).
pub(super) struct Checkpoints {
    pub writer: checkpoint::Writer,
    pub enabled: bool,
    pub every: Option<usize>,
    pub steps: usize,
    /// The contact/stick flags of the step just solved, when its checkpoint is due.
    due: Option<Vec<bool>>,
}

impl Checkpoints {
    pub fn new(writer: checkpoint::Writer, scene: &Scene) -> Checkpoints {
        Checkpoints {
            writer,
            enabled: scene.checkpoint,
            every: scene.checkpoint_every,
            steps: scene.steps,
            due: None,
        }
    }

    /// Decides whether the state after step n is saved; the flags are the solved step's.
    fn solved(&mut self, s: &Solved) {
        let next = s.step.n + 1;
        let due = self.enabled
            && !s.last
            && (s.stop || next == self.steps || self.every.is_some_and(|e| next.is_multiple_of(e)));
        self.due = due.then(|| state_flags(s.rows, &s.step));
    }

    fn advanced(&mut self, tl: &TimeLoop, log: &RunLog) -> Result<()> {
        match self.due.take() {
            Some(flags) => self.writer.write(tl, log, &flags),
            None => Ok(()),
        }
    }

    /// `DIR/checkpoint.h5` when checkpoints are written.
    pub fn path(&self) -> Option<std::path::PathBuf> {
        self.enabled.then(|| self.writer.path())
    }
}

/// The progress bar on a terminal (hidden otherwise or with `--quiet`).
pub(super) struct Progress {
    bar: indicatif::ProgressBar,
}

impl Progress {
    /// Progress over the steps `first..=last`.
    pub fn new(enabled: bool, first: usize, last: usize) -> Progress {
        Progress {
            bar: progress_bar(enabled, (last + 1 - first) as u64),
        }
    }

    fn solved(&mut self, _s: &Solved) {
        self.bar.inc(1);
    }

    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

fn progress_bar(enabled: bool, len: u64) -> indicatif::ProgressBar {
    use std::io::IsTerminal;
    if !enabled || !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(len);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} step {pos}/{len}  {elapsed} < {eta}")
            .expect("valid template"),
    );
    bar
}

/// Scale of a step's velocities and multipliers for relative tolerances.
fn scales(step: &Step) -> (f64, f64) {
    let ws = step.w.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    let zs = step.z.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    (ws, zs)
}

/// The largest n·w on Γ3,1 and the relative KKT residual of a solved step.
fn step_checks(rows: &Rows, step: &Step) -> (f64, f64) {
    let viol = rows.rows[..rows.n_contact]
        .iter()
        .map(|r| r.apply(step.w))
        .fold(f64::NEG_INFINITY, f64::max);
    let (ws, zs) = scales(step);
    (viol, kkt_residual(rows, step.w, step.z, ws, zs))
}

/// Γ3,1 rows with an active constraint and Γ3,2 rows whose node sticks (|w_τ| of the
/// node's block), up to 1e-9 of the largest velocity.
fn state_flags(rows: &Rows, step: &Step) -> Vec<bool> {
    let (ws, _) = scales(step);
    let tol = 1e-9 * ws.max(f64::MIN_POSITIVE);
    let mut flags: Vec<bool> = rows.rows[..rows.n_contact]
        .iter()
        .enumerate()
        .map(|(i, r)| step.z[i] > 0.0 || r.apply(step.w) >= -tol)
        .collect();
    for j in 0..rows.n_friction_nodes() {
        let block = rows.friction_block(j);
        let slip: f64 = rows.rows[block.clone()]
            .iter()
            .map(|r| r.apply(step.w).powi(2))
            .sum::<f64>()
            .sqrt();
        flags.extend(block.map(|_| slip <= tol));
    }
    flags
}

/// (active Γ3,1 nodes, sticking Γ3,2 nodes).
fn state_counts(rows: &Rows, step: &Step) -> (usize, usize) {
    let flags = state_flags(rows, step);
    let active = flags[..rows.n_contact].iter().filter(|&&f| f).count();
    let stick = flags[rows.n_contact..].iter().filter(|&&f| f).count();
    (active, stick / rows.block.max(1))
}

fn write_frame(
    series: &mut Series,
    disc: &Discretization,
    scene: &Scene,
    rows: &Rows,
    step: &Step,
) -> Result<()> {
    let nn = disc.nodes.len();
    let u = disc.nodal(step.u);
    let w = disc.nodal(step.w);
    let (stress, von_mises) = disc.stress(step.w, step.u, step.m, scene.model);
    // Nodal tractions from the multipliers: p = λ_i / ∫φ_i (contact pressure, ≥ 0) and the
    // friction traction γ_i / ∫φ_i: a scalar along τ_i in 2D, the tangential vector
    // Σ_k γ_ik τ_ik / ∫φ_i in 3D.
    let fc = if disc.dim == 2 { 1 } else { 3 };
    let mut pressure = vec![0.0; nn];
    let mut friction = vec![0.0; fc * nn];
    let mut state = vec![0.0; nn];
    for ((i, r), active) in rows.rows.iter().enumerate().zip(state_flags(rows, step)) {
        if i < rows.n_contact {
            pressure[r.node] = step.z[i] / r.area;
        } else if fc == 1 {
            friction[r.node] = step.z[i] / r.area;
        } else {
            for (k, t) in r.dir.iter().enumerate() {
                friction[3 * r.node + k] += step.z[i] * t / r.area;
            }
        }
        if active {
            state[r.node] = 1.0;
        }
    }
    let frame = Frame {
        step: step.n,
        time: step.t,
        point_data: vec![
            Field {
                name: "displacement",
                components: 3,
                values: &u,
            },
            Field {
                name: "velocity",
                components: 3,
                values: &w,
            },
            Field {
                name: "contact_pressure",
                components: 1,
                values: &pressure,
            },
            Field {
                name: "friction_traction",
                components: fc,
                values: &friction,
            },
            Field {
                name: "contact_state",
                components: 1,
                values: &state,
            },
        ],
        cell_data: vec![
            Field {
                name: "stress",
                components: 6,
                values: &stress,
            },
            Field {
                name: "von_mises",
                components: 1,
                values: &von_mises,
            },
        ],
    };
    series.write(&frame)?;
    Ok(())
}
