//! Element quality measures of a triangle mesh.

/// Quality of a triangle mesh (worst values over all triangles).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quality {
    /// Smallest interior angle of any triangle, in degrees (60 for equilateral triangles).
    pub min_angle_deg: f64,
    /// Largest aspect ratio `ℓ_max / (2√3 · r)`: the longest edge over 2√3 times the
    /// inradius `r = 2·area / perimeter`. It is 1 for an equilateral triangle and grows
    /// without bound as a triangle degenerates ((1 + √2)/√3 ≈ 1.39 for a right isosceles one).
    pub max_aspect_ratio: f64,
    /// Smallest triangle area.
    pub min_area: f64,
    /// Largest triangle area.
    pub max_area: f64,
}

/// Signed area of the triangle (a, b, c): positive if counter-clockwise.
pub(crate) fn signed_area(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> f64 {
    0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    (b[0] - a[0]).hypot(b[1] - a[1])
}

/// The angle at vertex `a` of the triangle (a, b, c), in radians.
fn angle(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> f64 {
    let (ux, uy) = (b[0] - a[0], b[1] - a[1]);
    let (vx, vy) = (c[0] - a[0], c[1] - a[1]);
    (ux * vy - uy * vx).abs().atan2(ux * vx + uy * vy)
}

/// Quality of the triangles `tris` over `nodes`. An empty list gives NaN angles and ratios
/// and zero areas (a `Mesh` always has triangles).
pub(crate) fn quality(nodes: &[[f64; 3]], tris: &[[usize; 3]]) -> Quality {
    let mut q = Quality {
        min_angle_deg: f64::INFINITY,
        max_aspect_ratio: 0.0,
        min_area: f64::INFINITY,
        max_area: 0.0,
    };
    if tris.is_empty() {
        return Quality {
            min_angle_deg: f64::NAN,
            max_aspect_ratio: f64::NAN,
            min_area: 0.0,
            max_area: 0.0,
        };
    }
    for t in tris {
        let [a, b, c] = t.map(|i| nodes[i]);
        let area = signed_area(a, b, c).abs();
        let (l0, l1, l2) = (dist(b, c), dist(c, a), dist(a, b));
        let lmax = l0.max(l1).max(l2);
        let perimeter = l0 + l1 + l2;
        let ratio = lmax * perimeter / (4.0 * 3f64.sqrt() * area);
        let min_angle = angle(a, b, c).min(angle(b, c, a)).min(angle(c, a, b));
        q.min_angle_deg = q.min_angle_deg.min(min_angle.to_degrees());
        q.max_aspect_ratio = q.max_aspect_ratio.max(ratio);
        q.min_area = q.min_area.min(area);
        q.max_area = q.max_area.max(area);
    }
    q
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equilateral_and_right_triangles() {
        let h = 3f64.sqrt() / 2.0;
        let nodes = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.5, h, 0.0],
            [0.0, 1.0, 0.0],
        ];
        let q = quality(&nodes, &[[0, 1, 2]]);
        assert!((q.min_angle_deg - 60.0).abs() < 1e-12);
        assert!((q.max_aspect_ratio - 1.0).abs() < 1e-12);
        assert!((q.min_area - h / 2.0).abs() < 1e-15);
        let q = quality(&nodes, &[[0, 1, 3]]);
        assert!((q.min_angle_deg - 45.0).abs() < 1e-12);
        let expected = 2f64.sqrt() * (2.0 + 2f64.sqrt()) / (4.0 * 3f64.sqrt() * 0.5);
        assert!((q.max_aspect_ratio - expected).abs() < 1e-12);
        assert_eq!(q.max_area, 0.5);
    }
}
