//! `Physics`: the material of (4.1)–(4.2), the relaxation kernel and how its memory sum is
//! run, contact, friction and the loads: everything of the scene that the equations see.
//! Converted from `[material]`, `[contact]`, `[friction]` and `[load]`, every number in
//! range and every expression compiled.
//!
//! The operators A and B may depend on x (the paper allows it): `[[material.region]]`
//! entries give the cells of a physical group a material of their own, its tables checked
//! by the same functions as `[material]`'s (under the keys `material.region[i].…`), the
//! tables a region leaves out taken from `[material]`. A region's own `relaxation` table
//! gives its cells a kernel of their own (checked as `[material.relaxation]`; `enabled =
//! false` leaves them without memory); `history` keeps one memory state per kernel.

use super::conditions::Dirichlet;
use super::file::{
    ElasticitySection, FrictionSection, LoadSection, MaterialSection, MemoryMode, Model, NumOrExpr,
    RegionSection, RelaxationSection, SceneFile, ViscositySection,
};
use super::values::{of_space_and_time, scalar, variables};
use super::TimeGrid;
use crate::expr::{Expr, Scalar};
use crate::kernel::Kernel;
use crate::{ranges, Error, Result};
use std::path::Path;

/// A traction on part of Γ2.
#[derive(Debug)]
pub struct Traction {
    /// Physical group key (resolved against the mesh later).
    pub on: String,
    pub value: Vec<Scalar>,
}

/// The friction data on Γ3,2.
#[derive(Debug)]
pub struct Friction {
    pub normal_stress: Scalar,
    pub coefficient: Scalar,
}

/// The material of (4.1)–(4.2) of the body or of a region of it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    /// θ, ζ of (4.1).
    pub theta: f64,
    pub zeta: f64,
    /// E, ν of (4.2); None when the elasticity term is disabled.
    pub elasticity: Option<(f64, f64)>,
}

/// A relaxation kernel as a table gives it, checked, and how its memory sum is run.
#[derive(Debug)]
pub struct Relaxation {
    /// r(s); None when the table disables relaxation (`enabled = false`).
    pub kernel: Option<Kernel>,
    /// For an expression or table kernel: compressed with this tolerance, or exact (None).
    /// Always None for a Prony series (already O(1)).
    pub compression: Option<f64>,
    /// `<table>.horizon`: the fit of a compressed kernel covers the lags up to
    /// max(time.end, horizon).
    pub horizon: Option<f64>,
}

/// The table of the body's kernel, `[material.relaxation]` (the prefix of its keys).
pub const BODY_KERNEL: &str = "material.relaxation";

/// A checked `[[material.region]]` entry.
#[derive(Debug)]
pub struct Region {
    /// Physical group key (resolved against the mesh later: a group of the body's
    /// dimension).
    pub on: String,
    /// `[material]`'s material with the region's tables in place of its own.
    pub material: Material,
    /// The region's own `relaxation` table (keys `material.region[i].relaxation.…`); None
    /// where it has none and its cells run `[material.relaxation]`.
    pub relaxation: Option<Relaxation>,
}

/// What the equations see.
#[derive(Debug)]
pub struct Physics {
    /// `[material]`: the material of every cell outside the regions.
    pub material: Material,
    /// `[[material.region]]`, in the file's order.
    pub regions: Vec<Region>,
    /// r(s) of the memory term; None when relaxation is disabled.
    pub relaxation: Option<Kernel>,
    /// For an expression or table kernel: compressed with this tolerance, or exact (None).
    /// Always None for a Prony series (already O(1)).
    pub compression: Option<f64>,
    /// `material.relaxation.horizon`: the fit of a compressed kernel covers the lags up to
    /// max(time.end, horizon).
    pub horizon: Option<f64>,
    /// The unilateral contact constraint on Γ3,1 (`[contact] enabled`).
    pub contact: bool,
    /// Friction on Γ3,2; None when disabled.
    pub friction: Option<Friction>,
    /// f_2: the tractions on Γ2.
    pub tractions: Vec<Traction>,
    /// f_0: the body forces, one vector each.
    pub body_forces: Vec<Vec<Scalar>>,
    /// `[[dirichlet]]`: prescribed displacement components.
    pub dirichlet: Vec<Dirichlet>,
}

/// The message for a key whose value is refused for a reason of its own.
fn bad(path: &Path, key: &str, why: &str) -> Error {
    Error::input(format!("{}: key '{key}': {why}", path.display()))
}

impl Physics {
    /// The physics of a scene file; `time` is its checked time grid (the memory of a
    /// compressed kernel is checked against it).
    pub(super) fn from_file(f: &SceneFile, time: &TimeGrid, path: &Path) -> Result<Physics> {
        let model = f.mesh.model;
        let (theta, zeta) = viscosity(&f.material.viscosity, "material", path)?;
        let elasticity = elasticity(f.material.elasticity.as_ref(), "material", model, path)?;
        let material = Material {
            theta,
            zeta,
            elasticity,
        };
        let Relaxation {
            kernel: relaxation,
            compression,
            horizon,
        } = relaxation(f.material.relaxation.as_ref(), BODY_KERNEL, time, path)?;
        let friction = friction(f.friction.as_ref(), model, path)?;
        let (tractions, body_forces) = loads(&f.load, &f.mesh.groups.traction, model, path)?;
        Ok(Physics {
            material,
            regions: regions(&f.material, material, model, time, path)?,
            relaxation,
            compression,
            horizon,
            contact: f.contact.as_ref().is_some_and(|c| c.enabled),
            friction,
            tractions,
            body_forces,
            dirichlet: super::conditions::dirichlet(&f.dirichlet, model, path)?,
        })
    }

    /// `[material]`'s material, then each region's.
    pub fn materials(&self) -> impl Iterator<Item = &Material> {
        std::iter::once(&self.material).chain(self.regions.iter().map(|r| &r.material))
    }

    /// The kernels of the memory groups beyond the body's: group g ≥ 1 is the g-th region
    /// with an enabled kernel of its own, given with the prefix of its keys. Group 0 is the
    /// body's, `[material.relaxation]` (`relaxation`, `compression`, `horizon`).
    pub fn region_kernels(&self) -> Vec<(String, &Relaxation)> {
        (self.regions.iter().enumerate())
            .filter_map(|(i, r)| match &r.relaxation {
                Some(own) if own.kernel.is_some() => {
                    Some((format!("material.region[{i}].relaxation"), own))
                }
                _ => None,
            })
            .collect()
    }

    /// The number of memory groups, each with its K_R and memory state: the body's (group 0,
    /// even where `[material.relaxation]` has no kernel) and each region kernel's.
    pub fn memory_groups(&self) -> usize {
        1 + (self.regions.iter())
            .filter(|r| {
                r.relaxation
                    .as_ref()
                    .is_some_and(|own| own.kernel.is_some())
            })
            .count()
    }

    /// The memory group of the cells of region `i` (None: outside every region), None where
    /// they have no relaxation term.
    pub fn memory_group(&self, region: Option<usize>) -> Option<usize> {
        let own = |r: &Region| r.relaxation.as_ref().map(|own| own.kernel.is_some());
        match region.map(|i| (i, own(&self.regions[i]))) {
            None | Some((_, None)) => self.relaxation.as_ref().map(|_| 0),
            Some((_, Some(false))) => None,
            Some((i, Some(true))) => Some(
                1 + self.regions[..i]
                    .iter()
                    .filter(|r| own(r) == Some(true))
                    .count(),
            ),
        }
    }

    /// The memory sum run directly (`material.relaxation.memory = "exact"`), checked as in
    /// a scene file.
    pub(super) fn set_exact_memory(&mut self, time: &TimeGrid, path: &Path) -> Result<()> {
        self.refuse_prony_memory(path)?;
        self.compression = None;
        self.check_memory(time, path)
    }

    /// `material.relaxation.tolerance = tolerance`, checked as in a scene file; a kernel run
    /// exactly stays exact.
    pub(super) fn set_tolerance(
        &mut self,
        tolerance: f64,
        time: &TimeGrid,
        path: &Path,
    ) -> Result<()> {
        self.refuse_prony_memory(path)?;
        let tolerance = tolerance_range(tolerance, BODY_KERNEL, path)?;
        self.compression = self.compression.map(|_| tolerance);
        self.check_memory(time, path)
    }

    /// The kernel's memory on the time grid `time` (see [`memory_fits`]).
    pub(super) fn check_memory(&self, time: &TimeGrid, path: &Path) -> Result<()> {
        memory_fits(self.compression, self.horizon, time, BODY_KERNEL, path)
    }

    fn refuse_prony_memory(&self, path: &Path) -> Result<()> {
        match self.relaxation {
            Some(Kernel::Prony(_)) => Err(prony_memory(BODY_KERNEL, path)),
            _ => Ok(()),
        }
    }
}

/// The relaxation table `section` (keys `<prefix>.…`): its kernel when enabled, how its
/// memory sum is run, and the lags a compressed kernel's fit takes on the time grid `time`.
fn relaxation(
    section: Option<&RelaxationSection>,
    prefix: &str,
    time: &TimeGrid,
    path: &Path,
) -> Result<Relaxation> {
    let kernel = match section {
        Some(r) if r.enabled => Some(kernel(r, prefix, path)?),
        _ => None,
    };
    let compression = match (&kernel, section) {
        (Some(kernel), Some(r)) => compression(kernel, r, prefix, path)?,
        _ => None,
    };
    let horizon = section.and_then(|r| r.horizon);
    memory_fits(compression, horizon, time, prefix, path)?;
    Ok(Relaxation {
        kernel,
        compression,
        horizon,
    })
}

/// The `[[material.region]]` entries of `m`: each region's tables checked as `[material]`'s
/// (keys `material.region[i].…`), the viscosity and elasticity it leaves out taken from
/// `base`; its own relaxation table, if any, replaces `[material.relaxation]` on its cells.
fn regions(
    m: &MaterialSection,
    base: Material,
    model: Model,
    time: &TimeGrid,
    path: &Path,
) -> Result<Vec<Region>> {
    let region = |(i, r): (usize, &RegionSection)| -> Result<Region> {
        let prefix = format!("material.region[{i}]");
        let kernel_prefix = format!("{prefix}.relaxation");
        let relaxation = (r.relaxation.as_ref())
            .map(|t| relaxation(Some(t), &kernel_prefix, time, path))
            .transpose()?;
        let (theta, zeta) = match &r.viscosity {
            Some(v) => viscosity(v, &prefix, path)?,
            None => (base.theta, base.zeta),
        };
        let elasticity = match &r.elasticity {
            Some(e) => elasticity(Some(e), &prefix, model, path)?,
            None => base.elasticity,
        };
        let material = Material {
            theta,
            zeta,
            elasticity,
        };
        Ok(Region {
            on: r.on.clone(),
            material,
            relaxation,
        })
    };
    m.region.iter().enumerate().map(region).collect()
}

/// θ and ζ of (4.1) from the table `[<prefix>.viscosity]`: θ > 0,
/// 0 ≤ ζ ≤ `ranges::MAX_BULK_RATIO`·θ.
fn viscosity(v: &ViscositySection, prefix: &str, path: &Path) -> Result<(f64, f64)> {
    let zeta_key = format!("{prefix}.viscosity.zeta");
    let theta = ranges::scaled_sign(v.theta, &format!("{prefix}.viscosity.theta"), path, true)?;
    let zeta = ranges::scaled_sign(v.zeta, &zeta_key, path, false)?;
    if zeta > ranges::MAX_BULK_RATIO * theta {
        let detail = format!(", {:e} times θ = {theta:?}", zeta / theta);
        return Err(ranges::refuse(path, &zeta_key, zeta, &detail));
    }
    Ok((theta, zeta))
}

/// E and ν of (4.2) from the table `[<prefix>.elasticity]` when it enables the elasticity
/// term; ν in the model's range.
fn elasticity(
    e: Option<&ElasticitySection>,
    prefix: &str,
    model: Model,
    path: &Path,
) -> Result<Option<(f64, f64)>> {
    let e = match e {
        Some(e) if e.enabled => e,
        _ => return Ok(None),
    };
    let key = |k: &str| format!("{prefix}.elasticity.{k}");
    let young = ranges::scaled_sign(e.young, &key("young"), path, false)?;
    let nu = ranges::scaled(e.poisson, &key("poisson"), path)?;
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
        return Err(bad(
            path,
            &key("poisson"),
            &format!("is {nu}; the Poisson ratio must satisfy {range}"),
        ));
    }
    Ok(Some((young, nu)))
}

/// A Prony series may not say how its memory is run (`prefix`: the kernel's table).
fn prony_memory(prefix: &str, path: &Path) -> Error {
    bad(
        path,
        &format!("{prefix}.memory"),
        "a Prony series already runs by the exact O(1) recursion; 'memory', 'tolerance' and \
         'horizon' apply to 'expr' and 'table' kernels only: remove them",
    )
}

/// `<prefix>.tolerance` in (0, 1).
fn tolerance_range(tolerance: f64, prefix: &str, path: &Path) -> Result<f64> {
    let key = format!("{prefix}.tolerance");
    let tolerance = ranges::scaled_sign(tolerance, &key, path, true)?;
    if tolerance >= 1.0 {
        return Err(ranges::refuse(path, &key, tolerance, ""));
    }
    Ok(tolerance)
}

/// How the memory sum of `kernel` is run: compressed at a tolerance, or exactly (None).
fn compression(
    kernel: &Kernel,
    r: &RelaxationSection,
    prefix: &str,
    path: &Path,
) -> Result<Option<f64>> {
    if let Kernel::Prony(_) = kernel {
        if r.memory.is_some() || r.tolerance.is_some() || r.horizon.is_some() {
            return Err(prony_memory(prefix, path));
        }
        return Ok(None);
    }
    let tolerance = tolerance_range(
        r.tolerance.unwrap_or(crate::kernel_fit::DEFAULT_TOLERANCE),
        prefix,
        path,
    )?;
    Ok(match r.memory.unwrap_or(MemoryMode::Compressed) {
        MemoryMode::Compressed => Some(tolerance),
        MemoryMode::Exact => None,
    })
}

/// The horizon of a compressed kernel and the lags its fit takes, on the time grid
/// `time`: a horizon needs a compressed kernel, lies in (0, 10⁶·T], and the fit's lags
/// max(N, horizon/k) stay within `kernel_fit::MAX_LAGS`.
fn memory_fits(
    compression: Option<f64>,
    horizon: Option<f64>,
    time: &TimeGrid,
    prefix: &str,
    path: &Path,
) -> Result<()> {
    let TimeGrid { end, steps } = *time;
    let horizon_key = format!("{prefix}.horizon");
    match horizon {
        Some(h) if compression.is_none() => {
            return Err(bad(
                path,
                &horizon_key,
                &format!(
                    "is {h}, but only a compressed kernel (an 'expr' or 'table' with memory \
                     = \"compressed\") is fitted: remove it"
                ),
            ))
        }
        Some(h) if !(ranges::in_scale(h) && h > 0.0 && h <= 1e6 * end) => {
            return Err(ranges::refuse(
                path,
                &horizon_key,
                h,
                &format!(
                    " (the latest time.end a resume may set; here time.end = {end:?}, so at \
                     most {:e})",
                    1e6 * end
                ),
            ))
        }
        _ => {}
    }
    if compression.is_none() {
        return Ok(());
    }
    // The fit's lags, max(N, horizon/k), bounded (kernel_fit::MAX_LAGS).
    let n = steps as f64;
    let lags = horizon.map_or(n, |h| (h * n / end).ceil().max(n));
    let max = crate::kernel_fit::MAX_LAGS as f64;
    if lags <= max {
        return Ok(());
    }
    let (key, fix) = match horizon {
        Some(h) if lags > n => (
            horizon_key,
            format!("is {h}: lower it to at most {:e}", max * end / n),
        ),
        _ => (
            "time.steps".to_string(),
            format!("is {steps}: lower it, or set {prefix}.memory = \"exact\""),
        ),
    };
    Err(bad(
        path,
        &key,
        &format!(
            "{fix} (the compressed kernel would be fitted and certified on {lags:.3e} lags, \
             max(time.steps, horizon/k) with k = time.end/time.steps, more than the {max:e} \
             the fit may take: 16 bytes and O(terms) work per lag)"
        ),
    ))
}

/// F and μ on Γ3,2 when friction is enabled: numbers ≥ 0 or expressions of x, y (z).
fn friction(f: Option<&FrictionSection>, model: Model, path: &Path) -> Result<Option<Friction>> {
    let fr = match f {
        Some(fr) if fr.enabled => fr,
        _ => return Ok(None),
    };
    let space = variables(model, false);
    let normal_stress = scalar(&fr.normal_stress, space, "friction.normal_stress", path)?;
    let coefficient = scalar(&fr.coefficient, space, "friction.coefficient", path)?;
    for (value, key) in [
        (&normal_stress, "friction.normal_stress"),
        (&coefficient, "friction.coefficient"),
    ] {
        if let Scalar::Const(v) = value {
            ranges::scaled_sign(*v, key, path, false)?;
        }
    }
    Ok(Some(Friction {
        normal_stress,
        coefficient,
    }))
}

/// The tractions (on `traction_group` unless they name their own group) and the body
/// forces, each a vector of the model's dimension.
fn loads(
    load: &LoadSection,
    traction_group: &str,
    model: Model,
    path: &Path,
) -> Result<(Vec<Traction>, Vec<Vec<Scalar>>)> {
    let mut tractions = Vec::new();
    for (i, t) in load.traction.iter().enumerate() {
        let key = format!("load.traction[{i}].value");
        tractions.push(Traction {
            on: t.on.clone().unwrap_or_else(|| traction_group.to_string()),
            value: vector(&t.value, &key, model, path)?,
        });
    }
    let mut body_forces = Vec::new();
    for (i, b) in load.body.iter().enumerate() {
        if b.on.is_some() {
            return Err(bad(
                path,
                &format!("load.body[{i}].on"),
                "a body force acts on the whole domain; remove 'on'",
            ));
        }
        let key = format!("load.body[{i}].value");
        body_forces.push(vector(&b.value, &key, model, path)?);
    }
    Ok((tractions, body_forces))
}

/// A load vector: one number or expression of x, y (z) and t per component.
fn vector(v: &[NumOrExpr], key: &str, model: Model, path: &Path) -> Result<Vec<Scalar>> {
    let components = model.dim();
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
    of_space_and_time(v, key, model, path)
}

/// The relaxation kernel of `[material.relaxation]`: exactly one of a Prony series, an
/// expression of s and a table.
fn kernel(r: &RelaxationSection, prefix: &str, path: &Path) -> Result<Kernel> {
    let given = [r.prony.is_some(), r.expr.is_some(), r.table.is_some()];
    if given.iter().filter(|&&g| g).count() != 1 {
        let names: Vec<&str> = ["prony", "expr", "table"]
            .iter()
            .zip(given)
            .filter(|(_, g)| *g)
            .map(|(n, _)| *n)
            .collect();
        return Err(Error::input(format!(
            "{}: [{prefix}] needs exactly one of 'prony', 'expr', 'table' (or enabled \
             = false); it has {}",
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
                "{}: key '{prefix}.prony' is empty; give pairs [a_i, b_i]",
                path.display()
            )));
        }
        let mut terms = Vec::new();
        for (i, [a, b]) in p.iter().enumerate() {
            let key = format!("{prefix}.prony[{i}]");
            let a = ranges::scaled(*a, &format!("{key}[0]"), path)?;
            let b = ranges::scaled_sign(*b, &format!("{key}[1]"), path, false)?;
            terms.push((a, b));
        }
        return Ok(Kernel::Prony(terms));
    }
    if let Some(e) = &r.expr {
        let key = format!("{}: key '{prefix}.expr'", path.display());
        return Ok(Kernel::Expr(Box::new(Expr::parse(e, &["s"], &key)?)));
    }
    let t = r.table.as_ref().expect("one of the three is present");
    let key = format!("{prefix}.table");
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
