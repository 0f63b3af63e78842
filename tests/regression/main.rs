//! Stored values of known-good runs, compared bit for bit (tests/data/golden.json), and the
//! same results bit for bit for every thread count.

#[path = "../common/mod.rs"]
mod common;

mod golden;
mod threads;
