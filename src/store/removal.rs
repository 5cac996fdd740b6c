//! Deleting runs and datasets, and the retention policy that deletes ended runs by age and
//! count. What is still in use is refused (`InUse`): a run not yet ended, a dataset a queued or
//! running run names. A folder leaves in two steps — renamed out of sight (`.deleting-{id}`)
//! with its index row removed, then removed — so a crash between them leaves a hidden folder
//! the next open removes, never a half-deleted run.

use super::error::{io, Result, StoreError};
use super::files::{remove_dir, sync_dir};
use super::ids::{DatasetId, RunId};
use super::index;
use super::record::{DatasetRecord, RunRecord};
use super::run_store::{lock, RunStore, DATASETS, DELETING_PREFIX, RUNS};
use super::usage::tree_bytes;
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::time::{Duration, SystemTime};

/// Which ended runs the store keeps (`[retention]` in the daemon's config). Runs not yet ended
/// are always kept, and so are datasets (an experiment's frames stay as its dataset).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields, default)]
pub struct Retention {
    /// Ended runs older than this many days (since they ended) are deleted; 0: kept whatever
    /// their age.
    pub max_age_days: u32,
    /// At most this many ended runs are kept, the newest; 0: no limit.
    pub max_ended_runs: usize,
}

impl Retention {
    pub fn keeps_everything(&self) -> bool {
        self.max_age_days == 0 && self.max_ended_runs == 0
    }
}

/// What [`RunStore::prune`] deleted.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Pruned {
    pub runs: Vec<RunId>,
    pub bytes: u64,
}

impl RunStore {
    /// Deletes ended run `id`, its folder and its index row; returns its last record. `InUse`
    /// while it is queued or running (cancel it first). The dataset an experiment registered
    /// stays.
    pub fn delete_run(&self, id: &RunId) -> Result<RunRecord> {
        let slot = self.slot(id);
        let guard = lock(&slot);
        let rec = self.get(id)?;
        if !rec.status.is_terminal() {
            return Err(StoreError::InUse(format!(
                "run {id} is {}: cancel it first, then delete it",
                rec.status
            )));
        }
        let bytes = self.remove_folder(&self.data_dir().join(RUNS), id.as_str(), |db| {
            index::delete_run(db, id)
        })?;
        self.runs_usage.adjust(-(bytes as i64));
        drop(guard);
        self.forget_slot(id);
        Ok(rec)
    }

    /// Deletes dataset `id` (its frames and record); returns its record. `InUse` while a queued
    /// or running run names it. Ended runs that analysed it keep their results.
    pub fn delete_dataset(&self, id: &DatasetId) -> Result<DatasetRecord> {
        let rec = self.get_dataset(id)?;
        self.remove_folder(&self.data_dir().join(DATASETS), id.as_str(), |db| {
            let users = index::unended_runs_naming(db, "$.dataset_id", id.as_str())?;
            if !users.is_empty() {
                return Err(in_use(&format!("dataset {id}"), &users));
            }
            index::delete_dataset(db, id)
        })?;
        Ok(rec)
    }

    /// `InUse` when a queued or running run names model `name` (a comparison, diagnosis or
    /// sweep), else what `remove` returns; the index is locked throughout, so no run is
    /// created in between.
    pub fn unless_model_in_use<T>(
        &self,
        name: &str,
        remove: impl FnOnce() -> Result<T>,
    ) -> Result<T> {
        let db = self.db();
        let users = index::unended_runs_naming(&db, "$.request.model", name)?;
        if !users.is_empty() {
            return Err(in_use(&format!("model '{name}'"), &users));
        }
        remove()
    }

    /// Deletes the ended runs `policy` does not keep, oldest last-ended first among those past
    /// the count; a run that cannot be deleted is logged and left.
    pub fn prune(&self, policy: &Retention, now: SystemTime) -> Result<Pruned> {
        let mut pruned = Pruned::default();
        if policy.keeps_everything() {
            return Ok(pruned);
        }
        let cutoff = (policy.max_age_days > 0).then(|| {
            let age = Duration::from_secs(u64::from(policy.max_age_days) * 86_400);
            humantime::format_rfc3339_millis(now.checked_sub(age).unwrap_or(SystemTime::UNIX_EPOCH))
                .to_string()
        });
        let ended = index::ended_runs(&self.db())?;
        for (rank, (id, ended_at)) in ended.iter().enumerate() {
            let too_many = policy.max_ended_runs > 0 && rank >= policy.max_ended_runs;
            let too_old = cutoff.as_ref().is_some_and(|c| ended_at < c);
            if !(too_many || too_old) {
                continue;
            }
            let before = self.runs_bytes();
            match self.delete_run(id) {
                Ok(_) => {
                    pruned.bytes += before.saturating_sub(self.runs_bytes());
                    pruned.runs.push(id.clone());
                }
                Err(e) => tracing::warn!(run = %id, "retention could not delete the run: {e}"),
            }
        }
        Ok(pruned)
    }

    /// Renames `parent/name` to a hidden `.deleting-` name and runs `unindex` under the index
    /// lock (which may refuse, leaving everything as it was), then removes the folder; returns
    /// the bytes it held.
    fn remove_folder(
        &self,
        parent: &Path,
        name: &str,
        unindex: impl FnOnce(&rusqlite::Connection) -> Result<()>,
    ) -> Result<u64> {
        let dir = parent.join(name);
        let doomed = parent.join(format!("{DELETING_PREFIX}{name}"));
        {
            let mut db = self.db();
            let tx = db.transaction()?;
            unindex(&tx)?;
            std::fs::rename(&dir, &doomed).map_err(io(&dir))?;
            if let Err(e) = tx.commit() {
                let _ = std::fs::rename(&doomed, &dir);
                return Err(e.into());
            }
        }
        sync_dir(parent)?;
        let bytes = tree_bytes(&doomed, &|_| false).unwrap_or(0);
        if let Err(e) = remove_dir(&doomed) {
            // Out of sight and out of the index already; the next open removes what is left.
            tracing::warn!(folder = %doomed.display(), "not removed yet: {e}");
        }
        Ok(bytes)
    }
}

fn in_use(what: &str, users: &[RunId]) -> StoreError {
    let shown: Vec<&str> = users.iter().take(5).map(RunId::as_str).collect();
    let more = users.len().saturating_sub(shown.len());
    let more = if more > 0 {
        format!(" and {more} more")
    } else {
        String::new()
    };
    StoreError::InUse(format!(
        "{what} is used by {} run(s) not yet ended ({}{more}): cancel them or wait, then delete it",
        users.len(),
        shown.join(", ")
    ))
}
