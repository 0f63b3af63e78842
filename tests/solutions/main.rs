//! Exact solutions, patch tests, the fast contact solver against clarabel, compressed kernels against exact sums.

#[path = "../common/mod.rs"]
mod common;

mod columns;
mod contact;
mod corner;
mod dirichlet;
mod force_balance;
mod friction_cone;
mod matrix_free;
mod memory;
mod patch;
mod punch;
mod regions;
mod three_d;
mod uniaxial_bar;
