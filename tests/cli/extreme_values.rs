//! Extreme values for every numeric scene key (docs/scene_ranges.md, src/ranges.rs).
//!
//! The numeric keys are found from the scene parser itself (`common::scene::scene_keys`:
//! each key's error for a table there says what it expects). The keys that expect a number
//! must be exactly the rows of `viscontact::ranges::RANGES`, so a new numeric key cannot
//! escape its range (nor this test).
//!
//! Then each key gets a fixed set of nasty values (1e300, -0.0, 1e-320, NaN, ±∞, i64::MAX,
//! an integer beyond i64, …) and `VISCONTACT_EXTREME_CASES` random ones (default 24; seeded,
//! the seed printed, `VISCONTACT_EXTREME_SEED` repeats a run), each through `viscontact
//! check` and `viscontact run --stop-after 1` on tests/data/rect_004.msh into a directory
//! that holds an earlier run. Every process must exit 0, 1 or 2 within 20 s (killed and
//! reported otherwise): 1 only with a summary.json that says "failed", and after 2 the
//! earlier run's files are byte for byte what they were. The keys a resume may change get
//! the same through `viscontact resume --set`.

use crate::common;

use common::*;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// The bound on one process.
const LIMIT: Duration = Duration::from_secs(20);

/// A scene with every section and every numeric key present (relaxation given three ways:
/// the parser does not check that only one is), on the mesh `mesh`.
fn full_scene(mesh: &str) -> SceneText {
    SceneText::parse(
        r#"name = "extreme"
[mesh.groups]
fixed = "Γ1"
traction = "Γ2"
contact = "Γ3,1"
friction = "Γ3,2"
[time]
end = 1.0
steps = 4
[material.viscosity]
theta = 0.1
zeta = 0.1
[material.elasticity]
young = 0.1
poisson = 0.3
[material.relaxation]
prony = [[1.0, 10.0]]
expr = "exp(-10*s)"
table = { s = [0.0, 0.5, 1.0], r = [1.0, 0.3, 0.1] }
tolerance = 1e-10
horizon = 2.0
[friction]
normal_stress = 0.01
coefficient = 0.5
[contact]
[[load.traction]]
on = "top"
value = ["0", "-0.1*x*(2-x)*min(t, 0.2)"]
[[load.body]]
value = [0.0, -0.01]
[output]
every = 1
[checkpoint]
every = 2
every_seconds = 600
"#,
    )
    .mesh(mesh)
}

/// The scene a key is drawn in: the full scene with one relaxation kernel, the one the key
/// belongs to (a Prony series for the keys outside [material.relaxation]).
fn scene_for(key: &str, mesh: &str) -> SceneText {
    let scene = full_scene(mesh);
    let relax = scene
        .get("material.relaxation")
        .unwrap()
        .as_table()
        .unwrap();
    // A region's kernel is the same table on the region Ω (the whole body).
    let (region, table) = match key.strip_prefix("material.region[].") {
        Some(rest) => (true, rest),
        None => (false, key),
    };
    let keep: &[&str] = if table.starts_with("relaxation.table") {
        &["table"]
    } else if table.starts_with("relaxation.tolerance") || table.starts_with("relaxation.horizon") {
        &["expr", "tolerance", "horizon"]
    } else {
        &["prony"]
    };
    let kept: toml::Table = relax
        .iter()
        .filter(|(k, _)| keep.contains(&k.as_str()))
        .map(|(k, v)| (k.clone(), v.clone()))
        .collect();
    let prony: toml::Table = (relax.iter())
        .filter(|(k, _)| *k == "prony")
        .map(|(k, v)| (k.clone(), v.clone()))
        .collect();
    match region {
        true => (scene.set("material.relaxation", prony))
            .set("material.region[0].on", "Ω")
            .set("material.region[0].relaxation", kept),
        false => scene.set("material.relaxation", kept),
    }
}

// ---------------------------------------------------------------------------------------
// The numeric keys, as the parser knows them
// ---------------------------------------------------------------------------------------

#[test]
fn the_ranges_cover_every_numeric_key_of_the_parser() {
    // The keys that expect a number, each as its row of RANGES names it (with `[]`).
    let found: BTreeSet<String> = common::scene::scene_keys()
        .into_iter()
        .filter(|(_, msg)| msg.contains("number") || msg.contains("integer"))
        .map(|(key, _)| key.replace("[0]", "[]"))
        .collect();
    let listed: BTreeSet<String> = viscontact::ranges::RANGES
        .iter()
        .map(|r| r.key.to_string())
        .collect();
    // The probe itself works: it finds keys of every kind of nesting.
    for k in [
        "time.steps",
        "material.relaxation.prony[][]",
        "load.body[].value[]",
    ] {
        assert!(found.contains(k), "the probe missed {k}: {found:?}");
    }
    assert_eq!(
        found, listed,
        "numeric keys of the parser (left) against the rows of src/ranges.rs (right)"
    );
    // And the user's table lists every row.
    let docs = std::fs::read_to_string(repo().join("docs/scene_ranges.md")).unwrap();
    for k in &listed {
        assert!(
            docs.contains(&format!("`{k}`")),
            "docs/scene_ranges.md lacks {k}"
        );
    }
}

// ---------------------------------------------------------------------------------------
// The values
// ---------------------------------------------------------------------------------------

/// The TOML text of each nasty value, always tried (the last one is no TOML integer).
fn nasty() -> Vec<String> {
    let f = |v: f64| toml::Value::Float(v).to_string();
    let mut v: Vec<String> = [1e300, -0.0, 1e-320, f64::NAN, f64::INFINITY]
        .into_iter()
        .chain([f64::NEG_INFINITY, 2e19, 1e-101])
        .map(f)
        .collect();
    v.extend([i64::MAX, i64::MIN, -1].map(|i| i.to_string()));
    v.push("18446744073709551616".into());
    v
}

/// A random value: any bit pattern as a double, a power of ten, any i64, a small integer,
/// or an ordinary number.
fn draw(rng: &mut SplitMix) -> String {
    let sign = if rng.next() & 1 == 0 { 1.0 } else { -1.0 };
    let v = match rng.below(5) {
        0 => toml::Value::Float(f64::from_bits(rng.next())),
        1 => toml::Value::Float(sign * 10f64.powi(rng.below(661) as i32 - 330)),
        2 => toml::Value::Integer(rng.next() as i64),
        3 => toml::Value::Integer(rng.below(24) as i64 - 3),
        _ => toml::Value::Float(sign * 2.0 * rng.unit()),
    };
    v.to_string()
}

/// The path of `key` (a row of RANGES) with each `[]` an element: the first, or for the
/// pair of a Prony term, either.
fn path_of(key: &str, rng: &mut SplitMix) -> String {
    if let Some(prefix) = key.strip_suffix("prony[][]") {
        format!("{}prony[0][{}]", prefix.replace("[]", "[0]"), rng.below(2))
    } else {
        key.replace("[]", "[0]")
    }
}

/// The scene text with `value` (TOML text, which may be no TOML value: an integer beyond
/// i64) at `key`.
fn scene_text(key: &str, value: &str, mesh: &str, rng: &mut SplitMix) -> String {
    const MARK: &str = "@@value@@";
    scene_for(key, mesh)
        .set(&path_of(key, rng), MARK)
        .text()
        .replace(&format!("{MARK:?}"), value)
}

// ---------------------------------------------------------------------------------------
// Running a case
// ---------------------------------------------------------------------------------------

/// A bounded process: its exit status (None: a signal), or Err after the limit (killed).
fn bounded(args: &[&str], log: &Path) -> Result<Option<i32>, String> {
    let file = std::fs::File::create(log).unwrap();
    let mut child = Command::new(BIN)
        .args(args)
        .current_dir(repo())
        .stdout(Stdio::null())
        .stderr(file)
        .spawn()
        .unwrap();
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            return Ok(status.code());
        }
        if start.elapsed() > LIMIT {
            child.kill().unwrap();
            child.wait().unwrap();
            return Err(format!("no exit within {LIMIT:?}: killed"));
        }
        std::thread::sleep(Duration::from_millis(3));
    }
}

/// The name and bytes of every file in `dir`.
fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap())
        .map(|e| {
            let bytes = std::fs::read(e.path()).unwrap_or_default();
            (e.file_name().to_string_lossy().into_owned(), bytes)
        })
        .collect()
}

/// What is wrong with an exit status of a run (or resume) into `out`, which held `before`.
fn judge(code: Option<i32>, out: &Path, before: &BTreeMap<String, Vec<u8>>) -> Option<String> {
    match code {
        Some(0) => None,
        Some(1) => {
            let status = std::fs::read_to_string(out.join("summary.json"))
                .ok()
                .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
                .and_then(|v| v["status"].as_str().map(String::from));
            (status.as_deref() != Some("failed"))
                .then(|| format!("exit 1 but summary.json says {status:?}"))
        }
        Some(2) => {
            let after = files(out);
            (after != *before).then(|| {
                let names = |m: &BTreeMap<String, Vec<u8>>| m.keys().cloned().collect::<Vec<_>>();
                format!(
                    "exit 2 changed the earlier run: {:?} -> {:?} (or their bytes)",
                    names(before),
                    names(&after)
                )
            })
        }
        other => Some(format!(
            "exit status {other:?} (a panic, an abort or a signal)"
        )),
    }
}

/// One case: `check` and `run --stop-after 1` of the scene with `value` at `key`, in
/// `dir`, whose `out` starts as a copy of `earlier`. The exit statuses or what went wrong.
fn run_case(dir: &Path, earlier: &Path, text: &str) -> Result<[i32; 2], String> {
    let scene = write(dir, "scene.toml", text);
    let out = dir.join("out");
    copy_dir(earlier, &out);
    let before = files(&out);
    let log = dir.join("log.txt");
    let s = scene.to_str().unwrap();
    let check = bounded(&["check", s], &log)?;
    if !matches!(check, Some(0..=2)) {
        return Err(format!("check: exit status {check:?}: {}", read(&log)));
    }
    let args = [
        "run",
        s,
        "--out",
        out.to_str().unwrap(),
        "--stop-after",
        "1",
    ];
    let run = bounded(&args, &log)?;
    match judge(run, &out, &before) {
        Some(why) => Err(format!("run: {why}: {}", read(&log))),
        None => Ok([check.unwrap(), run.unwrap()]),
    }
}

fn read(p: &Path) -> String {
    let t = std::fs::read_to_string(p).unwrap_or_default();
    t.chars().take(400).collect()
}

/// The earlier run every case's output directory starts from: `scene` run to its end.
fn earlier_run(dir: &Path, mesh: &str) -> PathBuf {
    let scene = write(dir, "earlier.toml", &scene_text_plain(mesh));
    let out = dir.join("earlier");
    let (code, text) = cli(&[
        "run",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{text}");
    out
}

fn scene_text_plain(mesh: &str) -> String {
    scene_for("", mesh).text()
}

/// Runs `cases` (key, value) on two threads; returns the failures and the count of each
/// pair of exit statuses.
fn run_all(
    cases: &[(String, String, String)],
    earlier: &Path,
    tmp: &Path,
) -> (Vec<String>, BTreeMap<[i32; 2], usize>) {
    let next = AtomicUsize::new(0);
    let results = Mutex::new((Vec::new(), BTreeMap::new()));
    std::thread::scope(|s| {
        for _ in 0..2 {
            s.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::SeqCst);
                let Some((key, value, text)) = cases.get(i) else {
                    return;
                };
                let dir = tmp.join(format!("case{i}"));
                std::fs::create_dir_all(&dir).unwrap();
                let r = run_case(&dir, earlier, text);
                let mut res = results.lock().unwrap();
                match r {
                    Ok(codes) => *res.1.entry(codes).or_insert(0) += 1,
                    Err(why) => res.0.push(format!("{key} = {value}: {why}")),
                }
                drop(res);
                let _ = std::fs::remove_dir_all(&dir);
            });
        }
    });
    results.into_inner().unwrap()
}

fn env_or(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

#[test]
fn no_scene_value_panics_aborts_hangs_or_destroys_the_earlier_run() {
    let tmp = tempfile::tempdir().unwrap();
    let mesh = repo().join("tests/data/rect_004.msh").display().to_string();
    let earlier = earlier_run(tmp.path(), &mesh);
    let seed = env_or(
        "VISCONTACT_EXTREME_SEED",
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_nanos() as u64,
    );
    let random = env_or("VISCONTACT_EXTREME_CASES", 24) as usize;
    println!("extreme values: seed {seed} (VISCONTACT_EXTREME_SEED), {random} random cases");
    let mut rng = SplitMix(seed);
    let keys: Vec<&str> = viscontact::ranges::RANGES.iter().map(|r| r.key).collect();
    let mut cases = Vec::new();
    for key in &keys {
        for value in nasty() {
            let text = scene_text(key, &value, &mesh, &mut rng);
            cases.push((key.to_string(), value, text));
        }
    }
    for _ in 0..random {
        let key = keys[rng.below(keys.len())];
        let value = draw(&mut rng);
        let text = scene_text(key, &value, &mesh, &mut rng);
        cases.push((key.to_string(), value, text));
    }
    let (failures, counts) = run_all(&cases, &earlier, tmp.path());
    println!(
        "{} cases; (check, run) exit statuses: {counts:?}",
        cases.len()
    );
    assert!(
        failures.is_empty(),
        "seed {seed}: {} of {} cases failed:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n")
    );
    // Not everything was refused: the draws reach the solver too.
    assert!(counts.keys().any(|c| c[1] == 0), "{counts:?}");
}

// ---------------------------------------------------------------------------------------
// Resume, and finding 1 of issue 26
// ---------------------------------------------------------------------------------------

/// A run of the plain scene stopped after step 1: its directory holds checkpoint.h5.
fn stopped_run(dir: &Path, mesh: &str) -> PathBuf {
    let scene = write(dir, "stopped.toml", &scene_text_plain(mesh));
    let out = dir.join("stopped");
    let args = [
        "run",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    let (code, text) = cli(&[&args[..], &["--stop-after", "1"]].concat());
    assert_eq!(code, 0, "{text}");
    out
}

/// `resume --set KEY=VALUE` of a copy of the stopped run in `dir`: its exit status, or what
/// went wrong.
fn resume_case(dir: &Path, stopped: &Path, set: &str) -> Result<i32, String> {
    let out = dir.join("out");
    let _ = std::fs::remove_dir_all(&out);
    copy_dir(stopped, &out);
    let before = files(&out);
    let log = dir.join("resume.txt");
    let cp = out.join("checkpoint.h5");
    let code = bounded(&["resume", cp.to_str().unwrap(), "--set", set], &log)?;
    match judge(code, &out, &before) {
        Some(why) => Err(format!("resume --set {set}: {why}: {}", read(&log))),
        None => Ok(code.unwrap()),
    }
}

#[test]
fn no_value_a_resume_may_set_panics_or_destroys_the_run() {
    let tmp = tempfile::tempdir().unwrap();
    let mesh = repo().join("tests/data/rect_004.msh").display().to_string();
    let stopped = stopped_run(tmp.path(), &mesh);
    let keys = [
        "time.end",
        "output.every",
        "checkpoint.every",
        "checkpoint.every_seconds",
    ];
    let mut failures = Vec::new();
    let mut counts = BTreeMap::new();
    // The ordinary values show that a resume gets through: 2.0 is 8 steps of k = 0.25.
    let ordinary = ["2.0".to_string(), "3".to_string()];
    for key in keys {
        for value in nasty().iter().chain(&ordinary) {
            match resume_case(tmp.path(), &stopped, &format!("{key}={value}")) {
                Ok(code) => *counts.entry(code).or_insert(0) += 1,
                Err(why) => failures.push(why),
            }
        }
    }
    println!("resume exit statuses: {counts:?}");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    assert!(counts.contains_key(&0), "{counts:?}");
}

/// Issue 26, finding 1: `checkpoint.every_seconds` beyond what a Duration holds (≈ 1.8e19
/// s) passed `check`, and `run` deleted the earlier run, then panicked converting it.
#[test]
fn every_seconds_beyond_a_duration_is_refused_before_the_directory_is_touched() {
    let tmp = tempfile::tempdir().unwrap();
    let mesh = repo().join("tests/data/rect_004.msh").display().to_string();
    let earlier = earlier_run(tmp.path(), &mesh);
    let stopped = stopped_run(tmp.path(), &mesh);
    let mut rng = SplitMix(26);
    for value in ["2e19", "1e300"] {
        let key = "checkpoint.every_seconds";
        let dir = tmp.path().join(value);
        std::fs::create_dir_all(&dir).unwrap();
        let text = scene_text(key, value, &mesh, &mut rng);
        assert_eq!(
            run_case(&dir, &earlier, &text),
            Ok([2, 2]),
            "{key} = {value}"
        );
        let (_, message) = cli(&["check", dir.join("scene.toml").to_str().unwrap()]);
        assert!(
            message.contains(&format!("'{key}' is {value}")) && message.contains("≤ 1e9"),
            "{message}"
        );
        let set = format!("{key}={value}");
        assert_eq!(
            resume_case(&dir, &stopped, &set),
            Ok(2),
            "resume --set {set}"
        );
    }
}
