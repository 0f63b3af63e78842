//! The scene file (TOML, DESIGN.md "Scene file"): what the user asks for. Reading it is
//! two steps: `SceneFile` mirrors the TOML exactly (unknown keys are errors, named by their
//! dotted path), then `Scene::from_file` checks every value and compiles the expressions.
//! `--set KEY=VALUE` overrides are applied to the TOML tree before either step, so an
//! override is checked exactly like a key written in the file.

use crate::expr::{Expr, Scalar};
use crate::{ranges, Error, Result};
use serde::Deserialize;
use std::path::{Path, PathBuf};

// ---------------------------------------------------------------------------------------
// The TOML schema
// ---------------------------------------------------------------------------------------

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
#[derive(Deserialize, Debug, Clone)]
#[serde(deny_unknown_fields, default)]
pub struct Groups {
    #[serde(deserialize_with = "group_ref")]
    pub fixed: String,
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

fn group_ref<'de, D: serde::Deserializer<'de>>(d: D) -> std::result::Result<String, D::Error> {
    Ok(match GroupRef::deserialize(d)? {
        GroupRef::Name(s) => s,
        GroupRef::Tag(t) => t.to_string(),
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
            fixed: "Γ1".into(),
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
    /// Certified max relative error of the compressed kernel on the lags (default 1e-10).
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
}

/// How a step with contact or friction is solved.
#[derive(Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum ContactSolver {
    /// Condensed onto the constrained boundary dofs, primal-dual active set (the default).
    #[default]
    Fast,
    /// The whole per-step problem handed to clarabel (the cross-check).
    Clarabel,
}

fn yes() -> bool {
    true
}

fn one() -> usize {
    1
}

// ---------------------------------------------------------------------------------------
// Reading and overriding
// ---------------------------------------------------------------------------------------

/// Applies one `--set KEY=VALUE` to a TOML tree. The value is read as a TOML value when it
/// parses as one (`64`, `false`, `[[1.0, 10.0]]`, `"x"`) and as a string otherwise.
pub fn apply_override(root: &mut toml::Table, assignment: &str) -> Result<()> {
    let (key, raw) = assignment.split_once('=').ok_or_else(|| {
        Error::input(format!(
            "--set {assignment:?}: expected KEY=VALUE, e.g. --set time.steps=64"
        ))
    })?;
    let key = key.trim();
    let value = parse_value(raw.trim());
    let parts: Vec<&str> = key.split('.').collect();
    if parts.iter().any(|p| p.is_empty()) {
        return Err(Error::input(format!(
            "--set {assignment:?}: '{key}' is not a dotted key path"
        )));
    }
    let mut table = root;
    for part in &parts[..parts.len() - 1] {
        let entry = table
            .entry(part.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        table = match entry {
            toml::Value::Table(t) => t,
            _ => {
                return Err(Error::input(format!(
                    "--set {assignment:?}: '{part}' is a value, not a table"
                )))
            }
        };
    }
    table.insert(parts[parts.len() - 1].to_string(), value);
    Ok(())
}

/// serde's messages in the scene's terms: no Rust type names, no repeated key line.
fn plain_serde_message(msg: &str) -> String {
    let mut out = msg
        .lines()
        .filter(|l| !l.trim_start().starts_with("in `") && !l.trim().is_empty())
        .collect::<Vec<_>>()
        .join(" ")
        .replace("expected usize", "expected a whole number ≥ 0")
        .replace("expected f64", "expected a number")
        .replace("expected a boolean", "expected true or false");
    while let Some(p) = out.find("expected struct ") {
        let end = out[p + 16..]
            .find(|c: char| !c.is_alphanumeric())
            .map_or(out.len(), |e| p + 16 + e);
        out.replace_range(p..end, "expected a table");
    }
    out
}

fn parse_value(raw: &str) -> toml::Value {
    // Parse as the right-hand side of `v = …`; anything that is not valid TOML is a string.
    match format!("v = {raw}").parse::<toml::Table>() {
        Ok(mut t) => t
            .remove("v")
            .unwrap_or_else(|| toml::Value::String(raw.into())),
        Err(_) => toml::Value::String(raw.to_string()),
    }
}

/// Reads a scene file and applies the overrides; returns the TOML text after overrides (the
/// exact scene that ran) and the schema-checked tree.
pub fn read_scene_file(path: &Path, overrides: &[String]) -> Result<(String, SceneFile)> {
    let bytes = read_input_file(path, "scene file", Some(SCENE_MAX_BYTES))?;
    let text = String::from_utf8(bytes).map_err(|e| {
        Error::input(format!(
            "scene file '{}' is not UTF-8 text (invalid byte at offset {}); save it as UTF-8",
            path.display(),
            e.utf8_error().valid_up_to()
        ))
    })?;
    parse_scene_text(path, text, overrides)
}

/// A scene is a few kilobytes; a larger file is not one.
const SCENE_MAX_BYTES: u64 = 16 << 20;

/// Reads an input file (a scene, a mesh) whole. It must be a regular file — a device such as
/// /dev/zero would be read until memory runs out, a FIFO could block forever — and is read up
/// to the size its metadata declares (and at most `max` bytes). `what` names the file in
/// messages.
pub(crate) fn read_input_file(path: &Path, what: &str, max: Option<u64>) -> Result<Vec<u8>> {
    use std::io::Read;
    let fail =
        |why: String| Error::input(format!("cannot read {what} '{}': {why}", path.display()));
    let plain = |e: std::io::Error| {
        let mut m = e.to_string();
        if let Some(p) = m.find(" (os error") {
            m.truncate(p);
        }
        m
    };
    let meta = std::fs::metadata(path).map_err(|e| fail(plain(e)))?;
    if !meta.is_file() {
        let kind = if meta.is_dir() {
            "a directory"
        } else {
            "a device, FIFO or socket"
        };
        return Err(fail(format!("it is {kind}, not a regular file")));
    }
    let len = meta.len();
    if let Some(max) = max.filter(|&m| len > m) {
        return Err(fail(format!(
            "it has {len} bytes, more than a {what} can have ({max})"
        )));
    }
    let file = std::fs::File::open(path).map_err(|e| fail(plain(e)))?;
    let mut bytes = Vec::with_capacity(len as usize);
    file.take(len)
        .read_to_end(&mut bytes)
        .map_err(|e| fail(plain(e)))?;
    Ok(bytes)
}

/// At most this many characters of a scene's text are quoted in a message.
const EXCERPT: usize = 80;

/// `text` cut to `EXCERPT` characters around byte `at` (a 2 MB line is not echoed whole).
fn excerpt(text: &str, at: usize) -> String {
    let at = at.min(text.len());
    let start = text[..at].rfind('\n').map_or(0, |p| p + 1);
    let end = text[at..].find('\n').map_or(text.len(), |p| at + p);
    let line = &text[start..end];
    let col = text[start..at].chars().count();
    let chars: Vec<char> = line.chars().collect();
    let from = col.saturating_sub(EXCERPT / 2).min(chars.len());
    let to = (from + EXCERPT).min(chars.len());
    format!(
        "{}{}{}",
        if from > 0 { "…" } else { "" },
        chars[from..to].iter().collect::<String>(),
        if to < chars.len() { "…" } else { "" }
    )
}

/// A message cut to a few hundred characters (a huge value quoted by serde, say).
fn shorten(msg: String) -> String {
    const MAX: usize = 300;
    match msg.char_indices().nth(MAX) {
        Some((cut, _)) => format!("{}…", &msg[..cut]),
        None => msg,
    }
}

/// [`read_scene_file`] for a scene text in hand (a checkpoint's): `path` is where the text
/// came from (errors name it; `mesh.file` is relative to its directory).
pub fn parse_scene_text(
    path: &Path,
    text: String,
    overrides: &[String],
) -> Result<(String, SceneFile)> {
    let mut root: toml::Table = text.parse().map_err(|e: toml::de::Error| {
        let at = e.span().map_or(0, |s| s.start);
        let line = text[..at.min(text.len())].matches('\n').count() + 1;
        Error::input(format!(
            "{}: not valid TOML at line {line}: {} (near {:?})",
            path.display(),
            shorten(e.message().trim().to_string()),
            excerpt(&text, at)
        ))
    })?;
    for o in overrides {
        apply_override(&mut root, o)?;
    }
    let effective = if overrides.is_empty() {
        text
    } else {
        toml::to_string(&root).map_err(|e| Error::input(format!("{}: {e}", path.display())))?
    };
    let file: SceneFile =
        serde_path_to_error::deserialize(toml::Value::Table(root)).map_err(|e| {
            let at = e.path().to_string();
            // Say where the key came from: a --set override or the file.
            let from_set = overrides.iter().any(|o| {
                let key = o.split('=').next().unwrap_or("").trim();
                at == key
                    || at.starts_with(&format!("{key}."))
                    || key.starts_with(&format!("{at}."))
            });
            let place = if from_set {
                format!("--set (scene {})", path.display())
            } else {
                path.display().to_string()
            };
            Error::input(format!(
                "{place}: {}{}",
                if at == "." {
                    String::new()
                } else {
                    format!("key '{at}': ")
                },
                shorten(plain_serde_message(&e.into_inner().to_string()))
            ))
        })?;
    Ok((effective, file))
}

// ---------------------------------------------------------------------------------------
// The checked scene
// ---------------------------------------------------------------------------------------

/// The relaxation function r(s) of R(s) = r(s)·I.
#[derive(Debug)]
pub enum Kernel {
    /// Σ a_i exp(−b_i s): pairs (a_i, b_i); memory by the exact O(1) recursion.
    Prony(Vec<(f64, f64)>),
    /// An expression of s; memory by the direct O(n) sum.
    Expr(Box<Expr>),
    /// Piecewise linear through (s_i, r_i), constant beyond the ends; direct sum.
    Table(Vec<f64>, Vec<f64>),
}

impl Kernel {
    /// r(s).
    pub fn eval(&self, s: f64) -> f64 {
        match self {
            Kernel::Prony(terms) => terms.iter().map(|(a, b)| a * (-b * s).exp()).sum(),
            Kernel::Expr(e) => e.eval(&crate::expr::Point {
                s,
                ..Default::default()
            }),
            Kernel::Table(ss, rs) => {
                let i = ss.partition_point(|&x| x <= s);
                if i == 0 {
                    rs[0]
                } else if i == ss.len() {
                    rs[rs.len() - 1]
                } else {
                    let w = (s - ss[i - 1]) / (ss[i] - ss[i - 1]);
                    rs[i - 1] + w * (rs[i] - rs[i - 1])
                }
            }
        }
    }
}

#[derive(Debug)]
pub struct Traction {
    /// Physical group key (resolved against the mesh later).
    pub on: String,
    pub value: Vec<Scalar>,
}

#[derive(Debug)]
pub struct Friction {
    pub normal_stress: Scalar,
    pub coefficient: Scalar,
}

/// A checked scene: every number in range, every expression compiled, paths resolved.
#[derive(Debug)]
pub struct Scene {
    pub name: String,
    /// The path the scene was read from.
    pub path: PathBuf,
    /// The TOML text that ran (after `--set` overrides).
    pub text: String,
    pub mesh_file: PathBuf,
    pub model: Model,
    pub groups: Groups,
    /// `mesh.separate_parts`: coincident nodes that no cell shares are allowed.
    pub separate_parts: bool,
    pub end: f64,
    pub steps: usize,
    /// θ, ζ of (4.1).
    pub theta: f64,
    pub zeta: f64,
    /// E, ν of (4.2); None when the elasticity term is disabled.
    pub elasticity: Option<(f64, f64)>,
    pub relaxation: Option<Kernel>,
    /// For an expression or table kernel: compressed with this tolerance, or exact (None).
    /// Always None for a Prony series (already O(1)).
    pub compression: Option<f64>,
    /// `material.relaxation.horizon`: the fit of a compressed kernel covers the lags up to
    /// max(time.end, horizon).
    pub horizon: Option<f64>,
    pub contact: bool,
    pub friction: Option<Friction>,
    pub tractions: Vec<Traction>,
    pub body_forces: Vec<Vec<Scalar>>,
    pub output_every: usize,
    /// `[output]` compression, precision and fields.
    pub output: crate::output::Options,
    pub contact_solver: ContactSolver,
    pub history: History,
    pub allow_unstable: bool,
    /// Write checkpoints at all (`[checkpoint] enabled`, default true: at least the final one).
    pub checkpoint: bool,
    /// Also write one every this many steps (`[checkpoint] every`).
    pub checkpoint_every: Option<usize>,
    /// Also write one once this many seconds of wall time passed since the last
    /// (`[checkpoint] every_seconds`, default 600; None: not by time).
    pub checkpoint_every_seconds: Option<f64>,
}

/// `time.end` and `time.steps` in their ranges, the step k = T/N too.
fn time_range(t: &TimeSection, path: &Path) -> Result<(f64, usize)> {
    let end = ranges::scaled_sign(t.end, "time.end", path, true)?;
    if !(1..=ranges::MAX_STEPS).contains(&t.steps) {
        return Err(ranges::refuse(path, "time.steps", t.steps, ""));
    }
    let k = end / t.steps as f64;
    if k < ranges::SCALE_MIN {
        let detail = format!(
            " with time.steps = {}: the step k = {k:e} is too small",
            t.steps
        );
        return Err(ranges::refuse(path, "time.end", end, &detail));
    }
    Ok((end, t.steps))
}

fn scalar(v: &NumOrExpr, allowed: &[&str], key: &str, file: &Path) -> Result<Scalar> {
    match v {
        NumOrExpr::Num(x) => Ok(Scalar::Const(ranges::scaled(*x, key, file)?)),
        NumOrExpr::Expr(s) => {
            // A plain number written as a string is a constant too.
            if let Ok(x) = s.trim().parse::<f64>() {
                return Ok(Scalar::Const(ranges::scaled(x, key, file)?));
            }
            Expr::parse(s, allowed, &format!("{}: key '{key}'", file.display()))
                .map(|e| Scalar::Expr(Box::new(e)))
        }
    }
}

/// The variables of loads (space and time) and of F, μ (space): a 2D model has no z.
fn variables(model: Model, time: bool) -> &'static [&'static str] {
    match (model.dim(), time) {
        (2, true) => &["x", "y", "t"],
        (2, false) => &["x", "y"],
        (_, true) => &["x", "y", "z", "t"],
        (_, false) => &["x", "y", "z"],
    }
}

impl Scene {
    /// Reads, overrides and checks a scene file.
    pub fn load(path: &Path, overrides: &[String]) -> Result<Scene> {
        let (text, file) = read_scene_file(path, overrides)?;
        Scene::from_file(path, text, file)
    }

    pub fn from_file(path: &Path, text: String, f: SceneFile) -> Result<Scene> {
        let bad = |key: &str, why: &str| {
            Err(Error::input(format!(
                "{}: key '{key}': {why}",
                path.display()
            )))
        };
        let (end, steps) = time_range(&f.time, path)?;
        let theta = ranges::scaled_sign(
            f.material.viscosity.theta,
            "material.viscosity.theta",
            path,
            true,
        )?;
        let zeta = ranges::scaled_sign(
            f.material.viscosity.zeta,
            "material.viscosity.zeta",
            path,
            false,
        )?;
        if zeta > ranges::MAX_BULK_RATIO * theta {
            let detail = format!(", {:e} times θ = {theta:?}", zeta / theta);
            return Err(ranges::refuse(
                path,
                "material.viscosity.zeta",
                zeta,
                &detail,
            ));
        }
        let model = f.mesh.model;
        let elasticity = match &f.material.elasticity {
            Some(e) if e.enabled => {
                let young = ranges::scaled_sign(e.young, "material.elasticity.young", path, false)?;
                let nu = ranges::scaled(e.poisson, "material.elasticity.poisson", path)?;
                let ok = match model {
                    Model::PlaneStress => nu > -1.0 && nu <= 0.5,
                    Model::PlaneStrain | Model::ThreeD => nu > -1.0 && nu < 0.5,
                };
                if !ok {
                    let range = match model {
                        Model::PlaneStress => "−1 < ν ≤ 0.5",
                        Model::PlaneStrain => "−1 < ν < 0.5 (plane strain)",
                        Model::ThreeD => "−1 < ν < 0.5 (3D)",
                    };
                    return bad(
                        "material.elasticity.poisson",
                        &format!("is {nu}; the Poisson ratio must satisfy {range}"),
                    );
                }
                Some((young, nu))
            }
            _ => None,
        };
        let relaxation = match &f.material.relaxation {
            Some(r) if r.enabled => Some(kernel(r, path)?),
            _ => None,
        };
        let compression = match (&relaxation, &f.material.relaxation) {
            (Some(Kernel::Prony(_)), Some(r))
                if r.memory.is_some() || r.tolerance.is_some() || r.horizon.is_some() =>
            {
                return bad(
                    "material.relaxation.memory",
                    "a Prony series already runs by the exact O(1) recursion; 'memory', \
                     'tolerance' and 'horizon' apply to 'expr' and 'table' kernels only: remove \
                     them",
                )
            }
            (Some(Kernel::Expr(_) | Kernel::Table(..)), Some(r)) => {
                let key = "material.relaxation.tolerance";
                let tolerance = ranges::scaled_sign(r.tolerance.unwrap_or(1e-10), key, path, true)?;
                if tolerance >= 1.0 {
                    return Err(ranges::refuse(path, key, tolerance, ""));
                }
                match r.memory.unwrap_or(MemoryMode::Compressed) {
                    MemoryMode::Compressed => Some(tolerance),
                    MemoryMode::Exact => None,
                }
            }
            _ => None,
        };
        let horizon = match f.material.relaxation.as_ref().and_then(|r| r.horizon) {
            Some(h) if compression.is_none() => {
                return bad(
                    "material.relaxation.horizon",
                    &format!(
                        "is {h}, but only a compressed kernel (an 'expr' or 'table' with memory \
                         = \"compressed\") is fitted: remove it"
                    ),
                )
            }
            Some(h) if !(ranges::in_scale(h) && h > 0.0 && h <= 1e6 * end) => {
                return Err(ranges::refuse(
                    path,
                    "material.relaxation.horizon",
                    h,
                    &format!(
                        " (the latest time.end a resume may set; here time.end = {end:?}, so at \
                         most {:e})",
                        1e6 * end
                    ),
                ))
            }
            h => h,
        };
        if compression.is_some() {
            // The fit's lags, max(N, horizon/k), bounded (kernel_fit::MAX_LAGS).
            let steps = f.time.steps as f64;
            let lags = horizon.map_or(steps, |h| (h * steps / end).ceil().max(steps));
            if lags > crate::kernel_fit::MAX_LAGS as f64 {
                let max = crate::kernel_fit::MAX_LAGS as f64;
                let (key, fix) = match horizon {
                    Some(h) if lags > steps => (
                        "material.relaxation.horizon",
                        format!("is {h}: lower it to at most {:e}", max * end / steps),
                    ),
                    _ => (
                        "time.steps",
                        format!(
                            "is {}: lower it, or set material.relaxation.memory = \"exact\"",
                            f.time.steps
                        ),
                    ),
                };
                return bad(
                    key,
                    &format!(
                        "{fix} (the compressed kernel would be fitted and certified on \
                         {lags:.3e} lags, max(time.steps, horizon/k) with k = \
                         time.end/time.steps, more than the {max:e} the fit may take: 16 bytes \
                         and O(terms) work per lag)"
                    ),
                );
            }
        }
        let friction = match &f.friction {
            Some(fr) if fr.enabled => {
                let space = variables(model, false);
                let normal_stress =
                    scalar(&fr.normal_stress, space, "friction.normal_stress", path)?;
                let coefficient = scalar(&fr.coefficient, space, "friction.coefficient", path)?;
                for (value, key) in [
                    (&normal_stress, "friction.normal_stress"),
                    (&coefficient, "friction.coefficient"),
                ] {
                    if let Scalar::Const(v) = value {
                        ranges::scaled_sign(*v, key, path, false)?;
                    }
                }
                Some(Friction {
                    normal_stress,
                    coefficient,
                })
            }
            _ => None,
        };
        let components = model.dim();
        let vector = |v: &[NumOrExpr], key: &str| -> Result<Vec<Scalar>> {
            if v.len() != components {
                let example = match components {
                    2 => "a 2D model needs 2 (x and y), e.g. [\"0\", \"-0.1*x\"]",
                    _ => "the 3D model needs 3 (x, y and z), e.g. [\"0\", \"0\", \"-0.1*x\"]",
                };
                return Err(Error::input(format!(
                    "{}: key '{key}': has {} components; {example}",
                    path.display(),
                    v.len()
                )));
            }
            v.iter()
                .enumerate()
                .map(|(i, c)| scalar(c, variables(model, true), &format!("{key}[{i}]"), path))
                .collect()
        };
        let mut tractions = Vec::new();
        for (i, t) in f.load.traction.iter().enumerate() {
            let key = format!("load.traction[{i}].value");
            tractions.push(Traction {
                on: t
                    .on
                    .clone()
                    .unwrap_or_else(|| f.mesh.groups.traction.clone()),
                value: vector(&t.value, &key)?,
            });
        }
        let mut body_forces = Vec::new();
        for (i, b) in f.load.body.iter().enumerate() {
            if b.on.is_some() {
                return bad(
                    &format!("load.body[{i}].on"),
                    "a body force acts on the whole domain; remove 'on'",
                );
            }
            body_forces.push(vector(&b.value, &format!("load.body[{i}].value"))?);
        }
        if f.output.every == 0 {
            return Err(ranges::refuse(
                path,
                "output.every",
                0,
                " (write every n ≥ 1 steps)",
            ));
        }
        if let Some(unknown) = f
            .output
            .fields
            .iter()
            .flatten()
            .find(|n| !crate::output::FIELDS.contains(&n.as_str()))
        {
            return bad(
                "output.fields",
                &format!(
                    "'{unknown}' is not a field; the fields are {}",
                    crate::output::FIELDS.join(", ")
                ),
            );
        }
        if f.checkpoint.as_ref().and_then(|c| c.every) == Some(0) {
            return Err(ranges::refuse(
                path,
                "checkpoint.every",
                0,
                " (leave 'every' out for only the final checkpoint, enabled = false for none)",
            ));
        }
        let checkpoint_every_seconds = match f.checkpoint.as_ref().and_then(|c| c.every_seconds) {
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
        let dir = path.parent().unwrap_or(Path::new("."));
        let name = f.name.clone().unwrap_or_else(|| {
            path.file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "scene".into())
        });
        Ok(Scene {
            name,
            path: path.to_path_buf(),
            text,
            mesh_file: dir.join(&f.mesh.file),
            model,
            groups: f.mesh.groups.clone(),
            separate_parts: f.mesh.separate_parts,
            end,
            steps,
            theta,
            zeta,
            elasticity,
            relaxation,
            compression,
            horizon,
            contact: f.contact.as_ref().is_some_and(|c| c.enabled),
            friction,
            tractions,
            body_forces,
            output_every: f.output.every,
            output: crate::output::Options {
                format: match f.output.format {
                    OutputFormat::Vtu => crate::output::Format::Vtu,
                    OutputFormat::Vtkhdf => crate::output::Format::Vtkhdf,
                },
                compression: match f.output.compression {
                    OutputCompression::None => crate::output::Compression::None,
                    OutputCompression::Zlib => crate::output::Compression::Zlib,
                },
                precision: match f.output.precision {
                    OutputPrecision::Float64 => crate::output::Precision::Float64,
                    OutputPrecision::Float32 => crate::output::Precision::Float32,
                },
                fields: f.output.fields.clone(),
            },
            contact_solver: f.solver.contact,
            history: f.scheme.history,
            allow_unstable: f.scheme.allow_unstable,
            checkpoint: f.checkpoint.as_ref().is_none_or(|c| c.enabled),
            checkpoint_every: f.checkpoint.as_ref().and_then(|c| c.every),
            checkpoint_every_seconds,
        })
    }

    /// The time step k = T/N.
    pub fn k(&self) -> f64 {
        self.end / self.steps as f64
    }
}

fn kernel(r: &RelaxationSection, path: &Path) -> Result<Kernel> {
    let given = [r.prony.is_some(), r.expr.is_some(), r.table.is_some()];
    if given.iter().filter(|&&g| g).count() != 1 {
        let names: Vec<&str> = ["prony", "expr", "table"]
            .iter()
            .zip(given)
            .filter(|(_, g)| *g)
            .map(|(n, _)| *n)
            .collect();
        return Err(Error::input(format!(
            "{}: [material.relaxation] needs exactly one of 'prony', 'expr', 'table' \
             (or enabled = false); it has {}",
            path.display(),
            if names.is_empty() {
                "none".to_string()
            } else {
                names.join(" and ")
            }
        )));
    }
    if let Some(p) = &r.prony {
        if p.is_empty() {
            return Err(Error::input(format!(
                "{}: key 'material.relaxation.prony' is empty; give pairs [a_i, b_i]",
                path.display()
            )));
        }
        let mut terms = Vec::new();
        for (i, [a, b]) in p.iter().enumerate() {
            let key = format!("material.relaxation.prony[{i}]");
            let a = ranges::scaled(*a, &format!("{key}[0]"), path)?;
            let b = ranges::scaled_sign(*b, &format!("{key}[1]"), path, false)?;
            terms.push((a, b));
        }
        return Ok(Kernel::Prony(terms));
    }
    if let Some(e) = &r.expr {
        let key = format!("{}: key 'material.relaxation.expr'", path.display());
        return Ok(Kernel::Expr(Box::new(Expr::parse(e, &["s"], &key)?)));
    }
    let t = r.table.as_ref().expect("one of the three is present");
    let key = "material.relaxation.table";
    if t.s.len() != t.r.len() || t.s.is_empty() {
        return Err(Error::input(format!(
            "{}: key '{key}': 's' and 'r' must be non-empty and of equal length ({} vs {})",
            path.display(),
            t.s.len(),
            t.r.len()
        )));
    }
    for (name, values) in [("s", &t.s), ("r", &t.r)] {
        for (i, v) in values.iter().enumerate() {
            ranges::scaled(*v, &format!("{key}.{name}[{i}]"), path)?;
        }
    }
    if t.s.windows(2).any(|w| w[1] <= w[0]) {
        return Err(Error::input(format!(
            "{}: key '{key}.s' must be strictly increasing",
            path.display()
        )));
    }
    Ok(Kernel::Table(t.s.clone(), t.r.clone()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn override_values_are_typed() {
        let mut root: toml::Table = "[time]\nend = 1.0\nsteps = 8\n".parse().unwrap();
        apply_override(&mut root, "time.steps=64").unwrap();
        apply_override(&mut root, "friction.enabled=false").unwrap();
        apply_override(&mut root, "mesh.groups.contact=Γ3,1").unwrap();
        apply_override(&mut root, "material.relaxation.prony=[[1.0, 10.0]]").unwrap();
        assert_eq!(root["time"]["steps"].as_integer(), Some(64));
        assert_eq!(root["friction"]["enabled"].as_bool(), Some(false));
        assert_eq!(root["mesh"]["groups"]["contact"].as_str(), Some("Γ3,1"));
        assert!(root["material"]["relaxation"]["prony"].is_array());
        assert!(apply_override(&mut root, "novalue").is_err());
    }

    #[test]
    fn table_kernel_interpolates() {
        let k = Kernel::Table(vec![0.0, 1.0], vec![1.0, 0.0]);
        assert_eq!(k.eval(0.25), 0.75);
        assert_eq!(k.eval(2.0), 0.0);
        assert_eq!(k.eval(-1.0), 1.0);
    }
}
