//! File names that come from outside (HTTP uploads, runners) and must stay inside their folder.

use super::error::StoreError;
use std::path::PathBuf;

/// Longest accepted path component, in bytes.
pub const MAX_COMPONENT_LEN: usize = 128;
/// Deepest accepted path (`a/b/c/d.tif`).
pub const MAX_DEPTH: usize = 4;

/// `rel` as a path inside a store folder, or `BadPath`. Refused: an empty name or component,
/// absolute paths, `.` and `..`, backslashes, NUL and other control characters, components that
/// start with '.' (hidden, and the store's own temporary files), components over 128 bytes, and
/// more than 4 levels. Only '/' separates components.
pub fn safe_relative_path(rel: &str) -> Result<PathBuf, StoreError> {
    let bad = |why: &str| {
        let shown: String = rel.chars().take(80).flat_map(char::escape_debug).collect();
        Err(StoreError::BadPath(format!("'{shown}': {why}")))
    };
    if rel.is_empty() {
        return bad("empty");
    }
    if rel.starts_with('/') {
        return bad("absolute");
    }
    if rel.contains('\\') {
        return bad("contains a backslash");
    }
    if rel.chars().any(char::is_control) {
        return bad("contains a control character");
    }
    let parts: Vec<&str> = rel.split('/').collect();
    if parts.len() > MAX_DEPTH {
        return bad("more than 4 levels");
    }
    let mut path = PathBuf::new();
    for part in parts {
        if part.is_empty() {
            return bad("empty component");
        }
        if part.starts_with('.') {
            return bad("a component starts with '.'");
        }
        if part.len() > MAX_COMPONENT_LEN {
            return bad("a component is longer than 128 bytes");
        }
        path.push(part);
    }
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ordinary_names_pass() {
        for ok in [
            "a.tif",
            "frames/b_ref.tif",
            "a/b/c/d.json",
            "x..y",
            "Ü-ber_1.csv",
        ] {
            let p = safe_relative_path(ok).unwrap();
            assert_eq!(p.to_str().unwrap(), ok);
            assert!(p.is_relative());
        }
    }

    #[test]
    fn escapes_and_oddities_are_refused() {
        let long = "a".repeat(129);
        for bad in [
            "",
            "../x",
            "/etc/passwd",
            "a/../../b",
            ".hidden",
            "a/.hidden",
            "a\\b",
            "..",
            ".",
            "./a",
            "a/./b",
            "a//b",
            "a/",
            "a\0b",
            "a\nb",
            "a/b/c/d/e",
            long.as_str(),
        ] {
            assert!(
                matches!(safe_relative_path(bad), Err(StoreError::BadPath(_))),
                "{bad:?}"
            );
        }
        assert!(safe_relative_path(&"a".repeat(128)).is_ok());
    }
}
