//! Several materials in one body (`[[material.region]]`, issue 51).
//!
//! The bimaterial bar: tests/data/bimaterial_bar.msh, (0,2) × (0,1) of two materials
//! bonded along x = 1, clamped at x = 0 with a uniform traction f(t) on x = 2, ν = ζ = 0 and
//! no contact. The stress is uniaxial and the same f(t) in both parts, so each part's strain
//! follows the scheme on its own scalar model,
//!
//!   2θ_i ε'_n + E_i ε_n + k Σ_{j<n} r(t_n − t_j) ε_j = f(t_n),   ε_{n+1} = ε_n + k ε'_n,
//!
//! and u = (ε_1 x, 0) for x ≤ 1, (ε_1 + ε_2 (x − 1), 0) for x ≥ 1: piecewise linear with
//! its kink on element edges, which P1 elements reproduce. The FEM run must equal it at
//! every step to round-off.

use crate::common;
use crate::uniaxial_bar::{scalar_recursion, END, STEPS};
use common::*;

/// (θ, E) of `[material]` (the part x < 1, in no region) and of the region "stiff".
const SOFT: (f64, f64) = (0.1, 0.5);
const STIFF: (f64, f64) = (0.3, 2.0);

fn bar_mesh() -> String {
    repo()
        .join("tests/data/bimaterial_bar.msh")
        .display()
        .to_string()
}

/// The bar with `[material]` = SOFT (ν = ζ = 0) and the Prony kernel r.
fn bar() -> SceneText {
    SceneText::on(bar_mesh())
        .set("name", "bimaterial")
        .set("time.end", END)
        .set("time.steps", STEPS as i64)
        .set("material.viscosity.theta", SOFT.0)
        .set("material.elasticity.young", SOFT.1)
        .table("material.relaxation", "prony = [[0.7, 3.0], [0.2, 0.5]]")
        .traction(Some("right"), &["0.01 + 0.02*t + 0.01*sin(3*t)", "0"])
}

/// A `[[material.region]]` entry on `on` with the tables written in TOML as `body`.
fn region(on: &str, body: &str) -> toml::Table {
    let mut t: toml::Table = toml::from_str(body).unwrap();
    t.insert("on".into(), on.into());
    t
}

/// u_N of `scene` run through the library.
fn u_final(scene: &SceneText, dir: &std::path::Path, name: &str) -> Vec<f64> {
    let (scene, _mesh, disc) = load(&scene.write(dir, name), &[]);
    trace(&scene, &disc).u_final
}

#[test]
fn a_bimaterial_bar_in_tension_follows_its_closed_form() {
    let dir = tempfile::tempdir().unwrap();
    let stiff = format!(
        "viscosity = {{ theta = {} }}\nelasticity = {{ young = {} }}",
        STIFF.0, STIFF.1
    );
    let scene = bar().push("material.region", region("stiff", &stiff));
    let (scene, _mesh, disc) = load(&scene.write(dir.path(), "bar.toml"), &[]);
    assert_eq!(disc.materials.distinct.len(), 2);
    let tr = trace(&scene, &disc);
    let (soft, stiff) = (scalar_recursion(SOFT), scalar_recursion(STIFF));
    // The exact u_x (or w_x) at x from the two strains (or rates).
    let exact = |x: f64, e1: f64, e2: f64| match x <= 1.0 {
        true => e1 * x,
        false => e1 + e2 * (x - 1.0),
    };
    let mut worst: f64 = 0.0;
    for n in 1..=STEPS {
        let (u, w) = (disc.nodal(&tr.u[n]), disc.nodal(&tr.w[n]));
        let ((e1, r1), (e2, r2)) = (soft[n], stiff[n]);
        let (u_scale, w_scale) = (exact(2.0, e1, e2).abs(), exact(2.0, r1, r2).abs());
        for (i, p) in disc.nodes.iter().enumerate() {
            for (field, want, scale) in [
                (&u, exact(p[0], e1, e2), u_scale),
                (&w, exact(p[0], r1, r2), w_scale),
            ] {
                let err = (field[3 * i] - want).abs().max(field[3 * i + 1].abs());
                let rel = err / scale;
                worst = worst.max(rel);
                assert!(
                    rel <= 1e-10,
                    "step {n}, node {i} at {p:?}: relative error {rel:e}"
                );
            }
        }
    }
    // The two parts really differ: the soft one strains more than twice the stiff one.
    assert!(soft[STEPS].0 > 2.0 * stiff[STEPS].0, "{soft:?} {stiff:?}");
    println!("bimaterial bar: worst relative error {worst:e} over {STEPS} steps");
}

#[test]
fn regions_that_repeat_the_material_give_the_bits_of_the_body_without_them() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // The bar: one region repeats [material]'s viscosity, the other its elasticity.
    let plain = u_final(&bar(), d, "plain.toml");
    let same = bar()
        .push(
            "material.region",
            region("soft", "viscosity = { theta = 0.1 }"),
        )
        .push(
            "material.region",
            region("stiff", "elasticity = { young = 0.5 }"),
        );
    let regions = u_final(&same, d, "regions.toml");
    assert!(max_abs(&plain) > 0.0);
    assert_eq!(
        plain.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        regions.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        "u_N of the bar with regions of [material]'s material"
    );
    // The paper's scene (contact, friction, ζ > 0, ν > 0) with its whole domain a region
    // that repeats every table of [material].
    let paper = paper("paper/rect_008.msh", false).set("time.steps", 8);
    let whole = paper.clone().push(
        "material.region",
        region(
            "Ω",
            "viscosity = { theta = 0.1, zeta = 0.1 }\n\
             elasticity = { young = 0.1, poisson = 0.3 }",
        ),
    );
    let (a, b) = (u_final(&paper, d, "p.toml"), u_final(&whole, d, "w.toml"));
    assert!(max_abs(&a) > 0.0);
    assert_eq!(
        a.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        b.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        "u_N of the paper's scene with Ω a region of [material]'s material"
    );
}
