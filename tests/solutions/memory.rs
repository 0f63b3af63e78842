//! Compressed memory (issue 13) and the kernel's part of issue 11: the certified error holds
//! on every lag for power laws, stretched exponentials and a table; a compressed run agrees
//! with the direct sum to the order of its tolerance; a compressed run stopped and resumed
//! equals the uninterrupted one bit for bit; an unfittable kernel runs exact and says why;
//! the stability guard and the non-finite check cover expression kernels.

use crate::common;

use common::{finished, resume_quiet, run_options as opts, without_run_id, SceneText};
use std::path::{Path, PathBuf};
use viscontact::expr::Expr;
use viscontact::kernel::Kernel;
use viscontact::kernel_fit::{fit, Lags};
use viscontact::run::{run, Outcome};

/// examples/paper.toml on `mesh` with the relaxation section `relaxation` (its lines).
fn paper_scene(dir: &Path, name: &str, mesh: &str, relaxation: &str) -> PathBuf {
    SceneText::paper()
        .mesh(common::mesh_path(mesh))
        .table("material.relaxation", relaxation)
        .write(dir, name)
}

/// The frames of `steps` in two run directories are the same bytes (but for the run id).
fn assert_same_frames(a: &Path, b: &Path, steps: &[usize]) {
    for n in steps {
        let name = format!("solution_{n:06}.vtu");
        let read = |d: &Path| without_run_id(std::fs::read(d.join(&name)).unwrap());
        assert!(read(a) == read(b), "{name} differs");
    }
}

/// The paper scene on rect_008 with r(s) = 0.2(s + 0.01)^(−1/2), compressed.
fn power_law() -> SceneText {
    SceneText::paper()
        .mesh(common::mesh_path("paper/rect_008.msh"))
        .table("material.relaxation", r#"expr = "0.2*(s+0.01)^(-0.5)""#)
}

fn expr(e: &str) -> Kernel {
    Kernel::Expr(Box::new(Expr::parse(e, &["s"], "r").unwrap()))
}

#[test]
fn certified_error_holds_on_every_lag() {
    // Relaxation-test data: (1 + s)^(−0.6) at s = 0 and 41 points from 0.05 to 376.
    let table_s: Vec<f64> = std::iter::once(0.0)
        .chain((0..=40).map(|i| 0.05 * 1.25f64.powi(i)))
        .collect();
    let table_r: Vec<f64> = table_s.iter().map(|s| (1.0 + s).powf(-0.6)).collect();
    let cases: Vec<(&str, Kernel, f64, usize, f64)> = vec![
        (
            "0.2(s+0.01)^-0.5",
            expr("0.2*(s+0.01)^(-0.5)"),
            1.0 / 32.0,
            4096,
            1e-10,
        ),
        ("s^-0.3", expr("s^(-0.3)"), 1e-3, 100_000, 1e-10),
        ("s^-0.7", expr("s^(-0.7)"), 1e-3, 100_000, 1e-8),
        (
            "exp(-(s/2)^0.5)",
            expr("exp(0 - (s/2)^0.5)"),
            0.01,
            20_000,
            1e-10,
        ),
        (
            "exp(-(s/0.5)^0.3)",
            expr("exp(0 - (s/0.5)^0.3)"),
            0.01,
            20_000,
            1e-6,
        ),
        ("table", Kernel::Table(table_s, table_r), 0.01, 20_000, 1e-3),
    ];
    for (name, kernel, k, n, tol) in cases {
        // r(0) (the implicit variant) where it is finite.
        let zero: &[bool] = if kernel.eval(0.0).is_finite() {
            &[false, true]
        } else {
            &[false]
        };
        for &with_zero in zero {
            let lags = Lags::new(&kernel, k, n, with_zero, "r").unwrap();
            let f = fit(&lags, tol).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert!(f.error <= tol, "{name}: {} > {tol}", f.error);
            // The certificate recomputed independently, with exp on every lag.
            let first = usize::from(!with_zero);
            let scale = lags.r.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let worst = (first..=n)
                .map(|l| {
                    let s = l as f64 * k;
                    let fitted: f64 = f.terms.iter().map(|(a, b)| a * (-b * s).exp()).sum();
                    (fitted - kernel.eval(s)).abs()
                })
                .fold(0.0f64, f64::max)
                / scale;
            assert!(
                worst <= tol * 1.01,
                "{name}: independent max error {worst:e} > {tol:e}"
            );
            assert!(f.terms.iter().all(|&(a, b)| a > 0.0 && b >= 0.0));
            println!(
                "{name} (r(0): {with_zero}): {} terms, {:.2e}, {:.3} s",
                f.terms.len(),
                f.error,
                f.seconds
            );
        }
    }
}

#[test]
fn compressed_agrees_with_exact_to_the_order_of_the_tolerance() {
    let dir = tempfile::tempdir().unwrap();
    let scene = power_law().write(dir.path(), "pl.toml");
    let set = ["time.steps=256", "time.end=8"];
    let u_n = |extra: &str| {
        let mut o: Vec<&str> = set.to_vec();
        o.push(extra);
        let (scene, _, disc) = common::load(&scene, &o);
        common::trace(&scene, &disc).u_final
    };
    let exact = u_n("material.relaxation.memory=exact");
    let d: Vec<f64> = [1e-4, 1e-7, 1e-10]
        .iter()
        .map(|tol| {
            let d = common::rel_diff(
                &u_n(&format!("material.relaxation.tolerance={tol}")),
                &exact,
            );
            println!("tolerance {tol:e}: u_N differs by {d:e}");
            assert!(d <= 10.0 * tol && d > 0.0, "tolerance {tol}: {d}");
            d
        })
        .collect();
    assert!(
        d[0] > 100.0 * d[2],
        "the difference must shrink with the tolerance: {d:?}"
    );
}

#[test]
fn compressed_run_resumed_equals_uninterrupted_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let scene = power_law()
        .set("material.relaxation.tolerance", 1e-8)
        .write(dir.path(), "pl.toml");
    let set = ["time.steps=16", "checkpoint.every=3"];
    let full = dir.path().join("full");
    let part = dir.path().join("part");
    let s = finished(run(&scene, &opts(&full, &set, None)).unwrap());
    let memory = s.memory.as_ref().unwrap();
    assert_eq!(memory.method, "compressed");
    assert!(memory.terms > 0 && memory.certified_error.unwrap() <= 1e-8);
    assert!(matches!(
        run(&scene, &opts(&part, &set, Some(7))).unwrap(),
        Outcome::Stopped { step: 7, .. }
    ));
    // No past displacements: the compressed kernel's state is its Prony terms.
    assert!(!part.join("checkpoint_history.h5").exists());
    let r = finished(resume_quiet(&part.join("checkpoint.h5")));
    assert_eq!(r.steps, 16);
    assert_same_frames(&full, &part, &[8, 12, 16]);
    assert_eq!(s.final_.u_h1.to_bits(), r.final_.u_h1.to_bits());
}

#[test]
fn unfittable_kernel_runs_exact_and_says_why() {
    let dir = tempfile::tempdir().unwrap();
    let scene = paper_scene(
        dir.path(),
        "bump.toml",
        "paper/rect_008.msh",
        "expr = \"exp(-s)*(2 + cos(10*s))\"",
    );
    let s = finished(run(&scene, &opts(&dir.path().join("out"), &[], None)).unwrap());
    let memory = s.memory.unwrap();
    assert_eq!(memory.method, "exact");
    let why = memory.fallback.unwrap();
    assert!(why.contains("grows"), "{why}");
    let json = std::fs::read_to_string(dir.path().join("out/summary.json")).unwrap();
    assert!(json.contains("\"fallback\""), "{json}");
}

#[test]
fn stability_guard_covers_expression_kernels() {
    let dir = tempfile::tempdir().unwrap();
    // 100·e^{−s} at k = 1/32: the Prony form is refused; so must the expression be, run by
    // the direct sum and compressed (the fit at 1e-8 is a Prony series).
    for (i, relaxation) in [
        "prony = [[100.0, 1.0]]",
        "expr = \"100*exp(-s)\"\nmemory = \"exact\"",
        "expr = \"100*exp(-s)\"\ntolerance = 1e-8",
    ]
    .iter()
    .enumerate()
    {
        let scene = paper_scene(
            dir.path(),
            &format!("u{i}.toml"),
            "paper/rect_008.msh",
            relaxation,
        );
        let err = run(&scene, &opts(&dir.path().join(format!("o{i}")), &[], None)).unwrap_err();
        assert_eq!(err.exit_code(), 2, "{relaxation}: {err}");
        assert!(err.to_string().contains("stab"), "{relaxation}: {err}");
        // With enough steps the same kernel runs.
        let ok = run(
            &scene,
            &opts(
                &dir.path().join(format!("p{i}")),
                &["time.steps=1024"],
                None,
            ),
        );
        assert!(ok.is_ok(), "{relaxation}: {:?}", ok.err());
    }
}

#[test]
fn non_finite_kernel_is_bad_input_naming_its_key() {
    let dir = tempfile::tempdir().unwrap();
    let scene = paper_scene(
        dir.path(),
        "ln.toml",
        "paper/rect_008.msh",
        "expr = \"ln(s-0.5)\"",
    );
    for memory in ["compressed", "exact"] {
        let set = [format!("material.relaxation.memory={memory}")];
        let set: Vec<&str> = set.iter().map(|s| s.as_str()).collect();
        let err = run(&scene, &opts(&dir.path().join(memory), &set, None)).unwrap_err();
        assert_eq!(err.exit_code(), 2, "{err}");
        assert!(
            err.to_string().contains("material.relaxation.expr"),
            "{err}"
        );
    }
    // r(0) = ∞ is read only by the implicit variant.
    let scene = paper_scene(
        dir.path(),
        "pow.toml",
        "paper/rect_008.msh",
        "expr = \"s^(-0.5)\"",
    );
    let err = run(
        &scene,
        &opts(&dir.path().join("imp"), &["scheme.history=implicit"], None),
    )
    .unwrap_err();
    assert!(err.to_string().contains("s = 0"), "{err}");
}

#[test]
fn compressed_run_extends_to_its_horizon_and_no_further() {
    let dir = tempfile::tempdir().unwrap();
    let kernel = power_law().set("material.relaxation.tolerance", 1e-8);
    let with_horizon = kernel
        .clone()
        .set("material.relaxation.horizon", 2.0)
        .write(dir.path(), "h.toml");
    let extend = |cp: &Path, end: &str| {
        viscontact::run::resume(
            cp,
            &viscontact::run::ResumeOptions {
                overrides: vec![format!("time.end={end}")],
                ..Default::default()
            },
        )
    };
    // Run to T = 1, extend to T = 2: the run straight to T = 2 with the same horizon, bit for
    // bit (the fit covers the lags up to the horizon in both).
    let straight = dir.path().join("straight");
    let s = finished(
        run(
            &with_horizon,
            &opts(&straight, &["time.steps=32", "time.end=2"], None),
        )
        .unwrap(),
    );
    let memory = s.memory.as_ref().unwrap();
    assert_eq!(memory.method, "compressed");
    assert_eq!(memory.certified_until, Some(2.0));
    let part = dir.path().join("part");
    finished(run(&with_horizon, &opts(&part, &["time.steps=16"], None)).unwrap());
    let r = finished(extend(&part.join("checkpoint.h5"), "2").unwrap());
    assert_eq!(r.steps, 32);
    assert_eq!(s.final_.u_h1.to_bits(), r.final_.u_h1.to_bits());
    assert_same_frames(&straight, &part, &[17, 32]);
    // Beyond the horizon, and without one: refused (bad input), naming the time the fit holds
    // to and the key that would make it hold further; nothing in the directory changes.
    let before = std::fs::read(part.join("checkpoint.h5")).unwrap();
    let e = extend(&part.join("checkpoint.h5"), "3").unwrap_err();
    assert_eq!(e.exit_code(), 2);
    let msg = e.to_string();
    assert!(
        msg.contains("holds up to t = 2") && msg.contains("horizon = 3"),
        "{msg}"
    );
    assert_eq!(before, std::fs::read(part.join("checkpoint.h5")).unwrap());
    let plain = kernel.write(dir.path(), "p.toml");
    let short = dir.path().join("short");
    finished(run(&plain, &opts(&short, &["time.steps=16"], None)).unwrap());
    let msg = extend(&short.join("checkpoint.h5"), "1.5")
        .unwrap_err()
        .to_string();
    // It holds on its own lags and perhaps a few beyond them (how far depends on the fit),
    // not up to 1.5.
    let held: f64 = msg
        .split("holds up to t = ")
        .nth(1)
        .and_then(|t| t.split(':').next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no time in {msg}"));
    assert!(
        (1.0..1.5).contains(&held) && msg.contains("horizon = 1.5"),
        "{msg}"
    );
    // The key is checked: only a compressed kernel has a fit, and a horizon is a positive time.
    let prony = SceneText::paper().mesh(common::mesh_path("paper/rect_008.msh"));
    for (relaxation, why) in [
        (
            prony.set("material.relaxation.horizon", 2.0),
            "apply to 'expr' and 'table'",
        ),
        (
            kernel
                .clone()
                .set("material.relaxation.memory", "exact")
                .set("material.relaxation.horizon", 2.0),
            "only a compressed",
        ),
        (kernel.set("material.relaxation.horizon", -1.0), "is -1"),
    ] {
        let scene = relaxation.write(dir.path(), "bad.toml");
        let e =
            viscontact::run::run(&scene, &opts(&dir.path().join("bad"), &[], None)).unwrap_err();
        assert_eq!(e.exit_code(), 2);
        let msg = e.to_string();
        assert!(
            msg.contains("material.relaxation") && msg.contains(why),
            "{msg}"
        );
    }
}

#[test]
fn study_of_tolerances_tracks_the_direct_sum() {
    use viscontact::study::memory_cost::{markdown, run_memory_cost, write_report, Options};
    let dir = tempfile::tempdir().unwrap();
    let scene = power_law().write(dir.path(), "pl.toml");
    let opts = Options {
        tolerances: vec![1e-4, 1e-7, 1e-10, 1e-17],
        steps: vec![48, 96],
        exact_up_to: 48,
        overrides: vec![],
        progress: false,
    };
    let report = run_memory_cost(&scene, &opts).unwrap();
    // N = 48: the direct sum and four tolerances; N = 96: four tolerances, no direct sum.
    assert_eq!(report.rows.len(), 9);
    let rows = |n: usize| report.rows.iter().filter(move |r| r.steps == n);
    let compressed: Vec<_> = rows(48).filter(|r| r.method == "compressed").collect();
    assert_eq!(compressed.len(), 3);
    for r in &compressed {
        let tol = r.tolerance.unwrap();
        assert!(r.certified_error.unwrap() <= tol && r.terms > 0);
        assert!(r.error_u.unwrap() <= 10.0 * tol, "{r:?}");
    }
    assert!(compressed[0].error_u.unwrap() > 100.0 * compressed[2].error_u.unwrap());
    assert!(compressed[0].terms < compressed[2].terms);
    // 1e-17 is beyond what the fit reaches: the direct sum runs where it is allowed (and
    // equals the exact row), and is not run beyond --exact-up-to.
    let missed: Vec<_> = report
        .rows
        .iter()
        .filter(|r| r.fallback.is_some())
        .collect();
    assert_eq!(missed.len(), 2, "{report:?}");
    assert_eq!(missed[0].error_u, Some(0.0));
    assert!(missed[1].steps == 96 && missed[1].wall_s.is_none());
    assert!(rows(96).all(|r| r.error_u.is_none()));
    let out = dir.path().join("study");
    let written = write_report(&report, &out).unwrap();
    assert_eq!(written.len(), 5);
    assert!(markdown(&report).contains("| 96 | 1e-17 | fit missed ε; direct sum not run |"));
    // A Prony kernel has nothing to compress: bad input naming the key.
    let prony = paper_scene(
        dir.path(),
        "p.toml",
        "paper/rect_008.msh",
        "prony = [[1.0, 10.0]]",
    );
    let e = run_memory_cost(&prony, &opts).unwrap_err();
    assert_eq!(e.exit_code(), 2);
    assert!(e.to_string().contains("[material.relaxation]"));
}

/// `viscontact check` (or `run` into `dir/out`) on `scene` with `set`: (exit status, output).
fn cli_on(command: &str, scene: &Path, set: &[&str]) -> (i32, String) {
    let scene = scene.to_str().unwrap().to_string();
    let out = scene.replace(".toml", "_out");
    let mut args = vec![command, &scene];
    if command == "run" {
        args.extend(["--out", &out]);
    }
    for s in set {
        args.extend(["--set", s]);
    }
    common::cli(&args)
}

#[test]
fn long_run_whose_kernel_misses_its_tolerance_is_refused_not_run_exact() {
    let dir = tempfile::tempdir().unwrap();
    // A kinked table: piecewise linear, no sum of exponentials follows it to 1e-6.
    let table = "table = { s = [0.0, 1.0, 2.0, 4.0], r = [1.0, 0.5, 0.3, 0.2] }";
    let scene = SceneText::paper()
        .mesh(common::mesh_path("paper/rect_008.msh"))
        .table("material.relaxation", table)
        .set("material.relaxation.tolerance", 1e-6)
        .write(dir.path(), "kink.toml");
    let long = ["time.steps=20000", "time.end=200"];
    for command in ["check", "run"] {
        let (code, text) = cli_on(command, &scene, &long);
        assert_eq!(code, 2, "{command}: {text}");
        for what in [
            "material.relaxation.tolerance",
            "reaches a relative error of",
            "memory = \"exact\"",
            "10000",
        ] {
            assert!(text.contains(what), "{command}: no {what:?} in {text}");
        }
    }
    // A short run still falls back to the direct sum and says why.
    let (code, text) = cli_on("check", &scene, &["time.steps=64", "time.end=0.64"]);
    assert_eq!(code, 0, "{text}");
    assert!(
        text.contains("runs exact (direct sum), not compressed"),
        "{text}"
    );
    // Asked for explicitly, the direct sum runs however long the run is.
    let mut exact = long.to_vec();
    exact.push("material.relaxation.memory=\"exact\"");
    let (code, text) = cli_on("check", &scene, &exact);
    assert_eq!(code, 0, "{text}");
    assert!(
        text.contains("runs exact (direct sum): memory = \"exact\""),
        "{text}"
    );
}

#[test]
fn power_law_of_1e5_steps_is_never_run_by_the_direct_sum() {
    // Issue 26, finding 10: 0.2(s + 0.01)^(−1/2), T = 10, 10^5 steps used to fall back to
    // the direct sum (3.4 GB, ~2 hours at h = 1/32) with a line in check's output, and then
    // to be refused: the fit's floor (1.5e-10) sat at the default tolerance 1e-10. The fit
    // now reaches the default 1e-12 on its 10^5 lags.
    let dir = tempfile::tempdir().unwrap();
    let scene = power_law().write(dir.path(), "pl.toml");
    let set = ["time.steps=100000", "time.end=10"];
    let (code, text) = cli_on("check", &scene, &set);
    assert_eq!(code, 0, "{text}");
    let certified: f64 = text
        .split("certified max relative error ")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no certified error in {text}"));
    assert!(
        text.contains("kernel     compressed") && certified <= 1e-12,
        "{text}"
    );
    println!("{text}");
}

#[test]
fn a_horizon_beyond_the_fits_lag_limit_is_refused_at_once() {
    // Issue 26, finding 3: horizon = 1e8 with end = 100 made check and run allocate 12.8 GB
    // and abort. 3200 steps of k = 1/32: 3.2e9 lags.
    let dir = tempfile::tempdir().unwrap();
    let scene = power_law()
        .set("material.relaxation.horizon", 1e8)
        .write(dir.path(), "pl.toml");
    let set = ["time.steps=3200", "time.end=100"];
    for command in ["check", "run"] {
        let start = std::time::Instant::now();
        let (code, text) = cli_on(command, &scene, &set);
        assert_eq!(code, 2, "{command}: {text}");
        assert!(
            text.contains("material.relaxation.horizon")
                && text.contains("1e7")
                && text.contains("at most 3.125e5"),
            "{command}: {text}"
        );
        assert!(start.elapsed().as_secs_f64() < 10.0, "{command}: slow");
    }
    // So is a run whose own steps exceed the limit, naming time.steps.
    let scene = power_law().write(dir.path(), "pl.toml");
    let (code, text) = cli_on("check", &scene, &["time.steps=20000000", "time.end=100"]);
    assert_eq!(code, 2, "{text}");
    assert!(
        text.contains("time.steps") && text.contains("1e7"),
        "{text}"
    );
    // A horizon within the limit is fitted and its memory counted in the estimate.
    let scene = power_law()
        .set("material.relaxation.horizon", 3e4)
        .write(dir.path(), "pl.toml");
    let (code, text) = cli_on("check", &scene, &set);
    assert_eq!(code, 0, "{text}");
    assert!(text.contains("kernel     compressed"), "{text}");
    // 16 bytes on each of its 3e4·32 = 960 000 lags (and the direct sum's rows: 3200 steps
    // may fall back).
    let mb: f64 = text
        .split("resources  ≈ ")
        .nth(1)
        .and_then(|t| t.split(" MB of memory").next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no estimate in {text}"));
    assert!(mb >= 15.36, "{text}");
}

/// The estimate counts the Prony states, a scene's own series from the start and a
/// compressed kernel's once the kernels' plans are known: 8 bytes a free dof for each
/// term, which a checkpoint gathers once more; and a compressed kernel's direct sum only where its fit failed, not
/// where it merely might have (N ≤ `kernel_fit::EXACT_STEPS`). `check` names the terms
/// where the states do not fit.
#[test]
fn the_estimate_counts_every_prony_terms_state_at_every_dof() {
    use viscontact::history::Plans;
    use viscontact::resources::Estimate;
    let dir = tempfile::tempdir().unwrap();
    let memory = |scene: &SceneText, set: &[&str]| {
        let (scene, _, disc) = common::load(&scene.write(dir.path(), "s.toml"), set);
        let sizes = Estimate::new(&scene, &disc, 0);
        let plans = Plans::new(&scene).unwrap();
        let held = sizes.clone().with_plans(&plans, &disc);
        (
            sizes.memory(),
            held.memory(),
            disc.n_free as f64,
            plans.terms(),
        )
    };
    let prony = |terms: usize| {
        let series: Vec<String> = (0..terms).map(|i| format!("[0.1, {}.0]", i + 1)).collect();
        SceneText::paper().table(
            "material.relaxation",
            &format!("prony = [{}]", series.join(", ")),
        )
    };
    let none = SceneText::paper().remove("material.relaxation");
    for (set, copies) in [(&[][..], 2.0), (&["checkpoint.enabled=false"][..], 1.0)] {
        let (_, without, d, t0) = memory(&none, set);
        let (sizes1, one, _, t1) = memory(&prony(1), set);
        let (sizes7, seven, _, t7) = memory(&prony(7), set);
        assert_eq!((t0, t1, t7), (0, 1, 7));
        // A scene's own series is counted from the start, before the plans.
        assert_eq!((sizes1, sizes7), (one, seven), "{set:?}");
        assert_eq!(one - without, copies * 8.0 * d, "{set:?}");
        assert_eq!(seven - one, copies * 6.0 * 8.0 * d, "{set:?}");
    }
    // 3200 steps may fall back to the direct sum: counted before the fit, not after it.
    let (sizes, held, d, terms) = memory(&power_law(), &["time.steps=3200", "time.end=100"]);
    let rows = 8.0 * d * 3201.0;
    assert!(terms > 0 && sizes > 2.0 * rows, "{sizes} {rows}");
    assert!(
        held < sizes - 2.0 * rows + 2.0 * 8.0 * d * terms as f64 + 1.0,
        "{held}"
    );
    assert!(held >= 2.0 * 8.0 * d * terms as f64, "{held}");
    // Where the states do not fit, `check` names the terms.
    let (_, seven, _, _) = memory(&prony(7), &[]);
    let scene = prony(7).write(dir.path(), "p7.toml");
    let out = common::with_memory(0.9 * seven / 0.8, &["check", scene.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{text}");
    assert!(text.contains("the kernels' terms"), "{text}");
}

/// A checkpoint of a direct sum holds the rows it streams to its writer at once (the
/// queue's and two more), not every row no checkpoint holds yet once more: the estimate
/// with checkpoints exceeds the one without by those rows alone, all of them where the
/// queue takes every one.
#[test]
fn a_direct_sums_checkpoint_counts_the_rows_it_streams() {
    use viscontact::history::{queue_len, Plans};
    use viscontact::resources::Estimate;
    let dir = tempfile::tempdir().unwrap();
    let exact = power_law()
        .table(
            "material.relaxation",
            "expr = \"exp(-10*s)\"\nmemory = \"exact\"",
        )
        .write(dir.path(), "exact.toml");
    let memory = |set: &[&str]| {
        let (scene, _, disc) = common::load(&exact, set);
        let plans = Plans::new(&scene).unwrap();
        let held = Estimate::new(&scene, &disc, 0).with_plans(&plans, &disc);
        (held.memory(), disc.n_free)
    };
    let mut capped = false;
    for steps in [10, 100_000] {
        let n = format!("time.steps={steps}");
        let (with, d) = memory(&[&n]);
        let (without, _) = memory(&[&n, "checkpoint.enabled=false"]);
        let rows = (steps + 1).min(queue_len(d) + 2);
        capped |= rows < steps + 1;
        assert_eq!(with - without, 8.0 * (d * rows) as f64, "{steps} steps");
    }
    assert!(capped, "the queue holds fewer rows than the longer run's");
}

/// A body without a memory term (no `[material.relaxation]`: Remark 2.5) assembles no K_R,
/// which would be zero, and runs as with a kernel whose weight is zero, to round-off (the
/// products of K_B then run alone or paired with K_R, in another order).
#[test]
fn a_body_without_memory_assembles_no_k_r() {
    let dir = tempfile::tempdir().unwrap();
    let none = SceneText::paper()
        .remove("material.relaxation")
        .write(dir.path(), "none.toml");
    let zero = SceneText::paper()
        .table("material.relaxation", "prony = [[0.0, 10.0]]")
        .write(dir.path(), "zero.toml");
    let (scene_none, _, disc_none) = common::load(&none, &[]);
    let (scene_zero, _, disc_zero) = common::load(&zero, &[]);
    assert!(disc_none.k_r.is_empty());
    assert_eq!(disc_zero.k_r.len(), 1);
    let (a, b) = (
        common::trace(&scene_none, &disc_none).u_final,
        common::trace(&scene_zero, &disc_zero).u_final,
    );
    assert!(common::max_abs(&a) > 0.0);
    let d = common::rel_diff(&a, &b);
    assert!(d < 1e-12, "u_N differs by {d:e}");
}
