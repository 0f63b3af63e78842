//! summary.json (docs/output.md): what a run did, in numbers.

use super::consumers::{largest_abs, OfPieces, Statistics};
use crate::fem::Discretization;
use crate::scene::Scene;
use crate::time_loop::TimeLoop;
use serde::Serialize;

/// summary.json (docs/output.md), written for every run that got past its
/// setup: completed, failed or interrupted.
#[derive(Serialize, Debug, Clone)]
pub struct Summary {
    pub status: Status,
    /// The run's id (kept by resume; the checkpoint's root attribute `run_id`).
    pub run_id: String,
    /// The last step n solved (null when none was).
    pub last_step: Option<usize>,
    /// Why a run that did not complete ended, and how to continue it (null when completed).
    pub message: Option<String>,
    pub name: String,
    /// The scene file and the mesh, absolute (`plot` reads them from any directory).
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
    /// The threads the run used (`threads::count`: `--threads`, `VISCONTACT_THREADS`, else
    /// the cores the process may use); the results do not depend on it.
    pub threads: usize,
    /// The MPI ranks the run spread over (`crate::ranks`; 1 without a launcher).
    pub ranks: usize,
    pub timing: Timing,
    pub final_: Final,
    pub contact: ContactSummary,
    pub iterations: Iterations,
    pub output: OutputSummary,
    /// See `effects::warnings`.
    pub warnings: Vec<String>,
    /// How the body's memory sum was computed (`history::Plan`); absent without relaxation.
    pub memory: Option<MemorySummary>,
    /// How the memory sum of each region's own kernel was computed, in the order of the
    /// `[[material.region]]` entries that have one; absent without.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub region_memory: Vec<MemorySummary>,
    /// PETSc's Krylov method of a run with `solver.linear = "petsc"` (absent otherwise);
    /// `iterations` counts its Krylov iterations per step.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub petsc: Option<PetscSummary>,
}

/// summary.json "petsc": the KSP a linear run through PETSc solved with.
#[derive(Serialize, Debug, Clone)]
pub struct PetscSummary {
    /// The KSP's and the PC's types after the options (`cg` and `gamg` by default).
    pub ksp_type: String,
    pub pc_type: String,
    /// `[solver.petsc] options` as the scene gave them.
    pub options: String,
    /// The `PETSC_OPTIONS` environment variable of the run (absent when unset).
    pub environment: Option<String>,
    /// The active-set solver's Newton systems and their Krylov iterations, over the steps
    /// this process solved (a resumed run: those after its checkpoint); absent for a
    /// linear run, whose `iterations` are the Krylov iterations.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub newton: Option<NewtonSummary>,
}

/// summary.json "petsc" "newton": what the active-set solver's Newton systems took, and
/// the settings they ran with (`[solver.active_set]` over its defaults).
#[derive(Serialize, Debug, Clone)]
pub struct NewtonSummary {
    pub tolerance: f64,
    pub max_iterations: usize,
    pub forcing: f64,
    pub krylov_tolerance: f64,
    pub steps: usize,
    pub systems: usize,
    pub krylov_total: usize,
    /// The Krylov iterations of the largest system, and their mean.
    pub krylov_max: usize,
    pub krylov_mean: f64,
}

impl PetscSummary {
    #[cfg(feature = "petsc")]
    fn new(tl: &TimeLoop) -> Option<Self> {
        tl.krylov().map(|k| PetscSummary {
            ksp_type: k.ksp_type.clone(),
            pc_type: k.pc_type.clone(),
            options: k.options.clone(),
            environment: std::env::var("PETSC_OPTIONS").ok(),
            newton: match tl.solver() {
                crate::solver::StepSolver::ActiveSet(a) => {
                    let (c, s) = (a.counts(), a.settings());
                    Some(NewtonSummary {
                        tolerance: s.tolerance,
                        max_iterations: s.max_iterations,
                        forcing: s.forcing,
                        krylov_tolerance: s.krylov_tolerance,
                        steps: c.steps,
                        systems: c.newton,
                        krylov_total: c.krylov,
                        krylov_max: c.max_krylov,
                        krylov_mean: c.krylov as f64 / c.newton.max(1) as f64,
                    })
                }
                _ => None,
            },
        })
    }

    #[cfg(not(feature = "petsc"))]
    fn new(_: &TimeLoop) -> Option<Self> {
        None
    }
}

/// How a run ended.
#[derive(Serialize, Debug, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    /// Every step solved.
    Completed,
    /// A step or a write failed (the command exits 1, or 2 for input found bad only then).
    Failed,
    /// Stopped by SIGINT/SIGTERM or `--stop-after`; the checkpoint continues it.
    Interrupted,
}

/// The end of a run as summary.json tells it.
pub(super) struct Ending {
    pub status: Status,
    pub message: Option<String>,
    pub timing: Timing,
    pub output: OutputSummary,
    /// `effects::warnings`, printed before the first step.
    pub warnings: Vec<String>,
    /// The MPI ranks of the run.
    pub ranks: usize,
}

#[derive(Serialize, Debug, Clone)]
pub struct Timing {
    pub setup_s: f64,
    pub steps_s: f64,
    pub total_s: f64,
}

/// Norms of u_N = u_0 + kΣ_{j<N} w_j, the displacement at t_N = T; for a run that did not
/// complete, of the latest displacement u_n it computed (at `time` = t_n).
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
pub(super) fn summary_json(s: &Summary) -> String {
    let mut v = serde_json::to_value(s).expect("summary serializes");
    if let Some(obj) = v.as_object_mut() {
        if let Some(f) = obj.remove("final_") {
            obj.insert("final".into(), f);
        }
    }
    serde_json::to_string_pretty(&v).expect("summary serializes") + "\n"
}

impl Summary {
    /// The summary of a run of `scene` whose time loop stands at `tl` (u_N = u_0 + kΣ_{j<N}
    /// w_j is the history's u at n = N: w_N is not added), with the statistics of every
    /// step solved.
    pub(super) fn new(
        ending: Ending,
        run_id: &str,
        scene: &Scene,
        disc: &Discretization,
        tl: &TimeLoop,
        stats: Statistics,
    ) -> Summary {
        let Statistics {
            log,
            active,
            stick,
            last,
            of_pieces,
        } = stats;
        // Where the ranks write their own pieces, what they computed (rank 0 may hold
        // neither every cell nor every dof); else of every cell and dof, here.
        let (l2, semi, u_max) = match of_pieces {
            Some(OfPieces {
                norms: [l2, h1],
                u_max,
            }) => (l2.sqrt(), h1.sqrt(), u_max),
            None => {
                let (l2, semi) = disc.norms(tl.u());
                (l2, semi, largest_abs(tl.u()))
            }
        };
        let rows = tl.rows();
        let per_step = log.iterations;
        let completed = ending.status == Status::Completed;
        Summary {
            status: ending.status,
            run_id: run_id.to_string(),
            last_step: last,
            message: ending.message,
            name: scene.name.clone(),
            scene: absolute(&scene.path),
            // The mesh itself is gone (after setup); the discretization holds its nodes and
            // cells (the summary is rank 0's, which keeps them, or their vertices).
            mesh: absolute(&scene.mesh.file),
            nodes: disc.nodes.len(),
            elements: disc.cells_in_mesh,
            dofs: disc.n_free,
            steps: scene.time.steps,
            step_size: tl.k(),
            end_time: scene.time.end,
            effects: tl.effects().names().iter().map(|s| s.to_string()).collect(),
            solver: tl.solver_name(),
            threads: crate::threads::count(),
            ranks: ending.ranks,
            timing: ending.timing,
            final_: Final {
                time: if completed { scene.time.end } else { tl.time() },
                u_l2: l2,
                u_h1: (l2 * l2 + semi * semi).sqrt(),
                u_max,
            },
            contact: ContactSummary {
                max_violation: if rows.n_contact == 0 {
                    0.0
                } else {
                    log.max_violation
                },
                contact_nodes: rows.n_contact,
                friction_nodes: rows.n_friction_nodes(),
                active_at_end: active,
                stick_at_end: stick,
                max_kkt_residual: log.max_kkt_residual,
            },
            iterations: Iterations {
                total: per_step.iter().sum(),
                max: per_step.iter().copied().max().unwrap_or(0),
                per_step,
            },
            output: ending.output,
            warnings: ending.warnings,
            memory: MemorySummary::new(&tl.plans().body, tl.k()),
            region_memory: (tl.plans().regions.iter())
                .filter_map(|p| MemorySummary::new(p, tl.k()))
                .collect(),
            petsc: PetscSummary::new(tl),
        }
    }
}

/// summary.json "memory": the kernel's compression (issue 13).
#[derive(Serialize, Debug, Clone)]
pub struct MemorySummary {
    /// "prony" (the scene's series), "compressed" or "exact" (direct sum).
    pub method: &'static str,
    /// Exponential terms run by the recursion (0 for the direct sum).
    pub terms: usize,
    /// Certified max relative error of the compressed kernel on the lags.
    pub certified_error: Option<f64>,
    /// The last lag the certificate covers, as a time: time.end, or the fit's horizon.
    pub certified_until: Option<f64>,
    /// Wall time of the fit and its certificate (a resumed run: of its certificate).
    pub fit_s: Option<f64>,
    /// Why an expression or table kernel runs exact although compression was asked for.
    pub fallback: Option<String>,
}

impl MemorySummary {
    fn new(plan: &crate::history::Plan, k: f64) -> Option<Self> {
        use crate::history::Plan;
        let (method, terms, fit, fallback) = match plan {
            Plan::None => return None,
            Plan::Prony(t) => ("prony", t.len(), None, None),
            Plan::Compressed(f) => ("compressed", f.terms.len(), Some(f), None),
            Plan::Exact { fallback, .. } => ("exact", 0, None, fallback.clone()),
        };
        Some(MemorySummary {
            method,
            terms,
            certified_error: fit.map(|f| f.error),
            certified_until: fit.map(|f| f.last_lag as f64 * k),
            fit_s: fit.map(|f| f.seconds),
            fallback,
        })
    }
}

/// `path` as summary.json keeps it: canonical (absolute, without `..`), so that `plot` finds
/// the run's scene and mesh from any working directory; as given when it cannot be resolved.
fn absolute(path: &std::path::Path) -> String {
    path.canonicalize()
        .or_else(|_| std::path::absolute(path))
        .unwrap_or_else(|_| path.to_path_buf())
        .display()
        .to_string()
}
