//! Moving a P1 field from one mesh to another (triangles in 2D, tetrahedra in 3D), and its
//! exact norms.
//!
//! The study measures ‖u(T) − u_N^{kh}‖ on the reference mesh: the coarse solution u^h is
//! evaluated at every reference node, and the difference of two P1 functions on the
//! reference mesh is integrated exactly ([`p1_norms`]).
//!
//! - Nested meshes (every reference cell lies inside one coarse cell, as for the paper's
//!   uniform refinements): u^h is linear on each reference cell, so its values at the
//!   reference nodes define exactly the same function. This is the exact P1 prolongation,
//!   and the error is the exact H¹ norm of u^h − u_ref.
//! - Non-nested meshes (unstructured families; in 3D also structured ones whose cubes are
//!   cut into tetrahedra differently at each level): u^h is replaced by its nodal
//!   interpolant I_ref u^h on the reference mesh (what `interpolate` does in FEniCS or
//!   scikit-fem). That adds the interpolation error u^h − I_ref u^h, which lives only in
//!   the reference cells cut by a coarse edge (2D) or face (3D), where the gradient of u^h
//!   jumps: a layer of width h_ref along them, a fraction h_ref/h of the domain, so
//!   |u^h − I_ref u^h|_{H¹} ≈ (h_ref/h)^{1/2} times the gradient jumps of u^h, which are
//!   themselves of the size of the discretization error. It is small against the measured
//!   error when the reference is much finer than the level, and it shrinks with h_ref.
//!   Reference nodes outside the coarse mesh (a curved boundary cut by straight coarse
//!   edges, or rounding) take the value at the nearest point of the coarse mesh.
//!
//! Point location uses an R-tree (`rstar`, AABBs in R^2 or R^3) of the cells, whose
//! distance is the exact point–simplex distance: the nearest cell is the one containing the
//! point.

use crate::fem::{Cell, Discretization};
use rstar::{PointDistance, RTree, RTreeObject, AABB};

/// The corners of a cell as points of space (z = 0 in the plane); a triangle uses 3.
type Corners = [[f64; 3]; 4];

/// The first D coordinates of a point of space.
fn head<const D: usize>(p: &[f64; 3]) -> [f64; D] {
    std::array::from_fn(|k| p[k])
}

/// A point of R^D as a point of space.
fn pad<const D: usize>(p: [f64; D]) -> [f64; 3] {
    let mut q = [0.0; 3];
    q[..D].copy_from_slice(&p);
    q
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dist2(a: [f64; 3], b: [f64; 3]) -> f64 {
    let d = sub(a, b);
    dot(d, d)
}

/// One cell in the R-tree of R^D: a triangle (D = 2) or a tetrahedron (D = 3).
struct CellBox<const D: usize> {
    index: usize,
    corners: Corners,
}

impl<const D: usize> CellBox<D> {
    fn corners(&self) -> &[[f64; 3]] {
        &self.corners[..=D]
    }
}

impl<const D: usize> RTreeObject for CellBox<D> {
    type Envelope = AABB<[f64; D]>;

    fn envelope(&self) -> Self::Envelope {
        let points = self.corners.map(|c| head::<D>(&c));
        AABB::from_points(points[..=D].iter())
    }
}

impl<const D: usize> PointDistance for CellBox<D> {
    fn distance_2(&self, p: &[f64; D]) -> f64 {
        let p = pad(*p);
        dist2(closest_point(self.corners(), p, D), p)
    }
}

/// Barycentric coordinates of `p` in the simplex of R^D with the D + 1 corners `c` (a
/// triangle of the plane or a tetrahedron): they sum to 1 and are all ≥ 0 inside; entry 3
/// is 0 for a triangle.
pub fn barycentric<const D: usize>(c: &[[f64; D]], p: [f64; D]) -> [f64; 4] {
    assert!(
        (2..=3).contains(&D) && c.len() == D + 1,
        "a simplex of R^{D} has {} corners, not {}",
        D + 1,
        c.len()
    );
    let mut corners: Corners = [[0.0; 3]; 4];
    for (k, x) in corners.iter_mut().zip(c) {
        *k = pad(*x);
    }
    coordinates(&corners[..=D], pad(p))
}

/// [`barycentric`] for corners and point in space: a triangle of the plane (3 corners, z
/// ignored) or a tetrahedron (4).
fn coordinates(c: &[[f64; 3]], p: [f64; 3]) -> [f64; 4] {
    if c.len() == 3 {
        let det =
            (c[1][0] - c[0][0]) * (c[2][1] - c[0][1]) - (c[2][0] - c[0][0]) * (c[1][1] - c[0][1]);
        let l1 =
            ((p[0] - c[0][0]) * (c[2][1] - c[0][1]) - (c[2][0] - c[0][0]) * (p[1] - c[0][1])) / det;
        let l2 =
            ((c[1][0] - c[0][0]) * (p[1] - c[0][1]) - (p[0] - c[0][0]) * (c[1][1] - c[0][1])) / det;
        return [1.0 - l1 - l2, l1, l2, 0.0];
    }
    // λ_i = (p − c_0)·∇λ_i with the rows of the inverse Jacobian e_j × e_k / det.
    let (e1, e2, e3, w) = (
        sub(c[1], c[0]),
        sub(c[2], c[0]),
        sub(c[3], c[0]),
        sub(p, c[0]),
    );
    let n1 = cross(e2, e3);
    let det = dot(e1, n1);
    let l1 = dot(w, n1) / det;
    let l2 = dot(w, cross(e3, e1)) / det;
    let l3 = dot(w, cross(e1, e2)) / det;
    [1.0 - l1 - l2 - l3, l1, l2, l3]
}

/// The point of the closed simplex `c` nearest to `p`: `c` is a cell of R^dim (dim + 1
/// corners) or one of its faces or edges (the recursion on the boundary).
fn closest_point(c: &[[f64; 3]], p: [f64; 3], dim: usize) -> [f64; 3] {
    let n = c.len();
    if n == 2 {
        let (a, e) = (c[0], sub(c[1], c[0]));
        let t = (dot(sub(p, a), e) / dot(e, e)).clamp(0.0, 1.0);
        return [0, 1, 2].map(|k| a[k] + t * e[k]);
    }
    // The projection q of p onto the affine hull and its barycentric coordinates: p itself
    // for a cell, the foot of the perpendicular for a face of a tetrahedron.
    let (l, q) = if n == dim + 1 {
        (coordinates(c, p), p)
    } else {
        let (e1, e2, w) = (sub(c[1], c[0]), sub(c[2], c[0]), sub(p, c[0]));
        let (d11, d12, d22) = (dot(e1, e1), dot(e1, e2), dot(e2, e2));
        let (r1, r2) = (dot(w, e1), dot(w, e2));
        let det = d11 * d22 - d12 * d12;
        let (l1, l2) = ((d22 * r1 - d12 * r2) / det, (d11 * r2 - d12 * r1) / det);
        (
            [1.0 - l1 - l2, l1, l2, 0.0],
            [0, 1, 2].map(|k| c[0][k] + l1 * e1[k] + l2 * e2[k]),
        )
    };
    if l[..n].iter().all(|&x| x >= 0.0) {
        return q;
    }
    // Outside: the nearest point of the facets, {c_i, c_{i+1}, …} cyclically.
    let mut best = (f64::INFINITY, c[0]);
    for i in 0..n {
        let mut facet: Corners = [[0.0; 3]; 4];
        for (j, f) in facet.iter_mut().take(n - 1).enumerate() {
            *f = c[(i + j) % n];
        }
        let q = closest_point(&facet[..n - 1], p, dim);
        let d = dist2(q, p);
        if d < best.0 {
            best = (d, q);
        }
    }
    best.1
}

/// Where a point lies in a mesh.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Location {
    /// The cell containing the point (or nearest to it).
    pub cell: usize,
    /// Barycentric coordinates of the point (of the nearest point, when outside); entry 3 is
    /// 0 for a triangle.
    pub lambda: [f64; 4],
    /// Distance from the point to the cell: 0 up to rounding when inside the mesh.
    pub distance: f64,
}

/// Point location in a mesh of R^D: triangles (D = 2, z of the nodes ignored) or tetrahedra
/// (D = 3).
pub struct Locator<const D: usize> {
    corners: Vec<Corners>,
    tree: RTree<CellBox<D>>,
    /// The diameter of the bounding box: the scale of "inside" tolerances.
    pub size: f64,
}

impl<const D: usize> Locator<D> {
    /// `cells` are the V = D + 1 nodes of each cell.
    pub fn new<const V: usize>(nodes: &[[f64; 3]], cells: &[[usize; V]]) -> Self {
        assert!(
            (2..=3).contains(&D) && V == D + 1,
            "a mesh of R^{D} has cells of {} nodes, not {V}",
            D + 1
        );
        let corners: Vec<Corners> = cells
            .iter()
            .map(|t| {
                let mut c: Corners = [[0.0; 3]; 4];
                for (ci, &n) in c.iter_mut().zip(t) {
                    *ci = pad(head::<D>(&nodes[n]));
                }
                c
            })
            .collect();
        let tree = RTree::bulk_load(
            corners
                .iter()
                .enumerate()
                .map(|(index, c)| CellBox { index, corners: *c })
                .collect(),
        );
        let (mut lo, mut hi) = ([f64::INFINITY; D], [f64::NEG_INFINITY; D]);
        for p in nodes {
            for ((l, h), x) in lo.iter_mut().zip(&mut hi).zip(p) {
                *l = l.min(*x);
                *h = h.max(*x);
            }
        }
        let size = lo
            .iter()
            .zip(&hi)
            .map(|(l, h)| (h - l).powi(2))
            .sum::<f64>()
            .sqrt();
        Locator {
            corners,
            tree,
            size,
        }
    }

    /// The cell containing `p`, or the nearest one when `p` lies outside the mesh (then
    /// `lambda` are the coordinates of the nearest point of the mesh). None for an empty mesh.
    pub fn locate(&self, p: [f64; D]) -> Option<Location> {
        let t = self.tree.nearest_neighbor(&p)?;
        let d2 = t.distance_2(&p);
        let p = pad(p);
        let q = if d2 > 0.0 {
            closest_point(t.corners(), p, D)
        } else {
            p
        };
        Some(Location {
            cell: t.index,
            lambda: coordinates(t.corners(), q),
            distance: d2.sqrt(),
        })
    }

    /// The D + 1 corners of cell `t` (z = 0 in the plane).
    pub fn corners(&self, t: usize) -> &[[f64; 3]] {
        &self.corners[t][..=D]
    }
}

/// Evaluation of P1 fields of a source mesh at the nodes of a target mesh.
pub struct Transfer {
    /// For each target node: the source cell (its node indices) and barycentric weights;
    /// entry 3 of both is unused for triangles.
    pub weights: Vec<([usize; 4], [f64; 4])>,
    /// Nodes per cell: 3 (triangles) or 4 (tetrahedra).
    pub corners: usize,
    /// Every target cell lies in one source cell: the transfer is the exact P1
    /// prolongation.
    pub nested: bool,
    /// Target nodes outside the source mesh (by more than 1e-10 of its size).
    pub outside: usize,
    /// The largest distance of a target node from the source mesh.
    pub max_distance: f64,
}

impl Transfer {
    /// Locates every target node in the source mesh and checks nesting: for each target
    /// cell, the source cell containing its centroid must contain all its corners
    /// (barycentric coordinates ≥ −1e-10). The cells are triangles (V = 3, z of the nodes
    /// ignored) or tetrahedra (V = 4).
    pub fn new<const V: usize>(
        source_nodes: &[[f64; 3]],
        source_cells: &[[usize; V]],
        target_nodes: &[[f64; 3]],
        target_cells: &[[usize; V]],
    ) -> Self {
        match V {
            3 => Transfer::locate(
                &Locator::<2>::new(source_nodes, source_cells),
                source_cells,
                target_nodes,
                target_cells,
            ),
            4 => Transfer::locate(
                &Locator::<3>::new(source_nodes, source_cells),
                source_cells,
                target_nodes,
                target_cells,
            ),
            _ => panic!("cells are triangles (3 nodes) or tetrahedra (4 nodes), not {V} nodes"),
        }
    }

    fn locate<const D: usize, const V: usize>(
        loc: &Locator<D>,
        source_cells: &[[usize; V]],
        target_nodes: &[[f64; 3]],
        target_cells: &[[usize; V]],
    ) -> Self {
        let tol = 1e-10 * loc.size;
        let mut outside = 0;
        let mut max_distance: f64 = 0.0;
        let weights = target_nodes
            .iter()
            .map(|p| {
                let l = loc.locate(head(p)).expect("source mesh has cells");
                if l.distance > tol {
                    outside += 1;
                }
                max_distance = max_distance.max(l.distance);
                let mut nodes = [0; 4];
                nodes[..V].copy_from_slice(&source_cells[l.cell]);
                (nodes, l.lambda)
            })
            .collect();
        let nested = outside == 0
            && target_cells.iter().all(|t| {
                let c = t.map(|n| head::<D>(&target_nodes[n]));
                let centroid: [f64; D] =
                    std::array::from_fn(|k| c.iter().map(|x| x[k]).sum::<f64>() / V as f64);
                let Some(l) = loc.locate(centroid) else {
                    return false;
                };
                let s = loc.corners(l.cell);
                c.iter()
                    .all(|&q| coordinates(s, pad(q))[..V].iter().all(|&x| x >= -1e-10))
            });
        Transfer {
            weights,
            corners: V,
            nested,
            outside,
            max_distance,
        }
    }

    /// From discretizations of the same dimension (the free-dof numbering does not matter
    /// here).
    pub fn between(source: &Discretization, target: &Discretization) -> Self {
        assert_eq!(
            source.dim, target.dim,
            "a transfer between 2D and 3D meshes"
        );
        if source.dim == 2 {
            Transfer::new(
                source.nodes.all(),
                &cells::<3>(source),
                target.nodes.all(),
                &cells::<3>(target),
            )
        } else {
            Transfer::new(
                source.nodes.all(),
                &cells::<4>(source),
                target.nodes.all(),
                &cells::<4>(target),
            )
        }
    }

    /// The source field (N components per source node) at the target nodes.
    pub fn apply<const N: usize>(&self, source: &[[f64; N]]) -> Vec<[f64; N]> {
        self.weights
            .iter()
            .map(|(n, l)| {
                let mut v = [0.0; N];
                for (ni, li) in n.iter().zip(l).take(self.corners) {
                    for (vk, sk) in v.iter_mut().zip(&source[*ni]) {
                        *vk += li * sk;
                    }
                }
                v
            })
            .collect()
    }
}

pub use crate::fem::{nodal_vectors, p1_norms};

/// The V nodes of each cell of a discretization (V = dim + 1).
fn cells<const V: usize>(disc: &Discretization) -> Vec<[usize; V]> {
    disc.cells
        .iter()
        .map(|c| std::array::from_fn(|i| c.nodes[i]))
        .collect()
}

/// The longest edge of a mesh (the mesh size h_max).
pub fn max_edge(nodes: &[[f64; 3]], cells: &[Cell]) -> f64 {
    let mut h: f64 = 0.0;
    for t in cells {
        let v = t.vertices();
        for (i, &a) in v.iter().enumerate() {
            for &b in &v[i + 1..] {
                h = h.max(dist2(nodes[a], nodes[b]).sqrt());
            }
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
        assert_eq!(l[3], 0.0);
        let c = c.map(pad);
        assert_eq!(closest_point(&c, [0.5, 0.25, 0.0], 2), [0.5, 0.25, 0.0]);
        assert_eq!(closest_point(&c, [1.0, -1.0, 0.0], 2), [1.0, 0.0, 0.0]);
        assert_eq!(closest_point(&c, [-1.0, -1.0, 0.0], 2), [0.0, 0.0, 0.0]);
    }

    #[test]
    fn tetrahedron_coordinates_and_closest_point() {
        let c = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ];
        let l = barycentric(&c, [0.1, 0.2, 0.3]);
        for (a, b) in l.iter().zip([0.4, 0.1, 0.2, 0.3]) {
            assert!((a - b).abs() < 1e-15, "{l:?}");
        }
        let near = |p: [f64; 3], q: [f64; 3]| {
            let r = closest_point(&c, p, 3);
            assert!(dist2(r, q) < 1e-30, "{p:?}: {r:?}, not {q:?}");
        };
        near([0.1, 0.2, 0.3], [0.1, 0.2, 0.3]);
        // Below a face, beside an edge, beyond a vertex, above the slanted face.
        near([0.2, 0.3, -1.0], [0.2, 0.3, 0.0]);
        near([0.5, -1.0, -1.0], [0.5, 0.0, 0.0]);
        near([2.0, -1.0, -1.0], [1.0, 0.0, 0.0]);
        near([1.0, 1.0, 1.0], [1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0]);
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
        assert_eq!((l.cell, l.distance), (0, 0.0));
        let l = loc.locate([0.1, 0.8]).unwrap();
        assert_eq!(l.cell, 1);
        let l = loc.locate([0.5, 1.5]).unwrap();
        assert_eq!(l.cell, 1);
        assert!((l.distance - 0.5).abs() < 1e-15);
    }

    #[test]
    fn locator_finds_containing_and_nearest_tetrahedra() {
        // The unit cube cut into the 6 tetrahedra around its diagonal (0,0,0)–(1,1,1).
        let nodes: Vec<[f64; 3]> = (0..8)
            .map(|i| [i & 1, (i >> 1) & 1, (i >> 2) & 1].map(f64::from))
            .collect();
        let tets = [
            [0, 1, 3, 7],
            [0, 1, 5, 7],
            [0, 2, 3, 7],
            [0, 2, 6, 7],
            [0, 4, 5, 7],
            [0, 4, 6, 7],
        ];
        let loc = Locator::<3>::new(&nodes, &tets);
        assert!((loc.size - 3f64.sqrt()).abs() < 1e-15);
        for p in [
            [0.9, 0.5, 0.1],
            [0.2, 0.7, 0.4],
            [0.3, 0.1, 0.95],
            [1.0, 1.0, 0.5],
        ] {
            let l = loc.locate(p).unwrap();
            assert_eq!(l.distance, 0.0, "{p:?}");
            assert!(l.lambda.iter().all(|&x| x >= -1e-15), "{p:?}: {l:?}");
            let c = loc.corners(l.cell);
            for (k, pk) in p.iter().enumerate() {
                let x: f64 = (0..4).map(|i| l.lambda[i] * c[i][k]).sum();
                assert!((x - pk).abs() < 1e-15);
            }
        }
        let l = loc.locate([0.5, 0.5, 1.5]).unwrap();
        assert!((l.distance - 0.5).abs() < 1e-15);
        assert!(loc
            .corners(l.cell)
            .iter()
            .all(|c| c[2] == 0.0 || c[2] == 1.0));
    }
}
