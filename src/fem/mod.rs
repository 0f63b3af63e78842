//! Discretization: P1 triangles, the dofs of V^h (w = 0 on Γ1 eliminated), the stiffness
//! matrices K_A, K_B, K_R, the load vector ⟨f_n, ·⟩, the given-normal-stress load g_F and the
//! nodal constraint rows on Γ3,1 (n_i·w_i ≤ 0) and Γ3,2 (weight c_i of |w_τ,i|).

pub mod element;
pub mod loads;

use crate::expr::Point;
use crate::mesh::{Group, Mesh};
use crate::scene::{Model, Scene};
use crate::{Error, Result};
pub use element::{Isotropic, Triangle};
use faer::sparse::{SparseColMat, Triplet};
pub use loads::Loads;

/// Sparse symmetric matrix (both triangles stored), columns compressed.
pub type Sparse = SparseColMat<usize, f64>;

/// y += alpha · A x for a matrix in free-dof numbering.
pub fn mul_add(a: &Sparse, x: &[f64], alpha: f64, y: &mut [f64]) {
    let a = a.as_ref();
    let (cp, ri, v) = (a.symbolic().col_ptr(), a.symbolic().row_idx(), a.val());
    for j in 0..a.ncols() {
        let xj = alpha * x[j];
        if xj != 0.0 {
            for p in cp[j]..cp[j + 1] {
                y[ri[p]] += v[p] * xj;
            }
        }
    }
}

/// One nodal row of the constraint operator P: the functional w ↦ dir·w_i at a node.
/// `dim` components are used (2 in 2D, 3 in 3D); unused entries are 0.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NodalRow {
    pub node: usize,
    /// Free indices of the node's x, y (and z) dofs.
    pub dofs: [usize; 3],
    /// n_i on Γ3,1 (constraint n_i·w_i ≤ 0); a unit tangent τ_i on Γ3,2 (in 3D each friction
    /// node has two rows, τ_i1 and τ_i2, spanning its tangent plane: w_τ,i = Σ_k (τ_ik·w_i) τ_ik).
    pub dir: [f64; 3],
    /// The number of components: the spatial dimension.
    pub dim: usize,
    /// Γ3,2: c_i = ∫ μF φ_i da, the bound of the friction multiplier. Γ3,1: +∞.
    pub bound: f64,
    /// ∫ φ_i da over the group: turns the nodal multiplier into a traction.
    pub area: f64,
}

impl NodalRow {
    /// The (free dof, coefficient) pairs of the row.
    pub fn entries(&self) -> impl Iterator<Item = (usize, f64)> + '_ {
        self.dofs[..self.dim]
            .iter()
            .copied()
            .zip(self.dir[..self.dim].iter().copied())
    }

    pub fn apply(&self, w: &[f64]) -> f64 {
        self.entries().map(|(d, c)| c * w[d]).sum()
    }

    /// w += z · Pᵀ_row.
    pub fn add_transpose(&self, z: f64, w: &mut [f64]) {
        for (d, c) in self.entries() {
            w[d] += z * c;
        }
    }
}

/// Everything the time loop needs from space: matrices, loads, boundary operators.
pub struct Discretization {
    /// Spatial dimension d (2 or 3): d dofs per node.
    pub dim: usize,
    pub nodes: Vec<[f64; 3]>,
    pub triangles: Vec<Triangle>,
    /// Global dof 2·node + component → free index; None on Γ1 (w = 0 there).
    pub free: Vec<Option<usize>>,
    pub n_free: usize,
    /// A (4.1), B (4.2) (None when E = 0 or disabled), R's constant part I.
    pub a: Isotropic,
    pub b: Option<Isotropic>,
    pub r: Isotropic,
    /// K_A, K_B, K_R in free numbering.
    pub k_a: Sparse,
    pub k_b: Option<Sparse>,
    pub k_r: Sparse,
    pub loads: Loads,
    /// g_F_i = ∫_{Γ3,2} F φ_i ν da (free numbering); empty when F = 0 or no friction group.
    pub g_f: Vec<f64>,
    /// Rows n_i on Γ3,1 (empty when contact is off).
    pub contact: Vec<NodalRow>,
    /// Rows τ_i with c_i > 0 on Γ3,2 (empty when friction is off or μF = 0).
    pub friction: Vec<NodalRow>,
    /// The largest kink (degrees) between facet normals at a node of Γ3,1 or Γ3,2.
    pub contact_kink_deg: f64,
}

fn group<'m>(mesh: &'m Mesh, scene: &Scene, key: &str, value: &str) -> Result<&'m Group> {
    mesh.boundary_group(value)
        .map_err(|e| Error::input(format!("{}: key '{key}': {e}", scene.path.display())))
}

impl Discretization {
    pub fn new(mesh: &Mesh, scene: &Scene) -> Result<Self> {
        let nn = mesh.nodes.len();
        let fixed = group(mesh, scene, "mesh.groups.fixed", &scene.groups.fixed)?;
        let mut clamped = vec![false; nn];
        for n in mesh.group_nodes(fixed) {
            clamped[n] = true;
        }
        let mut free = vec![None; 2 * nn];
        let mut n_free = 0;
        for (i, c) in clamped.iter().enumerate() {
            if !c {
                free[2 * i] = Some(n_free);
                free[2 * i + 1] = Some(n_free + 1);
                n_free += 2;
            }
        }
        if n_free == 0 {
            return Err(Error::input(format!(
                "{}: every node of '{}' is on the clamped group '{}'; nothing can move",
                scene.path.display(),
                mesh.path.display(),
                scene.groups.fixed
            )));
        }
        let xy = |i: usize| [mesh.nodes[i][0], mesh.nodes[i][1]];
        let triangles: Vec<Triangle> = mesh
            .triangles
            .iter()
            .map(|t| Triangle::new(*t, [xy(t[0]), xy(t[1]), xy(t[2])]))
            .collect();

        let a = Isotropic::viscosity(scene.theta, scene.zeta);
        let b = scene
            .elasticity
            .filter(|(e, _)| *e > 0.0)
            .map(|(e, nu)| match scene.model {
                Model::PlaneStress => Isotropic::plane_stress(e, nu),
                Model::PlaneStrain => Isotropic::plane_strain(e, nu),
            });
        let r = Isotropic::identity();
        let (k_a, k_b, k_r) = assemble(&triangles, &free, n_free, a, b, r)?;

        let loads = Loads::new(mesh, scene, &triangles)?;

        // Γ3,1: one row n_i per free node (Γ1 wins over every other part).
        let mut contact = Vec::new();
        let mut kink: f64 = 0.0;
        if scene.contact {
            let g = group(mesh, scene, "mesh.groups.contact", &scene.groups.contact)?;
            let (normals, k) = mesh.nodal_normals(g);
            kink = kink.max(k);
            let area = lumped_area(mesh, g);
            for (node, n) in normals {
                if let (Some(dx), Some(dy)) = (free[2 * node], free[2 * node + 1]) {
                    contact.push(NodalRow {
                        node,
                        dofs: [dx, dy, 0],
                        dir: [n[0], n[1], 0.0],
                        dim: 2,
                        bound: f64::INFINITY,
                        area: area[node],
                    });
                }
            }
        }
        // Γ3,2: g_F and the friction rows τ_i with c_i = ∫ μF φ_i da (2-point Gauss per edge).
        let mut g_f = Vec::new();
        let mut friction = Vec::new();
        if let Some(fr) = &scene.friction {
            let g = group(mesh, scene, "mesh.groups.friction", &scene.groups.friction)?;
            let mut gf = vec![0.0; n_free];
            let mut c = vec![0.0; nn];
            for &f in &g.facets {
                let n = mesh.facet_normal(f);
                for (p, w, phi) in loads::edge_gauss(mesh, f) {
                    let pt = Point {
                        x: p[0],
                        y: p[1],
                        ..Default::default()
                    };
                    let big_f = fr.normal_stress.eval(&pt);
                    let mu = fr.coefficient.eval(&pt);
                    check_data(big_f, "friction.normal_stress", scene, p, true)?;
                    check_data(mu, "friction.coefficient", scene, p, true)?;
                    for (node, ph) in f.iter().zip(phi) {
                        for comp in 0..2 {
                            if let Some(d) = free[2 * node + comp] {
                                gf[d] += w * ph * big_f * n[comp];
                            }
                        }
                        c[*node] += w * ph * mu * big_f;
                    }
                }
            }
            if gf.iter().any(|&v| v != 0.0) {
                g_f = gf;
            }
            let (normals, k) = mesh.nodal_normals(g);
            kink = kink.max(k);
            let area = lumped_area(mesh, g);
            for (node, n) in normals {
                if let (Some(dx), Some(dy)) = (free[2 * node], free[2 * node + 1]) {
                    // μF may vanish on parts of Γ3,2: rows with c_i = 0 carry no friction.
                    if c[node] > 0.0 {
                        friction.push(NodalRow {
                            node,
                            dofs: [dx, dy, 0],
                            dir: [-n[1], n[0], 0.0],
                            dim: 2,
                            bound: c[node],
                            area: area[node],
                        });
                    }
                }
            }
        }

        Ok(Discretization {
            dim: mesh.dim,
            nodes: mesh.nodes.clone(),
            triangles,
            free,
            n_free,
            a,
            b,
            r,
            k_a,
            k_b,
            k_r,
            loads,
            g_f,
            contact,
            friction,
            contact_kink_deg: kink,
        })
    }

    /// Expands a free-dof vector to 3-component nodal vectors (0 on Γ1, z = 0).
    pub fn nodal(&self, v: &[f64]) -> Vec<f64> {
        let nn = self.nodes.len();
        let mut out = vec![0.0; 3 * nn];
        for i in 0..nn {
            for c in 0..2 {
                if let Some(d) = self.free[2 * i + c] {
                    out[3 * i + c] = v[d];
                }
            }
        }
        out
    }

    fn local(&self, t: &Triangle, v: &[f64]) -> [[f64; 2]; 3] {
        let mut out = [[0.0; 2]; 3];
        for (o, &n) in out.iter_mut().zip(&t.nodes) {
            for (c, oc) in o.iter_mut().enumerate() {
                if let Some(d) = self.free[2 * n + c] {
                    *oc = v[d];
                }
            }
        }
        out
    }

    /// Per-cell stress σ_n = A ε(w_n) + B ε(u_n) + ε(m_n) (2.1 discretized; R = r·I, so the
    /// memory term is ε of m_n = kΣ r(t_n − t_j) u_j) as 6 components XX YY ZZ XY YZ XZ, and
    /// the von Mises stress. Plane stress has σ_zz = 0; plane strain σ_zz = b_A tr ε(w) +
    /// b_B tr ε(u) (the out-of-plane strain is zero).
    pub fn stress(
        &self,
        w: &[f64],
        u: &[f64],
        m: Option<&[f64]>,
        model: Model,
    ) -> (Vec<f64>, Vec<f64>) {
        let mut s6 = Vec::with_capacity(6 * self.triangles.len());
        let mut vm = Vec::with_capacity(self.triangles.len());
        for t in &self.triangles {
            let ew = t.strain(self.local(t, w));
            let eu = t.strain(self.local(t, u));
            let mut s = self.a.apply(ew);
            let mut szz = 0.0;
            if model == Model::PlaneStrain {
                szz += self.a.b * (ew[0] + ew[1]);
            }
            if let Some(b) = self.b {
                let sb = b.apply(eu);
                for c in 0..3 {
                    s[c] += sb[c];
                }
                if model == Model::PlaneStrain {
                    szz += b.b * (eu[0] + eu[1]);
                }
            }
            if let Some(m) = m {
                let sm = self.r.apply(t.strain(self.local(t, m)));
                for c in 0..3 {
                    s[c] += sm[c];
                }
            }
            s6.extend_from_slice(&[s[0], s[1], szz, s[2], 0.0, 0.0]);
            let (dx, dy, dz) = (s[0] - s[1], s[1] - szz, szz - s[0]);
            vm.push((0.5 * (dx * dx + dy * dy + dz * dz) + 3.0 * s[2] * s[2]).sqrt());
        }
        (s6, vm)
    }

    /// K_A + k K_B + k² r(0) K_R: the step matrix of the implicit variant (the three share
    /// one sparsity pattern, so this adds their value arrays).
    pub fn implicit_matrix(&self, k: f64, r0: Option<f64>) -> Sparse {
        let mut m = self.k_a.clone();
        let mut add = |other: &Sparse, c: f64| {
            debug_assert_eq!(other.symbolic().row_idx(), m.symbolic().row_idx());
            for (v, o) in m.val_mut().iter_mut().zip(other.val()) {
                *v += c * o;
            }
        };
        if let Some(k_b) = &self.k_b {
            add(k_b, k);
        }
        if let Some(r0) = r0 {
            add(&self.k_r, k * k * r0);
        }
        m
    }

    /// ‖v‖_{L²(Ω)} and |v|_{H¹(Ω)} of a P1 field (free-dof vector), computed exactly.
    pub fn norms(&self, v: &[f64]) -> (f64, f64) {
        p1_norms(&self.triangles, &nodal2(self, v))
    }
}

/// The 2 in-plane components at every node of a free-dof vector (0 on Γ1).
pub fn nodal2(disc: &Discretization, v: &[f64]) -> Vec<[f64; 2]> {
    (0..disc.nodes.len())
        .map(|i| {
            let c = |k: usize| disc.free[2 * i + k].map_or(0.0, |d| v[d]);
            [c(0), c(1)]
        })
        .collect()
}

/// ‖v‖_{L²} and |v|_{H¹} of a P1 vector field given by its nodal values, computed exactly:
/// per triangle ∫(Σ v_i φ_i)² = |T|/12 (Σ v_i² + (Σ v_i)²) and the constant gradient.
pub fn p1_norms(triangles: &[Triangle], v: &[[f64; 2]]) -> (f64, f64) {
    let (mut l2, mut h1) = (0.0, 0.0);
    for t in triangles {
        let lv = t.nodes.map(|n| v[n]);
        for c in 0..2 {
            let s: f64 = lv.iter().map(|x| x[c]).sum();
            let q: f64 = lv.iter().map(|x| x[c] * x[c]).sum();
            l2 += t.area / 12.0 * (q + s * s);
            let gx: f64 = (0..3).map(|k| t.grad[k][0] * lv[k][c]).sum();
            let gy: f64 = (0..3).map(|k| t.grad[k][1] * lv[k][c]).sum();
            h1 += t.area * (gx * gx + gy * gy);
        }
    }
    (l2.sqrt(), h1.sqrt())
}

/// ∫_g φ_i da for every node (zero off the group).
fn lumped_area(mesh: &Mesh, g: &Group) -> Vec<f64> {
    let mut area = vec![0.0; mesh.nodes.len()];
    for &f in &g.facets {
        let half = 0.5 * mesh.facet_length(f);
        area[f[0]] += half;
        area[f[1]] += half;
    }
    area
}

/// Refuses NaN/∞ (and negative values where `nonnegative`) in data evaluated on the mesh.
pub(crate) fn check_data(
    v: f64,
    key: &str,
    scene: &Scene,
    p: [f64; 2],
    nonnegative: bool,
) -> Result<()> {
    if !v.is_finite() || (nonnegative && v < 0.0) {
        return Err(Error::input(format!(
            "{}: key '{key}' evaluates to {v} at (x, y) = ({}, {}); it must be finite{}",
            scene.path.display(),
            p[0],
            p[1],
            if nonnegative { " and ≥ 0" } else { "" }
        )));
    }
    Ok(())
}

/// Assembles K_A, K_B, K_R over all triangles in free-dof numbering (Γ1 rows and columns
/// dropped); the three share one sparsity pattern.
fn assemble(
    triangles: &[Triangle],
    free: &[Option<usize>],
    n: usize,
    a: Isotropic,
    b: Option<Isotropic>,
    r: Isotropic,
) -> Result<(Sparse, Option<Sparse>, Sparse)> {
    let cap = 36 * triangles.len();
    let (mut ta, mut tb, mut tr) = (
        Vec::with_capacity(cap),
        Vec::with_capacity(if b.is_some() { cap } else { 0 }),
        Vec::with_capacity(cap),
    );
    for t in triangles {
        let ka = t.stiffness(a);
        let kb = b.map(|b| t.stiffness(b));
        let kr = t.stiffness(r);
        let dof = |l: usize| free[2 * t.nodes[l / 2] + l % 2];
        for i in 0..6 {
            let Some(gi) = dof(i) else { continue };
            for j in 0..6 {
                let Some(gj) = dof(j) else { continue };
                ta.push(Triplet::new(gi, gj, ka[i][j]));
                if let Some(kb) = &kb {
                    tb.push(Triplet::new(gi, gj, kb[i][j]));
                }
                tr.push(Triplet::new(gi, gj, kr[i][j]));
            }
        }
    }
    let build = |t: &[Triplet<usize, usize, f64>]| {
        SparseColMat::try_new_from_triplets(n, n, t)
            .map_err(|e| Error::solve(format!("sparse assembly failed: {e:?}")))
    };
    Ok((
        build(&ta)?,
        if b.is_some() { Some(build(&tb)?) } else { None },
        build(&tr)?,
    ))
}
