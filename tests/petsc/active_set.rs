//! The active-set contact solver (`solver.contact = "active_set"`, on PETSc) against the
//! dense dual and clarabel: every golden scene with contact or friction (2D and 3D: the
//! paper's variants, the bracket, the plate with a hole, the punch, the bimaterial, the
//! blocks, the half block and the thin slab), the corners
//! where Γ3,1 meets Γ3,2, half models with an inclined symmetry plane, friction whose
//! coefficient is an expression, and a block under a traction that turns (nodes change
//! state from step to step). u_N agrees with the dense dual's to 1e-8 relative; the runs are bit for
//! bit the same when stopped and resumed, their forces balance in history.csv, and
//! summary.json records the Newton and Krylov counts. The Newton systems' multigrid,
//! updated in place, is the Galerkin hierarchy of its system after every update.

use crate::common::{self, load, rel_diff, repo, trace, SceneText, Trace};

/// Traces of `scene` with each of `solvers` (values of `solver.contact`), through the
/// library, one PETSc run at a time.
fn traces(scene: &SceneText, solvers: &[&str]) -> Vec<Trace> {
    let dir = tempfile::tempdir().unwrap();
    solvers
        .iter()
        .map(|s| {
            let path = scene
                .clone()
                .set("solver.contact", *s)
                .write(dir.path(), "s.toml");
            let (scene, _mesh, disc) = load(&path, &[]);
            let _one = crate::PETSC.lock().unwrap_or_else(|e| e.into_inner());
            trace(&scene, &disc)
        })
        .collect()
}

/// The largest relative difference of w over the steps of two traces.
fn max_step_diff(a: &Trace, b: &Trace) -> f64 {
    (a.w.iter().zip(&b.w))
        .map(|(x, y)| rel_diff(x, y))
        .fold(0.0, f64::max)
}

/// `active_set` against `dense` (and `clarabel` where asked) on `scene`: u_N to 1e-8
/// relative, every step's w to 1e-7.
fn agrees(scene: SceneText, what: &str, with_clarabel: bool) {
    let solvers: &[&str] = match with_clarabel {
        true => &["dense", "active_set", "clarabel"],
        false => &["dense", "active_set"],
    };
    let t = traces(&scene, solvers);
    assert!(t[0].solver.starts_with("dual"), "{}", t[0].solver);
    assert!(t[1].solver.starts_with("active set"), "{}", t[1].solver);
    let (du, dw) = (
        rel_diff(&t[1].u_final, &t[0].u_final),
        max_step_diff(&t[1], &t[0]),
    );
    println!("{what}: |u_N − dense| {du:.1e}, max over steps |w − dense| {dw:.1e}");
    assert!(common::max_abs(&t[0].u_final) > 0.0);
    assert!(du <= 1e-8 && dw <= 1e-7, "{what}: {du:e} {dw:e}");
    if with_clarabel {
        let dc = rel_diff(&t[1].u_final, &t[2].u_final);
        println!("{what}: |u_N − clarabel| {dc:.1e}");
        assert!(dc <= 1e-7, "{what}: {dc:e}");
    }
}

const RELAXATION: &str = "material.relaxation";

/// The golden scenes with contact or friction (tests/regression/golden.rs), in 2D.
#[test]
fn the_golden_2d_scenes_agree_with_the_dense_dual() {
    let paper = SceneText::paper;
    let cases = [
        (paper(), "paper"),
        (
            paper().mesh(repo().join("meshes/paper/rect_064.msh")),
            "paper on rect_064",
        ),
        (paper().set("friction.normal_stress", 0.1), "paper F = 0.1"),
        (paper().set("friction.coefficient", 5), "paper μ = 5"),
        (paper().set("scheme.history", "implicit"), "paper, implicit"),
        (
            paper().table(RELAXATION, "expr = \"0.2*(s+0.01)^(-0.5)\""),
            "paper, power law compressed",
        ),
        (
            paper().table(RELAXATION, "table = { s = [0, 0.5, 1], r = [1, 0.3, 0.1] }"),
            "paper, table kernel",
        ),
        (
            paper().table(
                RELAXATION,
                "expr = \"0.2*(s+0.01)^(-0.5)\"\nmemory = \"exact\"",
            ),
            "paper, power law exact",
        ),
        (SceneText::example("bracket.toml"), "bracket"),
        (SceneText::example("plate_hole.toml"), "plate with a hole"),
        (SceneText::example("punch.toml"), "punch"),
        (SceneText::example("bimaterial.toml"), "bimaterial"),
    ];
    for (scene, what) in cases {
        agrees(scene, what, false);
    }
}

/// The golden 3D scenes with contact and friction, the slab 1/250 of its width thick
/// (tests/data/3d/slab_t0008.msh) among them: with ρ at K's diagonal its sets wandered
/// without converging (`RHO_START`).
#[test]
fn the_golden_3d_scenes_agree_with_the_dense_dual() {
    let block = SceneText::block;
    let cases = [
        (block(), "block"),
        (block().set("friction.coefficient", 5), "block μ = 5"),
        (
            block()
                .mesh(repo().join("tests/data/3d/block_unstructured.msh"))
                .set("time.steps", 16),
            "unstructured block",
        ),
        (SceneText::example("half_block.toml"), "half block"),
        (
            SceneText::paper()
                .mesh(repo().join("tests/data/3d/slab_t0008.msh"))
                .set("mesh.model", "3d")
                .set("time.steps", 8)
                .set("time.end", 0.25)
                .set("load.traction", toml::Value::Array(vec![]))
                .traction(Some("top"), &["0", "-0.1*x*(2-x)*min(t, 0.2)", "0"])
                .traction(
                    Some("right"),
                    &["if(t <= 0.5, 0.01*(1-y)*t, 0.01*(1-y)*0.2)", "0", "0"],
                ),
            "slab 0.008",
        ),
    ];
    for (scene, what) in cases {
        agrees(scene, what, false);
    }
}

/// Half models whose symmetry plane is inclined (tests/data/symmetry/*_turned.msh: the
/// plane nodes' dofs in frames of their own, and GAMG's rigid-body modes in those frames):
/// the block in 3D, contact meeting the plane, and the rectangle in 2D, friction on the line.
#[test]
fn half_models_with_an_inclined_symmetry_plane_agree_with_the_dense_dual() {
    let data = repo().join("tests/data/symmetry");
    let cases = [
        (SceneText::block(), "half_block_turned.msh"),
        (
            SceneText::paper()
                .set("load.traction", toml::Value::Array(vec![]))
                .traction(None, &["0", "-0.1*min(t, 0.2)"]),
            "half_rect_turned.msh",
        ),
    ];
    for (scene, mesh) in cases {
        let scene =
            scene
                .mesh(data.join(mesh))
                .set("time.steps", 16)
                .dirichlet("sym", &["normal"], None);
        agrees(scene, mesh, false);
    }
}

/// Γ3,1 and Γ3,2 meeting at a corner of 45°, 89.9°, 90° and 135° (tests/data/corner): the
/// contact normal and the friction tangent are dependent at 90°, and the force there splits
/// in many ways; w is unique, and agrees.
#[test]
fn corners_agree_with_the_dense_dual() {
    let dir = repo().join("tests/data/corner");
    for angle in ["0450", "0899", "0900", "1350"] {
        let scene =
            SceneText::file(&dir.join("corner.toml")).mesh(dir.join(format!("corner_{angle}.msh")));
        agrees(scene, &format!("corner {angle}"), false);
    }
}

/// Friction whose coefficient is an expression of the position (μ = 0.6 x, as
/// tests/solutions/friction_cone.rs) on the unstructured slider pushed at 30° to the x
/// axis: the nodes near x = 0 slide in every direction of their tangent plane, those near
/// x = 1 stick; u_N agrees with the dense dual and with clarabel.
#[test]
fn an_expression_friction_coefficient_agrees_with_the_dense_dual_and_clarabel() {
    let scene = SceneText::slider("0.6*x", 30.0).set("time.steps", 2);
    agrees(scene, "slider, μ = 0.6 x", true);
}

/// The block at h = 1/4 under a top traction whose tangential part turns once around over
/// the run and whose normal part pulsates (as tests/solutions/matrix_free.rs): contact and
/// friction nodes change state from step to step; u_N agrees with clarabel over 64 steps.
#[test]
fn a_rotating_traction_agrees_with_clarabel() {
    let traction: toml::Table = toml::from_str(
        "on = \"top\"\nvalue = [\"0.05*cos(2*pi*t)\", \"0.05*sin(2*pi*t)\", \
         \"-0.03*sin(6*pi*t)\"]",
    )
    .unwrap();
    let scene = SceneText::block()
        .mesh(repo().join("meshes/3d/block_004.msh"))
        .remove("load")
        .push("load.traction", traction)
        .set("time.steps", 64);
    agrees(scene, "rotating traction", true);
}

/// A run stopped after a step and resumed gives the uninterrupted run's series and
/// summary bit for bit (PETSc in one process is deterministic: GAMG's hierarchy is built
/// from K_A alone, the same at the resume); summary.json records the Newton systems and
/// their Krylov iterations.
#[test]
fn stop_and_resume_through_petsc_is_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let path = SceneText::paper()
        .set("solver.contact", "active_set")
        .set("output.every", 1)
        .write(dir.path(), "s.toml");
    let (whole, parts) = (dir.path().join("whole"), dir.path().join("parts"));
    let run = |args: &[&str]| {
        let (code, text) = common::cli(args);
        assert_eq!(code, 0, "{args:?}: {text}");
    };
    let (path, whole_s, parts_s) = (
        path.to_str().unwrap(),
        whole.to_str().unwrap(),
        parts.to_str().unwrap(),
    );
    run(&["run", "--quiet", "--out", whole_s, path]);
    run(&[
        "run",
        "--quiet",
        "--stop-after",
        "12",
        "--out",
        parts_s,
        path,
    ]);
    run(&["resume", "--quiet", &format!("{parts_s}/checkpoint.h5")]);
    common::assert_same_series(&whole, &parts, "paper through active_set");
    // The multipliers come from the residual of each Newton system: history.csv balances.
    common::History::read(&whole).assert_balanced("paper through active_set");
    let s = common::summary(&whole);
    let newton = &s["petsc"]["newton"];
    assert_eq!(newton["steps"], 33, "{s}");
    let systems = newton["systems"].as_u64().unwrap();
    let per_step = s["iterations"]["per_step"].as_array().unwrap();
    let sum: u64 = per_step.iter().map(|i| i.as_u64().unwrap()).sum();
    assert_eq!(systems, sum, "{s}");
    assert!(newton["krylov_total"].as_u64().unwrap() >= systems, "{s}");
}

/// `[solver.active_set]` reaches the solver: looser tolerances take fewer Krylov
/// iterations and move u_N by about the tolerance, summary.json records them, and a step
/// beyond `max_iterations` fails the run (exit 1) naming the key.
#[test]
fn the_scene_sets_the_active_sets_tolerances_and_its_iteration_limit() {
    let dir = tempfile::tempdir().unwrap();
    let scene = SceneText::paper().set("solver.contact", "active_set");
    let loose = (scene.clone())
        .set("solver.active_set.tolerance", 1e-6)
        .set("solver.active_set.forcing", 0.1)
        .set("solver.active_set.krylov_tolerance", 1e-8);
    let run = |scene: &SceneText, name: &str| {
        let path = scene.write(dir.path(), &format!("{name}.toml"));
        let out = dir.path().join(name);
        let (code, text) = common::cli(&[
            "run",
            "--quiet",
            "--out",
            out.to_str().unwrap(),
            path.to_str().unwrap(),
        ]);
        (code, text, out)
    };
    let (code, text, default) = run(&scene, "default");
    assert_eq!(code, 0, "{text}");
    let (code, text, looser) = run(&loose, "loose");
    assert_eq!(code, 0, "{text}");
    let newton = |out: &std::path::Path| common::summary(out)["petsc"]["newton"].clone();
    let (d, l) = (newton(&default), newton(&looser));
    assert_eq!(
        (&d["tolerance"], &d["max_iterations"], &d["forcing"]),
        (&1e-10.into(), &50.into(), &1e-2.into()),
        "{d}"
    );
    assert_eq!(d["krylov_tolerance"], 1e-12, "{d}");
    assert_eq!(
        (&l["tolerance"], &l["forcing"], &l["krylov_tolerance"]),
        (&1e-6.into(), &0.1.into(), &1e-8.into()),
        "{l}"
    );
    let krylov = |n: &serde_json::Value| n["krylov_total"].as_u64().unwrap();
    assert!(krylov(&l) < krylov(&d), "{l} against {d}");
    let t = traces(&loose, &["dense", "active_set"]);
    let du = rel_diff(&t[1].u_final, &t[0].u_final);
    println!(
        "tolerance 1e-6: |u_N − dense| {du:.1e}; Krylov {} against {}",
        krylov(&l),
        krylov(&d)
    );
    assert!(du > 1e-12 && du <= 1e-5, "{du:e}");

    let (code, text, out) = run(&scene.set("solver.active_set.max_iterations", 1), "one");
    assert_eq!(code, 1, "{text}");
    assert!(
        text.contains("did not converge in 1 iterations")
            && text.contains("raise [solver.active_set] max_iterations"),
        "{text}"
    );
    assert_eq!(common::summary(&out)["status"], "failed");
}

/// The Newton systems' terms for a choice of sets on `disc`'s rows, flat as the shim reads
/// them: the contact rows `active` picks removed; each friction node (not on Γ3,1) that
/// `stick` picks with its two tangents removed, the others with a slip stiffness s (τ₁τ₁ᵀ +
/// τ₂τ₂ᵀ) of s = 10⁻²·max |K|.
struct Sets {
    removed_dofs: Vec<i32>,
    removed: Vec<f64>,
    stiffness_dofs: Vec<i32>,
    stiffness: Vec<f64>,
}

impl Sets {
    fn of(
        disc: &viscontact::fem::Discretization,
        active: impl Fn(usize) -> bool,
        stick: impl Fn(usize) -> bool,
    ) -> Sets {
        let dofs = |row: &viscontact::fem::NodalRow| -> [i32; 3] {
            std::array::from_fn(|c| match row.dir[c] != 0.0 {
                true => row.dofs[c] as i32,
                false => -1,
            })
        };
        let mut sets = Sets {
            removed_dofs: Vec::new(),
            removed: Vec::new(),
            stiffness_dofs: Vec::new(),
            stiffness: Vec::new(),
        };
        for (_, row) in disc.contact.iter().enumerate().filter(|(i, _)| active(*i)) {
            sets.removed_dofs.extend(dofs(row));
            sets.removed.extend(row.dir);
        }
        let contact: std::collections::HashSet<usize> =
            disc.contact.iter().map(|r| r.node).collect();
        let s = 1e-2 * common::max_abs(disc.k_a.val());
        let pairs = disc
            .friction
            .chunks(2)
            .filter(|t| !contact.contains(&t[0].node));
        for (j, tangents) in pairs.enumerate() {
            if stick(j) {
                for t in tangents {
                    sets.removed_dofs.extend(dofs(t));
                    sets.removed.extend(t.dir);
                }
                continue;
            }
            let d: [i32; 3] =
                std::array::from_fn(|c| dofs(&tangents[0])[c].max(dofs(&tangents[1])[c]));
            sets.stiffness_dofs.extend(d);
            sets.stiffness.extend((0..9).map(|e| {
                let (a, b) = (e / 3, e % 3);
                s * tangents.iter().map(|t| t.dir[a] * t.dir[b]).sum::<f64>()
            }));
        }
        sets
    }

    fn view(&self) -> viscontact::petsc::NodalTerms<'_> {
        viscontact::petsc::NodalTerms {
            removed_dofs: &self.removed_dofs,
            removed: &self.removed,
            stiffness_dofs: &self.stiffness_dofs,
            stiffness: &self.stiffness,
        }
    }
}

/// The Newton systems' multigrid is not rebuilt by GAMG but updated in place: its coarse
/// operators are K's (at a step's first system) or the last system's plus the difference
/// carried down the levels. After every system, kept or updated, each coarse operator is
/// the Galerkin product of the level above computed anew, to 1e-12 relative; and a system
/// solved on an updated hierarchy takes the iterations and gives the solution of the same
/// system on a hierarchy made from K.
#[test]
fn the_updated_multigrid_is_the_galerkin_hierarchy_of_its_system() {
    use viscontact::petsc::{Hierarchy, Krylov, KrylovSettings, Reads, Tolerance};
    let dir = tempfile::tempdir().unwrap();
    let path = SceneText::block().write(dir.path(), "s.toml");
    let (_scene, _mesh, disc) = load(&path, &[]);
    assert!(!disc.contact.is_empty() && !disc.friction.is_empty());
    let _one = super::PETSC.lock().unwrap_or_else(|e| e.into_inner());
    let settings = KrylovSettings {
        options: String::new(),
        rtol: 1e-12,
        newton: true,
    };
    // One process: every unknown is its own.
    let reads = Reads {
        dofs: &[],
        held: false,
    };
    let mut krylov = Krylov::new(&disc.k_a, None, &disc, &settings, reads).unwrap();
    let mut rng = common::SplitMix(50);
    let b: Vec<f64> = (0..disc.n_free).map(|_| rng.unit() - 0.5).collect();
    let all = Sets::of(&disc, |_| true, |j| j % 2 == 0);
    let some = Sets::of(&disc, |i| i % 3 != 0, |_| false);
    let others = Sets::of(&disc, |i| i % 3 != 1, |j| j % 5 == 0);
    let mut solve = |sets: &Sets, hierarchy: Hierarchy| {
        let mut w = vec![0.0; disc.n_free];
        let (rhs, tolerance) = ((&b[..], &[][..], &[][..]), Tolerance::OfRhs(1e-12));
        let s = krylov
            .solve_constrained(sets.view(), rhs, &mut w, tolerance, hierarchy)
            .unwrap();
        assert!(s.failed.is_none(), "{hierarchy:?}: {:?}", s.failed);
        let defect = krylov.galerkin_defect().unwrap();
        println!(
            "{hierarchy:?}: {} iterations, Galerkin defect {defect:e}",
            s.iterations
        );
        assert!(defect <= 1e-12, "{hierarchy:?}: Galerkin defect {defect:e}");
        (w, s.iterations)
    };
    solve(&all, Hierarchy::FromK);
    let (updated, its_updated) = solve(&some, Hierarchy::Updated);
    solve(&some, Hierarchy::Last);
    solve(&others, Hierarchy::Updated);
    let (from_k, its_from_k) = solve(&some, Hierarchy::FromK);
    let d = rel_diff(&updated, &from_k);
    println!("updated against from K: {its_updated} and {its_from_k} iterations, {d:e}");
    assert!(
        its_updated.abs_diff(its_from_k) <= 1,
        "{its_updated} against {its_from_k}"
    );
    assert!(d <= 1e-9, "updated against from K: {d:e}");
}
