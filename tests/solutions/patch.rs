//! Constant-strain patch tests on an unstructured mesh (tests/data/patch_square.msh, 110
//! triangles, Γ1 = {x = 0}, Γ2 = the other three edges).
//!
//! For the linear field v = (p x, q x) (zero on Γ1) and each tensor C of the scheme (A of
//! (4.1), B of (4.2) in plane stress and plane strain, R = I), K_C v must equal the load
//! vector of the boundary traction σ n with σ = C ε(v), at every free dof: interior rows
//! vanish exactly and boundary rows carry the traction integral. And the scheme's first step
//! (u_0 = 0, so only A acts) reproduces w_0 = v exactly from that traction.

use crate::common;
use common::*;
use viscontact::fem::{mul_add, Isotropic, Sparse, StressCells};

const P: f64 = 0.7;
const Q: f64 = -0.4;

/// The traction σ n on the three edges of Γ2 for σ = C ε(v), as expressions of x, y.
fn traction(c: Isotropic) -> [String; 2] {
    let e = [P, 0.0, 0.0, 0.5 * Q, 0.0, 0.0];
    let s = c.apply(e);
    let (s11, s22, s12) = (s[0], s[1], s[3]);
    // bottom y = 0: n = (0, −1); right x = 1: n = (1, 0); top y = 1: n = (0, 1).
    [
        format!("if(y < 1e-9, {}, if(x > 1 - 1e-9, {s11}, {s12}))", -s12),
        format!("if(y < 1e-9, {}, if(x > 1 - 1e-9, {s12}, {s22}))", -s22),
    ]
}

fn scene(dir: &std::path::Path, model: &str, t: &[String; 2]) -> std::path::PathBuf {
    SceneText::on(repo().join("tests/data/patch_square.msh"))
        .set("mesh.model", model)
        .set("time.end", 0.01)
        .set("time.steps", 1)
        .set("material.viscosity.theta", 0.3)
        .set("material.viscosity.zeta", 0.2)
        .set("material.elasticity.young", 2.0)
        .set("material.elasticity.poisson", 0.3)
        .literal("material.relaxation.prony", "[[1.0, 1.0]]")
        .traction(None, &[&t[0], &t[1]])
        .write(dir, "patch.toml")
}

/// The free-dof vector of the linear field (p x, q x).
fn linear(disc: &viscontact::fem::Discretization, p: f64, q: f64) -> Vec<f64> {
    let mut v = vec![0.0; disc.n_free];
    for (i, x) in disc.nodes.all().iter().enumerate() {
        for (comp, val) in [(0, p * x[0]), (1, q * x[0])] {
            if let Some(d) = disc.free.get(2 * i + comp) {
                v[d] = val;
            }
        }
    }
    v
}

fn check(model: &str, pick: impl Fn(&viscontact::fem::Discretization) -> (Isotropic, &Sparse)) {
    let dir = tempfile::tempdir().unwrap();
    // First load with any traction to learn the tensor, then with the matching traction.
    let (_, _, d0) = load(&scene(dir.path(), model, &["0".into(), "0".into()]), &[]);
    let (c, _) = pick(&d0);
    let (s, _, disc) = load(&scene(dir.path(), model, &traction(c)), &[]);
    let (_, k) = pick(&disc);
    let v = linear(&disc, P, Q);
    let mut kv = vec![0.0; disc.n_free];
    mul_add(k, &v, 1.0, &mut kv);
    let mut f = vec![0.0; disc.n_free];
    disc.loads
        .add(0.0, (&disc.free, &disc.frames), &s, (&mut f, None))
        .unwrap();
    let d = rel_diff(&kv, &f);
    assert!(d < 1e-13, "{model}: |K v − f| / |f| = {d:e}");
    // Interior rows vanish (not just the total): at least half the rows are interior here.
    let interior = f.iter().filter(|x| **x == 0.0).count();
    assert!(interior > disc.n_free / 2);
}

#[test]
fn viscosity_patch_test() {
    check("plane_stress", |d| (d.materials.of(0).a, &d.k_a));
}

#[test]
fn elasticity_patch_test_plane_stress() {
    check("plane_stress", |d| {
        (d.materials.of(0).b.unwrap(), d.k_b.as_ref().unwrap())
    });
}

#[test]
fn elasticity_patch_test_plane_strain() {
    check("plane_strain", |d| {
        (d.materials.of(0).b.unwrap(), d.k_b.as_ref().unwrap())
    });
}

#[test]
fn relaxation_patch_test() {
    check("plane_stress", |d| (d.r, &d.k_r[0]));
}

/// The frame's stress of linear w, u, m is A ε(w) + B ε(u) + ε(m) in every cell (σ_zz = 0 in
/// plane stress, b_A tr ε(w) + b_B tr ε(u) + 0 in plane strain), and von Mises follows.
#[test]
fn stress_of_linear_fields_is_exact_in_every_cell() {
    let dir = tempfile::tempdir().unwrap();
    for model in ["plane_stress", "plane_strain"] {
        let (_, _, disc) = load(&scene(dir.path(), model, &["0".into(), "0".into()]), &[]);
        let fields = [(P, Q), (-0.3, 0.9), (0.25, 0.5)];
        let [w, u, m] = fields.map(|(p, q)| linear(&disc, p, q));
        let tensors = [
            disc.materials.of(0).a,
            disc.materials.of(0).b.unwrap(),
            disc.r,
        ];
        let mut want = [0.0; 6];
        for (c, (p, q)) in tensors.iter().zip(fields) {
            for (x, y) in want
                .iter_mut()
                .zip(c.apply([p, 0.0, 0.0, 0.5 * q, 0.0, 0.0]))
            {
                *x += y;
            }
        }
        if model == "plane_stress" {
            want[2] = 0.0;
        }
        let [xx, yy, zz, xy, ..] = want;
        let vm = (0.5 * ((xx - yy).powi(2) + (yy - zz).powi(2) + (zz - xx).powi(2))
            + 3.0 * xy * xy)
            .sqrt();
        let model = match model {
            "plane_stress" => viscontact::scene::Model::PlaneStress,
            _ => viscontact::scene::Model::PlaneStrain,
        };
        let (stress, von_mises) =
            disc.stress([&w, &u], (Some(&m), [None; 2]), model, StressCells::All);
        assert_eq!(von_mises.len(), disc.cells.len());
        for (c, (s, v)) in stress.chunks(6).zip(&von_mises).enumerate() {
            for (k, (x, y)) in s.iter().zip(&want).enumerate() {
                assert!(
                    (x - y).abs() < 1e-13,
                    "{model:?} cell {c} component {k}: {x} vs {y}"
                );
            }
            assert!(
                (v - vm).abs() < 1e-13,
                "{model:?} cell {c}: von Mises {v} vs {vm}"
            );
        }
    }
}

#[test]
fn first_step_reproduces_a_linear_velocity_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let (_, _, d0) = load(
        &scene(dir.path(), "plane_stress", &["0".into(), "0".into()]),
        &[],
    );
    let (s, _, disc) = load(
        &scene(dir.path(), "plane_stress", &traction(d0.materials.of(0).a)),
        &[],
    );
    let tr = trace(&s, &disc);
    let w = disc.nodal(&tr.w[0]);
    let scale = P.abs().max(Q.abs());
    for (i, p) in disc.nodes.all().iter().enumerate() {
        let err = (w[3 * i] - P * p[0])
            .abs()
            .max((w[3 * i + 1] - Q * p[0]).abs());
        assert!(err < 1e-12 * scale, "node {i} at {p:?}: {err:e}");
    }
}

#[test]
fn printed_tensors_match_the_paper() {
    // (4.1): (Aτ)_ij = 2θ τ_ij + ζ tr τ δ_ij; (4.2): (Bτ)_ij = E/(1+κ) τ_ij + Eκ/(1−κ²) tr τ δ_ij.
    let (theta, zeta, e, k) = (0.1, 0.1, 0.1, 0.3);
    let tau = [0.3, -0.2, 0.0, 0.05, 0.0, 0.0];
    let a = Isotropic::viscosity(theta, zeta).apply(tau);
    let b = Isotropic::plane_stress(e, k).apply(tau);
    let tr = tau[0] + tau[1];
    for i in 0..2 {
        assert!((a[i] - (2.0 * theta * tau[i] + zeta * tr)).abs() < 1e-16);
        assert!((b[i] - (e / (1.0 + k) * tau[i] + e * k / (1.0 - k * k) * tr)).abs() < 1e-16);
    }
    assert!((a[3] - 2.0 * theta * tau[3]).abs() < 1e-16);
    assert!((b[3] - e / (1.0 + k) * tau[3]).abs() < 1e-16);
}
