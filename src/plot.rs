//! PNG figures (plotters, bitmap backend): the `plot` command — the deformed body of a run
//! coloured by a field, the paper's Fig. 3 for any run — and the log-log charts of a study.
//!
//! Text is drawn with DejaVu Sans embedded in the binary (crate `dejavu`, rendered by
//! ab_glyph), so a figure needs no system font and no fontconfig.

use crate::output::read::{read_frame, read_series, Vtu};
use crate::{Error, Result};
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::{Path, PathBuf};

/// The font family every text of a figure uses.
const FONT: &str = "sans-serif";

fn register_fonts() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let regular = dejavu::sans::regular();
        for style in [
            FontStyle::Normal,
            FontStyle::Bold,
            FontStyle::Italic,
            FontStyle::Oblique,
        ] {
            // The embedded font is a valid TrueType file: registering cannot fail.
            let _ = plotters::style::register_font(FONT, style, regular);
        }
    });
}

/// A drawing error as an I/O error on the figure's path (exit status 1).
fn draw_err<E: std::fmt::Debug>(path: &Path) -> impl Fn(E) -> Error + '_ {
    move |e| {
        Error::io(
            path,
            std::io::Error::other(format!("drawing the figure failed: {e:?}")),
        )
    }
}

/// Data colours (colour-blind friendly, Okabe–Ito).
const PALETTE: [RGBColor; 7] = [
    RGBColor(0, 114, 178),
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(230, 159, 0),
    RGBColor(86, 180, 233),
    RGBColor(0, 0, 0),
];

/// Viridis, sampled at 0, 1/8, …, 1; `colormap(t)` interpolates linearly, t ∈ [0, 1].
const VIRIDIS: [(u8, u8, u8); 9] = [
    (68, 1, 84),
    (71, 45, 123),
    (59, 82, 139),
    (44, 114, 142),
    (33, 145, 140),
    (40, 174, 128),
    (94, 201, 98),
    (173, 220, 48),
    (253, 231, 37),
];

pub fn colormap(t: f64) -> RGBColor {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let x = t * (VIRIDIS.len() - 1) as f64;
    let i = (x.floor() as usize).min(VIRIDIS.len() - 2);
    let f = x - i as f64;
    let (a, b) = (VIRIDIS[i], VIRIDIS[i + 1]);
    let mix = |p: u8, q: u8| (p as f64 + f * (q as f64 - p as f64)).round() as u8;
    RGBColor(mix(a.0, b.0), mix(a.1, b.1), mix(a.2, b.2))
}

// ---------------------------------------------------------------------------------------
// Log-log charts (study)
// ---------------------------------------------------------------------------------------

/// One curve of a chart: data (coloured, with markers) or a reference line (grey, dashed).
#[derive(Clone, Debug)]
pub struct Curve {
    pub label: String,
    pub points: Vec<(f64, f64)>,
    /// A short label beside each point (empty: none).
    pub point_labels: Vec<String>,
    pub reference: bool,
    pub color: usize,
}

impl Curve {
    pub fn data(color: usize, label: String, points: Vec<(f64, f64)>) -> Self {
        Curve {
            label,
            points,
            point_labels: Vec::new(),
            reference: false,
            color,
        }
    }

    pub fn reference(label: String, points: Vec<(f64, f64)>) -> Self {
        Curve {
            label,
            points,
            point_labels: Vec::new(),
            reference: true,
            color: 0,
        }
    }

    /// With a short label beside each point.
    pub fn with_point_labels(mut self, labels: Vec<String>) -> Self {
        self.point_labels = labels;
        self
    }
}

/// `lo..hi` widened by a factor on each side (log axes).
fn log_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| *v > 0.0 && v.is_finite())
        .fold((f64::INFINITY, 0.0f64), |(a, b), v| (a.min(v), b.max(v)));
    if !lo.is_finite() {
        return (0.1, 10.0);
    }
    let pad = (hi / lo).powf(0.08).max(1.25);
    (lo / pad, hi * pad)
}

/// An axis label: plain for 0.01 ≤ |v| < 10⁴ (`0.05`, `200`), else `2e-3`.
fn sci(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    if (1e-2..1e4).contains(&v.abs()) {
        return trim_float(format!("{:.3}", v).parse::<f64>().unwrap_or(v));
    }
    let e = v.abs().log10().floor();
    let m = v / 10f64.powf(e);
    if (m - m.round()).abs() < 0.05 {
        format!("{:.0}e{}", m.round(), e)
    } else {
        format!("{m:.1}e{e}")
    }
}

/// A log-log chart of `curves` as a PNG at `path` (1000 × 700).
pub fn log_log_chart(
    path: &Path,
    title: &str,
    x_desc: &str,
    y_desc: &str,
    curves: &[Curve],
) -> Result<()> {
    register_fonts();
    let err = draw_err(path);
    let root = BitMapBackend::new(path, (1000, 700)).into_drawing_area();
    root.fill(&WHITE).map_err(&err)?;
    let (x0, x1) = log_range(curves.iter().flat_map(|c| c.points.iter().map(|p| p.0)));
    let (y0, y1) = log_range(curves.iter().flat_map(|c| c.points.iter().map(|p| p.1)));
    let mut chart = ChartBuilder::on(&root)
        .caption(title, (FONT, 26))
        .margin(20)
        .x_label_area_size(50)
        .y_label_area_size(80)
        .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
        .map_err(&err)?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .x_labels(8)
        .y_labels(12)
        .x_label_formatter(&|v| sci(*v))
        .y_label_formatter(&|v| sci(*v))
        .label_style((FONT, 16))
        .axis_desc_style((FONT, 18))
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(205, 205, 205))
        .draw()
        .map_err(&err)?;
    // Legend where the data are not: rising data leave the upper left corner free,
    // falling data the lower left one.
    let mut rising = 0i32;
    for c in curves.iter().filter(|c| !c.reference) {
        if let (Some(a), Some(b)) = (c.points.first(), c.points.last()) {
            rising += if (b.1 - a.1) * (b.0 - a.0) > 0.0 {
                1
            } else {
                -1
            };
        }
    }
    for c in curves {
        if c.reference {
            // Successive reference lines: grey, long dashes; lighter, short dashes.
            let (grey, dash) = if c.color % 2 == 0 { (110, 8) } else { (165, 3) };
            let style = RGBColor(grey, grey, grey).stroke_width(2);
            chart
                .draw_series(DashedLineSeries::new(c.points.clone(), dash, 5, style))
                .map_err(&err)?
                .label(c.label.clone())
                .legend(move |(x, y)| {
                    DashedPathElement::new(vec![(x, y), (x + 24, y)], dash, 4, style)
                });
        } else {
            let color = PALETTE[c.color % PALETTE.len()];
            chart
                .draw_series(LineSeries::new(c.points.clone(), color.stroke_width(2)))
                .map_err(&err)?
                .label(c.label.clone())
                .legend(move |(x, y)| {
                    EmptyElement::at((x, y))
                        + PathElement::new(vec![(0, 0), (24, 0)], color.stroke_width(2))
                        + Circle::new((12, 0), 4, color.filled())
                });
            chart
                .draw_series(c.points.iter().map(|&p| Circle::new(p, 5, color.filled())))
                .map_err(&err)?;
            let style = TextStyle::from((FONT, 13).into_font()).color(&color);
            chart
                .draw_series(c.points.iter().zip(&c.point_labels).map(|(&p, l)| {
                    EmptyElement::at(p) + Text::new(l.clone(), (7, -16), style.clone())
                }))
                .map_err(&err)?;
        }
    }
    chart
        .configure_series_labels()
        .position(if rising > 0 {
            SeriesLabelPosition::UpperLeft
        } else {
            SeriesLabelPosition::LowerLeft
        })
        .label_font((FONT, 16))
        .background_style(WHITE.mix(0.9))
        .border_style(RGBColor(160, 160, 160))
        .draw()
        .map_err(&err)?;
    root.present().map_err(&err)?;
    Ok(())
}

// ---------------------------------------------------------------------------------------
// The deformed body (`viscontact plot`)
// ---------------------------------------------------------------------------------------

/// Options of the `plot` command.
#[derive(Clone, Debug)]
pub struct PlotOptions {
    /// The frame nearest to this time (default: the last frame).
    pub time: Option<f64>,
    /// A point or cell field; a vector or tensor field gives its magnitude, `name_X`,
    /// `name_XY`, … one component.
    pub field: String,
    /// Displacement scale (default: the largest displacement drawn as 10 % of the body size).
    pub scale: Option<f64>,
    /// The PNG to write (default: DIR/<field>_t<time>.png).
    pub output: Option<PathBuf>,
    /// Width of the figure in pixels.
    pub width: u32,
}

impl Default for PlotOptions {
    fn default() -> Self {
        PlotOptions {
            time: None,
            field: "von_mises".into(),
            scale: None,
            output: None,
            width: 1400,
        }
    }
}

/// What `plot_run` drew.
#[derive(Clone, Debug)]
pub struct PlotInfo {
    pub output: PathBuf,
    pub time: f64,
    pub frame: PathBuf,
    pub scale: f64,
    pub range: (f64, f64),
    pub contact_marked: bool,
}

/// The values of `field` at points or cells (one scalar each), and whether per point.
fn field_values(v: &Vtu, field: &str) -> Result<(Vec<f64>, bool)> {
    const VEC: [&str; 3] = ["X", "Y", "Z"];
    const TENSOR: [&str; 6] = ["XX", "YY", "ZZ", "XY", "YZ", "XZ"];
    let pick = |name: &str| {
        v.point_field(name)
            .map(|a| (a, true))
            .or_else(|| v.cell_field(name).map(|a| (a, false)))
    };
    let scalarize = |a: &crate::output::read::Array, comp: Option<usize>| -> Vec<f64> {
        a.values
            .chunks_exact(a.components)
            .map(|c| match comp {
                Some(i) => c[i],
                None if c.len() == 1 => c[0],
                None => c.iter().map(|x| x * x).sum::<f64>().sqrt(),
            })
            .collect()
    };
    if let Some((a, per_point)) = pick(field) {
        return Ok((scalarize(a, None), per_point));
    }
    if let Some((base, suffix)) = field.rsplit_once('_') {
        if let Some((a, per_point)) = pick(base) {
            let names: &[&str] = match a.components {
                3 => &VEC,
                6 => &TENSOR,
                _ => &[],
            };
            if let Some(i) = names.iter().position(|n| n.eq_ignore_ascii_case(suffix)) {
                return Ok((scalarize(a, Some(i)), per_point));
            }
        }
    }
    let mut names: Vec<String> = v
        .point_data
        .iter()
        .chain(&v.cell_data)
        .map(|a| match a.components {
            3 => format!("{} (or {0}_X, _Y, _Z)", a.name),
            6 => format!("{} (or {0}_XX, _YY, _XY, …)", a.name),
            _ => a.name.clone(),
        })
        .collect();
    names.dedup();
    Err(Error::input(format!(
        "plot: the run has no field '{field}'; it has: {}",
        names.join(", ")
    )))
}

/// Γ3,1 and Γ3,2 edges of the run's mesh, from its summary.json and scene (None when they
/// cannot be found, e.g. the run was made from another directory).
/// Γ3,1 and Γ3,2 facets (node pairs).
type ContactEdges = (Vec<[usize; 2]>, Vec<[usize; 2]>);

fn contact_edges(dir: &Path, nodes: usize) -> Option<ContactEdges> {
    let text = std::fs::read_to_string(dir.join("summary.json")).ok()?;
    let v: serde_json::Value = serde_json::from_str(&text).ok()?;
    let mesh = crate::mesh::Mesh::read(Path::new(v["mesh"].as_str()?)).ok()?;
    if mesh.nodes.len() != nodes {
        return None;
    }
    let groups = crate::scene::read_scene_file(Path::new(v["scene"].as_str()?), &[])
        .map(|(_, f)| f.mesh.groups)
        .unwrap_or_default();
    let facets = |name: &str| {
        mesh.boundary_group(name)
            .map(|g| g.facets.clone())
            .unwrap_or_default()
    };
    Some((facets(&groups.contact), facets(&groups.friction)))
}

/// Draws the deformed body of a run at one time, coloured by a field (the paper's Fig. 3).
pub fn plot_run(dir: &Path, opts: &PlotOptions) -> Result<PlotInfo> {
    register_fonts();
    if !dir.exists() {
        return Err(Error::input(format!(
            "plot: {} does not exist; give the output directory of a run (viscontact run … --out DIR)",
            dir.display()
        )));
    }
    let (series, entries) = read_series(dir).map_err(|e| match e {
        Error::Input(m) => Error::input(format!("plot: {m}")),
        other => other,
    })?;
    let dir = if dir.is_dir() {
        dir.to_path_buf()
    } else {
        dir.parent().unwrap_or(Path::new(".")).to_path_buf()
    };
    let (time, frame) = match opts.time {
        None => entries.last(),
        Some(t) => entries
            .iter()
            .min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs())),
    }
    .cloned()
    .ok_or_else(|| Error::input(format!("plot: {} lists no frames", series.display())))?;
    let v = read_frame(&frame)?;
    let frame = frame.path().to_path_buf();
    let disp = v
        .point_field("displacement")
        .filter(|a| a.components == 3)
        .ok_or_else(|| {
            Error::input(format!(
                "plot: {} has no 3-component point field 'displacement'",
                frame.display()
            ))
        })?;
    let (values, per_point) = field_values(&v, &opts.field)?;
    let tris: Vec<[usize; 3]> = v
        .cells
        .iter()
        .filter(|c| c.len() == 3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    if tris.len() != v.cells.len() {
        return Err(Error::input(format!(
            "plot: {} holds cells other than triangles; only 2D runs can be plotted",
            frame.display()
        )));
    }

    // Scale: the largest displacement drawn as 10 % of the body size.
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in &v.points {
        for c in 0..2 {
            lo[c] = lo[c].min(p[c]);
            hi[c] = hi[c].max(p[c]);
        }
    }
    let size = (hi[0] - lo[0]).max(hi[1] - lo[1]);
    let umax = disp
        .values
        .chunks_exact(3)
        .map(|u| (u[0] * u[0] + u[1] * u[1]).sqrt())
        .fold(0.0f64, f64::max);
    let scale = opts
        .scale
        .unwrap_or(if umax > 0.0 { 0.1 * size / umax } else { 1.0 });
    let def: Vec<(f64, f64)> = v
        .points
        .iter()
        .zip(disp.values.chunks_exact(3))
        .map(|(p, u)| (p[0] + scale * u[0], p[1] + scale * u[1]))
        .collect();
    for &(x, y) in &def {
        lo = [lo[0].min(x), lo[1].min(y)];
        hi = [hi[0].max(x), hi[1].max(y)];
    }
    let (vmin, vmax) = values
        .iter()
        .filter(|x| x.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    let (vmin, vmax) = if !vmin.is_finite() {
        (0.0, 1.0)
    } else if vmax - vmin <= 1e-300 + 1e-12 * vmax.abs() {
        (
            vmin - 0.5 * vmin.abs().max(1e-30),
            vmax + 0.5 * vmax.abs().max(1e-30),
        )
    } else {
        (vmin, vmax)
    };
    let norm = |x: f64| (x - vmin) / (vmax - vmin);

    // Layout: the body keeps its aspect ratio; a colour bar on the right.
    let bar_w = 190u32;
    let (caption, xl, yl, margin, legend_h) = (44u32, 45u32, 65u32, 20u32, 36u32);
    let pad = 0.04 * size;
    let (dx, dy) = (hi[0] - lo[0] + 2.0 * pad, hi[1] - lo[1] + 2.0 * pad);
    let mut pw = (opts.width.max(600) - bar_w - yl - 2 * margin) as f64;
    let mut ph = pw * dy / dx;
    if ph > 1400.0 {
        ph = 1400.0;
        pw = ph * dx / dy;
    }
    let width = pw as u32 + bar_w + yl + 2 * margin;
    let height = ph as u32 + caption + xl + 2 * margin + legend_h;
    let output = opts.output.clone().unwrap_or_else(|| {
        dir.join(format!(
            "{}_t{}.png",
            opts.field,
            format!("{time}").replace('.', "_")
        ))
    });
    let err = draw_err(&output);
    let root = BitMapBackend::new(&output, (width, height)).into_drawing_area();
    root.fill(&WHITE).map_err(&err)?;
    let (body_area, rest) = root.split_horizontally(width - bar_w);
    let (body_area, legend_area) = body_area.split_vertically(height - legend_h);
    let (title_area, body_area) = body_area.split_vertically(caption);
    let title = format!(
        "{} at t = {} — displacement × {}",
        opts.field,
        trim_float(time),
        sig3(scale)
    );
    let (x0, y0) = (lo[0] - pad, lo[1] - pad);
    let title_style =
        TextStyle::from((FONT, 24).into_font()).pos(Pos::new(HPos::Center, VPos::Bottom));
    title_area
        .draw(&Text::new(
            title,
            (((width - bar_w) / 2) as i32, caption as i32 - 6),
            title_style,
        ))
        .map_err(&err)?;
    let mut chart = ChartBuilder::on(&body_area)
        .margin(margin)
        .x_label_area_size(xl)
        .y_label_area_size(yl)
        .build_cartesian_2d(x0..x0 + dx, y0..y0 + dy)
        .map_err(&err)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("x")
        .y_desc("y")
        .label_style((FONT, 15))
        .axis_desc_style((FONT, 17))
        .draw()
        .map_err(&err)?;

    // Filled triangles; a point field is drawn on 4 sub-triangles per cell.
    let mut polys: Vec<([(f64, f64); 3], f64)> = Vec::with_capacity(4 * tris.len());
    for (c, t) in tris.iter().enumerate() {
        let p = t.map(|n| def[n]);
        if per_point {
            let f = t.map(|n| values[n]);
            let mid = |a: usize, b: usize| {
                (
                    ((p[a].0 + p[b].0) / 2.0, (p[a].1 + p[b].1) / 2.0),
                    (f[a] + f[b]) / 2.0,
                )
            };
            let (m01, m12, m20) = (mid(0, 1), mid(1, 2), mid(2, 0));
            polys.push(([p[0], m01.0, m20.0], (f[0] + m01.1 + m20.1) / 3.0));
            polys.push(([m01.0, p[1], m12.0], (m01.1 + f[1] + m12.1) / 3.0));
            polys.push(([m20.0, m12.0, p[2]], (m20.1 + m12.1 + f[2]) / 3.0));
            polys.push(([m01.0, m12.0, m20.0], (m01.1 + m12.1 + m20.1) / 3.0));
        } else {
            polys.push((p, values[c]));
        }
    }
    chart
        .draw_series(
            polys
                .iter()
                .map(|(p, f)| Polygon::new(p.to_vec(), colormap(norm(*f)).filled())),
        )
        .map_err(&err)?;
    // The mesh, when it is coarse enough to see.
    if tris.len() <= 20_000 {
        chart
            .draw_series(tris.iter().map(|t| {
                let p = t.map(|n| def[n]);
                PathElement::new(vec![p[0], p[1], p[2], p[0]], BLACK.mix(0.22))
            }))
            .map_err(&err)?;
    }
    // Boundary edges: undeformed (grey) and deformed (black).
    let mut edges: std::collections::HashMap<(usize, usize), usize> = Default::default();
    for t in &tris {
        for i in 0..3 {
            let (a, b) = (t[i], t[(i + 1) % 3]);
            *edges.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    let boundary: Vec<(usize, usize)> = edges
        .into_iter()
        .filter(|(_, c)| *c == 1)
        .map(|(e, _)| e)
        .collect();
    let undeformed = |n: usize| (v.points[n][0], v.points[n][1]);
    chart
        .draw_series(boundary.iter().map(|&(a, b)| {
            PathElement::new(
                vec![undeformed(a), undeformed(b)],
                RGBColor(150, 150, 150).stroke_width(1),
            )
        }))
        .map_err(&err)?;
    chart
        .draw_series(
            boundary
                .iter()
                .map(|&(a, b)| PathElement::new(vec![def[a], def[b]], BLACK.stroke_width(2))),
        )
        .map_err(&err)?;

    // The contact boundary: Γ3,1 red, Γ3,2 orange; nodes in contact or sticking as dots.
    let red = RGBColor(220, 30, 30);
    let orange = RGBColor(240, 150, 0);
    let edges3 = contact_edges(&dir, v.points.len());
    let mut legend: Vec<(String, RGBColor, bool)> = Vec::new();
    if let Some((c31, c32)) = &edges3 {
        for (list, color, name) in [
            (c31, red, "Γ3,1 (contact)"),
            (c32, orange, "Γ3,2 (friction)"),
        ] {
            if list.is_empty() {
                continue;
            }
            chart
                .draw_series(
                    list.iter().map(|f| {
                        PathElement::new(vec![def[f[0]], def[f[1]]], color.stroke_width(5))
                    }),
                )
                .map_err(&err)?;
            legend.push((name.to_string(), color, false));
        }
    }
    let state = v.point_field("contact_state").map(|a| &a.values);
    let pressure = v.point_field("contact_pressure").map(|a| &a.values);
    let friction = v.point_field("friction_traction").map(|a| &a.values);
    if let Some(state) = state {
        let active: Vec<usize> = (0..v.points.len()).filter(|&i| state[i] > 0.5).collect();
        if !active.is_empty() {
            chart
                .draw_series(
                    active
                        .iter()
                        .map(|&i| Circle::new(def[i], 4, BLACK.filled())),
                )
                .map_err(&err)?;
            legend.push(("contact_state = 1 (active / stick)".into(), BLACK, true));
        }
    }
    if edges3.is_none() {
        // Without the mesh groups: mark the nodes that carry a contact or friction traction.
        for (vals, color, name) in [
            (pressure, red, "contact pressure > 0"),
            (friction, orange, "friction traction ≠ 0"),
        ] {
            if let Some(vals) = vals {
                let marked: Vec<usize> = (0..v.points.len()).filter(|&i| vals[i] != 0.0).collect();
                if !marked.is_empty() {
                    chart
                        .draw_series(
                            marked
                                .iter()
                                .map(|&i| Circle::new(def[i], 5, color.stroke_width(2))),
                        )
                        .map_err(&err)?;
                    legend.push((name.to_string(), color, true));
                }
            }
        }
    }
    legend.push(("undeformed boundary".into(), RGBColor(150, 150, 150), false));
    draw_legend(&legend_area, &legend, yl + margin).map_err(&err)?;
    draw_colorbar(
        &rest,
        &opts.field,
        vmin,
        vmax,
        caption + margin,
        xl + margin,
    )
    .map_err(&err)?;
    root.present().map_err(&err)?;
    drop(chart);
    drop(root);
    Ok(PlotInfo {
        output: output.clone(),
        time,
        frame,
        scale,
        range: (vmin, vmax),
        contact_marked: edges3.is_some(),
    })
}

type DrawResult = std::result::Result<
    (),
    DrawingAreaErrorKind<<BitMapBackend<'static> as DrawingBackend>::ErrorType>,
>;

fn draw_legend(
    area: &DrawingArea<BitMapBackend, Shift>,
    items: &[(String, RGBColor, bool)],
    x0: u32,
) -> DrawResult {
    let mut x = x0 as i32;
    let y = 14;
    for (label, color, dot) in items {
        if *dot {
            area.draw(&Circle::new((x + 10, y), 5, color.filled()))?;
        } else {
            area.draw(&PathElement::new(
                vec![(x, y), (x + 22, y)],
                color.stroke_width(5),
            ))?;
        }
        let style = TextStyle::from((FONT, 16).into_font()).pos(Pos::new(HPos::Left, VPos::Center));
        area.draw(&Text::new(label.clone(), (x + 30, y), style))?;
        x += 30 + 9 * label.chars().count() as i32 + 30;
    }
    Ok(())
}

fn draw_colorbar(
    area: &DrawingArea<BitMapBackend, Shift>,
    field: &str,
    vmin: f64,
    vmax: f64,
    top: u32,
    bottom: u32,
) -> DrawResult {
    let (w, h) = area.dim_in_pixel();
    let (x0, x1) = (20i32, 50i32);
    let (y0, y1) = (top as i32 + 10, h as i32 - bottom as i32 - 40);
    if y1 <= y0 {
        return Ok(());
    }
    for y in y0..y1 {
        let t = (y1 - 1 - y) as f64 / (y1 - 1 - y0).max(1) as f64;
        area.draw(&Rectangle::new(
            [(x0, y), (x1, y + 1)],
            colormap(t).filled(),
        ))?;
    }
    area.draw(&Rectangle::new([(x0, y0), (x1, y1)], BLACK.stroke_width(1)))?;
    let style = TextStyle::from((FONT, 15).into_font()).pos(Pos::new(HPos::Left, VPos::Center));
    for i in 0..=5 {
        let t = i as f64 / 5.0;
        let y = y1 - ((y1 - y0) as f64 * t).round() as i32;
        area.draw(&PathElement::new(vec![(x1, y), (x1 + 6, y)], BLACK))?;
        area.draw(&Text::new(
            sig3(vmin + t * (vmax - vmin)),
            (x1 + 10, y),
            style.clone(),
        ))?;
    }
    let title = TextStyle::from((FONT, 17).into_font()).pos(Pos::new(HPos::Left, VPos::Bottom));
    area.draw(&Text::new(field.to_string(), (x0 - 5, y0 - 12), title))?;
    let _ = w;
    Ok(())
}

/// Three significant digits, in exponent form for small or large numbers.
fn sig3(x: f64) -> String {
    if x == 0.0 {
        "0".into()
    } else if x.abs() >= 1e-2 && x.abs() < 1e4 {
        let digits = (2 - x.abs().log10().floor() as i32).max(0) as usize;
        format!("{x:.digits$}")
    } else {
        format!("{x:.2e}")
    }
}

fn trim_float(x: f64) -> String {
    let s = format!("{x:.6}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    s.to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colormap_ends_and_clamps() {
        assert_eq!(colormap(0.0), RGBColor(68, 1, 84));
        assert_eq!(colormap(1.0), RGBColor(253, 231, 37));
        assert_eq!(colormap(2.0), colormap(1.0));
        assert_eq!(colormap(f64::NAN), colormap(0.0));
    }

    #[test]
    fn number_formats() {
        assert_eq!(sig3(0.012345), "0.0123");
        assert_eq!(sig3(12.345), "12.3");
        assert_eq!(sig3(1.5e-5), "1.50e-5");
        assert_eq!(trim_float(1.0), "1");
        assert_eq!(trim_float(0.03125), "0.03125");
        assert_eq!(sci(1e-3), "1e-3");
        assert_eq!(sci(200.0), "200");
        assert_eq!(sci(0.05), "0.05");
    }
}
