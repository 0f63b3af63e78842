//! The load functional ⟨f_n, v⟩ = (f_0(t_n), v) + (f_2(t_n), v)_{Γ2}: quadrature points are
//! laid out once, the expressions are evaluated at t_n each step. Boundary loads use
//! [`Facet::quadrature`] (exact for a quadratic traction times P1, e.g. the paper's x(2−x));
//! body forces a degree-2 rule (exact for a linear force times P1): the edge midpoints of a
//! triangle, the 4-point rule of a tetrahedron.
//!
//! [`Facet::quadrature`]: crate::mesh::Facet::quadrature

use super::{Cell, CellSource, DofIndices, Frames, Points};
use crate::expr::{Point, Scalar};
use crate::mesh::{facet_rule, fmt_point, Mesh};
use crate::scene::Scene;
use crate::{Error, Result};
use std::collections::HashSet;

/// A quadrature point of a load: where, how much weight, which nodes with which φ (the
/// nodes' indices in four bytes, as the numbering holds its dofs': `DofIndices::MAX_DOFS`;
/// 80 bytes a point, where they took 96: four points a tetrahedron for a body force).
struct Qp {
    p: [f64; 3],
    weight: f64,
    nodes: [u32; 4],
    phi: [f64; 4],
}

/// A traction (index into `Scene::tractions`) or a body force (into `Scene::body_forces`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Source {
    Traction(usize),
    Body(usize),
}

struct VectorLoad {
    source: Source,
    qps: Vec<Qp>,
    /// A traction's every facet, where its points are a part and it visits every one all
    /// the same (rank 0 of several: [`Loads::visit_every`]); empty otherwise.
    facets: Vec<LoadFacet>,
}

/// A facet of a traction's boundary as rank 0 of several keeps every one: its nodes (an
/// edge's second repeated) and its rule's weights ([`Facet::weights`]), from which
/// [`facet_rule`] makes its points again with their bits (32 bytes a facet, where its
/// points take 80 bytes each, six a triangle).
///
/// [`Facet::weights`]: crate::mesh::Facet::weights
struct LoadFacet {
    nodes: [u32; 3],
    weights: [f64; 2],
}

/// All loads of a scene, ready to be evaluated at any t.
pub struct Loads {
    loads: Vec<VectorLoad>,
    /// Dofs per node (the mesh's dimension).
    dim: usize,
    /// Whether only the points that reach some nodes are kept ([`Loads::keep_reaching`]).
    part: bool,
    /// Whether every traction's facets are kept all the same (rank 0 of several:
    /// [`Keep::ReachingAndTractions`]).
    every_traction: bool,
}

/// Which of its quadrature points a discretization's loads keep.
#[derive(Clone, Copy)]
pub enum Keep<'r> {
    /// Every one (one process, or a rank of several that holds the matrices whole).
    Every,
    /// Those that put a value into one of the nodes `reaches` (increasing): a follower
    /// rank's own rows' ([`Loads::keep_reaching`]).
    Reaching(&'r [usize]),
    /// Those, and every traction's facets (a boundary's): rank 0 of several, which makes
    /// the other points again when it reads every value, a traction's from those facets,
    /// a body force's from its cells ([`Loads::visit_every`]).
    ReachingAndTractions(&'r [usize]),
}

impl<'r> Keep<'r> {
    /// The nodes whose points are kept, and whether every traction's facets are: None
    /// keeps all.
    fn reaches(self) -> Option<(&'r [usize], bool)> {
        match self {
            Keep::Every => None,
            Keep::Reaching(r) => Some((r, false)),
            Keep::ReachingAndTractions(r) => Some((r, true)),
        }
    }
}

impl Loads {
    /// The scene's loads on `mesh`, of their quadrature points those `keep` says
    /// ([`Loads::keep_reaching`]), a body force's made for the cells it keeps alone.
    pub fn new(mesh: &Mesh, scene: &Scene, cells: CellSource, keep: Keep) -> Result<Self> {
        // The traction boundary Γ2, for the check that every load group lies inside it.
        let gamma2: std::result::Result<HashSet<Vec<usize>>, String> = mesh
            .boundary_group(&scene.mesh.groups.traction)
            .map(|g| mesh.boundary_facets(g).iter().map(sorted).collect())
            .map_err(|e| e.to_string());
        let mut loads = Vec::new();
        for i in 0..scene.physics.tractions.len() {
            loads.push(traction(mesh, scene, i, &gamma2)?);
        }
        let reaches = keep.reaches();
        for i in 0..scene.physics.body_forces.len() {
            let reaches = reaches.map(|(r, _)| r);
            loads.push(body_force(mesh.nodes.points(), cells, i, reaches));
        }
        let mut loads = Loads {
            loads,
            ..Loads::none(mesh.dim)
        };
        match reaches {
            Some((reaches, every_traction)) => loads.keep_reaching(reaches, every_traction),
            // The quadrature points stay for the run: at their size, not their lists' growth.
            None => (loads.loads.iter_mut()).for_each(|l| l.qps.shrink_to_fit()),
        }
        Ok(loads)
    }

    /// No load (a discretization's, until it makes its own).
    pub fn none(dim: usize) -> Self {
        Loads {
            loads: Vec::new(),
            dim,
            part: false,
            every_traction: false,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.loads.is_empty()
    }

    /// Keeps the quadrature points that put a value into one of the nodes `reaches`
    /// (increasing) alone, and with `every_traction` every traction's facets, of which
    /// [`Loads::visit_every`] makes the points again: the terms that reach those nodes'
    /// dofs stay, in their order, so those entries of ⟨f(t), φ⟩ keep their bits, and
    /// the others become partial (on one of several MPI ranks: its own rows; the others'
    /// come with b_n's exchange where it reads them). Marks the loads as a part
    /// ([`Loads::is_part`]).
    pub fn keep_reaching(&mut self, reaches: &[usize], every_traction: bool) {
        // A facet's points, consecutive: an edge's two, a triangle's six.
        let per_facet = if self.dim == 2 { 2 } else { 6 };
        for load in &mut self.loads {
            if every_traction && matches!(load.source, Source::Traction(_)) {
                load.facets = (load.qps.chunks_exact(per_facet))
                    .map(|f| LoadFacet {
                        nodes: [0, 1, 2].map(|k| f[0].nodes[k]),
                        weights: [f[0].weight, f[per_facet - 1].weight],
                    })
                    .collect();
            }
            load.qps.retain(|q| {
                let reached = |n: u32| reaches.binary_search(&(n as usize)).is_ok();
                (q.nodes.iter().zip(q.phi)).any(|(&n, ph)| ph != 0.0 && reached(n))
            });
            load.qps.shrink_to_fit();
        }
        (self.part, self.every_traction) = (true, every_traction);
    }

    /// The nodes of every traction's facets where these loads keep them (rank 0 of
    /// several: [`Loads::visit_every`] makes their points again from their places).
    pub fn facet_nodes(&self) -> impl Iterator<Item = usize> + '_ {
        let facets = self.loads.iter().flat_map(|l| &l.facets);
        facets.flat_map(|f| f.nodes).map(|n| n as usize)
    }

    /// Whether these are the loads of some nodes alone ([`Loads::keep_reaching`]): an
    /// entry of [`Loads::add`] outside them is partial.
    pub fn is_part(&self) -> bool {
        self.part
    }

    /// Whether [`Loads::visit_every`] sees every value: one process's loads, and rank 0's
    /// of several (every traction's and body force's points made again); not a
    /// follower's, which a value that is not finite elsewhere does not reach.
    pub fn sees_every_value(&self) -> bool {
        !self.part || self.every_traction
    }

    /// The loads in the order [`Loads::visit`] numbers them.
    pub fn sources(&self) -> impl Iterator<Item = Source> + '_ {
        self.loads.iter().map(|l| l.source)
    }

    /// Adds ⟨f(t), φ_d⟩ for every free dof d to `rhs` (`free` its index, `frames` where
    /// a node's dofs are components in a frame of its own), held at the dofs `held` alone
    /// where given (`fem::place`). A value that is not finite
    /// stops the run with the key, the time and the place (bad input at t = 0, a failed run
    /// later).
    pub fn add(
        &self,
        t: f64,
        (free, frames): (&DofIndices, &Frames),
        scene: &Scene,
        (rhs, held): (&mut [f64], Option<&[usize]>),
    ) -> Result<()> {
        // Held at some dofs alone (a follower's b_n: its own rows' loads have their bits),
        // a term at another dof is dropped: its rank adds it.
        let at = |d: usize| super::place_if_held(held, d);
        self.visit(t, scene, |_, dof, v| {
            frames.spread(self.dim, dof, v, |g, v| {
                if let Some(d) = free.get(g).and_then(at) {
                    rhs[d] += v;
                }
            })
        })
    }

    /// Hands every term of ⟨f(t), φ⟩ to `put(load, global dof, value)`: the weight times φ
    /// times the load's component at a quadrature point (global dof d·node + c for the
    /// spatial component c, whatever the node's frame), load i the i-th of
    /// [`Loads::sources`]. Their sum over the dofs of a component is the load's resultant
    /// (Σ φ = 1); `add` sums them into the free dofs. A value that is not finite stops the
    /// run as `add` says.
    pub fn visit(&self, t: f64, scene: &Scene, put: impl FnMut(usize, usize, f64)) -> Result<()> {
        self.visit_making(None, (t, scene), put)
    }

    /// [`Loads::visit`] of every quadrature point, the same terms in the same order, where
    /// these loads are a part that keeps every traction's facets (rank 0 of several,
    /// [`Loads::sees_every_value`]): their points are made again, a traction's facet by
    /// facet and a body force's cell by cell from `cells` (the cells and the nodes'
    /// places), as [`Loads::new`] made them, the same bits in the same order. history.csv's
    /// resultants and reactions read them, and rank 0 finds there a value that is not
    /// finite on another rank's part. Any other loads are visited as they are.
    pub fn visit_every(
        &self,
        (t, scene): (f64, &Scene),
        cells: (CellSource, Points),
        put: impl FnMut(usize, usize, f64),
    ) -> Result<()> {
        let making = (self.part && self.every_traction).then_some(cells);
        self.visit_making(making, (t, scene), put)
    }

    /// [`Loads::visit`], a body force's points made again from `making` (the cells and
    /// the nodes' places) where it is Some, the kept ones visited otherwise.
    fn visit_making(
        &self,
        making: Option<(CellSource, Points)>,
        (t, scene): (f64, &Scene),
        mut put: impl FnMut(usize, usize, f64),
    ) -> Result<()> {
        for (l, load) in self.loads.iter().enumerate() {
            let at = (l, load.source);
            let Some((cells, nodes)) = making else {
                for q in &load.qps {
                    self.put_point(at, q, (t, scene), &mut put)?;
                }
                continue;
            };
            if let Source::Traction(_) = load.source {
                for f in &load.facets {
                    for q in facet_points(f, self.dim, nodes) {
                        self.put_point(at, &q, (t, scene), &mut put)?;
                    }
                }
                continue;
            }
            let mut failed = Ok(());
            cells.each(|_, cell| {
                for (phi, weight) in body_rule(cell) {
                    if failed.is_ok() {
                        let q = body_point(nodes, cell, phi, weight);
                        failed = self.put_point(at, &q, (t, scene), &mut put);
                    }
                }
            });
            failed?;
        }
        Ok(())
    }

    /// Hands the terms of quadrature point `q` of load l (from `source`) at t to `put`
    /// ([`Loads::visit`]).
    fn put_point(
        &self,
        (l, source): (usize, Source),
        q: &Qp,
        (t, scene): (f64, &Scene),
        put: &mut impl FnMut(usize, usize, f64),
    ) -> Result<()> {
        let value: &[Scalar] = match source {
            Source::Traction(i) => &scene.physics.tractions[i].value,
            Source::Body(i) => &scene.physics.body_forces[i],
        };
        let pt = Point {
            x: q.p[0],
            y: q.p[1],
            z: q.p[2],
            t,
            ..Default::default()
        };
        for (c, v) in value.iter().enumerate() {
            let val = v.eval(&pt);
            if !val.is_finite() {
                let key = match source {
                    Source::Traction(i) => format!("load.traction[{i}].value"),
                    Source::Body(i) => format!("load.body[{i}].value"),
                };
                let what = format!(
                    "{}: key '{key}[{c}]' evaluates to {val} at {} at t = {t}",
                    scene.path.display(),
                    super::fmt_at(q.p, scene.mesh.model)
                );
                // At t = 0 it is known before any step (`TimeLoop::new` evaluates the loads
                // there): bad input.
                return Err(if t == 0.0 {
                    Error::input(format!(
                        "{what}; a load must be finite wherever and whenever it acts"
                    ))
                } else {
                    Error::solve(format!(
                        "{what}; the run stops here (the last checkpoint is kept)"
                    ))
                });
            }
            for (&n, ph) in q.nodes.iter().zip(q.phi) {
                if ph != 0.0 {
                    put(l, self.dim * n as usize + c, q.weight * ph * val);
                }
            }
        }
        Ok(())
    }
}

/// Traction i on its group, which must lie inside Γ2 (`gamma2`: its facets' sorted nodes,
/// or why the group could not be read).
fn traction(
    mesh: &Mesh,
    scene: &Scene,
    i: usize,
    gamma2: &std::result::Result<HashSet<Vec<usize>>, String>,
) -> Result<VectorLoad> {
    let t = &scene.physics.tractions[i];
    let key = format!("{}: key 'load.traction[{i}].on'", scene.path.display());
    let g = (mesh.boundary_group(&t.on)).map_err(|e| Error::input(format!("{key}: {e}")))?;
    let facets = mesh.boundary_facets(g);
    let g2 = gamma2.as_ref().map_err(|why| {
        Error::input(format!(
            "{}: key 'mesh.groups.traction': load.traction[{i}] needs the traction \
             boundary '{}' (its group must lie inside it): {why}",
            scene.path.display(),
            scene.mesh.groups.traction
        ))
    })?;
    if let Some(f) = facets.iter().find(|f| !g2.contains(&sorted(f))) {
        let corners: Vec<String> = (f.nodes().iter())
            .map(|&n| fmt_point(mesh.nodes[n], mesh.dim))
            .collect();
        let (what, entity) = match mesh.dim {
            2 => ("edge", "curve"),
            _ => ("face", "surface"),
        };
        return Err(Error::input(format!(
            "{key}: group '{}' has the {what} {} outside the traction boundary '{}' (Γ2); \
             tractions act on Γ2 only: add the {entity} to Γ2 in gmsh",
            t.on,
            corners.join("–"),
            scene.mesh.groups.traction
        )));
    }
    let mut qps = Vec::new();
    for f in facets {
        let fnodes = f.nodes();
        let nodes = [0, 1, 2].map(|k| fnodes[k.min(fnodes.len() - 1)] as u32);
        qps.extend(
            f.quadrature(mesh)
                .into_iter()
                .map(|q| facet_point(nodes, q)),
        );
    }
    Ok(VectorLoad {
        source: Source::Traction(i),
        qps,
        facets: Vec::new(),
    })
}

/// The quadrature point (x, weight, φ) of a facet with the nodes `nodes` (an edge's second
/// repeated).
fn facet_point(nodes: [u32; 3], (p, weight, phi): ([f64; 3], f64, [f64; 3])) -> Qp {
    Qp {
        p,
        weight,
        nodes: [nodes[0], nodes[1], nodes[2], nodes[2]],
        phi: [phi[0], phi[1], phi[2], 0.0],
    }
}

/// The points of the facet `f` of dimension `dim` − 1, the nodes at `nodes`, made again
/// with the bits [`traction`] made them with.
fn facet_points(f: &LoadFacet, dim: usize, nodes: Points) -> impl Iterator<Item = Qp> {
    let (facet, places) = (f.nodes, f.nodes.map(|n| nodes[n as usize]));
    let rule = facet_rule(places, dim, f.weights);
    rule.into_iter().map(move |q| facet_point(facet, q))
}

/// Body force i over every cell (with `reaches`, every cell with one of its nodes), by
/// `body_rule`, the nodes at `nodes`.
fn body_force(nodes: Points, cells: CellSource, i: usize, reaches: Option<&[usize]>) -> VectorLoad {
    let mut qps = Vec::new();
    cells.each(|_, t| {
        let vertices = &t.nodes[..=t.dim];
        if reaches.is_some_and(|r| !vertices.iter().any(|n| r.binary_search(n).is_ok())) {
            return;
        }
        for (phi, weight) in body_rule(t) {
            qps.push(body_point(nodes, t, phi, weight));
        }
    });
    VectorLoad {
        source: Source::Body(i),
        qps,
        facets: Vec::new(),
    }
}

/// The quadrature point of cell `t` with φ `phi` of its vertices and weight `weight`, the
/// nodes at `nodes`.
fn body_point(nodes: Points, t: &Cell, phi: [f64; 4], weight: f64) -> Qp {
    let mut p = [0.0; 3];
    for (k, pk) in p.iter_mut().enumerate() {
        *pk = (0..=t.dim).map(|i| phi[i] * nodes[t.nodes[i]][k]).sum();
    }
    Qp {
        p,
        weight,
        nodes: t.nodes.map(|n| n as u32),
        phi,
    }
}

/// A facet's nodes, sorted: the same key for either orientation.
pub(crate) fn sorted(f: &crate::mesh::Facet) -> Vec<usize> {
    let mut v = f.nodes().to_vec();
    v.sort_unstable();
    v
}

/// A degree-2 rule on a cell as (φ of its vertices at the point, weight): the three edge
/// midpoints with weight |T|/3 on a triangle; on a tetrahedron the 4 points with barycentric
/// coordinates (α, β, β, β) and permutations, α = (5 + 3√5)/20, β = (5 − √5)/20, weight |T|/4.
fn body_rule(t: &Cell) -> Vec<([f64; 4], f64)> {
    if t.dim == 2 {
        return [
            [0.5, 0.5, 0.0, 0.0],
            [0.0, 0.5, 0.5, 0.0],
            [0.5, 0.0, 0.5, 0.0],
        ]
        .into_iter()
        .map(|phi| (phi, t.measure / 3.0))
        .collect();
    }
    let s5 = 5f64.sqrt();
    let (a, b) = ((5.0 + 3.0 * s5) / 20.0, (5.0 - s5) / 20.0);
    (0..4)
        .map(|k| {
            let mut phi = [b; 4];
            phi[k] = a;
            (phi, t.measure / 4.0)
        })
        .collect()
}
