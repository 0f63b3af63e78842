//! Convergence in h and k: the paper's Tables 1-3 and the transfer between meshes they need.

#[path = "../common/mod.rs"]
mod common;

mod jobs;
mod study;
