//! The `run` command as a library function: scene → mesh → discretization → effects → step
//! solver → time loop → ParaView series and summary.json. Reading this function tells the
//! whole story of a run.

mod consumers;
mod summary;

pub use summary::{ContactSummary, Final, Iterations, OutputSummary, Summary, Timing};

use crate::checkpoint::{self, RunLog};
use crate::fem::Discretization;
use crate::mesh::Mesh;
use crate::output::{write_atomic, Series};
use crate::scene::Scene;
use crate::time_loop::TimeLoop;
use crate::{Error, Result};
use consumers::{Checkpoints, Consumers, Frames, Progress, Solved, Statistics};
use std::path::{Path, PathBuf};
use std::time::Instant;
use summary::summary_json;

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
    let (cells, per_cell) = mesh.cell_nodes();
    let series = Series::create(&out, &mesh.nodes, &cells, per_cell)?;
    let identity = checkpoint::Identity::new(&scene, &mesh, &disc, None);
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
    let (cells, per_cell) = mesh.cell_nodes();
    let series = if cp.n == 0 {
        Series::create(&out, &mesh.nodes, &cells, per_cell)?
    } else {
        Series::reopen(&out, &mesh.nodes, &cells, per_cell, cp.n - 1)?
    };
    let identity = checkpoint::Identity::new(&scene, &mesh, &disc, Some(&cp));
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

/// The time loop of a run: solve step n and hand it to the consumers (statistics, frames,
/// checkpoints, progress); advance to t_{n+1} and tell them; until the last step or the
/// step the run stops after.
fn drive(d: Drive) -> Result<Outcome> {
    let Drive {
        scene,
        mesh,
        disc,
        mut tl,
        series,
        writer,
        log,
        out,
        start,
        setup_s,
        opts,
        resumed_from,
    } = d;
    let rows = tl.rows.clone();
    let mut consumers = Consumers {
        statistics: Statistics::new(log),
        frames: Frames {
            series,
            disc,
            scene,
        },
        checkpoints: Checkpoints::new(writer, scene),
        progress: Progress::new(opts.progress, tl.n(), scene.steps),
    };
    let steps_start = Instant::now();
    loop {
        let n = tl.n();
        let solved = Solved {
            step: tl.solve_step()?,
            rows: &rows,
            last: n == scene.steps,
            stop: opts.stop_after == Some(n),
        };
        consumers.solved(&solved)?;
        let (last, stop) = (solved.last, solved.stop);
        if last {
            break;
        }
        tl.advance();
        consumers.advanced(&tl)?;
        if stop {
            let Consumers {
                checkpoints,
                progress,
                ..
            } = consumers;
            progress.finish();
            let checkpoint = checkpoints.path().unwrap_or_default();
            checkpoints.writer.finish()?;
            return Ok(Outcome::Stopped {
                step: n,
                time: n as f64 * tl.history.k,
                checkpoint,
            });
        }
    }
    let Consumers {
        statistics,
        frames,
        checkpoints,
        progress,
    } = consumers;
    progress.finish();
    // The last checkpoint reaches the disk before the run reports success.
    checkpoints.writer.finish()?;
    let steps_s = steps_start.elapsed().as_secs_f64();
    // Frames an earlier (or the interrupted) run left that this series does not list.
    remove_stale_frames(&frames.series, resumed_from.unwrap_or(0));
    let timing = Timing {
        setup_s,
        steps_s,
        total_s: start.elapsed().as_secs_f64(),
    };
    let output = OutputSummary {
        directory: out.display().to_string(),
        files: frames.series.files().len(),
    };
    let summary = Summary::new(scene, mesh, disc, &tl, statistics, timing, output);
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
