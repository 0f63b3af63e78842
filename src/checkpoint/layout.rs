//! The checkpoint's HDF5 layout: every group, dataset and attribute (written through the
//! library), and the datasets whose values change between checkpoints.

use super::h5::{h5_create_sealed, rows_dataset, scalar, str_attr, string_dataset, vector};
use super::history_file::HistoryFile;
use super::snapshot::{Snapshot, SnapshotMemory};
use super::vectors::{le_range, Vectors};
use super::{Identity, RunLog, FORMAT, FORMAT_VERSION, HISTORY_DATASET, HISTORY_FILE_NAME};
use crate::output::FrameSum;
use hdf5_metno as hdf5;
use std::path::Path;

/// The datasets whose values change from one checkpoint to the next, in file byte order
/// (little endian, as the datasets are declared): their values where the snapshot holds
/// them, which a checkpoint writes where they go in its file (`Template`), never copied
/// whole; the rest as bytes.
pub(super) fn variable_data(s: &Snapshot, steps: usize) -> Vec<(&'static str, Raw<'_>)> {
    let bytes = |b: &[u8]| Raw::Bytes(b.to_vec());
    let f64s = Raw::F64s;
    let mut out = vec![
        ("step", bytes(&(s.n as u64).to_le_bytes())),
        ("time", bytes(&(s.n as f64 * s.k).to_le_bytes())),
        ("state/u", f64s(&s.u[..])),
        ("state/u_sum", f64s(&s.u_sum[..])),
        ("state/u_comp", f64s(&s.u_comp[..])),
        ("state/w", f64s(&s.w[..])),
        ("state/z", f64s(&s.z[..])),
        ("state/z_before", f64s(&s.z_before[..])),
        (
            "state/active",
            Raw::Bytes(s.active.iter().map(|&a| a as u8).collect()),
        ),
        ("run/iterations", Raw::Bytes(le(&iterations(&s.log, steps)))),
        (
            "run/max_violation",
            bytes(&s.log.max_violation.to_le_bytes()),
        ),
        (
            "run/max_kkt_residual",
            bytes(&s.log.max_kkt_residual.to_le_bytes()),
        ),
    ];
    let series = series_columns(&s.frames);
    out.push((
        "series/frames",
        bytes(&(s.frames.len() as u64).to_le_bytes()),
    ));
    out.push(("series/step", Raw::Bytes(le(&series.step))));
    out.push(("series/time", Raw::Bytes(le(&series.time))));
    out.push(("series/crc32", Raw::Bytes(le(&series.crc32))));
    out.push(("series/bytes", Raw::Bytes(le(&series.bytes))));
    match &s.memory {
        SnapshotMemory::None => {}
        SnapshotMemory::Prony { states, .. } => {
            out.push((PRONY_STATE, Raw::States(states)));
        }
        SnapshotMemory::Direct { .. } => {
            out.push(("memory/history_rows", bytes(&(s.n as u64).to_le_bytes())));
        }
    }
    out
}

/// The dataset of the Prony states among [`variable_data`]'s.
pub(super) const PRONY_STATE: &str = "memory/prony_state";

/// A variable dataset's raw data: bytes, f64 values (the state's vectors), or the Prony
/// states as they come from the run (one row a term), in file byte order once written.
pub(super) enum Raw<'a> {
    Bytes(Vec<u8>),
    F64s(&'a [f64]),
    States(&'a Vectors),
}

impl Raw<'_> {
    /// Its bytes' count.
    pub(super) fn len(&self) -> usize {
        match self {
            Raw::Bytes(b) => b.len(),
            Raw::F64s(v) => std::mem::size_of_val(*v),
            Raw::States(states) => states.len(),
        }
    }

    /// Its bytes from byte `from` on into `out`, as many as `out` holds (the Prony states
    /// in order: [`Vectors::write_range`]).
    pub(super) fn write_range(&self, from: usize, out: &mut [u8]) -> std::io::Result<()> {
        match self {
            Raw::Bytes(b) => out.copy_from_slice(&b[from..from + out.len()]),
            Raw::F64s(v) => le_range(v, from, out),
            Raw::States(states) => return states.write_range(from, out),
        }
        Ok(())
    }
}

/// Little-endian bytes of numbers.
fn le<T: Copy + bytemuck::Pod>(v: &[T]) -> Vec<u8> {
    if cfg!(target_endian = "little") {
        return bytemuck::cast_slice(v).to_vec();
    }
    let size = std::mem::size_of::<T>();
    bytemuck::cast_slice::<T, u8>(v)
        .chunks(size)
        .flat_map(|c| c.iter().rev().copied())
        .collect()
}

/// The `/series` arrays: one entry per frame, then padding (step −1, the rest 0) up to a
/// power of two ≥ frames + 1, at least 64, so that their size, and with it the `Template`,
/// changes only log₂ F times in a run of F frames.
pub(super) struct SeriesColumns {
    pub(super) step: Vec<i64>,
    pub(super) time: Vec<f64>,
    pub(super) crc32: Vec<u32>,
    pub(super) bytes: Vec<u64>,
}

pub(super) fn series_columns(frames: &[FrameSum]) -> SeriesColumns {
    let len = (frames.len() + 1).next_power_of_two().max(64);
    let column = |f: &dyn Fn(&FrameSum) -> u64| -> Vec<u64> {
        let mut v: Vec<u64> = frames.iter().map(f).collect();
        v.resize(len, 0);
        v
    };
    let mut step: Vec<i64> = frames.iter().map(|f| f.step as i64).collect();
    step.resize(len, -1);
    SeriesColumns {
        step,
        time: column(&|f| f.time.to_bits())
            .into_iter()
            .map(f64::from_bits)
            .collect(),
        crc32: column(&|f| f.crc32 as u64)
            .into_iter()
            .map(|c| c as u32)
            .collect(),
        bytes: column(&|f| f.bytes),
    }
}

/// Iterations of steps 0..n, then −1 up to a length that grows with n: the run's `steps` + 1
/// entries, or fewer for long runs (at least 1024, a power of two ≥ n + 1), so that a run of
/// N = 10^12 steps does not write (or allocate) N entries per checkpoint, while the length,
/// and with it the `Template`, changes only log₂ N times.
pub(super) fn iterations(log: &RunLog, steps: usize) -> Vec<i32> {
    let len =
        (steps.saturating_add(1)).min((log.iterations.len() + 1).next_power_of_two().max(1024));
    let mut v: Vec<i32> = log
        .iterations
        .iter()
        .map(|&i| i.min(i32::MAX as usize) as i32)
        .collect();
    v.resize(v.len().max(len), -1);
    v
}

/// Writes the checkpoint of snapshot `s` of a run of `steps` steps to `path`: a new sealed
/// HDF5 file, group by group (docs/restart.md). The order of the calls fixes
/// the file's layout, which later checkpoints patch in place (`Template`).
pub(super) fn write_checkpoint(
    path: &Path,
    id: &Identity,
    row_node: &[u64],
    s: &Snapshot,
    steps: usize,
    history: Option<&HistoryFile>,
) -> hdf5::Result<()> {
    let f = h5_create_sealed(path)?;
    write_header(&f, id, s)?;
    write_state(&f, row_node, s)?;
    write_memory(&f, s, history)?;
    write_series(&f, &s.frames)?;
    write_run_log(&f, s, steps)?;
    write_scene(&f, id)?;
    write_mesh(&f, id)?;
    write_physics(&f, id)?;
    f.close()?;
    Ok(())
}

/// The root's attributes, the step, its time and the step size.
fn write_header(f: &hdf5::File, id: &Identity, s: &Snapshot) -> hdf5::Result<()> {
    str_attr(f, "format", FORMAT)?;
    f.new_attr::<u32>()
        .shape(())
        .create("format_version")?
        .write_scalar(&FORMAT_VERSION)?;
    str_attr(
        f,
        "writer",
        concat!("viscontact ", env!("CARGO_PKG_VERSION")),
    )?;
    str_attr(
        f,
        "description",
        "restart state of a viscontact run (Problem 3.1 of Xu et al. 2021) before step \
         `step` is solved; continue it with `viscontact resume THIS_FILE`",
    )?;
    str_attr(f, "run_id", &id.run_id)?;

    scalar(
        f,
        "step",
        s.n as u64,
        "n: the next step to solve; steps 0..n-1 are done",
        "1",
    )?;
    scalar(f, "time", s.n as f64 * s.k, "t_n = n k", "s")?;
    scalar(f, "step_size", s.k, "k = T/N, the time step", "s")?;

    Ok(())
}

/// `/state`: u_n with its compensated sum, w and the multipliers of the last solved step.
fn write_state(f: &hdf5::File, row_node: &[u64], s: &Snapshot) -> hdf5::Result<()> {
    let n_free = s.u.len();
    let state = f.create_group("state")?;
    let nf = [n_free];
    vector(
        &state,
        "u",
        &nf,
        &s.u,
        "u_n = u_0 + k Σ_{j<n} w_j, displacement at t_n (free dofs, see /mesh/dof_of) \
         = u_sum + u_comp",
        "m",
    )?;
    vector(
        &state,
        "u_sum",
        &nf,
        &s.u_sum,
        "running sum of k w_j (Neumaier compensated summation)",
        "m",
    )?;
    vector(
        &state,
        "u_comp",
        &nf,
        &s.u_comp,
        "Neumaier compensation: rounding error not yet in u_sum",
        "m",
    )?;
    vector(
        &state,
        "w",
        &nf,
        &s.w,
        "w_{n-1}: velocity of the last solved step (free dofs)",
        "m/s",
    )?;
    vector(
        &state,
        "z",
        &[s.z.len()],
        &s.z,
        "multipliers of the last solved step: λ_i ≥ 0 on the Γ3,1 contact rows, then γ_i \
         (|γ_i| ≤ μF∫φ_i) on the Γ3,2 friction rows (nodal forces); the warm start of step n",
        "N/m",
    )?;
    vector(
        &state,
        "z_before",
        &[s.z_before.len()],
        &s.z_before,
        "multipliers of the step before the last solved one (z itself before a second \
         step): with z, the extrapolated warm start 2z − z_before of step n",
        "N/m",
    )?;
    let flags: Vec<u8> = s.active.iter().map(|&a| a as u8).collect();
    vector(
        &state,
        "active",
        &[flags.len()],
        &flags,
        "per row of z: 1 = contact active (Γ3,1) or sticking (Γ3,2) at the last solved step, \
         0 = free or slipping; recomputed by the solver from z, stored for inspection",
        "1",
    )?;
    vector(
        &state,
        "row_node",
        &[row_node.len()],
        row_node,
        "mesh node of each row of z (contact rows first, then friction rows)",
        "1",
    )?;
    Ok(())
}

/// `/memory`: the Prony terms' states, or where the direct sum's past displacements lie.
fn write_memory(f: &hdf5::File, s: &Snapshot, history: Option<&HistoryFile>) -> hdf5::Result<()> {
    let memory = f.create_group("memory")?;
    match &s.memory {
        SnapshotMemory::None => str_attr(&memory, "kind", "none")?,
        SnapshotMemory::Prony { terms, states } => {
            str_attr(&memory, "kind", "prony")?;
            let a: Vec<f64> = terms.iter().map(|t| t.a).collect();
            let decay: Vec<f64> = terms.iter().map(|t| t.decay).collect();
            let b: Vec<f64> = terms.iter().map(|t| -t.decay.ln() / s.k).collect();
            let nt = [terms.len()];
            vector(
                &memory,
                "prony_a",
                &nt,
                &a,
                "weights a_i of r(s) = Σ a_i exp(-b_i s)",
                "Pa/s",
            )?;
            vector(
                &memory,
                "prony_b",
                &nt,
                &b,
                "rates b_i of r(s) = Σ a_i exp(-b_i s) (recovered from prony_decay; \
                 informational)",
                "1/s",
            )?;
            vector(
                &memory,
                "prony_decay",
                &nt,
                &decay,
                "one-step decay exp(-b_i k) of each term (exactly as used)",
                "1",
            )?;
            if terms.iter().any(|t| t.group != 0) {
                let group: Vec<f64> = terms.iter().map(|t| t.group as f64).collect();
                vector(
                    &memory,
                    "prony_group",
                    &nt,
                    &group,
                    "memory group of each term: 0 the body's kernel ([material.relaxation]), \
                     g the g-th [[material.region]] with a kernel of its own",
                    "1",
                )?;
            }
            rows_dataset(
                &memory,
                "prony_state",
                (states.count(), states.width()),
                |i, write| {
                    (states.with_row(i, write)).map_err(|e| hdf5::Error::from(e.to_string()))?
                },
                "m^(i)_n = k Σ_{j<n} exp(-b_i (t_n - t_j)) u_j, one row per term; \
                 m_n = Σ a_i m^(i)_n",
                "m s",
            )?;
        }
        SnapshotMemory::Direct { .. } => {
            str_attr(&memory, "kind", "direct")?;
            let hist = history.expect("a direct-sum memory has a history file");
            scalar(
                &memory,
                "history_rows",
                s.n as u64,
                "valid rows of past_displacements: u_0..u_{n-1} (= step)",
                "1",
            )?;
            scalar(
                &memory,
                "history_hash",
                hist.hash.0,
                "64-bit running hash of the bits of rows 0..history_rows-1 of \
                 past_displacements (src/checkpoint/fingerprint.rs Hash64); resume checks it",
                "1",
            )?;
            str_attr(&memory, "history_file", HISTORY_FILE_NAME)?;
            str_attr(
                &memory,
                "description",
                "general kernel: m_n = k Σ_{j<n} r((n-j)k) u_j by the direct sum; \
                 u_0..u_{n-1} are rows 0..history_rows-1 of past_displacements (an external \
                 link to history_file, appended to at each checkpoint); history_hash is a \
                 64-bit running hash of those rows' bits",
            )?;
            memory.link_external(HISTORY_FILE_NAME, HISTORY_DATASET, "past_displacements")?;
        }
    }
    Ok(())
}

/// `/run`: the iterations of the steps so far and the running maxima of summary.json.
fn write_run_log(f: &hdf5::File, s: &Snapshot, steps: usize) -> hdf5::Result<()> {
    let run = f.create_group("run")?;
    let iterations = iterations(&s.log, steps);
    vector(
        &run,
        "iterations",
        &[iterations.len()],
        &iterations,
        "step solver iterations of each step 0..N of the run (summary.json \
         iterations.per_step); -1 for the steps n..N not solved yet",
        "1",
    )?;
    scalar(
        &run,
        "max_violation",
        s.log.max_violation,
        "largest n·w over the Γ3,1 nodes and steps 0..n-1 (-inf: none yet)",
        "m/s",
    )?;
    scalar(
        &run,
        "max_kkt_residual",
        s.log.max_kkt_residual,
        "largest relative KKT residual over steps 0..n-1",
        "1",
    )?;
    Ok(())
}

/// `/scene`: the scene text that ran and where it was.
fn write_scene(f: &hdf5::File, id: &Identity) -> hdf5::Result<()> {
    let sc = f.create_group("scene")?;
    string_dataset(
        &sc,
        "text",
        &id.scene_text,
        "the scene file (TOML) that ran, after --set overrides",
    )?;
    str_attr(&sc, "path", &id.scene_path)?;
    str_attr(&sc, "absolute_path", &id.scene_path_absolute)?;
    str_attr(
        &sc,
        "description",
        "mesh.file in text is relative to the directory of absolute_path",
    )?;
    Ok(())
}

/// `/mesh`: its file, sizes, fingerprints and the dof of each node.
fn write_mesh(f: &hdf5::File, id: &Identity) -> hdf5::Result<()> {
    let mesh = f.create_group("mesh")?;
    str_attr(&mesh, "file", &id.mesh_path)?;
    mesh.new_attr::<u64>()
        .shape(())
        .create("nodes")?
        .write_scalar(&(id.nodes as u64))?;
    mesh.new_attr::<u64>()
        .shape(())
        .create("triangles")?
        .write_scalar(&(id.triangles as u64))?;
    scalar(
        &mesh,
        "fingerprint",
        id.mesh_fingerprint,
        "64-bit hash of the node coordinates' bits and the triangles' node indices \
         (src/checkpoint/fingerprint.rs mesh_fingerprint)",
        "1",
    )?;
    scalar(
        &mesh,
        "groups_fingerprint",
        id.groups_fingerprint,
        "64-bit hash of the physical groups: name, tag, dimension, facets, cells",
        "1",
    )?;
    vector(
        &mesh,
        "dof_of",
        &[id.nodes, id.dof_of.len() / id.nodes.max(1)],
        &id.dof_of,
        "free dof index of each node's x, y (and z in 3D) component (row = node), -1 on Γ1 \
         (w = 0)",
        "1",
    )?;
    Ok(())
}

/// `/physics`: every physics key of the scene, which resume compares.
fn write_physics(f: &hdf5::File, id: &Identity) -> hdf5::Result<()> {
    let physics = f.create_group("physics")?;
    str_attr(
        &physics,
        "description",
        "every physics key of the scene (all but name, time, output, checkpoint) as \
         'dotted.key' = TOML value; resume refuses a scene that differs",
    )?;
    for (k, v) in &id.physics {
        str_attr(&physics, k, v)?;
    }
    Ok(())
}

/// The group `/series`: the frames written before step n and their checksums.
fn write_series(f: &hdf5::File, frames: &[FrameSum]) -> hdf5::Result<()> {
    let g = f.create_group("series")?;
    str_attr(
        &g,
        "description",
        "the frames of the series written before step `step`, entries 0..frames-1 of each \
         array (the rest is padding); resume checks that each is on disk with these bytes \
         (docs/restart.md, 'What resume verifies')",
    )?;
    scalar(
        &g,
        "frames",
        frames.len() as u64,
        "number of frames recorded",
        "1",
    )?;
    let c = series_columns(frames);
    let len = [c.step.len()];
    vector(
        &g,
        "step",
        &len,
        &c.step,
        "step n of each frame (-1: padding)",
        "1",
    )?;
    vector(&g, "time", &len, &c.time, "t_n of each frame", "s")?;
    vector(
        &g,
        "crc32",
        &len,
        &c.crc32,
        "CRC-32 of the frame: of its whole .vtu file, or for solution.vtkhdf of its field \
         values as stored (little-endian; point fields by name, then cell fields by name)",
        "1",
    )?;
    vector(
        &g,
        "bytes",
        &len,
        &c.bytes,
        "number of bytes the CRC-32 covers",
        "1",
    )
}

#[cfg(test)]
mod tests {
    use super::{Raw, Vectors};

    /// The state's vectors and the Prony states as they come, one row at a time, are
    /// written as their little-endian bytes in any range taken in order, also across a
    /// row's end; a range behind the last row taken, or a row that never comes, is an
    /// error, not a wrong value.
    #[test]
    fn values_and_states_are_written_as_their_little_endian_bytes_in_any_range_in_order() {
        let rows = [[1.5, -0.0], [f64::MIN_POSITIVE, 3.25e300], [7.0, -1e-300]];
        let values: Vec<f64> = rows.concat();
        let bytes: Vec<u8> = values.iter().flat_map(|x| x.to_le_bytes()).collect();
        let ranges = [(0, 5), (5, 5), (5, 16), (16, 29), (29, 48)];
        let queued = || {
            let (tx, states) = Vectors::queue(2, 3);
            std::thread::spawn(move || rows.iter().for_each(|r| tx.send(r.to_vec()).unwrap()));
            states
        };
        let states = queued();
        for raw in [
            Raw::F64s(&values),
            Raw::Bytes(bytes.clone()),
            Raw::States(&states),
        ] {
            assert_eq!(raw.len(), 48);
            for (from, to) in ranges {
                let mut out = vec![0u8; to - from];
                raw.write_range(from, &mut out).unwrap();
                assert_eq!(out, bytes[from..to], "{from}..{to}");
            }
        }
        assert_eq!(states.crc(), Some(crc32fast::hash(&bytes)));
        let states = queued();
        let mut out = vec![0u8; 8];
        Raw::States(&states).write_range(32, &mut out).unwrap();
        assert!(
            states.write_range(0, &mut out).is_err(),
            "behind the rows taken"
        );
        let (tx, short) = Vectors::queue(2, 3);
        tx.send(rows[0].to_vec()).unwrap();
        drop(tx);
        assert!(short.write_range(8, &mut out).is_ok());
        assert!(
            short.write_range(16, &mut out).is_err(),
            "a row that never came"
        );
        assert_eq!(short.crc(), None);
    }
}
