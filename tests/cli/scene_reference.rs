//! docs/scene.md is the reference of every key a scene may hold. Its TOML blocks, with the
//! keys written as comments (`# tolerance = 1e-12`) read as keys, make one scene; it must
//! be accepted by the scene parser, and its keys must be exactly the keys the parser
//! accepts (`common::scene::scene_keys`, found by asking the parser), so a key added to the
//! parser without its line in docs/scene.md fails here, and so does a documented key the
//! parser refuses.

use crate::common;

use common::*;
use std::collections::BTreeSet;
use std::path::Path;

/// Keys the parser's schema accepts that the scene check then refuses, with why: the
/// reference does not offer them.
const REFUSED: &[(&str, &str)] = &[(
    "load.body.on",
    "a body force acts on the whole domain (load.body and load.traction share one schema)",
)];

/// The TOML blocks of docs/scene.md as one TOML text, each commented key line uncommented.
fn documented_scene() -> String {
    let doc = std::fs::read_to_string(repo().join("docs/scene.md")).unwrap();
    let mut text = String::new();
    let mut inside = false;
    for line in doc.lines() {
        match line.trim() {
            "```toml" => inside = true,
            "```" => inside = false,
            l if inside => {
                let uncommented = l.strip_prefix('#').map(str::trim_start);
                text.push_str(match uncommented {
                    Some(key_line) if is_key_line(key_line) => key_line,
                    _ => line,
                });
                text.push('\n');
            }
            _ => {}
        }
    }
    text
}

/// Whether `line` starts with `key = `, as a key line of a TOML table does.
fn is_key_line(line: &str) -> bool {
    line.split_once('=').is_some_and(|(key, _)| {
        let key = key.trim_end();
        !key.is_empty()
            && key == key.trim_start()
            && key.chars().all(|c| c.is_ascii_lowercase() || c == '_')
    })
}

/// The keys that hold a value below `value` at `path`, without array indices (an array of
/// tables is walked into: `load.traction.on`).
fn value_keys(path: &str, value: &toml::Value, keys: &mut BTreeSet<String>) {
    let below = |k: &str| {
        if path.is_empty() {
            k.to_string()
        } else {
            format!("{path}.{k}")
        }
    };
    match value {
        toml::Value::Table(t) => t.iter().for_each(|(k, v)| value_keys(&below(k), v, keys)),
        toml::Value::Array(a) if a.iter().all(toml::Value::is_table) && !a.is_empty() => {
            a.iter().for_each(|v| value_keys(path, v, keys))
        }
        _ => {
            keys.insert(path.to_string());
        }
    }
}

#[test]
fn scene_md_documents_every_key_the_parser_accepts_and_no_other() {
    let text = documented_scene();
    let doc: toml::Table = toml::from_str(&text)
        .unwrap_or_else(|e| panic!("docs/scene.md's blocks are not one TOML scene: {e}\n{text}"));
    // Every documented key is accepted (an unknown key is an error naming it).
    if let Err(e) = viscontact::scene::parse_scene_text(Path::new("docs/scene.md"), text, &[]) {
        panic!("the scene parser refuses docs/scene.md's keys: {e}");
    }
    let mut documented = BTreeSet::new();
    value_keys("", &toml::Value::Table(doc), &mut documented);
    let accepted: BTreeSet<String> = common::scene::scene_keys()
        .into_keys()
        .map(|k| k.replace("[0]", ""))
        .collect();
    // The walk works: it finds keys of every kind of nesting.
    for k in [
        "time.steps",
        "material.relaxation.table.s",
        "load.traction.on",
    ] {
        assert!(accepted.contains(k), "the probe missed {k}: {accepted:?}");
    }
    for (key, why) in REFUSED {
        assert!(accepted.contains(*key), "{key} is no longer in the schema");
        assert!(
            !documented.contains(*key),
            "docs/scene.md offers {key}: {why}"
        );
    }
    let offered: BTreeSet<String> = accepted
        .into_iter()
        .filter(|k| REFUSED.iter().all(|(r, _)| r != k))
        .collect();
    let undocumented: Vec<_> = offered.difference(&documented).collect();
    assert!(
        undocumented.is_empty(),
        "docs/scene.md lacks these keys of the scene parser: {undocumented:?}"
    );
    assert_eq!(documented, offered);
}
