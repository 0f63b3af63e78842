//! The consumers of a run's stream of solved steps (after scikit-fem's time loop as an
//! iterator): the loop in `run::drive` solves step n, hands it to each consumer, advances to
//! t_{n+1} and tells the consumers that need the new state. Each consumer is a small type
//! that knows one job:
//!
//! - [`Statistics`]: the run-wide numbers of summary.json (iterations, the largest n·w on
//!   Γ3,1, the largest KKT residual, the contact state at the last step);
//! - [`Frames`]: the ParaView series, a frame every `output.every` steps and at the end;
//! - [`Checkpoints`]: `checkpoint.h5` at every `checkpoint.every`-th step, once
//!   `checkpoint.every_seconds` of wall time passed since the last one, before the last step
//!   and where the run stops;
//! - [`HistoryCsv`]: `history.csv`, the forces on the body at every step (`history_csv`);
//! - [`Progress`]: the progress bar on a terminal, a progress line every 10 s in a log.

use super::frame::{due, write_step, OwnFrames};
use super::history_csv::HistoryCsv;
use crate::checkpoint::{self, RunLog};
use crate::fem::Discretization;
use crate::output::Series;
use crate::scene::Scene;
use crate::solver::{kkt_residual, Rows};
use crate::time_loop::{Observer, Solved, Step, TimeLoop};
use crate::Result;
use std::sync::mpsc::Receiver;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Everything that consumes the solved steps, in the order they see them, and when the run
/// stops early.
pub(super) struct Consumers<'a> {
    pub statistics: Statistics,
    pub frames: Frames<'a>,
    pub checkpoints: Checkpoints,
    pub history: HistoryCsv,
    pub progress: Progress,
    pub stop: StopRule,
}

/// When a run stops before its last step: after step `after` (`--stop-after`) or after the
/// step being solved when a signal came, to this rank or, where the run has several, to
/// any (`crate::ranks`).
pub(super) struct StopRule {
    pub after: Option<usize>,
    pub interrupt: super::Interrupt,
    pub ranks: crate::ranks::Ranks,
}

impl StopRule {
    /// Whether the run stops after step n, and whether rank 0's clock says a checkpoint is
    /// due (`clock`, on rank 0: [`Schedule::clock`]), the same answers on every rank; a
    /// signal that reached another rank is recorded here as if it had come to this one.
    pub fn asks(&self, n: usize, clock: bool) -> (bool, bool) {
        let signal = self.interrupt.signal();
        let after = self.after == Some(n);
        // An MPI failure ends the process in PETSc's handler; were it to return, stop here.
        let said = (self.ranks.stop(signal, after, clock)).unwrap_or(crate::ranks::AfterStep {
            signal,
            stop: true,
            clock,
        });
        if let Some(s) = said.signal.filter(|_| signal.is_none()) {
            self.interrupt.raise(s);
        }
        (said.stop, said.clock)
    }

    /// A step given up (on every rank at once): the signal that did it, recorded on every
    /// rank, as `asks` does.
    pub fn share_signal(&self) {
        let _ = self.asks(usize::MAX, false);
    }
}

/// A follower rank's observer (`crate::ranks`): it writes its piece of the frames where
/// the ranks write their own, sends its part of the memory to rank 0's checkpoints,
/// nothing else, and stops with the others.
pub(super) struct Follower<'a> {
    pub stop: StopRule,
    pub frames: Option<OwnFrames>,
    pub schedule: Schedule,
    pub disc: &'a Discretization,
}

impl Observer for Follower<'_> {
    fn stop_after(&mut self, n: usize) -> bool {
        let stop;
        (stop, self.schedule.clock) = self.stop.asks(n, false);
        stop
    }

    fn solved(&mut self, s: &Solved) -> Result<()> {
        if let Some(frames) = self.frames.as_mut() {
            frames.solved(self.disc, s, &state_flags(&s.step))?;
        }
        // Its checkpoints' flags are rank 0's.
        self.schedule.solved(s, Vec::new());
        Ok(())
    }

    fn abandoned(&mut self, tl: &mut TimeLoop) -> Result<()> {
        self.stop.share_signal();
        self.schedule.abandoned();
        self.advanced(tl)
    }

    fn advanced(&mut self, tl: &mut TimeLoop) -> Result<()> {
        of_pieces(self.frames.as_ref(), self.disc, tl, self.stop.ranks)?;
        if self.schedule.due.take().is_some() {
            tl.state()?;
            tl.gather_memory(&mut |_| unreachable!("a follower gets no vector of the memory"))?;
        }
        Ok(())
    }
}

impl Observer for Consumers<'_> {
    fn stop_after(&mut self, n: usize) -> bool {
        let schedule = &mut self.checkpoints.schedule;
        let stop;
        (stop, schedule.clock) = self.stop.asks(n, schedule.clock());
        stop
    }

    fn solved(&mut self, s: &Solved) -> Result<()> {
        // The step's contact/stick flags, which three of the consumers use.
        let flags = state_flags(&s.step);
        self.statistics.solved(s, &flags);
        let von_mises = self.frames.solved(s, &flags)?;
        let rows = s.step.rows;
        let (active, stick) = state_counts(rows, &flags);
        let slip = rows.n_friction_nodes() - stick;
        self.history.solved(s, [active, stick, slip], von_mises)?;
        self.checkpoints.solved(s, flags);
        self.progress.solved(s);
        Ok(())
    }

    fn abandoned(&mut self, tl: &mut TimeLoop) -> Result<()> {
        self.stop.share_signal();
        self.checkpoints.schedule.abandoned();
        self.advanced(tl)
    }

    fn advanced(&mut self, tl: &mut TimeLoop) -> Result<()> {
        let frames = &self.frames;
        let of = of_pieces(frames.pieces.as_ref(), &frames.disc, tl, self.stop.ranks)?;
        self.statistics.of_pieces = of;
        // A checkpoint of step n + 1 may reach the disk only after the frames and the
        // history rows of steps ≤ n have: their writers run on threads of their own, and a
        // resume keeps the frames and rows before its step (a kill -9 in between lost a
        // frame for good).
        // The checkpoint records the checksums of those frames (output/verify.rs).
        if self.checkpoints.schedule.due.is_some() {
            self.frames.series.finish()?;
            self.history.finish()?;
        }
        self.checkpoints
            .advanced(tl, &self.statistics.log, &self.frames.series)
    }
}

/// Where the ranks write their own pieces of the frames (`frames`: this rank's), what
/// summary.json says of the loop's u_n, on rank 0 (a follower's own part elsewhere): the
/// squares of its norms as the ranks' pieces sum them (`Ranks::sum_at_first`), and
/// max|u_n| as the largest of the ranks' held values (`Ranks::largest`), which together
/// cover every dof with the whole's bits. Collective on several: every rank calls it where
/// the loop starts and after each step, before anything there that may fail on one rank
/// alone. None where the frames are not in pieces (rank 0 then computes both of every cell
/// and every dof itself).
pub(super) fn of_pieces(
    frames: Option<&OwnFrames>,
    disc: &Discretization,
    tl: &TimeLoop,
    ranks: crate::ranks::Ranks,
) -> Result<Option<OfPieces>> {
    let Some(frames) = frames else {
        return Ok(None);
    };
    let norms = ranks.sum_at_first(frames.norm_parts(disc, tl.u_held()))?;
    let u_max = ranks.largest(largest_abs(tl.u()))?;
    Ok(Some(OfPieces { norms, u_max }))
}

/// What summary.json says of u_n where the ranks' pieces compute it ([`of_pieces`]).
#[derive(Clone, Copy, Debug)]
pub(super) struct OfPieces {
    /// ‖u_n‖²_{L²} and |u_n|²_{H¹}.
    pub norms: [f64; 2],
    pub u_max: f64,
}

/// max|v_i|, a value that is not a number left out (0 for none).
pub(super) fn largest_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0f64, |a, x| a.max(x.abs()))
}

/// The run-wide numbers of summary.json that depend on every step so far.
pub(super) struct Statistics {
    /// What a checkpoint saves of them (iterations, running maxima).
    pub log: RunLog,
    /// Γ3,1 nodes with an active constraint and sticking Γ3,2 nodes at the last step solved.
    pub active: usize,
    pub stick: usize,
    /// The last step solved.
    pub last: Option<usize>,
    /// What summary.json says of the loop's u_n, where the ranks' pieces compute it
    /// ([`of_pieces`]).
    pub of_pieces: Option<OfPieces>,
}

impl Statistics {
    pub fn new(log: RunLog) -> Statistics {
        Statistics {
            log,
            active: 0,
            stick: 0,
            last: None,
            of_pieces: None,
        }
    }

    fn solved(&mut self, s: &Solved, flags: &[bool]) {
        let log = &mut self.log;
        log.iterations.push(s.step.report.iterations);
        let (viol, kkt) = step_checks(&s.step);
        log.max_violation = log.max_violation.max(viol);
        log.max_kkt_residual = log.max_kkt_residual.max(kkt);
        // At every step: a run that fails or stops reports the last one it solved.
        (self.active, self.stick) = state_counts(s.step.rows, flags);
        self.last = Some(s.step.n);
    }
}

/// The ParaView series: a frame at every `output.every`-th step and at the last.
pub(super) struct Frames<'a> {
    pub series: Series,
    /// Rank 0's piece where the ranks write their own pieces of a frame.
    pub pieces: Option<OwnFrames>,
    /// Shared with the writer thread, which computes the frames' fields.
    pub disc: Arc<Discretization>,
    pub rows: Arc<Rows>,
    pub scene: &'a Scene,
}

impl Frames<'_> {
    /// Writes the step's frame if one is due; the receiver of the step's largest von Mises
    /// stress where the frame has that field (`write_step`), or where the ranks write
    /// their own pieces, at every step (`OwnFrames::solved`).
    fn solved(&mut self, s: &Solved, flags: &[bool]) -> Result<Option<Receiver<f64>>> {
        if let Some(pieces) = &mut self.pieces {
            let (fields, largest) = pieces.solved(&self.disc, s, flags)?;
            if let Some(fields) = fields {
                self.series.list_pieces(s.step.n, s.step.t, fields)?;
            }
            let (tx, rx) = std::sync::mpsc::sync_channel(1);
            let _ = tx.send(largest);
            return Ok(Some(rx));
        }
        if !due(self.scene.output.every, s) {
            return Ok(None);
        }
        let (disc, rows) = (&self.disc, &self.rows);
        let model = self.scene.mesh.model;
        write_step(&mut self.series, disc, model, rows, &s.step, flags)
    }
}

/// `checkpoint.h5`: the state at t_{n+1} after step n when its [`Schedule`] says, written by
/// a thread of its own.
pub(super) struct Checkpoints {
    pub writer: checkpoint::Writer,
    pub schedule: Schedule,
}

impl Checkpoints {
    pub fn new(writer: checkpoint::Writer, scene: &Scene) -> Checkpoints {
        Checkpoints {
            writer,
            schedule: Schedule::new(scene),
        }
    }

    /// Decides whether the state after step n is saved; `flags` are the solved step's.
    fn solved(&mut self, s: &Solved, flags: Vec<bool>) {
        self.schedule.solved(s, flags);
    }

    /// The checkpoint of the loop at t_{n+1} where it is due, the memory gathered from the
    /// ranks' parts (collective on several: the followers' [`Schedule`] says the same).
    fn advanced(&mut self, tl: &mut TimeLoop, log: &RunLog, series: &Series) -> Result<()> {
        match self.schedule.due.take() {
            Some(flags) => {
                let state = tl.state()?.expect("rank 0 gets the whole state");
                let mut feed = (self.writer).write(state, log, &flags, series.checksums());
                tl.gather_memory(&mut |v| feed.send(v))?;
                feed.end()
            }
            None => Ok(()),
        }
    }

    /// `DIR/checkpoint.h5` when checkpoints are written.
    pub fn path(&self) -> Option<std::path::PathBuf> {
        self.schedule.enabled.then(|| self.writer.path())
    }
}

/// When the state at t_{n+1} after step n is saved: at every `checkpoint.every`-th step,
/// after the first step that ends `checkpoint.every_seconds` or more after the last
/// checkpoint (or the start), before the last step and where the run stops
/// (`[checkpoint] enabled = false`: never). The wall-clock checkpoints change no result: a
/// checkpoint copies the state, and resume from any of them is bit for bit. On several
/// ranks every rank keeps one, rank 0's clock reaching the others with the stop requests
/// ([`StopRule::asks`]), so that each sends its part of the memory to the same checkpoints.
pub(super) struct Schedule {
    pub enabled: bool,
    every: Option<usize>,
    every_seconds: Option<Duration>,
    steps: usize,
    /// When the last checkpoint was handed to the writer (or the loop started).
    last_written: Instant,
    /// Whether rank 0's clock said, after the step just solved, that a checkpoint is due.
    clock: bool,
    /// The contact/stick flags of the step just solved, when its checkpoint is due (none
    /// on a follower, which writes no checkpoint).
    due: Option<Vec<bool>>,
    /// Else (checkpoints enabled, not the last step) the same flags: a step given up next
    /// saves the state after this one with them (`Observer::abandoned`).
    unsaved: Option<Vec<bool>>,
}

impl Schedule {
    pub fn new(scene: &Scene) -> Schedule {
        Schedule {
            enabled: scene.checkpoint.enabled,
            every: scene.checkpoint.every,
            every_seconds: scene.checkpoint.every_seconds.map(Duration::from_secs_f64),
            steps: scene.time.steps,
            last_written: Instant::now(),
            clock: false,
            due: None,
            unsaved: None,
        }
    }

    /// Whether `checkpoint.every_seconds` have passed since the last checkpoint (rank 0's
    /// to say).
    fn clock(&self) -> bool {
        (self.every_seconds).is_some_and(|d| self.last_written.elapsed() >= d)
    }

    /// Decides whether the state after step n is saved; `flags` are the solved step's.
    fn solved(&mut self, s: &Solved, flags: Vec<bool>) {
        self.after(s.step.n, (s.last, s.stop), flags);
    }

    /// Decides whether the state after step `n` is saved, which is the run's `last` step or
    /// one it `stop`s after; `flags` are the step's.
    fn after(&mut self, n: usize, (last, stop): (bool, bool), flags: Vec<bool>) {
        let next = n + 1;
        let clock = std::mem::take(&mut self.clock);
        let due = self.enabled
            && !last
            && (stop
                || clock
                || next == self.steps
                || self.every.is_some_and(|e| next.is_multiple_of(e)));
        if due {
            self.last_written = Instant::now();
        }
        let flags = (self.enabled && !last).then_some(flags);
        (self.due, self.unsaved) = match due {
            true => (flags, None),
            false => (None, flags),
        };
    }

    /// A step given up: the state before it, the last solved step's, is saved unless its
    /// checkpoint is on disk already.
    fn abandoned(&mut self) {
        self.due = self.unsaved.take();
    }
}

/// The progress bar on a terminal; without a terminal (a batch job's log) a line every
/// [`Progress::EVERY`] on stderr: step, t, solver iterations, elapsed and estimated
/// remaining time. Nothing with `--quiet`. Both count the run's steps n = 0..=N as the run
/// numbers them, `step n/N`, a resumed run from its checkpoint's step on; the bar is
/// cleared however the run ends (dropped).
pub(super) struct Progress {
    kind: Kind,
    first: usize,
    last: usize,
    start: Instant,
    /// When the last line was printed (or the loop started).
    printed: Instant,
}

enum Kind {
    Quiet,
    Bar(indicatif::ProgressBar),
    Lines,
}

impl Progress {
    /// Seconds between two progress lines in a log.
    pub const EVERY: Duration = Duration::from_secs(10);

    /// Progress over the steps `first..=last`.
    pub fn new(enabled: bool, first: usize, last: usize) -> Progress {
        use std::io::IsTerminal;
        let kind = match (enabled, std::io::stderr().is_terminal()) {
            (false, _) => Kind::Quiet,
            (true, false) => Kind::Lines,
            (true, true) => Kind::Bar(Self::bar(first, last)),
        };
        let now = Instant::now();
        Progress {
            kind,
            first,
            last,
            start: now,
            printed: now,
        }
    }

    /// The bar over the run's N + 1 steps, filled by those solved, a resumed run's steps
    /// before its checkpoint included. Its text is [`Self::bar_text`]: indicatif's rate
    /// would count the steps before the checkpoint as solved in no time.
    fn bar(first: usize, last: usize) -> indicatif::ProgressBar {
        indicatif::ProgressBar::new(last as u64 + 1)
            .with_position(first as u64)
            .with_style(
                indicatif::ProgressStyle::with_template("{bar:40} {msg}").expect("valid template"),
            )
            .with_message(format!("step {first}/{last}"))
    }

    /// `step n/N  elapsed < remaining` once step `n` is solved ([`Self::times`]).
    fn bar_text(&self, n: usize) -> String {
        let (elapsed, remaining) = self.times(n);
        format!(
            "step {n}/{}  {} < {}",
            self.last,
            clock(elapsed),
            clock(remaining)
        )
    }

    fn solved(&mut self, s: &Solved) {
        match &self.kind {
            Kind::Quiet => {}
            Kind::Bar(bar) => {
                bar.set_message(self.bar_text(s.step.n));
                bar.inc(1);
            }
            Kind::Lines => {
                if self.printed.elapsed() >= Self::EVERY {
                    self.printed = Instant::now();
                    crate::errln!(
                        "{}",
                        self.line(s.step.n, s.step.t, s.step.report.iterations)
                    );
                }
            }
        }
    }

    /// The seconds this process has run the steps, and those it will take once step `n` is
    /// solved: the steps left cost what the steps of this process cost on average.
    fn times(&self, n: usize) -> (f64, f64) {
        let elapsed = self.start.elapsed().as_secs_f64();
        let done = (n + 1 - self.first) as f64;
        (elapsed, elapsed / done * (self.last - n) as f64)
    }

    /// `step n/N  t = …  iterations i  elapsed …  remaining ≈ …` ([`Self::times`]).
    fn line(&self, n: usize, t: f64, iterations: usize) -> String {
        let (elapsed, remaining) = self.times(n);
        format!(
            "step {n}/{}  t = {t:.6e}  iterations {iterations}  elapsed {}  remaining ≈ {}",
            self.last,
            clock(elapsed),
            clock(remaining)
        )
    }
}

impl Drop for Progress {
    /// Clears the bar: after the last step, a `--stop-after`, a signal or a failed step.
    fn drop(&mut self) {
        if let Kind::Bar(bar) = &self.kind {
            bar.finish_and_clear();
        }
    }
}

/// Seconds as `1h02m03s` / `2m03s` / `3s`.
fn clock(seconds: f64) -> String {
    let s = seconds.round() as u64;
    match (s / 3600, s / 60 % 60, s % 60) {
        (0, 0, s) => format!("{s}s"),
        (0, m, s) => format!("{m}m{s:02}s"),
        (h, m, s) => format!("{h}h{m:02}m{s:02}s"),
    }
}

/// Scale of a step's velocities and multipliers for relative tolerances (max|w_n| over
/// every dof, which a follower rank does not hold).
fn scales(step: &Step) -> (f64, f64) {
    let ws = step.w_max;
    let zs = step.z.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    (ws, zs)
}

/// The largest n·w on Γ3,1 and the relative KKT residual of a solved step.
fn step_checks(step: &Step) -> (f64, f64) {
    let rows = step.rows;
    let viol = rows.rows[..rows.n_contact]
        .iter()
        .map(|r| r.apply(step.w))
        .fold(f64::NEG_INFINITY, f64::max);
    let (ws, zs) = scales(step);
    (viol, kkt_residual(rows, step.w, step.z, ws, zs))
}

/// Γ3,1 rows with an active constraint and Γ3,2 rows whose node sticks (|w_τ| of the
/// node's block), up to 1e-9 of the largest velocity.
fn state_flags(step: &Step) -> Vec<bool> {
    let rows = step.rows;
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

/// (active Γ3,1 nodes, sticking Γ3,2 nodes) of a step's flags (`state_flags`).
fn state_counts(rows: &Rows, flags: &[bool]) -> (usize, usize) {
    let active = flags[..rows.n_contact].iter().filter(|&&f| f).count();
    let stick = flags[rows.n_contact..].iter().filter(|&&f| f).count();
    (active, stick / rows.block.max(1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn progress_line_estimates_the_remaining_time() {
        let mut p = Progress::new(false, 10, 110);
        p.start = Instant::now() - Duration::from_secs(20);
        // 10 of 100 steps (10..=19) took 20 s: 91 steps left take about 182 s.
        let line = p.line(19, 0.125, 7);
        assert!(
            line.starts_with("step 19/110  t = 1.250000e-1  iterations 7  elapsed 20s"),
            "{line}"
        );
        assert!(line.ends_with("remaining ≈ 3m02s"), "{line}");
        assert_eq!(clock(3723.4), "1h02m03s");
    }

    /// The steps after which a checkpoint is due: every 3rd, the one before the last, where
    /// rank 0's clock says (on every rank: `StopRule::asks`), where the run stops, and a
    /// step given up saves the last solved step's state unless it is saved already.
    #[test]
    fn the_schedule_saves_where_the_keys_the_clock_and_a_stop_say() {
        let mut schedule = Schedule {
            enabled: true,
            every: Some(3),
            every_seconds: None,
            steps: 10,
            last_written: Instant::now(),
            clock: false,
            due: None,
            unsaved: None,
        };
        let mut saved = Vec::new();
        // Steps 0..=10, the last one 10.
        for n in 0..=10 {
            // Rank 0's clock after step 3, shared by the stop requests' reduction.
            schedule.clock = n == 3;
            schedule.after(n, (n == 10, n == 6), vec![n % 2 == 0]);
            if let Some(flags) = schedule.due.take() {
                assert_eq!(flags, [n % 2 == 0], "the step's flags");
                saved.push(n);
            }
            assert!(!schedule.clock, "the clock is read once");
        }
        // After steps 2, 5 and 8 (the states at every 3rd step), 3 (the clock), 6 (a stop),
        // 9 (the state before the last step), none after the last.
        assert_eq!(saved, [2, 3, 5, 6, 8, 9]);
        // A step given up after step 3 saves the state after it; after step 5, whose
        // checkpoint is due already, nothing more.
        schedule.after(3, (false, false), vec![true]);
        schedule.abandoned();
        assert_eq!(schedule.due.take(), Some(vec![true]));
        schedule.after(4, (false, false), vec![false]);
        schedule.due.take();
        schedule.after(5, (false, false), vec![false]);
        assert!(schedule.due.take().is_some());
        schedule.abandoned();
        assert_eq!(schedule.due, None);
        schedule.enabled = false;
        schedule.after(5, (false, true), vec![true]);
        schedule.abandoned();
        assert_eq!(schedule.due, None, "checkpoints disabled");
    }

    /// Issue 49: the bar counted N + 1 steps and restarted at 0 after a resume.
    #[test]
    fn the_bar_counts_the_run_s_steps_from_a_resume_s_checkpoint() {
        let mut p = Progress::new(false, 81, 160);
        p.start = Instant::now() - Duration::from_secs(20);
        // Steps 81..=90 took 20 s: the 70 left take about 140 s.
        assert_eq!(p.bar_text(90), "step 90/160  20s < 2m20s");
        let bar = Progress::bar(81, 160);
        assert_eq!((bar.position(), bar.length()), (81, Some(161)));
        assert_eq!(bar.message(), "step 81/160");
    }
}
