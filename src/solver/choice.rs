//! Which contact solver a run uses (`[solver] contact`), the memory it will hold and what a
//! step costs, from the sizes alone (m constraint rows on c dofs, n dofs).
//!
//! The dense condensed dual (`dual`) holds m × m matrices (D, B = D⁻¹ in 3D, the Newton
//! matrices) and factors a Newton matrix of up to m rows per iteration (m³/3 flops); the
//! matrix-free dual (`matrix_free`) holds O(m) besides the factor of K_A that every solver
//! holds, and pays a solve with that factor per product with D. `auto` takes the dense dual
//! while its memory (`resources::dense_dual_bytes`) is at most `COMFORT` of the memory
//! available, the matrix-free one otherwise: every contact boundary small enough for the
//! dense dual gets it, with the results it has always given.

use super::Rows;
use crate::resources::{self, human, MARGIN};
use crate::scene::ContactSolver;
use crate::{Error, Result};

/// The share of available memory up to which `auto` takes the dense dual.
pub const COMFORT: f64 = 0.5;

/// The solver a run uses with contact or friction.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Contact {
    Dense,
    MatrixFree,
    Clarabel,
}

impl Contact {
    /// The value of `solver.contact` that names it.
    pub fn key(&self) -> &'static str {
        match self {
            Contact::Dense => "dense",
            Contact::MatrixFree => "matrix_free",
            Contact::Clarabel => "clarabel",
        }
    }
}

/// A run's contact solver, its memory (bytes; None where not estimated) and cost per step.
#[derive(Clone, Debug, PartialEq)]
pub struct ContactPlan {
    pub solver: Contact,
    pub memory: Option<f64>,
    /// The predicted cost of a step, in words.
    pub cost: String,
    /// The matrix-free dual's memory, named when the chosen solver does not fit.
    matrix_free: f64,
    available: Option<f64>,
}

impl ContactPlan {
    /// The plan for the scene's `choice` on `rows` of a problem with n dofs on this machine
    /// (its available memory now, `resources::available_memory`).
    pub fn here(choice: ContactSolver, rows: &Rows, n: usize) -> Self {
        Self::new(choice, rows, n, resources::available_memory())
    }

    /// The plan for the scene's `choice` on `rows` of a problem with n dofs, with `available`
    /// bytes of memory (None: unknown, and `auto` takes the dense dual).
    pub fn new(choice: ContactSolver, rows: &Rows, n: usize, available: Option<f64>) -> Self {
        let (m, c) = (rows.len(), rows.dofs().len());
        let dense = resources::dense_dual_bytes(m, c, rows.block);
        let matrix_free = resources::matrix_free_bytes(m, n);
        let solver = match choice {
            ContactSolver::Dense => Contact::Dense,
            ContactSolver::MatrixFree => Contact::MatrixFree,
            ContactSolver::Clarabel => Contact::Clarabel,
            ContactSolver::Auto => match available {
                Some(avail) if dense > COMFORT * avail => Contact::MatrixFree,
                _ => Contact::Dense,
            },
        };
        let cube = (m as f64).powi(3) / 3.0;
        let (memory, cost) = match solver {
            Contact::Dense => (
                Some(dense),
                format!(
                    "per Newton iteration at most a dense factorization of {m} rows \
                     ({cube:.1e} flops) and products with D ({:.1e} flops); a few to tens \
                     of iterations a step",
                    (m * m) as f64
                ),
            ),
            Contact::MatrixFree => (
                Some(matrix_free),
                "per Newton iteration tens to hundreds of products with D, each a forward \
                 and a backward solve with the factor of K_A; a few to tens of iterations a \
                 step"
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
            matrix_free,
            available,
        }
    }

    /// Refuses (exit 2) a solver whose memory exceeds `resources::MARGIN` of the memory
    /// available, naming `solver.contact = "matrix_free"` where that would fit.
    pub fn check(&self) -> Result<()> {
        let (Some(memory), Some(avail)) = (self.memory, self.available) else {
            return Ok(());
        };
        if memory <= MARGIN * avail {
            return Ok(());
        }
        let remedy = if self.solver != Contact::MatrixFree && self.matrix_free <= MARGIN * avail {
            format!(
                "set solver.contact = \"matrix_free\" (≈ {} besides the factor of K_A)",
                human(self.matrix_free)
            )
        } else {
            "use a coarser mesh on the contact boundary".to_string()
        };
        Err(Error::input(format!(
            "the {} contact solver would need ≈ {} of memory but this machine has {} \
             available (a run may plan {:.0} % of it): {remedy}",
            self.solver.key(),
            human(memory),
            human(avail),
            100.0 * MARGIN
        )))
    }
}

impl std::fmt::Display for ContactPlan {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        let memory = self
            .memory
            .map_or("not estimated".to_string(), |b| format!("≈ {}", human(b)));
        write!(f, "{}: memory {memory}; {}", self.solver.key(), self.cost)
    }
}
