//! A study on a cluster through Slurm: `study … --emit slurm DIR` writes a job array of its
//! cases, `study --collect DIR` makes the tables and plots once the array has run (issue 28).
//!
//! Each case is a `viscontact run` of the scene into `DIR/runs/<id>/` with the overrides
//! that make it the case (`mesh.file`, `time.steps`) and that keep the output small and
//! exact (`output.every = N`: the first and the last frame; displacement only, in float64).
//! A run, not the hidden `study-case` of `--jobs`, because a task must survive its time
//! limit: Slurm sends SIGTERM 120 s before it, the run stops after its step with a
//! checkpoint, and the task run again resumes it (`viscontact resume`), bit for bit the run
//! that never stopped. `--collect` reads u_N from each run's last frame (float64: the bits
//! of the solution) and rebuilds the case's discretization, so the numbers are those of a
//! local study; the wall times are the runs' own (`summary.json`, output included).
//!
//! DIR holds
//! - `study.json`: what the study is (scene, levels, families, meshes, overrides), read back
//!   by `--collect`;
//! - `runs.tsv`: a row per run: its id (the array index), its output directory (relative to
//!   DIR) and its `--set` overrides, tab-separated;
//! - `array.sh`: the job array, `--array=0-<last>%<at once>`, `--cpus-per-task`, `--mem`
//!   from `check`'s estimate, `--signal=B:TERM@120`; a task reads its row by
//!   `SLURM_ARRAY_TASK_ID`, exits 0 at once when its run is complete, resumes a run that
//!   left a checkpoint and else starts it;
//! - `collect.sh`: `viscontact study --collect DIR`;
//! - `submit.sh`: `sbatch array.sh`, then `sbatch --dependency=afterok:<array job>
//!   collect.sh`.

use super::meshes::Meshes;
use super::plan::{Case, Plan};
use super::shared::{Discs, Transfers};
use super::{
    assemble, check_levels, MeshFamily, Prepared, Solved, StudyOptions, StudyReport, Timed, Vary,
};
use crate::run::slurm::{exe_line, quoted, write_script};
use crate::{Error, Result};
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// How the job array is written.
#[derive(Clone, Debug)]
pub struct SlurmOptions {
    /// The directory to write.
    pub dir: PathBuf,
    /// Tasks running at once (`%K` of `--array`; default: all).
    pub at_once: Option<usize>,
    /// `--cpus-per-task`, also each run's `VISCONTACT_THREADS` (default 4).
    pub cpus_per_task: usize,
}

/// What a study is, as `study.json` keeps it for `--collect`: paths made absolute.
#[derive(Serialize, Deserialize)]
struct Saved {
    scene: PathBuf,
    levels: Vec<usize>,
    reference: usize,
    vary: Vec<Vary>,
    fixed: Option<usize>,
    mesh_pattern: Option<String>,
    meshes: Vec<PathBuf>,
    overrides: Vec<String>,
}

fn absolute(p: &Path) -> Result<PathBuf> {
    std::path::absolute(p).map_err(|e| Error::io(p, e))
}

impl Saved {
    fn new(scene_path: &Path, opts: &StudyOptions) -> Result<Saved> {
        let (mesh_pattern, meshes) = match &opts.meshes {
            Some(MeshFamily::Pattern(p)) => (Some(p.clone()), Vec::new()),
            Some(MeshFamily::List(l)) => {
                (None, l.iter().map(|p| absolute(p)).collect::<Result<_>>()?)
            }
            None => (None, Vec::new()),
        };
        Ok(Saved {
            scene: absolute(scene_path)?,
            levels: opts.levels.clone(),
            reference: opts.reference,
            vary: opts.vary.clone(),
            fixed: opts.fixed,
            mesh_pattern,
            meshes,
            overrides: opts.overrides.clone(),
        })
    }

    /// The options of the study run by the array: one run per case.
    fn options(&self) -> StudyOptions {
        StudyOptions {
            levels: self.levels.clone(),
            reference: self.reference,
            vary: self.vary.clone(),
            fixed: self.fixed,
            meshes: match (&self.mesh_pattern, self.meshes.is_empty()) {
                (Some(p), _) => Some(MeshFamily::Pattern(p.clone())),
                (None, false) => Some(MeshFamily::List(self.meshes.clone())),
                (None, true) => None,
            },
            repeat: Some(1),
            overrides: self.overrides.clone(),
            ..StudyOptions::default()
        }
    }
}

/// The `--set` overrides of the run of case `c`: the study's, then those that make the case
/// and keep its output to the last frame's displacement in float64.
fn run_overrides(overrides: &[String], c: &Case) -> Vec<String> {
    let mut sets = overrides.to_vec();
    sets.extend([
        format!("mesh.file={}", c.mesh),
        format!("time.steps={}", c.steps),
        format!("output.every={}", c.steps),
        "output.format=\"vtu\"".into(),
        "output.precision=\"float64\"".into(),
        "output.fields=[\"displacement\"]".into(),
    ]);
    sets
}

/// The output directory of run `id`, relative to the array's directory.
fn run_dir(id: usize) -> String {
    format!("runs/{id:04}")
}

/// Writes the job array of a study (module docs) and returns the files written.
pub fn emit(scene_path: &Path, opts: &StudyOptions, slurm: &SlurmOptions) -> Result<Vec<PathBuf>> {
    if opts.kernel_compare {
        return Err(Error::input(
            "study: --kernel-compare runs a kernel no scene key gives; it cannot be a run of a \
             job array (run it locally, with --jobs)",
        ));
    }
    check_levels(opts)?;
    let saved = Saved::new(scene_path, opts)?;
    let opts = saved.options();
    let plan = Plan::new(&opts, &Meshes::for_study(&saved.scene, &opts)?)?;
    let mut rows = String::from("id\tout\toverrides\n");
    let mut memory: f64 = 0.0;
    let mut discs = Discs::default();
    for (id, c) in plan.cases.iter().enumerate() {
        let sets = run_overrides(&opts.overrides, c);
        if let Some(bad) = sets.iter().find(|s| s.contains(['\t', '\n'])) {
            return Err(Error::input(format!(
                "study --emit slurm: the override '{bad}' holds a tab or a line break, which \
                 runs.tsv cannot hold"
            )));
        }
        let _ = writeln!(rows, "{id}\t{}\t{}", run_dir(id), sets.join("\t"));
        let p = Prepared::of_case(&saved.scene, &opts.overrides, c, &mut discs)?;
        memory = memory.max(p.memory());
    }
    let dir = absolute(&slurm.dir)?;
    std::fs::create_dir_all(dir.join("logs")).map_err(|e| Error::io(&dir, e))?;
    let script = Script {
        dir: &dir,
        scene: &saved.scene,
        exe: &std::env::current_exe().map_err(|e| Error::io(Path::new("current_exe"), e))?,
        runs: plan.cases.len(),
        at_once: slurm.at_once.unwrap_or(plan.cases.len()),
        cpus: slurm.cpus_per_task,
        mem_mib: (memory / (1024.0 * 1024.0)).ceil() as u64,
    };
    let json = serde_json::to_string_pretty(&saved).expect("the options serialize") + "\n";
    let files = [
        ("study.json", json),
        ("runs.tsv", rows),
        ("array.sh", script.array()),
        ("collect.sh", script.collect()),
        ("submit.sh", script.submit()),
    ];
    let mut written = Vec::new();
    for (name, text) in files {
        let path = dir.join(name);
        match name.ends_with(".sh") {
            true => write_script(&path, &text)?,
            false => crate::output::write_atomic(&path, text.as_bytes())?,
        }
        written.push(path);
    }
    Ok(written)
}

/// What the scripts say.
struct Script<'a> {
    dir: &'a Path,
    scene: &'a Path,
    exe: &'a Path,
    runs: usize,
    at_once: usize,
    cpus: usize,
    mem_mib: u64,
}

impl Script<'_> {
    fn array(&self) -> String {
        format!(
            r#"#!/bin/bash
# The runs of a viscontact study, one array task per row of runs.tsv (written by
# `viscontact study … --emit slurm`). --mem: check's estimate of the largest run's steps
# plus 1 GiB for its mesh, matrices and factor; raise it for large 3D meshes. SIGTERM
# 120 s before the time limit (B: to this shell, which execs viscontact) makes the run stop
# after its step with a checkpoint; submitting the array again resumes it.
#SBATCH --job-name=viscontact-study
#SBATCH --array=0-{last}%{at_once}
#SBATCH --cpus-per-task={cpus}
#SBATCH --mem={mem}M
#SBATCH --signal=B:TERM@120
#SBATCH --output={logs}/%A_%a.out
set -euo pipefail
DIR={dir}
SCENE={scene}
{exe}
IFS=$'\t' read -r -a row < <(awk -F'\t' -v id="$SLURM_ARRAY_TASK_ID" 'NR > 1 && $1 == id' "$DIR/runs.tsv") || true
if [ "${{#row[@]}}" -lt 2 ]; then
  echo "runs.tsv has no run $SLURM_ARRAY_TASK_ID" >&2
  exit 2
fi
out="$DIR/${{row[1]}}"
if grep -qs '"status": "completed"' "$out/summary.json"; then
  echo "run $SLURM_ARRAY_TASK_ID is complete"
  exit 0
fi
export VISCONTACT_THREADS="${{SLURM_CPUS_PER_TASK:-{cpus}}}"
if [ -f "$out/checkpoint.h5" ]; then
  exec "$VISCONTACT" resume "$out/checkpoint.h5" --quiet
fi
sets=()
for s in "${{row[@]:2}}"; do sets+=(--set "$s"); done
exec "$VISCONTACT" run "$SCENE" "${{sets[@]}}" --out "$out" --quiet
"#,
            last = self.runs - 1,
            at_once = self.at_once,
            cpus = self.cpus,
            mem = self.mem_mib,
            dir = quoted(self.dir),
            logs = self.dir.join("logs").display(),
            scene = quoted(self.scene),
            exe = exe_line(self.exe),
        )
    }

    fn collect(&self) -> String {
        format!(
            "#!/bin/bash\n# The tables and plots of the study, once every run of array.sh is complete.\n\
             #SBATCH --job-name=viscontact-collect\n#SBATCH --mem={mem}M\n\
             #SBATCH --output={logs}/collect_%j.out\nset -euo pipefail\n{exe}\n\
             exec \"$VISCONTACT\" study --collect {dir}\n",
            mem = self.mem_mib,
            logs = self.dir.join("logs").display(),
            dir = quoted(self.dir),
            exe = exe_line(self.exe),
        )
    }

    fn submit(&self) -> String {
        format!(
            "#!/bin/bash\n# Submits the runs, and the collect step to run once they all succeeded.\n\
             set -euo pipefail\narray=$(sbatch --parsable {dir}/array.sh)\n\
             sbatch --dependency=afterok:\"${{array%%;*}}\" {dir}/collect.sh\n",
            dir = quoted(self.dir),
        )
    }
}

/// The study of a job array whose runs are complete: the tables of a local study, the wall
/// times those of the runs.
pub fn collect(dir: &Path) -> Result<StudyReport> {
    let path = dir.join("study.json");
    let text = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))?;
    let saved: Saved = serde_json::from_str(&text)
        .map_err(|e| Error::input(format!("{}: {e}", path.display())))?;
    let opts = saved.options();
    let meshes = Meshes::for_study(&saved.scene, &opts)?;
    let plan = Plan::new(&opts, &meshes)?;
    let mut discs = Discs::default();
    let solved = plan
        .cases
        .iter()
        .enumerate()
        .map(|(id, c)| collect_run(&saved, c, (&dir.join(run_dir(id)), id), &mut discs))
        .collect::<Result<Vec<_>>>()?;
    let mut transfers = Transfers::default();
    let mut report = assemble(
        &saved.scene,
        &opts,
        (&meshes, &plan),
        &solved,
        &mut transfers,
    );
    report.timed = Timed::SlurmArray;
    Ok(report)
}

/// The solution of case `c` (run `id`) from its complete run in `out`.
fn collect_run(
    saved: &Saved,
    c: &Case,
    (out, id): (&Path, usize),
    discs: &mut Discs,
) -> Result<(Solved, &'static str)> {
    let summary = out.join("summary.json");
    let text = std::fs::read_to_string(&summary).unwrap_or_default();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap_or_default();
    if v["status"] != "completed" {
        return Err(Error::input(format!(
            "study --collect: run {id} ({c}) in {} is not complete (status: {}); submit \
             array.sh again: it resumes the runs that stopped",
            out.display(),
            v["status"]
                .as_str()
                .unwrap_or("not started, no summary.json")
        )));
    }
    let (_, frames) = crate::output::read::read_series(out)?;
    let last = frames
        .last()
        .ok_or_else(|| Error::input(format!("{}: no frames", out.display())))?;
    let frame = crate::output::read::read_frame(&last.1)?;
    let u = frame
        .point_field("displacement")
        .filter(|a| a.components == 3)
        .ok_or_else(|| Error::input(format!("{}: no displacement", last.1.path().display())))?
        .values
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    let time = |key: &str| v["timing"][key].as_f64().unwrap_or(f64::NAN);
    let prepared = Prepared::of_case(&saved.scene, &saved.overrides, c, discs)?;
    Ok(prepared.solved(u, time("total_s"), time("steps_s")))
}
