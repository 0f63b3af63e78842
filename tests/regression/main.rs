//! Stored values of known-good runs, compared bit for bit (tests/data/golden.json).

#[path = "../common/mod.rs"]
mod common;

mod golden;
