//! history.csv: the forces on the body balance at every step (docs/output.md). The
//! reactions come from the rows of the step's matrices at the held dofs, the other columns
//! from the loads and the multipliers, so their sum per component is the residual of the
//! step's equations summed over a translation: zero to the precision of the solve. Checked
//! with contact and friction (the paper's scene, in both schemes; the plate with a hole), in
//! 3D (the block), with a symmetry plane ([[dirichlet]] at zero; an axis plane and an
//! inclined one) and with prescribed displacements.

use crate::common;
use common::*;
use std::path::Path;
use toml::Value;

/// Runs `scene` into `dir/out` with `set` and checks every row of its history.csv: steps
/// 0..=N at t_n, and the balance (`History::assert_balanced`). Returns the history.
fn balanced(dir: &Path, scene: &Path, set: &[&str], what: &str) -> History {
    let out = dir.join(format!("out_{}", what.replace(' ', "_")));
    let s = finished(viscontact::run::run(scene, &run_options(&out, set, None)).unwrap());
    let h = History::read(&out);
    assert_eq!(h.rows.len(), s.steps + 1, "{what}: one row per step");
    let k = h.column("t")[1];
    for (n, row) in h.rows.iter().enumerate() {
        assert_eq!((row[0], row[1]), (n as f64, n as f64 * k), "{what}");
    }
    h.assert_balanced(what);
    let reactions = h.header.iter().filter(|n| n.starts_with("reaction_"));
    assert!(reactions.count() > 0, "{what}: {:?}", h.header);
    h
}

/// [`balanced`] with `steps` steps in the paper's scheme and in the implicit variant.
fn in_both_schemes(dir: &Path, scene: &Path, steps: usize) -> Vec<(&'static str, History)> {
    let runs = ["left", "implicit"].map(|scheme| {
        let set = [
            format!("time.steps={steps}"),
            format!("scheme.history={scheme}"),
        ];
        let set: Vec<&str> = set.iter().map(String::as_str).collect();
        (scheme, balanced(dir, scene, &set, scheme))
    });
    runs.into()
}

/// Whether some step has a nonzero value in column `name`.
fn acts(h: &History, name: &str) -> bool {
    h.column(name).iter().any(|&v| v != 0.0)
}

#[test]
fn the_paper_s_forces_balance_at_every_step_in_both_schemes() {
    let dir = tempfile::tempdir().unwrap();
    let scene = paper_scene(dir.path(), "p.toml", "paper/rect_016.msh", false);
    for (scheme, h) in in_both_schemes(dir.path(), &scene, 16) {
        for column in ["reaction_Γ1_x", "load_top_y", "load_right_x", "contact_y"] {
            assert!(acts(&h, column), "{scheme}: {column} is zero throughout");
        }
        // F = 0.01 on Γ3,2 = [1, 2] × {0} pushes up with 0.01 N; friction acts along x.
        assert!(h
            .column("friction_y")
            .iter()
            .all(|&v| (v - 0.01).abs() < 1e-15));
        assert!(acts(&h, "friction_x") && acts(&h, "active") && acts(&h, "stick"));
        assert!(h.column("max_von_mises").iter().all(|&v| v > 0.0));
    }
}

#[test]
fn the_block_s_forces_balance_in_3d() {
    let dir = tempfile::tempdir().unwrap();
    let scene = repo().join("examples/block.toml");
    let mesh = format!("mesh.file={}", mesh_path("3d/block_004.msh"));
    let h = balanced(dir.path(), &scene, &[&mesh, "time.steps=8"], "block");
    for column in ["reaction_Γ1_z", "contact_z", "friction_x", "moment_Γ1_y"] {
        assert!(acts(&h, column), "{column} is zero throughout");
    }
}

/// The plate with a hole (examples/plate_hole.toml): contact and friction, a compressed
/// kernel, plane strain.
#[test]
fn the_plate_s_forces_balance() {
    let dir = tempfile::tempdir().unwrap();
    let scene = repo().join("examples/plate_hole.toml");
    let h = balanced(dir.path(), &scene, &["time.steps=12"], "plate");
    for column in ["reaction_Γ1_x", "contact_y", "friction_x", "load_right_x"] {
        assert!(acts(&h, column), "{column} is zero throughout");
    }
}

/// A half model with a symmetry plane: the plane's reaction is normal to it, in 2D (with
/// friction on the line) and in 3D.
#[test]
fn forces_balance_with_a_symmetry_plane() {
    let dir = tempfile::tempdir().unwrap();
    let data = repo().join("tests/data/symmetry");
    let block = SceneText::block()
        .mesh(data.join("half_block.msh"))
        .dirichlet("sym", &["normal"], None)
        .write(dir.path(), "half_block.toml");
    let h = balanced(dir.path(), &block, &["time.steps=8"], "half block");
    assert!(acts(&h, "reaction_sym_y") && acts(&h, "moment_sym_x"));
    assert!(!acts(&h, "reaction_sym_x") && !acts(&h, "reaction_sym_z"));
    let rect = SceneText::paper()
        .set("load.traction", Value::Array(vec![]))
        .traction(None, &["0", "-0.1*(1-x*x)*min(t, 0.2)"])
        .mesh(data.join("half_rect.msh"))
        .dirichlet("sym", &["normal"], None)
        .write(dir.path(), "half_rect.toml");
    let h = balanced(dir.path(), &rect, &["time.steps=8"], "half rect");
    assert!(acts(&h, "reaction_sym_x") && !acts(&h, "reaction_sym_y"));
}

/// A half model whose symmetry plane is inclined (the half block turned by 30° about x:
/// normal n = (0, cos, sin), each plane node's dofs in a frame of its own): forces balance,
/// and the plane's reaction, summed from the frames' held components turned back into x,
/// y, z, is normal to it. Likewise the half rectangle turned by 30°.
#[test]
fn forces_balance_with_an_inclined_symmetry_plane() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = repo().join("tests/data/symmetry/half_block_turned.msh");
    let block = SceneText::block()
        .mesh(mesh)
        .dirichlet("sym", &["normal"], None)
        .write(dir.path(), "turned.toml");
    let h = balanced(dir.path(), &block, &["time.steps=8"], "turned block");
    let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
    let r = ["x", "y", "z"].map(|a| h.column(&format!("reaction_sym_{a}")));
    let size = r[1].iter().chain(&r[2]).fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(size > 0.0 && acts(&h, "moment_sym_x"));
    for ((x, y), z) in r[0].iter().zip(&r[1]).zip(&r[2]) {
        let across = -s * y + c * z;
        assert!(x.abs() <= 1e-12 * size && across.abs() <= 1e-12 * size);
    }
    // 2D, the rectangle turned by 30°: Γ3,2 meets the inclined line, so g_F acts at a
    // held dof of a frame.
    let rect = SceneText::paper()
        .set("load.traction", Value::Array(vec![]))
        .traction(None, &["0", "-0.1*min(t, 0.2)"])
        .mesh(repo().join("tests/data/symmetry/half_rect_turned.msh"))
        .dirichlet("sym", &["normal"], None)
        .write(dir.path(), "turned_rect.toml");
    let h = balanced(dir.path(), &rect, &["time.steps=8"], "turned rect");
    assert!(acts(&h, "reaction_sym_x") && acts(&h, "reaction_sym_y"));
}

/// Prescribed displacements (dofs numbered after the free ones) on two groups, no clamped
/// group, with memory, in both schemes: the two groups' reactions balance each other and
/// the body force.
#[test]
fn forces_balance_with_prescribed_displacements() {
    let dir = tempfile::tempdir().unwrap();
    let g = ["0.01*t*(x + 2*y)", "-0.02*t*x - 0.001*t"];
    let scene = SceneText::unclamped_square()
        .body(&["0", "-0.05*t"])
        .dirichlet("Γ1", &["x", "y"], Some(&g))
        .dirichlet("Γ2", &["x", "y"], Some(&g))
        .write(dir.path(), "prescribed.toml");
    for (_, h) in in_both_schemes(dir.path(), &scene, 6) {
        assert!(acts(&h, "reaction_Γ1_x") && acts(&h, "reaction_Γ2_y"));
        assert!(acts(&h, "body_y"));
    }
}

/// Two memory groups: the bimaterial bar clamped on its soft part, which relaxes with a
/// compressed kernel of its own, the stiff part with [material]'s Prony series; in both
/// schemes (the implicit one adds k² r_g(0) K_R^(g) of each group to the step matrix).
#[test]
fn forces_balance_with_a_kernel_per_region() {
    let dir = tempfile::tempdir().unwrap();
    let own: toml::Table =
        toml::from_str("on = \"soft\"\nrelaxation = { expr = \"2*exp(-3*s) + 0.5*exp(-s/2)\" }")
            .unwrap();
    let scene = SceneText::on(repo().join("tests/data/bimaterial_bar.msh"))
        .set("time.end", 1.0)
        .set("material.viscosity.theta", 0.1)
        .set("material.elasticity.young", 0.5)
        .set("material.elasticity.poisson", 0.3)
        .literal("material.relaxation.prony", "[[0.7, 3.0]]")
        .traction(Some("right"), &["0.01 + 0.02*t", "0.005 + 0.005*t"])
        .push("material.region", own)
        .write(dir.path(), "regions.toml");
    for (_, h) in in_both_schemes(dir.path(), &scene, 8) {
        assert!(acts(&h, "reaction_Γ1_x") && acts(&h, "reaction_Γ1_y"));
    }
}

/// A frame that has the von Mises stress hands its largest value to the step's row; a step
/// without one computes it for the row: history.csv is the same bytes either way.
#[test]
fn the_history_does_not_depend_on_the_frames() {
    let dir = tempfile::tempdir().unwrap();
    let scene = paper_scene(dir.path(), "p.toml", "paper/rect_008.msh", false);
    let history = |name: &str, set: &[&str]| {
        let out = dir.path().join(name);
        let mut set = set.to_vec();
        set.push("time.steps=8");
        finished(viscontact::run::run(&scene, &run_options(&out, &set, None)).unwrap());
        std::fs::read(out.join("history.csv")).unwrap()
    };
    let every_step = history("every", &[]);
    assert!(every_step == history("some", &["output.every=3"]));
    assert!(every_step == history("no_stress", &["output.fields=[\"displacement\"]"]));
}
