//! Data users bring that used to run to exit 0 with results that should not be trusted, or
//! to be refused for the wrong reason (issue 11): NaN constants in expressions, `check` and
//! `run` disagreeing, integer group tags, groups the scene does not use, physical points,
//! constraint groups on Γ1, gmsh's parametric and partitioned files, devices and FIFOs as
//! inputs, huge lines in a scene.

use crate::common;
use common::*;
use std::path::Path;

/// The paper's material on `mesh`, 8 steps, without loads, contact or memory: the base the
/// tests add to.
fn base(mesh: &str) -> SceneText {
    SceneText::on(mesh)
        .set("name", "s")
        .set("time.end", 1.0)
        .set("time.steps", 8)
        .set("material.viscosity.theta", 0.1)
        .set("material.viscosity.zeta", 0.1)
        .set("material.elasticity.young", 0.1)
        .set("material.elasticity.poisson", 0.3)
}

/// `scene` written as s.toml into `dir`: its path.
fn written(dir: &Path, scene: SceneText) -> String {
    scene.write(dir, "s.toml").display().to_string()
}

/// `check` and `run` of a scene both fail with exit 2 and `needle` in the message, and `run`
/// writes nothing.
fn refused(dir: &Path, scene: &str, needle: &str) {
    let out = dir.join("out");
    for args in [
        vec!["check", scene],
        vec!["run", scene, "--out", out.to_str().unwrap()],
    ] {
        let (code, text) = cli(&args);
        assert_eq!(code, 2, "{args:?}: {text}");
        assert!(text.contains(needle), "{args:?}: {text}");
        assert!(!text.contains("panicked"), "{text}");
    }
    assert!(!out.join("summary.json").exists());
}

#[test]
fn nan_constants_in_loads_are_refused_naming_the_key() {
    let dir = tempfile::tempdir().unwrap();
    let rect = mesh_path("paper/rect_008.msh");
    for value in [
        "0/0",
        "0*(1/0)",
        "(0-0)/(1-1)",
        "-(0/0)",
        "x + 0/0",
        "ln(0)*t",
    ] {
        let s = written(dir.path(), base(&rect).traction(Some("top"), &["0", value]));
        refused(dir.path(), &s, "load.traction[0].value[1]");
    }
    // The same load with a finite constant runs.
    let s = written(
        dir.path(),
        base(&rect).traction(Some("top"), &["0", "-(0/1) - 0.01"]),
    );
    let (code, text) = cli(&["run", &s, "--out", dir.path().join("ok").to_str().unwrap()]);
    assert_eq!(code, 0, "{text}");
}

#[test]
fn check_refuses_what_run_refuses() {
    // k = 1 with θ = 0.001: far above the left endpoint scheme's limit.
    let dir = tempfile::tempdir().unwrap();
    let s = written(
        dir.path(),
        base(&mesh_path("paper/rect_008.msh")).traction(Some("top"), &["0", "-0.01"]),
    );
    let (code, text) = cli(&[
        "check",
        &s,
        "--set",
        "time.steps=1",
        "--set",
        "material.viscosity.theta=0.001",
    ]);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("stability limit"), "{text}");
}

#[test]
fn group_tags_may_be_toml_integers() {
    let dir = tempfile::tempdir().unwrap();
    let s = written(
        dir.path(),
        base(&mesh_path("paper/rect_008.msh"))
            .section("contact")
            .traction(None, &["0", "-0.01*t"])
            .set("load.traction[0].on", 5),
    );
    let run = |name: &str, sets: &[&str]| {
        let out = dir.path().join(name);
        let mut args = vec!["run", &s, "--out", out.to_str().unwrap()];
        for set in sets {
            args.extend(["--set", set]);
        }
        let (code, text) = cli(&args);
        assert_eq!(code, 0, "{text}");
        without_run_id(std::fs::read(out.join("solution_000008.vtu")).unwrap())
    };
    let by_name = run("names", &[]);
    let by_tag = run(
        "tags",
        &[
            "mesh.groups.fixed=1",
            "mesh.groups.traction=2",
            "mesh.groups.contact=3",
        ],
    );
    assert_eq!(by_name, by_tag);
}

#[test]
fn unused_groups_do_not_matter_and_used_ones_are_explained() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = repo().join("tests/data/user/embedded_spline.msh");
    let mesh = mesh.to_str().unwrap();
    // mesh-info reports the mesh with its warnings.
    let (code, text) = cli(&["mesh-info", mesh]);
    assert_eq!(code, 0, "{text}");
    assert!(text.contains("warning") && text.contains("crack"), "{text}");
    assert!(text.contains("physical point corner"), "{text}");
    // A scene that does not use the embedded curve runs.
    let s = written(
        dir.path(),
        base(mesh)
            .section("contact")
            .traction(None, &["0.01", "-0.01*t"]),
    );
    let (code, text) = cli(&["run", &s, "--out", dir.path().join("o").to_str().unwrap()]);
    assert_eq!(code, 0, "{text}");
    // One that uses it as a boundary is told why not.
    let (code, text) = cli(&["check", &s, "--set", "mesh.groups.contact=crack"]);
    assert_eq!(code, 2, "{text}");
    assert!(
        text.contains("mesh.groups.contact") && text.contains("not on the boundary"),
        "{text}"
    );
    // A physical point is named as such.
    let (code, text) = cli(&["check", &s, "--set", "mesh.groups.fixed=corner"]);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("'corner' is a physical point"), "{text}");
    // A contact group whose every node is clamped would do nothing.
    let (code, text) = cli(&["check", &s, "--set", "mesh.groups.contact=Γ1"]);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("lies on the clamped group"), "{text}");
}

#[test]
fn gmsh_options_mshio_cannot_read_are_named() {
    for (file, option) in [
        ("embedded_spline_parametric.msh", "Mesh.SaveParametric 0"),
        ("embedded_spline_partitioned.msh", "Mesh.NbPartitions 0"),
    ] {
        let path = repo().join("tests/data/user").join(file);
        let (code, text) = cli(&["mesh-info", path.to_str().unwrap()]);
        assert_eq!(code, 2, "{text}");
        assert!(text.contains(option), "{text}");
    }
}

#[test]
fn devices_fifos_and_huge_lines_are_bounded() {
    let dir = tempfile::tempdir().unwrap();
    let (code, text) = cli(&["check", "/dev/zero"]);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("not a regular file"), "{text}");
    let s = written(dir.path(), base("/dev/zero"));
    let (code, text) = cli(&["check", &s]);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("not a regular file"), "{text}");
    let fifo = dir.path().join("fifo.msh");
    assert!(std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    let s = written(dir.path(), base(fifo.to_str().unwrap()));
    let (code, text) = cli(&["check", &s]);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("not a regular file"), "{text}");
    // A 2 MB line (not TOML: a bare word) is quoted by a short excerpt.
    let long = write(
        dir.path(),
        "long.toml",
        &format!("name = {}\n", "a".repeat(2_000_000)),
    );
    let (code, text) = cli(&["check", long.to_str().unwrap()]);
    assert_eq!(code, 2, "{text}");
    assert!(text.len() < 1000, "{} bytes of message", text.len());
}

#[test]
fn a_2d_model_on_a_3d_mesh_is_reported_under_mesh_model() {
    let (code, text) = cli(&[
        "check",
        "examples/block.toml",
        "--set",
        "mesh.model=plane_strain",
    ]);
    assert_eq!(code, 2, "{text}");
    assert!(
        text.contains("mesh.model") && text.contains("\"plane_strain\""),
        "{text}"
    );
}

/// tests/data/3d/interior_face.msh: two tetrahedra and a surface group "inner" holding their
/// shared face. The mesh is read; only a scene using "inner" as a boundary is refused.
#[test]
fn an_interior_face_group_is_refused_only_where_it_is_used() {
    let mesh = repo().join("tests/data/3d/interior_face.msh");
    let mesh = mesh.to_str().unwrap();
    let (code, text) = cli(&["mesh-info", mesh]);
    assert_eq!(code, 0, "{text}");
    assert!(
        text.contains("warning") && text.contains("\"inner\""),
        "{text}"
    );
    let dir = tempfile::tempdir().unwrap();
    let s = SceneText::on(mesh)
        .set("mesh.model", "3d")
        .set("mesh.groups.traction", "inner")
        .set("time.end", 1.0)
        .set("time.steps", 2)
        .set("material.viscosity.theta", 0.1)
        .traction(None, &["0", "0", "-1"]);
    let s = written(dir.path(), s);
    let (code, text) = cli(&["check", &s]);
    assert_eq!(code, 2, "{text}");
    for needle in ["load.traction[0].on", "\"inner\"", "interior face"] {
        assert!(text.contains(needle), "{text}");
    }
}
