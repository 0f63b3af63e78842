//! The small parts of a checked scene: where the mesh is and how it is read, the time grid,
//! how each step is solved, what is written and when checkpoints are taken. Each is
//! converted from its TOML section and checked there.

use super::file::{
    ActiveSetSection, CheckpointSection, ContactSolver, Groups, History, LinearSolver, MeshSection,
    Model, OutputCompression, OutputFormat, OutputPrecision, OutputSection, SchemeSection, Seconds,
    SolverSection, TimeSection, DEFAULT_CHECKPOINT_SECONDS,
};
use super::physics::Physics;
use crate::{ranges, Error, Result};
use std::path::{Path, PathBuf};

/// `[mesh]`: the mesh file, the model and the groups that carry the boundary conditions.
#[derive(Debug)]
pub struct MeshChoice {
    /// `mesh.file`, resolved against the scene file's directory.
    pub file: PathBuf,
    pub model: Model,
    pub groups: Groups,
    /// `mesh.separate_parts`: coincident nodes that no cell shares are allowed.
    pub separate_parts: bool,
}

impl MeshChoice {
    /// `[mesh]` of a scene file read from `scene_path`.
    pub fn from_section(m: &MeshSection, scene_path: &Path) -> MeshChoice {
        MeshChoice {
            file: resolve(scene_path, Path::new(&m.file)),
            model: m.model,
            groups: m.groups.clone(),
            separate_parts: m.separate_parts,
        }
    }
}

/// A mesh file as a scene writes it: relative to the scene file's directory (or absolute).
pub(super) fn resolve(scene_path: &Path, file: &Path) -> PathBuf {
    scene_path.parent().unwrap_or(Path::new(".")).join(file)
}

/// `[time]`: the interval [0, T] cut into N steps of k = T/N.
#[derive(Clone, Copy, Debug)]
pub struct TimeGrid {
    /// T.
    pub end: f64,
    /// N.
    pub steps: usize,
}

impl TimeGrid {
    pub(super) fn from_section(t: &TimeSection, path: &Path) -> Result<TimeGrid> {
        TimeGrid::new(t.end, t.steps, path)
    }

    /// `time.end` and `time.steps` in their ranges, the step k = T/N too; `path` is the
    /// scene's, for messages.
    pub(super) fn new(end: f64, steps: usize, path: &Path) -> Result<TimeGrid> {
        let end = ranges::scaled_sign(end, "time.end", path, true)?;
        if !(1..=ranges::MAX_STEPS).contains(&steps) {
            return Err(ranges::refuse(path, "time.steps", steps, ""));
        }
        let k = end / steps as f64;
        if k < ranges::SCALE_MIN {
            let detail = format!(" with time.steps = {steps}: the step k = {k:e} is too small");
            return Err(ranges::refuse(path, "time.end", end, &detail));
        }
        Ok(TimeGrid { end, steps })
    }

    /// The time step k = T/N.
    pub fn k(&self) -> f64 {
        self.end / self.steps as f64
    }
}

/// `[solver]` and `[scheme]`: how each step of (3.1) is discretized and solved.
#[derive(Clone, Debug)]
pub struct SolverChoice {
    /// How a step with contact or friction is solved (`solver.contact`, as the scene
    /// gives it: `solver::choice::Descriptor` resolves `auto`).
    pub contact: ContactSolver,
    /// How the step matrix is solved (`solver.linear`, as the scene gives it).
    pub linear: LinearSolver,
    /// `[solver.petsc] options`, passed to PETSc where `linear = "petsc"` (empty by default).
    pub petsc_options: String,
    /// `[solver.active_set]`, each key checked against its range.
    pub active_set: ActiveSetSection,
    /// The treatment of the elastic and memory terms (`scheme.history`).
    pub history: History,
    /// Run the left endpoint scheme beyond its stability limit (`scheme.allow_unstable`).
    pub allow_unstable: bool,
}

impl SolverChoice {
    /// Whether the keys alone take PETSc's Krylov solves, whatever the mesh: `linear =
    /// "petsc"`, or `contact = "active_set"` (the two rules of `solver::choice::Descriptor`
    /// that read nothing of K_A). A rank of several then assembles only its own columns
    /// (`Ranks::discretize`).
    pub fn takes_petsc(&self) -> bool {
        self.linear == LinearSolver::Petsc || self.contact == ContactSolver::ActiveSet
    }

    /// The sections checked (`backend_refusal`): PETSc needs a build with the `petsc`
    /// feature, and the contact solvers other than `active_set` need the stored factor.
    /// The keys are kept as given; `solver::choice::Descriptor` resolves them on the
    /// discretization, once per run.
    pub(super) fn from_sections(
        solver: &SolverSection,
        scheme: &SchemeSection,
        physics: &Physics,
        path: &Path,
    ) -> Result<SolverChoice> {
        backend_refusal(solver, physics, path)?;
        active_set_ranges(&solver.active_set, path)?;
        Ok(SolverChoice {
            contact: solver.contact,
            linear: solver.linear,
            petsc_options: solver
                .petsc
                .as_ref()
                .map_or(String::new(), |p| p.options.clone()),
            active_set: solver.active_set,
            history: scheme.history,
            allow_unstable: scheme.allow_unstable,
        })
    }
}

/// Why the scene's backend and contact solver cannot run (exit 2): PETSc (`solver.linear =
/// "petsc"` or `solver.contact = "active_set"`) in a build without the `petsc` feature; the
/// active-set solver with the stored factor; a contact solver that needs the factor with
/// PETSc, where the scene has contact or friction.
fn backend_refusal(solver: &SolverSection, physics: &Physics, path: &Path) -> Result<()> {
    let at =
        |key: &str, value: &str| format!("{}: key 'solver.{key}' = \"{value}\"", path.display());
    let (linear, contact) = (solver.linear, solver.contact);
    let active_set = contact == ContactSolver::ActiveSet;
    let at_petsc = match active_set {
        true => at("contact", "active_set"),
        false => at("linear", "petsc"),
    };
    if (linear == LinearSolver::Petsc || active_set) && !cfg!(feature = "petsc") {
        return Err(Error::input(format!(
            "{at_petsc}: this viscontact was built without PETSc; build it with \
             `cargo build --release --features petsc` after installing PETSc's development \
             files (Debian 12: `apt-get install --no-install-recommends petsc-dev`), or set \
             {}",
            match active_set {
                true => "another solver.contact (\"auto\" picks the stored factor's)",
                false => "solver.linear = \"cholesky\"",
            }
        )));
    }
    if active_set && linear == LinearSolver::Cholesky {
        return Err(Error::input(format!(
            "{}: solver.contact = \"active_set\" solves its Newton systems by PETSc's Krylov \
             method, not with the stored factor; set solver.linear = \"petsc\" or \"auto\", \
             or another solver.contact",
            at("linear", "cholesky")
        )));
    }
    let needs_factor = !matches!(contact, ContactSolver::Auto | ContactSolver::ActiveSet);
    if linear == LinearSolver::Petsc
        && needs_factor
        && (physics.contact || physics.friction.is_some())
    {
        return Err(Error::input(format!(
            "{}: the {:?} contact solver works with the stored factor of K_A; with PETSc \
             the contact solver is the active-set one: set solver.contact = \"active_set\" \
             (or \"auto\"), or solver.linear = \"cholesky\"",
            at("linear", "petsc"),
            contact
        )));
    }
    Ok(())
}

/// The keys of `[solver.active_set]` against their rows of `ranges::RANGES`.
fn active_set_ranges(a: &ActiveSetSection, path: &Path) -> Result<()> {
    let relative = [
        ("tolerance", a.tolerance),
        ("forcing", a.forcing),
        ("krylov_tolerance", a.krylov_tolerance),
    ];
    for (key, value) in relative {
        if let Some(v) = value.filter(|v| !(1e-15..1.0).contains(v)) {
            return Err(ranges::refuse(
                path,
                &format!("solver.active_set.{key}"),
                v,
                "",
            ));
        }
    }
    match a.max_iterations {
        Some(n) if !(1..=10_000).contains(&n) => Err(ranges::refuse(
            path,
            "solver.active_set.max_iterations",
            n,
            "",
        )),
        _ => Ok(()),
    }
}

/// `[output]`: which frames are written, and how.
#[derive(Debug)]
pub struct OutputPlan {
    /// Write every this many steps (the last step is always written).
    pub every: usize,
    /// Format, compression, precision and fields.
    pub options: crate::output::Options,
}

impl OutputPlan {
    pub(super) fn from_section(o: &OutputSection, path: &Path) -> Result<OutputPlan> {
        if o.every == 0 {
            return Err(ranges::refuse(
                path,
                "output.every",
                0,
                " (write every n ≥ 1 steps)",
            ));
        }
        if let Some(unknown) = o
            .fields
            .iter()
            .flatten()
            .find(|n| !crate::output::FIELDS.contains(&n.as_str()))
        {
            return Err(Error::input(format!(
                "{}: key 'output.fields': '{unknown}' is not a field; the fields are {}",
                path.display(),
                crate::output::FIELDS.join(", ")
            )));
        }
        Ok(OutputPlan {
            every: o.every,
            options: crate::output::Options {
                format: match o.format {
                    OutputFormat::Vtu => crate::output::Format::Vtu,
                    OutputFormat::Vtkhdf => crate::output::Format::Vtkhdf,
                },
                compression: match o.compression {
                    OutputCompression::None => crate::output::Compression::None,
                    OutputCompression::Zlib => crate::output::Compression::Zlib,
                },
                precision: match o.precision {
                    OutputPrecision::Float64 => crate::output::Precision::Float64,
                    OutputPrecision::Float32 => crate::output::Precision::Float32,
                },
                fields: o.fields.clone(),
            },
        })
    }
}

/// `[checkpoint]`: when restart files are written.
#[derive(Clone, Copy, Debug)]
pub struct CheckpointPlan {
    /// Write checkpoints at all (`enabled`, default true: at least the final one).
    pub enabled: bool,
    /// Also write one every this many steps (`every`).
    pub every: Option<usize>,
    /// Also write one once this many seconds of wall time passed since the last
    /// (`every_seconds`, default [`DEFAULT_CHECKPOINT_SECONDS`]; None: not by time).
    pub every_seconds: Option<f64>,
}

impl CheckpointPlan {
    pub(super) fn from_section(c: Option<&CheckpointSection>, path: &Path) -> Result<Self> {
        if c.and_then(|c| c.every) == Some(0) {
            return Err(ranges::refuse(
                path,
                "checkpoint.every",
                0,
                " (leave 'every' out for only the final checkpoint, enabled = false for none)",
            ));
        }
        let every_seconds = match c.and_then(|c| c.every_seconds) {
            None | Some(Seconds::Switch(true)) => Some(DEFAULT_CHECKPOINT_SECONDS),
            Some(Seconds::Switch(false)) => None,
            Some(Seconds::Seconds(0.0)) => None,
            Some(Seconds::Seconds(s)) if s > 0.0 && s <= ranges::MAX_CHECKPOINT_SECONDS => Some(s),
            Some(Seconds::Seconds(s)) => {
                return Err(ranges::refuse(
                    path,
                    "checkpoint.every_seconds",
                    s,
                    " (the wall time between checkpoints in seconds)",
                ))
            }
        };
        Ok(CheckpointPlan {
            enabled: c.is_none_or(|c| c.enabled),
            every: c.and_then(|c| c.every),
            every_seconds,
        })
    }
}
