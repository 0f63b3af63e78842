//! Where a user asks for something that cannot happen as asked (issue 49): a thread count
//! far above the cores, a `--stop-after` step the checkpoint has passed or the run never
//! reaches, the resume of a completed run, a contact or friction group that the scene
//! leaves without its condition. Each is refused (exit 2, saying what would do) or said on
//! stderr, never silently done otherwise.

use crate::common;
use common::{SceneText, BIN};
use std::path::Path;
use std::process::Command;

/// `viscontact ARGS` with `env` set: (exit code, stdout + stderr).
fn with_env(args: &[&str], env: &[(&str, &str)]) -> (i32, String) {
    let out = Command::new(BIN)
        .args(args)
        .envs(env.iter().copied())
        .current_dir(common::repo())
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.code().unwrap_or(-1), text)
}

fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// `--threads 20000` wrote nothing for 60 s and VISCONTACT_THREADS=1000000000 spawned
/// threads for 11 minutes before aborting; `" 2"` was taken for 2. Now: refused at once,
/// naming the cores; a few more than the cores run, with a warning.
#[test]
fn thread_counts_far_above_the_cores_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("o");
    let run = |threads: &[&str], env: &[(&str, &str)]| {
        let mut args = vec!["run", "examples/paper.toml", "--quiet", "--out"];
        args.push(out.to_str().unwrap());
        args.extend(["--set", "time.steps=4"]);
        args.extend(threads);
        let start = std::time::Instant::now();
        let r = with_env(&args, env);
        (r, start.elapsed())
    };
    let cores = cores();
    let too_many = (4 * cores + 1).to_string();
    let cores_text = format!("{cores} core");
    for (threads, env) in [
        (vec!["--threads", "20000"], vec![]),
        (vec!["--threads", too_many.as_str()], vec![]),
        (vec![], vec![("VISCONTACT_THREADS", "1000000000")]),
    ] {
        let ((code, text), took) = run(&threads, &env);
        assert_eq!(code, 2, "{threads:?} {env:?}: {text}");
        assert!(text.contains(&cores_text), "{text}");
        assert!(took.as_secs() < 5, "{threads:?}: refused after {took:?}");
        assert!(!out.exists(), "a refused run wrote {}", out.display());
    }
    let ((code, text), _) = run(&[], &[("VISCONTACT_THREADS", " 2")]);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("VISCONTACT_THREADS"), "{text}");
    let more = (cores + 1).to_string();
    let ((code, text), _) = run(&["--threads", &more], &[]);
    assert_eq!(code, 0, "{text}");
    assert!(
        text.contains("warning") && text.contains(&cores_text),
        "{text}"
    );
}

/// `mpirun -n 2 viscontact run` ran the whole scene twice into one directory, each exiting
/// 0 (or one refused by the other's lock, where they overlapped). Now every process that
/// an MPI launcher started as one of several is refused before it writes anything, naming
/// the variable; a launcher's single process, and a value that is no count, run.
#[test]
fn a_process_that_mpi_started_as_one_of_several_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("o");
    let run = |command: &str, env: &[(&str, &str)]| {
        let mut args = match command {
            "run" => vec!["run", "examples/paper.toml", "--set", "time.steps=4"],
            _ => vec!["resume", out.to_str().unwrap()],
        };
        args.extend(["--quiet", "--out", out.to_str().unwrap()]);
        with_env(&args, env)
    };
    for (command, var, value) in [
        ("run", "OMPI_COMM_WORLD_SIZE", "2"),
        ("run", "PMI_SIZE", "16"),
        ("resume", "OMPI_COMM_WORLD_SIZE", "3"),
    ] {
        let (code, text) = run(command, &[(var, value)]);
        assert_eq!(code, 2, "{command} {var}={value}: {text}");
        assert!(text.contains(&format!("{var}={value}")), "{text}");
        assert!(
            text.contains("one of") && text.contains("--threads"),
            "{text}"
        );
        assert!(!out.exists(), "a refused process wrote {}", out.display());
    }
    for env in [[("OMPI_COMM_WORLD_SIZE", "1")], [("PMI_SIZE", "two")]] {
        let (code, text) = run("run", &env);
        assert_eq!(code, 0, "{env:?}: {text}");
    }
    let (code, text) = with_env(&["check", "examples/paper.toml"], &[("PMI_SIZE", "2")]);
    assert_eq!(code, 0, "check only prints, on any launcher: {text}");
}

/// `check --ranks N` plans a run over N MPI ranks: one rank is every run; more are refused
/// (exit 2) in a build without PETSc, saying how to get one, and for a run whose steps do
/// not spread (docs/cluster.md); 0 is no count.
#[test]
fn check_plans_one_rank_and_refuses_more_where_the_run_cannot_spread() {
    let (code, text) = common::cli(&["check", "examples/paper.toml", "--ranks", "1"]);
    assert_eq!(code, 0, "{text}");
    let (code, text) = common::cli(&["check", "examples/paper.toml", "--ranks", "2"]);
    assert_eq!(code, 2, "{text}");
    let why = match cfg!(feature = "petsc") {
        true => "this run's steps take the contact solver dense",
        false => "this build has no MPI",
    };
    assert!(text.contains("--ranks 2") && text.contains(why), "{text}");
    let (code, text) = common::cli(&["check", "examples/paper.toml", "--ranks", "0"]);
    assert_eq!(code, 2, "{text}");
}

/// A run of the paper scene on the coarse mesh with N = 16, stopped after step 8: its
/// directory and its checkpoint (at step 9).
fn stopped_run(dir: &Path) -> (std::path::PathBuf, String) {
    let scene = SceneText::paper()
        .mesh(common::mesh_path("paper/rect_008.msh"))
        .set("time.steps", 16)
        .write(dir, "s.toml");
    let out = dir.join("out");
    let (code, text) = common::cli(&[
        "run",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--quiet",
        "--stop-after",
        "8",
    ]);
    assert_eq!(code, 0, "{text}");
    let cp = out.join("checkpoint.h5").display().to_string();
    (out, cp)
}

/// `resume --stop-after S` with S before the checkpoint's step ran the run to its end with
/// exit 0; now refused. A step at or past the last one is said, and the run completes.
#[test]
fn stop_after_steps_that_cannot_stop_the_run_are_said() {
    let tmp = tempfile::tempdir().unwrap();
    let (out, cp) = stopped_run(tmp.path());
    let before = common::dir_contents(&out);
    for s in ["0", "5", "8"] {
        let (code, text) = common::cli(&["resume", &cp, "--quiet", "--stop-after", s]);
        assert_eq!(code, 2, "--stop-after {s}: {text}");
        assert!(
            text.contains(&format!("--stop-after {s}")) && text.contains("step 9"),
            "{text}"
        );
        assert_eq!(
            common::dir_contents(&out),
            before,
            "--stop-after {s} changed the directory"
        );
    }
    let (code, text) = common::cli(&["resume", &cp, "--quiet", "--stop-after", "100"]);
    assert_eq!(code, 0, "{text}");
    assert!(
        text.contains("warning: --stop-after 100") && text.contains("last step is 16"),
        "{text}"
    );
    assert_eq!(common::summary(&out)["status"], "completed");
}

/// Resuming a completed run solved its last step again and said "completed"; now refused,
/// naming `time.end` as the way to continue it; with a later end it continues.
#[test]
fn a_completed_run_is_not_resumed_unless_its_end_moves() {
    let tmp = tempfile::tempdir().unwrap();
    let (out, cp) = stopped_run(tmp.path());
    let (code, text) = common::cli(&["resume", &cp, "--quiet"]);
    assert_eq!(code, 0, "{text}");
    let before = common::dir_contents(&out);
    let (code, text) = common::cli(&["resume", &cp, "--quiet"]);
    assert_eq!(code, 2, "{text}");
    assert!(
        text.contains("complete") && text.contains("time.end"),
        "{text}"
    );
    assert_eq!(common::dir_contents(&out), before);
    let (code, text) = common::cli(&["resume", &cp, "--quiet", "--set", "time.end=1.5"]);
    assert_eq!(code, 0, "{text}");
    assert_eq!(common::summary(&out)["steps"], 24);
}

/// A mesh with Γ3,1 and Γ3,2 under a scene without [contact] and [friction] ran without a
/// word while the body passed through the foundation; `check` and the run's start now say
/// which group carries nothing.
#[test]
fn a_contact_group_without_its_condition_is_said() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = SceneText::paper()
        .mesh(common::mesh_path("paper/rect_008.msh"))
        .remove("contact")
        .remove("friction")
        .write(tmp.path(), "s.toml");
    let scene = scene.to_str().unwrap();
    let said = |text: &str| {
        for what in ["contact", "friction"] {
            assert!(
                text.contains(&format!("the mesh has the {what} group"))
                    && text.contains(&format!("[{what}]")),
                "{what}: {text}"
            );
        }
    };
    let (code, text) = common::cli(&["check", scene]);
    assert_eq!(code, 0, "{text}");
    said(&text);
    let out = tmp.path().join("out");
    let (code, text) = common::cli(&[
        "run",
        scene,
        "--quiet",
        "--out",
        out.to_str().unwrap(),
        "--set",
        "time.steps=2",
    ]);
    assert_eq!(code, 0, "{text}");
    said(&text);
    // The paper scene itself, with both conditions, says neither.
    let (_, text) = common::cli(&["check", "examples/paper.toml"]);
    assert!(!text.contains("the mesh has the"), "{text}");
}
