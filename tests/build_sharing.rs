//! The test command builds the Python wheel on top of the workspace's test build
//! (`scripts/test-all.sh`, `python/Cargo.toml`'s `share-test-build` feature): the wheel reuses
//! every crate the tests built only if Cargo resolves each crate of the wheel's graph with the
//! features the test build gave it. A new dev-dependency or feature that breaks this costs no
//! test but ≈ 190 s of the suite (the library and 60 crates built again); this test names the
//! crate that differs.

use std::collections::{BTreeMap, BTreeSet};
use std::process::Command;

/// `package (name and version) -> features`, as `cargo tree` resolves them with `args`.
fn resolved(args: &[&str]) -> BTreeMap<String, BTreeSet<String>> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(cargo)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args([
            "tree",
            "--offline",
            "--prefix",
            "none",
            "--format",
            "{p} [{f}]",
        ])
        .args(args)
        .output()
        .expect("cargo tree runs");
    assert!(
        out.status.success(),
        "cargo tree {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut packages: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        let line = line.trim().trim_end_matches(" (*)");
        let Some((package, features)) = line.strip_suffix(']').and_then(|l| l.split_once(" ["))
        else {
            continue;
        };
        // A path dependency prints its folder, which differs between clones: name and version only.
        let package = package.split(" (").next().unwrap_or(package).to_string();
        packages.entry(package).or_default().extend(
            features
                .split(',')
                .filter(|f| !f.is_empty())
                .map(String::from),
        );
    }
    packages
}

#[test]
fn the_wheel_resolves_every_crate_as_the_test_build_did() {
    // The test build: `cargo test --all-features --workspace --tests` (dev-dependencies active).
    let tests = resolved(&[
        "--workspace",
        "--all-features",
        "--edges",
        "normal,build,dev",
    ]);
    // The wheel: maturin's build of the module alone, with the features test-all.sh names.
    let wheel = resolved(&[
        "--package",
        "ffdic-python",
        "--edges",
        "normal,build",
        "--features",
        "extension-module,share-test-build",
    ]);
    assert!(wheel.contains_key("ffdic v0.1.0"), "{:?}", wheel.keys());
    let differ: Vec<String> = wheel
        .iter()
        .filter(|(package, features)| tests.get(*package) != Some(*features))
        .map(|(package, features)| {
            let built = tests.get(package).cloned().unwrap_or_default();
            format!(
                "{package}: wheel {:?}, tests {:?}",
                features.difference(&built).collect::<Vec<_>>(),
                built.difference(features).collect::<Vec<_>>()
            )
        })
        .collect();
    assert!(
        differ.is_empty(),
        "the wheel would build these crates again (add the dev-dependency or feature to \
         python/Cargo.toml's share-test-build):\n{}",
        differ.join("\n")
    );
}
