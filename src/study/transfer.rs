//! Moving a P1 field from one triangulation to another, and its exact norms.
//!
//! The study measures ‖u(T) − u_N^{kh}‖ on the reference mesh: the coarse solution u^h is
//! evaluated at every reference node, and the difference of two P1 functions on the
//! reference mesh is integrated exactly ([`p1_norms`]).
//!
//! - Nested meshes (every reference triangle lies inside one coarse triangle, as for the
//!   paper's uniform refinements): u^h is linear on each reference triangle, so its values at
//!   the reference nodes define exactly the same function. This is the exact P1 prolongation,
//!   and the error is the exact H¹ norm of u^h − u_ref.
//! - Non-nested meshes (unstructured families): u^h is replaced by its nodal interpolant
//!   I_ref u^h on the reference mesh (what `interpolate` does in FEniCS or scikit-fem). That
//!   adds the interpolation error u^h − I_ref u^h, which lives only in the reference
//!   triangles cut by a coarse edge (where the gradient of u^h jumps): a strip of width
//!   h_ref along the coarse edges, so |u^h − I_ref u^h|_{H¹} ≈ (h_ref/h)^{1/2} times the
//!   gradient jumps of u^h, which are themselves of the size of the discretization error.
//!   It is small against the measured error when the reference is much finer than the
//!   level, and it shrinks with h_ref. Reference nodes outside the coarse mesh (a curved
//!   boundary cut by straight coarse edges) take the value at the nearest point of the
//!   coarse mesh.
//!
//! Point location uses an R-tree (`rstar`) of the triangles, whose distance is the exact
//! point–triangle distance: the nearest triangle is the one containing the point.

use crate::fem::{Discretization, Triangle};
use rstar::{PointDistance, RTree, RTreeObject, AABB};

/// One triangle in the R-tree: its index and corners.
struct TriangleBox {
    index: usize,
    corners: [[f64; 2]; 3],
}

impl RTreeObject for TriangleBox {
    type Envelope = AABB<[f64; 2]>;

    fn envelope(&self) -> Self::Envelope {
        AABB::from_points(self.corners.iter())
    }
}

impl PointDistance for TriangleBox {
    fn distance_2(&self, p: &[f64; 2]) -> f64 {
        let q = closest_point(&self.corners, *p);
        let (dx, dy) = (q[0] - p[0], q[1] - p[1]);
        dx * dx + dy * dy
    }
}

/// Barycentric coordinates of `p` in the triangle `c` (they sum to 1; all ≥ 0 inside).
pub fn barycentric(c: &[[f64; 2]; 3], p: [f64; 2]) -> [f64; 3] {
    let det = (c[1][0] - c[0][0]) * (c[2][1] - c[0][1]) - (c[2][0] - c[0][0]) * (c[1][1] - c[0][1]);
    let l1 =
        ((p[0] - c[0][0]) * (c[2][1] - c[0][1]) - (c[2][0] - c[0][0]) * (p[1] - c[0][1])) / det;
    let l2 =
        ((c[1][0] - c[0][0]) * (p[1] - c[0][1]) - (p[0] - c[0][0]) * (c[1][1] - c[0][1])) / det;
    [1.0 - l1 - l2, l1, l2]
}

/// The point of the (closed) triangle `c` nearest to `p`.
fn closest_point(c: &[[f64; 2]; 3], p: [f64; 2]) -> [f64; 2] {
    let l = barycentric(c, p);
    if l.iter().all(|&x| x >= 0.0) {
        return p;
    }
    let mut best = c[0];
    let mut best_d = f64::INFINITY;
    for i in 0..3 {
        let (a, b) = (c[i], c[(i + 1) % 3]);
        let (ex, ey) = (b[0] - a[0], b[1] - a[1]);
        let t = (((p[0] - a[0]) * ex + (p[1] - a[1]) * ey) / (ex * ex + ey * ey)).clamp(0.0, 1.0);
        let q = [a[0] + t * ex, a[1] + t * ey];
        let d = (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2);
        if d < best_d {
            best_d = d;
            best = q;
        }
    }
    best
}

/// Where a point lies in a triangulation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Location {
    /// The triangle containing the point (or nearest to it).
    pub triangle: usize,
    /// Barycentric coordinates of the point (of the nearest point, when outside).
    pub lambda: [f64; 3],
    /// Distance from the point to the triangle: 0 up to rounding when inside the mesh.
    pub distance: f64,
}

/// Point location in a 2D triangulation (z of the nodes is ignored).
pub struct Locator {
    corners: Vec<[[f64; 2]; 3]>,
    tree: RTree<TriangleBox>,
    /// The diameter of the bounding box: the scale of "inside" tolerances.
    pub size: f64,
}

impl Locator {
    pub fn new(nodes: &[[f64; 3]], triangles: &[[usize; 3]]) -> Self {
        let corners: Vec<[[f64; 2]; 3]> = triangles
            .iter()
            .map(|t| t.map(|n| [nodes[n][0], nodes[n][1]]))
            .collect();
        let tree = RTree::bulk_load(
            corners
                .iter()
                .enumerate()
                .map(|(index, c)| TriangleBox { index, corners: *c })
                .collect(),
        );
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in nodes {
            for c in 0..2 {
                lo[c] = lo[c].min(p[c]);
                hi[c] = hi[c].max(p[c]);
            }
        }
        let size = ((hi[0] - lo[0]).powi(2) + (hi[1] - lo[1]).powi(2)).sqrt();
        Locator {
            corners,
            tree,
            size,
        }
    }

    /// Builds the locator of a discretization's mesh.
    pub fn of(disc: &Discretization) -> Self {
        let tris: Vec<[usize; 3]> = disc.triangles.iter().map(|t| t.nodes).collect();
        Locator::new(&disc.nodes, &tris)
    }

    /// The triangle containing `p`, or the nearest one when `p` lies outside the mesh (then
    /// `lambda` are the coordinates of the nearest point of the mesh). None for an empty mesh.
    pub fn locate(&self, p: [f64; 2]) -> Option<Location> {
        let t = self.tree.nearest_neighbor(&p)?;
        let d2 = t.distance_2(&p);
        let q = if d2 > 0.0 {
            closest_point(&t.corners, p)
        } else {
            p
        };
        Some(Location {
            triangle: t.index,
            lambda: barycentric(&t.corners, q),
            distance: d2.sqrt(),
        })
    }

    /// The corners of triangle `t`.
    pub fn corners(&self, t: usize) -> &[[f64; 2]; 3] {
        &self.corners[t]
    }
}

/// Evaluation of P1 fields of a source mesh at the nodes of a target mesh.
pub struct Transfer {
    /// For each target node: source triangle (its node indices) and barycentric weights.
    pub weights: Vec<([usize; 3], [f64; 3])>,
    /// Every target triangle lies in one source triangle: the transfer is the exact P1
    /// prolongation.
    pub nested: bool,
    /// Target nodes outside the source mesh (by more than 1e-10 of its size).
    pub outside: usize,
    /// The largest distance of a target node from the source mesh.
    pub max_distance: f64,
}

impl Transfer {
    /// Locates every target node in the source mesh and checks nesting: for each target
    /// triangle, the source triangle containing its centroid must contain its three corners
    /// (barycentric coordinates ≥ −1e-10).
    pub fn new(
        source_nodes: &[[f64; 3]],
        source_triangles: &[[usize; 3]],
        target_nodes: &[[f64; 3]],
        target_triangles: &[[usize; 3]],
    ) -> Self {
        let loc = Locator::new(source_nodes, source_triangles);
        let tol = 1e-10 * loc.size;
        let mut outside = 0;
        let mut max_distance: f64 = 0.0;
        let weights = target_nodes
            .iter()
            .map(|p| {
                let l = loc.locate([p[0], p[1]]).expect("source mesh has triangles");
                if l.distance > tol {
                    outside += 1;
                }
                max_distance = max_distance.max(l.distance);
                (source_triangles[l.triangle], l.lambda)
            })
            .collect();
        let nested = outside == 0
            && target_triangles.iter().all(|t| {
                let c = t.map(|n| [target_nodes[n][0], target_nodes[n][1]]);
                let centroid = [
                    (c[0][0] + c[1][0] + c[2][0]) / 3.0,
                    (c[0][1] + c[1][1] + c[2][1]) / 3.0,
                ];
                let Some(l) = loc.locate(centroid) else {
                    return false;
                };
                let s = loc.corners(l.triangle);
                c.iter()
                    .all(|&q| barycentric(s, q).iter().all(|&x| x >= -1e-10))
            });
        Transfer {
            weights,
            nested,
            outside,
            max_distance,
        }
    }

    /// From discretizations (the free-dof numbering does not matter here).
    pub fn between(source: &Discretization, target: &Discretization) -> Self {
        let tris = |d: &Discretization| -> Vec<[usize; 3]> {
            d.triangles.iter().map(|t| t.nodes).collect()
        };
        Transfer::new(&source.nodes, &tris(source), &target.nodes, &tris(target))
    }

    /// The source field (2 components per source node) at the target nodes.
    pub fn apply(&self, source: &[[f64; 2]]) -> Vec<[f64; 2]> {
        self.weights
            .iter()
            .map(|(n, l)| {
                let mut v = [0.0; 2];
                for (ni, li) in n.iter().zip(l) {
                    v[0] += li * source[*ni][0];
                    v[1] += li * source[*ni][1];
                }
                v
            })
            .collect()
    }
}

pub use crate::fem::{nodal2, p1_norms};

/// The largest edge of a triangulation (the mesh size h_max).
pub fn max_edge(nodes: &[[f64; 3]], triangles: &[Triangle]) -> f64 {
    let mut h: f64 = 0.0;
    for t in triangles {
        for i in 0..3 {
            let (a, b) = (nodes[t.nodes[i]], nodes[t.nodes[(i + 1) % 3]]);
            h = h.max(((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt());
        }
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn barycentric_and_closest_point() {
        let c = [[0.0, 0.0], [2.0, 0.0], [0.0, 1.0]];
        let l = barycentric(&c, [0.5, 0.25]);
        assert!((l[0] - 0.5).abs() < 1e-15 && (l[1] - 0.25).abs() < 1e-15);
        assert_eq!(closest_point(&c, [0.5, 0.25]), [0.5, 0.25]);
        assert_eq!(closest_point(&c, [1.0, -1.0]), [1.0, 0.0]);
        assert_eq!(closest_point(&c, [-1.0, -1.0]), [0.0, 0.0]);
    }

    #[test]
    fn locator_finds_containing_and_nearest_triangles() {
        // The unit square cut along its diagonal.
        let nodes = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ];
        let tris = [[0, 1, 2], [0, 2, 3]];
        let loc = Locator::new(&nodes, &tris);
        let l = loc.locate([0.8, 0.1]).unwrap();
        assert_eq!((l.triangle, l.distance), (0, 0.0));
        let l = loc.locate([0.1, 0.8]).unwrap();
        assert_eq!(l.triangle, 1);
        let l = loc.locate([0.5, 1.5]).unwrap();
        assert_eq!(l.triangle, 1);
        assert!((l.distance - 0.5).abs() < 1e-15);
    }
}
