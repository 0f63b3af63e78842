//! `run --emit slurm DIR`: the job script as Slurm would run it, with a stand-in `sbatch`
//! on the PATH that records what it was asked to submit. SIGTERM to the batch shell in the
//! middle of the run (what `--signal=B:TERM@120` does before the time limit) stops the run
//! with a checkpoint and submits the job again; the job run again resumes it to the end and
//! submits nothing; a third says the run is complete. The series equals the run never
//! stopped, bit for bit. A job of several ranks, of a scene without checkpoints, or into a
//! directory that holds a run already, is refused (exit 2).

use crate::common;

use common::SceneText;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

/// The job's batch shell, as Slurm starts it, with `bin` first on the PATH.
fn job(script: &Path, bin: &Path) -> Command {
    let mut c = Command::new("bash");
    c.arg(script)
        .env(
            "PATH",
            format!("{}:{}", bin.display(), std::env::var("PATH").unwrap()),
        )
        .env("SLURM_CPUS_PER_TASK", "1");
    c
}

fn submitted(log: &Path) -> String {
    std::fs::read_to_string(log).unwrap_or_default()
}

#[test]
fn the_job_stops_at_its_time_limit_submits_itself_and_resumes_to_the_uninterrupted_run() {
    let tmp = tempfile::tempdir().unwrap();
    let t = tmp.path();
    let scene = SceneText::paper()
        .set("time.steps", 600)
        .set("time.end", 600.0 / 32.0)
        .write(t, "s.toml");
    let (out, whole) = (t.join("out"), t.join("whole"));
    let (code, text) = common::cli(&[
        "run",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--emit",
        "slurm",
        t.join("job").to_str().unwrap(),
        "--time",
        "1:00:00",
    ]);
    assert_eq!(code, 0, "{text}");
    let script = t.join("job/job.sh");
    let text = std::fs::read_to_string(&script).unwrap();
    for line in [
        "#SBATCH --signal=B:TERM@120",
        "#SBATCH --time=1:00:00",
        "#SBATCH --mem=",
    ] {
        assert!(text.contains(line), "{line}: {text}");
    }
    assert!(!out.exists(), "--emit ran the scene");
    // The stand-in sbatch.
    let bin = t.join("bin");
    std::fs::create_dir(&bin).unwrap();
    let log = t.join("sbatch.log");
    let sbatch = bin.join("sbatch");
    std::fs::write(
        &sbatch,
        format!("#!/bin/sh\necho \"$@\" >> '{}'\n", log.display()),
    )
    .unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&sbatch, std::fs::Permissions::from_mode(0o755)).unwrap();

    // The first job, told to stop once its run has solved 40 steps.
    let mut first = job(&script, &bin).spawn().unwrap();
    let start = Instant::now();
    let rows = || std::fs::read_to_string(out.join("history.csv")).map_or(0, |h| h.lines().count());
    while rows() < 40 {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "the run did not start"
        );
        assert!(
            first.try_wait().unwrap().is_none(),
            "the job ended before its limit"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    let pid = first.id().to_string();
    assert!(Command::new("kill")
        .args(["-TERM", &pid])
        .status()
        .unwrap()
        .success());
    let status = first.wait().unwrap();
    assert_eq!(status.code(), Some(0), "{}", submitted(&log));
    assert_eq!(common::summary(&out)["status"], "interrupted");
    assert_eq!(submitted(&log).trim(), script.to_str().unwrap());

    // The job submitted again resumes to the end, and submits nothing more.
    let o = job(&script, &bin).output().unwrap();
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert_eq!(common::summary(&out)["status"], "completed");
    assert_eq!(submitted(&log).lines().count(), 1);
    let o = job(&script, &bin).output().unwrap();
    assert_eq!(o.status.code(), Some(0));
    assert!(String::from_utf8_lossy(&o.stdout).contains("is complete"));

    let (code, text) = common::cli(&[
        "run",
        "--quiet",
        "--threads",
        "1",
        scene.to_str().unwrap(),
        "--out",
        whole.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{text}");
    common::assert_same_series(&whole, &out, "a job stopped at its limit and resumed");
}

#[test]
fn a_job_of_several_ranks_or_without_checkpoints_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = SceneText::paper().write(tmp.path(), "s.toml");
    let job = tmp.path().join("job");
    let emit = |extra: &[&str]| {
        let args = [
            &[
                "run",
                scene.to_str().unwrap(),
                "--emit",
                "slurm",
                job.to_str().unwrap(),
            ],
            extra,
        ]
        .concat();
        common::cli(&args)
    };
    let (code, text) = emit(&["--nodes", "2"]);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("a run is one process"), "{text}");
    let (code, text) = emit(&["--set", "checkpoint.enabled=false"]);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("[checkpoint] enabled = false"), "{text}");
    let earlier = tmp.path().join("earlier");
    std::fs::create_dir(&earlier).unwrap();
    std::fs::write(earlier.join("checkpoint.h5"), b"a run of another scene").unwrap();
    let (code, text) = emit(&["--out", earlier.to_str().unwrap()]);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("holds a run already"), "{text}");
    let (code, text) = emit(&["--time", "1 day"]);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("Slurm's form"), "{text}");
    assert!(!job.join("job.sh").exists());
}
