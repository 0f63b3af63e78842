//! Contact and friction on the paper's scene and the unstructured scenes: the constraint
//! holds at every Γ3,1 node and is active somewhere, complementarity holds, large μF sticks,
//! μF = 0 is the frictionless run, and the fast solver agrees with clarabel.

use crate::common;
use common::*;
use viscontact::solver::StepSolver;

fn paper() -> std::path::PathBuf {
    repo().join("examples/paper.toml")
}

fn rect(n: usize) -> String {
    format!("mesh.file={}", mesh_path(&format!("paper/rect_{n:03}.msh")))
}

#[test]
fn contact_holds_is_active_and_complementary() {
    let (scene, _m, disc) = load(&paper(), &[&rect(16), "time.steps=16"]);
    let tr = trace(&scene, &disc);
    assert!(tr.effects.contains(&"contact") && tr.effects.contains(&"friction"));
    let mut active_somewhere = false;
    for (n, (w, z)) in tr.w.iter().zip(&tr.z).enumerate() {
        for (i, row) in disc.contact.iter().enumerate() {
            let nw = row.apply(w);
            assert!(nw <= 1e-10, "step {n}, node {}: n·w = {nw:e}", row.node);
            assert!(z[i] >= 0.0, "step {n}: λ = {} < 0", z[i]);
            // Complementarity λ (n·w) = 0, relative to the step's scales.
            let scale = max_abs(w) * max_abs(z).max(f64::MIN_POSITIVE);
            assert!(
                (z[i] * nw).abs() <= 1e-10 * scale,
                "step {n}: λ n·w = {:e}",
                z[i] * nw
            );
            if z[i] > 1e-8 * max_abs(z) && nw.abs() <= 1e-12 * max_abs(w) {
                active_somewhere = true;
            }
        }
    }
    assert!(
        active_somewhere,
        "the load presses the body into Γ3,1: contact must be active"
    );
}

#[test]
fn huge_friction_bound_makes_gamma32_stick() {
    let (scene, _m, disc) = load(
        &paper(),
        &[&rect(16), "time.steps=16", "friction.coefficient=1e6"],
    );
    let tr = trace(&scene, &disc);
    assert!(!disc.friction.is_empty());
    for (n, w) in tr.w.iter().enumerate() {
        for row in &disc.friction {
            let slip = row.apply(w);
            assert!(
                slip.abs() <= 1e-12 * max_abs(w),
                "step {n}, node {}: w_τ = {slip:e}",
                row.node
            );
        }
    }
    // With the paper's μ = 0.5 the nodes do slide somewhere: the test above is not vacuous.
    let (scene, _m, disc) = load(&paper(), &[&rect(16), "time.steps=16"]);
    let tr = trace(&scene, &disc);
    let slides = tr.w.iter().any(|w| {
        disc.friction
            .iter()
            .any(|r| r.apply(w).abs() > 1e-6 * max_abs(w))
    });
    assert!(slides);
}

#[test]
fn zero_friction_bound_equals_a_run_without_friction() {
    // μF = 0 with F = 0: no friction term and no normal-stress load, exactly as without the
    // friction group.
    let (s1, _m, d1) = load(
        &paper(),
        &[&rect(16), "time.steps=16", "friction.normal_stress=0"],
    );
    let (s2, _m, d2) = load(
        &paper(),
        &[&rect(16), "time.steps=16", "friction.enabled=false"],
    );
    let (t1, t2) = (trace(&s1, &d1), trace(&s2, &d2));
    assert_eq!(t1.effects, t2.effects);
    assert!(!t1.effects.contains(&"friction"));
    assert_eq!(t1.u_final, t2.u_final);
    // μ = 0 with F > 0: the friction term vanishes (no rows) but F still loads Γ3,2.
    let (s3, _m, d3) = load(
        &paper(),
        &[&rect(16), "time.steps=16", "friction.coefficient=0"],
    );
    let t3 = trace(&s3, &d3);
    assert!(d3.friction.is_empty());
    assert!(t3.effects.contains(&"normal_stress") && !t3.effects.contains(&"friction"));
    assert!(rel_diff(&t3.u_final, &t2.u_final) > 1e-6);
}

#[test]
fn no_contact_and_no_friction_is_one_linear_solve_per_step() {
    let (scene, _m, disc) = load(
        &paper(),
        &[
            &rect(8),
            "time.steps=8",
            "contact.enabled=false",
            "friction.enabled=false",
        ],
    );
    let tr = trace(&scene, &disc);
    assert_eq!(tr.solver, StepSolver::Linear.name());
    assert!(!tr.effects.contains(&"contact") && !tr.effects.contains(&"friction"));
}

/// Runs a scene with the fast solver and with clarabel and returns the relative max-norm
/// difference of u_N.
fn fast_vs_clarabel(scene: &std::path::Path, overrides: &[&str]) -> f64 {
    let (s1, _m, d1) = load(scene, overrides);
    let mut o2 = overrides.to_vec();
    o2.push("solver.contact=clarabel");
    let (s2, _m, d2) = load(scene, &o2);
    let (t1, t2) = (trace(&s1, &d1), trace(&s2, &d2));
    assert!(t1.solver.starts_with("dual") && t2.solver.starts_with("clarabel"));
    rel_diff(&t1.u_final, &t2.u_final)
}

#[test]
fn fast_solver_agrees_with_clarabel_on_the_paper_scene() {
    for (h, steps) in [(8, 8), (16, 16), (16, 8), (8, 32)] {
        let d = fast_vs_clarabel(&paper(), &[&rect(h), &format!("time.steps={steps}")]);
        println!("paper h = 1/{h}, k = 1/{steps}: |u_N fast − clarabel| / |u_N| = {d:e}");
        assert!(d <= 1e-7, "h = 1/{h}, k = 1/{steps}: {d:e}");
    }
}

#[test]
fn fast_solver_agrees_with_clarabel_on_unstructured_scenes() {
    for (scene, steps) in [("bracket", 10), ("plate_hole", 8)] {
        let path = repo().join(format!("examples/{scene}.toml"));
        let d = fast_vs_clarabel(&path, &[&format!("time.steps={steps}")]);
        println!("{scene}: |u_N fast − clarabel| / |u_N| = {d:e}");
        assert!(d <= 1e-7, "{scene}: {d:e}");
    }
    // The 3D block (contact, friction, memory) on gmsh's own
    // tetrahedra (tests/data/3d/block_unstructured.msh).
    let mesh = repo().join("tests/data/3d/block_unstructured.msh");
    let d = fast_vs_clarabel(
        &repo().join("examples/block.toml"),
        &[&format!("mesh.file={}", mesh.display()), "time.steps=16"],
    );
    println!("unstructured block: |u_N fast − clarabel| / |u_N| = {d:e}");
    assert!(d <= 1e-7, "unstructured block: {d:e}");
}

#[test]
fn normal_stress_pushes_gamma32_away_from_the_foundation_and_nothing_stops_it_there() {
    // docs/scene.md, `friction.normal_stress`: F is the foundation's pressure on Γ3,2, the
    // load −Fν (ν the outward normal), so it pushes the body away from the foundation; and
    // Γ3,2 has no non-penetration condition. On the paper's rectangle Γ3,2 is the right half
    // of the bottom edge, ν = (0, −1): "away" is up. Without contact and with μ = 0 the
    // problem is linear, so the difference of two runs is the response to F alone.
    let linear = [&rect(8) as &str, "time.steps=8", "contact.enabled=false"];
    let run = |f: &str| {
        let (s, _m, d) = load(
            &paper(),
            &[&linear[..], &[f, "friction.coefficient=0"]].concat(),
        );
        (trace(&s, &d).u_final, d)
    };
    let (with_f, disc) = run("friction.normal_stress=0.01");
    let (without_f, _) = run("friction.normal_stress=0");
    let d = disc.dim;
    let g_f = |i: usize| {
        disc.g_f
            .iter()
            .find(|&&(j, _)| j == i)
            .map_or(0.0, |&(_, g)| g)
    };
    let mut gamma32_nodes = 0;
    for node in 0..disc.nodes.len() {
        let dofs: Vec<usize> = (0..d).filter_map(|c| disc.free.get(d * node + c)).collect();
        if dofs.len() < d || dofs.iter().all(|&i| g_f(i) == 0.0) {
            continue;
        }
        gamma32_nodes += 1;
        let (ix, iy) = (dofs[0], dofs[1]);
        assert!(disc.nodes[node][1].abs() < 1e-12 && g_f(iy) < 0.0 && g_f(ix) == 0.0);
        let up = with_f[iy] - without_f[iy];
        assert!(up > 0.0, "node {node}: F moved it by {up:e} in y, not up");
        // Without F the top load presses Γ3,2 below y = 0: nothing holds it there.
        if disc.nodes[node][0] > 1.5 {
            assert!(
                without_f[iy] < 0.0,
                "node {node}: u_y = {:e}",
                without_f[iy]
            );
        }
    }
    assert!(gamma32_nodes >= 4, "{gamma32_nodes} Γ3,2 nodes");
}
