//! Whole-file integrity: a 512-byte HDF5 user block at the start of `checkpoint.h5` and of
//! `checkpoint_history.h5` that says what the file is and carries a CRC-32 of its bytes.
//!
//! HDF5 skips a user block (the superblock is then found at byte 512, and h5py and h5dump
//! read the file as usual), so the check lives inside the file it protects and is renamed
//! with it: there is no moment at which a checksum beside the file could disagree with it.
//! Resume verifies the block before libhdf5 parses a single byte, so damage anywhere in the
//! file (raw data or HDF5 metadata, whose corruption has crashed libhdf5) is refused with a
//! message instead of a crash or a silent answer.
//!
//! The block is text, NUL padded: `key value` lines ending with `crc32 XXXXXXXX`, the CRC of
//! the lines before it and of the covered bytes. A reader re-renders the block from what it
//! parsed and compares all 512 bytes, so a flipped bit in the padding is found too. CRC-32
//! finds every error of up to 32 consecutive bits (every flipped bit among them) and misses
//! random damage with probability 2^−32; it runs at memory speed (crate crc32fast), which
//! matters because a later checkpoint streams the last one's bytes through it (`Template`).

/// Bytes of the user block (HDF5 allows 512 · 2^k).
pub(super) const USERBLOCK: usize = 512;

/// The user block for `fields` (`key value` lines, each ending in '\n') and `crc`.
fn render(fields: &str, crc: u32) -> Option<[u8; USERBLOCK]> {
    let text = format!("{fields}crc32 {crc:08x}\n");
    let mut block = [0u8; USERBLOCK];
    if text.len() > USERBLOCK {
        return None;
    }
    block[..text.len()].copy_from_slice(text.as_bytes());
    Some(block)
}

/// CRC-32 of `fields` and then of each covered byte range.
pub(super) fn crc(fields: &str, covered: &[&[u8]]) -> u32 {
    let mut h = crc32fast::Hasher::new();
    h.update(fields.as_bytes());
    for part in covered {
        h.update(part);
    }
    h.finalize()
}

/// The user block for `fields` over `covered`; fields too long for the block are an internal
/// error (ours are a few short lines).
pub(super) fn block(fields: &str, covered: &[&[u8]]) -> [u8; USERBLOCK] {
    render(fields, crc(fields, covered)).expect("user block fields fit in 512 bytes")
}

/// The fields and the stored CRC of a user block that is exactly as `render` writes it, with
/// its first line `magic`; None for anything else.
pub(super) fn parse<'a>(block: &'a [u8], magic: &str) -> Option<(&'a str, u32)> {
    let end = block.iter().position(|&b| b == 0).unwrap_or(block.len());
    let text = std::str::from_utf8(&block[..end]).ok()?;
    let body = text.strip_suffix('\n')?;
    let at = body.rfind('\n')? + 1;
    let (fields, last) = text.split_at(at);
    let crc = u32::from_str_radix(last.strip_prefix("crc32 ")?.strip_suffix('\n')?, 16).ok()?;
    if !fields.starts_with(&format!("{magic}\n")) || render(fields, crc)?[..] != block[..] {
        return None;
    }
    Some((fields, crc))
}

/// The value of `key` among `fields`.
pub(super) fn field<'a>(fields: &'a str, key: &str) -> Option<&'a str> {
    fields
        .lines()
        .find_map(|l| l.strip_prefix(key)?.strip_prefix(' '))
}

/// The fields of a checkpoint's user block for a file of `len` bytes.
fn checkpoint_fields(len: usize) -> String {
    format!("{}\nlength {len}\n", super::FORMAT)
}

/// Writes the user block of a checkpoint's final bytes: CRC-32 of everything after it (a
/// file is sealed where it lies: [`seal_checkpoint_file`]).
#[cfg(test)]
pub(super) fn seal_checkpoint(bytes: &mut [u8]) {
    let block = block(&checkpoint_fields(bytes.len()), &[&bytes[USERBLOCK..]]);
    bytes[..USERBLOCK].copy_from_slice(&block);
}

/// The CRC-32 of a checkpoint of a given length, fed its bytes in order as they stream by
/// (a file sealed, or copied and patched, a chunk at a time: `Template`).
#[derive(Clone)]
pub(super) struct Sealing {
    fields: String,
    hasher: crc32fast::Hasher,
}

impl Sealing {
    /// For a checkpoint of `len` bytes.
    pub(super) fn checkpoint(len: usize) -> Sealing {
        let fields = checkpoint_fields(len);
        let mut hasher = crc32fast::Hasher::new();
        hasher.update(fields.as_bytes());
        Sealing { fields, hasher }
    }

    /// Feeds the file's bytes at `at..at + chunk.len()` (the user block's are not covered).
    pub(super) fn feed(&mut self, at: usize, chunk: &[u8]) {
        if at + chunk.len() > USERBLOCK {
            self.hasher.update(&chunk[USERBLOCK.saturating_sub(at)..]);
        }
    }

    /// Whether `block` is the user block of the bytes fed.
    pub(super) fn seals(&self, block: &[u8]) -> bool {
        let parsed = parse(block, super::FORMAT);
        parsed.is_some_and(|(fields, crc)| fields == self.fields && crc == self.crc())
    }

    /// The user block of the bytes fed.
    pub(super) fn block(&self) -> [u8; USERBLOCK] {
        render(&self.fields, self.crc()).expect("user block fields fit in 512 bytes")
    }

    fn crc(&self) -> u32 {
        self.hasher.clone().finalize()
    }
}

/// Seals the checkpoint file at `path` in place, reading it a chunk at a time.
pub(super) fn seal_checkpoint_file(path: &std::path::Path) -> std::io::Result<()> {
    use std::os::unix::fs::FileExt;
    let file = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(path)?;
    let len = file.metadata()?.len() as usize;
    let mut sealing = Sealing::checkpoint(len);
    let mut chunk = vec![0u8; CHUNK.min(len)];
    for at in (0..len).step_by(CHUNK) {
        let part = &mut chunk[..CHUNK.min(len - at)];
        file.read_exact_at(part, at as u64)?;
        sealing.feed(at, part);
    }
    file.write_all_at(&sealing.block(), 0)
}

/// The bytes a checkpoint is read and written in at a time where it streams.
pub(super) const CHUNK: usize = 8 << 20;

/// Whether `bytes` begin like a sealed checkpoint (the first line of the user block); such a
/// file is verified by [`verify_checkpoint_file`] and never parsed otherwise.
pub(super) fn looks_sealed(bytes: &[u8]) -> bool {
    bytes.starts_with(format!("{}\n", super::FORMAT).as_bytes())
}

/// Checks the sealed checkpoint `file`, reading it a chunk at a time (a resume on every
/// rank of a run checks it, and none holds its bytes whole); the error says what is wrong.
pub(super) fn verify_checkpoint_file(file: &std::fs::File) -> std::result::Result<(), String> {
    use std::os::unix::fs::FileExt;
    let len = file.metadata().map_err(|e| e.to_string())?.len() as usize;
    verify_sealed(len, |at, part| file.read_exact_at(part, at as u64))
}

/// Checks a sealed checkpoint's bytes; the error says what is wrong.
#[cfg(test)]
pub(super) fn verify_checkpoint(bytes: &[u8]) -> std::result::Result<(), String> {
    verify_sealed(bytes.len(), |at, part| {
        part.copy_from_slice(&bytes[at..at + part.len()]);
        Ok(())
    })
}

/// Checks a sealed checkpoint of `len` bytes, which `read_at(at, part)` reads a chunk at a
/// time: its user block, the length it records and the CRC-32 of the rest.
fn verify_sealed(
    len: usize,
    mut read_at: impl FnMut(usize, &mut [u8]) -> std::io::Result<()>,
) -> std::result::Result<(), String> {
    let mut block = [0u8; USERBLOCK];
    let head = &mut block[..USERBLOCK.min(len)];
    read_at(0, head).map_err(|e| e.to_string())?;
    let (fields, crc) = (len >= USERBLOCK)
        .then(|| parse(&block, super::FORMAT))
        .flatten()
        .ok_or("its 512-byte header is damaged")?;
    if fields != checkpoint_fields(len) {
        return Err(format!(
            "the file is {len} bytes long, its header says {} (truncated or damaged)",
            field(fields, "length").unwrap_or("?")
        ));
    }
    let mut sealing = Sealing::checkpoint(len);
    let mut chunk = vec![0u8; CHUNK.min(len)];
    for at in (0..len).step_by(CHUNK) {
        let part = &mut chunk[..CHUNK.min(len - at)];
        read_at(at, part).map_err(|e| e.to_string())?;
        sealing.feed(at, part);
    }
    if sealing.crc() != crc {
        return Err(
            "its bytes do not match the CRC-32 in its header (changed since viscontact wrote \
             it: a disk, copy or transfer error)"
                .into(),
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_single_bit_flip_of_a_block_is_found() {
        let fields = "viscontact test\nlength 3\n";
        let data = [1u8, 2, 3];
        let good = block(fields, &[&data]);
        assert_eq!(
            parse(&good, "viscontact test"),
            Some((fields, crc(fields, &[&data])))
        );
        for bit in 0..USERBLOCK * 8 {
            let mut bad = good;
            bad[bit / 8] ^= 1 << (bit % 8);
            let found = match parse(&bad, "viscontact test") {
                None => true,
                Some((f, c)) => c != crc(f, &[&data]),
            };
            assert!(found, "flip of bit {bit} not found");
        }
    }
}
