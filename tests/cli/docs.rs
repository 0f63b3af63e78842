//! The docs against the code they describe: docs/performance.md begins with what holds
//! today, in one table, and keeps the history after it; the code and the docs point into it
//! by title (`docs/performance.md, "Threads"`), and every such title is one of its headings
//! or bold paragraph titles; docs/architecture.md's floors hold every module of src/, and
//! each module names (`crate::…`) only modules on the floors below its own; and every
//! document the repository names is in it.

use crate::common;

use common::*;
use std::collections::{BTreeMap, BTreeSet};

fn read(rel: &str) -> String {
    std::fs::read_to_string(repo().join(rel)).unwrap()
}

#[test]
fn performance_md_begins_with_one_table_of_today_then_the_history() {
    let doc = read("docs/performance.md");
    let sections: Vec<&str> = doc.split("\n## ").skip(1).collect();
    let names: Vec<&str> = sections.iter().map(|s| s.lines().next().unwrap()).collect();
    assert_eq!(
        names,
        ["Today", "History"],
        "docs/performance.md's top-level sections"
    );
    let tables = sections[0]
        .lines()
        .filter(|l| l.starts_with("|---"))
        .count();
    assert_eq!(tables, 1, "\"Today\" holds one table");
}

/// The text of a file as one line of words: a Rust file's comments only, a Markdown file
/// whole (a title that a comment wraps over two lines reads as written).
fn words(text: &str, rust: bool) -> String {
    let lines = text.lines().map(|l| {
        let l = l.trim_start();
        if !rust {
            l
        } else {
            ["///", "//!", "//"]
                .iter()
                .find_map(|c| l.strip_prefix(c))
                .unwrap_or("")
        }
    });
    lines
        .flat_map(str::split_whitespace)
        .collect::<Vec<_>>()
        .join(" ")
}

/// The titles quoted after `performance.md, ` in `text` (one line of words).
fn pointers(text: &str) -> Vec<String> {
    text.split("performance.md, \"")
        .skip(1)
        .filter_map(|rest| rest.split_once('"').map(|(title, _)| title.to_string()))
        .collect()
}

#[test]
fn every_pointer_into_performance_md_names_one_of_its_titles() {
    let doc = read("docs/performance.md");
    let titles: Vec<String> = doc
        .lines()
        .filter_map(|l| {
            let heading = l.starts_with('#').then(|| l.trim_start_matches('#').trim());
            let bold = l
                .strip_prefix("**")
                .and_then(|b| b.split_once("**").map(|t| t.0));
            heading.or(bold).map(|t| words(t, false))
        })
        .collect();
    let mut files = repo_files("src", "rs");
    files.extend(repo_files("docs", "md"));
    files.push(repo().join("README.md"));
    let mut seen = 0;
    for file in &files {
        let text = std::fs::read_to_string(file).unwrap();
        let rust = file.extension().is_some_and(|x| x == "rs");
        for title in pointers(&words(&text, rust)) {
            seen += 1;
            assert!(
                titles.iter().any(|t| t.starts_with(&title)),
                "{} points to docs/performance.md, \"{title}\", which has no such title",
                file.display()
            );
        }
    }
    assert!(
        seen >= 5,
        "only {seen} pointers found: the search is broken"
    );
}

/// The floor of every module in docs/architecture.md's table, counted from 0 at the bottom:
/// a row is one floor, but the modules of its bottom row ("5–1") each stand on their own,
/// the first listed highest.
fn floors() -> BTreeMap<String, usize> {
    let doc = read("docs/architecture.md");
    let rows: Vec<(bool, Vec<String>)> = doc
        .lines()
        .filter_map(|l| {
            let cells: Vec<&str> = l.split('|').map(str::trim).collect();
            let number = cells.get(1)?;
            let is_floor =
                !number.is_empty() && number.chars().all(|c| c.is_ascii_digit() || c == '–');
            is_floor.then(|| {
                let modules = cells[2]
                    .split('`')
                    .skip(1)
                    .step_by(2)
                    .map(|m| m.trim_end_matches('/').trim_end_matches(".rs").to_string())
                    .collect();
                (number.contains('–'), modules)
            })
        })
        .collect();
    let mut floor = BTreeMap::new();
    let mut level = 0;
    for (several, modules) in rows.iter().rev() {
        if *several {
            for m in modules.iter().rev() {
                floor.insert(m.clone(), level);
                level += 1;
            }
        } else {
            for m in modules {
                floor.insert(m.clone(), level);
            }
            level += 1;
        }
    }
    floor
}

/// The top-level modules a file names through `crate::` (or `viscontact::`, in main.rs),
/// `use crate::{…}` groups included; `Error` and `Result` are the `error` module's.
fn named_modules(text: &str) -> BTreeSet<String> {
    let mut names = BTreeSet::new();
    for prefix in ["crate::", "viscontact::"] {
        for rest in text.split(prefix).skip(1) {
            let items: Vec<&str> = match rest.strip_prefix('{') {
                Some(group) => top_level_items(group),
                None => vec![rest],
            };
            for item in items {
                let name: String = item
                    .trim_start()
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect();
                names.insert(match name.as_str() {
                    "Error" | "Result" => "error".to_string(),
                    // The crate's two macros, exported at its root.
                    "outln" | "errln" => "console".to_string(),
                    _ => name,
                });
            }
        }
    }
    names.remove("");
    names
}

/// The items of a `use` group up to its closing brace, split at its top-level commas.
fn top_level_items(group: &str) -> Vec<&str> {
    let (mut depth, mut start, mut items) = (0, 0, Vec::new());
    for (i, c) in group.char_indices() {
        match c {
            '{' => depth += 1,
            '}' if depth == 0 => {
                items.push(&group[start..i]);
                break;
            }
            '}' => depth -= 1,
            ',' if depth == 0 => {
                items.push(&group[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    items
}

#[test]
fn architecture_md_floors_hold_every_module_and_imports_run_down() {
    let floor = floors();
    // The test helpers of `#[cfg(test)] mod testing` stand outside the layering.
    let outside = ["lib", "testing"];
    let mut modules = BTreeMap::<String, BTreeSet<String>>::new();
    for file in repo_files("src", "rs") {
        let rel = file.strip_prefix(repo().join("src")).unwrap();
        let top = rel.iter().next().unwrap().to_string_lossy();
        let module = top.trim_end_matches(".rs").to_string();
        let text = std::fs::read_to_string(&file).unwrap();
        modules
            .entry(module)
            .or_default()
            .extend(named_modules(&text));
    }
    for (module, names) in &modules {
        if outside.contains(&module.as_str()) {
            continue;
        }
        let Some(&own) = floor.get(module) else {
            panic!("docs/architecture.md's floors lack the module {module}");
        };
        for name in names
            .iter()
            .filter(|n| *n != module && !outside.contains(&n.as_str()))
        {
            let below = floor.get(name).is_some_and(|&f| f < own);
            assert!(
                below,
                "src/{module} names {name}, which docs/architecture.md's floors do not put \
                 below it"
            );
        }
    }
    assert!(
        floor.len() >= 20,
        "the floors table was not read: {floor:?}"
    );
}

/// The documents `text` (one line of words) names: `docs/….md`, a project document in
/// capitals (`README.md`), and in a Markdown file the targets of its links (`](memory.md)`);
/// not the files a command writes (`study.md`).
fn named_documents(text: &str, markdown: bool) -> Vec<String> {
    let word = |c: char| c.is_ascii_alphanumeric() || "_./-".contains(c);
    let mut names = Vec::new();
    for (i, _) in text.match_indices(".md") {
        if text[i + 3..].starts_with(|c: char| c.is_ascii_alphanumeric()) {
            continue;
        }
        let start = text[..i]
            .char_indices()
            .rev()
            .find(|&(_, c)| !word(c))
            .map_or(0, |(s, c)| s + c.len_utf8());
        let name = &text[start..i + 3];
        let stem = name.trim_end_matches(".md");
        let capitals = !stem.is_empty() && stem.chars().all(|c| c.is_ascii_uppercase() || c == '_');
        let link = markdown && text[..start].ends_with("](");
        if name.starts_with("docs/") || capitals || link {
            names.push(name.to_string());
        }
    }
    names
}

#[test]
fn every_document_the_repository_names_is_in_it() {
    let mut files = Vec::new();
    for (dir, ext) in [
        ("src", "rs"),
        ("docs", "md"),
        ("tests", "rs"),
        ("examples", "rs"),
    ] {
        files.extend(repo_files(dir, ext));
    }
    files.extend(repo_files("scripts", "sh"));
    files.extend(repo_files("scripts", "py"));
    files.push(repo().join("README.md"));
    let mut seen = 0;
    for file in &files {
        let markdown = file.extension().is_some_and(|x| x == "md");
        let text = std::fs::read_to_string(file).unwrap();
        for name in named_documents(&text, markdown) {
            seen += 1;
            let here = file.parent().unwrap().join(&name);
            assert!(
                repo().join(&name).is_file() || here.is_file(),
                "{} names {name}, which is not in the repository: cite the repository's own \
                 docs, or say the thing itself",
                file.display()
            );
        }
    }
    assert!(
        seen >= 50,
        "only {seen} documents named: the search is broken"
    );
}
