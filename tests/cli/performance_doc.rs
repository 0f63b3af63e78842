//! docs/performance.md begins with what holds today, in one table, and keeps the history
//! after it; the code and the docs point into it by title (`docs/performance.md,
//! "Threads"`), and every such title is one of its headings or bold paragraph titles.

use crate::common;

use common::*;

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
