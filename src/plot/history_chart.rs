//! `viscontact plot DIR --history`: columns of a run's `history.csv` against t (`chart`'s
//! linear chart). By default the force columns: every `…_x`, `…_y`, `…_z` column but the
//! moments (reactions, loads, body force, contact, friction), so the figure shows the
//! balance of the forces on the body.

use super::chart::{line_chart, Curve};
use crate::{Error, Result};
use std::path::{Path, PathBuf};

/// What `plot_history` drew.
#[derive(Clone, Debug)]
pub struct HistoryPlot {
    pub output: PathBuf,
    pub columns: Vec<String>,
    pub rows: usize,
}

/// The columns of `history.csv` and its complete rows (a killed run may leave half a row).
struct Table {
    header: Vec<String>,
    rows: Vec<Vec<f64>>,
}

fn read_table(path: &Path) -> Result<Table> {
    let text = std::fs::read_to_string(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => Error::input(format!(
            "plot --history: {} does not exist; give the output directory of a run (runs \
             write history.csv)",
            path.display()
        )),
        _ => Error::io(path, e),
    })?;
    let mut lines = text.split_inclusive('\n').filter(|l| l.ends_with('\n'));
    let header: Vec<String> = match lines.next() {
        Some(h) => h.trim_end().split(',').map(String::from).collect(),
        None => Vec::new(),
    };
    let rows = lines
        .map(|l| {
            l.trim_end()
                .split(',')
                .map(|v| v.parse().unwrap_or(f64::NAN))
                .collect()
        })
        .collect();
    match header.first().map(String::as_str) {
        Some("step") => Ok(Table { header, rows }),
        _ => Err(Error::input(format!(
            "plot --history: {} is not a history.csv of viscontact (no header starting with \
             'step')",
            path.display()
        ))),
    }
}

/// The columns drawn: `asked`, each of which the file must have, or the force columns.
fn chosen(table: &Table, asked: Option<&[String]>, path: &Path) -> Result<Vec<usize>> {
    let Some(asked) = asked else {
        let force = |n: &str| {
            !n.starts_with("moment_") && ["_x", "_y", "_z"].iter().any(|s| n.ends_with(s))
        };
        return Ok((0..table.header.len())
            .filter(|&i| force(&table.header[i]))
            .collect());
    };
    asked
        .iter()
        .map(|name| {
            table.header.iter().position(|h| h == name).ok_or_else(|| {
                Error::input(format!(
                    "plot --history: --columns: {} has no column '{name}'; it has: {}",
                    path.display(),
                    table.header[1..].join(", ")
                ))
            })
        })
        .collect()
}

/// Draws the columns `asked` (default: the force columns) of `DIR/history.csv` against t
/// into `output` (default `<run>_history.png` in the current directory).
pub fn plot_history(
    dir: &Path,
    asked: Option<&[String]>,
    output: Option<&Path>,
) -> Result<HistoryPlot> {
    let dir = match dir.is_file() {
        true => dir.parent().unwrap_or(Path::new(".")),
        false => dir,
    };
    let path = dir.join("history.csv");
    let table = read_table(&path)?;
    let columns = chosen(&table, asked, &path)?;
    let t = table.header.iter().position(|h| h == "t").unwrap_or(0);
    let curves: Vec<Curve> = columns
        .iter()
        .enumerate()
        .map(|(color, &c)| {
            let points = table
                .rows
                .iter()
                .filter_map(|r| Some((*r.get(t)?, *r.get(c)?)));
            Curve::data(color, table.header[c].clone(), points.collect())
        })
        .collect();
    let output = match output {
        Some(o) => o.to_path_buf(),
        None => PathBuf::from(format!("{}_history.png", super::run_name(dir))),
    };
    let title = format!("{} — history", super::run_name(dir));
    line_chart(&output, &title, "t", "force on the body", &curves)?;
    Ok(HistoryPlot {
        output,
        columns: columns.iter().map(|&c| table.header[c].clone()).collect(),
        rows: table.rows.len(),
    })
}
