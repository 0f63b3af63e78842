//! A study's report: the tables (Markdown, CSV, JSON) and the plots of error against h,
//! k and wall time, and of the cost of memory.

use super::{CostRow, Family, Row, StudyOptions, StudyReport, Timed, Vary};
use crate::plot::{log_log_chart, Curve};
use crate::{Error, Result};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// `1/n` when x is the reciprocal of an integer (up to rounding), else x in short form.
pub fn fraction(x: f64) -> String {
    let n = (1.0 / x).round();
    if n >= 1.0 && ((1.0 / n) - x).abs() <= 1e-12 * x {
        format!("1/{n}")
    } else {
        format!("{x:.4}")
    }
}

fn opt(v: Option<f64>) -> String {
    v.map_or("–".into(), |x| format!("{x:.4}"))
}

/// The study as Markdown: one table per family, then the cost of memory.
pub fn markdown(report: &StudyReport) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Study of {} (T = {})\n", report.scene, report.end_time);
    let _ = writeln!(
        s,
        "Error e = u_N − u_ref(T) on the reference mesh; ‖·‖_1 is the full H¹ norm \
         (‖e‖²_L² + |e|²_H¹)^½. Wall time: median over runs of the whole run (setup + all \
         steps, no output).\n"
    );
    match report.timed {
        Timed::InTurn => {}
        Timed::SideBySide(n) => {
            let _ = writeln!(
                s,
                "The cases ran up to {n} side by side (--jobs {n}), each with its share of the \
                 cores: their wall times were measured concurrently and are longer than a \
                 case's alone.\n"
            );
        }
        Timed::SlurmArray => {
            let _ = writeln!(
                s,
                "The cases ran as the tasks of a Slurm job array: their wall times are those \
                 of the runs (summary.json, output included) on the cluster's nodes.\n"
            );
        }
    }
    for f in &report.families {
        family_table(&mut s, f);
    }
    if !report.kernel_cost.is_empty() {
        kernel_cost_table(&mut s, report);
    }
    s
}

/// The table of one family, under a heading that names it and its reference.
fn family_table(s: &mut String, f: &Family) {
    let r = &f.reference;
    let _ = writeln!(
        s,
        "## {} — kernel: {}\n\nReference: h = {}, k = {} (N = {}, {} dofs, ‖u_ref‖_1 = {:.4e}, {:.2} s), {}\n",
        f.vary.title(),
        f.kernel,
        fraction(r.h),
        fraction(r.k),
        r.steps,
        r.dofs,
        r.u_h1,
        r.wall_s,
        r.mesh
    );
    let _ = writeln!(
        s,
        "| h | k | dofs | steps | ‖e‖_1 | ‖e‖_1/‖u‖_1 | ‖e‖_L² | order ‖·‖_1 | order L² | wall [s] | per step [ms] | nested |"
    );
    let _ = writeln!(
        s,
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|:---:|"
    );
    for row in &f.rows {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {:.4e} | {:.3e} | {:.4e} | {} | {} | {:.3} | {:.3} | {} |",
            fraction(row.h),
            fraction(row.k),
            row.dofs,
            row.steps,
            row.err_h1,
            row.rel_h1,
            row.err_l2,
            opt(row.order_h1),
            opt(row.order_l2),
            row.wall_s,
            row.per_step_s * 1e3,
            if row.nested { "yes" } else { "no" }
        );
    }
    s.push('\n');
}

/// The cost of memory: Prony against expression at each level (`--kernel-compare`).
fn kernel_cost_table(s: &mut String, report: &StudyReport) {
    let _ = writeln!(
        s,
        "## The cost of memory: Prony recursion (O(1) per step) against the direct sum \
         (O(n) per step)\n"
    );
    let _ = writeln!(
        s,
        "| vary | N | dofs | Prony steps [s] | expression steps [s] | ratio | Prony per step [ms] | expression per step [ms] | rel. max difference of u_N |"
    );
    let _ = writeln!(s, "|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    for c in &report.kernel_cost {
        let n1 = (c.steps + 1) as f64;
        let _ = writeln!(
            s,
            "| {} | {} | {} | {:.3} | {:.3} | {:.1} | {:.3} | {:.3} | {:.1e} |",
            c.family,
            c.steps,
            c.dofs,
            c.prony_steps_s,
            c.expression_steps_s,
            c.expression_steps_s / c.prony_steps_s,
            c.prony_steps_s / n1 * 1e3,
            c.expression_steps_s / n1 * 1e3,
            c.max_rel_diff
        );
    }
    s.push('\n');
}

/// The rows of every family as CSV.
pub fn csv(report: &StudyReport) -> String {
    let mut s = String::from(
        "family,kernel,level,h,h_max,k,steps,nodes,dofs,err_h1,err_h1_semi,err_l2,rel_h1,rel_l2,\
         order_h1,order_l2,wall_s,steps_s,per_step_s,runs,nested,mesh\n",
    );
    let o = |v: Option<f64>| v.map_or(String::new(), |x| format!("{x}"));
    for f in &report.families {
        for r in &f.rows {
            let _ = writeln!(
                s,
                "{},{},{},{},{},{},{},{},{},{:e},{:e},{:e},{:e},{:e},{},{},{},{},{},{},{},\"{}\"",
                r.family,
                r.kernel,
                r.level,
                r.h,
                r.h_max,
                r.k,
                r.steps,
                r.nodes,
                r.dofs,
                r.err_h1,
                r.err_h1_semi,
                r.err_l2,
                r.rel_h1,
                r.rel_l2,
                o(r.order_h1),
                o(r.order_l2),
                r.wall_s,
                r.steps_s,
                r.per_step_s,
                r.runs,
                r.nested,
                r.mesh.replace('"', "\"\"")
            );
        }
    }
    s
}

fn kernel_cost_csv(report: &StudyReport) -> String {
    let mut s = String::from(
        "family,level,steps,dofs,prony_steps_s,expression_steps_s,prony_wall_s,expression_wall_s,max_rel_diff\n",
    );
    for c in &report.kernel_cost {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{},{:e}",
            c.family,
            c.level,
            c.steps,
            c.dofs,
            c.prony_steps_s,
            c.expression_steps_s,
            c.prony_wall_s,
            c.expression_wall_s,
            c.max_rel_diff
        );
    }
    s
}

/// The default output directory: `out/<scene name>-study-<vary>/`.
pub fn default_out(scene_path: &Path, opts: &StudyOptions) -> Result<PathBuf> {
    let scene = crate::scene::Scene::load(scene_path, &opts.overrides)?;
    let vary: Vec<String> = opts.vary.iter().map(|v| v.to_string()).collect();
    Ok(Path::new("out").join(format!("{}-study-{}", scene.name, vary.join("-"))))
}

/// Writes study.md, study.csv, study.json, the PNG plots (and kernel_cost.csv) into `dir`;
/// returns the paths written.
pub fn write_report(report: &StudyReport, dir: &Path) -> Result<Vec<PathBuf>> {
    use crate::output::write_atomic;
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let mut written = Vec::new();
    let mut put = |name: &str, bytes: &[u8]| -> Result<()> {
        let p = dir.join(name);
        write_atomic(&p, bytes)?;
        written.push(p);
        Ok(())
    };
    put("study.md", markdown(report).as_bytes())?;
    put("study.csv", csv(report).as_bytes())?;
    let json = serde_json::to_string_pretty(report).expect("report serializes") + "\n";
    put("study.json", json.as_bytes())?;
    if !report.kernel_cost.is_empty() {
        put("kernel_cost.csv", kernel_cost_csv(report).as_bytes())?;
    }
    written.push(plot_error_vs_time(report, dir)?);
    written.extend(plot_error_vs_h_and_k(report, dir)?);
    if !report.kernel_cost.is_empty() {
        written.push(plot_kernel_cost(report, dir)?);
    }
    Ok(written)
}

/// A family's name in the plots (with its kernel when the kernels are compared).
fn family_label(report: &StudyReport, f: &Family) -> String {
    if report.kernel_cost.is_empty() {
        f.vary.title().to_string()
    } else {
        format!("{} [{}]", f.vary.title(), f.kernel)
    }
}

/// Error against wall time: which refinement buys accuracy most cheaply.
fn plot_error_vs_time(report: &StudyReport, dir: &Path) -> Result<PathBuf> {
    let curves: Vec<Curve> = report
        .families
        .iter()
        .enumerate()
        .map(|(i, f)| {
            Curve::data(
                i,
                family_label(report, f),
                f.rows.iter().map(|r| (r.wall_s, r.err_h1)).collect(),
            )
            .with_point_labels(
                f.rows
                    .iter()
                    .map(|r| match f.vary {
                        Vary::Both => format!("h=k={}", fraction(r.k)),
                        Vary::H => format!("h={}", fraction(r.h)),
                        Vary::K => format!("k={}", fraction(r.k)),
                    })
                    .collect(),
            )
        })
        .collect();
    let p = dir.join("error_vs_time.png");
    log_log_chart(
        &p,
        "Error at T against wall time",
        "wall time of a run [s]",
        "‖u_N − u_ref(T)‖₁",
        &curves,
    )?;
    Ok(p)
}

/// Error against h and against k, with slope-1 reference lines (a plot only where a
/// family varies that parameter).
fn plot_error_vs_h_and_k(report: &StudyReport, dir: &Path) -> Result<Vec<PathBuf>> {
    let mut written = Vec::new();
    for (name, axis, x_of, varies) in [
        (
            "error_vs_h.png",
            "h",
            (|r: &Row| r.h) as fn(&Row) -> f64,
            [Vary::Both, Vary::H],
        ),
        (
            "error_vs_k.png",
            "k",
            (|r: &Row| r.k) as fn(&Row) -> f64,
            [Vary::Both, Vary::K],
        ),
    ] {
        let mut curves = Vec::new();
        for (i, f) in report.families.iter().enumerate() {
            if !varies.contains(&f.vary) || f.rows.is_empty() {
                continue;
            }
            let pts: Vec<(f64, f64)> = f.rows.iter().map(|r| (x_of(r), r.err_h1)).collect();
            let (x0, e0) = pts[0];
            let x1 = pts[pts.len() - 1].0;
            if curves.is_empty() {
                // One slope-1 line, through the first point of the first family.
                curves.push(Curve::reference(
                    "slope 1".into(),
                    vec![(x0, e0), (x1, e0 * x1 / x0)],
                ));
            }
            let labels = pts.iter().map(|p| fraction(p.0)).collect();
            curves.push(Curve::data(i, family_label(report, f), pts).with_point_labels(labels));
        }
        if curves.is_empty() {
            continue;
        }
        let p = dir.join(name);
        log_log_chart(
            &p,
            &format!("Error at T against {axis}"),
            axis,
            "‖u_N − u_ref(T)‖₁",
            &curves,
        )?;
        written.push(p);
    }
    Ok(written)
}

/// The cost of memory: time of the steps against N, Prony and expression per family, with
/// slope-1 and slope-2 reference lines.
fn plot_kernel_cost(report: &StudyReport, dir: &Path) -> Result<PathBuf> {
    let mut curves = Vec::new();
    let mut varies: Vec<Vary> = report.kernel_cost.iter().map(|c| c.family).collect();
    varies.dedup();
    for (i, v) in varies.iter().enumerate() {
        let rows: Vec<&CostRow> = report
            .kernel_cost
            .iter()
            .filter(|c| c.family == *v)
            .collect();
        let pts = |f: fn(&CostRow) -> f64| -> Vec<(f64, f64)> {
            rows.iter().map(|c| (c.steps as f64, f(c))).collect()
        };
        curves.push(Curve::data(
            2 * i,
            format!("Prony, O(1) per step (vary {v})"),
            pts(|c| c.prony_steps_s),
        ));
        curves.push(Curve::data(
            2 * i + 1,
            format!("expression, O(n) per step (vary {v})"),
            pts(|c| c.expression_steps_s),
        ));
    }
    if let (Some(first), Some(last)) = (report.kernel_cost.first(), report.kernel_cost.last()) {
        let (n0, n1) = (first.steps as f64, last.steps as f64);
        let t0 = first.prony_steps_s.min(first.expression_steps_s);
        if n1 > n0 {
            curves.push(Curve::reference(
                "slope 1".into(),
                vec![(n0, t0), (n1, t0 * n1 / n0)],
            ));
            let mut slope2 = Curve::reference(
                "slope 2".into(),
                vec![(n0, t0), (n1, t0 * (n1 / n0).powi(2))],
            );
            slope2.color = 1;
            curves.push(slope2);
        }
    }
    let p = dir.join("kernel_cost.png");
    log_log_chart(
        &p,
        "The cost of memory: time of the N + 1 steps",
        "N (number of time steps)",
        "time of all steps [s]",
        &curves,
    )?;
    Ok(p)
}
