//! `[[material.region]]` entries as a user writes them, right and wrong (issue 51): `check`
//! prints the regions, and refuses (exit 2, naming the key, the group and the fix) regions
//! that overlap, a group that is not of the body's dimension or not in the mesh, unknown keys
//! and a region kernel run by the direct sum; a region kernel is printed and judged.

use crate::common;
use common::*;

/// The bar of tests/data/bimaterial_bar.msh (groups "soft", "stiff", "Ω" over both, the
/// curve "bond" between them), clamped on Γ1, pulled on "right".
fn bar() -> SceneText {
    SceneText::on(repo().join("tests/data/bimaterial_bar.msh"))
        .set("time.end", 1.0)
        .set("time.steps", 8)
        .set("material.viscosity.theta", 0.1)
        .set("material.elasticity.young", 0.5)
        .traction(Some("right"), &["0.01", "0"])
}

/// `bar()` with a region on `on` whose tables are written in TOML as `body`.
fn with_region(scene: SceneText, on: &str, body: &str) -> SceneText {
    let mut t: toml::Table = toml::from_str(body).unwrap();
    t.insert("on".into(), on.into());
    scene.push("material.region", t)
}

/// `check` of `scene`: (exit status, output).
fn check(scene: &SceneText, dir: &std::path::Path, name: &str) -> (i32, String) {
    cli(&["check", &scene.write(dir, name).display().to_string()])
}

#[test]
fn check_prints_each_region_with_its_elements_and_material() {
    let dir = tempfile::tempdir().unwrap();
    let scene = with_region(bar(), "stiff", "elasticity = { young = 2.0 }");
    let (code, text) = check(&scene, dir.path(), "one.toml");
    assert_eq!(code, 0, "{text}");
    let lines: Vec<&str> = text.lines().filter(|l| l.starts_with("region ")).collect();
    assert_eq!(lines.len(), 2, "{text}");
    assert!(
        lines[0].contains("1: 'stiff'") && lines[0].contains("E = 2, ν = 0"),
        "{text}"
    );
    assert!(
        lines[1].contains("outside every region") && lines[1].contains("2 distinct materials"),
        "{text}"
    );
    // The step limit is the stiff region's 4θ/E = 0.2 ([material]'s alone: 0.8).
    assert!(text.contains("stable for k ≤ 2.000000e-1"), "{text}");
    // The counts add up to the mesh's triangles.
    let count = |l: &str| -> usize {
        let words: Vec<&str> = l.split_whitespace().collect();
        let i = words
            .iter()
            .position(|w| w.starts_with("triangles"))
            .unwrap();
        words[i - 1].parse().unwrap()
    };
    let mesh_line = text.lines().find(|l| l.starts_with("mesh ")).unwrap();
    assert!(
        mesh_line.contains(&format!("{} triangles", count(lines[0]) + count(lines[1]))),
        "{text}"
    );
    // Without regions: no region line.
    let (code, text) = check(&bar(), dir.path(), "none.toml");
    assert_eq!(code, 0, "{text}");
    assert!(!text.lines().any(|l| l.starts_with("region ")), "{text}");
}

/// The step limit `check` prints ("stable for k ≤ …").
fn step_limit(text: &str) -> f64 {
    let after = text.split("stable for k ≤ ").nth(1).expect(text);
    after.split_whitespace().next().unwrap().parse().unwrap()
}

#[test]
fn check_prints_each_region_kernel_and_judges_its_stability() {
    let dir = tempfile::tempdir().unwrap();
    // k = 1/64: below the limit of the strong kernel below.
    let body = (bar().set("time.steps", 64)).table("material.relaxation", "prony = [[0.7, 3.0]]");
    let (code, plain) = check(&body, dir.path(), "plain.toml");
    assert_eq!(code, 0, "{plain}");
    // The soft part without relaxation, the stiff one with a strong kernel of its own.
    let scene = with_region(body.clone(), "soft", "relaxation = { enabled = false }");
    let scene = with_region(scene, "stiff", "relaxation = { expr = \"40*exp(-2*s)\" }");
    let (code, text) = check(&scene, dir.path(), "own.toml");
    assert_eq!(code, 0, "{text}");
    let region = |i: &str| text.lines().find(|l| l.contains(i)).expect(&text);
    assert!(region("1: 'soft'").ends_with("no relaxation"), "{text}");
    assert!(
        region("2: 'stiff'").ends_with("its own kernel (memory group 1)"),
        "{text}"
    );
    assert!(
        text.contains("kernel     [material.region[1].relaxation] compressed: "),
        "{text}"
    );
    // The stiff part's kernel is stronger than [material]'s: a smaller step limit.
    let (own, alone) = (step_limit(&text), step_limit(&plain));
    assert!(own < 0.5 * alone, "{own} against {alone}");
    // The same kernel on no element of the body (every element in a region without
    // relaxation) has no step limit from memory: E = 0.5, θ = 0.1 alone give 4θ/E = 0.8.
    let none = with_region(body, "Ω", "relaxation = { enabled = false }");
    let (code, text) = check(&none, dir.path(), "none.toml");
    assert_eq!(code, 0, "{text}");
    assert!((step_limit(&text) - 0.8).abs() < 1e-6, "{text}");
}

#[test]
fn bad_regions_are_refused_naming_the_key_the_group_and_the_fix() {
    let dir = tempfile::tempdir().unwrap();
    let cases: Vec<(SceneText, Vec<&str>)> = vec![
        // Ω holds every element of "stiff".
        (
            with_region(
                with_region(bar(), "Ω", "viscosity = { theta = 0.2 }"),
                "stiff",
                "viscosity = { theta = 0.3 }",
            ),
            vec![
                "material.region[0].on",
                "material.region[1].on",
                "'Ω' and 'stiff' share",
                "make the groups disjoint",
            ],
        ),
        // A curve is not a part of the body.
        (
            with_region(bar(), "bond", "viscosity = { theta = 0.2 }"),
            vec![
                "material.region[0].on",
                "bond",
                "a curve group",
                "soft",
                "stiff",
            ],
        ),
        (
            with_region(bar(), "core", "viscosity = { theta = 0.2 }"),
            vec!["material.region[0].on", "no physical group 'core'", "stiff"],
        ),
        (
            with_region(bar(), "stiff", "viscosity = { theta = 0.2 }\ncolour = 1"),
            vec!["material.region", "colour"],
        ),
        (
            with_region(bar(), "stiff", "viscosity = { theta = -1.0 }"),
            vec!["material.region[0].viscosity.theta", "-1"],
        ),
        (
            with_region(
                bar(),
                "stiff",
                "elasticity = { young = 1.0, poisson = 0.7 }",
            ),
            vec!["material.region[0].elasticity.poisson", "0.7"],
        ),
        (
            with_region(bar(), "stiff", "relaxation = { prony = [[1.0, -2.0]] }"),
            vec!["material.region[0].relaxation.prony[0][1]", "-2"],
        ),
        // A region's kernel runs by the recursion: the direct sum is refused.
        (
            with_region(
                bar(),
                "stiff",
                "relaxation = { expr = \"exp(-s)\", memory = \"exact\" }",
            ),
            vec!["material.region[0].relaxation.memory", "O(1)", "compressed"],
        ),
        (
            with_region(
                bar(),
                "stiff",
                "relaxation = { expr = \"exp(-s)\", tolerance = 2.0 }",
            ),
            vec!["material.region[0].relaxation.tolerance", "2"],
        ),
    ];
    for (i, (scene, needles)) in cases.into_iter().enumerate() {
        let (code, text) = check(&scene, dir.path(), &format!("bad{i}.toml"));
        assert_eq!(code, 2, "case {i}: {text}");
        assert!(!text.contains("panicked"), "case {i}: {text}");
        for n in needles {
            assert!(text.contains(n), "case {i}: missing {n:?} in:\n{text}");
        }
    }
}
