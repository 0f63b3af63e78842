//! The scene file (TOML, DESIGN.md "Scene file"): what the user asks for. Reading it is
//! two steps: `SceneFile` mirrors the TOML exactly (unknown keys are errors, named by their
//! dotted path), then `Scene::from_file` checks every value and compiles the expressions.
//! `--set KEY=VALUE` overrides are applied to the TOML tree before either step, so an
//! override is checked exactly like a key written in the file.

pub mod file;
mod read;

pub use file::{
    ContactSolver, Groups, History, MemoryMode, Model, NumOrExpr, RelaxationSection, SceneFile,
    TimeSection, DEFAULT_CHECKPOINT_SECONDS,
};
pub use read::{apply_override, parse_scene_text, read_scene_file};

use crate::expr::{Expr, Scalar};
use crate::kernel::Kernel;
use crate::{ranges, Error, Result};
use file::{OutputCompression, OutputFormat, OutputPrecision, Seconds};
use std::path::{Path, PathBuf};

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
