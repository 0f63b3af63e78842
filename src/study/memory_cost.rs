//! What accuracy costs: `viscontact study SCENE --tolerances …` (issue 13).
//!
//! For a scene whose kernel is an expression or a table, the memory sum of (3.1) is run with
//! the kernel compressed at each tolerance ε (`kernel_fit`: a certified sum of exponentials,
//! O(p) per step) and, where it is affordable (N ≤ `--exact-up-to`), with the direct sum
//! (`memory = "exact"`, O(n) per step), for several numbers of steps N at the scene's step
//! size k (time.end = N·k). Each row records
//!
//! - the terms p of the fit and its certified error max_l |r̃(lk) − r(lk)| / max_l |r(lk)|,
//!   or that the fit missed ε and the run fell back to the direct sum;
//! - the error of the end displacement against the direct sum,
//!   max_i |u_N,i − u_N,i^exact| / max_i |u_N,i^exact| over the free dofs;
//! - the wall time from reading the scene to u_N (mesh, assembly, fit, factorization and
//!   the N + 1 steps; no output).
//!
//! Written: memory_cost.md, .csv, .json and two plots, the error of u_N against ε (one curve
//! per N, with the line error = ε) and the wall time against N (one curve per ε and the
//! direct sum).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;

use super::say;
use crate::history::{Plan, Plans};
use crate::kernel::Kernel;
use crate::plot::{log_log_chart, Curve};
use crate::run::{discretize, load_scene};
use crate::scene::Scene;
use crate::time_loop::TimeLoop;
use crate::{Error, Result};

/// What a memory-cost study runs.
#[derive(Clone, Debug)]
pub struct Options {
    pub tolerances: Vec<f64>,
    /// Numbers of steps N (k stays the scene's).
    pub steps: Vec<usize>,
    /// The direct sum is run for N up to this (it costs O(N²)).
    pub exact_up_to: usize,
    pub overrides: Vec<String>,
    /// Progress lines on stderr.
    pub progress: bool,
}

/// One run: N steps with the kernel compressed at `tolerance`, or exact (None).
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    pub steps: usize,
    pub tolerance: Option<f64>,
    /// "compressed", or "exact" (asked for, or the fit missed the tolerance: `fallback`).
    pub method: &'static str,
    pub terms: usize,
    pub certified_error: Option<f64>,
    pub fallback: Option<String>,
    /// max|u_N − u_N^exact| / max|u_N^exact|, where the direct sum ran.
    pub error_u: Option<f64>,
    /// None: not run (a fallback to the direct sum beyond `exact_up_to`).
    pub wall_s: Option<f64>,
}

#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub scene: String,
    pub kernel: String,
    pub k: f64,
    pub rows: Vec<Row>,
}

/// Runs the study; the scene's kernel must be an expression or a table.
pub fn run_memory_cost(scene_path: &Path, opts: &Options) -> Result<Report> {
    let scene = crate::scene::Scene::load(scene_path, &opts.overrides)?;
    let kernel = match &scene.physics.relaxation {
        Some(Kernel::Expr(e)) => format!("expr {}", e.source()),
        Some(Kernel::Table(..)) => "table".into(),
        _ => {
            return Err(Error::input(format!(
                "{}: study --tolerances compares compressed kernels with the direct sum, so \
                 [material.relaxation] must give 'expr' or 'table' (a Prony series is already \
                 exact and O(1) per step)",
                scene_path.display()
            )))
        }
    };
    if let Some(t) = opts.tolerances.iter().find(|t| !(**t > 0.0 && **t < 1.0)) {
        return Err(Error::input(format!(
            "--tolerances: {t} is not a relative error in (0, 1); e.g. 1e-4,1e-8,1e-12"
        )));
    }
    if opts.steps.contains(&0) {
        return Err(Error::input("--steps: a number of steps is at least 1"));
    }
    let k = scene.time.k();
    let mut rows = Vec::new();
    for &n in &opts.steps {
        let end = n as f64 * k;
        let direct = n <= opts.exact_up_to;
        let exact = if direct {
            say(opts.progress, &format!("N = {n}: exact (direct sum)"));
            let exact = |s: Scene| s.with_exact_memory()?.with_time(end, n);
            let (u, row) = solve(scene_path, &opts.overrides, exact, true)?;
            rows.push(row);
            u
        } else {
            None
        };
        for &tol in &opts.tolerances {
            say(opts.progress, &format!("N = {n}: tolerance {tol:e}"));
            let at_tol = |s: Scene| s.with_tolerance(tol)?.with_time(end, n);
            let (u, row) = solve(scene_path, &opts.overrides, at_tol, direct)?;
            rows.push(Row {
                tolerance: Some(tol),
                error_u: u.zip(exact.as_ref()).map(|(u, e)| relative_max(&u, e)),
                ..row
            });
        }
    }
    Ok(Report {
        scene: scene_path.display().to_string(),
        kernel,
        k,
        rows,
    })
}

/// One run to t_N of the scene as `case` changes it: u_N and its row (steps, tolerance and
/// error_u left for the caller). A fit that misses its tolerance falls back to the direct
/// sum, which runs only when `direct` allows it (u_N is then None and so is the wall time).
fn solve(
    scene_path: &Path,
    overrides: &[String],
    case: impl FnOnce(Scene) -> Result<Scene>,
    direct: bool,
) -> Result<(Option<Vec<f64>>, Row)> {
    let start = Instant::now();
    let (scene, _mesh, disc) = discretize(case(load_scene(scene_path, overrides)?)?)?;
    let plans = Plans::new(&scene)?;
    let (method, terms, certified_error, fallback) = match &plans.body {
        Plan::Compressed(fit) => ("compressed", fit.terms.len(), Some(fit.error), None),
        Plan::Exact { fallback, .. } => ("exact", 0, None, fallback.clone()),
        Plan::None | Plan::Prony(_) => unreachable!("the study checked for expr or table"),
    };
    let mut row = Row {
        steps: scene.time.steps,
        tolerance: None,
        method,
        terms,
        certified_error,
        fallback,
        error_u: None,
        wall_s: None,
    };
    if method == "exact" && !direct {
        return Ok((None, row));
    }
    let mut tl = TimeLoop::with_plan(&scene, &disc, plans)?;
    super::solve_to_end(&mut tl, scene.time.steps)?;
    row.wall_s = Some(start.elapsed().as_secs_f64());
    Ok((Some(tl.u().to_vec()), row))
}

fn relative_max(u: &[f64], exact: &[f64]) -> f64 {
    let max = exact.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let diff = u
        .iter()
        .zip(exact)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    diff / max
}

fn opt(v: Option<f64>, fmt: fn(f64) -> String) -> String {
    v.map_or("–".into(), fmt)
}

fn tolerance(r: &Row) -> String {
    opt(r.tolerance, |t| format!("{t:.0e}"))
}

fn method(r: &Row) -> String {
    match (&r.fallback, r.method) {
        (Some(_), _) if r.wall_s.is_none() => "fit missed ε; direct sum not run".into(),
        (Some(_), _) => "exact (fit missed ε)".into(),
        (None, m) => m.into(),
    }
}

/// The table, with the fallback reasons under it.
pub fn markdown(report: &Report) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# What accuracy costs: {} ({}, k = {})\n",
        report.scene, report.kernel, report.k
    );
    s.push_str(
        "| N | tolerance | method | terms | certified error | ‖u_N − u_N^exact‖∞ / ‖u_N^exact‖∞ | wall (s) |\n\
         |---:|---:|---|---:|---:|---:|---:|\n",
    );
    for r in &report.rows {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} |",
            r.steps,
            tolerance(r),
            method(r),
            if r.method == "compressed" {
                r.terms.to_string()
            } else {
                "–".into()
            },
            opt(r.certified_error, |e| format!("{e:.1e}")),
            opt(r.error_u, |e| format!("{e:.1e}")),
            opt(r.wall_s, |t| format!("{t:.2}"))
        );
    }
    for r in report.rows.iter().filter(|r| r.fallback.is_some()) {
        let _ = writeln!(
            s,
            "\nN = {}, tolerance {}: {}",
            r.steps,
            tolerance(r),
            r.fallback.as_deref().unwrap_or_default()
        );
    }
    s
}

pub fn csv(report: &Report) -> String {
    let mut s = String::from("steps,tolerance,method,terms,certified_error,error_u,wall_s\n");
    let num = |v: Option<f64>| v.map_or(String::new(), |x| format!("{x:e}"));
    for r in &report.rows {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{}",
            r.steps,
            num(r.tolerance),
            if r.fallback.is_some() {
                "fallback"
            } else {
                r.method
            },
            r.terms,
            num(r.certified_error),
            num(r.error_u),
            num(r.wall_s)
        );
    }
    s
}

/// Writes memory_cost.{md,csv,json} and the plots into `dir`; returns the paths.
pub fn write_report(report: &Report, dir: &Path) -> Result<Vec<PathBuf>> {
    use crate::output::write_atomic;
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let mut written = Vec::new();
    for (name, bytes) in [
        ("memory_cost.md", markdown(report)),
        ("memory_cost.csv", csv(report)),
        (
            "memory_cost.json",
            serde_json::to_string_pretty(report).expect("report serializes") + "\n",
        ),
    ] {
        let p = dir.join(name);
        write_atomic(&p, bytes.as_bytes())?;
        written.push(p);
    }
    written.extend(plot_error(report, dir)?);
    written.push(plot_time(report, dir)?);
    Ok(written)
}

/// The error of u_N against the tolerance, one curve per N where the direct sum ran, with
/// the line error = ε; None when the direct sum ran nowhere.
fn plot_error(report: &Report, dir: &Path) -> Result<Option<PathBuf>> {
    let mut steps: Vec<usize> = report.rows.iter().map(|r| r.steps).collect();
    steps.dedup();
    let mut curves: Vec<Curve> = steps
        .iter()
        .enumerate()
        .filter_map(|(i, &n)| {
            let pts: Vec<(f64, f64)> = report
                .rows
                .iter()
                .filter(|r| r.steps == n && r.method == "compressed")
                .filter_map(|r| Some((r.tolerance?, r.error_u?.max(1e-17))))
                .collect();
            (!pts.is_empty()).then(|| Curve::data(i, format!("N = {n}"), pts))
        })
        .collect();
    if curves.is_empty() {
        return Ok(None);
    }
    let (t0, t1) = report
        .rows
        .iter()
        .filter_map(|r| r.tolerance)
        .fold((f64::INFINITY, 0.0f64), |(a, b), t| (a.min(t), b.max(t)));
    curves.push(Curve::reference(
        "error = tolerance".into(),
        vec![(t0, t0), (t1, t1)],
    ));
    let p = dir.join("memory_cost_error.png");
    log_log_chart(
        &p,
        "Compressed memory: error of u_N against the tolerance",
        "tolerance ε of the fit",
        "max|u_N − u_N^exact| / max|u_N^exact|",
        &curves,
    )?;
    Ok(Some(p))
}

/// The wall time against N: one curve per tolerance and the direct sum.
fn plot_time(report: &Report, dir: &Path) -> Result<PathBuf> {
    let mut series: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    for r in &report.rows {
        let label = match r.tolerance {
            None => "exact (direct sum)".to_string(),
            Some(t) => format!("ε = {t:.0e}"),
        };
        let Some(wall) = r.wall_s else { continue };
        let point = (r.steps as f64, wall);
        match series.iter_mut().find(|(l, _)| *l == label) {
            Some((_, pts)) => pts.push(point),
            None => series.push((label, vec![point])),
        }
    }
    let curves: Vec<Curve> = series
        .into_iter()
        .enumerate()
        .map(|(i, (label, pts))| Curve::data(i, label, pts))
        .collect();
    let p = dir.join("memory_cost_time.png");
    log_log_chart(
        &p,
        "What accuracy costs: wall time of a run",
        "N (number of time steps)",
        "wall time [s]",
        &curves,
    )?;
    Ok(p)
}
