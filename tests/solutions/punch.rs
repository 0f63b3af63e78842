//! A displacement-driven punch agrees with the same loading applied as the equivalent
//! traction (issue 51): where the discrete equations give both, prescribing the top's
//! displacement and prescribing the traction it needs make the same run.
//!
//! # The body and its exact discrete solution
//!
//! The paper's rectangle Ω = (0, L) × (0, H), L = 2, H = 1 (meshes/paper/rect_008.msh),
//! plane stress, Aτ = 2θτ + ζ tr(τ) I, Bτ = E/(1+ν) τ + Eν/(1−ν²) tr(τ) I, no relaxation
//! kernel. Rollers hold u_x = 0 on the left side and u_y = 0 on the bottom; the right side
//! x = L is Γ3,1, unilateral contact with a rigid wall (w_x ≤ 0 there); the top is pressed
//! down. (The foundation cannot be the bottom here: the traction-driven run needs a
//! Dirichlet condition to hold the translation along y, and holding y at a node of a
//! bottom Γ3,1 is refused, so the bottom is a roller and the wall carries the contact.)
//!
//! The scheme's unknown is the velocity: u_n = u_0 + k Σ_{j<n} w_j with u_0 = 0, and step
//! n = 0, …, N solves (Aε(w_n) + Bε(u_n), ε(v − w_n)) ≥ ⟨f_n, v − w_n⟩ for all v ∈ K^h, with
//! f_n the traction at t_n. The homogeneous field
//!
//!   w_n = (0, −δ y/H),   u_n = (0, −δ t_n y/H),   ε(w_n) = diag(0, −δ/H),  ε(u_n) = t_n ε(w_n)
//!
//! (P1 holds it exactly) has the constant stress σ_n = Aε(w_n) + Bε(u_n), σ_xy = 0,
//!
//!   σ_yy,n = −(δ/H) [2θ + ζ + E/(1−ν²) t_n],    σ_xx,n = −(δ/H) [ζ + Eν/(1−ν²) t_n].
//!
//! A constant stress makes every row of the step's equations the boundary term ∫ σν·φ_i:
//! zero in the interior and at the rollers' free dofs (σ_xy = 0), the contact multiplier
//! λ_i = −σ_xx,n ∫φ_i ≥ 0 on the wall, where w_x = 0 keeps the constraint active
//! (σ_xx,n < 0 as ζ, δ > 0), and σ_yy,n ∫_top φ_i at the top's y dofs. With K_A symmetric
//! positive definite on the dofs the rollers leave, the step problem has one solution, so
//! this field is the discrete solution of both runs:
//!
//! - displacement-driven, u_y = g(t) = −δ t on the top: the loop sets the velocity there to
//!   w_{n,y} = (g(t_{n+1}) − u_{n,y}) / k = −δ, and the top's reaction is σ_yy,n ∫_top φ_i,
//!   in all L σ_yy,n;
//! - traction-driven, f(t) = (0, s(t)) on the top with s(t_n) = σ_yy,n:
//!   s(t) = −(δ/H) [2θ + ζ + E/(1−ν²) t], affine in t and written as an expression of t;
//!   its resultant is L s(t_n).
//!
//! In the implicit variant the elastic term acts on u_{n+1} = u_n + k w_n, so σ_yy,n and
//! σ_xx,n have t_{n+1} for t_n and the traction is s(t + k). The runs differ by round-off
//! only (t_n = nk against the sum of the steps, the contact solve's residual): their fields
//! agree to 1e-10 relative at every step, the top's reaction in the first equals the
//! traction's resultant in the second and L σ_yy,n, and the wall's contact force is H σ_xx,n
//! in both.

use crate::common;
use common::*;
use std::path::Path;
use toml::Value;

/// δ (the top's speed), θ, ζ, E, ν; the rectangle's L and H; T and N.
const DELTA: f64 = 0.01;
const THETA: f64 = 0.3;
const ZETA: f64 = 0.2;
const YOUNG: f64 = 2.0;
const NU: f64 = 0.3;
const L: f64 = 2.0;
const H: f64 = 1.0;
const STEPS: usize = 10;
const K: f64 = 1.0 / STEPS as f64;

/// The rollers, the wall and the material, without the top's loading, in the scheme
/// `history` ("left" or "implicit").
fn confined_bar(history: &str) -> SceneText {
    SceneText::on(mesh_path("paper/rect_008.msh"))
        .set("mesh.model", "plane_stress")
        .set("mesh.groups.fixed", Value::Array(vec![]))
        .set("mesh.groups.traction", "top")
        .set("mesh.groups.contact", "right")
        .set("time.end", 1.0)
        .set("time.steps", STEPS as i64)
        .set("scheme.history", history)
        .set("material.viscosity.theta", THETA)
        .set("material.viscosity.zeta", ZETA)
        .set("material.elasticity.young", YOUNG)
        .set("material.elasticity.poisson", NU)
        .section("contact")
        .dirichlet("Γ1", &["x"], None)
        .dirichlet("Γ3,1", &["y"], None)
        .dirichlet("Γ3,2", &["y"], None)
}

/// t at which the elastic term is evaluated in step n's equations: t_n, or t_{n+1} in the
/// implicit variant.
fn elastic_time(n: usize, history: &str) -> f64 {
    let n = if history == "implicit" { n + 1 } else { n };
    n as f64 * K
}

/// σ_yy,n and σ_xx,n of the exact discrete solution.
fn stress(n: usize, history: &str) -> (f64, f64) {
    let t = elastic_time(n, history);
    let c = YOUNG / (1.0 - NU * NU);
    let yy = -(DELTA / H) * (2.0 * THETA + ZETA + c * t);
    let xx = -(DELTA / H) * (ZETA + NU * c * t);
    (yy, xx)
}

/// Step by step: the nodal displacements (the library's loop) and history.csv (a run);
/// the largest `rel_diff` of u_n against the exact field (0, −δ t_n y/H) over the steps.
struct Run {
    u: Vec<Vec<f64>>,
    history: History,
    active: Vec<f64>,
    off_exact: f64,
}

fn run(dir: &Path, scene: &SceneText, name: &str) -> Run {
    let path = scene.write(dir, &format!("{name}.toml"));
    let (scene, _, disc) = load(&path, &[]);
    let tr = trace(&scene, &disc);
    assert!(tr.effects.contains(&"contact"), "{name}: {:?}", tr.effects);
    let u: Vec<Vec<f64>> = (tr.u.iter())
        .map(|u| {
            let nodal = viscontact::fem::nodal_vectors::<2>(&disc, u);
            nodal.into_iter().flatten().collect()
        })
        .collect();
    let off_exact = u.iter().enumerate().fold(0.0f64, |m, (n, u)| {
        let t = n as f64 * K;
        let exact: Vec<f64> = (disc.nodes.all().iter())
            .flat_map(|x| [0.0, -DELTA * t * x[1] / H])
            .collect();
        m.max(rel_diff(u, &exact))
    });
    let out = dir.join(name);
    finished(viscontact::run::run(&path, &run_options(&out, &[], None)).unwrap());
    let history = History::read(&out);
    let active = history.column("active");
    assert_eq!(history.rows.len(), STEPS + 1, "{name}");
    Run {
        u,
        history,
        active,
        off_exact,
    }
}

/// |a − b| / |b|.
fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

#[test]
fn a_displacement_driven_punch_agrees_with_the_equivalent_traction() {
    let dir = tempfile::tempdir().unwrap();
    for history in ["left", "implicit"] {
        let shift = if history == "implicit" { K } else { 0.0 };
        let s = format!("-{DELTA}/{H}*(2*{THETA} + {ZETA} + {YOUNG}/(1 - {NU}^2)*(t + {shift}))");
        let pressed =
            confined_bar(history).dirichlet("top", &["y"], Some(&[&format!("-{DELTA}*t")]));
        let pushed = confined_bar(history).traction(Some("top"), &["0", s.as_str()]);
        let a = run(dir.path(), &pressed, &format!("pressed_{history}"));
        let b = run(dir.path(), &pushed, &format!("pushed_{history}"));
        let (mut fields, mut forces, mut exact) = (0.0f64, 0.0f64, 0.0f64);
        for n in 0..=STEPS {
            let d = rel_diff(&a.u[n], &b.u[n]);
            assert!(d <= 1e-10, "{history}, step {n}: fields differ by {d:e}");
            fields = fields.max(d);
            let (yy, xx) = stress(n, history);
            let reaction = a.history.column("reaction_top_y")[n];
            let load = b.history.column("load_top_y")[n];
            forces = forces.max(rel(reaction, load));
            exact = exact.max(rel(reaction, L * yy)).max(rel(load, L * yy));
            for h in [&a.history, &b.history] {
                exact = exact.max(rel(h.column("contact_x")[n], H * xx));
            }
            assert!(
                a.active[n] > 0.0 && a.active[n] == b.active[n],
                "{history}, step {n}"
            );
        }
        let off = a.off_exact.max(b.off_exact);
        eprintln!(
            "{history}: fields {fields:e}, against the exact field {off:e}, reaction against \
             load {forces:e}, forces against the closed form {exact:e}"
        );
        assert!(
            off <= 1e-10,
            "{history}: fields against the exact field {off:e}"
        );
        assert!(
            forces <= 1e-10,
            "{history}: reaction against load {forces:e}"
        );
        assert!(
            exact <= 1e-10,
            "{history}: forces against the closed form {exact:e}"
        );
    }
}
