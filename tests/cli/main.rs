//! The command line as a user meets it: bad input and its messages, extreme values, expressions, meshes, directories, plots.

#[path = "../common/mod.rs"]
mod common;

mod asked_for;
mod cli_errors;
mod conditions;
mod contact_plan;
mod docs;
mod expr_differential;
mod extreme_values;
mod hard_meshes;
mod mesh_checks;
mod mesh_import;
mod plot;
mod regions;
mod run_dir;
mod scene_reference;
mod streams;
