//! The uniaxial bar: with ν = ζ = 0, Γ1 clamped, a uniform traction f(t) on the right end and
//! no contact, u = (ε(t)·x, 0) exactly, and P1 elements reproduce it. So the FEM run must
//! equal the scheme applied to the scalar model,
//!
//!   2θ ε'_n + E ε_n + k Σ_{j<n} r(t_n − t_j) ε_j = f(t_n),   ε_{n+1} = ε_n + k ε'_n,
//!
//! at every step, for a Prony kernel (O(1) recursion) and for the same kernel given as an
//! expression (direct sum).

use crate::common;
use common::*;

const THETA: f64 = 0.1;
const E: f64 = 0.5;
pub(crate) const STEPS: usize = 40;
pub(crate) const END: f64 = 2.0;

fn f(t: f64) -> f64 {
    0.01 + 0.02 * t + 0.01 * (3.0 * t).sin()
}

fn r(s: f64) -> f64 {
    0.7 * (-3.0 * s).exp() + 0.2 * (-0.5 * s).exp()
}

/// The scheme on the scalar model of a material (θ, E): (ε_n, ε'_n) for n = 0..=N.
pub(crate) fn scalar_recursion(material: (f64, f64)) -> Vec<(f64, f64)> {
    scalar_recursion_with(material, &r)
}

/// [`scalar_recursion`] with the kernel `r`.
pub(crate) fn scalar_recursion_with(
    (theta, young): (f64, f64),
    r: &dyn Fn(f64) -> f64,
) -> Vec<(f64, f64)> {
    let k = END / STEPS as f64;
    let mut eps: Vec<f64> = vec![0.0];
    let mut out = Vec::new();
    for n in 0..=STEPS {
        let t = n as f64 * k;
        let mem: f64 = (0..n).map(|j| k * r((n - j) as f64 * k) * eps[j]).sum();
        let rate = (f(t) - young * eps[n] - mem) / (2.0 * theta);
        out.push((eps[n], rate));
        eps.push(eps[n] + k * rate);
    }
    out
}

/// The bar on `mesh` (clamped on Γ1, f(t) on the group "right", no contact) with the
/// relaxation section `relaxation`.
fn bar_scene(dir: &std::path::Path, mesh: &str, relaxation: &str) -> std::path::PathBuf {
    SceneText::on(mesh)
        .set("name", "bar")
        .set("time.end", END)
        .set("time.steps", STEPS as i64)
        .set("material.viscosity.theta", THETA)
        .set("material.viscosity.zeta", 0.0)
        .set("material.elasticity.young", E)
        .set("material.elasticity.poisson", 0.0)
        .table("material.relaxation", relaxation)
        .traction(Some("right"), &["0.01 + 0.02*t + 0.01*sin(3*t)", "0"])
        .write(dir, "bar.toml")
}

fn check_bar(mesh: &str, relaxation: &str) -> f64 {
    let dir = tempfile::tempdir().unwrap();
    let scene = bar_scene(dir.path(), mesh, relaxation);
    let (scene, _mesh, disc) = load(&scene, &[]);
    let tr = trace(&scene, &disc);
    assert_eq!(tr.solver, viscontact::solver::StepSolver::Linear.name());
    let exact = scalar_recursion((THETA, E));
    let mut worst: f64 = 0.0;
    for (n, (eps, rate)) in exact.iter().enumerate() {
        let u = disc.nodal(&tr.u[n]);
        let w = disc.nodal(&tr.w[n]);
        let xmax = disc.nodes.all().iter().fold(0.0f64, |a, p| a.max(p[0]));
        for (i, p) in disc.nodes.all().iter().enumerate() {
            for (field, val, scale) in [(&u, eps, eps.abs()), (&w, rate, rate.abs())] {
                let err_x = (field[3 * i] - val * p[0]).abs();
                let err_y = field[3 * i + 1].abs();
                let rel = err_x.max(err_y) / (scale * xmax).max(f64::MIN_POSITIVE);
                if n > 0 || scale > 0.0 {
                    worst = worst.max(rel);
                    assert!(
                        rel <= 1e-10,
                        "step {n}, node {i} at {p:?}: relative error {rel:e}"
                    );
                }
            }
        }
    }
    worst
}

#[test]
fn bar_equals_scalar_recursion_prony() {
    let worst = check_bar(
        &mesh_path("paper/rect_008.msh"),
        "prony = [[0.7, 3.0], [0.2, 0.5]]",
    );
    println!("prony kernel: worst relative error {worst:e}");
}

#[test]
fn bar_equals_scalar_recursion_expression() {
    let worst = check_bar(
        &mesh_path("paper/rect_008.msh"),
        "expr = \"0.7*exp(-3*s) + 0.2*exp(-0.5*s)\"\nmemory = \"exact\"",
    );
    println!("expression kernel: worst relative error {worst:e}");
}

#[test]
fn bar_on_unstructured_mesh_of_a_plate_with_a_hole_is_not_exact() {
    // A sanity check that the comparison above can fail: on the plate with a hole the
    // solution is not uniaxial, so the same comparison must find a large error.
    let dir = tempfile::tempdir().unwrap();
    let scene = bar_scene(
        dir.path(),
        &mesh_path("plate_hole/plate_hole.msh"),
        "prony = [[0.7, 3.0], [0.2, 0.5]]",
    );
    let (scene, _mesh, disc) = load(&scene, &[]);
    let tr = trace(&scene, &disc);
    let (eps, _) = scalar_recursion((THETA, E))[STEPS];
    let u = disc.nodal(&tr.u[STEPS]);
    let worst = disc
        .nodes
        .all()
        .iter()
        .enumerate()
        .map(|(i, p)| (u[3 * i] - eps * p[0]).abs() / (eps * 2.0))
        .fold(0.0f64, f64::max);
    assert!(worst > 1e-3, "{worst}");
}

/// The reaction of the clamped end of the bar is the applied traction's resultant,
/// −f(t_n)·1 along x (the right end x = 2 has height 1) and nothing along y, at every step
/// of history.csv.
#[test]
fn the_clamped_end_s_reaction_is_the_applied_traction_s_resultant() {
    let dir = tempfile::tempdir().unwrap();
    let scene = bar_scene(
        dir.path(),
        &mesh_path("paper/rect_008.msh"),
        "prony = [[0.7, 3.0], [0.2, 0.5]]",
    );
    let out = dir.path().join("out");
    finished(viscontact::run::run(&scene, &run_options(&out, &[], None)).unwrap());
    let h = History::read(&out);
    assert_eq!(h.rows.len(), STEPS + 1);
    let (t, rx, ry) = (
        h.column("t"),
        h.column("reaction_Γ1_x"),
        h.column("reaction_Γ1_y"),
    );
    for n in 0..=STEPS {
        let f = f(t[n]);
        assert!(
            (rx[n] + f).abs() <= 1e-12 * f,
            "step {n}: reaction {} against −f = {}",
            rx[n],
            -f
        );
        assert!(ry[n].abs() <= 1e-12 * f, "step {n}: y reaction {}", ry[n]);
    }
    let load = h.column("load_right_x")[STEPS];
    assert!((load - f(END)).abs() <= 1e-14 * f(END), "{load}");
}
