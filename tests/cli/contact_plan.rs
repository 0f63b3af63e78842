//! The contact solver's plan at the command line (issue 29): `auto` decides by the problem
//! alone, `check` prints the solver, its memory and its cost, and `check`, `run` and `resume`
//! refuse (exit 2) a plan that does not fit the memory available, naming the key that would,
//! before the run directory is touched. `VISCONTACT_MEMORY` stands for a smaller machine.

use crate::common::{self, with_memory, SceneText};

use std::path::{Path, PathBuf};
use std::process::Output;
use viscontact::resources::{Estimate, MARGIN, MEMORY_ENV};
use viscontact::solver::choice::{Contact, ContactPlan, Why};
use viscontact::solver::Rows;

/// The block's scene at h = 1/4 over `steps` steps.
fn block(steps: i64) -> SceneText {
    SceneText::block()
        .mesh(common::mesh_path("3d/block_004.msh"))
        .set("time.steps", steps)
}

/// The block at h = 1/4 over 4 steps, written into `dir`, a memory (bytes) in which its
/// sparse plan fits and its dense one does not (each besides the factor of K_A, as `check`
/// counts them), and the bytes of that factor's values; and a memory in which what its
/// steps hold fits and its sparse plan alone does not.
fn scene_and_tight_memory(dir: &Path) -> (PathBuf, f64, f64, f64) {
    let scene = block(4).write(dir, "s.toml");
    let (s, _m, disc) = common::load(&scene, &[]);
    let rows = Rows::new(&disc.contact, &disc.friction, disc.dim - 1);
    let memory = |solver| {
        let plan = ContactPlan::new(solver, Why::Key, &rows, &disc);
        plan.memory.unwrap()
    };
    let (dense, sparse) = (memory(Contact::Dense), memory(Contact::Sparse));
    assert!(sparse < dense, "{sparse} {dense}");
    let factor = common::descriptor(&s, &disc).factor_bytes(&disc);
    let factor = factor.unwrap().unwrap();
    let plans = viscontact::history::Plans::new(&s).unwrap();
    let steps = Estimate::new(&s, &disc, 0)
        .with_plans(&plans, &disc)
        .memory();
    assert!(steps < sparse, "{steps} {sparse}");
    let below_plan = (steps + sparse) / 2.0 / MARGIN;
    (scene, (dense * sparse).sqrt() / MARGIN, factor, below_plan)
}

/// Exit 2 and a message holding every one of `parts`.
fn refused(o: &Output, parts: &[&str]) {
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{stderr}");
    for p in parts {
        assert!(stderr.contains(p), "{p:?} not in: {stderr}");
    }
}

#[test]
fn check_prints_the_plan_and_refuses_one_that_does_not_fit() {
    let tmp = tempfile::tempdir().unwrap();
    let (scene, tight, factor, below_plan) = scene_and_tight_memory(tmp.path());
    let scene = scene.to_str().unwrap();
    let (code, text) = common::cli(&["check", scene]);
    assert_eq!(code, 0, "{text}");
    assert!(
        text.contains("contact    dense (auto: its matrices ≈ ") && text.contains("m³/3 = "),
        "{text}"
    );
    let (code, text) = common::cli(&["check", scene, "--set", "solver.contact=matrix_free"]);
    assert_eq!(code, 0, "{text}");
    assert!(
        text.contains("contact    matrix_free (solver.contact = \"matrix_free\"): memory ≈ ")
            && text.contains("the dense trailing block"),
        "{text}"
    );
    // auto is still the dense dual on a smaller machine, and refused there.
    let o = with_memory(tight, &["check", scene]);
    refused(
        &o,
        &[
            "the dense contact solver would need",
            "solver.contact = \"sparse\"",
        ],
    );
    // The sparse plan fits there; its factor of K_A (here larger than D) must fit too.
    let forced = ["check", scene, "--set", "solver.contact=sparse"];
    refused(&with_memory(tight, &forced), &["Cholesky factor of K_A"]);
    let o = with_memory(tight + factor / MARGIN, &forced);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        stdout.contains("contact    sparse (solver.contact = \"sparse\"): memory ≈ "),
        "{stdout}"
    );
    refused(&with_memory(below_plan, &forced), &["coarser mesh"]);
    refused(
        &with_memory(-1.0, &["check", scene]),
        &[MEMORY_ENV, "bytes"],
    );
}

#[test]
fn run_and_resume_refuse_a_plan_that_does_not_fit_and_leave_the_directory_as_it_was() {
    let tmp = tempfile::tempdir().unwrap();
    let (scene, tight, _, _) = scene_and_tight_memory(tmp.path());
    let (scene, dir) = (scene.to_str().unwrap(), tmp.path().join("o"));
    let dir_s = dir.to_str().unwrap();
    let (code, text) = common::cli(&["run", scene, "--out", dir_s, "--quiet", "--stop-after", "2"]);
    assert_eq!(code, 0, "{text}");
    let before = common::dir_contents(&dir);
    let checkpoint = dir.join("checkpoint.h5");
    let checkpoint = checkpoint.to_str().unwrap();
    let rerun = with_memory(tight, &["run", scene, "--out", dir_s, "--quiet"]);
    refused(&rerun, &["solver.contact = \"sparse\""]);
    assert!(
        common::dir_contents(&dir) == before,
        "a refused run changed the directory"
    );
    let resume = with_memory(tight, &["resume", checkpoint, "--quiet"]);
    refused(&resume, &["solver.contact = \"sparse\"", "a resume keeps"]);
    assert!(
        common::dir_contents(&dir) == before,
        "a refused resume changed the directory"
    );
    // The run the refusals left continues where more memory is available.
    let (code, text) = common::cli(&["resume", checkpoint, "--quiet"]);
    assert_eq!(code, 0, "{text}");
    assert_eq!(common::summary(&dir)["status"], "completed");
}

/// The solver's memory and the steps' (a general kernel's direct sum keeps every u_n) are
/// held at once: a run is refused when each fits alone but the two together do not, by
/// `check` and by `run` before the directory is made.
#[test]
fn the_contact_solver_and_the_steps_are_counted_together() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = block(20_000)
        .table(
            "material.relaxation",
            "expr = \"0.2*(s+0.01)^(-0.5)\"\nmemory = \"exact\"",
        )
        .write(tmp.path(), "s.toml");
    let (s, _m, disc) = common::load(&scene, &[]);
    let solver = common::descriptor(&s, &disc)
        .contact()
        .unwrap()
        .memory
        .unwrap();
    let steps = viscontact::resources::Estimate::new(&s, &disc, 0).memory();
    assert!(steps > solver, "{steps} {solver}");
    // Room for the steps and half of the solver, in the share a run may plan.
    let memory = (steps + 0.5 * solver) / MARGIN;
    let scene = scene.to_str().unwrap();
    let o = with_memory(memory, &["check", scene]);
    refused(&o, &["that the steps hold", "solver.contact = \"sparse\""]);
    let dir = tmp.path().join("o");
    let o = with_memory(memory, &["run", scene, "--out", dir.to_str().unwrap()]);
    refused(&o, &["that the steps hold"]);
    assert!(!dir.exists(), "a refused run made its directory");
}

/// A dual without D can make a run take hours where the body starts to slide: `check` and
/// `run` say so before the first step, and summary.json keeps it; the dense dual does not.
#[test]
fn the_duals_without_d_warn_that_sliding_steps_can_be_slow() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = block(2).write(tmp.path(), "s.toml");
    let scene = scene.to_str().unwrap();
    let slow = "minutes to tens of minutes each";
    for solver in ["sparse", "matrix_free", "dense"] {
        let set = format!("solver.contact=\"{solver}\"");
        let (code, text) = common::cli(&["check", scene, "--set", &set]);
        assert_eq!(code, 0, "{text}");
        let warned = text.contains(&format!(
            "warning    the contact solver is the {solver} dual"
        ));
        assert_eq!(warned, solver != "dense", "{solver}: {text}");
        assert_eq!(text.contains(slow), solver != "dense", "{solver}: {text}");
        let dir = tmp.path().join(solver);
        let o = common::viscontact(&[
            "run",
            scene,
            "--set",
            &set,
            "--quiet",
            "--out",
            dir.to_str().unwrap(),
        ]);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(0), "{stderr}");
        assert_eq!(
            stderr.starts_with("warning: the contact solver"),
            solver != "dense",
            "{stderr}"
        );
        let warnings = common::summary(&dir)["warnings"].to_string();
        assert_eq!(warnings.contains(slow), solver != "dense", "{warnings}");
    }
}

/// The Cholesky factor of K_A is sized by its symbolic analysis before anything is factored:
/// `check` prints it, and `check` and `run` refuse (exit 2, naming the backend without a
/// factor) a factor whose values do not fit, before the run directory is touched.
#[test]
fn a_factor_that_does_not_fit_is_refused_before_it_is_factored() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = block(4)
        .set("contact.enabled", false)
        .set("friction.enabled", false)
        .write(tmp.path(), "s.toml");
    let (s, _m, disc) = common::load(&scene, &[]);
    let bytes = common::descriptor(&s, &disc).factor_bytes(&disc);
    let bytes = bytes.unwrap().unwrap();
    assert!(bytes > 0.0);
    let scene = scene.to_str().unwrap();
    let (code, text) = common::cli(&["check", scene]);
    assert_eq!(code, 0, "{text}");
    assert!(
        text.contains("factor     Cholesky factor of K_A: ≈ "),
        "{text}"
    );
    let parts = [
        "Cholesky factor of K_A",
        "for its values alone",
        "--features petsc",
    ];
    refused(&with_memory(bytes, &["check", scene]), &parts);
    let dir = tmp.path().join("o");
    let dir_s = dir.to_str().unwrap();
    refused(
        &with_memory(bytes, &["run", scene, "--out", dir_s, "--quiet"]),
        &parts,
    );
    assert!(!dir.exists(), "a refused run left {}", dir.display());
    let o = with_memory(
        bytes / MARGIN * 1.01,
        &["run", scene, "--out", dir_s, "--quiet"],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// clarabel builds no factor of K_A: it assembles and factors its own step problem.
/// `check` says so (and sizes no factor), and its run agrees with the dense dual's.
#[test]
fn clarabel_builds_no_factor() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = block(2).write(tmp.path(), "s.toml");
    let (s, _m, disc) = common::load(&scene, &["solver.contact=clarabel"]);
    let mut solver = viscontact::solver::choice::Descriptor::of_run(&s, &disc).unwrap();
    assert_eq!(*solver.build(), viscontact::solver::choice::Build::Nothing);
    assert_eq!(solver.factor_bytes(&disc).unwrap(), None);
    let scene = scene.to_str().unwrap();
    let (code, text) = common::cli(&["check", scene, "--set", "solver.contact=clarabel"]);
    assert_eq!(code, 0, "{text}");
    assert!(text.contains("factor     none: clarabel"), "{text}");
    assert!(!text.contains("Cholesky factor of K_A: ≈"), "{text}");
    let u = |contact: &str| {
        let set = format!("solver.contact={contact}");
        let (s, _m, disc) = common::load(Path::new(scene), &[&set]);
        common::trace(&s, &disc).u_final
    };
    let (conic, dense) = (u("clarabel"), u("dense"));
    let scale = common::max_abs(&dense);
    let diff = conic.iter().zip(&dense).map(|(a, b)| (a - b).abs());
    assert!(
        diff.fold(0.0, f64::max) <= 1e-6 * scale,
        "{conic:?} {dense:?}"
    );
}

/// In a build without PETSc, `check` says where the build with it would pick otherwise, and
/// how to get it: beyond `DENSE_LIMIT` `auto` takes the sparse dual here and the active set
/// there; a plan that does not fit names that build too. A scene within both limits (the
/// block) prints no such line.
#[cfg(not(feature = "petsc"))]
#[test]
fn check_says_what_the_build_with_petsc_would_pick() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = common::strip_scene(tmp.path());
    let (s, _m, disc) = common::load(&scene, &[]);
    let solver = common::descriptor(&s, &disc);
    assert_eq!(solver.contact_solver(), Some(Contact::Sparse));
    let scene = scene.to_str().unwrap();
    let (code, text) = common::cli(&["check", scene]);
    assert_eq!(code, 0, "{text}");
    for part in [
        "contact    sparse (auto: the dense dual would need ≈ 4.1 GB, over 4.0 GB)",
        "petsc      a build with PETSc would pick solver.contact = \"active_set\" (auto: the \
         dense dual would need ≈ 4.1 GB, over 4.0 GB); to get it, install PETSc's development \
         files (Debian 12: `apt-get install --no-install-recommends petsc-dev`)",
        "cargo build --release --features petsc",
    ] {
        assert!(text.contains(part), "{part:?} not in: {text}");
    }
    // Room for the steps and half of the sparse plan: refused, naming the build with PETSc.
    let plan = solver.contact().unwrap().memory.unwrap();
    let steps = viscontact::resources::Estimate::new(&s, &disc, 0).memory();
    let o = with_memory((steps + 0.5 * plan) / MARGIN, &["check", scene]);
    refused(
        &o,
        &[
            "the sparse contact solver would need",
            "a build with PETSc, whose auto picks the active-set solver",
            "--features petsc",
        ],
    );
    let block = block(4).write(tmp.path(), "b.toml");
    let (code, text) = common::cli(&["check", block.to_str().unwrap()]);
    assert_eq!(code, 0, "{text}");
    assert!(
        text.contains("contact    dense (auto: ") && !text.contains("petsc      "),
        "{text}"
    );
}

/// `[solver.active_set]` in a scene whose steps another solver solves is said to be
/// unused (`check`), and its values are checked all the same (exit 2 naming the key).
#[test]
fn active_set_keys_that_no_step_reads_are_warned_about_and_still_checked() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = SceneText::paper()
        .set("solver.contact", "dense")
        .set("solver.active_set.tolerance", 1e-8)
        .write(tmp.path(), "s.toml");
    let scene = scene.to_str().unwrap();
    let (code, text) = common::cli(&["check", scene]);
    assert_eq!(code, 0, "{text}");
    assert!(
        text.contains("[solver.active_set] is set, but this run's steps are solved by the dense")
            && text.contains("its keys are not used"),
        "{text}"
    );
    let (code, text) = common::cli(&["check", scene, "--set", "solver.active_set.forcing=1.5"]);
    assert_eq!(code, 2, "{text}");
    assert!(
        text.contains("key 'solver.active_set.forcing' is 1.5") && text.contains("1e-15 ≤ η < 1"),
        "{text}"
    );
}
