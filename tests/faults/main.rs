//! Faults: interrupted and killed runs resumed bit for bit, damaged files, signals during setup, fuzzed input.

#[path = "../common/mod.rs"]
mod common;

mod bad_data;
mod checkpoint;
mod fuzz;
mod repeated_signals;
mod resume_verify;
mod robustness;
mod setup_signals;
mod slurm_job;
