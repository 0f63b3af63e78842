//! The P1 simplex (triangle or tetrahedron): basis gradients, measure, and the element
//! matrix of a tensor of the isotropic form C τ = 2a τ + b tr(τ) I. Viscosity A (4.1),
//! elasticity B (4.2) and the relaxation tensor's constant part R = I all have this form.

use crate::mesh::{cross, dot, sub};

/// A tensor C τ = 2a τ + b tr(τ) I on symmetric tensors.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Isotropic {
    pub a: f64,
    pub b: f64,
}

impl Isotropic {
    /// (4.1): (Aτ)_ij = 2θ τ_ij + ζ tr(τ) δ_ij (the same form in 2D and 3D).
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

    /// Plane strain and 3D: the 3D Lamé coefficients, λ = Eν/((1+ν)(1−2ν)),
    /// μ = E/(2(1+ν)): (Bτ)_ij = E/(1+ν) τ_ij + λ tr(τ) δ_ij.
    pub fn lame(young: f64, poisson: f64) -> Self {
        Isotropic {
            a: young / (2.0 * (1.0 + poisson)),
            b: young * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson)),
        }
    }

    /// The identity on symmetric tensors: R(s) = r(s)·I has C = I.
    pub fn identity() -> Self {
        Isotropic { a: 0.5, b: 0.0 }
    }

    /// σ = C ε for ε = [ε11, ε22, ε33, ε12, ε23, ε13]; returns σ in the same order.
    /// (In 2D ε33 = ε23 = ε13 = 0 and σ33 = b tr ε is the plane strain out-of-plane stress.)
    pub fn apply(&self, e: [f64; 6]) -> [f64; 6] {
        let tr = e[0] + e[1] + e[2];
        let mut s = e.map(|x| 2.0 * self.a * x);
        for sk in &mut s[..3] {
            *sk += self.b * tr;
        }
        s
    }
}

/// Symmetric-tensor component pairs in the order of [`Isotropic::apply`].
const PAIRS: [(usize, usize); 6] = [(0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2)];

/// The largest element matrix: a tetrahedron's 12×12.
pub type ElementMatrix = [[f64; 12]; 12];

/// Geometry of one P1 simplex (a triangle in 2D, a tetrahedron in 3D): its nodes, measure
/// (area or volume) and the constant gradients of its barycentric basis functions.
#[derive(Clone, Copy, Debug)]
pub struct Cell {
    /// The dim + 1 vertices; entry 3 is unused for triangles.
    pub nodes: [usize; 4],
    /// Area (2D) or volume (3D).
    pub measure: f64,
    /// ∇φ_i; the z entries are 0 and entry 3 unused for triangles.
    pub grad: [[f64; 3]; 4],
    /// 2 or 3.
    pub dim: usize,
}

impl Cell {
    pub fn triangle(nodes: [usize; 3], p: [[f64; 2]; 3]) -> Self {
        let [p0, p1, p2] = p;
        let det = (p1[0] - p0[0]) * (p2[1] - p0[1]) - (p2[0] - p0[0]) * (p1[1] - p0[1]);
        // ∇φ_i = rot(p_{i+2} − p_{i+1}) / det, the standard P1 formula.
        let grad = [
            [(p1[1] - p2[1]) / det, (p2[0] - p1[0]) / det, 0.0],
            [(p2[1] - p0[1]) / det, (p0[0] - p2[0]) / det, 0.0],
            [(p0[1] - p1[1]) / det, (p1[0] - p0[0]) / det, 0.0],
            [0.0; 3],
        ];
        Cell {
            nodes: [nodes[0], nodes[1], nodes[2], nodes[2]],
            measure: 0.5 * det,
            grad,
            dim: 2,
        }
    }

    /// A positively oriented tetrahedron: ∇φ_i = (face opposite i's inward normal) · area /
    /// (3V), i.e. ∇φ_0 = (p2 − p1) × (p3 − p1) / 6V with the signs of the vertex cycle.
    pub fn tetrahedron(nodes: [usize; 4], p: [[f64; 3]; 4]) -> Self {
        let (e1, e2, e3) = (sub(p[1], p[0]), sub(p[2], p[0]), sub(p[3], p[0]));
        // Rows of the inverse Jacobian: ∇λ_1 = (e2 × e3)/det, ∇λ_2 = (e3 × e1)/det,
        // ∇λ_3 = (e1 × e2)/det, ∇λ_0 = −Σ.
        let c1 = cross(e2, e3);
        let det = dot(e1, c1);
        let g1 = c1.map(|x| x / det);
        let g2 = cross(e3, e1).map(|x| x / det);
        let g3 = cross(e1, e2).map(|x| x / det);
        let g0 = [0, 1, 2].map(|k| -(g1[k] + g2[k] + g3[k]));
        Cell {
            nodes,
            measure: det / 6.0,
            grad: [g0, g1, g2, g3],
            dim: 3,
        }
    }

    /// The dim + 1 vertices.
    pub fn vertices(&self) -> &[usize] {
        &self.nodes[..=self.dim]
    }

    /// ε(v) = [ε11, ε22, ε33, ε12, ε23, ε13] of a P1 field given by its nodal values (3
    /// components each; the z components are ignored in 2D).
    pub fn strain(&self, v: &[[f64; 3]; 4]) -> [f64; 6] {
        let mut du = [[0.0; 3]; 3]; // du[α][β] = ∂_β v_α
        for (g, vi) in self.grad.iter().zip(v).take(self.dim + 1) {
            for (a, row) in du.iter_mut().enumerate().take(self.dim) {
                for (b, d) in row.iter_mut().enumerate().take(self.dim) {
                    *d += g[b] * vi[a];
                }
            }
        }
        PAIRS.map(|(a, b)| 0.5 * (du[a][b] + du[b][a]))
    }

    /// The element matrix (C ε(φ_i e_α), ε(φ_j e_β)) over the cell, dofs ordered (node 0 x,
    /// node 0 y, [node 0 z,] node 1 x, …), size d(d+1):
    /// K = |T| [a (δ_αβ ∇φ_i·∇φ_j + ∂_β φ_i ∂_α φ_j) + b ∂_α φ_i ∂_β φ_j].
    pub fn stiffness(&self, c: Isotropic) -> ElementMatrix {
        let d = self.dim;
        let mut k = [[0.0; 12]; 12];
        for i in 0..=d {
            for j in 0..=d {
                for al in 0..d {
                    for be in 0..d {
                        k[d * i + al][d * j + be] = self.entry(c, self.parts(i, j, al, be));
                    }
                }
            }
        }
        k
    }

    /// The two factors of a, b in the entry (d i + α, d j + β) of [`Cell::stiffness`]:
    /// (δ_αβ ∇φ_i·∇φ_j + ∂_β φ_i ∂_α φ_j, ∂_α φ_i ∂_β φ_j); shared by the materials of a
    /// cell, whose entries [`Cell::entry`] then gives.
    pub fn parts(&self, i: usize, j: usize, al: usize, be: usize) -> [f64; 2] {
        let (gi, gj) = (self.grad[i], self.grad[j]);
        let delta = if al == be {
            gi[0] * gj[0] + gi[1] * gj[1] + gi[2] * gj[2]
        } else {
            0.0
        };
        [delta + gi[be] * gj[al], gi[al] * gj[be]]
    }

    /// [`Cell::parts`] where vertices have frames of their own (`constraints::Frames`): the
    /// row's dof al of vertex i is the component along axis al of `frames[0]`, the column's
    /// dof be of vertex j along axis be of `frames[1]` (None: the coordinate axes), so the
    /// factors are Σ_{a,b} (a_al)_a (a_be)_b parts(i, j, a, b); without frames, `parts`.
    pub fn parts_in(
        &self,
        [i, j]: [usize; 2],
        [al, be]: [usize; 2],
        frames: [Option<&[[f64; 3]; 3]>; 2],
    ) -> [f64; 2] {
        if frames == [None, None] {
            return self.parts(i, j, al, be);
        }
        let along = |f: Option<&[[f64; 3]; 3]>, k: usize, a: usize| match f {
            Some(axes) => axes[k][a],
            None => f64::from(u8::from(k == a)),
        };
        let mut sum = [0.0; 2];
        for a in 0..self.dim {
            for b in 0..self.dim {
                let w = along(frames[0], al, a) * along(frames[1], be, b);
                if w != 0.0 {
                    let p = self.parts(i, j, a, b);
                    sum[0] += w * p[0];
                    sum[1] += w * p[1];
                }
            }
        }
        sum
    }

    /// The stiffness entry of material c with the factors `parts` (see [`Cell::parts`]).
    pub fn entry(&self, c: Isotropic, parts: [f64; 2]) -> f64 {
        self.measure * (c.a * parts[0] + c.b * parts[1])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn energy(k: &ElementMatrix, v: &[f64]) -> f64 {
        (0..v.len())
            .map(|i| (0..v.len()).map(|j| v[i] * k[i][j] * v[j]).sum::<f64>())
            .sum()
    }

    /// Nodal values of x ↦ f(x) as a flat dof vector.
    fn dofs(p: &[[f64; 3]], d: usize, f: impl Fn([f64; 3]) -> [f64; 3]) -> Vec<f64> {
        p.iter().flat_map(|&x| f(x)[..d].to_vec()).collect()
    }

    fn cells() -> Vec<(Cell, Vec<[f64; 3]>)> {
        let tri = [[0.1, 0.2], [1.3, 0.1], [0.4, 0.9]];
        let tet = [
            [0.1, 0.2, 0.0],
            [1.3, 0.1, 0.2],
            [0.4, 0.9, 0.1],
            [0.3, 0.4, 1.1],
        ];
        vec![
            (
                Cell::triangle([0, 1, 2], tri),
                tri.iter().map(|p| [p[0], p[1], 0.0]).collect(),
            ),
            (Cell::tetrahedron([0, 1, 2, 3], tet), tet.to_vec()),
        ]
    }

    /// A displacement field x ↦ v(x).
    type Motion = fn([f64; 3]) -> [f64; 3];

    #[test]
    fn rigid_motions_have_zero_energy() {
        for (cell, p) in cells() {
            let d = cell.dim;
            let k = cell.stiffness(Isotropic::lame(2.0, 0.3));
            let scale = k.iter().flatten().map(|x| x.abs()).fold(0.0, f64::max);
            let mut motions: Vec<Vec<f64>> = (0..d)
                .map(|c| dofs(&p, d, |_| [0, 1, 2].map(|i| f64::from(i == c))))
                .collect();
            // Infinitesimal rotations ω × x about the axes the dimension has.
            let rotations: &[Motion] = match d {
                2 => &[|x| [-x[1], x[0], 0.0]],
                _ => &[
                    |x| [-x[1], x[0], 0.0],
                    |x| [0.0, -x[2], x[1]],
                    |x| [x[2], 0.0, -x[0]],
                ],
            };
            motions.extend(rotations.iter().map(|r| dofs(&p, d, r)));
            for m in &motions {
                assert!(energy(&k, m).abs() < 1e-14 * scale, "{}", energy(&k, m));
            }
            // A stretch does have energy.
            let stretch = dofs(&p, d, |x| [x[0], 0.0, 0.0]);
            assert!(energy(&k, &stretch) > 1e-3 * scale);
        }
    }

    #[test]
    fn stiffness_matches_strain_energy_density() {
        // For a linear field v, vᵀKv = |T| Cε:ε with ε the constant strain, and ε is exact.
        let g = [[0.3, -0.2, 0.5], [0.7, 0.1, -0.4], [0.2, 0.6, 0.25]];
        for (cell, p) in cells() {
            let d = cell.dim;
            let f = |x: [f64; 3]| [0, 1, 2].map(|a| (0..d).map(|b| g[a][b] * x[b]).sum::<f64>());
            let mut v4 = [[0.0; 3]; 4];
            for (vi, &x) in v4.iter_mut().zip(&p) {
                *vi = f(x);
            }
            let e = cell.strain(&v4);
            for (k, &(a, b)) in PAIRS.iter().enumerate() {
                let exact = if a < d && b < d {
                    0.5 * (g[a][b] + g[b][a])
                } else {
                    0.0
                };
                assert!(
                    (e[k] - exact).abs() < 1e-14,
                    "{d}D ε[{k}] {} vs {exact}",
                    e[k]
                );
            }
            let c = Isotropic::viscosity(0.1, 0.1);
            let s = c.apply(e);
            let density: f64 = (0..6)
                .map(|k| if k < 3 { 1.0 } else { 2.0 } * s[k] * e[k])
                .sum();
            let v = dofs(&p, d, f);
            let vkv = energy(&cell.stiffness(c), &v);
            assert!((vkv - cell.measure * density).abs() < 1e-14, "{d}D {vkv}");
        }
    }

    #[test]
    fn tetrahedron_gradients_are_the_barycentric_ones() {
        let (cell, p) = cells().pop().unwrap();
        // Σ ∇φ_i = 0 and ∇φ_i · (p_j − p_0) = δ_ij − δ_i0.
        for j in 1..4 {
            for i in 0..4 {
                let dp = [0, 1, 2].map(|k| p[j][k] - p[0][k]);
                let v: f64 = (0..3).map(|k| cell.grad[i][k] * dp[k]).sum();
                let expected = f64::from(i == j) - f64::from(i == 0);
                assert!((v - expected).abs() < 1e-14);
            }
        }
        assert!(cell.measure > 0.0);
    }
}
