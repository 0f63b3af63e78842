//! The TOML schema of a scene file: `SceneFile` mirrors the TOML exactly (unknown keys are
//! errors, named by their dotted path); its sections are checked by `Scene::from_file`.

use serde::Deserialize;

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    pub name: Option<String>,
    pub mesh: MeshSection,
    pub time: TimeSection,
    pub material: MaterialSection,
    pub friction: Option<FrictionSection>,
    pub contact: Option<ContactSection>,
    #[serde(default)]
    pub load: LoadSection,
    #[serde(default)]
    pub output: OutputSection,
    #[serde(default)]
    pub solver: SolverSection,
    pub checkpoint: Option<CheckpointSection>,
    #[serde(default)]
    pub scheme: SchemeSection,
    /// `[[dirichlet]]`: prescribed components of the displacement on boundary groups.
    #[serde(default)]
    pub dirichlet: Vec<DirichletSection>,
}

/// One `[[dirichlet]]` entry: on the group `on`, the displacement components `components`
/// (any of "x", "y", "z", or "normal" alone on a flat group) equal `value` (one number or
/// expression of x, y, z, t per component; zero when absent).
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct DirichletSection {
    #[serde(deserialize_with = "group_ref")]
    pub on: String,
    pub components: ComponentNames,
    pub value: Option<Vec<NumOrExpr>>,
}

/// `components`: one name or a list (`components = "x"`, `components = ["x", "y"]`).
#[derive(Deserialize, Debug, Clone)]
#[serde(
    untagged,
    expecting = "a component (\"x\", \"y\", \"z\" or \"normal\") or a list of them"
)]
pub enum ComponentNames {
    One(String),
    Many(Vec<String>),
}

impl ComponentNames {
    pub fn to_vec(&self) -> Vec<String> {
        match self {
            ComponentNames::One(x) => vec![x.clone()],
            ComponentNames::Many(v) => v.clone(),
        }
    }
}

/// Which time discretization of the history terms.
#[derive(Deserialize, Debug, Default)]
#[serde(deny_unknown_fields)]
pub struct SchemeSection {
    #[serde(default)]
    pub history: History,
    /// Run the left endpoint scheme even when k exceeds its stability limit.
    #[serde(default)]
    pub allow_unstable: bool,
}

/// The treatment of the elastic and memory terms in each step.
#[derive(Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum History {
    /// The paper's scheme (3.1): B ε(u_n) and the left endpoint memory sum, both explicit.
    #[default]
    Left,
    /// B ε(u_n + k w_n) and the newest memory weight k² r(0) K_R implicit (see `time_loop`).
    Implicit,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct MeshSection {
    pub file: String,
    #[serde(default)]
    pub model: Model,
    #[serde(default)]
    pub groups: Groups,
    /// The mesh may hold separate bodies that touch (coincident nodes no cell shares);
    /// docs/meshes.md.
    #[serde(default)]
    pub separate_parts: bool,
}

/// The model: 2D (how the elasticity tensor B is reduced to the plane) or 3D.
#[derive(Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum Model {
    /// B as printed in (4.2) of the paper.
    #[default]
    PlaneStress,
    /// B with the 3D Lamé coefficient λ = Eν/((1+ν)(1−2ν)).
    PlaneStrain,
    /// Tetrahedral meshes; A and B in their 3D isotropic forms: Aτ = 2θτ + ζ tr(τ) I (4.1)
    /// and Bτ = E/(1+ν) τ + λ tr(τ) I with the 3D Lamé λ = Eν/((1+ν)(1−2ν)).
    #[serde(rename = "3d")]
    ThreeD,
}

impl Model {
    /// The model as a scene writes it (`mesh.model`).
    pub fn name(self) -> &'static str {
        match self {
            Model::PlaneStress => "plane_stress",
            Model::PlaneStrain => "plane_strain",
            Model::ThreeD => "3d",
        }
    }

    /// The spatial dimension of the model.
    pub fn dim(self) -> usize {
        match self {
            Model::ThreeD => 3,
            _ => 2,
        }
    }
}

/// Which physical groups carry which boundary condition: each by its name or its integer
/// tag, written as a TOML string or integer (`fixed = "Γ1"`, `fixed = 5`, `fixed = "5"`).
/// `fixed` also takes a list of groups, or `[]` (no clamped group: `[[dirichlet]]` entries
/// must then remove the rigid motions).
#[derive(Deserialize, Debug, Clone)]
#[serde(deny_unknown_fields, default)]
pub struct Groups {
    #[serde(deserialize_with = "group_refs")]
    pub fixed: Vec<String>,
    #[serde(deserialize_with = "group_ref")]
    pub traction: String,
    #[serde(deserialize_with = "group_ref")]
    pub contact: String,
    #[serde(deserialize_with = "group_ref")]
    pub friction: String,
}

/// A physical group's name, or its tag given as a TOML integer (kept as its decimal text:
/// the mesh resolves names and tags alike).
#[derive(Deserialize)]
#[serde(
    untagged,
    expecting = "a physical group's name (a string) or tag (an integer)"
)]
enum GroupRef {
    Name(String),
    Tag(i64),
}

impl GroupRef {
    fn text(self) -> String {
        match self {
            GroupRef::Name(s) => s,
            GroupRef::Tag(t) => t.to_string(),
        }
    }
}

fn group_ref<'de, D: serde::Deserializer<'de>>(d: D) -> std::result::Result<String, D::Error> {
    Ok(GroupRef::deserialize(d)?.text())
}

/// One group or a list of groups (names or tags).
fn group_refs<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> std::result::Result<Vec<String>, D::Error> {
    #[derive(Deserialize)]
    #[serde(
        untagged,
        expecting = "a physical group's name (a string) or tag (an integer), or a list of them ([] for none)"
    )]
    enum Refs {
        One(GroupRef),
        Many(Vec<GroupRef>),
    }
    Ok(match Refs::deserialize(d)? {
        Refs::One(r) => vec![r.text()],
        Refs::Many(v) => v.into_iter().map(GroupRef::text).collect(),
    })
}

fn opt_group_ref<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> std::result::Result<Option<String>, D::Error> {
    group_ref(d).map(Some)
}

impl Default for Groups {
    fn default() -> Self {
        Groups {
            fixed: vec!["Γ1".into()],
            traction: "Γ2".into(),
            contact: "Γ3,1".into(),
            friction: "Γ3,2".into(),
        }
    }
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct TimeSection {
    pub end: f64,
    pub steps: usize,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct MaterialSection {
    pub viscosity: ViscositySection,
    pub elasticity: Option<ElasticitySection>,
    pub relaxation: Option<RelaxationSection>,
    /// `[[material.region]]`: parts of the body with a material of their own.
    #[serde(default)]
    pub region: Vec<RegionSection>,
}

/// One `[[material.region]]` entry: the cells of the physical group `on` (of the body's
/// dimension) take the tables given here in place of `[material]`'s, checked as those are.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct RegionSection {
    #[serde(deserialize_with = "group_ref")]
    pub on: String,
    pub viscosity: Option<ViscositySection>,
    pub elasticity: Option<ElasticitySection>,
    /// A kernel of the region's own, in place of `[material.relaxation]` on its cells.
    pub relaxation: Option<RelaxationSection>,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct ViscositySection {
    pub theta: f64,
    #[serde(default)]
    pub zeta: f64,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct ElasticitySection {
    #[serde(default = "yes")]
    pub enabled: bool,
    pub young: f64,
    #[serde(default)]
    pub poisson: f64,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct RelaxationSection {
    #[serde(default = "yes")]
    pub enabled: bool,
    pub prony: Option<Vec<[f64; 2]>>,
    pub expr: Option<String>,
    pub table: Option<TableSection>,
    /// "compressed" (default) or "exact"; for `expr` and `table` only.
    pub memory: Option<MemoryMode>,
    /// Certified max relative error of the compressed kernel on the lags (default 1e-12,
    /// `kernel_fit::DEFAULT_TOLERANCE`).
    pub tolerance: Option<f64>,
    /// The latest end time the compressed kernel's fit covers (default time.end): a run
    /// resumed with a later `time.end` keeps its fit, so it must already hold there.
    pub horizon: Option<f64>,
}

/// How the memory sum of an expression or table kernel is computed.
#[derive(Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum MemoryMode {
    /// A certified sum-of-exponentials fit run by the O(1) Prony recursion (`kernel_fit`).
    Compressed,
    /// The direct O(n) sum over every past displacement (the reference).
    Exact,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct TableSection {
    pub s: Vec<f64>,
    pub r: Vec<f64>,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct FrictionSection {
    #[serde(default = "yes")]
    pub enabled: bool,
    /// F ≥ 0, the given normal stress on Γ3,2: a number or an expression of x, y, z.
    pub normal_stress: NumOrExpr,
    /// μ ≥ 0: a number or an expression of x, y, z.
    pub coefficient: NumOrExpr,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct ContactSection {
    #[serde(default = "yes")]
    pub enabled: bool,
}

#[derive(Deserialize, Debug, Default)]
#[serde(deny_unknown_fields)]
pub struct LoadSection {
    #[serde(default)]
    pub traction: Vec<VectorLoad>,
    #[serde(default)]
    pub body: Vec<VectorLoad>,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct VectorLoad {
    /// For a traction: the physical group it acts on (inside the traction group Γ2); the
    /// whole traction group when absent. Not allowed for a body force.
    #[serde(default, deserialize_with = "opt_group_ref")]
    pub on: Option<String>,
    pub value: Vec<NumOrExpr>,
}

#[derive(Deserialize, Debug, Clone)]
#[serde(untagged, expecting = "a number or an expression (a string)")]
pub enum NumOrExpr {
    Num(f64),
    Expr(String),
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct OutputSection {
    /// Write every this many steps (the last step is always written).
    #[serde(default = "one")]
    pub every: usize,
    /// "vtu" (default: a .vtu file per frame + solution.pvd) or "vtkhdf" (one file).
    #[serde(default)]
    pub format: OutputFormat,
    /// "zlib" (default) or "none" (raw appended data).
    #[serde(default)]
    pub compression: OutputCompression,
    /// "float64" (default) or "float32" for the field values.
    #[serde(default)]
    pub precision: OutputPrecision,
    /// The fields to write (crate::output::FIELDS); all when left out.
    pub fields: Option<Vec<String>>,
}

impl Default for OutputSection {
    fn default() -> Self {
        OutputSection {
            every: 1,
            format: OutputFormat::default(),
            compression: OutputCompression::default(),
            precision: OutputPrecision::default(),
            fields: None,
        }
    }
}

/// `output.format`.
#[derive(Deserialize, Debug, Clone, Copy, Default)]
#[serde(rename_all = "lowercase")]
pub enum OutputFormat {
    #[default]
    Vtu,
    Vtkhdf,
}

/// `output.compression`.
#[derive(Deserialize, Debug, Clone, Copy, Default)]
#[serde(rename_all = "lowercase")]
pub enum OutputCompression {
    None,
    #[default]
    Zlib,
}

/// `output.precision`.
#[derive(Deserialize, Debug, Clone, Copy, Default)]
#[serde(rename_all = "lowercase")]
pub enum OutputPrecision {
    #[default]
    Float64,
    Float32,
}

/// `[checkpoint]`: restart files (src/checkpoint.rs). Without the section a run still writes
/// the final checkpoint; `enabled = false` writes none.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct CheckpointSection {
    #[serde(default = "yes")]
    pub enabled: bool,
    /// Also write a checkpoint every this many steps (steps ≥ 1).
    pub every: Option<usize>,
    /// Also write one once this many seconds of wall time passed since the last (default
    /// [`DEFAULT_CHECKPOINT_SECONDS`]; 0 or false: not by time; true: the default).
    pub every_seconds: Option<Seconds>,
}

/// `[checkpoint] every_seconds`: a number of seconds, or true / false.
#[derive(Deserialize, Debug, Clone, Copy)]
#[serde(untagged, expecting = "a number of seconds, or true or false")]
pub enum Seconds {
    Switch(bool),
    Seconds(f64),
}

/// Wall time between two checkpoints by default: a kill -9 or a power cut loses at most
/// this much work (plus the step in progress).
pub const DEFAULT_CHECKPOINT_SECONDS: f64 = 600.0;

#[derive(Deserialize, Debug, Default)]
#[serde(deny_unknown_fields)]
pub struct SolverSection {
    #[serde(default)]
    pub contact: ContactSolver,
    #[serde(default)]
    pub linear: LinearSolver,
    /// `[solver.petsc]`: read where `linear = "petsc"`.
    pub petsc: Option<PetscSection>,
    /// `[solver.active_set]`: read where the contact solver is the active-set one.
    #[serde(default)]
    pub active_set: ActiveSetSection,
}

/// `[solver.active_set]`: the active-set solver's stopping test and Newton systems; a key
/// left out takes the solver's default (`solver::active_set::ActiveSetSettings`), checked
/// against its range (`ranges`) where the scene is read.
#[derive(Deserialize, Debug, Default, Clone, Copy, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ActiveSetSection {
    /// The KKT residual at which a step is solved.
    pub tolerance: Option<f64>,
    /// Newton iterations before a step fails.
    pub max_iterations: Option<usize>,
    /// The reduction of its starting residual each Newton system before the last solves for.
    pub forcing: Option<f64>,
    /// The Krylov tolerance of a step's last system, relative to its right side.
    pub krylov_tolerance: Option<f64>,
}

/// How the step matrix K_A is solved (the linear backend).
#[derive(Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum LinearSolver {
    /// The stored Cholesky factor, or PETSc where `contact = "active_set"`.
    #[default]
    Auto,
    /// K_A factored once (sparse Cholesky), one solve with the factor per step.
    Cholesky,
    /// PETSc's Krylov method with algebraic multigrid (CG + GAMG); builds with the cargo
    /// feature `petsc` only. With contact or friction the contact solver is the active-set
    /// one (`contact = "auto"` or `"active_set"`).
    Petsc,
}

/// `[solver.petsc]`: what a run with `linear = "petsc"` passes to PETSc.
#[derive(Deserialize, Debug, Default, Clone)]
#[serde(deny_unknown_fields)]
pub struct PetscSection {
    /// Options for PETSc's options database, in its command-line syntax
    /// ("-ksp_monitor -pc_type hypre"), inserted after `PETSC_OPTIONS`.
    #[serde(default)]
    pub options: String,
}

/// How a step with contact or friction is solved (`solver::choice`).
#[derive(Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum ContactSolver {
    /// The dense dual while its m × m matrices take at most `solver::choice::DENSE_LIMIT`,
    /// else the sparse dual (the default).
    #[default]
    Auto,
    /// Condensed onto the constrained boundary dofs, the dense dual active set method
    /// (`"fast"` is its old name).
    #[serde(alias = "fast")]
    Dense,
    /// The same dual with D applied through the factor of K_A (its trailing block L_CC): no
    /// m × m matrix of the dual, but the factor holds the dense L_CC.
    MatrixFree,
    /// The same dual with D applied through solves with the factor of a linear run:
    /// nothing dense.
    Sparse,
    /// The whole per-step problem handed to clarabel (the cross-check).
    Clarabel,
    /// The primal active-set (semismooth Newton) method, its Newton systems solved by
    /// PETSc's Krylov method with algebraic multigrid: no factor of K_A (cargo feature
    /// `petsc`).
    ActiveSet,
}

fn yes() -> bool {
    true
}

fn one() -> usize {
    1
}
