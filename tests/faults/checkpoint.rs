//! Checkpoint and restart (issue 4): restarts are bit for bit (stopped, extended, killed with
//! SIGKILL), runs are deterministic, h5py reads the documented layout, resume refuses broken
//! and mismatched checkpoints (exit status 2, a message saying what differs, the file left
//! alone), and the displacement sum does not drift over 10^5 steps.

use crate::common;

use common::{
    assert_same_series, finished, frames, paper_scene, resume_quiet, run_options as opts,
    viscontact,
};
use hdf5_metno as hdf5;
use std::path::{Path, PathBuf};
use std::process::Command;
use viscontact::run::{resume, run, Outcome, ResumeOptions, Summary};

/// Stop at N/2 and resume = the run that never stopped, for a Prony and a general kernel,
/// with contact and friction active.
#[test]
fn stopped_and_resumed_equals_uninterrupted() {
    let tmp = tempfile::tempdir().unwrap();
    for expr in [false, true] {
        let what = if expr {
            "general kernel"
        } else {
            "Prony kernel"
        };
        let scene = common::paper_scene(
            tmp.path(),
            &format!("s{expr}.toml"),
            "paper/rect_008.msh",
            expr,
        );
        let set = ["time.steps=16", "checkpoint.every=3"];
        let full = tmp.path().join(format!("full{expr}"));
        let part = tmp.path().join(format!("part{expr}"));
        let s = finished(run(&scene, &opts(&full, &set, None)).unwrap());
        assert!(s.effects.iter().any(|e| e == "contact"), "{:?}", s.effects);
        assert!(s.effects.iter().any(|e| e == "friction"), "{:?}", s.effects);
        assert!(
            s.iterations.total > 0,
            "the contact solver must do some work"
        );
        assert!(s.contact.active_at_end > 0 || s.contact.stick_at_end > 0);
        match run(&scene, &opts(&part, &set, Some(7))).unwrap() {
            Outcome::Stopped {
                step,
                time,
                checkpoint,
                signal,
                ..
            } => {
                assert_eq!((step, time, signal), (7, 7.0 / 16.0, None));
                assert_eq!(checkpoint, Some(part.join("checkpoint.h5")));
            }
            other => panic!("--stop-after 7 did not stop: {other:?}"),
        }
        let stopped = common::summary(&part);
        assert_eq!(stopped["status"], "interrupted");
        assert_eq!(stopped["last_step"], 7);
        assert!(part.join("solution_000007.vtu").exists());
        assert!(!part.join("solution_000008.vtu").exists());
        assert_eq!(part.join("checkpoint_history.h5").exists(), expr);
        // history.csv: the rows of steps 0..=7; a run killed after its checkpoint would
        // have written more, half a row last: the resume cuts them off.
        let history = std::fs::read_to_string(part.join("history.csv")).unwrap();
        let full_history = std::fs::read_to_string(full.join("history.csv")).unwrap();
        assert_eq!(history.lines().count(), 1 + 8);
        assert!(
            full_history.starts_with(&history),
            "{what}: rows 0..=7 differ"
        );
        let beyond: String = full_history
            .lines()
            .skip(9)
            .take(2)
            .collect::<Vec<_>>()
            .join("\n");
        let mut longer = history + &beyond + "\n9,0.5625,0.00";
        longer.push_str(&"9".repeat(3));
        std::fs::write(part.join("history.csv"), longer).unwrap();
        let r = finished(resume_quiet(&part.join("checkpoint.h5")));
        assert_eq!(r.steps, 16);
        let resumed = std::fs::read(part.join("history.csv")).unwrap();
        assert!(
            resumed == full_history.as_bytes(),
            "{what}: the resumed history.csv differs from the uninterrupted run's"
        );
        common::assert_same_series(&full, &part, what);
    }
}

/// The same in 3D: the block (tetrahedra, contact and disc friction, Prony memory) stopped
/// at step 13 of 32 and resumed equals the run that never stopped, bit for bit.
#[test]
fn stopped_and_resumed_equals_uninterrupted_in_3d() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = common::repo().join("examples/block.toml");
    let mesh = format!("mesh.file={}", common::mesh_path("3d/block_004.msh"));
    let set = [mesh.as_str(), "checkpoint.every=5"];
    let s = resumed_equals_uninterrupted(tmp.path(), &scene, &set, 13, "3D block");
    assert!(s.iterations.total > 0 && s.contact.friction_nodes > 0);
}

/// Runs `scene` with `set` whole into `dir/full`, and stopped after step `stop` and resumed
/// into `dir/part`: the two series are the same bit for bit. Returns the whole run's
/// summary.
fn resumed_equals_uninterrupted(
    dir: &Path,
    scene: &Path,
    set: &[&str],
    stop: usize,
    what: &str,
) -> Summary {
    let (full, part) = (dir.join("full"), dir.join("part"));
    let s = finished(run(scene, &opts(&full, set, None)).unwrap());
    assert!(matches!(
        run(scene, &opts(&part, set, Some(stop))).unwrap(),
        Outcome::Stopped { step, .. } if step == stop
    ));
    let resume_opts = ResumeOptions {
        progress: false,
        ..Default::default()
    };
    finished(resume(&part.join("checkpoint.h5"), &resume_opts).unwrap());
    common::assert_same_series(&full, &part, what);
    s
}

/// The half block turned by 30° (tests/data/symmetry/half_block_turned.msh), its inclined
/// symmetry plane held in frames of the plane's nodes: the state is kept in those frames'
/// components, and the resumed run equals the uninterrupted one bit for bit.
#[test]
fn stopped_and_resumed_equals_uninterrupted_with_an_inclined_plane() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = common::SceneText::block()
        .mesh(common::repo().join("tests/data/symmetry/half_block_turned.msh"))
        .set("time.steps", 12)
        .dirichlet("sym", &["normal"], None)
        .write(tmp.path(), "turned.toml");
    resumed_equals_uninterrupted(tmp.path(), &scene, &[], 5, "turned half block");
}

/// A step given up (a second signal while a dual method solves it: `solver::abandon`)
/// leaves the run where a stop after the step before leaves it: summary.json "interrupted"
/// with that step as the last, no frame of the step given up, the checkpoint of the state
/// before it written then (the scene writes no other before the end), and the resumed run
/// equals the one never stopped, bit for bit; with the dense and the sparse dual. The
/// request is made before the run, so the first step the run can stop before that needs
/// an iteration is given up: the same step on any machine.
#[test]
fn a_step_given_up_resumes_as_the_run_never_stopped() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = common::repo().join("examples/block.toml");
    let mesh = format!("mesh.file={}", common::mesh_path("3d/block_004.msh"));
    for contact in ["dense", "sparse"] {
        let solver = format!("solver.contact={contact}");
        let set = [mesh.as_str(), solver.as_str(), "time.steps=8"];
        let full = tmp.path().join(format!("full_{contact}"));
        let part = tmp.path().join(format!("part_{contact}"));
        let s = finished(run(&scene, &opts(&full, &set, None)).unwrap());
        let given_up = (1..=8)
            .find(|&n| s.iterations.per_step[n] > 0)
            .expect("a step after the first with dual iterations");
        let o = opts(&part, &set, None);
        let abandon = o.interrupt.abandon();
        let armed = abandon.arm();
        assert!(abandon.request(), "granted while armed");
        drop(armed);
        match run(&scene, &o).unwrap() {
            Outcome::Stopped {
                step,
                checkpoint,
                signal,
                ..
            } => {
                assert_eq!((step, signal), (given_up - 1, None), "{contact}");
                assert_eq!(checkpoint, Some(part.join("checkpoint.h5")), "{contact}");
            }
            other => panic!("{contact}: step {given_up} was not given up: {other:?}"),
        }
        let stopped = common::summary(&part);
        assert_eq!(stopped["status"], "interrupted", "{contact}");
        assert_eq!(stopped["last_step"], given_up - 1, "{contact}");
        assert!(!part.join(format!("solution_{given_up:06}.vtu")).exists());
        // A resumed run's first step is not given up either (resumed into another directory
        // it would leave no checkpoint there): with the request made before it, that step
        // is solved.
        let o = ResumeOptions {
            progress: false,
            ..Default::default()
        };
        let armed = o.interrupt.abandon().arm();
        assert!(o.interrupt.abandon().request());
        drop(armed);
        let cp = part.join("checkpoint.h5");
        if let Outcome::Stopped { step, .. } = resume(&cp, &o).unwrap() {
            assert!(
                step >= given_up,
                "{contact}: the resume gave up its first step"
            );
            finished(resume_quiet(&cp));
        }
        common::assert_same_series(&full, &part, contact);
    }
}

/// The time loop's side of a step given up, at every step s of the 3D block from the
/// second on, dense and sparse: the loop stands where a stop after step s − 1 leaves it (the
/// same n, u, w and both multiplier vectors, bit for bit, though the iteration had moved z
/// to its warm start), and the steps from there on, with the request withdrawn, end at the
/// uninterrupted run's u_N.
#[test]
fn a_step_given_up_leaves_the_loop_as_a_stop_before_it() {
    use viscontact::solver::Abandon;
    use viscontact::time_loop::{Observer, RunEnd, Solved, TimeLoop};
    /// Stops after step `stop`, or requests that the step after `request` be given up.
    struct At {
        stop: Option<usize>,
        request: Option<(usize, Abandon)>,
    }
    impl Observer for At {
        fn stop_after(&mut self, n: usize) -> bool {
            self.stop == Some(n)
        }
        fn solved(&mut self, s: &Solved) -> viscontact::Result<()> {
            if let Some((_, a)) = self.request.as_ref().filter(|(r, _)| *r == s.step.n) {
                let armed = a.arm();
                assert!(a.request());
                drop(armed);
            }
            Ok(())
        }
    }
    let scene = common::repo().join("examples/block.toml");
    let mesh = format!("mesh.file={}", common::mesh_path("3d/block_004.msh"));
    let steps = 8;
    for contact in ["dense", "sparse"] {
        let solver = format!("solver.contact={contact}");
        let (scene, _mesh, disc) = common::load(&scene, &[&mesh, &solver, "time.steps=8"]);
        let full = common::trace(&scene, &disc);
        let mut given_up = 0;
        for s in 2..=steps {
            let mut stopped = TimeLoop::new(&scene, &disc).unwrap();
            let mut at = At {
                stop: Some(s - 1),
                request: None,
            };
            assert_eq!(stopped.run(steps, &mut at).unwrap(), RunEnd::Stopped);
            let mut abandoned = TimeLoop::new(&scene, &disc).unwrap();
            let abandon = Abandon::default();
            abandoned.abandon_on(&abandon);
            let mut at = At {
                stop: None,
                request: Some((s - 1, abandon)),
            };
            if abandoned.run(steps, &mut at).unwrap() == RunEnd::Completed {
                continue; // every step from s on was solved at its warm start
            }
            given_up += 1;
            let (a, b) = (stopped.state().unwrap(), abandoned.state().unwrap());
            let (a, b) = (a.expect("one process"), b.expect("one process"));
            assert_eq!(stopped.n(), s, "{contact}");
            assert_eq!(abandoned.n(), s, "{contact}: given up at another step");
            assert!(
                stopped.u() == abandoned.u() && a.w == b.w,
                "{contact}, step {s}"
            );
            assert!(
                a.z == b.z && a.z_before == b.z_before,
                "{contact}, step {s}"
            );
            abandoned.abandon_on(&Abandon::default());
            let mut never = |_: &Solved| Ok(());
            abandoned.run(steps, &mut never).unwrap();
            assert!(
                abandoned.u() == full.u_final.as_slice(),
                "{contact}, step {s}"
            );
        }
        assert!(
            given_up >= steps - 2,
            "{contact}: {given_up} steps given up"
        );
    }
}

/// A run to T/2 resumed with --set time.end=T keeps k and equals the run to T; and a finished
/// run can be extended again, its history file growing by a copy, once.
#[test]
fn extending_past_the_end_equals_the_longer_run() {
    let tmp = tempfile::tempdir().unwrap();
    for expr in [false, true] {
        let what = if expr {
            "general kernel"
        } else {
            "Prony kernel"
        };
        let scene = common::paper_scene(
            tmp.path(),
            &format!("s{expr}.toml"),
            "paper/rect_008.msh",
            expr,
        );
        let long = tmp.path().join(format!("long{expr}"));
        let short = tmp.path().join(format!("short{expr}"));
        finished(
            run(
                &scene,
                &opts(&long, &["time.end=1.5", "time.steps=24"], None),
            )
            .unwrap(),
        );
        let s = finished(
            run(
                &scene,
                &opts(
                    &short,
                    &["time.end=0.5", "time.steps=8", "output.every=1"],
                    None,
                ),
            )
            .unwrap(),
        );
        assert_eq!(s.steps, 8);
        let cp = short.join("checkpoint.h5");
        for end in ["1.0", "1.5"] {
            let r = finished(
                resume(
                    &cp,
                    &ResumeOptions {
                        overrides: vec![format!("time.end={end}")],
                        ..Default::default()
                    },
                )
                .unwrap(),
            );
            assert_eq!(r.step_size, 1.0 / 16.0);
        }
        common::assert_same_series(&long, &short, what);
    }
}

/// The same scene run twice writes identical bytes (series and summary values).
#[test]
fn runs_are_deterministic() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = common::paper_scene(tmp.path(), "s.toml", "paper/rect_016.msh", false);
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    for d in [&a, &b] {
        finished(run(&scene, &opts(d, &["time.steps=16"], None)).unwrap());
    }
    common::assert_same_series(&a, &b, "two runs of one scene");
}

/// Stops a run with `signals` (KILL, INT, TERM; one, or two back to back) somewhere after
/// the frame of step 200..790 of 1000 appeared (the step varies from run to run), resumes
/// it, and compares with the run that was not stopped: every .vtu, the .pvd and
/// summary.json's values. The exit status must be one of `exits` (None: killed). SIGKILL
/// needs a checkpoint at every step to lose nothing; SIGINT/SIGTERM write their own and exit
/// 130/143 with summary.json saying "interrupted".
fn stopped_by_signal_and_resumed(signals: &[&str], exits: &[Option<i32>], set: &[&str]) {
    let signal = signals[0];
    let tmp = tempfile::tempdir().unwrap();
    let seed = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .subsec_nanos() as usize;
    for (i, expr) in [false, true].into_iter().enumerate() {
        let what = format!(
            "SIG{signal}, {}",
            if expr {
                "general kernel"
            } else {
                "Prony kernel"
            }
        );
        let scene = common::paper_scene(
            tmp.path(),
            &format!("s{expr}.toml"),
            "paper/rect_016.msh",
            expr,
        );
        let scene = scene.to_str().unwrap();
        let mut args = vec!["--set", "time.steps=1000", "--set", "output.every=10"];
        for s in set {
            args.extend(["--set", s]);
        }
        args.push("--quiet");
        let full = tmp.path().join(format!("full{expr}"));
        let stopped = tmp.path().join(format!("stopped{expr}"));
        let mut run = vec!["run", scene, "--out", full.to_str().unwrap()];
        run.extend(&args);
        let out = common::viscontact(&run);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );

        let at = 10 * (20 + (seed / (i + 1)) % 60);
        let mut run = vec!["run", scene, "--out", stopped.to_str().unwrap()];
        run.extend(&args);
        let (status, stderr) = common::signal_at_frame(&run, &stopped, at, signals);
        assert!(
            exits.contains(&status.code()),
            "{what}: {status:?}, {stderr}"
        );
        let summary = stopped.join("summary.json");
        match status.code() {
            // A second signal may also come after the first one's stop wrote summary.json.
            None if signals.len() > 1 => {}
            None => assert!(
                !summary.exists(),
                "{what}: the run finished before it was killed; make it longer"
            ),
            Some(_) => {
                let s = common::summary(&stopped);
                assert_eq!(s["status"], "interrupted", "{what}");
                let last = s["last_step"].as_u64().unwrap() as usize;
                assert!(
                    last >= at && last < 1000,
                    "{what}: stopped after step {last}"
                );
                assert!(
                    stderr.contains(&format!("interrupted by SIG{signal} after step {last}"))
                        && stderr.contains("viscontact resume"),
                    "{what}: {stderr}"
                );
                // The last line; a second signal's note may come before it.
                assert_eq!(
                    s["message"].as_str(),
                    stderr.trim().lines().last(),
                    "{what}"
                );
            }
        }
        let cp = stopped.join("checkpoint.h5");
        let out = common::viscontact(&["resume", cp.to_str().unwrap(), "--quiet"]);
        assert!(
            out.status.success(),
            "{what}: resume after the signal at frame {at} failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        common::assert_same_series(&full, &stopped, &what);
        assert_eq!(common::summary(&stopped)["status"], "completed");
        assert!(!cp.with_file_name("checkpoint.h5.tmp").exists());
    }
}

#[test]
fn killed_with_sigkill_and_resumed_equals_uninterrupted() {
    stopped_by_signal_and_resumed(&["KILL"], &[None], &["checkpoint.every=1"]);
}

/// Without `every`, the checkpoints by wall time (here every millisecond) are what a resume
/// after SIGKILL continues from.
#[test]
fn killed_after_wall_clock_checkpoints_and_resumed_equals_uninterrupted() {
    stopped_by_signal_and_resumed(&["KILL"], &[None], &["checkpoint.every_seconds=0.001"]);
}

#[test]
fn interrupted_with_sigint_and_resumed_equals_uninterrupted() {
    stopped_by_signal_and_resumed(&["INT"], &[Some(130)], &[]);
}

#[test]
fn terminated_with_sigterm_and_resumed_equals_uninterrupted() {
    stopped_by_signal_and_resumed(&["TERM"], &[Some(143)], &[]);
}

/// SIGINT then SIGTERM at once: the second gives up the step being solved where a dual
/// method is solving one (`solver::abandon`: exit 130, summary.json "interrupted" after the
/// step before it); anywhere else (setup is long past: between steps, writing a frame) it
/// is noted and the run stops after its step as the first asked, never killed; either
/// resumes to the run that was never stopped.
#[test]
fn interrupted_twice_and_resumed_equals_uninterrupted() {
    stopped_by_signal_and_resumed(&["INT", "TERM"], &[Some(130)], &[]);
}

/// With a general kernel the history file is appended to in place (never rewritten or
/// replaced) when a run is resumed in its own directory within its length.
#[test]
fn history_file_is_appended_in_place() {
    use std::os::unix::fs::MetadataExt;
    let tmp = tempfile::tempdir().unwrap();
    let scene = common::paper_scene(tmp.path(), "s.toml", "paper/rect_008.msh", true);
    let out = tmp.path().join("o");
    run(
        &scene,
        &opts(&out, &["time.steps=16", "checkpoint.every=2"], Some(5)),
    )
    .unwrap();
    let hist = out.join("checkpoint_history.h5");
    let before = std::fs::metadata(&hist).unwrap();
    finished(resume(&out.join("checkpoint.h5"), &ResumeOptions::default()).unwrap());
    let after = std::fs::metadata(&hist).unwrap();
    assert_eq!(before.ino(), after.ino(), "the history file was replaced");
    assert_eq!(
        before.len(),
        after.len(),
        "the history file's rows are preallocated: appends do not grow it"
    );
    let f = hdf5::File::open(out.join("checkpoint.h5")).unwrap();
    let mem = f.group("memory").unwrap();
    let rows: u64 = mem.dataset("history_rows").unwrap().read_scalar().unwrap();
    assert_eq!(rows, 16);
    let ds = f.dataset("memory/past_displacements").unwrap();
    assert_eq!(
        ds.shape()[0],
        17,
        "room for the run's rows: steps + 1 (< 64)"
    );
}

// ---- h5py ------------------------------------------------------------------------------

const H5PY_CHECK: &str = r#"
import sys, h5py, numpy as np
path, kind = sys.argv[1], sys.argv[2]
f = h5py.File(path, "r")
assert f.attrs["format"] == "viscontact checkpoint", f.attrs["format"]
assert int(f.attrs["format_version"]) == 4
assert open(path, "rb").read(22) == b"viscontact checkpoint\n", "the integrity header"
for a in ("writer", "description", "run_id"):
    assert a in f.attrs, a
expected = ["step", "time", "step_size", "state/u", "state/u_sum", "state/u_comp", "state/w",
            "state/z", "state/z_before", "state/active", "state/row_node", "run/iterations",
            "run/max_violation", "run/max_kkt_residual", "scene/text", "mesh/fingerprint",
            "mesh/groups_fingerprint", "mesh/dof_of"]
if kind == "prony":
    expected += ["memory/prony_a", "memory/prony_b", "memory/prony_decay", "memory/prony_state"]
else:
    expected += ["memory/past_displacements", "memory/history_rows", "memory/history_hash"]
for name in expected:
    ds = f[name]
    assert isinstance(ds, h5py.Dataset), name
    assert ds.attrs["description"], name
    assert "units" in ds.attrs, name
n, t, k = int(f["step"][()]), float(f["time"][()]), float(f["step_size"][()])
assert n == 8 and t == n * k and k == 1 / 16, (n, t, k)
u, s, c = f["state/u"][:], f["state/u_sum"][:], f["state/u_comp"][:]
assert u.shape == s.shape == c.shape and np.array_equal(u, s + c)
it = f["run/iterations"][:]
assert it.shape == (17,) and (it[:n] >= 0).all() and (it[n:] == -1).all(), it
assert f["state/z"].shape == f["state/z_before"].shape == f["state/active"].shape
assert f["state/z"].shape == f["state/row_node"].shape
assert "viscosity" in f["scene/text"][()].decode()
assert f["mesh/dof_of"].shape == (int(f["mesh"].attrs["nodes"]), 2)
assert f["mesh/dof_of"][:].max() + 1 == u.shape[0]
assert f["memory"].attrs["kind"] == kind
assert "material.viscosity.theta" in f["physics"].attrs
if kind == "prony":
    assert f["memory/prony_state"].shape == (1, u.shape[0])
    assert np.allclose(f["memory/prony_b"][:], [10.0])
    assert np.isclose(f["memory/prony_decay"][0], np.exp(-10.0 / 16), rtol=1e-15, atol=0)
else:
    rows = int(f["memory/history_rows"][()])
    assert f["memory/history_hash"].dtype == np.uint64
    h = f["memory/past_displacements"]
    assert rows == n and h.shape[0] >= rows and h.shape[1] == u.shape[0], (rows, h.shape)
    assert h.chunks is None and h.shape[0] <= 17
    assert not h[0].any(), "u_0 = 0"
    w = f["state/w"][:]
    assert np.allclose(h[rows - 1] + k * w, u, rtol=0, atol=1e-12 * abs(u).max())
print("ok")
"#;

#[test]
fn h5py_reads_the_documented_layout() {
    let probe = Command::new("python3").args(["-c", "import h5py"]).output();
    if !probe.map(|o| o.status.success()).unwrap_or(false) {
        assert!(
            std::env::var_os("CI").is_none(),
            "python3 with h5py is required in CI"
        );
        eprintln!("SKIPPED h5py_reads_the_documented_layout: python3 with h5py is not installed");
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    for (expr, kind) in [(false, "prony"), (true, "direct")] {
        let scene = common::paper_scene(
            tmp.path(),
            &format!("s{expr}.toml"),
            "paper/rect_008.msh",
            expr,
        );
        let out = tmp.path().join(kind);
        // Checkpoints at steps 1..8: all but the first are written by patching the first.
        run(
            &scene,
            &opts(&out, &["time.steps=16", "checkpoint.every=1"], Some(7)),
        )
        .unwrap();
        let py = Command::new("python3")
            .args(["-c", H5PY_CHECK])
            .arg(out.join("checkpoint.h5"))
            .arg(kind)
            .output()
            .unwrap();
        assert!(
            py.status.success() && String::from_utf8_lossy(&py.stdout).contains("ok"),
            "h5py check of the {kind} checkpoint failed:\n{}{}",
            String::from_utf8_lossy(&py.stdout),
            String::from_utf8_lossy(&py.stderr)
        );
    }
}

// ---- refusals ----------------------------------------------------------------------------

/// `viscontact resume ARGS` must exit 2 with every `needles` in its message, and leave the
/// checkpoint as it was.
fn refused(case: &str, checkpoint: &Path, extra: &[&str], needles: &[&str]) {
    let before = std::fs::read(checkpoint).ok();
    let mut args = vec!["resume", checkpoint.to_str().unwrap(), "--quiet"];
    args.extend(extra);
    let out = common::viscontact(&args);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(2), "[{case}] {stderr}");
    for n in needles {
        assert!(stderr.contains(n), "[{case}] message lacks {n:?}: {stderr}");
    }
    assert_eq!(
        std::fs::read(checkpoint).ok(),
        before,
        "[{case}] resume changed the file"
    );
}

/// A stopped run in `dir/name`: scene `s.toml` beside a private copy of the mesh, so that
/// the mesh can be changed afterwards.
fn stopped_run(dir: &Path, name: &str, expr: bool) -> PathBuf {
    let mesh = dir.join(format!("{name}.msh"));
    std::fs::copy(common::mesh_path("paper/rect_008.msh"), &mesh).unwrap();
    let scene = common::paper("paper/rect_008.msh", expr)
        .mesh(format!("{name}.msh"))
        .write(dir, &format!("{name}.toml"));
    let out = dir.join(name);
    run(&scene, &opts(&out, &["time.steps=16"], Some(7))).unwrap();
    out.join("checkpoint.h5")
}

/// Rewrites one scalar string dataset or attribute of a copy of `cp`.
fn tampered(cp: &Path, name: &str, edit: impl FnOnce(&hdf5::File)) -> PathBuf {
    let copy = cp.with_file_name(name);
    std::fs::copy(cp, &copy).unwrap();
    let f = hdf5::File::open_rw(&copy).unwrap();
    edit(&f);
    f.close().unwrap();
    viscontact::checkpoint::reseal(&copy).unwrap();
    copy
}

fn set_scene_text(f: &hdf5::File, from: &str, to: &str) {
    use std::str::FromStr;
    let ds = f.dataset("scene/text").unwrap();
    let text: hdf5::types::VarLenUnicode = ds.read_scalar().unwrap();
    assert!(text.as_str().contains(from), "{from:?} not in the scene");
    let new = text.as_str().replacen(from, to, 1);
    ds.write_scalar(&hdf5::types::VarLenUnicode::from_str(&new).unwrap())
        .unwrap();
}

#[test]
fn resume_refuses_broken_and_mismatched_checkpoints() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let cp = stopped_run(dir, "a", false);

    // Not HDF5, truncated, missing, not a checkpoint, newer format.
    let text = common::write(dir, "a/text.h5", "name = \"not hdf5\"\n");
    refused("not HDF5", &text, &[], &["text.h5", "not an HDF5 file"]);
    let bytes = std::fs::read(&cp).unwrap();
    let cut = dir.join("a/cut.h5");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    refused("truncated", &cut, &[], &["cut.h5", "truncated or damaged"]);
    let out = common::viscontact(&["resume", dir.join("a/none.h5").to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("none.h5"));
    let foreign = dir.join("a/foreign.h5");
    {
        let f = hdf5::File::create(&foreign).unwrap();
        f.new_dataset::<f64>().shape(3).create("x").unwrap();
    }
    refused(
        "foreign HDF5",
        &foreign,
        &[],
        &["foreign.h5", "not a viscontact checkpoint"],
    );
    let newer = tampered(&cp, "newer.h5", |f| {
        f.attr("format_version")
            .unwrap()
            .write_scalar(&99u32)
            .unwrap()
    });
    refused(
        "newer format",
        &newer,
        &[],
        &["newer.h5", "version 99", "newer"],
    );

    // Physics that differ from the run's (the stored scene edited): material, kernel,
    // boundary groups, step size.
    let cases = [
        ("theta = 0.1", "theta = 0.2", "material.viscosity.theta"),
        (
            "prony = [[1.0, 10.0]]",
            "prony = [[1.0, 11.0]]",
            "material.relaxation.prony",
        ),
        (
            "contact = \"Γ3,1\"",
            "contact = \"top\"",
            "mesh.groups.contact",
        ),
        ("steps = 16", "steps = 20", "step size"),
    ];
    for (i, (from, to, needle)) in cases.into_iter().enumerate() {
        let bad = tampered(&cp, &format!("physics{i}.h5"), |f| {
            set_scene_text(f, from, to)
        });
        refused(needle, &bad, &[], &[&format!("physics{i}.h5"), needle]);
    }

    // Overrides a resume does not take, and an end time off the step grid.
    refused(
        "--set physics",
        &cp,
        &["--set", "material.viscosity.theta=0.3"],
        &["material.viscosity.theta", "viscontact run"],
    );
    refused(
        "--set time.steps",
        &cp,
        &["--set", "time.steps=32"],
        &["time.steps"],
    );
    refused(
        "T2/k not whole",
        &cp,
        &["--set", "time.end=1.01"],
        &["time.end", "whole number", "0.0625"],
    );
    refused(
        "T2 before the checkpoint",
        &cp,
        &["--set", "time.end=0.25"],
        &["time.end", "before"],
    );

    // The mesh file changed since the run: other coordinates, then other groups.
    let mesh = dir.join("a.msh");
    let good = std::fs::read(&mesh).unwrap();
    std::fs::copy(common::repo().join("tests/data/rect_004.msh"), &mesh).unwrap();
    refused(
        "other mesh",
        &cp,
        &[],
        &["a.msh", "not the one the run used"],
    );
    std::fs::write(&mesh, &good).unwrap();

    // A general kernel whose history file belongs to another run.
    let cp_b = stopped_run(dir, "b", true);
    let cp_c = stopped_run(dir, "c", true);
    std::fs::copy(
        cp_c.with_file_name("checkpoint_history.h5"),
        cp_b.with_file_name("checkpoint_history.h5"),
    )
    .unwrap();
    refused(
        "foreign history",
        &cp_b,
        &[],
        &["checkpoint_history.h5", "another run"],
    );

    // After all this the good checkpoint still resumes (beside the broken copies above,
    // which are not viscontact's files: --force).
    let out = common::viscontact(&["resume", cp.to_str().unwrap(), "--quiet", "--force"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn checkpoint_section_is_checked() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = common::paper_scene(tmp.path(), "s.toml", "paper/rect_008.msh", false);
    let out = tmp.path().join("off");
    finished(
        run(
            &scene,
            &opts(&out, &["time.steps=4", "checkpoint.enabled=false"], None),
        )
        .unwrap(),
    );
    assert!(!out.join("checkpoint.h5").exists());
    let out = tmp.path().join("default");
    finished(run(&scene, &opts(&out, &["time.steps=4"], None)).unwrap());
    assert!(out.join("checkpoint.h5").exists(), "the final checkpoint");
    for set in [
        "checkpoint.every_seconds=false",
        "checkpoint.every_seconds=0",
    ] {
        let out = tmp.path().join("no-clock");
        finished(run(&scene, &opts(&out, &["time.steps=4", set], None)).unwrap());
    }
    for (set, needle) in [
        ("checkpoint.every=0", "checkpoint.every"),
        ("checkpoint.often=2", "often"),
        ("checkpoint.every_seconds=-1", "checkpoint.every_seconds"),
        ("checkpoint.every_seconds=\"often\"", "every_seconds"),
    ] {
        let err = run(&scene, &opts(&tmp.path().join("x"), &[set], None)).unwrap_err();
        assert_eq!(err.exit_code(), 2);
        assert!(err.to_string().contains(needle), "{err}");
    }
}

// ---- long-run numerics -------------------------------------------------------------------

/// Issue 4: constant velocity (B = 0, no memory, constant load, no contact): u_N = T·w must
/// hold to a few ulps after N = 10^5 steps with the compensated sum of the time loop, where
/// plain summation drifts visibly.
#[test]
fn displacement_sum_does_not_drift_over_1e5_steps() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = common::SceneText::on(common::repo().join("tests/data/rect_004.msh"))
        .set("time.end", 1.0)
        .set("time.steps", 100000)
        .set("material.viscosity.theta", 0.1)
        .set("material.viscosity.zeta", 0.1)
        .traction(Some("top"), &["0.01", "-0.1"])
        .set("checkpoint.enabled", false)
        .write(tmp.path(), "drift.toml");
    let (scene, _mesh, disc) = common::load(&scene, &[]);
    let mut tl = viscontact::time_loop::TimeLoop::new(&scene, &disc).unwrap();
    assert_eq!(tl.effects().names(), ["viscosity", "tractions"]);
    let k = scene.time.k();
    let mut plain = vec![0.0; disc.n_free];
    let mut w0: Option<Vec<f64>> = None;
    let mut sum = |s: &viscontact::time_loop::Solved| {
        let w = s.step.w;
        match &w0 {
            None => w0 = Some(w.to_vec()),
            Some(w0) => assert!(w == w0.as_slice(), "the velocity is constant"),
        }
        if !s.last {
            for (p, wi) in plain.iter_mut().zip(w) {
                *p += k * wi;
            }
        }
        Ok(())
    };
    tl.run(scene.time.steps, &mut sum).unwrap();
    let w = w0.unwrap();
    let scale = common::max_abs(&w) * scene.time.end;
    let (mut compensated, mut naive) = (0.0f64, 0.0f64);
    for ((u, p), wi) in tl.u().iter().zip(&plain).zip(&w) {
        let exact = scene.time.end * wi;
        compensated = compensated.max((u - exact).abs() / scale);
        naive = naive.max((p - exact).abs() / scale);
    }
    let ulp = f64::EPSILON;
    assert!(
        compensated <= 4.0 * ulp,
        "compensated u_N is {:.1} ulps from T·w",
        compensated / ulp
    );
    assert!(
        naive > 100.0 * ulp,
        "plain summation should drift visibly: only {:.1} ulps",
        naive / ulp
    );
    eprintln!(
        "after 10^5 steps: compensated {:.2} ulps, plain {:.0} ulps from T·w",
        compensated / ulp,
        naive / ulp
    );
}

// ---- damage (issue 12 item 3) ----------------------------------------------------------------

/// `resume` of `cp` (into `out`) must exit 2 naming `name` and saying "damaged": never 0,
/// never a signal.
fn refused_as_damaged(cp: &Path, out: &Path, name: &str, what: &str) {
    let o = viscontact(&[
        "resume",
        cp.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(
        o.status.code(),
        Some(2),
        "{what}: resume gave {:?}: {stderr}",
        o.status
    );
    assert!(
        stderr.contains(name) && stderr.contains("damaged"),
        "{what}: {stderr}"
    );
}

/// Random single bit flips anywhere in checkpoint.h5, of a Prony and of an expression-kernel
/// run: every one is refused with exit 2 and a message, before libhdf5 could misread it.
#[test]
fn any_flipped_bit_in_a_checkpoint_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let mut rng = common::SplitMix(12);
    for expr in [false, true] {
        let cp = stopped_run(tmp.path(), &format!("r{expr}"), expr);
        let good = std::fs::read(&cp).unwrap();
        let damaged = cp.with_file_name("damaged.h5");
        for trial in 0..200 {
            let bit = rng.below(good.len() * 8);
            let mut bytes = good.clone();
            bytes[bit / 8] ^= 1 << (bit % 8);
            std::fs::write(&damaged, &bytes).unwrap();
            let what = format!(
                "expr {expr}, trial {trial}, bit {bit} of {}",
                good.len() * 8
            );
            refused_as_damaged(&damaged, &tmp.path().join("never"), "damaged.h5", &what);
        }
        assert!(!tmp.path().join("never").exists());
        // The intact one still resumes (the damaged copy, not viscontact's, goes first).
        std::fs::remove_file(&damaged).unwrap();
        let o = viscontact(&["resume", cp.to_str().unwrap(), "--quiet"]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
}

/// The history file's `key value` header line.
fn header_value(bytes: &[u8], key: &str) -> usize {
    let text = String::from_utf8_lossy(&bytes[..512]);
    text.lines()
        .find_map(|l| l.strip_prefix(key)?.trim().parse().ok())
        .unwrap_or_else(|| panic!("no {key} in {text:?}"))
}

/// Random single bit flips in checkpoint_history.h5: a flip in its header, its HDF5 metadata
/// or the rows the checkpoint uses is refused (exit 2, a message naming the file); a flip in
/// its unused preallocated rows changes nothing: resume succeeds with the series of the
/// undamaged resume, bit for bit.
#[test]
fn any_flipped_bit_in_a_history_file_is_refused_or_harmless() {
    let tmp = tempfile::tempdir().unwrap();
    let cp = stopped_run(tmp.path(), "r", true);
    let run_dir = cp.parent().unwrap().to_path_buf();
    let reference = tmp.path().join("reference");
    common::copy_dir(&run_dir, &reference);
    let o = viscontact(&[
        "resume",
        reference.join("checkpoint.h5").to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));

    let good = std::fs::read(run_dir.join("checkpoint_history.h5")).unwrap();
    let rows: u64 = hdf5::File::open(&cp)
        .unwrap()
        .dataset("memory/history_rows")
        .unwrap()
        .read_scalar()
        .unwrap();
    let offset = header_value(&good, "rows_offset");
    let row_bytes = header_value(&good, "row_bytes");
    let unused =
        offset + rows as usize * row_bytes..offset + header_value(&good, "capacity") * row_bytes;
    assert!(!unused.is_empty() && unused.end <= good.len());
    let mut rng = common::SplitMix(34);
    let (mut refused, mut harmless) = (0, 0);
    for trial in 0..100 {
        let bit = rng.below(good.len() * 8);
        let dir = tmp.path().join(format!("t{trial}"));
        common::copy_dir(&run_dir, &dir);
        let mut bytes = good.clone();
        bytes[bit / 8] ^= 1 << (bit % 8);
        std::fs::write(dir.join("checkpoint_history.h5"), &bytes).unwrap();
        let what = format!("trial {trial}, bit {bit} of {}", good.len() * 8);
        let cp = dir.join("checkpoint.h5");
        if unused.contains(&(bit / 8)) {
            let o = viscontact(&["resume", cp.to_str().unwrap(), "--quiet"]);
            assert!(
                o.status.success(),
                "{what}: {}",
                String::from_utf8_lossy(&o.stderr)
            );
            assert_eq!(frames(&dir), frames(&reference), "{what}");
            harmless += 1;
        } else {
            refused_as_damaged(&cp, &dir, "checkpoint_history.h5", &what);
            refused += 1;
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
    assert!(
        refused > 20 && harmless > 5,
        "{refused} refused, {harmless} harmless"
    );
}

// ---- moved runs (issue 12 item 5) ------------------------------------------------------------

/// A run directory and its mesh copied to another place (the original gone) resumes with
/// `--set mesh.file=NEW` and gives the series of the run that never stopped; without it, the
/// message says how; a different mesh is refused naming both files.
#[test]
fn a_moved_run_resumes_with_its_mesh_in_a_new_place() {
    let tmp = tempfile::tempdir().unwrap();
    let (here, there) = (tmp.path().join("cluster"), tmp.path().join("laptop"));
    std::fs::create_dir_all(&here).unwrap();
    let cp = stopped_run(&here, "a", false);
    let full = tmp.path().join("full");
    let scene = here.join("a.toml");
    finished(run(&scene, &opts(&full, &["time.steps=16"], None)).unwrap());

    common::copy_dir(&here.join("a"), &there.join("run"));
    std::fs::copy(here.join("a.msh"), there.join("moved.msh")).unwrap();
    std::fs::remove_dir_all(&here).unwrap();
    assert!(!cp.exists());
    let cp = there.join("run/checkpoint.h5");

    refused("mesh gone", &cp, &[], &["a.msh", "--set mesh.file=NEW"]);
    let other = common::repo().join("tests/data/rect_004.msh");
    let set_other = format!("mesh.file={}", other.display());
    refused(
        "other mesh",
        &cp,
        &["--set", &set_other],
        &["rect_004.msh", "a.msh", "not the one the run used"],
    );
    let set_moved = format!("mesh.file={}", there.join("moved.msh").display());
    let o = viscontact(&[
        "resume",
        cp.to_str().unwrap(),
        "--set",
        &set_moved,
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(frames(&there.join("run")), frames(&full));
}

/// A general kernel's run resumed into another directory: its first checkpoint there copies
/// the checkpoint's past rows from the history file it came from (a chunk at a time: no
/// process holds the past whole, `checkpoint::Writer::resume`), which stays as it was, and
/// the run stopped and resumed again there equals the run that never stopped, bit for bit.
#[test]
fn a_direct_sum_resumed_into_another_directory_copies_its_past_and_resumes_again() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = paper_scene(tmp.path(), "s.toml", "paper/rect_008.msh", true);
    let set = ["time.steps=16", "checkpoint.every=2"];
    let [full, a, b] = ["full", "a", "b"].map(|d| tmp.path().join(d));
    let s = finished(run(&scene, &opts(&full, &set, None)).unwrap());
    run(&scene, &opts(&a, &set, Some(5))).unwrap();
    let a_history = std::fs::read(a.join("checkpoint_history.h5")).unwrap();
    let into_b = ResumeOptions {
        out: Some(b.clone()),
        stop_after: Some(10),
        ..ResumeOptions::default()
    };
    let stopped = resume(&a.join("checkpoint.h5"), &into_b).unwrap();
    assert!(
        matches!(stopped, Outcome::Stopped { step: 10, .. }),
        "{stopped:?}"
    );
    let rows = |dir: &Path| -> u64 {
        let f = hdf5::File::open(dir.join("checkpoint.h5")).unwrap();
        f.dataset("memory/history_rows")
            .unwrap()
            .read_scalar()
            .unwrap()
    };
    assert_eq!(rows(&b), 11, "rows 0..6 copied from a's file, 6..11 sent");
    assert_eq!(
        std::fs::read(a.join("checkpoint_history.h5")).unwrap(),
        a_history,
        "the history file the resume came from is left as it was"
    );
    let r = finished(resume_quiet(&b.join("checkpoint.h5")));
    assert_eq!(s.final_.u_h1.to_bits(), r.final_.u_h1.to_bits());
    let (whole, resumed) = (frames(&full), frames(&b));
    assert!(resumed.len() >= 2, "{:?}", resumed.keys());
    for (name, bytes) in &resumed {
        if name.ends_with(".vtu") {
            assert_eq!(Some(bytes), whole.get(name), "{name}");
        }
    }
}

// ---- hostile sizes (issue 12 item 4) ---------------------------------------------------------

/// The history file grows with the run (64, 128, 256 rows, …, at most N + 1) instead of
/// being allocated for all N steps, and a run resumed across the growth equals the run that
/// never stopped.
#[test]
fn history_file_grows_with_the_run() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = paper_scene(tmp.path(), "s.toml", "paper/rect_008.msh", true);
    let set = ["time.steps=300", "checkpoint.every=7", "output.every=50"];
    let (full, part) = (tmp.path().join("full"), tmp.path().join("part"));
    finished(run(&scene, &opts(&full, &set, None)).unwrap());
    run(&scene, &opts(&part, &set, Some(150))).unwrap();
    let capacity = |dir: &Path| {
        header_value(
            &std::fs::read(dir.join("checkpoint_history.h5")).unwrap(),
            "capacity",
        )
    };
    // 64, 128, 256 rows (or fewer steps between when checkpoints coalesce).
    assert_eq!(
        capacity(&part),
        256,
        "a power of two ≥ 151 rows by step 150"
    );
    finished(resume(&part.join("checkpoint.h5"), &ResumeOptions::default()).unwrap());
    assert_eq!(capacity(&part), 301, "at most N + 1 rows");
    assert_same_series(&full, &part, "resumed across the history file's growth");
}

/// `time.steps = 10^12` is refused by `check` and by `run` (exit 2, the estimate and the key
/// to change) before anything is written.
#[test]
fn a_run_this_machine_cannot_hold_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    for expr in [false, true] {
        let scene = paper_scene(
            tmp.path(),
            &format!("s{expr}.toml"),
            "paper/rect_008.msh",
            expr,
        );
        let out = tmp.path().join(format!("o{expr}"));
        for cmd in ["check", "run"] {
            let mut args = vec![
                cmd,
                scene.to_str().unwrap(),
                "--set",
                "time.steps=1000000000000",
            ];
            if cmd == "run" {
                args.extend(["--out", out.to_str().unwrap()]);
            }
            let o = viscontact(&args);
            let stderr = String::from_utf8_lossy(&o.stderr);
            assert_eq!(o.status.code(), Some(2), "{cmd}: {stderr}");
            assert!(
                stderr.contains("time.steps") && stderr.contains("TB"),
                "{cmd}: {stderr}"
            );
        }
        assert!(!out.exists(), "a refused run writes nothing");
    }
}

/// Scenes with Dirichlet conditions (issue 51), whose prescribed dofs the checkpoint keeps
/// beside the free ones: the paper's rectangle pulled by a prescribed displacement of its
/// right edge, and the half block with a symmetry plane whose right face is pushed down;
/// stopped at step 7 of 16 and resumed = the run that never stopped, bit for bit.
#[test]
fn stopped_and_resumed_equals_uninterrupted_with_prescribed_displacements() {
    let tmp = tempfile::tempdir().unwrap();
    let data = common::repo().join("tests/data/symmetry");
    let scenes = [
        common::SceneText::paper()
            .set("mesh.file", common::mesh_path("paper/rect_016.msh"))
            .dirichlet("right", &["x"], Some(&["0.02*t*(1-y)"])),
        common::SceneText::block()
            .mesh(data.join("half_block.msh"))
            .set("load.traction", toml::Value::Array(vec![]))
            .dirichlet("sym", &["normal"], None)
            .dirichlet("right", &["z"], Some(&["-0.02*t"])),
    ];
    for (i, s) in scenes.into_iter().enumerate() {
        let s = s.set("time.steps", 16).set("checkpoint.every", 5);
        let scene = s.write(tmp.path(), &format!("scene{i}.toml"));
        let (full, part) = (
            tmp.path().join(format!("full{i}")),
            tmp.path().join(format!("part{i}")),
        );
        let summary = finished(run(&scene, &opts(&full, &[], None)).unwrap());
        assert!(summary.iterations.total > 0);
        assert!(matches!(
            run(&scene, &opts(&part, &[], Some(7))).unwrap(),
            Outcome::Stopped { step: 7, .. }
        ));
        finished(resume_quiet(&part.join("checkpoint.h5")));
        assert_same_series(&full, &part, &format!("scene {i}"));
    }
}
