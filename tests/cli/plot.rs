//! `viscontact plot` (issue 26): a 3D run's boundary surface from .vtu and .vtkhdf series,
//! seen from two directions, with its contact boundary marked; unknown fields refused; the
//! 2D figure still drawn; a run's history.csv against t (`--history`).

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

/// Runs the 2D `scene` for 2 steps into `run`.
fn run_2d(scene: &Path, run: &Path) -> PathBuf {
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
    run.to_path_buf()
}

#[test]
fn a_2d_run_is_still_drawn_and_refuses_a_view() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = paper_scene(tmp.path(), "s.toml", "paper/rect_008.msh", false);
    let run = run_2d(&scene, &tmp.path().join("run"));
    let px = plot(&run, &tmp.path().join("fig.png"), &[]);
    assert!(px.iter().filter(|p| **p == RED).count() > 200);
    let (code, text) = cli(&["plot", run.to_str().unwrap(), "--view", "1,1,1"]);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("--view is for 3D runs"), "{text}");
}

/// `plot DIR --history`: the force columns (or those asked for) against t as a PNG; an
/// unknown column is refused (exit 2) naming the columns the file has; `check` lists them.
#[test]
fn the_history_is_drawn_and_an_unknown_column_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = paper_scene(tmp.path(), "s.toml", "paper/rect_008.msh", false);
    let run = run_2d(&scene, &tmp.path().join("run"));
    let dir = run.to_str().unwrap();
    let png = tmp.path().join("history.png");
    let (code, text) = cli(&["plot", dir, "--history", "-o", png.to_str().unwrap()]);
    assert_eq!(code, 0, "{text}");
    assert!(
        text.contains("reaction_Γ1_x, reaction_Γ1_y, load_top_x"),
        "{text}"
    );
    assert!(!text.contains("max_von_mises"), "{text}");
    let (w, h, px) = pixels(&png);
    assert_eq!((w, h), (1000, 700));
    assert!(px.iter().filter(|p| **p != [255, 255, 255]).count() > 5000);
    let columns = ["--columns", "reaction_Γ1_y,max_von_mises"];
    let mut args = vec!["plot", dir, "--history", "-o", png.to_str().unwrap()];
    args.extend(columns);
    let (code, text) = cli(&args);
    assert_eq!(code, 0, "{text}");
    assert!(
        text.contains("(reaction_Γ1_y, max_von_mises over 3 steps)"),
        "{text}"
    );
    let (code, text) = cli(&["plot", dir, "--history", "--columns", "reaction_x"]);
    assert_eq!(code, 2, "{text}");
    for needle in [
        "no column 'reaction_x'",
        "reaction_Γ1_x, reaction_Γ1_y",
        "iterations",
    ] {
        assert!(text.contains(needle), "{needle:?} not in {text}");
    }
    let no_history = tmp.path().join("empty");
    std::fs::create_dir(&no_history).unwrap();
    let (code, text) = cli(&["plot", no_history.to_str().unwrap(), "--history"]);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("history.csv does not exist"), "{text}");
    let (code, text) = cli(&["check", scene.to_str().unwrap()]);
    assert_eq!(code, 0, "{text}");
    assert!(
        text.contains("history    17 columns of history.csv: step,t,reaction_Γ1_x,"),
        "{text}"
    );
}

/// A run whose scene leaves Γ3,1 and Γ3,2 without [contact] and [friction] drew them as the
/// contact boundary all the same, while the body passed through the foundation (issue 49,
/// item 6): their colours (and legend) are drawn only for conditions the run imposed.
#[test]
fn groups_without_their_condition_are_not_drawn_as_contact() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = SceneText::paper()
        .mesh(mesh_path("paper/rect_008.msh"))
        .remove("contact")
        .remove("friction")
        .write(tmp.path(), "s.toml");
    let run = run_2d(&scene, &tmp.path().join("run"));
    let px = plot(&run, &tmp.path().join("fig.png"), &[]);
    let orange = [240, 150, 0];
    let marked = px.iter().filter(|p| **p == RED || **p == orange).count();
    assert_eq!(
        marked, 0,
        "{marked} pixels of the contact and friction colours"
    );
}

/// examples/paper.toml on rect_008, 2 steps (frames at t = 0, 0.5, 1), run from the
/// repository root with the scene's relative path, as a user runs it: into `out`.
fn paper_run(out: &Path) {
    let o = viscontact(&[
        "run",
        "examples/paper.toml",
        "--set",
        "mesh.file=\"../meshes/paper/rect_008.msh\"",
        "--set",
        "time.steps=2",
        "--quiet",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// Issue 49, items 2 and 4: `plot DIR` without `-o` writes into the current directory, not
/// into the run's (which a rerun then refused), and draws the same figure, Γ3,1 and Γ3,2
/// included, from any working directory; a mesh that cannot be found is named in a warning.
#[test]
fn plot_leaves_the_run_directory_alone_and_draws_the_same_from_any_directory() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("paper");
    paper_run(&run);
    let from_root = tmp.path().join("root.png");
    plot(&run, &from_root, &[]);
    let elsewhere = tmp.path().join("elsewhere");
    std::fs::create_dir(&elsewhere).unwrap();
    let o = viscontact_in(
        &elsewhere,
        &["plot", run.to_str().unwrap(), "--width", "800"],
    );
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(!stderr.contains("warning"), "{stderr}");
    let png = elsewhere.join("paper_von_mises_t1.png");
    assert!(
        std::fs::read(&png).unwrap() == std::fs::read(&from_root).unwrap(),
        "plot from another directory drew another figure"
    );
    let in_run: Vec<_> = std::fs::read_dir(&run)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".png"))
        .collect();
    assert!(in_run.is_empty(), "plot wrote {in_run:?} into the run");
    // A rerun into the directory is not refused.
    paper_run(&run);

    // A mesh moved since the run: a warning names it, the traction nodes are circled.
    let summary = run.join("summary.json");
    let text = std::fs::read_to_string(&summary).unwrap();
    let mesh = common::summary(&run)["mesh"].as_str().unwrap().to_string();
    assert!(Path::new(&mesh).is_absolute(), "{mesh}");
    let moved = tmp.path().join("moved/rect_008.msh");
    std::fs::write(&summary, text.replace(&mesh, moved.to_str().unwrap())).unwrap();
    let o = viscontact_in(
        &elsewhere,
        &["plot", run.to_str().unwrap(), "-o", "moved.png"],
    );
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(
        stderr.contains("warning") && stderr.contains(moved.to_str().unwrap()),
        "{stderr}"
    );
    assert!(elsewhere.join("moved.png").exists());
}

/// Issue 49, item 9: `--time` outside the frames' times (t = 0, 0.5, 1) by more than half
/// their interval is refused, naming the range; between frames, plot says which it drew.
#[test]
fn plot_refuses_a_time_outside_the_run_and_names_the_frame_it_drew() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("paper");
    paper_run(&run);
    let png = tmp.path().join("fig.png");
    let at = |time: &str| {
        let time = format!("--time={time}");
        cli(&[
            "plot",
            run.to_str().unwrap(),
            &time,
            "-o",
            png.to_str().unwrap(),
        ])
    };
    for outside in ["5", "1.3", "-0.3", "NaN"] {
        let (code, text) = at(outside);
        assert_eq!(code, 2, "--time {outside}: {text}");
        assert!(
            text.contains("outside the run's frames, t = 0 to 1 (3 frames)"),
            "{text}"
        );
    }
    for (between, drawn) in [("0.3", "0.5"), ("1.2", "1"), ("-0.1", "0")] {
        let (code, text) = at(between);
        assert_eq!(code, 0, "--time {between}: {text}");
        assert!(
            text.contains(&format!(
                "no frame at t = {between}; drew the nearest, t = {drawn}"
            )),
            "{text}"
        );
    }
    let (code, text) = at("0.5");
    assert_eq!(code, 0, "{text}");
    assert!(!text.contains("no frame"), "{text}");
    // A field of the contact boundary: discs on its nodes (the largest value's in the top
    // colour of the colour bar) on a neutral body, not a smear over the first row of cells.
    let fig = tmp.path().join("pressure.png");
    let px = plot(&run, &fig, &["--field", "contact_pressure"]);
    let neutral = px.iter().filter(|p| **p == [225, 225, 225]).count();
    assert!(
        neutral > px.len() / 10,
        "{neutral} of {} pixels neutral",
        px.len()
    );
    let top = px.iter().filter(|p| **p == [253, 231, 37]).count();
    assert!(top > 100, "{top} pixels of the largest pressure's colour");
    // A directory without a series: one sentence, without the run of spaces of issue 49.
    let (code, text) = cli(&["plot", tmp.path().to_str().unwrap()]);
    assert_eq!(code, 2, "{text}");
    assert!(
        text.contains("give the output directory of a run (viscontact run … --out DIR)"),
        "{text}"
    );
}
