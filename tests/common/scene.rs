//! The tests' one way to write a scene file: a [`SceneText`] starts from a base (a shipped
//! example, a scene of tests/data, or a bare scene on a mesh), is edited key by key and
//! written out. It holds the scene as a TOML table, so an edit names the key the scene
//! reference names (`"time.steps"`, `"material.relaxation.prony[0][1]"`,
//! `"load.traction[1].value"`) rather than a line of text, and the file it writes is the
//! table: formatted by the toml crate, comments dropped, the same scene.
//!
//! A test that must write a file the scene reader refuses as TOML (a syntax error, an
//! integer beyond 64 bits) writes that text itself; everything that is TOML goes through
//! here.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use toml::{Table, Value};

/// A scene file's contents, built by a test.
#[derive(Clone, Debug)]
pub struct SceneText {
    /// Always a table.
    root: Value,
}

impl SceneText {
    /// A scene with nothing but `mesh.file = mesh`: every other key at its default until set.
    pub fn on(mesh: impl AsRef<Path>) -> SceneText {
        SceneText::parse("").mesh(mesh)
    }

    /// The scene written in TOML as `text`.
    pub fn parse(text: &str) -> SceneText {
        let table: Table =
            toml::from_str(text).unwrap_or_else(|e| panic!("not a TOML scene: {e}\n{text}"));
        SceneText {
            root: Value::Table(table),
        }
    }

    /// The scene file at `path` with a relative `mesh.file` made absolute (it is read from
    /// the scene's directory), so that the copy may be written anywhere.
    pub fn file(path: &Path) -> SceneText {
        let text =
            std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let mut scene = SceneText::parse(&text);
        let relative = scene
            .get("mesh.file")
            .and_then(Value::as_str)
            .filter(|m| Path::new(m).is_relative());
        if let Some(mesh) = relative {
            let from = path.parent().unwrap().join(mesh);
            let abs = from
                .canonicalize()
                .unwrap_or_else(|e| panic!("{}: {e}", from.display()));
            scene = scene.mesh(abs);
        }
        scene
    }

    /// examples/`name`, its mesh path made absolute.
    pub fn example(name: &str) -> SceneText {
        SceneText::file(&super::repo().join("examples").join(name))
    }

    /// examples/paper.toml: the paper's Section 4 (contact on Γ3,1, friction on Γ3,2, the
    /// Prony kernel e^{−10 s}, two tractions) on rect_032 with k = 1/32.
    pub fn paper() -> SceneText {
        SceneText::example("paper.toml")
    }

    /// examples/block.toml: the paper's scene extruded to the 3D block.
    pub fn block() -> SceneText {
        SceneText::example("block.toml")
    }

    /// The unstructured square (tests/data/patch_square.msh) with no clamped group, for the
    /// scenes that prescribe its boundary: T = 0.5 in 5 steps, viscosity θ = 0.3, ζ = 0.2,
    /// elasticity E = 2, ν = 0.3 and the Prony kernel e^{−s}.
    pub fn unclamped_square() -> SceneText {
        SceneText::on(super::repo().join("tests/data/patch_square.msh"))
            .set("mesh.groups.fixed", Value::Array(vec![]))
            .set("time.end", 0.5)
            .set("time.steps", 5)
            .set("material.viscosity.theta", 0.3)
            .set("material.viscosity.zeta", 0.2)
            .set("material.elasticity.young", 2.0)
            .set("material.elasticity.poisson", 0.3)
            .literal("material.relaxation.prony", "[[1.0, 1.0]]")
    }

    /// The unstructured slider (meshes/3d/slider.msh: clamped on top, friction on the
    /// bottom) with viscosity only (each step is the same static problem), F = 1, friction
    /// coefficient `mu` (an expression of x, y) and a body force of unit size at
    /// `angle_deg` to the x axis; one step.
    pub fn slider(mu: &str, angle_deg: f64) -> SceneText {
        let a = angle_deg.to_radians();
        SceneText::on(super::mesh_path("3d/slider.msh"))
            .set("name", "slider")
            .set("mesh.model", "3d")
            .set("mesh.groups.fixed", "Γ1")
            .set("mesh.groups.traction", "Γ2")
            .set("mesh.groups.friction", "Γ3,2")
            .set("time.end", 1.0)
            .set("time.steps", 1)
            .set("material.viscosity.theta", 1.0)
            .set("material.viscosity.zeta", 0.5)
            .set("friction.normal_stress", 1.0)
            .set("friction.coefficient", mu)
            .body(&[&a.cos().to_string(), &a.sin().to_string(), "0"])
    }

    /// `mesh.file = mesh`.
    pub fn mesh(self, mesh: impl AsRef<Path>) -> SceneText {
        self.set("mesh.file", mesh.as_ref().display().to_string())
    }

    /// Sets `key` (dotted, with `[i]` for the i-th element of an array:
    /// `"load.traction[1].value"`, `"material.relaxation.prony[0][1]"`) to `value`, making
    /// the tables and arrays on the way (an array is filled up with empty tables).
    pub fn set(mut self, key: &str, value: impl Into<Value>) -> SceneText {
        set_at(&mut self.root, &segments(key), value.into());
        self
    }

    /// Sets `key` to the value written in TOML as `literal` (`"1e-300"`, `"[[1.0, 10.0]]"`,
    /// `"inf"`): for values that are easier read as TOML than built.
    pub fn literal(self, key: &str, literal: &str) -> SceneText {
        let mut one: Table = toml::from_str(&format!("v = {literal}"))
            .unwrap_or_else(|e| panic!("{literal:?} is not a TOML value: {e}"));
        self.set(key, one.remove("v").unwrap())
    }

    /// Sets `key` to the table written in TOML as `body` (its `key = value` lines): a
    /// section given whole, such as a relaxation kernel.
    pub fn table(self, key: &str, body: &str) -> SceneText {
        let table: Table =
            toml::from_str(body).unwrap_or_else(|e| panic!("{body:?} is not a TOML table: {e}"));
        self.set(key, table)
    }

    /// An empty section `[key]` (such as `[contact]`, which switches contact on).
    pub fn section(self, key: &str) -> SceneText {
        self.set(key, Table::new())
    }

    /// Removes the table entry `key` (which must be there).
    pub fn remove(mut self, key: &str) -> SceneText {
        let (table, name) = key.rsplit_once('.').unwrap_or(("", key));
        let removed = match get_at(&mut self.root, &segments(table)) {
            Some(Value::Table(t)) => t.remove(name),
            _ => None,
        };
        assert!(removed.is_some(), "{key} is not in the scene");
        self
    }

    /// Appends an entry to the array of tables `key` (`[[key]]`).
    pub fn push(self, key: &str, entry: Table) -> SceneText {
        let n = self.get(key).map_or(0, |v| v.as_array().unwrap().len());
        self.set(&format!("{key}[{n}]"), entry)
    }

    /// Appends a `[[load.traction]]` with `value` (its components, numbers or expressions as
    /// TOML strings) on the group `on` (`None`: the default, `mesh.groups.traction`).
    pub fn traction(self, on: Option<&str>, value: &[impl AsRef<str>]) -> SceneText {
        let mut entry = Table::new();
        if let Some(on) = on {
            entry.insert("on".into(), on.into());
        }
        entry.insert("value".into(), strings(value));
        self.push("load.traction", entry)
    }

    /// Appends a `[[load.body]]` with `value` (its components).
    pub fn body(self, value: &[impl AsRef<str>]) -> SceneText {
        let mut entry = Table::new();
        entry.insert("value".into(), strings(value));
        self.push("load.body", entry)
    }

    /// Appends a `[[dirichlet]]` on the group `on` holding `components` (names, or
    /// ["normal"]) at `value` (one expression each; `None`: zero).
    pub fn dirichlet(self, on: &str, components: &[&str], value: Option<&[&str]>) -> SceneText {
        let mut entry = Table::new();
        entry.insert("on".into(), on.into());
        entry.insert("components".into(), strings(components));
        if let Some(v) = value {
            entry.insert("value".into(), strings(v));
        }
        self.push("dirichlet", entry)
    }

    /// The value of `key`, if the scene has it.
    pub fn get(&self, key: &str) -> Option<&Value> {
        segments(key)
            .iter()
            .try_fold(&self.root, |v, seg| match *seg {
                Seg::Key(k) => v.get(k),
                Seg::Index(i) => v.get(i),
            })
    }

    /// The scene as TOML text (checked to read back as the same scene: to the same text,
    /// as NaN is not equal to itself).
    pub fn text(&self) -> String {
        let text = toml::to_string(&self.root).unwrap();
        let back: Table = toml::from_str(&text).unwrap();
        assert_eq!(
            toml::to_string(&back).unwrap(),
            text,
            "the scene does not read back"
        );
        text
    }

    /// Writes the scene as `name` into `dir` and returns its path.
    pub fn write(&self, dir: &Path, name: &str) -> PathBuf {
        super::write(dir, name, &self.text())
    }
}

/// Every key a scene may hold, found by asking the scene parser itself, so that a key added
/// to it cannot escape the tests that walk them: each table gets an unknown key, whose error
/// lists the table's fields; each field gets a table, whose error says what the field
/// expects (a table: walked in turn; a sequence: its first element, walked as `[0]`; else a
/// value). The keys that hold a value, by path with `[0]` for an array's element
/// (`"material.relaxation.prony[0][0]"`, `"load.traction[0].on"`), each with the parser's
/// message for a table there, which says what it expects (`"… expected a number"`).
pub fn scene_keys() -> BTreeMap<String, String> {
    let mut keys = BTreeMap::new();
    walk_keys(String::new(), &mut keys);
    keys
}

/// The keys at or below `path` into `keys` ([`scene_keys`]).
fn walk_keys(path: String, keys: &mut BTreeMap<String, String>) {
    let probe = Table::from_iter([("zzz_probe".to_string(), Value::Integer(1))]);
    let msg = parse_error(&path, Value::Table(probe));
    if msg.contains("unknown field `zzz_probe`") {
        for field in expected_fields(&msg) {
            let below = if path.is_empty() {
                field
            } else {
                format!("{path}.{field}")
            };
            walk_keys(below, keys);
        }
    } else if msg.contains("expected a sequence") || msg.contains("expected an array") {
        walk_keys(format!("{path}[0]"), keys);
    } else {
        keys.insert(path, msg);
    }
}

/// The parser's message for the smallest scene its schema takes with `value` at `path` (a
/// key of [`SceneText::set`]; `""` replaces the whole scene).
fn parse_error(path: &str, value: Value) -> String {
    let base =
        SceneText::parse("[time]\nend = 1.0\nsteps = 4\n[material.viscosity]\ntheta = 0.1\n");
    let text = base.mesh("m.msh").set(path, value).text();
    match viscontact::scene::parse_scene_text(Path::new("s.toml"), text, &[]) {
        Ok(_) => String::new(),
        Err(e) => e.to_string(),
    }
}

/// The names between backticks after "expected" in serde's unknown-field message.
fn expected_fields(msg: &str) -> Vec<String> {
    let tail = &msg[msg.find("expected").unwrap_or(msg.len())..];
    tail.split('`')
        .skip(1)
        .step_by(2)
        .map(String::from)
        .collect()
}

/// One step of a key path: a table's key or an array's element.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Seg<'a> {
    Key(&'a str),
    Index(usize),
}

/// The steps of `"a.b[0][1].c"`: a, b, 0, 1, c (`""`: none).
fn segments(key: &str) -> Vec<Seg<'_>> {
    let mut out = Vec::new();
    for part in key.split('.').filter(|p| !p.is_empty()) {
        let mut pieces = part.split('[');
        out.push(Seg::Key(pieces.next().unwrap()));
        for i in pieces {
            let i = i.strip_suffix(']').and_then(|i| i.parse().ok());
            out.push(Seg::Index(
                i.unwrap_or_else(|| panic!("{key}: a bad index")),
            ));
        }
    }
    out
}

/// Sets `value` at `path` below `root`, making the tables and arrays on the way.
fn set_at(root: &mut Value, path: &[Seg], value: Value) {
    let Some((first, rest)) = path.split_first() else {
        *root = value;
        return;
    };
    let child = match *first {
        Seg::Key(k) => {
            if !root.is_table() {
                *root = Value::Table(Table::new());
            }
            let t = root.as_table_mut().unwrap();
            t.entry(k).or_insert(Value::Table(Table::new()))
        }
        Seg::Index(i) => {
            if !root.is_array() {
                *root = Value::Array(Vec::new());
            }
            let a = root.as_array_mut().unwrap();
            while a.len() <= i {
                a.push(Value::Table(Table::new()));
            }
            &mut a[i]
        }
    };
    set_at(child, rest, value);
}

/// The value at `path` below `root`, if there is one.
fn get_at<'v>(root: &'v mut Value, path: &[Seg]) -> Option<&'v mut Value> {
    path.iter().try_fold(root, |v, seg| match *seg {
        Seg::Key(k) => v.get_mut(k),
        Seg::Index(i) => v.get_mut(i),
    })
}

/// A TOML array of strings.
pub fn strings(items: &[impl AsRef<str>]) -> Value {
    Value::Array(items.iter().map(|s| s.as_ref().into()).collect())
}
