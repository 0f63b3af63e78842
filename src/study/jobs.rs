//! A study's cases side by side: `study … --jobs N` (issue 28).
//!
//! Each case runs in a process of its own: the current executable's hidden command
//! `study-case` ([`run_case`]), not `run` into a case directory, because a study needs more
//! of a case than a run directory gives: its wall time without output, the median of
//! `--repeat` runs, and the kernel handed over as an expression (`--kernel-compare`). The
//! process writes u_N per node as the bits of its f64 values, with its times, into a result
//! file; this process reads and discretizes the case's mesh (which is deterministic; once
//! per mesh, `shared::Discs`) for the error norms. The numbers of the report are therefore
//! those of `--jobs 1`, bit for bit.
//!
//! - Order: the longest case first (the longest-processing-time rule: a long case started
//!   last runs alone at the end), by the size of its mesh file times its steps, an estimate
//!   that reads nothing; ties in the order of the study.
//! - Packing: a case starts while fewer than N run and the memory of its run and of the
//!   running ones fits in the share of the available memory a run may plan: `check`'s
//!   estimate of what the steps hold ([`crate::resources::Estimate`]) plus
//!   [`crate::resources::SETUP_MEMORY`] each; a case that does not fit waits, unless nothing runs.
//! - This process, while it waits, makes the transfers of the cases' meshes onto their
//!   references' meshes (`shared::Transfers`) for the error norms, which would otherwise
//!   run alone after the last case.
//! - Threads: each process gets the study's threads (`--threads`, else the cores it may
//!   use: `threads::count`) / N of them (at least 1) through `VISCONTACT_THREADS`.
//! - Failure: a case whose process fails or is killed stops the study: the other processes
//!   are stopped and the error names the case (the process's own message is on stderr
//!   above). Ctrl-C reaches the processes of the terminal's foreground group alike: the
//!   study stops with them and is run again from the start, as a study run one case after
//!   another is.

use super::plan::Plan;
use super::shared::{Discretized, Discs, Transfers};
use super::{solve_case_timed, Case, KernelForm, Prepared, Solved, StudyOptions};
use crate::resources::{available_memory, MARGIN};
use crate::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

/// What a case's process hands back: u_N per node as f64 bits, and its times.
#[derive(Serialize, Deserialize)]
struct CaseResult {
    u_bits: Vec<[u64; 3]>,
    wall_s: f64,
    steps_s: f64,
    runs: usize,
}

/// The hidden command `study-case`: solves one case of a study as a study does and writes
/// its result to `result`.
pub fn run_case(scene_path: &Path, overrides: &[String], c: &Case, result: &Path) -> Result<()> {
    let (s, _) = solve_case_timed(scene_path, overrides, c)?;
    let out = CaseResult {
        u_bits: s.u.iter().map(|v| v.map(f64::to_bits)).collect(),
        wall_s: s.wall_s,
        steps_s: s.steps_s,
        runs: s.runs,
    };
    let json = serde_json::to_vec(&out).map_err(|e| Error::solve(e.to_string()))?;
    crate::output::write_atomic(result, &json)
}

/// A case's process and what it needs when it ends.
struct Job {
    index: usize,
    child: Child,
    prepared: Prepared,
    memory: f64,
    result: PathBuf,
}

/// The processes running; those still running when it is dropped (a failed study) are
/// stopped and reaped.
struct Running(Vec<Job>);

impl Drop for Running {
    fn drop(&mut self) {
        for mut r in self.0.drain(..) {
            let _ = r.child.kill();
            let _ = r.child.wait();
        }
    }
}

/// A directory for the result files, removed with what it holds when dropped.
struct Scratch(PathBuf);

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Solves the cases of `plan` in up to `opts.jobs` processes at a time (`solved[i]` solves
/// `plan.cases[i]`), and makes the transfers of their error norms meanwhile.
pub(super) fn solve_side_by_side(
    scene_path: &Path,
    opts: &StudyOptions,
    plan: &Plan,
    transfers: &mut Transfers,
) -> Result<Vec<(Solved, &'static str)>> {
    let cases = &plan.cases;
    let errors: Vec<(usize, usize)> = plan.errors().collect();
    let scratch =
        Scratch(std::env::temp_dir().join(format!("viscontact-study-{}", std::process::id())));
    std::fs::create_dir_all(&scratch.0).map_err(|e| Error::io(&scratch.0, e))?;
    let threads = (crate::threads::count() / opts.jobs).max(1);
    let budget = available_memory()?.map(|m| MARGIN * m);
    let mut solved: Vec<Option<(Solved, &'static str)>> = cases.iter().map(|_| None).collect();
    let mut running = Running(Vec::new());
    let (mut discs, mut meshes) = (Discs::default(), vec![None; cases.len()]);
    let mut order = longest_first(scene_path, cases).into_iter();
    let mut next: Option<(usize, Prepared)> = None;
    loop {
        if next.is_none() {
            if let Some(i) = order.next() {
                let p = Prepared::of_case(scene_path, &opts.overrides, &cases[i], &mut discs)?;
                meshes[i] = Some(p.mesh.clone());
                next = Some((i, p));
            }
        }
        let in_use: f64 = running.0.iter().map(|r| r.memory).sum();
        let fits = |p: &Prepared| budget.is_none_or(|b| in_use + p.memory() <= b);
        match next.take() {
            Some((i, p)) if running.0.is_empty() || (running.0.len() < opts.jobs && fits(&p)) => {
                let job = start(scene_path, opts, &cases[i], (i, p), (&scratch.0, threads))?;
                running.0.push(job);
            }
            waiting => {
                next = waiting;
                if running.0.is_empty() {
                    break;
                }
                let (i, s) = wait_any(&mut running, cases, || {
                    transfer_one(&errors, &meshes, transfers)
                })?;
                solved[i] = Some(s);
            }
        }
    }
    Ok(solved
        .into_iter()
        .map(|s| s.expect("every case ran"))
        .collect())
}

/// The order in which the cases start (module docs).
fn longest_first(scene_path: &Path, cases: &[Case]) -> Vec<usize> {
    let dir = scene_path.parent().unwrap_or(Path::new(""));
    let cost = |c: &Case| {
        let bytes = std::fs::metadata(dir.join(&c.mesh)).map_or(0, |m| m.len());
        u128::from(bytes) * (c.steps as u128 + 1)
    };
    let mut order: Vec<usize> = (0..cases.len()).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(cost(&cases[i])));
    order
}

/// Makes one transfer that an error norm needs and whose two meshes are discretized, if
/// one is left; false if none is.
fn transfer_one(
    errors: &[(usize, usize)],
    meshes: &[Option<Discretized>],
    transfers: &mut Transfers,
) -> bool {
    for &(i, r) in errors {
        if let (Some(s), Some(t)) = (&meshes[i], &meshes[r]) {
            if !transfers.has(&s.mesh, &t.mesh) {
                transfers.between((&s.mesh, &s.disc), (&t.mesh, &t.disc));
                return true;
            }
        }
    }
    false
}

/// Starts the process of case `i` (prepared as `p`), writing its result into `dir`, with
/// `threads` threads.
fn start(
    scene_path: &Path,
    opts: &StudyOptions,
    c: &Case,
    (index, prepared): (usize, Prepared),
    (dir, threads): (&Path, usize),
) -> Result<Job> {
    super::say(
        opts.progress,
        &format!("study: {c} … (a process of its own)"),
    );
    let exe = std::env::current_exe().map_err(|e| Error::io(Path::new("current_exe"), e))?;
    let result = dir.join(format!("case_{index}.json"));
    let mut cmd = Command::new(&exe);
    cmd.arg("study-case")
        .arg(scene_path)
        .args(["--mesh", &c.mesh, "--steps", &c.steps.to_string()])
        .arg("--result")
        .arg(&result)
        .env(crate::threads::ENV, threads.to_string())
        .stdin(Stdio::null())
        .stdout(Stdio::null());
    if c.form == KernelForm::Expression {
        cmd.arg("--expression");
    }
    if let Some(r) = c.repeat {
        cmd.args(["--repeat", &r.to_string()]);
    }
    for o in &opts.overrides {
        cmd.arg(format!("--set={o}"));
    }
    let child = cmd.spawn().map_err(|e| Error::io(&exe, e))?;
    let memory = prepared.memory();
    Ok(Job {
        index,
        child,
        prepared,
        memory,
        result,
    })
}

/// Waits until a process ends and returns its case's solution; a process that failed fails
/// the study, naming its case. Meanwhile it calls `idle` while that finds work (returns
/// true), then sleeps between looks.
fn wait_any(
    running: &mut Running,
    cases: &[Case],
    mut idle: impl FnMut() -> bool,
) -> Result<(usize, (Solved, &'static str))> {
    loop {
        for j in 0..running.0.len() {
            let status = match running.0[j].child.try_wait() {
                Ok(None) => continue,
                Ok(Some(status)) => status,
                Err(e) => return Err(Error::io(Path::new("study-case"), e)),
            };
            let job = running.0.swap_remove(j);
            if !status.success() {
                return Err(Error::solve(format!(
                    "study: the case {} failed ({status}); its process's message is above",
                    cases[job.index]
                )));
            }
            return read_result(job);
        }
        if !idle() {
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

/// The solution of a case whose process succeeded.
fn read_result(r: Job) -> Result<(usize, (Solved, &'static str))> {
    let bytes = std::fs::read(&r.result).map_err(|e| Error::io(&r.result, e))?;
    let out: CaseResult = serde_json::from_slice(&bytes)
        .map_err(|e| Error::solve(format!("{}: {e}", r.result.display())))?;
    let u = out.u_bits.iter().map(|v| v.map(f64::from_bits)).collect();
    let (mut s, given) = r.prepared.solved(u, out.wall_s, out.steps_s);
    s.runs = out.runs;
    Ok((r.index, (s, given)))
}
