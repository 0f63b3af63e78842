//! The `run` command as a library function: scene → mesh → discretization → effects → step
//! solver → time loop → ParaView series and summary.json. Reading this function tells the
//! whole story of a run.

use crate::checkpoint::{self, RunLog};
use crate::fem::Discretization;
use crate::mesh::Mesh;
use crate::output::frame::open_series;
use crate::output::{write_atomic, Series};
use crate::scene::Scene;
use crate::solver::{kkt_residual, Rows};
use crate::time_loop::{Step, TimeLoop};
use crate::{Error, Result};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// summary.json (DESIGN.md "Output of run").
#[derive(Serialize, Debug, Clone)]
pub struct Summary {
    pub name: String,
    pub scene: String,
    pub mesh: String,
    pub nodes: usize,
    pub elements: usize,
    pub dofs: usize,
    pub steps: usize,
    pub step_size: f64,
    pub end_time: f64,
    pub effects: Vec<String>,
    pub solver: String,
    pub timing: Timing,
    pub final_: Final,
    pub contact: ContactSummary,
    pub iterations: Iterations,
    pub output: OutputSummary,
    /// See `effects::warnings`.
    pub warnings: Vec<String>,
}

#[derive(Serialize, Debug, Clone)]
pub struct Timing {
    pub setup_s: f64,
    pub steps_s: f64,
    pub total_s: f64,
}

/// Norms of u_N = u_0 + kΣ_{j<N} w_j, the displacement at t_N = T.
#[derive(Serialize, Debug, Clone)]
pub struct Final {
    pub time: f64,
    pub u_l2: f64,
    /// The full H¹ norm (‖u‖²_{L²} + |u|²_{H¹})^{1/2}.
    pub u_h1: f64,
    pub u_max: f64,
}

#[derive(Serialize, Debug, Clone)]
pub struct ContactSummary {
    /// The largest n_i·w_i over Γ3,1 nodes and all steps (≤ 0 up to solver tolerance).
    pub max_violation: f64,
    /// Constrained rows: Γ3,1 nodes, Γ3,2 nodes with friction.
    pub contact_nodes: usize,
    pub friction_nodes: usize,
    /// Γ3,1 nodes with an active constraint (n·w = 0) at the last step.
    pub active_at_end: usize,
    /// Γ3,2 nodes sticking (w_τ = 0) at the last step.
    pub stick_at_end: usize,
    /// The largest relative KKT residual over all steps (see `solver::kkt_residual`).
    pub max_kkt_residual: f64,
}

#[derive(Serialize, Debug, Clone)]
pub struct Iterations {
    pub total: usize,
    pub max: usize,
    /// Iterations of the step solver at each step n = 0..=N.
    pub per_step: Vec<usize>,
}

#[derive(Serialize, Debug, Clone)]
pub struct OutputSummary {
    pub directory: String,
    pub files: usize,
}

/// The serialized form renames `final_` to `final` (a Rust keyword).
fn summary_json(s: &Summary) -> String {
    let mut v = serde_json::to_value(s).expect("summary serializes");
    if let Some(obj) = v.as_object_mut() {
        if let Some(f) = obj.remove("final_") {
            obj.insert("final".into(), f);
        }
    }
    serde_json::to_string_pretty(&v).expect("summary serializes") + "\n"
}

/// Options of a run that are not part of the scene.
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    pub out: Option<PathBuf>,
    pub overrides: Vec<String>,
    pub progress: bool,
    /// Stop once step S is solved and written: write the checkpoint of step S + 1 (the state
    /// at t_{S+1}) and return [`Outcome::Stopped`]; `viscontact resume` continues from there.
    pub stop_after: Option<usize>,
    /// Write into a directory that holds files viscontact did not write (never touching them).
    pub force: bool,
}

/// The files a run writes into its directory; anything else there is the user's.
fn ours(name: &str) -> bool {
    let name = name.strip_suffix(".tmp").unwrap_or(name);
    let frame = name
        .strip_prefix("solution_")
        .and_then(|r| r.strip_suffix(".vtu"))
        .is_some_and(|d| d.len() == 6 && d.bytes().all(|b| b.is_ascii_digit()));
    frame
        || matches!(
            name,
            "solution.pvd" | "summary.json" | "checkpoint.h5" | "checkpoint_history.h5"
        )
}

/// Refuses an output directory holding files viscontact did not write, unless `force`.
fn check_out_dir(out: &Path, force: bool) -> Result<()> {
    let Ok(entries) = std::fs::read_dir(out) else {
        return Ok(()); // does not exist yet
    };
    let foreign: Vec<String> = entries
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| !ours(n))
        .collect();
    if foreign.is_empty() || force {
        return Ok(());
    }
    Err(Error::input(format!(
        "output directory '{}' holds files viscontact did not write ({}{}); choose another \
         --out, or pass --force to write beside them (they are never touched)",
        out.display(),
        foreign
            .iter()
            .take(3)
            .map(|n| format!("'{n}'"))
            .collect::<Vec<_>>()
            .join(", "),
        if foreign.len() > 3 { ", …" } else { "" }
    )))
}

/// How a run ended.
#[derive(Debug, Clone)]
pub enum Outcome {
    /// Every step solved; summary.json written.
    Finished(Box<Summary>),
    /// Stopped by `stop_after` after step `step`; `checkpoint` continues it. No summary.json
    /// is written for a run that has not reached its end.
    Stopped {
        step: usize,
        time: f64,
        checkpoint: PathBuf,
    },
}

/// The default output directory: `out/<scene name>/`.
pub fn default_out(scene: &Scene) -> PathBuf {
    Path::new("out").join(&scene.name)
}

/// Loads everything a run needs and checks it: scene, mesh, discretization.
pub fn setup(scene_path: &Path, overrides: &[String]) -> Result<(Scene, Mesh, Discretization)> {
    let scene = Scene::load(scene_path, overrides)?;
    let mesh = read_mesh(&scene)?;
    let disc = Discretization::new(&mesh, &scene)?;
    Ok((scene, mesh, disc))
}

fn read_mesh(scene: &Scene) -> Result<Mesh> {
    Mesh::read(&scene.mesh_file).map_err(|e| match e {
        Error::Input(m) => Error::input(format!(
            "{}: key 'mesh.file': {m} (mesh.file is relative to the scene file)",
            scene.path.display()
        )),
        other => other,
    })
}

/// Runs a scene to its end (or to `stop_after`), writing the series, the checkpoints and
/// summary.json into the output directory.
pub fn run(scene_path: &Path, opts: &RunOptions) -> Result<Outcome> {
    let start = Instant::now();
    let (scene, mesh, disc) = setup(scene_path, &opts.overrides)?;
    let out = opts.out.clone().unwrap_or_else(|| default_out(&scene));
    check_out_dir(&out, opts.force)?;
    std::fs::create_dir_all(&out).map_err(|e| Error::io(&out, e))?;
    let tl = TimeLoop::new(&scene, &disc)?;
    let identity = checkpoint::Identity::new(&scene, &mesh, &disc, None);
    let series = open_series(&out, &mesh, &identity.run_id, &scene.output, None)?;
    let writer = checkpoint::Writer::new(&out, identity, scene.steps, &tl);
    let setup_s = start.elapsed().as_secs_f64();
    drive(Drive {
        scene: &scene,
        mesh: &mesh,
        disc: &disc,
        tl,
        series,
        writer,
        log: RunLog::default(),
        out,
        start,
        setup_s,
        opts,
        resumed_from: None,
    })
}

/// Options of `viscontact resume`.
#[derive(Clone, Debug, Default)]
pub struct ResumeOptions {
    /// Output directory (default: the checkpoint's directory).
    pub out: Option<PathBuf>,
    /// Only `time.end`, `output.*` and `checkpoint.*` (see [`checkpoint::Checkpoint::scene`]).
    pub overrides: Vec<String>,
    pub progress: bool,
    pub stop_after: Option<usize>,
}

/// Continues a run from its checkpoint: the stored scene (with the allowed overrides), the
/// same mesh (checked by fingerprint) and physics, the saved state; the series in the output
/// directory keeps its frames before the checkpoint's step and gets the rest, summary.json
/// describes the whole run. Bit for bit the run that never stopped.
pub fn resume(checkpoint_path: &Path, opts: &ResumeOptions) -> Result<Outcome> {
    let start = Instant::now();
    let cp = checkpoint::Checkpoint::read(checkpoint_path)?;
    let scene = cp.scene(&opts.overrides)?;
    let mesh = read_mesh(&scene).map_err(|e| {
        Error::input(format!(
            "{}: the run's mesh cannot be read: {e}",
            checkpoint_path.display()
        ))
    })?;
    let disc = Discretization::new(&mesh, &scene)?;
    cp.check(&scene, &mesh, &disc)?;
    let mut tl = TimeLoop::new(&scene, &disc)?;
    cp.restore(&mut tl)?;
    let out = opts.out.clone().unwrap_or_else(|| cp.dir());
    std::fs::create_dir_all(&out).map_err(|e| Error::io(&out, e))?;
    let identity = checkpoint::Identity::new(&scene, &mesh, &disc, Some(&cp));
    let keep_until = cp.n.checked_sub(1);
    let series = open_series(&out, &mesh, &identity.run_id, &scene.output, keep_until)?;
    let writer = checkpoint::Writer::resume(&out, identity, scene.steps, &tl, &cp);
    let setup_s = start.elapsed().as_secs_f64();
    let run_opts = RunOptions {
        out: Some(out.clone()),
        overrides: Vec::new(),
        progress: opts.progress,
        stop_after: opts.stop_after,
        force: false,
    };
    drive(Drive {
        scene: &scene,
        mesh: &mesh,
        disc: &disc,
        tl,
        series,
        writer,
        log: cp.log.clone(),
        out,
        start,
        setup_s,
        opts: &run_opts,
        resumed_from: Some(cp.n),
    })
}

/// A run in progress: what [`drive`] needs.
struct Drive<'a> {
    scene: &'a Scene,
    mesh: &'a Mesh,
    disc: &'a Discretization,
    tl: TimeLoop<'a>,
    series: Series,
    writer: checkpoint::Writer,
    log: RunLog,
    out: PathBuf,
    start: Instant,
    setup_s: f64,
    opts: &'a RunOptions,
    /// The checkpoint step a resumed run starts from.
    resumed_from: Option<usize>,
}

/// The time loop of a run: solve step n, record it, write its frame; advance; write a
/// checkpoint at every `checkpoint.every`-th step, at the last step and where the run stops.
fn drive(d: Drive) -> Result<Outcome> {
    let Drive {
        scene,
        mesh,
        disc,
        mut tl,
        mut series,
        mut writer,
        mut log,
        out,
        start,
        setup_s,
        opts,
        resumed_from,
    } = d;
    let n_steps = scene.steps;
    let first = tl.n();
    let bar = progress_bar(opts.progress, (n_steps + 1 - first) as u64);
    let rows = tl.rows.clone();
    let steps_start = Instant::now();
    let (active_at_end, stick_at_end) = loop {
        let n = tl.n();
        let step = tl.solve_step()?;
        log.iterations.push(step.report.iterations);
        let (viol, kkt) = step_checks(&rows, &step);
        log.max_violation = log.max_violation.max(viol);
        log.max_kkt_residual = log.max_kkt_residual.max(kkt);
        if n % scene.output_every == 0 || n == n_steps {
            series.write_step(disc, scene, &rows, &step, &state_flags(&rows, &step))?;
        }
        if n == n_steps {
            break state_counts(&rows, &step);
        }
        // The checkpoint after this step holds the state at t_{n+1} (before solving n + 1).
        let next = n + 1;
        let stop = opts.stop_after == Some(n);
        let checkpoint_due = scene.checkpoint
            && (stop || next == n_steps || scene.checkpoint_every.is_some_and(|e| next % e == 0));
        let flags = if checkpoint_due {
            state_flags(&rows, &step)
        } else {
            Vec::new()
        };
        tl.advance();
        if checkpoint_due {
            writer.write(&tl, &log, &flags)?;
        }
        bar.inc(1);
        if stop {
            bar.finish_and_clear();
            let checkpoint = if scene.checkpoint {
                writer.path()
            } else {
                PathBuf::new()
            };
            writer.finish()?;
            series.finish()?;
            return Ok(Outcome::Stopped {
                step: n,
                time: n as f64 * tl.history.k,
                checkpoint,
            });
        }
    };
    bar.finish_and_clear();
    // The last checkpoint reaches the disk before the run reports success.
    writer.finish()?;
    series.finish()?;
    let steps_s = steps_start.elapsed().as_secs_f64();
    // Frames an earlier (or the interrupted) run left that this series does not list.
    remove_stale_frames(&series, resumed_from.unwrap_or(0));
    // u_N = u_0 + kΣ_{j<N} w_j is the history's u at n = N (w_N is not added).
    let u_n = &tl.history.u;
    let (l2, semi) = disc.norms(u_n);
    let RunLog {
        iterations: per_step,
        max_violation,
        max_kkt_residual,
    } = log;
    let summary = Summary {
        name: scene.name.clone(),
        scene: scene.path.display().to_string(),
        mesh: mesh.path.display().to_string(),
        nodes: mesh.nodes.len(),
        elements: mesh.n_cells(),
        dofs: disc.n_free,
        steps: n_steps,
        step_size: tl.history.k,
        end_time: scene.end,
        effects: tl.effects.names().iter().map(|s| s.to_string()).collect(),
        solver: tl.solver.name().to_string(),
        timing: Timing {
            setup_s,
            steps_s,
            total_s: start.elapsed().as_secs_f64(),
        },
        final_: Final {
            time: scene.end,
            u_l2: l2,
            u_h1: (l2 * l2 + semi * semi).sqrt(),
            u_max: u_n.iter().fold(0.0f64, |a, v| a.max(v.abs())),
        },
        contact: ContactSummary {
            max_violation: if rows.n_contact == 0 {
                0.0
            } else {
                max_violation
            },
            contact_nodes: rows.n_contact,
            friction_nodes: rows.n_friction_nodes(),
            active_at_end,
            stick_at_end,
            max_kkt_residual,
        },
        iterations: Iterations {
            total: per_step.iter().sum(),
            max: per_step.iter().copied().max().unwrap_or(0),
            per_step,
        },
        output: OutputSummary {
            directory: out.display().to_string(),
            files: series.files().len(),
        },
        warnings: crate::effects::warnings(scene, disc),
    };
    write_atomic(&out.join("summary.json"), summary_json(&summary).as_bytes())?;
    Ok(Outcome::Finished(Box::new(summary)))
}

/// After a resume: frames of steps ≥ `from` left by the interrupted run that the finished
/// series does not list (a run extended past its old end no longer has a frame at the old
/// end, or one at a step beyond the new end) are removed, so the directory holds what an
/// uninterrupted run would have written.
fn remove_stale_frames(series: &Series, from: usize) {
    let Ok(entries) = std::fs::read_dir(series.dir()) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let step = name
            .strip_prefix("solution_")
            .and_then(|r| r.strip_suffix(".vtu"))
            .and_then(|r| r.parse::<usize>().ok());
        if step.is_some_and(|s| s >= from) && !series.files().iter().any(|(_, f)| *f == name) {
            let _ = std::fs::remove_file(e.path());
        }
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
