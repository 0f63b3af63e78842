//! Later checkpoints of a process: the first one's bytes with the variable data patched.

use super::h5::{h5_file, OpenMode};
use std::path::Path;

/// The first checkpoint of a run is written through the HDF5 library; every later one has
/// the same structure and differs only in the raw data of its variable datasets (contiguous
/// layout, fixed sizes: `/run/iterations` has one entry per step of the whole run, −1 for
/// steps not yet solved). So the file's bytes are kept with the offsets of those datasets
/// (H5Dget_offset), and a later checkpoint is the same bytes with the new values written at
/// those offsets: a valid HDF5 file (raw data carries no checksum) at the cost of a memory
/// copy instead of creating some fifty HDF5 objects. Whatever does not fit (a dataset
/// without an offset, a size that changed) falls back to the library.
pub(super) struct Template {
    pub(super) bytes: Vec<u8>,
    /// (offset, length) of each entry of [`variable_data`], in its order.
    pub(super) regions: Vec<(usize, usize)>,
}

impl Template {
    /// The file just written at `path`, whose bytes are `bytes`, with its variable
    /// datasets found; None when one is not contiguous with exactly the expected size.
    pub(super) fn capture(
        path: &Path,
        bytes: Vec<u8>,
        data: &[(&'static str, Vec<u8>)],
    ) -> Option<Template> {
        let regions = {
            let f = h5_file(OpenMode::Read, path).ok()?;
            let mut regions = Vec::with_capacity(data.len());
            for (name, bytes) in data {
                let ds = f.dataset(name).ok()?;
                if bytes.is_empty() {
                    regions.push((0, 0));
                    continue;
                }
                let offset = ds.offset()? as usize;
                if ds.storage_size() as usize != bytes.len() {
                    return None;
                }
                regions.push((offset, bytes.len()));
            }
            regions
        };
        for ((offset, len), (_, data)) in regions.iter().zip(data) {
            if offset + len > bytes.len() || bytes[*offset..offset + len] != data[..] {
                return None;
            }
        }
        Some(Template { bytes, regions })
    }

    /// The file bytes for `data`; None when the sizes no longer match.
    pub(super) fn patch(&mut self, data: &[(&'static str, Vec<u8>)]) -> Option<&mut [u8]> {
        if data.len() != self.regions.len() {
            return None;
        }
        for ((_, len), (_, d)) in self.regions.iter().zip(data) {
            if *len != d.len() {
                return None;
            }
        }
        for ((offset, len), (_, d)) in self.regions.iter().zip(data) {
            self.bytes[*offset..offset + len].copy_from_slice(d);
        }
        Some(&mut self.bytes)
    }
}
