//! What output costs (issue 14's targets): the h = k = 1/128 paper scene (examples/paper.toml
//! on rect_128.msh, 128 steps) writing a frame every step, in each layout, against the same
//! run writing only its last frame, and as one `.vtkhdf` file. The configurations run `REPEAT`
//! times, interleaved (the machine is shared, so only side-by-side ratios mean something);
//! each run starts after the one before is off the disk (`sync`). Reported: the median wall
//! time, the median over the rounds of each round's ratio to the run with one frame, and
//! the size of one frame (the last `.vtu`; for the `.vtkhdf`, the file ÷ its 129 frames)
//! and of the whole series.
//!
//! Then the encoder alone: the fields of the raw run's last frame (3.03 MB), in VTK's
//! 32 KiB blocks, through `output::zlib::compress` and through zlib-rs at level 1 (flate2),
//! best of 20.
//!
//! Run: `cargo build --release && cargo run --release --example bench_output [REPEAT]` (from
//! the repository root; the runs are processes of target/release/viscontact).

use std::io::Write;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Instant;
use viscontact::output::{read::read_vtu, zlib};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn dir_size(dir: &Path) -> u64 {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap())
        .filter(|e| e.file_name().to_string_lossy().starts_with("solution"))
        .map(|e| e.metadata().unwrap().len())
        .sum()
}

fn main() {
    let repeat: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(5);
    let base = ["mesh.file=../meshes/paper/rect_128.msh", "time.steps=128"];
    let configs: [(&str, &[&str]); 5] = [
        ("last frame only (zlib)", &["output.every=1000000"]),
        ("every step, zlib (default)", &[]),
        ("every step, zlib, float32", &["output.precision=float32"]),
        ("every step, none (raw)", &["output.compression=none"]),
        ("every step, vtkhdf (zlib)", &["output.format=vtkhdf"]),
    ];
    // The raw configuration, whose last frame the encoder is timed on.
    const RAW: usize = 3;
    // Each run is a process of its own, as a user runs it (runs in one process shared its
    // heap and were slower with frames, faster without).
    let bin = Path::new("target/release/viscontact");
    assert!(
        bin.exists(),
        "build the binary first: cargo build --release"
    );
    let tmp = tempfile::tempdir().unwrap();
    let mut times = vec![Vec::new(); configs.len()];
    let mut sizes = vec![(0, 0); configs.len()];
    for _ in 0..repeat {
        for (i, (_, set)) in configs.iter().enumerate() {
            let out = tmp.path().join(format!("c{i}"));
            let _ = std::fs::remove_dir_all(&out);
            let mut cmd = Command::new(bin);
            cmd.args(["run", "examples/paper.toml", "--quiet", "--out"])
                .arg(&out);
            for s in base.iter().chain(set.iter()) {
                cmd.args(["--set", s]);
            }
            let t = Instant::now();
            let status = cmd.stdout(Stdio::null()).status().unwrap();
            times[i].push(t.elapsed().as_secs_f64());
            assert!(status.success(), "{} failed", bin.display());
            let series = dir_size(&out);
            let last = std::fs::metadata(out.join("solution_000128.vtu"))
                .map_or(series / 129, |m| m.len());
            sizes[i] = (last, series);
            // The next run must not pay for writing this one's frames back to the disk:
            // drop them (the raw run's last frame is kept for the encoder's timing) and wait
            // for the disk.
            if i != RAW {
                std::fs::remove_dir_all(&out).unwrap();
            }
            let _ = Command::new("sync").status();
        }
    }
    // The ratio to the run with one frame is taken in each round (runs seconds apart, which
    // a slow spell of the shared machine slows alike), then the median over the rounds.
    println!(
        "h = k = 1/128, 128 steps, median of {repeat} interleaved runs (ratio: median of each \
         round's ratio to the first row):"
    );
    for (i, (name, _)) in configs.iter().enumerate() {
        let t = median(times[i].clone());
        let ratio = median(times[i].iter().zip(&times[0]).map(|(t, r)| t / r).collect());
        println!(
            "  {name:28} {t:6.2} s ({ratio:4.2}×)  frame {:6.2} MB  series {:7.1} MB",
            sizes[i].0 as f64 / 1e6,
            sizes[i].1 as f64 / 1e6
        );
    }
    // The encoder on the fields of the last raw frame (region is not a field of the step).
    let raw = read_vtu(&tmp.path().join(format!("c{RAW}/solution_000128.vtu"))).unwrap();
    let bytes: Vec<u8> = raw
        .point_data
        .iter()
        .chain(&raw.cell_data)
        .filter(|a| a.name != "region")
        .flat_map(|a| a.values.iter().flat_map(|x| x.to_le_bytes()))
        .collect();
    let best = |encode: &dyn Fn(&[u8], &mut Vec<u8>)| {
        let mut out = Vec::new();
        let mut best = f64::MAX;
        for _ in 0..20 {
            out.clear();
            let t = Instant::now();
            for block in bytes.chunks(32768) {
                encode(block, &mut out);
            }
            best = best.min(t.elapsed().as_secs_f64());
        }
        (best, out.len())
    };
    let zlib_rs = |block: &[u8], out: &mut Vec<u8>| {
        let mut z = flate2::write::ZlibEncoder::new(out, flate2::Compression::fast());
        z.write_all(block).unwrap();
        z.finish().unwrap();
    };
    println!(
        "encoder on the last frame's fields ({:.2} MB), best of 20:",
        bytes.len() as f64 / 1e6
    );
    for (name, (t, size)) in [
        ("output::zlib::compress", best(&zlib::compress)),
        ("zlib-rs level 1", best(&zlib_rs)),
    ] {
        println!(
            "  {name:24} {:5.2} ms ({:4.0} MB/s)  {:4.1}% of the size",
            t * 1e3,
            bytes.len() as f64 / t / 1e6,
            100.0 * size as f64 / bytes.len() as f64
        );
    }
}
