//! Resume verifies the series it continues (issue 26; docs/restart.md "What resume
//! verifies"): every frame the checkpoint recorded must be on disk with the bytes it had, or
//! `resume` exits 2 naming the frames and what to do and changes nothing; a `.pvd` is
//! rebuilt from the verified frames; a `solution.vtkhdf` with damaged metadata or frames is
//! refused before anything is appended, and a resumed one is read in full by h5py and VTK.

use crate::common;

use common::{assert_same_series, copy_dir, paper_scene, viscontact, SplitMix};
use hdf5_metno as hdf5;
use std::path::{Path, PathBuf};

const VTKHDF: &str = "output.format=\"vtkhdf\"";

/// `viscontact ARGS` from the repository root with `--set` overrides: (exit code, stderr).
fn cli(args: &[&str], set: &[&str]) -> (Option<i32>, String) {
    let mut all: Vec<&str> = args.to_vec();
    for s in set {
        all.extend(["--set", s]);
    }
    all.push("--quiet");
    let o = viscontact(&all);
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// The paper scene on rect_008 (32 steps, a frame every step): run whole into `full`, and
/// into `part` stopped after step `stop` (checkpoint at step `stop` + 1).
fn runs(tmp: &Path, set: &[&str], stop: usize) -> (PathBuf, PathBuf, PathBuf) {
    let scene = paper_scene(tmp, "s.toml", "paper/rect_008.msh", false);
    let s = scene.to_str().unwrap();
    let (full, part) = (tmp.join("full"), tmp.join("part"));
    let stop = stop.to_string();
    for (dir, extra) in [(&full, &[][..]), (&part, &["--stop-after", &stop[..]][..])] {
        let mut args = vec!["run", s, "--out", dir.to_str().unwrap()];
        args.extend(extra);
        let (code, err) = cli(&args, set);
        assert_eq!(code, Some(0), "{err}");
    }
    (scene, full, part)
}

/// Resumes `dir`'s checkpoint and expects exit 2 with every needle in the message and the
/// directory as it was.
fn refused(case: &str, dir: &Path, needles: &[&str]) {
    let before = common::dir_contents(dir);
    let cp = dir.join("checkpoint.h5");
    let (code, err) = cli(&["resume", cp.to_str().unwrap()], &[]);
    assert_eq!(code, Some(2), "[{case}] {err}");
    for n in needles {
        assert!(err.contains(n), "[{case}] message lacks {n:?}: {err}");
    }
    assert!(
        common::dir_contents(dir) == before,
        "[{case}] resume changed the directory"
    );
}

/// A fresh copy of the stopped run `part` as `tmp/name`.
fn copy_of(part: &Path, tmp: &Path, name: &str) -> PathBuf {
    let dir = tmp.join(name);
    copy_dir(part, &dir);
    dir
}

#[test]
fn a_vtu_series_with_missing_damaged_or_foreign_frames_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let (scene, full, part) = runs(tmp.path(), &[], 11);
    let t = tmp.path();

    let d = copy_of(&part, t, "missing");
    for s in 4..=6 {
        std::fs::remove_file(d.join(format!("solution_{s:06}.vtu"))).unwrap();
    }
    refused(
        "frames deleted",
        &d,
        &[
            "3 frames missing: steps 4–6 (solution_000004.vtu, …)",
            "cannot be recomputed from this checkpoint (step 12",
            "--out NEW",
            "Nothing was changed",
        ],
    );

    let d = copy_of(&part, t, "flipped");
    let frame = d.join("solution_000007.vtu");
    let mut bytes = std::fs::read(&frame).unwrap();
    let at = bytes.len() / 2;
    bytes[at] ^= 0x10;
    std::fs::write(&frame, bytes).unwrap();
    refused(
        "a flipped byte",
        &d,
        &["1 frame damaged", "step 7 (solution_000007.vtu)", "CRC-32"],
    );

    // The uninterrupted run's frame 3: the same physics, another run id.
    let d = copy_of(&part, t, "foreign frame");
    std::fs::copy(
        full.join("solution_000003.vtu"),
        d.join("solution_000003.vtu"),
    )
    .unwrap();
    let full_id = common::summary(&full)["run_id"]
        .as_str()
        .unwrap()
        .to_string();
    refused(
        "a frame of another run",
        &d,
        &[&format!("of another run (run id {full_id}): step 3")],
    );

    // Another stopped run's checkpoint, history, summary and .pvd beside this run's frames.
    let other = t.join("other");
    let (code, err) = cli(
        &[
            "run",
            scene.to_str().unwrap(),
            "--out",
            other.to_str().unwrap(),
            "--stop-after",
            "11",
        ],
        &[],
    );
    assert_eq!(code, Some(0), "{err}");
    let d = copy_of(&part, t, "foreign checkpoint");
    for name in ["checkpoint.h5", "summary.json", "solution.pvd"] {
        std::fs::copy(other.join(name), d.join(name)).unwrap();
    }
    let part_id = common::summary(&part)["run_id"]
        .as_str()
        .unwrap()
        .to_string();
    refused(
        "another run's checkpoint",
        &d,
        &[&format!(
            "12 frames of another run (run id {part_id}): steps 0–11"
        )],
    );
}

#[test]
fn a_missing_pvd_is_rebuilt_and_a_format_2_checkpoint_resumes_unverified() {
    let tmp = tempfile::tempdir().unwrap();
    let (_, full, part) = runs(tmp.path(), &[], 11);
    let d = copy_of(&part, tmp.path(), "no pvd");
    std::fs::remove_file(d.join("solution.pvd")).unwrap();
    let cp = d.join("checkpoint.h5");
    let (code, err) = cli(&["resume", cp.to_str().unwrap()], &[]);
    assert_eq!(code, Some(0), "{err}");
    assert_same_series(&d, &full, "resumed without its .pvd");

    // The same checkpoint as format version 2 (no frame checksums): resumed as before, with a
    // warning, and bit for bit the run that never stopped.
    let d = copy_of(&part, tmp.path(), "v2");
    let cp = d.join("checkpoint.h5");
    let f = hdf5::File::open_rw(&cp).unwrap();
    f.attr("format_version")
        .unwrap()
        .write_scalar(&2u32)
        .unwrap();
    f.close().unwrap();
    viscontact::checkpoint::reseal(&cp).unwrap();
    let (code, err) = cli(&["resume", cp.to_str().unwrap()], &[]);
    assert_eq!(code, Some(0), "{err}");
    assert!(err.contains("warning:"), "{err}");
    assert!(err.contains("without verifying it"), "{err}");
    assert_same_series(&d, &full, "resumed from a format-2 checkpoint");
}

/// python3 scripts/check_vtkhdf.py FILE --digest: VTK's vtkHDFReader reads the steps and h5py
/// every dataset; (steps, digest of every dataset but the run id).
fn read_in_full(file: &Path) -> (serde_json::Value, serde_json::Value) {
    let v = common::check_vtkhdf(file, &["--digest"]);
    (v["steps"].clone(), v["digest"].clone())
}

#[test]
fn an_older_vtkhdf_of_the_same_run_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let (_, _, part) = runs(tmp.path(), &[VTKHDF], 5);
    let file = part.join("solution.vtkhdf");
    let old = tmp.path().join("old.vtkhdf");
    std::fs::copy(&file, &old).unwrap();
    let cp = part.join("checkpoint.h5");
    let (code, err) = cli(&["resume", cp.to_str().unwrap(), "--stop-after", "20"], &[]);
    assert_eq!(code, Some(0), "{err}");
    std::fs::copy(&old, &file).unwrap();
    refused(
        "frames 0-5 of 0-20",
        &part,
        &[
            "solution.vtkhdf",
            "15 frames missing: steps 6–20",
            "cannot be recomputed from this checkpoint (step 21",
        ],
    );
    std::fs::remove_file(&file).unwrap();
    refused("no file", &part, &["21 frames missing: steps 0–20"]);
}

/// The byte ranges of `file` that hold no chunk of any dataset: the superblock, object
/// headers, chunk indexes, the few contiguous values and free space.
fn outside_chunks(file: &Path, len: usize) -> Vec<(usize, usize)> {
    fn chunks(g: &hdf5::Group, out: &mut Vec<(usize, usize)>) {
        for ds in g.datasets().unwrap() {
            for i in 0..ds.num_chunks().unwrap_or(0) {
                let c = ds.chunk_info(i).unwrap();
                out.push((c.addr as usize, (c.addr + c.size) as usize));
            }
        }
        for sub in g.groups().unwrap() {
            chunks(&sub, out);
        }
    }
    let mut inside = Vec::new();
    chunks(&hdf5::File::open(file).unwrap(), &mut inside);
    inside.sort();
    let mut outside = Vec::new();
    let mut at = 0;
    for (from, to) in inside.into_iter().chain([(len, len)]) {
        if from > at {
            outside.push((at, from));
        }
        at = at.max(to);
    }
    outside
}

/// A byte drawn uniformly from `ranges`.
fn byte_in(ranges: &[(usize, usize)], rng: &mut SplitMix) -> usize {
    let mut k = rng.below(ranges.iter().map(|(a, b)| b - a).sum());
    for (from, to) in ranges {
        if k < to - from {
            return from + k;
        }
        k -= to - from;
    }
    unreachable!("k is below the total length")
}

/// Seeded bit flips in a stopped run's solution.vtkhdf, in its first 8 KB, its last 64 KB
/// and anywhere outside its chunks (the HDF5 metadata: superblock, object headers, chunk
/// indexes): each resume either exits 2 leaving the file as it was, or completes with a file
/// that VTK and h5py read in full and whose datasets equal the uninterrupted run's. The
/// chunk indexes are the checksummed ones of the HDF5 1.10 format (src/output/vtkhdf.rs,
/// "File format"); in the 1.8 format's B-tree 1 a flip (the node of /VTKHDF/Connectivity)
/// passed HDF5 1.10 and broke the resumed file for HDF5 1.14 and 2.0.
#[test]
fn flipped_bits_in_a_vtkhdf_are_refused_or_harmless() {
    if !common::python_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let (_, full, part) = runs(tmp.path(), &[VTKHDF], 20);
    let want = read_in_full(&full.join("solution.vtkhdf"));
    let len = std::fs::metadata(part.join("solution.vtkhdf"))
        .unwrap()
        .len() as usize;
    let flips = if std::env::var_os("CI").is_some() {
        6
    } else {
        30
    };
    let regions = [
        ("head", vec![(0, 8192.min(len))]),
        ("tail", vec![(len.saturating_sub(65536), len)]),
        (
            "metadata",
            outside_chunks(&part.join("solution.vtkhdf"), len),
        ),
    ];
    let mut rng = SplitMix(26);
    let (mut refused_n, mut harmless) = (0, 0);
    for (region, ranges) in &regions {
        for i in 0..flips {
            let d = copy_of(&part, tmp.path(), &format!("{region}{i}"));
            let file = d.join("solution.vtkhdf");
            let mut bytes = std::fs::read(&file).unwrap();
            let at = byte_in(ranges, &mut rng);
            bytes[at] ^= 1 << rng.below(8);
            std::fs::write(&file, &bytes).unwrap();
            let cp = d.join("checkpoint.h5");
            let (code, err) = cli(&["resume", cp.to_str().unwrap()], &[]);
            let case = format!("{region} byte {at}");
            match code {
                Some(2) => {
                    assert!(err.contains("solution.vtkhdf"), "[{case}] {err}");
                    assert!(
                        std::fs::read(&file).unwrap() == bytes,
                        "[{case}] file changed"
                    );
                    refused_n += 1;
                }
                Some(0) => {
                    assert_eq!(read_in_full(&file), want, "[{case}] differs");
                    harmless += 1;
                }
                other => panic!("[{case}] exit {other:?}: {err}"),
            }
            std::fs::remove_dir_all(&d).unwrap();
        }
    }
    eprintln!(
        "{} flips: {refused_n} refused, {harmless} harmless",
        regions.len() * flips
    );
}
