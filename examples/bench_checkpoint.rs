//! What checkpointing costs (issue 4's targets).
//!
//! 1. Wall time of the h = k = 1/64 paper scene (examples/paper.toml on rect_064.msh, 64
//!    steps, Prony kernel, contact and friction) without checkpoints, with only the final one
//!    (the default) and with one every step; once with a frame every 64 steps (to isolate the
//!    checkpoint cost) and once with the default frame every step. Each configuration runs
//!    `REPEAT` times, interleaved; the median is reported.
//! 2. The latency of one checkpoint of a general kernel (direct sum, history in
//!    checkpoint_history.h5) as the history grows: the time to hand over and write one
//!    checkpoint, waited for, at steps n of a 256-step run. It stays flat: each checkpoint
//!    appends the new rows only.
//!
//! 3. The CRC-32 of a checkpoint's bytes (the integrity check), per checkpoint.
//!
//! Run: `cargo run --release --example bench_checkpoint [REPEAT]` (from the repository root).

use std::path::Path;
use std::time::Instant;
use viscontact::checkpoint::{Identity, RunLog, Writer};
use viscontact::run::{run, setup, Outcome, RunOptions};
use viscontact::time_loop::{Observer, Solved, TimeLoop};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let repeat: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(7);
    let tmp = tempfile_dir();
    let base = ["mesh.file=../meshes/paper/rect_064.msh", "time.steps=64"];
    let configs: [(&str, &[&str]); 3] = [
        ("no checkpoint", &["checkpoint.enabled=false"]),
        ("final checkpoint only (default)", &[]),
        ("checkpoint every step", &["checkpoint.every=1"]),
    ];
    println!("paper scene, h = k = 1/64, Prony kernel, {repeat} runs each, median wall time");
    for output in ["output.every=64", "output.every=1"] {
        let mut times = vec![Vec::new(); configs.len()];
        for _ in 0..repeat {
            for (i, (_, extra)) in configs.iter().enumerate() {
                let mut overrides: Vec<String> = base.iter().map(|s| s.to_string()).collect();
                overrides.push(output.to_string());
                overrides.extend(extra.iter().map(|s| s.to_string()));
                let opts = RunOptions {
                    out: Some(tmp.join(format!("run{i}"))),
                    overrides,
                    progress: false,
                    stop_after: None,
                    ..Default::default()
                };
                let t = Instant::now();
                match run(Path::new("examples/paper.toml"), &opts).expect("the paper scene runs") {
                    Outcome::Finished(_) => {}
                    other => unreachable!("{other:?}"),
                }
                times[i].push(t.elapsed().as_secs_f64());
            }
        }
        let reference = median(times[0].clone());
        println!("  {output}:");
        for ((name, _), t) in configs.iter().zip(times) {
            let m = median(t);
            println!(
                "    {name:<34} {:>8.1} ms  ({:+.1}% against no checkpoint)",
                m * 1e3,
                100.0 * (m / reference - 1.0)
            );
        }
    }

    // 2. General kernel: checkpoint latency against the step.
    let overrides: Vec<String> = ["mesh.file=../meshes/paper/rect_032.msh", "time.steps=256"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    let scene_text = std::fs::read_to_string("examples/paper.toml")
        .expect("run from the repository root")
        .replace("prony = [[1.0, 10.0]]", "expr = \"exp(-10*s)\"");
    let scene_path = Path::new("examples").join(".bench_checkpoint_expr.toml");
    std::fs::write(&scene_path, scene_text).expect("write the scene");
    let (scene, mesh, disc) = setup(&scene_path, &overrides).expect("scene");
    let _ = std::fs::remove_file(&scene_path);
    let dir = tmp.join("general");
    std::fs::create_dir_all(&dir).expect("dir");
    let mut tl = TimeLoop::new(&scene, &disc).expect("time loop");
    let writer = Writer::new(
        &dir,
        Identity::new(&scene, &mesh, &disc, None),
        scene.time.steps,
        tl.rows(),
    );
    // Steps 0..N-1, a checkpoint after each, waited for.
    struct EveryStep {
        writer: Writer,
        log: RunLog,
        active: Vec<bool>,
        latency: Vec<(usize, f64)>,
        stop: usize,
    }
    impl Observer for EveryStep {
        fn stop_after(&mut self, n: usize) -> bool {
            n == self.stop
        }
        fn solved(&mut self, s: &Solved) -> viscontact::Result<()> {
            self.log.iterations.push(s.step.report.iterations);
            Ok(())
        }
        fn advanced(&mut self, tl: &mut TimeLoop) -> viscontact::Result<()> {
            let t = Instant::now();
            let state = tl.state()?.expect("one process");
            let mut feed = (self.writer).write(state, &self.log, &self.active, Vec::new());
            tl.gather_memory(&mut |v| feed.send(v))?;
            feed.end()?;
            self.writer.flush()?;
            self.latency.push((tl.n(), t.elapsed().as_secs_f64()));
            Ok(())
        }
    }
    let mut every = EveryStep {
        writer,
        log: RunLog::default(),
        active: vec![false; tl.rows().len()],
        latency: Vec::new(),
        stop: scene.time.steps - 1,
    };
    tl.run(scene.time.steps, &mut every).expect("steps");
    let EveryStep {
        writer, latency, ..
    } = every;
    writer.finish().expect("checkpoint");
    // 3. The integrity check's own cost: the CRC-32 over a checkpoint's bytes, which every
    //    checkpoint computes once and resume once more (src/checkpoint/seal.rs).
    for (what, path) in [
        ("Prony, rect_064", tmp.join("run2/checkpoint.h5")),
        ("general kernel, rect_032", dir.join("checkpoint.h5")),
    ] {
        let bytes = std::fs::read(&path).expect("a checkpoint");
        let t: Vec<f64> = (0..101)
            .map(|_| {
                let t = Instant::now();
                std::hint::black_box(crc32fast::hash(std::hint::black_box(&bytes)));
                t.elapsed().as_secs_f64()
            })
            .collect();
        println!(
            "CRC-32 of a checkpoint ({what}, {} kB): median {:.1} µs",
            bytes.len() / 1000,
            median(t) * 1e6
        );
    }
    println!(
        "general kernel (direct sum), rect_032 ({} free dofs), one checkpoint per step, \
         written and waited for:",
        disc.n_free
    );
    for window in [1..17, 64..81, 128..145, 240..257] {
        let t: Vec<f64> = latency
            .iter()
            .filter(|(n, _)| window.contains(n))
            .map(|(_, t)| *t)
            .collect();
        println!(
            "    steps {:>3}..{:<3} median {:>6.2} ms per checkpoint",
            window.start,
            window.end - 1,
            median(t) * 1e3
        );
    }
    let _ = std::fs::remove_dir_all(&tmp);
}

fn tempfile_dir() -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("bench_checkpoint_{}", std::process::id()));
    std::fs::create_dir_all(&d).expect("temporary directory");
    d
}
