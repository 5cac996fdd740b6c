//! `index.sqlite`: a cache of the folders for listing and idempotency look-ups. It holds each
//! record whole (JSON) plus the columns queries need, and is rebuilt from the folders at will.

use super::error::{Result, StoreError};
use super::ids::{DatasetId, RunId};
use super::record::{DatasetRecord, RunKind, RunRecord, RunStatus};
use rusqlite::{params, Connection, OptionalExtension};
use std::path::Path;

pub const FILE: &str = "index.sqlite";

/// Bump when the tables change: an index of another version is dropped and refilled.
const SCHEMA_VERSION: i64 = 1;

const SCHEMA: &str = "
CREATE TABLE IF NOT EXISTS runs (
    id TEXT PRIMARY KEY,
    kind TEXT NOT NULL,
    status TEXT NOT NULL,
    created_at TEXT NOT NULL,
    idempotency_key TEXT,
    record TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS runs_newest ON runs (created_at DESC, id DESC);
CREATE INDEX IF NOT EXISTS runs_key ON runs (kind, idempotency_key) WHERE idempotency_key IS NOT NULL;
CREATE TABLE IF NOT EXISTS datasets (
    id TEXT PRIMARY KEY,
    created_at TEXT NOT NULL,
    record TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS datasets_newest ON datasets (created_at DESC, id DESC);
";

/// Opens (creating) the index in WAL mode with `synchronous=NORMAL`: a power cut may lose the
/// last transactions, which the folders restore at the next open.
pub fn open(path: &Path) -> Result<Connection> {
    let conn = Connection::open(path)?;
    conn.busy_timeout(std::time::Duration::from_secs(5))?;
    let mode: String = conn.query_row("PRAGMA journal_mode = WAL", [], |r| r.get(0))?;
    if !mode.eq_ignore_ascii_case("wal") {
        tracing::warn!(index = %path.display(), "journal mode is {mode}, not WAL");
    }
    conn.pragma_update(None, "synchronous", "NORMAL")?;
    let version: i64 = conn.query_row("PRAGMA user_version", [], |r| r.get(0))?;
    if version != SCHEMA_VERSION {
        conn.execute_batch("DROP TABLE IF EXISTS runs; DROP TABLE IF EXISTS datasets;")?;
    }
    conn.execute_batch(SCHEMA)?;
    conn.pragma_update(None, "user_version", SCHEMA_VERSION)?;
    Ok(conn)
}

/// Replaces the whole content with `runs` and `datasets`, in one transaction.
pub fn replace_all(
    conn: &mut Connection,
    runs: &[RunRecord],
    datasets: &[DatasetRecord],
) -> Result<()> {
    let tx = conn.transaction()?;
    tx.execute("DELETE FROM runs", [])?;
    tx.execute("DELETE FROM datasets", [])?;
    for r in runs {
        upsert_run(&tx, r)?;
    }
    for d in datasets {
        upsert_dataset(&tx, d)?;
    }
    tx.commit()?;
    Ok(())
}

pub fn upsert_run(conn: &Connection, r: &RunRecord) -> Result<()> {
    let json = serde_json::to_string(r).expect("a run record always serialises");
    conn.execute(
        "INSERT INTO runs (id, kind, status, created_at, idempotency_key, record)
         VALUES (?1, ?2, ?3, ?4, ?5, ?6)
         ON CONFLICT (id) DO UPDATE SET kind = ?2, status = ?3, created_at = ?4,
             idempotency_key = ?5, record = ?6",
        params![
            r.id.as_str(),
            r.kind.as_str(),
            r.status.as_str(),
            r.created_at,
            r.idempotency_key,
            json
        ],
    )?;
    Ok(())
}

pub fn upsert_dataset(conn: &Connection, d: &DatasetRecord) -> Result<()> {
    let json = serde_json::to_string(d).expect("a dataset record always serialises");
    conn.execute(
        "INSERT INTO datasets (id, created_at, record) VALUES (?1, ?2, ?3)
         ON CONFLICT (id) DO UPDATE SET created_at = ?2, record = ?3",
        params![d.id.as_str(), d.created_at, json],
    )?;
    Ok(())
}

fn decode<T: serde::de::DeserializeOwned>(text: &str) -> Result<T> {
    serde_json::from_str(text).map_err(|e| StoreError::Corrupt {
        path: FILE.into(),
        message: e.to_string(),
    })
}

/// Where a page of a newest-first list begins: after the item with this `created_at` and `id`
/// (the last one of the page before). Deleting items between two pages moves nothing.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PageAfter {
    pub created_at: String,
    pub id: String,
}

/// Runs newest first, optionally of one status and kind, at most `limit`, beginning after
/// `after`.
pub fn list_runs(
    conn: &Connection,
    status: Option<RunStatus>,
    kind: Option<RunKind>,
    limit: usize,
    after: Option<&PageAfter>,
) -> Result<Vec<RunRecord>> {
    let limit = i64::try_from(limit).unwrap_or(i64::MAX);
    let mut stmt = conn.prepare_cached(
        "SELECT record FROM runs
         WHERE (?1 IS NULL OR status = ?1) AND (?2 IS NULL OR kind = ?2)
           AND (?4 IS NULL OR created_at < ?4 OR (created_at = ?4 AND id < ?5))
         ORDER BY created_at DESC, id DESC LIMIT ?3",
    )?;
    let rows = stmt.query_map(
        params![
            status.map(|s| s.as_str()),
            kind.map(|k| k.as_str()),
            limit,
            after.map(|a| a.created_at.as_str()),
            after.map(|a| a.id.as_str())
        ],
        |r| r.get::<_, String>(0),
    )?;
    rows.map(|text| decode(&text?)).collect()
}

/// The statuses of runs not yet ended, as the index writes them.
fn unended() -> String {
    let words: Vec<&str> = RunStatus::ALL
        .into_iter()
        .filter(|s| !s.is_terminal())
        .map(RunStatus::as_str)
        .collect();
    serde_json::to_string(&words).expect("a list of words serialises")
}

/// Runs not yet ended (queued or running) whose record has `value` at the JSON `path`
/// (`$.dataset_id`, `$.request.model`): what a deletion must wait for.
pub fn unended_runs_naming(conn: &Connection, path: &str, value: &str) -> Result<Vec<RunId>> {
    let mut stmt = conn.prepare_cached(
        "SELECT id FROM runs
         WHERE status IN (SELECT value FROM json_each(?1)) AND json_extract(record, ?2) = ?3
         ORDER BY created_at, id",
    )?;
    let rows = stmt.query_map(params![unended(), path, value], |r| r.get::<_, String>(0))?;
    rows.map(|id| id?.parse()).collect()
}

/// Ended runs, newest first, with the time each ended (`finished_at`; its creation time when
/// the record has none): what a retention policy chooses from.
pub fn ended_runs(conn: &Connection) -> Result<Vec<(RunId, String)>> {
    let mut stmt = conn.prepare_cached(
        "SELECT id, coalesce(json_extract(record, '$.finished_at'), created_at) FROM runs
         WHERE status NOT IN (SELECT value FROM json_each(?1))
         ORDER BY created_at DESC, id DESC",
    )?;
    let rows = stmt.query_map(params![unended()], |r| {
        Ok((r.get::<_, String>(0)?, r.get::<_, String>(1)?))
    })?;
    rows.map(|row| {
        let (id, ended_at) = row?;
        Ok((id.parse()?, ended_at))
    })
    .collect()
}

pub fn delete_run(conn: &Connection, id: &RunId) -> Result<()> {
    conn.execute("DELETE FROM runs WHERE id = ?1", params![id.as_str()])?;
    Ok(())
}

pub fn delete_dataset(conn: &Connection, id: &DatasetId) -> Result<()> {
    conn.execute("DELETE FROM datasets WHERE id = ?1", params![id.as_str()])?;
    Ok(())
}

/// Runs of `kinds` that name dataset `dataset`, newest first, at most `limit`. The dataset id
/// lives in the record's JSON only (the table has no column for it): the index is small and a
/// dataset's page asks once per load.
pub fn list_runs_of_dataset(
    conn: &Connection,
    dataset: &str,
    kinds: &[RunKind],
    limit: usize,
) -> Result<Vec<RunRecord>> {
    let limit = i64::try_from(limit).unwrap_or(i64::MAX);
    let kinds: Vec<&str> = kinds.iter().map(|k| k.as_str()).collect();
    let kinds = serde_json::to_string(&kinds).expect("a list of words serialises");
    let mut stmt = conn.prepare_cached(
        "SELECT record FROM runs
         WHERE json_extract(record, '$.dataset_id') = ?1
           AND kind IN (SELECT value FROM json_each(?2))
         ORDER BY created_at DESC, id DESC LIMIT ?3",
    )?;
    let rows = stmt.query_map(params![dataset, kinds, limit], |r| r.get::<_, String>(0))?;
    rows.map(|text| decode(&text?)).collect()
}

/// The run of `kind` created with idempotency `key`, if any (the first, should there be more).
pub fn find_by_key(conn: &Connection, kind: RunKind, key: &str) -> Result<Option<RunId>> {
    let id: Option<String> = conn
        .query_row(
            "SELECT id FROM runs WHERE kind = ?1 AND idempotency_key = ?2
             ORDER BY created_at, id LIMIT 1",
            params![kind.as_str(), key],
            |r| r.get(0),
        )
        .optional()?;
    match id {
        Some(id) => Ok(Some(id.parse()?)),
        None => Ok(None),
    }
}

/// Datasets newest first, at most `limit`, beginning after `after`.
pub fn list_datasets(
    conn: &Connection,
    limit: usize,
    after: Option<&PageAfter>,
) -> Result<Vec<DatasetRecord>> {
    let limit = i64::try_from(limit).unwrap_or(i64::MAX);
    let mut stmt = conn.prepare_cached(
        "SELECT record FROM datasets
         WHERE ?2 IS NULL OR created_at < ?2 OR (created_at = ?2 AND id < ?3)
         ORDER BY created_at DESC, id DESC LIMIT ?1",
    )?;
    let rows = stmt.query_map(
        params![
            limit,
            after.map(|a| a.created_at.as_str()),
            after.map(|a| a.id.as_str())
        ],
        |r| r.get::<_, String>(0),
    )?;
    rows.map(|text| decode(&text?)).collect()
}
