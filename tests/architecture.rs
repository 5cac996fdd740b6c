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

/// The Rust files at or under `path`, leaving out `node_modules` folders: npm's packages (the
/// browser tests' `tests/browser/node_modules`), not the project's code.
fn rust_files(path: &Path, out: &mut Vec<PathBuf>) {
    if path.ends_with("node_modules") {
        return;
    }
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

/// The functions in the Rust files under `dir` (of the repository) longer than 100 lines
/// (signature to closing brace), each as `file:line (n lines)`.
fn functions_over_100_lines(dir: &str) -> Vec<String> {
    let mut files = Vec::new();
    rust_files(&root().join(dir), &mut files);
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
    long
}

/// Issue 16: no function in `src/` longer than 100 lines (signature to closing brace).
#[test]
fn no_function_in_src_is_over_100_lines() {
    let long = functions_over_100_lines("src");
    assert!(long.is_empty(), "functions over 100 lines: {long:#?}");
}

/// The same rule for the tests: every Rust file under `tests/` (the browser tests' npm
/// packages in `tests/browser/node_modules` are not ours, and `rust_files` leaves them out).
#[test]
fn no_function_in_tests_is_over_100_lines() {
    let long = functions_over_100_lines("tests");
    assert!(long.is_empty(), "functions over 100 lines: {long:#?}");
}

/// The variants of `EffectId`, read from its definition.
fn effect_variants() -> Vec<String> {
    let text = std::fs::read_to_string(root().join("src/model/effects/id.rs")).unwrap();
    let start = text
        .find("pub enum EffectId {")
        .expect("EffectId is defined");
    let body = &text[start..text[start..].find('}').unwrap() + start];
    body.lines()
        .skip(1)
        .map(|l| l.trim().trim_end_matches(',').to_string())
        .filter(|l| !l.is_empty() && !l.starts_with("//") && !l.starts_with('#'))
        .collect()
}

/// The enums the workspace defines (src/ and the driver, mock and FFT crates): closed
/// vocabularies whose every variant a `match` should name.
fn closed_enums() -> Vec<String> {
    let mut files = Vec::new();
    for dir in ["src", "drivers", "mocks", "fft"] {
        rust_files(&root().join(dir), &mut files);
    }
    let mut names = BTreeSet::new();
    for file in files {
        let code = code_only(&std::fs::read_to_string(&file).unwrap());
        for line in code.lines() {
            let t = line.trim_start();
            let t = t
                .strip_prefix("pub(crate) ")
                .or_else(|| t.strip_prefix("pub(super) "))
                .or_else(|| t.strip_prefix("pub "))
                .unwrap_or(t);
            if let Some(rest) = t.strip_prefix("enum ") {
                let name: String = rest
                    .chars()
                    .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                    .collect();
                if !name.is_empty() {
                    names.insert(name);
                }
            }
        }
    }
    names.into_iter().collect()
}

/// Whether `text` names a variant of one of `enums` as `Enum::Variant`.
fn names_a_variant_of(text: &str, enums: &[String]) -> bool {
    enums.iter().any(|e| {
        text.match_indices(&format!("{e}::")).any(|(k, _)| {
            let before = text[..k].chars().last();
            let after = text[k + e.len() + 2..].chars().next();
            !matches!(before, Some(c) if c.is_alphanumeric() || c == '_')
                && matches!(after, Some(c) if c.is_ascii_uppercase())
        })
    })
}

/// The patterns of a `match`'s arms whose body opens at `open` (the `{`), each with the byte
/// offset where it starts: the text between one arm's end (a `,` or the `}` of a block body at
/// the body's depth) and the next `=>`.
fn arm_patterns(code: &str, open: usize) -> Vec<(usize, &str)> {
    let bytes = code.as_bytes();
    let (mut depth, mut start, mut in_pattern) = (0i32, open + 1, true);
    let mut arms = Vec::new();
    let mut i = open;
    while i < bytes.len() {
        match bytes[i] {
            b'{' | b'(' | b'[' => depth += 1,
            b'}' | b')' | b']' => {
                depth -= 1;
                if depth == 0 {
                    break;
                }
                if depth == 1 && bytes[i] == b'}' && !in_pattern {
                    (start, in_pattern) = (i + 1, true);
                }
            }
            b',' if depth == 1 => (start, in_pattern) = (i + 1, true),
            b'=' if depth == 1 && in_pattern && bytes.get(i + 1) == Some(&b'>') => {
                arms.push((start, &code[start..i]));
                in_pattern = false;
            }
            _ => {}
        }
        i += 1;
    }
    arms
}

/// The catch-all arms of `match`es whose patterns name a variant of a closed enum
/// (`Enum::Variant`, or an `EffectId` variant bare, as `use EffectId::*` writes it), in code
/// without comments and literals: the line of each. A catch-all is `_`; on the effects also a
/// lone binding (`other =>`), which swallows a new effect as `_` does. (Elsewhere a binding is
/// how an error is forwarded whole — `other => Wrap(other)` — which a new variant should be.)
fn wildcards_on_closed_enums(code: &str, enums: &[String], variants: &[String]) -> Vec<usize> {
    let bytes = code.as_bytes();
    let names_an_effect = |pattern: &str| {
        pattern.contains("EffectId::")
            || variants.iter().any(|v| {
                pattern.match_indices(v.as_str()).any(|(k, _)| {
                    let before = pattern[..k].chars().last();
                    let after = pattern[k + v.len()..].chars().next();
                    !matches!(before, Some(c) if c.is_alphanumeric() || c == ':' || c == '_')
                        && !matches!(after, Some(c) if c.is_alphanumeric() || c == '_' || c == ':')
                })
            })
    };
    let mut found = Vec::new();
    let mut search = 0;
    while let Some(at) = code[search..].find("match ") {
        let at = search + at;
        search = at + 6;
        if at > 0 && (bytes[at - 1].is_ascii_alphanumeric() || bytes[at - 1] == b'_') {
            continue;
        }
        let Some(open) = code[at..].find('{').map(|o| at + o) else {
            break;
        };
        let arms = arm_patterns(code, open);
        let on_effects = arms.iter().any(|(_, p)| names_an_effect(p));
        if !on_effects && !arms.iter().any(|(_, p)| names_a_variant_of(p, enums)) {
            continue;
        }
        for (start, pattern) in &arms {
            let p = pattern.trim();
            let binding = !p.is_empty()
                && p.starts_with(|c: char| c.is_ascii_lowercase())
                && p.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
            if p == "_" || on_effects && binding {
                let offset = start + (pattern.len() - pattern.trim_start().len());
                found.push(code[..offset + 1].lines().count());
            }
        }
    }
    found
}

/// Issues 32 and 35: an effect, a job kind, a driver is one unit the compiler walks a
/// contributor through — no `match` that names the variants of a closed enum ends in a wildcard
/// that would swallow a new one.
#[test]
fn no_wildcard_arm_on_a_closed_enum_in_src() {
    let variants = effect_variants();
    assert!(variants.len() >= 14, "{variants:?}");
    let enums = closed_enums();
    for e in [
        "EffectId",
        "RunKind",
        "EventKind",
        "CameraConfig",
        "PoiStatus",
    ] {
        assert!(enums.iter().any(|n| n == e), "{e} in {enums:?}");
    }
    let count = |code: &str| wildcards_on_closed_enums(code, &enums, &variants);
    // The counter finds what it looks for.
    let sample = "fn f(e: EffectId) -> u8 {\n    match e {\n        EffectId::Scale => 1,\n        _ => 0,\n    }\n}\nfn g(p: P) -> u8 {\n    match p {\n        P::A => 1,\n        _ => 0,\n    }\n}\n";
    assert_eq!(count(sample), vec![4]);
    let binding = "fn f(e: EffectId) -> u8 {\n    match e {\n        EffectId::Scale => 1,\n        other => other as u8,\n    }\n}\n";
    assert_eq!(count(binding), vec![4]);
    let guarded = "fn f(e: EffectId, n: u8) -> u8 {\n    match e {\n        Rotation | Scale if n > 0 => 1,\n        EffectId::Scale => 2,\n    }\n}\n";
    assert!(count(guarded).is_empty());
    let tuple = "fn h(e: EffectId, n: &str) -> u8 {\n    match (e, n) {\n        (EffectId::PsfBlur, \"s\") => 1,\n        _ => 0,\n    }\n}\n";
    assert_eq!(count(tuple).len(), 1);
    // Any closed enum of the workspace, not only the effects.
    let kind = "fn k(r: RunKind) -> u8 {\n    match r {\n        RunKind::Study => 1,\n        _ => 0,\n    }\n}\n";
    assert_eq!(count(kind), vec![4]);
    // A foreign enum (serde_json's Value) is not a closed vocabulary of ours.
    let foreign = "fn v(x: &Value) -> u8 {\n    match x {\n        serde_json::Value::Null => 1,\n        _ => 0,\n    }\n}\n";
    assert!(count(foreign).is_empty());
    let mut files = Vec::new();
    rust_files(&root().join("src"), &mut files);
    let mut found = Vec::new();
    for file in files {
        let code = code_only(&std::fs::read_to_string(&file).unwrap());
        for line in count(&code) {
            found.push(format!(
                "{}:{line}",
                file.strip_prefix(root()).unwrap().display()
            ));
        }
    }
    assert!(
        found.is_empty(),
        "wildcard arms on closed enums: {found:#?}"
    );
}

/// Issue 34: the README is for a user who has just cloned the repository — short enough to read
/// before the first command — and neither it nor a page under docs/ points outside the
/// repository (`../shared`) or dates a figure by a commit hash, which a reader cannot resolve:
/// measured figures live in docs/, dated, each with the command that reproduces it.
#[test]
fn the_readme_is_for_users() {
    let readme = std::fs::read_to_string(root().join("README.md")).expect("README.md");
    let lines = readme.lines().count();
    assert!(
        lines < 250,
        "README.md has {lines} lines: fewer than 250, the rest belongs in docs/"
    );
    // The rule finds what it looks for, and passes what the pages legitimately hold.
    assert_eq!(
        commit_hashes(
            "k1 = 1.0227e-4 at `5f5e806`, OpenCorr 44532cc55fc788eda922acd8958fee71db603ab0"
        ),
        ["5f5e806", "44532cc55fc788eda922acd8958fee71db603ab0"]
    );
    let legitimate =
        "0x50 = 80, `deadbeef`, 2560x2160, 2026-11-24, 3.14159e5, 1.0138e-4 ± 0.026e-4, \
         1.5494059725722e-05, exp-20261126t101500-abcdef, `ffdic-dataset/1`, 25,921 points, \
         Kähler";
    assert!(commit_hashes(legitimate).is_empty(), "{legitimate}");
    let mut problems = Vec::new();
    for path in user_pages() {
        let text = std::fs::read_to_string(&path).unwrap();
        let name = path.strip_prefix(root()).unwrap().display().to_string();
        if text.contains("../shared") {
            problems.push(format!("{name}: a ../shared path, outside the repository"));
        }
        for hash in commit_hashes(&text) {
            problems.push(format!(
                "{name}: `{hash}` reads as a commit hash; date it instead"
            ));
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

/// README.md and the Markdown pages directly under docs/.
fn user_pages() -> Vec<PathBuf> {
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root().join("docs"))
        .expect("docs/")
        .map(|entry| entry.unwrap().path())
        .filter(|path| path.extension().is_some_and(|e| e == "md"))
        .collect();
    docs.sort();
    let mut pages = vec![root().join("README.md")];
    pages.extend(docs);
    pages
}

/// Words that read as a git commit hash, abbreviated or full: 7 to 40 lowercase hex digits with
/// at least one digit and one letter. Words are split on everything but ASCII letters and digits,
/// so `0x50`, `2560x2160`, dates, counts, English words and run ids (`exp-…-abcdef`) are not
/// one; nor is a word whose only letter is one `e`: a float's digits around its exponent
/// (`14159e5` of 3.14159e5, `5494059725722e` of 1.5494059725722e-05).
fn commit_hashes(text: &str) -> Vec<&str> {
    let hex = |b: u8| b.is_ascii_digit() || (b'a'..=b'f').contains(&b);
    let float = |w: &str| w.bytes().filter(u8::is_ascii_alphabetic).eq([b'e']);
    text.split(|c: char| !c.is_ascii_alphanumeric())
        .filter(|w| (7..=40).contains(&w.len()) && w.bytes().all(hex))
        .filter(|w| {
            w.bytes().any(|b| b.is_ascii_digit()) && w.bytes().any(|b| b.is_ascii_alphabetic())
        })
        .filter(|&w| !float(w))
        .collect()
}
