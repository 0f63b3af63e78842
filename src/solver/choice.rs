//! The run's solver, resolved once: which contact solver a step with contact or friction
//! uses (`[solver] contact`), how the step matrix is solved (`[solver] linear`), what the
//! run builds for it (the stored Cholesky factor with the dofs it orders last, or PETSc's
//! KSP), the memory it will hold and what a step costs, from the problem alone (m
//! constraint rows on c dofs, n dofs, the factor's symbolic analysis). One [`Descriptor`]
//! carries all of it: `check` prints it, `run` and `resume` check it against the memory
//! available, the time loop builds what it names and `effects` warns from it.
//!
//! The dense condensed dual (`dual`) holds m × m matrices (D, B = D⁻¹ in 3D, the Newton
//! matrices) and factors a Newton matrix of up to m rows per iteration (m³/3 flops). The
//! two duals without D (`matrix_free`) pay a solve with the factor of K_A per product with
//! D: `matrix_free` orders C last, and its factor then holds the dense trailing block L_CC
//! (the Schur complement's factor, which also preconditions); `sparse` keeps the factor of a
//! linear run and holds O(m) besides it. The active-set solver (`active_set`, on PETSc)
//! builds neither a factor nor an m × m matrix.
//!
//! `auto` decides from the problem alone, never from the machine, so a scene runs the same
//! solver, and gives the same bits, on every machine and at every resume (`auto`):
//! - with contact or friction rows, the dense dual while its memory
//!   (`resources::dense_dual_bytes`) is at most `DENSE_LIMIT` and, in a build with the
//!   `petsc` feature, the values of its factor of K_A (`factor::predicted_bytes`, C ordered
//!   last) at most `FACTOR_LIMIT`; beyond either limit the active-set solver on PETSc in a
//!   build with it, the sparse dual on the stored factor in a build without it;
//! - without them (`solver.linear = "auto"`), the stored factor, or in a build with PETSc
//!   its Krylov method where the factor's values exceed `FACTOR_LIMIT`.
//!
//! The factor's symbolic analysis is asked for only where the answer depends on it: in a
//! build with PETSc, and where even a dense factor of the n dofs could exceed the limit
//! (4n(n + 1) bytes > `FACTOR_LIMIT`, n > 44 720). A build without PETSc says in `check`
//! where the build with it would pick otherwise, and how to get it. A key other than
//! `auto` is obeyed. Whether the plan fits this machine is a separate question, asked by
//! `ContactPlan::check` before a run touches its directory: a plan that does not fit is
//! refused (exit 2), naming the key that would, never silently changed.

use super::active_set::ActiveSetSettings;
use super::matrix_free::MatrixFreeSettings;
use super::Rows;
use crate::fem::Discretization;
use crate::resources::{self, human, Estimate, MARGIN};
use crate::scene::{ContactSolver, LinearSolver, Scene};
use crate::{Error, Result};

/// The dense dual's memory (bytes) up to which `auto` takes it: 4 GB, m ≈ 11 180 rows in 3D
/// (8·4m² bytes where c ≈ m). The coarse plate of issue 29 (m = 4 274, 0.58 GB) and the block
/// at h = 1/48 (m ≈ 7 400, ≈ 1.8 GB) stay dense; the finer plate (m = 16 055: D alone 2.1
/// GB, with B = D⁻¹ and the Newton matrices ≈ 8 GB) goes beyond it (to the active-set
/// solver in a build with PETSc, to the sparse dual without). 4 GB leaves room for the
/// factor of K_A and the run's own state on a 16 GB workstation; a larger dense dual needs a
/// large machine, where `solver.contact = "dense"` asks for it.
pub const DENSE_LIMIT: f64 = 4e9;

/// The values of the Cholesky factor of the step matrix (bytes, from its symbolic analysis,
/// `factor::predicted_bytes`) up to which `auto` keeps the stored factor in a build with
/// PETSc: 8 GB. The fine plate of issue 50 (size 0.015, 367 470 dofs: 3.2 GB of values, its
/// linear run's peak 4.4 GB, 20 steps in 32.7 s on two cores) stays on the factor, which is
/// faster wherever it fits (docs/performance.md); the plate at size 0.01 (1 162 293 dofs:
/// 16.9 GB of values by its symbolic analysis) goes to PETSc. A run's peak is about
/// 1.4× its factor's values (4.4 / 3.2 GB on the plate), so the limit is a run of ≈ 11 GB:
/// within a 16 GB workstation with the run's own state, as `DENSE_LIMIT` is. Like it, a
/// property of the problem, not of the machine.
pub const FACTOR_LIMIT: f64 = 8e9;

/// Whether this build has PETSc (the cargo feature `petsc`).
pub const PETSC_BUILD: bool = cfg!(feature = "petsc");

/// How to get a build with PETSc (docs/scene.md, "Building with PETSc").
pub const PETSC_HOW: &str = "install PETSc's development files (Debian 12: `apt-get install \
                             --no-install-recommends petsc-dev`) and build with \
                             `HDF5_DIR=/usr/lib/x86_64-linux-gnu/hdf5/serial cargo build \
                             --release --features petsc` (docs/scene.md, \"Building with \
                             PETSc\")";

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

    /// The solver a key other than `auto` names.
    fn named(key: ContactSolver) -> Option<Contact> {
        match key {
            ContactSolver::Auto => None,
            ContactSolver::Dense => Some(Contact::Dense),
            ContactSolver::MatrixFree => Some(Contact::MatrixFree),
            ContactSolver::Sparse => Some(Contact::Sparse),
            ContactSolver::Clarabel => Some(Contact::Clarabel),
            ContactSolver::ActiveSet => Some(Contact::ActiveSet),
        }
    }
}

/// How a run solves its step matrix (`solver.linear`, resolved).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Linear {
    /// The stored Cholesky factor.
    Cholesky,
    /// PETSc's Krylov method with algebraic multigrid.
    Petsc,
}

impl Linear {
    /// The value of `solver.linear` that names it.
    pub fn key(&self) -> &'static str {
        match self {
            Linear::Cholesky => "cholesky",
            Linear::Petsc => "petsc",
        }
    }
}

/// What a run builds to solve its step matrix.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Build {
    /// The stored Cholesky factor, with these dofs (sorted) ordered last
    /// (`Contact::ordered_last`).
    Factor { last: Vec<usize> },
    /// Nothing: clarabel assembles and factors its own whole step problem.
    Nothing,
    /// PETSc's KSP of the step matrix (`crate::petsc::Krylov`); `newton`: for the active
    /// set's Newton systems alone (their multigrid is set up, K_A's own KSP never solves).
    Krylov { newton: bool },
}

/// Why a solver was chosen: the scene's key, or `auto`'s rule with the size it decided by.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Why {
    /// The scene's key names it.
    Key,
    /// `auto`: the dense dual's matrices take these bytes, at most `DENSE_LIMIT` (and, in a
    /// build with PETSc, its factor's values at most `FACTOR_LIMIT`).
    DenseFits(f64),
    /// `auto`: the dense dual would need these bytes, over `DENSE_LIMIT`.
    DenseOver(f64),
    /// `auto`: the factor's values would need these bytes, over `FACTOR_LIMIT`.
    FactorOver(f64),
    /// `auto` in a build with PETSc: the factor's values within `FACTOR_LIMIT` (None: n so
    /// small that even a dense factor would be), or `auto` without PETSc: the stored factor.
    FactorFits(Option<f64>),
    /// `auto` where the other key asks for PETSc: `solver.linear = "petsc"` (the contact
    /// solver is the active-set one) or `solver.contact = "active_set"` (the step matrix
    /// is solved by PETSc).
    OtherKey,
    /// `solver.linear = "auto"` with a contact solver that works with the stored factor.
    NeedsFactor,
}

/// `auto`'s rule on a problem whose dense dual would need `dense` bytes (None: no contact
/// or friction rows, a linear run), in a build with PETSc or without (`petsc`). `factor`
/// gives the bytes of the values of the factor that the stored-factor choice would build
/// (C ordered last for the dense dual; a linear run's order without rows), None where even
/// a dense factor would be within `FACTOR_LIMIT`; it is asked only in a build with PETSc
/// where the dense dual fits or there are no rows. Returns the contact solver (None without
/// rows), the linear backend and why.
pub fn auto(
    dense: Option<f64>,
    petsc: bool,
    factor: impl FnOnce() -> Result<Option<f64>>,
) -> Result<(Option<Contact>, Linear, Why)> {
    let contact = dense.is_some();
    if let Some(d) = dense.filter(|&d| d > DENSE_LIMIT) {
        return Ok(match petsc {
            true => (Some(Contact::ActiveSet), Linear::Petsc, Why::DenseOver(d)),
            false => (Some(Contact::Sparse), Linear::Cholesky, Why::DenseOver(d)),
        });
    }
    let factor = match petsc {
        true => factor()?,
        false => None,
    };
    if let Some(f) = factor.filter(|&f| f > FACTOR_LIMIT) {
        let solver = contact.then_some(Contact::ActiveSet);
        return Ok((solver, Linear::Petsc, Why::FactorOver(f)));
    }
    Ok(match dense {
        Some(d) => (Some(Contact::Dense), Linear::Cholesky, Why::DenseFits(d)),
        None => (None, Linear::Cholesky, Why::FactorFits(factor)),
    })
}

/// Whether a factor of n dofs could have more than `FACTOR_LIMIT` bytes of values: a dense
/// one has n(n + 1)/2 (n > 44 720). Below, `auto` needs no symbolic analysis.
fn factor_may_exceed(n: usize) -> bool {
    4.0 * n as f64 * (n as f64 + 1.0) > FACTOR_LIMIT
}

/// The run's solver, resolved once from the scene and its discretization (see the module
/// doc): the contact solver and its plan, the linear backend and what the run builds.
#[derive(Clone, Debug)]
pub struct Descriptor {
    /// The contact solver's plan; None for a run without contact or friction rows (every
    /// step is a linear solve).
    contact: Option<ContactPlan>,
    linear: Linear,
    /// Why `linear`.
    linear_why: Why,
    build: Build,
    /// The bytes of the values of the factor with these dofs last, where known.
    factor: Option<(Vec<usize>, f64)>,
    /// The dense dual's bytes where both keys are `auto` (what the build with PETSc would
    /// decide by); None otherwise.
    both_auto: Option<Option<f64>>,
    /// `[solver.active_set]` over its defaults (used where the contact solver is that one).
    active_set: ActiveSetSettings,
}

impl Descriptor {
    /// Resolves the scene's `[solver]` keys on `disc` (`auto` by `auto`'s rule).
    pub fn of_run(scene: &Scene, disc: &Discretization) -> Result<Self> {
        let rows = Rows::new(&disc.contact, &disc.friction, disc.dim - 1);
        let has_rows = !rows.is_empty();
        let dense = has_rows
            .then(|| resources::dense_dual_bytes(rows.len(), rows.dofs().len(), rows.block));
        let mut known = None;
        // Without rows a contact solver other than the active set (which asks for PETSc) is
        // no choice: the step is linear, and `solver.linear = "auto"` decides alone.
        let contact_key = match (has_rows, scene.solver.contact) {
            (false, key) if key != ContactSolver::ActiveSet => ContactSolver::Auto,
            (_, key) => key,
        };
        let (contact, linear, why, linear_why) = match (contact_key, scene.solver.linear) {
            (contact, LinearSolver::Petsc) => {
                let (solver, why) = match Contact::named(contact) {
                    Some(c) => (c, Why::Key),
                    None => (Contact::ActiveSet, Why::OtherKey),
                };
                (Some(solver), Linear::Petsc, why, Why::Key)
            }
            (ContactSolver::ActiveSet, _) => (
                Some(Contact::ActiveSet),
                Linear::Petsc,
                Why::Key,
                Why::OtherKey,
            ),
            (ContactSolver::Auto, LinearSolver::Cholesky) => {
                let (c, l, why) = auto(dense, false, || Ok(None))?;
                (c, l, why, Why::Key)
            }
            (ContactSolver::Auto, LinearSolver::Auto) => {
                let last = rows.dofs();
                let (c, l, why) = auto(dense, PETSC_BUILD, || {
                    if !factor_may_exceed(disc.n_free) {
                        return Ok(None);
                    }
                    let bytes = super::factor::predicted_bytes(&disc.k_a, &last)?;
                    known = Some((last.clone(), bytes));
                    Ok(Some(bytes))
                })?;
                (c, l, why, why)
            }
            (named, linear) => {
                let why = match linear {
                    LinearSolver::Cholesky => Why::Key,
                    _ => Why::NeedsFactor,
                };
                (Contact::named(named), Linear::Cholesky, Why::Key, why)
            }
        };
        // A run without rows has no contact solver, whatever the key.
        let contact = contact.filter(|_| has_rows);
        let build = match (linear, contact) {
            (_, Some(Contact::Clarabel)) => Build::Nothing,
            (Linear::Petsc, contact) => Build::Krylov {
                newton: contact == Some(Contact::ActiveSet),
            },
            (Linear::Cholesky, contact) => Build::Factor {
                last: contact.map_or(Vec::new(), |c| c.ordered_last(&rows)),
            },
        };
        let both_auto = (contact_key == ContactSolver::Auto
            && scene.solver.linear == LinearSolver::Auto)
            .then_some(dense);
        Ok(Descriptor {
            contact: contact.map(|c| ContactPlan::new(c, why, &rows, disc)),
            linear,
            linear_why,
            build,
            factor: known,
            both_auto,
            active_set: ActiveSetSettings::from_keys(&scene.solver.active_set),
        })
    }

    /// The contact solver's plan; None for a linear run.
    pub fn contact(&self) -> Option<&ContactPlan> {
        self.contact.as_ref()
    }

    /// The contact solver; None for a linear run.
    pub fn contact_solver(&self) -> Option<Contact> {
        self.contact.as_ref().map(|p| p.solver)
    }

    /// The active-set solver's settings (`[solver.active_set]`).
    pub fn active_set(&self) -> ActiveSetSettings {
        self.active_set
    }

    /// The linear backend.
    pub fn linear(&self) -> Linear {
        self.linear
    }

    /// What the run builds for its step matrix.
    pub fn build(&self) -> &Build {
        &self.build
    }

    /// Whether the run spreads over MPI ranks (docs/cluster.md): its steps are PETSc's
    /// Krylov solves (`solver.linear = "petsc"`: K_A's, or the active set's Newton
    /// systems), whose KSPs span the ranks.
    pub fn spreads(&self) -> bool {
        matches!(self.build, Build::Krylov { .. })
    }

    /// The bytes of the values of the run's Cholesky factor of K_A, in its ordering, from
    /// its symbolic analysis (`factor::predicted_bytes`; once, kept); None where the run
    /// solves K_A through PETSc. The implicit variant's step matrix has K_A's pattern, so
    /// the same analysis.
    pub fn factor_bytes(&mut self, disc: &Discretization) -> Result<Option<f64>> {
        let Build::Factor { last } = &self.build else {
            return Ok(None);
        };
        if let Some((known, bytes)) = &self.factor {
            if known == last {
                return Ok(Some(*bytes));
            }
        }
        let bytes = super::factor::predicted_bytes(&disc.k_a, last)?;
        self.factor = Some((last.clone(), bytes));
        Ok(Some(bytes))
    }

    /// Where `auto` took PETSc's Krylov method for a large problem (n > 44 720, where a
    /// factor could exceed `FACTOR_LIMIT`): the bytes of the values of the stored factor it
    /// avoided, in a linear run's order (`check` prints them beside its `factor` line; the
    /// analysis takes seconds where the factorization would take minutes). None otherwise.
    pub fn avoided_factor(&mut self, disc: &Discretization) -> Result<Option<f64>> {
        let by_auto = !matches!(self.linear_why, Why::Key | Why::OtherKey);
        if !matches!(self.build, Build::Krylov { .. })
            || !by_auto
            || !factor_may_exceed(disc.n_free)
        {
            return Ok(None);
        }
        match &self.factor {
            Some((_, bytes)) => Ok(Some(*bytes)),
            None => super::factor::predicted_bytes(&disc.k_a, &[]).map(Some),
        }
    }

    /// In a build without PETSc, where `auto` would pick otherwise in the build with it:
    /// what it would pick, why, and how to get that build (`check` prints it). None in a
    /// build with PETSc, where a key decided, or where both builds pick the same.
    pub fn with_petsc(&mut self, disc: &Discretization) -> Result<Option<String>> {
        let Some(dense) = self.both_auto.filter(|_| !PETSC_BUILD) else {
            return Ok(None);
        };
        let n = disc.n_free;
        let factor = match dense.is_some_and(|d| d > DENSE_LIMIT) || !factor_may_exceed(n) {
            true => None,
            false => self.factor_bytes(disc)?,
        };
        let (contact, linear, why) = auto(dense, true, || Ok(factor))?;
        if linear == self.linear && contact == self.contact_solver() {
            return Ok(None);
        }
        let what = match contact {
            Some(c) => format!("solver.contact = \"{}\"", c.key()),
            None => format!("solver.linear = \"{}\"", linear.key()),
        };
        Ok(Some(format!(
            "a build with PETSc would pick {what} ({}); to get it, {PETSC_HOW}",
            reason(why, contact.map_or("", |c| c.key()))
        )))
    }

    /// `check`'s `solver` line: what a step is and what the run builds for it.
    pub fn summary(&self, disc: &Discretization) -> String {
        match (&self.contact, self.linear) {
            (None, Linear::Petsc) => format!(
                "linear (one Krylov solve per step by PETSc, CG + GAMG unless [solver.petsc] \
                 options or PETSC_OPTIONS change it; K_A is not factored{})",
                self.linear_reason()
            ),
            (None, Linear::Cholesky) => format!(
                "linear (one solve with the stored Cholesky factor of K_A per step{})",
                self.linear_reason()
            ),
            (Some(_), _) => format!(
                "contact solver on {} Γ3,1 rows + {} Γ3,2 rows (nodes × tangents)",
                disc.contact.len(),
                disc.friction.len()
            ),
        }
    }

    /// Why the linear backend, where `auto` decided by a size: "; auto: …".
    fn linear_reason(&self) -> String {
        match self.linear_why {
            Why::FactorOver(_) => format!("; {}", reason(self.linear_why, "")),
            _ => String::new(),
        }
    }

    /// The name of the linear backend and why, for `check`'s `factor` line where the run
    /// builds no factor.
    pub fn krylov_line(&self) -> Option<String> {
        if self.build == Build::Nothing {
            return Some("none: clarabel factors its own step problem, K_A is not factored".into());
        }
        matches!(self.build, Build::Krylov { .. }).then(|| {
            let why = match self.linear_why {
                Why::Key => "solver.linear = \"petsc\"".to_string(),
                Why::OtherKey => "solver.contact = \"active_set\"".to_string(),
                w => reason(w, ""),
            };
            format!("none: K_A is solved by PETSc's Krylov method ({why})")
        })
    }
}

/// The words for `why` (`key` the solver's key, for `Why::Key`).
fn reason(why: Why, key: &str) -> String {
    match why {
        Why::DenseFits(dense) => format!(
            "auto: its matrices ≈ {}, at most {}",
            human(dense),
            human(DENSE_LIMIT)
        ),
        Why::DenseOver(dense) => format!(
            "auto: the dense dual would need ≈ {}, over {}",
            human(dense),
            human(DENSE_LIMIT)
        ),
        Why::FactorOver(f) => format!(
            "auto: the Cholesky factor of K_A would need ≈ {} for its values, over {}",
            human(f),
            human(FACTOR_LIMIT)
        ),
        Why::FactorFits(Some(f)) => format!(
            "auto: the Cholesky factor of K_A ≈ {} for its values, at most {}",
            human(f),
            human(FACTOR_LIMIT)
        ),
        Why::FactorFits(None) | Why::NeedsFactor => "auto".to_string(),
        Why::OtherKey => "auto with solver.linear = \"petsc\"".to_string(),
        Why::Key => format!("solver.contact = \"{key}\""),
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
    /// Why this solver: the key, or `auto`'s rule.
    why: Why,
    /// The dense dual's memory, which `auto` decided by.
    dense: f64,
    /// The sparse dual's memory, named when the chosen solver does not fit.
    sparse: f64,
}

impl ContactPlan {
    /// The plan of `solver`, chosen for `why`, on `rows` of the problem `disc`.
    pub fn new(solver: Contact, why: Why, rows: &Rows, disc: &Discretization) -> Self {
        let (m, c, n) = (rows.len(), rows.dofs().len(), disc.n_free);
        let dense = resources::dense_dual_bytes(m, c, rows.block);
        let sparse = resources::matrix_free_bytes(m, n);
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
                Some(resources::active_set_bytes(m, n, disc.k_a.compute_nnz())),
                "per Newton iteration one Krylov solve of the primal system (the step matrix with \
                 the active and sticking directions removed) preconditioned by a multigrid of \
                 that matrix, made from K_A's at a step's first system and updated where the \
                 sets change (an update costs a fraction of a solve); a step takes three to \
                 five Newton systems where the contact and slip sets stand (solves to 1/100 \
                 of their initial residual, then the last to 1e-12), tens where contact or \
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
            why,
            dense,
            sparse,
        }
    }

    /// Refuses (exit 2) a solver whose memory, with what the run's steps hold besides it
    /// (`steps`: both are held at once), exceeds `resources::MARGIN` of the memory available
    /// (`resources::available_memory`; unknown: it passes), naming `solver.contact =
    /// "sparse"` where that would fit, else the estimate's key where the solver alone fits;
    /// in a build without PETSc where `auto` left the dense dual by its size, the build with
    /// PETSc too, whose `auto` picks the active-set solver.
    pub fn check(&self, steps: &Estimate) -> Result<()> {
        match resources::available_memory()? {
            Some(avail) => self.fits(avail, steps.memory(), steps.memory_key()),
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
        let remedy = match (PETSC_BUILD, self.why) {
            (false, Why::DenseOver(_)) => format!(
                "{remedy}; or use a build with PETSc, whose auto picks the active-set solver \
                 (no factor, no m × m matrix): {PETSC_HOW}"
            ),
            _ => remedy,
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
        reason(self.why, self.solver.key())
    }
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
                "≈ {} with PETSc's three matrices of K_A's size (K_A, the Newton matrix and the \
                 copy its multigrid was built from), that multigrid's hierarchy and K_A's coarse \
                 operators, estimated",
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

    /// `auto`'s contact solver on m rows over c dofs with `block` tangents per friction
    /// node, in a build with PETSc or without, whose factor (where asked) has `factor`
    /// bytes of values.
    fn pick(m: usize, c: usize, block: usize, petsc: bool, factor: f64) -> Contact {
        let dense = resources::dense_dual_bytes(m, c, block);
        auto(Some(dense), petsc, || Ok(Some(factor)))
            .unwrap()
            .0
            .unwrap()
    }

    /// With c = m, the 3D dense dual holds 8·4m² bytes: 4e9 between m = 11 180 and 11 181;
    /// the 2D one 8·3m² bytes, 4e9 between m = 12 909 and 12 910.
    #[test]
    fn auto_is_dense_up_to_the_limit_and_sparse_beyond() {
        let small = 1e6;
        assert_eq!(pick(11_180, 11_180, 2, false, small), Contact::Dense);
        assert_eq!(pick(11_181, 11_181, 2, false, small), Contact::Sparse);
        assert_eq!(pick(12_909, 12_909, 1, false, small), Contact::Dense);
        assert_eq!(pick(12_910, 12_910, 1, false, small), Contact::Sparse);
        // Issue 29's plates: the coarse one stays dense, the finer one has D alone of 2.1 GB.
        assert_eq!(pick(4_274, 4_274, 2, false, small), Contact::Dense);
        assert_eq!(pick(16_055, 16_055, 2, false, small), Contact::Sparse);
        // Without PETSc the factor's size is never asked for: the stored factor is all
        // there is.
        let (c, l, _) = auto(Some(1e6), false, || panic!("asked")).unwrap();
        assert_eq!((c, l), (Some(Contact::Dense), Linear::Cholesky));
    }

    /// With PETSc, `auto` leaves the stored factor where the dense dual exceeds
    /// `DENSE_LIMIT` (without asking for the factor) or the factor's values exceed
    /// `FACTOR_LIMIT`: the fine plate (m = 16 055) goes to the active set, the coarse one
    /// (m = 4 274, its factor far below) stays dense, as does a factor of 3.2 GB (the fine
    /// plate's, were its D small); 16.9 GB (the plate at size 0.01) does not.
    #[test]
    fn auto_with_petsc_takes_the_active_set_beyond_either_limit() {
        let petsc = |m, factor| pick(m, m, 2, true, factor);
        assert_eq!(petsc(11_180, 1e6), Contact::Dense);
        assert_eq!(petsc(11_181, 1e6), Contact::ActiveSet);
        assert_eq!(petsc(16_055, 1e6), Contact::ActiveSet);
        assert_eq!(petsc(4_274, 3.2e9), Contact::Dense);
        assert_eq!(petsc(4_274, FACTOR_LIMIT), Contact::Dense);
        assert_eq!(petsc(4_274, FACTOR_LIMIT * 1.0001), Contact::ActiveSet);
        assert_eq!(petsc(4_274, 20e9), Contact::ActiveSet);
        let over = resources::dense_dual_bytes(11_181, 11_181, 2);
        let (c, l, why) = auto(Some(over), true, || panic!("asked")).unwrap();
        assert_eq!(
            (c, l, why),
            (
                Some(Contact::ActiveSet),
                Linear::Petsc,
                Why::DenseOver(over)
            )
        );
        // A run without rows: `solver.linear = "auto"` takes PETSc over the limit only,
        // and only in a build with it; a small problem (None) keeps the factor.
        let linear = |petsc, f| auto(None, petsc, || Ok(f)).unwrap();
        assert_eq!(
            linear(true, Some(20e9)),
            (None, Linear::Petsc, Why::FactorOver(20e9))
        );
        assert_eq!(linear(true, Some(3.2e9)).1, Linear::Cholesky);
        assert_eq!(linear(true, None).1, Linear::Cholesky);
        assert_eq!(linear(false, Some(20e9)).1, Linear::Cholesky);
        // Even a dense factor of 44 720 dofs is within the limit: no analysis asked.
        assert!(!factor_may_exceed(44_720));
        assert!(factor_may_exceed(44_721));
    }

    /// The key an estimate names for a run whose steps' memory does not fit.
    const KEY: &str = "time.steps";

    #[test]
    fn a_plan_that_does_not_fit_is_refused_naming_the_key_that_would() {
        let plan = |why| ContactPlan {
            solver: Contact::Dense,
            memory: Some(1e9),
            cost: String::new(),
            why,
            dense: 1e9,
            sparse: 1e6,
        };
        let forced = plan(Why::Key);
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
        assert!(plan(Why::DenseFits(1e9))
            .to_string()
            .starts_with("dense (auto: "));
    }
}
