//! Small file-system helpers shared by the run and dataset halves of the store.

use super::error::{io, Result, StoreError};
use super::paths::safe_relative_path;
use crate::atomic_write::{write_atomically_as, Sync};
use serde::{de::DeserializeOwned, Serialize};
use std::path::Path;

/// The JSON document at `path`; `None` when there is no such file.
pub fn read_json<T: DeserializeOwned>(path: &Path) -> Result<Option<T>> {
    let bytes = match std::fs::read(path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => {
            return Err(StoreError::Io {
                path: path.into(),
                source: e,
            })
        }
    };
    serde_json::from_slice(&bytes)
        .map(Some)
        .map_err(|e| StoreError::Corrupt {
            path: path.into(),
            message: e.to_string(),
        })
}

/// Writes `value` as pretty JSON, atomically (temporary file, fsync, rename).
pub fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    write_json_as(path, value, Sync::Now)
}

/// As [`write_json`], synced as `sync` says (a batch syncs once after).
pub fn write_json_as<T: Serialize>(path: &Path, value: &T, sync: Sync) -> Result<()> {
    let mut text = serde_json::to_vec_pretty(value).expect("store records always serialise");
    text.push(b'\n');
    write_atomically_as(path, &text, sync).map_err(io(path))
}

/// Syncs a folder, so the renames and creations inside it survive a power cut.
pub fn sync_dir(dir: &Path) -> Result<()> {
    std::fs::File::open(dir)
        .and_then(|f| f.sync_all())
        .map_err(io(dir))
}

/// Removes a folder and everything in it; a folder already gone is fine.
pub fn remove_dir(dir: &Path) -> Result<()> {
    match std::fs::remove_dir_all(dir) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(StoreError::Io {
            path: dir.into(),
            source: e,
        }),
        _ => Ok(()),
    }
}

/// Sub-folders of `dir` whose names do not start with '.', sorted by name.
pub fn visible_subdirs(dir: &Path) -> Result<Vec<(String, std::path::PathBuf)>> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(io(dir))? {
        let entry = entry.map_err(io(dir))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with('.') || !entry.file_type().map_err(io(entry.path()))?.is_dir() {
            continue;
        }
        out.push((name, entry.path()));
    }
    out.sort();
    Ok(out)
}

/// Every regular file under `dir` as a '/'-separated relative path, sorted. Hidden entries are
/// skipped when `skip_hidden`, refused otherwise; symbolic links and other special files, and
/// names [`safe_relative_path`] refuses, are `BadPath`.
pub fn list_files(dir: &Path, skip_hidden: bool) -> Result<Vec<String>> {
    fn walk(dir: &Path, prefix: &str, skip_hidden: bool, out: &mut Vec<String>) -> Result<()> {
        for entry in std::fs::read_dir(dir).map_err(io(dir))? {
            let entry = entry.map_err(io(dir))?;
            let name = entry.file_name().to_string_lossy().into_owned();
            if skip_hidden && name.starts_with('.') {
                continue;
            }
            let rel = format!("{prefix}{name}");
            safe_relative_path(&rel)?;
            let kind = entry.file_type().map_err(io(entry.path()))?;
            if kind.is_dir() {
                walk(&entry.path(), &format!("{rel}/"), skip_hidden, out)?;
            } else if kind.is_file() {
                out.push(rel);
            } else {
                return Err(StoreError::BadPath(format!(
                    "'{rel}' is not a regular file or folder"
                )));
            }
        }
        Ok(())
    }
    let mut out = Vec::new();
    walk(dir, "", skip_hidden, &mut out)?;
    out.sort();
    Ok(out)
}
