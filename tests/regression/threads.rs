//! The results do not depend on the thread count (`--threads`, src/threads.rs): the same
//! scene run with 1, 2, 3 and 4 threads (3 and 4 oversubscribe a 2-core machine) writes
//! the same frames byte for byte and the same checkpoint, apart from the run id. The scenes
//! reach the threaded parts of a step: the 2D paper scene at h = 1/128 (memory and
//! friction; its factor is large enough for the solves' two groups of subtrees), the 3D
//! block (a dense dual with Newton steps), the plate on its foundation (a root supernode
//! large enough to share its rows, D z in eight parts; and with the two duals without D)
//! and a run written as one `.vtkhdf` file.

use crate::common;

use common::{cli, frames, paper_scene, repo, BIN};
use std::path::Path;
use std::process::Command;
use viscontact::checkpoint::Checkpoint;
use viscontact::history::HeldAt;
use viscontact::output::read::{read_frame, read_vtkhdf, FrameRef};

const COUNTS: [&str; 4] = ["1", "2", "3", "4"];

/// Runs `scene` with `--threads N` into `out`; the summary must say N threads.
fn run_with(scene: &Path, out: &Path, threads: &str, set: &[&str]) {
    let mut args = vec![
        "run",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--quiet",
        "--threads",
        threads,
    ];
    for s in set {
        args.extend(["--set", s]);
    }
    let (code, text) = cli(&args);
    assert_eq!(code, 0, "{threads} threads: {text}");
    assert!(text.contains(&format!(" s on {threads} thread")), "{text}");
    assert_eq!(
        common::summary(out)["threads"],
        threads.parse::<u64>().unwrap()
    );
}

/// The checkpoint's contents without what names the run: its path, run id and the
/// checksums of its frames (which hold the run id; the frames are compared themselves).
fn checkpoint(dir: &Path) -> String {
    let mut cp = Checkpoint::read(&dir.join("checkpoint.h5")).unwrap();
    // The vectors stay in the file until read (a resume reads its part of them): every
    // dof's here.
    let saved = (cp.saved(cp.n_dofs, cp.z.len(), HeldAt::default())).unwrap();
    cp.path = Default::default();
    cp.id.run_id.clear();
    cp.frames = None;
    // Debug writes every f64 so that it reads back to the same bits.
    format!("{cp:?}\n{saved:?}")
}

/// Every frame of a run, as bytes (.vtu/.pvd without the run id) or, for a .vtkhdf, as
/// the values read back (Debug: exact), and the checkpoint.
fn results(dir: &Path) -> (Vec<String>, String) {
    let file = dir.join("solution.vtkhdf");
    let series: Vec<String> = if file.exists() {
        let steps = read_vtkhdf(&file).unwrap();
        (0..steps.len())
            .map(|index| {
                let frame = FrameRef::Vtkhdf {
                    path: file.clone(),
                    index,
                };
                format!("{steps:?} {:?}", read_frame(&frame).unwrap())
            })
            .collect()
    } else {
        frames(dir)
            .into_iter()
            .map(|(name, bytes)| format!("{name} {bytes:?}"))
            .collect()
    };
    assert!(
        series.len() > 2,
        "{}: {} frames",
        dir.display(),
        series.len()
    );
    (series, checkpoint(dir))
}

/// Runs `scene` with every thread count and compares each run's results with one thread's.
fn same_for_every_count(name: &str, scene: &Path, set: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let runs: Vec<_> = COUNTS
        .iter()
        .map(|&n| {
            let out = dir.path().join(format!("{name}-{n}"));
            run_with(scene, &out, n, set);
            results(&out)
        })
        .collect();
    for (n, r) in COUNTS.iter().zip(&runs).skip(1) {
        assert!(
            r.0 == runs[0].0,
            "{name}: the frames differ with {n} threads"
        );
        assert!(
            r.1 == runs[0].1,
            "{name}: the checkpoint differs with {n} threads"
        );
    }
}

#[test]
fn paper_with_memory_and_friction_is_the_same_for_every_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let scene = paper_scene(dir.path(), "paper.toml", "paper/rect_128.msh", false);
    same_for_every_count("paper", &scene, &["time.steps=16", "output.every=4"]);
}

#[test]
fn block_3d_is_the_same_for_every_thread_count() {
    let scene = repo().join("examples/block.toml");
    same_for_every_count("block", &scene, &["time.steps=8"]);
}

#[test]
fn plate_with_a_wide_root_is_the_same_for_every_thread_count() {
    let scene = repo().join("examples/block.toml");
    let mesh = repo().join("tests/data/3d/plate_005.msh");
    let mesh = format!("mesh.file={:?}", mesh.to_str().unwrap());
    same_for_every_count("plate", &scene, &["time.steps=6", &mesh]);
}

/// The duals without D on the same plate: the sparse one (each product a solve with
/// the factor, its solves split over the threads) and the matrix-free one (passes over the
/// trailing block, its rows shared out over the threads).
#[test]
fn duals_without_d_are_the_same_for_every_thread_count() {
    let scene = repo().join("examples/block.toml");
    let mesh = repo().join("tests/data/3d/plate_005.msh");
    let mesh = format!("mesh.file={:?}", mesh.to_str().unwrap());
    for solver in ["sparse", "matrix_free"] {
        let set = ["time.steps=4", &mesh, &format!("solver.contact={solver:?}")];
        same_for_every_count(&format!("plate-{solver}"), &scene, &set);
    }
}

#[test]
fn vtkhdf_run_is_the_same_for_every_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let scene = paper_scene(dir.path(), "paper.toml", "paper/rect_032.msh", false);
    let set = ["time.steps=8", "output.format=\"vtkhdf\""];
    same_for_every_count("vtkhdf", &scene, &set);
}

/// `VISCONTACT_THREADS` sets the count when `--threads` is not given; a count that is not
/// a whole number ≥ 1, from either, is refused as bad input (exit 2) saying what it wants.
#[test]
fn thread_count_from_the_environment_and_bad_counts() {
    let dir = tempfile::tempdir().unwrap();
    let scene = paper_scene(dir.path(), "paper.toml", "paper/rect_008.msh", false);
    let run = |env: &str, extra: &[&str]| {
        let out = dir.path().join(format!("out-{env}-{}", extra.len()));
        let mut args = vec!["run", scene.to_str().unwrap(), "--quiet", "--out"];
        args.push(out.to_str().unwrap());
        args.extend(extra);
        let o = Command::new(BIN)
            .args(&args)
            .env("VISCONTACT_THREADS", env)
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&o.stderr).into_owned();
        (o.status.code(), text, out)
    };
    let (code, text, out) = run("3", &[]);
    assert_eq!(code, Some(0), "{text}");
    assert_eq!(common::summary(&out)["threads"], 3);
    let (code, text, out) = run("3", &["--threads", "1"]);
    assert_eq!(code, Some(0), "{text}");
    assert_eq!(common::summary(&out)["threads"], 1);
    for bad in ["0", "two", "-1"] {
        let (code, text, out) = run(bad, &[]);
        assert_eq!(code, Some(2), "{bad}: {text}");
        assert!(
            text.contains("VISCONTACT_THREADS") && text.contains("≥ 1"),
            "{text}"
        );
        assert!(!out.exists(), "{bad}");
    }
    let (code, text, _) = run("2", &["--threads", "0"]);
    assert_eq!(code, Some(2), "{text}");
    assert!(text.contains("--threads"), "{text}");
}
