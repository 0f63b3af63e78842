//! `[[dirichlet]]`: prescribed displacement components on boundary groups, checked and
//! compiled. Which nodes they reach, and whether they hold together, is decided on the mesh
//! (`fem::constraints`).

use super::file::{DirichletSection, Model, NumOrExpr};
use super::values::of_space_and_time;
use crate::expr::Scalar;
use crate::{Error, Result};
use std::path::Path;

/// Which displacement components an entry prescribes.
#[derive(Debug, Clone, PartialEq)]
pub enum Components {
    /// Coordinate components (0 = x, 1 = y, 2 = z), each once, in the order written.
    Axes(Vec<usize>),
    /// The component along the group's outward unit normal (a flat group): a symmetry plane
    /// or a roller.
    Normal,
}

/// One checked `[[dirichlet]]` entry: u_c = value_c(x, t) on the group `on`.
#[derive(Debug)]
pub struct Dirichlet {
    /// The physical group (resolved against the mesh later).
    pub on: String,
    pub components: Components,
    /// One value per component (Axes) or one (Normal); all zero when `value` is absent.
    pub value: Vec<Scalar>,
    /// Each value as written (trimmed; "0" when absent): two entries that hold a node's
    /// component at the same written value agree.
    pub written: Vec<String>,
}

impl Components {
    /// The number of values an entry takes: one per component, one for `normal`.
    pub fn n_values(&self) -> usize {
        match self {
            Components::Axes(a) => a.len(),
            Components::Normal => 1,
        }
    }
}

impl Dirichlet {
    /// Whether value `i` is zero at all times (a constant 0): the component is then
    /// eliminated as a clamped one is.
    pub fn is_zero(&self, i: usize) -> bool {
        matches!(self.value[i], Scalar::Const(v) if v == 0.0)
    }
}

/// The `[[dirichlet]]` entries of a scene read from `path`, for `model`.
pub(super) fn dirichlet(
    entries: &[DirichletSection],
    model: Model,
    path: &Path,
) -> Result<Vec<Dirichlet>> {
    entries
        .iter()
        .enumerate()
        .map(|(i, e)| entry(e, i, model, path))
        .collect()
}

fn entry(e: &DirichletSection, i: usize, model: Model, path: &Path) -> Result<Dirichlet> {
    let key = format!("dirichlet[{i}].components");
    let components = components(&e.components.to_vec(), model, path, &key)?;
    let n = components.n_values();
    let written = match &e.value {
        None => vec!["0".to_string(); n],
        Some(v) => v
            .iter()
            .map(|x| match x {
                NumOrExpr::Num(x) => x.to_string(),
                NumOrExpr::Expr(s) => s.trim().to_string(),
            })
            .collect(),
    };
    let value = match &e.value {
        None => (0..n).map(|_| Scalar::Const(0.0)).collect(),
        Some(v) => {
            let key = format!("dirichlet[{i}].value");
            if v.len() != n {
                return Err(Error::input(format!(
                    "{}: key '{key}': has {} values for {n} component(s); give one number or \
                     expression of x, y{}, t per component, in the order of 'components'",
                    path.display(),
                    v.len(),
                    if model.dim() == 3 { ", z" } else { "" }
                )));
            }
            of_space_and_time(v, &key, model, path)?
        }
    };
    Ok(Dirichlet {
        on: e.on.clone(),
        components,
        value,
        written,
    })
}

/// "x", "y", "z" (each once; z only in 3D) or "normal" alone.
fn components(names: &[String], model: Model, path: &Path, key: &str) -> Result<Components> {
    let refuse = |why: String| Error::input(format!("{}: key '{key}': {why}", path.display()));
    let axes = &["x", "y", "z"][..model.dim()];
    if names.iter().any(|n| n == "normal") {
        return match names.len() {
            1 => Ok(Components::Normal),
            _ => Err(refuse(
                "\"normal\" stands alone (components = [\"normal\"]); use separate \
                 [[dirichlet]] entries for other components"
                    .into(),
            )),
        };
    }
    if names.is_empty() {
        return Err(refuse(format!(
            "is empty; name the components to prescribe: any of {} or [\"normal\"]",
            quoted(axes)
        )));
    }
    let mut out = Vec::new();
    for n in names {
        let Some(c) = axes.iter().position(|a| a == n) else {
            return Err(refuse(format!(
                "unknown component \"{n}\"; the {} model has {} (or [\"normal\"] on a flat \
                 group)",
                model.name(),
                quoted(axes)
            )));
        };
        if out.contains(&c) {
            return Err(refuse(format!("\"{n}\" is named twice")));
        }
        out.push(c);
    }
    Ok(Components::Axes(out))
}

fn quoted(axes: &[&str]) -> String {
    let q: Vec<String> = axes.iter().map(|a| format!("\"{a}\"")).collect();
    q.join(", ")
}
