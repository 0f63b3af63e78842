//! The load functional ⟨f_n, v⟩ = (f_0(t_n), v) + (f_2(t_n), v)_{Γ2}: quadrature points are
//! laid out once, the expressions are evaluated at t_n each step. Boundary loads use 2-point
//! Gauss per edge (exact for a quadratic traction times P1, e.g. the paper's x(2−x));
//! body forces the edge-midpoint rule (exact for a linear force times P1).

use super::Triangle;
use crate::expr::{Point, Scalar};
use crate::mesh::Mesh;
use crate::scene::Scene;
use crate::{Error, Result};

/// 2-point Gauss on a facet: (point, weight, [φ_a, φ_b] at the point).
pub fn edge_gauss(mesh: &Mesh, f: [usize; 2]) -> [([f64; 2], f64, [f64; 2]); 2] {
    let (pa, pb) = (mesh.nodes[f[0]], mesh.nodes[f[1]]);
    let half = 0.5 * mesh.facet_length(f);
    let g = 0.5 / 3f64.sqrt();
    let at = |s: f64| -> ([f64; 2], f64, [f64; 2]) {
        // s ∈ (0, 1) along a → b; φ_a = 1 − s, φ_b = s.
        let p = [pa[0] + s * (pb[0] - pa[0]), pa[1] + s * (pb[1] - pa[1])];
        (p, half, [1.0 - s, s])
    };
    [at(0.5 - g), at(0.5 + g)]
}

/// A quadrature point of a load: where, how much weight, which nodes with which φ.
struct Qp {
    p: [f64; 2],
    weight: f64,
    nodes: [usize; 3],
    phi: [f64; 3],
}

/// A traction (index into `Scene::tractions`) or a body force (into `Scene::body_forces`).
enum Source {
    Traction(usize),
    Body(usize),
}

struct VectorLoad {
    source: Source,
    qps: Vec<Qp>,
}

/// All loads of a scene, ready to be evaluated at any t.
pub struct Loads {
    loads: Vec<VectorLoad>,
}

impl Loads {
    pub fn new(mesh: &Mesh, scene: &Scene, triangles: &[Triangle]) -> Result<Self> {
        let mut loads = Vec::new();
        // The traction boundary Γ2, for the check that every load group lies inside it.
        let gamma2: Option<std::collections::HashSet<[usize; 2]>> = mesh
            .boundary_group(&scene.groups.traction)
            .ok()
            .map(|g| g.facets.iter().map(|f| sorted(*f)).collect());
        for (i, t) in scene.tractions.iter().enumerate() {
            let g = mesh.boundary_group(&t.on).map_err(|e| {
                Error::input(format!(
                    "{}: key 'load.traction[{i}].on': {e}",
                    scene.path.display()
                ))
            })?;
            match &gamma2 {
                Some(g2) => {
                    if let Some(f) = g.facets.iter().find(|f| !g2.contains(&sorted(**f))) {
                        let (a, b) = (mesh.nodes[f[0]], mesh.nodes[f[1]]);
                        return Err(Error::input(format!(
                            "{}: key 'load.traction[{i}].on': group '{}' has the edge \
                             ({}, {})–({}, {}) outside the traction boundary '{}' (Γ2); \
                             tractions act on Γ2 only: add the curve to Γ2 in gmsh",
                            scene.path.display(),
                            t.on,
                            a[0],
                            a[1],
                            b[0],
                            b[1],
                            scene.groups.traction
                        )));
                    }
                }
                None => {
                    return Err(Error::input(format!(
                        "{}: key 'mesh.groups.traction': mesh '{}' has no group '{}', \
                         but load.traction[{i}] needs it",
                        scene.path.display(),
                        mesh.path.display(),
                        scene.groups.traction
                    )))
                }
            }
            let mut qps = Vec::new();
            for &f in &g.facets {
                for (p, weight, phi) in edge_gauss(mesh, f) {
                    qps.push(Qp {
                        p,
                        weight,
                        nodes: [f[0], f[1], f[1]],
                        phi: [phi[0], phi[1], 0.0],
                    });
                }
            }
            loads.push(VectorLoad {
                source: Source::Traction(i),
                qps,
            });
        }
        for i in 0..scene.body_forces.len() {
            let mut qps = Vec::new();
            for t in triangles {
                // Edge-midpoint rule: weight |T|/3 at each midpoint, φ = ½ at its two ends.
                for (a, b, c) in [(0, 1, 2), (1, 2, 0), (2, 0, 1)] {
                    let (pa, pb) = (mesh.nodes[t.nodes[a]], mesh.nodes[t.nodes[b]]);
                    qps.push(Qp {
                        p: [0.5 * (pa[0] + pb[0]), 0.5 * (pa[1] + pb[1])],
                        weight: t.area / 3.0,
                        nodes: [t.nodes[a], t.nodes[b], t.nodes[c]],
                        phi: [0.5, 0.5, 0.0],
                    });
                }
            }
            loads.push(VectorLoad {
                source: Source::Body(i),
                qps,
            });
        }
        Ok(Loads { loads })
    }

    pub fn is_empty(&self) -> bool {
        self.loads.is_empty()
    }

    /// Adds ⟨f(t), φ_d⟩ for every free dof d to `rhs`. A value that is not finite stops the
    /// run with the key, the time and the place.
    pub fn add(
        &self,
        t: f64,
        free: &[Option<usize>],
        scene: &Scene,
        rhs: &mut [f64],
    ) -> Result<()> {
        for load in &self.loads {
            let value: &[Scalar] = match load.source {
                Source::Traction(i) => &scene.tractions[i].value,
                Source::Body(i) => &scene.body_forces[i],
            };
            for q in &load.qps {
                let pt = Point {
                    x: q.p[0],
                    y: q.p[1],
                    t,
                    ..Default::default()
                };
                for (c, v) in value.iter().enumerate() {
                    let val = v.eval(&pt);
                    if !val.is_finite() {
                        // The scene was valid; the data went bad during the run: a failed
                        // run (exit 1), the last checkpoint stays as it was.
                        let key = match load.source {
                            Source::Traction(i) => format!("load.traction[{i}].value"),
                            Source::Body(i) => format!("load.body[{i}].value"),
                        };
                        return Err(Error::solve(format!(
                            "{}: key '{key}[{c}]' evaluates to {val} at (x, y) = ({}, {}) at \
                             t = {t}; the run stops here (the last checkpoint is kept)",
                            scene.path.display(),
                            q.p[0],
                            q.p[1]
                        )));
                    }
                    for (n, ph) in q.nodes.iter().zip(q.phi) {
                        if let Some(d) = free[2 * n + c] {
                            rhs[d] += q.weight * ph * val;
                        }
                    }
                }
            }
        }
        Ok(())
    }
}

fn sorted(f: [usize; 2]) -> [usize; 2] {
    [f[0].min(f[1]), f[0].max(f[1])]
}
