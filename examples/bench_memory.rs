//! The cost of memory (issue 13): the paper scene at h = 1/32 with the power-law kernel
//! r(s) = 0.2(s + 0.01)^(−1/2), N steps of k = 1/32, run with `memory = "exact"` (direct sum)
//! and compressed (default tolerance 1e-10), alternating, in one process; prints the wall
//! times, their ratio and max|u_N^compressed − u_N^exact| / max|u_N^exact|.
//!
//!   cargo run --release --example bench_memory [N]   (default 4096)
//!
//! The cost of each tolerance is the `study --tolerances` command (`study::memory_cost`).

use std::time::Instant;
use viscontact::time_loop::TimeLoop;

/// u_N and the wall time of setup + steps.
fn u_final(scene: &std::path::Path, set: &[String]) -> (Vec<f64>, f64) {
    let (scene, _mesh, disc) = viscontact::run::setup(scene, set).unwrap();
    let start = Instant::now();
    let mut tl = TimeLoop::new(&scene, &disc).unwrap();
    viscontact::study::solve_to_end(&mut tl, scene.time.steps).unwrap();
    (tl.u().to_vec(), start.elapsed().as_secs_f64())
}

fn max(v: &[f64]) -> f64 {
    v.iter().fold(0.0f64, |m, x| m.max(x.abs()))
}

fn rel(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
        / max(b)
}

fn main() {
    let arg = std::env::args().nth(1);
    let root = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join("examples/paper.toml"))
        .unwrap()
        .replace("../meshes", &root.join("meshes").display().to_string())
        .replace("prony = [[1.0, 10.0]]", "expr = \"0.2*(s+0.01)^(-0.5)\"");
    let dir = std::env::temp_dir().join(format!("bench_memory_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scene = dir.join("paper_power_law.toml");
    std::fs::write(&scene, text).unwrap();
    let n: usize = arg.map_or(4096, |a| a.parse().unwrap());
    let set = |memory: &str| {
        vec![
            format!("time.steps={n}"),
            format!("time.end={}", n as f64 / 32.0),
            format!("material.relaxation.memory={memory}"),
        ]
    };
    let (mut t_exact, mut t_comp) = (Vec::new(), Vec::new());
    let (mut u_exact, mut u_comp) = (Vec::new(), Vec::new());
    for _ in 0..2 {
        let (u, t) = u_final(&scene, &set("compressed"));
        (u_comp, t_comp) = (u, [t_comp, vec![t]].concat());
        let (u, t) = u_final(&scene, &set("exact"));
        (u_exact, t_exact) = (u, [t_exact, vec![t]].concat());
    }
    let best = |t: &[f64]| t.iter().cloned().fold(f64::INFINITY, f64::min);
    println!(
        "N = {n}, k = 1/32: exact {:.2} s, compressed {:.2} s (best of 2 each, alternating): \
         {:.1}x faster; max|u_N diff| / max|u_N| = {:.2e}",
        best(&t_exact),
        best(&t_comp),
        best(&t_exact) / best(&t_comp),
        rel(&u_comp, &u_exact)
    );
    std::fs::remove_dir_all(&dir).ok();
}
