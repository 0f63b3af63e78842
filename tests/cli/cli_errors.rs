//! Bad input through the real binary (issue 2, "Bad input"; README.md, "Commands"): each
//! case exits with status 2, names the file, key or physical group at fault on stderr and
//! says what is wrong with it, does not panic, prints nothing on stdout, and leaves no output
//! behind (`--out` points into a temporary directory that must stay absent or empty, or keep
//! its earlier content untouched).
//!
//! Scenes are variants of examples/paper.toml written into a temporary directory, with
//! `mesh.file` made absolute (it is relative to the scene file), or the example itself with
//! `--set` overrides. A few positive cases check that good input is accepted.

use crate::common;
use common::scene::{strings, SceneText};

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const BIN: &str = env!("CARGO_BIN_EXE_viscontact");

/// Runs the binary from the repository root.
fn viscontact<I, S>(args: I) -> Output
where
    I: IntoIterator<Item = S>,
    S: Into<OsString>,
{
    Command::new(BIN)
        .args(args.into_iter().map(Into::into))
        .current_dir(common::repo())
        .env("RUST_BACKTRACE", "0")
        .output()
        .expect("the viscontact binary runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn describe(args: &[OsString], out: &Output) -> String {
    let cmd: Vec<String> = args.iter().map(|a| a.to_string_lossy().into()).collect();
    format!(
        "command: viscontact {}\nstatus: {:?}\n--- stdout ---\n{}--- stderr ---\n{}",
        cmd.join(" "),
        out.status.code(),
        text(&out.stdout),
        text(&out.stderr)
    )
}

/// Runs `args` and checks the bad-input contract: exit status 2, no panic, nothing on stdout,
/// and every one of `needles` in stderr (the culprit and what is wrong with it).
fn expect_input_error(case: &str, args: &[OsString], needles: &[&str]) -> String {
    let out = viscontact(args);
    let what = describe(args, &out);
    assert_eq!(
        out.status.code(),
        Some(2),
        "[{case}] expected exit status 2 (bad input)\n{what}"
    );
    let stderr = text(&out.stderr);
    assert!(
        !stderr.contains("panicked"),
        "[{case}] the program panicked\n{what}"
    );
    assert!(
        stderr.trim_start().starts_with("error"),
        "[{case}] stderr should start with an error line\n{what}"
    );
    for needle in needles {
        assert!(
            stderr.contains(needle),
            "[{case}] stderr does not mention {needle:?}\n{what}"
        );
    }
    assert!(
        out.stdout.is_empty(),
        "[{case}] a failed command printed a report on stdout\n{what}"
    );
    stderr
}

/// The output directory is absent or empty.
fn assert_no_output(case: &str, out_dir: &Path) {
    if !out_dir.exists() {
        return;
    }
    let entries: Vec<PathBuf> = std::fs::read_dir(out_dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert!(
        entries.is_empty(),
        "[{case}] a failed run left files in {}: {entries:?}",
        out_dir.display()
    );
    assert!(!out_dir.join("solution.pvd").exists());
    assert!(!out_dir.join("summary.json").exists());
}

/// A temporary directory holding a variant of a scene.
struct Fixture {
    dir: tempfile::TempDir,
}

impl Fixture {
    fn new() -> Self {
        Fixture {
            dir: tempfile::tempdir().unwrap(),
        }
    }

    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }

    fn out(&self) -> PathBuf {
        self.path("out")
    }

    /// `scene` written as `scene.toml`.
    fn scene(&self, scene: SceneText) -> PathBuf {
        scene.write(self.dir.path(), "scene.toml")
    }

    /// Runs `viscontact run SCENE --out OUT ARGS...` and checks the bad-input contract and that
    /// no output appeared.
    fn run_fails(&self, case: &str, scene: &Path, extra: &[&str], needles: &[&str]) -> String {
        let mut args: Vec<OsString> = vec!["run".into(), scene.into(), "--out".into()];
        args.push(self.out().into());
        args.extend(extra.iter().map(OsString::from));
        let stderr = expect_input_error(case, &args, needles);
        assert_no_output(case, &self.out());
        stderr
    }
}

fn data(name: &str) -> String {
    common::repo()
        .join("tests/data")
        .join(name)
        .display()
        .to_string()
}

fn set_mesh(name: &str) -> String {
    format!("mesh.file={}", data(name))
}

/// Runs examples/paper.toml with `--set` overrides into a fresh output directory and expects
/// bad input.
fn run_set_fails(case: &str, sets: &[&str], needles: &[&str]) -> String {
    let f = Fixture::new();
    let scene = f.scene(SceneText::paper());
    let mut extra = Vec::new();
    for s in sets {
        extra.push("--set");
        extra.push(s);
    }
    f.run_fails(case, &scene, &extra, needles)
}

/// Runs an edited examples/paper.toml and expects bad input; the scene path must be named.
fn run_edit_fails(case: &str, scene: SceneText, needles: &[&str]) -> String {
    let f = Fixture::new();
    let scene = f.scene(scene);
    let name = scene.display().to_string();
    let mut all = vec![name.as_str()];
    all.extend_from_slice(needles);
    f.run_fails(case, &scene, &[], &all)
}

// ---- files -------------------------------------------------------------------------------

#[test]
fn missing_scene_file() {
    let f = Fixture::new();
    let scene = f.path("no_such_scene.toml");
    let p = scene.display().to_string();
    f.run_fails("run: missing scene", &scene, &[], &[&p]);
    expect_input_error(
        "check: missing scene",
        &["check".into(), scene.clone().into()],
        &[&p],
    );
}

#[test]
fn missing_mesh_file() {
    let f = Fixture::new();
    let scene = f.scene(SceneText::paper());
    let mesh = f.path("no_such_mesh.msh").display().to_string();
    let set = format!("mesh.file={mesh}");
    f.run_fails(
        "missing mesh",
        &scene,
        &["--set", &set],
        &[&mesh, "mesh.file"],
    );
}

#[test]
fn missing_mesh_file_relative_to_scene() {
    // mesh.file is relative to the scene file: the message must show where it looked.
    let f = Fixture::new();
    let scene = f.scene(SceneText::paper().mesh("meshes/gone.msh"));
    f.run_fails(
        "missing relative mesh",
        &scene,
        &[],
        &["gone.msh", "mesh.file", "relative"],
    );
}

// ---- physical groups ---------------------------------------------------------------------

#[test]
fn mesh_without_contact_group() {
    let set = set_mesh("no_contact_group.msh");
    let stderr = run_set_fails(
        "mesh without Γ3,1",
        &[&set],
        &["no_contact_group.msh", "Γ3,1", "mesh.groups.contact"],
    );
    // It lists what the mesh does have, so the user can pick a name.
    assert!(stderr.contains("Γ3,2"), "{stderr}");
}

#[test]
fn misspelled_group_name() {
    let stderr = run_set_fails(
        "misspelled group",
        &["mesh.groups.contact=Gamma3_9"],
        &["Gamma3_9", "mesh.groups.contact"],
    );
    // The existing names are offered.
    assert!(stderr.contains("Γ3,1"), "{stderr}");
}

#[test]
fn misspelled_load_group() {
    run_edit_fails(
        "misspelled traction group",
        SceneText::paper().set("load.traction[0].on", "tpo"),
        &["tpo", "load.traction"],
    );
}

#[test]
fn traction_outside_gamma2() {
    run_edit_fails(
        "traction on Γ3,1",
        SceneText::paper().set("load.traction[0].on", "Γ3,1"),
        &["Γ3,1", "load.traction", "Γ2"],
    );
}

// ---- unknown keys ------------------------------------------------------------------------

#[test]
fn unknown_top_level_key() {
    run_edit_fails(
        "unknown top-level key",
        SceneText::paper().set("bogus", 3),
        &["bogus", "unknown"],
    );
}

#[test]
fn unknown_nested_key() {
    run_edit_fails(
        "unknown nested key",
        SceneText::paper()
            .remove("material.viscosity.theta")
            .set("material.viscosity.thetaa", 0.1),
        &["material.viscosity.thetaa", "unknown"],
    );
}

#[test]
fn unknown_key_in_array_of_tables() {
    run_edit_fails(
        "unknown key in [[load.traction]]",
        SceneText::paper().set("load.traction[0].scale", 2.0),
        &["load.traction", "scale", "unknown"],
    );
}

#[test]
fn set_unknown_key() {
    run_set_fails(
        "--set unknown nested key",
        &["material.viscosity.thetaa=1"],
        &["material.viscosity.thetaa", "unknown"],
    );
    run_set_fails(
        "--set unknown key",
        &["time.stepz=64"],
        &["time.stepz", "unknown"],
    );
    run_set_fails(
        "--set unknown top-level key",
        &["solverr.kind=x"],
        &["solverr", "unknown"],
    );
}

#[test]
fn set_without_equals_sign() {
    run_set_fails(
        "--set without =",
        &["time.steps"],
        &["time.steps", "KEY=VALUE"],
    );
}

#[test]
fn wrong_value_type() {
    run_set_fails(
        "time.steps = string",
        &["time.steps=abc"],
        &["time.steps", "abc"],
    );
    run_set_fails("time.steps = -3", &["time.steps=-3"], &["time.steps", "-3"]);
}

// ---- values ------------------------------------------------------------------------------

#[test]
fn theta_not_positive() {
    run_set_fails(
        "θ = 0",
        &["material.viscosity.theta=0"],
        &["material.viscosity.theta", "must"],
    );
    run_edit_fails(
        "θ < 0",
        SceneText::paper().set("material.viscosity.theta", -0.1),
        &["material.viscosity.theta", "must"],
    );
}

#[test]
fn young_negative() {
    run_set_fails(
        "E < 0",
        &["material.elasticity.young=-1"],
        &["material.elasticity.young", "-1", "must"],
    );
}

#[test]
fn poisson_out_of_range() {
    for nu in ["0.7", "-1.5"] {
        let set = format!("material.elasticity.poisson={nu}");
        run_set_fails(
            &format!("ν = {nu}"),
            &[&set],
            &["material.elasticity.poisson", nu, "must"],
        );
    }
}

/// Issue 49: a bad value given with `--set` is named as the `--set`, not as the scene
/// file's, where the user would look for it in vain; checked while parsing, while checking
/// the sections and while reading the mesh.
#[test]
fn a_bad_set_value_names_the_set() {
    for (set, key) in [
        ("time.steps=\"abc\"", "time.steps"),
        ("time.steps=0", "time.steps"),
        (
            "material.elasticity.poisson=0.7",
            "material.elasticity.poisson",
        ),
        ("mesh.groups.contact=\"zz\"", "mesh.groups.contact"),
    ] {
        let named = format!("--set {set} (scene ");
        run_set_fails(set, &[set], &[&named, key]);
    }
}

/// Issue 49: `study --help` kept the `{n}` of `--mesh-pattern` (clap made it a line break).
#[test]
fn study_help_shows_the_mesh_pattern_placeholder() {
    let out = viscontact(["study", "--help"]);
    let help = text(&out.stdout);
    assert!(
        help.contains("`{n}` or `{n:03}` for the level") && !help.contains('\x1b'),
        "{help}"
    );
}

#[test]
fn steps_zero() {
    run_set_fails("N = 0", &["time.steps=0"], &["time.steps", "must"]);
}

#[test]
fn end_not_positive() {
    for end in ["0", "-1", "-0.5"] {
        let set = format!("time.end={end}");
        run_set_fails(&format!("T = {end}"), &[&set], &["time.end", end, "must"]);
    }
}

#[test]
fn nan_and_inf_in_scene() {
    run_edit_fails(
        "θ = nan",
        SceneText::paper().set("material.viscosity.theta", f64::NAN),
        &["material.viscosity.theta", "NaN"],
    );
    run_set_fails("T = nan", &["time.end=nan"], &["time.end", "NaN"]);
    run_set_fails(
        "E = inf",
        &["material.elasticity.young=inf"],
        &["material.elasticity.young", "finite"],
    );
}

// ---- expressions -------------------------------------------------------------------------

/// examples/paper.toml with `expr` as the y component of its top traction (in place of
/// "-0.1*x*(2-x)*min(t, 0.2)").
fn top_load(expr: &str) -> SceneText {
    SceneText::paper().set("load.traction[0].value", strings(&["0", expr]))
}

#[test]
fn expression_does_not_parse() {
    run_edit_fails(
        "unparsable expression",
        top_load("-0.1*x*(2-"),
        &["load.traction", "-0.1*x*(2-", "parse"],
    );
}

#[test]
fn expression_unknown_variable() {
    run_edit_fails(
        "unknown variable",
        top_load("q*t"),
        &["load.traction", "q*t", "unknown variable", "'q'"],
    );
}

#[test]
fn expression_unknown_function() {
    run_edit_fails(
        "unknown function",
        top_load("foo(t)"),
        &["load.traction", "foo(t)", "unknown function", "foo"],
    );
}

#[test]
fn expression_z_in_a_2d_scene_and_log() {
    run_edit_fails(
        "z in 2D",
        top_load("-0.1*z*t"),
        &["load.traction", "variable 'z'", "a 2D model has no z"],
    );
    run_edit_fails(
        "log",
        top_load("log(1 + t)"),
        &["load.traction", "ln(x)", "log10(x)"],
    );
}

#[test]
fn relaxation_expression_unknown_variable() {
    // s is the variable of a relaxation expression; t is not.
    run_edit_fails(
        "relaxation expr with t",
        SceneText::paper().table("material.relaxation", r#"expr = "exp(-10*t)""#),
        &["material.relaxation", "exp(-10*t)", "'t'"],
    );
}

#[test]
fn relaxation_with_two_kernels() {
    run_edit_fails(
        "prony + expr",
        SceneText::paper().set("material.relaxation.expr", "exp(-10*s)"),
        &["material.relaxation", "exactly one"],
    );
    run_edit_fails(
        "expr + table",
        SceneText::paper().table(
            "material.relaxation",
            "expr = \"exp(-10*s)\"\ntable = { s = [0, 1], r = [1, 0.1] }",
        ),
        &["material.relaxation", "exactly one"],
    );
}

// ---- meshes ------------------------------------------------------------------------------

#[test]
fn zero_area_element() {
    let set = set_mesh("zero_area.msh");
    run_set_fails(
        "zero-area element",
        &[&set],
        &["zero_area.msh", "mesh.file", "zero area"],
    );
}

#[test]
fn quadratic_triangles() {
    let set = set_mesh("quadratic.msh");
    run_set_fails(
        "6-node triangles",
        &[&set],
        &["quadratic.msh", "mesh.file", "6-node"],
    );
}

#[test]
fn truncated_msh() {
    let set = set_mesh("truncated.msh");
    run_set_fails(
        "truncated .msh",
        &[&set],
        &["truncated.msh", "mesh.file", "truncated"],
    );
}

#[test]
fn msh22_file() {
    let set = set_mesh("msh22.msh");
    run_set_fails(
        "MSH 2.2",
        &[&set],
        &["msh22.msh", "mesh.file", "2.2", "-format msh41"],
    );
}

#[test]
fn not_a_mesh_file() {
    let f = Fixture::new();
    let garbage = common::write(f.dir.path(), "garbage.msh", "this is not a gmsh file\n");
    let set = format!("mesh.file={}", garbage.display());
    let scene = f.scene(SceneText::paper());
    f.run_fails(
        "garbage .msh",
        &scene,
        &["--set", &set],
        &["garbage.msh", "mesh.file"],
    );
}

// ---- check and mesh-info -----------------------------------------------------------------

#[test]
fn check_rejects_bad_scenes() {
    let f = Fixture::new();
    let scene = f.scene(SceneText::paper().set("material.viscosity.theta", 0));
    let p = scene.display().to_string();
    expect_input_error(
        "check: θ = 0",
        &["check".into(), scene.into()],
        &[&p, "material.viscosity.theta"],
    );
    let set = set_mesh("no_contact_group.msh");
    expect_input_error(
        "check: mesh without Γ3,1",
        &[
            "check".into(),
            "examples/paper.toml".into(),
            "--set".into(),
            set.into(),
        ],
        &["no_contact_group.msh", "Γ3,1", "mesh.groups.contact"],
    );
    expect_input_error(
        "check: --set unknown key",
        &[
            "check".into(),
            "examples/paper.toml".into(),
            "--set".into(),
            "contact.gap=1".into(),
        ],
        &["contact.gap", "unknown"],
    );
}

#[test]
fn mesh_info_rejects_bad_meshes() {
    let cases: [(&str, &[&str]); 5] = [
        ("truncated.msh", &["truncated"]),
        ("msh22.msh", &["2.2", "-format msh41"]),
        ("quadratic.msh", &["6-node"]),
        ("zero_area.msh", &["zero area"]),
        ("no_such_file.msh", &[]),
    ];
    for (name, needles) in cases {
        let path = data(name);
        let mut all = vec![path.as_str()];
        all.extend_from_slice(needles);
        for json in [false, true] {
            let mut args: Vec<OsString> = vec!["mesh-info".into(), path.clone().into()];
            if json {
                args.push("--json".into());
            }
            expect_input_error(&format!("mesh-info {name} (json: {json})"), &args, &all);
        }
    }
}

// ---- no partial file where a good one was ------------------------------------------------

#[test]
fn failed_run_keeps_earlier_output() {
    let f = Fixture::new();
    let out = f.out();
    std::fs::create_dir_all(&out).unwrap();
    let earlier = [
        ("solution.pvd", "earlier pvd\n"),
        ("solution_000000.vtu", "earlier vtu\n"),
        ("summary.json", "{\"earlier\": true}\n"),
    ];
    for (name, body) in earlier {
        common::write(&out, name, body);
    }
    let scene = f.scene(SceneText::paper().set("time.steps", 0));
    let args: Vec<OsString> = vec![
        "run".into(),
        scene.into(),
        "--out".into(),
        out.clone().into(),
    ];
    expect_input_error("run into an earlier output", &args, &["time.steps"]);
    let mut names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(
        names,
        ["solution.pvd", "solution_000000.vtu", "summary.json"],
        "a failed run changed the output directory"
    );
    for (name, body) in earlier {
        assert_eq!(std::fs::read_to_string(out.join(name)).unwrap(), body);
    }
}

// ---- good input is accepted --------------------------------------------------------------

#[test]
fn check_paper_scene() {
    let out = viscontact(["check", "examples/paper.toml"]);
    let what = describe(&["check".into(), "examples/paper.toml".into()], &out);
    assert_eq!(out.status.code(), Some(0), "{what}");
    let stdout = text(&out.stdout);
    let effects = stdout
        .lines()
        .find(|l| l.trim_start().starts_with("effects"))
        .unwrap_or_else(|| panic!("no effects line\n{what}"));
    for e in ["contact", "friction", "memory"] {
        assert!(effects.contains(e), "effects line lacks {e}: {effects}");
    }
}

#[test]
fn check_accepts_ascii_aliases() {
    let out = viscontact([
        "check",
        "examples/paper.toml",
        "--set",
        "mesh.groups.contact=Gamma3_1",
        "--set",
        "mesh.groups.fixed=gamma1",
        "--set",
        "time.steps=4",
    ]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "stdout:\n{}\nstderr:\n{}",
        text(&out.stdout),
        text(&out.stderr)
    );
}

const PAPER_GROUPS: [&str; 6] = ["Γ1", "Γ2", "Γ3,1", "Γ3,2", "top", "right"];

#[test]
fn mesh_info_lists_groups() {
    let mesh = common::mesh_path("paper/rect_008.msh");
    let out = viscontact(["mesh-info", mesh.as_str()]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    for g in PAPER_GROUPS {
        assert!(
            stdout
                .lines()
                .any(|l| l.split_whitespace().next() == Some(g)),
            "mesh-info does not list group {g}:\n{stdout}"
        );
    }

    let out = viscontact(["mesh-info", mesh.as_str(), "--json"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("mesh-info --json");
    let names: Vec<&str> = v["groups"]
        .as_array()
        .unwrap()
        .iter()
        .map(|g| g["name"].as_str().unwrap())
        .collect();
    for g in PAPER_GROUPS {
        assert!(names.contains(&g), "--json lacks {g}: {names:?}");
    }
    assert_eq!(v["nodes"], 81);
    assert_eq!(v["triangles"], 128);
}

#[test]
fn inverted_triangle_is_reoriented() {
    let mesh = data("inverted.msh");
    let out = viscontact(["mesh-info", mesh.as_str(), "--json"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("mesh-info --json");
    assert_eq!(v["reoriented"], 1, "{v}");

    let out = viscontact(["mesh-info", mesh.as_str()]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    assert!(stdout.contains("1 reoriented"), "{stdout}");

    // and a scene on it is accepted
    let set = set_mesh("inverted.msh");
    let out = viscontact(["check", "examples/paper.toml", "--set", set.as_str()]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "stdout:\n{}\nstderr:\n{}",
        text(&out.stdout),
        text(&out.stderr)
    );
}

#[test]
fn output_directory_with_foreign_files_is_refused_unless_forced() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    let mesh = format!(
        "mesh.file={}",
        common::repo().join("meshes/paper/rect_008.msh").display()
    );
    let scene = common::repo().join("examples/paper.toml");
    let run = |force: bool| {
        let mut args: Vec<OsString> = vec!["run".into(), scene.clone().into(), "--out".into()];
        args.push(out.clone().into());
        for a in ["--set", &mesh, "--set", "time.steps=8"] {
            args.push(a.into());
        }
        if force {
            args.push("--force".into());
        }
        viscontact(args)
    };
    let o = run(false);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("notes.txt") && err.contains("--force"),
        "{err}"
    );
    assert!(!out.join("solution.pvd").exists());
    let o = run(true);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.join("solution.pvd").exists());
    assert_eq!(
        std::fs::read_to_string(out.join("notes.txt")).unwrap(),
        "mine"
    );
}

#[test]
fn curved_contact_boundary_is_warned_about_with_its_worst_angle() {
    let scene = common::repo().join("examples/plate_hole.toml");
    let o = viscontact([
        OsString::from("check"),
        scene.into(),
        "--set".into(),
        "mesh.groups.contact=hole".into(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = String::from_utf8_lossy(&o.stdout);
    let line = out
        .lines()
        .find(|l| l.starts_with("warning") && l.contains("bends by up to"))
        .unwrap_or_else(|| panic!("no warning in:\n{out}"));
    // The hole has 104 edges: neighbouring facet normals differ by 360°/104 ≈ 3.5°.
    assert!(line.contains("3.4") || line.contains("3.5"), "{line}");
}

// ---- 3D input ------------------------------------------------------------------------------

/// `scene` (a variant of examples/block.toml, the 3D scene) written as `block.toml`.
fn block_scene(f: &Fixture, scene: SceneText) -> PathBuf {
    scene.write(f.dir.path(), "block.toml")
}

fn data3d(name: &str) -> String {
    common::repo()
        .join("tests/data/3d")
        .join(name)
        .display()
        .to_string()
}

#[test]
fn three_d_model_on_a_2d_mesh() {
    let f = Fixture::new();
    let scene = block_scene(&f, SceneText::block());
    let set = format!("mesh.file={}", common::mesh_path("paper/rect_008.msh"));
    let p = scene.display().to_string();
    f.run_fails(
        "3D model on a triangle mesh",
        &scene,
        &["--set", &set],
        &[&p, "'mesh.model'", "rect_008.msh", "triangles"],
    );
}

#[test]
fn two_d_model_on_a_3d_mesh() {
    let f = Fixture::new();
    let scene = f.scene(SceneText::paper());
    let set = format!("mesh.file={}", common::mesh_path("3d/block_004.msh"));
    let p = scene.display().to_string();
    f.run_fails(
        "plane stress on a tetrahedral mesh",
        &scene,
        &["--set", &set],
        &[&p, "'mesh.model'", "block_004.msh", "tetrahedra", "\"3d\""],
    );
}

#[test]
fn three_d_load_with_two_components() {
    let f = Fixture::new();
    let scene = block_scene(
        &f,
        SceneText::block().set(
            "load.traction[0].value",
            strings(&["0", "-0.1*x*(2-x)*min(t, 0.2)"]),
        ),
    );
    let p = scene.display().to_string();
    f.run_fails(
        "3D traction with 2 components",
        &scene,
        &[],
        &[
            &p,
            "load.traction[0].value",
            "2 components",
            "3D model needs 3",
        ],
    );
}

#[test]
fn three_d_volume_group_as_a_boundary_condition() {
    let f = Fixture::new();
    let scene = block_scene(&f, SceneText::block());
    f.run_fails(
        "volume group as Γ1",
        &scene,
        &["--set", "mesh.groups.fixed=Ω"],
        &["mesh.groups.fixed", "Ω", "volume", "boundary (surface)"],
    );
}

#[test]
fn three_d_mesh_without_contact_group() {
    // slider.msh has no Γ3,1; block.toml asks for contact there (its loads moved to the
    // slider's load group "sides", so that the contact group is what is missing).
    let f = Fixture::new();
    let scene = block_scene(
        &f,
        SceneText::block()
            .set("load.traction[0].on", "sides")
            .set("load.traction[1].on", "sides"),
    );
    let set = format!("mesh.file={}", common::mesh_path("3d/slider.msh"));
    f.run_fails(
        "3D mesh without Γ3,1",
        &scene,
        &["--set", &set],
        &["mesh.groups.contact", "Γ3,1", "slider.msh"],
    );
}

const BAD_TET_MESHES: [(&str, &[&str]); 5] = [
    ("flat_tet.msh", &["tetrahedron 42", "zero volume"]),
    ("folded_tets.msh", &["folds over itself", "10 and 12"]),
    ("three_tets_face.msh", &["three or more tetrahedra"]),
    ("quadratic_tets.msh", &["type 11", "gmsh -3 -order 1"]),
    ("hexahedron.msh", &["type 5", "Mesh.RecombineAll = 0"]),
];

#[test]
fn bad_tetrahedral_meshes_are_refused_by_run() {
    for (name, needles) in BAD_TET_MESHES {
        let f = Fixture::new();
        let scene = block_scene(&f, SceneText::block());
        let set = format!("mesh.file={}", data3d(name));
        let mut all = vec![name, "mesh.file"];
        all.extend_from_slice(needles);
        f.run_fails(&format!("run on {name}"), &scene, &["--set", &set], &all);
    }
}

#[test]
fn bad_tetrahedral_meshes_are_refused_by_mesh_info_and_check() {
    for (name, needles) in BAD_TET_MESHES {
        let path = data3d(name);
        let mut all = vec![path.as_str()];
        all.extend_from_slice(needles);
        for json in [false, true] {
            let mut args: Vec<OsString> = vec!["mesh-info".into(), path.clone().into()];
            if json {
                args.push("--json".into());
            }
            expect_input_error(&format!("mesh-info {name} (json: {json})"), &args, &all);
        }
        let set = format!("mesh.file={path}");
        expect_input_error(
            &format!("check on {name}"),
            &[
                "check".into(),
                "examples/block.toml".into(),
                "--set".into(),
                set.into(),
            ],
            &all,
        );
    }
}

#[test]
fn inverted_tetrahedron_is_reoriented_by_mesh_info() {
    let mesh = data3d("inverted_tet.msh");
    let out = viscontact(["mesh-info", mesh.as_str(), "--json"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("mesh-info --json");
    assert_eq!(
        (v["dim"].as_u64(), v["reoriented"].as_u64()),
        (Some(3), Some(1)),
        "{v}"
    );
    assert_eq!(v["tetrahedra"], 2);
    let out = viscontact(["mesh-info", mesh.as_str()]);
    let stdout = text(&out.stdout);
    assert!(stdout.contains("2 tetrahedra (1 reoriented"), "{stdout}");
}

/// A scene name is a name, not a path: without --out it would choose out/<name>/, so a name
/// that is absolute or climbs out of out/ is refused, and nothing is written anywhere.
#[test]
fn scene_name_that_is_a_path() {
    let f = Fixture::new();
    let target = f.path("elsewhere");
    for (case, name) in [
        ("absolute name", target.display().to_string()),
        ("name with ..", "../../escaped".to_string()),
        ("name with a separator", "a/b".to_string()),
    ] {
        let scene = f.scene(SceneText::paper().set("name", name));
        let args: Vec<OsString> = vec!["run".into(), scene.into()];
        expect_input_error(case, &args, &["scene.toml", "key 'name'", "--out"]);
        assert!(!target.exists(), "[{case}] wrote outside out/");
        assert!(!common::repo().join("escaped").exists());
    }
}

/// `--out` naming an existing file says so; the file is left as it was.
#[test]
fn out_is_a_file() {
    let f = Fixture::new();
    let scene = f.scene(SceneText::paper());
    let file = common::write(f.dir.path(), "taken", "mine\n");
    let args: Vec<OsString> = vec![
        "run".into(),
        scene.into(),
        "--out".into(),
        file.clone().into(),
    ];
    expect_input_error("--out is a file", &args, &["taken", "is an existing file"]);
    assert_eq!(std::fs::read_to_string(&file).unwrap(), "mine\n");
}
