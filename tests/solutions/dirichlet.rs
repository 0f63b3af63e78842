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

/// Runs the half and the whole scene and compares u_N on the half (whose nodes are the
/// whole mesh's first, in the same order: tests/data/symmetry/mirror.py), with contact and
/// friction engaged in the half; on the plane (`axis` = `plane`) nothing crosses it.
fn half_agrees_with_whole(half: SceneText, whole: SceneText, axis: usize, plane: f64) {
    let dir = tempfile::tempdir().unwrap();
    let (sw, _, dw) = load(&whole.write(dir.path(), "whole.toml"), &[]);
    let (sh, _, dh) = load(&half.write(dir.path(), "half.toml"), &[]);
    let (tw, th) = (trace(&sw, &dw), trace(&sh, &dh));
    for t in [&tw, &th] {
        assert!(t.effects.contains(&"contact") && t.effects.contains(&"friction"));
    }
    let last = th.z.last().unwrap();
    let n_contact = dh.contact.len();
    assert!(last[..n_contact].iter().any(|&z| z != 0.0));
    assert!(last[n_contact..].iter().any(|&z| z != 0.0));
    for (a, b) in dh.nodes.iter().zip(&dw.nodes) {
        assert_eq!(a, b);
    }
    let uw = viscontact::fem::nodal_vectors::<3>(&dw, &tw.u_final);
    let uh = viscontact::fem::nodal_vectors::<3>(&dh, &th.u_final);
    let got: Vec<f64> = uh.iter().flatten().copied().collect();
    let want: Vec<f64> = uw[..uh.len()].iter().flatten().copied().collect();
    let d = rel_diff(&got, &want);
    assert!(d <= 1e-10, "half against whole: {d:e}");
    let on_plane = dh
        .nodes
        .iter()
        .zip(&uh)
        .filter(|(x, _)| (x[axis] - plane).abs() < 1e-12);
    assert!(on_plane.clone().count() > 0);
    for (_, u) in on_plane {
        assert_eq!(u[axis], 0.0);
    }
}

/// The half block with a symmetry plane (u·n = 0 on y = 0.5) and the whole block, meshed as
/// the half and its mirror image, agree on the half: contact on Γ3,1 (which meets the
/// plane) and friction on Γ3,2 on, the paper's loads and memory.
#[test]
fn a_half_model_with_a_symmetry_plane_agrees_with_the_whole() {
    let data = repo().join("tests/data/symmetry");
    let base = || SceneText::block().set("time.steps", 16);
    half_agrees_with_whole(
        base()
            .mesh(data.join("half_block.msh"))
            .dirichlet("sym", &["normal"], None),
        base().mesh(data.join("whole_block.msh")),
        1,
        0.5,
    );
}

/// The same in 2D, with friction on the symmetry line: the friction node there cannot
/// slide in the half model (its tangent is the held component), as by symmetry in the whole.
#[test]
fn a_half_model_in_2d_agrees_with_the_whole_with_friction_on_the_line() {
    let data = repo().join("tests/data/symmetry");
    let base = || {
        SceneText::paper()
            .set("time.steps", 16)
            .set("load.traction", Value::Array(vec![]))
            .traction(None, &["0", "-0.1*(1-x*x)*min(t, 0.2)"])
    };
    let half = base()
        .mesh(data.join("half_rect.msh"))
        .dirichlet("sym", &["normal"], None);
    let (_, _, disc) = load(
        &half.write(tempfile::tempdir().unwrap().path(), "h.toml"),
        &[],
    );
    assert!(disc.friction.iter().all(|r| disc.nodes[r.node][0] > 0.0));
    half_agrees_with_whole(half, base().mesh(data.join("whole_rect.msh")), 0, 0.0);
}
