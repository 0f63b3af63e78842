//! Later checkpoints of a process: the first one's bytes with the variable data patched.

use super::h5::{h5_file, OpenMode};
use super::layout::Raw;
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
    pub(super) fn capture(path: &Path, bytes: Vec<u8>, data: &[(&str, Raw)]) -> Option<Template> {
        let regions = {
            let f = h5_file(OpenMode::Read, path).ok()?;
            let mut regions = Vec::with_capacity(data.len());
            for (name, raw) in data {
                let ds = f.dataset(name).ok()?;
                let len = raw.len();
                if len == 0 {
                    regions.push((0, 0));
                    continue;
                }
                let offset = ds.offset()? as usize;
                if ds.storage_size() as usize != len {
                    return None;
                }
                regions.push((offset, len));
            }
            regions
        };
        for ((offset, len), (_, raw)) in regions.iter().zip(data) {
            if offset + len > bytes.len() || !raw.is(&bytes[*offset..offset + len]) {
                return None;
            }
        }
        Some(Template { bytes, regions })
    }

    /// The file bytes for `data`, written where each dataset's raw data lies; None when
    /// the sizes no longer match.
    pub(super) fn patch(&mut self, data: &[(&str, Raw)]) -> Option<&mut [u8]> {
        if data.len() != self.regions.len() {
            return None;
        }
        for ((_, len), (_, raw)) in self.regions.iter().zip(data) {
            if *len != raw.len() {
                return None;
            }
        }
        for ((offset, len), (_, raw)) in self.regions.iter().zip(data) {
            raw.write_into(&mut self.bytes[*offset..offset + len]);
        }
        Some(&mut self.bytes)
    }
}
