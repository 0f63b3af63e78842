//! Reading a scene file and applying `--set KEY=VALUE` overrides to its TOML tree, with
//! messages that name the file, the key and the line.

use super::SceneFile;
use crate::input_file::read_input_file;
use crate::{Error, Result};
use std::path::Path;

/// Applies one `--set KEY=VALUE` to a TOML tree. The value is read as a TOML value when it
/// parses as one (`64`, `false`, `[[1.0, 10.0]]`, `"x"`) and as a string otherwise.
pub fn apply_override(root: &mut toml::Table, assignment: &str) -> Result<()> {
    let (key, raw) = assignment.split_once('=').ok_or_else(|| {
        Error::input(format!(
            "--set {assignment:?}: expected KEY=VALUE, e.g. --set time.steps=64"
        ))
    })?;
    let key = key.trim();
    let value = parse_value(raw.trim());
    let parts: Vec<&str> = key.split('.').collect();
    if parts.iter().any(|p| p.is_empty()) {
        return Err(Error::input(format!(
            "--set {assignment:?}: '{key}' is not a dotted key path"
        )));
    }
    insert(root, &parts, value).map_err(|part| {
        Error::input(format!(
            "--set {assignment:?}: '{part}' is a value, not a table"
        ))
    })
}

/// Sets the dotted key `parts` of a TOML tree to `value`, making the tables on the way;
/// Err names a part on the way that is a value, not a table.
fn insert(
    root: &mut toml::Table,
    parts: &[&str],
    value: toml::Value,
) -> std::result::Result<(), String> {
    let (last, path) = parts.split_last().expect("a key has at least one part");
    let mut table = root;
    for part in path {
        let entry = table
            .entry(part.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        table = match entry {
            toml::Value::Table(t) => t,
            _ => return Err(part.to_string()),
        };
    }
    table.insert(last.to_string(), value);
    Ok(())
}

/// A scene's TOML text with the dotted key `parts` set to `value` (a typed change of a
/// checked scene, e.g. `Scene::with_time`); `path` names the scene in messages.
pub(super) fn set_key(
    text: &str,
    parts: &[&str],
    value: toml::Value,
    path: &Path,
) -> Result<String> {
    let fail = |why: String| Error::input(format!("{}: {why}", path.display()));
    let mut root: toml::Table = text.parse().map_err(|e| fail(format!("{e}")))?;
    insert(&mut root, parts, value)
        .map_err(|part| fail(format!("'{part}' is a value, not a table")))?;
    toml::to_string(&root).map_err(|e| fail(format!("{e}")))
}

/// serde's messages in the scene's terms: no Rust type names, no repeated key line.
fn plain_serde_message(msg: &str) -> String {
    let mut out = msg
        .lines()
        .filter(|l| !l.trim_start().starts_with("in `") && !l.trim().is_empty())
        .collect::<Vec<_>>()
        .join(" ")
        .replace("expected usize", "expected a whole number ≥ 0")
        .replace("expected f64", "expected a number")
        .replace("expected a boolean", "expected true or false");
    while let Some(p) = out.find("expected struct ") {
        let end = out[p + 16..]
            .find(|c: char| !c.is_alphanumeric())
            .map_or(out.len(), |e| p + 16 + e);
        out.replace_range(p..end, "expected a table");
    }
    out
}

fn parse_value(raw: &str) -> toml::Value {
    // Parse as the right-hand side of `v = …`; anything that is not valid TOML is a string.
    match format!("v = {raw}").parse::<toml::Table>() {
        Ok(mut t) => t
            .remove("v")
            .unwrap_or_else(|| toml::Value::String(raw.into())),
        Err(_) => toml::Value::String(raw.to_string()),
    }
}

/// Reads a scene file and applies the overrides; returns the TOML text after overrides (the
/// exact scene that ran) and the schema-checked tree.
pub fn read_scene_file(path: &Path, overrides: &[String]) -> Result<(String, SceneFile)> {
    let bytes = read_input_file(path, "scene file", Some(SCENE_MAX_BYTES))?;
    let text = String::from_utf8(bytes).map_err(|e| {
        Error::input(format!(
            "scene file '{}' is not UTF-8 text (invalid byte at offset {}); save it as UTF-8",
            path.display(),
            e.utf8_error().valid_up_to()
        ))
    })?;
    parse_scene_text(path, text, overrides)
}

/// A scene is a few kilobytes; a larger file is not one.
const SCENE_MAX_BYTES: u64 = 16 << 20;

/// At most this many characters of a scene's text are quoted in a message.
const EXCERPT: usize = 80;

/// `text` cut to `EXCERPT` characters around byte `at` (a 2 MB line is not echoed whole).
fn excerpt(text: &str, at: usize) -> String {
    let at = at.min(text.len());
    let start = text[..at].rfind('\n').map_or(0, |p| p + 1);
    let end = text[at..].find('\n').map_or(text.len(), |p| at + p);
    let line = &text[start..end];
    let col = text[start..at].chars().count();
    let chars: Vec<char> = line.chars().collect();
    let from = col.saturating_sub(EXCERPT / 2).min(chars.len());
    let to = (from + EXCERPT).min(chars.len());
    format!(
        "{}{}{}",
        if from > 0 { "…" } else { "" },
        chars[from..to].iter().collect::<String>(),
        if to < chars.len() { "…" } else { "" }
    )
}

/// A message cut to a few hundred characters (a huge value quoted by serde, say).
fn shorten(msg: String) -> String {
    const MAX: usize = 300;
    match msg.char_indices().nth(MAX) {
        Some((cut, _)) => format!("{}…", &msg[..cut]),
        None => msg,
    }
}

/// [`read_scene_file`] for a scene text in hand (a checkpoint's): `path` is where the text
/// came from (errors name it; `mesh.file` is relative to its directory).
pub fn parse_scene_text(
    path: &Path,
    text: String,
    overrides: &[String],
) -> Result<(String, SceneFile)> {
    let mut root: toml::Table = text.parse().map_err(|e: toml::de::Error| {
        let at = e.span().map_or(0, |s| s.start);
        let line = text[..at.min(text.len())].matches('\n').count() + 1;
        Error::input(format!(
            "{}: not valid TOML at line {line}: {} (near {:?})",
            path.display(),
            shorten(e.message().trim().to_string()),
            excerpt(&text, at)
        ))
    })?;
    for o in overrides {
        apply_override(&mut root, o)?;
    }
    let effective = if overrides.is_empty() {
        text
    } else {
        toml::to_string(&root).map_err(|e| Error::input(format!("{}: {e}", path.display())))?
    };
    let file: SceneFile =
        serde_path_to_error::deserialize(toml::Value::Table(root)).map_err(|e| {
            let at = e.path().to_string();
            Error::input(format!(
                "{}: {}{}",
                place(path, &at, overrides),
                if at == "." {
                    String::new()
                } else {
                    format!("key '{at}': ")
                },
                shorten(plain_serde_message(&e.into_inner().to_string()))
            ))
        })?;
    Ok((effective, file))
}

/// The `--set KEY=VALUE` that gave `at` its value (its key is `at`, a table holding it or
/// a key within it), if one did.
fn set_of<'o>(overrides: &'o [String], at: &str) -> Option<&'o str> {
    overrides.iter().map(String::as_str).find(|o| {
        let key = o.split('=').next().unwrap_or("").trim();
        at == key || at.starts_with(&format!("{key}.")) || key.starts_with(&format!("{at}."))
    })
}

/// Where the value of key `at` came from, as its error names it: the scene file, or the
/// `--set KEY=VALUE` on the command line (with the scene it overrides).
fn place(path: &Path, at: &str, overrides: &[String]) -> String {
    match set_of(overrides, at) {
        Some(o) => format!("--set {o} (scene {})", path.display()),
        None => path.display().to_string(),
    }
}

/// An input error about a key of the scene at `path` (`PATH: key 'K'…`, as the checks of
/// every section write it) names the `--set` that gave K its value instead of the file, in
/// which the user would look for the value in vain (issue 49).
pub fn name_set_key(e: Error, path: &Path, overrides: &[String]) -> Error {
    let Error::Input(message) = &e else {
        return e;
    };
    let Some(rest) = message.strip_prefix(&format!("{}: key '", path.display())) else {
        return e;
    };
    let key = rest.split('\'').next().unwrap_or_default();
    match set_of(overrides, key) {
        Some(_) => Error::input(format!("{}: key '{rest}", place(path, key, overrides))),
        None => e,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn override_values_are_typed() {
        let mut root: toml::Table = "[time]\nend = 1.0\nsteps = 8\n".parse().unwrap();
        apply_override(&mut root, "time.steps=64").unwrap();
        apply_override(&mut root, "friction.enabled=false").unwrap();
        apply_override(&mut root, "mesh.groups.contact=Γ3,1").unwrap();
        apply_override(&mut root, "material.relaxation.prony=[[1.0, 10.0]]").unwrap();
        assert_eq!(root["time"]["steps"].as_integer(), Some(64));
        assert_eq!(root["friction"]["enabled"].as_bool(), Some(false));
        assert_eq!(root["mesh"]["groups"]["contact"].as_str(), Some("Γ3,1"));
        assert!(root["material"]["relaxation"]["prony"].is_array());
        assert!(apply_override(&mut root, "novalue").is_err());
    }
}
