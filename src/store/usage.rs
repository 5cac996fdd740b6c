//! Bytes on disk: what a folder tree takes, and the run folders held against their quota.

use super::error::{Result, StoreError};
use super::ids::RunId;
use super::run_store::RunStore;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

/// Bytes of the regular files under `dir`, recursively, leaving out the sub-folders whose name
/// `skip` accepts (at any depth). A missing `dir` takes 0 bytes.
pub(crate) fn tree_bytes(dir: &Path, skip: &dyn Fn(&str) -> bool) -> std::io::Result<u64> {
    let entries = match std::fs::read_dir(dir) {
        Ok(entries) => entries,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(0),
        Err(e) => return Err(e),
    };
    let mut total = 0;
    for entry in entries {
        let entry = entry?;
        let kind = entry.file_type()?;
        if kind.is_dir() {
            if !skip(&entry.file_name().to_string_lossy()) {
                total += tree_bytes(&entry.path(), skip)?;
            }
        } else if kind.is_file() {
            // A file removed between the listing and its metadata takes nothing.
            match entry.metadata() {
                Ok(m) => total += m.len(),
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => return Err(e),
            }
        }
    }
    Ok(total)
}

/// Bytes of the regular files under `dir`, recursively (0 when it does not exist).
pub fn folder_bytes(dir: &Path) -> std::io::Result<u64> {
    tree_bytes(dir, &|_| false)
}

/// The run folders' bytes against their quota (`runs_quota_bytes`). A file a run writes
/// through `RunStore::write_file` is reserved before it is written, so no write passes the
/// quota; what a run writes otherwise (its events, `run.json`, a sweep's task results) is
/// counted from its folder when it ends. An experiment once wrote ≈ 20.7 GB with no limit.
pub(crate) struct RunsUsage {
    quota_bytes: AtomicU64,
    used_bytes: AtomicU64,
}

impl RunsUsage {
    /// `used_bytes` measured now; no quota until [`RunsUsage::set_quota`].
    pub fn new(used_bytes: u64) -> Self {
        Self {
            quota_bytes: AtomicU64::new(u64::MAX),
            used_bytes: AtomicU64::new(used_bytes),
        }
    }

    pub fn set_quota(&self, quota_bytes: u64) {
        self.quota_bytes.store(quota_bytes, Ordering::SeqCst);
    }

    pub fn quota_bytes(&self) -> u64 {
        self.quota_bytes.load(Ordering::SeqCst)
    }

    pub fn used_bytes(&self) -> u64 {
        self.used_bytes.load(Ordering::SeqCst)
    }

    fn full(&self, used_bytes: u64, needed_bytes: u64) -> StoreError {
        StoreError::QuotaFull {
            what: "the run folders",
            setting: "runs_quota_bytes",
            used_bytes,
            quota_bytes: self.quota_bytes(),
            needed_bytes,
        }
    }

    /// Whether `needed_bytes` more would fit now (nothing is reserved).
    pub fn check_room(&self, needed_bytes: u64) -> Result<()> {
        let used = self.used_bytes();
        if used.saturating_add(needed_bytes) > self.quota_bytes() {
            return Err(self.full(used, needed_bytes));
        }
        Ok(())
    }

    /// Takes `bytes` of the quota, or none and `QuotaFull` when they would pass it.
    pub fn reserve(&self, bytes: u64) -> Result<()> {
        let quota = self.quota_bytes();
        self.used_bytes
            .fetch_update(Ordering::SeqCst, Ordering::SeqCst, |used| {
                used.checked_add(bytes).filter(|&after| after <= quota)
            })
            .map(|_| ())
            .map_err(|used| self.full(used, bytes))
    }

    /// Corrects the count by `delta_bytes` (a run's folder measured when it ends, a deleted
    /// folder), never below zero.
    pub fn adjust(&self, delta_bytes: i64) {
        let _ = self
            .used_bytes
            .fetch_update(Ordering::SeqCst, Ordering::SeqCst, |used| {
                Some(used.saturating_add_signed(delta_bytes))
            });
    }
}

impl RunStore {
    /// Sets the run folders' quota, bytes (`u64::MAX`: none).
    pub fn set_runs_quota(&self, quota_bytes: u64) {
        self.runs_usage.set_quota(quota_bytes);
    }

    /// Bytes the run folders take, as counted (measured at open, then kept up to date).
    pub fn runs_bytes(&self) -> u64 {
        self.runs_usage.used_bytes()
    }

    pub fn runs_quota_bytes(&self) -> u64 {
        self.runs_usage.quota_bytes()
    }

    /// `QuotaFull` when a run that writes `needed_bytes` would not fit in the run folders' quota
    /// now: checked when an experiment is submitted, before it takes the bench.
    pub fn check_runs_room(&self, needed_bytes: u64) -> Result<()> {
        self.runs_usage.check_room(needed_bytes)
    }

    /// A run has ended: its folder is measured and the count corrected by what it holds beyond
    /// the `written_bytes` already counted.
    pub(crate) fn count_ended_run(&self, id: &RunId, written_bytes: u64) {
        match tree_bytes(&self.run_dir(id), &|_| false) {
            Ok(total) => self.runs_usage.adjust(total as i64 - written_bytes as i64),
            Err(e) => tracing::warn!(run = %id, "the run's folder not measured: {e}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_reservation_that_would_pass_the_quota_takes_nothing() {
        let usage = RunsUsage::new(60);
        usage.set_quota(100);
        assert!(usage.reserve(40).is_ok());
        assert_eq!(usage.used_bytes(), 100);
        match usage.reserve(1) {
            Err(StoreError::QuotaFull {
                used_bytes,
                quota_bytes,
                needed_bytes,
                ..
            }) => assert_eq!((used_bytes, quota_bytes, needed_bytes), (100, 100, 1)),
            other => panic!("{other:?}"),
        }
        assert_eq!(usage.used_bytes(), 100);
        usage.adjust(-150);
        assert_eq!(usage.used_bytes(), 0);
        assert!(usage.check_room(100).is_ok());
        assert!(usage.check_room(101).is_err());
    }

    #[test]
    fn a_tree_is_counted_without_the_folders_it_skips() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(dir.path().join("a/b")).unwrap();
        std::fs::create_dir_all(dir.path().join(".skip")).unwrap();
        std::fs::write(dir.path().join("a/one"), [0u8; 10]).unwrap();
        std::fs::write(dir.path().join("a/b/two"), [0u8; 20]).unwrap();
        std::fs::write(dir.path().join(".skip/three"), [0u8; 40]).unwrap();
        let skip_hidden = |name: &str| name.starts_with('.');
        assert_eq!(tree_bytes(dir.path(), &skip_hidden).unwrap(), 30);
        assert_eq!(tree_bytes(dir.path(), &|_| false).unwrap(), 70);
        assert_eq!(tree_bytes(&dir.path().join("none"), &|_| false).unwrap(), 0);
    }
}
