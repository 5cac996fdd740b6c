//! The history of a dataset's comparisons: one JSON line per comparison in
//! `HISTORY_DIR/ffdic-history.jsonl` (time, model name, model version, discrepancy), appended,
//! never rewritten, so the fall of the error as effects are added can be read and drawn.
//!
//! The history folder is the daemon's own dataset folder for a stored dataset, and for a dataset
//! a user names on the command line or from Python one per dataset under the data folder
//! ([`history_dir_for`]): nothing is written into a measurement folder (often shared or
//! read-only) unless asked.

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
    /// NaN (written `null`) where no run could be measured.
    #[serde(deserialize_with = "crate::dic::f64_or_nan")]
    pub discrepancy_px: f64,
    /// Its standard error (0 in entries written before it was recorded; NaN, written `null`,
    /// where it could not be estimated).
    #[serde(default, deserialize_with = "crate::dic::f64_or_nan")]
    pub discrepancy_se_px: f64,
    /// Effects of the model, in vocabulary order.
    #[serde(default)]
    pub effects: Vec<String>,
    /// The manifest compared, by content ([`short_hash`] of its JSON; empty in entries written
    /// before it was recorded), and its number of runs: a dataset that grew is told apart from
    /// the one it was.
    #[serde(default)]
    pub manifest_version: String,
    #[serde(default)]
    pub manifest_runs: usize,
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
            discrepancy_se_px: 0.0,
            effects,
            manifest_version: String::new(),
            manifest_runs: 0,
        }
    }

    /// The history entry of a comparison made now.
    pub fn of(cmp: &super::Comparison) -> Self {
        Self {
            manifest_version: cmp.manifest_version.clone(),
            manifest_runs: cmp.manifest_runs,
            discrepancy_se_px: cmp.discrepancy_se_px,
            ..Self::now(
                &cmp.dataset,
                &cmp.model.name,
                &cmp.model.version,
                cmp.discrepancy_px,
                cmp.model.effects.names(),
            )
        }
    }
}

pub fn history_path(dataset_dir: &Path) -> PathBuf {
    dataset_dir.join(HISTORY_FILE)
}

/// Appends one entry (creates the file).
/// The history folder of the dataset in `dataset_dir` under the data folder `data_dir`:
/// `DATA/history/NAME-HASH`, NAME the dataset folder's name, HASH of its full path (two folders
/// of the same name keep two histories).
pub fn history_dir_for(data_dir: &Path, dataset_dir: &Path) -> PathBuf {
    let full = std::fs::canonicalize(dataset_dir).unwrap_or_else(|_| dataset_dir.to_owned());
    let name: String = full
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "dataset".into())
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .take(64)
        .collect();
    data_dir
        .join("history")
        .join(format!("{name}-{}", short_hash(&full.to_string_lossy())))
}

/// Twelve hex digits of FNV-1a over `text`: stable across builds and platforms, unlike std's
/// hasher (a model's version, a dataset's history folder).
pub(super) fn short_hash(text: &str) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in text.bytes() {
        h ^= b as u64;
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    format!("{:012x}", h & 0xffff_ffff_ffff)
}

/// Appends `entry` to the history in `history_dir` (made when missing).
pub fn append_history(history_dir: &Path, entry: &HistoryEntry) -> Result<(), DiagnoseError> {
    let path = history_path(history_dir);
    let err = |e: std::io::Error| DiagnoseError::History {
        path: path.clone(),
        message: e.to_string(),
    };
    std::fs::create_dir_all(history_dir).map_err(err)?;
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
pub fn read_history(history_dir: &Path) -> Result<Vec<HistoryEntry>, DiagnoseError> {
    let path = history_path(history_dir);
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

    /// A comparison whose error could not be estimated (NaN, which JSON writes as `null`) is
    /// recorded and read back, not a history that no longer reads (the fuzzer's 500).
    #[test]
    fn an_entry_without_an_error_reads_back() {
        let dir = tempfile::tempdir().unwrap();
        let entry = HistoryEntry {
            discrepancy_se_px: f64::NAN,
            ..HistoryEntry::now("ds", "baseline", "abc", f64::NAN, vec![])
        };
        append_history(dir.path(), &entry).unwrap();
        let h = read_history(dir.path()).unwrap();
        assert!(h[0].discrepancy_px.is_nan() && h[0].discrepancy_se_px.is_nan());
    }

    #[test]
    fn a_dataset_named_on_the_command_line_keeps_its_history_in_the_data_folder() {
        let root = tempfile::tempdir().unwrap();
        let (a, b) = (root.path().join("one/meas"), root.path().join("two/meas"));
        std::fs::create_dir_all(&a).unwrap();
        std::fs::create_dir_all(&b).unwrap();
        let data = root.path().join("data");
        let (ha, hb) = (history_dir_for(&data, &a), history_dir_for(&data, &b));
        assert!(
            ha.starts_with(data.join("history")) && ha != hb,
            "{ha:?} {hb:?}"
        );
        assert!(ha
            .file_name()
            .unwrap()
            .to_string_lossy()
            .starts_with("meas-"));
        assert_eq!(ha, history_dir_for(&data, &a.join(".")));
        append_history(
            &ha,
            &HistoryEntry::now("meas", "baseline", "v", 0.1, vec![]),
        )
        .unwrap();
        assert_eq!(read_history(&ha).unwrap().len(), 1);
        assert!(
            std::fs::read_dir(&a).unwrap().next().is_none(),
            "nothing in the measurement folder"
        );
    }
}
