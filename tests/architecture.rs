//! ARCHITECTURE.md's arrows are the code's (issue 16): the fenced `arrows` block lists, for each
//! top-level module of `src/`, the modules it uses; this test reads every `crate::…` path in
//! that module's files and fails on an import the block does not list, on a listed arrow the
//! code no longer uses (the document must stay true), on a module the block forgets, and on a
//! cycle.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `module -> [modules]` from the ```arrows block of ARCHITECTURE.md.
fn documented() -> BTreeMap<String, BTreeSet<String>> {
    let text = std::fs::read_to_string(root().join("ARCHITECTURE.md")).expect("ARCHITECTURE.md");
    let block = text
        .split("```arrows\n")
        .nth(1)
        .and_then(|rest| rest.split("```").next())
        .expect("ARCHITECTURE.md has an ```arrows block");
    block
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .map(|line| {
            let (from, to) = line
                .split_once("->")
                .unwrap_or_else(|| panic!("not `module -> modules`: {line}"));
            (
                from.trim().to_string(),
                to.split_whitespace().map(String::from).collect(),
            )
        })
        .collect()
}

fn rust_files(path: &Path, out: &mut Vec<PathBuf>) {
    if path.is_dir() {
        for entry in std::fs::read_dir(path).unwrap() {
            rust_files(&entry.unwrap().path(), out);
        }
    } else if path.extension().is_some_and(|e| e == "rs") {
        out.push(path.to_owned());
    }
}

/// The modules a top-level module's files name as `crate::module`.
fn used_by(module: &str) -> BTreeSet<String> {
    let dir = root().join("src").join(module);
    let mut files = Vec::new();
    if dir.is_dir() {
        rust_files(&dir, &mut files);
    } else {
        files.push(root().join("src").join(format!("{module}.rs")));
    }
    let mut used = BTreeSet::new();
    for file in files {
        let text = std::fs::read_to_string(&file).unwrap();
        // Grouped imports (`use crate::{a, b}`) would hide arrows from this reading.
        assert!(
            !text.contains("crate::{"),
            "{}: name each module in its own `use crate::module::…`",
            file.display()
        );
        for (i, _) in text.match_indices("crate::") {
            // `ffdic::crate::` never occurs; skip `$crate::` in macros.
            if text[..i].ends_with('$') {
                continue;
            }
            let name: String = text[i + "crate::".len()..]
                .chars()
                .take_while(|c| c.is_ascii_lowercase() || *c == '_' || c.is_ascii_digit())
                .collect();
            if !name.is_empty() && name != module {
                used.insert(name);
            }
        }
    }
    used
}

/// The library's top-level modules, from `src/lib.rs`.
fn library_modules() -> BTreeSet<String> {
    std::fs::read_to_string(root().join("src/lib.rs"))
        .unwrap()
        .lines()
        .filter_map(|l| l.trim().strip_prefix("pub mod "))
        .map(|m| m.trim_end_matches(';').to_string())
        .collect()
}

#[test]
fn every_import_follows_an_arrow_of_architecture_md() {
    let arrows = documented();
    let modules = library_modules();
    let listed: BTreeSet<String> = arrows.keys().cloned().collect();
    assert_eq!(
        listed, modules,
        "the arrows block lists exactly the library's modules (src/lib.rs)"
    );
    let mut problems = Vec::new();
    for (module, allowed) in &arrows {
        let used = used_by(module);
        for m in used.difference(allowed) {
            problems.push(format!(
                "{module} uses {m}: not an arrow of ARCHITECTURE.md"
            ));
        }
        for m in allowed.difference(&used) {
            problems.push(format!(
                "{module} -> {m} is listed but no longer used: take it out of ARCHITECTURE.md"
            ));
        }
        for m in allowed {
            assert!(modules.contains(m), "{module} -> {m}: no such module");
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

/// Panics naming the modules of a cycle in `arrows` (Kahn's algorithm: repeatedly take a module
/// whose every target is already taken; targets outside `arrows` count as taken).
fn assert_acyclic(arrows: &BTreeMap<String, BTreeSet<String>>, what: &str) {
    let mut placed: BTreeSet<String> = BTreeSet::new();
    while placed.len() < arrows.len() {
        let next = arrows
            .iter()
            .find(|(m, to)| {
                !placed.contains(*m)
                    && to
                        .iter()
                        .all(|t| placed.contains(t) || !arrows.contains_key(t))
            })
            .map(|(m, _)| m.clone());
        match next {
            Some(m) => {
                placed.insert(m);
            }
            None => {
                let left: Vec<&String> = arrows.keys().filter(|m| !placed.contains(*m)).collect();
                panic!("{what}: a cycle among {left:?}");
            }
        }
    }
}

/// The files of `src/diagnose/` import one another without a cycle (issue 18: the result types
/// in `results.rs`, the stage's landing in `stage_landing.rs`, the noise-floor read-out in
/// `floor_read_out.rs`, so each step imports what it needs and not the steps beside it).
#[test]
fn the_files_of_diagnose_have_no_cycle() {
    let dir = root().join("src/diagnose");
    let mut files = Vec::new();
    rust_files(&dir, &mut files);
    let names: BTreeSet<String> = files
        .iter()
        .map(|f| f.file_stem().unwrap().to_string_lossy().into_owned())
        .collect();
    let mut arrows = BTreeMap::new();
    for file in &files {
        let name = file.file_stem().unwrap().to_string_lossy().into_owned();
        let code = code_only(&std::fs::read_to_string(file).unwrap());
        let code = code.split("#[cfg(test)]").next().unwrap_or_default();
        let uses: BTreeSet<String> = code
            .split("super::")
            .skip(1)
            .filter_map(|rest| {
                let word: String = rest
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect();
                (word != name && names.contains(&word)).then_some(word)
            })
            .collect();
        arrows.insert(name, uses);
    }
    assert!(arrows["compare"].contains("results"), "{arrows:?}");
    assert_acyclic(&arrows, "src/diagnose");
}

#[test]
fn the_arrows_have_no_cycle() {
    let arrows = documented();
    assert_acyclic(&arrows, "ARCHITECTURE.md");
    // The numerics know nothing of files, HTTP, cameras or jobs (the mission's rule).
    for numeric in ["dic", "model", "reduce"] {
        for forbidden in [
            "atomic_write",
            "store",
            "api",
            "service",
            "experiment",
            "dataset",
        ] {
            assert!(
                !arrows[numeric].contains(forbidden),
                "{numeric} must not use {forbidden}"
            );
        }
    }
}

/// `text` with the contents of string and character literals and of comments blanked (newlines
/// kept), so the braces left are the code's.
fn code_only(text: &str) -> String {
    let chars: Vec<char> = text.chars().collect();
    let mut out = String::with_capacity(text.len());
    let mut i = 0;
    let blank = |c: char| if c == '\n' { '\n' } else { ' ' };
    while i < chars.len() {
        let c = chars[i];
        let next = chars.get(i + 1).copied();
        if c == '/' && next == Some('/') {
            while i < chars.len() && chars[i] != '\n' {
                i += 1;
            }
        } else if c == '/' && next == Some('*') {
            while i + 1 < chars.len() && !(chars[i] == '*' && chars[i + 1] == '/') {
                out.push(blank(chars[i]));
                i += 1;
            }
            i += 2;
        } else if c == 'r' && (next == Some('"') || next == Some('#')) {
            // A raw string r#…"…"#…: ends at a quote followed by as many #.
            let mut j = i + 1;
            let mut hashes = 0;
            while chars.get(j) == Some(&'#') {
                hashes += 1;
                j += 1;
            }
            if chars.get(j) != Some(&'"') {
                out.push(c);
                i += 1;
                continue;
            }
            j += 1;
            while j < chars.len() {
                if chars[j] == '"' && (1..=hashes).all(|k| chars.get(j + k) == Some(&'#')) {
                    break;
                }
                out.push(blank(chars[j]));
                j += 1;
            }
            i = j + 1 + hashes;
        } else if c == '"' {
            i += 1;
            while i < chars.len() && chars[i] != '"' {
                if chars[i] == '\\' {
                    i += 1;
                }
                out.push(blank(chars[i]));
                i += 1;
            }
            i += 1;
        } else if c == '\'' && (chars.get(i + 2) == Some(&'\'') || next == Some('\\')) {
            // A character literal ('{', '\n', '\''); a lifetime ('a) has no closing quote.
            i += 1;
            while i < chars.len() && chars[i] != '\'' {
                if chars[i] == '\\' {
                    i += 1;
                }
                i += 1;
            }
            i += 1;
        } else {
            out.push(c);
            i += 1;
        }
    }
    out
}

/// Issue 16: no function in `src/` longer than 100 lines (signature to closing brace).
#[test]
fn no_function_in_src_is_over_100_lines() {
    let mut files = Vec::new();
    rust_files(&root().join("src"), &mut files);
    let mut long = Vec::new();
    for file in files {
        let code = code_only(&std::fs::read_to_string(&file).unwrap());
        let lines: Vec<&str> = code.lines().collect();
        for (start, line) in lines.iter().enumerate() {
            let words: Vec<&str> = line.split_whitespace().collect();
            let Some(at) = words.iter().position(|w| *w == "fn") else {
                continue;
            };
            if !words[..at]
                .iter()
                .all(|w| w.starts_with("pub") || matches!(*w, "async" | "const" | "unsafe"))
            {
                continue;
            }
            let mut depth = 0i32;
            let mut opened = false;
            for (k, l) in lines[start..].iter().enumerate() {
                for ch in l.chars() {
                    match ch {
                        '{' => {
                            depth += 1;
                            opened = true;
                        }
                        '}' => depth -= 1,
                        _ => {}
                    }
                }
                if !opened && l.trim_end().ends_with(';') {
                    break;
                }
                if opened && depth == 0 {
                    if k + 1 > 100 {
                        long.push(format!(
                            "{}:{} ({} lines)",
                            file.strip_prefix(root()).unwrap().display(),
                            start + 1,
                            k + 1
                        ));
                    }
                    break;
                }
            }
        }
    }
    assert!(long.is_empty(), "functions over 100 lines: {long:#?}");
}
