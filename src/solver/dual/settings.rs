//! The tuning of the dual method, one typed value per choice the method makes (Clarabel's
//! `DefaultSettings` is the model). No scene key sets them (docs/scene.md lists every key): a run
//! uses `DualSettings::default()`, whose values are the ones `tests/regression/golden.rs` pins bit for
//! bit; tests pick others. The measurements behind each default are in docs/performance.md,
//! "Contact solver tuning".

use crate::{Error, Result};

/// Which form the Newton systems are solved in (see `newton::newton_step`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NewtonForm {
    /// In 3D, whichever form the flop estimate finds cheaper, iteration by iteration; in 2D
    /// the direct form (the default).
    Cheaper,
    /// Always the direct form.
    Direct,
    /// The Woodbury form whenever B exists (tests).
    Woodbury,
}

/// The settings of a `DualSolver`; `validate` checks the ranges given with each field.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DualSettings {
    /// Relative tolerance of the dual optimality conditions, in units of the velocities P w:
    /// a step is solved when the residual of the module doc's stopping test is at most
    /// `tolerance` · max|d|. Default 1e-12; in (0, 1).
    pub tolerance: f64,
    /// A step's iterations at most; reaching it fails the step (exit 1), so the limit only
    /// bounds how long a failing step takes (thin plates need up to 776). Default 2000; ≥ 1.
    pub max_iterations: usize,
    /// η of the Newton step's prediction v = z − g/(ηδ): large, so that the prediction
    /// follows the iterate and few groups are predicted off their set; the iteration after
    /// a rejected Newton point, and with `far_after_damped` a damped one, predicts with
    /// η = 1. The answer does not depend on it.
    /// Default 64; > 0.
    pub eta: f64,
    /// In a step's first this many iterations the Newton prediction holds a 3D disc
    /// multiplier that lies on its rim there (|z_j| ≥ `rim` c_j) on the rim, with the shift
    /// κ_j = max(μ_j, 0)/c_j of its tangent (μ_j = −g_j·ẑ_j), where v_j = z_j − g_j/(ηδ_j)
    /// falls inside the disc. The warm start carries the last step's friction forces, but
    /// its gradient is that of the new loads: at nodes that go on sliding it can point into
    /// the disc, and the prediction then frees them: the first Newton step takes them as
    /// sticking, and the next Newton point is rejected (the plate of issue 29:
    /// 4–14 such nodes in each of its middle steps, over a thousand where it starts to
    /// slide). Holding them lets the first Newton step follow the new loads with the last
    /// step's sliding nodes. With `far_after_damped` the iteration after a damped Newton
    /// point holds them too; the others predict as the module doc says, so the answer does
    /// not depend on it. Default 1 (2 took more iterations: docs/performance.md); 0 never
    /// but after damped points.
    pub held_rims: usize,
    /// After a damped Newton point the next prediction takes η = 1 and holds the rims
    /// (`held_rims`), as after a rejected one: the damped point stopped short because the
    /// Newton point overshot, so the prediction that chose it was wrong for the groups it
    /// moved. Default true (the dense dual's golden scenes and plates: docs/performance.md);
    /// the matrix-free dual's default is false (`MatrixFreeSettings`).
    pub far_after_damped: bool,
    /// The shortest damped Newton step Π(z + α(z⁺ − z)) tried before the projected Newton
    /// step (α = 1, then interpolated fractions down to it). Default 0.02; in (0, 1].
    pub min_damping: f64,
    /// A damped Newton step is accepted where q falls by at least this fraction of its
    /// first-order prediction g·(z − trial): near the minimizer along the path, not past it
    /// (without it, short steps that barely lower q replace projected Newton steps that do
    /// better). Default 0.3; in (0, 1).
    pub damped_decrease: f64,
    /// A projected Newton step α shorter than this also tries the projected gradient step
    /// and widens the next binding set (`widen`). Default 1e-3; in (0, 1).
    pub pg_switch: f64,
    /// After a projected Newton step shorter than `pg_switch`, the next binding set is this
    /// many times wider (ε ← widen·ε), so that groups near the boundary that stopped the step
    /// are held: the thin slabs' steps zigzagged without it. Default 3; ≥ 1.
    pub widen: f64,
    /// The largest factor of ε (`widen`). Default 1e8; ≥ 1.
    pub max_widen: f64,
    /// The Armijo searches interpolate (`iteration::backtrack`) in the first this many
    /// iterations of a step and halve after them: interpolation throughout zigzags on an
    /// ill-conditioned D as exact line searches do. Default 20.
    pub interpolated: usize,
    /// |γ_j| ≥ `rim` · c_j counts as on the rim: a projected disc multiplier c v̂ has the
    /// norm c only up to a few roundings. Default 1 − 8ε; in (0, 1].
    pub rim: f64,
    /// ρ: the relative Newton shift ρ δ_j of the groups at nodes with dependent rows (the
    /// module doc): far above the rounding level of the factorizations and of g, far below
    /// the curvature of independent rows. Default 1e-8; in (0, 1).
    pub dependent_shift: f64,
    /// A Woodbury solve is accepted when its Newton equations hold to this fraction of the
    /// dual's tolerance, so that its inexactness cannot reach the stopping test. Default
    /// 1e-2; in (0, 1].
    pub newton_accuracy: f64,
    /// Refinements of a Woodbury solve at most before the system is solved in the direct
    /// form instead. Default 2.
    pub refinements: usize,
    /// Conjugate gradient iterations at most with the step's last Newton factor as the
    /// preconditioner before a new factorization. Default 30.
    pub pcg_max: usize,
    /// Below this many rows (columns of a Newton matrix) a pass over D or the Newton
    /// matrix runs on one thread: handing pieces of it to `Team`'s workers costs more. The
    /// arithmetic is the same either way. Default 512; ≥ 2.
    pub split_rows: usize,
    /// The dense factorization of an n × n Newton matrix runs on one thread for n below
    /// this and on all the process's threads above (`threads`): handing a small
    /// factorization to the thread pool costs more than it saves. (Its solves, of one
    /// vector, run on one thread.) Default 1024.
    pub par_min: usize,
    /// A Newton matrix of this many rows or more is factored in single precision (twice as
    /// fast as in double at these sizes), and its system solved by the conjugate gradients
    /// that a kept factor preconditions (`pcg`), to the same relative residual of 1e-14;
    /// where it is not definite in f32 or they do not converge, it is factored in double
    /// precision after all. Below it the factorization is double and its solve direct:
    /// there the few CG iterations cost about what the factorization saves (both measured
    /// in docs/performance.md, "Single precision where it pays"). Default 1024.
    pub single_min: usize,
    /// The form of the Newton systems. Default `NewtonForm::Cheaper`.
    pub newton_form: NewtonForm,
}

impl Default for DualSettings {
    fn default() -> Self {
        DualSettings {
            tolerance: 1e-12,
            max_iterations: 2000,
            eta: 64.0,
            held_rims: 1,
            far_after_damped: true,
            min_damping: 0.02,
            damped_decrease: 0.3,
            pg_switch: 1e-3,
            widen: 3.0,
            max_widen: 1e8,
            interpolated: 20,
            rim: 1.0 - 8.0 * f64::EPSILON,
            dependent_shift: 1e-8,
            newton_accuracy: 1e-2,
            refinements: 2,
            pcg_max: 30,
            split_rows: 512,
            par_min: 1024,
            single_min: 1024,
            newton_form: NewtonForm::Cheaper,
        }
    }
}

impl DualSettings {
    /// Checks every field against its range; the error names the first field out of it.
    pub fn validate(&self) -> Result<()> {
        let open = |x: f64, hi: f64| x > 0.0 && x < hi;
        let checks = [
            ("tolerance", open(self.tolerance, 1.0), "in (0, 1)"),
            ("max_iterations", self.max_iterations >= 1, "at least 1"),
            ("eta", open(self.eta, f64::INFINITY), "positive and finite"),
            (
                "min_damping",
                open(self.min_damping, 1.0) || self.min_damping == 1.0,
                "in (0, 1]",
            ),
            (
                "damped_decrease",
                open(self.damped_decrease, 1.0),
                "in (0, 1)",
            ),
            ("pg_switch", open(self.pg_switch, 1.0), "in (0, 1)"),
            (
                "widen",
                self.widen >= 1.0 && self.widen.is_finite(),
                "at least 1 and finite",
            ),
            (
                "max_widen",
                self.max_widen >= 1.0 && self.max_widen.is_finite(),
                "at least 1 and finite",
            ),
            ("rim", open(self.rim, 1.0) || self.rim == 1.0, "in (0, 1]"),
            (
                "dependent_shift",
                open(self.dependent_shift, 1.0),
                "in (0, 1)",
            ),
            (
                "newton_accuracy",
                open(self.newton_accuracy, 1.0) || self.newton_accuracy == 1.0,
                "in (0, 1]",
            ),
            ("split_rows", self.split_rows >= 2, "at least 2"),
        ];
        in_ranges("dual", &checks, self)
    }
}

/// Ok if every check holds, else the input error that names the first field out of its
/// range: `checks` are (field, whether it is in range, the range), `solver` names the
/// contact solver whose `settings` they are.
pub(in crate::solver) fn in_ranges(
    solver: &str,
    checks: &[(&str, bool, &str)],
    settings: &dyn std::fmt::Debug,
) -> Result<()> {
    match checks.iter().find(|(_, ok, _)| !ok) {
        None => Ok(()),
        Some((field, _, range)) => Err(Error::input(format!(
            "the {solver} contact solver's setting `{field}` must be {range} ({settings:?})"
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::DualSettings;

    #[test]
    fn defaults_are_valid_and_ranges_are_checked() {
        DualSettings::default().validate().unwrap();
        let bad = [
            DualSettings {
                tolerance: 0.0,
                ..Default::default()
            },
            DualSettings {
                eta: f64::NAN,
                ..Default::default()
            },
            DualSettings {
                min_damping: 1.5,
                ..Default::default()
            },
            DualSettings {
                damped_decrease: 1.0,
                ..Default::default()
            },
            DualSettings {
                rim: 1.0 + f64::EPSILON,
                ..Default::default()
            },
            DualSettings {
                max_iterations: 0,
                ..Default::default()
            },
        ];
        for (s, field) in bad.iter().zip([
            "tolerance",
            "eta",
            "min_damping",
            "damped_decrease",
            "rim",
            "max_iterations",
        ]) {
            let err = s.validate().unwrap_err().to_string();
            assert!(err.contains(&format!("`{field}`")), "{err}");
        }
    }
}
