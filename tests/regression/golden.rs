//! Golden regression values: numbers from known-good runs, stored in
//! `tests/data/golden.json` and checked bit for bit.
//!
//! Each case runs a scene with the command-line tool (every `examples/*.toml` as it stands,
//! which `every_example_is_a_case` checks; variants of the paper's scene — friction, memory
//! kernels, schemes, solvers, meshes —, 3D blocks and a thin slab, a 2D corner) and
//! compares what summary.json says of it: the norms of u_N, the step solver's iterations
//! (total and most in a step), the largest KKT residual and normal-velocity violation, the
//! active and sticking nodes at the end. The build is
//! deterministic (the same bits whatever the thread count and across stop/resume), so the
//! comparison is exact: any change of a result shows, with the relative difference.
//!
//! The errors of the paper's Tables 1–3 (h = k, k fixed, h fixed; u_N against a reference
//! at h = k = 1/128) are stored under the key `study_tables` for levels 8, 16, 32: the
//! study's numbers, not only its orders, are checked the same way.
//!
//! A change that is meant to change results stores new values with
//! `VISCONTACT_GOLDEN=bless cargo test --release --test regression golden::` and says why in its commit.

use crate::common;

use common::{repo, SceneText};
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Mutex;
use viscontact::study::{self, StudyOptions, Vary};

/// A case's (or a table's) values by name.
type Values = BTreeMap<String, String>;

/// The stored file: sections of values by name.
type Golden = BTreeMap<String, Values>;

/// The section that holds the study's tables; every other section is a scene case.
const TABLES: &str = "study_tables";

/// A scene: `base` (an example) on `mesh` (relative to the repository; `None`: its own)
/// with the keys `edit` set (each to a TOML value), run with `set` overrides.
struct Case {
    name: &'static str,
    base: &'static str,
    mesh: Option<&'static str>,
    edit: &'static [(&'static str, &'static str)],
    set: &'static [&'static str],
}

const PAPER: &str = "paper.toml";
const BLOCK: &str = "block.toml";
const RELAXATION: &str = "material.relaxation";

const CASES: &[Case] = &[
    case("paper", PAPER, &[], &[]),
    case("bracket", "bracket.toml", &[], &[]),
    case("plate_hole", "plate_hole.toml", &[], &[]),
    case("block", BLOCK, &[], &[]),
    case("half_block", "half_block.toml", &[], &[]),
    case("punch", "punch.toml", &[], &[]),
    case("bimaterial", "bimaterial.toml", &[], &[]),
    case("paper_064", PAPER, &[], &[]).on("meshes/paper/rect_064.msh"),
    case("paper_F0.1", PAPER, &[], &["friction.normal_stress=0.1"]),
    case("paper_mu5", PAPER, &[], &["friction.coefficient=5"]),
    case("paper_implicit", PAPER, &[], &["scheme.history=\"implicit\""]),
    case("paper_clarabel", PAPER, &[], &["solver.contact=\"clarabel\""]),
    case(
        "paper_linear",
        PAPER,
        &[],
        &["contact.enabled=false", "friction.enabled=false"],
    ),
    case(
        "paper_power_law_compressed",
        PAPER,
        &[(RELAXATION, r#"{ expr = "0.2*(s+0.01)^(-0.5)" }"#)],
        &[],
    ),
    case(
        "paper_power_law_exact",
        PAPER,
        &[(
            RELAXATION,
            r#"{ expr = "0.2*(s+0.01)^(-0.5)", memory = "exact" }"#,
        )],
        &[],
    ),
    case(
        "paper_table",
        PAPER,
        &[(RELAXATION, "{ table = { s = [0, 0.5, 1], r = [1, 0.3, 0.1] } }")],
        &[],
    ),
    case("block_mu5", BLOCK, &[], &["friction.coefficient=5"]),
    case("block_unstructured", BLOCK, &[], &["time.steps=16"])
        .on("tests/data/3d/block_unstructured.msh"),
    case(
        "slab_t0008",
        PAPER,
        &[("mesh.model", r#""3d""#)],
        &[
            "time.steps=8",
            "time.end=0.25",
            "load.traction=[{on = \"top\", value = [\"0\", \"-0.1*x*(2-x)*min(t, 0.2)\", \"0\"]}, \
             {on = \"right\", value = [\"if(t <= 0.5, 0.01*(1-y)*t, 0.01*(1-y)*0.2)\", \"0\", \"0\"]}]",
        ],
    )
    .on("tests/data/3d/slab_t0008.msh"),
];

const fn case(
    name: &'static str,
    base: &'static str,
    edit: &'static [(&'static str, &'static str)],
    set: &'static [&'static str],
) -> Case {
    Case {
        name,
        base,
        mesh: None,
        edit,
        set,
    }
}

impl Case {
    /// The case on `mesh` (relative to the repository) in place of its example's mesh.
    const fn on(self, mesh: &'static str) -> Case {
        Case {
            mesh: Some(mesh),
            ..self
        }
    }
}

/// The values a case is checked by, as summary.json gives them (floats in Rust's shortest
/// round-trip form, which parses back to the same bits).
fn values(dir: &Path) -> Values {
    let s = common::summary(dir);
    let number = |v: &serde_json::Value| float(v.as_f64().unwrap());
    let mut out = BTreeMap::new();
    for key in ["u_l2", "u_h1", "u_max"] {
        out.insert(key.to_string(), number(&s["final"][key]));
    }
    for key in ["max_kkt_residual", "max_violation"] {
        out.insert(key.to_string(), number(&s["contact"][key]));
    }
    for key in ["active_at_end", "stick_at_end"] {
        out.insert(key.to_string(), s["contact"][key].to_string());
    }
    for key in ["total", "max"] {
        out.insert(
            format!("iterations_{key}"),
            s["iterations"][key].to_string(),
        );
    }
    out.insert("status".into(), s["status"].to_string());
    out
}

/// Runs `case` into a directory of `tmp`: its values.
fn run(case: &Case, tmp: &Path) -> Values {
    let mut scene = SceneText::example(case.base);
    if let Some(mesh) = case.mesh {
        scene = scene.mesh(repo().join(mesh));
    }
    let scene = case
        .edit
        .iter()
        .fold(scene, |scene, (key, value)| scene.literal(key, value))
        .write(tmp, &format!("{}.toml", case.name));
    let out = tmp.join(case.name);
    let mut args = vec![
        "run".to_string(),
        scene.display().to_string(),
        "--out".into(),
        out.display().to_string(),
        "--quiet".into(),
    ];
    for s in case.set {
        args.extend(["--set".to_string(), s.to_string()]);
    }
    let args: Vec<&str> = args.iter().map(|s| s.as_str()).collect();
    let (code, text) = common::cli(&args);
    assert_eq!(code, 0, "{}: {text}", case.name);
    values(&out)
}

/// The relative difference of two stored values, for the message (None: not numbers).
fn relative(a: &str, b: &str) -> Option<f64> {
    let (a, b) = (a.parse::<f64>().ok()?, b.parse::<f64>().ok()?);
    Some((a - b).abs() / a.abs().max(b.abs()).max(f64::MIN_POSITIVE))
}

/// The float's shortest round-trip form (parses back to the same bits).
fn float(x: f64) -> String {
    format!("{x:?}")
}

/// The paper's Tables 1–3 at levels 8, 16, 32 against h = k = 1/128 (one reference run
/// serves the three): for each table, the reference's norms and each level's errors.
fn study_tables() -> Values {
    let opts = StudyOptions {
        levels: vec![8, 16, 32],
        reference: 128,
        vary: vec![Vary::Both, Vary::H, Vary::K],
        repeat: Some(1),
        ..Default::default()
    };
    let report = study::run_study(&repo().join("examples").join(PAPER), &opts).unwrap();
    let mut out = Values::new();
    for f in &report.families {
        let table = match f.vary {
            Vary::Both => "table_1",
            Vary::H => "table_2",
            Vary::K => "table_3",
        };
        out.insert(format!("{table}.reference.u_l2"), float(f.reference.u_l2));
        out.insert(format!("{table}.reference.u_h1"), float(f.reference.u_h1));
        for r in &f.rows {
            let level = format!("{table}.level_{:03}", r.level);
            out.insert(format!("{level}.err_l2"), float(r.err_l2));
            out.insert(format!("{level}.err_h1_semi"), float(r.err_h1_semi));
            out.insert(format!("{level}.err_h1"), float(r.err_h1));
        }
    }
    out
}

/// Serializes the read-modify-write of the stored file between the tests of this binary.
static STORE: Mutex<()> = Mutex::new(());

/// Compares `got` with the stored sections that `owns` names, bit for bit; with
/// `VISCONTACT_GOLDEN=bless`, stores `got` in their place and keeps the other sections.
fn check_or_bless(got: Golden, owns: impl Fn(&str) -> bool) {
    let path = repo().join("tests/data/golden.json");
    let _store = STORE.lock().unwrap_or_else(|e| e.into_inner());
    let mut stored: Golden =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    if std::env::var("VISCONTACT_GOLDEN").as_deref() == Ok("bless") {
        stored.retain(|name, _| !owns(name));
        stored.extend(got);
        let text = serde_json::to_string_pretty(&stored).unwrap() + "\n";
        std::fs::write(&path, text).unwrap();
        return;
    }
    stored.retain(|name, _| owns(name));
    let mut changes = Vec::new();
    for (name, values) in &got {
        let Some(want) = stored.get(name) else {
            changes.push(format!("{name}: no stored values (bless them)"));
            continue;
        };
        for (key, value) in values {
            let expected = want.get(key).map(String::as_str).unwrap_or("missing");
            if value != expected {
                let rel = relative(value, expected)
                    .map(|r| format!(" (relative {r:.1e})"))
                    .unwrap_or_default();
                changes.push(format!("{name}.{key}: {value}, stored {expected}{rel}"));
            }
        }
    }
    assert_eq!(
        stored.len(),
        got.len(),
        "stored sections: {:?}",
        stored.keys()
    );
    assert!(
        changes.is_empty(),
        "results differ from tests/data/golden.json:\n{}",
        changes.join("\n")
    );
}

#[test]
fn results_equal_the_stored_golden_values() {
    let tmp = tempfile::tempdir().unwrap();
    let got: Golden = CASES
        .iter()
        .map(|c| (c.name.to_string(), run(c, tmp.path())))
        .collect();
    check_or_bless(got, |name| name != TABLES);
}

#[test]
fn study_tables_equal_the_stored_golden_values() {
    let got = Golden::from([(TABLES.to_string(), study_tables())]);
    check_or_bless(got, |name| name == TABLES);
}

/// Every scene of examples/ is the base of a case as it stands (no edits, no overrides), so
/// that a new example gets its golden values.
#[test]
fn every_example_is_a_case() {
    for scene in common::repo_files("examples", "toml") {
        let name = scene.file_name().unwrap().to_string_lossy().into_owned();
        let plain = |c: &&Case| c.base == name && c.mesh.is_none() && c.edit.is_empty();
        assert!(
            CASES.iter().filter(plain).any(|c| c.set.is_empty()),
            "examples/{name} is not a case of CASES: add it and bless its values"
        );
    }
}
