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
use crate::uniaxial_bar::{scalar_recursion, scalar_recursion_with, END, STEPS};
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

/// The largest relative error of the bar's u and w against the closed form of its two
/// parts, `soft` for x < 1 and `stiff` beyond ((ε_n, ε'_n) of each, `scalar_recursion`),
/// asserted ≤ 1e-10 at every step and node.
fn closed_form_error(
    scene: &SceneText,
    dir: &std::path::Path,
    soft: &[(f64, f64)],
    stiff: &[(f64, f64)],
) -> f64 {
    let (scene, _mesh, disc) = load(&scene.write(dir, "bar.toml"), &[]);
    let tr = trace(&scene, &disc);
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
        for (i, p) in disc.nodes.all().iter().enumerate() {
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
    worst
}

/// The region entry of STIFF's viscosity and elasticity, with `more` TOML lines.
fn stiff_region(more: &str) -> toml::Table {
    let body = format!(
        "viscosity = {{ theta = {} }}\nelasticity = {{ young = {} }}\n{more}",
        STIFF.0, STIFF.1
    );
    region("stiff", &body)
}

#[test]
fn a_bimaterial_bar_in_tension_follows_its_closed_form() {
    let dir = tempfile::tempdir().unwrap();
    let scene = bar().push("material.region", stiff_region(""));
    let (soft, stiff) = (scalar_recursion(SOFT), scalar_recursion(STIFF));
    let worst = closed_form_error(&scene, dir.path(), &soft, &stiff);
    // The two parts really differ: the soft one strains more than twice the stiff one.
    assert!(soft[STEPS].0 > 2.0 * stiff[STEPS].0, "{soft:?} {stiff:?}");
    println!("bimaterial bar: worst relative error {worst:e} over {STEPS} steps");
}

#[test]
fn each_region_relaxes_with_its_own_kernel() {
    let dir = tempfile::tempdir().unwrap();
    // The stiff part relaxes with r₂(s) = 1.5 e^{−2s} + 0.4 e^{−s/4}: as a Prony series, and
    // as an expression compressed to one (the default); the soft part keeps [material]'s r.
    let r2 = |s: f64| 1.5 * (-2.0 * s).exp() + 0.4 * (-0.25 * s).exp();
    let (soft, stiff) = (scalar_recursion(SOFT), scalar_recursion_with(STIFF, &r2));
    for (name, table) in [
        ("prony", "prony = [[1.5, 2.0], [0.4, 0.25]]"),
        ("compressed", "expr = \"1.5*exp(-2*s) + 0.4*exp(-s/4)\""),
    ] {
        let own = format!("[relaxation]\n{table}");
        let scene = bar().push("material.region", stiff_region(&own));
        let worst = closed_form_error(&scene, dir.path(), &soft, &stiff);
        println!("bar with the stiff part's own kernel ({name}): worst relative error {worst:e}");
    }
    // The same kernel without the region's: the stiff part's response is not this one.
    let same = scalar_recursion(STIFF);
    assert!((same[STEPS].0 - stiff[STEPS].0).abs() > 1e-3 * stiff[STEPS].0.abs());
    // A region without relaxation: the soft part runs r = 0, the stiff part [material]'s r.
    let off = bar().push(
        "material.region",
        region("soft", "relaxation = { enabled = false }"),
    );
    let off = off.push("material.region", stiff_region(""));
    let soft = scalar_recursion_with(SOFT, &|_| 0.0);
    let worst = closed_form_error(&off, dir.path(), &soft, &scalar_recursion(STIFF));
    println!("bar with the soft part without relaxation: worst relative error {worst:e}");
}

#[test]
fn a_region_that_repeats_the_body_s_kernel_gives_its_result() {
    // Its own memory group with the same kernel: K_R^(0) m + K_R^(1) m instead of K_R m, the
    // same to round-off (not to the bit: the sums are grouped differently).
    let dir = tempfile::tempdir().unwrap();
    let plain = u_final(&bar(), dir.path(), "plain.toml");
    let own = region("stiff", "relaxation = { prony = [[0.7, 3.0], [0.2, 0.5]] }");
    let split = u_final(&bar().push("material.region", own), dir.path(), "own.toml");
    let diff = plain.iter().zip(&split).map(|(a, b)| (a - b).abs());
    let rel = diff.fold(0.0, f64::max) / max_abs(&plain);
    assert!(rel <= 1e-13, "relative difference {rel:e}");
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
