//! Issue 26, findings 7–9: meshes that are not one body, groups that are not boundary
//! edges, overlapping Γ3,1/Γ3,2, and warnings that say only what is true. The fixtures are in
//! tests/data/mesh_checks/, made by gmsh from the .geo files beside them.

use crate::common;

use common::{cli, descriptor, load, repo};
use std::path::PathBuf;

fn data(name: &str) -> String {
    repo()
        .join("tests/data/mesh_checks")
        .join(name)
        .display()
        .to_string()
}

/// Runs `args`, expects `status`, and that the output holds every needle and no Rust Debug
/// value of a factorization error.
fn expect(status: i32, args: &[&str], needles: &[&str]) -> String {
    let (code, text) = cli(args);
    assert_eq!(code, status, "{args:?}: {text}");
    for n in needles {
        assert!(text.contains(n), "{args:?}: no '{n}' in: {text}");
    }
    for bad in ["NonPositivePivot", "{ index", "panicked"] {
        assert!(!text.contains(bad), "{args:?}: '{bad}' in: {text}");
    }
    text
}

fn out_dir() -> (tempfile::TempDir, String) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out").display().to_string();
    (dir, out)
}

/// Finding 7: two rectangles (boxes) not fragmented. `check` and `run` used to accept the
/// scene (run: exit 1 with a Debug value); both refuse it now, naming where and the fix.
#[test]
fn unfragmented_halves_are_refused_in_2d_and_3d() {
    for (scene, at, entities, count) in [
        (
            "unfragmented.toml",
            "(1, 0)",
            "surfaces 1, 2",
            "18 nodes at 9 places",
        ),
        (
            "unfragmented_3d.toml",
            "(1, 0, 1)",
            "volumes 1, 2",
            "24 nodes at 12 places",
        ),
    ] {
        let scene = data(scene);
        let (_dir, out) = out_dir();
        let needles = [
            count,
            at,
            entities,
            "BooleanFragments",
            "Coherence Mesh;",
            "separate_parts = true",
        ];
        expect(2, &["check", &scene], &needles);
        expect(2, &["run", &scene, "--out", &out], &needles);
        assert!(!std::path::Path::new(&out).exists(), "run wrote {out}");
    }
}

/// `separate_parts = true` admits bodies that only touch, but every part needs Γ1.
#[test]
fn separate_parts_allow_touching_bodies_but_not_a_part_without_gamma1() {
    let scene = data("unfragmented.toml");
    let separate = "mesh.separate_parts=true";
    expect(
        2,
        &["check", &scene, "--set", separate],
        &[
            "has 2 parts",
            "part 2 (162 triangles, 98 nodes, gmsh surface 2, spanning (1, 0)–(2, 1))",
            "no edge of the clamped group 'Γ1'",
            "K_A is singular",
            "not parts without Γ1",
        ],
    );
    // Without the key the coincident nodes are reported first.
    let text = expect(2, &["check", &scene], &["coincide"]);
    assert!(!text.contains("has 2 parts"), "{text}");
    // Both halves clamped: the two bodies run.
    let (_dir, out) = out_dir();
    let fixed = "mesh.groups.fixed=ends";
    expect(
        0,
        &["check", &scene, "--set", separate, "--set", fixed],
        &[],
    );
    expect(
        0,
        &[
            "run", &scene, "--set", separate, "--set", fixed, "--out", &out,
        ],
        &[],
    );
    // The same in 3D.
    let scene = data("unfragmented_3d.toml");
    expect(
        2,
        &["check", &scene, "--set", separate],
        &["part 2 (100 tetrahedra", "no face of the clamped group"],
    );
    expect(
        0,
        &["check", &scene, "--set", separate, "--set", fixed],
        &[],
    );
}

/// `mesh-info` reports the parts and the coincident nodes, as text and in --json; a sound
/// mesh has one part and none.
#[test]
fn mesh_info_reports_parts_and_coincident_nodes() {
    for (mesh, places, cells) in [
        ("unfragmented.msh", 9, "triangles"),
        ("unfragmented_3d.msh", 12, "tetrahedra"),
    ] {
        let mesh = data(mesh);
        let text = expect(
            0,
            &["mesh-info", &mesh],
            &[
                "parts: 2",
                "part 2: ",
                "warning: ",
                "coincide",
                "BooleanFragments",
            ],
        );
        assert!(text.contains(&format!("at {places} places")), "{text}");
        let (_, json) = cli(&["mesh-info", "--json", &mesh]);
        let v: serde_json::Value = serde_json::from_str(&json).unwrap();
        let parts = v["parts"].as_array().unwrap();
        assert_eq!(parts.len(), 2, "{json}");
        assert_eq!(parts[1]["entities"], serde_json::json!([2]));
        assert_eq!(parts[1]["min"][0], 1.0);
        let total: u64 = parts.iter().map(|p| p[cells].as_u64().unwrap()).sum();
        assert_eq!(Some(total), v[cells].as_u64());
        let places_json = v["coincident_nodes"].as_array().unwrap();
        assert_eq!(places_json.len(), places, "{json}");
        for p in places_json {
            assert_eq!(p["nodes"], 2);
            assert_eq!(p["entities"], serde_json::json!([1, 2]));
            assert_eq!(p["at"][0], 1.0, "every place is on the interface x = 1");
        }
    }
    let sound = repo().join("tests/data/rect_004.msh").display().to_string();
    let (_, json) = cli(&["mesh-info", "--json", &sound]);
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(v["parts"].as_array().unwrap().len(), 1);
    assert_eq!(v["coincident_nodes"], serde_json::json!([]));
}

/// Finding 8: Γ2 holds the top side and a fillet arc that is no edge of the mesh; a load on
/// "top" (inside Γ2) used to be refused with "mesh has no group 'Γ2'".
#[test]
fn group_with_elements_off_the_mesh_says_it_exists_and_how_many() {
    let scene = data("fillet.toml");
    let text = expect(
        2,
        &["check", &scene],
        &[
            "key 'mesh.groups.traction'",
            "\"Γ2\" (tag 2) exists, with 20 line elements",
            "4 of them are not boundary edges of the triangle mesh",
            "4 are not an edge of any triangle",
            "(2, 0.75)–(1.98097, 0.845671)",
            "BooleanFragments",
        ],
    );
    assert!(!text.contains("has no"), "{text}");
    // A group made of the arc alone: none of its elements is an edge.
    expect(
        2,
        &["check", &scene, "--set", "mesh.groups.fixed=arc"],
        &[
            "key 'mesh.groups.fixed'",
            "\"arc\" (tag 5) exists, with 4 line elements",
            "none of them is a boundary edge of the triangle mesh",
        ],
    );
}

/// Finding 9: Γ3,1 and Γ3,2 sharing edges are refused naming both and where; meeting at a
/// node (tests/data/corner) is fine.
#[test]
fn overlapping_contact_and_friction_groups_are_refused() {
    expect(
        2,
        &["check", &data("overlap.toml")],
        &[
            "'Γ3,1'",
            "'Γ3,2'",
            "share 8 edges",
            "(1, 0)–(1.125, 0)",
            "sharing the nodes where they meet is fine",
        ],
    );
    // Without contact the same groups are fine.
    let overlap = data("overlap.toml");
    expect(
        0,
        &["check", &overlap, "--set", "contact.enabled=false"],
        &[],
    );
    let corner = repo().join("tests/data/corner/corner.toml");
    expect(0, &["check", &corner.display().to_string()], &[]);
}

/// Finding 9: the bend warning names the group that bends: Γ3,2 with contact off (it used to
/// say "the contact boundary").
#[test]
fn bend_warning_names_the_group_that_bends() {
    let scene = PathBuf::from(data("bend.toml"));
    let (scene_v, _, disc) = load(&scene, &[]);
    let warnings = viscontact::effects::warnings(&scene_v, &disc, &descriptor(&scene_v, &disc));
    let bend: Vec<&String> = warnings.iter().filter(|w| w.contains("bends")).collect();
    assert_eq!(bend.len(), 1, "{warnings:?}");
    assert!(
        bend[0].contains("'Γ2' bends by up to 90.00°") && bend[0].contains("slip"),
        "{}",
        bend[0]
    );
    // Contact on the straight bottom: no bend of its own, still only Γ2's.
    let (scene_v, _, disc) = load(&scene, &["contact.enabled=true"]);
    let warnings = viscontact::effects::warnings(&scene_v, &disc, &descriptor(&scene_v, &disc));
    let bend: Vec<&String> = warnings.iter().filter(|w| w.contains("bends")).collect();
    assert_eq!(bend.len(), 1, "{warnings:?}");
    assert!(bend[0].contains("'Γ2'"), "{}", bend[0]);
}

/// Finding 9: `region` holds the tag of the first cell group in file order, which gmsh sorts
/// by tag, so the inner group with the smaller tag shows; mesh-info notes each overlap.
#[test]
fn region_holds_the_first_group_in_file_order_and_overlaps_are_noted() {
    let path = data("regions.msh");
    let mesh = viscontact::mesh::Mesh::read(std::path::Path::new(&path)).unwrap();
    let region = viscontact::run::region(&mesh);
    for (c, &tag) in region.iter().enumerate() {
        let expected = match mesh.cell_entity[c] {
            1 => 10,
            _ => 5,
        };
        assert_eq!(tag, expected, "cell {c} of surface {}", mesh.cell_entity[c]);
    }
    expect(
        0,
        &["mesh-info", &path],
        &[
            "cell groups 'inner' (tag 5) and 'Ω' (tag 10) share 14 cells; the output's \
             `region` holds 5 there",
            "cell groups 'Ω' (tag 10) and 'left' (tag 20) share 14 cells; the output's \
             `region` holds 10 there",
        ],
    );
}
