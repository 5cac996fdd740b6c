//! The history of a dataset's comparisons: one JSON line per comparison in
//! `DATASET/ffdic-history.jsonl` (time, model name, model version, discrepancy), appended, never
//! rewritten, so the fall of the error as effects are added can be read and drawn.

use super::DiagnoseError;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};

pub const HISTORY_FILE: &str = "ffdic-history.jsonl";

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HistoryEntry {
    /// RFC 3339, UTC.
    pub time: String,
    pub dataset: String,
    pub model: String,
    pub version: String,
    pub discrepancy_px: f64,
    /// Effects of the model, in vocabulary order.
    #[serde(default)]
    pub effects: Vec<String>,
}

impl HistoryEntry {
    pub fn now(
        dataset: &str,
        model: &str,
        version: &str,
        discrepancy_px: f64,
        effects: Vec<String>,
    ) -> Self {
        Self {
            time: humantime::format_rfc3339_seconds(std::time::SystemTime::now()).to_string(),
            dataset: dataset.into(),
            model: model.into(),
            version: version.into(),
            discrepancy_px,
            effects,
        }
    }

    /// The history entry of a comparison made now.
    pub fn of(cmp: &super::Comparison) -> Self {
        Self::now(
            &cmp.dataset,
            &cmp.model.name,
            &cmp.model.version,
            cmp.discrepancy_px,
            cmp.model.effects.names(),
        )
    }
}

pub fn history_path(dataset_dir: &Path) -> PathBuf {
    dataset_dir.join(HISTORY_FILE)
}

/// Appends one entry (creates the file).
pub fn append_history(dataset_dir: &Path, entry: &HistoryEntry) -> Result<(), DiagnoseError> {
    let path = history_path(dataset_dir);
    let err = |e: std::io::Error| DiagnoseError::History {
        path: path.clone(),
        message: e.to_string(),
    };
    let mut line = serde_json::to_string(entry).expect("an entry serialises");
    line.push('\n');
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&path)
        .map_err(err)?;
    f.write_all(line.as_bytes()).map_err(err)
}

/// Every entry, oldest first; no file is an empty history. A malformed line is an error naming it.
pub fn read_history(dataset_dir: &Path) -> Result<Vec<HistoryEntry>, DiagnoseError> {
    let path = history_path(dataset_dir);
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => {
            return Err(DiagnoseError::History {
                path,
                message: e.to_string(),
            })
        }
    };
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            serde_json::from_str(l).map_err(|e| DiagnoseError::History {
                path: path.clone(),
                message: format!("line {}: {e}", i + 1),
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn appends_and_reads_back() {
        let dir = tempfile::tempdir().unwrap();
        assert!(read_history(dir.path()).unwrap().is_empty());
        for (m, d) in [("baseline", 0.2), ("baseline+lens_distortion", 0.01)] {
            append_history(dir.path(), &HistoryEntry::now("ds", m, "abc", d, vec![])).unwrap();
        }
        let h = read_history(dir.path()).unwrap();
        assert_eq!(h.len(), 2);
        assert_eq!(h[1].model, "baseline+lens_distortion");
        assert!(h[0].time.ends_with('Z'));
    }
}
