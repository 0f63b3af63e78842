//! Hard meshes and boundary node rules: an unstructured mesh with sliver elements (min angle
//! < 1°, aspect ratio ≥ 10³, some of them at a contact node) runs the paper's scene with the
//! constraint holding and the fast solver agreeing with clarabel; the nodes where boundary
//! parts meet get the rows docs/decisions.md states (a node belongs to every part whose closure holds
//! it, Γ1 wins); plane strain with ν = 0.4999 runs and stays finite.

use crate::common;
use common::*;
use viscontact::fem::{Discretization, NodalRow};
use viscontact::time_loop::TimeLoop;

fn paper() -> std::path::PathBuf {
    repo().join("examples/paper.toml")
}

/// tests/data/hard/sliver.msh (from sliver.geo by tests/data/hard/generate.sh).
fn sliver() -> String {
    repo()
        .join("tests/data/hard/sliver.msh")
        .display()
        .to_string()
}

fn all_finite(vs: &[Vec<f64>]) -> bool {
    vs.iter().flatten().all(|v| v.is_finite())
}

/// The node at (x, y) of the discretization.
fn node_at(d: &Discretization, x: f64, y: f64) -> usize {
    d.nodes
        .all()
        .iter()
        .position(|p| (p[0] - x).abs() < 1e-12 && (p[1] - y).abs() < 1e-12)
        .unwrap_or_else(|| panic!("no node at ({x}, {y})"))
}

fn rows_at(rows: &[NodalRow], node: usize) -> Vec<NodalRow> {
    rows.iter().filter(|r| r.node == node).copied().collect()
}

// ---------------------------------------------------------------------------------------
// (a) Sliver elements
// ---------------------------------------------------------------------------------------

#[test]
fn sliver_mesh_is_as_bad_as_claimed() {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_viscontact"))
        .args(["mesh-info", "--json", &sliver()])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let info: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let q = &info["quality"];
    let min_angle = q["min_angle_deg"].as_f64().unwrap();
    let aspect = q["max_aspect_ratio"].as_f64().unwrap();
    println!("sliver.msh: min angle {min_angle}°, max aspect ratio {aspect}");
    assert!(min_angle < 1.0, "{q}");
    assert!(aspect >= 1e3, "{q}");
    // Unstructured, with all the paper's groups.
    let names: Vec<&str> = info["groups"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|g| g["name"].as_str())
        .collect();
    for g in ["Γ1", "Γ2", "Γ3,1", "Γ3,2", "top", "right"] {
        assert!(names.contains(&g), "{names:?}");
    }

    // The slivers touch Γ3,1: a triangle with an angle < 1° has a vertex at a contact node.
    let (_s, mesh, d) = load(&paper(), &[&format!("mesh.file={}", sliver())]);
    let contact_nodes: Vec<usize> = d.contact.iter().map(|r| r.node).collect();
    let min_angle_deg = |t: &[usize; 3]| {
        (0..3)
            .map(|i| {
                let [a, b, c] = [t[i], t[(i + 1) % 3], t[(i + 2) % 3]].map(|n| mesh.nodes[n]);
                let (ux, uy, vx, vy) = (b[0] - a[0], b[1] - a[1], c[0] - a[0], c[1] - a[1]);
                (ux * vy - uy * vx)
                    .abs()
                    .atan2(ux * vx + uy * vy)
                    .to_degrees()
            })
            .fold(f64::INFINITY, f64::min)
    };
    let slivers: Vec<&[usize; 3]> = mesh
        .triangles
        .iter()
        .filter(|t| min_angle_deg(t) < 1.0)
        .collect();
    assert!(slivers.len() >= 2, "{slivers:?}");
    assert!(
        slivers
            .iter()
            .any(|t| t.iter().any(|n| contact_nodes.contains(n))),
        "no sliver at a contact node"
    );
}

#[test]
fn sliver_mesh_runs_with_contact_holding_and_solvers_agreeing() {
    let mesh = format!("mesh.file={}", sliver());
    let o = [mesh.as_str(), "time.steps=8"];
    let (s1, _m, d1) = load(&paper(), &o);
    let t1 = trace(&s1, &d1);
    assert!(t1.effects.contains(&"contact") && t1.effects.contains(&"friction"));
    assert!(t1.solver.starts_with("dual"), "{}", t1.solver);
    assert!(all_finite(&t1.u) && all_finite(&t1.w) && all_finite(&t1.z));
    assert!(t1.u_final.iter().all(|v| v.is_finite()) && max_abs(&t1.u_final) > 0.0);
    // Γ3,1 has 5 nodes; (0, 0) is on Γ1.
    assert_eq!(d1.contact.len(), 4);
    let mut active = false;
    for (n, (w, z)) in t1.w.iter().zip(&t1.z).enumerate() {
        for (i, row) in d1.contact.iter().enumerate() {
            let nw = row.apply(w);
            assert!(nw <= 1e-10, "step {n}, node {}: n·w = {nw:e}", row.node);
            assert!(z[i] >= 0.0, "step {n}, node {}: λ = {:e}", row.node, z[i]);
            active |= z[i] > 1e-8 * max_abs(z);
        }
    }
    assert!(active, "the paper's load presses the body into Γ3,1");

    // clarabel on the same discrete problem.
    let (s2, _m, d2) = load(&paper(), &[o[0], o[1], "solver.contact=clarabel"]);
    let t2 = trace(&s2, &d2);
    assert!(t2.solver.starts_with("clarabel"), "{}", t2.solver);
    let diff = rel_diff(&t1.u_final, &t2.u_final);
    println!("sliver mesh: |u_N fast − clarabel| / |u_N| = {diff:e}");
    assert!(diff <= 1e-7, "{diff:e}");
    for (n, w) in t2.w.iter().enumerate() {
        for row in &d2.contact {
            // clarabel is an interior point method: feasible to its own tolerance.
            let nw = row.apply(w);
            assert!(
                nw <= 1e-8 * max_abs(w),
                "clarabel, step {n}, node {}: n·w = {nw:e}",
                row.node
            );
        }
    }
}

// ---------------------------------------------------------------------------------------
// (b) Which boundary part a node belongs to
// ---------------------------------------------------------------------------------------

#[test]
fn nodes_where_boundary_parts_meet_get_every_row_of_their_parts_and_gamma1_wins() {
    let (scene, _m, d) = load(
        &paper(),
        &[
            &format!("mesh.file={}", mesh_path("paper/rect_008.msh")),
            "time.steps=8",
        ],
    );
    let fr = scene.physics.friction.as_ref().unwrap();
    let p = viscontact::expr::Point::default();
    let mu_f = fr.normal_stress.eval(&p) * fr.coefficient.eval(&p);
    assert_eq!(mu_f, 0.01 * 0.5);
    let edge = 2.0 / 8.0; // rect_008: the bottom is cut into edges of 2/8
    let free = |n: usize| (d.free.get(2 * n), d.free.get(2 * n + 1));

    // (1, 0): on Γ3,1 and on Γ3,2. One contact row with the normal of Γ3,1's last edge and
    // one friction row with half an edge's bound (only one Γ3,2 edge meets it).
    let mid = node_at(&d, 1.0, 0.0);
    assert!(matches!(free(mid), (Some(_), Some(_))));
    let c = rows_at(&d.contact, mid);
    assert_eq!(c.len(), 1, "{c:?}");
    assert_eq!(c[0].dir, [0.0, -1.0, 0.0]);
    assert_eq!(c[0].bound, f64::INFINITY);
    assert!((c[0].area - edge / 2.0).abs() <= 1e-15, "{}", c[0].area);
    let f = rows_at(&d.friction, mid);
    assert_eq!(f.len(), 1, "{f:?}");
    assert_eq!(f[0].dir[0].abs(), 1.0);
    assert_eq!(f[0].dir[1], 0.0);
    let half = mu_f * edge / 2.0;
    assert!(
        (f[0].bound - half).abs() <= 1e-15 * half,
        "c = {:e}, μF·h/2 = {half:e}",
        f[0].bound
    );
    assert!((f[0].area - edge / 2.0).abs() <= 1e-15);
    assert_eq!(c[0].dofs, f[0].dofs);

    // An interior node of Γ3,2 gets a whole edge's bound: the half above is the corner's.
    let inner = node_at(&d, 1.5, 0.0);
    let f = rows_at(&d.friction, inner);
    assert_eq!(f.len(), 1);
    assert!((f[0].bound - 2.0 * half).abs() <= 1e-15 * half);
    assert!(rows_at(&d.contact, inner).is_empty());

    // (0, 0): on Γ1 and Γ3,1. Γ1 wins: clamped, no dofs, no row.
    let left = node_at(&d, 0.0, 0.0);
    assert_eq!(free(left), (None, None));
    assert!(rows_at(&d.contact, left).is_empty());
    assert!(rows_at(&d.friction, left).is_empty());
    // (0, 1): on Γ1 and Γ2: clamped too.
    assert_eq!(free(node_at(&d, 0.0, 1.0)), (None, None));
    // Γ3,1 has 5 nodes, the first of which is clamped.
    assert_eq!(d.contact.len(), 4);

    // (2, 0): on Γ2 and Γ3,2. Free, a friction row with half an edge's bound, no contact row.
    let right = node_at(&d, 2.0, 0.0);
    assert!(matches!(free(right), (Some(_), Some(_))));
    assert!(rows_at(&d.contact, right).is_empty());
    let f = rows_at(&d.friction, right);
    assert_eq!(f.len(), 1, "{f:?}");
    assert_eq!((f[0].dir[0].abs(), f[0].dir[1]), (1.0, 0.0));
    assert!(
        (f[0].bound - half).abs() <= 1e-15 * half,
        "{:e}",
        f[0].bound
    );
    // Γ3,2 has 5 nodes, none clamped.
    assert_eq!(d.friction.len(), 5);

    // In a run, the shared node (1, 0) obeys the constraint at every step.
    let tr = trace(&scene, &d);
    let row = rows_at(&d.contact, mid)[0];
    for (n, w) in tr.w.iter().enumerate() {
        assert!(row.apply(w) <= 1e-10, "step {n}: n·w = {:e}", row.apply(w));
    }
}

// ---------------------------------------------------------------------------------------
// (c) Nearly incompressible plane strain
// ---------------------------------------------------------------------------------------

#[test]
fn plane_strain_with_poisson_ratio_0_4999_runs_and_stays_finite() {
    let scene = repo().join("examples/plate_hole.toml");
    // T = 0.2 instead of 1 keeps the run short; N = 40 gives k = 5e-3.
    let base = [
        "material.elasticity.poisson=0.4999",
        "time.end=0.2",
        "time.steps=40",
    ];
    let (s, _m, d) = load(&scene, &base);
    assert!(matches!(
        s.mesh.model,
        viscontact::scene::Model::PlaneStrain
    ));
    assert_eq!(s.physics.material.elasticity, Some((0.2, 0.4999)));
    // The run warns that P1 triangles lock.
    let warnings = viscontact::effects::warnings(&s, &d, &descriptor(&s, &d));
    assert!(warnings.iter().any(|w| w.contains("lock")), "{warnings:?}");
    // λ/μ = 2ν/(1 − 2ν) ≈ 5·10³: the volumetric mode limits the paper's explicit scheme.
    let steps = match TimeLoop::new(&s, &d) {
        Ok(_) => 40,
        Err(e) => {
            let msg = e.to_string();
            assert!(msg.contains("stability limit"), "{msg}");
            let tail = msg
                .split("time.steps ≥ ")
                .nth(1)
                .unwrap_or_else(|| panic!("no suggested time.steps in: {msg}"));
            let digits: String = tail.chars().take_while(|c| c.is_ascii_digit()).collect();
            digits.parse::<usize>().unwrap()
        }
    };
    println!("ν = 0.4999: running with time.steps = {steps}");
    let set_steps = format!("time.steps={steps}");
    let (s, _m, d) = load(&scene, &[base[0], base[1], &set_steps]);
    let tr = trace(&s, &d);
    assert!(all_finite(&tr.u) && all_finite(&tr.w) && all_finite(&tr.z));
    let u = max_abs(&tr.u_final);
    assert!(u.is_finite() && u > 0.0, "{u}");
    for (n, w) in tr.w.iter().enumerate() {
        for row in &d.contact {
            assert!(row.apply(w) <= 1e-10, "step {n}: n·w = {:e}", row.apply(w));
        }
    }
    // Bounded: no larger than the compressible run (ν = 0.3) by more than a factor; locking
    // makes the body stiffer, not softer.
    let (s3, _m, d3) = load(
        &scene,
        &["material.elasticity.poisson=0.3", base[1], &set_steps],
    );
    let u3 = max_abs(&trace(&s3, &d3).u_final);
    println!("max |u_N|: ν = 0.4999 → {u:e}, ν = 0.3 → {u3:e}");
    assert!(u <= 2.0 * u3, "{u:e} vs {u3:e}");

    // The implicit variant runs the original 40 steps.
    let (s, _m, d) = load(
        &scene,
        &[base[0], base[1], base[2], "scheme.history=\"implicit\""],
    );
    let tr = trace(&s, &d);
    assert!(all_finite(&tr.u) && tr.u_final.iter().all(|v| v.is_finite()));
    assert!(max_abs(&tr.u_final) > 0.0);
}
