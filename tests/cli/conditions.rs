//! Dirichlet conditions as a user writes them wrong (issue 51): each refused by `check` with
//! exit 2, naming the key or group and the fix.

use crate::common;
use common::*;
use toml::Value;

/// `check` of `scene` exits 2 with a message holding every needle.
fn refused(scene: &std::path::Path, needles: &[&str]) {
    let (code, text) = cli(&["check", &scene.display().to_string()]);
    assert_eq!(code, 2, "{text}");
    assert!(!text.contains("panicked"), "{text}");
    for n in needles {
        assert!(text.contains(n), "missing {n:?} in:\n{text}");
    }
}

fn free_paper() -> SceneText {
    SceneText::paper().set("mesh.groups.fixed", Value::Array(vec![]))
}

#[test]
fn a_body_the_conditions_leave_free_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    refused(
        &free_paper().write(d, "none.toml"),
        &["no condition", "mesh.groups.fixed = []", "K_A is singular"],
    );
    // Only x held on the left edge: the body can slide along y.
    let s = free_paper().dirichlet("Γ1", &["x"], None);
    refused(
        &s.write(d, "slides.toml"),
        &["rigid body", "a translation along y", "[[dirichlet]]"],
    );
    // x and y held at one edge's nodes hold everything; so do two rollers plus a point-free
    // pair of planes in 3D (x on x = 0 cannot stop a rotation about x).
    let s = free_paper().dirichlet("Γ1", &["x", "y"], None);
    let (code, text) = cli(&["check", &s.write(d, "held.toml").display().to_string()]);
    assert_eq!(code, 0, "{text}");
    let s = SceneText::block()
        .set("mesh.groups.fixed", Value::Array(vec![]))
        .dirichlet("Γ1", &["x"], None)
        .dirichlet("sides", &["y"], None);
    refused(&s.write(d, "block.toml"), &["a translation along z"]);
}

#[test]
fn fixed_takes_a_list_of_groups() {
    let dir = tempfile::tempdir().unwrap();
    let s = SceneText::paper().set(
        "mesh.groups.fixed",
        toml::Value::Array(vec!["Γ1".into(), "right".into()]),
    );
    let (code, text) = cli(&[
        "check",
        &s.write(dir.path(), "two.toml").display().to_string(),
    ]);
    assert_eq!(code, 0, "{text}");
    let s = SceneText::paper().set(
        "mesh.groups.fixed",
        toml::Value::Array(vec!["Γ1".into(), "nope".into()]),
    );
    refused(
        &s.write(dir.path(), "nope.toml"),
        &["mesh.groups.fixed", "nope"],
    );
}

#[test]
fn bad_dirichlet_entries_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cases: Vec<(SceneText, Vec<&str>)> = vec![
        (
            SceneText::paper().dirichlet("nowhere", &["x"], None),
            vec!["dirichlet[0].on", "nowhere"],
        ),
        (
            SceneText::paper().dirichlet("top", &["w"], None),
            vec!["dirichlet[0].components", "unknown component \"w\""],
        ),
        (
            SceneText::paper().dirichlet("top", &["z"], None),
            vec!["dirichlet[0].components", "\"z\""],
        ),
        (
            SceneText::paper().dirichlet("top", &["x", "x"], None),
            vec!["named twice"],
        ),
        (
            SceneText::paper().dirichlet("top", &["normal", "x"], None),
            vec!["\"normal\" stands alone"],
        ),
        (
            SceneText::paper().dirichlet("top", &["x", "y"], Some(&["t"])),
            vec!["dirichlet[0].value", "has 1 values for 2 component(s)"],
        ),
        (
            SceneText::paper().dirichlet("top", &["x"], Some(&["t +"])),
            vec!["dirichlet[0].value[0]"],
        ),
        // Γ2 is the top and the right edge: not one plane.
        (
            SceneText::paper().dirichlet("Γ2", &["normal"], None),
            vec!["dirichlet[0].components", "'Γ2'", "not flat"],
        ),
        // The top meets Γ1 at (0, 1), where Γ1 holds x at 0.
        (
            SceneText::paper().dirichlet("top", &["x"], Some(&["0.01*t"])),
            vec![
                "(x, y) = (0, 1)",
                "'Γ1'",
                "'top' (dirichlet[0])",
                "x component",
            ],
        ),
        // Holding the contact group's normal component contradicts contact.
        (
            SceneText::paper().dirichlet("Γ3,1", &["y"], None),
            vec!["mesh.groups.contact", "along the contact normal"],
        ),
        // In 3D, friction where a condition holds a tangent component.
        (
            SceneText::block().dirichlet("Γ3,2", &["x"], None),
            vec!["mesh.groups.friction", "tangent plane", "2D only"],
        ),
    ];
    for (i, (scene, needles)) in cases.into_iter().enumerate() {
        refused(&scene.write(d, &format!("case{i}.toml")), &needles);
    }
}

/// `normal` on an inclined plane: the half block turned by 30° about x holds its symmetry
/// plane in frames of the plane's nodes, and `check` says how many; on the square turned by
/// 30°, an axis component held beside the inclined left edge's normal on the same nodes is
/// neither parallel nor perpendicular to it, and is refused.
#[test]
fn an_inclined_normal_is_held_in_frames_and_an_oblique_pair_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let turned = repo().join("tests/data/symmetry/half_block_turned.msh");
    let half = SceneText::block()
        .mesh(&turned)
        .dirichlet("sym", &["normal"], None)
        .write(dir.path(), "half.toml");
    let (code, text) = cli(&["check", &half.display().to_string()]);
    assert_eq!(code, 0, "{text}");
    assert!(text.contains("'sym' normal = 0"), "{text}");
    assert!(text.contains("nodes in frames of their own"), "{text}");
    let text = std::fs::read_to_string(repo().join("tests/data/patch_square.msh")).unwrap();
    let (s, c) = (0.5f64, 0.75f64.sqrt());
    let square = map_msh_nodes(&text, |x| [c * x[0] - s * x[1], s * x[0] + c * x[1], x[2]]);
    let mesh = write(dir.path(), "turned.msh", &square);
    let scene = SceneText::on(&mesh)
        .set("time.end", 1.0)
        .set("time.steps", 1)
        .set("material.viscosity.theta", 1.0)
        .set("mesh.groups.fixed", Value::Array(vec![]))
        .dirichlet("Γ1", &["normal"], None)
        .dirichlet("Γ1", &["x"], None)
        .write(dir.path(), "oblique.toml");
    refused(
        &scene,
        &[
            "'Γ1' (dirichlet[0])",
            "'Γ1' (dirichlet[1])",
            "neither parallel nor perpendicular",
            "right angle",
        ],
    );
}

/// Two entries holding a shared node's component at the same written value agree; a roller
/// on the clamped edge's neighbour (zero on both) is merged.
#[test]
fn agreeing_conditions_are_merged() {
    let dir = tempfile::tempdir().unwrap();
    let s = SceneText::paper()
        .dirichlet("top", &["x"], Some(&["0.01*t"]))
        .dirichlet("right", &["x"], Some(&["0.01*t"]))
        .set("mesh.groups.fixed", Value::Array(vec![]))
        .dirichlet("Γ1", &["x", "y"], Some(&["0.01*t", "0"]));
    let (code, text) = cli(&[
        "check",
        &s.write(dir.path(), "a.toml").display().to_string(),
    ]);
    assert_eq!(code, 0, "{text}");
    let s = SceneText::paper().dirichlet("top", &["y"], None);
    let (code, text) = cli(&[
        "check",
        &s.write(dir.path(), "b.toml").display().to_string(),
    ]);
    assert_eq!(code, 0, "{text}");
}
