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
        let path = SceneText::unclamped_square()
            .set("scheme.history", history)
            .dirichlet("Γ1", &["x", "y"], Some(&G))
            .dirichlet("Γ2", &["x", "y"], Some(&G))
            .write(dir.path(), "affine.toml");
        let (scene, _, disc) = load(&path, &[]);
        assert_eq!(disc.n_dofs - disc.n_free, disc.prescribed.len());
        assert!(disc.n_free > 0 && !disc.prescribed.is_empty());
        let tr = trace(&scene, &disc);
        let t_end = scene.time.end;
        let u = viscontact::fem::nodal_vectors::<2>(&disc, &tr.u_final);
        let want: Vec<f64> = disc.nodes.all().iter().flat_map(|&x| g(x, t_end)).collect();
        let got: Vec<f64> = u.into_iter().flatten().collect();
        let d = rel_diff(&got, &want);
        assert!(
            d < 1e-12,
            "{history}: max |u_N − g(T)| / max |g(T)| = {d:e}"
        );
    }
}

/// A symmetry plane: the nodes x with n·x = offset.
#[derive(Clone, Copy)]
struct Plane {
    normal: [f64; 3],
    offset: f64,
}

/// Runs the half and the whole scene and compares u_N on the half (whose nodes are the
/// whole mesh's first, in the same order: tests/data/symmetry/mirror.py), with contact and
/// friction engaged in the half; on the plane nothing crosses it (u·n is zero, exactly
/// where n is an axis, to round-off where the plane is inclined and u·n is the held dof of
/// the node's frame turned back). Returns the half's u_N.
fn half_agrees_with_whole(half: SceneText, whole: SceneText, plane: Plane) -> Vec<[f64; 3]> {
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
    for (a, b) in dh.nodes.all().iter().zip(dw.nodes.all()) {
        assert_eq!(a, b);
    }
    let uw = viscontact::fem::nodal_vectors::<3>(&dw, &tw.u_final);
    let uh = viscontact::fem::nodal_vectors::<3>(&dh, &th.u_final);
    let got: Vec<f64> = uh.iter().flatten().copied().collect();
    let want: Vec<f64> = uw[..uh.len()].iter().flatten().copied().collect();
    let d = rel_diff(&got, &want);
    assert!(d <= 1e-10, "half against whole: {d:e}");
    let along = |v: &[f64; 3]| (0..3).map(|c| v[c] * plane.normal[c]).sum::<f64>();
    let on_plane = dh
        .nodes
        .all()
        .iter()
        .zip(&uh)
        .filter(|(x, _)| (along(x) - plane.offset).abs() < 1e-9);
    assert!(on_plane.clone().count() > 0);
    let u_max = max_abs(&got);
    for (_, u) in on_plane {
        assert!(along(u).abs() <= 1e-14 * u_max, "u·n = {:e}", along(u));
    }
    uh
}

/// The half block with its symmetry plane y = 0.5 against the whole block (the block's
/// scene, 16 steps): the half's u_N.
fn half_block_against_whole() -> Vec<[f64; 3]> {
    let data = repo().join("tests/data/symmetry");
    let base = || SceneText::block().set("time.steps", 16);
    half_agrees_with_whole(
        base()
            .mesh(data.join("half_block.msh"))
            .dirichlet("sym", &["normal"], None),
        base().mesh(data.join("whole_block.msh")),
        Plane {
            normal: [0.0, 1.0, 0.0],
            offset: 0.5,
        },
    )
}

/// The half block with a symmetry plane (u·n = 0 on y = 0.5) and the whole block, meshed as
/// the half and its mirror image, agree on the half: contact on Γ3,1 (which meets the
/// plane) and friction on Γ3,2 on, the paper's loads and memory.
#[test]
fn a_half_model_with_a_symmetry_plane_agrees_with_the_whole() {
    half_block_against_whole();
}

/// The 2D half model's scene: the paper's, loaded by a traction symmetric about x = 0.
fn half_rect_scene() -> SceneText {
    SceneText::paper()
        .set("time.steps", 16)
        .set("load.traction", Value::Array(vec![]))
        .traction(None, &["0", "-0.1*(1-x*x)*min(t, 0.2)"])
}

/// The half rectangle with its symmetry line x = 0 against the whole one: the half's u_N.
fn half_rect_against_whole(half: SceneText) -> Vec<[f64; 3]> {
    let whole = half_rect_scene().mesh(repo().join("tests/data/symmetry/whole_rect.msh"));
    let plane = Plane {
        normal: [1.0, 0.0, 0.0],
        offset: 0.0,
    };
    half_agrees_with_whole(half, whole, plane)
}

/// The unturned 2D half model.
fn half_rect() -> SceneText {
    half_rect_scene()
        .mesh(repo().join("tests/data/symmetry/half_rect.msh"))
        .dirichlet("sym", &["normal"], None)
}

/// The same in 2D, with friction on the symmetry line: the friction node there cannot
/// slide in the half model (its tangent is the held component), as by symmetry in the whole.
#[test]
fn a_half_model_in_2d_agrees_with_the_whole_with_friction_on_the_line() {
    let (_, _, disc) = load(
        &half_rect().write(tempfile::tempdir().unwrap().path(), "h.toml"),
        &[],
    );
    assert!(disc.friction.iter().all(|r| disc.nodes[r.node][0] > 0.0));
    half_rect_against_whole(half_rect());
}

/// The 30° of tests/data/symmetry/turn.py, which turns the fixtures: (cos, sin).
fn turn() -> (f64, f64) {
    let a = std::f64::consts::PI / 6.0;
    (a.cos(), a.sin())
}

/// `got` (each node's vector) against `unturned` turned by `rotate`: to 1e-10 relative.
fn agrees_turned(got: Vec<[f64; 3]>, unturned: &[[f64; 3]], rotate: impl Fn([f64; 3]) -> [f64; 3]) {
    let want: Vec<f64> = unturned.iter().flat_map(|&v| rotate(v)).collect();
    let got: Vec<f64> = got.into_iter().flatten().collect();
    let d = rel_diff(&got, &want);
    assert!(
        d <= 1e-10,
        "turned half against the unturned one turned: {d:e}"
    );
}

/// The half block and the whole block turned by 30° about the x axis: the symmetry plane
/// (normal (0, cos, sin)), the foundation under Γ3,1 and Γ3,2 and the top are inclined, and
/// the loads turn with them. The half model holds u·n = 0 in each plane node's own frame;
/// it agrees with the turned whole block (no frames) on the half, and with the unturned
/// half model (an axis plane, no frames) turned, both to 1e-10: contact and friction on.
#[test]
fn a_half_model_with_an_inclined_symmetry_plane_agrees_with_the_whole_and_the_unturned() {
    let data = repo().join("tests/data/symmetry");
    let (c, s) = turn();
    // Turned by R about x: a point's unturned z is −s y + c z; a vector v turns to R v.
    let z0 = format!("({:?}*y + {c:?}*z)", -s);
    let top = "-0.1*x*(2-x)*min(t, 0.2)";
    let base = || {
        SceneText::block()
            .set("time.steps", 16)
            .set("load.traction", Value::Array(vec![]))
            .traction(
                Some("top"),
                &[
                    "0".into(),
                    format!("{:?}*({top})", -s),
                    format!("{c:?}*({top})"),
                ],
            )
            .traction(
                Some("right"),
                &[
                    format!("if(t <= 0.5, 0.01*(1-{z0})*t, 0.01*(1-{z0})*0.2)"),
                    "0".into(),
                    "0".into(),
                ],
            )
    };
    let half = base()
        .mesh(data.join("half_block_turned.msh"))
        .dirichlet("sym", &["normal"], None);
    let (_, _, disc) = load(
        &half.write(tempfile::tempdir().unwrap().path(), "h.toml"),
        &[],
    );
    assert!(
        !disc.frames.is_empty(),
        "the inclined plane's nodes have frames"
    );
    let plane = Plane {
        normal: [0.0, c, s],
        offset: 0.5,
    };
    let whole = base().mesh(data.join("whole_block_turned.msh"));
    let uh = half_agrees_with_whole(half, whole, plane);
    agrees_turned(uh, &half_block_against_whole(), |v| {
        [v[0], c * v[1] - s * v[2], s * v[1] + c * v[2]]
    });
}

/// The same in 2D: the rectangles turned by 30° about the origin, the symmetry line (normal
/// (cos, sin)) inclined, friction on it (the friction tangent there is the held direction,
/// so that node cannot slide).
#[test]
fn a_half_model_in_2d_with_an_inclined_symmetry_line_agrees_with_the_whole() {
    let data = repo().join("tests/data/symmetry");
    let (c, s) = turn();
    // Turned by R about the origin: a point's unturned x is c x + s y.
    let x0 = format!("({c:?}*x + {s:?}*y)");
    let g = format!("-0.1*(1-{x0}*{x0})*min(t, 0.2)");
    let base = || {
        SceneText::paper()
            .set("time.steps", 16)
            .set("load.traction", Value::Array(vec![]))
            .traction(None, &[format!("{:?}*({g})", -s), format!("{c:?}*({g})")])
    };
    let half = base()
        .mesh(data.join("half_rect_turned.msh"))
        .dirichlet("sym", &["normal"], None);
    let plane = Plane {
        normal: [c, s, 0.0],
        offset: 0.0,
    };
    let uh = half_agrees_with_whole(half, base().mesh(data.join("whole_rect_turned.msh")), plane);
    agrees_turned(uh, &half_rect_against_whole(half_rect()), |v| {
        [c * v[0] - s * v[1], s * v[0] + c * v[1], v[2]]
    });
}

/// Two inclined planes at a right angle: the turned half block's symmetry plane and its
/// top, pressed down by a prescribed normal displacement (no traction), the end x = 0 a
/// roller instead of clamped. The nodes on two or three of these hold two or three
/// directions in one frame, the top's nodes a prescribed value along an inclined axis; the
/// turned run agrees with the unturned one (axis planes, no frames) turned.
#[test]
fn two_inclined_planes_at_a_right_angle_share_a_frame() {
    let data = repo().join("tests/data/symmetry");
    let (c, s) = turn();
    let dir = tempfile::tempdir().unwrap();
    let run = |mesh: &str| {
        let scene = SceneText::block()
            .set("time.steps", 8)
            .set("load.traction", Value::Array(vec![]))
            .set("mesh.groups.fixed", Value::Array(vec![]))
            .mesh(data.join(mesh))
            .dirichlet("Γ1", &["normal"], None)
            .dirichlet("sym", &["normal"], None)
            .dirichlet("top", &["normal"], Some(&["-0.002*t"]))
            .write(dir.path(), mesh);
        let (scene, _, disc) = load(&scene, &[]);
        let t = trace(&scene, &disc);
        assert!(
            t.z.last().unwrap().iter().any(|&z| z != 0.0),
            "{mesh}: no contact"
        );
        (
            disc.frames.is_empty(),
            viscontact::fem::nodal_vectors::<3>(&disc, &t.u_final),
        )
    };
    let (no_frames, unturned) = run("half_block.msh");
    let (none, got) = run("half_block_turned.msh");
    assert!(no_frames && !none);
    agrees_turned(got, &unturned, |v| {
        [v[0], c * v[1] - s * v[2], s * v[1] + c * v[2]]
    });
}
