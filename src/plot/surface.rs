//! What `plot` sees of a 3D (tetrahedral) run from a direction: the geometry of the 3D
//! figure, without any drawing.
//!
//! - **Boundary surface.** The faces of the tetrahedra that belong to exactly one tetrahedron,
//!   each oriented outward: its nodes `[a, b, c]` are ordered so that (b − a) × (c − a)
//!   points away from the fourth node of its tetrahedron (undeformed positions, where every
//!   tetrahedron of a run has positive volume).
//! - **Camera.** Orthographic. `w` is the unit view direction, from the body towards the eye
//!   (`--view`); z is up: the screen's right is r = ẑ × w / |ẑ × w| (ŷ × w when w is along
//!   z), its up u = w × r. A point p is drawn at (p·r, p·u) with depth p·w (larger: nearer).
//! - **Visible faces.** Back faces are culled: a face is drawn when its outward normal n on
//!   the deformed body has n·w > 0. The visible faces are drawn far to near by the depth of
//!   their centroid (painter's algorithm). That is exact for a convex body; on a non-convex
//!   one a large face may be ordered wrongly against a small one that it partly hides.
//! - **Shading.** Lambert with one light a little above and left of the eye,
//!   L = (−0.25 r + 0.35 u + w) / |…|: a face's colour is the colour map's colour times
//!   s = 0.6 + 0.4 max(0, n·L), so faces of other directions differ in brightness and the
//!   shape reads, while no colour gets darker than 60 % of the colour bar's.
//! - **Feature edges.** Boundary edges whose two faces' undeformed normals differ by more
//!   than 30° (cos < 0.866): the box's 12 edges for the block, the rim of a hole. They are
//!   drawn on the deformed body, and on the undeformed one as its ghost.

use crate::mesh::{cross, dot, norm, sub};
use std::collections::HashMap;

/// A boundary face: its nodes, outward, and the tetrahedron it belongs to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Face {
    pub nodes: [usize; 3],
    pub cell: usize,
}

/// The faces of `tets` that belong to exactly one tetrahedron, oriented outward, in the
/// order of their sorted node numbers (found by sorting all faces: no hashing).
pub fn boundary_faces(points: &[[f64; 3]], tets: &[[usize; 4]]) -> Vec<Face> {
    const LOCAL: [[usize; 4]; 4] = [[1, 2, 3, 0], [0, 2, 3, 1], [0, 1, 3, 2], [0, 1, 2, 3]];
    let mut all: Vec<([usize; 3], Face)> = Vec::with_capacity(4 * tets.len());
    for (cell, t) in tets.iter().enumerate() {
        for l in LOCAL {
            let [a, mut b, mut c, d] = l.map(|i| t[i]);
            let (pa, pd) = (points[a], points[d]);
            let n = cross(sub(points[b], pa), sub(points[c], pa));
            if dot(n, sub(pd, pa)) > 0.0 {
                std::mem::swap(&mut b, &mut c);
            }
            let mut key = [a, b, c];
            key.sort_unstable();
            let nodes = [a, b, c];
            all.push((key, Face { nodes, cell }));
        }
    }
    all.sort_unstable_by_key(|(key, face)| (*key, face.cell));
    all.chunk_by(|x, y| x.0 == y.0)
        .filter(|run| run.len() == 1)
        .map(|run| run[0].1)
        .collect()
}

/// The unit normal of the triangle `p` by the right-hand rule (zero for a degenerate one).
pub fn normal(p: [[f64; 3]; 3]) -> [f64; 3] {
    let n = cross(sub(p[1], p[0]), sub(p[2], p[0]));
    let l = norm(n);
    if l > 0.0 {
        n.map(|x| x / l)
    } else {
        [0.0; 3]
    }
}

/// An orthographic camera looking along −w, z up (see the module doc).
#[derive(Clone, Copy, Debug)]
pub struct Camera {
    r: [f64; 3],
    u: [f64; 3],
    w: [f64; 3],
    light: [f64; 3],
}

impl Camera {
    /// The camera that sees the body from `view` (from the body towards the eye); None for
    /// a zero or non-finite direction.
    pub fn new(view: [f64; 3]) -> Option<Camera> {
        let l = norm(view);
        if !l.is_finite() || l == 0.0 {
            return None;
        }
        let w = view.map(|x| x / l);
        let mut r = cross([0.0, 0.0, 1.0], w);
        if norm(r) < 1e-9 {
            r = cross([0.0, 1.0, 0.0], w);
        }
        let r = r.map(|x| x / norm(r));
        let u = cross(w, r);
        let light = [0, 1, 2].map(|k| -0.25 * r[k] + 0.35 * u[k] + w[k]);
        let light = light.map(|x| x / norm(light));
        Some(Camera { r, u, w, light })
    }

    /// Where `p` is drawn on the screen.
    pub fn project(&self, p: [f64; 3]) -> (f64, f64) {
        (dot(p, self.r), dot(p, self.u))
    }

    /// How near `p` is to the eye.
    pub fn depth(&self, p: [f64; 3]) -> f64 {
        dot(p, self.w)
    }

    /// Whether a face of outward unit normal `n` faces the eye.
    pub fn faces(&self, n: [f64; 3]) -> bool {
        dot(n, self.w) > 0.0
    }

    /// The brightness factor of a face of outward unit normal `n`, in [0.6, 1].
    pub fn shade(&self, n: [f64; 3]) -> f64 {
        0.6 + 0.4 * dot(n, self.light).max(0.0)
    }
}

/// The visible faces of the deformed body (`points` deformed), far to near, each with its
/// brightness factor.
pub fn painter_order(camera: &Camera, points: &[[f64; 3]], faces: &[Face]) -> Vec<(usize, f64)> {
    let mut seen: Vec<(usize, f64, f64)> = faces
        .iter()
        .enumerate()
        .filter_map(|(i, f)| {
            let p = f.nodes.map(|n| points[n]);
            let n = normal(p);
            camera.faces(n).then(|| {
                let centroid = [0, 1, 2].map(|k| (p[0][k] + p[1][k] + p[2][k]) / 3.0);
                (i, camera.depth(centroid), camera.shade(n))
            })
        })
        .collect();
    seen.sort_by(|a, b| a.1.total_cmp(&b.1));
    seen.into_iter().map(|(i, _, s)| (i, s)).collect()
}

/// An undirected edge, smaller node first.
pub fn edge(a: usize, b: usize) -> (usize, usize) {
    (a.min(b), a.max(b))
}

/// The boundary faces of each edge of `faces` (two on a closed surface).
pub fn edge_faces(faces: &[Face]) -> HashMap<(usize, usize), Vec<usize>> {
    let mut map: HashMap<(usize, usize), Vec<usize>> = HashMap::new();
    for (i, f) in faces.iter().enumerate() {
        for k in 0..3 {
            map.entry(edge(f.nodes[k], f.nodes[(k + 1) % 3]))
                .or_default()
                .push(i);
        }
    }
    map
}

/// The feature edges of the surface (undeformed `points`): edges whose two faces' normals
/// differ by more than 30°, and edges that do not have exactly two faces. Each with its
/// faces, sorted by node numbers.
pub fn feature_edges(
    points: &[[f64; 3]],
    faces: &[Face],
    by_edge: &HashMap<(usize, usize), Vec<usize>>,
) -> Vec<((usize, usize), Vec<usize>)> {
    let n = |i: usize| normal(faces[i].nodes.map(|k| points[k]));
    let mut out: Vec<_> = by_edge
        .iter()
        .filter(|(_, f)| f.len() != 2 || dot(n(f[0]), n(f[1])) < 0.866)
        .map(|(e, f)| (*e, f.clone()))
        .collect();
    out.sort_unstable_by_key(|(e, _)| *e);
    out
}

/// The edges of a group of faces that bound it: those that belong to one face of the group.
pub fn outline(group: &[[usize; 3]]) -> Vec<(usize, usize)> {
    let mut count: HashMap<(usize, usize), usize> = HashMap::new();
    for f in group {
        for k in 0..3 {
            *count.entry(edge(f[k], f[(k + 1) % 3])).or_default() += 1;
        }
    }
    let mut out: Vec<_> = count
        .into_iter()
        .filter(|(_, c)| *c == 1)
        .map(|(e, _)| e)
        .collect();
    out.sort_unstable();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The unit cube cut into 6 tetrahedra around its diagonal 0–6 (nodes numbered
    /// x + 2y + 4z, as bits: node 6 = (0, 1, 1)… with 7 = (1, 1, 1)).
    fn cube() -> (Vec<[f64; 3]>, Vec<[usize; 4]>) {
        let points: Vec<[f64; 3]> = (0..8)
            .map(|i| [(i & 1) as f64, ((i >> 1) & 1) as f64, ((i >> 2) & 1) as f64])
            .collect();
        let tets = vec![
            [0, 1, 3, 7],
            [0, 3, 2, 7],
            [0, 2, 6, 7],
            [0, 6, 4, 7],
            [0, 4, 5, 7],
            [0, 5, 1, 7],
        ];
        (points, tets)
    }

    fn centroid(points: &[[f64; 3]], f: &Face) -> [f64; 3] {
        [0, 1, 2].map(|k| f.nodes.iter().map(|&n| points[n][k]).sum::<f64>() / 3.0)
    }

    #[test]
    fn the_cube_has_twelve_outward_boundary_faces() {
        let (points, tets) = cube();
        let faces = boundary_faces(&points, &tets);
        assert_eq!(faces.len(), 12);
        for f in &faces {
            let c = centroid(&points, f);
            let n = normal(f.nodes.map(|k| points[k]));
            // Outward: from the cube's centre through the face.
            assert!(dot(n, sub(c, [0.5; 3])) > 0.0, "{f:?} points inward");
            // On a face of the cube: one coordinate of the centroid is 0 or 1.
            assert!(c.iter().any(|&x| x == 0.0 || x == 1.0), "{f:?} is inside");
        }
        // The six interior faces (each shared by two tetrahedra) are not listed.
        let by_edge = edge_faces(&faces);
        assert!(by_edge.values().all(|f| f.len() == 2));
        // The 12 edges of the box are the feature edges; the 6 face diagonals are not.
        let features = feature_edges(&points, &faces, &by_edge);
        assert_eq!(features.len(), 12);
        for ((a, b), _) in features {
            let d = sub(points[a], points[b]);
            assert_eq!(d.iter().filter(|x| **x != 0.0).count(), 1, "{a}–{b}");
        }
    }

    #[test]
    fn the_camera_culls_back_faces_and_orders_far_to_near() {
        let (points, tets) = cube();
        let faces = boundary_faces(&points, &tets);
        // From +x: the two triangles of the face x = 1 only.
        let cam = Camera::new([3.0, 0.0, 0.0]).unwrap();
        let seen = painter_order(&cam, &points, &faces);
        assert_eq!(seen.len(), 2);
        assert!(seen
            .iter()
            .all(|(i, _)| centroid(&points, &faces[*i])[0] == 1.0));
        // From (1, −1, −1): the faces x = 1, y = 0, z = 0; far to near.
        let cam = Camera::new([1.0, -1.0, -1.0]).unwrap();
        let seen = painter_order(&cam, &points, &faces);
        assert_eq!(seen.len(), 6);
        let depths: Vec<f64> = seen
            .iter()
            .map(|(i, _)| cam.depth(centroid(&points, &faces[*i])))
            .collect();
        assert!(depths.windows(2).all(|d| d[0] <= d[1]), "{depths:?}");
        // z up: the screen's up is the projection of +z; right-handed screen.
        let (top, bottom) = (cam.project([0.0, 0.0, 1.0]), cam.project([0.0; 3]));
        assert!(top.1 > bottom.1 && (top.0 - bottom.0).abs() < 1e-12);
        // Shading: faces of three directions get three brightness factors in [0.6, 1].
        let mut shades: Vec<f64> = seen.iter().map(|s| s.1).collect();
        shades.sort_by(f64::total_cmp);
        shades.dedup_by(|a, b| (*a - *b).abs() < 1e-12);
        assert_eq!(shades.len(), 3, "{shades:?}");
        assert!(shades.iter().all(|s| (0.6..=1.0).contains(s)));
        // Looking straight down still has a screen basis; a zero view has none.
        assert!(Camera::new([0.0, 0.0, 2.0]).is_some());
        assert!(Camera::new([0.0; 3]).is_none());
        assert!(Camera::new([f64::NAN, 1.0, 0.0]).is_none());
    }

    #[test]
    fn the_outline_of_a_group_is_its_boundary() {
        // Two triangles of a square: the diagonal 0–3 is inside, the 4 sides bound it.
        let out = outline(&[[0, 1, 3], [0, 3, 2]]);
        assert_eq!(out, vec![(0, 1), (0, 2), (1, 3), (2, 3)]);
    }
}
