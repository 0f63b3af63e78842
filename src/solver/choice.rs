//! Which contact solver a run uses (`[solver] contact`), the memory it will hold and what a
//! step costs, from the sizes alone (m constraint rows on c dofs, n dofs).
//!
//! The dense condensed dual (`dual`) holds m × m matrices (D, B = D⁻¹ in 3D, the Newton
//! matrices) and factors a Newton matrix of up to m rows per iteration (m³/3 flops). The
//! two duals without D (`matrix_free`) pay a solve with the factor of K_A per product with
//! D: `matrix_free` orders C last, and its factor then holds the dense trailing block L_CC
//! (the Schur complement's factor, which also preconditions); `sparse` keeps the factor of a
//! linear run and holds O(m) besides it.
//!
//! `auto` decides from the problem alone, never from the machine: the dense dual while its
//! memory (`resources::dense_dual_bytes`) is at most `DENSE_LIMIT`, the sparse one
//! otherwise, so that no contact solver `auto` picks holds a dense block over the limit. So
//! a scene runs the same solver, and gives the same bits, on every machine and at every
//! resume; every contact boundary small enough for the dense dual gets it, with the results
//! it has always given. Whether the plan fits this machine is a separate question, asked by
//! `ContactPlan::check` before a run touches its directory: a plan that does not fit is
//! refused (exit 2), naming the key that would, never silently changed.

use super::matrix_free::MatrixFreeSettings;
use super::Rows;
use crate::fem::Discretization;
use crate::resources::{self, human, Estimate, MARGIN};
use crate::scene::{ContactSolver, Scene};
use crate::{Error, Result};

/// The dense dual's memory (bytes) up to which `auto` takes it: 4 GB, m ≈ 11 180 rows in 3D
/// (8·4m² bytes where c ≈ m). The coarse plate of issue 29 (m = 4 274, 0.58 GB) and the block
/// at h = 1/48 (m ≈ 7 400, ≈ 1.8 GB) stay dense; the finer plate (m = 16 055: D alone 2.1
/// GB, with B = D⁻¹ and the Newton matrices ≈ 8 GB) goes sparse. 4 GB leaves room for the
/// factor of K_A and the run's own state on a 16 GB workstation; a larger dense dual needs a
/// large machine, where `solver.contact = "dense"` asks for it.
pub const DENSE_LIMIT: f64 = 4e9;

/// The solver a run uses with contact or friction.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Contact {
    Dense,
    MatrixFree,
    Sparse,
    Clarabel,
    ActiveSet,
}

impl Contact {
    /// The value of `solver.contact` that names it.
    pub fn key(&self) -> &'static str {
        match self {
            Contact::Dense => "dense",
            Contact::MatrixFree => "matrix_free",
            Contact::Sparse => "sparse",
            Contact::Clarabel => "clarabel",
            Contact::ActiveSet => "active_set",
        }
    }

    /// The dofs its factor of K_A orders last: the constrained boundary dofs C of `rows`
    /// for the dense dual (it condenses through the trailing block) and the matrix-free one
    /// (it multiplies by it); none for the others, which take a linear run's fill-reducing
    /// order.
    pub fn ordered_last(&self, rows: &Rows) -> Vec<usize> {
        match self {
            Contact::Dense | Contact::MatrixFree => rows.dofs(),
            _ => Vec::new(),
        }
    }

    /// The solver the scene's `choice` names on `rows`, `auto` resolved (`Contact::auto`).
    pub fn of(choice: ContactSolver, rows: &Rows) -> Contact {
        match choice {
            ContactSolver::Dense => Contact::Dense,
            ContactSolver::MatrixFree => Contact::MatrixFree,
            ContactSolver::Sparse => Contact::Sparse,
            ContactSolver::Clarabel => Contact::Clarabel,
            ContactSolver::ActiveSet => Contact::ActiveSet,
            ContactSolver::Auto => Contact::auto(rows.len(), rows.dofs().len(), rows.block),
        }
    }

    /// What `auto` takes on m rows touching c dofs with `block` multipliers per friction
    /// node: the dense dual while its memory is at most `DENSE_LIMIT`, else the sparse one.
    pub fn auto(m: usize, c: usize, block: usize) -> Contact {
        if resources::dense_dual_bytes(m, c, block) <= DENSE_LIMIT {
            Contact::Dense
        } else {
            Contact::Sparse
        }
    }
}

/// What the products with D of the duals without D are (`ContactPlan::cost`).
const PRODUCTS: &str = "two gradients and the conjugate gradient iterations; a rejected Newton \
                        point adds a damped or projected search";

/// How many Newton iterations a step takes (`ContactPlan::cost`).
const ITERATIONS: &str = "a step takes a few to tens of iterations";

/// A run's contact solver, its memory (bytes; None where not estimated) and cost per step.
#[derive(Clone, Debug, PartialEq)]
pub struct ContactPlan {
    pub solver: Contact,
    pub memory: Option<f64>,
    /// The predicted cost of a step, in words.
    pub cost: String,
    /// The scene's `solver.contact`, which `auto` resolved to `solver`.
    choice: ContactSolver,
    /// The dense dual's memory, which `auto` decided by.
    dense: f64,
    /// The sparse dual's memory, named when the chosen solver does not fit.
    sparse: f64,
}

impl ContactPlan {
    /// The plan of a run of `scene` on `disc`; None where it has no contact or friction rows
    /// (every step is a linear solve).
    pub fn of_run(scene: &Scene, disc: &Discretization) -> Option<Self> {
        let rows = Rows::new(&disc.contact, &disc.friction, disc.dim - 1);
        (!rows.is_empty()).then(|| Self::new(scene.solver.contact, &rows, disc.n_free))
    }

    /// The plan for the scene's `choice` on `rows` of a problem with n dofs.
    pub fn new(choice: ContactSolver, rows: &Rows, n: usize) -> Self {
        let (m, c) = (rows.len(), rows.dofs().len());
        let dense = resources::dense_dual_bytes(m, c, rows.block);
        let sparse = resources::matrix_free_bytes(m, n);
        let solver = Contact::of(choice, rows);
        let (m_f, products) = (m as f64, MatrixFreeSettings::default().cg_max + 2);
        let (memory, cost) = match solver {
            Contact::Dense => (
                Some(dense),
                format!(
                    "per Newton iteration at most one dense Cholesky factorization of ≤ {m} \
                     rows (m³/3 = {:.1e} flops) and products with D (2m² = {:.1e} flops \
                     each); a step takes a few to tens of iterations",
                    m_f.powi(3) / 3.0,
                    2.0 * m_f * m_f
                ),
            ),
            Contact::MatrixFree => (
                Some(sparse + resources::trailing_bytes(c)),
                format!(
                    "per Newton iteration {products} products with D at most ({PRODUCTS}) and \
                     as many with S = D⁻¹ for the preconditioner, each a pass down and up over \
                     the factor's trailing block L_CC (2c² = {:.1e} flops); {ITERATIONS}",
                    2.0 * (c as f64).powi(2)
                ),
            ),
            Contact::Sparse => (
                Some(sparse),
                format!(
                    "per Newton iteration {products} products with D at most ({PRODUCTS}), \
                     each a forward and backward solve with the factor of K_A over the \
                     supernodes that hold C and their ancestors (at most a linear step's \
                     solve); {ITERATIONS}"
                ),
            ),
            Contact::ActiveSet => (
                Some(resources::active_set_bytes(m, n)),
                "per Newton iteration one Krylov solve of the primal system (the step matrix with \
                 the active and sticking directions removed) preconditioned by a multigrid of \
                 that matrix, built at a step's first system and rebuilt where the sets change \
                 (a setup costs one or two solves); a step takes two or three Newton systems \
                 where the contact and slip sets stand in 2D (a loose solve, then the last to \
                 1e-12), about four in 3D where slipping nodes turn, tens where contact or \
                 sliding sets in"
                    .to_string(),
            ),
            Contact::Clarabel => (
                None,
                format!("an interior point solve of the whole problem ({n} + {m} unknowns)"),
            ),
        };
        ContactPlan {
            solver,
            memory,
            cost,
            choice,
            dense,
            sparse,
        }
    }

    /// Refuses (exit 2) a solver whose memory, with what the run's steps hold besides it
    /// (`steps`: both are held at once), exceeds `resources::MARGIN` of the memory available
    /// (`resources::available_memory`; unknown: it passes), naming `solver.contact =
    /// "sparse"` where that would fit, else the estimate's key where the solver alone fits.
    pub fn check(&self, steps: &Estimate) -> Result<()> {
        match resources::available_memory()? {
            Some(avail) => self.fits(avail, steps.memory, steps.memory_key()),
            None => Ok(()),
        }
    }

    /// `check` with `avail` bytes of memory available and `steps` bytes held by the steps,
    /// `key` the key that lowers them.
    fn fits(&self, avail: f64, steps: f64, key: &str) -> Result<()> {
        let Some(memory) = self.memory else {
            return Ok(());
        };
        if memory + steps <= MARGIN * avail {
            return Ok(());
        }
        let sparse_fits = self.sparse + steps <= MARGIN * avail;
        let remedy = if self.solver != Contact::Sparse && sparse_fits {
            format!(
                "set solver.contact = \"sparse\" (≈ {} besides the factor of K_A)",
                human(self.sparse)
            )
        } else if memory <= MARGIN * avail {
            format!("lower {key}")
        } else {
            "use a coarser mesh on the contact boundary".to_string()
        };
        let besides = match steps > 0.0 {
            true => format!(" besides the ≈ {} that the steps hold", human(steps)),
            false => String::new(),
        };
        Err(Error::input(format!(
            "the {} contact solver would need ≈ {} of memory{besides} but {} (a run may \
             plan {:.0} % of it): {remedy}",
            self.solver.key(),
            human(memory),
            resources::memory_phrase(avail),
            100.0 * MARGIN
        )))
    }

    /// A warning for a solver that can make a run take hours without saying so: the duals
    /// without D, whose steps where the body starts to slide take hundreds of solves with
    /// the factor of K_A (the plate with m = 16 055 rows: minutes to tens of minutes a step,
    /// docs/performance.md, "Large contact boundaries").
    pub fn slow_warning(&self) -> Option<String> {
        matches!(self.solver, Contact::Sparse | Contact::MatrixFree).then(|| {
            format!(
                "the contact solver is the {} dual ({}): a step where the body starts to \
                 slide can take hundreds of solves with the factor of K_A, minutes to tens of \
                 minutes each on a large contact boundary (docs/performance.md); time the \
                 first steps before planning a long run",
                self.solver.key(),
                self.reason()
            )
        })
    }

    /// Why this solver: the key that forced it, or `auto`'s rule.
    fn reason(&self) -> String {
        match (self.choice, self.solver) {
            (ContactSolver::Auto, Contact::Dense) => format!(
                "auto: its matrices ≈ {}, at most {}",
                human(self.dense),
                human(DENSE_LIMIT)
            ),
            (ContactSolver::Auto, _) => format!(
                "auto: the dense dual would need ≈ {}, over {}",
                human(self.dense),
                human(DENSE_LIMIT)
            ),
            _ => format!("solver.contact = \"{}\"", self.solver.key()),
        }
    }
}

/// The bytes of the values of the run's Cholesky factor of K_A, in its ordering, from its
/// symbolic analysis (`factor::predicted_bytes`); None where the run solves K_A through
/// PETSc. The implicit variant's step matrix has K_A's pattern, so the same analysis.
pub fn factor_bytes(scene: &Scene, disc: &Discretization) -> Result<Option<f64>> {
    if scene.solver.petsc() {
        return Ok(None);
    }
    let rows = Rows::new(&disc.contact, &disc.friction, disc.dim - 1);
    let last = Contact::of(scene.solver.contact, &rows).ordered_last(&rows);
    super::factor::predicted_bytes(&disc.k_a, &last).map(Some)
}

impl std::fmt::Display for ContactPlan {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        let memory = match (self.memory, self.solver) {
            (None, _) => "not estimated".to_string(),
            (Some(b), Contact::MatrixFree) => format!(
                "≈ {} besides the factor of a linear run (with the dense trailing block that \
                 ordering C last adds to it)",
                human(b)
            ),
            (Some(b), Contact::Sparse) => format!("≈ {} besides the factor of K_A", human(b)),
            (Some(b), Contact::ActiveSet) => format!(
                "≈ {} besides PETSc's three matrices of K_A's size (K_A, the Newton matrix and \
                 the copy its multigrid was built from) and two multigrid hierarchies",
                human(b)
            ),
            (Some(b), _) => format!("≈ {}", human(b)),
        };
        write!(
            f,
            "{} ({}): memory {memory}; {}",
            self.solver.key(),
            self.reason(),
            self.cost
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// With c = m, the 3D dense dual holds 8·4m² bytes: 4e9 between m = 11 180 and 11 181;
    /// the 2D one 8·3m² bytes, 4e9 between m = 12 909 and 12 910.
    #[test]
    fn auto_is_dense_up_to_the_limit_and_sparse_beyond() {
        assert_eq!(Contact::auto(11_180, 11_180, 2), Contact::Dense);
        assert_eq!(Contact::auto(11_181, 11_181, 2), Contact::Sparse);
        assert_eq!(Contact::auto(12_909, 12_909, 1), Contact::Dense);
        assert_eq!(Contact::auto(12_910, 12_910, 1), Contact::Sparse);
        // Issue 29's plates: the coarse one stays dense, the finer one has D alone of 2.1 GB.
        assert_eq!(Contact::auto(4_274, 4_274, 2), Contact::Dense);
        assert_eq!(Contact::auto(16_055, 16_055, 2), Contact::Sparse);
    }

    /// The key an estimate names for a run whose steps' memory does not fit.
    const KEY: &str = "time.steps";

    #[test]
    fn a_plan_that_does_not_fit_is_refused_naming_the_key_that_would() {
        let plan = |choice| ContactPlan {
            solver: Contact::Dense,
            memory: Some(1e9),
            cost: String::new(),
            choice,
            dense: 1e9,
            sparse: 1e6,
        };
        let forced = plan(ContactSolver::Dense);
        forced.fits(1.25e9, 0.0, KEY).unwrap();
        let err = forced.fits(1.2e9, 0.0, KEY).unwrap_err();
        assert_eq!(err.exit_code(), 2);
        assert!(
            err.to_string().contains("solver.contact = \"sparse\""),
            "{err}"
        );
        let err = forced.fits(1e6, 0.0, KEY).unwrap_err().to_string();
        assert!(err.contains("coarser mesh"), "{err}");
        // The steps' memory counts as well: each part fits alone, the two together do not.
        let err = forced.fits(1.25e9, 0.2e9, KEY).unwrap_err().to_string();
        assert!(
            err.contains("besides the ≈ 200.0 MB that the steps hold"),
            "{err}"
        );
        assert!(err.contains("solver.contact = \"sparse\""), "{err}");
        let err = forced.fits(1.25e9, 0.9999e9, KEY).unwrap_err().to_string();
        assert!(err.contains("lower time.steps"), "{err}");
        assert!(plan(ContactSolver::Auto)
            .to_string()
            .starts_with("dense (auto: "));
    }
}
