//! Later checkpoints of a process: the last one's file, copied with the variable data patched.

use super::h5::{h5_file, OpenMode};
use super::layout::Raw;
use super::seal::{Sealing, CHUNK, USERBLOCK};
use std::fs::File;
use std::io::Write;
use std::os::unix::fs::FileExt;
use std::path::Path;

/// The first checkpoint of a run is written through the HDF5 library; every later one has
/// the same structure and differs only in the raw data of its variable datasets (contiguous
/// layout, fixed sizes: `/run/iterations` has one entry per step of the whole run, −1 for
/// steps not yet solved). So the writer keeps the file's length and the offsets of those
/// datasets (H5Dget_offset), and a later checkpoint is the last one's bytes with the new
/// values written at those offsets: a valid HDF5 file (raw data carries no checksum) at the
/// cost of a copy instead of creating some fifty HDF5 objects. The copy streams a chunk at a
/// time ([`CHUNK`]), the last file's CRC checked and the new one computed on the way, so the
/// writer holds no copy of the file (it held the first file's bytes, the size of the
/// state, for the whole run: docs/restart.md, "Checkpoint cost"). Whatever does not fit (a
/// dataset without an offset, a size that changed, a last file that is not as sealed)
/// falls back to the library.
pub(super) struct Template {
    len: usize,
    /// (offset, length) of each entry of [`variable_data`], in its order.
    ///
    /// [`variable_data`]: super::layout::variable_data
    regions: Vec<(usize, usize)>,
}

impl Template {
    /// The sealed file just written at `path` with its variable datasets found; None when
    /// one is not contiguous with exactly the expected size and bytes.
    pub(super) fn capture(path: &Path, data: &[(&str, Raw)]) -> Option<Template> {
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
        let file = File::open(path).ok()?;
        let len = file.metadata().ok()?.len() as usize;
        let (mut found, mut expected) = (Vec::new(), Vec::new());
        for ((offset, len_r), (_, raw)) in regions.iter().zip(data) {
            if offset + len_r > len {
                return None;
            }
            // The Prony states came one at a time and are gone: their CRC stands for them.
            let mut crc = crc32fast::Hasher::new();
            for from in (0..*len_r).step_by(CHUNK) {
                let n = CHUNK.min(len_r - from);
                found.resize(n, 0);
                file.read_exact_at(&mut found, (offset + from) as u64)
                    .ok()?;
                if let Raw::States(_) = raw {
                    crc.update(&found);
                    continue;
                }
                expected.resize(n, 0);
                raw.write_range(from, &mut expected).ok()?;
                if found != expected {
                    return None;
                }
            }
            if let Raw::States(states) = raw {
                if states.crc() != Some(crc.finalize()) {
                    return None;
                }
            }
        }
        Some(Template { len, regions })
    }

    /// Whether `data` has the sizes this template was captured with.
    pub(super) fn fits(&self, data: &[(&str, Raw)]) -> bool {
        data.len() == self.regions.len()
            && (self.regions.iter().zip(data)).all(|((_, len), (_, raw))| *len == raw.len())
    }

    /// Writes at `to` the checkpoint `last` (the last one written, sealed) with `data` (of
    /// the sizes [`Template::fits`] checked), and seals it. Ok(false) where `last` cannot be
    /// read or is not as sealed: the caller writes through HDF5. Before any of `data` is
    /// taken where `last` cannot be opened or has another length; otherwise once all was
    /// taken, `to` then holding every value where its dataset lies but not sealed (the Prony
    /// states, which came one at a time, are read back from there: `Disk::write`).
    pub(super) fn write(
        &self,
        last: &Path,
        to: &Path,
        data: &[(&str, Raw)],
    ) -> std::io::Result<bool> {
        let Ok(from) = File::open(last) else {
            return Ok(false);
        };
        if from.metadata().map(|m| m.len() as usize).ok() != Some(self.len) {
            return Ok(false);
        }
        let mut out = File::create(to)?;
        let (mut old, mut new) = (Sealing::checkpoint(self.len), Sealing::checkpoint(self.len));
        let mut chunk = vec![0u8; CHUNK.min(self.len)];
        let mut block = [0u8; USERBLOCK];
        let mut intact = true;
        for at in (0..self.len).step_by(CHUNK) {
            let part = &mut chunk[..CHUNK.min(self.len - at)];
            intact = intact && from.read_exact_at(part, at as u64).is_ok();
            if intact {
                old.feed(at, part);
            }
            if at == 0 {
                block.copy_from_slice(&part[..USERBLOCK]);
            }
            self.patch(at, part, data)?;
            new.feed(at, part);
            out.write_all(part)?;
        }
        if !intact || !old.seals(&block) {
            return Ok(false);
        }
        out.write_all_at(&new.block(), 0)?;
        Ok(true)
    }

    /// Where the `i`-th entry of the data lies in the file.
    pub(super) fn offset(&self, i: usize) -> usize {
        self.regions[i].0
    }

    /// Writes into `part`, the file's bytes from `at`, the values of `data` that fall there.
    fn patch(&self, at: usize, part: &mut [u8], data: &[(&str, Raw)]) -> std::io::Result<()> {
        let end = at + part.len();
        for ((offset, len), (_, raw)) in self.regions.iter().zip(data) {
            let (lo, hi) = (at.max(*offset), end.min(offset + len));
            if lo < hi {
                raw.write_range(lo - offset, &mut part[lo - at..hi - at])?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::checkpoint::seal::{seal_checkpoint, verify_checkpoint};
    use crate::checkpoint::vectors::Vectors;

    /// A later checkpoint is the last file with the values written where their datasets
    /// lie (the Prony states as they come), also across a chunk's end, and sealed; a last
    /// file whose bytes no longer match its CRC is not copied (the writer then uses HDF5),
    /// the states taken and left where they lie in the unsealed copy, nor one whose length
    /// changed, the states left in their queue.
    #[test]
    fn the_last_file_is_copied_with_the_values_patched_and_sealed_unless_it_was_damaged() {
        let dir = tempfile::tempdir().unwrap();
        let (last, to) = (dir.path().join("last.h5"), dir.path().join("to.h5"));
        let len = CHUNK + 4096;
        let mut bytes: Vec<u8> = (0..len).map(|i| (i * 7 % 251) as u8).collect();
        seal_checkpoint(&mut bytes);
        std::fs::write(&last, &bytes).unwrap();
        let values = [1.5, -2.25, 3e300];
        let regions = vec![(CHUNK - 8, 24), (600, 0), (1000, 2)];
        let template = Template { len, regions };
        let queued = || {
            let (tx, states) = Vectors::queue(1, 3);
            values.iter().for_each(|&x| tx.send(vec![x]).unwrap());
            states
        };
        let states = queued();
        let data = |states| {
            [
                ("x", Raw::States(states)),
                ("empty", Raw::Bytes(Vec::new())),
                ("flags", Raw::Bytes(vec![9, 8])),
            ]
        };
        assert!(template.fits(&data(&states)));
        assert!(template.write(&last, &to, &data(&states)).unwrap());
        let written = std::fs::read(&to).unwrap();
        verify_checkpoint(&written).unwrap();
        let mut expected = bytes.clone();
        let le: Vec<u8> = values.iter().flat_map(|x| x.to_le_bytes()).collect();
        expected[CHUNK - 8..CHUNK + 16].copy_from_slice(&le);
        expected[1000..1002].copy_from_slice(&[9, 8]);
        seal_checkpoint(&mut expected);
        assert!(written == expected);
        // One flipped bit in the last file: not copied, the states where they lie in `to`.
        bytes[CHUNK + 100] ^= 4;
        std::fs::write(&last, &bytes).unwrap();
        let states = queued();
        assert!(!template.write(&last, &to, &data(&states)).unwrap());
        assert!(!states.untouched());
        let copy = std::fs::read(&to).unwrap();
        assert_eq!(copy[template.offset(0)..][..24], le[..]);
        // Another length, or no last file at all: not copied either, no state taken.
        std::fs::write(&last, &bytes[..len - 1]).unwrap();
        let states = queued();
        assert!(!template.write(&last, &to, &data(&states)).unwrap());
        std::fs::remove_file(&last).unwrap();
        assert!(!template.write(&last, &to, &data(&states)).unwrap());
        assert!(states.untouched());
        assert!(!template.fits(&data(&states)[..2]));
    }
}
