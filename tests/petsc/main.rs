//! The PETSc linear backend (`[solver] linear = "petsc"`, cargo feature `petsc`): a linear
//! run through PETSc's CG + GAMG agrees with the stored Cholesky factor's to 1e-8 relative in
//! u_N (the paper's scene and the 3D block without contact and friction); the scene's options
//! and `PETSC_OPTIONS` reach PETSc; a KSP that does not converge fails the run (exit 1)
//! naming its reason; the scenes PETSc cannot run are refused (exit 2). Without the feature
//! only the refusal of a build without PETSc is tested here.
//!
//! CI runs this binary with the feature: `cargo test --release --features petsc --test
//! petsc`. The library runs share the process's one PETSc (not thread-safe), one at a time
//! (`PETSC`); the command-line runs are processes of their own.

#[path = "../common/mod.rs"]
mod common;

use common::SceneText;

/// The paper's scene without Γ3 (no contact, no friction): a linear run.
#[cfg(feature = "petsc")]
fn paper_linear() -> SceneText {
    SceneText::paper().remove("contact").remove("friction")
}

/// The 3D block (examples/block.toml) without contact and friction.
#[cfg(feature = "petsc")]
fn block_linear() -> SceneText {
    SceneText::block().remove("contact").remove("friction")
}

/// One library run through PETSc at a time (PETSc is not thread-safe).
#[cfg(feature = "petsc")]
static PETSC: std::sync::Mutex<()> = std::sync::Mutex::new(());

#[cfg(feature = "petsc")]
mod active_set;

#[cfg(feature = "petsc")]
mod ranks;

#[cfg(feature = "petsc")]
mod with_petsc {
    use super::*;

    /// u_N of `scene` with `solver.linear = linear`, run through the library, and the
    /// solver's name.
    fn u_final(scene: &SceneText, linear: &str) -> (Vec<f64>, &'static str) {
        let dir = tempfile::tempdir().unwrap();
        let path = scene
            .clone()
            .set("solver.linear", linear)
            .write(dir.path(), "s.toml");
        let (scene, _mesh, disc) = common::load(&path, &[]);
        let _one = super::PETSC.lock().unwrap_or_else(|e| e.into_inner());
        let trace = common::trace(&scene, &disc);
        (trace.u_final, trace.solver)
    }

    fn agrees_with_cholesky(scene: SceneText, what: &str) {
        let (petsc, _) = u_final(&scene, "petsc");
        let (cholesky, name) = u_final(&scene, "cholesky");
        assert!(name.contains("Cholesky"), "{name}");
        let d = common::rel_diff(&petsc, &cholesky);
        println!("{what}: max|u_N(petsc) − u_N(cholesky)| / max|u_N| = {d:e}");
        assert!(common::max_abs(&cholesky) > 0.0);
        assert!(d <= 1e-8, "{what}: u_N differs by {d:e} relative");
    }

    #[test]
    fn paper_scene_without_contact_agrees_with_cholesky() {
        agrees_with_cholesky(paper_linear(), "paper (2D) without contact and friction");
    }

    #[test]
    fn block_without_contact_agrees_with_cholesky() {
        agrees_with_cholesky(block_linear(), "block (3D) without contact and friction");
    }

    /// A prescribed displacement (`[[dirichlet]]`, a value that is not zero) enters the right
    /// side and leaves the unknowns: the Krylov solve and GAMG's near-null space take the
    /// unknowns alone.
    #[test]
    fn a_prescribed_displacement_agrees_with_cholesky() {
        let held: toml::Table =
            toml::from_str("on = \"Γ3,2\"\ncomponents = [\"y\"]\nvalue = [\"0.01*t\"]").unwrap();
        let scene = paper_linear().push("dirichlet", held);
        agrees_with_cholesky(scene.clone(), "paper (2D) with Γ3,2 lifted by u_y = 0.01 t");
        // Over ranks every rank holds the matrices whole (their velocities reach every row),
        // and `check` plans them so.
        let dir = tempfile::tempdir().unwrap();
        let path = scene
            .set("solver.linear", "petsc")
            .write(dir.path(), "s.toml");
        let path = path.to_str().unwrap();
        let (code, text) = common::cli(&["check", path, "--ranks", "2"]);
        assert_eq!(code, 0, "{text}");
        assert!(
            text.contains("with the matrices whole (prescribed dofs)"),
            "{text}"
        );
    }

    /// Runs the binary on `scene` into a temporary directory with `env` set: its exit status,
    /// stderr and (for a run that wrote one) summary.json.
    fn run(scene: SceneText, env: &[(&str, &str)]) -> (i32, String, Option<serde_json::Value>) {
        let dir = tempfile::tempdir().unwrap();
        let path = scene.set("time.steps", 4).write(dir.path(), "s.toml");
        let out = dir.path().join("out");
        let out = std::process::Command::new(common::BIN)
            .args(["run", "--quiet", "--out"])
            .arg(&out)
            .arg(&path)
            .env_remove("PETSC_OPTIONS")
            .envs(env.iter().copied())
            .output()
            .unwrap();
        let summary = out
            .status
            .success()
            .then(|| common::summary(&dir.path().join("out")));
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        (out.status.code().unwrap_or(-1), stderr, summary)
    }

    #[test]
    fn summary_records_the_ksp_and_its_iterations() {
        let scene = block_linear().set("solver.linear", "petsc");
        let (code, stderr, summary) = run(scene, &[]);
        assert_eq!(code, 0, "{stderr}");
        let s = summary.unwrap();
        assert_eq!(s["petsc"]["ksp_type"], "cg", "{s}");
        assert_eq!(s["petsc"]["pc_type"], "gamg", "{s}");
        assert_eq!(s["petsc"]["options"], "");
        assert!(s["solver"].as_str().unwrap().contains("PETSc"), "{s}");
        let per_step = s["iterations"]["per_step"].as_array().unwrap();
        assert_eq!(per_step.len(), 5);
        // Step 0 starts from rest under a load: the Krylov method iterates.
        assert!(
            per_step.iter().skip(1).all(|i| i.as_u64().unwrap() > 0),
            "{s}"
        );
    }

    #[test]
    fn check_names_the_petsc_backend() {
        let dir = tempfile::tempdir().unwrap();
        let path = paper_linear()
            .set("solver.linear", "petsc")
            .write(dir.path(), "s.toml");
        let (code, text) = common::cli(&["check", path.to_str().unwrap()]);
        assert_eq!(code, 0, "{text}");
        assert!(text.contains("Krylov solve per step by PETSc"), "{text}");
        assert!(!text.contains("Cholesky"), "{text}");
    }

    #[test]
    fn scene_options_reach_petsc() {
        let scene = paper_linear()
            .set("solver.linear", "petsc")
            .set("solver.petsc.options", "-ksp_type gmres -pc_type hypre");
        let (code, stderr, summary) = run(scene, &[]);
        assert_eq!(code, 0, "{stderr}");
        let s = summary.unwrap();
        assert_eq!(s["petsc"]["ksp_type"], "gmres", "{s}");
        assert_eq!(s["petsc"]["pc_type"], "hypre", "{s}");
        assert_eq!(s["petsc"]["options"], "-ksp_type gmres -pc_type hypre");
    }

    #[test]
    fn petsc_options_environment_reaches_petsc() {
        let scene = paper_linear().set("solver.linear", "petsc");
        let (code, stderr, summary) = run(scene, &[("PETSC_OPTIONS", "-ksp_type bcgs")]);
        assert_eq!(code, 0, "{stderr}");
        let s = summary.unwrap();
        assert_eq!(s["petsc"]["ksp_type"], "bcgs", "{s}");
        assert_eq!(s["petsc"]["environment"], "-ksp_type bcgs", "{s}");
    }

    #[test]
    fn a_ksp_that_does_not_converge_fails_the_run_with_its_reason() {
        let scene = block_linear()
            .set("solver.linear", "petsc")
            .set("solver.petsc.options", "-ksp_max_it 1");
        let (code, stderr, _) = run(scene, &[]);
        assert_eq!(code, 1, "{stderr}");
        assert!(stderr.contains("DIVERGED_ITS after"), "{stderr}");
        assert!(stderr.contains("after 1 iterations"), "{stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    }

    #[test]
    fn an_option_petsc_refuses_is_bad_input() {
        let scene = paper_linear()
            .set("solver.linear", "petsc")
            .set("solver.petsc.options", "-pc_type no_such_pc");
        let (code, stderr, _) = run(scene, &[]);
        assert_eq!(code, 2, "{stderr}");
        assert!(stderr.contains("-pc_type no_such_pc"), "{stderr}");
        assert!(stderr.contains("PETSC_OPTIONS"), "{stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    }

    /// With PETSc the contact solver is the active-set one: a contact solver that works with
    /// the stored factor is refused with `linear = "petsc"`, and `active_set` with `linear =
    /// "cholesky"` (exit 2, naming the keys).
    #[test]
    fn solvers_that_need_the_other_backend_are_refused() {
        for (linear, contact, named) in [
            ("petsc", "dense", "solver.linear"),
            ("petsc", "clarabel", "solver.linear"),
            ("cholesky", "active_set", "solver.linear"),
        ] {
            let scene = SceneText::paper()
                .set("solver.linear", linear)
                .set("solver.contact", contact);
            let (code, stderr, _) = run(scene, &[]);
            assert_eq!(code, 2, "{linear} {contact}: {stderr}");
            assert!(stderr.contains(named), "{stderr}");
            assert!(stderr.contains("active_set"), "{stderr}");
        }
    }
}

/// `auto` with PETSc (`solver::choice`): the paper's scene on a strip of 13 000 squares
/// (13 000 rows, a dense dual of ≈ 4.1 GB, over `DENSE_LIMIT`) takes the active set and
/// PETSc's KSP, no factor, and `check` prints no line of what another build would pick; the
/// example scenes, within both limits, keep the dense dual on the stored factor (their bits:
/// the golden test), and a linear run keeps the factor.
#[cfg(feature = "petsc")]
#[test]
fn auto_takes_the_active_set_beyond_the_dense_limit() {
    use viscontact::solver::choice::{Build, Contact, Linear};
    let tmp = tempfile::tempdir().unwrap();
    let strip = common::strip_scene(tmp.path());
    let (s, _m, disc) = common::load(&strip, &[]);
    let solver = common::descriptor(&s, &disc);
    assert_eq!(solver.contact_solver(), Some(Contact::ActiveSet));
    assert_eq!(solver.linear(), Linear::Petsc);
    assert_eq!(solver.build(), &Build::Krylov { newton: true });
    let (code, text) = common::cli(&["check", strip.to_str().unwrap()]);
    assert_eq!(code, 0, "{text}");
    assert!(
        text.contains("contact    active_set (auto: the dense dual would need ≈ 4.1 GB, over")
            && text.contains("factor     none: K_A is solved by PETSc's Krylov method (auto:")
            && text.contains("; the stored Cholesky factor would need ≈ ")
            && !text.contains("petsc      "),
        "{text}"
    );
    // With solver.linear = "cholesky" auto stays on the factor: the sparse dual.
    let (s, _m, disc) = common::load(&strip, &["solver.linear=cholesky"]);
    let solver = common::descriptor(&s, &disc);
    assert_eq!(solver.contact_solver(), Some(Contact::Sparse));
    for example in [
        "examples/paper.toml",
        "examples/block.toml",
        "examples/half_block.toml",
    ] {
        let (s, _m, disc) = common::load(&common::repo().join(example), &[]);
        let solver = common::descriptor(&s, &disc);
        assert_eq!(solver.contact_solver(), Some(Contact::Dense), "{example}");
        assert!(matches!(solver.build(), Build::Factor { .. }), "{example}");
    }
    let (s, _m, disc) = common::load(
        &common::repo().join("examples/paper.toml"),
        &["contact.enabled=false", "friction.enabled=false"],
    );
    assert_eq!(common::descriptor(&s, &disc).linear(), Linear::Cholesky);
}

/// Each rank's share of K_A (`petsc::Layout::partition`, `check --ranks`), counted on the
/// nodes' graph that METIS partitioned (so that a rank that assembled its own columns
/// alone counts every rank's, and METIS left the graph as it was), is what the whole K_A's
/// pattern says: on the 3D block over 3 ranks and the paper's 2D scene over 2, each rank's
/// rows, stored entries, and distinct columns outside its rows.
#[cfg(feature = "petsc")]
#[test]
fn the_ranks_shares_of_k_a_are_those_of_its_pattern() {
    use std::collections::BTreeSet;
    let tmp = tempfile::tempdir().unwrap();
    for (scene, size) in [(SceneText::block(), 3), (SceneText::paper(), 2)] {
        let path = scene.write(tmp.path(), "s.toml");
        let (_s, _m, disc) = common::load(&path, &[]);
        let cells = disc.cell_source();
        let (layout, shares) = viscontact::petsc::Layout::partition(&disc, cells, size).unwrap();
        let rank = |i: usize| layout.blocks.partition_point(|&b| b <= layout.row(i)) - 1;
        let k = disc.k_a.as_ref();
        let (ptr, idx) = (k.symbolic().col_ptr(), k.symbolic().row_idx());
        let mut expected = vec![(0, 0, BTreeSet::<usize>::new()); size];
        for i in 0..disc.n_free {
            let (rows, entries, ghosts) = &mut expected[rank(i)];
            *rows += 1;
            *entries += ptr[i + 1] - ptr[i];
            ghosts.extend(
                idx[ptr[i]..ptr[i + 1]]
                    .iter()
                    .filter(|&&j| rank(j) != rank(i)),
            );
        }
        for (r, ((rows, entries, ghosts), share)) in expected.iter().zip(&shares).enumerate() {
            assert_eq!(share.rows, *rows, "rank {r} of {size}");
            assert_eq!(share.entries, *entries, "rank {r} of {size}");
            assert_eq!(share.ghosts, ghosts.len(), "rank {r} of {size}");
            assert!(share.ghosts > 0 && share.rows > disc.n_free / (2 * size));
        }
    }
}

/// Each follower's part of the mesh (`petsc::Layout::cell_parts`, what rank 0 sends it) is
/// the cells with one of its own nodes, in the whole's order, and rank 0's is empty: no
/// cell of Γ3's neighbourhood beyond them (the diagonal there comes from the ranks that hold
/// it). On the 3D block over 3 ranks and the paper's 2D scene over 2; with prescribed dofs,
/// whose matrices every rank holds whole, every cell.
#[cfg(feature = "petsc")]
#[test]
fn a_followers_part_of_the_mesh_is_the_cells_with_one_of_its_own_nodes() {
    let tmp = tempfile::tempdir().unwrap();
    let prescribed =
        SceneText::unclamped_square().dirichlet("Γ1", &["x", "y"], Some(&["0.01*t", "0"]));
    for (scene, size) in [
        (SceneText::block(), 3),
        (SceneText::paper(), 2),
        (prescribed, 2),
    ] {
        let path = scene.write(tmp.path(), "s.toml");
        let (_s, _m, disc) = common::load(&path, &[]);
        let (layout, _) =
            viscontact::petsc::Layout::partition(&disc, disc.cell_source(), size).unwrap();
        let parts = layout.cell_parts(&disc, disc.cell_source());
        let d = disc.dim;
        // A node's rank, that of its unknowns' rows (none where it has no unknown).
        let of_node = |v: usize| {
            let mut unknowns = (d * v..d * v + d).filter_map(|g| disc.free.get(g));
            let unknown = unknowns.find(|&i| i < disc.n_free)?;
            Some(layout.rank_of_row(layout.row(unknown)))
        };
        let whole = !disc.keeps_own_columns();
        let mut expected = vec![Vec::new(); size];
        let mut c = 0u32;
        disc.cell_source().each_vertices(|v| {
            for (r, part) in expected.iter_mut().enumerate().skip(1) {
                if whole || v.iter().any(|&p| of_node(p) == Some(r)) {
                    part.push(c);
                }
            }
            c += 1;
        });
        assert_eq!(parts.len(), size);
        assert!(
            parts[0].is_empty(),
            "{}: rank 0 holds the mesh",
            path.display()
        );
        for r in 1..size {
            assert_eq!(parts[r], expected[r], "rank {r} of {size}, whole {whole}");
            assert!(!parts[r].is_empty() && (whole || parts[r].len() < c as usize));
        }
    }
}

/// A barrier of `size` threads that fails where one does not arrive within a minute (a
/// thread that panicked, or threads that sum a different number of times), where
/// `std::sync::Barrier` would wait for ever.
#[cfg(feature = "petsc")]
struct Rendezvous {
    /// The threads arrived at this round, and the rounds completed.
    state: std::sync::Mutex<(usize, usize)>,
    all_in: std::sync::Condvar,
    size: usize,
}

#[cfg(feature = "petsc")]
impl Rendezvous {
    fn new(size: usize) -> Self {
        Rendezvous {
            state: std::sync::Mutex::new((0, 0)),
            all_in: std::sync::Condvar::new(),
            size,
        }
    }

    fn wait(&self) {
        let mut state = self.state.lock().unwrap();
        let round = state.1;
        state.0 += 1;
        if state.0 == self.size {
            *state = (0, round + 1);
            self.all_in.notify_all();
            return;
        }
        let minute = std::time::Duration::from_secs(60);
        let (_state, waited) = (self.all_in)
            .wait_timeout_while(state, minute, |s| s.1 == round)
            .unwrap();
        assert!(!waited.timed_out(), "a rank did not come to the sum");
    }
}

/// GAMG's near-null space as the ranks make it, each its own rows of the rigid-body modes
/// and its part of each inner product, summed over the ranks: together the modes that one
/// process makes, to rounding, and orthonormal over the whole. The ranks are threads here,
/// summing through a barrier in rank order as `MPI_Allgatherv` does in a run: the 3D block
/// over 3 ranks (6 modes) and the paper's 2D scene over 2 (3 modes).
#[cfg(feature = "petsc")]
#[test]
fn each_rank_makes_its_own_rows_of_the_near_null_space() {
    use std::sync::Mutex;
    use viscontact::petsc::{rigid_body_modes, Layout};
    let tmp = tempfile::tempdir().unwrap();
    for (scene, size) in [(SceneText::block(), 3), (SceneText::paper(), 2)] {
        let path = scene.write(tmp.path(), "s.toml");
        let (_s, _m, disc) = common::load(&path, &[]);
        let n = disc.n_free;
        let of = |size| {
            Layout::partition(&disc, disc.cell_source(), size)
                .unwrap()
                .0
        };
        let (one, layout) = (of(1), of(size));
        // Each rank's rows of each mode, the sums through `slots` (each rank's part in its
        // own; every rank adds them in rank order).
        let (barrier, slots) = (Rendezvous::new(size), Mutex::new(vec![0.0; size]));
        let ranks: Vec<Vec<Vec<f64>>> = std::thread::scope(|scope| {
            let (disc, layout, barrier, slots) = (&disc, &layout, &barrier, &slots);
            let threads: Vec<_> = (0..size)
                .map(|r| {
                    scope.spawn(move || {
                        let sum = |x: f64| {
                            slots.lock().unwrap()[r] = x;
                            barrier.wait();
                            let all = slots.lock().unwrap().iter().fold(0.0, |s, x| s + x);
                            barrier.wait();
                            Ok(all)
                        };
                        let mine = layout.blocks[r]..layout.blocks[r + 1];
                        rigid_body_modes(disc, layout, mine, sum).unwrap()
                    })
                })
                .collect();
            threads.into_iter().map(|t| t.join().unwrap()).collect()
        });
        // A mode in the unknowns' order, from the ranks' rows of it.
        let joined = |layout: &Layout, ranks: &[Vec<Vec<f64>>], k: usize| -> Vec<f64> {
            (0..n)
                .map(|i| {
                    let row = layout.row(i);
                    let r = layout.rank_of_row(row);
                    ranks[r][k][row - layout.blocks[r]]
                })
                .collect()
        };
        let whole = [rigid_body_modes(&disc, &one, 0..n, Ok).unwrap()];
        let modes = disc.dim * (disc.dim + 1) / 2;
        assert_eq!(whole[0].len(), modes, "{}", path.display());
        assert!(ranks.iter().all(|rank| rank.len() == modes));
        let spread: Vec<Vec<f64>> = (0..modes).map(|k| joined(&layout, &ranks, k)).collect();
        for k in 0..modes {
            let d = common::rel_diff(&spread[k], &joined(&one, &whole, k));
            assert!(d <= 1e-12, "mode {k} over {size} ranks differs by {d:e}");
            for (l, other) in spread.iter().enumerate() {
                let dot: f64 = spread[k].iter().zip(other).map(|(a, b)| a * b).sum();
                let delta = if k == l { 1.0 } else { 0.0 };
                assert!((dot - delta).abs() <= 1e-12, "modes {k} and {l}: {dot:e}");
            }
        }
    }
}

/// A build without the feature refuses `linear = "petsc"` and `contact = "active_set"`
/// (exit 2) and says how to build with it; `cholesky` and `auto` run as before.
#[cfg(not(feature = "petsc"))]
#[test]
fn petsc_without_the_feature_is_refused_with_the_build_line() {
    let dir = tempfile::tempdir().unwrap();
    let scene = SceneText::paper()
        .remove("contact")
        .remove("friction")
        .set("time.steps", 2);
    for (linear, code) in [("petsc", 2), ("cholesky", 0), ("auto", 0)] {
        let path = scene
            .clone()
            .set("solver.linear", linear)
            .write(dir.path(), "s.toml");
        let out = dir.path().join(linear);
        let (got, text) = common::cli(&[
            "run",
            "--quiet",
            "--out",
            out.to_str().unwrap(),
            path.to_str().unwrap(),
        ]);
        assert_eq!(got, code, "{linear}: {text}");
        if code == 2 {
            assert!(text.contains("s.toml"), "{text}");
            assert!(
                text.contains("cargo build --release --features petsc"),
                "{text}"
            );
            assert!(text.contains("petsc-dev"), "{text}");
            assert!(!out.exists(), "a refused run wrote {}", out.display());
        }
    }
    let path = SceneText::paper()
        .set("solver.contact", "active_set")
        .write(dir.path(), "a.toml");
    let (got, text) = common::cli(&["check", path.to_str().unwrap()]);
    assert_eq!(got, 2, "{text}");
    assert!(text.contains("solver.contact"), "{text}");
    assert!(text.contains("--features petsc"), "{text}");
}
