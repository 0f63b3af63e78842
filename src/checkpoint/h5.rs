//! HDF5 helpers shared by the writer and the reader, and the file-system steps of a crash
//! safe write (fsync of a file and of its directory).

use crate::{Error, Result};
use hdf5::types::VarLenUnicode;
use hdf5_metno as hdf5;
use std::path::Path;
use std::str::FromStr;

pub(super) use hdf5::file::OpenMode;

/// Opens or creates an HDF5 file with HDF5's file locking off. Our files are never shared by
/// two writers (a checkpoint is written to a private temporary file and renamed), and the
/// lock (flock) is inherited by child processes that a program spawns while a file is open,
/// which then makes opening the file fail elsewhere for as long as the child lives.
pub(super) fn h5_file<P: AsRef<Path>>(mode: OpenMode, path: P) -> hdf5::Result<hdf5::File> {
    hdf5::File::with_options()
        .with_fapl(|p| p.file_locking(false))
        .open_as(path, mode)
}

/// Creates an HDF5 file (locking off, as [`h5_file`]) whose first 512 bytes are a user block
/// for the integrity header of `seal.rs`.
pub(super) fn h5_create_sealed<P: AsRef<Path>>(path: P) -> hdf5::Result<hdf5::File> {
    hdf5::File::with_options()
        .with_fapl(|p| p.file_locking(false))
        .with_fcpl(|p| p.userblock(super::seal::USERBLOCK as u64))
        .create(path)
}

pub(super) fn fsync_file(path: &Path) -> Result<()> {
    std::fs::File::open(path)
        .and_then(|f| f.sync_all())
        .map_err(|e| Error::io(path, e))
}

/// fsync of a directory makes a rename in it durable; failure (some file systems cannot) is
/// not an error: the rename itself is what makes a crash of the process safe.
pub(super) fn fsync_dir(dir: &Path) {
    if let Ok(d) = std::fs::File::open(dir) {
        let _ = d.sync_all();
    }
}

pub(super) fn vlu(s: &str) -> VarLenUnicode {
    // Strings we write never hold NUL; replace any to keep the attribute writable.
    VarLenUnicode::from_str(&s.replace('\0', " ")).expect("no NUL in the string")
}

pub(super) fn str_attr(loc: &hdf5::Location, name: &str, value: &str) -> hdf5::Result<()> {
    loc.new_attr::<VarLenUnicode>()
        .shape(())
        .create(name)?
        .write_scalar(&vlu(value))
}

pub(super) fn describe(ds: &hdf5::Dataset, description: &str, units: &str) -> hdf5::Result<()> {
    str_attr(ds, "description", description)?;
    str_attr(ds, "units", units)
}

pub(super) fn scalar<T: hdf5::H5Type>(
    g: &hdf5::Group,
    name: &str,
    value: T,
    description: &str,
    units: &str,
) -> hdf5::Result<()> {
    let ds = g.new_dataset::<T>().shape(()).create(name)?;
    ds.write_scalar(&value)?;
    describe(&ds, description, units)
}

pub(super) fn vector<T: hdf5::H5Type>(
    g: &hdf5::Group,
    name: &str,
    shape: &[usize],
    values: &[T],
    description: &str,
    units: &str,
) -> hdf5::Result<()> {
    let ds = g.new_dataset::<T>().shape(shape).create(name)?;
    if !values.is_empty() {
        ds.write_raw(values)?;
    }
    describe(&ds, description, units)
}

/// A 2-D dataset of `rows` rows of `width` values, written row by row as `with_row` hands
/// each to its writer: the Prony states, the checkpoint's largest dataset, are never held
/// in one array (they come one at a time: `Vectors`).
pub(super) fn rows_dataset(
    g: &hdf5::Group,
    name: &str,
    (rows, width): (usize, usize),
    with_row: impl Fn(usize, &mut dyn FnMut(&[f64]) -> hdf5::Result<()>) -> hdf5::Result<()>,
    description: &str,
    units: &str,
) -> hdf5::Result<()> {
    let ds = g.new_dataset::<f64>().shape([rows, width]).create(name)?;
    for i in 0..rows {
        with_row(i, &mut |row| {
            let row =
                ndarray::ArrayView2::from_shape((1, width), row).map_err(|e| e.to_string())?;
            ds.write_slice(row, ndarray::s![i..i + 1, ..])
        })?;
    }
    describe(&ds, description, units)
}

pub(super) fn string_dataset(
    g: &hdf5::Group,
    name: &str,
    value: &str,
    description: &str,
) -> hdf5::Result<()> {
    let ds = g.new_dataset::<VarLenUnicode>().shape(()).create(name)?;
    ds.write_scalar(&vlu(value))?;
    describe(&ds, description, "")
}

/// The 8-byte HDF5 signature; HDF5 looks for it at 0, 512, 1024, 2048, ….
pub(super) const HDF5_SIGNATURE: &[u8; 8] = b"\x89HDF\r\n\x1a\n";

pub(super) fn has_hdf5_signature(path: &Path) -> std::io::Result<bool> {
    use std::io::{Read, Seek, SeekFrom};
    let mut f = std::fs::File::open(path)?;
    let len = f.metadata()?.len();
    let mut at = 0u64;
    while at + 8 <= len {
        let mut buf = [0u8; 8];
        f.seek(SeekFrom::Start(at))?;
        f.read_exact(&mut buf)?;
        if &buf == HDF5_SIGNATURE {
            return Ok(true);
        }
        at = if at == 0 { 512 } else { at * 2 };
    }
    Ok(false)
}

pub(super) fn str_attr_of(loc: &hdf5::Location, name: &str) -> hdf5::Result<String> {
    Ok(loc
        .attr(name)?
        .read_scalar::<VarLenUnicode>()?
        .as_str()
        .to_string())
}
