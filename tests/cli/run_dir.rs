//! A run directory describes exactly one run (issue 12, item 1): a failed rerun either leaves
//! the old run untouched (setup failed) or replaces it with its own frames and a summary that
//! says "failed"; one process owns a directory at a time; leftovers of a killed process are
//! recognised and removed; resume does not mix another run's frames into its series; files
//! viscontact did not write are never touched.

use crate::common;

use std::path::Path;

/// The .vtu files of a directory, sorted.
fn vtus(dir: &Path) -> Vec<String> {
    common::dir_contents(dir)
        .into_keys()
        .filter(|n| n.ends_with(".vtu"))
        .collect()
}

/// A temporary directory with the paper scene on `meshes/paper/MESH.msh` in it.
fn paper(mesh: &str) -> (tempfile::TempDir, std::path::PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let scene = common::paper_scene(tmp.path(), "s.toml", &format!("paper/{mesh}.msh"), false);
    (tmp, scene)
}

fn run_ok(args: &[&str]) {
    let out = common::viscontact(args);
    assert!(
        out.status.success(),
        "viscontact {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn a_rerun_that_fails_in_setup_leaves_the_old_run_untouched() {
    let (tmp, scene) = paper("rect_008");
    let (scene, dir) = (scene.to_str().unwrap(), tmp.path().join("o"));
    let dir_s = dir.to_str().unwrap();
    run_ok(&["run", scene, "--out", dir_s, "--quiet"]);
    let before = common::dir_contents(&dir);
    let out = common::viscontact(&[
        "run",
        scene,
        "--out",
        dir_s,
        "--quiet",
        "--set",
        "mesh.file=missing.msh",
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(common::dir_contents(&dir) == before, "the old run changed");
}

/// A load that turns infinite at t = 0.53: the rerun fails at step 17 of 32 (exit 1), and
/// the directory holds the failed run alone: its frames 0..=16, no frame or checkpoint of
/// the old run, a summary that says "failed", at which step, and why.
#[test]
fn a_rerun_that_fails_later_replaces_the_old_run() {
    let (tmp, scene) = paper("rect_008");
    let bad = common::paper("paper/rect_008.msh", false)
        .set(
            "load.traction[0].value",
            common::scene::strings(&["0", "if(t > 0.53, 1/(t-t), -0.1*x*(2-x)*min(t, 0.2))"]),
        )
        .write(tmp.path(), "bad.toml");
    let dir = tmp.path().join("o");
    let dir_s = dir.to_str().unwrap();
    run_ok(&["run", scene.to_str().unwrap(), "--out", dir_s, "--quiet"]);
    assert_eq!(vtus(&dir).len(), 33);
    let out = common::viscontact(&["run", bad.to_str().unwrap(), "--out", dir_s, "--quiet"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    let expected: Vec<String> = (0..=16).map(|n| format!("solution_{n:06}.vtu")).collect();
    assert_eq!(vtus(&dir), expected);
    let pvd = std::fs::read_to_string(dir.join("solution.pvd")).unwrap();
    assert_eq!(pvd.matches("<DataSet").count(), 17, "{pvd}");
    assert!(
        !dir.join("checkpoint.h5").exists(),
        "the old run's checkpoint"
    );
    let s = common::summary(&dir);
    assert_eq!(s["status"], "failed");
    assert_eq!(s["last_step"], 16);
    let message = s["message"].as_str().unwrap();
    assert!(
        message.contains("load.traction[0].value") && stderr.contains(message),
        "{message} / {stderr}"
    );
    assert_eq!(s["iterations"]["per_step"].as_array().unwrap().len(), 17);
    assert!(!dir.join(viscontact::run::LOCK_NAME).exists());
}

/// A second run or resume into a directory in use is refused (exit 2) naming the process
/// that owns it; the owner finishes undisturbed.
#[test]
fn a_directory_in_use_is_refused_naming_its_owner() {
    let (tmp, scene) = paper("rect_016");
    let (scene, dir) = (scene.to_str().unwrap(), tmp.path().join("o"));
    let dir_s = dir.to_str().unwrap();
    let set = [
        "--set",
        "time.steps=100000",
        "--set",
        "output.every=1000",
        "--set",
        "checkpoint.every=1",
        "--quiet",
    ];
    let mut args = vec!["run", scene, "--out", dir_s];
    args.extend(set);
    let mut owner = std::process::Command::new(common::BIN)
        .args(&args)
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let start = std::time::Instant::now();
    while !dir.join("checkpoint.h5").exists() {
        assert!(start.elapsed().as_secs() < 60, "no checkpoint appeared");
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    let cp = dir.join("checkpoint.h5");
    for second in [
        args.clone(),
        vec!["resume", cp.to_str().unwrap(), "--quiet"],
    ] {
        let out = common::viscontact(&second);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{second:?}: {stderr}");
        assert!(
            stderr.contains("in use by another viscontact process")
                && stderr.contains(&format!("pid {}", owner.id()))
                && stderr.contains("command viscontact run"),
            "{stderr}"
        );
    }
    // Deleting the lock file does not let a run of other physics in (issue 26, finding 4):
    // the directory itself is locked too.
    std::fs::remove_file(dir.join(viscontact::run::LOCK_NAME)).unwrap();
    let mut other = args.clone();
    other.extend(["--set", "friction.coefficient=1"]);
    let out = common::viscontact(&other);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("was deleted"), "{stderr}");
    // The owner was still running (a run of 10^5 steps); stop it and look at what it wrote.
    let term = std::process::Command::new("kill")
        .args(["-s", "TERM", &owner.id().to_string()])
        .status()
        .unwrap();
    assert!(term.success());
    assert_eq!(owner.wait().unwrap().code(), Some(143));
    let s = common::summary(&dir);
    assert_eq!(s["status"], "interrupted");
    let last = s["last_step"].as_u64().unwrap() as usize;
    let expected: Vec<String> = (0..=last / 1000)
        .map(|i| format!("solution_{:06}.vtu", 1000 * i))
        .collect();
    assert_eq!(vtus(&dir), expected, "frames of one run, up to step {last}");
    assert!(!dir.join(viscontact::run::LOCK_NAME).exists());
}

/// Temporary files a killed process left are ours: the next run removes them instead of
/// refusing the directory; a user's file stays as it was (with --force).
#[test]
fn leftover_temporaries_are_removed_and_user_files_kept() {
    let (tmp, scene) = paper("rect_008");
    let (scene, dir) = (scene.to_str().unwrap(), tmp.path().join("o"));
    let dir_s = dir.to_str().unwrap();
    std::fs::create_dir(&dir).unwrap();
    let leftovers = [
        ".solution_000012.vtu.tmp.4242.3",
        ".solution.pvd.tmp.4242.4",
        ".summary.json.tmp.4242.5",
        "checkpoint.h5.tmp",
        "checkpoint_history.h5.tmp",
    ];
    for name in leftovers {
        common::write(&dir, name, "half written");
    }
    run_ok(&["run", scene, "--out", dir_s, "--quiet"]);
    for name in leftovers {
        assert!(!dir.join(name).exists(), "{name} left behind");
    }
    common::write(&dir, "notes.txt", "mine");
    common::write(&dir, ".solution_000001.vtu.tmp.77.0", "half written");
    let out = common::viscontact(&["run", scene, "--out", dir_s, "--quiet"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("notes.txt"));
    run_ok(&["run", scene, "--out", dir_s, "--quiet", "--force"]);
    assert_eq!(
        std::fs::read_to_string(dir.join("notes.txt")).unwrap(),
        "mine"
    );
    assert!(!dir.join(".solution_000001.vtu.tmp.77.0").exists());
}

/// `resume A/checkpoint.h5 --out B` refuses a B that holds another run, or files that are
/// not viscontact's, and leaves B as it was; into an empty directory it continues the run.
#[test]
fn resume_does_not_mix_runs() {
    let (tmp, scene) = paper("rect_008");
    let scene = scene.to_str().unwrap();
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    let a_s = a.to_str().unwrap();
    run_ok(&["run", scene, "--out", a_s, "--quiet", "--stop-after", "7"]);
    run_ok(&["run", scene, "--out", b.to_str().unwrap(), "--quiet"]);
    let cp = a.join("checkpoint.h5");
    let cp_s = cp.to_str().unwrap();
    let before = common::dir_contents(&b);
    let out = common::viscontact(&["resume", cp_s, "--out", b.to_str().unwrap(), "--quiet"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("holds another run"), "{stderr}");
    assert!(common::dir_contents(&b) == before, "the other run changed");

    // A copy of b's checkpoint resumed beside a's run.
    let copy = a.join("copy.h5");
    std::fs::copy(b.join("checkpoint.h5"), &copy).unwrap();
    let a_before = common::dir_contents(&a);
    let out = common::viscontact(&["resume", copy.to_str().unwrap(), "--force", "--quiet"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("holds another run"), "{stderr}");
    assert!(common::dir_contents(&a) == a_before, "a's run changed");
    std::fs::remove_file(&copy).unwrap();

    // Frames with nothing that names their run.
    std::fs::remove_file(b.join("summary.json")).unwrap();
    std::fs::remove_file(b.join("checkpoint.h5")).unwrap();
    let out = common::viscontact(&["resume", cp_s, "--out", b.to_str().unwrap(), "--quiet"]);
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("'solution.pvd' and no summary.json"),
        "{stderr}"
    );

    let c = tmp.path().join("c");
    std::fs::create_dir(&c).unwrap();
    common::write(&c, "notes.txt", "mine");
    let out = common::viscontact(&["resume", cp_s, "--out", c.to_str().unwrap(), "--quiet"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("notes.txt"));

    let d = tmp.path().join("d");
    run_ok(&["resume", cp_s, "--out", d.to_str().unwrap(), "--quiet"]);
    let s = common::summary(&d);
    assert_eq!(s["status"], "completed");
    assert_eq!(s["run_id"], common::summary(&a)["run_id"]);
    assert_eq!(
        vtus(&d).first().map(String::as_str),
        Some("solution_000008.vtu")
    );
    // And the run's own directory still resumes.
    run_ok(&["resume", cp_s, "--quiet"]);
    assert_eq!(common::summary(&a)["status"], "completed");
    let full = tmp.path().join("full");
    run_ok(&["run", scene, "--out", full.to_str().unwrap(), "--quiet"]);
    common::assert_same_series(&a, &full, "resumed in its own directory");
}
