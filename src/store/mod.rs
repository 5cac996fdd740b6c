//! The run store. Run folders are the source of truth: every file lands whole or not at all, and
//! the SQLite index beside them is a cache that can be rebuilt from them at any time.
//!
//! ```text
//! data/index.sqlite              the index (WAL)
//! data/runs/{id}/run.json        the RunRecord, rewritten atomically until the run has ended
//! data/runs/{id}/events.jsonl    one Event per line, append-only, synced per append
//! data/runs/{id}/frames/ …       what the runner writes through RunStore::write_file
//! data/datasets/{id}/            dataset.json + frames (ffdic-dataset/1) and record.json
//! data/models/{name}.toml        analysis models users added (never rewritten)
//! ```
//!
//! A run moves queued → running → succeeded | failed | cancelled (or straight from queued to
//! failed or cancelled). Its terminal event is the last thing written to it: after that
//! `set_progress`, `append_event` and `write_file` answer `Finished`. A run left queued or running
//! by a process that died is failed, with the reason, the next time the store is opened.

mod datasets;
mod error;
mod events;
mod files;
mod ids;
mod index;
mod models;
mod paths;
mod record;
mod removal;
mod run_store;
mod usage;

pub use datasets::StagingDir;
pub use error::{Result, StoreError};
pub use ids::{DatasetId, RunId, MAX_ID_LEN};
pub use index::PageAfter;
pub use models::{is_model_name, ModelFolder, ModelSaved, MAX_MODEL_NAME_LEN};
pub use paths::{safe_relative_path, MAX_COMPONENT_LEN, MAX_DEPTH};
pub use record::{now_rfc3339, DatasetRecord, DatasetSource, Event, RunKind, RunRecord, RunStatus};
pub use removal::{Pruned, Retention};
pub use run_store::{
    rebuild_index, RebuildReport, RecoveryReport, RunStore, MAX_IDEMPOTENCY_KEY_LEN,
};
pub use usage::folder_bytes;
