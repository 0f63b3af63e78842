//! Dirichlet conditions (issue 51): prescribed displacements reproduce an affine motion
//! exactly, and a symmetry plane makes a half model of a symmetric body.

use crate::common;
use common::*;
use toml::Value;

/// g(x, t), an affine field in x for every t (no traction, no body force: it solves the
/// continuous problem, its stress being constant in space).
const G: [&str; 2] = [
    "0.01*t*(x + 2*y) + 0.003*t*t",
    "-0.02*t*x + 0.005*y*t*t - 0.001*t",
];

fn g(x: [f64; 3], t: f64) -> [f64; 2] {
    [
        0.01 * t * (x[0] + 2.0 * x[1]) + 0.003 * t * t,
        -0.02 * t * x[0] + 0.005 * x[1] * t * t - 0.001 * t,
    ]
}

/// The whole boundary of the unstructured square prescribed at g (no clamped group): every
/// node, the interior ones too, ends at g(x, T) to round-off, with memory and elasticity,
/// in the paper's scheme and in its implicit variant.
#[test]
fn a_prescribed_affine_motion_is_reproduced_exactly() {
    let dir = tempfile::tempdir().unwrap();
    for history in ["left", "implicit"] {
        let path = SceneText::on(repo().join("tests/data/patch_square.msh"))
            .set("mesh.groups.fixed", Value::Array(vec![]))
            .set("time.end", 0.5)
            .set("time.steps", 5)
            .set("scheme.history", history)
            .set("material.viscosity.theta", 0.3)
            .set("material.viscosity.zeta", 0.2)
            .set("material.elasticity.young", 2.0)
            .set("material.elasticity.poisson", 0.3)
            .literal("material.relaxation.prony", "[[1.0, 1.0]]")
            .dirichlet("Γ1", &["x", "y"], Some(&G))
            .dirichlet("Γ2", &["x", "y"], Some(&G))
            .write(dir.path(), "affine.toml");
        let (scene, _, disc) = load(&path, &[]);
        assert_eq!(disc.n_dofs - disc.n_free, disc.prescribed.len());
        assert!(disc.n_free > 0 && !disc.prescribed.is_empty());
        let tr = trace(&scene, &disc);
        let t_end = scene.time.end;
        let u = viscontact::fem::nodal_vectors::<2>(&disc, &tr.u_final);
        let want: Vec<f64> = disc.nodes.iter().flat_map(|&x| g(x, t_end)).collect();
        let got: Vec<f64> = u.into_iter().flatten().collect();
        let d = rel_diff(&got, &want);
        assert!(
            d < 1e-12,
            "{history}: max |u_N − g(T)| / max |g(T)| = {d:e}"
        );
    }
}

/// The half block with a symmetry plane (u·n = 0 on y = 0.5) and the whole block, meshed as
/// the half and its mirror image, agree on the half: contact on Γ3,1 (which meets the
/// plane) and friction on Γ3,2 on, the paper's loads and memory.
#[test]
fn a_half_model_with_a_symmetry_plane_agrees_with_the_whole() {
    let dir = tempfile::tempdir().unwrap();
    let data = repo().join("tests/data/symmetry");
    let base = || SceneText::block().set("time.steps", 16);
    let whole = base()
        .mesh(data.join("whole_block.msh"))
        .write(dir.path(), "whole.toml");
    let half = base()
        .mesh(data.join("half_block.msh"))
        .dirichlet("sym", &["normal"], None)
        .write(dir.path(), "half.toml");
    let (sw, _, dw) = load(&whole, &[]);
    let (sh, _, dh) = load(&half, &[]);
    let (tw, th) = (trace(&sw, &dw), trace(&sh, &dh));
    for t in [&tw, &th] {
        assert!(t.effects.contains(&"contact") && t.effects.contains(&"friction"));
    }
    // Contact is active somewhere, and some friction node slides or sticks with γ ≠ 0.
    let last = th.z.last().unwrap();
    let n_contact = dh.contact.len();
    assert!(last[..n_contact].iter().any(|&z| z != 0.0));
    assert!(last[n_contact..].iter().any(|&z| z != 0.0));
    let uw = viscontact::fem::nodal_vectors::<3>(&dw, &tw.u_final);
    let uh = viscontact::fem::nodal_vectors::<3>(&dh, &th.u_final);
    // The whole mesh's first nodes are the half's, in the same order (mirror.py).
    for (a, b) in dh.nodes.iter().zip(&dw.nodes) {
        assert_eq!(a, b);
    }
    let got: Vec<f64> = uh.iter().flatten().copied().collect();
    let want: Vec<f64> = uw[..uh.len()].iter().flatten().copied().collect();
    let d = rel_diff(&got, &want);
    assert!(d <= 1e-10, "half against whole: {d:e}");
    // The plane's nodes do not move across it.
    for (x, u) in dh.nodes.iter().zip(&uh) {
        if (x[1] - 0.5).abs() < 1e-12 {
            assert_eq!(u[1], 0.0);
        }
    }
}
