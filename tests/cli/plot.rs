//! `viscontact plot` (issue 26): a 3D run's boundary surface from .vtu and .vtkhdf series,
//! seen from two directions, with its contact boundary marked; unknown fields refused; the
//! 2D figure still drawn.

use crate::common;
use common::*;
use std::path::{Path, PathBuf};

/// Γ3,1's colour in the figures (src/plot.rs, CONTACT_COLOURS).
const RED: [u8; 3] = [220, 30, 30];

/// The RGB pixels of a PNG and its size.
fn pixels(path: &Path) -> (u32, u32, Vec<[u8; 3]>) {
    let decoder = png::Decoder::new(std::fs::File::open(path).unwrap());
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb, "{}", path.display());
    let px = buf[..info.buffer_size()]
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    (info.width, info.height, px)
}

/// examples/block.toml on the unstructured block (428 nodes), 2 steps, into `out`.
fn block_run(dir: &Path, out: &str, extra: &[&str]) -> PathBuf {
    let out = dir.join(out);
    let mesh = format!(
        "mesh.file={}",
        repo()
            .join("tests/data/3d/block_unstructured.msh")
            .display()
    );
    let scene = repo().join("examples/block.toml");
    let mut args = vec!["run", scene.to_str().unwrap(), "--set", &mesh];
    args.extend([
        "--set",
        "time.steps=2",
        "--quiet",
        "--out",
        out.to_str().unwrap(),
    ]);
    for e in extra {
        args.extend(["--set", e]);
    }
    let o = viscontact(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    out
}

/// Plots `run` with `args` into `png`; the figure must be 800 pixels wide and not blank.
fn plot(run: &Path, png: &Path, args: &[&str]) -> Vec<[u8; 3]> {
    let mut all = vec!["plot", run.to_str().unwrap(), "--width", "800"];
    all.extend(["-o", png.to_str().unwrap()]);
    all.extend(args);
    let o = viscontact(&all);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (w, h, px) = pixels(png);
    assert_eq!(w, 800);
    assert!(h > 300, "{h}");
    let drawn = px.iter().filter(|p| **p != [255, 255, 255]).count();
    assert!(drawn > px.len() / 5, "{drawn} of {} pixels drawn", px.len());
    px
}

#[test]
fn a_3d_run_is_drawn_from_two_views_with_its_contact_boundary() {
    let tmp = tempfile::tempdir().unwrap();
    let run = block_run(tmp.path(), "vtu", &[]);
    let below = plot(&run, &tmp.path().join("below.png"), &[]);
    let above = plot(&run, &tmp.path().join("above.png"), &["--view", "1,-2,1"]);
    let differ = below.iter().zip(&above).filter(|(a, b)| a != b).count();
    assert!(differ > below.len() / 10, "{differ} pixels differ");
    // Γ3,1 is outlined in red from below and from above (its edges along the front).
    for px in [&below, &above] {
        let red = px.iter().filter(|p| **p == RED).count();
        assert!(red > 200, "{red} red pixels");
    }
    // A point field, a component, and the frame nearest to a time, from a .vtkhdf series.
    let h5 = block_run(tmp.path(), "h5", &["output.format=\"vtkhdf\""]);
    let png = tmp.path().join("h5.png");
    let px = plot(&h5, &png, &["--field", "displacement_Z", "--time", "0.4"]);
    assert!(px.iter().filter(|p| **p == RED).count() > 200);
    // The same frame from the .vtu series: the same figure.
    let same = plot(
        &run,
        &tmp.path().join("same.png"),
        &["--field", "displacement_Z", "--time", "0.4"],
    );
    assert!(
        px == same,
        "the .vtkhdf and .vtu series draw different figures"
    );

    // An unknown field is an input error that names the fields there are.
    let (code, text) = cli(&["plot", run.to_str().unwrap(), "--field", "nope"]);
    assert_eq!(code, 2, "{text}");
    assert!(
        text.contains("'nope'") && text.contains("von_mises") && text.contains("contact_pressure"),
        "{text}"
    );
    // A view without a direction, and a view of three numbers not given.
    for bad in ["0,0,0", "1,2"] {
        let (code, text) = cli(&["plot", run.to_str().unwrap(), "--view", bad]);
        assert_eq!(code, 2, "{text}");
        assert!(text.contains("--view"), "{text}");
    }
}

#[test]
fn a_2d_run_is_still_drawn_and_refuses_a_view() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = paper_scene(tmp.path(), "s.toml", "paper/rect_008.msh", false);
    let run = tmp.path().join("run");
    let o = viscontact(&[
        "run",
        scene.to_str().unwrap(),
        "--set",
        "time.steps=2",
        "--quiet",
        "--out",
        run.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let px = plot(&run, &tmp.path().join("fig.png"), &[]);
    assert!(px.iter().filter(|p| **p == RED).count() > 200);
    let (code, text) = cli(&["plot", run.to_str().unwrap(), "--view", "1,1,1"]);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("--view is for 3D runs"), "{text}");
}
