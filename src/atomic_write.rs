//! Files written whole or not at all: a crash never leaves half a file under its final name. The
//! lowest floor of the house (no crate imports but libc's syncfs): the TIFF writer, the dataset manifest, the store,
//! sweeps and the CLI's outputs all write through it; a file linked or copied durably (`link_or_copy`) beside them.

use std::io::Write;
use std::path::Path;

/// Whether a write is synced at once or left to one sync of the file system after a batch
/// ([`sync_file_system`]): three thousand synced writes took 30 s.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sync {
    Now,
    Batched,
}

/// Writes `bytes` to a hidden temporary file beside `path`, syncs it and renames it into place,
/// so a crash never leaves a half-written file under the final name.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_atomically_as(path, bytes, Sync::Now)
}

/// As [`write_atomically`], synced as `sync` says: unsynced, the file is whole under its final
/// name yet only as durable as the next sync of its file system.
pub fn write_atomically_as(path: &Path, bytes: &[u8], sync: Sync) -> std::io::Result<()> {
    let name = path.file_name().ok_or_else(|| {
        std::io::Error::new(std::io::ErrorKind::InvalidInput, "path has no file name")
    })?;
    let tmp = path.with_file_name(format!(".{}.tmp", name.to_string_lossy()));
    let result = (|| {
        let mut file = std::fs::File::create(&tmp)?;
        file.write_all(bytes)?;
        if sync == Sync::Now {
            file.sync_all()?;
        }
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Syncs the whole file system that holds `dir` (Linux `syncfs`; elsewhere `dir` itself).
pub fn sync_file_system(dir: &Path) -> std::io::Result<()> {
    let folder = std::fs::File::open(dir)?;
    #[cfg(target_os = "linux")]
    {
        use std::os::fd::AsRawFd;
        // SAFETY: syncfs only reads the descriptor, which `folder` keeps open.
        if unsafe { libc::syncfs(folder.as_raw_fd()) } != 0 {
            return Err(std::io::Error::last_os_error());
        }
        Ok(())
    }
    #[cfg(not(target_os = "linux"))]
    folder.sync_all()
}

/// `to` made the same file as `from`: a hard link where the file system allows (the bytes exist
/// once on disk; every file here is written under a temporary name and renamed, never rewritten
/// in place, so neither name can change the other), else a copy synced to disk. On failure, the
/// path that failed with its error.
pub fn link_or_copy(from: &Path, to: &Path) -> Result<(), (std::path::PathBuf, std::io::Error)> {
    if std::fs::hard_link(from, to).is_ok() {
        return Ok(());
    }
    std::fs::copy(from, to).map_err(|e| (from.to_owned(), e))?;
    std::fs::File::open(to)
        .and_then(|f| f.sync_all())
        .map_err(|e| (to.to_owned(), e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_whole_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.json");
        write_atomically(&p, b"{}").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"{}");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
        assert!(write_atomically(&dir.path().join("missing/a.json"), b"x").is_err());
    }
}
