//! SIGINT and SIGTERM at random moments of a run's and a resume's setup (scene, mesh,
//! discretization, METIS ordering, factorization) on the 33k-dof paper mesh, with an
//! earlier run in the directory: every process exits 130 / 143 within 5 s of the signal
//! and leaves the directory byte for byte as it was (a signal that comes before `main` has
//! blocked it, while the process is still being loaded, ends it by the signal's default
//! action, which a shell reports as the same 128 + sig; counted). A signal that lands after setup (the
//! moments are drawn from the measured setup time, which varies) must end the run as an
//! interrupted run that can be resumed; such draws are counted, and most draws must land
//! in setup for the test to mean something.
//!
//! `VISCONTACT_SETUP_SIGNALS=N` sets the number of signals of each kind (default 4 in CI;
//! the acceptance run used 50), `VISCONTACT_SEED` the seed (printed).

use crate::common;

use common::SplitMix;
use std::path::Path;
use std::time::Duration;

/// Starts `viscontact ARGS`, sends `signal` after `delay`, and waits at most 5 s after the
/// signal: the exit status. A process ended by the signal itself (minus the signal) got it
/// before `main` blocked it (the dynamic loader's and the runtime's start, some ms): what a
/// shell reports as 128 + sig.
fn signalled(args: &[&str], delay: Duration, signal: i32) -> i32 {
    common::signalled(
        args,
        delay,
        &[(signal, Duration::ZERO)],
        Duration::from_secs(5),
    )
}

/// The setup time the summary of a run in `dir` reports.
fn setup_seconds(dir: &Path) -> f64 {
    common::summary(dir)["timing"]["setup_s"].as_f64().unwrap()
}

#[test]
fn signals_during_setup_exit_at_once_and_leave_the_earlier_run_intact() {
    let count: usize = common::env_or("VISCONTACT_SETUP_SIGNALS", 4);
    let seed: u64 = common::env_or("VISCONTACT_SEED", 26);
    println!("seed {seed}, {count} signals of each kind, for run and for resume");
    let tmp = tempfile::tempdir().unwrap();
    let scene = common::paper_scene(tmp.path(), "big.toml", "paper/rect_128.msh", false);
    let scene = scene.to_str().unwrap();
    let out = tmp.path().join("out");
    let out_s = out.to_str().unwrap();
    let run = [
        "run",
        scene,
        "--out",
        out_s,
        "--quiet",
        "--set",
        "time.steps=64",
    ];
    let earlier = |stop: &str| {
        let (code, text) = common::cli(&[&run[..], &["--stop-after", stop]].concat());
        assert_eq!(code, 0, "{text}");
    };
    let mut rng = SplitMix(seed);
    let mut in_setup = 0;
    let mut after = 0;
    let mut before_main = 0;
    for command in ["run", "resume"] {
        earlier("1");
        let setup = setup_seconds(&out);
        let checkpoint = out.join("checkpoint.h5");
        let cp = checkpoint.to_str().unwrap();
        let args: Vec<&str> = match command {
            "run" => run.to_vec(),
            _ => vec!["resume", cp, "--quiet"],
        };
        for i in 0..2 * count {
            let signal = if i % 2 == 0 {
                libc::SIGTERM
            } else {
                libc::SIGINT
            };
            let before = common::dir_contents(&out);
            let delay = Duration::from_secs_f64(setup * rng.unit());
            let code = signalled(&args, delay, signal);
            if code == -signal {
                before_main += 1;
                assert_eq!(
                    common::dir_contents(&out),
                    before,
                    "{command} after {delay:?}"
                );
                continue;
            }
            assert_eq!(code, 128 + signal, "{command} after {delay:?}");
            if common::dir_contents(&out) == before {
                in_setup += 1;
                continue;
            }
            // Past setup: an interrupted run with a checkpoint (the next draws start from it).
            after += 1;
            let summary = common::summary(&out);
            assert_eq!(
                summary["status"], "interrupted",
                "{command} after {delay:?}"
            );
            assert!(checkpoint.exists());
            earlier("1");
        }
    }
    println!("{in_setup} signals landed in setup, {after} after it, {before_main} before main");
    assert!(
        before_main <= count,
        "{before_main} of {} processes ended by the signal itself",
        4 * count
    );
    assert!(
        in_setup >= 2 * count,
        "only {in_setup} of {} signals landed in setup",
        4 * count
    );
}
