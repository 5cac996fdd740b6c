//! The run store: one folder per run under `runs/` (the truth) and the SQLite index (a cache).
//!
//! Locking: every change to a run happens under that run's own lock, so runs never wait for each
//! other's file writes; the index connection has one lock of its own, always taken after a run's
//! lock, never before. `get` and `events` read the folder and take no lock: files are replaced by
//! rename and events are appended whole, so a reader never sees half a change.

use super::error::{io, Result, StoreError};
use super::events;
use super::files::{read_json, remove_dir, sync_dir, visible_subdirs, write_json, write_json_as};
use super::ids::{DatasetId, RunId};
use super::index::{self, PageAfter};
use super::paths::safe_relative_path;
use super::record::{now_rfc3339, DatasetRecord, Event, RunKind, RunRecord, RunStatus};
use super::usage::{tree_bytes, RunsUsage};
use crate::atomic_write::Sync;
use crate::run_event::EventKind;
use rusqlite::Connection;
use serde_json::{json, Value};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard};

pub(crate) const RUNS: &str = "runs";
pub(crate) const DATASETS: &str = "datasets";
pub(crate) const RUN_FILE: &str = "run.json";
pub(crate) const DATASET_RECORD: &str = "record.json";
/// Prefix of a run folder being created; renamed to the id once complete.
const NEW_RUN_PREFIX: &str = ".new-";
/// Prefix of a run or dataset folder being deleted: renamed out of sight first, then removed
/// (what a crash leaves of it is removed at the next open).
pub(crate) const DELETING_PREFIX: &str = ".deleting-";
/// The data folder's lock file (see `lock_data_dir`).
const LOCK_FILE: &str = ".lock";
pub(crate) const STAGING_PREFIX: &str = ".staging-";
/// Longest idempotency key kept, in bytes (the API takes the same: 1 to this many visible ASCII
/// characters in `Idempotency-Key`).
pub const MAX_IDEMPOTENCY_KEY_LEN: usize = 200;

/// What `open` found and repaired.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RecoveryReport {
    /// Runs left queued or running by an earlier process, now failed.
    pub failed: Vec<RunId>,
    /// Runs whose terminal event was written but whose `run.json` was not (a crash in between):
    /// their status is now the one that event names.
    pub completed: Vec<RunId>,
    /// Folders under `runs/` or `datasets/` that could not be read; left alone and not indexed.
    pub unreadable: Vec<PathBuf>,
    /// Runs and datasets indexed.
    pub runs: usize,
    pub datasets: usize,
}

/// What [`rebuild_index`] indexed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RebuildReport {
    pub runs: usize,
    pub datasets: usize,
    /// Folders that could not be read; not indexed.
    pub unreadable: Vec<PathBuf>,
}

#[derive(Default)]
pub(crate) struct RunSlot {
    /// The id of the run's last event, once known.
    last_event: Option<u64>,
    /// Bytes this process reserved for the run's files (`write_file`): when the run ends its
    /// folder is measured and the run folders' count corrected by the difference.
    written_bytes: u64,
}

/// Runs and datasets under one data folder. `Send + Sync`: share it in an `Arc`.
pub struct RunStore {
    root: PathBuf,
    db: Mutex<Connection>,
    slots: Mutex<HashMap<RunId, Arc<Mutex<RunSlot>>>>,
    pub(crate) runs_usage: RunsUsage,
    /// The exclusive lock on `DATA/.lock`, held as long as the store is open.
    _lock: std::fs::File,
}

pub(crate) fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // Every change is a whole-file replacement or one appended line, so a panic elsewhere leaves
    // nothing half-done behind the lock.
    m.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

fn clamp_progress(p: f64) -> Option<f64> {
    p.is_finite().then(|| p.clamp(0.0, 1.0))
}

impl RunStore {
    /// Opens the store in `data_dir` (creating the folders and the index), fails every run an
    /// earlier process left queued or running, and brings the index in line with the folders.
    pub fn open(data_dir: impl AsRef<Path>) -> Result<(RunStore, RecoveryReport)> {
        let root = data_dir.as_ref().to_path_buf();
        for dir in [root.clone(), root.join(RUNS), root.join(DATASETS)] {
            std::fs::create_dir_all(&dir).map_err(io(&dir))?;
        }
        // Before anything is recovered: recovery fails the runs it finds unfinished, which are
        // another live daemon's runs if one holds the folder.
        let lock = lock_data_dir(&root)?;
        for (folder, prefix) in [
            (RUNS, NEW_RUN_PREFIX),
            (RUNS, DELETING_PREFIX),
            (DATASETS, STAGING_PREFIX),
            (DATASETS, DELETING_PREFIX),
        ] {
            remove_leftovers(&root.join(folder), prefix)?;
        }
        let runs_dir = root.join(RUNS);
        let runs_bytes = tree_bytes(&runs_dir, &|_| false).map_err(io(&runs_dir))?;
        let mut conn = open_index(&root)?;
        let found = scan(&root)?;
        let mut report = RecoveryReport {
            unreadable: found.unreadable,
            runs: found.runs.len(),
            datasets: found.datasets.len(),
            ..Default::default()
        };
        let mut runs = found.runs;
        for rec in runs.iter_mut().filter(|r| !r.status.is_terminal()) {
            recover(&root, rec, &mut report)?;
        }
        index::replace_all(&mut conn, &runs, &found.datasets)?;
        let store = RunStore {
            root,
            db: Mutex::new(conn),
            slots: Mutex::new(HashMap::new()),
            runs_usage: RunsUsage::new(runs_bytes),
            _lock: lock,
        };
        Ok((store, report))
    }

    /// The data folder.
    pub fn data_dir(&self) -> &Path {
        &self.root
    }

    /// The folder of run `id` (which may not exist).
    pub fn run_dir(&self, id: &RunId) -> PathBuf {
        self.root.join(RUNS).join(id.as_str())
    }

    /// The folder of dataset `id` (which may not exist).
    pub fn dataset_dir(&self, id: &DatasetId) -> PathBuf {
        self.root.join(DATASETS).join(id.as_str())
    }

    pub(crate) fn db(&self) -> MutexGuard<'_, Connection> {
        lock(&self.db)
    }

    pub(crate) fn slot(&self, id: &RunId) -> Arc<Mutex<RunSlot>> {
        lock(&self.slots).entry(id.clone()).or_default().clone()
    }

    /// Forgets the lock of an ended run; a later caller gets a fresh one and finds it sealed.
    pub(crate) fn forget_slot(&self, id: &RunId) {
        lock(&self.slots).remove(id);
    }

    /// Queues a new run of `kind` for `request`: writes its folder with `run.json` and a `queued`
    /// event. With a non-empty `idempotency_key` already used by a run of this kind, returns that
    /// run and `false` instead, or `Conflict` when it was for a different request.
    pub fn create_run(
        &self,
        kind: RunKind,
        request: Value,
        idempotency_key: Option<&str>,
        dataset_id: Option<DatasetId>,
    ) -> Result<(RunRecord, bool)> {
        let key = idempotency_key.filter(|k| !k.is_empty());
        if let Some(k) = key {
            if k.len() > MAX_IDEMPOTENCY_KEY_LEN || k.chars().any(char::is_control) {
                return Err(StoreError::Conflict(format!(
                    "an idempotency key is at most {MAX_IDEMPOTENCY_KEY_LEN} bytes of printable text"
                )));
            }
        }
        // The index lock is held throughout, so two requests with one key make one run.
        let mut db = self.db();
        // Checked under the index lock, as a deletion is: a dataset cannot go between this
        // check and the run that names it.
        if let Some(d) = &dataset_id {
            if !self.dataset_dir(d).join(DATASET_RECORD).is_file() {
                return Err(StoreError::NotFound(format!("dataset {d}")));
            }
        }
        if let Some(k) = key {
            if let Some(id) = index::find_by_key(&db, kind, k)? {
                let existing = self.get(&id)?;
                if existing.request != request {
                    return Err(StoreError::Conflict(format!(
                        "idempotency key '{k}' was used for a different {kind} request (run {id})"
                    )));
                }
                return Ok((existing, false));
            }
        }
        let runs = self.root.join(RUNS);
        let id = loop {
            let id = RunId::generate(kind);
            if !runs.join(id.as_str()).exists() {
                break id;
            }
        };
        let now = now_rfc3339();
        let record = RunRecord {
            id: id.clone(),
            kind,
            status: RunStatus::Queued,
            progress: 0.0,
            message: "queued".into(),
            created_at: now.clone(),
            started_at: None,
            finished_at: None,
            dataset_id,
            request,
            idempotency_key: key.map(str::to_string),
            result_files: Vec::new(),
        };
        let event = Event {
            id: 1,
            run_id: id.clone(),
            kind: EventKind::Queued,
            progress: 0.0,
            message: "queued".into(),
            at: now,
            data: json!({ "status": RunStatus::Queued }),
        };
        // Built under a hidden name and renamed: a run folder always has its run.json.
        let tmp = runs.join(format!("{NEW_RUN_PREFIX}{id}"));
        let dir = self.run_dir(&id);
        let result = (|| {
            std::fs::create_dir(&tmp).map_err(io(&tmp))?;
            write_json(&tmp.join(RUN_FILE), &record)?;
            events::append(&tmp.join(events::FILE), &event)?;
            let tx = db.transaction()?;
            index::upsert_run(&tx, &record)?;
            std::fs::rename(&tmp, &dir).map_err(io(&dir))?;
            if let Err(e) = tx.commit() {
                let _ = std::fs::rename(&dir, &tmp);
                return Err(e.into());
            }
            sync_dir(&runs)
        })();
        if result.is_err() {
            let _ = std::fs::remove_dir_all(&tmp);
        }
        result?;
        Ok((record, true))
    }

    /// Run `id` as its `run.json` says now.
    pub fn get(&self, id: &RunId) -> Result<RunRecord> {
        read_json(&self.run_dir(id).join(RUN_FILE))?
            .ok_or_else(|| StoreError::NotFound(format!("run {id}")))
    }

    /// Runs newest first, optionally only of one `status` and one `kind`, at most `limit`.
    pub fn list(
        &self,
        status: Option<RunStatus>,
        kind: Option<RunKind>,
        limit: usize,
    ) -> Result<Vec<RunRecord>> {
        index::list_runs(&self.db(), status, kind, limit, None)
    }

    /// A page of [`RunStore::list`]: at most `limit` runs after `after` (the last of the page
    /// before; `None`: the first page).
    pub fn list_page(
        &self,
        status: Option<RunStatus>,
        kind: Option<RunKind>,
        limit: usize,
        after: Option<&PageAfter>,
    ) -> Result<Vec<RunRecord>> {
        index::list_runs(&self.db(), status, kind, limit, after)
    }

    /// Runs of `kinds` made for dataset `dataset` (comparisons and diagnoses of it, say), newest
    /// first, at most `limit`.
    pub fn list_for_dataset(
        &self,
        dataset: &DatasetId,
        kinds: &[RunKind],
        limit: usize,
    ) -> Result<Vec<RunRecord>> {
        index::list_runs_of_dataset(&self.db(), dataset.as_str(), kinds, limit)
    }

    /// Moves run `id` to `next` (see [`RunStatus::can_become`]) with `message`; stamps
    /// `started_at` / `finished_at`, sets progress 1 on success and writes the matching event
    /// (`started`, `succeeded`, `failed` or `cancelled`). After a terminal status nothing more can
    /// be written to the run: its terminal event is its last.
    pub fn set_status(&self, id: &RunId, next: RunStatus, message: &str) -> Result<RunRecord> {
        let rec = self.transition(id, next, message, Sync::Now)?;
        if let Err(e) = index::upsert_run(&self.db(), &rec) {
            tracing::warn!(run = %rec.id, "index not updated: {e}");
        }
        Ok(rec)
    }

    /// Ends every run of `ids` that is still queued as `next` (a terminal status) with
    /// `message`, as [`RunStore::set_status`] would, but as one batch: the events and records
    /// unsynced, the index in one transaction, then one sync of the file system. A daemon asked
    /// to stop with 3,000 jobs queued wrote them one synced file at a time for 30 s. Returns the
    /// runs it ended; runs no longer queued are left as they are.
    pub fn end_queued(&self, ids: &[RunId], next: RunStatus, message: &str) -> Result<Vec<RunId>> {
        let mut ended = Vec::new();
        for id in ids {
            if !self.get(id).is_ok_and(|r| r.status == RunStatus::Queued) {
                continue;
            }
            match self.transition(id, next, message, Sync::Batched) {
                Ok(rec) => ended.push(rec),
                Err(StoreError::Finished(_) | StoreError::Transition { .. }) => {}
                Err(e) => return Err(e),
            }
        }
        crate::atomic_write::sync_file_system(&self.data_dir().join(RUNS))
            .map_err(io(self.data_dir().join(RUNS)))?;
        let mut db = self.db();
        let indexed = db.transaction().map_err(StoreError::from).and_then(|tx| {
            for rec in &ended {
                index::upsert_run(&tx, rec)?;
            }
            Ok(tx.commit()?)
        });
        if let Err(e) = indexed {
            tracing::warn!("index not updated for {} ended runs: {e}", ended.len());
        }
        Ok(ended.into_iter().map(|r| r.id).collect())
    }

    /// The status change of [`RunStore::set_status`] in the run's folder (event, then
    /// `run.json`), synced as `sync` says; the caller updates the index.
    fn transition(
        &self,
        id: &RunId,
        next: RunStatus,
        message: &str,
        sync: Sync,
    ) -> Result<RunRecord> {
        let slot = self.slot(id);
        let mut slot = lock(&slot);
        let mut rec = self.get(id)?;
        if rec.status.is_terminal() {
            return Err(StoreError::Finished(id.clone()));
        }
        if !rec.status.can_become(next) {
            return Err(StoreError::Transition {
                from: rec.status,
                to: next,
            });
        }
        let now = now_rfc3339();
        rec.status = next;
        rec.message = message.to_string();
        if next == RunStatus::Running {
            rec.started_at = Some(now.clone());
        }
        if next == RunStatus::Succeeded {
            rec.progress = 1.0;
        }
        if next.is_terminal() {
            rec.finished_at = Some(now.clone());
        }
        let kind = next.event_kind();
        // The event first: should the process die before run.json is rewritten, the next open
        // finds the terminal event and completes the transition it records.
        self.push_event(
            &mut slot,
            &rec,
            kind,
            rec.progress,
            message,
            json!({ "status": next }),
            &now,
            sync,
        )?;
        write_json_as(&self.run_dir(&rec.id).join(RUN_FILE), &rec, sync)?;
        if next.is_terminal() {
            self.count_ended_run(id, slot.written_bytes);
            drop(slot);
            self.forget_slot(id);
        }
        Ok(rec)
    }

    /// Records progress (0–1, never lower than before: a lower or non-finite value keeps the
    /// current one) and `message`. `Finished` once the run has ended.
    pub fn set_progress(&self, id: &RunId, progress: f64, message: &str) -> Result<RunRecord> {
        let slot = self.slot(id);
        let _slot = lock(&slot);
        let mut rec = self.get(id)?;
        if rec.status.is_terminal() {
            return Err(StoreError::Finished(id.clone()));
        }
        if let Some(p) = clamp_progress(progress) {
            rec.progress = rec.progress.max(p);
        }
        rec.message = message.to_string();
        self.save(&rec)?;
        Ok(rec)
    }

    /// Links the dataset a running run made (an experiment's frames) to its record, so clients
    /// find it from the run. `Finished` once the run has ended.
    pub fn set_dataset(&self, id: &RunId, dataset: &DatasetId) -> Result<RunRecord> {
        let slot = self.slot(id);
        let _slot = lock(&slot);
        let mut rec = self.get(id)?;
        if rec.status.is_terminal() {
            return Err(StoreError::Finished(id.clone()));
        }
        rec.dataset_id = Some(dataset.clone());
        self.save(&rec)?;
        Ok(rec)
    }

    /// Appends an event of `kind` with the next id; not a status change (`queued`, `started` and
    /// the terminal kinds are `set_status`'s: the terminal event seals the run). `Finished` once
    /// the run has ended.
    pub fn append_event(
        &self,
        id: &RunId,
        kind: EventKind,
        progress: f64,
        message: &str,
        data: Value,
    ) -> Result<Event> {
        if RunStatus::writes(kind) {
            return Err(StoreError::BadEvent(format!(
                "'{kind}' events are written by set_status only"
            )));
        }
        let slot = self.slot(id);
        let mut slot = lock(&slot);
        let rec = self.get(id)?;
        if rec.status.is_terminal() {
            return Err(StoreError::Finished(id.clone()));
        }
        let progress = clamp_progress(progress).unwrap_or(rec.progress);
        self.push_event(
            &mut slot,
            &rec,
            kind,
            progress,
            message,
            data,
            &now_rfc3339(),
            Sync::Now,
        )
    }

    /// Events of run `id` with an id above `after` (all when `None`), oldest first.
    pub fn events(&self, id: &RunId, after: Option<u64>) -> Result<Vec<Event>> {
        let dir = self.run_dir(id);
        if !dir.join(RUN_FILE).is_file() {
            return Err(StoreError::NotFound(format!("run {id}")));
        }
        events::read(&dir.join(events::FILE), after)
    }

    /// Writes `bytes` to `rel` (see [`safe_relative_path`]) inside run `id`'s folder, atomically,
    /// and records it in `result_files`. `Finished` once the run has ended; `BadPath` for an
    /// unsafe name or the store's own `run.json` / `events.jsonl`.
    pub fn write_file(&self, id: &RunId, rel: &str, bytes: &[u8]) -> Result<PathBuf> {
        let rel_path = safe_relative_path(rel)?;
        if rel == RUN_FILE || rel == events::FILE {
            return Err(StoreError::BadPath(format!("'{rel}' belongs to the store")));
        }
        let slot = self.slot(id);
        let mut slot = lock(&slot);
        let mut rec = self.get(id)?;
        if rec.status.is_terminal() {
            return Err(StoreError::Finished(id.clone()));
        }
        let path = self.run_dir(id).join(&rel_path);
        let len = bytes.len() as u64;
        self.runs_usage.reserve(len)?;
        let written = path
            .parent()
            .map_or(Ok(()), std::fs::create_dir_all)
            .and_then(|()| crate::atomic_write::write_atomically(&path, bytes));
        if let Err(e) = written {
            self.runs_usage.adjust(-(len as i64));
            return Err(io(&path)(e));
        }
        slot.written_bytes += len;
        if !rec.result_files.iter().any(|f| f == rel) {
            rec.result_files.push(rel.to_string());
            self.save(&rec)?;
        }
        Ok(path)
    }

    /// A file of run `id` opened for reading, and its length: for serving it piece by piece (a
    /// client that reads slowly then holds a piece of it, not the whole file).
    pub fn open_file(&self, id: &RunId, rel: &str) -> Result<(std::fs::File, u64)> {
        let path = self.run_dir(id).join(safe_relative_path(rel)?);
        let not_found = || StoreError::NotFound(format!("run {id} has no file '{rel}'"));
        let file = match std::fs::File::open(&path) {
            Ok(f) => f,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Err(not_found()),
            Err(e) => return Err(StoreError::Io { path, source: e }),
        };
        let meta = file.metadata().map_err(|e| StoreError::Io {
            path: path.clone(),
            source: e,
        })?;
        if !meta.is_file() {
            return Err(not_found());
        }
        Ok((file, meta.len()))
    }

    /// The bytes of `rel` inside run `id`'s folder; `NotFound` when there is no such file.
    pub fn read_file(&self, id: &RunId, rel: &str) -> Result<Vec<u8>> {
        use std::io::Read;
        let (mut file, len) = self.open_file(id, rel)?;
        let mut bytes = Vec::with_capacity(len as usize);
        file.read_to_end(&mut bytes).map_err(|e| StoreError::Io {
            path: self.run_dir(id).join(rel),
            source: e,
        })?;
        Ok(bytes)
    }

    /// Builds and appends an event; the caller holds the run's lock.
    #[allow(clippy::too_many_arguments)]
    fn push_event(
        &self,
        slot: &mut RunSlot,
        rec: &RunRecord,
        kind: EventKind,
        progress: f64,
        message: &str,
        data: Value,
        at: &str,
        sync: Sync,
    ) -> Result<Event> {
        let path = self.run_dir(&rec.id).join(events::FILE);
        let last = match slot.last_event {
            Some(n) => n,
            None => events::last(&path)?.map_or(0, |e| e.id),
        };
        let event = Event {
            id: last + 1,
            run_id: rec.id.clone(),
            kind,
            progress,
            message: message.to_string(),
            at: at.to_string(),
            data,
        };
        // Unknown after a failed append (a torn line may or may not hold the id): re-read then.
        slot.last_event = None;
        events::append_with(&path, &event, sync)?;
        slot.last_event = Some(event.id);
        Ok(event)
    }

    /// Rewrites `run.json` (the truth), then the index. An index failure is logged, not
    /// returned: the change is made, and the next open puts the index right.
    fn save(&self, rec: &RunRecord) -> Result<()> {
        write_json(&self.run_dir(&rec.id).join(RUN_FILE), rec)?;
        if let Err(e) = index::upsert_run(&self.db(), rec) {
            tracing::warn!(run = %rec.id, "index not updated: {e}");
        }
        Ok(())
    }
}

/// Deletes the index and recreates it from the folders under `data_dir` (`ffdic store
/// rebuild`). Runs are indexed as their folders say, without recovery. It takes the data
/// folder's lock as a daemon does: beside a live daemon (which would go on writing to an index
/// no longer in the folder) it is refused with [`StoreError::Locked`], naming the holder.
pub fn rebuild_index(data_dir: impl AsRef<Path>) -> Result<RebuildReport> {
    let root = data_dir.as_ref();
    if !root.join(RUNS).is_dir() && !root.join(DATASETS).is_dir() {
        return Err(StoreError::NotFound(format!(
            "{} holds no runs/ or datasets/ folder",
            root.display()
        )));
    }
    let _lock = lock_data_dir(root)?;
    remove_index(root)?;
    let mut conn = index::open(&root.join(index::FILE))?;
    let found = scan(root)?;
    index::replace_all(&mut conn, &found.runs, &found.datasets)?;
    Ok(RebuildReport {
        runs: found.runs.len(),
        datasets: found.datasets.len(),
        unreadable: found.unreadable,
    })
}

/// Removes the index with its WAL and shared-memory files: a stale WAL beside a new database
/// would be replayed into it.
fn remove_index(root: &Path) -> Result<()> {
    for suffix in ["", "-wal", "-shm"] {
        let p = root.join(format!("{}{suffix}", index::FILE));
        match std::fs::remove_file(&p) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(io(&p)(e)),
            _ => {}
        }
    }
    Ok(())
}

/// The index, recreated from nothing when the file is not a usable database: it is a cache.
/// Takes the data folder for this process: an exclusive lock on `DATA/.lock` (released by the
/// kernel when the process ends, however it ends), with the holder's pid written in it so the
/// refusal can name it.
fn lock_data_dir(root: &Path) -> Result<std::fs::File> {
    use std::io::{Read, Seek, Write};
    let path = root.join(LOCK_FILE);
    let mut file = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(&path)
        .map_err(io(&path))?;
    if file.try_lock().is_err() {
        let mut holder = String::new();
        let _ = file.read_to_string(&mut holder);
        let holder = holder.trim();
        return Err(StoreError::Locked {
            holder: if holder.is_empty() {
                "holder unknown".into()
            } else {
                holder.to_string()
            },
        });
    }
    let me = format!("pid {}", std::process::id());
    file.set_len(0)
        .and_then(|()| file.rewind())
        .and_then(|()| file.write_all(me.as_bytes()))
        .map_err(io(&path))?;
    Ok(file)
}

/// Opens the index, or recreates it when SQLite cannot open it or its integrity check fails
/// (a damaged page): the folders are the truth and the index is rebuilt from them right after.
fn open_index(root: &Path) -> Result<Connection> {
    let path = root.join(index::FILE);
    let checked = index::open(&path).and_then(|conn| {
        let verdict: String = conn.query_row("PRAGMA quick_check", [], |r| r.get(0))?;
        if verdict == "ok" {
            Ok(conn)
        } else {
            Err(StoreError::Corrupt {
                path: path.clone(),
                message: verdict,
            })
        }
    });
    match checked {
        Ok(conn) => Ok(conn),
        Err(e) => {
            tracing::warn!(index = %path.display(), "unusable index, recreating it: {e}");
            remove_index(root)?;
            index::open(&path)
        }
    }
}

fn remove_leftovers(dir: &Path, prefix: &str) -> Result<()> {
    for entry in std::fs::read_dir(dir).map_err(io(dir))? {
        let entry = entry.map_err(io(dir))?;
        if entry.file_name().to_string_lossy().starts_with(prefix) {
            tracing::info!(folder = %entry.path().display(), "removing an unfinished folder");
            remove_dir(&entry.path())?;
        }
    }
    Ok(())
}

struct Scan {
    runs: Vec<RunRecord>,
    datasets: Vec<DatasetRecord>,
    unreadable: Vec<PathBuf>,
}

/// Reads every run and dataset record under `root`.
fn scan(root: &Path) -> Result<Scan> {
    let mut found = Scan {
        runs: Vec::new(),
        datasets: Vec::new(),
        unreadable: Vec::new(),
    };
    let runs = root.join(RUNS);
    if runs.is_dir() {
        for (name, dir) in visible_subdirs(&runs)? {
            match read_record::<RunRecord>(&dir, RUN_FILE) {
                Some(r) if r.id.as_str() == name => found.runs.push(r),
                _ => found.unreadable.push(dir),
            }
        }
    }
    let datasets = root.join(DATASETS);
    if datasets.is_dir() {
        for (name, dir) in visible_subdirs(&datasets)? {
            match read_record::<DatasetRecord>(&dir, DATASET_RECORD) {
                Some(d) if d.id.as_str() == name => found.datasets.push(d),
                _ => found.unreadable.push(dir),
            }
        }
    }
    Ok(found)
}

fn read_record<T: serde::de::DeserializeOwned>(dir: &Path, file: &str) -> Option<T> {
    match read_json::<T>(&dir.join(file)) {
        Ok(Some(r)) => Some(r),
        Ok(None) => {
            tracing::warn!(folder = %dir.display(), "no {file}: not indexed");
            None
        }
        Err(e) => {
            tracing::warn!(folder = %dir.display(), "not indexed: {e}");
            None
        }
    }
}

/// Ends a run an earlier process left unfinished: completes a terminal transition whose event
/// was written, else fails the run with the reason and an event.
fn recover(root: &Path, rec: &mut RunRecord, report: &mut RecoveryReport) -> Result<()> {
    let dir = root.join(RUNS).join(rec.id.as_str());
    let log = dir.join(events::FILE);
    let last = events::last(&log)?;
    let sealed = last
        .as_ref()
        .and_then(|e| RunStatus::sealed_by(e.kind).map(|s| (s, e)))
        .filter(|(s, _)| rec.status.can_become(*s));
    if let Some((status, event)) = sealed {
        rec.status = status;
        rec.message = event.message.clone();
        rec.finished_at = Some(event.at.clone());
        if status == RunStatus::Succeeded {
            rec.progress = 1.0;
        }
        write_json(&dir.join(RUN_FILE), rec)?;
        report.completed.push(rec.id.clone());
        return Ok(());
    }
    let now = now_rfc3339();
    let message = format!("the server stopped while this run was {}", rec.status);
    let event = Event {
        id: last.map_or(0, |e| e.id) + 1,
        run_id: rec.id.clone(),
        kind: RunStatus::Failed.event_kind(),
        progress: rec.progress,
        message: message.clone(),
        at: now.clone(),
        data: json!({ "status": RunStatus::Failed, "recovered": true }),
    };
    events::append(&log, &event)?;
    rec.status = RunStatus::Failed;
    rec.message = message;
    rec.finished_at = Some(now);
    write_json(&dir.join(RUN_FILE), rec)?;
    report.failed.push(rec.id.clone());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn open_removes_unfinished_folders_and_reports_unreadable_ones() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path();
        for d in [
            "runs/.new-exp-1",
            "datasets/.staging-abc",
            "runs/no-run-json",
            "runs/exp-2",
            "runs/Not_An_Id",
        ] {
            std::fs::create_dir_all(root.join(d)).unwrap();
        }
        std::fs::write(root.join("runs/exp-2/run.json"), b"{ torn").unwrap();
        std::fs::write(root.join("runs/Not_An_Id/run.json"), b"{}").unwrap();
        let (store, report) = RunStore::open(root).unwrap();
        assert!(!root.join("runs/.new-exp-1").exists());
        assert!(!root.join("datasets/.staging-abc").exists());
        assert_eq!(report.unreadable.len(), 3, "{report:?}");
        assert_eq!((report.runs, report.datasets), (0, 0));
        // Left alone for a person to look at.
        assert!(root.join("runs/exp-2/run.json").is_file());
        assert!(store.list(None, None, 10).unwrap().is_empty());
        let id: RunId = "exp-2".parse().unwrap();
        assert!(matches!(store.get(&id), Err(StoreError::Corrupt { .. })));
    }

    #[test]
    fn runs_of_a_dataset_are_listed_by_kind_newest_first() {
        let dir = tempfile::tempdir().unwrap();
        let (store, _) = RunStore::open(dir.path()).unwrap();
        let (a, b) = (DatasetId::generate(), DatasetId::generate());
        // A run may name only a stored dataset: their records, as a commit leaves them.
        for d in [&a, &b] {
            std::fs::create_dir_all(store.dataset_dir(d)).unwrap();
            std::fs::write(store.dataset_dir(d).join(DATASET_RECORD), "{}").unwrap();
        }
        let mut made = Vec::new();
        for (kind, ds) in [
            (RunKind::Comparison, Some(a.clone())),
            (RunKind::Diagnosis, Some(a.clone())),
            (RunKind::Comparison, Some(b.clone())),
            (RunKind::Experiment, Some(a.clone())),
            (RunKind::Comparison, None),
        ] {
            let (r, _) = store.create_run(kind, json!({}), None, ds).unwrap();
            made.push(r.id);
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
        let kinds = [RunKind::Comparison, RunKind::Diagnosis];
        let ids: Vec<RunId> = store
            .list_for_dataset(&a, &kinds, 10)
            .unwrap()
            .into_iter()
            .map(|r| r.id)
            .collect();
        assert_eq!(ids, vec![made[1].clone(), made[0].clone()]);
        assert_eq!(store.list_for_dataset(&a, &kinds, 1).unwrap().len(), 1);
        assert_eq!(
            store.list_for_dataset(&b, &kinds, 10).unwrap()[0].id,
            made[2]
        );
    }

    #[test]
    fn rebuild_needs_a_data_folder() {
        let dir = tempfile::tempdir().unwrap();
        assert!(matches!(
            rebuild_index(dir.path().join("none")),
            Err(StoreError::NotFound(_))
        ));
        assert!(!dir.path().join("none").exists());
    }

    /// Issue 36: `ffdic store rebuild` ran beside a live daemon, which then wrote to an index
    /// no longer in the folder.
    #[test]
    fn rebuild_is_refused_while_the_store_is_open() {
        let dir = tempfile::tempdir().unwrap();
        let (store, _) = RunStore::open(dir.path()).unwrap();
        let e = rebuild_index(dir.path()).unwrap_err();
        assert!(matches!(e, StoreError::Locked { .. }), "{e}");
        assert!(
            dir.path().join(index::FILE).exists(),
            "the index is untouched"
        );
        drop(store);
        assert!(rebuild_index(dir.path()).is_ok());
    }
}
