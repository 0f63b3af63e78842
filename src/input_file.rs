//! Reading an input file (a scene, a mesh) whole, safely.

use crate::{Error, Result};
use std::path::Path;

/// Reads an input file (a scene, a mesh) whole. It must be a regular file — a device such as
/// /dev/zero would be read until memory runs out, a FIFO could block forever — and is read up
/// to the size its metadata declares (and at most `max` bytes). `what` names the file in
/// messages.
pub(crate) fn read_input_file(path: &Path, what: &str, max: Option<u64>) -> Result<Vec<u8>> {
    use std::io::Read;
    let fail =
        |why: String| Error::input(format!("cannot read {what} '{}': {why}", path.display()));
    let plain = |e: std::io::Error| {
        let mut m = e.to_string();
        if let Some(p) = m.find(" (os error") {
            m.truncate(p);
        }
        m
    };
    let meta = std::fs::metadata(path).map_err(|e| fail(plain(e)))?;
    if !meta.is_file() {
        let kind = if meta.is_dir() {
            "a directory"
        } else {
            "a device, FIFO or socket"
        };
        return Err(fail(format!("it is {kind}, not a regular file")));
    }
    let len = meta.len();
    if let Some(max) = max.filter(|&m| len > m) {
        return Err(fail(format!(
            "it has {len} bytes, more than a {what} can have ({max})"
        )));
    }
    let file = std::fs::File::open(path).map_err(|e| fail(plain(e)))?;
    let mut bytes = Vec::with_capacity(len as usize);
    file.take(len)
        .read_to_end(&mut bytes)
        .map_err(|e| fail(plain(e)))?;
    Ok(bytes)
}
