//! Mesh import: the shipped gmsh meshes, group lookup, normals, and every bad-mesh fixture.

use crate::common::{self, repo};
use std::path::Path;

use viscontact::mesh::{Group, Mesh};
use viscontact::Error;

fn read(rel: &str) -> Mesh {
    let path = repo().join(rel);
    Mesh::read(&path).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

/// Reads a mesh that must be refused with an input error; returns the message after checking
/// that it names the file and contains every one of `needles`.
fn refused(path: &Path, needles: &[&str]) -> String {
    let err = match Mesh::read(path) {
        Ok(m) => panic!(
            "{} was accepted ({} triangles)",
            path.display(),
            m.triangles.len()
        ),
        Err(e) => e,
    };
    let Error::Input(msg) = &err else {
        panic!("{}: not an input error: {err:?}", path.display())
    };
    assert_eq!(err.exit_code(), 2);
    assert!(
        msg.contains(&path.display().to_string()),
        "message does not name the file {}: {msg}",
        path.display()
    );
    eprintln!("{msg}");
    for n in needles {
        assert!(msg.contains(n), "message lacks '{n}': {msg}");
    }
    msg.clone()
}

fn signed_area(m: &Mesh, t: [usize; 3]) -> f64 {
    let [a, b, c] = t.map(|i| m.nodes[i]);
    0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
}

fn total_area(m: &Mesh) -> f64 {
    m.triangles.iter().map(|&t| signed_area(m, t)).sum()
}

fn boundary_length(m: &Mesh, g: &Group) -> f64 {
    g.facets.iter().map(|&f| m.facet_length(f)).sum()
}

/// Every facet of a boundary group is an edge of a triangle whose third vertex lies on its
/// left, i.e. strictly inside the outward normal's opposite half plane.
fn assert_oriented(m: &Mesh, g: &Group) {
    for &[a, b] in &g.facets {
        let tri = m
            .triangles
            .iter()
            .find(|t| t.contains(&a) && t.contains(&b))
            .unwrap_or_else(|| panic!("facet {a}-{b} of {:?} is no triangle edge", g.name));
        let c = *tri.iter().find(|&&v| v != a && v != b).unwrap();
        assert!(
            signed_area(m, [a, b, c]) > 0.0,
            "facet {a}-{b} wrongly oriented"
        );
    }
}

fn assert_normals(m: &Mesh, key: &str, expected: [f64; 2]) {
    let g = m.boundary_group(key).unwrap();
    assert!(!g.facets.is_empty(), "{key} has no facets");
    for &f in &g.facets {
        assert_eq!(m.facet_normal(f), expected, "{key}: facet {f:?}");
    }
    let (normals, kink) = m.nodal_normals(g);
    assert_eq!(
        normals.len(),
        g.facets.len() + 1,
        "{key}: an open straight chain"
    );
    assert_eq!(kink, 0.0, "{key}: a straight group has no kink");
    for (node, n) in normals {
        assert_eq!(
            n,
            [expected[0], expected[1], 0.0],
            "{key}: nodal normal at node {node}"
        );
    }
    assert_oriented(m, g);
}

fn check_paper_rect(m: &Mesh, n: usize) {
    let name = m.path.display();
    assert_eq!(m.dim, 2);
    assert_eq!(m.nodes.len(), (n + 1) * (n + 1), "{name}: nodes");
    assert_eq!(m.triangles.len(), 2 * n * n, "{name}: triangles");
    assert_eq!(
        m.flipped, 0,
        "{name}: gmsh writes counter-clockwise triangles"
    );
    assert!(m.triangles.iter().all(|&t| signed_area(m, t) > 0.0));
    assert!(
        (total_area(m) - 2.0).abs() < 1e-12,
        "{name}: area {}",
        total_area(m)
    );
    let names: Vec<String> = m.groups.iter().map(Mesh::display_name).collect();
    assert_eq!(
        names,
        ["Γ1", "Γ2", "Γ3,1", "Γ3,2", "top", "right", "Ω"],
        "{name}: groups in file order"
    );
    let edges = |key: &str| m.boundary_group(key).unwrap().facets.len();
    assert_eq!(edges("Γ1"), n);
    assert_eq!(edges("Γ2"), 2 * n);
    assert_eq!(edges("Γ3,1"), n / 2);
    assert_eq!(edges("Γ3,2"), n / 2);
    assert_eq!(edges("top"), n);
    assert_eq!(edges("right"), n);
    let omega = m.group("Ω").unwrap();
    assert_eq!((omega.dim, omega.tag), (2, 10));
    assert_eq!(omega.cells.len(), 2 * n * n);
    assert!(omega.facets.is_empty());
    assert_eq!(m.group_nodes(omega).len(), m.nodes.len());

    assert_normals(m, "Γ3,1", [0.0, -1.0]);
    assert_normals(m, "Γ3,2", [0.0, -1.0]);
    assert_normals(m, "Γ1", [-1.0, 0.0]);
    assert_normals(m, "top", [0.0, 1.0]);
    assert_normals(m, "right", [1.0, 0.0]);
    // The bottom groups meet at (1, 0); Γ3,1 spans x in [0, 1].
    let contact = m.boundary_group("Γ3,1").unwrap();
    let xs: Vec<f64> = m
        .group_nodes(contact)
        .iter()
        .map(|&i| m.nodes[i][0])
        .collect();
    assert_eq!(xs.len(), n / 2 + 1);
    assert!(xs.iter().all(|&x| (0.0..=1.0).contains(&x)));
    assert!(m.group_nodes(contact).iter().all(|&i| m.nodes[i][1] == 0.0));
    // The whole boundary: perimeter 6.
    let perimeter: f64 = ["Γ1", "Γ2", "Γ3,1", "Γ3,2"]
        .iter()
        .map(|k| boundary_length(m, m.boundary_group(k).unwrap()))
        .sum();
    assert!((perimeter - 6.0).abs() < 1e-12);
}

#[test]
fn paper_rectangles() {
    let mut read_any = 0;
    for n in [8, 16, 32, 64, 128] {
        let rel = format!("meshes/paper/rect_{n:03}.msh");
        if n != 8 && !repo().join(&rel).exists() {
            continue;
        }
        check_paper_rect(&read(&rel), n);
        read_any += 1;
    }
    assert!(read_any >= 1);
    check_paper_rect(&read("tests/data/rect_004.msh"), 4);
}

/// Boundary edges of the triangle mesh, each as the counter-clockwise directed edge.
fn boundary_edges(m: &Mesh) -> std::collections::BTreeSet<[usize; 2]> {
    let mut count = std::collections::HashMap::new();
    for t in &m.triangles {
        for i in 0..3 {
            let (a, b) = (t[i], t[(i + 1) % 3]);
            count.entry([a.min(b), a.max(b)]).or_insert((0, [a, b])).0 += 1;
        }
    }
    count
        .into_values()
        .filter(|v| v.0 == 1)
        .map(|v| v.1)
        .collect()
}

/// Every shipped mesh reads, counter-clockwise, and Γ1, Γ2, Γ3,1, Γ3,2 partition its boundary.
#[test]
fn every_shipped_mesh_reads_and_its_boundary_is_partitioned() {
    let files = common::shipped_meshes();
    assert!(files.len() >= 3, "{files:?}");
    for path in &files {
        let m = Mesh::read(path).unwrap_or_else(|e| panic!("{e}"));
        if m.dim == 3 {
            continue; // the 3D meshes are checked in tests/solutions/three_d.rs
        }
        let name = path.display();
        assert_eq!(m.flipped, 0, "{name}");
        assert!(
            m.quality().min_angle_deg > 15.0,
            "{name}: {:?}",
            m.quality()
        );
        let mut union = std::collections::BTreeSet::new();
        for key in ["Gamma1", "Gamma2", "Gamma3_1", "Gamma3_2"] {
            let g = m.boundary_group(key).unwrap_or_else(|e| panic!("{e}"));
            assert!(!g.facets.is_empty(), "{name}: {key} empty");
            for &f in &g.facets {
                assert!(
                    union.insert(f),
                    "{name}: facet {f:?} in two of the Γ groups"
                );
            }
        }
        assert_eq!(
            union,
            boundary_edges(&m),
            "{name}: Γ1 ∪ Γ2 ∪ Γ3 is the boundary"
        );
    }
}

#[test]
fn paper_rectangle_quality() {
    // Right triangles with legs 2/8 and 1/8.
    let q = read("meshes/paper/rect_008.msh").quality();
    assert!(
        (q.min_angle_deg - 0.5f64.atan().to_degrees()).abs() < 1e-9,
        "{q:?}"
    );
    assert!((q.min_area - 1.0 / 64.0).abs() < 1e-15, "{q:?}");
    assert!((q.max_area - 1.0 / 64.0).abs() < 1e-15, "{q:?}");
    // ℓ_max · perimeter / (4√3 · area) for legs a = 1/4, b = 1/8.
    let (a, b) = (0.25f64, 0.125f64);
    let c = a.hypot(b);
    let expected = c * (a + b + c) / (4.0 * 3f64.sqrt() * (a * b / 2.0));
    assert!((q.max_aspect_ratio - expected).abs() < 1e-9, "{q:?}");
}

#[test]
fn ascii_and_binary_give_the_same_mesh() {
    let ascii = read("meshes/paper/rect_016.msh");
    let mut binary = read("meshes/paper/rect_016_binary.msh");
    assert_ne!(ascii.path, binary.path);
    binary.path = ascii.path.clone();
    assert_eq!(ascii, binary);
    check_paper_rect(&binary, 16);
}

#[test]
fn groups_by_name_alias_and_tag() {
    let m = read("meshes/paper/rect_008.msh");
    for key in [
        "Γ3,1",
        "Gamma3_1",
        "gamma3,1",
        "Γ3_1",
        "GAMMA3_1",
        " Gamma 3,1 ",
        "3",
    ] {
        let g = m.group(key).unwrap_or_else(|e| panic!("{key}: {e}"));
        assert_eq!(g.name.as_deref(), Some("Γ3,1"), "{key}");
        assert_eq!(m.boundary_group(key).unwrap().tag, 3, "{key}");
    }
    assert_eq!(m.group("Gamma1").unwrap().name.as_deref(), Some("Γ1"));
    assert_eq!(m.group("gamma3_2").unwrap().tag, 4);
    assert_eq!(m.group("TOP").unwrap().name.as_deref(), Some("top"));
    let omega = m.group("10").unwrap();
    assert_eq!((omega.dim, Mesh::display_name(omega)), (2, "Ω".to_string()));
    assert_eq!(
        m.group("ω").map(|g| g.tag).ok(),
        None,
        "no Unicode case folding"
    );

    // A surface group is not a boundary group.
    let Err(Error::Input(msg)) = m.boundary_group("Ω") else {
        panic!("Ω accepted as a boundary group")
    };
    assert!(
        msg.contains("surface") && msg.contains("\"Γ1\" (tag 1, curve, 8 edges)"),
        "{msg}"
    );

    // An unknown key: the message names the file and the key and lists the groups.
    let Err(Error::Input(msg)) = m.group("Γ3,3") else {
        panic!("Γ3,3 found")
    };
    for needle in [
        "rect_008.msh",
        "'Γ3,3'",
        "\"Γ1\" (tag 1, curve, 8 edges)",
        "\"Γ3,2\" (tag 4, curve, 4 edges)",
        "\"Ω\" (tag 10, surface, 128 triangles)",
        "rename",
    ] {
        assert!(msg.contains(needle), "lacks {needle}: {msg}");
    }
    assert!(m.group("11").is_err());
}

#[test]
fn missing_group_is_reported_with_the_groups_present() {
    let path = repo().join("tests/data/no_contact_group.msh");
    let m = Mesh::read(&path).unwrap();
    assert!(m.group("Γ3,2").is_ok());
    let err = m.boundary_group("Gamma3_1").unwrap_err();
    let msg = err.to_string();
    assert_eq!(err.exit_code(), 2);
    assert!(msg.contains(&path.display().to_string()), "{msg}");
    assert!(
        msg.contains("'Gamma3_1'") && msg.contains("\"Γ3,2\""),
        "{msg}"
    );
    assert!(!msg.contains("\"Γ3,1\""), "{msg}");
}

#[test]
fn inverted_triangle_is_flipped() {
    let m = read("tests/data/inverted.msh");
    assert_eq!(m.flipped, 1);
    assert_eq!((m.nodes.len(), m.triangles.len()), (9, 8));
    assert!(m.triangles.iter().all(|&t| signed_area(&m, t) > 0.0));
    assert!((total_area(&m) - 2.0).abs() < 1e-12);
    assert_normals(&m, "Γ3,1", [0.0, -1.0]);
    assert_normals(&m, "Γ1", [-1.0, 0.0]);
    // Reading the same mesh without the inversion gives the same triangles up to rotation.
    let good = read("tests/data/rect_004.msh");
    assert_eq!(good.flipped, 0);
}

#[test]
fn all_clockwise_mesh_with_saveall() {
    let m = read("tests/data/mesh_import/clockwise_saveall.msh");
    assert!(m.triangles.len() >= 4);
    assert_eq!(
        m.flipped,
        m.triangles.len(),
        "gmsh wrote every triangle clockwise"
    );
    assert!(m.triangles.iter().all(|&t| signed_area(&m, t) > 0.0));
    assert!((total_area(&m) - 1.0).abs() < 1e-12);
    assert!(
        m.nodes.all().iter().all(|p| p[0] <= 1.0 && p[1] <= 1.0),
        "point (3, 3) dropped"
    );
    let names: Vec<String> = m.groups.iter().map(Mesh::display_name).collect();
    assert_eq!(
        names,
        ["bottom", "left", "square"],
        "the point group is ignored"
    );
    assert_normals(&m, "bottom", [0.0, -1.0]);
    assert_normals(&m, "left", [-1.0, 0.0]);
    assert!(m.group("corner").is_err());
    assert_eq!(m.group("square").unwrap().cells.len(), m.triangles.len());
}

#[test]
fn sparse_tags_unused_nodes_duplicates_and_names_with_commas() {
    let m = read("tests/data/mesh_import/sparse_tags.msh");
    // Node 99 is not used by any triangle; file order 20, 10, 40, 30 gives indices 0..3.
    assert_eq!(
        m.nodes.all(),
        vec![
            [1.0, 0.0, 0.0],
            [0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 1.0, 0.0]
        ]
    );
    assert_eq!(m.flipped, 1);
    assert_eq!(m.triangles, vec![[1, 0, 3], [1, 3, 2]]);
    let bottom = m.boundary_group("bottom").unwrap();
    assert_eq!(
        bottom.facets,
        vec![[1, 0]],
        "listed twice, kept once, body on the left"
    );
    let left = m.boundary_group("left edge, fixed").unwrap();
    assert_eq!(left.facets, vec![[2, 1]]);
    assert_eq!(m.facet_normal(left.facets[0]), [-1.0, 0.0]);
    assert_eq!(m.group("leftedge_fixed").unwrap().tag, 2);
    assert_eq!(m.group("body").unwrap().cells, vec![0, 1]);
    assert_eq!(m.group_nodes(m.group("2").unwrap()), vec![1, 2]);
}

#[test]
fn nodal_normals_and_kinks() {
    let m = read("meshes/paper/rect_008.msh");
    // Γ2 = top + right: a 90° corner at (2, 1).
    let g2 = m.boundary_group("Γ2").unwrap();
    let (normals, kink) = m.nodal_normals(g2);
    assert_eq!(normals.len(), 2 * 8 + 1);
    assert!((kink - 90.0).abs() < 1e-12, "{kink}");
    assert!(
        normals.windows(2).all(|w| w[0].0 < w[1].0),
        "sorted by node"
    );
    for &(node, n) in &normals {
        assert!((n[0].hypot(n[1]) - 1.0).abs() < 1e-15);
        let p = m.nodes[node];
        if p[0] == 2.0 && p[1] == 1.0 {
            // length-weighted: top facets are 2/8 long, right facets 1/8.
            let expected = [1.0 / 5f64.sqrt(), 2.0 / 5f64.sqrt()];
            assert!((n[0] - expected[0]).abs() < 1e-15 && (n[1] - expected[1]).abs() < 1e-15);
        }
    }
    // A surface group has no boundary normals.
    assert_eq!(m.nodal_normals(m.group("Ω").unwrap()), (vec![], 0.0));
}

#[test]
fn plate_with_hole_normals_point_into_the_hole() {
    let m = read("meshes/plate_hole/plate_hole.msh");
    assert_eq!(m.flipped, 0);
    let (c, r) = ([1.0, 0.55], 0.2);
    let hole = m.boundary_group("hole").unwrap();
    assert!(hole.facets.len() >= 16);
    assert_oriented(&m, hole);
    for &f in &hole.facets {
        let n = m.facet_normal(f);
        let p = m.nodes[f[0]];
        assert!((c[0] - p[0]) * n[0] + (c[1] - p[1]) * n[1] > 0.0);
    }
    let (normals, kink) = m.nodal_normals(hole);
    assert_eq!(normals.len(), hole.facets.len(), "a closed curve");
    assert!(kink > 0.0 && kink < 30.0, "{kink}");
    for (node, n) in normals {
        let p = m.nodes[node];
        assert!(
            ((p[0] - c[0]).hypot(p[1] - c[1]) - r).abs() < 1e-9,
            "on the circle"
        );
        let radial_in = [(c[0] - p[0]) / r, (c[1] - p[1]) / r];
        let cos = n[0] * radial_in[0] + n[1] * radial_in[1];
        assert!(
            cos > 0.99,
            "node {node}: normal {n:?}, inward radial {radial_in:?}"
        );
    }
    // Domain area: 2 - π r² up to the polygonal approximation of the circle.
    let area = total_area(&m);
    let exact = 2.0 - std::f64::consts::PI * r * r;
    assert!(area > exact && area < exact + 0.01, "{area}");
    assert_normals(&m, "Γ1", [-1.0, 0.0]);
    assert_normals(&m, "Γ3,1", [0.0, -1.0]);
    for key in ["Γ1", "Γ2", "Γ3,1", "Γ3,2", "top", "right"] {
        assert!(!m.boundary_group(key).unwrap().facets.is_empty(), "{key}");
    }
    // Γ2 holds the hole, the top and the right side.
    let g2 = m.boundary_group("Γ2").unwrap();
    let parts: usize = ["hole", "top", "right"]
        .iter()
        .map(|k| m.boundary_group(k).unwrap().facets.len())
        .sum();
    assert_eq!(g2.facets.len(), parts);
}

#[test]
fn bracket_reads_with_all_groups() {
    let rel = "meshes/bracket/bracket.msh";
    let m = read(rel);
    assert_eq!(m.flipped, 0);
    assert!(m.triangles.iter().all(|&t| signed_area(&m, t) > 0.0));
    for key in ["Gamma1", "Gamma2", "Gamma3_1", "Gamma3_2"] {
        let g = m.boundary_group(key).unwrap();
        assert!(!g.facets.is_empty(), "{key}");
        assert_oriented(&m, g);
    }
    let q = m.quality();
    assert!(q.min_angle_deg > 10.0 && q.min_area > 0.0, "{q:?}");
}

#[test]
fn msh22_is_refused_with_the_conversion_command() {
    let path = repo().join("tests/data/msh22.msh");
    refused(&path, &["version 2.2", "-save -format msh41 -o"]);
}

#[test]
fn converted_msh22_with_dense_unordered_node_tags() {
    let m = read("tests/data/mesh_import/msh22_converted.msh");
    assert_eq!((m.nodes.len(), m.triangles.len(), m.flipped), (9, 8, 0));
    assert!((total_area(&m) - 2.0).abs() < 1e-12);
    assert!(m.triangles.iter().all(|&t| signed_area(&m, t) > 0.0));
    let edges = |k: &str| m.boundary_group(k).unwrap().facets.len();
    assert_eq!(
        ["Γ1", "Γ2", "Γ3,1", "Γ3,2", "top", "right"].map(edges),
        [2, 4, 1, 1, 2, 2]
    );
    assert_normals(&m, "right", [1.0, 0.0]);
    assert_normals(&m, "top", [0.0, 1.0]);
    assert_normals(&m, "Gamma3_2", [0.0, -1.0]);
}

/// The conversion command in the MSH 2.2 message works (needs the gmsh CLI; skipped without).
#[test]
fn msh22_conversion_hint_works() {
    if std::process::Command::new("gmsh")
        .arg("--version")
        .output()
        .is_err()
    {
        eprintln!("gmsh not on PATH: conversion hint not exercised");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let old = dir.path().join("old mesh.msh");
    std::fs::copy(repo().join("tests/data/msh22.msh"), &old).unwrap();
    let msg = refused(&old, &["-format msh41"]);
    let command = msg.split('`').nth(1).expect("a command in backticks");
    let status = std::process::Command::new("sh")
        .args(["-c", &format!("{command} -v 0")])
        .status()
        .unwrap();
    assert!(status.success(), "{command}");
    let new = read_abs(&dir.path().join("old mesh_msh41.msh"));
    assert_eq!((new.nodes.len(), new.triangles.len()), (9, 8));
    assert_eq!(new.boundary_group("Gamma3_1").unwrap().facets.len(), 1);
}

fn read_abs(path: &Path) -> Mesh {
    Mesh::read(path).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn quadratic_triangles_are_refused() {
    let path = repo().join("tests/data/quadratic.msh");
    refused(
        &path,
        &[
            "6-node (quadratic) triangles (gmsh element type 9)",
            "P1 triangles",
            "gmsh -2 -order 1",
        ],
    );
}

#[test]
fn zero_area_triangle_is_refused() {
    let path = repo().join("tests/data/zero_area.msh");
    refused(
        &path,
        &["triangle 10", "zero area", "(1, 0.5)", "(1, 0)", "(1, 1)"],
    );
}

#[test]
fn truncated_files_are_refused() {
    refused(&repo().join("tests/data/truncated.msh"), &["truncated"]);
    // A binary file cut in the middle of $Nodes and of $Elements.
    let bytes = std::fs::read(repo().join("meshes/paper/rect_016_binary.msh")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    for frac in [0.3, 0.5, 0.9, 0.999] {
        let path = dir.path().join(format!("cut_{frac}.msh"));
        std::fs::write(&path, &bytes[..(bytes.len() as f64 * frac) as usize]).unwrap();
        refused(&path, &["truncated"]);
    }
}

#[test]
fn missing_file_is_refused() {
    let path = repo().join("tests/data/no_such_mesh.msh");
    refused(
        &path,
        &[
            "cannot read mesh file",
            "no_such_mesh.msh",
            "No such file or directory",
        ],
    );
}

#[test]
fn boundary_group_off_the_boundary_is_refused_where_it_is_used() {
    // The mesh reads (mesh-info shows it); the group is refused as a boundary group.
    let path = repo().join("tests/data/mesh_import/interior_edge.msh");
    let mesh = Mesh::read(&path).unwrap();
    let err = mesh.boundary_group("diagonal").unwrap_err().to_string();
    for needle in ["\"diagonal\"", "(0, 0)–(1, 1)", "not on the boundary"] {
        assert!(err.contains(needle), "{err}");
    }
}

#[test]
fn folded_mesh_is_refused() {
    let path = repo().join("tests/data/mesh_import/folded.msh");
    refused(&path, &["folds over itself", "triangles 1 and 2"]);
}

#[test]
fn garbage_is_refused_without_panic() {
    let dir = tempfile::tempdir().unwrap();
    let head = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n";
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("empty", vec![], "not a gmsh MSH file"),
        ("text", b"hello\n".to_vec(), "not a gmsh MSH file"),
        ("header_only", head.into(), "no $Nodes"),
        (
            "bad_version_line",
            b"$MeshFormat\n4.1\n$EndMeshFormat\n".to_vec(),
            "malformed",
        ),
        (
            "msh4.0",
            b"$MeshFormat\n4 0 8\n$EndMeshFormat\n".to_vec(),
            "version 4",
        ),
        (
            "bad_size_t",
            b"$MeshFormat\n4.1 1 3\n\x01\x00\x00\x00\n$EndMeshFormat\n".to_vec(),
            "data-size",
        ),
        (
            "empty_nodes",
            format!("{head}$Nodes\n0 0 0 0\n$EndNodes\n$Elements\n0 0 0 0\n$EndElements\n").into(),
            "has no nodes",
        ),
        (
            "second_empty_nodes",
            format!(
                "{head}$Nodes\n1 1 1 1\n2 1 0 1\n1\n0 0 0\n$EndNodes\n$Nodes\n0 0 1 1\n$EndNodes\n"
            )
            .into(),
            "has no nodes",
        ),
        (
            "cut_after_nodes",
            format!("{head}$Nodes\n1 1 1 1\n2 1 0 1\n1\n0 0 0\n$EndNodes\n").into(),
            "no $Elements section; it looks truncated",
        ),
        (
            "zero_count_nonzero_tags",
            format!("{head}$Nodes\n0 0 1 1\n$EndNodes\n").into(),
            "has no nodes",
        ),
        (
            "lines_only",
            format!(
                "{head}$Nodes\n1 2 1 2\n1 1 0 2\n1\n2\n0 0 0\n1 0 0\n$EndNodes\n\
                 $Elements\n1 1 1 1\n1 1 1 1\n1 1 2\n$EndElements\n"
            )
            .into(),
            "contains no triangles",
        ),
        (
            "unknown_node",
            format!(
                "{head}$Nodes\n1 3 1 3\n2 1 0 3\n1\n2\n3\n0 0 0\n1 0 0\n0 1 0\n$EndNodes\n\
                 $Elements\n1 1 1 1\n2 1 2 1\n1 1 2 7\n$EndElements\n"
            )
            .into(),
            "refers to node 7",
        ),
        (
            "flat_tetrahedron",
            format!(
                "{head}$Nodes\n1 4 1 4\n3 1 0 4\n1\n2\n3\n4\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n\
                 $EndNodes\n$Elements\n1 1 1 1\n3 1 4 1\n1 1 2 3 4\n$EndElements\n"
            )
            .into(),
            "tetrahedron 1 (gmsh element tag) has zero volume",
        ),
        (
            "not_planar",
            format!(
                "{head}$Nodes\n1 3 1 3\n2 1 0 3\n1\n2\n3\n0 0 0\n1 0 0\n0 1 1\n$EndNodes\n\
                 $Elements\n1 1 1 1\n2 1 2 1\n1 1 2 3\n$EndElements\n"
            )
            .into(),
            "xy-plane",
        ),
        (
            "bad_names",
            format!(
                "{head}$PhysicalNames\n2\n1 1 \"a\"\n$EndPhysicalNames\n$Nodes\n1 3 1 3\n\
                 2 1 0 3\n1\n2\n3\n0 0 0\n1 0 0\n0 1 0\n$EndNodes\n$Elements\n1 1 1 1\n\
                 2 1 2 1\n1 1 2 3\n$EndElements\n"
            )
            .into(),
            "$PhysicalNames",
        ),
    ];
    for (name, content, needle) in cases {
        let path = dir.path().join(format!("{name}.msh"));
        std::fs::write(&path, content).unwrap();
        refused(&path, &[needle]);
    }
}

#[test]
fn empty_boundary_group_is_refused_where_a_condition_needs_it() {
    // A group named in $PhysicalNames that no curve carries would silently drop its
    // boundary condition.
    let text = std::fs::read_to_string(repo().join("meshes/paper/rect_008.msh")).unwrap();
    let text = text.replacen(
        "$PhysicalNames\n7\n",
        "$PhysicalNames\n8\n1 9 \"ghost\"\n",
        1,
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ghost.msh");
    std::fs::write(&path, text).unwrap();
    let mesh = Mesh::read(&path).unwrap();
    let err = mesh.boundary_group("ghost").unwrap_err().to_string();
    assert!(
        err.contains("ghost") && err.contains("no boundary edges"),
        "{err}"
    );
    assert!(mesh.boundary_group("Γ3,1").is_ok());
}
