//! Contact at the cost of a linear solve: wall time of a scene with contact, friction and
//! memory against the same scene with contact and friction disabled, side by side in one
//! run, setup (assembly, factorization, condensed operator) included, output excluded (both
//! runs would write the same files).
//!
//!   cargo run --release --example bench_contact -- 128 256 block:24
//!
//! An argument n is the 2D paper scene (examples/paper.toml) at 1/h = 1/k = n; meshes missing
//! from meshes/paper/ (256, 512) are made with gmsh from meshes/paper/rect.geo into
//! out/meshes/. An argument block:n is the 3D block (examples/block.toml) on
//! meshes/3d/block_n.msh (h = 1/n; made by `meshes/generate.sh block n` when missing) with
//! 100 steps; n = 24 has 90 000 free dofs. An argument block:PATH is the same scene on the
//! mesh file PATH (a mesh of the block that is not in the repo: `meshes/3d/block.geo` with
//! `-setnumber unstructured 1`, see there). An argument plate:s is the same scene on the
//! plate lying on its foundation: `meshes/3d/block.geo` at height 1/4 with gmsh's
//! unstructured tetrahedra of size s (plate:0.03 has 54 990 free dofs and m = 4 274
//! contact rows), made with gmsh into out/meshes/ when missing. Each pair is timed `REPEAT` times (alternating
//! full and linear) and the medians are reported.

use std::path::{Path, PathBuf};
use std::time::Instant;
use viscontact::run::setup;
use viscontact::time_loop::{Solved, TimeLoop};

const REPEAT: usize = 3;

/// The 3D block mesh of level n, generated with meshes/generate.sh when missing.
fn block_mesh(n: usize) -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = root.join(format!("meshes/3d/block_{n:03}.msh"));
    if !out.exists() {
        eprintln!("generating {} with meshes/generate.sh", out.display());
        let status = std::process::Command::new(root.join("meshes/generate.sh"))
            .args(["block", &n.to_string()])
            .status()
            .expect("meshes/generate.sh (needs gmsh: pip install gmsh)");
        assert!(status.success(), "meshes/generate.sh block {n} failed");
    }
    out
}

fn mesh_for(level: usize) -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let shipped = root.join(format!("meshes/paper/rect_{level:03}.msh"));
    if shipped.exists() {
        return shipped;
    }
    generated(
        &format!("rect_{level:03}.msh"),
        "-2",
        "meshes/paper/rect.geo",
        &[("n", &level.to_string())],
    )
}

/// The plate on its foundation (block.geo at height 1/4, unstructured tetrahedra of size
/// `size`).
fn plate_mesh(size: &str) -> PathBuf {
    size.parse::<f64>().expect("plate:<tetrahedron size>");
    generated(
        &format!("plate_{size}.msh"),
        "-3",
        "meshes/3d/block.geo",
        &[
            ("height", "0.25"),
            ("unstructured", "1"),
            ("Mesh.MeshSizeMax", size),
        ],
    )
}

/// out/meshes/`name`, made by gmsh (`dim` -2 or -3) from the repo's `geo` with the
/// `-setnumber` values when missing.
fn generated(name: &str, dim: &str, geo: &str, numbers: &[(&str, &str)]) -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = root.join("out/meshes");
    std::fs::create_dir_all(&dir).expect("out/meshes");
    let out = dir.join(name);
    if !out.exists() {
        eprintln!("generating {} with gmsh", out.display());
        let mut gmsh = std::process::Command::new("gmsh");
        gmsh.arg(dim).arg(root.join(geo));
        for (key, value) in numbers {
            gmsh.args(["-setnumber", key, value]);
        }
        let status = gmsh
            .args(["-format", "msh41", "-bin", "-o"])
            .arg(&out)
            .stdout(std::process::Stdio::null())
            .status()
            .expect("gmsh on PATH (pip install gmsh)");
        assert!(status.success(), "gmsh failed");
    }
    out
}

/// Setup + all steps of the scheme, no output. Returns (seconds, u_N max).
fn time_run(scene: &Path, overrides: &[String]) -> (f64, f64, usize) {
    let start = Instant::now();
    let (scene, _mesh, disc) = setup(scene, overrides).expect("scene");
    let mut tl = TimeLoop::new(&scene, &disc).expect("setup");
    let mut iterations = 0;
    let mut count = |s: &Solved| {
        iterations += s.step.report.iterations;
        Ok(())
    };
    tl.run(scene.time.steps, &mut count).expect("steps");
    let umax = tl.u().iter().fold(0.0f64, |a, v| a.max(v.abs()));
    (start.elapsed().as_secs_f64(), umax, iterations)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let args = if args.is_empty() {
        vec!["128".to_string(), "256".to_string()]
    } else {
        args
    };
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    println!(
        "| scene | h | dofs | steps | full (s) | linear only (s) | ratio | active-set iterations |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for arg in args {
        // The h column: 1/n, or the mesh file's name.
        let (name, h, mesh, steps) = match arg.strip_prefix("block:") {
            None if arg.starts_with("plate:") => {
                let size = &arg["plate:".len()..];
                ("block", format!("plate {size}"), plate_mesh(size), 100)
            }
            Some(n) => match n.parse::<usize>() {
                Ok(n) => ("block", format!("1/{n}"), block_mesh(n), 100),
                Err(_) => {
                    // The scene resolves relative paths from examples/.
                    let path = std::fs::canonicalize(n).expect("block:<n> or block:<mesh file>");
                    let file = path.file_name().unwrap().to_string_lossy().into_owned();
                    ("block", file, path, 100)
                }
            },
            None => {
                let n: usize = arg
                    .parse()
                    .expect("levels are integers, block:<n> or plate:<size>");
                ("paper", format!("1/{n}"), mesh_for(n), n)
            }
        };
        let scene = root.join(format!("examples/{name}.toml"));
        let base = vec![
            format!("mesh.file={}", mesh.display()),
            format!("time.steps={steps}"),
        ];
        let mut linear = base.clone();
        linear.push("contact.enabled=false".into());
        linear.push("friction.enabled=false".into());
        let (mut tf, mut tl) = (Vec::new(), Vec::new());
        let mut iterations = 0;
        for _ in 0..REPEAT {
            let (t, _, it) = time_run(&scene, &base);
            tf.push(t);
            iterations = it;
            tl.push(time_run(&scene, &linear).0);
        }
        let (_, _, disc) = setup(&scene, &base).expect("scene");
        let (f, l) = (median(tf), median(tl));
        println!(
            "| {name} | {h} | {} | {steps} | {f:.3} | {l:.3} | {:.2} | {iterations} |",
            disc.n_free,
            f / l
        );
    }
}
