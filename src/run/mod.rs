//! The `run` and `resume` commands as library functions: scene → mesh → discretization →
//! effects → step solver → time loop → ParaView series, checkpoints and summary.json.
//! Reading [`run`] and [`resume`] tells the whole story of a run:
//!
//! 1. load and check everything the run needs (the scene first, then, owning the output
//!    directory, the mesh, the discretization and the step solver); a failure here leaves
//!    the directory as it was (`dir`). On several MPI ranks every rank does, but rank 0
//!    alone reads the mesh and hands it to the others once all agree on their setup so
//!    far, and they agree again before PETSc's first collective call; rank 0 owns the
//!    directory and the others `follow` (`crate::ranks`);
//! 2. replace the run the directory holds (`run`) or continue it (`resume`);
//! 3. `drive` the time loop: each solved step goes to the consumers (`consumers`:
//!    statistics, frames, history.csv (`history_csv`), checkpoints, progress) until the
//!    last step, a `--stop-after` step,
//!    a signal (`interrupt`) or a failure;
//! 4. write summary.json however the run ended (`summary`).

mod consumers;
mod dir;
mod frame;
mod history_csv;
mod interrupt;
pub mod slurm;
mod summary;

pub use crate::error::signal_name;
pub use dir::LOCK_NAME;
pub use frame::region;
pub use history_csv::{columns as history_columns, FILE_NAME as HISTORY_FILE};
pub use interrupt::Interrupt;
pub use summary::{ContactSummary, Final, Iterations, OutputSummary, Status, Summary, Timing};

use crate::checkpoint::{self, RunLog};
use crate::fem::reactions::Reactions;
use crate::fem::Discretization;
use crate::history::Plans;
use crate::mesh::Mesh;
use crate::output::{write_atomic, Resumed, Series};
use crate::ranks::Ranks;
use crate::resources::Estimate;
use crate::scene::{read_scene_file, MeshChoice, Scene};
use crate::solver::choice::Descriptor;
use crate::time_loop::{RunEnd, TimeLoop};
use crate::{Error, Result};
use consumers::{
    of_pieces, Checkpoints, Consumers, Follower, Frames, Progress, Schedule, Statistics, StopRule,
};
use dir::DirLock;
use frame::{open_series, OwnFrames, PieceSetup};
use history_csv::HistoryCsv;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;
use summary::{summary_json, Ending};

/// Options of a run (and of a resume) that are not part of the scene.
#[derive(Clone, Debug)]
pub struct RunOptions {
    pub out: Option<PathBuf>,
    pub overrides: Vec<String>,
    pub progress: bool,
    /// Stop once step S is solved and written: write the checkpoint of step S + 1 (the state
    /// at t_{S+1}) and return [`Outcome::Stopped`]; `viscontact resume` continues from there.
    pub stop_after: Option<usize>,
    /// Write into a directory that holds files viscontact did not write (never touching them).
    pub force: bool,
    /// Set by SIGINT/SIGTERM (see [`Interrupt::on_signals`]): stop like `stop_after` after
    /// the step being solved, or (during setup) before the directory is changed.
    pub interrupt: Interrupt,
    /// The MPI ranks the run spreads over (`crate::ranks`; one by default).
    pub ranks: Ranks,
}

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions {
            out: None,
            overrides: Vec::new(),
            progress: false,
            stop_after: None,
            force: false,
            interrupt: Interrupt::default(),
            ranks: Ranks::ONE,
        }
    }
}

/// How a run ended, when it did not fail (a failed run returns its error, after writing
/// summary.json with status "failed").
#[derive(Debug, Clone)]
pub enum Outcome {
    /// Every step solved; summary.json written (status "completed").
    Finished(Box<Summary>),
    /// Stopped after step `step` by `stop_after` or by `signal`; `checkpoint` (None when
    /// checkpoints are disabled) continues it; summary.json says "interrupted" and
    /// `message` (also in summary.json) says how to continue.
    Stopped {
        step: usize,
        time: f64,
        checkpoint: Option<PathBuf>,
        signal: Option<i32>,
        message: String,
    },
    /// A follower rank's part of a run on several MPI ranks ended as rank 0's did, which
    /// reported it; `signal` as in `Stopped`.
    Followed { signal: Option<i32> },
}

/// The default output directory: `out/<scene name>/`. A scene name is a name, not a path:
/// one that is not a single plain file name (`/abs`, `a/b`, `..`, empty) is refused.
pub fn default_out(scene: &Scene) -> Result<PathBuf> {
    use std::path::Component;
    let mut parts = Path::new(&scene.name).components();
    match (parts.next(), parts.next()) {
        (Some(Component::Normal(_)), None) if !scene.name.contains(['/', '\\']) => {
            Ok(Path::new("out").join(&scene.name))
        }
        _ => Err(Error::input(format!(
            "{}: key 'name' = {:?} is not a plain name (the default output directory is \
             out/<name>/); use a name without '/' or '..', or choose the directory with --out",
            scene.path.display(),
            scene.name
        ))),
    }
}

/// Loads everything a run needs and checks it: scene, mesh, discretization.
pub fn setup(scene_path: &Path, overrides: &[String]) -> Result<(Scene, Mesh, Discretization)> {
    discretize(load_scene(scene_path, overrides)?)
        .map_err(|e| crate::scene::name_set_key(e, scene_path, overrides))
}

/// The mesh and the discretization of a checked scene (a study's case of one, say).
pub fn discretize(scene: Scene) -> Result<(Scene, Mesh, Discretization)> {
    let mesh = read_mesh(&scene)?;
    let disc = Discretization::new(&mesh, &scene)?;
    Ok((scene, mesh, disc))
}

/// The scene; when it fails its checks because its model does not fit the mesh, that is
/// what is reported (see `fem::model_mismatch`).
pub fn load_scene(scene_path: &Path, overrides: &[String]) -> Result<Scene> {
    let (text, file) = read_scene_file(scene_path, overrides)?;
    Scene::from_file(scene_path, text, &file).map_err(|e| {
        let mesh = MeshChoice::from_section(&file.mesh, scene_path);
        let e = crate::fem::model_mismatch(scene_path, &mesh).unwrap_or(e);
        crate::scene::name_set_key(e, scene_path, overrides)
    })
}

fn read_mesh(scene: &Scene) -> Result<Mesh> {
    Mesh::read(&scene.mesh.file).map_err(|e| match e {
        Error::Input(m) => Error::input(format!(
            "{}: key 'mesh.file': {m} (mesh.file is relative to the scene file)",
            scene.path.display()
        )),
        other => other,
    })
}

/// Runs a scene to its end (or to `stop_after`, or a signal), writing the series, the
/// checkpoints and summary.json into the output directory, which then holds this run alone.
/// A bad value given with `--set` is named as such (`scene::name_set_key`).
pub fn run(scene_path: &Path, opts: &RunOptions) -> Result<Outcome> {
    run_scene(scene_path, opts)
        .map_err(|e| crate::scene::name_set_key(e, scene_path, &opts.overrides))
}

fn run_scene(scene_path: &Path, opts: &RunOptions) -> Result<Outcome> {
    if !opts.ranks.is_first() {
        return follow(scene_path, Begun::Run, opts);
    }
    let start = Instant::now();
    let mut ready = opts.ranks.agree(prepare_run(scene_path, opts))?;
    tell_followers_the_series(opts, &ready.opened)?;
    hold_history_of_first(opts.ranks, &mut ready);
    first_lets_go_of_cells(opts.ranks, &mut ready);
    let tl = ready.solving.time_loop(&ready.scene, &ready.disc)?;
    // Setup succeeded: the run the directory held goes, before the first new frame, unless
    // a signal came first (then it stays as it was).
    let committed = opts
        .interrupt
        .unless_signalled(|| dir::remove_run(&ready.opened.out));
    tell_followers(opts, &committed)?;
    committed.map_err(Error::Interrupted)??;
    drive(Drive {
        scene: &ready.scene,
        reactions: ready.reactions,
        disc: &ready.disc,
        tl,
        opened: ready.opened,
        resumed: None,
        start,
        opts,
    })
}

/// What a run or a resume has made ready before its time loop: everything that can fail
/// on bad input, so that the ranks agree on it before PETSc's first collective call.
struct Ready {
    /// Shared with the writer thread of history.csv.
    scene: Arc<Scene>,
    /// history.csv's held rows, made from the mesh, which goes before the step solver's
    /// setup (`history_csv::reactions`).
    reactions: Reactions,
    /// Shared with the frame writer's thread (run/frame.rs).
    disc: Arc<Discretization>,
    solving: Solving,
    opened: Opened,
}

/// What the time loop is made of besides the scene and the discretization.
struct Solving {
    solver: Descriptor,
    /// On one of several ranks, its layout and rows of K_A for PETSc (`Ranks::keep_own_columns`).
    own: Option<crate::ranks::Own>,
    plans: Plans,
}

impl Solving {
    /// The time loop of `scene` on `disc` (PETSc's first collective call, where the run
    /// goes through PETSc: after the ranks agreed on the setup).
    fn time_loop<'a>(self, scene: &'a Scene, disc: &'a Discretization) -> Result<TimeLoop<'a>> {
        TimeLoop::with_solver(scene, disc, self.plans, self.solver, self.own)
    }
}

/// The output directory as a run or a resume has opened it: locked, its series open for
/// the frames to come, with the run's identity.
struct Opened {
    identity: checkpoint::Identity,
    series: Series,
    /// Rank 0's piece of the frames where the ranks write their own (`frame::OwnFrames`).
    pieces: Option<OwnFrames>,
    out: PathBuf,
    lock: DirLock,
}

/// What rank 0's setup of a new run has read before its mesh: the scene, the output
/// directory, locked.
type Read = (Arc<Scene>, PathBuf, DirLock);

/// A new run's setup up to its mesh, with the output directory locked; the mesh for the
/// other ranks too (`Ranks::with_mesh_of_first`).
fn read_run(scene_path: &Path, opts: &RunOptions) -> Result<(Read, Option<Mesh>)> {
    // A signal between two stages ends setup with the directory as it was.
    let stage = || opts.interrupt.between_setup_stages();
    let scene = Arc::new(load_scene(scene_path, &opts.overrides)?);
    let out = match &opts.out {
        Some(out) => out.clone(),
        None => default_out(&scene)?,
    };
    dir::check_out_dir(&out, opts.force)?;
    stage()?;
    let lock = DirLock::acquire(&out, "run")?;
    stage()?;
    let mesh = read_mesh(&scene)?;
    Ok(((scene, out, lock), Some(mesh)))
}

/// A new run's setup up to its time loop, with the output directory locked.
fn prepare_run(scene_path: &Path, opts: &RunOptions) -> Result<Ready> {
    let stage = || opts.interrupt.between_setup_stages();
    let read = read_run(scene_path, opts);
    let ((scene, out, lock), mut mesh) = opts.ranks.with_mesh_of_first(read, |r| &r.0)?;
    before_discretizing(opts, &scene)?;
    let (mut disc, made) = opts.ranks.discretize(&mut mesh, &scene)?;
    stage()?;
    let (estimate, plans) = estimate(&scene, &disc, (0, &out), || Plans::new(&scene), &mut |_| {})?;
    let ranks = (opts.ranks.size, made.as_ref());
    let solver = check_contact_plan(&scene, &disc, &estimate, None, ranks)?;
    check_started_ranks(&scene, &solver, opts)?;
    let own = opts.ranks.keep_own_columns(&mut disc, &scene, made)?;
    let disc = Arc::new(disc);
    let identity = checkpoint::Identity::new(&scene, &mesh, &disc, None);
    // Before the factorization: the series' writer thread compresses the mesh beside it.
    let (series, pieces) = open_series(
        (&out, &identity.run_id),
        (&mesh, &disc),
        (own.as_ref(), opts.ranks),
        &scene,
        None,
    )?;
    stage()?;
    let reactions = history_csv::reactions(&scene, &mesh, &disc, &plans)?;
    Ok(Ready {
        scene,
        reactions,
        disc,
        solving: Solving { solver, own, plans },
        opened: Opened {
            identity,
            series,
            pieces,
            out,
            lock,
        },
    })
}

/// What a run's steps from `from` on will hold in memory and write into `out`, refused
/// (exit 2) where it would not fit: sizes first, so that a hostile `time.steps` is refused
/// before the kernels' `plans` evaluate anything per step, then with their terms, each of
/// which keeps a state at every dof. `show` gets the estimate that is checked last
/// (`check` prints it).
pub fn estimate(
    scene: &Scene,
    disc: &Discretization,
    (from, out): (usize, &Path),
    plans: impl FnOnce() -> Result<Plans>,
    show: &mut dyn FnMut(&Estimate),
) -> Result<(Estimate, Plans)> {
    let sizes = Estimate::new(scene, disc, from);
    if let Err(e) = sizes.check(out) {
        show(&sizes);
        return Err(e);
    }
    let plans = plans()?;
    let estimate = sizes.with_plans(&plans, disc);
    show(&estimate);
    estimate.check(out)?;
    Ok((estimate, plans))
}

/// The stage boundary of setup between the mesh and its discretization, where the latter
/// is rank 0's alone: where the ranks' discretization is collective
/// (`Ranks::spreads_setup`), the followers already wait in it for rank 0 (the partition,
/// their parts of the mesh), which must reach them; the boundary after it takes the signal.
fn before_discretizing(opts: &RunOptions, scene: &Scene) -> Result<()> {
    match opts.ranks.spreads_setup(scene) {
        true => Ok(()),
        false => opts.interrupt.between_setup_stages(),
    }
}

/// Refuses (exit 2) a run on `ranks` MPI ranks whose steps do not spread over them
/// (`crate::ranks`); `how` says where the count comes from ("started on 2 MPI ranks").
pub fn check_ranks(scene: &Scene, solver: &Descriptor, ranks: usize, how: &str) -> Result<()> {
    match why_not_spread(solver, ranks) {
        None => Ok(()),
        Some(why) => Err(Error::input(format!(
            "{}: {how}, but {why}. Run it as one process, without mpirun or srun -n",
            scene.path.display(),
        ))),
    }
}

/// Why a run of `solver` cannot spread over `ranks` MPI ranks (`crate::ranks`); None where
/// it can, or is one rank.
fn why_not_spread(solver: &Descriptor, ranks: usize) -> Option<String> {
    if ranks == 1 || solver.spreads() {
        return None;
    }
    if !cfg!(feature = "petsc") {
        return Some(format!(
            "this build has no MPI, and a run is one process; to spread a run whose steps are \
             PETSc solves over MPI ranks (docs/cluster.md), {}",
            crate::solver::choice::PETSC_HOW
        ));
    }
    let this = match solver.contact_solver() {
        Some(c) => format!("contact solver {}", c.key()),
        None => "the stored Cholesky factor of K_A".to_string(),
    };
    Some(format!(
        "{}; this run's steps take the {this}",
        crate::ranks::WHAT_SPREADS
    ))
}

/// `check_ranks` for the ranks this run or resume was started on.
fn check_started_ranks(scene: &Scene, solver: &Descriptor, opts: &RunOptions) -> Result<()> {
    let how = format!("started on {} MPI ranks", opts.ranks.size);
    check_ranks(scene, solver, opts.ranks.size, &how)
}

/// Rank 0's commit (the directory changed, or a signal came first), told to the followers
/// of a run on several ranks, who stop with it.
fn tell_followers<T>(opts: &RunOptions, committed: &std::result::Result<T, i32>) -> Result<()> {
    let code = committed.as_ref().err().map_or(0, |s| 128 + s);
    opts.ranks.first_says(code).map(|_| ())
}

/// Tells the followers the run id and the output directory (collective on several ranks),
/// which they write their pieces of the frames with ([`series_of_follower`]).
fn tell_followers_the_series(opts: &RunOptions, opened: &Opened) -> Result<()> {
    let out = std::path::absolute(&opened.out).unwrap_or_else(|_| opened.out.clone());
    let text = format!("{}\n{}", opened.identity.run_id, out.display());
    opts.ranks.first_says_text(&text).map(|_| ())
}

/// A follower's frames: its piece of them, if the ranks write their own (`piece`: its mesh
/// and its cells' materials, made during its setup), in rank 0's directory.
fn series_of_follower(
    piece: Option<PieceSetup>,
    scene: &Scene,
    opts: &RunOptions,
) -> Result<Option<OwnFrames>> {
    let text = opts.ranks.first_says_text("")?;
    let (run_id, out) = text.split_once('\n').unwrap_or((&text, "."));
    let frames = |p| OwnFrames::new(p, (Path::new(out), run_id), scene, opts.ranks);
    Ok(piece.map(frames))
}

/// What a follower rank follows: a run of the scene at its path, or a resume of the
/// checkpoint at its path.
#[derive(Clone, Copy)]
enum Begun {
    Run,
    Resume,
}

/// A follower rank's part of a run or a resume (`crate::ranks`): the same setup without
/// the directory, the same steps, nothing written.
fn follow(path: &Path, begun: Begun, opts: &RunOptions) -> Result<Outcome> {
    opts.interrupt.follow();
    let read = || -> Result<_> {
        let read = match begun {
            Begun::Run => (load_scene(path, &opts.overrides)?, None),
            Begun::Resume => {
                let cp = checkpoint::Checkpoint::read(path)?;
                (cp.scene(&opts.overrides)?, Some(cp))
            }
        };
        Ok((read, None))
    };
    let ready = || -> Result<_> {
        // Rank 0 reads the mesh; a follower gets it from rank 0, and its part of the cells
        // with the partition (`crate::ranks`).
        let ((scene, cp), mut mesh) = opts.ranks.with_mesh_of_first(read(), |r| &r.0)?;
        let (mut disc, made) = opts.ranks.discretize(&mut mesh, &scene)?;
        let solver = Descriptor::of_run(&scene, &disc)?;
        check_started_ranks(&scene, &solver, opts)?;
        let mut own = opts.ranks.keep_own_columns(&mut disc, &scene, made)?;
        let options = &scene.output.options;
        let piece =
            frame::piece_of_follower((&mesh, &disc), own.as_ref(), options, opts.ranks.rank);
        let points = piece.as_ref().map_or(Vec::new(), |p| p.dofs(&disc));
        opts.ranks.hold_history(&mut disc, own.as_mut(), points);
        // Before PETSc's setup, the rank's peak: a follower holds no cell (or, where `auto`
        // assembled the whole, no longer), and its piece makes its own cells at its first
        // step, after that peak.
        disc.forget_cells();
        disc.keep_places(&mesh.nodes, piece.as_ref().map_or(&[][..], |p| p.points()));
        let plans = match &cp {
            Some(cp) => cp.plans(&scene)?,
            None => Plans::new(&scene)?,
        };
        Ok((scene, (disc, piece), Solving { solver, own, plans }, cp))
    };
    let (scene, (disc, piece), solving, cp) = opts.ranks.agree(ready())?;
    let frames = series_of_follower(piece, &scene, opts)?;
    let mut tl = solving.time_loop(&scene, &disc)?;
    // The checkpoint goes once restored: the follower holds its part of the state alone.
    if let Some(mut cp) = cp {
        tl.restore(cp.saved(disc.n_dofs, tl.rows().len(), tl.held_at())?)?;
    }
    match opts.ranks.first_says(0)? {
        0 => {}
        code => return Err(Error::Elsewhere(code)),
    }
    follow_signals(&mut tl, opts);
    of_pieces(frames.as_ref(), &disc, &tl, opts.ranks)?;
    let mut follower = Follower {
        stop: StopRule {
            after: opts.stop_after,
            interrupt: opts.interrupt.clone(),
            ranks: opts.ranks,
        },
        frames,
        schedule: Schedule::new(&scene),
        disc: &disc,
    };
    tl.run(scene.time.steps, &mut follower)?;
    Ok(Outcome::Followed {
        signal: opts.interrupt.signal(),
    })
}

/// Hands the run's request to give a step up to the time loop; on several ranks the first
/// signal makes it (`Interrupt::give_up_at_first`), and the step is given up on every rank
/// at once (only PETSc's steps spread, and their Krylov solves share the request).
fn follow_signals(tl: &mut TimeLoop, opts: &RunOptions) {
    if opts.ranks.size > 1 {
        opts.interrupt.give_up_at_first();
    }
    tl.abandon_on(opts.interrupt.abandon());
}

/// On rank 0 of several whose frames are in pieces, its history holds what its steps, its
/// piece and history.csv read, as a follower's does (`Ranks::hold_history`), and its
/// checkpoints gather the rest from the ranks' own rows (`TimeLoop::state`,
/// `TimeLoop::gather_memory`): besides a follower's dofs, its piece's points', those the
/// held rows read (`Reactions::dofs_read`) and the prescribed dofs (which it sends to its
/// checkpoints, where there are any). It holds every dof where it computes every cell's
/// stress (`format = "vtkhdf"`).
fn hold_history_of_first(ranks: Ranks, ready: &mut Ready) {
    let Some(pieces) = ready.opened.pieces.as_ref().filter(|_| ranks.size > 1) else {
        return;
    };
    // Nothing shares the discretization before the time loop's setup.
    let disc = Arc::get_mut(&mut ready.disc).expect("rank 0's setup alone holds it");
    let mut also = frame::dofs_of(disc, pieces.points());
    also.extend_from_slice(ready.reactions.dofs_read());
    also.extend(disc.n_free..disc.n_dofs);
    ranks.hold_history(disc, ready.solving.own.as_mut(), also);
}

/// On rank 0 of several whose frames are in pieces and whose loads have no body force,
/// the discretization lets go of its cells' vertices (16 bytes a tetrahedron of the whole
/// mesh), which nothing reads past the setup there: summary.json's norms are the ranks'
/// pieces' sums (`consumers::of_pieces`), and rank 0's piece makes its own cells from
/// their vertices as a follower's does (`OwnFrames::keep_own_cells`). A body force keeps
/// them: history.csv's resultant of it is made again from every cell at every step
/// (`Discretization::visit_every_load`). With them go the places of the nodes it no longer
/// reads, as on a follower (24 bytes a node of the whole mesh:
/// `Discretization::keep_places`).
fn first_lets_go_of_cells(ranks: Ranks, ready: &mut Ready) {
    if ranks.size == 1 || crate::ranks::first_keeps_vertices(&ready.scene) {
        return;
    }
    let Some(pieces) = ready.opened.pieces.as_mut() else {
        return;
    };
    pieces.keep_own_cells(&ready.disc);
    let d = ready.disc.dim;
    let held = ready.reactions.held.iter().map(|&(dof, _)| dof / d);
    let read: Vec<usize> = pieces.points().iter().copied().chain(held).collect();
    // Nothing shares the discretization before the time loop's setup.
    let alone = Arc::get_mut(&mut ready.disc);
    debug_assert!(
        alone.is_some(),
        "rank 0's discretization is shared in its setup"
    );
    if let Some(disc) = alone {
        disc.forget_cells();
        let every = std::mem::take(&mut disc.nodes);
        disc.keep_places(&every, &read);
    }
}

/// Options of `viscontact resume`: those of a run; `out` defaults to the checkpoint's
/// directory, and `overrides` may only set `time.end`, `output.*` and `checkpoint.*` (see
/// [`checkpoint::Checkpoint::scene`]).
pub type ResumeOptions = RunOptions;

/// Continues a run from its checkpoint: the stored scene (with the allowed overrides), the
/// same mesh (checked by fingerprint) and physics, the saved state; the series in the output
/// directory keeps its frames before the checkpoint's step and gets the rest, summary.json
/// describes the whole run. Bit for bit the run that never stopped. An output directory
/// that holds another run is refused.
pub fn resume(checkpoint_path: &Path, opts: &ResumeOptions) -> Result<Outcome> {
    if !opts.ranks.is_first() {
        return follow(checkpoint_path, Begun::Resume, opts);
    }
    let start = Instant::now();
    let (mut ready, mut cp) = opts.ranks.agree(prepare_resume(checkpoint_path, opts))?;
    tell_followers_the_series(opts, &ready.opened)?;
    hold_history_of_first(opts.ranks, &mut ready);
    first_lets_go_of_cells(opts.ranks, &mut ready);
    let mut tl = ready.solving.time_loop(&ready.scene, &ready.disc)?;
    let saved = cp.saved(ready.disc.n_dofs, tl.rows().len(), tl.held_at())?;
    tl.restore(saved)
        .map_err(|e| Error::input(format!("{}: {e}", checkpoint_path.display())))?;
    // The last moment a signal ends the resume unchanged; after it, it stops after a step.
    let committed = opts
        .interrupt
        .unless_signalled(|| dir::remove_temporaries(&ready.opened.out));
    tell_followers(opts, &committed)?;
    committed.map_err(Error::Interrupted)?;
    drive(Drive {
        scene: &ready.scene,
        reactions: ready.reactions,
        disc: &ready.disc,
        tl,
        opened: ready.opened,
        resumed: Some(&cp),
        start,
        opts,
    })
}

/// A resume's setup up to its time loop: the checkpoint, its scene and mesh checked, the
/// output directory locked and its series verified.
fn prepare_resume(
    checkpoint_path: &Path,
    opts: &ResumeOptions,
) -> Result<(Ready, checkpoint::Checkpoint)> {
    let stage = || opts.interrupt.between_setup_stages();
    let read = || -> Result<_> {
        // What is wrong with the checkpoint itself is said first, then the directory.
        let cp = checkpoint::Checkpoint::read(checkpoint_path)?;
        let scene = Arc::new(cp.scene(&opts.overrides)?);
        stage()?;
        let mesh = read_mesh(&scene).map_err(|e| {
            Error::input(format!(
                "{}: the run's mesh cannot be read: {e} (a run moved to another place: give \
                 its mesh with --set mesh.file=NEW)",
                checkpoint_path.display()
            ))
        })?;
        Ok(((cp, scene), Some(mesh)))
    };
    let ((cp, scene), mut mesh) = opts.ranks.with_mesh_of_first(read(), |r| &r.1)?;
    before_discretizing(opts, &scene)?;
    let (mut disc, made) = opts.ranks.discretize(&mut mesh, &scene)?;
    stage()?;
    cp.check(&scene, &mesh, &disc)?;
    check_continuation(checkpoint_path, &cp, &scene, opts.stop_after)?;
    let out = opts.out.clone().unwrap_or_else(|| cp.dir());
    let (estimate, plans) = estimate(
        &scene,
        &disc,
        (cp.n, &out),
        || cp.plans(&scene),
        &mut |_| {},
    )?;
    let solver = check_contact_plan(
        &scene,
        &disc,
        &estimate,
        Some(checkpoint_path),
        (opts.ranks.size, made.as_ref()),
    )?;
    check_started_ranks(&scene, &solver, opts)?;
    let own = opts.ranks.keep_own_columns(&mut disc, &scene, made)?;
    let disc = Arc::new(disc);
    dir::check_out_dir(&out, opts.force)?;
    let lock = DirLock::acquire(&out, "resume")?;
    dir::check_same_run(&out, checkpoint_path, &cp.id.run_id)?;
    let identity = checkpoint::Identity::new(&scene, &mesh, &disc, Some(&cp));
    // The series is verified against the frames the checkpoint recorded, unless the run
    // continues in another directory that holds no series (without the old frames).
    let resumed = (dir::is_checkpoint_dir(&out, checkpoint_path) || dir::holds_series(&out))
        .then_some(Resumed {
            checkpoint: checkpoint_path,
            step: cp.n,
            frames: cp.frames.as_deref(),
        });
    if cp.frames.is_none() {
        crate::errln!(
            "warning: {}: checkpoint format version {} records no checksums of the frames \
             before it; the series in {} is continued without verifying it",
            checkpoint_path.display(),
            cp.version,
            out.display()
        );
    }
    // Before the factorization: the series' writer thread compresses the mesh beside it.
    let (series, pieces) = open_series(
        (&out, &identity.run_id),
        (&mesh, &disc),
        (own.as_ref(), opts.ranks),
        &scene,
        resumed.as_ref(),
    )?;
    stage()?;
    let reactions = history_csv::reactions(&scene, &mesh, &disc, &plans)?;
    let ready = Ready {
        scene,
        reactions,
        disc,
        solving: Solving { solver, own, plans },
        opened: Opened {
            identity,
            series,
            pieces,
            out,
            lock,
        },
    };
    Ok((ready, cp))
}

/// Refuses (exit 2) a resume that would do nothing the user asked for: one of a run that
/// completed (it would solve its last step again) unless `time.end` moves the end later,
/// and a `--stop-after` step that the checkpoint has passed.
fn check_continuation(
    path: &Path,
    cp: &checkpoint::Checkpoint,
    scene: &Scene,
    stop_after: Option<usize>,
) -> Result<()> {
    let steps = scene.time.steps;
    if cp.n >= steps && dir::completed(&cp.dir(), &cp.id.run_id) {
        return Err(Error::input(format!(
            "{}: the run is complete (summary.json: \"completed\", t = {}); to continue it, \
             give a later end: --set time.end=T2",
            path.display(),
            scene.time.end
        )));
    }
    match stop_after {
        Some(s) if s < cp.n => Err(Error::input(format!(
            "{}: --stop-after {s}: the checkpoint continues the run at step {} (steps up to \
             {} are solved); give a step from {} to {steps}, or leave --stop-after out",
            path.display(),
            cp.n,
            cp.n - 1,
            cp.n
        ))),
        _ => Ok(()),
    }
}

/// Says (on stderr) that a `--stop-after` step at or past the last step does not stop the
/// run: it runs to its end.
fn note_stop_after(stop_after: Option<usize>, steps: usize) {
    if let Some(s) = stop_after.filter(|&s| s >= steps) {
        crate::errln!(
            "warning: --stop-after {s}: the run's last step is {steps}, so it runs to its end \
             (a stop after step {} or earlier leaves a checkpoint to resume)",
            steps.saturating_sub(1)
        );
    }
}

/// The run's solver, resolved once (`Descriptor::of_run`); refuses (exit 2) a run whose
/// memory would not fit (`check_memory`) on its `ranks` (their count, and this rank's
/// layout where `Ranks::discretize` made one). A resume of `checkpoint` cannot
/// change `solver.contact`, the run's physics: where the contact solver's memory is what
/// does not fit, its message says so.
fn check_contact_plan(
    scene: &Scene,
    disc: &Discretization,
    steps: &Estimate,
    checkpoint: Option<&Path>,
    ranks: (usize, Option<&crate::ranks::Own>),
) -> Result<Descriptor> {
    let solver = Descriptor::of_run(scene, disc)?;
    let spreads = solver.spreads();
    check_memory(scene, disc, &solver, steps, ranks, None).map_err(|e| match checkpoint {
        Some(cp) if !spreads => Error::input(format!(
            "{}: {e}; a resume keeps the run's solver.contact: resume it where more memory \
             is available, or start a new run with `viscontact run`",
            cp.display()
        )),
        _ => e,
    })?;
    Ok(solver)
}

/// Refuses (exit 2) a run whose memory would not fit the memory available: through PETSc,
/// a rank's on `ranks` ranks (their count, and the layout a rank made where it has one:
/// `ranks::Plan::new`; `ranks::Plan::check`, which names how many would fit; `show`,
/// where given, gets its line before, with a step's time on this machine), else its
/// contact solver's with what its steps hold (`steps`: `ContactPlan::check`).
pub fn check_memory(
    scene: &Scene,
    disc: &Discretization,
    solver: &Descriptor,
    steps: &Estimate,
    ranks: (usize, Option<&crate::ranks::Own>),
    show: Option<&mut dyn FnMut(&str)>,
) -> Result<()> {
    #[cfg(feature = "petsc")]
    if let Some(plan) = ranks_plan(scene, disc, solver, ranks, steps)? {
        if let Some(show) = show {
            show(&plan.clone().timed(disc).to_string());
        }
        return plan.check();
    }
    let _ = (scene, disc, ranks, show);
    match solver.contact() {
        Some(plan) => plan.check(steps),
        None => Ok(()),
    }
}

/// What a rank of a run through PETSc over `ranks` ranks holds and does (`ranks::Plan`,
/// what `check --ranks` prints), holding what `steps` estimates besides its setup; None
/// for a run that does not go through PETSc.
#[cfg(feature = "petsc")]
fn ranks_plan(
    scene: &Scene,
    disc: &Discretization,
    solver: &Descriptor,
    (ranks, made): (usize, Option<&crate::ranks::Own>),
    steps: &Estimate,
) -> Result<Option<crate::ranks::Plan>> {
    match *solver.build() {
        crate::solver::choice::Build::Krylov { newton } => {
            crate::ranks::Plan::new(disc, scene, (ranks, made), newton, steps).map(Some)
        }
        _ => Ok(None),
    }
}

/// A run in progress: what [`drive`] needs.
struct Drive<'a> {
    /// Shared with the writer thread of history.csv.
    scene: &'a Arc<Scene>,
    /// history.csv's held rows (`history_csv::reactions`).
    reactions: Reactions,
    disc: &'a Arc<Discretization>,
    tl: TimeLoop<'a>,
    /// The directory is this run's until `drive` returns.
    opened: Opened,
    /// The checkpoint a resume continues; None for a new run.
    resumed: Option<&'a checkpoint::Checkpoint>,
    start: Instant,
    opts: &'a RunOptions,
}

/// The time loop of a run with its consumers (history.csv and the checkpoints opened here,
/// from the step a resume continues), then summary.json however the run ended.
fn drive(d: Drive) -> Result<Outcome> {
    let Opened {
        identity,
        series,
        pieces,
        out,
        lock: _lock,
    } = d.opened;
    let from = d.resumed.map(|cp| cp.n);
    let history = HistoryCsv::open(&out, d.scene, d.reactions, d.disc, &d.tl, from)?;
    let run_id = identity.run_id.clone();
    let steps = d.scene.time.steps;
    let writer = match d.resumed {
        Some(cp) => checkpoint::Writer::resume(&out, identity, steps, d.tl.rows(), cp),
        None => checkpoint::Writer::new(&out, identity, steps, d.tl.rows()),
    };
    let log = d.resumed.map_or_else(RunLog::default, |cp| cp.log.clone());
    let setup_s = d.start.elapsed().as_secs_f64();
    let warnings = crate::effects::warnings(d.scene, d.disc, d.tl.descriptor());
    for w in &warnings {
        crate::errln!("warning: {w}");
    }
    note_stop_after(d.opts.stop_after, d.scene.time.steps);
    let mut tl = d.tl;
    let rows = Arc::new(tl.rows().clone());
    let mut consumers = Consumers {
        statistics: Statistics::new(log),
        frames: Frames {
            series,
            pieces,
            disc: Arc::clone(d.disc),
            rows: Arc::clone(&rows),
            scene: d.scene,
        },
        checkpoints: Checkpoints::new(writer, d.scene),
        history,
        progress: Progress::new(d.opts.progress, tl.n(), d.scene.time.steps),
        stop: StopRule {
            after: d.opts.stop_after,
            interrupt: d.opts.interrupt.clone(),
            ranks: d.opts.ranks,
        },
    };
    follow_signals(&mut tl, d.opts);
    let steps_start = Instant::now();
    let (frames, ranks) = (&consumers.frames, d.opts.ranks);
    consumers.statistics.of_pieces = of_pieces(frames.pieces.as_ref(), d.disc, &tl, ranks)?;
    let ended = tl.run(d.scene.time.steps, &mut consumers);
    let Consumers {
        statistics,
        mut frames,
        checkpoints,
        mut history,
        progress,
        ..
    } = consumers;
    drop(progress);
    let checkpoint = checkpoints.path();
    // Every checkpoint handed over reaches the disk before the run reports how it ended.
    // So does every frame handed to the series' writer thread and every history row (their
    // errors name the file).
    let flushed = checkpoints
        .writer
        .finish()
        .and_then(|()| frames.series.finish())
        .and_then(|()| history.finish());
    let ended = ended.and_then(|end| flushed.map(|()| end));
    let steps_s = steps_start.elapsed().as_secs_f64();
    if let Ok(RunEnd::Completed) = ended {
        // Frames an earlier (or the interrupted) run left that this series does not list.
        dir::remove_stale_frames(&frames.series, from.unwrap_or(0));
    }
    let last = statistics.last.unwrap_or(0);
    let signal = d.opts.interrupt.signal();
    let message = match &ended {
        Ok(RunEnd::Completed) => None,
        Ok(RunEnd::Stopped) => Some(stopped_message(
            last,
            last as f64 * tl.k(),
            signal,
            checkpoint.as_deref(),
            d.opts.force,
        )),
        Err(e) => Some(e.to_string()),
    };
    let ending = Ending {
        status: match &ended {
            Ok(RunEnd::Completed) => Status::Completed,
            Ok(RunEnd::Stopped) => Status::Interrupted,
            Err(_) => Status::Failed,
        },
        message: message.clone(),
        timing: Timing {
            setup_s,
            steps_s,
            total_s: d.start.elapsed().as_secs_f64(),
        },
        output: OutputSummary {
            directory: out.display().to_string(),
            files: frames.series.files().len(),
        },
        warnings,
        ranks: d.opts.ranks.size,
    };
    let summary = Summary::new(ending, &run_id, d.scene, d.disc, &tl, statistics);
    let written = write_atomic(&out.join("summary.json"), summary_json(&summary).as_bytes());
    match ended {
        // The failure is what the run reports; its summary is written if the disk allows.
        Err(e) => Err(e),
        Ok(RunEnd::Completed) => written.map(|()| Outcome::Finished(Box::new(summary))),
        Ok(RunEnd::Stopped) => written.map(|()| Outcome::Stopped {
            step: last,
            time: last as f64 * tl.k(),
            checkpoint,
            signal,
            message: message.unwrap_or_default(),
        }),
    }
}

/// What summary.json and the command say about a run stopped after step `step`.
fn stopped_message(
    step: usize,
    time: f64,
    signal: Option<i32>,
    checkpoint: Option<&Path>,
    force: bool,
) -> String {
    let why = match signal {
        Some(s) => format!("interrupted by {}", signal_name(s)),
        None => "stopped as asked (--stop-after)".to_string(),
    };
    let next = match checkpoint {
        Some(cp) => format!(
            "continue with: viscontact resume {}{}",
            cp.display(),
            if force { " --force" } else { "" }
        ),
        None => "checkpoints are disabled ([checkpoint] enabled = false), so the run cannot \
                 be continued"
            .to_string(),
    };
    format!("{why} after step {step} (t = {}); {next}", time_text(time))
}

/// A time t_n = n·k as a user reads it: rounded to 12 significant digits, then the
/// shortest text that reads back as that number (`0.332375`, not the `0.33237500000000003`
/// of 2659 · 0.000125).
fn time_text(t: f64) -> String {
    let rounded: f64 = format!("{t:.11e}").parse().unwrap_or(t);
    format!("{rounded}")
}

#[cfg(test)]
mod tests {
    #[test]
    fn times_are_shown_without_float_noise() {
        assert_eq!(super::time_text(2659.0 * 0.000125), "0.332375");
        assert_eq!(super::time_text(1.0 / 3.0), "0.333333333333");
        assert_eq!(super::time_text(3.0e-9), "0.000000003");
        assert_eq!(super::time_text(1.0), "1");
    }
}
