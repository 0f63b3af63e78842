//! The output files (docs/output.md): `.vtu` frames and the `.pvd` collection.
//!
//! Written files are read back four ways: with VTK's own reader (Python `vtk`, every layout,
//! bit for bit), with this crate's reader (`output::read`, used by `plot`), as text (the
//! `.pvd`), and with meshio through `scripts/check_vtu.py` and a small inline script (bit for
//! bit again). vtkio no longer reads the frames: its XML parser ends the raw appended data at
//! the first `<` byte in it (see src/output/vtu.rs).
//! The meshio checks are skipped only when `python3 -c "import meshio"` fails; if meshio is
//! there but cannot read our files, the test fails.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use viscontact::mesh::Points;
use viscontact::output::{write_atomic, Field, Frame, Geometry, Options, OwnedField, Series};

/// The run id the series of these tests carry.
const RUN: &str = "test-run";

/// A series with the default options (zlib, Float64, every field), no region.
fn create(
    dir: &Path,
    points: &[[f64; 3]],
    cells: &[usize],
    per_cell: usize,
) -> viscontact::Result<Series> {
    let g = Geometry {
        points: Points::Every(points),
        cells,
        nodes_per_cell: per_cell,
        region: &[],
        material_region: &[],
        pieces: &[],
        pieces_by_ranks: false,
    };
    Series::create(dir, &g, RUN, &Options::default())
}

/// [`Series::reopen`] with the default options for run `run`.
fn reopen(dir: &Path, run: &str, last_step: usize) -> viscontact::Result<Series> {
    let g = Geometry {
        points: Points::Every(&POINTS),
        cells: &CELLS,
        nodes_per_cell: 3,
        region: &[],
        material_region: &[],
        pieces: &[],
        pieces_by_ranks: false,
    };
    Series::reopen(dir, &g, run, &Options::default(), last_step)
}
use viscontact::Error;

/// The unit square as two triangles.
const POINTS: [[f64; 3]; 4] = [
    [0.0, 0.0, 0.0],
    [1.0, 0.0, 0.0],
    [1.0, 1.0, 0.0],
    [0.0, 1.0, 0.0],
];
const CELLS: [usize; 6] = [0, 1, 2, 0, 2, 3];

const TIMES: [f64; 3] = [0.0, 0.03125, 0.1 + 0.2];

/// Values of frame `k` whose bits are awkward: repeating binary fractions, negative zero,
/// subnormals, huge and tiny magnitudes.
struct FrameValues {
    displacement: Vec<f64>,
    pressure: Vec<f64>,
    stress: Vec<f64>,
    von_mises: Vec<f64>,
}

fn frame_values(k: usize) -> FrameValues {
    let s = k as f64 + 1.0;
    FrameValues {
        displacement: (0..12)
            .map(|i| {
                if i % 3 == 2 {
                    0.0
                } else {
                    (i as f64 + 0.1) / (3.0 * s)
                }
            })
            .collect(),
        pressure: vec![-0.0, 5e-324 * s, 1e300 / s, std::f64::consts::PI * s],
        stress: (0..12)
            .map(|i| (i as f64 - 5.5) * 1e-7 / s + 1.0 / 7.0)
            .collect(),
        von_mises: vec![f64::MIN_POSITIVE * s, f64::MAX / s],
    }
}

fn frame<'a>(k: usize, v: &'a FrameValues) -> Frame<'a> {
    Frame {
        step: k,
        time: TIMES[k],
        point_data: vec![
            Field {
                name: "displacement",
                components: 3,
                values: &v.displacement,
            },
            Field {
                name: "contact_pressure",
                components: 1,
                values: &v.pressure,
            },
        ],
        cell_data: vec![
            Field {
                name: "stress",
                components: 6,
                values: &v.stress,
            },
            Field {
                name: "von_mises",
                components: 1,
                values: &v.von_mises,
            },
        ],
    }
}

/// Writes the 3-frame series into `dir`.
fn write_series(dir: &Path) -> Series {
    let mut series = create(dir, &POINTS, &CELLS, 3).unwrap();
    for k in 0..3 {
        let v = frame_values(k);
        let path = series.write(&frame(k, &v)).unwrap();
        assert_eq!(path, dir.join(format!("solution_{k:06}.vtu")));
    }
    series.finish().unwrap();
    assert!(dir.join("solution.pvd").is_file());
    series
}

fn assert_bits(what: &str, got: &[f64], want: &[f64]) {
    assert_eq!(got.len(), want.len(), "{what}: length");
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        assert_eq!(
            g.to_bits(),
            w.to_bits(),
            "{what}[{i}]: got {g:e}, want {w:e}"
        );
    }
}

#[test]
fn vtu_frames_read_back_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    write_series(dir.path());
    for k in 0..3 {
        let path = dir.path().join(format!("solution_{k:06}.vtu"));
        let bytes = std::fs::read(&path).unwrap();
        let text = String::from_utf8_lossy(&bytes);
        assert!(text.contains("type=\"UnstructuredGrid\""));
        assert!(text.contains("header_type=\"UInt64\""));
        assert!(text.contains("byte_order=\"LittleEndian\""));
        assert!(
            text.contains("compressor=\"vtkZLibDataCompressor\""),
            "frames are zlib-compressed by default"
        );
        assert!(text.contains("<AppendedData encoding=\"raw\">"));
        assert!(
            text.contains(
                "Name=\"stress\" NumberOfComponents=\"6\" ComponentName0=\"XX\" \
                 ComponentName1=\"YY\" ComponentName2=\"ZZ\" ComponentName3=\"XY\" \
                 ComponentName4=\"YZ\" ComponentName5=\"XZ\""
            ),
            "the symmetric tensor's components are named in ParaView's order"
        );

        let vtu = viscontact::output::read::read_vtu(&path).unwrap();
        let flat: Vec<f64> = POINTS.iter().flatten().copied().collect();
        let points: Vec<f64> = vtu.points.iter().flatten().copied().collect();
        assert_bits("points", &points, &flat);
        assert_eq!(
            vtu.cells,
            CELLS.chunks(3).map(<[usize]>::to_vec).collect::<Vec<_>>()
        );
        let v = frame_values(k);
        let names: Vec<_> = vtu.point_data.iter().map(|a| a.name.as_str()).collect();
        assert_eq!(names, ["displacement", "contact_pressure"]);
        let names: Vec<_> = vtu.cell_data.iter().map(|a| a.name.as_str()).collect();
        assert_eq!(names, ["stress", "von_mises"]);
        for (name, want, comps) in [
            ("displacement", &v.displacement, 3),
            ("contact_pressure", &v.pressure, 1),
            ("stress", &v.stress, 6),
            ("von_mises", &v.von_mises, 1),
        ] {
            let a = vtu
                .point_field(name)
                .or_else(|| vtu.cell_field(name))
                .unwrap();
            assert_eq!(a.components, comps, "{name}");
            assert_bits(name, &a.values, want);
        }
    }
}

fn pvd_entries(text: &str) -> Vec<(String, String)> {
    let attr = |el: &str, name: &str| {
        let start = el.find(&format!(" {name}=\"")).unwrap() + name.len() + 3;
        el[start..start + el[start..].find('"').unwrap()].to_string()
    };
    text.split("<DataSet")
        .skip(1)
        .map(|el| {
            let el = &el[..el.find("/>").unwrap()];
            (attr(el, "timestep"), attr(el, "file"))
        })
        .collect()
}

#[test]
fn pvd_lists_every_frame_with_its_exact_time() {
    let dir = tempfile::tempdir().unwrap();
    let series = write_series(dir.path());
    let text = std::fs::read_to_string(dir.path().join("solution.pvd")).unwrap();
    assert!(text.contains("<VTKFile type=\"Collection\""), "{text}");
    assert!(text.contains(
        "<DataSet timestep=\"0.03125\" group=\"\" part=\"0\" file=\"solution_000001.vtu\"/>"
    ));
    let entries = pvd_entries(&text);
    assert_eq!(entries.len(), 3);
    for (k, (t, file)) in entries.iter().enumerate() {
        assert_eq!(
            t.parse::<f64>().unwrap().to_bits(),
            TIMES[k].to_bits(),
            "{t}"
        );
        assert_eq!(file, &format!("solution_{k:06}.vtu"));
    }
    let listed: Vec<_> = series.files().to_vec();
    assert_eq!(
        listed,
        (0..3)
            .map(|k| (TIMES[k], format!("solution_{k:06}.vtu")))
            .collect::<Vec<_>>()
    );
    // Nothing but the frames and the collection: no temporary left behind.
    let mut names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    assert_eq!(
        names,
        [
            "solution.pvd",
            "solution_000000.vtu",
            "solution_000001.vtu",
            "solution_000002.vtu"
        ]
    );
}

/// The `.pvd` lists every frame, so it is not rewritten per frame (a run of 10⁵ frames would
/// write gigabytes of it): the first frame writes it, later ones at most every PVD_EVERY, and
/// `finish` (before every checkpoint and at the end of a run) brings it up to date. What is on
/// disk is always a prefix of the frames, every listed file present.
#[test]
fn pvd_is_rewritten_at_most_every_second_and_complete_after_finish() {
    let dir = tempfile::tempdir().unwrap();
    let mut series = create(dir.path(), &POINTS, &CELLS, 3).unwrap();
    let v = frame_values(0);
    let frames = 40;
    let start = std::time::Instant::now();
    let mut listed_before_finish = 0;
    for k in 0..frames {
        series
            .write(&Frame {
                step: k,
                time: k as f64 * 0.5,
                ..frame(0, &v)
            })
            .unwrap();
        // The writer thread holds at most 3 frames, so frame 0's .pvd is on disk by now.
        if k >= 3 {
            let text = std::fs::read_to_string(dir.path().join("solution.pvd")).unwrap();
            let entries = pvd_entries(&text);
            assert!(!entries.is_empty() && entries.len() <= k + 1);
            for (i, (t, file)) in entries.iter().enumerate() {
                assert_eq!(file, &format!("solution_{i:06}.vtu"));
                assert_eq!(t.parse::<f64>().unwrap(), i as f64 * 0.5);
                assert!(dir.path().join(file).is_file(), "{file}");
            }
            listed_before_finish = entries.len();
        }
    }
    if start.elapsed() < viscontact::output::PVD_EVERY {
        assert_eq!(listed_before_finish, 1, "rewritten within a second");
    }
    series.finish().unwrap();
    let text = std::fs::read_to_string(dir.path().join("solution.pvd")).unwrap();
    assert_eq!(pvd_entries(&text).len(), frames);
}

#[test]
fn rewriting_a_step_replaces_its_entry_and_reopen_keeps_earlier_frames() {
    let dir = tempfile::tempdir().unwrap();
    let mut series = write_series(dir.path());
    let v = frame_values(1);
    series.write(&frame(1, &v)).unwrap();
    series.finish().unwrap();
    assert_eq!(series.files().len(), 3);

    // Another run's directory is refused, naming it.
    let err = reopen(dir.path(), "other-run", 1).err().unwrap();
    assert!(matches!(err, Error::Input(_)), "{err:?}");
    let msg = err.to_string();
    assert!(msg.contains("holds frames of another run"), "{msg}");
    assert!(msg.contains(&dir.path().display().to_string()), "{msg}");

    // A resume from step 1 keeps frames 0 and 1 and recomputes 2.
    let mut again = reopen(dir.path(), RUN, 1).unwrap();
    assert_eq!(
        again.files(),
        &[
            (TIMES[0], "solution_000000.vtu".to_string()),
            (TIMES[1], "solution_000001.vtu".to_string())
        ]
    );
    let v = frame_values(2);
    again.write(&frame(2, &v)).unwrap();
    again.finish().unwrap();
    let text = std::fs::read_to_string(dir.path().join("solution.pvd")).unwrap();
    assert_eq!(pvd_entries(&text).len(), 3);

    // Without a .pvd, reopen starts an empty series.
    let fresh = tempfile::tempdir().unwrap();
    let s = reopen(fresh.path(), RUN, 10).unwrap();
    assert!(s.files().is_empty());
}

#[test]
fn errors_name_the_path_or_the_field() {
    let dir = tempfile::tempdir().unwrap();
    // A directory that cannot be made: its parent is a regular file.
    let file = dir.path().join("plain_file");
    std::fs::write(&file, b"x").unwrap();
    let bad = file.join("out");
    let err = create(&bad, &POINTS, &CELLS, 3).err().unwrap();
    assert!(matches!(err, Error::Io { .. }), "{err:?}");
    assert!(
        err.to_string().contains(&bad.display().to_string()),
        "{err}"
    );

    // The directory vanishes between frames.
    let out = dir.path().join("gone");
    let mut series = create(&out, &POINTS, &CELLS, 3).unwrap();
    std::fs::remove_dir(&out).unwrap();
    let v = frame_values(0);
    // The write happens on the writer thread: its error surfaces at the next write or at
    // finish.
    series.write(&frame(0, &v)).unwrap();
    let err = series.finish().unwrap_err();
    assert!(matches!(err, Error::Io { .. }), "{err:?}");
    assert!(err.to_string().contains("solution_000000.vtu"), "{err}");

    // Fields that do not fit the mesh, and bad meshes.
    let mut series = create(&dir.path().join("ok"), &POINTS, &CELLS, 3).unwrap();
    let short = [0.0; 5];
    let mut f = frame(0, &v);
    f.point_data[0].values = &short;
    let err = series.write(&f).unwrap_err();
    assert!(matches!(err, Error::Input(_)), "{err:?}");
    assert!(err.to_string().contains("displacement"), "{err}");
    let mut f = frame(0, &v);
    f.cell_data[1].name = "stress";
    let err = series.write(&f).unwrap_err();
    assert!(err.to_string().contains("twice"), "{err}");
    let mut f = frame(0, &v);
    f.time = f64::NAN;
    assert!(matches!(series.write(&f), Err(Error::Input(_))));
    assert!(series.files().is_empty());

    assert!(matches!(
        create(dir.path(), &POINTS, &CELLS, 5),
        Err(Error::Input(_))
    ));
    assert!(matches!(
        create(dir.path(), &POINTS, &[0, 1, 4], 3),
        Err(Error::Input(_))
    ));
    assert!(matches!(
        create(dir.path(), &POINTS, &[0, 1, 2, 3], 3),
        Err(Error::Input(_))
    ));

    let err = write_atomic(&dir.path().join("no/such/dir/x.txt"), b"x").unwrap_err();
    assert!(err.to_string().contains("x.txt"), "{err}");
}

#[test]
fn fields_made_on_the_writer_thread_are_written_and_checked_there() {
    // The frame that `write` takes, and the same fields made by a closure on the writer
    // thread (`write_with`, how a run writes its steps): the files are equal byte for byte.
    let dir = tempfile::tempdir().unwrap();
    let v = frame_values(1);
    let eager = dir.path().join("eager");
    let mut series = create(&eager, &POINTS, &CELLS, 3).unwrap();
    series.write(&frame(1, &v)).unwrap();
    series.finish().unwrap();
    let owned = |fields: &[Field]| {
        fields
            .iter()
            .map(|f| OwnedField {
                name: f.name.to_string(),
                components: f.components,
                values: f.values.to_vec(),
            })
            .collect::<Vec<_>>()
    };
    let f = frame(1, &v);
    let (points, cells) = (owned(&f.point_data), owned(&f.cell_data));
    let later = dir.path().join("later");
    let mut series = create(&later, &POINTS, &CELLS, 3).unwrap();
    let path = series
        .write_with(f.step, f.time, move || (points, cells))
        .unwrap();
    series.finish().unwrap();
    assert_eq!(path, later.join("solution_000001.vtu"));
    assert_eq!(
        std::fs::read(&path).unwrap(),
        std::fs::read(eager.join("solution_000001.vtu")).unwrap()
    );

    // A field that does not fit the mesh is an input error of the next write or of finish,
    // naming the file and the field; nothing is written for that frame.
    let bad = dir.path().join("bad");
    let mut series = create(&bad, &POINTS, &CELLS, 3).unwrap();
    let short = OwnedField {
        name: "displacement".into(),
        components: 3,
        values: vec![0.0; 5],
    };
    series
        .write_with(2, 0.5, move || (vec![short], Vec::new()))
        .unwrap();
    let err = series.finish().unwrap_err();
    assert!(matches!(err, Error::Input(_)), "{err:?}");
    let msg = err.to_string();
    assert!(
        msg.contains("solution_000002.vtu") && msg.contains("displacement"),
        "{msg}"
    );
    assert!(!bad.join("solution_000002.vtu").exists());
    assert!(matches!(
        series.write_with(3, f64::INFINITY, || (Vec::new(), Vec::new())),
        Err(Error::Input(_))
    ));
}

#[test]
fn tetrahedra_are_vtk_tetra() {
    let dir = tempfile::tempdir().unwrap();
    let points = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
    ];
    let mut series = create(dir.path(), &points, &[0, 1, 2, 3], 4).unwrap();
    let u = [1.0; 12];
    let path = series
        .write(&Frame {
            step: 7,
            time: 0.5,
            point_data: vec![Field {
                name: "displacement",
                components: 3,
                values: &u,
            }],
            cell_data: vec![],
        })
        .unwrap();
    series.finish().unwrap();
    let text = String::from_utf8_lossy(&std::fs::read(&path).unwrap()).into_owned();
    assert!(text.contains("Name=\"types\""));
    let vtu = viscontact::output::read::read_vtu(&path).unwrap();
    assert_eq!(vtu.cells, [[0, 1, 2, 3]]);
    // VTK's reader sees a tetrahedron (VTK_TETRA = 10).
    let out = Command::new("python3")
        .args([
            "-c",
            "import sys, vtk\nr = vtk.vtkXMLUnstructuredGridReader()\nr.SetFileName(sys.argv[1])\n\
             r.Update()\nprint(r.GetOutput().GetCellType(0))",
        ])
        .arg(&path)
        .output()
        .unwrap();
    if out.status.success() {
        assert_eq!(String::from_utf8_lossy(&out.stdout).trim(), "10");
    }
}

// ---------------------------------------------------------------------------------------
// meshio

fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// True when `python3 -c "import meshio"` works; prints a loud note otherwise.
fn meshio_available() -> bool {
    let ok = Command::new("python3")
        .args(["-c", "import meshio"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    if !ok {
        // Straight to stderr, past the test harness's capture, so that the skip shows.
        let _ = writeln!(
            std::io::stderr(),
            "\n!!!!!!!! SKIPPED: python3 with meshio is not available, so the .vtu files were \
             NOT checked with an independent reader. Install it: pip install meshio !!!!!!!!\n"
        );
    }
    ok
}

fn check_vtu(dir: &Path, extra: &[&str]) -> std::process::Output {
    Command::new("python3")
        .arg(repo_root().join("scripts/check_vtu.py"))
        .arg(dir)
        .args(extra)
        .output()
        .expect("python3 runs")
}

#[test]
fn meshio_reads_the_series() {
    if !meshio_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    write_series(dir.path());

    let out = check_vtu(
        dir.path(),
        &[
            "--expect-points",
            "4",
            "--expect-fields",
            "displacement,contact_pressure,stress,von_mises",
        ],
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "check_vtu.py failed:\n{stdout}\n{stderr}"
    );
    assert!(stdout.starts_with("ok: 3 files, 4 points"), "{stdout}");

    // Wrong expectations and a broken frame must fail, with status 1.
    let out = check_vtu(dir.path(), &["--expect-points", "5"]);
    assert_eq!(out.status.code(), Some(1), "{out:?}");
    let out = check_vtu(dir.path(), &["--expect-fields", "displacement,velocity"]);
    assert_eq!(out.status.code(), Some(1), "{out:?}");
    let broken = dir.path().join("solution_000001.vtu");
    let text = std::fs::read(&broken).unwrap();
    std::fs::write(&broken, &text[..text.len() / 2]).unwrap();
    let out = check_vtu(dir.path(), &[]);
    assert_eq!(out.status.code(), Some(1), "{out:?}");
    assert!(String::from_utf8_lossy(&out.stderr).contains("solution_000001.vtu"));
    std::fs::remove_file(&broken).unwrap();
    let out = check_vtu(dir.path(), &[]);
    assert_eq!(out.status.code(), Some(1), "{out:?}");
}

#[test]
fn meshio_reads_the_values_bit_for_bit() {
    if !meshio_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    write_series(dir.path());
    // Python's repr of a float is its shortest round-trip form, so parsing it back in Rust
    // gives the same bits.
    let script = r#"
import sys, meshio
m = meshio.read(sys.argv[1])
print("points", *[repr(float(x)) for x in m.points.ravel()])
print("cells", m.cells[0].type, *[int(i) for i in m.cells[0].data.ravel()])
for name, a in m.point_data.items():
    print("point", name, a.dtype, *[repr(float(x)) for x in a.ravel()])
for name, blocks in m.cell_data.items():
    print("cell", name, blocks[0].dtype, *[repr(float(x)) for x in blocks[0].ravel()])
"#;
    for k in 0..3 {
        let path = dir.path().join(format!("solution_{k:06}.vtu"));
        let out = Command::new("python3")
            .args(["-c", script])
            .arg(&path)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "meshio cannot read {}:\n{}",
            path.display(),
            String::from_utf8_lossy(&out.stderr)
        );
        let stdout = String::from_utf8(out.stdout).unwrap();
        let v = frame_values(k);
        let flat: Vec<f64> = POINTS.iter().flatten().copied().collect();
        let mut seen = 0;
        for line in stdout.lines() {
            let words: Vec<&str> = line.split_whitespace().collect();
            let nums = |from: usize| -> Vec<f64> {
                words[from..].iter().map(|w| w.parse().unwrap()).collect()
            };
            match words[0] {
                "points" => assert_bits("meshio points", &nums(1), &flat),
                "cells" => {
                    assert_eq!(words[1], "triangle");
                    let ids: Vec<usize> = words[2..].iter().map(|w| w.parse().unwrap()).collect();
                    assert_eq!(ids, CELLS);
                }
                "point" | "cell" => {
                    assert_eq!(words[2], "float64", "{line}");
                    let want = match words[1] {
                        "displacement" => &v.displacement,
                        "contact_pressure" => &v.pressure,
                        "stress" => &v.stress,
                        "von_mises" => &v.von_mises,
                        other => panic!("unexpected field {other}"),
                    };
                    assert_bits(words[1], &nums(3), want);
                }
                other => panic!("unexpected line {other}"),
            }
            seen += 1;
        }
        assert_eq!(seen, 6, "{stdout}");
    }
}

/// VTK's own reader (`vtkXMLUnstructuredGridReader`, the one ParaView uses) reads every
/// frame of every layout this module writes — raw and zlib, Float64 and Float32 — with the
/// values, the region tags and the run id. Skipped (loudly) without the `vtk` Python package.
#[test]
fn vtk_reads_every_layout() {
    use viscontact::output::{Compression, Precision};
    let has_vtk = Command::new("python3")
        .args(["-c", "import vtk"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !has_vtk {
        eprintln!("\n!!!!!!!! SKIPPED: python3 with vtk is not available (pip install vtk)\n");
        return;
    }
    let script = r#"
import sys, vtk
from vtk.util.numpy_support import vtk_to_numpy
r = vtk.vtkXMLUnstructuredGridReader()
r.SetFileName(sys.argv[1])
r.Update()
g = r.GetOutput()
assert g.GetNumberOfPoints() > 0, "VTK read no points"
print("run_id", bytes(vtk_to_numpy(g.GetFieldData().GetArray("run_id"))).decode())
print("points", *[repr(float(x)) for x in vtk_to_numpy(g.GetPoints().GetData()).ravel()])
for kind, data in (("point", g.GetPointData()), ("cell", g.GetCellData())):
    for i in range(data.GetNumberOfArrays()):
        a = data.GetArray(i)
        v = vtk_to_numpy(a)
        print(kind, a.GetName(), v.dtype, *[repr(float(x)) for x in v.ravel()])
"#;
    for compression in [Compression::None, Compression::Zlib] {
        for precision in [Precision::Float64, Precision::Float32] {
            let dir = tempfile::tempdir().unwrap();
            let g = Geometry {
                points: Points::Every(&POINTS),
                cells: &CELLS,
                nodes_per_cell: 3,
                region: &[3, 8],
                material_region: &[],
                pieces: &[],
                pieces_by_ranks: false,
            };
            let options = Options {
                compression,
                precision,
                fields: None,
                ..Options::default()
            };
            let mut series = Series::create(dir.path(), &g, RUN, &options).unwrap();
            for k in 0..3 {
                let v = frame_values(k);
                series.write(&frame(k, &v)).unwrap();
            }
            series.finish().unwrap();
            let round = |x: &[f64]| -> Vec<f64> {
                match precision {
                    Precision::Float64 => x.to_vec(),
                    Precision::Float32 => x.iter().map(|&v| v as f32 as f64).collect(),
                }
            };
            let dtype = match precision {
                Precision::Float64 => "float64",
                Precision::Float32 => "float32",
            };
            for k in 0..3 {
                let path = dir.path().join(format!("solution_{k:06}.vtu"));
                let out = Command::new("python3")
                    .args(["-c", script])
                    .arg(&path)
                    .output()
                    .unwrap();
                let what = format!("{compression:?} {precision:?} {}", path.display());
                assert!(
                    out.status.success(),
                    "VTK cannot read {what}:\n{}",
                    String::from_utf8_lossy(&out.stderr)
                );
                let stdout = String::from_utf8(out.stdout).unwrap();
                let v = frame_values(k);
                let flat: Vec<f64> = POINTS.iter().flatten().copied().collect();
                let mut seen = Vec::new();
                for line in stdout.lines() {
                    let words: Vec<&str> = line.split_whitespace().collect();
                    let nums = |from: usize| -> Vec<f64> {
                        words[from..].iter().map(|w| w.parse().unwrap()).collect()
                    };
                    match words[0] {
                        "run_id" => assert_eq!(words[1], RUN),
                        "points" => assert_bits("VTK points", &nums(1), &flat),
                        _ if words[1] == "region" => {
                            assert_eq!(words[2], "int32", "{line}");
                            assert_eq!(nums(3), [3.0, 8.0]);
                        }
                        _ => {
                            assert_eq!(words[2], dtype, "{what}: {line}");
                            let want = match words[1] {
                                "displacement" => &v.displacement,
                                "contact_pressure" => &v.pressure,
                                "stress" => &v.stress,
                                "von_mises" => &v.von_mises,
                                other => panic!("unexpected field {other}"),
                            };
                            assert_bits(words[1], &nums(3), &round(want));
                        }
                    }
                    seen.push(words[..2].join(" "));
                }
                assert_eq!(seen.len(), 7, "{what}: {seen:?}");
            }
        }
    }
}

/// `[output] fields` leaves the others out of the files.
#[test]
fn only_the_chosen_fields_are_written() {
    let dir = tempfile::tempdir().unwrap();
    let g = Geometry {
        points: Points::Every(&POINTS),
        cells: &CELLS,
        nodes_per_cell: 3,
        region: &[1, 2],
        material_region: &[],
        pieces: &[],
        pieces_by_ranks: false,
    };
    let options = Options {
        fields: Some(vec!["von_mises".into()]),
        ..Options::default()
    };
    let mut series = Series::create(dir.path(), &g, RUN, &options).unwrap();
    let v = frame_values(0);
    let path = series.write(&frame(0, &v)).unwrap();
    series.finish().unwrap();
    let vtu = viscontact::output::read::read_vtu(&path).unwrap();
    assert!(vtu.point_data.is_empty());
    let names: Vec<_> = vtu.cell_data.iter().map(|a| a.name.as_str()).collect();
    assert_eq!(names, ["von_mises"]);
    assert_bits("von_mises", &vtu.cell_data[0].values, &v.von_mises);
}

// ---------------------------------------------------------------------------------------
// Speed

/// A structured triangulation of the unit square with `n × n` squares: (n+1)² nodes, 2n²
/// triangles.
fn square_mesh(n: usize) -> (Vec<[f64; 3]>, Vec<usize>) {
    let h = 1.0 / n as f64;
    let points = (0..=n)
        .flat_map(|j| (0..=n).map(move |i| [i as f64 * h, j as f64 * h, 0.0]))
        .collect();
    let id = |i: usize, j: usize| j * (n + 1) + i;
    let cells = (0..n)
        .flat_map(|j| (0..n).map(move |i| (i, j)))
        .flat_map(|(i, j)| {
            [
                id(i, j),
                id(i + 1, j),
                id(i + 1, j + 1),
                id(i, j),
                id(i + 1, j + 1),
                id(i, j + 1),
            ]
        })
        .collect();
    (points, cells)
}

/// A full frame of a run (every field docs/output.md lists) on ~33k nodes / ~65k triangles.
/// Prints the time per frame; the bound asserted is loose (shared CI machines), the target is
/// well under 50 ms in an optimized build.
#[test]
fn writing_a_33k_node_frame_is_fast() {
    let (points, cells) = square_mesh(181);
    let (np, nc) = (points.len(), cells.len() / 3);
    let dir = tempfile::tempdir().unwrap();
    let t = Instant::now();
    let mut series = create(dir.path(), &points, &cells, 3).unwrap();
    let setup = t.elapsed();
    let wave = |n: usize, c: usize, phase: f64| -> Vec<f64> {
        (0..n * c)
            .map(|i| (i as f64 * 0.001 + phase).sin())
            .collect()
    };
    let mut times = Vec::new();
    let frames = 8;
    for k in 0..frames {
        let ph = k as f64;
        let (u, w, p, f, s) = (
            wave(np, 3, ph),
            wave(np, 3, ph + 1.0),
            wave(np, 1, ph + 2.0),
            wave(np, 3, ph + 3.0),
            wave(np, 1, ph + 4.0),
        );
        let (sigma, vm) = (wave(nc, 6, ph + 5.0), wave(nc, 1, ph + 6.0));
        let frame = Frame {
            step: k,
            time: k as f64 / 64.0,
            point_data: vec![
                Field {
                    name: "displacement",
                    components: 3,
                    values: &u,
                },
                Field {
                    name: "velocity",
                    components: 3,
                    values: &w,
                },
                Field {
                    name: "contact_pressure",
                    components: 1,
                    values: &p,
                },
                Field {
                    name: "friction_traction",
                    components: 3,
                    values: &f,
                },
                Field {
                    name: "contact_state",
                    components: 1,
                    values: &s,
                },
            ],
            cell_data: vec![
                Field {
                    name: "stress",
                    components: 6,
                    values: &sigma,
                },
                Field {
                    name: "von_mises",
                    components: 1,
                    values: &vm,
                },
            ],
        };
        let t = Instant::now();
        series.write(&frame).unwrap();
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    series.finish().unwrap();
    let size = std::fs::metadata(dir.path().join("solution_000000.vtu"))
        .unwrap()
        .len();
    let mut sorted = times.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[frames / 2];
    let _ = writeln!(
        std::io::stderr(),
        "output speed: {np} nodes, {nc} triangles, {:.1} MB per frame: create {:.1} ms, \
         write per frame median {median:.1} ms, best {:.1} ms (all: {times:.1?})",
        size as f64 / 1e6,
        setup.as_secs_f64() * 1e3,
        sorted[0],
    );
    assert_eq!(series.files().len(), frames);
    assert!(median < 500.0, "writing a frame took {median:.1} ms");
}

/// `[output]` keys are checked: an unknown field name is an input error (exit 2) that names
/// `output.fields` and lists the fields; a run with a subset writes only those.
#[test]
fn output_keys_are_checked_and_applied() {
    let tmp = tempfile::tempdir().unwrap();
    let root = repo_root();
    let run = |out: &str, set: &str| {
        Command::new(env!("CARGO_BIN_EXE_viscontact"))
            .args([
                "run",
                "examples/paper.toml",
                "--quiet",
                "--set",
                set,
                "--out",
            ])
            .arg(tmp.path().join(out))
            .args(["--set", "mesh.file=../meshes/paper/rect_008.msh"])
            .current_dir(&root)
            .output()
            .unwrap()
    };
    let o = run("bad", r#"output.fields=["displacement", "bogus"]"#);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("output.fields") && err.contains("bogus"),
        "{err}"
    );
    assert!(err.contains("von_mises") && err.contains("region"), "{err}");

    let o = run("some", r#"output.fields=["von_mises", "region"]"#);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let last = tmp.path().join("some").join("solution_000032.vtu");
    let vtu = viscontact::output::read::read_vtu(&last).unwrap();
    assert!(vtu.point_data.is_empty());
    let names: Vec<_> = vtu.cell_data.iter().map(|a| a.name.as_str()).collect();
    assert_eq!(names, ["von_mises", "region"]);
    let region = &vtu.cell_data[1].values;
    assert!(
        region.iter().all(|&t| t > 0.0),
        "every cell is in a physical surface"
    );
}

/// A run on a mesh made at test time from a gmsh geometry of the kind users bring
/// (tests/data/user/embedded_spline.geo: an embedded spline, unused groups), refined with
/// `-clscale 0.12` so that every field spans several 32 KiB zlib blocks and von Mises is
/// stored (it does not shrink): VTK's own reader gives bit for bit the same values from the
/// default zlib frames as from the raw frames of the same run. Needs the gmsh CLI and
/// python3 with vtk (skipped loudly without).
#[test]
fn vtk_reads_zlib_frames_of_a_refined_user_mesh_as_the_raw_ones() {
    let tools = ["gmsh --version", "python3 -c 'import vtk'"]
        .iter()
        .all(|c| {
            Command::new("sh")
                .args(["-c", c])
                .output()
                .is_ok_and(|o| o.status.success())
        });
    if !tools {
        eprintln!("\n!!!!!!!! SKIPPED: needs the gmsh CLI and python3 with vtk\n");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let msh = dir.path().join("fine.msh");
    let geo = repo_root().join("tests/data/user/embedded_spline.geo");
    let o = Command::new("gmsh")
        .args(["-2", "-clscale", "0.12", "-format", "msh41", "-v", "0"])
        .arg(&geo)
        .arg("-o")
        .arg(&msh)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let scene = crate::common::SceneText::on(&msh)
        .set("name", "s")
        .set("time.end", 1.0)
        .set("time.steps", 3)
        .set("material.viscosity.theta", 0.1)
        .set("material.viscosity.zeta", 0.1)
        .set("material.elasticity.young", 0.1)
        .set("material.elasticity.poisson", 0.3)
        .literal("material.relaxation.prony", "[[1.0, 10.0]]")
        .section("contact")
        .traction(None, &["0.01", "-0.02*t"])
        .write(dir.path(), "s.toml");
    let script = r#"
import sys, vtk
from vtk.util.numpy_support import vtk_to_numpy
out = []
for name in sys.argv[1:]:
    r = vtk.vtkXMLUnstructuredGridReader()
    r.SetFileName(name)
    r.Update()
    g = r.GetOutput()
    assert g.GetNumberOfPoints() > 0, name
    arrays = [vtk_to_numpy(g.GetPoints().GetData())]
    for data in (g.GetPointData(), g.GetCellData()):
        arrays += [vtk_to_numpy(data.GetArray(i)) for i in range(data.GetNumberOfArrays())]
    out.append(b"".join(a.tobytes() for a in arrays))
assert out[0] == out[1], "zlib and raw frames differ"
print(g.GetNumberOfPoints(), sum(len(a.tobytes()) for a in arrays))
"#;
    let mut frames = Vec::new();
    for compression in ["zlib", "none"] {
        let out = dir.path().join(compression);
        let o = Command::new(env!("CARGO_BIN_EXE_viscontact"))
            .arg("run")
            .arg(&scene)
            .args(["--quiet", "--out"])
            .arg(&out)
            .args(["--set", &format!("output.compression=\"{compression}\"")])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        frames.push(out.join("solution_000003.vtu"));
    }
    let o = Command::new("python3")
        .args(["-c", script])
        .args(&frames)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let nodes: usize = text.split_whitespace().next().unwrap().parse().unwrap();
    assert!(nodes > 4000, "{nodes} nodes: the mesh is not refined");
    let (zlib, raw) = (
        frames[0].metadata().unwrap().len(),
        frames[1].metadata().unwrap().len(),
    );
    assert!(zlib < raw * 3 / 4, "zlib frame {zlib} bytes, raw {raw}");
}

/// Issue 49: `check`'s disk estimate of the frames is within 1.5 times what the paper's
/// example and the block write (it was 2.7 times the paper's: the size before zlib).
#[test]
fn the_disk_estimate_is_near_what_a_run_writes() {
    let tmp = tempfile::tempdir().unwrap();
    for (scene, set) in [
        ("examples/paper.toml", None),
        ("examples/paper.toml", Some("output.precision=\"float32\"")),
        ("examples/block.toml", None),
    ] {
        let out = tmp.path().join(format!("run{}", set.is_some()));
        let mut args = vec!["run", scene, "--quiet", "--out", out.to_str().unwrap()];
        args.extend(set.iter().flat_map(|s| ["--set", s]));
        let o = crate::common::viscontact(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let written: u64 = std::fs::read_dir(&out)
            .unwrap()
            .map(|e| e.unwrap())
            .filter(|e| e.file_name().to_string_lossy().starts_with("solution"))
            .map(|e| e.metadata().unwrap().len())
            .sum();
        let path = crate::common::repo().join(scene);
        let (s, _, disc) = crate::common::load(&path, &Vec::from_iter(set));
        let estimate = viscontact::resources::Estimate::new(&s, &disc, 0).disk();
        let ratio = estimate / written as f64;
        assert!(
            (1.0 / 1.5..=1.5).contains(&ratio),
            "{scene} {set:?}: {estimate} bytes estimated, {written} written"
        );
    }
}
