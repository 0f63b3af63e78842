//! Fuzzing the two readers of user files with proptest: the gmsh `.msh` reader
//! ([`Mesh::read`]) and the scene reader ([`Scene::load`], `--set` overrides included) take
//! arbitrary bytes and return `Ok` or `Err`, never panic. A mesh that is accepted is sane
//! (indices in range, counter-clockwise triangles of positive area, finite coordinates), and
//! whatever is accepted goes on through the discretization and the first steps of the time
//! loop without a panic and without a step that succeeds with a non-finite solution. The
//! properties on mutated real files also check that a share of their inputs gets that far
//! (so that the fuzzing does not stop at the first parse error).
//!
//! Bounded: 300 cases per property by default (the whole file takes a few seconds in
//! release). For a longer session set `VISCONTACT_FUZZ_CASES`, e.g.
//! `VISCONTACT_FUZZ_CASES=20000 cargo test --release --test faults fuzz::`. Seeds are random on every
//! run (proptest prints the minimal failing input when one is found); failures are not
//! persisted to files: a panic that is found gets its own regression test at the end of this
//! file. Run it in debug builds too (`cargo test --test faults fuzz::`): integer overflow panics there
//! and wraps silently in release.

use crate::common;

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;

use common::*;
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;
use viscontact::mesh::Mesh;
use viscontact::scene::Scene;
use viscontact::time_loop::{Solved, TimeLoop};

fn config() -> ProptestConfig {
    let cases = crate::common::env_or("VISCONTACT_FUZZ_CASES", 300);
    ProptestConfig {
        cases,
        failure_persistence: None,
        max_shrink_iters: 2000,
        ..ProptestConfig::default()
    }
}

// ---------------------------------------------------------------------------------------
// Helpers: run a reader on bytes, turn a panic into a failure that prints the input
// ---------------------------------------------------------------------------------------

/// Bytes as a readable literal (ASCII kept, the rest escaped), cut to a few kB.
fn show(bytes: &[u8]) -> String {
    let cut = bytes.len().min(4000);
    let mut s = bytes[..cut].escape_ascii().to_string();
    if cut < bytes.len() {
        s.push_str(&format!("… ({} more bytes)", bytes.len() - cut));
    }
    s
}

/// Runs `f`; a panic becomes a test failure naming `what` and the panic message.
fn no_panic<T>(what: impl FnOnce() -> String, f: impl FnOnce() -> T) -> Result<T, TestCaseError> {
    catch_unwind(AssertUnwindSafe(f)).map_err(|p| {
        let msg = p
            .downcast_ref::<String>()
            .cloned()
            .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
            .unwrap_or_else(|| "non-string panic payload".into());
        TestCaseError::fail(format!("PANIC: {msg}\n  input: {}", what()))
    })
}

/// A mesh that `Mesh::read` accepted must be usable without further checks.
fn check_mesh(m: &Mesh) -> Result<(), String> {
    let n = m.nodes.len();
    if m.triangles.is_empty() {
        return Err("accepted a mesh without triangles".into());
    }
    for (i, p) in m.nodes.all().iter().enumerate() {
        if !p.iter().all(|c| c.is_finite()) || p[2] != 0.0 {
            return Err(format!("node {i} = {p:?}"));
        }
    }
    for (k, t) in m.triangles.iter().enumerate() {
        if t.iter().any(|&i| i >= n) {
            return Err(format!("triangle {k} = {t:?} with {n} nodes"));
        }
        let [a, b, c] = t.map(|i| m.nodes[i]);
        let area = 0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]));
        if area.is_nan() || area <= 0.0 {
            return Err(format!("triangle {k} = {t:?} has signed area {area:e}"));
        }
    }
    // Every node is used by a triangle (unused ones are dropped).
    let mut used = vec![false; n];
    m.triangles.iter().flatten().for_each(|&i| used[i] = true);
    if let Some(i) = used.iter().position(|u| !u) {
        return Err(format!("node {i} is used by no triangle"));
    }
    for g in &m.groups {
        if g.facets.iter().flatten().any(|&i| i >= n) {
            return Err(format!("group {:?}: facet index out of range", g.name));
        }
        if g.cells.iter().any(|&c| c >= m.triangles.len()) {
            return Err(format!("group {:?}: cell index out of range", g.name));
        }
        if g.dim == 1 {
            for &f in &g.facets {
                if m.facet_length(f).is_nan() || m.facet_length(f) <= 0.0 {
                    return Err(format!("group {:?}: facet {f:?} of length 0", g.name));
                }
            }
            let (normals, kink) = m.nodal_normals(g);
            if !kink.is_finite()
                || normals
                    .iter()
                    .any(|(_, v)| !v.iter().all(|c| c.is_finite()))
            {
                return Err(format!("group {:?}: non-finite nodal normal", g.name));
            }
        }
    }
    let q = m.quality();
    if !(q.min_area > 0.0 && q.min_angle_deg > 0.0 && q.max_aspect_ratio.is_finite()) {
        return Err(format!("quality {q:?}"));
    }
    Ok(())
}

/// Writes `bytes` to a temporary `.msh` and reads it: no panic; if `Ok`, the mesh is sane
/// and the paper's scene gets through setup and two steps on it without a panic.
fn read_mesh_bytes(bytes: &[u8], downstream: bool) -> Result<(), TestCaseError> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("fuzz.msh");
    std::fs::write(&path, bytes).unwrap();
    let what = || show(bytes);
    let result = no_panic(what, || Mesh::read(&path))?;
    let Ok(mesh) = result else { return Ok(()) };
    count(|r| r.meshes += 1);
    if let Err(e) = check_mesh(&mesh) {
        return Err(TestCaseError::fail(format!(
            "accepted an insane mesh: {e}\n  input: {}",
            what()
        )));
    }
    if downstream {
        let set = format!("mesh.file={}", path.display());
        runs_sanely(
            || format!("examples/paper.toml --set {set}\n  mesh: {}", what()),
            || {
                run_a_little(
                    &repo().join("examples/paper.toml"),
                    std::slice::from_ref(&set),
                )
            },
        )?;
    }
    Ok(())
}

/// `setup`, `TimeLoop::new` and at most two steps; errors are fine, panics are not, and
/// neither is a step that succeeds with a non-finite velocity (a silent blow-up).
fn run_a_little(scene: &Path, overrides: &[String]) -> Result<(), String> {
    let Ok((s, _m, d)) = viscontact::run::setup(scene, overrides) else {
        return Ok(());
    };
    count(|r| r.setups += 1);
    let Ok(mut tl) = TimeLoop::new(&s, &d) else {
        return Ok(());
    };
    let mut non_finite = None;
    let mut check = |solved: &Solved| {
        let step = &solved.step;
        if !step.w.iter().chain(step.u).all(|v| v.is_finite()) {
            non_finite.get_or_insert(step.n);
        }
        count(|r| r.steps += 1);
        Ok(())
    };
    // Errors are fine; steps 0 and 1 at most.
    let _ = tl.run(s.time.steps.min(1), &mut check);
    match non_finite {
        Some(n) => Err(format!("step {n} succeeded with a non-finite u or w")),
        None => Ok(()),
    }
}

/// [`no_panic`] for [`run_a_little`]: its `Err` is a failure too.
fn runs_sanely(
    what: impl Fn() -> String,
    f: impl FnOnce() -> Result<(), String>,
) -> Result<(), TestCaseError> {
    no_panic(&what, f)?.map_err(|e| TestCaseError::fail(format!("{e}\n  input: {}", what())))
}

/// Writes `text` as a scene file next to nothing and loads it: no panic.
fn load_scene_bytes(bytes: &[u8], overrides: &[String]) -> Result<(), TestCaseError> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("fuzz.toml");
    std::fs::write(&path, bytes).unwrap();
    let loaded = no_panic(
        || format!("{}\n  --set {overrides:?}", show(bytes)),
        || Scene::load(&path, overrides).is_ok(),
    )?;
    if loaded {
        count(|r| r.scenes += 1);
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------
// Mutations
// ---------------------------------------------------------------------------------------

/// Numbers that break parsers: zero, signs, limits of the integer types, float specials.
const NASTY_TOKENS: &[&str] = &[
    "0",
    "1",
    "2",
    "3",
    "-1",
    "-0",
    "+1",
    "15",
    "255",
    "4294967295",
    "4294967296",
    "2147483647",
    "-2147483648",
    "9223372036854775807",
    "18446744073709551615",
    "18446744073709551616",
    "99999999999999999999999",
    "nan",
    "NaN",
    "inf",
    "-inf",
    "1e308",
    "1e400",
    "-1e308",
    "1e-320",
    "0.5",
    "1e-13",
    "0.9999999999999999",
    "",
    "x",
    "\"Γ3,1\"",
    "$Nodes",
    "$EndNodes",
    "$Elements",
    "$EndElements",
    "$Entities",
    "$PhysicalNames",
    "$EndPhysicalNames",
];

/// 64-bit patterns for binary fields: integers near limits and float specials.
fn nasty_words() -> Vec<u64> {
    vec![
        0,
        1,
        2,
        3,
        4,
        15,
        0xff,
        0x7fff_ffff,
        0x8000_0000,
        0xffff_ffff,
        0x1_0000_0000,
        1 << 40,
        u64::MAX,
        u64::MAX - 1,
        i64::MAX as u64,
        f64::NAN.to_bits(),
        f64::INFINITY.to_bits(),
        f64::NEG_INFINITY.to_bits(),
        f64::MAX.to_bits(),
        (-0.0f64).to_bits(),
        1e-310f64.to_bits(),
        0.5f64.to_bits(),
        1.0f64.to_bits(),
        2.0f64.to_bits(),
    ]
}

#[derive(Debug, Clone)]
enum Mutation {
    /// Flip one bit.
    Flip(usize, u8),
    /// Overwrite one byte.
    Set(usize, u8),
    /// Insert bytes.
    Insert(usize, Vec<u8>),
    /// Delete up to `len` bytes.
    Delete(usize, usize),
    /// Cut the file.
    Truncate(usize),
    /// Overwrite a little-endian word of 4 or 8 bytes (binary fields).
    Word(usize, bool, u64),
    /// Replace the i-th whitespace-separated token (ASCII fields).
    Token(usize, String),
    /// Copy the i-th `$Section … $EndSection` block to another place.
    DuplicateSection(usize, usize),
    /// Remove the i-th section.
    DeleteSection(usize),
    /// Swap two lines.
    SwapLines(usize, usize),
    /// Put a space or a tab before the i-th section marker (`$Name` line).
    Indent(usize, bool),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    let pos = any::<usize>();
    prop_oneof![
        (pos, 0u8..8).prop_map(|(p, b)| Mutation::Flip(p, b)),
        (pos, any::<u8>()).prop_map(|(p, b)| Mutation::Set(p, b)),
        (
            pos,
            prop_oneof![
                prop::collection::vec(any::<u8>(), 1..16),
                prop::sample::select(NASTY_TOKENS).prop_map(|t| format!(" {t} ").into_bytes()),
                Just(b"\n".to_vec()),
                Just(b"\r\n".to_vec()),
            ]
        )
            .prop_map(|(p, b)| Mutation::Insert(p, b)),
        (pos, 1usize..64).prop_map(|(p, l)| Mutation::Delete(p, l)),
        pos.prop_map(Mutation::Truncate),
        (pos, any::<bool>(), prop::sample::select(nasty_words()))
            .prop_map(|(p, w, v)| Mutation::Word(p, w, v)),
        (
            pos,
            prop_oneof![
                3 => prop::sample::select(NASTY_TOKENS).prop_map(str::to_string),
                2 => (-3i64..40).prop_map(|v| v.to_string()),
                1 => (-2.5f64..2.5).prop_map(|v| v.to_string()),
            ]
        )
            .prop_map(|(p, t)| Mutation::Token(p, t)),
        (pos, pos).prop_map(|(a, b)| Mutation::DuplicateSection(a, b)),
        pos.prop_map(Mutation::DeleteSection),
        (pos, pos).prop_map(|(a, b)| Mutation::SwapLines(a, b)),
        (pos, any::<bool>()).prop_map(|(i, tab)| Mutation::Indent(i, tab)),
    ]
}

/// `(start, end)` byte ranges of every `$Name … $EndName\n` block.
fn sections(b: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let at_line_start = i == 0 || b[i - 1] == b'\n';
        if at_line_start && b[i] == b'$' && !b[i..].starts_with(b"$End") {
            let name_end = b[i..]
                .iter()
                .position(|&c| c == b'\n' || c == b'\r')
                .map_or(b.len(), |p| i + p);
            let mut end_tag = b"\n$End".to_vec();
            end_tag.extend_from_slice(&b[i + 1..name_end]);
            if let Some(p) = b[name_end..]
                .windows(end_tag.len())
                .position(|w| w == end_tag.as_slice())
            {
                let mut end = name_end + p + end_tag.len();
                while end < b.len() && b[end - 1] != b'\n' {
                    end += 1;
                }
                out.push((i, end));
                i = end;
                continue;
            }
        }
        i += 1;
    }
    out
}

/// Byte ranges of whitespace-separated tokens.
fn tokens(b: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        if b[i].is_ascii_whitespace() {
            i += 1;
            continue;
        }
        let s = i;
        while i < b.len() && !b[i].is_ascii_whitespace() {
            i += 1;
        }
        out.push((s, i));
    }
    out
}

/// Byte ranges of lines (with their `\n`).
fn lines(b: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut s = 0;
    for (i, &c) in b.iter().enumerate() {
        if c == b'\n' {
            out.push((s, i + 1));
            s = i + 1;
        }
    }
    if s < b.len() {
        out.push((s, b.len()));
    }
    out
}

fn apply(b: &mut Vec<u8>, m: &Mutation) {
    let len = b.len();
    let at = |p: usize| if len == 0 { 0 } else { p % (len + 1) };
    match m {
        Mutation::Flip(p, bit) if len > 0 => b[p % len] ^= 1 << bit,
        Mutation::Set(p, v) if len > 0 => b[p % len] = *v,
        Mutation::Insert(p, bytes) => {
            let p = at(*p);
            b.splice(p..p, bytes.iter().copied());
        }
        Mutation::Delete(p, l) => {
            let p = at(*p);
            b.drain(p..(p + l).min(len));
        }
        Mutation::Truncate(p) => b.truncate(at(*p)),
        Mutation::Word(p, wide, v) => {
            let w = if *wide { 8 } else { 4 };
            if len >= w {
                let p = p % (len - w + 1);
                b[p..p + w].copy_from_slice(&v.to_le_bytes()[..w]);
            }
        }
        Mutation::Token(i, t) => {
            let toks = tokens(b);
            if !toks.is_empty() {
                let (s, e) = toks[i % toks.len()];
                b.splice(s..e, t.bytes());
            }
        }
        Mutation::DuplicateSection(i, to) => {
            let secs = sections(b);
            if !secs.is_empty() {
                let (s, e) = secs[i % secs.len()];
                let copy = b[s..e].to_vec();
                // Insert at a line start so that the copy is a section of its own.
                let starts: Vec<usize> = lines(b).iter().map(|l| l.0).chain([len]).collect();
                let p = starts[to % starts.len()];
                b.splice(p..p, copy);
            }
        }
        Mutation::DeleteSection(i) => {
            let secs = sections(b);
            if !secs.is_empty() {
                let (s, e) = secs[i % secs.len()];
                b.drain(s..e);
            }
        }
        Mutation::SwapLines(i, j) => {
            let ls = lines(b);
            if ls.len() >= 2 {
                let (a, c) = (ls[i % ls.len()], ls[j % ls.len()]);
                let (a, c) = if a.0 <= c.0 { (a, c) } else { (c, a) };
                if a != c {
                    let mut out = b[..a.0].to_vec();
                    out.extend_from_slice(&b[c.0..c.1]);
                    out.extend_from_slice(&b[a.1..c.0]);
                    out.extend_from_slice(&b[a.0..a.1]);
                    out.extend_from_slice(&b[c.1..]);
                    *b = out;
                }
            }
        }
        Mutation::Indent(i, tab) => {
            let markers: Vec<usize> = lines(b)
                .iter()
                .map(|l| l.0)
                .filter(|&s| b[s] == b'$')
                .collect();
            if !markers.is_empty() {
                let p = markers[i % markers.len()];
                b.insert(p, if *tab { b'\t' } else { b' ' });
            }
        }
        _ => {}
    }
}

/// Mostly one mutation (so that some files stay acceptable), sometimes several.
fn mutations() -> impl Strategy<Value = Vec<Mutation>> {
    prop_oneof![
        3 => prop::collection::vec(mutation(), 1..2),
        1 => prop::collection::vec(mutation(), 2..6),
    ]
}

fn mutated(base: &[u8], ms: &[Mutation]) -> Vec<u8> {
    let mut b = base.to_vec();
    for m in ms {
        apply(&mut b, m);
    }
    b
}

fn file(rel: &str) -> Vec<u8> {
    std::fs::read(repo().join(rel)).unwrap()
}

// ---------------------------------------------------------------------------------------
// Random MSH-like text: section markers and short lines of small numbers, so that the
// parser gets past the header into every section
// ---------------------------------------------------------------------------------------

fn msh_line() -> impl Strategy<Value = String> {
    let number = prop_oneof![
        6 => (-2i64..12).prop_map(|v| v.to_string()),
        1 => prop::sample::select(NASTY_TOKENS).prop_map(str::to_string),
        1 => (-2.0f64..3.0).prop_map(|v| v.to_string()),
    ];
    prop_oneof![
        2 => prop::sample::select(vec![
            "$MeshFormat", "$EndMeshFormat", "$PhysicalNames", "$EndPhysicalNames",
            "$Entities", "$EndEntities", "$Nodes", "$EndNodes", "$Elements", "$EndElements",
            "$PartitionedEntities", "$Periodic", "$NodeData", "$Comments", "$EndComments",
            "4.1 0 8", "4.1 1 8", "4.1 0 4", "2.2 0 8", "1 3 \"Γ3,1\"", "2 10 \"Ω\"",
        ])
        .prop_map(str::to_string),
        5 => prop::collection::vec(number, 1..9).prop_map(|v| v.join(" ")),
    ]
}

fn msh_text() -> impl Strategy<Value = Vec<u8>> {
    prop::collection::vec(msh_line(), 0..40).prop_map(|ls| {
        let mut s = String::from("$MeshFormat\n4.1 0 8\n$EndMeshFormat\n");
        for l in ls {
            s.push_str(&l);
            s.push('\n');
        }
        s.into_bytes()
    })
}

// ---------------------------------------------------------------------------------------
// Random scene text: keys of the schema, values that are numbers at the limits, strings,
// expressions, arrays and tables
// ---------------------------------------------------------------------------------------

/// A random expression of the scene's variables and functions (valid or not).
fn expression() -> impl Strategy<Value = String> {
    let leaf = prop_oneof![
        prop::sample::select(vec![
            "x", "y", "z", "t", "s", "pi", "e", "0", "1", "-1", "0.5", "1e308", "1e-308", "1e400",
            "nan", "inf", "w", "pi()", "e()", "",
        ])
        .prop_map(str::to_string),
        (-10.0f64..10.0).prop_map(|v| format!("{v}")),
    ];
    let tree = leaf.prop_recursive(4, 24, 3, |inner| {
        prop_oneof![
            (
                inner.clone(),
                prop::sample::select(vec![
                    "+", "-", "*", "/", "^", "%", "<", "<=", "==", "!=", ">", "&&", "||", " ", ",",
                ]),
                inner.clone()
            )
                .prop_map(|(a, op, b)| format!("{a}{op}{b}")),
            (
                prop::sample::select(vec![
                    "if", "exp", "ln", "sqrt", "pow", "tanh", "min", "max", "abs", "sin", "cos",
                    "log", "round", "floor", "ceil", "sign", "int", "print", "asin", "acosh",
                    "atan", "foo", "",
                ]),
                prop::collection::vec(inner.clone(), 0..4)
            )
                .prop_map(|(f, args)| format!("{f}({})", args.join(", "))),
            inner.clone().prop_map(|a| format!("-({a})")),
            inner.clone().prop_map(|a| format!("!{a}")),
            inner.prop_map(|a| format!("(({a})")),
        ]
    });
    prop_oneof![
        8 => tree,
        1 => "[-+*/^%()!<>=&|,.0-9a-z \\[\\]{}\"]{0,40}",
        1 => any::<String>(),
    ]
}

fn toml_string(s: &str) -> String {
    toml::Value::String(s.to_string()).to_string()
}

/// A TOML value (or something close to one).
fn toml_value() -> impl Strategy<Value = String> {
    let scalar = prop_oneof![
        prop::sample::select(vec![
            "0",
            "1",
            "-1",
            "0.0",
            "-0.0",
            "1e-320",
            "1e308",
            "1.7976931348623157e308",
            "nan",
            "+nan",
            "-nan",
            "inf",
            "-inf",
            "+inf",
            "9223372036854775807",
            "-9223372036854775808",
            "9223372036854775808",
            "18446744073709551615",
            "true",
            "false",
            "\"\"",
            "\"Γ3,1\"",
            "\"Gamma1\"",
            "\"plane_strain\"",
            "\"plane_stress\"",
            "\"3d\"",
            "\"implicit\"",
            "\"left\"",
            "\"clarabel\"",
            "\"dual\"",
            "\"top\"",
            "\"right\"",
            "\"../meshes/paper/rect_008.msh\"",
            "\"/\"",
            "\"\\u0000\"",
            "1979-05-27",
            "1979-05-27T07:32:00Z",
            "07:32:00",
            "0x10",
            "0o7",
            "0b1",
            "1_000",
            "[]",
            "[[]]",
            "{}",
            "[[1.0, 10.0]]",
            "[[1.0, nan]]",
            "[[1.0, -1.0]]",
            "[[0.0, 1e309]]",
            "[[1.0]]",
            "[[1.0, 2.0, 3.0]]",
            "[\"0\", \"0\"]",
            "[\"0\"]",
            "[0, 0, 0]",
            "{ s = [0, 1], r = [1, 0] }",
            "{ s = [1, 0], r = [1, 0] }",
            "{ s = [], r = [] }",
            "{ s = [0, 0], r = [1, 1] }",
            "{ s = [0, nan], r = [1, 1] }",
            "[{on = \"top\", value = [\"0\", \"-t\"]}]",
            "[{value = [\"x\", \"y\"]}]",
        ])
        .prop_map(str::to_string),
        (-1e3f64..1e3).prop_map(|v| format!("{v:?}")),
        any::<i64>().prop_map(|v| v.to_string()),
        any::<f64>().prop_map(|v| format!("{v:?}")),
        expression().prop_map(|e| toml_string(&e)),
    ];
    prop_oneof![
        6 => scalar.clone(),
        1 => prop::collection::vec(scalar.clone(), 0..4).prop_map(|v| format!("[{}]", v.join(", "))),
        1 => (scalar.clone(), scalar).prop_map(|(a, b)| format!("[[{a}, {b}]]")),
        1 => prop::collection::vec(expression(), 0..4).prop_map(|v| {
            let items: Vec<String> = v.iter().map(|e| toml_string(e)).collect();
            format!("[{}]", items.join(", "))
        }),
    ]
}

const SECTIONS: &[&str] = &[
    "[mesh]",
    "[mesh.groups]",
    "[time]",
    "[material]",
    "[material.viscosity]",
    "[material.elasticity]",
    "[material.relaxation]",
    "[material.relaxation.table]",
    "[contact]",
    "[friction]",
    "[[load.traction]]",
    "[[load.body]]",
    "[load]",
    "[output]",
    "[checkpoint]",
    "[solver]",
    "[scheme]",
    "[[mesh]]",
    "[time.end]",
    "[a.b.c]",
    "[",
    "[[",
    "[]",
    "[\"Γ\"]",
];

const KEYS: &[&str] = &[
    "name",
    "file",
    "model",
    "groups",
    "fixed",
    "traction",
    "contact",
    "friction",
    "end",
    "steps",
    "theta",
    "zeta",
    "young",
    "poisson",
    "enabled",
    "prony",
    "expr",
    "table",
    "s",
    "r",
    "normal_stress",
    "coefficient",
    "on",
    "value",
    "every",
    "history",
    "allow_unstable",
    "time.steps",
    "material.viscosity.theta",
    "\"Γ3,1\"",
    "unknown",
    "a.b",
    "",
];

fn toml_line() -> impl Strategy<Value = String> {
    prop_oneof![
        2 => prop::sample::select(SECTIONS).prop_map(str::to_string),
        6 => (prop::sample::select(KEYS), toml_value()).prop_map(|(k, v)| format!("{k} = {v}")),
        1 => "[ -~]{0,30}",
        1 => Just(String::new()),
    ]
}

fn toml_text() -> impl Strategy<Value = String> {
    prop::collection::vec(toml_line(), 0..30).prop_map(|ls| ls.join("\n"))
}

/// Edits of a scene text: replace a line, or the value of a `key = value` line.
#[derive(Debug, Clone)]
enum SceneEdit {
    Line(usize, String),
    Value(usize, String),
    Delete(usize),
    Bytes(Mutation),
}

fn scene_edit() -> impl Strategy<Value = SceneEdit> {
    prop_oneof![
        1 => (any::<usize>(), toml_line()).prop_map(|(i, l)| SceneEdit::Line(i, l)),
        4 => (any::<usize>(), toml_value()).prop_map(|(i, v)| SceneEdit::Value(i, v)),
        1 => any::<usize>().prop_map(SceneEdit::Delete),
        2 => mutation().prop_map(SceneEdit::Bytes),
    ]
}

fn edit_scene(base: &str, edits: &[SceneEdit]) -> Vec<u8> {
    let mut b = base.as_bytes().to_vec();
    for e in edits {
        let text = String::from_utf8_lossy(&b).into_owned();
        let mut ls: Vec<String> = text.lines().map(str::to_string).collect();
        match e {
            SceneEdit::Bytes(m) => {
                apply(&mut b, m);
                continue;
            }
            _ if ls.is_empty() => continue,
            SceneEdit::Line(i, l) => {
                let n = ls.len();
                ls[i % n] = l.clone();
            }
            SceneEdit::Delete(i) => {
                let n = ls.len();
                ls.remove(i % n);
            }
            SceneEdit::Value(i, v) => {
                let kv: Vec<usize> = (0..ls.len()).filter(|&j| ls[j].contains(" = ")).collect();
                if kv.is_empty() {
                    continue;
                }
                let j = kv[i % kv.len()];
                let key = ls[j].split(" = ").next().unwrap().to_string();
                ls[j] = format!("{key} = {v}");
            }
        }
        b = (ls.join("\n") + "\n").into_bytes();
    }
    b
}

/// Dotted keys for `--set`: all keys of the schema, and broken ones.
const SET_KEYS: &[&str] = &[
    "name",
    "mesh",
    "mesh.file",
    "mesh.model",
    "mesh.groups",
    "mesh.groups.fixed",
    "mesh.groups.traction",
    "mesh.groups.contact",
    "mesh.groups.friction",
    "time",
    "time.end",
    "time.steps",
    "material.viscosity.theta",
    "material.viscosity.zeta",
    "material.elasticity",
    "material.elasticity.young",
    "material.elasticity.poisson",
    "material.elasticity.enabled",
    "material.relaxation",
    "material.relaxation.prony",
    "material.relaxation.expr",
    "material.relaxation.table",
    "material.relaxation.table.s",
    "material.relaxation.enabled",
    "contact",
    "contact.enabled",
    "friction",
    "friction.enabled",
    "friction.normal_stress",
    "friction.coefficient",
    "load",
    "load.traction",
    "load.body",
    "load.traction.0",
    "load.traction.0.on",
    "output.every",
    "checkpoint.every",
    "checkpoint.enabled",
    "solver.contact",
    "scheme.history",
    "scheme.allow_unstable",
    "time.steps.x",
    "mesh.file.x",
    "a..b",
    ".x",
    "x.",
    ".",
    "",
    " ",
    "Γ",
    "time. steps",
    "unknown.key",
];

fn set_value() -> impl Strategy<Value = String> {
    prop_oneof![
        4 => toml_value(),
        2 => expression(),
        1 => any::<String>(),
        1 => Just(String::new()),
        1 => Just("=".to_string()),
    ]
}

fn set_string() -> impl Strategy<Value = String> {
    prop_oneof![
        4 => prop::sample::select(vec![
            "time.steps=16", "time.end=0.5", "friction.enabled=false", "contact.enabled=false",
            "solver.contact=clarabel", "scheme.history=implicit", "material.relaxation.expr=exp(-s)",
            "material.relaxation={table = {s = [0, 1], r = [1, 0]}}", "mesh.model=plane_strain",
            "material.elasticity.enabled=false", "friction.normal_stress=x", "output.every=3",
        ])
        .prop_map(str::to_string),
        8 => (prop::sample::select(SET_KEYS), set_value()).prop_map(|(k, v)| format!("{k}={v}")),
        1 => any::<String>(),
        1 => "[a-z.=\\[\\]\" ]{0,20}",
    ]
}

// ---------------------------------------------------------------------------------------
// The properties
// ---------------------------------------------------------------------------------------

thread_local! {
    /// How far the inputs of the running property got: accepted meshes, loaded scenes,
    /// completed setups, solved steps. Each test runs its cases on its own thread.
    static REACH: std::cell::RefCell<Reach> = Default::default();
}

#[derive(Debug, Default, Clone, Copy)]
struct Reach {
    cases: usize,
    meshes: usize,
    scenes: usize,
    setups: usize,
    steps: usize,
}

fn count(f: impl FnOnce(&mut Reach)) {
    REACH.with(|r| f(&mut r.borrow_mut()));
}

/// Runs `test` on `config().cases` inputs of `strategy`; a failure panics with proptest's
/// report (the minimal failing input). Returns how far the inputs got.
fn fuzz<S: Strategy>(strategy: S, test: impl Fn(S::Value) -> Result<(), TestCaseError>) -> Reach {
    REACH.with(|r| *r.borrow_mut() = Reach::default());
    let mut runner = proptest::test_runner::TestRunner::new(config());
    if let Err(e) = runner.run(&strategy, |v| {
        count(|r| r.cases += 1);
        test(v)
    }) {
        panic!("{e}");
    }
    let reach = REACH.with(|r| *r.borrow());
    println!("{reach:?}");
    reach
}

/// (a) Arbitrary bytes as a .msh file.
#[test]
fn msh_reader_takes_random_bytes() {
    fuzz(prop::collection::vec(any::<u8>(), 0..2048), |b| {
        read_mesh_bytes(&b, false)
    });
}

/// (a) Arbitrary bytes after a valid MSH 4.1 header (ASCII or binary).
#[test]
fn msh_reader_takes_random_bytes_after_a_header() {
    let strategy = (any::<bool>(), prop::collection::vec(any::<u8>(), 0..2048));
    fuzz(strategy, |(binary, bytes)| {
        let mut b = if binary {
            b"$MeshFormat\n4.1 1 8\n\x01\x00\x00\x00\n$EndMeshFormat\n".to_vec()
        } else {
            b"$MeshFormat\n4.1 0 8\n$EndMeshFormat\n".to_vec()
        };
        b.extend_from_slice(&bytes);
        read_mesh_bytes(&b, false)
    });
}

/// (a) Random MSH-like text: sections and lines of small numbers.
#[test]
fn msh_reader_takes_random_sections() {
    fuzz(msh_text(), |b| read_mesh_bytes(&b, true));
}

/// (b) Mutations of a real ASCII mesh; many of them are still accepted (coordinates moved
/// a little, lines swapped) and go on through setup and two steps.
#[test]
fn msh_reader_takes_mutated_ascii_meshes() {
    let base = file("meshes/paper/rect_008.msh");
    let r = fuzz(mutations(), |ms| {
        read_mesh_bytes(&mutated(&base, &ms), true)
    });
    assert!(r.meshes * 50 >= r.cases && r.steps > 0, "{r:?}");
}

/// (b) Mutations of a real binary mesh.
#[test]
fn msh_reader_takes_mutated_binary_meshes() {
    let base = file("meshes/paper/rect_016_binary.msh");
    let r = fuzz(mutations(), |ms| {
        read_mesh_bytes(&mutated(&base, &ms), true)
    });
    assert!(r.meshes * 50 >= r.cases && r.steps > 0, "{r:?}");
}

/// (c) Random TOML-ish text as a scene file.
#[test]
fn scene_parser_takes_random_toml() {
    fuzz(toml_text(), |text| load_scene_bytes(text.as_bytes(), &[]));
}

/// (c) Arbitrary bytes as a scene file.
#[test]
fn scene_parser_takes_random_bytes() {
    fuzz(prop::collection::vec(any::<u8>(), 0..1024), |b| {
        load_scene_bytes(&b, &[])
    });
}

/// (c) Mutations of examples/paper.toml (lines, values, bytes); what loads also gets
/// through setup and two steps.
#[test]
fn scene_parser_takes_mutated_paper_scenes() {
    let base = std::fs::read_to_string(repo().join("examples/paper.toml")).unwrap();
    let mesh = format!("mesh.file={}", mesh_path("paper/rect_008.msh"));
    let r = fuzz(prop::collection::vec(scene_edit(), 1..5), |edits| {
        let bytes = edit_scene(&base, &edits);
        load_scene_bytes(&bytes, &[])?;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.toml");
        std::fs::write(&path, &bytes).unwrap();
        runs_sanely(
            || format!("{}\n  --set {mesh}", show(&bytes)),
            || run_a_little(&path, std::slice::from_ref(&mesh)),
        )
    });
    assert!(r.scenes * 20 >= r.cases && r.steps > 0, "{r:?}");
}

/// (d) Random `--set KEY=VALUE` overrides of examples/paper.toml; what loads also gets
/// through setup and two steps.
#[test]
fn set_overrides_take_random_strings() {
    let scene = repo().join("examples/paper.toml");
    let r = fuzz(prop::collection::vec(set_string(), 1..4), |sets| {
        no_panic(
            || format!("examples/paper.toml --set {sets:?}"),
            || Scene::load(&scene, &sets).is_ok(),
        )?
        .then(|| count(|r| r.scenes += 1));
        let mut all = vec![format!("mesh.file={}", mesh_path("paper/rect_008.msh"))];
        all.extend(sets.iter().cloned());
        runs_sanely(
            || format!("examples/paper.toml --set {all:?}"),
            || run_a_little(&scene, &all),
        )
    });
    assert!(r.scenes * 20 >= r.cases && r.steps > 0, "{r:?}");
}

// ---------------------------------------------------------------------------------------
// The harness itself: the mutators do mutate, the sanity check does catch insane meshes
// ---------------------------------------------------------------------------------------

#[test]
fn mutators_reach_every_section_and_the_real_files_are_sane() {
    for rel in [
        "meshes/paper/rect_008.msh",
        "meshes/paper/rect_016_binary.msh",
    ] {
        let b = file(rel);
        let names: Vec<String> = sections(&b)
            .iter()
            .map(|&(s, _)| {
                let e = b[s..].iter().position(|&c| c == b'\n').unwrap();
                String::from_utf8_lossy(&b[s..s + e]).into_owned()
            })
            .collect();
        for n in [
            "$MeshFormat",
            "$PhysicalNames",
            "$Entities",
            "$Nodes",
            "$Elements",
        ] {
            assert!(names.iter().any(|x| x == n), "{rel}: {names:?}");
        }
        let m = Mesh::read(&repo().join(rel)).unwrap();
        check_mesh(&m).unwrap();
        // A duplicated $Nodes section is refused, not silently merged or panicking.
        let i = names.iter().position(|x| x == "$Nodes").unwrap();
        let dup = mutated(&b, &[Mutation::DuplicateSection(i, usize::MAX)]);
        assert!(dup.len() > b.len());
        read_mesh_bytes(&dup, false).unwrap();
    }
    // The sanity check is not vacuous.
    let mut m = Mesh::read(&repo().join("meshes/paper/rect_008.msh")).unwrap();
    m.triangles[0].swap(1, 2);
    assert!(check_mesh(&m).unwrap_err().contains("signed area"));
    // Token replacement hits the token it is told to.
    assert_eq!(
        mutated(b"a bb c", &[Mutation::Token(1, "X".into())]),
        b"a X c"
    );
    // A panic is turned into a failure carrying the input.
    let e = no_panic(
        || "the input".into(),
        || panic!("boom (an intentional panic)"),
    )
    .unwrap_err();
    assert!(e.to_string().contains("boom") && e.to_string().contains("the input"));
}

// ---------------------------------------------------------------------------------------
// Regressions: inputs the fuzzer (or reading the parsers) found
// ---------------------------------------------------------------------------------------

/// rect_008.msh with `replacements` (each must match exactly once) applied.
fn rect_008_with(replacements: &[(&str, &str)]) -> Vec<u8> {
    let mut text = String::from_utf8(file("meshes/paper/rect_008.msh")).unwrap();
    for (from, to) in replacements {
        assert_eq!(text.matches(from).count(), 1, "{from:?}");
        text = text.replacen(from, to, 1);
    }
    text.into_bytes()
}

/// Reads the bytes: no panic (the failure prints the input), and a sane mesh if accepted.
fn read_regression(bytes: &[u8]) -> Option<Mesh> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("regression.msh");
    std::fs::write(&path, bytes).unwrap();
    match catch_unwind(|| Mesh::read(&path)) {
        Err(_) => panic!("Mesh::read panicked on:\n{}", show(bytes)),
        Ok(Ok(m)) => {
            check_mesh(&m).unwrap();
            Some(m)
        }
        Ok(Err(_)) => None,
    }
}

/// mshio recognizes a section marker after leading blanks (` $Nodes`); the reader's own
/// header check must too, or a section announcing 0 entries reaches mshio's
/// `num_nodes - 1` (`num_elements - 1`), which overflows (a panic with overflow checks).
#[test]
fn indented_section_marker_of_an_empty_section_is_not_a_panic() {
    // Minimal: the whole file.
    read_regression(b"$MeshFormat\n4.1 0 8\n$EndMeshFormat\n $Nodes\n1 0 1 3\n$EndNodes\n");
    for (marker, header, empty) in [
        ("\n$Nodes\n", "\n11 81 1 81\n", "\n11 0 1 81\n"),
        ("\n$Elements\n", "\n6 160 1 160\n", "\n6 0 1 160\n"),
    ] {
        for indent in [" ", "\t"] {
            let m = marker.replacen('\n', &format!("\n{indent}"), 1);
            read_regression(&rect_008_with(&[(marker, &m), (header, empty)]));
            read_regression(&rect_008_with(&[(marker, &m)]));
        }
    }
}

/// A physical tag of i32::MIN in `$Entities` must not overflow `abs()`.
#[test]
fn physical_tag_i32_min_is_not_a_panic() {
    // Minimal: the whole file (one curve entity with physical tag i32::MIN).
    read_regression(
        b"$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Entities\n0 1 0 0\n\
          1 0 0 0 1 0 0 1 -2147483648 0\n$EndEntities\n",
    );
    let bytes = rect_008_with(&[(" 1 3 2 1 -2 \n", " 1 -2147483648 2 1 -2 \n")]);
    // Either refused, or read with the contact group Γ3,1 (tag 3) left empty.
    if let Some(m) = read_regression(&bytes) {
        assert!(m.group("Γ3,1").unwrap().facets.is_empty());
    }
}
