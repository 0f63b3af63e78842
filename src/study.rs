//! Accuracy against cost: the `study` command (README.md, "Commands"; docs/verification.md).
//!
//! A study runs one scene at several levels and measures, as Section 4 of the paper does,
//! the error at the end time in the H¹ norm against a reference solution,
//!
//!   e = ‖u_ref(T) − u_N^{kh}‖_1,   ‖v‖_1 = (‖v‖²_{L²} + |v|²_{H¹})^{1/2}  (the full H¹ norm),
//!
//! computed on the reference mesh (see [`transfer`]: exact P1 prolongation for nested meshes,
//! nodal interpolation for non-nested ones), together with the wall time of each run. The
//! seminorm |e|_{H¹}, the L² norm and the errors relative to the reference's norms are
//! reported too. 2D scenes (triangles) and 3D scenes (tetrahedra, `mesh.model = "3d"`) are
//! studied alike: the fields carry 3 components, z = 0 in 2D.
//!
//! # Levels, families and the reference
//!
//! A level n stands for the mesh of level n (h = 1/n: the `{n}` of the mesh pattern) and for
//! N = n time steps (k = T/n; T = 1 in the paper, so k = 1/n). One family varies one thing:
//!
//! | `--vary` | level run             | reference run               | paper   |
//! |----------|-----------------------|-----------------------------|---------|
//! | `both`   | mesh n, N = n         | mesh R, N = R               | Table 1 |
//! | `h`      | mesh n, N = F         | mesh R, N = F               | Table 2 |
//! | `k`      | mesh F, N = n         | mesh F, N = R               | Table 3 |
//!
//! with R = `--reference` and F = `--fixed` (default F = R). The reference keeps the fixed
//! parameter at its fixed value, so a family measures the error of what it varies alone;
//! with F = R (the paper's choice) all three families share the reference h = k = 1/R,
//! which is then computed once.
//!
//! # Meshes per level
//!
//! - A pattern (`--mesh-pattern`), relative to the scene file like `mesh.file`, with `{n}`
//!   or `{n:03}` (zero-padded) for the level: `../meshes/paper/rect_{n:03}.msh`.
//! - Without one, the pattern is derived from the scene's `mesh.file` when its name ends in
//!   `_<digits>.msh` (`rect_032.msh` → `rect_{n:03}.msh`, `block_008.msh` →
//!   `block_{n:03}.msh`: the block's level n has cubes of side h = 1/n, each cut into 6
//!   tetrahedra). Every mesh must exist before anything runs; a missing one is an input
//!   error that says how to make it (`meshes/generate.sh block 16` for the block meshes too
//!   big to commit, else gmsh on the `.geo` beside it).
//! - A list (`--meshes a.msh,b.msh,…,ref.msh`, relative to the working directory) for
//!   families that are not numbered, such as unstructured meshes: one mesh per level, then
//!   the reference mesh. `h` is then the longest edge of each mesh and a level is only the
//!   number of steps N; `--vary k` runs on the last (reference) mesh.
//!
//! # Cost
//!
//! The wall time of a run is everything from reading the scene to u_N: mesh, assembly, the
//! factorization of K_A and all N + 1 steps (no output is written). It is the median of
//! `--repeat` runs (default: 3 when one run takes under a second, else 1). With
//! `--kernel-compare` every level runs twice: with the scene's Prony kernel (O(1) memory
//! update per step) and with the same kernel written as an expression, which the scheme sums
//! directly (O(n) per step); the table and plot show how the time grows with N for each.
//!
//! # Cases
//!
//! A study is planned first as a list of distinct cases (`plan`: each reference and level
//! run once); they are solved one after another in this process, side by side in processes
//! of their own (`--jobs N`, [`jobs`]) or as the runs of a Slurm job array (`--emit slurm`,
//! then `--collect`, [`slurm`]), and the report is made from their solutions alone: the
//! numbers do not depend on how, only the wall times ([`Timed`]).

pub mod jobs;
pub mod memory_cost;
mod meshes;
mod plan;
mod report;
mod shared;
pub mod slurm;
pub mod transfer;

use crate::fem::Discretization;
use crate::kernel::Kernel;
use crate::resources::SETUP_MEMORY;
use crate::run::{discretize, load_scene};
use crate::scene::Scene;
use crate::time_loop::TimeLoop;
use crate::{Error, Result};
use serde::Serialize;
use shared::{Discretized, Discs, Transfers};
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::sync::Arc;
use std::time::Instant;
use transfer::{max_edge, nodal_vectors, p1_norms, Transfer};

use meshes::Meshes;
pub use meshes::{derive_pattern, expand_pattern};
pub use plan::Case;
use plan::{Level, Plan};
pub use report::{csv, default_out, fraction, markdown, write_report};

/// Which parameter a family of runs varies.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Vary {
    /// h = k = 1/n (the paper's Table 1).
    Both,
    /// h = 1/n, k fixed (Table 2).
    H,
    /// k = T/n, h fixed (Table 3).
    K,
}

impl FromStr for Vary {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s.trim() {
            "both" => Ok(Vary::Both),
            "h" => Ok(Vary::H),
            "k" => Ok(Vary::K),
            other => Err(format!("'{other}' is not one of both, h, k")),
        }
    }
}

impl std::fmt::Display for Vary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Vary::Both => "both",
            Vary::H => "h",
            Vary::K => "k",
        })
    }
}

impl Vary {
    /// A title naming the family and the paper's table it reproduces.
    pub fn title(&self) -> &'static str {
        match self {
            Vary::Both => "h = k (the paper's Table 1)",
            Vary::H => "k fixed, h varies (Table 2)",
            Vary::K => "h fixed, k varies (Table 3)",
        }
    }
}

/// How the kernel of the scene is handed to the scheme.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum KernelForm {
    /// As the scene gives it.
    AsGiven,
    /// A Prony series rewritten as the expression Σ a_i exp(−b_i s): direct O(n) sum.
    Expression,
}

impl KernelForm {
    fn label(&self, scene_kernel: &str) -> String {
        match self {
            KernelForm::AsGiven => scene_kernel.to_string(),
            KernelForm::Expression => "expression".into(),
        }
    }
}

/// Where the mesh of each level comes from.
#[derive(Clone, Debug)]
pub enum MeshFamily {
    /// A path with `{n}` or `{n:0W}`, relative to the scene file.
    Pattern(String),
    /// One mesh per level followed by the reference mesh (relative to the working
    /// directory).
    List(Vec<PathBuf>),
}

/// Everything a study needs besides the scene.
#[derive(Clone, Debug)]
pub struct StudyOptions {
    pub levels: Vec<usize>,
    pub reference: usize,
    pub vary: Vec<Vary>,
    /// The level of the fixed parameter (default: the reference level).
    pub fixed: Option<usize>,
    /// None: derived from the scene's mesh.file.
    pub meshes: Option<MeshFamily>,
    /// Runs per level for the median wall time (None: 3 under a second, else 1).
    pub repeat: Option<usize>,
    pub overrides: Vec<String>,
    pub kernel_compare: bool,
    /// Progress lines on stderr.
    pub progress: bool,
    /// Cases solved side by side, each in a process of its own ([`jobs`]); 1 (the default):
    /// one after another in this process. The numbers are the same.
    pub jobs: usize,
}

impl Default for StudyOptions {
    fn default() -> Self {
        StudyOptions {
            levels: vec![8, 16, 32, 64],
            reference: 128,
            vary: vec![Vary::Both],
            fixed: None,
            meshes: None,
            repeat: None,
            overrides: Vec::new(),
            kernel_compare: false,
            progress: false,
            jobs: 1,
        }
    }
}

/// One row of a study table.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    pub family: Vary,
    pub kernel: String,
    pub level: usize,
    /// The nominal mesh size: 1/n for a pattern family, the longest edge for a list.
    pub h: f64,
    /// The longest edge of the mesh.
    pub h_max: f64,
    pub k: f64,
    pub steps: usize,
    pub nodes: usize,
    pub dofs: usize,
    /// ‖e‖_1 = (‖e‖²_{L²} + |e|²_{H¹})^{1/2}, e = u_N − u_ref(T) on the reference mesh.
    pub err_h1: f64,
    /// |e|_{H¹}.
    pub err_h1_semi: f64,
    pub err_l2: f64,
    /// ‖e‖_1 / ‖u_ref‖_1 and ‖e‖_{L²} / ‖u_ref‖_{L²}.
    pub rel_h1: f64,
    pub rel_l2: f64,
    /// ln(e_{i−1}/e_i) / ln(p_{i−1}/p_i), p = h (vary h) or k (vary k, both).
    pub order_h1: Option<f64>,
    pub order_l2: Option<f64>,
    /// Median wall time of a whole run (setup and all steps), and of the steps alone.
    pub wall_s: f64,
    pub steps_s: f64,
    /// steps_s / (N + 1).
    pub per_step_s: f64,
    pub runs: usize,
    /// The mesh is nested in the reference mesh (exact prolongation).
    pub nested: bool,
    pub mesh: String,
}

/// The reference run of a family.
#[derive(Clone, Debug, Serialize)]
pub struct ReferenceInfo {
    pub mesh: String,
    pub h: f64,
    pub h_max: f64,
    pub k: f64,
    pub steps: usize,
    pub dofs: usize,
    pub u_l2: f64,
    pub u_h1: f64,
    pub wall_s: f64,
}

/// One family: a table.
#[derive(Clone, Debug, Serialize)]
pub struct Family {
    pub vary: Vary,
    pub kernel: String,
    pub form: KernelForm,
    pub reference: ReferenceInfo,
    pub rows: Vec<Row>,
}

/// Prony against expression at one level (`--kernel-compare`).
#[derive(Clone, Debug, Serialize)]
pub struct CostRow {
    pub family: Vary,
    pub level: usize,
    pub steps: usize,
    pub dofs: usize,
    pub prony_steps_s: f64,
    pub expression_steps_s: f64,
    pub prony_wall_s: f64,
    pub expression_wall_s: f64,
    /// max|u_expr − u_prony| / max|u_prony| at T: the two forms agree up to rounding.
    pub max_rel_diff: f64,
}

/// How the cases of a study ran, and so what their wall times measure.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Timed {
    /// One after another in the study's process.
    InTurn,
    /// Up to this many side by side, each in a process of its own (`--jobs`): measured
    /// concurrently, sharing the machine's cores and memory bandwidth.
    SideBySide(usize),
    /// As the runs of a Slurm job array (`--collect`): each a whole `run` on a cluster
    /// node, its output included.
    SlurmArray,
}

/// Everything a study found.
#[derive(Clone, Debug, Serialize)]
pub struct StudyReport {
    pub scene: String,
    pub end_time: f64,
    /// How the wall times were measured.
    pub timed: Timed,
    pub families: Vec<Family>,
    pub kernel_cost: Vec<CostRow>,
}

// ---------------------------------------------------------------------------------------
// Running one case
// ---------------------------------------------------------------------------------------

/// The solution of one run at T and what it cost.
pub struct Solved {
    /// Shared by the cases on one mesh where the study discretizes for them (`shared`).
    pub disc: Arc<Discretization>,
    /// u_N per node (3 components, z = 0 in 2D; 0 on Γ1).
    pub u: Vec<[f64; 3]>,
    pub steps: usize,
    pub k: f64,
    pub end: f64,
    pub mesh: String,
    pub wall_s: f64,
    pub steps_s: f64,
    pub runs: usize,
}

/// The scene's Prony kernel as the expression Σ a_i exp(−b_i s); other kernels are refused.
pub fn prony_as_expression(kernel: Option<&Kernel>) -> Result<Kernel> {
    let Some(Kernel::Prony(terms)) = kernel else {
        return Err(Error::input(
            "--kernel-compare needs a scene whose [material.relaxation] is a Prony series \
             ('prony = [[a, b], …]'); this scene's kernel is not one",
        ));
    };
    let text = terms
        .iter()
        .map(|(a, b)| format!("({a})*exp(-({b})*s)"))
        .collect::<Vec<_>>()
        .join(" + ");
    let e = crate::expr::Expr::parse(&text, &["s"], "kernel-compare")?;
    Ok(Kernel::Expr(Box::new(e)))
}

fn kernel_name(kernel: Option<&Kernel>) -> &'static str {
    match kernel {
        None => "none",
        Some(Kernel::Prony(_)) => "prony",
        Some(Kernel::Expr(_)) => "expression",
        Some(Kernel::Table(_, _)) => "table",
    }
}

/// Runs a scene once (with overrides) to t_N without output; returns u_N and the times.
pub fn solve_once(
    scene_path: &Path,
    overrides: &[String],
    form: KernelForm,
) -> Result<(Solved, &'static str)> {
    solve_case(scene_path, overrides, Ok, form)
}

/// A study's case of a scene: on `mesh` (written as `mesh.file` is, relative to the scene
/// file) in `steps` steps to the scene's end time.
fn case(mesh: &str, steps: usize) -> impl Fn(Scene) -> Result<Scene> + '_ {
    move |scene| {
        let end = scene.time.end;
        scene.with_mesh(Path::new(mesh))?.with_time(end, steps)
    }
}

/// A case read and discretized with its kernel in the form asked for: all of a run but its
/// steps, and the name of the kernel the scene gives.
pub(crate) struct Prepared {
    scene: Scene,
    /// The mesh and its discretization (shared by the cases on that mesh, `shared::Discs`).
    mesh: Discretized,
    given: &'static str,
}

impl Prepared {
    /// The scene as `case` changes it, discretized; for [`KernelForm::Expression`] with its
    /// Prony kernel written as an expression.
    fn new(
        scene_path: &Path,
        overrides: &[String],
        case: impl FnOnce(Scene) -> Result<Scene>,
        form: KernelForm,
    ) -> Result<Prepared> {
        let (scene, mesh, disc) = discretize(case(load_scene(scene_path, overrides)?)?)?;
        let d = Discretized {
            mesh: mesh.path.display().to_string(),
            disc: Arc::new(disc),
        };
        Prepared::of(scene, d, form)
    }

    /// The scene of a case and the discretization of its mesh, with its kernel in `form`.
    fn of(mut scene: Scene, d: Discretized, form: KernelForm) -> Result<Prepared> {
        let given = kernel_name(scene.physics.relaxation.as_ref());
        if form == KernelForm::Expression {
            scene.physics.relaxation =
                Some(prony_as_expression(scene.physics.relaxation.as_ref())?);
            // The reference form is the direct sum, not a fit of it.
            scene.physics.compression = None;
        }
        Ok(Prepared {
            scene,
            mesh: d,
            given,
        })
    }

    /// The case of a study, prepared with the discretization of its mesh from `discs`.
    fn of_case(
        scene_path: &Path,
        overrides: &[String],
        c: &Case,
        discs: &mut Discs,
    ) -> Result<Prepared> {
        let (scene, d) = discs.prepare(scene_path, overrides, case(&c.mesh, c.steps))?;
        Prepared::of(scene, d, c.form)
    }

    /// The memory a run of the case may take, in bytes: what `check` estimates its steps
    /// hold, plus [`SETUP_MEMORY`].
    fn memory(&self) -> f64 {
        crate::resources::Estimate::new(&self.scene, &self.mesh.disc, 0).memory() + SETUP_MEMORY
    }

    /// The case solved: u_N per node and the times of one run.
    fn solved(self, u: Vec<[f64; 3]>, wall_s: f64, steps_s: f64) -> (Solved, &'static str) {
        let solved = Solved {
            disc: self.mesh.disc,
            u,
            steps: self.scene.time.steps,
            k: self.scene.time.k(),
            end: self.scene.time.end,
            mesh: self.mesh.mesh,
            wall_s,
            steps_s,
            runs: 1,
        };
        (solved, self.given)
    }
}

/// [`solve_once`] for the scene as `case` changes it; the wall time runs from reading the
/// scene file.
fn solve_case(
    scene_path: &Path,
    overrides: &[String],
    case: impl FnOnce(Scene) -> Result<Scene>,
    form: KernelForm,
) -> Result<(Solved, &'static str)> {
    let start = Instant::now();
    let prepared = Prepared::new(scene_path, overrides, case, form)?;
    let steps_start = Instant::now();
    let u = {
        let mut tl = TimeLoop::new(&prepared.scene, &prepared.mesh.disc)?;
        solve_to_end(&mut tl, prepared.scene.time.steps)?;
        tl.u().to_vec()
    };
    let steps_s = steps_start.elapsed().as_secs_f64();
    let wall_s = start.elapsed().as_secs_f64();
    let u = nodal_vectors::<3>(&prepared.mesh.disc, &u);
    Ok(prepared.solved(u, wall_s, steps_s))
}

/// Solves the steps of a time loop up to n = N, without output: then `tl.u()` is
/// u_N = u_0 + kΣ_{j<N} w_j.
pub fn solve_to_end(tl: &mut TimeLoop, steps: usize) -> Result<()> {
    tl.run(steps, &mut |_: &crate::time_loop::Solved| Ok(()))
        .map(|_| ())
}

/// Runs a case `repeat` times (None: 3 when the first run takes under a second) and keeps
/// the median times.
fn solve_timed(
    scene_path: &Path,
    overrides: &[String],
    case: impl Fn(Scene) -> Result<Scene>,
    form: KernelForm,
    repeat: Option<usize>,
) -> Result<(Solved, &'static str)> {
    let (mut first, given) = solve_case(scene_path, overrides, &case, form)?;
    let runs = repeat
        .unwrap_or(if first.wall_s < 1.0 { 3 } else { 1 })
        .max(1);
    let (mut walls, mut steps) = (vec![first.wall_s], vec![first.steps_s]);
    for _ in 1..runs {
        let (again, _) = solve_case(scene_path, overrides, &case, form)?;
        walls.push(again.wall_s);
        steps.push(again.steps_s);
    }
    first.wall_s = median(&mut walls);
    first.steps_s = median(&mut steps);
    first.runs = runs;
    Ok((first, given))
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

// ---------------------------------------------------------------------------------------
// Errors against the reference
// ---------------------------------------------------------------------------------------

/// The error norms of a solution against the reference, on the reference mesh.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ErrorNorms {
    pub l2: f64,
    pub h1_semi: f64,
    /// The full H¹ norm (‖e‖²_{L²} + |e|²_{H¹})^{1/2}.
    pub h1: f64,
    pub nested: bool,
}

/// ‖u − u_ref‖ on the reference mesh: u is moved onto the reference nodes by `t` (a
/// [`Transfer`] from u's mesh to the reference mesh) and the difference of the two P1
/// fields is integrated exactly.
pub fn error_norms(
    t: &Transfer,
    u: &[[f64; 3]],
    reference: &Discretization,
    u_ref: &[[f64; 3]],
) -> ErrorNorms {
    let on_ref = t.apply(u);
    let e: Vec<[f64; 3]> = on_ref
        .iter()
        .zip(u_ref)
        .map(|(a, b)| [a[0] - b[0], a[1] - b[1], a[2] - b[2]])
        .collect();
    let (l2, semi) = p1_norms(&reference.cells, &e);
    ErrorNorms {
        l2,
        h1_semi: semi,
        h1: (l2 * l2 + semi * semi).sqrt(),
        nested: t.nested,
    }
}

/// ln(e0/e1) / ln(p0/p1).
pub fn observed_order(e0: f64, e1: f64, p0: f64, p1: f64) -> Option<f64> {
    (e0 > 0.0 && e1 > 0.0 && p0 != p1).then(|| (e0 / e1).ln() / (p0 / p1).ln())
}

// ---------------------------------------------------------------------------------------
// The study
// ---------------------------------------------------------------------------------------

fn say(progress: bool, msg: &str) {
    use std::io::IsTerminal;
    if progress && std::io::stderr().is_terminal() {
        crate::errln!("{msg}");
    }
}

/// Runs a study (no files written; see [`write_report`]): plans its cases, solves them (one
/// after another, or `opts.jobs` side by side in processes of their own: the same numbers)
/// and makes the tables of their solutions.
pub fn run_study(scene_path: &Path, opts: &StudyOptions) -> Result<StudyReport> {
    check_levels(opts)?;
    let meshes = Meshes::for_study(scene_path, opts)?;
    let plan = Plan::new(opts, &meshes)?;
    let mut transfers = Transfers::default();
    let solved = if opts.jobs > 1 {
        jobs::solve_side_by_side(scene_path, opts, &plan, &mut transfers)?
    } else {
        solve_in_turn(scene_path, opts, &plan.cases)?
    };
    Ok(assemble(
        scene_path,
        opts,
        (&meshes, &plan),
        &solved,
        &mut transfers,
    ))
}

/// Solves the cases one after another in this process.
fn solve_in_turn(
    scene_path: &Path,
    opts: &StudyOptions,
    cases: &[Case],
) -> Result<Vec<(Solved, &'static str)>> {
    cases
        .iter()
        .map(|c| {
            say(opts.progress, &format!("study: {c} …"));
            solve_case_timed(scene_path, &opts.overrides, c)
        })
        .collect()
}

/// A case solved and timed as a study times it.
pub fn solve_case_timed(
    scene_path: &Path,
    overrides: &[String],
    c: &Case,
) -> Result<(Solved, &'static str)> {
    solve_timed(
        scene_path,
        overrides,
        case(&c.mesh, c.steps),
        c.form,
        c.repeat,
    )
}

/// The report of a study from the solutions of its cases (`solved[i]` solves
/// `plan.cases[i]`), with the transfers made so far.
fn assemble(
    scene_path: &Path,
    opts: &StudyOptions,
    (meshes, plan): (&Meshes, &Plan),
    solved: &[(Solved, &'static str)],
    transfers: &mut Transfers,
) -> StudyReport {
    let mut families = Vec::new();
    let mut kernel_cost = Vec::new();
    let mut end_time = 0.0;
    for v in &plan.varies {
        let r = &solved[v.reference.case].0;
        end_time = r.end;
        let reference = reference_info(meshes, r, v.reference.mesh_n);
        let mut solved_by_form: Vec<Vec<&Solved>> = Vec::new();
        for (form, levels) in &v.forms {
            let family = FamilyCase {
                vary: v.vary,
                form: *form,
                reference: &reference,
                ref_run: r,
            };
            families.push(family_of(family, meshes, levels, solved, transfers));
            solved_by_form.push(levels.iter().map(|l| &solved[l.case].0).collect());
        }
        if let [prony, expr] = &solved_by_form[..] {
            kernel_cost.extend(cost_rows(v.vary, &opts.levels, prony, expr));
        }
    }
    StudyReport {
        scene: scene_path.display().to_string(),
        end_time,
        timed: match opts.jobs {
            0 | 1 => Timed::InTurn,
            n => Timed::SideBySide(n),
        },
        families,
        kernel_cost,
    }
}

/// The levels and families a study asks for are there, and levels are ≥ 1.
fn check_levels(opts: &StudyOptions) -> Result<()> {
    if opts.levels.is_empty() {
        return Err(Error::input(
            "study: --levels is empty; give e.g. --levels 8,16,32,64",
        ));
    }
    if opts.levels.contains(&0) || opts.reference == 0 || opts.fixed == Some(0) {
        return Err(Error::input("study: levels must be ≥ 1"));
    }
    if opts.vary.is_empty() {
        return Err(Error::input("study: --vary is empty; give both, h or k"));
    }
    Ok(())
}

/// What the report says of the reference run `r` (on the mesh of level `ref_n`).
fn reference_info(meshes: &Meshes, r: &Solved, ref_n: usize) -> ReferenceInfo {
    let (ref_l2, ref_semi) = p1_norms(&r.disc.cells, &r.u);
    let ref_hmax = max_edge(r.disc.nodes.all(), &r.disc.cells);
    ReferenceInfo {
        mesh: r.mesh.clone(),
        h: meshes.nominal_h(ref_n, ref_hmax),
        h_max: ref_hmax,
        k: r.k,
        steps: r.steps,
        dofs: r.disc.n_free,
        u_l2: ref_l2,
        u_h1: (ref_l2 * ref_l2 + ref_semi * ref_semi).sqrt(),
        wall_s: r.wall_s,
    }
}

/// One family of a study: what it varies, the kernel's form and its reference.
#[derive(Clone, Copy)]
struct FamilyCase<'a> {
    vary: Vary,
    form: KernelForm,
    reference: &'a ReferenceInfo,
    /// The reference run's solution.
    ref_run: &'a Solved,
}

/// The table of one family from the solutions of its levels.
fn family_of(
    family: FamilyCase,
    meshes: &Meshes,
    levels: &[Level],
    solved: &[(Solved, &'static str)],
    transfers: &mut Transfers,
) -> Family {
    let mut rows: Vec<Row> = Vec::new();
    let mut kernel = String::new();
    for l in levels {
        let (s, given) = &solved[l.case];
        kernel = family.form.label(given);
        let h_max = max_edge(s.disc.nodes.all(), &s.disc.cells);
        let h = [meshes.nominal_h(l.mesh_n, h_max), h_max];
        let (r, ref_mesh) = (family.ref_run, &family.reference.mesh);
        let t = transfers.between((&s.mesh, &s.disc), (ref_mesh, &r.disc));
        let e = error_norms(t, &s.u, &r.disc, &r.u);
        rows.push(row(family, (l.n, h), &kernel, (s, e), rows.last()));
    }
    Family {
        vary: family.vary,
        kernel,
        form: family.form,
        reference: family.reference.clone(),
        rows,
    }
}

/// The row of level n of a family, solved as `s` with the error `e` on a mesh of nominal
/// size h and longest edge h_max; `prev` is the row before it (for the observed orders).
fn row(
    family: FamilyCase,
    (n, [h, h_max]): (usize, [f64; 2]),
    kernel: &str,
    (s, e): (&Solved, ErrorNorms),
    prev: Option<&Row>,
) -> Row {
    let (vary, reference) = (family.vary, family.reference);
    let (order_h1, order_l2) = match prev {
        Some(prev) => {
            let (p0, p1) = match vary {
                Vary::H => (prev.h, h),
                Vary::K | Vary::Both => (prev.k, s.k),
            };
            (
                observed_order(prev.err_h1, e.h1, p0, p1),
                observed_order(prev.err_l2, e.l2, p0, p1),
            )
        }
        None => (None, None),
    };
    Row {
        family: vary,
        kernel: kernel.to_string(),
        level: n,
        h,
        h_max,
        k: s.k,
        steps: s.steps,
        nodes: s.disc.nodes.len(),
        dofs: s.disc.n_free,
        err_h1: e.h1,
        err_h1_semi: e.h1_semi,
        err_l2: e.l2,
        rel_h1: e.h1 / reference.u_h1,
        rel_l2: e.l2 / reference.u_l2,
        order_h1,
        order_l2,
        wall_s: s.wall_s,
        steps_s: s.steps_s,
        per_step_s: s.steps_s / (s.steps + 1) as f64,
        runs: s.runs,
        nested: e.nested,
        mesh: s.mesh.clone(),
    }
}

/// Prony against expression at each level of a family (`--kernel-compare`).
fn cost_rows(vary: Vary, levels: &[usize], prony: &[&Solved], expr: &[&Solved]) -> Vec<CostRow> {
    prony
        .iter()
        .zip(expr)
        .enumerate()
        .map(|(i, (p, x))| {
            let scale =
                p.u.iter()
                    .flatten()
                    .fold(0.0f64, |a, v| a.max(v.abs()))
                    .max(f64::MIN_POSITIVE);
            let diff =
                p.u.iter()
                    .flatten()
                    .zip(x.u.iter().flatten())
                    .fold(0.0f64, |a, (u, v)| a.max((u - v).abs()));
            CostRow {
                family: vary,
                level: levels[i],
                steps: p.steps,
                dofs: p.disc.n_free,
                prony_steps_s: p.steps_s,
                expression_steps_s: x.steps_s,
                prony_wall_s: p.wall_s,
                expression_wall_s: x.wall_s,
                max_rel_diff: diff / scale,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn patterns_expand_and_derive() {
        assert_eq!(
            expand_pattern("m/rect_{n:03}.msh", 8).unwrap(),
            "m/rect_008.msh"
        );
        assert_eq!(expand_pattern("a{n}b{n:04}", 16).unwrap(), "a16b0016");
        assert!(expand_pattern("rect.msh", 8).is_err());
        assert!(expand_pattern("rect_{k}.msh", 8).is_err());
        assert_eq!(
            derive_pattern("../meshes/paper/rect_032.msh").as_deref(),
            Some("../meshes/paper/rect_{n:03}.msh")
        );
        assert_eq!(derive_pattern("plate_hole.msh"), None);
        assert_eq!(derive_pattern("rect32.msh"), None);
    }

    #[test]
    fn orders_and_fractions() {
        let o = observed_order(0.4, 0.1, 0.5, 0.25).unwrap();
        assert!((o - 2.0).abs() < 1e-15);
        assert_eq!(observed_order(0.0, 0.1, 0.5, 0.25), None);
        assert_eq!(fraction(0.125), "1/8");
        assert_eq!(fraction(1.0 / 128.0), "1/128");
        assert_eq!(fraction(0.3), "0.3000");
        let mut v = vec![3.0, 1.0, 2.0];
        assert_eq!(median(&mut v), 2.0);
    }

    #[test]
    fn vary_parses() {
        assert_eq!("both".parse::<Vary>().unwrap(), Vary::Both);
        assert_eq!("k".parse::<Vary>().unwrap(), Vary::K);
        assert!("x".parse::<Vary>().is_err());
    }
}
