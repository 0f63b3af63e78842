//! The `viscontact` command line (README.md, "Commands").

use clap::{Parser, Subcommand};
use std::num::NonZeroUsize;
use std::path::PathBuf;
use std::process::ExitCode;
use viscontact::fem::Discretization;
use viscontact::history::{Plan, Plans};
use viscontact::ranks::Ranks;
use viscontact::run::{resume, run, setup, Interrupt, Outcome, RunOptions};
use viscontact::scene::Scene;
use viscontact::{effects::Effects, mesh::Mesh, Result};

#[derive(Parser)]
#[command(
    name = "viscontact",
    version,
    about = "Quasi-static contact of viscoelastic bodies with long memory (Problem 3.1 of Xu et al. 2021)"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a scene: writes solution.pvd + solution_NNNNNN.vtu and summary.json.
    Run {
        scene: PathBuf,
        /// Output directory (default: out/<scene name>/ in the working directory).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Override a scene key by its dotted path, e.g. --set time.steps=64 (repeatable).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        #[command(flatten)]
        steps: StepFlags,
        #[command(flatten)]
        job: JobFlags,
    },
    /// Continue a run from its checkpoint: same results as if it had never stopped.
    Resume {
        /// DIR/checkpoint.h5 of a run.
        checkpoint: PathBuf,
        /// Output directory (default: the checkpoint's directory, whose series is continued).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Only time.end (the step size stays: T2/k must be whole), mesh.file (the same mesh
        /// in a new place, checked by fingerprint), output.* and checkpoint.* may be
        /// overridden, e.g. --set time.end=2.0.
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        #[command(flatten)]
        steps: StepFlags,
    },
    /// Validate a scene and print its effects, sizes and solver path; runs nothing.
    Check {
        scene: PathBuf,
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// The MPI ranks to plan for (a build with PETSc, a run through it): what each
        /// holds and does; refused where they would not fit the memory available.
        #[arg(long, value_name = "N", default_value_t = 1,
              value_parser = clap::value_parser!(u32).range(1..))]
        ranks: u32,
    },
    /// Nodes, elements, physical groups with sizes, and element quality of a gmsh mesh.
    MeshInfo {
        mesh: PathBuf,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Accuracy against cost: errors at T against a reference, orders, wall times (tables
    /// like the paper's Tables 1–3, CSV, Markdown, PNG plots).
    Study(Box<StudyArgs>),
    /// One case of a study, for `study --jobs`: solved as the study solves it, its u_N and
    /// times written to RESULT (internal: the arguments may change).
    #[command(hide = true)]
    StudyCase(StudyCaseArgs),
    /// Draw the deformed body of a run coloured by a field (the paper's Fig. 3) as a PNG.
    Plot {
        /// The output directory of a run (or its solution.pvd).
        dir: PathBuf,
        /// The frame nearest to this time, within the run's times (default: the last).
        #[arg(long)]
        time: Option<f64>,
        /// A point or cell field: von_mises, displacement, stress_XY, contact_pressure, …
        #[arg(long, default_value = "von_mises")]
        field: String,
        /// Displacement scale (default: the largest displacement is 10% of the body size).
        #[arg(long)]
        scale: Option<f64>,
        /// The PNG to write (default: <run>_<field>_t<time>.png in the current directory).
        #[arg(short = 'o', long = "output")]
        output: Option<PathBuf>,
        /// 3D runs: the direction from the body towards the eye (default 1,-1.5,-1:
        /// front, right, below, where the examples touch their foundation).
        #[arg(long, value_name = "X,Y,Z", value_parser = viscontact::plot::parse_view, allow_hyphen_values = true)]
        view: Option<[f64; 3]>,
        /// Width of the figure in pixels.
        #[arg(long, default_value_t = 1400, value_parser = clap::value_parser!(u32).range(600..=10000))]
        width: u32,
        /// Draw columns of DIR/history.csv against t instead of the body (default: the
        /// force columns; default output <run>_history.png).
        #[arg(long, conflicts_with_all = ["time", "scale", "view"])]
        history: bool,
        /// With --history: the columns to draw, e.g. reaction_Gamma1_y,load_Gamma2_y.
        #[arg(long, value_delimiter = ',', requires = "history")]
        columns: Option<Vec<String>>,
    },
}

/// `study --mesh-pattern`'s help. clap turns every `{n}` of a help text into a line break
/// (issue 49: the placeholder vanished); a style reset between `{` and `n`, which clap
/// strips off when the help is not coloured, keeps it.
fn mesh_pattern_help() -> String {
    let n = format!("{{{}n}}", clap::builder::styling::Reset);
    format!(
        "Mesh of level n, relative to the scene file: `{n}` or `{{n:03}}` for the level \
         (default: from mesh.file when it ends in _NNN.msh)"
    )
}

/// The flags that `run` and `resume` share: how the steps run and where they stop.
#[derive(clap::Args)]
struct StepFlags {
    /// Do not show a progress bar even on a terminal.
    #[arg(long)]
    quiet: bool,
    /// Stop after step N (solved and written), leaving the checkpoint of the state at
    /// t_{N+1}; `viscontact resume DIR/checkpoint.h5` continues the run.
    #[arg(long, value_name = "N")]
    stop_after: Option<usize>,
    /// Write into an output directory that also holds files viscontact did not write
    /// (they are left alone).
    #[arg(long)]
    force: bool,
    /// Threads for the steps (default: VISCONTACT_THREADS, else the cores this process
    /// may use); the results are the same bit for bit for every count.
    #[arg(long, value_name = "N")]
    threads: Option<NonZeroUsize>,
}

/// `run --emit slurm DIR`: the run as a Slurm job that resumes itself, written, not run.
#[derive(clap::Args)]
struct JobFlags {
    /// Write DIR/job.sh, a Slurm job of this run that resubmits itself until the run is
    /// complete (submit it with sbatch), instead of running.
    #[arg(long, num_args = 2, value_names = ["slurm", "DIR"], conflicts_with_all = ["stop_after", "force", "threads"])]
    emit: Vec<String>,
    /// With --emit slurm: the cores of the job's one task (its threads).
    #[arg(long, default_value_t = 4, requires = "emit", value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..))]
    cpus_per_task: usize,
    /// With --emit slurm: the time limit of each job, in Slurm's form (e.g. 1-00:00:00;
    /// default: the partition's).
    #[arg(long, requires = "emit")]
    time: Option<String>,
    /// With --emit slurm: nodes (more than 1: the run's MPI ranks, docs/cluster.md).
    #[arg(long, default_value_t = 1, requires = "emit")]
    nodes: usize,
    /// With --emit slurm: tasks per node, each a rank of the run (1: one process a node).
    #[arg(long, default_value_t = 1, requires = "emit")]
    ntasks_per_node: usize,
}

impl StepFlags {
    /// The options of `run` or `resume` (`threads` is set for the process in `main`).
    fn options(
        self,
        out: Option<PathBuf>,
        overrides: Vec<String>,
        interrupt: Interrupt,
        ranks: Ranks,
    ) -> RunOptions {
        RunOptions {
            ranks,
            out,
            overrides,
            progress: !self.quiet,
            stop_after: self.stop_after,
            force: self.force,
            interrupt,
        }
    }
}

fn main() -> ExitCode {
    // Until the command is known (clap's help and errors too), a closed reader ends the
    // process quietly; a run or a study outlives its terminal (src/console.rs).
    viscontact::console::end_quietly_on_broken_pipe();
    let cli = Cli::parse();
    let interrupt = match interrupt_for(&cli.command) {
        Ok(i) => i,
        Err(code) => return code,
    };
    let threads = match &cli.command {
        Command::Run { steps, .. } | Command::Resume { steps, .. } => steps.threads,
        Command::Study(a) => a.threads,
        _ => None,
    };
    let only_prints = !matches!(
        cli.command,
        Command::Run { .. } | Command::Resume { .. } | Command::Study(_) | Command::StudyCase(_)
    );
    // `run --emit slurm` writes a job script and runs nothing.
    let emits = matches!(&cli.command, Command::Run { job, .. } if !job.emit.is_empty());
    let mut ranks = Ranks::ONE;
    if (only_prints || emits) && viscontact::ranks::launcher_rank() > 0 {
        // `mpirun -n 4 viscontact check …` prints once, on rank 0 (whose status mpirun reports).
        return ExitCode::SUCCESS;
    }
    if !only_prints && !emits {
        viscontact::console::outlive_broken_pipes();
        // After the signal handling (which must come before any thread is started, MPI's
        // too), before anything is read.
        let (name, spreads) = match &cli.command {
            Command::Run { .. } => ("run", true),
            Command::Resume { .. } => ("resume", true),
            _ => ("study", false),
        };
        match Ranks::of_process(name, spreads) {
            Ok(r) => ranks = r,
            Err(e) => return exit_code(Err(e)),
        }
    } else if emits {
        viscontact::console::outlive_broken_pipes();
    }
    if let Err(e) = viscontact::threads::init(threads) {
        return exit_code(Err(e));
    }
    let result = dispatch(cli.command, interrupt, ranks);
    if let (Err(e), true) = (&result, ranks.size > 1) {
        // A failure after setup may be this rank's alone: it ends them all, so that none
        // waits for it in a collective call (`viscontact::ranks`). Setup's were agreed.
        use viscontact::Error::{Elsewhere, Input, Interrupted};
        if !matches!(e, Input(_) | Interrupted(_) | Elsewhere(_)) {
            viscontact::errln!("error: rank {}: {e}", ranks.rank);
            ranks.abort(e.exit_code());
        }
    }
    // Printed before PETSc's finalize: MPI's waits there for every rank, and a follower
    // that leaves it first and exits with a failed setup's status makes mpirun end the
    // others, which took rank 0's message with it when rank 0 printed after.
    let code = match viscontact::console::stdout_failure() {
        Some(why) if only_prints && result.is_ok() => {
            viscontact::errln!("error: cannot write to standard output: {why}");
            ExitCode::FAILURE
        }
        _ => exit_code(result),
    };
    // After every PETSc object of the run is dropped (with the time loop, in dispatch).
    #[cfg(feature = "petsc")]
    viscontact::petsc::finalize();
    code
}

/// SIGINT/SIGTERM stop a run or resume after its current step, or its setup before it
/// changes anything (exit 130 / 143). Set up first, before any thread is started (see
/// run/interrupt.rs).
fn interrupt_for(command: &Command) -> std::result::Result<Interrupt, ExitCode> {
    match command {
        Command::Run { .. } | Command::Resume { .. } => Interrupt::on_signals().map_err(|e| {
            viscontact::errln!("error: cannot handle SIGINT/SIGTERM: {e}");
            ExitCode::FAILURE
        }),
        _ => Ok(Interrupt::default()),
    }
}

/// Runs the command: the signal that stopped a run, if one did.
fn dispatch(command: Command, interrupt: Interrupt, ranks: Ranks) -> Result<Option<i32>> {
    match command {
        Command::Run {
            scene,
            out,
            set,
            job,
            ..
        } if !job.emit.is_empty() => emit_job(&scene, &set, out.as_deref(), job).map(|()| None),
        Command::Run {
            scene,
            out,
            set,
            steps,
            ..
        } => run(&scene, &steps.options(out, set, interrupt, ranks)).map(report),
        Command::Resume {
            checkpoint,
            out,
            set,
            steps,
        } => resume(&checkpoint, &steps.options(out, set, interrupt, ranks)).map(report),
        Command::Check { scene, set, ranks } => check(&scene, &set, ranks as usize).map(|()| None),
        Command::MeshInfo { mesh, json } => mesh_info(&mesh, json).map(|()| None),
        Command::Study(args) => study(*args).map(|()| None),
        Command::StudyCase(args) => study_case(args).map(|()| None),
        Command::Plot {
            dir,
            history: true,
            columns,
            output,
            ..
        } => plot_history(&dir, columns.as_deref(), output.as_deref()).map(|()| None),
        Command::Plot {
            dir,
            time,
            field,
            scale,
            output,
            view,
            width,
            ..
        } => plot(
            &dir,
            &viscontact::plot::PlotOptions {
                time,
                field,
                scale,
                output,
                view,
                width,
            },
        )
        .map(|()| None),
    }
}

/// Draws the figure and says what it shows.
fn plot(dir: &std::path::Path, options: &viscontact::plot::PlotOptions) -> Result<()> {
    let i = viscontact::plot::plot_run(dir, options)?;
    for note in &i.notes {
        viscontact::errln!("{note}");
    }
    let view = i.view.map(|v| format!(", seen from {v:?}"));
    viscontact::outln!(
        "wrote {} (t = {}, displacement × {:.4e}, {} from {:.4e} to {:.4e}{})",
        i.output.display(),
        i.time,
        i.scale,
        i.frame.display(),
        i.range.0,
        i.range.1,
        view.unwrap_or_default()
    );
    Ok(())
}

/// Draws the history chart and says what it shows.
fn plot_history(
    dir: &std::path::Path,
    columns: Option<&[String]>,
    output: Option<&std::path::Path>,
) -> Result<()> {
    let p = viscontact::plot::plot_history(dir, columns, output)?;
    viscontact::outln!(
        "wrote {} ({} over {} steps)",
        p.output.display(),
        p.columns.join(", "),
        p.rows
    );
    Ok(())
}

/// The process's exit status: 0, 128 + the signal that stopped a run, or the error's code
/// (the error printed on stderr).
fn exit_code(result: Result<Option<i32>>) -> ExitCode {
    match result {
        Ok(None) => ExitCode::SUCCESS,
        // 128 + the signal: what a shell reports for a process the signal ended.
        Ok(Some(signal)) => ExitCode::from((128 + signal) as u8),
        Err(e) => {
            match e {
                // Not an error of the user's or of the solve: what they asked for.
                viscontact::Error::Interrupted(_) => viscontact::errln!("{e}"),
                // Another rank said why.
                viscontact::Error::Elsewhere(_) => {}
                _ => viscontact::errln!("error: {e}"),
            }
            ExitCode::from(e.exit_code() as u8)
        }
    }
}

/// Prints how a run ended; the signal that stopped it, if one did.
fn report(outcome: Outcome) -> Option<i32> {
    match outcome {
        Outcome::Finished(s) => {
            // The warnings were printed before the first step (`run::drive`).
            viscontact::outln!(
                "{}: {} steps, {} dofs, {:.2} s on {} thread{}; ‖u_N‖_H1 = {:.6e}; wrote {}",
                s.name,
                s.steps,
                s.dofs,
                s.timing.total_s,
                s.threads,
                if s.threads == 1 { "" } else { "s" },
                s.final_.u_h1,
                s.output.directory
            );
            None
        }
        // Rank 0 reports the run (`viscontact::ranks`).
        Outcome::Followed { signal } => signal,
        Outcome::Stopped {
            signal: None,
            message,
            ..
        } => {
            viscontact::outln!("{message}");
            None
        }
        Outcome::Stopped {
            signal: Some(signal),
            message,
            ..
        } => {
            viscontact::errln!("{message}");
            Some(signal)
        }
    }
}

/// The directory of `--emit KIND DIR` where KIND is slurm, the one kind `command` writes.
fn slurm_dir(command: &str, emit: &[String]) -> Result<PathBuf> {
    match emit {
        [kind, dir] if kind == "slurm" => Ok(PathBuf::from(dir)),
        [kind, _] => Err(viscontact::Error::input(format!(
            "{command}: --emit {kind}: the one kind is 'slurm' (--emit slurm DIR)"
        ))),
        _ => Err(viscontact::Error::input(format!(
            "{command}: --emit takes two values: slurm DIR"
        ))),
    }
}

/// `run --emit slurm DIR`: writes the job and says how to submit it.
fn emit_job(
    scene: &std::path::Path,
    set: &[String],
    out: Option<&std::path::Path>,
    job: JobFlags,
) -> Result<()> {
    use viscontact::run::slurm::{emit, JobOptions};
    let options = JobOptions {
        dir: slurm_dir("run", &job.emit)?,
        cpus_per_task: job.cpus_per_task,
        time: job.time,
        nodes: job.nodes,
        ntasks_per_node: job.ntasks_per_node,
    };
    let (path, memory) = emit(scene, set, out, &options)?;
    viscontact::outln!(
        "wrote {} (--mem {}, --cpus-per-task {})",
        path.display(),
        viscontact::resources::human(memory),
        options.cpus_per_task
    );
    viscontact::outln!("submit with sbatch {}", path.display());
    Ok(())
}

/// `check`: what a run of the scene on `ranks` MPI ranks would be, and whatever `run`
/// refuses before its first step (exit 2).
fn check(path: &std::path::Path, set: &[String], ranks: usize) -> Result<()> {
    let (scene, mesh, disc) = setup(path, set)?;
    // The run's solver, resolved once: every line below and the refusals read it.
    let mut solver = viscontact::solver::choice::Descriptor::of_run(&scene, &disc)?;
    viscontact::run::check_ranks(&scene, &solver, ranks, &format!("--ranks {ranks}"))?;
    print_problem(&scene, &mesh, &disc, &solver);
    if let Some(plan) = solver.contact() {
        viscontact::outln!("contact    {plan}");
    }
    let factor = solver.factor_bytes(&disc)?;
    if let Some(bytes) = factor {
        viscontact::outln!(
            "factor     Cholesky factor of K_A: ≈ {} for its values (symbolic analysis in the \
             run's ordering)",
            viscontact::resources::human(bytes)
        );
    }
    if let Some(line) = solver.krylov_line() {
        let avoided = match solver.avoided_factor(&disc)? {
            Some(bytes) => format!(
                "; the stored Cholesky factor would need ≈ {} for its values",
                viscontact::resources::human(bytes)
            ),
            None => String::new(),
        };
        viscontact::outln!("factor     {line}{avoided}");
    }
    if let Some(line) = solver.with_petsc(&disc)? {
        viscontact::outln!("petsc      {line}");
    }
    let out = viscontact::run::default_out(&scene)?;
    let (estimate, plans) =
        viscontact::run::estimate(&scene, &disc, (0, &out), || Plans::new(&scene), &mut |e| {
            viscontact::outln!("resources  {e}")
        })?;
    let mut show = |line: &str| viscontact::outln!("ranks      {line}");
    viscontact::run::check_memory(
        &scene,
        &disc,
        &solver,
        &estimate,
        (ranks, None),
        Some(&mut show),
    )?;
    if let Some(bytes) = factor {
        viscontact::resources::check_factor(bytes, disc.n_free)?;
    }
    print_stability(&scene, &disc, &plans);
    print_kernels(&scene, &disc, &plans);
    for w in viscontact::effects::warnings(&scene, &disc, &solver) {
        viscontact::outln!("warning    {w}");
    }
    viscontact::time_loop::refusals(&scene, &disc, &plans)
}

/// `check`'s first lines: the scene, its mesh and sizes, the time grid, the effects, the
/// solver.
fn print_problem(
    scene: &Scene,
    mesh: &Mesh,
    disc: &Discretization,
    solver: &viscontact::solver::choice::Descriptor,
) {
    let effects = Effects::new(scene, disc);
    viscontact::outln!("scene      {} ({})", scene.name, scene.path.display());
    viscontact::outln!(
        "mesh       {}: {}D, {} nodes, {} {}, {} free dofs",
        mesh.path.display(),
        mesh.dim,
        mesh.nodes.len(),
        mesh.n_cells(),
        if mesh.dim == 2 {
            "triangles"
        } else {
            "tetrahedra"
        },
        disc.n_free
    );
    viscontact::outln!(
        "conditions {}",
        viscontact::fem::constraints::summary(scene, disc.prescribed.len(), &disc.frames)
    );
    for line in viscontact::fem::materials::summary(&disc.materials, scene) {
        viscontact::outln!("region     {line}");
    }
    viscontact::outln!(
        "time       T = {}, N = {}, k = {}",
        scene.time.end,
        scene.time.steps,
        scene.time.k()
    );
    viscontact::outln!("effects    {}", effects.names().join(", "));
    viscontact::outln!("solver     {}", solver.summary(disc));
    let columns = viscontact::run::history_columns(scene, disc);
    viscontact::outln!(
        "history    {} columns of {}: {}",
        columns.len(),
        viscontact::run::HISTORY_FILE,
        columns.join(",")
    );
}

/// `check`'s stability line: the explicit scheme's step limit, or why there is none.
fn print_stability(scene: &Scene, disc: &Discretization, plans: &Plans) {
    use viscontact::stability::{StepLimit, Verdict};
    let limit_line = |l: &StepLimit, what: &str| match l.k_max {
        Some(k) => format!(
            "left endpoint scheme stable for k ≤ {k:.6e} (k/limit = {:.3}{what})",
            scene.time.k() / k
        ),
        None => "no explicit elastic or memory term: no step limit".to_string(),
    };
    match Verdict::new(scene, disc, plans) {
        Verdict::Implicit => {
            viscontact::outln!("stability  implicit history: unconditionally stable")
        }
        Verdict::Limit(l) => viscontact::outln!("stability  {}", limit_line(&l, "")),
        Verdict::Amplification(a, l) => viscontact::outln!(
            "stability  {}; direct-sum memory: response to a unit state peaks at {a:.3} over \
             the run's {} steps (stable: ≤ {})",
            limit_line(&l, ", elastic term"),
            scene.time.steps,
            viscontact::stability::MAX_AMPLIFICATION
        ),
    }
}

/// `check`'s kernel and memory lines: how each memory group's sum runs (the body's, then
/// each region kernel's, named by its table) and the history they keep.
fn print_kernels(scene: &Scene, disc: &Discretization, plans: &Plans) {
    let kernels = scene.physics.region_kernels();
    let bytes: usize = (0..plans.groups())
        .map(|g| {
            let name = match g {
                0 => String::new(),
                g => format!("[{}] ", kernels[g - 1].0),
            };
            print_kernel(scene, disc, plans.group(g), &name)
        })
        .sum();
    viscontact::outln!("memory     history state ≈ {:.1} MB", bytes as f64 / 1e6);
}

/// `check`'s kernel line for one memory group's `plan` (`name`: its table, for a region's);
/// returns the bytes of its history state.
fn print_kernel(scene: &Scene, disc: &Discretization, plan: &Plan, name: &str) -> usize {
    let direct_bytes = (scene.time.steps + 1) * disc.n_free * 8;
    let history_bytes = match plan {
        Plan::None => 0,
        Plan::Exact { .. } => direct_bytes,
        _ => plan.prony().map_or(0, |t| t.len()) * disc.n_free * 8,
    };
    match plan {
        Plan::Compressed(fit) => viscontact::outln!(
            "kernel     {name}compressed: {} exponentials, certified max relative error {:.2e} \
             on the {} lags, fitted in {:.3} s; saves {:.1} MB against the direct sum",
            fit.terms.len(),
            fit.error,
            fit.last_lag,
            fit.seconds,
            (direct_bytes.saturating_sub(history_bytes)) as f64 / 1e6
        ),
        Plan::Exact {
            fallback: Some(why),
            ..
        } => viscontact::outln!("kernel     runs exact (direct sum), not compressed: {why}"),
        Plan::Exact { fallback: None, .. } => {
            viscontact::outln!("kernel     runs exact (direct sum): memory = \"exact\"")
        }
        Plan::Prony(terms) if !name.is_empty() => {
            viscontact::outln!("kernel     {name}Prony series of {} terms", terms.len())
        }
        _ => {}
    }
    history_bytes
}

fn mesh_info(path: &std::path::Path, json: bool) -> Result<()> {
    let mesh = Mesh::read(path)?;
    let groups = group_summaries(&mesh);
    if json {
        let v = mesh_json(path, &mesh, groups);
        viscontact::outln!("{}", serde_json::to_string_pretty(&v).expect("json"));
        return Ok(());
    }
    print_mesh_summary(path, &mesh, &groups);
    print_mesh_notes(&mesh);
    Ok(())
}

/// The name of the cells of a mesh of dimension `dim`.
fn cells_key(dim: usize) -> &'static str {
    if dim == 2 {
        "triangles"
    } else {
        "tetrahedra"
    }
}

/// The measure of a cell of a mesh of dimension `dim`.
fn cell_size(dim: usize) -> &'static str {
    if dim == 2 {
        "area"
    } else {
        "volume"
    }
}

/// Each physical group as mesh-info reports it: name, tag, dimension, elements, nodes, the
/// measure of a boundary group (length in 2D, area in 3D) and its defect.
fn group_summaries(mesh: &Mesh) -> Vec<serde_json::Value> {
    mesh.groups
        .iter()
        .map(|g| {
            // The measure of a boundary group: length (2D) or area (3D).
            let measure: f64 = mesh
                .boundary_facets(g)
                .iter()
                .map(|f| f.measure)
                .sum::<f64>()
                + 0.0;
            let boundary = g.dim + 1 == mesh.dim;
            let key = if mesh.dim == 2 { "length" } else { "area" };
            serde_json::json!({
                "name": Mesh::display_name(g),
                "tag": g.tag,
                "dim": g.dim,
                "elements": if boundary { g.n_facets() } else { g.cells.len() },
                "nodes": mesh.group_nodes(g).len(),
                key: if boundary { Some(measure) } else { None },
                "defect": g.defect,
            })
        })
        .collect()
}

/// `mesh-info --json`: sizes, groups, parts, coincident nodes and quality.
fn mesh_json(
    path: &std::path::Path,
    mesh: &Mesh,
    groups: Vec<serde_json::Value>,
) -> serde_json::Value {
    let q = mesh.quality();
    let cells_key = cells_key(mesh.dim);
    let size = cell_size(mesh.dim);
    let size_key = |which: &str| format!("{which}_{size}");
    let point = |p: [f64; 3]| p[..mesh.dim].to_vec();
    serde_json::json!({
        "file": path.display().to_string(),
        "dim": mesh.dim,
        "nodes": mesh.nodes.len(),
        cells_key: mesh.n_cells(),
        "reoriented": mesh.flipped,
        "groups": groups,
        "parts": mesh.parts().iter().map(|p| serde_json::json!({
            cells_key: p.cells.len(),
            "nodes": p.nodes.len(),
            "entities": p.entities,
            "min": point(p.min),
            "max": point(p.max),
        })).collect::<Vec<_>>(),
        "coincident_nodes": mesh.coincident_nodes().iter().map(|c| serde_json::json!({
            "at": point(mesh.nodes[c.nodes[0]]),
            "nodes": c.nodes.len(),
            "entities": c.entities,
        })).collect::<Vec<_>>(),
        "quality": {
            "min_angle_deg": q.min_angle_deg,
            "max_aspect_ratio": q.max_aspect_ratio,
            size_key("min"): q.min_area,
            size_key("max"): q.max_area,
        }
    })
}

/// mesh-info as text: sizes, the groups, quality and parts.
fn print_mesh_summary(path: &std::path::Path, mesh: &Mesh, groups: &[serde_json::Value]) {
    let q = mesh.quality();
    let (angle, orientation) = match mesh.dim {
        2 => ("angle", "counter-clockwise"),
        _ => ("dihedral angle", "positive volume"),
    };
    viscontact::outln!("{}", path.display());
    viscontact::outln!(
        "  {}D: {} nodes, {} {} ({} reoriented to {orientation})",
        mesh.dim,
        mesh.nodes.len(),
        mesh.n_cells(),
        cells_key(mesh.dim),
        mesh.flipped
    );
    viscontact::outln!("  physical groups:");
    for g in groups {
        viscontact::outln!(
            "    {:<10} tag {:<4} dim {}  {:>7} {}  {:>7} nodes{}",
            g["name"].as_str().unwrap_or(""),
            g["tag"],
            g["dim"],
            g["elements"],
            match (mesh.dim, g["dim"].as_u64()) {
                (2, Some(1)) => "edges",
                (3, Some(2)) => "faces",
                _ => "cells",
            },
            g["nodes"],
            ["length", "area"]
                .iter()
                .find_map(|k| g[*k].as_f64().map(|l| format!("  {k} {l:.6}")))
                .unwrap_or_default()
        );
    }
    viscontact::outln!(
        "  quality: min {angle} {:.2}°, max aspect ratio {:.3}, {} {:.3e} .. {:.3e}",
        q.min_angle_deg,
        q.max_aspect_ratio,
        cell_size(mesh.dim),
        q.min_area,
        q.max_area
    );
    let parts = mesh.parts();
    viscontact::outln!(
        "  parts: {} (cells connected through shared nodes)",
        parts.len()
    );
    if parts.len() > 1 {
        for (k, p) in parts.iter().enumerate() {
            viscontact::outln!("    part {}: {}", k + 1, mesh.describe_part(p));
        }
    }
}

/// mesh-info's notes and warnings: overlapping cell groups, coincident nodes, groups that
/// carry no condition, boundary groups with a defect.
fn print_mesh_notes(mesh: &Mesh) {
    for note in overlapping_cell_groups(mesh) {
        viscontact::outln!("  note: {note}");
    }
    let coincident = mesh.coincident_nodes();
    if !coincident.is_empty() {
        viscontact::outln!(
            "  warning: {}: a forgotten BooleanFragments (OpenCASCADE) or Coherence (built-in \
             kernel)? `check` and `run` refuse it unless [mesh] separate_parts = true",
            mesh.describe_coincident(&coincident)
        );
    }
    for (dim, tag, name) in &mesh.other_groups {
        let kind = ["point", "curve", "surface", "volume"][(*dim).min(3)];
        viscontact::outln!(
            "  note: physical {kind} {} (tag {tag}) carries no condition in a {}D mesh",
            name.as_deref().unwrap_or("(no name)"),
            mesh.dim
        );
    }
    for g in mesh.groups.iter().filter_map(|g| g.defect.as_ref()) {
        viscontact::outln!(
            "  warning: {g} (refused only where a scene uses it as a boundary group)"
        );
    }
}

/// Cell groups that share cells, with the tag the output's `region` holds there (the first
/// group in file order; docs/meshes.md).
fn overlapping_cell_groups(mesh: &Mesh) -> Vec<String> {
    let cell_groups: Vec<&viscontact::mesh::Group> =
        mesh.groups.iter().filter(|g| g.dim == mesh.dim).collect();
    let mut first: Vec<Option<usize>> = vec![None; mesh.n_cells()];
    let mut shared = std::collections::BTreeMap::new();
    for (k, g) in cell_groups.iter().enumerate() {
        for &c in &g.cells {
            match first[c] {
                None => first[c] = Some(k),
                Some(f) => *shared.entry((f, k)).or_insert(0) += 1,
            }
        }
    }
    let name = |g: &viscontact::mesh::Group| format!("'{}' (tag {})", Mesh::display_name(g), g.tag);
    shared
        .into_iter()
        .map(|((a, b), n)| {
            format!(
                "cell groups {} and {} share {n} cells; the output's `region` holds {} there \
                 (the first group in file order)",
                name(cell_groups[a]),
                name(cell_groups[b]),
                cell_groups[a].tag
            )
        })
        .collect()
}

#[derive(clap::Args)]
struct StudyArgs {
    #[arg(required_unless_present = "collect")]
    scene: Option<PathBuf>,
    /// Levels n: h = 1/n (the mesh of level n) and N = n steps (k = T/n).
    #[arg(long, value_delimiter = ',', default_value = "8,16,32,64")]
    levels: Vec<usize>,
    /// The level of the reference solution.
    #[arg(long, default_value_t = 128)]
    reference: usize,
    /// What varies: both (h = k), h (k fixed), k (h fixed); a list runs several families.
    #[arg(long, value_delimiter = ',', default_value = "both")]
    vary: Vec<viscontact::study::Vary>,
    /// The level of the parameter held fixed (default: the reference level).
    #[arg(long)]
    fixed: Option<usize>,
    #[arg(long, conflicts_with = "meshes", help = mesh_pattern_help())]
    mesh_pattern: Option<String>,
    /// One mesh per level, then the reference mesh (for meshes that are not numbered).
    #[arg(long, value_delimiter = ',')]
    meshes: Vec<PathBuf>,
    /// Output directory (default: out/<scene name>-study-<vary>/ in the working directory).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Runs per level for the median wall time (default: 3 under a second, else 1).
    #[arg(long)]
    repeat: Option<usize>,
    /// Also run every level with the Prony kernel written as an expression (direct sum).
    #[arg(long)]
    kernel_compare: bool,
    /// Run up to N cases side by side, each in a process of its own with its share of the
    /// cores, as many as fit in memory; the numbers are those of --jobs 1, the wall times
    /// are measured concurrently.
    #[arg(long, default_value_t = 1, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..))]
    jobs: usize,
    /// Write the study as a Slurm job array into DIR instead of running it: runs.tsv,
    /// array.sh, collect.sh, submit.sh (--jobs N: at most N tasks at once).
    #[arg(long, num_args = 2, value_names = ["slurm", "DIR"], conflicts_with = "kernel_compare")]
    emit: Vec<String>,
    /// With --emit slurm: the cores of each task (its --cpus-per-task and threads).
    #[arg(long, default_value_t = 4, requires = "emit")]
    cpus_per_task: usize,
    /// Make the tables and plots of a job array written by --emit slurm once its runs are
    /// complete (into DIR).
    #[arg(long, value_name = "DIR", conflicts_with_all = ["emit", "tolerances", "jobs"])]
    collect: Option<PathBuf>,
    /// What accuracy costs instead of convergence: the scene's expression or table kernel
    /// compressed at each tolerance, against the direct sum (e.g. 1e-4,1e-6,1e-8,1e-10,1e-12).
    #[arg(long, value_delimiter = ',', conflicts_with_all = ["levels", "vary", "kernel_compare", "jobs"])]
    tolerances: Vec<f64>,
    /// With --tolerances: the numbers of steps N, at the scene's step size k.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "1024,4096",
        requires = "tolerances"
    )]
    steps: Vec<usize>,
    /// With --tolerances: run the direct sum (O(N²)) for N up to this.
    #[arg(long, default_value_t = 4096, requires = "tolerances")]
    exact_up_to: usize,
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Threads for the steps (default: VISCONTACT_THREADS, else the cores this process
    /// may use); the results are the same bit for bit for every count.
    #[arg(long, value_name = "N")]
    threads: Option<NonZeroUsize>,
}

#[derive(clap::Args)]
struct StudyCaseArgs {
    scene: PathBuf,
    #[arg(long)]
    mesh: String,
    #[arg(long)]
    steps: usize,
    /// The Prony kernel written as an expression (`study --kernel-compare`).
    #[arg(long)]
    expression: bool,
    #[arg(long)]
    repeat: Option<usize>,
    #[arg(long)]
    result: PathBuf,
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
}

/// One case of `study --jobs` in this process (see viscontact::study::jobs).
fn study_case(a: StudyCaseArgs) -> Result<()> {
    use viscontact::study::{jobs, Case, KernelForm};
    let case = Case {
        mesh: a.mesh,
        steps: a.steps,
        form: if a.expression {
            KernelForm::Expression
        } else {
            KernelForm::AsGiven
        },
        repeat: a.repeat,
    };
    jobs::run_case(&a.scene, &a.set, &case, &a.result)
}

fn study(a: StudyArgs) -> Result<()> {
    use viscontact::study::{self, slurm, MeshFamily, StudyOptions};
    if let Some(dir) = &a.collect {
        return print_study(&slurm::collect(dir)?, dir);
    }
    let scene = a
        .scene
        .clone()
        .expect("clap requires a scene without --collect");
    if !a.tolerances.is_empty() {
        return memory_study(a, &scene);
    }
    let opts = StudyOptions {
        levels: a.levels,
        reference: a.reference,
        vary: a.vary,
        fixed: a.fixed,
        meshes: match (a.mesh_pattern, a.meshes.is_empty()) {
            (Some(p), _) => Some(MeshFamily::Pattern(p)),
            (None, false) => Some(MeshFamily::List(a.meshes)),
            (None, true) => None,
        },
        repeat: a.repeat,
        overrides: a.set,
        kernel_compare: a.kernel_compare,
        progress: true,
        jobs: a.jobs,
    };
    if !a.emit.is_empty() {
        let slurm = slurm::SlurmOptions {
            dir: slurm_dir("study", &a.emit)?,
            at_once: (a.jobs > 1).then_some(a.jobs),
            cpus_per_task: a.cpus_per_task,
        };
        for p in slurm::emit(&scene, &opts, &slurm)? {
            viscontact::outln!("wrote {}", p.display());
        }
        viscontact::outln!("submit with {}", slurm.dir.join("submit.sh").display());
        return Ok(());
    }
    let out = match a.out {
        Some(o) => o,
        None => study::default_out(&scene, &opts)?,
    };
    print_study(&study::run_study(&scene, &opts)?, &out)
}

/// Prints a study's tables and writes its files into `out`.
fn print_study(report: &viscontact::study::StudyReport, out: &std::path::Path) -> Result<()> {
    use viscontact::study;
    viscontact::outln!("{}", study::markdown(report).trim_end());
    for p in study::write_report(report, out)? {
        viscontact::outln!("wrote {}", p.display());
    }
    Ok(())
}

/// `study --tolerances`: what accuracy costs (viscontact::study::memory_cost).
fn memory_study(a: StudyArgs, scene: &std::path::Path) -> Result<()> {
    use viscontact::study::memory_cost;
    let opts = memory_cost::Options {
        tolerances: a.tolerances,
        steps: a.steps,
        exact_up_to: a.exact_up_to,
        overrides: a.set,
        progress: true,
    };
    let out = match a.out {
        Some(o) => o,
        None => {
            let scene = viscontact::scene::Scene::load(scene, &opts.overrides)?;
            PathBuf::from("out").join(format!("{}-study-memory", scene.name))
        }
    };
    let report = memory_cost::run_memory_cost(scene, &opts)?;
    viscontact::outln!("{}", memory_cost::markdown(&report).trim_end());
    for p in memory_cost::write_report(&report, &out)? {
        viscontact::outln!("wrote {}", p.display());
    }
    Ok(())
}
