//! The range of every numeric scene value (docs/scene_ranges.md is this table for users).
//! `Scene::from_file` checks each value against its row here, so `check`, `run` and `resume`
//! (whose scene is the checkpoint's stored scene with its overrides) refuse the same values,
//! before an output directory is touched; a refusal names the key, the value, the range and
//! why (exit status 2).
//!
//! # The scale rule
//!
//! The physical values (times, moduli, viscosities, kernel coefficients and rates, stresses,
//! loads) have no units the program knows of, so their range is a numerical one: each is 0
//! (where 0 is allowed) or of magnitude in [1e-100, 1e100]. A step multiplies up to three
//! of them with the mesh's own sizes (k·θ in K_A, k·E in the elastic term, k²·r·a in the
//! memory term, e^{−b k}); inside 1e±100 every such product is a normal double (its range
//! is 1e±308), outside it a product may overflow to ∞ or underflow to a subnormal or 0, and
//! the run would fail later with a message blaming something else (a factorization that is
//! "not positive definite", a contact solver that "does not converge", a time printed as
//! 0.000…). Subnormal inputs (below 2.2e-308, e.g. 1e-320), NaN and ±∞ are refused by it.
//!
//! # Counts
//!
//! `time.steps` is at most 2^53: t_n = n·k is computed from n as a double, and beyond 2^53
//! consecutive indices are no longer distinct doubles. What a count implies in memory, disk
//! and time (frames, files, checkpoints, the direct memory sum) is estimated and checked
//! against this machine by `resources`, also before the directory is touched.

use crate::{Error, Result};
use std::path::Path;

/// The smallest nonzero magnitude of a physical scene value.
pub const SCALE_MIN: f64 = 1e-100;
/// The largest magnitude of a physical scene value.
pub const SCALE_MAX: f64 = 1e100;
/// The largest `time.steps` (2^53).
pub const MAX_STEPS: usize = 1 << 53;
/// The largest `checkpoint.every_seconds` (about 31.7 years).
pub const MAX_CHECKPOINT_SECONDS: f64 = 1e9;
/// The largest bulk to shear viscosity ratio ζ/θ.
pub const MAX_BULK_RATIO: f64 = 1e12;

/// One numeric scene key: its dotted path (`[]` for any index), its range, its default and
/// why the limits are what they are.
#[derive(Debug)]
pub struct Range {
    pub key: &'static str,
    pub range: &'static str,
    pub default: &'static str,
    pub why: &'static str,
}

const SCALE: &str = "the scale rule: products of a few scene values must stay normal doubles";
const RELATIVE: &str = "a relative residual: below 1e-15 it is the round-off of doubles and \
                        would never be met";
const GROUP: &str = "a name (string) or any integer tag";
const GROUP_WHY: &str = "a tag is looked up in the mesh's physical groups; no number is computed \
                         from it";

/// Every numeric key the scene parser knows (tests/cli/extreme_values.rs checks that the parser
/// has no other), in the order of docs/scene.md.
pub const RANGES: &[Range] = &[
    row(
        "mesh.groups.fixed",
        "a group (a name or any integer tag), a list of groups, or []",
        "\"Γ1\"",
        GROUP_WHY,
    ),
    row("mesh.groups.traction", GROUP, "\"Γ2\"", GROUP_WHY),
    row("mesh.groups.contact", GROUP, "\"Γ3,1\"", GROUP_WHY),
    row("mesh.groups.friction", GROUP, "\"Γ3,2\"", GROUP_WHY),
    row(
        "time.end",
        "1e-100 ≤ T ≤ 1e100, and the step k = T/N ≥ 1e-100",
        "required",
        SCALE,
    ),
    row(
        "time.steps",
        "1 ≤ N ≤ 2^53 = 9007199254740992, and the memory, disk and time it implies fit this \
         machine",
        "required",
        "t_n = n·k needs n exact as a double; the estimate of `check` is checked",
    ),
    row(
        "material.viscosity.theta",
        "1e-100 ≤ θ ≤ 1e100",
        "required",
        "H(A): A must be coercive (θ > 0); the scale rule",
    ),
    row(
        "material.viscosity.zeta",
        "0, or 1e-100 ≤ ζ ≤ 1e100 and ζ ≤ 1e12·θ",
        "0",
        "beyond 1e12·θ the bulk part of K_A swamps its shear part and the Cholesky \
         factorization in double precision fails (measured on rect_004: ζ/θ = 1e13 factors, \
         1e20 does not)",
    ),
    row(
        "material.elasticity.young",
        "0, or 1e-100 ≤ E ≤ 1e100",
        "required in [material.elasticity]",
        "the scale rule; the step limit k ≤ 4θ/E of the explicit term is checked apart",
    ),
    row(
        "material.elasticity.poisson",
        "−1 < ν ≤ 0.5 (plane stress), −1 < ν < 0.5 (plane strain, 3D); 0 or |ν| ≥ 1e-100",
        "0",
        "B must be positive definite; ν = 0.5 makes λ infinite in plane strain and 3D",
    ),
    row(
        "material.relaxation.prony[][]",
        "pairs [a, b]: a = 0 or 1e-100 ≤ |a| ≤ 1e100; b = 0 or 1e-100 ≤ b ≤ 1e100",
        "none",
        "b < 0 makes exp(−b s) grow; the scale rule",
    ),
    row(
        "material.relaxation.tolerance",
        "1e-100 ≤ tol < 1",
        "1e-10",
        "a relative error; the scale rule",
    ),
    row(
        "material.relaxation.horizon",
        "1e-100 ≤ h ≤ 1e6·time.end",
        "time.end",
        "the fit covers the lags up to h/k; the scale rule",
    ),
    row(
        "material.relaxation.table.s[]",
        "0 or 1e-100 ≤ |s| ≤ 1e100, strictly increasing",
        "none",
        SCALE,
    ),
    row(
        "material.relaxation.table.r[]",
        "0 or 1e-100 ≤ |r| ≤ 1e100",
        "none",
        SCALE,
    ),
    row("material.region[].on", GROUP, "required", GROUP_WHY),
    row(
        "material.region[].viscosity.theta",
        "as material.viscosity.theta",
        "required in the region's [viscosity]",
        "as material.viscosity.theta",
    ),
    row(
        "material.region[].viscosity.zeta",
        "as material.viscosity.zeta",
        "0",
        "as material.viscosity.zeta",
    ),
    row(
        "material.region[].elasticity.young",
        "as material.elasticity.young",
        "required in the region's [elasticity]",
        "as material.elasticity.young",
    ),
    row(
        "material.region[].elasticity.poisson",
        "as material.elasticity.poisson",
        "0",
        "as material.elasticity.poisson",
    ),
    row(
        "material.region[].relaxation.prony[][]",
        "as material.relaxation.prony[][]",
        "none",
        "as material.relaxation.prony[][]",
    ),
    row(
        "material.region[].relaxation.tolerance",
        "as material.relaxation.tolerance",
        "1e-12",
        "as material.relaxation.tolerance",
    ),
    row(
        "material.region[].relaxation.horizon",
        "as material.relaxation.horizon",
        "time.end",
        "as material.relaxation.horizon",
    ),
    row(
        "material.region[].relaxation.table.s[]",
        "as material.relaxation.table.s[]",
        "none",
        SCALE,
    ),
    row(
        "material.region[].relaxation.table.r[]",
        "as material.relaxation.table.r[]",
        "none",
        SCALE,
    ),
    row(
        "friction.normal_stress",
        "a number: 0 or 1e-100 ≤ F ≤ 1e100; or an expression of x, y, z",
        "required in [friction]",
        "H(C): F ≥ 0; the scale rule (an expression is checked where it is evaluated)",
    ),
    row(
        "friction.coefficient",
        "a number: 0 or 1e-100 ≤ μ ≤ 1e100; or an expression of x, y, z",
        "required in [friction]",
        "μ ≥ 0; the scale rule (an expression is checked where it is evaluated)",
    ),
    row(
        "load.traction[].on",
        GROUP,
        "mesh.groups.traction",
        GROUP_WHY,
    ),
    row(
        "load.traction[].value[]",
        "a number: 0 or 1e-100 ≤ |f| ≤ 1e100; or an expression of x, y, z, t",
        "required",
        "the scale rule (an expression is checked where it is evaluated)",
    ),
    row("load.body[].on", GROUP, "not allowed", GROUP_WHY),
    row(
        "load.body[].value[]",
        "a number: 0 or 1e-100 ≤ |f| ≤ 1e100; or an expression of x, y, z, t",
        "required",
        "the scale rule (an expression is checked where it is evaluated)",
    ),
    row("dirichlet[].on", GROUP, "required", GROUP_WHY),
    row(
        "dirichlet[].value[]",
        "a number: 0 or 1e-100 ≤ |g| ≤ 1e100; or an expression of x, y, z, t",
        "0 for each component",
        "the scale rule (an expression is checked where it is evaluated)",
    ),
    row(
        "solver.active_set.tolerance",
        "1e-15 ≤ tol < 1",
        "1e-10",
        RELATIVE,
    ),
    row(
        "solver.active_set.max_iterations",
        "1 ≤ n ≤ 10000",
        "50",
        "a step that needs more is not converging: it fails with the residual reached",
    ),
    row(
        "solver.active_set.forcing",
        "1e-15 ≤ η < 1",
        "1e-2",
        RELATIVE,
    ),
    row(
        "solver.active_set.krylov_tolerance",
        "1e-15 ≤ rtol < 1",
        "1e-12",
        RELATIVE,
    ),
    row(
        "output.every",
        "1 ≤ n ≤ 2^63 − 1",
        "1",
        "⌈N/n⌉ + 1 frames are written: their bytes and files are checked against the disk",
    ),
    row(
        "checkpoint.every",
        "1 ≤ n ≤ 2^63 − 1",
        "none (the final checkpoint only)",
        "each checkpoint rewrites the per-step log: their bytes are checked with the run's",
    ),
    row(
        "checkpoint.every_seconds",
        "0 or false (off), true (600), or 0 < s ≤ 1e9",
        "600",
        "a wall-clock interval; 1e9 s is 31.7 years, longer than any run (write 0 or false for \
         never)",
    ),
];

const fn row(
    key: &'static str,
    range: &'static str,
    default: &'static str,
    why: &'static str,
) -> Range {
    Range {
        key,
        range,
        default,
        why,
    }
}

/// The row of `key`, a dotted path whose indices (`[3]`) are ignored.
pub fn range_of(key: &str) -> Option<&'static Range> {
    let mut pattern = String::with_capacity(key.len());
    let mut in_index = false;
    for c in key.chars() {
        match c {
            '[' => in_index = true,
            ']' => in_index = false,
            _ if in_index => continue,
            _ => {}
        }
        pattern.push(c);
    }
    RANGES.iter().find(|r| r.key == pattern)
}

/// The error for `value` of `key` outside its range: the file, the key, the value, the range,
/// `detail` (what in this scene the value breaks, may be empty) and why.
pub fn refuse(file: &Path, key: &str, value: impl std::fmt::Debug, detail: &str) -> Error {
    let range = range_of(key).map_or(String::new(), |row| {
        format!(
            "; it must be finite and in its range: {} ({})",
            row.range, row.why
        )
    });
    Error::input(format!(
        "{}: key '{key}' is {value:?}{detail}{range}; see docs/scene_ranges.md",
        file.display()
    ))
}

/// Whether `v` obeys the scale rule: 0, or finite with 1e-100 ≤ |v| ≤ 1e100.
pub fn in_scale(v: f64) -> bool {
    v == 0.0 || (SCALE_MIN..=SCALE_MAX).contains(&v.abs())
}

/// `v` when it obeys the scale rule, else the refusal naming `key`.
pub fn scaled(v: f64, key: &str, file: &Path) -> Result<f64> {
    if in_scale(v) {
        Ok(v)
    } else {
        Err(refuse(file, key, v, ""))
    }
}

/// `v` when it obeys the scale rule and is ≥ 0 (> 0 when `positive`), else the refusal.
pub fn scaled_sign(v: f64, key: &str, file: &Path, positive: bool) -> Result<f64> {
    let v = scaled(v, key, file)?;
    if v > 0.0 || (!positive && v == 0.0) {
        Ok(v)
    } else {
        Err(refuse(file, key, v, ""))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_scale_rule_refuses_the_extremes() {
        for v in [0.0, -0.0, 1e-100, -1e-100, 1e100, -1e100, 0.3, -7.0] {
            assert!(in_scale(v), "{v}");
        }
        for v in [
            1e-101,
            1e-320,
            -1e-320,
            f64::MIN_POSITIVE,
            1.0000001e100,
            1e300,
            f64::MAX,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ] {
            assert!(!in_scale(v), "{v}");
        }
    }

    #[test]
    fn every_indexed_key_finds_its_row_and_the_refusal_says_why() {
        assert_eq!(
            range_of("load.traction[12].value[1]").map(|r| r.key),
            Some("load.traction[].value[]")
        );
        assert!(range_of("time.nothing").is_none());
        let e = scaled_sign(-1.0, "material.viscosity.theta", Path::new("s.toml"), true)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("s.toml")
                && e.contains("'material.viscosity.theta' is -1")
                && e.contains("must be finite and in its range: 1e-100 ≤ θ ≤ 1e100")
                && e.contains("coercive"),
            "{e}"
        );
        assert!(scaled_sign(0.0, "material.viscosity.zeta", Path::new("s"), false).is_ok());
        assert!(scaled_sign(0.0, "material.viscosity.theta", Path::new("s"), true).is_err());
    }
}
