//! Two or three SIGINT/SIGTERM a few milliseconds apart, at random moments of a run that
//! replaces a completed earlier run of the same scene in its directory (with the default
//! checkpoints, so that none is written by the clock before the signals): whatever the
//! moment, the run is never lost. Either the directory still holds the earlier run (a
//! signal in setup), or the run completed, or it stopped with a checkpoint that `resume`
//! continues to the uninterrupted run's answer, bit for bit. Until issue 49, two signals
//! within about 26 ms after setup ended the process by the second one, with the earlier run
//! removed and no checkpoint (38 losses in 60 trials).
//!
//! Half the moments fall around the end of setup (0.5 to 1.5 times the setup time), the
//! rest anywhere in the run; the gaps between the signals are drawn from 0–20 ms or
//! 0–200 ms; .vtu and vtkhdf series take turns. `VISCONTACT_SIGNAL_TRIALS=N` sets the number
//! of trials (default 8 in CI; 200 for the acceptance run), `VISCONTACT_SEED` the
//! seed (printed).

use crate::common;

use common::SplitMix;
use std::collections::BTreeMap;
use std::path::Path;
use std::time::Duration;

/// How a trial ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Ending {
    /// Setup was stopped: the directory holds the earlier run, unchanged.
    EarlierIntact,
    /// The signals came after the last step: the run completed.
    Completed,
    /// Stopped with a checkpoint; the resumed run equals the uninterrupted one.
    Resumed,
}

/// The directory's files, without the lock file a process ended during setup leaves behind
/// (`flock`ed, so it holds nobody out).
fn contents(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut c = common::dir_contents(dir);
    c.remove(viscontact::run::LOCK_NAME);
    c
}

/// One trial: the signals at `delay` into a run in `out`, which holds a copy of `full`.
fn trial(
    args: &[&str],
    full: &Path,
    out: &Path,
    delay: Duration,
    signals: &[(i32, Duration)],
) -> Ending {
    let _ = std::fs::remove_dir_all(out);
    common::copy_dir(full, out);
    let earlier = contents(out);
    let what = format!("{args:?} after {delay:?}, signals {signals:?}");
    let code = common::signalled(args, delay, signals, Duration::from_secs(120));
    let intact = contents(out) == earlier;
    match code {
        0 => {
            common::assert_same_series(full, out, &what);
            Ending::Completed
        }
        // Ended by a signal itself: before `main` blocked it, or a second one in setup.
        c if c < 0 => {
            assert!(
                intact,
                "{what}: ended by signal {} with the directory changed",
                -c
            );
            Ending::EarlierIntact
        }
        130 | 143 if intact => Ending::EarlierIntact,
        130 | 143 => {
            let summary = common::summary(out);
            assert_eq!(summary["status"], "interrupted", "{what}");
            let cp = out.join("checkpoint.h5");
            let (rc, text) = common::cli(&["resume", cp.to_str().unwrap(), "--quiet"]);
            assert_eq!(rc, 0, "{what}: the resume failed: {text}");
            common::assert_same_series(full, out, &what);
            Ending::Resumed
        }
        c => panic!("{what}: exit status {c}"),
    }
}

#[test]
fn two_or_three_quick_signals_never_lose_a_run() {
    let trials: usize = common::env_or("VISCONTACT_SIGNAL_TRIALS", 8);
    let seed: u64 = common::env_or("VISCONTACT_SEED", 49);
    println!("seed {seed}, {trials} trials");
    let tmp = tempfile::tempdir().unwrap();
    let scene = common::paper_scene(tmp.path(), "s.toml", "paper/rect_032.msh", false);
    let scene = scene.to_str().unwrap();
    let mut rng = SplitMix(seed);
    let mut endings = BTreeMap::new();
    for format in ["vtu", "vtkhdf"] {
        let full = tmp.path().join(format!("full-{format}"));
        let out = tmp.path().join("out");
        let set = format!("output.format=\"{format}\"");
        let args = |dir: &Path| -> Vec<String> {
            ["run", scene, "--out", dir.to_str().unwrap(), "--quiet"]
                .into_iter()
                .chain(["--set", "time.steps=1000", "--set", &set])
                .map(str::to_string)
                .collect()
        };
        let full_args = args(&full);
        let (rc, text) = common::cli(&full_args.iter().map(String::as_str).collect::<Vec<_>>());
        assert_eq!(rc, 0, "{text}");
        let timing = &common::summary(&full)["timing"];
        let (setup, total) = (
            timing["setup_s"].as_f64().unwrap(),
            timing["total_s"].as_f64().unwrap(),
        );
        let run_args = args(&out);
        let run_args: Vec<&str> = run_args.iter().map(String::as_str).collect();
        for i in 0..trials.div_ceil(2) {
            let delay = match i % 2 {
                0 => setup * (0.5 + rng.unit()),
                _ => total * rng.unit(),
            };
            let most = if rng.below(2) == 0 { 20.0 } else { 200.0 };
            let signals: Vec<(i32, Duration)> = (0..2 + rng.below(2))
                .map(|k| {
                    let signal = rng.pick(&[libc::SIGINT, libc::SIGTERM]);
                    let gap = if k == 0 { 0.0 } else { most * rng.unit() };
                    (signal, Duration::from_secs_f64(gap / 1e3))
                })
                .collect();
            let ending = trial(
                &run_args,
                &full,
                &out,
                Duration::from_secs_f64(delay),
                &signals,
            );
            *endings.entry((format, ending)).or_insert(0) += 1;
        }
    }
    println!("{endings:?}");
    assert!(
        endings.keys().any(|(_, e)| *e == Ending::Resumed),
        "no trial stopped a run that then resumed: the moments miss the run"
    );
}
