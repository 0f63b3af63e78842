//! What a newcomer's terminal does to the commands (issue 49): a pipe whose reader goes
//! (`| head -1`), a full stream (`> /dev/full`), a terminal that goes away (SIGHUP). A run
//! goes on and ends as it would have, with its results; a command that only prints ends
//! quietly, as Unix tools do; nothing panics.

use crate::common;
use common::{SceneText, BIN};
use std::path::Path;
use std::process::Command;

/// Starts `viscontact ARGS` with stdout and stderr on one pipe whose reader reads `keep`
/// bytes and goes (`| head -c KEEP`), and waits: the exit code (minus the signal that ended
/// it) and what the reader got.
fn into_closed_pipe(args: &[&str], keep: usize) -> (i32, String) {
    use std::io::Read;
    use std::os::unix::process::ExitStatusExt;
    let (mut reader, writer) = std::io::pipe().unwrap();
    let mut child = Command::new(BIN)
        .args(args)
        .current_dir(common::repo())
        .env("RUST_BACKTRACE", "1")
        .stdout(writer.try_clone().unwrap())
        .stderr(writer)
        .spawn()
        .unwrap();
    let mut got = vec![0u8; keep];
    reader.read_exact(&mut got).unwrap();
    drop(reader);
    let status = child.wait().unwrap();
    let code = status
        .code()
        .unwrap_or_else(|| -status.signal().unwrap_or(0));
    (code, String::from_utf8_lossy(&got).into_owned())
}

/// A run whose log pipe is gone after its first bytes (`run … 2>&1 | head -c 1`, the
/// progress lines of a long run) still runs to its end and writes all it should: today's
/// `run` panicked at its next line to the closed pipe, with no checkpoint and no summary.
#[test]
fn a_run_outlives_its_closed_log_pipe() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = common::paper_scene(tmp.path(), "s.toml", "paper/rect_016.msh", false);
    let out = tmp.path().join("out");
    // Not --quiet: progress lines go to the (closed) pipe, and so do the warnings.
    let (code, _) = into_closed_pipe(
        &[
            "run",
            scene.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--stop-after",
            "200",
            "--set",
            "time.steps=16",
        ],
        1,
    );
    assert_eq!(code, 0);
    assert_eq!(common::summary(&out)["status"], "completed");
    assert!(out.join("solution.pvd").exists());
}

/// `check X | head -1` and `mesh-info X | head -1`: the command ends quietly once its
/// reader has gone (by SIGPIPE, as `cat` does, or having printed all), never with a panic
/// or a backtrace.
#[test]
fn printing_commands_end_quietly_on_a_closed_pipe() {
    let mesh = common::mesh_path("paper/rect_032.msh");
    for args in [
        vec!["check", "examples/paper.toml"],
        vec!["mesh-info", mesh.as_str()],
        vec!["mesh-info", mesh.as_str(), "--json"],
        vec!["--help"],
    ] {
        for _ in 0..5 {
            let (code, got) = into_closed_pipe(&args, 1);
            assert!(
                code == 0 || code == -libc::SIGPIPE,
                "{args:?}: exit {code} ({got:?})"
            );
        }
    }
}

/// A stdout that cannot be written (`> /dev/full`) is an error of a command that only
/// prints (exit 1, said on stderr), not a panic; a run still completes with its results.
#[test]
fn a_full_stdout_is_an_error_of_check_and_not_of_a_run() {
    let full = || {
        std::fs::OpenOptions::new()
            .write(true)
            .open("/dev/full")
            .unwrap()
    };
    let out = Command::new(BIN)
        .args(["check", "examples/paper.toml"])
        .current_dir(common::repo())
        .stdout(full())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("cannot write to standard output"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");

    let tmp = tempfile::tempdir().unwrap();
    let scene = SceneText::paper()
        .mesh(common::mesh_path("paper/rect_008.msh"))
        .write(tmp.path(), "s.toml");
    let dir = tmp.path().join("out");
    let status = Command::new(BIN)
        .args([
            "run",
            scene.to_str().unwrap(),
            "--out",
            dir.to_str().unwrap(),
        ])
        .stdout(full())
        .stderr(full())
        .status()
        .unwrap();
    assert_eq!(status.code(), Some(0));
    assert_eq!(common::summary(&dir)["status"], "completed");
}

/// SIGHUP (the terminal went away) stops a run as SIGTERM does: after its step, with a
/// checkpoint that resumes to the run that was never stopped.
#[test]
fn a_hangup_stops_a_run_with_a_checkpoint() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = common::paper_scene(tmp.path(), "s.toml", "paper/rect_016.msh", false);
    let scene = scene.to_str().unwrap();
    let [full, cut] = ["full", "cut"].map(|d| tmp.path().join(d));
    let args = |dir: &Path| {
        [
            "run",
            scene,
            "--out",
            dir.to_str().unwrap(),
            "--quiet",
            "--set",
            "time.steps=600",
        ]
        .map(str::to_string)
    };
    let full_args = args(&full);
    let (code, text) = common::cli(&full_args.each_ref().map(String::as_str));
    assert_eq!(code, 0, "{text}");
    let cut_args = args(&cut);
    let (status, stderr) =
        common::signal_at_frame(&cut_args.each_ref().map(String::as_str), &cut, 50, &["HUP"]);
    assert_eq!(status.code(), Some(129), "{stderr}");
    assert!(stderr.contains("interrupted by SIGHUP"), "{stderr}");
    let (code, text) = common::cli(&[
        "resume",
        cut.join("checkpoint.h5").to_str().unwrap(),
        "--quiet",
    ]);
    assert_eq!(code, 0, "{text}");
    common::assert_same_series(&full, &cut, "stopped by SIGHUP and resumed");
}
