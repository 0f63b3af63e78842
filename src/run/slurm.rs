//! One run as a Slurm job that resumes itself: `viscontact run SCENE --emit slurm DIR`
//! writes `DIR/job.sh` (and `DIR/logs/`), which `sbatch DIR/job.sh` submits.
//!
//! A job runs the scene into its output directory, or resumes it from the checkpoint an
//! earlier job left. Slurm sends SIGTERM 120 s before the time limit (`--signal=B:TERM@120`,
//! to the batch shell, which passes it on): the run stops after its step with a checkpoint
//! (exit 143), and the job submits itself again. The next job resumes, bit for bit the run
//! that never stopped (docs/restart.md), until summary.json says "completed". A job whose
//! run solved no step since the job before (a step longer than the time limit, a failure)
//! is not submitted again: its exit status and log say why.
//!
//! The script's lines come from `check`: `--mem` is the run's estimate (what grows with the
//! steps, the stored factor or the contact solver's matrices, and 1 GiB for the mesh and
//! the rest of its setup; for a run through PETSc what `check --ranks` says a rank holds),
//! for each of a node's tasks. The cores of a task are its threads
//! (`--cpus-per-task`). A job of several tasks (`--nodes`, `--ntasks-per-node`) starts
//! them with `srun` as the ranks of one run, which only a build with PETSc and a run whose
//! steps spread over ranks allow (`crate::ranks`); srun passes the SIGTERM on to every rank.

use super::{default_out, setup};
use crate::output::write_atomic;
use crate::resources::{human, Estimate, SETUP_MEMORY};
use crate::solver::choice::Descriptor;
use crate::{Error, Result};
use std::path::{Path, PathBuf};

/// What the job asks of Slurm.
#[derive(Clone, Debug)]
pub struct JobOptions {
    /// The directory of `job.sh` and `logs/`.
    pub dir: PathBuf,
    /// `--cpus-per-task`, the run's threads.
    pub cpus_per_task: usize,
    /// `--time`, as Slurm writes it (e.g. `1-00:00:00`); None: the partition's default.
    pub time: Option<String>,
    /// `--nodes` and `--ntasks-per-node`: the run's ranks (`crate::ranks`), 1 and 1 for one
    /// process.
    pub nodes: usize,
    pub ntasks_per_node: usize,
}

/// A path as a single-quoted shell word.
pub fn quoted(p: &Path) -> String {
    word(&p.display().to_string())
}

/// Text as a single-quoted shell word.
fn word(s: &str) -> String {
    format!("'{}'", s.replace('\'', r"'\''"))
}

/// The line that sets `$VISCONTACT`, unless the environment sets it, to `exe`. An
/// assignment, not `"${VISCONTACT:-'…'}"`: inside double quotes the single quotes would stay
/// part of the word (issue 49: `bash collect.sh` exited 127).
pub fn exe_line(exe: &Path) -> String {
    format!("VISCONTACT=${{VISCONTACT:-{}}}", quoted(exe))
}

/// Writes `DIR/job.sh` for the run of `scene_path` with `overrides` into `out` (default:
/// the run's default directory) and returns it with the memory it asks for.
pub fn emit(
    scene_path: &Path,
    overrides: &[String],
    out: Option<&Path>,
    job: &JobOptions,
) -> Result<(PathBuf, f64)> {
    if let Some(t) = job
        .time
        .as_deref()
        .filter(|t| t.is_empty() || t.contains(char::is_whitespace))
    {
        return Err(Error::input(format!(
            "run --emit slurm: --time {t:?}: write Slurm's form, e.g. 1-00:00:00 or 90:00"
        )));
    }
    let started = std::time::Instant::now();
    let (scene, _mesh, disc) = setup(scene_path, overrides)?;
    let setup_s = started.elapsed().as_secs_f64();
    if !scene.checkpoint.enabled {
        return Err(Error::input(format!(
            "{}: [checkpoint] enabled = false: the job resumes from checkpoints after its \
             time limit; enable them (the default) to write a job",
            scene_path.display()
        )));
    }
    let mut solver = Descriptor::of_run(&scene, &disc)?;
    check_ranks(job, &solver)?;
    let plans = crate::history::Plans::new(&scene)?;
    let estimate = Estimate::new(&scene, &disc, 0).with_plans(&plans, &disc);
    // A run through PETSc: what `check --ranks` says a rank holds, and a step's time.
    #[cfg(feature = "petsc")]
    let plan = super::ranks_plan(
        &scene,
        &disc,
        &solver,
        (job.nodes * job.ntasks_per_node, None),
        &estimate,
    )?
    .map(|p| p.timed(&disc));
    #[cfg(feature = "petsc")]
    let (rank, step_s) = (
        plan.as_ref().map(|p| p.per_rank()),
        plan.and_then(|p| p.step_s()),
    );
    #[cfg(not(feature = "petsc"))]
    let (rank, step_s): (Option<f64>, Option<f64>) = (None, None);
    let estimated = step_s.map(|step| run_seconds(setup_s, scene.time.steps, step));
    let task = match rank {
        Some(rank) => rank,
        None => {
            let factor = solver.factor_bytes(&disc)?.unwrap_or(0.0);
            let contact = solver.contact().and_then(|p| p.memory).unwrap_or(0.0);
            estimate.memory() + factor + contact + SETUP_MEMORY
        }
    };
    let memory = task * job.ntasks_per_node as f64;
    let out = match out {
        Some(o) => o.to_path_buf(),
        None => default_out(&scene)?,
    };
    // A checkpoint already there would be resumed by the first job, whatever scene it is of.
    if ["summary.json", "checkpoint.h5"]
        .iter()
        .any(|f| out.join(f).exists())
    {
        return Err(Error::input(format!(
            "run --emit slurm: {} holds a run already; the job starts its run there and \
             resumes only what its own jobs left: give another --out, or remove that run \
             (to continue it, `viscontact resume {}/checkpoint.h5`)",
            out.display(),
            out.display()
        )));
    }
    let absolute = |p: &Path| std::path::absolute(p).map_err(|e| Error::io(p, e));
    let dir = absolute(&job.dir)?;
    std::fs::create_dir_all(dir.join("logs")).map_err(|e| Error::io(&dir, e))?;
    let script = Script {
        name: &scene.name,
        dir: &dir,
        scene: &absolute(scene_path)?,
        overrides,
        out: &absolute(&out)?,
        exe: &std::env::current_exe().map_err(|e| Error::io(Path::new("current_exe"), e))?,
        job,
        mem_mib: (memory / (1024.0 * 1024.0)).ceil() as u64,
        estimated,
    };
    let path = dir.join("job.sh");
    write_script(&path, &script.text())?;
    Ok((path, memory))
}

/// Refuses (exit 2) a job of several ranks whose run does not spread over them
/// (`crate::ranks`), and a count of none.
fn check_ranks(job: &JobOptions, solver: &Descriptor) -> Result<()> {
    let ranks = job.nodes * job.ntasks_per_node;
    let why = match ranks {
        0 => "a job has at least one node and one task on each".to_string(),
        _ => match super::why_not_spread(solver, ranks) {
            None => return Ok(()),
            Some(why) => why,
        },
    };
    Err(Error::input(format!(
        "run --emit slurm: --nodes {} --ntasks-per-node {}: {why}; otherwise write --nodes 1 \
         --ntasks-per-node 1 and give the node's cores as threads (--cpus-per-task)",
        job.nodes, job.ntasks_per_node
    )))
}

/// Writes a shell script (atomically) and makes it executable.
pub fn write_script(path: &Path, text: &str) -> Result<()> {
    write_atomic(path, text.as_bytes())?;
    use std::os::unix::fs::PermissionsExt;
    let mode = std::fs::Permissions::from_mode(0o755);
    std::fs::set_permissions(path, mode).map_err(|e| Error::io(path, e))
}

/// What the script says.
struct Script<'a> {
    name: &'a str,
    dir: &'a Path,
    scene: &'a Path,
    overrides: &'a [String],
    out: &'a Path,
    exe: &'a Path,
    job: &'a JobOptions,
    mem_mib: u64,
    /// `check`'s estimate of the whole run in seconds, where it has one (`run_seconds`).
    estimated: Option<f64>,
}

/// What the job asks for a run's time where `--time` is not given: 1.5 times `check`'s
/// estimate, twice the setup measured here (PETSc's multigrid besides it) and `steps`
/// steps of `step_s` (`ranks::Plan::timed`).
fn run_seconds(setup_s: f64, steps: usize, step_s: f64) -> f64 {
    1.5 * (2.0 * setup_s + steps as f64 * step_s)
}

/// Slurm's `--time` for `seconds`, in whole minutes, at least 10 and at most a day: a
/// longer run goes on in the jobs it submits, each resuming from the last checkpoint.
fn slurm_time(seconds: f64) -> String {
    let minutes = (seconds / 60.0).ceil().clamp(10.0, 24.0 * 60.0) as u64;
    format!(
        "{}-{:02}:{:02}:00",
        minutes / (24 * 60),
        minutes / 60 % 24,
        minutes % 60
    )
}

impl Script<'_> {
    fn text(&self) -> String {
        let time = match (&self.job.time, self.estimated) {
            (Some(t), _) => format!("#SBATCH --time={t}\n"),
            (None, Some(s)) => format!(
                "# --time: 1.5 × check's estimate of the run ({} s), at most a day.\n\
                 #SBATCH --time={}\n",
                s.round(),
                slurm_time(s)
            ),
            (None, None) => String::new(),
        };
        let sets: String = (self.overrides.iter())
            .map(|s| format!(" --set {}", word(s)))
            .collect();
        // The run's ranks are the job's tasks (srun starts them; one that fails ends all).
        let srun = match self.job.nodes * self.job.ntasks_per_node {
            1 => "",
            _ => "srun --kill-on-bad-exit=1 ",
        };
        format!(
            r#"#!/bin/bash
# One viscontact run as a job that resumes itself, written by `viscontact run … --emit
# slurm`. --mem: check's estimate ({mem_h} a node). SIGTERM 120 s before the time limit (B: to
# this shell, which passes it on) makes the run stop after its step with a checkpoint; the
# job then submits itself again, and the next job resumes the run, until it is complete.
# A job whose run solved no step is not submitted again. Submit it with
#   sbatch {job}
#SBATCH --job-name=viscontact-{name}
#SBATCH --nodes={nodes}
#SBATCH --ntasks-per-node={ntasks}
#SBATCH --cpus-per-task={cpus}
#SBATCH --mem={mem}M
{time}#SBATCH --signal=B:TERM@120
#SBATCH --output={logs}/%j.out
set -uo pipefail
{exe}
OUT={out}
JOB={job}
export VISCONTACT_THREADS="${{SLURM_CPUS_PER_TASK:-{cpus}}}"
field() {{ sed -n "s/^  \"$1\": \"\{{0,1\}}\([^\",]*\)\"\{{0,1\}},\{{0,1\}}\$/\1/p" "$OUT/summary.json" 2>/dev/null; }}
if [ "$(field status)" = completed ]; then
  echo "the run in $OUT is complete"
  exit 0
fi
before=$(field last_step)
if [ -f "$OUT/checkpoint.h5" ]; then
  {srun}"$VISCONTACT" resume "$OUT/checkpoint.h5" --quiet &
else
  {srun}"$VISCONTACT" run {scene}{sets} --out "$OUT" --quiet &
fi
pid=$!
trap 'kill -TERM "$pid" 2>/dev/null' TERM
while true; do
  wait "$pid"
  code=$?
  kill -0 "$pid" 2>/dev/null || break
done
if [ "$(field status)" = completed ]; then
  exit 0
fi
after=$(field last_step)
if [ "$(field status)" = interrupted ] && [ -f "$OUT/checkpoint.h5" ] && [ "$after" != "$before" ]; then
  echo "stopped after step $after: submitting $JOB again to resume"
  sbatch "$JOB" && exit 0
fi
echo "the run ended with status $code (summary.json: $(field status), last step ${{after:-none}}); not submitted again" >&2
exit "$code"
"#,
            job = quoted(&self.dir.join("job.sh")),
            mem_h = human(self.mem_mib as f64 * 1024.0 * 1024.0),
            name = self.name.replace(char::is_whitespace, "_"),
            cpus = self.job.cpus_per_task,
            nodes = self.job.nodes,
            ntasks = self.job.ntasks_per_node,
            mem = self.mem_mib,
            logs = self.dir.join("logs").display(),
            exe = exe_line(self.exe),
            out = quoted(self.out),
            scene = quoted(self.scene),
        )
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_estimated_time_is_in_slurms_form_between_ten_minutes_and_a_day() {
        assert_eq!(super::slurm_time(0.0), "0-00:10:00");
        assert_eq!(super::slurm_time(3599.5), "0-01:00:00");
        assert_eq!(super::slurm_time(3601.0), "0-01:01:00");
        assert_eq!(super::slurm_time(86_399.0), "1-00:00:00");
        assert_eq!(super::slurm_time(1e9), "1-00:00:00");
        assert_eq!(super::run_seconds(10.0, 100, 2.0), 330.0);
    }
}
