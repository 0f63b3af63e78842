//! The 3D mode: tetrahedral meshes (MSH 4.1, gmsh type 4), the 3D discretization (3D Lamé
//! elasticity, tractions on triangle faces, body forces), runs, output and the command line.
//!
//! - Mesh import: every shipped tetrahedral mesh (boundary partition, outward normals,
//!   divergence theorem), the block in detail (counts, areas, normals, kinks), hand-written
//!   fixtures in tests/data/3d/ (an inverted tetrahedron is reoriented; flat tetrahedra,
//!   folds, a face shared by three tetrahedra, an interior face in a boundary group,
//!   quadratic tetrahedra and hexahedra are refused), and scenes whose model does not fit
//!   the mesh or whose vector loads lack a component.
//! - Patch tests: the element matrices and their unclamped assembly annihilate the 6 rigid
//!   motions, and the assembly reproduces the boundary load of any affine field; the
//!   library's clamped K_A, K_B, K_R reproduce the traction load of a constant stress; the
//!   load quadrature is exact for polynomial loads; whole runs reproduce the affine
//!   solutions that a body clamped on x = 0 can have (uniaxial bar with ν = 0, confined
//!   uniaxial strain and simple shear with ν ≠ 0) step by step, against the scheme applied
//!   to the scalar model.
//! - Thin slabs against the 2D plane-stress model on the same triangulation: the difference
//!   shrinks with the thickness where the 2D model is the thin limit of the 3D one (and,
//!   printed, what happens with the paper's constants, where it is not).
//! - Output: the .vtu frames of a 3D run (VTK_TETRA cells, 3-component friction traction)
//!   read back; `mesh-info` and `check` on 3D input.
//!
//! Expected values are derived here from geometry and mechanics, never copied from a run.
//! `cargo test --release --test solutions three_d:: -- --nocapture` prints the measured errors and the
//! slab differences.

use crate::common;

use std::collections::{BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::process::Command;

use common::*;
use viscontact::fem::{mul_add, nodal_vectors, p1_norms, Cell, Discretization, Isotropic};
use viscontact::mesh::Mesh;
use viscontact::Error;

const BIN: &str = env!("CARGO_BIN_EXE_viscontact");

// ---- small helpers -----------------------------------------------------------------------

type V3 = [f64; 3];

fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn norm(a: V3) -> f64 {
    dot(a, a).sqrt()
}

fn dist(a: V3, b: V3) -> f64 {
    norm(sub(a, b))
}

/// Six times the signed volume of a tetrahedron.
fn vol6(p: [V3; 4]) -> f64 {
    dot(sub(p[1], p[0]), cross(sub(p[2], p[0]), sub(p[3], p[0])))
}

fn data3d(name: &str) -> PathBuf {
    repo().join("tests/data/3d").join(name)
}

fn read_mesh(path: &Path) -> Mesh {
    Mesh::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Reads a mesh that must be refused with an input error naming the file and every needle.
fn refused(path: &Path, needles: &[&str]) -> String {
    let err = match Mesh::read(path) {
        Ok(m) => panic!(
            "{} was accepted ({} tetrahedra)",
            path.display(),
            m.tetrahedra.len()
        ),
        Err(e) => e,
    };
    let Error::Input(msg) = &err else {
        panic!("{}: not an input error: {err:?}", path.display())
    };
    assert_eq!(err.exit_code(), 2);
    let file = path.display().to_string();
    assert!(msg.contains(&file), "message does not name {file}: {msg}");
    for n in needles {
        assert!(msg.contains(n), "message lacks '{n}': {msg}");
    }
    msg.clone()
}

/// The boundary of a tetrahedral mesh computed from scratch, independently of the mesh
/// module: the faces used by exactly one tetrahedron, as (sorted nodes, outward unit normal,
/// area), outward meaning away from the tetrahedron's fourth vertex.
fn boundary_faces(m: &Mesh) -> Vec<([usize; 3], V3, f64)> {
    let mut uses: HashMap<[usize; 3], (usize, usize)> = HashMap::new();
    for t in &m.tetrahedra {
        for k in 0..4 {
            let mut f = [0; 3];
            let others = (0..4).filter(|&i| i != k).map(|i| t[i]);
            for (slot, n) in f.iter_mut().zip(others) {
                *slot = n;
            }
            f.sort_unstable();
            uses.entry(f).or_insert((0, t[k])).0 += 1;
        }
    }
    let mut out: Vec<([usize; 3], V3, f64)> = uses
        .into_iter()
        .filter(|(_, (count, _))| *count == 1)
        .map(|(f, (_, opposite))| {
            let [a, b, c] = f.map(|i| m.nodes[i]);
            let mut n = cross(sub(b, a), sub(c, a));
            let twice_area = norm(n);
            if dot(n, sub(m.nodes[opposite], a)) > 0.0 {
                n = n.map(|x| -x);
            }
            (f, n.map(|x| x / twice_area), 0.5 * twice_area)
        })
        .collect();
    out.sort_by_key(|e| e.0);
    out
}

fn sorted3(f: &[usize]) -> [usize; 3] {
    let mut k = [f[0], f[1], f[2]];
    k.sort_unstable();
    k
}

/// The outward normal of the face of the box [lo, hi] on which all points lie.
fn box_normal(pts: &[V3], lo: V3, hi: V3) -> V3 {
    for c in 0..3 {
        for (value, sign) in [(lo[c], -1.0), (hi[c], 1.0)] {
            if pts.iter().all(|p| (p[c] - value).abs() < 1e-12) {
                let mut n = [0.0; 3];
                n[c] = sign;
                return n;
            }
        }
    }
    panic!("{pts:?} is not on a face of the box {lo:?}..{hi:?}");
}

/// Nodal values of x ↦ f(x) as a flat vector with 3 dofs per node (3·node + component).
fn nodal_field(m: &Mesh, f: impl Fn(V3) -> V3) -> Vec<f64> {
    m.nodes.all().iter().flat_map(|&p| f(p)).collect()
}

// ---- 1. mesh import ----------------------------------------------------------------------

#[test]
fn block_008_counts_areas_and_normals() {
    let n = 8usize;
    let m = read_mesh(&repo().join("meshes/3d/block_008.msh"));
    // block.geo: (2n+1)(n+1)² nodes, 2n³ cubes of side h = 1/n cut into 6 tetrahedra each.
    assert_eq!(m.dim, 3);
    assert_eq!(m.nodes.len(), (2 * n + 1) * (n + 1) * (n + 1));
    assert_eq!(m.tetrahedra.len(), 12 * n * n * n);
    assert!(m.triangles.is_empty());
    assert_eq!(m.flipped, 0, "gmsh writes positively oriented tetrahedra");
    let h = 1.0 / n as f64;
    let mut volume = 0.0;
    for t in &m.tetrahedra {
        let v = vol6(t.map(|i| m.nodes[i])) / 6.0;
        // Equal volumes h³/6; the nodes are (i, j, k)/n to rounding (1e-16 relative).
        assert!(
            (v - h * h * h / 6.0).abs() < 1e-12 * h * h * h,
            "{t:?}: {v}"
        );
        volume += v;
    }
    assert!((volume - 2.0).abs() < 1e-12, "volume {volume}");

    let names: Vec<String> = m.groups.iter().map(Mesh::display_name).collect();
    assert_eq!(
        names,
        ["Γ1", "Γ2", "Γ3,1", "Γ3,2", "top", "right", "sides", "Ω"]
    );
    // Faces and areas: a face of the box of area A holds 2A/h² triangles.
    let n2 = n * n;
    let expected = [
        ("Γ1", 2 * n2, 1.0),
        ("Γ2", 14 * n2, 7.0),
        ("Γ3,1", 2 * n2, 1.0),
        ("Γ3,2", 2 * n2, 1.0),
        ("top", 4 * n2, 2.0),
        ("right", 2 * n2, 1.0),
        ("sides", 8 * n2, 4.0),
    ];
    let (lo, hi) = ([0.0; 3], [2.0, 1.0, 1.0]);
    for (key, faces, area) in expected {
        let g = m.boundary_group(key).unwrap();
        assert_eq!(g.dim, 2, "{key}");
        assert!(g.facets.is_empty(), "{key}: no 2D edges in 3D");
        assert_eq!(g.faces.len(), faces, "{key}: faces");
        let facets = m.boundary_facets(g);
        let sum: f64 = facets.iter().map(|f| f.measure).sum();
        assert!((sum - area).abs() < 1e-12, "{key}: area {sum}");
        // Every face lies on a face of the box and its normal is that face's outward normal.
        for f in &facets {
            let pts: Vec<V3> = f.nodes().iter().map(|&i| m.nodes[i]).collect();
            let want = box_normal(&pts, lo, hi);
            assert!(
                dist(f.normal, want) < 1e-12,
                "{key}: {:?} vs {want:?}",
                f.normal
            );
            assert!((f.measure - 0.5 * h * h).abs() < 1e-12 * h * h);
        }
    }
    let omega = m.group("Ω").unwrap();
    assert_eq!((omega.dim, omega.cells.len()), (3, 12 * n * n * n));
    assert!(m.boundary_facets(omega).is_empty());

    // Γ1, Γ2, Γ3,1, Γ3,2 partition the boundary of the tetrahedral mesh (computed here from
    // the tetrahedra), with the same outward normals.
    let bnd = boundary_faces(&m);
    assert_eq!(bnd.len(), 20 * n2);
    let mut parts: Vec<([usize; 3], V3)> = Vec::new();
    for key in ["Γ1", "Γ2", "Γ3,1", "Γ3,2"] {
        let g = m.boundary_group(key).unwrap();
        parts.extend(
            m.boundary_facets(g)
                .iter()
                .map(|f| (sorted3(f.nodes()), f.normal)),
        );
    }
    parts.sort_by_key(|p| p.0);
    assert_eq!(parts.len(), bnd.len());
    for ((f, n), (g, nb, _)) in parts.iter().zip(&bnd) {
        assert_eq!(f, g);
        assert!(dist(*n, *nb) < 1e-12);
    }

    // Nodal normals: flat groups have their face's normal at every node and no kink.
    let bottom = [0.0, 0.0, -1.0];
    for (key, nodes, want) in [
        ("Γ1", (n + 1) * (n + 1), Some([-1.0, 0.0, 0.0])),
        ("Γ3,1", (n + 1) * (n + 1), Some(bottom)),
        ("Γ3,2", (n + 1) * (n + 1), Some(bottom)),
        ("top", (2 * n + 1) * (n + 1), Some([0.0, 0.0, 1.0])),
        ("right", (n + 1) * (n + 1), Some([1.0, 0.0, 0.0])),
        ("sides", 2 * (2 * n + 1) * (n + 1), None),
    ] {
        let g = m.boundary_group(key).unwrap();
        let (normals, kink) = m.nodal_normals(g);
        assert_eq!(normals.len(), nodes, "{key}: nodes");
        assert!(kink.abs() < 1e-9, "{key}: kink {kink}°");
        for (node, nn) in normals {
            let p = m.nodes[node];
            // "sides" = y = 0 and y = 1, which share no node.
            let want = want.unwrap_or(if p[1] < 0.5 {
                [0.0, -1.0, 0.0]
            } else {
                [0.0, 1.0, 0.0]
            });
            assert!(
                dist(nn, want) < 1e-12,
                "{key}: node {node} at {p:?}: {nn:?}"
            );
        }
    }
    // Γ2 bends by 90° along the edges of the box; each nodal normal is a unit vector that
    // points out of every face at its node (a convex corner).
    let g2 = m.boundary_group("Γ2").unwrap();
    let (normals, kink) = m.nodal_normals(g2);
    assert!((kink - 90.0).abs() < 1e-9, "Γ2: kink {kink}°");
    let facets = m.boundary_facets(g2);
    for (node, nn) in normals {
        assert!((norm(nn) - 1.0).abs() < 1e-12);
        for f in facets.iter().filter(|f| f.nodes().contains(&node)) {
            assert!(
                dot(nn, f.normal) > 0.0,
                "node {node}: {nn:?} vs {:?}",
                f.normal
            );
        }
    }
}

/// Every shipped tetrahedral mesh (meshes/3d/, and any other 3D mesh under meshes/) reads
/// without reorientation; Γ1, Γ2 and the parts of Γ3 it has partition the boundary computed
/// here from the tetrahedra, with the same outward normals; every other boundary group lies
/// inside Γ2; and the volume equals the boundary integral (1/3)∫ x·ν da (divergence
/// theorem), which holds only for a closed, consistently outward boundary.
#[test]
fn every_shipped_3d_mesh_reads_and_its_boundary_is_partitioned() {
    let files = common::shipped_meshes();
    let mut seen = Vec::new();
    for path in &files {
        let m = read_mesh(path);
        if m.dim != 3 {
            continue;
        }
        let name = path.display().to_string();
        assert_eq!(m.flipped, 0, "{name}");
        let mut volume = 0.0;
        for t in &m.tetrahedra {
            let v = vol6(t.map(|i| m.nodes[i])) / 6.0;
            assert!(v > 0.0, "{name}: {t:?}");
            volume += v;
        }
        let bnd = boundary_faces(&m);
        let flux: f64 = bnd
            .iter()
            .map(|(f, n, area)| {
                let c = [0, 1, 2].map(|k| f.iter().map(|&i| m.nodes[i][k]).sum::<f64>() / 3.0);
                area / 3.0 * dot(c, *n)
            })
            .sum();
        // Both sums add up many same-sign terms: rounding up to ~N ε relative (N cells).
        let tol = 1e-15 * m.tetrahedra.len() as f64 * volume;
        assert!((flux - volume).abs() < tol, "{name}: {flux} vs {volume}");

        let mut parts: Vec<([usize; 3], V3)> = Vec::new();
        let mut present = Vec::new();
        for key in ["Γ1", "Γ2", "Γ3,1", "Γ3,2"] {
            let Ok(g) = m.boundary_group(key) else {
                continue;
            };
            present.push(key);
            parts.extend(
                m.boundary_facets(g)
                    .iter()
                    .map(|f| (sorted3(f.nodes()), f.normal)),
            );
        }
        assert!(
            present.starts_with(&["Γ1", "Γ2"]) && present.len() >= 3,
            "{name}: {present:?}"
        );
        parts.sort_by_key(|p| p.0);
        assert_eq!(parts.len(), bnd.len(), "{name}: Σ parts vs boundary faces");
        for ((f, n), (g, nb, _)) in parts.iter().zip(&bnd) {
            assert_eq!(f, g, "{name}: a boundary face is missing or in two parts");
            assert!(dist(*n, *nb) < 1e-12, "{name}: face {f:?}: {n:?} vs {nb:?}");
        }
        let g2: BTreeSet<[usize; 3]> = m
            .boundary_facets(m.boundary_group("Γ2").unwrap())
            .iter()
            .map(|f| sorted3(f.nodes()))
            .collect();
        for g in m.groups.iter().filter(|g| g.dim == 2) {
            let key = Mesh::display_name(g);
            if ["Γ1", "Γ2", "Γ3,1", "Γ3,2"].contains(&key.as_str()) {
                continue;
            }
            for f in m.boundary_facets(g) {
                assert!(g2.contains(&sorted3(f.nodes())), "{name}: {key} leaves Γ2");
            }
        }
        seen.push(path.file_name().unwrap().to_string_lossy().into_owned());
    }
    for want in [
        "block_002.msh",
        "block_004.msh",
        "block_008.msh",
        "slab_016_t0040.msh",
        "slab_016_t0200.msh",
        "slider.msh",
    ] {
        assert!(
            seen.iter().any(|s| s == want),
            "{want} not checked: {seen:?}"
        );
    }
}

/// The two tetrahedra of tests/data/3d/two_tets.msh (and inverted_tet.msh): (0,0,0), e_x,
/// e_y, e_z and, across the face x + y + z = 1, the node (1,1,1). Γ1 is the face x = 0,
/// Γ2 the five other boundary faces, some written inward in the file.
fn check_two_tets(m: &Mesh) {
    assert_eq!((m.dim, m.nodes.len(), m.tetrahedra.len()), (3, 5, 2));
    let mut cells: Vec<[usize; 4]> = m
        .tetrahedra
        .iter()
        .map(|t| {
            let mut s = *t;
            s.sort_unstable();
            s
        })
        .collect();
    cells.sort_unstable();
    // Node tags 1..5 in file order are indices 0..4.
    assert_eq!(cells, [[0, 1, 2, 3], [1, 2, 3, 4]]);
    let mut vols: Vec<f64> = m
        .tetrahedra
        .iter()
        .map(|t| vol6(t.map(|i| m.nodes[i])) / 6.0)
        .collect();
    vols.sort_by(f64::total_cmp);
    assert!((vols[0] - 1.0 / 6.0).abs() < 1e-15 && (vols[1] - 1.0 / 3.0).abs() < 1e-15);

    let g1 = m.boundary_group("Γ1").unwrap();
    let f1 = m.boundary_facets(g1);
    assert_eq!(f1.len(), 1);
    assert_eq!(sorted3(f1[0].nodes()), [0, 2, 3]);
    assert!(
        dist(f1[0].normal, [-1.0, 0.0, 0.0]) < 1e-15,
        "{:?}",
        f1[0].normal
    );
    assert!((f1[0].measure - 0.5).abs() < 1e-15);
    let (_, kink) = m.nodal_normals(g1);
    assert_eq!(kink, 0.0);

    let s = 1.0 / 3f64.sqrt();
    let want: HashMap<[usize; 3], V3> = [
        ([0, 1, 2], [0.0, 0.0, -1.0]),
        ([0, 1, 3], [0.0, -1.0, 0.0]),
        ([1, 2, 4], [s, s, -s]),
        ([1, 3, 4], [s, -s, s]),
        ([2, 3, 4], [-s, s, s]),
    ]
    .into_iter()
    .collect();
    let g2 = m.boundary_group("Γ2").unwrap();
    let f2 = m.boundary_facets(g2);
    assert_eq!(f2.len(), 5);
    for f in &f2 {
        let key = sorted3(f.nodes());
        let w = want[&key];
        assert!(
            dist(f.normal, w) < 1e-15,
            "{key:?}: {:?} vs {w:?}",
            f.normal
        );
        // The stored orientation: (b − a) × (c − a) points out, too.
        let [a, b, c] = [0, 1, 2].map(|i| m.nodes[f.nodes()[i]]);
        assert!(dot(cross(sub(b, a), sub(c, a)), w) > 0.0);
    }
    // The largest angle between facet normals at a node of Γ2: e.g. at e_x between the
    // bottom (0,0,−1) and the slanted face (1,−1,1)/√3, arccos(−1/√3) = 125.26°.
    let (_, kink) = m.nodal_normals(g2);
    let expected = (-s).acos().to_degrees();
    assert!((kink - expected).abs() < 1e-9, "{kink} vs {expected}");
    assert_eq!(m.group("Ω").unwrap().cells.len(), 2);
}

#[test]
fn two_hand_written_tetrahedra_have_outward_faces() {
    let m = read_mesh(&data3d("two_tets.msh"));
    assert_eq!(m.flipped, 0);
    check_two_tets(&m);
}

#[test]
fn inverted_tetrahedron_is_reoriented() {
    // inverted_tet.msh = two_tets.msh with the second tetrahedron given as 3 2 4 5.
    let m = read_mesh(&data3d("inverted_tet.msh"));
    assert_eq!(m.flipped, 1);
    for t in &m.tetrahedra {
        assert!(vol6(t.map(|i| m.nodes[i])) > 0.0, "{t:?}");
    }
    check_two_tets(&m);
}

#[test]
fn flat_tetrahedron_is_refused_naming_it() {
    // Element 42 = nodes (1,0,0), (0,1,0), (0,0,1), (1,1,−1): all on x + y + z = 1.
    refused(
        &data3d("flat_tet.msh"),
        &["tetrahedron 42", "zero volume", "(1, 1, -1)"],
    );
}

#[test]
fn folded_mesh_and_a_face_of_three_tetrahedra_are_refused() {
    // Tetrahedra 10 and 12 lie on the same side of their common face.
    refused(
        &data3d("folded_tets.msh"),
        &["folds over itself", "10 and 12"],
    );
    // Tetrahedra 10, 11 and 12 share the face (1,0,0)–(0,1,0)–(0,0,1).
    refused(
        &data3d("three_tets_face.msh"),
        &[
            "three or more tetrahedra",
            "(1, 0, 0)",
            "(0, 1, 0)",
            "(0, 0, 1)",
        ],
    );
}

#[test]
fn interior_face_in_a_boundary_group_is_refused_as_a_boundary() {
    let mesh = read_mesh(&data3d("interior_face.msh"));
    let err = mesh.boundary_group("inner").unwrap_err().to_string();
    for needle in ["\"inner\"", "gmsh element 7", "interior face"] {
        assert!(err.contains(needle), "{err}");
    }
}

#[test]
fn quadratic_tetrahedra_and_hexahedra_are_refused_with_the_remedy() {
    // gmsh -3 -order 2: 10-node tetrahedra (type 11) and 6-node triangles (type 9).
    let msg = refused(
        &data3d("quadratic_tets.msh"),
        &["10-node", "tetrahedra", "type 11", "gmsh -3 -order 1"],
    );
    // The tetrahedra decide the remedy: no 2D advice for the boundary triangles.
    assert!(!msg.contains("gmsh -2"), "{msg}");
    refused(
        &data3d("hexahedron.msh"),
        &["8-node", "hexahedra", "type 5", "Mesh.RecombineAll = 0"],
    );
}

/// Sets up a scene that must be refused with an input error naming it and every needle.
fn setup_refused(scene: &Path, overrides: &[String], needles: &[&str]) -> String {
    let err = match viscontact::run::setup(scene, overrides) {
        Ok(_) => panic!("{} {overrides:?} was accepted", scene.display()),
        Err(e) => e,
    };
    let Error::Input(msg) = &err else {
        panic!("not an input error: {err:?}")
    };
    let name = scene.display().to_string();
    assert!(msg.contains(&name), "message does not name {name}: {msg}");
    for n in needles {
        assert!(msg.contains(n), "message lacks '{n}': {msg}");
    }
    msg.clone()
}

#[test]
fn model_and_mesh_dimension_must_agree() {
    let dir = tempfile::tempdir().unwrap();
    // A plane-stress scene (2-component loads) on the 3D block.
    let block = repo().join("meshes/3d/block_004.msh");
    let scene = SceneText::paper()
        .mesh(&block)
        .write(dir.path(), "paper_on_block.toml");
    let msg = setup_refused(&scene, &[], &["'mesh.model'", "tetrahedra", "\"3d\""]);
    assert!(msg.contains("block_004.msh"), "{msg}");
    // The 3D scene on the 2D rectangle.
    let rect = repo().join("meshes/paper/rect_008.msh");
    let scene = SceneText::block()
        .mesh(&rect)
        .write(dir.path(), "block_on_rect.toml");
    let msg = setup_refused(&scene, &[], &["'mesh.model'", "triangles"]);
    assert!(msg.contains("rect_008.msh"), "{msg}");
    // And the same through --set.
    let scene = repo().join("examples/block.toml");
    setup_refused(
        &scene,
        &[format!("mesh.file={}", rect.display())],
        &["'mesh.model'"],
    );
}

#[test]
fn three_d_vector_loads_need_three_components() {
    let dir = tempfile::tempdir().unwrap();
    let scene = SceneText::block()
        .set(
            "load.traction[1].value",
            scene::strings(&["if(t <= 0.5, 0.01*(1-z)*t, 0.01*(1-z)*0.2)", "0"]),
        )
        .write(dir.path(), "two.toml");
    setup_refused(
        &scene,
        &[],
        &["load.traction[1].value", "2 components", "3D model needs 3"],
    );
    let scene = SceneText::block()
        .body(&["0", "-1"])
        .write(dir.path(), "body.toml");
    setup_refused(&scene, &[], &["load.body[0].value", "2 components"]);
}

#[test]
fn volume_group_is_not_a_boundary_group() {
    let scene = repo().join("examples/block.toml");
    setup_refused(
        &scene,
        &["mesh.groups.fixed=Ω".to_string()],
        &["mesh.groups.fixed", "Ω", "volume", "boundary (surface)"],
    );
}

// ---- 2. patch tests ----------------------------------------------------------------------

/// y = K v and the rounding scale |K| |v| (entrywise absolute values) for the unclamped
/// assembly of the tensor C over all tetrahedra (3 dofs per node, none eliminated), from
/// the element matrices of `Cell::tetrahedron` + `stiffness`; and the largest element-level
/// ratio max|K_T v_T| / max(|K_T||v_T|) (how far v is from the kernel of each element).
fn unclamped_apply(m: &Mesh, c: Isotropic, v: &[f64]) -> (Vec<f64>, Vec<f64>, f64) {
    let mut y = vec![0.0; v.len()];
    let mut s = vec![0.0; v.len()];
    let mut worst: f64 = 0.0;
    for t in &m.tetrahedra {
        let cell = Cell::tetrahedron(*t, t.map(|i| m.nodes[i]));
        let k = cell.stiffness(c);
        let dof = |l: usize| 3 * t[l / 3] + l % 3;
        let (mut ye, mut se) = ([0.0; 12], [0.0; 12]);
        for (i, row) in k.iter().enumerate() {
            for (j, kij) in row.iter().enumerate() {
                ye[i] += kij * v[dof(j)];
                se[i] += (kij * v[dof(j)]).abs();
            }
            y[dof(i)] += ye[i];
            s[dof(i)] += se[i];
        }
        worst = worst.max(max_abs(&ye) / max_abs(&se).max(f64::MIN_POSITIVE));
    }
    (y, s, worst)
}

/// σ = 2a ε + b tr(ε) I for the constant strain of the displacement gradient G.
fn stress(c: Isotropic, g: [V3; 3]) -> [V3; 3] {
    let tr = g[0][0] + g[1][1] + g[2][2];
    let mut s = [[0.0; 3]; 3];
    for (i, row) in s.iter_mut().enumerate() {
        for (j, sij) in row.iter_mut().enumerate() {
            *sij = c.a * (g[i][j] + g[j][i]) + if i == j { c.b * tr } else { 0.0 };
        }
    }
    s
}

fn mat_vec(s: [V3; 3], n: V3) -> V3 {
    [0, 1, 2].map(|i| dot(s[i], n))
}

/// The three tensors of the scheme in 3D, for θ = 0.3, ζ = 0.2, E = 2, ν = 0.3: A (4.1),
/// B by the Lamé coefficients μ = E/(2(1+ν)), λ = Eν/((1+ν)(1−2ν)) written out here, R = I.
fn tensors() -> [(&'static str, Isotropic); 3] {
    let (e, nu) = (2.0, 0.3);
    [
        ("A", Isotropic { a: 0.3, b: 0.2 }),
        (
            "B",
            Isotropic {
                a: e / (2.0 * (1.0 + nu)),
                b: e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)),
            },
        ),
        ("R", Isotropic { a: 0.5, b: 0.0 }),
    ]
}

#[test]
fn three_d_tensors_are_lame_and_viscosity() {
    let (e, nu) = (2.0, 0.3);
    let b = Isotropic::lame(e, nu);
    let want = tensors()[1].1;
    assert!(
        (b.a - want.a).abs() < 1e-15 && (b.b - want.b).abs() < 1e-15,
        "{b:?}"
    );
    // The meaning of E and ν: a uniaxial stress σ = E e1⊗e1 goes with ε = diag(1, −ν, −ν).
    let s = b.apply([1.0, -nu, -nu, 0.0, 0.0, 0.0]);
    assert!((s[0] - e).abs() < 1e-14, "{s:?}");
    assert!(s[1].abs() < 1e-14 && s[2].abs() < 1e-14, "{s:?}");
    // Shear: σ12 = 2μ ε12.
    let s = b.apply([0.0, 0.0, 0.0, 0.25, 0.0, 0.0]);
    assert!((s[3] - e / (1.0 + nu) * 0.25).abs() < 1e-15);

    // The 3D discretization carries A = (θ, ζ), B = Lamé, R = I and 3 dofs per node.
    let dir = tempfile::tempdir().unwrap();
    let scene = patch_box(&[]).write(dir.path(), "box.toml");
    let (_, mesh, disc) = load(&scene, &[]);
    for ((name, want), got) in tensors().iter().zip([
        disc.materials.of(0).a,
        disc.materials.of(0).b.unwrap(),
        disc.r,
    ]) {
        assert!(
            (got.a - want.a).abs() < 1e-15 && (got.b - want.b).abs() < 1e-15,
            "{name}: {got:?} vs {want:?}"
        );
    }
    assert_eq!(disc.dim, 3);
    assert_eq!(disc.cells.len(), mesh.tetrahedra.len());
    assert!(disc.cells.iter().all(|c| c.dim == 3 && c.measure > 0.0));
    assert_eq!(disc.free.dofs(), 3 * mesh.nodes.len());
    let clamped = mesh.group_nodes(mesh.boundary_group("Γ1").unwrap()).len();
    assert_eq!(disc.n_free, 3 * (mesh.nodes.len() - clamped));
    assert_eq!(disc.k_a.nrows(), disc.n_free);
}

#[test]
fn unclamped_assembly_annihilates_rigid_motions_only() {
    // slider.msh: 1122 nodes, 4191 unstructured tetrahedra.
    let m = read_mesh(&repo().join("meshes/3d/slider.msh"));
    let x0 = [0.3, 0.4, 0.1];
    let mut rigid: Vec<(String, Vec<f64>)> = (0..3)
        .map(|c| {
            let e = [0, 1, 2].map(|i| f64::from(i == c));
            (format!("translation e{c}"), nodal_field(&m, |_| e))
        })
        .collect();
    for c in 0..3 {
        let w = [0, 1, 2].map(|i| f64::from(i == c));
        rigid.push((
            format!("rotation about e{c}"),
            nodal_field(&m, |p| cross(w, sub(p, x0))),
        ));
    }
    let volume: f64 = m
        .tetrahedra
        .iter()
        .map(|t| vol6(t.map(|i| m.nodes[i])) / 6.0)
        .sum();
    assert!((volume - 0.25).abs() < 1e-12);
    for (name, c) in tensors() {
        for (what, v) in &rigid {
            let (y, s, element) = unclamped_apply(&m, c, v);
            // Exact arithmetic gives 0, for the assembly and for every element matrix alone;
            // rounding leaves a few ulps of the terms summed.
            let rel = max_abs(&y) / max_abs(&s);
            assert!(rel < 1e-12, "K_{name} · {what}: relative {rel:e}");
            assert!(element < 1e-12, "K_T,{name} · {what}: relative {element:e}");
        }
        // A stretch is no rigid motion: v = (x, 0, 0) has the strain energy
        // vᵀKv = |Ω| Cε:ε = |Ω| (2a + b) (ε = e1⊗e1), and K v does not vanish.
        let v = nodal_field(&m, |p| [p[0], 0.0, 0.0]);
        let (y, s, element) = unclamped_apply(&m, c, &v);
        assert!(element > 0.1, "K_T,{name} · stretch: {element:e}");
        // On boundary rows K v is the traction load (~ a h² per node) against |K||v| ~ a h
        // per term with max x = 1 and ~20 terms: a ratio ~ h/20 ~ 5e-3 on this mesh, eight
        // orders of magnitude above the rounding level asserted for rigid motions.
        let rel = max_abs(&y) / max_abs(&s);
        assert!(rel > 1e-4, "K_{name} · stretch: {rel:e}");
        let energy: f64 = y.iter().zip(&v).map(|(a, b)| a * b).sum();
        let want = volume * (2.0 * c.a + c.b);
        assert!(
            (energy - want).abs() < 1e-12 * want,
            "K_{name}: {energy} vs {want}"
        );
    }
}

#[test]
fn unclamped_assembly_passes_the_patch_test_for_any_affine_field() {
    // For g(x) = G x + c, K g must be the load of the traction σ ν of the constant stress
    // σ = C ε(g) on the whole boundary: ∫_∂Ω σν·φ_i e_α = Σ_faces∋i (area/3) (σν)_α (φ_i
    // integrates to area/3 on a triangle; σν is constant on a flat face). Interior rows
    // vanish. The boundary is found from the tetrahedra, not from the groups.
    let m = read_mesh(&repo().join("meshes/3d/slider.msh"));
    let g = [[0.3, -0.2, 0.5], [0.7, 0.1, -0.4], [0.2, 0.6, 0.25]];
    let c0 = [0.01, -0.02, 0.03];
    let v = nodal_field(&m, |p| [0, 1, 2].map(|i| dot(g[i], p) + c0[i]));
    let faces = boundary_faces(&m);
    let on_boundary: BTreeSet<usize> = faces.iter().flat_map(|f| f.0).collect();
    let interior = m.nodes.len() - on_boundary.len();
    assert!(interior > 100, "slider.msh has {interior} interior nodes");
    for (name, c) in tensors() {
        let s = stress(c, g);
        let mut f = vec![0.0; v.len()];
        for (nodes, n, area) in &faces {
            let t = mat_vec(s, *n);
            for &i in nodes {
                for a in 0..3 {
                    f[3 * i + a] += area / 3.0 * t[a];
                }
            }
        }
        let (y, scale, _) = unclamped_apply(&m, c, &v);
        let err = y
            .iter()
            .zip(&f)
            .fold(0.0f64, |e, (a, b)| e.max((a - b).abs()));
        // Rounding only: a few ulps of the summed terms |K||v|.
        let rel = err / max_abs(&scale);
        assert!(rel < 1e-12, "K_{name} g vs boundary load: {rel:e}");
        assert!(
            max_abs(&f) > 1e-3 * max_abs(&scale),
            "the load is not trivial"
        );
    }
}

/// The box of tests/data/3d/patch_box.msh: (0,1) × (0,0.8) × (0,0.6), Γ1 = {x = 0}, one
/// load group per other face with its outward normal.
const BOX_FACES: [(&str, V3); 5] = [
    ("x1", [1.0, 0.0, 0.0]),
    ("y0", [0.0, -1.0, 0.0]),
    ("y1", [0.0, 1.0, 0.0]),
    ("z0", [0.0, 0.0, -1.0]),
    ("z1", [0.0, 0.0, 1.0]),
];

/// θ = 0.3, ζ = 0.2, E = 2, ν = 0.3, R(s) = e^{−s} I: the tensors of [`tensors`].
/// The box with the patch tests' material: θ = 0.3, ζ = 0.2, E = 2, ν = 0.3, R = e^{−s} I,
/// one step of k = 0.01.
fn patch_box(tractions: &[(&str, [String; 3])]) -> SceneText {
    box_scene([0.3, 0.2], [2.0, 0.3], tractions, 1, 0.01)
        .literal("material.relaxation.prony", "[[1.0, 1.0]]")
}

/// The traction σν on each face of the box, times the expression `factor` of t; faces with
/// zero traction are left out.
fn box_tractions(s: [V3; 3], factor: &str) -> Vec<(&'static str, [String; 3])> {
    BOX_FACES
        .iter()
        .filter_map(|&(face, n)| {
            let t = mat_vec(s, n);
            if t.iter().all(|&x| x == 0.0) {
                return None;
            }
            let comp = |x: f64| {
                if x == 0.0 {
                    "0".to_string()
                } else {
                    format!("{x:?}*({factor})")
                }
            };
            Some((face, t.map(comp)))
        })
        .collect()
}

/// A 3D scene on patch_box.msh without contact, friction and memory: viscosity (θ, ζ),
/// elasticity (E, ν) and the tractions on the faces.
fn box_scene(
    viscosity: [f64; 2],
    elasticity: [f64; 2],
    tractions: &[(&str, [String; 3])],
    steps: usize,
    end: f64,
) -> SceneText {
    let scene = SceneText::on(data3d("patch_box.msh"))
        .set("name", "box")
        .set("mesh.model", "3d")
        .set("time.end", end)
        .set("time.steps", steps as i64)
        .set("material.viscosity.theta", viscosity[0])
        .set("material.viscosity.zeta", viscosity[1])
        .set("material.elasticity.young", elasticity[0])
        .set("material.elasticity.poisson", elasticity[1]);
    tractions
        .iter()
        .fold(scene, |scene, (on, v)| scene.traction(Some(on), v))
}

/// K_C v = the traction load of σ = C ε(v) for v = x (P, Q, R), which vanishes on Γ1: the
/// library's clamped matrix against its own load assembly (6-point rule on the faces).
fn clamped_patch(
    name: &str,
    c: Isotropic,
    pick: impl Fn(&Discretization) -> &viscontact::fem::Sparse,
) {
    let (p, q, r) = (0.7, -0.4, 0.25);
    let g = [[p, 0.0, 0.0], [q, 0.0, 0.0], [r, 0.0, 0.0]];
    let dir = tempfile::tempdir().unwrap();
    let scene = patch_box(&box_tractions(stress(c, g), "1")).write(dir.path(), "box.toml");
    let (s, mesh, disc) = load(&scene, &[]);
    let k = pick(&disc);
    let mut v = vec![0.0; disc.n_free];
    for (i, x) in disc.nodes.all().iter().enumerate() {
        for (comp, val) in [p, q, r].iter().enumerate() {
            if let Some(d) = disc.free.get(3 * i + comp) {
                v[d] = val * x[0];
            }
        }
    }
    let mut kv = vec![0.0; disc.n_free];
    mul_add(k, &v, 1.0, &mut kv);
    let mut f = vec![0.0; disc.n_free];
    disc.loads
        .add(0.0, (&disc.free, &disc.frames), &s, (&mut f, None))
        .unwrap();
    // Rounding only (sums of ~20 element contributions per row): 1e-12 of the load.
    let d = rel_diff(&kv, &f);
    assert!(d < 1e-12, "K_{name} v − f: {d:e}");
    // Interior rows carry no load, and K v vanishes there (included in d above).
    let on_boundary: BTreeSet<usize> = boundary_faces(&mesh).iter().flat_map(|f| f.0).collect();
    let interior = (0..mesh.nodes.len()).filter(|i| !on_boundary.contains(i));
    let mut rows = 0;
    for i in interior {
        for comp in 0..3 {
            let dof = disc
                .free
                .get(3 * i + comp)
                .expect("interior nodes are free");
            assert_eq!(f[dof], 0.0);
            rows += 1;
        }
    }
    assert!(rows >= 30, "patch_box.msh has {} interior nodes", rows / 3);
}

#[test]
fn clamped_viscosity_matrix_patch_test() {
    clamped_patch("A", tensors()[0].1, |d| &d.k_a);
}

#[test]
fn clamped_elasticity_matrix_patch_test() {
    clamped_patch("B", tensors()[1].1, |d| d.k_b.as_ref().unwrap());
}

#[test]
fn clamped_relaxation_matrix_patch_test() {
    clamped_patch("R", tensors()[2].1, |d| &d.k_r[0]);
}

/// A polynomial Σ c x^a y^b z^c as (coefficient, exponents).
type Poly = Vec<(f64, [i32; 3])>;

fn poly_expr(p: &Poly) -> String {
    let terms: Vec<String> = p
        .iter()
        .map(|(c, e)| format!("{c:?}*x^{}*y^{}*z^{}", e[0], e[1], e[2]))
        .collect();
    if terms.is_empty() {
        "0".into()
    } else {
        terms.join(" + ")
    }
}

/// ∫ over [0, l0] × [0, l1] × [0, l2] of p times x^m, exactly; a length 0 means that the
/// coordinate is fixed at the value in `at` (a face).
fn box_integral(p: &Poly, m: [i32; 3], l: V3, at: V3) -> f64 {
    p.iter()
        .map(|(c, e)| {
            c * (0..3)
                .map(|k| {
                    let n = e[k] + m[k];
                    if l[k] == 0.0 {
                        at[k].powi(n)
                    } else {
                        l[k].powi(n + 1) / f64::from(n + 1)
                    }
                })
                .product::<f64>()
        })
        .sum()
}

#[test]
fn three_d_load_quadrature_is_exact_for_polynomials() {
    // A linear body force (4-point degree-2 rule: exact for linear × P1) and a quadratic
    // traction on the face z = 0.6 (6-point degree-4 rule: exact for quadratic × P1). With
    // every dof free, Σ_i φ_i = 1 and Σ_i x_i φ_i = x make the load vector's moments
    // Σ_i w(x_i) F_iα = ∫_Ω w f0_α + ∫_{z=0.6} w f2_α for w = 1, x, y, z: exact integrals of
    // polynomials over the box, computed here.
    let l = [1.0, 0.8, 0.6];
    let body: [Poly; 3] = [
        vec![
            (1.0, [0, 0, 0]),
            (2.0, [1, 0, 0]),
            (-1.0, [0, 1, 0]),
            (0.5, [0, 0, 1]),
        ],
        vec![],
        vec![(3.0, [0, 0, 1]), (-0.25, [1, 0, 0])],
    ];
    let traction: [Poly; 3] = [
        vec![(1.0, [0, 2, 0])],
        vec![(1.0, [1, 1, 0]), (-0.5, [2, 0, 0])],
        vec![(1.0, [0, 0, 0]), (0.3, [0, 1, 0])],
    ];
    let dir = tempfile::tempdir().unwrap();
    let t = [0, 1, 2].map(|a| poly_expr(&traction[a]));
    let scene = patch_box(&[("z1", t)])
        .body(&body.each_ref().map(poly_expr))
        .write(dir.path(), "box.toml");
    let (s, mesh, disc) = load(&scene, &[]);
    let all_free = viscontact::fem::DofIndices::each(3 * mesh.nodes.len());
    let mut f = vec![0.0; 3 * mesh.nodes.len()];
    disc.loads
        .add(0.0, (&all_free, &Default::default()), &s, (&mut f, None))
        .unwrap();
    for (a, (fb, ft)) in body.iter().zip(&traction).enumerate() {
        for (m, w) in [
            ([0, 0, 0], "1"),
            ([1, 0, 0], "x"),
            ([0, 1, 0], "y"),
            ([0, 0, 1], "z"),
        ] {
            let got: f64 = mesh
                .nodes
                .all()
                .iter()
                .enumerate()
                .map(|(i, p)| (0..3).map(|k| p[k].powi(m[k])).product::<f64>() * f[3 * i + a])
                .sum();
            let want = box_integral(fb, m, l, [0.0; 3])
                + box_integral(ft, m, [1.0, 0.8, 0.0], [0.0, 0.0, 0.6]);
            // Exact quadrature; rounding of ~400 cells × 4–6 points: 1e-13 is ample.
            assert!(
                (got - want).abs() < 1e-13 * (1.0 + want.abs()),
                "component {a}, moment {w}: {got} vs {want}"
            );
        }
    }
}

// ---- 2b. whole runs that must reproduce an affine solution -------------------------------
//
// With Γ1 = {x = 0} clamped (w = 0 there, so u = 0 there), the affine fields a run can
// reproduce are those vanishing on the plane x = 0: u(x) = x·c for a constant vector c. (A
// free lateral contraction u_y = −νε y, u_z = −νε z is not among them: the clamp forbids it,
// and the clamped bar with ν ≠ 0 is not uniaxial, see the last test of this section.) For
// u(x, t) = s(t) x c to solve the problem, the tractions σν on the other faces must keep a
// fixed pattern in time while σ = A ε(w) + B ε(u) + ε(m) mixes three tensors; this holds for
//
// - the uniaxial bar c = e1 with ν = ζ = 0: σ = σ11 e1⊗e1 for all three tensors (b = 0);
// - confined uniaxial strain c = e1 with ν ≠ 0 and no memory, when ζ/θ = λ/μ: then
//   σ22 = σ33 = κ σ11 with κ = λ/(2μ + λ) = ν/(1 − ν) for both A and B, so the lateral
//   faces get κ f(t) (R = I has b = 0 and would break the proportion: no memory here);
// - simple shear c = e2 with any ν, ζ and memory: tr ε = 0, so σ = σ12 (e1⊗e2 + e2⊗e1)
//   with σ12 = θ s' + μ s + ½ k Σ r s_j, the b coefficients never enter.
//
// In each case the scheme acts on the scalar s as on c_a s' + c_b s + c_r (r ∗ s) = f, and
// P1 tetrahedra represent u exactly, so the FEM run must equal the scalar recursion at
// every step up to rounding.

const STEPS: usize = 40;
const END: f64 = 2.0;
const F_EXPR: &str = "0.01 + 0.02*t + 0.01*sin(3*t)";

fn f(t: f64) -> f64 {
    0.01 + 0.02 * t + 0.01 * (3.0 * t).sin()
}

const PRONY: &str = "prony = [[0.7, 3.0], [0.2, 0.5]]";

fn r(s: f64) -> f64 {
    0.7 * (-3.0 * s).exp() + 0.2 * (-0.5 * s).exp()
}

/// The paper's scheme on c_a s' + c_b s + c_r ∫ r(t − τ) s(τ) dτ = f(t): the left endpoint
/// rule m_n = k Σ_{j<n} r(t_n − t_j) s_j, s_{n+1} = s_n + k s'_n, s_0 = 0. Returns (s_n, s'_n),
/// n = 0..=N.
fn scalar_scheme(c: [f64; 3], kernel: &dyn Fn(f64) -> f64) -> Vec<(f64, f64)> {
    let k = END / STEPS as f64;
    let mut s = vec![0.0];
    let mut out = Vec::new();
    for n in 0..=STEPS {
        let t = n as f64 * k;
        let mem: f64 = (0..n).map(|j| k * kernel((n - j) as f64 * k) * s[j]).sum();
        let rate = (f(t) - c[1] * s[n] - c[2] * mem) / c[0];
        out.push((s[n], rate));
        s.push(s[n] + k * rate);
    }
    out
}

/// Runs the scene and compares u_n and w_n with s_n x·dir and s'_n x·dir at every node and
/// step; returns the worst error relative to max_n |s_n| max x (resp. max_n |s'_n| max x: a
/// rate that passes through 0 at some step has no relative error of its own there).
fn check_affine_run(scene: &Path, overrides: &[&str], dir: V3, exact: &[(f64, f64)]) -> f64 {
    let (scene, _mesh, disc) = load(scene, overrides);
    let tr = trace(&scene, &disc);
    assert!(
        !tr.effects.contains(&"contact") && !tr.effects.contains(&"friction"),
        "{:?}",
        tr.effects
    );
    assert_eq!(tr.u.len(), exact.len());
    let xmax = disc.nodes.all().iter().fold(0.0f64, |a, p| a.max(p[0]));
    let s_max = exact.iter().fold(0.0f64, |a, e| a.max(e.0.abs())) * xmax;
    let rate_max = exact.iter().fold(0.0f64, |a, e| a.max(e.1.abs())) * xmax;
    let mut worst: f64 = 0.0;
    for (n, &(s, rate)) in exact.iter().enumerate() {
        let u = disc.nodal(&tr.u[n]);
        let w = disc.nodal(&tr.w[n]);
        for (what, field, val, scale) in [("u", &u, s, s_max), ("w", &w, rate, rate_max)] {
            for (i, p) in disc.nodes.all().iter().enumerate() {
                let err = (0..3)
                    .map(|c| (field[3 * i + c] - val * p[0] * dir[c]).abs())
                    .fold(0.0, f64::max);
                let rel = err / scale;
                worst = worst.max(rel);
                // The affine field is the exact FE solution; what is left is rounding in the
                // Cholesky solves (cond(K_A) ~ 1e3 on these meshes) accumulated over 40
                // steps of the u and memory sums: ~1e-14 observed. 1e-10 leaves a wide
                // margin and still catches any modelling error (≥ 1e-3 in the control test
                // below).
                assert!(rel <= 1e-10, "step {n}, {what} at node {i} {p:?}: {rel:e}");
            }
        }
    }
    // u_0 = 0 exactly.
    assert!(tr.u[0].iter().all(|&x| x == 0.0));
    worst
}

/// A bar scene on the block: clamped at x = 0, the traction (f(t), 0, 0) on x = 2.
fn bar_on_block(dir: &Path, mesh: &str, nu: f64, relaxation: &str) -> PathBuf {
    SceneText::on(mesh_path(mesh))
        .set("name", "bar3d")
        .set("mesh.model", "3d")
        .set("time.end", END)
        .set("time.steps", STEPS as i64)
        .set("material.viscosity.theta", 0.1)
        .set("material.viscosity.zeta", 0.0)
        .set("material.elasticity.young", 0.5)
        .set("material.elasticity.poisson", nu)
        .table("material.relaxation", relaxation)
        .traction(Some("right"), &[F_EXPR, "0", "0"])
        .write(dir, "bar.toml")
}

#[test]
fn bar_on_the_block_equals_the_scalar_recursion() {
    // ν = ζ = 0: 2θ ε' + E ε + k Σ r ε_j = f, u = ε x e1.
    let dir = tempfile::tempdir().unwrap();
    let scene = bar_on_block(dir.path(), "3d/block_004.msh", 0.0, PRONY);
    let exact = scalar_scheme([0.2, 0.5, 1.0], &r);
    let worst = check_affine_run(&scene, &[], [1.0, 0.0, 0.0], &exact);
    println!("bar on block_004 (Prony kernel): worst relative error {worst:e}");
}

#[test]
fn bar_on_the_unstructured_box_equals_the_scalar_recursion() {
    // The same on the unstructured patch_box.msh, with the kernel as an expression (the
    // direct sum) and θ = 0.3, E = 2: 2θ ε' + E ε + k Σ r ε_j = f.
    let dir = tempfile::tempdir().unwrap();
    let s = [[1.0, 0.0, 0.0], [0.0; 3], [0.0; 3]];
    let scene = box_scene(
        [0.3, 0.0],
        [2.0, 0.0],
        &box_tractions(s, F_EXPR),
        STEPS,
        END,
    )
    .set(
        "material.relaxation.expr",
        "0.7*exp(-3*s) + 0.2*exp(-0.5*s)",
    )
    .set("material.relaxation.memory", "exact")
    .write(dir.path(), "box.toml");
    let exact = scalar_scheme([0.6, 2.0, 1.0], &r);
    let worst = check_affine_run(&scene, &[], [1.0, 0.0, 0.0], &exact);
    println!("bar on patch_box (expression kernel): worst relative error {worst:e}");
}

#[test]
fn confined_uniaxial_strain_with_poisson_ratio_is_exact() {
    // ν = 0.3, E = 2: μ = E/(2(1+ν)), λ = Eν/((1+ν)(1−2ν)); ζ = θ λ/μ makes A ∝ B.
    let (theta, e, nu): (f64, f64, f64) = (0.3, 2.0, 0.3);
    let mu = e / (2.0 * (1.0 + nu));
    let lambda = e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
    let zeta = theta * lambda / mu;
    let kappa = nu / (1.0 - nu);
    assert!((kappa - lambda / (2.0 * mu + lambda)).abs() < 1e-15);
    // σ / f(t) = diag(1, κ, κ): f on x = 1, the confining κ f on the four lateral faces.
    let s = [[1.0, 0.0, 0.0], [0.0, kappa, 0.0], [0.0, 0.0, kappa]];
    let dir = tempfile::tempdir().unwrap();
    let scene = box_scene(
        [theta, zeta],
        [e, nu],
        &box_tractions(s, F_EXPR),
        STEPS,
        END,
    )
    .write(dir.path(), "box.toml");
    let exact = scalar_scheme([2.0 * theta + zeta, 2.0 * mu + lambda, 0.0], &|_: f64| 0.0);
    let worst = check_affine_run(&scene, &[], [1.0, 0.0, 0.0], &exact);
    println!("confined uniaxial strain, ν = {nu}: worst relative error {worst:e}");
}

#[test]
fn simple_shear_with_memory_and_poisson_ratio_is_exact() {
    // u = s(t) x e2, σ12 = θ s' + μ s + ½ k Σ r s_j = f (R = I: σ = ε(m), ε12 = s/2).
    let (theta, e, nu): (f64, f64, f64) = (0.3, 2.0, 0.3);
    let mu = e / (2.0 * (1.0 + nu));
    // σ / f(t) = e1⊗e2 + e2⊗e1: (0, f, 0) on x = 1, (∓f, 0, 0) on y = 0 and y = 0.8.
    let s = [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0; 3]];
    let dir = tempfile::tempdir().unwrap();
    let scene = box_scene([theta, 0.2], [e, nu], &box_tractions(s, F_EXPR), STEPS, END)
        .table("material.relaxation", PRONY)
        .write(dir.path(), "box.toml");
    let exact = scalar_scheme([theta, mu, 0.5], &r);
    let worst = check_affine_run(&scene, &[], [0.0, 1.0, 0.0], &exact);
    println!("simple shear, ν = {nu}, Prony memory: worst relative error {worst:e}");
}

#[test]
fn clamped_bar_with_poisson_ratio_is_not_uniaxial() {
    // The control: with ν = 0.3 the clamp at x = 0 holds the lateral contraction back, the
    // solution is not ε x e1, and the comparison above must fail by far.
    let dir = tempfile::tempdir().unwrap();
    let scene = bar_on_block(dir.path(), "3d/block_004.msh", 0.3, PRONY);
    let (scene, _mesh, disc) = load(&scene, &[]);
    let tr = trace(&scene, &disc);
    let (eps, _) = scalar_scheme([0.2, 0.5, 1.0], &r)[STEPS];
    let u = disc.nodal(&tr.u[STEPS]);
    let worst = disc
        .nodes
        .all()
        .iter()
        .enumerate()
        .map(|(i, p)| {
            (0..3)
                .map(|c| (u[3 * i + c] - if c == 0 { eps * p[0] } else { 0.0 }).abs())
                .fold(0.0, f64::max)
                / (eps * 2.0)
        })
        .fold(0.0f64, f64::max);
    assert!(worst > 1e-3, "{worst}");
}

// ---- 3. the thin slab and plane stress ---------------------------------------------------
//
// The slabs of meshes/3d (thickness t = 0.2 and 0.04, free faces z = ±t/2) have the
// triangulation of rect_016.msh as mid-plane; a 3D run is compared with a plane-stress run on
// rect_016.msh node by node on that plane. The loads keep their numbers: a 2D traction is a
// force per length of a body of unit thickness, i.e. a stress, and so is a 3D traction
// (force per area) on the edge faces y = 1, x = 2 of a slab of any thickness; F and μF are
// stresses in both. So the slab carries the plane-stress state up to through-thickness
// effects that vanish as t → 0, *provided the 2D model is the thin limit of the 3D one*.
//
// It is not for the paper's constants as they stand: (4.2) is the plane-stress reduction of
// B only, while A (4.1) and R = r(s) I are used in 2D as printed. In a slab σ_zz = 0 reads
// ζ tr ε(w) + 2θ ε_zz(w) + λ tr ε(u) + 2μ ε_zz(u) + ε_zz(m) = 0, which ties ε_zz to the
// history, and the in-plane law that results is not of the paper's 2D form. The thin limit
// is exactly a 2D model of the paper's form when (a) every trace coupling vanishes (ν = ζ =
// 0; then B = E τ in both, any kernel) or (b) there is no memory and A ∝ B (ζ/θ = λ/μ), and
// 2D uses the reduced ζ* = 2θζ/(2θ + ζ) next to (4.2) (the same reduction that turns λ into
// Eν/(1 − ν²)). The test asserts (a) and (b) with the rest of the paper's scene unchanged
// (loads, contact, friction with F and μ, E, θ, kernel in (a), h = 1/16, k = 1/32) and prints
// the paper's own constants, which stay ~10% apart at both thicknesses.

/// examples/paper.toml on `mesh` with the keys `edits` set; in 3D with model "3d" and each
/// traction given a z component 0.
fn paper_scene(
    dir: &Path,
    name: &str,
    mesh: &Path,
    three_d: bool,
    edits: &[(&str, toml::Value)],
) -> PathBuf {
    let mut scene = edits
        .iter()
        .fold(SceneText::paper().mesh(mesh), |scene, (key, value)| {
            scene.set(key, value.clone())
        });
    if three_d {
        scene = scene.set("mesh.model", "3d");
        let loads = scene
            .get("load.traction")
            .unwrap()
            .as_array()
            .unwrap()
            .len();
        assert_eq!(loads, 2, "examples/paper.toml has two tractions");
        for i in 0..loads {
            let key = format!("load.traction[{i}].value");
            let mut value = scene.get(&key).unwrap().as_array().unwrap().clone();
            value.push("0".into());
            scene = scene.set(&key, value);
        }
    }
    scene.write(dir, name)
}

/// The differences of the slabs' mid-plane u_N (x, y components) from the plane-stress u_N,
/// for t = 0.2 and t = 0.04: [max-norm, H¹-seminorm, L²] each relative to the 2D field's; H¹
/// and L² over rect_016's triangles of the P1 interpolant of the nodal differences.
fn slab_differences(
    case: &str,
    edits_3d: &[(&str, toml::Value)],
    edits_2d: &[(&str, toml::Value)],
) -> [[f64; 3]; 2] {
    let dir = tempfile::tempdir().unwrap();
    let rect = repo().join("meshes/paper/rect_016.msh");
    let scene2 = paper_scene(dir.path(), "plane_stress.toml", &rect, false, edits_2d);
    let (s2, mesh2, disc2) = load(&scene2, &[]);
    assert_eq!(mesh2.dim, 2);
    let tr2 = trace(&s2, &disc2);
    assert!(tr2.effects.contains(&"contact") && tr2.effects.contains(&"friction"));
    let u2 = nodal_vectors::<2>(&disc2, &tr2.u_final);
    let max2 = u2.iter().flatten().fold(0.0f64, |a, x| a.max(x.abs()));
    let (l2_ref, h1_ref) = p1_norms(&disc2.cells, &u2);
    // slab.geo: the mid-plane nodes (z = 0 exactly) have bit for bit the coordinates of
    // rect_016.msh's nodes.
    let index: HashMap<(u64, u64), usize> = disc2
        .nodes
        .all()
        .iter()
        .enumerate()
        .map(|(i, p)| ((p[0].to_bits(), p[1].to_bits()), i))
        .collect();

    let mut out = [[0.0; 3]; 2];
    for (k, (t, slab)) in [(0.2, "slab_016_t0200.msh"), (0.04, "slab_016_t0040.msh")]
        .into_iter()
        .enumerate()
    {
        let mesh = repo().join("meshes/3d").join(slab);
        let scene = paper_scene(dir.path(), "slab.toml", &mesh, true, edits_3d);
        let (s3, mesh3, disc3) = load(&scene, &[]);
        assert_eq!(mesh3.dim, 3);
        let tr = trace(&s3, &disc3);
        assert_eq!(tr.effects, tr2.effects, "same effects in 2D and 3D");
        let u3 = nodal_vectors::<3>(&disc3, &tr.u_final);
        let mut diff = vec![[f64::NAN; 2]; u2.len()];
        for (i, p) in disc3.nodes.all().iter().enumerate() {
            if p[2] == 0.0 {
                let j = index[&(p[0].to_bits(), p[1].to_bits())];
                diff[j] = [u3[i][0] - u2[j][0], u3[i][1] - u2[j][1]];
            }
        }
        assert!(
            diff.iter().all(|d| d[0].is_finite()),
            "a 2D node has no slab node"
        );
        let dmax = diff.iter().flatten().fold(0.0f64, |a, x| a.max(x.abs())) / max2;
        let (l2, h1) = p1_norms(&disc2.cells, &diff);
        out[k] = [dmax, h1 / h1_ref, l2 / l2_ref];
        println!(
            "{case}, t = {t}: slab mid-plane u_N − plane stress u_N (rect_016, k = 1/32), \
             relative: max-norm {dmax:.3e}, H1-seminorm {:.3e}, L2 {:.3e}",
            out[k][1], out[k][2]
        );
    }
    out
}

#[test]
fn thin_slab_approaches_plane_stress() {
    // (a) ν = ζ = 0, everything else as in examples/paper.toml (memory, contact, friction).
    let edits = [
        ("material.viscosity.zeta", 0.0.into()),
        ("material.elasticity.poisson", 0.0.into()),
    ];
    let [thick, thin] = slab_differences("ν = ζ = 0", &edits, &edits);
    for (k, what) in ["max-norm", "H1", "L2"].iter().enumerate() {
        // Measured: the difference drops by ~10 (8.2e-3 → 7.2e-4 in the max-norm) when t
        // drops by 5; asserted: by at least 3, and below 3e-3 at t = 0.04.
        assert!(
            thin[k] < thick[k] / 3.0,
            "{what}: t = 0.04 {:e} vs t = 0.2 {:e}",
            thin[k],
            thick[k]
        );
        assert!(thin[k] < 3e-3, "{what} at t = 0.04: {:e}", thin[k]);
    }
}

#[test]
fn thin_slab_with_poisson_ratio_approaches_the_matching_plane_stress_model() {
    // (b) ν = 0.3, no memory, A ∝ B: ζ = θ λ/μ in 3D, ζ* = 2θζ/(2θ + ζ) in 2D.
    let (theta, nu): (f64, f64) = (0.1, 0.3);
    let zeta = theta * 2.0 * nu / (1.0 - 2.0 * nu); // λ/μ = 2ν/(1 − 2ν)
    let zeta_2d = 2.0 * theta * zeta / (2.0 * theta + zeta);
    let no_memory: (&str, toml::Value) = ("material.relaxation.enabled", false.into());
    let [thick, thin] = slab_differences(
        "ν = 0.3, A ∝ B, no memory",
        &[("material.viscosity.zeta", zeta.into()), no_memory.clone()],
        &[("material.viscosity.zeta", zeta_2d.into()), no_memory],
    );
    // What is left at t = 0.04 (~1.4%) is mostly the difference of the two discretizations
    // on the same triangles: the slab's ε_zz comes from a continuous P1 u_z, plane stress
    // eliminates it elementwise; it shrinks with h (~0.5% on the slabs of rect_032, measured
    // with meshes/3d/slab.geo at n = 32, not shipped). So the thickness effect is only
    // part of it: measured reductions 16% (max-norm), 24% (H¹), 23% (L²); asserted ≥ 10%,
    // and both within the discretization level of 2.5%.
    for (k, what) in ["max-norm", "H1", "L2"].iter().enumerate() {
        assert!(
            thin[k] < 0.9 * thick[k],
            "{what}: t = 0.04 {:e} vs t = 0.2 {:e}",
            thin[k],
            thick[k]
        );
        assert!(
            thick[k] < 2.5e-2 && thin[k] < 2.5e-2,
            "{what}: {thick:?} {thin:?}"
        );
    }
}

#[test]
fn paper_constants_in_a_thin_slab_are_not_the_papers_plane_stress() {
    // The paper's scene unchanged: printed for the record (see the comment above the section).
    // The difference stays at ~10% for both thicknesses (and on the slabs of rect_032 too):
    // it is the difference of the models, not a discretization or thickness effect. Asserted
    // only that far: it does not shrink like (a) does.
    let [thick, thin] = slab_differences("paper's constants", &[], &[]);
    assert!(
        thin[0] > 0.5 * thick[0] && thin[0] > 0.05,
        "{thick:?} {thin:?}"
    );
}

// ---- 4. output of a 3D run ---------------------------------------------------------------

fn run_block(out: &Path, mesh: &str, steps: usize) {
    let o = Command::new(BIN)
        .current_dir(repo())
        .args(["run", "examples/block.toml", "--quiet", "--out"])
        .arg(out)
        .args(["--set", &format!("mesh.file={}", mesh_path(mesh))])
        .args(["--set", &format!("time.steps={steps}")])
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "viscontact run: {:?}\n{}",
        o.status.code(),
        String::from_utf8_lossy(&o.stderr)
    );
}

#[test]
fn three_d_run_writes_tetra_frames() {
    let steps = 4;
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    run_block(&out, "3d/block_004.msh", steps);

    // The same scene through the library: the last frame must hold its u_N.
    let overrides = [
        format!("mesh.file={}", mesh_path("3d/block_004.msh")),
        format!("time.steps={steps}"),
    ];
    let o: Vec<&str> = overrides.iter().map(String::as_str).collect();
    let (scene, mesh, disc) = load(&repo().join("examples/block.toml"), &o);
    let tr = trace(&scene, &disc);
    let u_lib = disc.nodal(&tr.u_final);

    let pvd = std::fs::read_to_string(out.join("solution.pvd")).unwrap();
    assert_eq!(pvd.matches("<DataSet").count(), steps + 1, "{pvd}");
    let path = out.join(format!("solution_{steps:06}.vtu"));
    // The frames are raw appended zlib data, which vtkio's parser cannot read (it stops at a
    // `<` byte in the binary); the crate's reader (also `plot`'s) reads them, and
    // tests/formats/output_format.rs reads every layout with VTK's own reader.
    let vtu = viscontact::output::read::read_vtu(&path).unwrap();
    // block_004: 9·5·5 nodes, 12·4³ tetrahedra.
    let points: Vec<f64> = vtu.points.iter().flatten().copied().collect();
    assert_eq!(points.len(), 3 * 225);
    let nc = 768;
    assert_eq!(vtu.cells.len(), nc);
    assert!(vtu.cells.iter().all(|c| c.len() == 4));
    let connectivity: Vec<u64> = vtu.cells.iter().flatten().map(|&i| i as u64).collect();
    // The cells as written are positively oriented tetrahedra filling the block's volume 2.
    let pt = |k: u64| -> V3 { [0, 1, 2].map(|c| points[3 * k as usize + c]) };
    let mut volume = 0.0;
    for c in connectivity.chunks(4) {
        let v = vol6([pt(c[0]), pt(c[1]), pt(c[2]), pt(c[3])]) / 6.0;
        assert!(v > 0.0);
        volume += v;
    }
    assert!((volume - 2.0).abs() < 1e-12, "{volume}");

    let field = |attrs: &[viscontact::output::read::Array], name: &str| -> (usize, Vec<f64>) {
        let a = attrs
            .iter()
            .find(|a| a.name == name)
            .unwrap_or_else(|| panic!("no field {name}"));
        (a.components, a.values.clone())
    };
    let names: Vec<&str> = vtu.point_data.iter().map(|a| a.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "displacement",
            "velocity",
            "contact_pressure",
            "friction_traction",
            "contact_state"
        ]
    );
    let names: Vec<&str> = vtu.cell_data.iter().map(|a| a.name.as_str()).collect();
    assert_eq!(names, ["stress", "von_mises", "region"]);
    let np = 225;
    let (c, u) = field(&vtu.point_data, "displacement");
    assert_eq!((c, u.len()), (3, 3 * np));
    let d = rel_diff(&u, &u_lib);
    assert!(d < 1e-12, "displacement: file vs library run {d:e}");
    assert!(
        u.iter().skip(2).step_by(3).any(|&z| z != 0.0),
        "u_z is written"
    );
    let (c, w) = field(&vtu.point_data, "velocity");
    assert_eq!((c, w.len()), (3, 3 * np));

    // Contact output: pressure ≥ 0 on Γ3,1 only; friction traction tangential to the bottom
    // (z component 0) and bounded by μF = 0.5 · 0.01 (|γ_i| ≤ c_i = μF ∫φ_i), on Γ3,2 only.
    let nodes_of = |key: &str| -> BTreeSet<usize> {
        mesh.group_nodes(mesh.boundary_group(key).unwrap())
            .into_iter()
            .collect()
    };
    let (g31, g32) = (nodes_of("Γ3,1"), nodes_of("Γ3,2"));
    let (c, p) = field(&vtu.point_data, "contact_pressure");
    assert_eq!((c, p.len()), (1, np));
    let (c, ft) = field(&vtu.point_data, "friction_traction");
    assert_eq!((c, ft.len()), (3, 3 * np));
    let (c, state) = field(&vtu.point_data, "contact_state");
    assert_eq!((c, state.len()), (1, np));
    let mu_f = 0.5 * 0.01;
    let mut sliding_or_sticking = 0;
    for i in 0..np {
        let t = [ft[3 * i], ft[3 * i + 1], ft[3 * i + 2]];
        if !g31.contains(&i) {
            assert_eq!(p[i], 0.0, "pressure off Γ3,1 at node {i}");
        }
        assert!(p[i] >= -1e-12, "negative pressure {} at node {i}", p[i]);
        if g32.contains(&i) {
            assert!(t[2].abs() <= 1e-12 * norm(t), "node {i}: {t:?}");
            assert!(
                norm(t) <= mu_f * (1.0 + 1e-6),
                "node {i}: |τ| = {}",
                norm(t)
            );
            if norm(t) > 0.0 {
                sliding_or_sticking += 1;
            }
        } else {
            assert_eq!(t, [0.0; 3], "friction off Γ3,2 at node {i}");
        }
        assert!(state[i] == 0.0 || state[i] == 1.0);
    }
    assert!(sliding_or_sticking > 0, "no friction traction at all");

    let (c, s) = field(&vtu.cell_data, "stress");
    assert_eq!((c, s.len()), (6, 6 * nc));
    let (c, vm) = field(&vtu.cell_data, "von_mises");
    assert_eq!((c, vm.len()), (1, nc));
    for (k, s) in s.chunks(6).enumerate() {
        let want = (0.5 * ((s[0] - s[1]).powi(2) + (s[1] - s[2]).powi(2) + (s[2] - s[0]).powi(2))
            + 3.0 * (s[3] * s[3] + s[4] * s[4] + s[5] * s[5]))
            .sqrt();
        assert!((vm[k] - want).abs() <= 1e-12 * want.max(1e-300), "cell {k}");
    }
    // A 3D stress has σ_zz ≠ 0 (unlike plane stress).
    assert!(s.iter().skip(2).step_by(6).any(|&x| x != 0.0));
}

// ---- 5. the command line -----------------------------------------------------------------

fn viscontact(args: &[&str]) -> (String, String) {
    let o = Command::new(BIN)
        .current_dir(repo())
        .args(args)
        .output()
        .unwrap();
    let (out, err) = (
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    );
    assert_eq!(
        o.status.code(),
        Some(0),
        "viscontact {args:?}\n{out}\n{err}"
    );
    (out, err)
}

#[test]
fn mesh_info_reports_the_3d_block() {
    let n = 8usize;
    let (out, _) = viscontact(&["mesh-info", "meshes/3d/block_008.msh"]);
    assert!(
        out.contains("3D: 1377 nodes, 6144 tetrahedra (0 reoriented"),
        "{out}"
    );
    for (g, faces, area) in [
        ("Γ1", 2 * n * n, "1.000000"),
        ("Γ2", 14 * n * n, "7.000000"),
        ("Γ3,1", 2 * n * n, "1.000000"),
        ("Γ3,2", 2 * n * n, "1.000000"),
        ("top", 4 * n * n, "2.000000"),
        ("right", 2 * n * n, "1.000000"),
        ("sides", 8 * n * n, "4.000000"),
    ] {
        let line = out
            .lines()
            .find(|l| l.split_whitespace().next() == Some(g))
            .unwrap_or_else(|| panic!("no line for {g}:\n{out}"));
        assert!(line.contains(&format!("{faces} faces")), "{line}");
        assert!(line.contains(&format!("area {area}")), "{line}");
    }
    assert!(out.contains("dihedral angle"), "{out}");

    let (out, _) = viscontact(&["mesh-info", "meshes/3d/block_008.msh", "--json"]);
    let v: serde_json::Value = serde_json::from_str(&out).expect("JSON");
    assert_eq!(v["dim"], 3);
    assert_eq!(v["nodes"], 1377);
    assert_eq!(v["tetrahedra"], 6144);
    assert_eq!(v["reoriented"], 0);
    let groups = v["groups"].as_array().unwrap();
    let area = |name: &str| -> &serde_json::Value {
        let g = groups.iter().find(|g| g["name"] == name).unwrap();
        &g["area"]
    };
    for (g, a) in [
        ("Γ1", 1.0),
        ("Γ2", 7.0),
        ("Γ3,1", 1.0),
        ("top", 2.0),
        ("sides", 4.0),
    ] {
        let got = area(g).as_f64().unwrap();
        assert!((got - a).abs() < 1e-12, "{g}: {got}");
    }
    let omega = groups.iter().find(|g| g["name"] == "Ω").unwrap();
    assert_eq!(
        (omega["dim"].as_u64(), omega["elements"].as_u64()),
        (Some(3), Some(6144))
    );
    assert!(omega["area"].is_null());
    // Every tetrahedron has volume h³/6.
    let want = 1.0 / (6.0 * (n * n * n) as f64);
    for key in ["min_volume", "max_volume"] {
        let got = v["quality"][key].as_f64().unwrap();
        assert!((got - want).abs() < 1e-12 * want, "{key}: {got}");
    }
}

#[test]
fn check_names_the_3d_block_scene() {
    let n = 8usize;
    let (out, _) = viscontact(&["check", "examples/block.toml"]);
    let nodes = (2 * n + 1) * (n + 1) * (n + 1);
    // Γ1 (x = 0) holds (n+1)² nodes; 3 dofs per other node.
    let dofs = 3 * (nodes - (n + 1) * (n + 1));
    let mesh_line = out.lines().find(|l| l.starts_with("mesh")).unwrap();
    assert!(
        mesh_line.contains(&format!(
            "3D, {nodes} nodes, {} tetrahedra, {dofs} free dofs",
            12 * n * n * n
        )),
        "{mesh_line}"
    );
    let effects = out.lines().find(|l| l.starts_with("effects")).unwrap();
    for e in [
        "contact",
        "friction",
        "memory",
        "normal_stress",
        "tractions",
    ] {
        assert!(effects.contains(e), "{effects}");
    }
    // One contact row per Γ3,1 node off Γ1 ((n+1)² − (n+1)), two tangent rows per Γ3,2 node.
    let solver = out.lines().find(|l| l.starts_with("solver")).unwrap();
    let rows = format!(
        "{} Γ3,1 rows + {} Γ3,2 rows",
        (n + 1) * (n + 1) - (n + 1),
        2 * (n + 1) * (n + 1)
    );
    assert!(solver.contains(&rows), "{solver}");
}
