//! A series in pieces (a run over MPI ranks, docs/output.md): each frame a `.pvtu` listing
//! one `.vtu` piece per rank's part of the mesh. VTK's own parallel reader reads it with the
//! right point and cell counts and the values of every point by its global id; this crate's
//! reader joins the pieces into the whole mesh, in its order; resume verifies every piece,
//! and a step written again in one file replaces its pieces.

use crate::common;

use std::path::Path;

use viscontact::mesh::Points;
use viscontact::output::read::{read_frame, read_series};
use viscontact::output::{Field, Frame, FrameSum, Geometry, Options, Resumed, Series};

const RUN: &str = "pieces-run";

/// A 3 × 2 grid of unit squares, two triangles each: 12 points, 12 cells.
fn grid() -> (Vec<[f64; 3]>, Vec<usize>) {
    let points = (0..12)
        .map(|i| [(i % 4) as f64, (i / 4) as f64, 0.0])
        .collect();
    let mut cells = Vec::new();
    for j in 0..2 {
        for i in 0..3 {
            let a = 4 * j + i;
            cells.extend([a, a + 1, a + 5, a, a + 5, a + 4]);
        }
    }
    (points, cells)
}

/// The cells in three pieces by the column of their square (one piece per column).
fn pieces() -> Vec<u32> {
    (0..12).map(|c| ((c / 2) % 3) as u32).collect()
}

/// Frame k's displacement (3 a point) and von Mises stress (1 a cell).
fn values(k: usize) -> (Vec<f64>, Vec<f64>) {
    let u = (0..36)
        .map(|i| (i as f64 + 0.25) * (k as f64 + 1.0))
        .collect();
    let vm = (0..12).map(|c| 1.0 / (c as f64 + k as f64 + 1.0)).collect();
    (u, vm)
}

/// `f` of the grid's geometry, with region 7 everywhere and `pieces`.
fn with_geometry<T>(pieces: &[u32], f: impl FnOnce(&Geometry) -> T) -> T {
    let (points, cells) = grid();
    let region = vec![7; 12];
    f(&Geometry {
        points: Points::Every(&points),
        cells: &cells,
        nodes_per_cell: 3,
        region: &region,
        material_region: &[],
        pieces,
        pieces_by_ranks: false,
    })
}

/// Writes the frames of `steps` into `dir` (`pieces`: each cell's piece, or none), to a new
/// series or to `series`, and returns the checksums of the series' frames.
fn write(
    dir: &Path,
    pieces: &[u32],
    steps: std::ops::Range<usize>,
    series: Option<Series>,
) -> Vec<FrameSum> {
    let create = |g: &Geometry| Series::create(dir, g, RUN, &Options::default()).unwrap();
    let mut series = series.unwrap_or_else(|| with_geometry(pieces, create));
    for k in steps {
        let (u, vm) = values(k);
        let frame = Frame {
            step: k,
            time: k as f64 * 0.5,
            point_data: vec![Field {
                name: "displacement",
                components: 3,
                values: &u,
            }],
            cell_data: vec![Field {
                name: "von_mises",
                components: 1,
                values: &vm,
            }],
        };
        series.write(&frame).unwrap();
    }
    series.finish().unwrap();
    series.checksums()
}

#[test]
fn a_series_in_pieces_is_read_whole_by_vtk_and_by_this_crate() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    write(dir, &pieces(), 0..3, None);
    for k in 0..3 {
        let name = format!("solution_{k:06}");
        assert!(dir.join(format!("{name}.pvtu")).is_file(), "{name}.pvtu");
        for r in 0..3 {
            assert!(dir.join(&name).join(format!("{name}_{r}.vtu")).is_file());
        }
        assert!(!dir.join(format!("{name}.vtu")).exists());
    }
    // This crate's reader: the whole mesh, its points in their order.
    let (_, frames) = read_series(dir).unwrap();
    assert_eq!(frames.len(), 3);
    let (points, cells) = grid();
    for (k, (time, frame)) in frames.iter().enumerate() {
        assert_eq!(*time, k as f64 * 0.5);
        let v = read_frame(frame).unwrap();
        let (u, vm) = values(k);
        assert_eq!(v.points, points);
        assert_eq!(v.point_field("displacement").unwrap().values, u);
        assert!(v.point_field("GlobalPointIds").is_none());
        // The cells come piece by piece: compare them as sets with their values.
        let mut got: Vec<(Vec<usize>, u64)> = (v.cells.iter().cloned())
            .zip(
                v.cell_field("von_mises")
                    .unwrap()
                    .values
                    .iter()
                    .map(|x| x.to_bits()),
            )
            .collect();
        let mut want: Vec<(Vec<usize>, u64)> = (cells.chunks(3).map(<[usize]>::to_vec))
            .zip(vm.iter().map(|x| x.to_bits()))
            .collect();
        got.sort();
        want.sort();
        assert_eq!(got, want, "frame {k}'s cells");
    }
    if !common::python_available() {
        return;
    }
    // VTK's parallel reader: 3 pieces of 2 columns of squares hold 3 × 6 points, the 12
    // cells, and each point the value of the point its global id names.
    let script = r#"
import sys, vtk
from vtk.util.numpy_support import vtk_to_numpy as n
r = vtk.vtkXMLPUnstructuredGridReader()
r.SetFileName(sys.argv[1])
r.Update()
g = r.GetOutput()
ids = g.GetPointData().GetGlobalIds()
print(g.GetNumberOfPoints(), g.GetNumberOfCells(), ids.GetName())
u = n(g.GetPointData().GetArray("displacement"))
for i, row in zip(n(ids), u):
    print(int(i), *[repr(float(x)) for x in row])
print("region", *sorted(set(int(x) for x in n(g.GetCellData().GetArray("region")))))
"#;
    let text = common::python_out(script, &[&dir.join("solution_000002.pvtu")]);
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("18 12 GlobalPointIds"));
    let (u, _) = values(2);
    let mut seen = vec![0; 12];
    for _ in 0..18 {
        let words: Vec<&str> = lines.next().unwrap().split(' ').collect();
        let i: usize = words[0].parse().unwrap();
        let row: Vec<f64> = words[1..].iter().map(|w| w.parse().unwrap()).collect();
        assert_eq!(row, u[3 * i..3 * i + 3], "point {i}");
        seen[i] += 1;
    }
    assert!(
        seen.iter().all(|&s| s >= 1),
        "every point is in a piece: {seen:?}"
    );
    assert_eq!(lines.next(), Some("region 7"));
}

#[test]
fn resume_verifies_every_piece_and_a_step_written_again_in_one_file_replaces_its_pieces() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let sums = write(dir, &pieces(), 0..3, None);
    assert_eq!(sums.len(), 3);
    let resume = |resumed: &Resumed| {
        with_geometry(&[], |whole| {
            Series::resume(dir, whole, RUN, &Options::default(), resumed)
        })
    };
    let checkpoint = dir.join("checkpoint.h5");
    let resumed = Resumed {
        checkpoint: &checkpoint,
        step: 2,
        frames: Some(&sums),
    };
    // One byte of one piece of frame 1 changed: resume refuses, naming the frame.
    let piece = dir.join("solution_000001/solution_000001_2.vtu");
    let good = std::fs::read(&piece).unwrap();
    let mut bad = good.clone();
    let at = bad.len() - 40;
    bad[at] ^= 1;
    std::fs::write(&piece, &bad).unwrap();
    let err = resume(&resumed).err().unwrap();
    let msg = err.to_string();
    assert_eq!(err.exit_code(), 2, "{msg}");
    assert!(msg.contains("damaged") && msg.contains("step 1"), "{msg}");
    assert!(msg.contains("solution_000001.pvtu"), "{msg}");
    // So does a missing piece.
    std::fs::remove_file(&piece).unwrap();
    let err = resume(&resumed).err().unwrap();
    assert!(err.to_string().contains("step 1"), "{err}");
    std::fs::write(&piece, &good).unwrap();
    // Intact again: resumed in one file a frame (one rank), step 2 is written again as a
    // .vtu, and its .pvtu and pieces go.
    let series = resume(&resumed).unwrap();
    let sums = write(dir, &[], 2..3, Some(series));
    assert_eq!(sums.len(), 3);
    assert!(dir.join("solution_000002.vtu").is_file());
    assert!(!dir.join("solution_000002.pvtu").exists());
    assert!(!dir.join("solution_000002").exists());
    assert!(dir.join("solution_000001.pvtu").is_file());
    let (_, frames) = read_series(dir).unwrap();
    let names: Vec<String> = frames
        .iter()
        .map(|(_, f)| f.path().file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    assert_eq!(
        names,
        [
            "solution_000000.pvtu",
            "solution_000001.pvtu",
            "solution_000002.vtu"
        ]
    );
    for (k, (_, frame)) in frames.iter().enumerate() {
        let v = read_frame(frame).unwrap();
        assert_eq!(v.point_field("displacement").unwrap().values, values(k).0);
    }
    // Both layouts verify on a second resume.
    let resumed = Resumed {
        checkpoint: &checkpoint,
        step: 3,
        frames: Some(&sums),
    };
    resume(&resumed).unwrap();
}
