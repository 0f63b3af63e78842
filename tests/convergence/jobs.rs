//! A study's cases side by side (`study --jobs N`) and as a Slurm job array (`--emit slurm`,
//! `--collect`), issue 28: the numbers are those of the cases run one after another, bit
//! for bit; only the wall times differ.

use crate::common::*;
use serde_json::Value;
use std::path::Path;

/// `viscontact study ARGS` of the paper's scene at levels 8, 16, reference 32, the three
/// families.
fn study_args<'a>(scene: &'a Path, extra: &[&'a str]) -> Vec<&'a str> {
    let mut args = vec![
        "study",
        scene.to_str().unwrap(),
        "--levels",
        "8,16",
        "--reference",
        "32",
        "--vary",
        "both,h,k",
        "--repeat",
        "1",
    ];
    args.extend_from_slice(extra);
    args
}

/// `viscontact study` (see [`study_args`]) with `extra` arguments: its study.json.
fn paper_study(out: &Path, extra: &[&str]) -> Value {
    let scene = repo().join("examples/paper.toml");
    let mut args = study_args(&scene, extra);
    args.extend(["--out", out.to_str().unwrap()]);
    let (code, text) = cli(&args);
    assert_eq!(code, 0, "{text}");
    study_json(out)
}

fn study_json(dir: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(dir.join("study.json")).unwrap()).unwrap()
}

/// The report without what is timed: the keys ending in `_s` and `timed`.
fn untimed(v: &Value) -> Value {
    match v {
        Value::Object(m) => Value::Object(
            m.iter()
                .filter(|(k, _)| !k.ends_with("_s") && *k != "timed")
                .map(|(k, v)| (k.clone(), untimed(v)))
                .collect(),
        ),
        Value::Array(a) => Value::Array(a.iter().map(untimed).collect()),
        other => other.clone(),
    }
}

#[test]
fn cases_side_by_side_give_the_numbers_of_one_after_another() {
    let dir = tempfile::tempdir().unwrap();
    let compare = ["--kernel-compare"];
    let one = paper_study(&dir.path().join("one"), &compare);
    let two = paper_study(
        &dir.path().join("two"),
        &["--kernel-compare", "--jobs", "2"],
    );
    assert_eq!(one["timed"], "in_turn");
    assert_eq!(two["timed"]["side_by_side"], 2);
    // serde_json writes the shortest text that reads back as the same f64: equal values
    // are equal bits.
    assert_eq!(untimed(&one), untimed(&two));
    let md = std::fs::read_to_string(dir.path().join("two/study.md")).unwrap();
    assert!(md.contains("measured concurrently"), "{md}");
    // Three processes at a time on a machine of any size agree too.
    let three = paper_study(
        &dir.path().join("three"),
        &["--kernel-compare", "--jobs", "3"],
    );
    assert_eq!(untimed(&one), untimed(&three));
}

/// Runs task `id` of the job array in `dir` as Slurm would (`SLURM_ARRAY_TASK_ID`); with
/// `term`, sends it SIGTERM once its run has written its first frame (the frames are written
/// by a thread of their own: the run may also be further on, or done). Its exit status.
fn task(dir: &Path, id: usize, term: bool) -> std::process::ExitStatus {
    let mut child = std::process::Command::new("bash")
        .arg(dir.join("array.sh"))
        .env("SLURM_ARRAY_TASK_ID", id.to_string())
        .env("VISCONTACT", env!("CARGO_BIN_EXE_viscontact"))
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let frame = dir.join(format!("runs/{id:04}/solution_000000.vtu"));
    while term && !frame.exists() && child.try_wait().unwrap().is_none() {
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    if term {
        // The task execs viscontact: the process is the run.
        let pid = child.id().to_string();
        let _ = std::process::Command::new("kill")
            .args(["-s", "TERM", &pid])
            .status();
    }
    child.wait().unwrap()
}

/// Task `id` stopped by SIGTERM midway, trying again from a fresh directory while the run
/// got done first (at most 30 times): whether it was.
fn stop_midway(dir: &Path, id: usize) -> bool {
    let out = dir.join(format!("runs/{id:04}"));
    (0..30).any(|_| {
        let _ = std::fs::remove_dir_all(&out);
        let status = task(dir, id, true);
        let summary = std::fs::read_to_string(out.join("summary.json")).unwrap_or_default();
        status.code() == Some(143) && summary.contains("\"interrupted\"")
    })
}

#[test]
fn a_slurm_array_run_task_by_task_collects_the_tables_of_a_local_study() {
    let dir = tempfile::tempdir().unwrap();
    let local = paper_study(&dir.path().join("local"), &[]);
    let array = dir.path().join("array");
    let scene = repo().join("examples/paper.toml");
    // A checkpoint at every step, so that a SIGTERM finds one to stop with.
    let extra = ["--set", "checkpoint.every=1", "--emit", "slurm"];
    let mut args = study_args(&scene, &extra);
    args.push(array.to_str().unwrap());
    let (code, text) = cli(&args);
    assert_eq!(code, 0, "{text}");
    let runs = std::fs::read_to_string(array.join("runs.tsv")).unwrap();
    let n = runs.lines().count() - 1;
    let script = std::fs::read_to_string(array.join("array.sh")).unwrap();
    for line in [
        format!("#SBATCH --array=0-{}%{n}", n - 1),
        "#SBATCH --cpus-per-task=4".into(),
        "#SBATCH --signal=B:TERM@120".into(),
    ] {
        assert!(script.contains(&line), "{line} not in\n{script}");
    }
    assert!(script.contains("#SBATCH --mem="), "{script}");
    // Every other task sent SIGTERM, as at its time limit: the reference's run (task 0, the
    // longest) certainly stopped midway, the others wherever they were.
    assert!(stop_midway(&array, 0), "task 0 was never stopped midway");
    for id in (2..n).step_by(2) {
        task(&array, id, true);
    }
    // Collecting before every run is complete says which is not.
    let (code, text) = cli(&["study", "--collect", array.to_str().unwrap()]);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("is not complete"), "{text}");
    // The array again: the stopped runs resume, the others start; once more, every task
    // finds its run complete.
    for _ in 0..2 {
        for id in 0..n {
            assert!(task(&array, id, false).success(), "task {id}");
        }
    }
    let (code, text) = cli(&["study", "--collect", array.to_str().unwrap()]);
    assert_eq!(code, 0, "{text}");
    let collected = study_json(&array);
    assert_eq!(collected["timed"], "slurm_array");
    assert_eq!(untimed(&local), untimed(&collected));
}

/// Issue 49, item 3: the emitted scripts run as they are, `VISCONTACT` unset, although the
/// array's directory and the binary that wrote them have a space, a quote and a `$` in
/// their paths: every task of array.sh (`SLURM_ARRAY_TASK_ID`), then collect.sh, which
/// exited 127 when the binary's path kept its single quotes.
#[test]
fn the_emitted_slurm_scripts_run_from_paths_with_spaces_and_quotes() {
    let tmp = tempfile::tempdir().unwrap();
    let odd = tmp.path().join("a b'c \"d $HOME");
    std::fs::create_dir(&odd).unwrap();
    let exe = odd.join("viscontact");
    std::fs::copy(BIN, &exe).unwrap();
    let array = odd.join("array");
    let scene = repo().join("examples/paper.toml");
    let o = std::process::Command::new(&exe)
        .args(["study", scene.to_str().unwrap(), "--levels", "8"])
        .args(["--reference", "16", "--vary", "h", "--repeat", "1"])
        .args(["--emit", "slurm", array.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let bash = |script: &str, id: Option<usize>| {
        let mut c = std::process::Command::new("bash");
        c.arg(array.join(script)).env_remove("VISCONTACT");
        if let Some(id) = id {
            c.env("SLURM_ARRAY_TASK_ID", id.to_string());
        }
        let o = c.output().unwrap();
        let text = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(o.status.success(), "{script} ({id:?}): {text}");
    };
    // Collected before any run: which run is not complete, in words (item 11: it printed
    // the internal `AsGiven`).
    let (code, text) = cli(&["study", "--collect", array.to_str().unwrap()]);
    assert_eq!(code, 2, "{text}");
    assert!(
        text.contains(".msh, N = 16) in") && !text.contains("AsGiven"),
        "{text}"
    );
    assert!(
        text.contains("(status: not started, no summary.json)"),
        "{text}"
    );
    let runs = std::fs::read_to_string(array.join("runs.tsv")).unwrap();
    let n = runs.lines().count() - 1;
    assert!(n >= 2, "{runs}");
    for id in 0..n {
        bash("array.sh", Some(id));
        let summary = summary(&array.join(format!("runs/{id:04}")));
        assert_eq!(summary["status"], "completed", "run {id}");
    }
    bash("collect.sh", None);
    assert_eq!(study_json(&array)["timed"], "slurm_array");
}
