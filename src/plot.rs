//! PNG figures (plotters, bitmap backend): the `plot` command — the deformed body of a run
//! coloured by a field, the paper's Fig. 3 for any run — (`chart`) the log-log charts
//! of a study, and (`history_chart`) a run's forces against t (`plot --history`).
//!
//! Text is drawn with DejaVu Sans embedded in the binary (crate `dejavu`, rendered by
//! ab_glyph), so a figure needs no system font and no fontconfig.

use crate::output::read::{read_frame, read_series, FrameRef, Vtu};
use crate::{Error, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::{Path, PathBuf};

mod body3d;
mod chart;
mod history_chart;
mod surface;

pub use chart::{log_log_chart, Curve};
pub use history_chart::{plot_history, HistoryPlot};

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
// The deformed body (`viscontact plot`)
// ---------------------------------------------------------------------------------------

/// Options of the `plot` command.
#[derive(Clone, Debug)]
pub struct PlotOptions {
    /// The frame nearest to this time (default: the last frame); refused when it lies
    /// outside the frames' times by more than half the interval between frames.
    pub time: Option<f64>,
    /// A point or cell field; a vector or tensor field gives its magnitude, `name_X`,
    /// `name_XY`, … one component.
    pub field: String,
    /// Displacement scale (default: the largest displacement drawn as 10 % of the body size).
    pub scale: Option<f64>,
    /// The PNG to write (default: `<run>_<field>_t<time>.png` in the current directory,
    /// not in the run's directory; see `default_output`).
    pub output: Option<PathBuf>,
    /// Width of the figure in pixels.
    pub width: u32,
    /// A 3D run is seen from this direction, from the body towards the eye (default
    /// [`DEFAULT_VIEW`]); refused for a 2D run.
    pub view: Option<[f64; 3]>,
}

impl Default for PlotOptions {
    fn default() -> Self {
        PlotOptions {
            time: None,
            field: "von_mises".into(),
            scale: None,
            output: None,
            width: 1400,
            view: None,
        }
    }
}

/// The view of a 3D run unless `--view` says otherwise: from the front (−y), the right
/// (+x) and below (−z), so that the bottom face, where the examples' bodies touch their
/// foundation (Γ3), is seen together with the front and the loaded right side.
pub const DEFAULT_VIEW: [f64; 3] = [1.0, -1.5, -1.0];

/// Parses `--view X,Y,Z`: three finite numbers, not all zero.
pub fn parse_view(text: &str) -> std::result::Result<[f64; 3], String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let numbers: Vec<f64> = parts.iter().filter_map(|p| p.parse().ok()).collect();
    match numbers[..] {
        [x, y, z] if parts.len() == 3 && numbers.iter().all(|v| v.is_finite()) => {
            if x == 0.0 && y == 0.0 && z == 0.0 {
                Err("the view direction 0,0,0 has no direction; give e.g. 1,-2,1".into())
            } else {
                Ok([x, y, z])
            }
        }
        _ => Err(format!(
            "'{text}' is not a direction X,Y,Z of three numbers (e.g. 1,-2,1: from the \
             right, the front and above)"
        )),
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
    /// The view direction of a 3D run (None: a 2D run).
    pub view: Option<[f64; 3]>,
    /// What the user should know of the figure (one line each, for stderr): the time drawn
    /// when no frame is at `--time`, why the contact groups could not be found.
    pub notes: Vec<String>,
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

/// The facets of Γ3,1 and Γ3,2 in the run's mesh: edges (2D) and faces (3D).
#[derive(Clone, Debug, Default)]
struct ContactGroups {
    edges: [Vec<[usize; 2]>; 2],
    faces: [Vec<[usize; 3]>; 2],
}

/// Γ3,1 and Γ3,2 of the run's mesh, from the scene and mesh that its summary.json names
/// (absolute paths: found from any working directory). Err: why they cannot be found
/// (a copied series, a moved or changed mesh), which `plot` says.
fn contact_groups(dir: &Path, nodes: usize) -> std::result::Result<ContactGroups, String> {
    let summary = dir.join("summary.json");
    let text = std::fs::read_to_string(&summary)
        .map_err(|e| format!("cannot read {}: {e}", summary.display()))?;
    let v: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| format!("{}: {e}", summary.display()))?;
    let named = |key: &str| {
        v[key]
            .as_str()
            .map(PathBuf::from)
            .ok_or_else(|| format!("{} names no {key} file", summary.display()))
    };
    let mesh_path = named("mesh")?;
    let mesh = crate::mesh::Mesh::read(&mesh_path)
        .map_err(|e| format!("the run's mesh {} cannot be read: {e}", mesh_path.display()))?;
    if mesh.nodes.len() != nodes {
        return Err(format!(
            "the run's mesh {} has {} nodes, its frames {nodes}: the mesh changed since the run",
            mesh_path.display(),
            mesh.nodes.len()
        ));
    }
    let scene_path = named("scene")?;
    let groups = crate::scene::read_scene_file(&scene_path, &[])
        .map(|(_, f)| f.mesh.groups)
        .map_err(|e| {
            format!(
                "the run's scene {} cannot be read: {e}",
                scene_path.display()
            )
        })?;
    // A group the run left without its condition is no contact boundary (issue 49, item 6).
    let effects: Vec<&str> = v["effects"]
        .as_array()
        .map(|a| a.iter().filter_map(|e| e.as_str()).collect())
        .unwrap_or_default();
    let acts = |names: &[&str]| names.iter().any(|n| effects.contains(n));
    let group = |name: &str, on: bool| on.then(|| mesh.boundary_group(name).ok()).flatten();
    let contact = group(&groups.contact, acts(&["contact"]));
    let friction = group(&groups.friction, acts(&["friction", "normal_stress"]));
    let edges = |g: Option<&crate::mesh::Group>| g.map(|g| g.facets.clone()).unwrap_or_default();
    let faces = |g: Option<&crate::mesh::Group>| g.map(|g| g.faces.clone()).unwrap_or_default();
    Ok(ContactGroups {
        edges: [edges(contact), edges(friction)],
        faces: [faces(contact), faces(friction)],
    })
}

/// The frame `plot` draws: the run's directory, the frame's time and file, its content,
/// and a note when the frame is not at the time asked for.
struct Loaded {
    dir: PathBuf,
    time: f64,
    frame: PathBuf,
    v: Vtu,
    note: Option<String>,
}

/// The frame of `entries` (in time order, at least one) nearest to `t`, and a note when it
/// is not at `t`. A time outside the frames' times by more than half the smallest interval
/// between frames is refused: drawing the last frame for `--time 5` of a run to T = 1
/// would show what the user did not ask for (issue 49).
fn nearest_frame(
    entries: &[(f64, FrameRef)],
    t: f64,
) -> Result<(&(f64, FrameRef), Option<String>)> {
    let (first, last) = (entries[0].0, entries[entries.len() - 1].0);
    let interval = entries
        .windows(2)
        .map(|w| w[1].0 - w[0].0)
        .fold(f64::INFINITY, f64::min);
    // Round-off of the times as the series file writes them.
    let eps = 1e-9 * first.abs().max(last.abs()).max(1.0);
    let slack = if interval.is_finite() {
        0.5 * interval
    } else {
        0.0
    } + eps;
    if !(t >= first - slack && t <= last + slack) {
        return Err(Error::input(format!(
            "plot: --time {t} is outside the run's frames, t = {first} to {last} ({} frame{}); \
             give a time in that range or leave --time out (the last frame)",
            entries.len(),
            if entries.len() == 1 { "" } else { "s" }
        )));
    }
    let nearest = entries
        .iter()
        .min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs()))
        .expect("at least one frame");
    let note = ((nearest.0 - t).abs() > eps).then(|| {
        format!(
            "plot: no frame at t = {t}; drew the nearest, t = {}",
            nearest.0
        )
    });
    Ok((nearest, note))
}

/// Reads the frame of the run at `dir` nearest to `time` (default: the last).
fn load_frame(dir: &Path, time: Option<f64>) -> Result<Loaded> {
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
    if entries.is_empty() {
        return Err(Error::input(format!(
            "plot: {} lists no frames",
            series.display()
        )));
    }
    let ((time, frame), note) = match time {
        None => (&entries[entries.len() - 1], None),
        Some(t) => nearest_frame(&entries, t)?,
    };
    let v = read_frame(frame)?;
    Ok(Loaded {
        dir,
        time: *time,
        frame: frame.path().to_path_buf(),
        v,
        note,
    })
}

/// The cells of a frame: a 2D run's triangles or a 3D run's tetrahedra.
enum Cells {
    Triangles(Vec<[usize; 3]>),
    Tetrahedra(Vec<[usize; 4]>),
}

fn cells(run: &Loaded) -> Result<Cells> {
    let cells = &run.v.cells;
    if cells.iter().all(|c| c.len() == 3) {
        Ok(Cells::Triangles(
            cells.iter().map(|c| [c[0], c[1], c[2]]).collect(),
        ))
    } else if cells.iter().all(|c| c.len() == 4) {
        Ok(Cells::Tetrahedra(
            cells.iter().map(|c| [c[0], c[1], c[2], c[3]]).collect(),
        ))
    } else {
        Err(Error::input(format!(
            "plot: {} holds cells that are neither all triangles (a 2D run) nor all \
             tetrahedra (a 3D run); plot draws the frames that viscontact run writes",
            run.frame.display()
        )))
    }
}

/// What a figure is coloured by: one value per point or per cell, and the colour bar's range.
struct Colouring {
    name: String,
    values: Vec<f64>,
    per_point: bool,
    range: (f64, f64),
    /// A field of the contact boundary (`TRACTIONS`), zero elsewhere: drawn as coloured
    /// markers on the nodes that carry it, the body neutral (coloured cells would smear the
    /// boundary's values over its first row of cells).
    boundary: bool,
}

impl Colouring {
    /// `t` ∈ [0, 1] of a value on the colour bar.
    fn norm(&self, x: f64) -> f64 {
        (x - self.range.0) / (self.range.1 - self.range.0)
    }

    /// The colour of a piece of the body whose value is `x`.
    fn fill(&self, x: f64) -> RGBColor {
        if self.boundary {
            NEUTRAL
        } else {
            colormap(self.norm(x))
        }
    }

    /// The marker of node `n` at `at`: a disc of its value's colour, outlined, where a
    /// boundary field is nonzero.
    fn marker(&self, n: usize, at: (f64, f64)) -> Option<[Circle<(f64, f64), i32>; 2]> {
        let x = self.values[n];
        (self.boundary && x != 0.0).then(|| {
            [
                Circle::new(at, 7, colormap(self.norm(x)).filled()),
                Circle::new(at, 7, BLACK.stroke_width(1)),
            ]
        })
    }

    /// The coloured pieces of a cell drawn as the triangle `p` (its corners' nodes `nodes`):
    /// the cell's value, or a point field on 4 sub-triangles, each with the mean of its
    /// corners' values (linear along the edges).
    fn pieces(
        &self,
        cell: usize,
        nodes: [usize; 3],
        p: [(f64, f64); 3],
        out: &mut Vec<([(f64, f64); 3], f64)>,
    ) {
        if !self.per_point {
            out.push((p, self.values[cell]));
            return;
        }
        let f = nodes.map(|n| self.values[n]);
        let mid = |a: usize, b: usize| {
            (
                ((p[a].0 + p[b].0) / 2.0, (p[a].1 + p[b].1) / 2.0),
                (f[a] + f[b]) / 2.0,
            )
        };
        let (m01, m12, m20) = (mid(0, 1), mid(1, 2), mid(2, 0));
        out.push(([p[0], m01.0, m20.0], (f[0] + m01.1 + m20.1) / 3.0));
        out.push(([m01.0, p[1], m12.0], (m01.1 + f[1] + m12.1) / 3.0));
        out.push(([m20.0, m12.0, p[2]], (m20.1 + m12.1 + f[2]) / 3.0));
        out.push(([m01.0, m12.0, m20.0], (m01.1 + m12.1 + m20.1) / 3.0));
    }
}

/// The colour bar's range of `values`: their finite extremes, widened around a constant.
fn value_range(values: &[f64]) -> (f64, f64) {
    let (vmin, vmax) = values
        .iter()
        .filter(|x| x.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    if !vmin.is_finite() {
        (0.0, 1.0)
    } else if vmax - vmin <= 1e-300 + 1e-12 * vmax.abs() {
        (
            vmin - 0.5 * vmin.abs().max(1e-30),
            vmax + 0.5 * vmax.abs().max(1e-30),
        )
    } else {
        (vmin, vmax)
    }
}

/// The run's 3-component point field `displacement`.
fn displacement(run: &Loaded) -> Result<&[f64]> {
    run.v
        .point_field("displacement")
        .filter(|a| a.components == 3)
        .map(|a| &a.values[..])
        .ok_or_else(|| {
            Error::input(format!(
                "plot: {} has no 3-component point field 'displacement'",
                run.frame.display()
            ))
        })
}

/// The displacement scale and the body's size (its largest extent over the first `dim`
/// coordinates): `given`, else the largest displacement drawn as 10 % of the size.
fn auto_scale(points: &[[f64; 3]], disp: &[f64], dim: usize, given: Option<f64>) -> (f64, f64) {
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for p in points {
        for c in 0..dim {
            lo[c] = lo[c].min(p[c]);
            hi[c] = hi[c].max(p[c]);
        }
    }
    let size = (0..dim).fold(f64::NEG_INFINITY, |s, c| s.max(hi[c] - lo[c]));
    let umax = disp
        .chunks_exact(3)
        .map(|u| u[..dim].iter().map(|x| x * x).sum::<f64>().sqrt())
        .fold(0.0f64, f64::max);
    let scale = given.unwrap_or(if umax > 0.0 { 0.1 * size / umax } else { 1.0 });
    (scale, size)
}

/// The nodes at which a point field is nonzero (any component).
fn nonzero_nodes(v: &Vtu, name: &str) -> Vec<bool> {
    match v.point_field(name) {
        Some(a) => a
            .values
            .chunks_exact(a.components)
            .map(|c| c.iter().any(|x| *x != 0.0))
            .collect(),
        None => vec![false; v.points.len()],
    }
}

/// One entry of a figure's legend: label, colour, drawn as a dot (else a line).
type LegendItem = (String, RGBColor, bool);

/// Colours of Γ3,1 (contact) and Γ3,2 (friction).
const CONTACT_COLOURS: [RGBColor; 2] = [RGBColor(220, 30, 30), RGBColor(240, 150, 0)];
const CONTACT_NAMES: [&str; 2] = ["Γ3,1 (contact)", "Γ3,2 (friction)"];
/// The undeformed body's lines.
const GHOST: RGBColor = RGBColor(150, 150, 150);
/// The body under a boundary field's markers.
const NEUTRAL: RGBColor = RGBColor(225, 225, 225);

/// Pixel layout of a body figure: the body's plot area keeps its aspect ratio; a title
/// above, a legend below, the colour bar on the right; axes around the body in 2D only.
#[derive(Clone, Copy, Debug)]
struct Layout {
    width: u32,
    height: u32,
    bar_w: u32,
    caption: u32,
    xl: u32,
    yl: u32,
    margin: u32,
    legend_h: u32,
    /// Free space below the colour bar (3D: the axes' directions).
    bar_bottom: u32,
}

impl Layout {
    /// For a body of extent `dx` × `dy` and a figure `width` pixels wide (at least 600).
    fn new(width: u32, dx: f64, dy: f64, axes: bool) -> Layout {
        let (bar_w, caption, margin, legend_h) = (190u32, 44u32, 20u32, 36u32);
        let (xl, yl) = if axes { (45u32, 65u32) } else { (0, 0) };
        let mut pw = (width.max(600) - bar_w - yl - 2 * margin) as f64;
        let mut ph = pw * dy / dx;
        if ph > 1400.0 {
            ph = 1400.0;
            pw = ph * dx / dy;
        }
        Layout {
            width: pw as u32 + bar_w + yl + 2 * margin,
            height: ph as u32 + caption + xl + 2 * margin + legend_h,
            bar_w,
            caption,
            xl,
            yl,
            margin,
            legend_h,
            bar_bottom: if axes { xl + margin } else { 150 },
        }
    }
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;
type Chart<'a, 'b> = ChartContext<
    'a,
    BitMapBackend<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;
type DrawError = DrawingAreaErrorKind<<BitMapBackend<'static> as DrawingBackend>::ErrorType>;

/// Draws a body figure at `output`: title, the body (`body` draws it into its area and
/// returns the legend's entries), legend and colour bar; `bar_extra` draws into the colour
/// bar's column.
fn render(
    output: &Path,
    lay: &Layout,
    title: &str,
    colouring: &Colouring,
    body: impl FnOnce(&Area) -> std::result::Result<Vec<LegendItem>, DrawError>,
    bar_extra: impl FnOnce(&Area) -> DrawResult,
) -> Result<()> {
    let err = draw_err(output);
    let root = BitMapBackend::new(output, (lay.width, lay.height)).into_drawing_area();
    root.fill(&WHITE).map_err(&err)?;
    let (body_area, rest) = root.split_horizontally(lay.width - lay.bar_w);
    let (body_area, legend_area) = body_area.split_vertically(lay.height - lay.legend_h);
    let (title_area, body_area) = body_area.split_vertically(lay.caption);
    let title_style =
        TextStyle::from((FONT, 24).into_font()).pos(Pos::new(HPos::Center, VPos::Bottom));
    title_area
        .draw(&Text::new(
            title.to_string(),
            (((lay.width - lay.bar_w) / 2) as i32, lay.caption as i32 - 6),
            title_style,
        ))
        .map_err(&err)?;
    let legend = body(&body_area).map_err(&err)?;
    draw_legend(&legend_area, &legend, lay.yl + lay.margin).map_err(&err)?;
    let (vmin, vmax) = colouring.range;
    let top = lay.caption + lay.margin;
    draw_colorbar(&rest, &colouring.name, vmin, vmax, top, lay.bar_bottom).map_err(&err)?;
    bar_extra(&rest).map_err(&err)?;
    root.present().map_err(&err)?;
    Ok(())
}

/// The smallest box `(lo, hi)` holding every point.
fn bounds(points: impl Iterator<Item = (f64, f64)>) -> ([f64; 2], [f64; 2]) {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for (x, y) in points {
        lo = [lo[0].min(x), lo[1].min(y)];
        hi = [hi[0].max(x), hi[1].max(y)];
    }
    (lo, hi)
}

/// The title of a body figure.
fn title(field: &str, time: f64, scale: f64) -> String {
    format!(
        "{} at t = {} — displacement × {}",
        field,
        trim_float(time),
        sig3(scale)
    )
}

/// Draws the deformed body of a run at one time, coloured by a field (the paper's Fig. 3):
/// a 2D run in its plane, a 3D run's boundary surface seen from `opts.view`
/// (`plot/body3d.rs`).
pub fn plot_run(dir: &Path, opts: &PlotOptions) -> Result<PlotInfo> {
    register_fonts();
    let run = load_frame(dir, opts.time)?;
    let disp = displacement(&run)?;
    let (values, per_point) = field_values(&run.v, &opts.field)?;
    let boundary = per_point
        && TRACTIONS.iter().any(|t| {
            (opts.field.strip_prefix(t))
                .is_some_and(|rest| rest.is_empty() || rest.starts_with('_'))
        });
    let colouring = Colouring {
        name: opts.field.clone(),
        range: value_range(&values),
        values,
        per_point,
        boundary,
    };
    let output = match &opts.output {
        Some(path) => path.clone(),
        None => default_output(&run.dir, &opts.field, run.time),
    };
    let mut notes: Vec<String> = run.note.iter().cloned().collect();
    let contact = contact_groups(&run.dir, run.v.points.len())
        .map_err(|why| {
            notes.push(format!(
                "warning: plot: {why}; Γ3,1 and Γ3,2 are not drawn, the nodes that carry a contact \
                 pressure or a friction traction are circled instead"
            ))
        })
        .ok();
    let (scale, view) = match cells(&run)? {
        Cells::Triangles(tris) => {
            if opts.view.is_some() {
                return Err(Error::input(format!(
                    "plot: --view is for 3D runs; {} is a 2D run (triangles): leave --view out",
                    run.frame.display()
                )));
            }
            let body = Body2d::new(&run, &tris, disp, opts.scale);
            body.draw(&output, &colouring, contact.as_ref(), opts.width)?;
            (body.scale, None)
        }
        Cells::Tetrahedra(tets) => {
            let view = opts.view.unwrap_or(DEFAULT_VIEW);
            let body = body3d::Body3d::new(&run, &tets, disp, opts.scale, view)?;
            body.draw(&output, &colouring, contact.as_ref(), opts.width)?;
            (body.scale, Some(view))
        }
    };
    Ok(PlotInfo {
        output,
        time: run.time,
        frame: run.frame,
        scale,
        range: colouring.range,
        contact_marked: contact.is_some(),
        view,
        notes,
    })
}

/// The figure's file unless `-o` names one: `<run>_<field>_t<time>.png` (e.g.
/// `paper_von_mises_t1.png`) in the current directory. Not in the run's directory: that
/// directory is viscontact's own, which a rerun replaces and `resume` continues, and both
/// refuse a directory holding files a run did not write (issue 49: a figure written there
/// stopped the run from being resumed). The run's name keeps the figures of two runs apart.
fn default_output(run_dir: &Path, field: &str, time: f64) -> PathBuf {
    let time = format!("{time}").replace('.', "_");
    PathBuf::from(format!("{}_{field}_t{time}.png", run_name(run_dir)))
}

/// The name of a run's directory ("run" when it has none), for default figure names.
fn run_name(run_dir: &Path) -> String {
    run_dir
        .canonicalize()
        .ok()
        .and_then(|d| d.file_name().map(|n| n.to_string_lossy().into_owned()))
        .unwrap_or_else(|| "run".into())
}

/// A 2D run's body: the frame, its triangles, their deformed positions.
struct Body2d<'a> {
    run: &'a Loaded,
    tris: &'a [[usize; 3]],
    def: Vec<(f64, f64)>,
    scale: f64,
    size: f64,
}

impl<'a> Body2d<'a> {
    fn new(run: &'a Loaded, tris: &'a [[usize; 3]], disp: &[f64], scale: Option<f64>) -> Self {
        let (scale, size) = auto_scale(&run.v.points, disp, 2, scale);
        let def = run
            .v
            .points
            .iter()
            .zip(disp.chunks_exact(3))
            .map(|(p, u)| (p[0] + scale * u[0], p[1] + scale * u[1]))
            .collect();
        Body2d {
            run,
            tris,
            def,
            scale,
            size,
        }
    }

    /// The undeformed position of node `n`.
    fn undeformed(&self, n: usize) -> (f64, f64) {
        (self.run.v.points[n][0], self.run.v.points[n][1])
    }

    /// The figure: the body keeps its aspect ratio, with axes.
    fn draw(
        &self,
        output: &Path,
        colouring: &Colouring,
        contact: Option<&ContactGroups>,
        width: u32,
    ) -> Result<()> {
        let undeformed = (0..self.def.len()).map(|n| self.undeformed(n));
        let (lo, hi) = bounds(undeformed.chain(self.def.iter().copied()));
        let pad = 0.04 * self.size;
        let (dx, dy) = (hi[0] - lo[0] + 2.0 * pad, hi[1] - lo[1] + 2.0 * pad);
        let (x0, y0) = (lo[0] - pad, lo[1] - pad);
        let lay = Layout::new(width, dx, dy, true);
        let title = title(&colouring.name, self.run.time, self.scale);
        let body = |area: &Area| {
            let mut chart = ChartBuilder::on(area)
                .margin(lay.margin)
                .x_label_area_size(lay.xl)
                .y_label_area_size(lay.yl)
                .build_cartesian_2d(x0..x0 + dx, y0..y0 + dy)?;
            chart
                .configure_mesh()
                .disable_mesh()
                .x_desc("x")
                .y_desc("y")
                .label_style((FONT, 15))
                .axis_desc_style((FONT, 17))
                .draw()?;
            self.draw_cells(&mut chart, colouring)?;
            self.draw_boundary(&mut chart)?;
            let legend = self.draw_contact(&mut chart, contact)?;
            let markers = (0..self.def.len()).filter_map(|n| colouring.marker(n, self.def[n]));
            chart.draw_series(markers.flatten())?;
            Ok(legend)
        };
        render(output, &lay, &title, colouring, body, |_| Ok(()))
    }

    /// Filled triangles, and the mesh when it is coarse enough to see.
    fn draw_cells(&self, chart: &mut Chart, colouring: &Colouring) -> DrawResult {
        let mut polys: Vec<([(f64, f64); 3], f64)> = Vec::with_capacity(4 * self.tris.len());
        for (c, t) in self.tris.iter().enumerate() {
            colouring.pieces(c, *t, t.map(|n| self.def[n]), &mut polys);
        }
        chart.draw_series(
            polys
                .iter()
                .map(|(p, f)| Polygon::new(p.to_vec(), colouring.fill(*f).filled())),
        )?;
        if self.tris.len() <= 20_000 {
            chart.draw_series(self.tris.iter().map(|t| {
                let p = t.map(|n| self.def[n]);
                PathElement::new(vec![p[0], p[1], p[2], p[0]], BLACK.mix(0.22))
            }))?;
        }
        Ok(())
    }

    /// Boundary edges: undeformed (grey) and deformed (black).
    fn draw_boundary(&self, chart: &mut Chart) -> DrawResult {
        let mut edges: std::collections::HashMap<(usize, usize), usize> = Default::default();
        for t in self.tris {
            for i in 0..3 {
                let (a, b) = (t[i], t[(i + 1) % 3]);
                *edges.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        let mut boundary: Vec<(usize, usize)> = edges
            .into_iter()
            .filter(|(_, c)| *c == 1)
            .map(|(e, _)| e)
            .collect();
        // In one order, so that the figure is the same pixel for pixel at every plot.
        boundary.sort_unstable();
        chart.draw_series(boundary.iter().map(|&(a, b)| {
            PathElement::new(
                vec![self.undeformed(a), self.undeformed(b)],
                GHOST.stroke_width(1),
            )
        }))?;
        chart.draw_series(boundary.iter().map(|&(a, b)| {
            PathElement::new(vec![self.def[a], self.def[b]], BLACK.stroke_width(2))
        }))?;
        Ok(())
    }

    /// The contact boundary: Γ3,1 red, Γ3,2 orange; nodes in contact or sticking as dots.
    /// Without the mesh's groups, the nodes that carry a contact or friction traction.
    fn draw_contact(
        &self,
        chart: &mut Chart,
        contact: Option<&ContactGroups>,
    ) -> std::result::Result<Vec<LegendItem>, DrawError> {
        let v = &self.run.v;
        let mut legend: Vec<LegendItem> = Vec::new();
        if let Some(groups) = contact {
            for ((list, color), name) in groups.edges.iter().zip(CONTACT_COLOURS).zip(CONTACT_NAMES)
            {
                if list.is_empty() {
                    continue;
                }
                chart.draw_series(list.iter().map(|f| {
                    PathElement::new(vec![self.def[f[0]], self.def[f[1]]], color.stroke_width(5))
                }))?;
                legend.push((name.to_string(), color, false));
            }
        }
        if let Some(state) = v.point_field("contact_state") {
            let active: Vec<usize> = (0..v.points.len())
                .filter(|&i| state.values[i] > 0.5)
                .collect();
            if !active.is_empty() {
                chart.draw_series(
                    active
                        .iter()
                        .map(|&i| Circle::new(self.def[i], 4, BLACK.filled())),
                )?;
                legend.push(("contact_state = 1 (active / stick)".into(), BLACK, true));
            }
        }
        if contact.is_none() {
            for ((name, color), label) in TRACTIONS.iter().zip(CONTACT_COLOURS).zip(TRACTION_LABELS)
            {
                let marked = nonzero_nodes(v, name);
                if marked.iter().any(|m| *m) {
                    chart.draw_series(
                        (0..v.points.len())
                            .filter(|&i| marked[i])
                            .map(|i| Circle::new(self.def[i], 5, color.stroke_width(2))),
                    )?;
                    legend.push((label.to_string(), color, true));
                }
            }
        }
        legend.push(("undeformed boundary".into(), GHOST, false));
        Ok(legend)
    }
}

/// The point fields that mark the contact nodes when the mesh's groups cannot be found.
const TRACTIONS: [&str; 2] = ["contact_pressure", "friction_traction"];
const TRACTION_LABELS: [&str; 2] = ["contact pressure > 0", "friction traction ≠ 0"];

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
    }
}
