//! The 3D figure of `plot`: a tetrahedral run's deformed boundary surface seen from a
//! direction (geometry in `surface.rs`), drawn with the 2D figure's title, legend and
//! colour bar.
//!
//! Each visible face is drawn far to near, and right after its fill its own lines, so that
//! nearer faces hide them too: the mesh (faint), the feature edges (black), the contact
//! boundary (Γ3,1 red, Γ3,2 orange: thin on every edge of its faces, thick on the outline of
//! the group, which also shows on the faces next to it when the group itself faces away)
//! and the nodes with contact_state = 1 (black dots). A cell field colours a face by its
//! tetrahedron's value; a point field is drawn on 4 sub-triangles per face, as in 2D.
//! Before all faces, the feature edges of the undeformed body that face the eye are drawn
//! in grey: the deformed body hides them where it covers them. The axes' directions are
//! shown below the colour bar.

use super::surface::{
    boundary_faces, edge, edge_faces, feature_edges, normal, outline, painter_order, Camera, Face,
};
use super::*;
use std::collections::{HashMap, HashSet};

/// More boundary faces than this: the mesh lines are left out (they would cover the body).
const MESH_LINES_UP_TO: usize = 20_000;

/// A 3D run's body as seen from the camera.
pub(super) struct Body3d<'a> {
    run: &'a Loaded,
    camera: Camera,
    view: [f64; 3],
    faces: Vec<Face>,
    /// The deformed positions of the nodes on the screen.
    screen: Vec<(f64, f64)>,
    /// Visible faces, far to near, with their brightness.
    order: Vec<(usize, f64)>,
    /// Feature edges of the undeformed surface, with their faces.
    features: Vec<((usize, usize), Vec<usize>)>,
    pub(super) scale: f64,
    size: f64,
}

impl<'a> Body3d<'a> {
    pub(super) fn new(
        run: &'a Loaded,
        tets: &[[usize; 4]],
        disp: &[f64],
        scale: Option<f64>,
        view: [f64; 3],
    ) -> Result<Self> {
        let camera = Camera::new(view).ok_or_else(|| {
            Error::input(format!(
                "plot: the view direction {view:?} has no direction; give three numbers, not all zero"
            ))
        })?;
        let points = &run.v.points;
        let (scale, size) = auto_scale(points, disp, 3, scale);
        let def: Vec<[f64; 3]> = points
            .iter()
            .zip(disp.chunks_exact(3))
            .map(|(p, u)| [0, 1, 2].map(|k| p[k] + scale * u[k]))
            .collect();
        let faces = boundary_faces(points, tets);
        let order = painter_order(&camera, &def, &faces);
        let screen = def.iter().map(|p| camera.project(*p)).collect();
        let features = feature_edges(points, &faces, &edge_faces(&faces));
        Ok(Body3d {
            run,
            camera,
            view,
            faces,
            screen,
            order,
            features,
            scale,
            size,
        })
    }

    /// The undeformed position of node `n` on the screen.
    fn ghost(&self, n: usize) -> (f64, f64) {
        self.camera.project(self.run.v.points[n])
    }

    /// The figure: the surface keeps its aspect ratio (at least 1 : 2), no axes.
    pub(super) fn draw(
        &self,
        output: &Path,
        colouring: &Colouring,
        contact: Option<&ContactGroups>,
        width: u32,
    ) -> Result<()> {
        let corners = self.faces.iter().flat_map(|f| f.nodes.iter());
        let (lo, hi) = bounds(corners.flat_map(|&n| [self.screen[n], self.ghost(n)]));
        let pad = 0.04 * self.size;
        let dx = hi[0] - lo[0] + 2.0 * pad;
        let dy = (hi[1] - lo[1] + 2.0 * pad).max(0.5 * dx);
        let (x0, y0) = (lo[0] - pad, 0.5 * (lo[1] + hi[1] - dy));
        let lay = Layout::new(width, dx, dy, false);
        let view = self.view.map(trim_float).join(", ");
        let title = format!(
            "{}, seen from ({view})",
            title(&colouring.name, self.run.time, self.scale)
        );
        let marks = Marks::new(self, contact);
        let body = |area: &Area| {
            let mut chart = ChartBuilder::on(area)
                .margin(lay.margin)
                .build_cartesian_2d(x0..x0 + dx, y0..y0 + dy)?;
            self.draw_ghost(&mut chart)?;
            self.draw_faces(&mut chart, colouring, &marks)?;
            Ok(marks.legend())
        };
        render(output, &lay, &title, colouring, body, |bar| {
            self.draw_axes(bar, lay.bar_bottom)
        })
    }

    /// The visible faces, far to near, each with its lines and dots.
    fn draw_faces(&self, chart: &mut Chart, colouring: &Colouring, marks: &Marks) -> DrawResult {
        let area = chart.plotting_area();
        let mesh_lines = self.faces.len() <= MESH_LINES_UP_TO;
        let mut pieces = Vec::with_capacity(4);
        for &(i, shade) in &self.order {
            let face = &self.faces[i];
            let p = face.nodes.map(|n| self.screen[n]);
            pieces.clear();
            colouring.pieces(face.cell, face.nodes, p, &mut pieces);
            for (q, f) in &pieces {
                let RGBColor(r, g, b) = colouring.fill(*f);
                let dim = |c: u8| (c as f64 * shade).round() as u8;
                area.draw(&Polygon::new(
                    q.to_vec(),
                    RGBColor(dim(r), dim(g), dim(b)).filled(),
                ))?;
            }
            for k in 0..3 {
                let (a, b) = (face.nodes[k], face.nodes[(k + 1) % 3]);
                if let Some(style) = marks.edge_style(i, edge(a, b), mesh_lines) {
                    area.draw(&PathElement::new(vec![p[k], p[(k + 1) % 3]], style))?;
                }
            }
            for &n in face.nodes.iter().filter(|&&n| marks.dots[n]) {
                area.draw(&Circle::new(self.screen[n], 3, BLACK.filled()))?;
            }
            for (n, colour) in marks.tractions(face.nodes) {
                area.draw(&Circle::new(self.screen[n], 5, colour.stroke_width(2)))?;
            }
            for marker in face
                .nodes
                .iter()
                .filter_map(|&n| colouring.marker(n, self.screen[n]))
            {
                marker.iter().try_for_each(|m| area.draw(m))?;
            }
        }
        Ok(())
    }

    /// The feature edges of the undeformed body that belong to a face seen by the eye.
    fn draw_ghost(&self, chart: &mut Chart) -> DrawResult {
        let points = &self.run.v.points;
        let seen = |f: &usize| {
            let p = self.faces[*f].nodes.map(|n| points[n]);
            self.camera.faces(normal(p))
        };
        let lines: Vec<_> = (self.features.iter())
            .filter(|(_, faces)| faces.iter().any(seen))
            .map(|((a, b), _)| PathElement::new(vec![self.ghost(*a), self.ghost(*b)], GHOST))
            .collect();
        chart.draw_series(lines)?;
        Ok(())
    }

    /// The directions of x, y and z on the screen, below the colour bar.
    fn draw_axes(&self, bar: &Area, space: u32) -> DrawResult {
        let (w, h) = bar.dim_in_pixel();
        let centre = ((w / 2) as i32 - 20, h as i32 - space as i32 / 2 - 10);
        let len = 0.3 * space as f64;
        let style =
            TextStyle::from((FONT, 16).into_font()).pos(Pos::new(HPos::Center, VPos::Center));
        for (k, name) in ["x", "y", "z"].into_iter().enumerate() {
            let mut e = [0.0; 3];
            e[k] = 1.0;
            let (sx, sy) = self.camera.project(e);
            let tip = |l: f64| {
                (
                    centre.0 + (l * sx).round() as i32,
                    centre.1 - (l * sy).round() as i32,
                )
            };
            bar.draw(&PathElement::new(
                vec![centre, tip(len)],
                RGBColor(60, 60, 60).stroke_width(2),
            ))?;
            bar.draw(&Text::new(name, tip(len + 12.0), style.clone()))?;
        }
        Ok(())
    }
}

/// What marks the contact boundary on the 3D surface (see the module doc).
struct Marks {
    /// The group (0: Γ3,1, 1: Γ3,2) of each boundary face.
    group: Vec<Option<usize>>,
    /// The outlines of the groups.
    outlines: [HashSet<(usize, usize)>; 2],
    /// Feature edges of the undeformed surface.
    features: HashSet<(usize, usize)>,
    /// Nodes with contact_state = 1.
    dots: Vec<bool>,
    /// Without the groups: nodes that carry a contact pressure / a friction traction.
    tractions: [Vec<bool>; 2],
    /// Whether the run has Γ3,1 / Γ3,2 faces.
    named: [bool; 2],
}

impl Marks {
    fn new(body: &Body3d, contact: Option<&ContactGroups>) -> Self {
        let v = &body.run.v;
        let key = |f: &[usize; 3]| {
            let mut k = *f;
            k.sort_unstable();
            k
        };
        let mut group = vec![None; body.faces.len()];
        let mut outlines = [HashSet::new(), HashSet::new()];
        let mut named = [false; 2];
        if let Some(c) = contact {
            let index: HashMap<[usize; 3], usize> = (body.faces.iter().enumerate())
                .map(|(i, f)| (key(&f.nodes), i))
                .collect();
            for (g, list) in c.faces.iter().enumerate() {
                for i in list.iter().filter_map(|f| index.get(&key(f))) {
                    group[*i].get_or_insert(g);
                }
                outlines[g] = outline(list).into_iter().collect();
                named[g] = !list.is_empty();
            }
        }
        let none = vec![false; v.points.len()];
        let dots = match v.point_field("contact_state") {
            Some(a) => a.values.iter().map(|s| *s > 0.5).collect(),
            None => none.clone(),
        };
        let tractions = match contact {
            None => TRACTIONS.map(|name| nonzero_nodes(v, name)),
            Some(_) => [none.clone(), none],
        };
        Marks {
            group,
            outlines,
            features: body.features.iter().map(|(e, _)| *e).collect(),
            dots,
            tractions,
            named,
        }
    }

    /// How the edge `e` of face `face` is drawn: the outline of a contact group (the face's
    /// own first), a feature edge, an edge of a contact face, a mesh edge, in this order.
    fn edge_style(&self, face: usize, e: (usize, usize), mesh_lines: bool) -> Option<ShapeStyle> {
        let own = self.group[face];
        let outlined = (own.into_iter().chain(0..2)).find(|g| self.outlines[*g].contains(&e));
        if let Some(g) = outlined {
            Some(CONTACT_COLOURS[g].stroke_width(4))
        } else if self.features.contains(&e) {
            Some(BLACK.stroke_width(2))
        } else if let Some(g) = own {
            Some(CONTACT_COLOURS[g].stroke_width(1))
        } else {
            mesh_lines.then(|| BLACK.mix(0.22).stroke_width(1))
        }
    }

    /// The nodes of a face that carry a contact pressure or friction traction (only when
    /// the groups are unknown), with their colour.
    fn tractions(&self, nodes: [usize; 3]) -> impl Iterator<Item = (usize, RGBColor)> + '_ {
        nodes.into_iter().flat_map(move |n| {
            (0..2)
                .filter(move |&g| self.tractions[g][n])
                .map(move |g| (n, CONTACT_COLOURS[g]))
        })
    }

    fn legend(&self) -> Vec<LegendItem> {
        let mut legend: Vec<LegendItem> = (0..2)
            .filter(|&g| self.named[g])
            .map(|g| (CONTACT_NAMES[g].to_string(), CONTACT_COLOURS[g], false))
            .collect();
        if self.dots.iter().any(|d| *d) {
            legend.push(("contact_state = 1".into(), BLACK, true));
        }
        for g in (0..2).filter(|&g| self.tractions[g].iter().any(|t| *t)) {
            legend.push((TRACTION_LABELS[g].to_string(), CONTACT_COLOURS[g], true));
        }
        legend.push(("undeformed edges".into(), GHOST, false));
        legend
    }
}
