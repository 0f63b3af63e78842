//! Helpers shared by the integration tests.
#![allow(dead_code)]

pub mod scene;
pub use scene::SceneText;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use viscontact::fem::Discretization;
use viscontact::mesh::Mesh;
use viscontact::scene::Scene;
use viscontact::time_loop::{Solved, TimeLoop};

/// The viscontact binary.
pub const BIN: &str = env!("CARGO_BIN_EXE_viscontact");

/// The repository root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A shipped mesh by its path below meshes/.
pub fn mesh_path(rel: &str) -> String {
    repo().join("meshes").join(rel).display().to_string()
}

/// Writes `text` as `name` into `dir` and returns its path.
pub fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// Loads a scene with overrides, its mesh and discretization.
pub fn load(scene: &Path, overrides: &[&str]) -> (Scene, Mesh, Discretization) {
    let o: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    viscontact::run::setup(scene, &o).unwrap()
}

/// The scene's solver resolved on its discretization (`solver::choice::Descriptor`).
pub fn descriptor(scene: &Scene, disc: &Discretization) -> viscontact::solver::choice::Descriptor {
    viscontact::solver::choice::Descriptor::of_run(scene, disc).unwrap()
}

/// Result of running a scene through the library: per step (u_n, w_n, z_n), and u_N.
pub struct Trace {
    pub u: Vec<Vec<f64>>,
    pub w: Vec<Vec<f64>>,
    pub z: Vec<Vec<f64>>,
    pub u_final: Vec<f64>,
    pub effects: Vec<&'static str>,
    pub solver: &'static str,
}

/// Runs all steps n = 0..=N and records them.
pub fn trace(scene: &Scene, disc: &Discretization) -> Trace {
    let mut tl = TimeLoop::new(scene, disc).unwrap();
    let (mut u, mut w, mut z) = (Vec::new(), Vec::new(), Vec::new());
    let mut record = |s: &Solved| {
        u.push(s.step.u.to_vec());
        w.push(s.step.w.to_vec());
        z.push(s.step.z.to_vec());
        Ok(())
    };
    tl.run(scene.time.steps, &mut record).unwrap();
    Trace {
        u,
        w,
        z,
        u_final: tl.u().to_vec(),
        effects: tl.effects().names(),
        solver: tl.solver().name(),
    }
}

pub fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0f64, |a, x| a.max(x.abs()))
}

/// max|a − b| / max|b|.
pub fn rel_diff(a: &[f64], b: &[f64]) -> f64 {
    let d = a
        .iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    d / max_abs(b).max(f64::MIN_POSITIVE)
}

/// The text of an ASCII MSH 4.1 file with every node's coordinates mapped by `f` (the
/// `$Nodes` section; entity bounding boxes are left as they are, nothing reads them).
pub fn map_msh_nodes(text: &str, f: impl Fn([f64; 3]) -> [f64; 3]) -> String {
    let mut out = String::with_capacity(text.len());
    let mut lines = text.lines();
    while let Some(line) = lines.next() {
        out.push_str(line);
        out.push('\n');
        if line.trim() != "$Nodes" {
            continue;
        }
        let header = lines.next().unwrap();
        out.push_str(header);
        out.push('\n');
        let blocks: usize = header.split_whitespace().next().unwrap().parse().unwrap();
        for _ in 0..blocks {
            let block = lines.next().unwrap();
            out.push_str(block);
            out.push('\n');
            let b: Vec<usize> = block
                .split_whitespace()
                .map(|v| v.parse().unwrap())
                .collect();
            assert_eq!(b[2], 0, "parametric nodes are not mapped");
            for _ in 0..b[3] {
                out.push_str(lines.next().unwrap());
                out.push('\n');
            }
            for _ in 0..b[3] {
                let x: Vec<f64> = lines
                    .next()
                    .unwrap()
                    .split_whitespace()
                    .map(|v| v.parse().unwrap())
                    .collect();
                let y = f([x[0], x[1], x[2]]);
                out.push_str(&format!("{:e} {:e} {:e}\n", y[0], y[1], y[2]));
            }
        }
    }
    out
}

/// Every .msh file under the repository's meshes/, sorted.
pub fn shipped_meshes() -> Vec<PathBuf> {
    repo_files("meshes", "msh")
}

/// Every file ending in `.ext` under the repository's folder `dir`, sorted.
pub fn repo_files(dir: &str, ext: &str) -> Vec<PathBuf> {
    fn walk(dir: &Path, ext: &str, out: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(&p, ext, out);
            } else if p.extension().is_some_and(|x| x == ext) {
                out.push(p);
            }
        }
    }
    let mut files = Vec::new();
    walk(&repo().join(dir), ext, &mut files);
    files.sort();
    files
}

/// Runs the binary from the repository root: (exit status, stdout + stderr).
pub fn cli(args: &[&str]) -> (i32, String) {
    let out = viscontact(args);
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.code().unwrap_or(-1), text)
}

/// examples/paper.toml (contact on Γ3,1, friction on Γ3,2, Prony memory) on the shipped
/// `mesh`; `expr` switches the kernel to the same function as an expression (the direct-sum
/// path).
pub fn paper(mesh: &str, expr: bool) -> SceneText {
    let scene = SceneText::paper().mesh(mesh_path(mesh));
    if expr {
        scene.table(
            "material.relaxation",
            "expr = \"exp(-10*s)\"\nmemory = \"exact\"",
        )
    } else {
        scene
    }
}

/// [`paper`] written as `name` into `dir`.
pub fn paper_scene(dir: &Path, name: &str, mesh: &str, expr: bool) -> PathBuf {
    paper(mesh, expr).write(dir, name)
}

/// summary.json of a run directory.
pub fn summary(dir: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(dir.join("summary.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

/// summary.json without what legitimately differs between two runs: wall times, the
/// output directory and the work of this process (the active-set solver's Newton systems
/// and Krylov iterations since the start or the resume).
pub fn summary_values(dir: &Path) -> serde_json::Value {
    let mut v = summary(dir);
    v.as_object_mut().unwrap().remove("timing");
    v.as_object_mut().unwrap().remove("run_id");
    v["output"].as_object_mut().unwrap().remove("directory");
    if let Some(memory) = v.get_mut("memory").and_then(|m| m.as_object_mut()) {
        memory.remove("fit_s"); // the compressed kernel's fit, a wall time
    }
    if let Some(petsc) = v.get_mut("petsc").and_then(|p| p.as_object_mut()) {
        petsc.remove("newton");
    }
    v
}

/// Every file of `dir` that a run's series consists of (the pieces of a `.pvtu` frame as
/// `solution_NNNNNN/NAME`), and its history.csv, by name, run ids taken out.
pub fn frames(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let series = |n: &str| {
        let ours = !n.contains('/') || n.starts_with("solution_");
        ours && ([".vtu", ".pvtu", ".pvd"].iter().any(|x| n.ends_with(x)) || n == "history.csv")
    };
    (dir_contents(dir).into_iter())
        .filter(|(n, _)| series(n))
        .map(|(n, bytes)| (n, without_run_id(bytes)))
        .collect()
}

/// A run's history.csv: its header and its rows as numbers.
pub struct History {
    pub header: Vec<String>,
    pub rows: Vec<Vec<f64>>,
}

impl History {
    pub fn read(dir: &Path) -> History {
        let text = std::fs::read_to_string(dir.join("history.csv")).unwrap();
        let mut lines = text.lines();
        let header = lines.next().unwrap().split(',').map(String::from).collect();
        let rows = lines
            .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
            .collect();
        History { header, rows }
    }

    /// The values of column `name` at every step.
    pub fn column(&self, name: &str) -> Vec<f64> {
        let i = (self.header.iter().position(|h| h == name))
            .unwrap_or_else(|| panic!("no column {name} in {:?}", self.header));
        self.rows.iter().map(|r| r[i]).collect()
    }

    /// Every row's forces balance: per component |Σ forces| ≤ 1e-10 max |force| (the
    /// moments apart).
    pub fn assert_balanced(&self, what: &str) {
        let axes = match self.header.iter().any(|n| n.ends_with("_z")) {
            true => &["x", "y", "z"][..],
            false => &["x", "y"][..],
        };
        for (n, row) in self.rows.iter().enumerate() {
            for axis in axes {
                let terms: Vec<f64> = (self.header.iter().zip(row))
                    .filter(|(name, _)| name.ends_with(&format!("_{axis}")))
                    .filter(|(name, _)| !name.starts_with("moment_"))
                    .map(|(_, v)| *v)
                    .collect();
                let sum: f64 = terms.iter().sum();
                let max = terms.iter().fold(0.0f64, |a, v| a.max(v.abs()));
                assert!(
                    sum.abs() <= 1e-10 * max,
                    "{what}, step {n}, {axis}: Σ forces = {sum:e}, max |force| = {max:e}"
                );
            }
        }
    }
}

/// The bytes of a series file without its run id (the `<FieldData>` of a `.vtu`, the
/// `<!-- run_id: … -->` comment of the `.pvd`): two runs of one scene differ only there.
pub fn without_run_id(mut bytes: Vec<u8>) -> Vec<u8> {
    let find = |b: &[u8], pat: &[u8], from: usize| {
        b[from..]
            .windows(pat.len())
            .position(|w| w == pat)
            .map(|p| p + from)
    };
    for (open, close) in [
        (&b"<FieldData>"[..], &b"</FieldData>"[..]),
        (b"<!-- run_id:", b"-->"),
    ] {
        if let Some(a) = find(&bytes, open, 0) {
            let b = find(&bytes, close, a).expect("closed") + close.len();
            bytes.drain(a..b);
        }
    }
    bytes
}

pub fn assert_same_series(a: &Path, b: &Path, what: &str) {
    let (fa, fb) = (frames(a), frames(b));
    assert_eq!(
        fa.keys().collect::<Vec<_>>(),
        fb.keys().collect::<Vec<_>>(),
        "{what}: the series differ in their files"
    );
    for (name, bytes) in &fa {
        assert!(bytes == &fb[name], "{what}: {name} differs");
    }
    assert_eq!(
        summary_values(a),
        summary_values(b),
        "{what}: summary.json differs"
    );
}

/// Runs the binary from the repository root.
pub fn viscontact(args: &[&str]) -> Output {
    viscontact_in(&repo(), args)
}

/// Runs the binary from the repository root with `VISCONTACT_MEMORY` = `memory` bytes, a
/// smaller machine.
pub fn with_memory(memory: f64, args: &[&str]) -> Output {
    Command::new(BIN)
        .args(args)
        .env(viscontact::resources::MEMORY_ENV, format!("{memory}"))
        .current_dir(repo())
        .output()
        .unwrap()
}

/// Runs the binary from the working directory `cwd`.
pub fn viscontact_in(cwd: &Path, args: &[&str]) -> Output {
    Command::new(BIN)
        .args(args)
        .current_dir(cwd)
        .output()
        .unwrap()
}

/// Spawns `viscontact ARGS`, waits until `dir` holds the frame of step `at`, sends
/// `signals` (`kill -s SIGNAL` each, in order) and waits for the process: its exit status
/// and stderr.
pub fn signal_at_frame(
    args: &[&str],
    dir: &Path,
    at: usize,
    signals: &[&str],
) -> (std::process::ExitStatus, String) {
    let frame = dir.join(format!("solution_{at:06}.vtu"));
    signal_when(
        args,
        || frame.exists(),
        &frame.display().to_string(),
        signals,
    )
}

/// Spawns `viscontact ARGS`, waits until `ready()` (polled every 2 ms; `what` names what is
/// awaited in the panic after 120 s), sends `signals` (`kill -s SIGNAL` each, in order) and
/// waits for the process: its exit status and stderr.
pub fn signal_when(
    args: &[&str],
    ready: impl Fn() -> bool,
    what: &str,
    signals: &[&str],
) -> (std::process::ExitStatus, String) {
    use std::io::Read;
    let mut child = Command::new(BIN)
        .args(args)
        .current_dir(repo())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let start = std::time::Instant::now();
    while !ready() {
        assert!(
            start.elapsed().as_secs() < 120,
            "{what} never appeared ({args:?})"
        );
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    for signal in signals {
        let kill = Command::new("kill")
            .args(["-s", signal, &child.id().to_string()])
            .status()
            .unwrap();
        assert!(kill.success(), "kill -s {signal} failed");
    }
    let mut stderr = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    (child.wait().unwrap(), stderr)
}

/// The environment variable `name` parsed as a `T` (a test's size or seed), else `default`.
pub fn env_or<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// Waits at most `limit` for `child`: its exit code, or minus the signal that ended it (a
/// hang fails the test, naming `what`, after killing the process).
pub fn exit_within(child: &mut std::process::Child, limit: std::time::Duration, what: &str) -> i32 {
    use std::os::unix::process::ExitStatusExt;
    let start = std::time::Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            return status
                .code()
                .unwrap_or_else(|| -status.signal().unwrap_or(0));
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{what}: no exit within {limit:?}");
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
}

/// Starts `viscontact ARGS` (from the repository root, its output discarded), waits
/// `delay`, sends `signals`, each after its gap, and waits at most `limit` for the process:
/// its exit code, or minus the signal that ended it (a hang fails the test).
pub fn signalled(
    args: &[&str],
    delay: std::time::Duration,
    signals: &[(i32, std::time::Duration)],
    limit: std::time::Duration,
) -> i32 {
    use std::process::Stdio;
    let mut child = Command::new(BIN)
        .args(args)
        .current_dir(repo())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(delay);
    for &(signal, gap) in signals {
        std::thread::sleep(gap);
        // SAFETY: kill(2) on our own child's pid.
        unsafe { libc::kill(child.id() as i32, signal) };
    }
    let what = format!("{args:?} after {delay:?}, signals {signals:?}");
    exit_within(&mut child, limit, &what)
}

/// Copies the files of `from` (not recursive) into a new directory `to`.
pub fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        if e.file_type().unwrap().is_file() {
            std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
        }
    }
}

/// The tests' one pseudo-random sequence (splitmix64): seeded, so that "random" angles, bit
/// positions, values and moments are the same in every run of a test (and a failing seed
/// can be given back).
pub struct SplitMix(pub u64);

impl SplitMix {
    pub fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in 0..n.
    pub fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }

    /// Uniform in [0, 1), 53 bits.
    pub fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// One of `from`, uniformly.
    pub fn pick<T: Copy>(&mut self, from: &[T]) -> T {
        from[self.below(from.len())]
    }
}

/// Options of a library run into `out` with `--set` overrides, no progress bar.
pub fn run_options(
    out: &Path,
    set: &[&str],
    stop_after: Option<usize>,
) -> viscontact::run::RunOptions {
    viscontact::run::RunOptions {
        out: Some(out.to_path_buf()),
        overrides: set.iter().map(|s| s.to_string()).collect(),
        progress: false,
        stop_after,
        ..Default::default()
    }
}

/// Resumes a checkpoint into its own directory without a progress bar.
pub fn resume_quiet(checkpoint: &Path) -> viscontact::run::Outcome {
    viscontact::run::resume(checkpoint, &viscontact::run::ResumeOptions::default()).unwrap()
}

/// The summary of a run that must have finished.
pub fn finished(o: viscontact::run::Outcome) -> viscontact::run::Summary {
    match o {
        viscontact::run::Outcome::Finished(s) => *s,
        viscontact::run::Outcome::Stopped { step, .. } => panic!("run stopped at step {step}"),
        viscontact::run::Outcome::Followed { .. } => panic!("a follower rank has no summary"),
    }
}

/// Every file of a directory with its bytes, by name (a subdirectory's files as `DIR/NAME`).
pub fn dir_contents(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut files = BTreeMap::new();
    for e in std::fs::read_dir(dir).unwrap().map(|e| e.unwrap()) {
        let name = e.file_name().to_string_lossy().into_owned();
        if e.path().is_dir() {
            // The pieces of a `.pvtu` frame (a run over MPI ranks).
            for (inner, bytes) in dir_contents(&e.path()) {
                files.insert(format!("{name}/{inner}"), bytes);
            }
        } else {
            files.insert(name, std::fs::read(e.path()).unwrap());
        }
    }
    files
}

/// `python3 -c SCRIPT ARGS…`: its standard output; the test fails, showing its standard
/// error, if the script does.
pub fn python_out(script: &str, args: &[&Path]) -> String {
    let out = Command::new("python3")
        .args(["-c", script])
        .args(args)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Whether python3 imports vtk and h5py; a loud note when not (a failure with CI set).
pub fn python_available() -> bool {
    let ok = Command::new("python3")
        .args(["-c", "import vtk, h5py"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI is set but python3 cannot import vtk and h5py"
        );
        eprintln!("\n!!!!!!!! SKIPPED: python3 with vtk and h5py is not available\n");
    }
    ok
}

/// scripts/check_vtkhdf.py FILE ARGS: its JSON report (the test fails if the script does).
pub fn check_vtkhdf(file: &Path, args: &[&str]) -> serde_json::Value {
    let out = Command::new("python3")
        .arg(repo().join("scripts/check_vtkhdf.py"))
        .arg(file)
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "check_vtkhdf.py {} {args:?}: {}",
        file.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// The paper's scene over 2 steps on `strip_mesh` of 13 000 squares (13 002 rows on 13 002
/// dofs, 2D: the dense dual would need 8·3·13 002² ≈ 4.06 GB, over `DENSE_LIMIT`), written
/// into `dir` as s.toml, and its path.
pub fn strip_scene(dir: &Path) -> PathBuf {
    SceneText::paper()
        .mesh(strip_mesh(dir, 13_000))
        .set("time.steps", 2)
        .write(dir, "s.toml")
}

/// A strip (0, 2) × (0, 2/nx) of one row of `nx` squares, each cut into two triangles,
/// written as an MSH 4.1 mesh `strip.msh` into `dir` with the paper's groups (Γ1 at x = 0,
/// Γ2 = top ∪ right, Γ3,1 the bottom's x < 1, Γ3,2 its x > 1; `nx` even): the paper's scene
/// on it has about nx contact and friction rows, a boundary whose dense dual exceeds
/// `solver::choice::DENSE_LIMIT` from nx ≈ 12 910 on, in a mesh that `check` reads in a
/// second.
pub fn strip_mesh(dir: &Path, nx: usize) -> PathBuf {
    use std::fmt::Write;
    assert!(nx.is_multiple_of(2));
    let h = 2.0 / nx as f64;
    // Node tags: the bottom row's node at x = ih is i + 1, the top row's nx + 2 + i.
    let (bottom, top) = (|i: usize| i + 1, |i: usize| nx + 2 + i);
    let mut t = String::from(
        "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$PhysicalNames\n7\n1 1 \"Γ1\"\n\
         1 2 \"Γ2\"\n1 3 \"Γ3,1\"\n1 4 \"Γ3,2\"\n1 5 \"top\"\n1 6 \"right\"\n\
         2 10 \"Ω\"\n$EndPhysicalNames\n$Entities\n0 5 1 0\n",
    );
    // Curves (tag, box, physical tags, no bounding points): left, the bottom's two
    // halves, top, right; the surface.
    for (tag, physical) in [
        (1, "1 1"),
        (2, "1 3"),
        (3, "1 4"),
        (4, "2 2 5"),
        (5, "2 2 6"),
    ] {
        writeln!(t, "{tag} 0 0 0 2 {h} 0 {physical} 0").unwrap();
    }
    writeln!(t, "1 0 0 0 2 {h} 0 1 10 0\n$EndEntities").unwrap();
    let n_nodes = 2 * (nx + 1);
    writeln!(t, "$Nodes\n1 {n_nodes} 1 {n_nodes}\n2 1 0 {n_nodes}").unwrap();
    for tag in 1..=n_nodes {
        writeln!(t, "{tag}").unwrap();
    }
    for y in [0.0, h] {
        for i in 0..=nx {
            writeln!(t, "{} {y} 0", i as f64 * h).unwrap();
        }
    }
    t.push_str("$EndNodes\n");
    let lines = |range: std::ops::Range<usize>, node: &dyn Fn(usize) -> usize| {
        range.map(|i| [node(i), node(i + 1)]).collect::<Vec<_>>()
    };
    let mut blocks: Vec<(usize, usize, usize, Vec<Vec<usize>>)> = vec![
        (1, 1, 1, vec![vec![bottom(0), top(0)]]),
        (
            1,
            2,
            1,
            lines(0..nx / 2, &bottom)
                .into_iter()
                .map(Vec::from)
                .collect(),
        ),
        (
            1,
            3,
            1,
            lines(nx / 2..nx, &bottom)
                .into_iter()
                .map(Vec::from)
                .collect(),
        ),
        (
            1,
            4,
            1,
            lines(0..nx, &top).into_iter().map(Vec::from).collect(),
        ),
        (1, 5, 1, vec![vec![bottom(nx), top(nx)]]),
    ];
    let triangles = (0..nx)
        .flat_map(|i| {
            let (a, b, c, d) = (bottom(i), bottom(i + 1), top(i + 1), top(i));
            [vec![a, b, c], vec![a, c, d]]
        })
        .collect();
    blocks.push((2, 1, 2, triangles));
    let n_elements: usize = blocks.iter().map(|b| b.3.len()).sum();
    writeln!(t, "$Elements\n{} {n_elements} 1 {n_elements}", blocks.len()).unwrap();
    let mut tag = 0;
    for (dim, entity, kind, elements) in &blocks {
        writeln!(t, "{dim} {entity} {kind} {}", elements.len()).unwrap();
        for e in elements {
            tag += 1;
            let nodes: Vec<String> = e.iter().map(|n| n.to_string()).collect();
            writeln!(t, "{tag} {}", nodes.join(" ")).unwrap();
        }
    }
    t.push_str("$EndElements\n");
    write(dir, "strip.msh", &t)
}
