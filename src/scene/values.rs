//! A scene's numbers-or-expressions, checked and compiled: the values of loads, of F and μ,
//! and of prescribed displacements. Below `physics` and `conditions`, which both read them.

use super::file::{Model, NumOrExpr};
use crate::expr::{Expr, Scalar};
use crate::{ranges, Result};
use std::path::Path;

/// `v` at key `key` of `file`: a number in range (also one written as a string), or an
/// expression of the variables `allowed`.
pub(super) fn scalar(v: &NumOrExpr, allowed: &[&str], key: &str, file: &Path) -> Result<Scalar> {
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
pub(super) fn variables(model: Model, time: bool) -> &'static [&'static str] {
    match (model.dim(), time) {
        (2, true) => &["x", "y", "t"],
        (2, false) => &["x", "y"],
        (_, true) => &["x", "y", "z", "t"],
        (_, false) => &["x", "y", "z"],
    }
}

/// The entries of the list at `key`, each a number or an expression of x, y (z) and t
/// (`key[i]` naming entry i); its length is the caller's to check.
pub(super) fn of_space_and_time(
    v: &[NumOrExpr],
    key: &str,
    model: Model,
    file: &Path,
) -> Result<Vec<Scalar>> {
    v.iter()
        .enumerate()
        .map(|(i, c)| scalar(c, variables(model, true), &format!("{key}[{i}]"), file))
        .collect()
}
