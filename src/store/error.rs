use super::ids::RunId;
use super::record::RunStatus;
use crate::dataset::DatasetError;
use std::path::PathBuf;

/// What can go wrong in the run store. The HTTP layer maps these to status codes, so each variant
/// is one kind of cause: a caller mistake (`BadId`, `BadPath`, `NotFound`, `Finished`,
/// `Transition`, `Conflict`, `InUse`, `Dataset`), a limit (`QuotaFull`) or the machine (`Io`,
/// `Sqlite`, `Corrupt`).
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    #[error("cannot access {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("run index: {0}")]
    Sqlite(#[from] rusqlite::Error),
    #[error(
        "'{0}' is not a valid id (1 to 64 characters a-z, 0-9 and '-', not starting with '-')"
    )]
    BadId(String),
    #[error("bad file name: {0}")]
    BadPath(String),
    #[error("not found: {0}")]
    NotFound(String),
    #[error("run {0} has already ended")]
    Finished(RunId),
    #[error("a run cannot go from {from} to {to}")]
    Transition { from: RunStatus, to: RunStatus },
    #[error("invalid dataset: {0}")]
    Dataset(#[from] DatasetError),
    #[error("conflict: {0}")]
    Conflict(String),
    /// What a caller asked to delete is still used: a run not yet ended, a dataset or a model a
    /// queued or running run names. Nothing was deleted.
    #[error("{0}")]
    InUse(String),
    /// A write that would take `what` past its quota; nothing was written.
    #[error("{what} take {used_bytes} bytes of the {quota_bytes}-byte quota ({setting}); {needed_bytes} more bytes would pass it: delete finished runs, set a retention or raise the quota")]
    QuotaFull {
        what: &'static str,
        setting: &'static str,
        used_bytes: u64,
        quota_bytes: u64,
        needed_bytes: u64,
    },
    /// An event a caller may not write: a status change (`queued`, `started`, a terminal kind),
    /// which only `set_status` writes (the terminal one seals the run).
    #[error("bad event: {0}")]
    BadEvent(String),
    /// Another process holds the data folder (a second daemon on the same data would mark the
    /// first one's live runs failed).
    #[error(
        "the data folder is in use by another ffdic ({holder}); stop it or use another data folder"
    )]
    Locked { holder: String },
    /// A file of the store that does not parse: the folder was edited or damaged by hand.
    #[error("{path} is damaged: {message}")]
    Corrupt { path: PathBuf, message: String },
}

impl StoreError {
    /// The disk (or the user's quota) is full: the caller can try again once space returns.
    pub fn is_storage_full(&self) -> bool {
        match self {
            StoreError::Io { source, .. } => matches!(
                source.kind(),
                std::io::ErrorKind::StorageFull | std::io::ErrorKind::QuotaExceeded
            ),
            StoreError::Sqlite(e) => matches!(
                e,
                rusqlite::Error::SqliteFailure(f, _) if f.code == rusqlite::ErrorCode::DiskFull
            ),
            StoreError::QuotaFull { .. }
            | StoreError::BadId(_)
            | StoreError::BadPath(_)
            | StoreError::NotFound(_)
            | StoreError::Finished(_)
            | StoreError::Transition { .. }
            | StoreError::Dataset(_)
            | StoreError::Conflict(_)
            | StoreError::InUse(_)
            | StoreError::BadEvent(_)
            | StoreError::Locked { .. }
            | StoreError::Corrupt { .. } => false,
        }
    }
}

pub type Result<T, E = StoreError> = std::result::Result<T, E>;

/// `map_err` helper: an I/O error at `path`.
pub(crate) fn io(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> StoreError {
    let path = path.into();
    move |source| StoreError::Io { path, source }
}
