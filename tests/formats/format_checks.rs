//! Format checks with independent readers (issue 2, "Format checks"): what `viscontact`
//! writes and what it reports about gmsh files is read back with Python (meshio, xml.etree).
//!
//! (a) The paper scene at h = k = 1/8 is run through the binary; scripts/check_vtu.py reads
//!     the whole series with meshio, and an inline script compares the last frame's
//!     displacement with summary.json and the .pvd times with t_n = n/8.
//! (b) Every shipped .msh under meshes/ is read by `viscontact mesh-info --json` and by
//!     scripts/check_msh_groups.py (meshio); the physical groups must agree.
//!
//! Without meshio (`python3 -c "import meshio"` fails) the tests print a loud note and
//! pass, unless the environment variable CI is set: CI installs meshio, so there they fail.

use crate::common;

use std::collections::BTreeMap;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const BIN: &str = env!("CARGO_BIN_EXE_viscontact");

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn python() -> Command {
    let mut c = Command::new("python3");
    c.current_dir(common::repo())
        .env("PYTHONIOENCODING", "utf-8")
        .env("PYTHONUTF8", "1");
    c
}

/// Whether meshio can be imported; panics when it cannot and CI is set.
fn meshio_available(test: &str) -> bool {
    let probe = python().args(["-c", "import meshio"]).output();
    let why = match &probe {
        Ok(o) if o.status.success() => return true,
        Ok(o) => text(&o.stderr),
        Err(e) => format!("cannot run python3: {e}"),
    };
    if std::env::var_os("CI").is_some() {
        panic!("{test}: CI is set but `python3 -c \"import meshio\"` fails: {why}");
    }
    // Written to the stderr handle, not with eprintln!, so that the test harness's output
    // capture does not swallow the note of a passing test.
    let bar = "*".repeat(76);
    let note = format!(
        "\n{bar}\n*** SKIPPED {test}: python3 with meshio is not available.\n*** ({})\n\
         *** Install it with `pip install meshio` to run this format check;\n\
         *** with CI set, this test fails instead of skipping.\n{bar}\n",
        why.trim()
    );
    let _ = std::io::stderr().lock().write_all(note.as_bytes());
    false
}

fn checked(what: &str, out: std::io::Result<Output>) -> String {
    let out = out.unwrap_or_else(|e| panic!("{what}: cannot start: {e}"));
    assert!(
        out.status.success(),
        "{what} failed with {:?}\n--- stdout ---\n{}--- stderr ---\n{}",
        out.status.code(),
        text(&out.stdout),
        text(&out.stderr)
    );
    text(&out.stdout)
}

// ---- (a) the written series ----------------------------------------------------------------

/// Reads DIR/solution.pvd (xml.etree) and its last frame (meshio); prints JSON with the
/// times, the number of points and max |displacement| of the last frame.
const READ_SERIES: &str = r#"
import json, os, sys
import xml.etree.ElementTree as ET
import meshio
import numpy as np
d = sys.argv[1]
root = ET.parse(os.path.join(d, "solution.pvd")).getroot()
sets = list(root.iter("DataSet"))
times = [float(s.get("timestep")) for s in sets]
last = meshio.read(os.path.join(d, sets[-1].get("file")), file_format="vtu")
u = np.asarray(last.point_data["displacement"], dtype=np.float64)
print(json.dumps({
    "times": times,
    "points": int(len(last.points)),
    "u_shape": list(u.shape),
    "u_max": float(np.max(np.abs(u))),
}))
"#;

/// Runs examples/`name`.toml on meshes/`mesh` with `steps` steps into `out`.
fn run_example(out: &Path, name: &str, mesh: &str, steps: usize) {
    let mesh_key = format!("mesh.file={}", common::mesh_path(mesh));
    let steps_key = format!("time.steps={steps}");
    let scene = format!("examples/{name}.toml");
    checked(
        &format!("viscontact run {scene} ({mesh}, {steps} steps)"),
        Command::new(BIN)
            .current_dir(common::repo())
            .args(["run", &scene, "--quiet", "--out"])
            .arg(out)
            .args(["--set", &mesh_key, "--set", &steps_key])
            .output(),
    );
}

#[test]
fn paper_series_reads_back_with_meshio() {
    if !meshio_available("paper_series_reads_back_with_meshio") {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    run_example(&out, "paper", "paper/rect_008.msh", 8);

    let report = checked(
        "scripts/check_vtu.py",
        python()
            .arg("scripts/check_vtu.py")
            .arg(&out)
            .args([
                "--expect-points",
                "81",
                "--expect-fields",
                "displacement,velocity,contact_pressure,friction_traction,contact_state,stress,von_mises,region",
            ])
            .output(),
    );
    assert!(report.starts_with("ok: 9 files, 81 points"), "{report}");

    let read: serde_json::Value = serde_json::from_str(&checked(
        "inline meshio reader",
        python().args(["-c", READ_SERIES]).arg(&out).output(),
    ))
    .expect("the reader prints JSON");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap())
            .expect("summary.json is JSON");

    // t_n = n k, k = 1/8: all exact in binary, so the written times must be exact.
    let times: Vec<f64> = read["times"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t.as_f64().unwrap())
        .collect();
    let want: Vec<f64> = (0..=8).map(|n| n as f64 / 8.0).collect();
    assert_eq!(times, want, ".pvd times");

    assert_eq!(read["points"], 81);
    assert_eq!(read["u_shape"], serde_json::json!([81, 3]));
    let u_meshio = read["u_max"].as_f64().unwrap();
    let u_summary = summary["final"]["u_max"].as_f64().expect("final.u_max");
    assert!(
        u_summary > 0.0,
        "the paper scene moves: u_max = {u_summary}"
    );
    let rel = (u_meshio - u_summary).abs() / u_summary;
    assert!(
        rel <= 1e-12,
        "max|displacement| of the last frame: meshio {u_meshio:e}, summary.json {u_summary:e} (rel {rel:e})"
    );
    assert_eq!(summary["steps"], 8);
    assert_eq!(summary["nodes"], 81);
}

// ---- (b) the shipped meshes ----------------------------------------------------------------

/// Every .msh below `dir`, sorted.
fn msh_files(dir: &Path) -> Vec<PathBuf> {
    let mut found = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "msh") {
                found.push(p);
            }
        }
    }
    found.sort();
    found
}

/// The number of line elements meshio reads, and the number of triangle edges that belong
/// to one triangle only (the boundary of the triangulation).
const COUNT_LINES: &str = r#"
import json, sys
from collections import Counter
import meshio
m = meshio.read(sys.argv[1], file_format="gmsh")
lines = sum(len(b.data) for b in m.cells if b.type == "line")
edges = Counter()
for b in m.cells:
    if b.type == "triangle":
        for a, c, d in b.data.tolist():
            for e in ((a, c), (c, d), (d, a)):
                edges[tuple(sorted(e))] += 1
print(json.dumps({"lines": lines, "boundary_edges": sum(1 for n in edges.values() if n == 1)}))
"#;

#[derive(Debug, PartialEq)]
struct Group {
    tag: i64,
    dim: i64,
    elements: u64,
}

/// The boundary parts of a scene (docs/scene.md, `[mesh.groups]`), which every shipped mesh
/// has and which partition its boundary (load groups such as "top" are subsets of Γ2).
const PARTS: [&str; 4] = ["Γ1", "Γ2", "Γ3,1", "Γ3,2"];

#[test]
fn shipped_meshes_have_the_same_groups_in_meshio() {
    if !meshio_available("shipped_meshes_have_the_same_groups_in_meshio") {
        return;
    }
    let files = msh_files(&common::repo().join("meshes"));
    assert!(files.len() >= 3, "shipped meshes: {files:?}");
    for file in &files {
        let name = file.display().to_string();

        let ours: serde_json::Value = serde_json::from_str(&checked(
            &format!("viscontact mesh-info {name} --json"),
            Command::new(BIN)
                .args(["mesh-info", "--json"])
                .arg(file)
                .output(),
        ))
        .expect("mesh-info --json prints JSON");
        if ours["dim"] == 3 {
            // Tetrahedral meshes (meshes/3d/): shipped_3d_meshes_have_the_same_groups_in_meshio.
            continue;
        }
        let ours: BTreeMap<String, Group> = ours["groups"]
            .as_array()
            .unwrap()
            .iter()
            .map(|g| {
                (
                    g["name"].as_str().unwrap().to_string(),
                    Group {
                        tag: g["tag"].as_i64().unwrap(),
                        dim: g["dim"].as_i64().unwrap(),
                        elements: g["elements"].as_u64().unwrap(),
                    },
                )
            })
            .collect();

        let theirs: serde_json::Map<String, serde_json::Value> = serde_json::from_str(&checked(
            &format!("scripts/check_msh_groups.py {name}"),
            python()
                .arg("scripts/check_msh_groups.py")
                .arg(file)
                .output(),
        ))
        .expect("check_msh_groups.py prints JSON");
        let theirs: BTreeMap<String, Group> = theirs
            .iter()
            .map(|(k, g)| {
                (
                    k.clone(),
                    Group {
                        tag: g["tag"].as_i64().unwrap(),
                        dim: g["dim"].as_i64().unwrap(),
                        elements: g["elements"].as_u64().unwrap(),
                    },
                )
            })
            .collect();

        // Same names, and each with the same tag and dimension.
        assert_eq!(
            ours.keys().collect::<Vec<_>>(),
            theirs.keys().collect::<Vec<_>>(),
            "{name}: group names (viscontact vs meshio)"
        );
        for (g, o) in &ours {
            let t = &theirs[g];
            assert_eq!(
                (o.tag, o.dim),
                (t.tag, t.dim),
                "{name}: group {g}: (tag, dim) viscontact vs meshio"
            );
        }

        // Element counts. meshio keeps only the first physical tag of a gmsh entity in
        // cell_data["gmsh:physical"], so a group whose curves also belong to an earlier group
        // (the load groups "top", "right", "tip", "hole" share their curves with "Γ2") can
        // come out with zero elements there. check_msh_groups.py counts through
        // meshio's cell_sets, which keep every tag, but with an older meshio (or MSH 2.2) the
        // count falls back on that single tag; so a zero from meshio is not compared, every
        // nonzero count must be equal, and the boundary parts and the domain must be nonzero.
        for (g, o) in &ours {
            let t = &theirs[g];
            if t.elements == 0 {
                assert!(
                    t.dim == 1 && !PARTS.contains(&g.as_str()),
                    "{name}: meshio finds no elements in {g} (dim {}), viscontact {}",
                    t.dim,
                    o.elements
                );
                eprintln!(
                    "note: {name}: meshio reports 0 elements in {g} (first-tag rule), not compared"
                );
                continue;
            }
            assert_eq!(
                o.elements, t.elements,
                "{name}: group {g}: elements viscontact vs meshio"
            );
        }
        assert!(
            ours.values().any(|g| g.dim == 2 && g.elements > 0),
            "{name}: no 2D group"
        );

        // The total number of boundary line elements: the boundary parts Γ1, Γ2, Γ3,1, Γ3,2
        // partition the boundary, so their edge counts in viscontact add up to the line
        // elements meshio reads, which in turn are the edges of exactly one triangle.
        let lines: serde_json::Value = serde_json::from_str(&checked(
            &format!("inline meshio line count {name}"),
            python().args(["-c", COUNT_LINES]).arg(file).output(),
        ))
        .expect("JSON");
        let ours_total: u64 = PARTS
            .iter()
            .map(|p| {
                ours.get(*p)
                    .unwrap_or_else(|| panic!("{name}: no group {p}"))
                    .elements
            })
            .sum();
        assert_eq!(
            ours_total,
            lines["lines"].as_u64().unwrap(),
            "{name}: boundary line elements: Σ viscontact over {PARTS:?} vs meshio's line cells"
        );
        assert_eq!(
            ours_total,
            lines["boundary_edges"].as_u64().unwrap(),
            "{name}: boundary line elements vs boundary edges of meshio's triangles"
        );
    }
}

// ---- (c) 3D: a run on tetrahedra and the shipped tetrahedral meshes ------------------------

/// Reads a 3D run's series (xml.etree for the .pvd, meshio for the last frame); prints JSON
/// with the times, the cell blocks (type, count), the volumes of the tetrahedra as written,
/// the number of values and components of every point and cell field and max |displacement|,
/// max |u_z|.
const READ_SERIES_3D: &str = r#"
import json, os, sys
import xml.etree.ElementTree as ET
import meshio
import numpy as np
d = sys.argv[1]
root = ET.parse(os.path.join(d, "solution.pvd")).getroot()
sets = list(root.iter("DataSet"))
m = meshio.read(os.path.join(d, sets[-1].get("file")), file_format="vtu")
tets = np.concatenate([b.data for b in m.cells if b.type == "tetra"])
p = np.asarray(m.points, dtype=np.float64)
a, b, c, e = (p[tets[:, i]] for i in range(4))
vol = np.einsum("ij,ij->i", b - a, np.cross(c - a, e - a)) / 6.0
def shape(v):  # [values, components]; meshio may or may not squeeze 1 component
    v = np.asarray(v)
    return [int(v.shape[0]), 1 if v.ndim == 1 else int(v.shape[1])]
u = np.asarray(m.point_data["displacement"], dtype=np.float64)
print(json.dumps({
    "times": [float(s.get("timestep")) for s in sets],
    "cells": [[blk.type, int(len(blk.data))] for blk in m.cells],
    "min_volume": float(vol.min()),
    "volume": float(vol.sum()),
    "point_data": {k: shape(v) for k, v in m.point_data.items()},
    "cell_data": {k: [shape(x) for x in v] for k, v in m.cell_data.items()},
    "u_max": float(np.max(np.abs(u))),
    "u_z_max": float(np.max(np.abs(u[:, 2]))),
}))
"#;

#[test]
fn block_series_reads_back_with_meshio() {
    if !meshio_available("block_series_reads_back_with_meshio") {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    run_example(&out, "block", "3d/block_002.msh", 4);

    // block_002: (2n+1)(n+1)² = 45 nodes, 12 n³ = 96 tetrahedra for n = 2.
    let report = checked(
        "scripts/check_vtu.py",
        python()
            .arg("scripts/check_vtu.py")
            .arg(&out)
            .args([
                "--expect-points",
                "45",
                "--expect-fields",
                "displacement,velocity,contact_pressure,friction_traction,contact_state,stress,von_mises,region",
            ])
            .output(),
    );
    assert!(
        report.starts_with("ok: 5 files, 45 points, 96 cells"),
        "{report}"
    );

    let read: serde_json::Value = serde_json::from_str(&checked(
        "inline meshio reader (3D)",
        python().args(["-c", READ_SERIES_3D]).arg(&out).output(),
    ))
    .expect("the reader prints JSON");
    let times: Vec<f64> = read["times"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t.as_f64().unwrap())
        .collect();
    assert_eq!(
        times,
        [0.0, 0.25, 0.5, 0.75, 1.0],
        ".pvd times (exact in binary)"
    );
    assert_eq!(read["cells"], serde_json::json!([["tetra", 96]]));
    // The cells as meshio reads them are positively oriented and fill the block (volume 2).
    assert!(read["min_volume"].as_f64().unwrap() > 0.0, "{read}");
    let volume = read["volume"].as_f64().unwrap();
    assert!((volume - 2.0).abs() < 1e-12, "volume {volume}");
    // Vector fields have 3 components, the friction traction too (a tangent vector in 3D).
    assert_eq!(
        read["point_data"],
        serde_json::json!({
            "displacement": [45, 3],
            "velocity": [45, 3],
            "friction_traction": [45, 3],
            "contact_pressure": [45, 1],
            "contact_state": [45, 1],
        })
    );
    assert_eq!(
        read["cell_data"],
        serde_json::json!({"stress": [[96, 6]], "von_mises": [[96, 1]], "region": [[96, 1]]})
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap())
            .expect("summary.json is JSON");
    assert_eq!(summary["nodes"], 45);
    assert_eq!(summary["elements"], 96);
    let u_summary = summary["final"]["u_max"].as_f64().expect("final.u_max");
    let u_meshio = read["u_max"].as_f64().unwrap();
    assert!(u_summary > 0.0);
    let rel = (u_meshio - u_summary).abs() / u_summary;
    assert!(
        rel <= 1e-12,
        "meshio {u_meshio:e} vs summary.json {u_summary:e}"
    );
    assert!(
        read["u_z_max"].as_f64().unwrap() > 0.0,
        "the block moves in z"
    );
}

/// Counts what meshio reads in a tetrahedral mesh: triangles, tetrahedra, the faces of
/// exactly one tetrahedron (the boundary), and any other cell types.
const COUNT_FACES: &str = r#"
import json, sys
from collections import Counter
import meshio
m = meshio.read(sys.argv[1], file_format="gmsh")
faces = Counter()
for b in m.cells:
    if b.type == "tetra":
        for t in b.data.tolist():
            for f in ((t[1], t[2], t[3]), (t[0], t[2], t[3]), (t[0], t[1], t[3]), (t[0], t[1], t[2])):
                faces[tuple(sorted(f))] += 1
print(json.dumps({
    "triangles": sum(len(b.data) for b in m.cells if b.type == "triangle"),
    "tetrahedra": sum(len(b.data) for b in m.cells if b.type == "tetra"),
    "boundary_faces": sum(1 for n in faces.values() if n == 1),
    "other": sorted({b.type for b in m.cells} - {"triangle", "tetra"}),
}))
"#;

fn groups_from(v: &serde_json::Value) -> BTreeMap<String, Group> {
    let entry = |g: &serde_json::Value| Group {
        tag: g["tag"].as_i64().unwrap(),
        dim: g["dim"].as_i64().unwrap(),
        elements: g["elements"].as_u64().unwrap(),
    };
    match v {
        serde_json::Value::Array(a) => a
            .iter()
            .map(|g| (g["name"].as_str().unwrap().to_string(), entry(g)))
            .collect(),
        serde_json::Value::Object(o) => o.iter().map(|(k, g)| (k.clone(), entry(g))).collect(),
        other => panic!("unexpected groups JSON {other}"),
    }
}

#[test]
fn shipped_3d_meshes_have_the_same_groups_in_meshio() {
    if !meshio_available("shipped_3d_meshes_have_the_same_groups_in_meshio") {
        return;
    }
    let mut seen = 0;
    for file in &msh_files(&common::repo().join("meshes")) {
        let name = file.display().to_string();
        let info: serde_json::Value = serde_json::from_str(&checked(
            &format!("viscontact mesh-info {name} --json"),
            Command::new(BIN)
                .args(["mesh-info", "--json"])
                .arg(file)
                .output(),
        ))
        .expect("mesh-info --json prints JSON");
        if info["dim"] != 3 {
            continue;
        }
        seen += 1;
        let ours = groups_from(&info["groups"]);
        let theirs = groups_from(
            &serde_json::from_str::<serde_json::Value>(&checked(
                &format!("scripts/check_msh_groups.py {name}"),
                python()
                    .arg("scripts/check_msh_groups.py")
                    .arg(file)
                    .output(),
            ))
            .expect("check_msh_groups.py prints JSON"),
        );
        assert_eq!(
            ours.keys().collect::<Vec<_>>(),
            theirs.keys().collect::<Vec<_>>(),
            "{name}: group names (viscontact vs meshio)"
        );
        for (g, o) in &ours {
            let t = &theirs[g];
            assert_eq!(
                (o.tag, o.dim),
                (t.tag, t.dim),
                "{name}: group {g}: (tag, dim)"
            );
            // As in 2D: a zero from meshio (first-tag rule of older versions) is not
            // compared, and only load groups inside Γ2 may show it.
            if t.elements == 0 {
                assert!(
                    t.dim == 2 && !PARTS.contains(&g.as_str()),
                    "{name}: meshio finds no elements in {g}"
                );
                continue;
            }
            assert_eq!(o.elements, t.elements, "{name}: group {g}: elements");
        }

        let counts: serde_json::Value = serde_json::from_str(&checked(
            &format!("inline meshio face count {name}"),
            python().args(["-c", COUNT_FACES]).arg(file).output(),
        ))
        .expect("JSON");
        assert_eq!(counts["other"], serde_json::json!([]), "{name}");
        // The volume groups hold all tetrahedra.
        let tets = counts["tetrahedra"].as_u64().unwrap();
        assert_eq!(
            info["tetrahedra"].as_u64(),
            Some(tets),
            "{name}: tetrahedra"
        );
        let in_volumes: u64 = ours
            .values()
            .filter(|g| g.dim == 3)
            .map(|g| g.elements)
            .sum();
        assert_eq!(in_volumes, tets, "{name}: tetrahedra in volume groups");
        // Γ1 and Γ2 exist, and at least one part of Γ3 (the paper allows either to be
        // empty: slider.msh has no Γ3,1); the parts present partition the boundary: their
        // face counts add up to meshio's triangles, which are the faces of exactly one
        // tetrahedron.
        for p in ["Γ1", "Γ2"] {
            assert!(ours.contains_key(p), "{name}: no group {p}");
        }
        assert!(
            ours.contains_key("Γ3,1") || ours.contains_key("Γ3,2"),
            "{name}: no Γ3"
        );
        let parts: u64 = PARTS
            .iter()
            .filter_map(|p| ours.get(*p))
            .map(|g| g.elements)
            .sum();
        assert_eq!(
            parts,
            counts["triangles"].as_u64().unwrap(),
            "{name}: Σ parts vs triangles"
        );
        assert_eq!(
            parts,
            counts["boundary_faces"].as_u64().unwrap(),
            "{name}: Σ parts vs boundary faces of meshio's tetrahedra"
        );
    }
    // block_002/004/008, the two slabs, the slider.
    assert!(seen >= 6, "{seen} tetrahedral meshes under meshes/");
}
