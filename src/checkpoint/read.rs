//! Reading a checkpoint back.

use super::h5::{h5_file, has_hdf5_signature, str_attr_of, OpenMode, HDF5_SIGNATURE};
use super::seal;
use super::{Checkpoint, Identity, RunLog, StoredMemory, FORMAT, FORMAT_VERSION};
use crate::history::HeldAt;
use crate::{Error, Result};
use hdf5::types::VarLenUnicode;
use hdf5_metno as hdf5;
use std::io::Read;
use std::path::{Path, PathBuf};

impl Checkpoint {
    /// The Prony states term by term, each at the dofs `at` alone (None: every dof),
    /// read from the file a term at a time.
    pub(super) fn prony_states_at(&self, at: Option<&[usize]>) -> Result<Vec<Vec<f64>>> {
        self.read_file("memory/prony_state", |f| prony_states(f, at))
    }

    /// u_n, its compensated sum, the compensation and w_n, each at the dofs `held` gives
    /// (`n_dofs` values where None), read from the file 2^20 values at a time.
    pub(super) fn state_at(&self, held: &HeldAt) -> Result<[Vec<f64>; 4]> {
        self.read_file("/state", |f| {
            let read = |name: &str, at| row_at(&f.dataset(name)?, None, self.n_dofs, at);
            Ok([
                read("state/u", held.u)?,
                read("state/u_sum", held.u)?,
                read("state/u_comp", held.u)?,
                read("state/w", held.w)?,
            ])
        })
    }

    /// What `read` reads of the checkpoint's file, its failure told as a damaged
    /// checkpoint's (`what`: the datasets it reads).
    fn read_file<T>(
        &self,
        what: &str,
        read: impl FnOnce(&hdf5::File) -> hdf5::Result<T>,
    ) -> Result<T> {
        h5_file(OpenMode::Read, &self.path)
            .and_then(|f| read(&f))
            .map_err(|e| {
                Error::input(format!(
                    "{}: damaged checkpoint: {what} unreadable ({e}); resume from an intact \
                 checkpoint or start the run again",
                    self.path.display()
                ))
            })
    }

    /// The directory the checkpoint is in.
    pub fn dir(&self) -> PathBuf {
        match self.path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        }
    }

    /// Reads and checks a checkpoint file. Refuses (input errors naming the file): a missing
    /// file or one that is not a regular file, a file that is not HDF5, a truncated or damaged
    /// one (its CRC-32, checked before libhdf5 parses anything, `seal.rs`), an HDF5 file that
    /// is not a viscontact checkpoint, a format version without a checksum or newer than
    /// this one.
    pub fn read(path: &Path) -> Result<Checkpoint> {
        let shown = path.display();
        let sealed = verify_seal(path)?;
        let f = h5_file(OpenMode::Read, path).map_err(|e| {
            Error::input(format!(
                "{shown}: cannot open as HDF5 ({e}): the file is truncated or damaged; resume \
                 from an intact checkpoint (a run writes checkpoint.h5 whole and renames it, \
                 so the one a run left is intact unless something else changed it)"
            ))
        })?;
        let version = format_version(&f, path, sealed)?;
        read_body(&f, path, version).map_err(|e| {
            Error::input(format!(
                "{shown}: damaged checkpoint ({e}); resume from an intact checkpoint or start \
                 the run again"
            ))
        })
    }
}

/// Reads the first bytes of the file at `path` and verifies its checksum, a chunk at a time,
/// where it carries our header; returns whether it does (an HDF5 file without it is told
/// apart by `format_version`). Anything else is refused.
fn verify_seal(path: &Path) -> Result<bool> {
    let shown = path.display();
    let cannot = |e: String| {
        Error::input(format!(
            "cannot read checkpoint '{shown}': {e}; give the checkpoint.h5 of a run \
             directory"
        ))
    };
    match std::fs::metadata(path) {
        Ok(m) if m.is_file() => {}
        Ok(_) => return Err(cannot("not a regular file".into())),
        Err(e) => return Err(cannot(e.to_string())),
    }
    // Its first bytes tell what it is; a sealed one is then checked a chunk at a time.
    let mut bytes = Vec::new();
    let file = std::fs::File::open(path).map_err(|e| cannot(e.to_string()))?;
    ((&file).take(seal::USERBLOCK as u64).read_to_end(&mut bytes))
        .map_err(|e| cannot(e.to_string()))?;
    if seal::looks_sealed(&bytes) {
        seal::verify_checkpoint_file(&file).map_err(|why| {
            Error::input(format!(
                "{shown}: damaged checkpoint, refused: {why}; resume from an intact copy \
                 of the run directory or start the run again"
            ))
        })?;
    } else if bytes.starts_with(HDF5_SIGNATURE) {
        // An HDF5 file without our header: someone else's file, or an unverifiable
        // checkpoint of format version 1 (both told apart by `format_version`, and refused).
    } else if has_hdf5_signature(path).map_err(|e| cannot(e.to_string()))? {
        return Err(Error::input(format!(
            "{shown}: damaged checkpoint, refused: its 512-byte header is not a \
             viscontact checkpoint header (or this is an HDF5 file of another program); \
             resume from an intact copy of the run directory or start the run again"
        )));
    } else {
        return Err(Error::input(format!(
            "{shown}: not an HDF5 file, so not a viscontact checkpoint; give the \
             checkpoint.h5 of a run directory"
        )));
    }
    Ok(seal::looks_sealed(&bytes))
}

/// The checkpoint's format version, refusing another program's HDF5 file, a checkpoint
/// without a checksum (`sealed` false) and a newer format.
fn format_version(f: &hdf5::File, path: &Path, sealed: bool) -> Result<u32> {
    let shown = path.display();
    let format = f
        .attr("format")
        .and_then(|a| a.read_scalar::<VarLenUnicode>())
        .map(|s| s.as_str().to_string())
        .ok();
    if format.as_deref() != Some(FORMAT) {
        return Err(Error::input(format!(
            "{shown}: an HDF5 file but not a viscontact checkpoint (its root attribute \
             'format' is {}, expected \"{FORMAT}\"); give the checkpoint.h5 that \
             `viscontact run` wrote",
            format.map_or("missing".to_string(), |s| format!("{s:?}"))
        )));
    }
    let version = f
        .attr("format_version")
        .and_then(|a| a.read_scalar::<u32>())
        .map_err(|e| {
            Error::input(format!(
                "{shown}: damaged checkpoint: attribute 'format_version' unreadable ({e})"
            ))
        })?;
    if !sealed {
        return Err(Error::input(format!(
            "{shown}: checkpoint format version {version} carries no checksum, so its \
             integrity cannot be verified and it is refused (a damaged file could give \
             wrong results); resume it with the viscontact version that wrote it ({}) or \
             start the run again",
            str_attr_of(f, "writer").unwrap_or_else(|_| "unknown".into())
        )));
    }
    if version > FORMAT_VERSION {
        return Err(Error::input(format!(
            "{shown}: checkpoint format version {version} is newer than this viscontact \
             reads (≤ {FORMAT_VERSION}); resume it with the viscontact version that \
             wrote it ({})",
            str_attr_of(f, "writer").unwrap_or_else(|_| "unknown".into())
        )));
    }
    Ok(version)
}

pub(super) fn read_body(f: &hdf5::File, path: &Path, version: u32) -> hdf5::Result<Checkpoint> {
    let vec = |name: &str| f64s(f, name);
    let n = f.dataset("step")?.read_scalar::<u64>()? as usize;
    let time = f.dataset("time")?.read_scalar::<f64>()?;
    let k = f.dataset("step_size")?.read_scalar::<f64>()?;
    let memory = read_memory(f)?;
    let log = read_log(f, n)?;
    let id = read_identity(f)?;
    // u_n, its sums and w_n stay in the file: a resume reads each rank's part of them.
    let n_dofs = length(f, "state/u")?;
    for name in ["state/u_sum", "state/u_comp", "state/w"] {
        if length(f, name)? != n_dofs {
            return Err(format!("{name} and state/u differ in length").into());
        }
    }
    let cp = Checkpoint {
        path: path.to_path_buf(),
        version,
        n,
        time,
        k,
        id,
        n_dofs,
        z: vec("state/z")?,
        z_before: if version >= super::Z_BEFORE_VERSION || f.link_exists("state/z_before") {
            vec("state/z_before")?
        } else {
            vec("state/z")?
        },
        memory,
        log,
        frames: match version {
            super::UNVERIFIED_VERSION => None,
            _ => Some(read_series(f, n)?),
        },
    };
    if cp.log.iterations.len() != cp.n {
        return Err(format!(
            "/run/iterations has {} entries for step {}",
            cp.log.iterations.len(),
            cp.n
        )
        .into());
    }
    if !(cp.k > 0.0 && cp.k.is_finite()) {
        return Err(format!("step_size {} is not a positive number", cp.k).into());
    }
    Ok(cp)
}

/// The f64 dataset `name`, flat.
fn f64s(f: &hdf5::File, name: &str) -> hdf5::Result<Vec<f64>> {
    f.dataset(name)?.read_raw::<f64>()
}

/// `/memory`: none, the Prony terms with their states, or the direct sum's history file.
fn read_memory(f: &hdf5::File) -> hdf5::Result<StoredMemory> {
    let vec = |name: &str| f64s(f, name);
    let mem = f.group("memory")?;
    let kind = str_attr_of(&mem, "kind")?;
    Ok(match kind.as_str() {
        "none" => StoredMemory::None,
        "prony" => {
            let a = vec("memory/prony_a")?;
            let decay = vec("memory/prony_decay")?;
            let shape = f.dataset("memory/prony_state")?.shape();
            if shape.len() != 2 || shape[0] != a.len() || decay.len() != a.len() {
                return Err("memory/prony_* have inconsistent shapes".into());
            }
            // Written only where a region has a kernel of its own.
            let group = match f.link_exists("memory/prony_group") {
                true => vec("memory/prony_group")?,
                false => vec![0.0; a.len()],
            };
            if group.len() != a.len() || group.iter().any(|&g| g.fract() != 0.0 || g < 0.0) {
                return Err("memory/prony_group is not one group index per term".into());
            }
            let group = group.iter().map(|&g| g as usize).collect();
            StoredMemory::Prony {
                a,
                decay,
                group,
                width: shape[1],
            }
        }
        "direct" => StoredMemory::Direct {
            file: str_attr_of(&mem, "history_file")?,
            rows: mem.dataset("history_rows")?.read_scalar::<u64>()? as usize,
            hash: mem.dataset("history_hash")?.read_scalar::<u64>()?,
        },
        other => return Err(format!("/memory kind {other:?} is unknown").into()),
    })
}

/// The length of the 1-D dataset `name`.
fn length(f: &hdf5::File, name: &str) -> hdf5::Result<usize> {
    match f.dataset(name)?.shape()[..] {
        [len] => Ok(len),
        _ => Err(format!("{name} is not a vector").into()),
    }
}

/// The values a resume reads of a vector at a time: 2^20 (8 MiB), as the CRC check reads.
const CHUNK: usize = 1 << 20;

/// Row `row` of the f64 dataset `ds` (None: `ds` is a vector), `len` values, at the dofs
/// `at` alone (increasing, each below `len`; None: every one), read `CHUNK` values at a
/// time, so that a rank that keeps some dofs alone never holds the whole row.
fn row_at(
    ds: &hdf5::Dataset,
    row: Option<usize>,
    len: usize,
    at: Option<&[usize]>,
) -> hdf5::Result<Vec<f64>> {
    let read = |r: std::ops::Range<usize>| -> hdf5::Result<Vec<f64>> {
        if r.is_empty() {
            return Ok(Vec::new());
        }
        let values = match row {
            None => ds.read_slice_1d::<f64, _>(ndarray::s![r])?,
            Some(i) => ds.read_slice_1d::<f64, _>(ndarray::s![i, r])?,
        };
        Ok(values.into_raw_vec_and_offset().0)
    };
    let Some(at) = at else { return read(0..len) };
    if at.last().is_some_and(|&d| d >= len) {
        return Err(format!("{} holds {len} values, fewer than the dofs read", ds.name()).into());
    }
    let mut out = Vec::with_capacity(at.len());
    let mut rest = at;
    while let Some(&first) = rest.first() {
        let start = first - first % CHUNK;
        let end = (start + CHUNK).min(len);
        let values = read(start..end)?;
        let here = rest.partition_point(|&d| d < end);
        out.extend(rest[..here].iter().map(|&d| values[d - start]));
        rest = &rest[here..];
    }
    Ok(out)
}

/// The Prony states m^(i)_n of the checkpoint's file `f`, term by term, each at the dofs
/// `at` alone (increasing, each below the states' width; None: every dof), read
/// [`row_at`].
fn prony_states(f: &hdf5::File, at: Option<&[usize]>) -> hdf5::Result<Vec<Vec<f64>>> {
    let state = f.dataset("memory/prony_state")?;
    let (terms, width) = match state.shape()[..] {
        [terms, width] => (terms, width),
        _ => return Err("memory/prony_state is not terms × dofs".into()),
    };
    (0..terms)
        .map(|i| row_at(&state, Some(i), width, at))
        .collect()
}

/// `/run`: the iteration counts of steps 0..n and the run's worst violation and residual.
fn read_log(f: &hdf5::File, n: usize) -> hdf5::Result<RunLog> {
    let run = f.group("run")?;
    Ok(RunLog {
        iterations: {
            let all = run.dataset("iterations")?.read_raw::<i32>()?;
            if all.len() < n || all[..n].iter().any(|&i| i < 0) {
                return Err(format!("/run/iterations lacks the counts of steps 0..{n}").into());
            }
            all[..n].iter().map(|&i| i as usize).collect()
        },
        max_violation: run.dataset("max_violation")?.read_scalar::<f64>()?,
        max_kkt_residual: run.dataset("max_kkt_residual")?.read_scalar::<f64>()?,
    })
}

/// The run's identity: its id, scene, mesh and physics.
fn read_identity(f: &hdf5::File) -> hdf5::Result<Identity> {
    let sc = f.group("scene")?;
    let mesh = f.group("mesh")?;
    let physics_group = f.group("physics")?;
    let mut physics = Vec::new();
    for name in physics_group.attr_names()? {
        if name != "description" {
            physics.push((name.clone(), str_attr_of(&physics_group, &name)?));
        }
    }
    physics.sort();
    Ok(Identity {
        run_id: str_attr_of(f, "run_id")?,
        scene_text: sc
            .dataset("text")?
            .read_scalar::<VarLenUnicode>()?
            .as_str()
            .to_string(),
        scene_path: str_attr_of(&sc, "path")?,
        scene_path_absolute: str_attr_of(&sc, "absolute_path")?,
        mesh_path: str_attr_of(&mesh, "file")?,
        mesh_fingerprint: mesh.dataset("fingerprint")?.read_scalar::<u64>()?,
        groups_fingerprint: mesh.dataset("groups_fingerprint")?.read_scalar::<u64>()?,
        nodes: mesh.attr("nodes")?.read_scalar::<u64>()? as usize,
        triangles: mesh.attr("triangles")?.read_scalar::<u64>()? as usize,
        physics,
        dof_of: mesh.dataset("dof_of")?.read_raw::<i64>()?,
    })
}

/// The frames `/series` records: steps increasing and below the checkpoint's step `n`.
fn read_series(f: &hdf5::File, n: usize) -> hdf5::Result<Vec<crate::output::FrameSum>> {
    let g = f.group("series")?;
    let frames = g.dataset("frames")?.read_scalar::<u64>()? as usize;
    let step = g.dataset("step")?.read_raw::<i64>()?;
    let time = g.dataset("time")?.read_raw::<f64>()?;
    let crc32 = g.dataset("crc32")?.read_raw::<u32>()?;
    let bytes = g.dataset("bytes")?.read_raw::<u64>()?;
    if [step.len(), time.len(), crc32.len(), bytes.len()]
        .iter()
        .any(|&l| l < frames)
    {
        return Err(format!("/series has fewer entries than its {frames} frames").into());
    }
    let out: Vec<_> = (0..frames)
        .map(|k| crate::output::FrameSum {
            step: step[k].max(0) as usize,
            time: time[k],
            crc32: crc32[k],
            bytes: bytes[k],
        })
        .collect();
    let increasing = step[..frames].windows(2).all(|w| w[0] < w[1]);
    if !increasing || step[..frames].iter().any(|&s| s < 0 || s as usize >= n) {
        return Err(format!("/series/step is not a list of steps before step {n}").into());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A vector and a row of a matrix longer than one chunk, read at dofs on both sides of
    /// the chunks' border, at none, and whole: each value is the file's.
    #[test]
    fn a_row_read_at_some_dofs_has_their_values_across_chunks() {
        let dir = tempfile::tempdir().unwrap();
        let len = CHUNK + 5;
        let value = |r: usize, j: usize| (r * len + j) as f64 / 3.0;
        let f = h5_file(OpenMode::Create, dir.path().join("rows.h5")).unwrap();
        let rows: Vec<f64> = (0..2 * len).map(|i| value(i / len, i % len)).collect();
        let vector = f.new_dataset::<f64>().shape([len]).create("v").unwrap();
        vector.write_raw(&rows[len..]).unwrap();
        let matrix = f.new_dataset::<f64>().shape([2, len]).create("m").unwrap();
        matrix.write_raw(&rows).unwrap();
        let at = [0, 3, CHUNK - 1, CHUNK, CHUNK + 4];
        for (ds, row) in [(&vector, None), (&matrix, Some(1))] {
            let got = row_at(ds, row, len, Some(&at)).unwrap();
            let expected: Vec<f64> = at.iter().map(|&j| value(1, j)).collect();
            assert_eq!(got, expected, "{row:?}");
            assert!(row_at(ds, row, len, Some(&[])).unwrap().is_empty());
            assert_eq!(row_at(ds, row, len, None).unwrap(), rows[len..]);
            assert!(row_at(ds, row, len, Some(&[len])).is_err(), "past the end");
        }
    }
}
