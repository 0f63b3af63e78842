//! The P1 triangle: basis gradients, area, and the element matrix of a tensor of the
//! isotropic form C τ = 2a τ + b tr(τ) I. Viscosity A (4.1), elasticity B (4.2) and the
//! relaxation tensor's constant part R = I all have this form.

/// A tensor C τ = 2a τ + b tr(τ) I on symmetric 2×2 tensors.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Isotropic {
    pub a: f64,
    pub b: f64,
}

impl Isotropic {
    /// (4.1): (Aτ)_ij = 2θ τ_ij + ζ (τ_11 + τ_22) δ_ij.
    pub fn viscosity(theta: f64, zeta: f64) -> Self {
        Isotropic { a: theta, b: zeta }
    }

    /// (4.2), plane stress as printed: (Bτ)_ij = E/(1+κ) τ_ij + Eκ/(1−κ²) (τ_11 + τ_22) δ_ij.
    pub fn plane_stress(young: f64, poisson: f64) -> Self {
        Isotropic {
            a: young / (2.0 * (1.0 + poisson)),
            b: young * poisson / (1.0 - poisson * poisson),
        }
    }

    /// Plane strain: the 3D Lamé coefficients, λ = Eν/((1+ν)(1−2ν)), μ = E/(2(1+ν)).
    pub fn plane_strain(young: f64, poisson: f64) -> Self {
        Isotropic {
            a: young / (2.0 * (1.0 + poisson)),
            b: young * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson)),
        }
    }

    /// The identity on symmetric tensors: R(s) = r(s)·I has C = I.
    pub fn identity() -> Self {
        Isotropic { a: 0.5, b: 0.0 }
    }

    /// σ = C ε for ε = [ε11, ε22, ε12]; returns [σ11, σ22, σ12].
    pub fn apply(&self, e: [f64; 3]) -> [f64; 3] {
        let tr = e[0] + e[1];
        [
            2.0 * self.a * e[0] + self.b * tr,
            2.0 * self.a * e[1] + self.b * tr,
            2.0 * self.a * e[2],
        ]
    }
}

/// Geometry of one P1 triangle: its nodes, area and the constant gradients of its three
/// barycentric basis functions.
#[derive(Clone, Copy, Debug)]
pub struct Triangle {
    pub nodes: [usize; 3],
    pub area: f64,
    pub grad: [[f64; 2]; 3],
}

impl Triangle {
    pub fn new(nodes: [usize; 3], p: [[f64; 2]; 3]) -> Self {
        let [p0, p1, p2] = p;
        let det = (p1[0] - p0[0]) * (p2[1] - p0[1]) - (p2[0] - p0[0]) * (p1[1] - p0[1]);
        // ∇φ_i = rot(p_{i+2} − p_{i+1}) / det, the standard P1 formula.
        let grad = [
            [(p1[1] - p2[1]) / det, (p2[0] - p1[0]) / det],
            [(p2[1] - p0[1]) / det, (p0[0] - p2[0]) / det],
            [(p0[1] - p1[1]) / det, (p1[0] - p0[0]) / det],
        ];
        Triangle {
            nodes,
            area: 0.5 * det,
            grad,
        }
    }

    /// ε(v) = [ε11, ε22, ε12] of a P1 field given by its nodal values on this triangle.
    pub fn strain(&self, v: [[f64; 2]; 3]) -> [f64; 3] {
        let mut e = [0.0; 3];
        for (g, vi) in self.grad.iter().zip(v) {
            e[0] += g[0] * vi[0];
            e[1] += g[1] * vi[1];
            e[2] += 0.5 * (g[1] * vi[0] + g[0] * vi[1]);
        }
        e
    }

    /// The 6×6 element matrix (C ε(φ_i e_α), ε(φ_j e_β)) over the triangle, dofs ordered
    /// (node 0 x, node 0 y, node 1 x, …):
    /// K = |T| [a (δ_αβ ∇φ_i·∇φ_j + ∂_β φ_i ∂_α φ_j) + b ∂_α φ_i ∂_β φ_j].
    pub fn stiffness(&self, c: Isotropic) -> [[f64; 6]; 6] {
        let mut k = [[0.0; 6]; 6];
        for i in 0..3 {
            for j in 0..3 {
                let gi = self.grad[i];
                let gj = self.grad[j];
                let dot = gi[0] * gj[0] + gi[1] * gj[1];
                for al in 0..2 {
                    for be in 0..2 {
                        let delta = if al == be { dot } else { 0.0 };
                        k[2 * i + al][2 * j + be] =
                            self.area * (c.a * (delta + gi[be] * gj[al]) + c.b * gi[al] * gj[be]);
                    }
                }
            }
        }
        k
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn energy(k: &[[f64; 6]; 6], v: &[f64; 6]) -> f64 {
        (0..6)
            .map(|i| (0..6).map(|j| v[i] * k[i][j] * v[j]).sum::<f64>())
            .sum()
    }

    #[test]
    fn rigid_motions_have_zero_energy() {
        let p = [[0.1, 0.2], [1.3, 0.1], [0.4, 0.9]];
        let t = Triangle::new([0, 1, 2], p);
        let c = Isotropic::plane_stress(2.0, 0.3);
        let k = t.stiffness(c);
        let scale = k.iter().flatten().map(|x| x.abs()).fold(0.0, f64::max);
        // Two translations and the infinitesimal rotation (−y, x).
        let motions = [
            [1.0, 0.0, 1.0, 0.0, 1.0, 0.0],
            [0.0, 1.0, 0.0, 1.0, 0.0, 1.0],
            [-p[0][1], p[0][0], -p[1][1], p[1][0], -p[2][1], p[2][0]],
        ];
        for m in motions {
            assert!(energy(&k, &m).abs() < 1e-14 * scale, "{}", energy(&k, &m));
        }
        // A stretch does have energy.
        let stretch = [p[0][0], 0.0, p[1][0], 0.0, p[2][0], 0.0];
        assert!(energy(&k, &stretch) > 1e-3 * scale);
    }

    #[test]
    fn stiffness_matches_strain_energy_density() {
        // For a linear field v, vᵀKv = |T| Cε:ε with ε the constant strain.
        let t = Triangle::new([0, 1, 2], [[0.0, 0.0], [2.0, 0.5], [0.3, 1.1]]);
        let c = Isotropic::viscosity(0.1, 0.1);
        let pts = [[0.0, 0.0], [2.0, 0.5], [0.3, 1.1]];
        let f = |p: [f64; 2]| [0.3 * p[0] - 0.2 * p[1], 0.7 * p[0] + 0.1 * p[1]];
        let v3 = [f(pts[0]), f(pts[1]), f(pts[2])];
        let e = t.strain(v3);
        assert!((e[0] - 0.3).abs() < 1e-14 && (e[1] - 0.1).abs() < 1e-14);
        assert!((e[2] - 0.25).abs() < 1e-14);
        let s = c.apply(e);
        let density = s[0] * e[0] + s[1] * e[1] + 2.0 * s[2] * e[2];
        let v = [v3[0][0], v3[0][1], v3[1][0], v3[1][1], v3[2][0], v3[2][1]];
        assert!((energy(&t.stiffness(c), &v) - t.area * density).abs() < 1e-14);
    }
}
