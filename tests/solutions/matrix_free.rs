//! The contact solvers without D (`solver.contact = "matrix_free"`, through the trailing
//! block of a factor with C last, and `"sparse"`, through solves with a linear run's
//! factor) against the dense dual and clarabel: the paper's scene (2D), the unstructured
//! block (3D, contact, friction and memory), and a block sliding under a traction that turns
//! (contact and friction nodes change state from step to step); `auto` takes the dense dual
//! on every such boundary, by its size alone, and the plan names the solver, its memory and
//! its cost. (The refusal of a plan that does not fit the machine:
//! tests/cli/contact_plan.rs.)

use crate::common;
use common::*;
use viscontact::resources::dense_dual_bytes;
use viscontact::solver::choice::{auto, Contact, ContactPlan, Why, DENSE_LIMIT};
use viscontact::solver::Rows;

/// u_N of a scene with each of `solvers` (values of solver.contact), and the solver names.
fn finals(scene: &std::path::Path, overrides: &[&str], solvers: &[&str]) -> Vec<Trace> {
    solvers
        .iter()
        .map(|s| {
            let mut o = overrides.to_vec();
            let key = format!("solver.contact={s}");
            o.push(&key);
            let (scene, _m, disc) = load(scene, &o);
            trace(&scene, &disc)
        })
        .collect()
}

/// The largest relative difference of w over the steps of two traces.
fn max_step_diff(a: &Trace, b: &Trace) -> f64 {
    a.w.iter()
        .zip(&b.w)
        .map(|(x, y)| rel_diff(x, y))
        .fold(0.0, f64::max)
}

/// Each dual without D against dense (both at the dual's KKT tolerance) and against
/// clarabel.
fn agree(scene: &std::path::Path, overrides: &[&str], what: &str) {
    let t = finals(
        scene,
        overrides,
        &["dense", "clarabel", "auto", "matrix_free", "sparse"],
    );
    assert!(t[0].solver.starts_with("dual"));
    assert_eq!(t[2].solver, t[0].solver, "auto takes the dense dual");
    assert_eq!(
        t[2].u_final, t[0].u_final,
        "auto is the dense dual bit for bit"
    );
    for (free, name) in t[3..].iter().zip(["matrix-free", "sparse"]) {
        assert!(free.solver.starts_with(name), "{}", free.solver);
        let (dense, clarabel) = (
            rel_diff(&t[0].u_final, &free.u_final),
            rel_diff(&t[1].u_final, &free.u_final),
        );
        let steps = max_step_diff(&t[0], free);
        println!("{what}, {name}: |u_N − dense| {dense:.1e}, |u_N − clarabel| {clarabel:.1e}, max over steps |w − dense| {steps:.1e}");
        assert!(
            dense <= 1e-9 && steps <= 1e-8,
            "{what}, {name}: {dense:e} {steps:e}"
        );
        assert!(clarabel <= 1e-7, "{what}, {name}: {clarabel:e}");
    }
}

#[test]
fn duals_without_d_agree_on_the_paper_scene() {
    let mesh = format!("mesh.file={}", mesh_path("paper/rect_008.msh"));
    agree(
        &repo().join("examples/paper.toml"),
        &[&mesh, "time.steps=8"],
        "paper 1/8",
    );
}

#[test]
fn duals_without_d_agree_on_the_unstructured_block() {
    let mesh = repo().join("tests/data/3d/block_unstructured.msh");
    agree(
        &repo().join("examples/block.toml"),
        &[&format!("mesh.file={}", mesh.display()), "time.steps=16"],
        "unstructured block",
    );
}

/// The block at h = 1/4 under a top traction whose tangential part turns once around over
/// the run and whose normal part pulsates: contact and friction nodes change state from
/// step to step; u_N agrees with clarabel to 1e-7 over 64 steps.
#[test]
fn duals_without_d_agree_under_a_rotating_traction() {
    let dir = tempfile::tempdir().unwrap();
    let base = std::fs::read_to_string(repo().join("examples/block.toml")).unwrap();
    let cut = base.find("[[load.traction]]").unwrap();
    let text = format!(
        "{}[[load.traction]]\non = \"top\"\nvalue = [\"0.05*cos(2*pi*t)\", \"0.05*sin(2*pi*t)\", \
         \"-0.03*sin(6*pi*t)\"]\n",
        base[..cut].replace("../meshes/3d/block_008.msh", &mesh_path("3d/block_004.msh"))
    );
    let scene = write(dir.path(), "rotating.toml", &text);
    agree(&scene, &["time.steps=64"], "rotating traction");
}

/// `auto` takes the dense dual while its matrices stay under `DENSE_LIMIT`, whatever the
/// machine, and the sparse one beyond; a forced key is obeyed; the plan says which.
#[test]
fn the_plan_names_the_solver_that_fits() {
    // The block at h = 1/8: 234 rows, D and its kin 1.8 MB, the matrix-free vectors 0.1 MB.
    let (scene, _m, disc) = load(&repo().join("examples/block.toml"), &[]);
    let rows = Rows::new(&disc.contact, &disc.friction, disc.dim - 1);
    let solver = descriptor(&scene, &disc);
    let plan = solver.contact().unwrap();
    assert_eq!(plan.solver, Contact::Dense);
    let dense = plan.memory.unwrap();
    assert!(dense < DENSE_LIMIT, "{dense}");
    assert!(
        plan.to_string()
            .starts_with("dense (auto: its matrices ≈ 1.8 MB, at most 4.0 GB)"),
        "{plan}"
    );
    let forced = ContactPlan::new(Contact::MatrixFree, Why::Key, &rows, &disc);
    assert_eq!(forced.solver, Contact::MatrixFree);
    assert!(forced.memory.unwrap() < dense);
    assert!(
        forced
            .to_string()
            .starts_with("matrix_free (solver.contact = \"matrix_free\")"),
        "{forced}"
    );
    let sparse = ContactPlan::new(Contact::Sparse, Why::Key, &rows, &disc);
    assert_eq!(sparse.solver, Contact::Sparse);
    assert!(sparse.memory.unwrap() < forced.memory.unwrap());
    // A boundary of 50 times the rows and dofs would hold a dense dual over the limit.
    // Without PETSc `auto` takes the sparse dual there, with it the active set.
    let (m, c) = (50 * rows.len(), 50 * rows.dofs().len());
    let dense = Some(dense_dual_bytes(m, c, rows.block));
    let pick = |petsc| auto(dense, petsc, || Ok(None)).unwrap().0;
    assert_eq!(pick(false), Some(Contact::Sparse));
    assert_eq!(pick(true), Some(Contact::ActiveSet));
}
