//! The paper's Tables 1–3 (Section 4), reproduced through the library API and printed beside
//! the published numbers.
//!
//! The scene is examples/paper.toml (the rectangle of Section 4, plane stress, R(s) = e^{−10s}
//! I, T = 1); the meshes are meshes/paper/rect_NNN.msh (1/h = 8 … 128, nested). The error is
//! ‖u_ref(T) − u_N^{kh}‖_1 (the full H¹ norm) against the reference h = k = 1/128, computed
//! on the reference mesh by exact P1 prolongation. All three tables share that reference, so
//! one study runs the three families:
//!
//! - Table 1: h = k = 1/8 … 1/64;
//! - Table 2: k = 1/128, h = 1/16 … 1/64;
//! - Table 3: h = 1/128, k = 1/8 … 1/32.
//!
//! The paper does not give the normal stress F and the friction coefficient μ on Γ3,2; the
//! scene uses F = 0.01 and μ = 0.5, so absolute errors are not expected to match, orders are.
//!
//!     cargo run --release --example paper_tables [-- OUT_DIR]
//!
//! Writes study.md, study.csv, study.json and the plots into OUT_DIR (default
//! out/paper-tables/).

use std::path::{Path, PathBuf};
use viscontact::study::{self, fraction, StudyOptions, Vary};

/// (h level, k level, error, order) of the paper's tables.
type PaperRow = (usize, usize, f64, Option<f64>);

const TABLE_1: [PaperRow; 4] = [
    (8, 8, 1.1919e-1, None),
    (16, 16, 6.4970e-2, Some(0.8754)),
    (32, 32, 3.3671e-2, Some(0.9482)),
    (64, 64, 1.5125e-2, Some(1.1546)),
];
const TABLE_2: [PaperRow; 3] = [
    (16, 128, 4.9313e-2, None),
    (32, 128, 2.7174e-2, Some(0.8598)),
    (64, 128, 1.3199e-2, Some(1.0418)),
];
const TABLE_3: [PaperRow; 3] = [
    (128, 8, 6.3619e-2, None),
    (128, 16, 3.3138e-2, Some(0.9410)),
    (128, 32, 1.5130e-2, Some(1.1311)),
];

fn main() -> viscontact::Result<()> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let scene = root.join("examples/paper.toml");
    let out = std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("out/paper-tables"));
    let opts = StudyOptions {
        levels: vec![8, 16, 32, 64],
        reference: 128,
        vary: vec![Vary::Both, Vary::H, Vary::K],
        progress: true,
        ..Default::default()
    };
    let report = study::run_study(&scene, &opts)?;

    for (family, (title, table)) in report.families.iter().zip([
        ("Table 1: h = k", &TABLE_1[..]),
        ("Table 2: k = 1/128 fixed", &TABLE_2[..]),
        ("Table 3: h = 1/128 fixed", &TABLE_3[..]),
    ]) {
        println!("\n{title} (reference h = k = 1/128)\n");
        println!(
            "| h | k | ‖e‖_1 (ours) | ‖e‖_1 (paper) | order (ours) | order (paper) | wall [s] |"
        );
        println!("|---|---|---:|---:|---:|---:|---:|");
        let mut prev: Option<&study::Row> = None;
        for &(hn, kn, paper_err, paper_order) in table {
            let (h, k) = (1.0 / hn as f64, 1.0 / kn as f64);
            let Some(row) = family
                .rows
                .iter()
                .find(|r| (r.h - h).abs() < 1e-12 && (r.k - k).abs() < 1e-12)
            else {
                continue;
            };
            // The order between the rows shown (the first row of a table has none).
            let order = prev.and_then(|p| {
                let (p0, p1) = if family.vary == Vary::H {
                    (p.h, row.h)
                } else {
                    (p.k, row.k)
                };
                study::observed_order(p.err_h1, row.err_h1, p0, p1)
            });
            let fmt = |o: Option<f64>| o.map_or("–".to_string(), |x| format!("{x:.4}"));
            println!(
                "| {} | {} | {:.4e} | {:.4e} | {} | {} | {:.3} |",
                fraction(row.h),
                fraction(row.k),
                row.err_h1,
                paper_err,
                fmt(order),
                fmt(paper_order),
                row.wall_s
            );
            prev = Some(row);
        }
    }
    let r = &report.families[0].reference;
    println!(
        "\nreference: {} dofs, N = {}, ‖u_ref(T)‖_1 = {:.4e}, {:.2} s",
        r.dofs, r.steps, r.u_h1, r.wall_s
    );
    for p in study::write_report(&report, &out)? {
        println!("wrote {}", p.display());
    }
    Ok(())
}
