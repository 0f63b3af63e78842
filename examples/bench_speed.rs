//! Issue 15's 2D targets: the paper scene (examples/paper.toml) at h = k = 1/n, contact +
//! friction + memory, run by a baseline binary and by this tree's binary, alternating in one
//! benchmark run (the machine is shared, so only side-by-side ratios mean something). Each
//! run is the whole `viscontact run` process — mesh reading, assembly, factorization, all
//! n + 1 steps and the last frame — with `output.every` beyond the last step (only the last
//! frame is written) and no checkpoints. Reported: the median wall time of each binary, their
//! ratio, the same for the CPU time (user + system: steadier on a loaded machine), and
//! max|u_N − u_N,base| / max|u_N,base| from the two last frames.
//!
//! Then, in this process: the time per step (setup excluded, all of `solve_step` and
//! `advance`), the time of one forward + backward solve with the stored factor, and the
//! streaming bound: two passes (sums with eight partial sums) over an array of nnz(L) f64,
//! the least a step that reads the factor forward and backward can cost (issue 15's bound;
//! run on their own, the passes find the array in the last-level cache), and the same
//! streaming of all the data a step must read (L forward and backward, K_B and K_R, six
//! vectors), whose working set does not stay in that cache. Medians throughout.
//!
//!   cargo build --release && cargo run --release --example bench_speed -- BASELINE [n] [repeat]
//!
//! BASELINE is the baseline's `viscontact` binary (or set VISCONTACT_BASELINE); n = 128 by
//! default (meshes/paper/rect_n.msh must exist), repeat = 3.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;
use viscontact::output::read::read_vtu;
use viscontact::run::setup;
use viscontact::time_loop::{Solved, TimeLoop};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// One `viscontact run` of the scene into `out`: its wall time and its CPU time (user +
/// system, all threads) in seconds. On a shared machine the CPU time is the steadier figure:
/// the wall time also counts the time the process waited for a core.
fn run(bin: &Path, scene: &Path, sets: &[String], out: &Path) -> (f64, f64) {
    let _ = std::fs::remove_dir_all(out);
    let mut cmd = Command::new(bin);
    cmd.arg("run")
        .arg(scene)
        .arg("--out")
        .arg(out)
        .arg("--quiet");
    cmd.stdout(std::process::Stdio::null());
    for s in sets {
        cmd.args(["--set", s]);
    }
    let start = Instant::now();
    // Reaped by wait4 below, which also gives its resource usage.
    #[allow(clippy::zombie_processes)]
    let child = cmd.spawn().expect("the viscontact binary runs");
    let mut status = 0;
    // SAFETY: an all-zero rusage is valid; wait4 fills it and reaps our own child.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    let pid = unsafe { libc::wait4(child.id() as libc::pid_t, &mut status, 0, &mut usage) };
    let t = start.elapsed().as_secs_f64();
    assert_eq!(pid, child.id() as libc::pid_t, "wait4 failed");
    assert!(
        libc::WIFEXITED(status) && libc::WEXITSTATUS(status) == 0,
        "{} failed: status {status}",
        bin.display()
    );
    let secs = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    (t, secs(usage.ru_utime) + secs(usage.ru_stime))
}

/// The displacement field of the last frame.
fn last_displacement(out: &Path, n: usize) -> Vec<f64> {
    let vtu = read_vtu(&out.join(format!("solution_{n:06}.vtu"))).expect("last frame");
    vtu.point_field("displacement")
        .expect("displacement field")
        .values
        .clone()
}

fn max_abs(v: impl Iterator<Item = f64>) -> f64 {
    v.fold(0.0f64, |a, x| a.max(x.abs()))
}

fn main() {
    let mut args = std::env::args().skip(1);
    let baseline = args
        .next()
        .or_else(|| std::env::var("VISCONTACT_BASELINE").ok())
        .map(PathBuf::from)
        .expect("usage: bench_speed BASELINE [n] [repeat] (or VISCONTACT_BASELINE)");
    let n: usize = args.next().map_or(128, |a| a.parse().expect("n"));
    let repeat: usize = args.next().map_or(3, |a| a.parse().expect("repeat"));
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let new = root.join("target/release/viscontact");
    assert!(
        new.exists(),
        "{} missing: run cargo build --release first",
        new.display()
    );
    let scene = root.join("examples/paper.toml");
    let mesh = format!("../meshes/paper/rect_{n:03}.msh");
    assert!(root.join("examples").join(&mesh).exists(), "{mesh} missing");
    let sets: Vec<String> = [
        format!("mesh.file={mesh}"),
        format!("time.steps={n}"),
        "output.every=1000000".into(),
        "checkpoint.enabled=false".into(),
    ]
    .into();

    let tmp = tempfile::tempdir().unwrap();
    let bins = [("baseline", &baseline), ("new", &new)];
    let mut times = [Vec::new(), Vec::new()];
    let mut cpu = [Vec::new(), Vec::new()];
    for r in 0..repeat {
        // Alternate which binary goes first, so that neither always follows the other.
        for k in 0..2 {
            let i = (k + r) % 2;
            let (t, c) = run(bins[i].1, &scene, &sets, &tmp.path().join(bins[i].0));
            eprintln!("  round {r}: {} {t:.3} s (CPU {c:.3} s)", bins[i].0);
            times[i].push(t);
            cpu[i].push(c);
        }
    }
    let (base, fast) = (median(times[0].clone()), median(times[1].clone()));
    let u_base = last_displacement(&tmp.path().join("baseline"), n);
    let u_new = last_displacement(&tmp.path().join("new"), n);
    assert_eq!(u_base.len(), u_new.len());
    let diff =
        max_abs(u_base.iter().zip(&u_new).map(|(a, b)| a - b)) / max_abs(u_base.iter().copied());
    println!("paper scene h = k = 1/{n}, full run (process wall time, medians of {repeat}):");
    println!(
        "  baseline {base:.3} s, new {fast:.3} s: ratio {:.2}",
        base / fast
    );
    let (base_cpu, fast_cpu) = (median(cpu[0].clone()), median(cpu[1].clone()));
    println!(
        "  CPU time (user + system): baseline {base_cpu:.3} s, new {fast_cpu:.3} s: ratio {:.2}",
        base_cpu / fast_cpu
    );
    println!("  max|u_N − u_N,base| / max|u_N,base| = {diff:.1e}");

    // In this process: per-step time and the streaming bound.
    let overrides: Vec<String> = sets[..2].to_vec();
    let (scene, _mesh, disc) = setup(&scene, &overrides).expect("scene");
    let mut step_times = Vec::new();
    let mut tl = TimeLoop::new(&scene, &disc).expect("setup");
    for _ in 0..repeat {
        tl = TimeLoop::new(&scene, &disc).expect("setup");
        let start = Instant::now();
        tl.run(scene.time.steps, &mut |_: &Solved| Ok(()))
            .expect("steps");
        step_times.push(start.elapsed().as_secs_f64() / (scene.time.steps + 1) as f64);
    }
    let per_step = median(step_times);
    let factor = tl
        .factor()
        .expect("the benchmark's scenes solve with the stored factor (solver.linear)");
    let mut y: Vec<f64> = (0..factor.dim()).map(|i| (i % 7) as f64 - 3.0).collect();
    let solves: Vec<f64> = (0..20)
        .map(|_| {
            let start = Instant::now();
            factor.forward(&mut y);
            factor.backward(&mut y);
            start.elapsed().as_secs_f64()
        })
        .collect();
    let solve = median(solves);
    let nnz = factor.nonzeros();
    let l: Vec<f64> = (0..nnz).map(|i| (i % 13) as f64).collect();
    let passes: Vec<f64> = (0..20)
        .map(|_| {
            let start = Instant::now();
            // Eight partial sums: a single running sum is bound by the latency of its
            // additions (one element per 3–4 cycles), not by memory.
            let mut acc = [0.0; 8];
            for _ in 0..2 {
                for c in std::hint::black_box(&l).chunks_exact(8) {
                    for (a, x) in acc.iter_mut().zip(c) {
                        *a += x;
                    }
                }
            }
            std::hint::black_box(acc);
            start.elapsed().as_secs_f64()
        })
        .collect();
    let bound = median(passes);
    // The data a step cannot avoid reading, streamed in the order a step reads it: L's
    // values forward, the same backward, the lower triangles of K_B and K_R (two values and
    // a u32 row per entry: 20 bytes) and six vectors of n values (b, u, m, w, y and the
    // memory term). Unlike the two passes above, which stay in the last-level cache when run
    // on their own, this touches the step's whole working set, as the time loop does.
    let k_r = disc.k_r[0].as_ref();
    let lower = (k_r.compute_nnz() - k_r.nrows()) / 2;
    let other: Vec<f64> = (0..(lower * 20).div_ceil(8) + 6 * factor.dim())
        .map(|i| (i % 11) as f64)
        .collect();
    let sum = |x: &[f64], acc: &mut [f64; 8]| {
        for c in std::hint::black_box(x).chunks_exact(8) {
            for (a, v) in acc.iter_mut().zip(c) {
                *a += v;
            }
        }
    };
    let data: Vec<f64> = (0..40)
        .map(|_| {
            let start = Instant::now();
            let mut acc = [0.0; 8];
            sum(&l, &mut acc);
            for c in std::hint::black_box(&l).rchunks_exact(8) {
                for (a, v) in acc.iter_mut().zip(c) {
                    *a += v;
                }
            }
            sum(&other, &mut acc);
            std::hint::black_box(acc);
            start.elapsed().as_secs_f64()
        })
        .collect();
    let step_data = median(data[10..].to_vec());
    println!(
        "per step (setup excluded, medians of {repeat} runs of {} steps): {:.2} ms",
        scene.time.steps + 1,
        per_step * 1e3
    );
    println!(
        "  one forward + backward solve: {:.2} ms; two passes over nnz(L) = {nnz} f64 \
         ({:.1} MB; {} stored): {:.2} ms",
        solve * 1e3,
        nnz as f64 * 8e-6,
        factor.stored(),
        bound * 1e3
    );
    println!(
        "  per step / two passes = {:.2}; solve / two passes = {:.2}",
        per_step / bound,
        solve / bound
    );
    println!(
        "  the step's data streamed (L twice, K_B and K_R once, six vectors: {:.1} MB): \
         {:.2} ms; per step / that = {:.2}",
        (2 * nnz * 8 + other.len() * 8) as f64 * 1e-6,
        step_data * 1e3,
        per_step / step_data
    );
}
