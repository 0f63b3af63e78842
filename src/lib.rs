//! viscontact: quasi-static contact of viscoelastic bodies with long memory, solved by the
//! fully discrete scheme of Problem 3.1 in Xu, Wang, He, Chen, Han, Huang (2021): P1 finite
//! elements in space, the left endpoint rule for both history integrals in time.
//!
//! The modules follow the data flow of a run, one stage each (docs/architecture.md):
//! [`scene`] → [`mesh`] → [`fem`] (discretization) → [`effects`] → [`solver`] (the per-step
//! problem (3.1)) → [`time_loop`] (with [`history`]) → [`output`]; [`run`] drives them.

pub mod checkpoint;
pub mod console;
pub mod effects;
pub mod error;
pub mod expr;
pub mod fem;
pub mod history;
mod input_file;
pub mod kernel;
pub mod kernel_fit;
pub mod mesh;
pub mod output;
#[cfg(feature = "petsc")]
pub mod petsc;
pub mod plot;
pub mod ranges;
pub mod ranks;
pub mod resources;
pub mod run;
pub mod scene;
pub mod solver;
pub mod stability;
pub mod study;
pub mod threads;
pub mod time_loop;

#[cfg(test)]
mod testing;

pub use error::{Error, Result};
