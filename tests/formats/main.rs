//! The files a run writes, read back by independent readers (VTK, h5py, our own).

#[path = "../common/mod.rs"]
mod common;

mod format_checks;
mod output_format;
mod output_pieces;
mod output_vtkhdf;
mod regions;
