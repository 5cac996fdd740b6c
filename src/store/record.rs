//! What the store keeps: run records (`run.json`), their events (`events.jsonl`) and dataset
//! records (`record.json`). Times are RFC 3339 UTC strings with milliseconds, so they sort as text.

use super::ids::{DatasetId, RunId};
use crate::run_event::EventKind;
use serde::{Deserialize, Serialize};
use serde_json::Value;
use std::fmt;

/// Now, as RFC 3339 UTC with milliseconds (`2026-11-22T10:15:00.123Z`).
pub fn now_rfc3339() -> String {
    humantime::format_rfc3339_millis(std::time::SystemTime::now()).to_string()
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RunKind {
    Experiment,
    Analysis,
    Comparison,
    Diagnosis,
    /// A design map (`POST /sweeps`), run on the compute lane.
    Sweep,
    /// A calibration (`POST /calibrations`): a move plan captured on the bench, diagnosed, and a
    /// camera card written; on the bench lane.
    Calibration,
    /// A diagnosis completed on the bench (`POST /datasets/{id}/on-bench`): the runs that
    /// separate what the dataset left open captured, appended, diagnosed again; on the bench
    /// lane.
    OnBench,
    /// A perpendicularity check (`POST /perpendicularity-checks`): a move back and forth, the
    /// target's tilt and the stage's angle read from the fields; on the bench lane.
    Perpendicularity,
}

impl RunKind {
    pub const ALL: [RunKind; 8] = [
        RunKind::Experiment,
        RunKind::Analysis,
        RunKind::Comparison,
        RunKind::Diagnosis,
        RunKind::Sweep,
        RunKind::Calibration,
        RunKind::OnBench,
        RunKind::Perpendicularity,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            RunKind::Experiment => "experiment",
            RunKind::Analysis => "analysis",
            RunKind::Comparison => "comparison",
            RunKind::Diagnosis => "diagnosis",
            RunKind::Sweep => "sweep",
            RunKind::Calibration => "calibration",
            RunKind::OnBench => "on_bench",
            RunKind::Perpendicularity => "perpendicularity",
        }
    }

    /// The first part of this kind's run ids.
    pub fn id_prefix(self) -> &'static str {
        match self {
            RunKind::Experiment => "exp",
            RunKind::Analysis => "ana",
            RunKind::Comparison => "cmp",
            RunKind::Diagnosis => "dia",
            RunKind::Sweep => "swp",
            RunKind::Calibration => "cal",
            RunKind::OnBench => "onb",
            RunKind::Perpendicularity => "prp",
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RunStatus {
    Queued,
    Running,
    Succeeded,
    Failed,
    Cancelled,
}

impl RunStatus {
    pub const ALL: [RunStatus; 5] = [
        RunStatus::Queued,
        RunStatus::Running,
        RunStatus::Succeeded,
        RunStatus::Failed,
        RunStatus::Cancelled,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            RunStatus::Queued => "queued",
            RunStatus::Running => "running",
            RunStatus::Succeeded => "succeeded",
            RunStatus::Failed => "failed",
            RunStatus::Cancelled => "cancelled",
        }
    }

    pub fn is_terminal(self) -> bool {
        matches!(
            self,
            RunStatus::Succeeded | RunStatus::Failed | RunStatus::Cancelled
        )
    }

    /// The event a move to this status writes (a run's first, `queued`, is written on creation;
    /// `Running` is announced as `started`).
    pub fn event_kind(self) -> EventKind {
        match self {
            RunStatus::Queued => EventKind::Queued,
            RunStatus::Running => EventKind::Started,
            RunStatus::Succeeded => EventKind::Succeeded,
            RunStatus::Failed => EventKind::Failed,
            RunStatus::Cancelled => EventKind::Cancelled,
        }
    }

    /// The status a terminal event seals its run with (the recovery of a run whose process died
    /// between the event and `run.json`).
    pub fn sealed_by(kind: EventKind) -> Option<RunStatus> {
        RunStatus::ALL
            .into_iter()
            .find(|s| s.is_terminal() && s.event_kind() == kind)
    }

    /// Whether events of `kind` are written only by status changes (never appended).
    pub fn writes(kind: EventKind) -> bool {
        RunStatus::ALL.into_iter().any(|s| s.event_kind() == kind)
    }

    /// The only moves: queued → running | cancelled | failed, running → succeeded | failed |
    /// cancelled. Never backwards, never to itself, and a terminal status is final.
    pub fn can_become(self, next: RunStatus) -> bool {
        use RunStatus::*;
        matches!(
            (self, next),
            (Queued, Running | Cancelled | Failed) | (Running, Succeeded | Failed | Cancelled)
        )
    }
}

crate::text_enum::text_enum!(RunKind, "RunKind");
crate::text_enum::text_enum!(RunStatus, "RunStatus");

/// One run: `runs/{id}/run.json`, rewritten whole on every change until the run has ended.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunRecord {
    pub id: RunId,
    pub kind: RunKind,
    pub status: RunStatus,
    /// 0 to 1, never decreasing.
    pub progress: f64,
    #[serde(default)]
    pub message: String,
    pub created_at: String,
    #[serde(default)]
    pub started_at: Option<String>,
    #[serde(default)]
    pub finished_at: Option<String>,
    #[serde(default)]
    pub dataset_id: Option<DatasetId>,
    /// The request as submitted.
    #[serde(default)]
    pub request: Value,
    #[serde(default)]
    pub idempotency_key: Option<String>,
    /// Files the run wrote, relative to its folder, in the order first written.
    #[serde(default)]
    pub result_files: Vec<String>,
}

/// One line of `runs/{id}/events.jsonl`. Ids count 1, 2, 3… within a run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Event {
    pub id: u64,
    pub run_id: RunId,
    pub kind: EventKind,
    pub progress: f64,
    #[serde(default)]
    pub message: String,
    pub at: String,
    #[serde(default)]
    pub data: Value,
}

/// Where a stored dataset came from. Written as `upload` or `experiment:{run id}` (the wire
/// form of `record.json` and the API); a word this version does not know reads as `Other`, kept
/// as it was.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum DatasetSource {
    /// `POST /datasets` (or `ffdic store import`).
    Upload,
    /// The frames of an experiment run.
    Experiment(RunId),
    Other(String),
}

impl fmt::Display for DatasetSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DatasetSource::Upload => f.write_str("upload"),
            DatasetSource::Experiment(id) => write!(f, "experiment:{id}"),
            DatasetSource::Other(text) => f.write_str(text),
        }
    }
}

impl From<&str> for DatasetSource {
    fn from(text: &str) -> Self {
        if text == "upload" {
            return DatasetSource::Upload;
        }
        text.strip_prefix("experiment:")
            .and_then(|id| id.parse().ok())
            .map_or_else(
                || DatasetSource::Other(text.to_string()),
                DatasetSource::Experiment,
            )
    }
}

impl Serialize for DatasetSource {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for DatasetSource {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        Ok(DatasetSource::from(String::deserialize(d)?.as_str()))
    }
}

/// A stored dataset: `datasets/{id}/record.json` beside its `dataset.json` and frames.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DatasetRecord {
    pub id: DatasetId,
    pub name: String,
    pub created_at: String,
    /// Where the frames came from; `upload` or `experiment:{run id}` on the wire.
    pub source: DatasetSource,
    /// Runs in the manifest.
    pub runs: usize,
    /// Frame size in pixels.
    pub width: usize,
    pub height: usize,
    /// Bits per sample of the first full-resolution reference frame, read from its header when
    /// the dataset was stored (absent in records written before it was recorded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bit_depth: Option<u8>,
    /// Every file of the dataset (not `record.json`), relative to its folder, sorted.
    pub files: Vec<String>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use RunStatus::*;

    #[test]
    fn transitions_go_forward_only_and_terminal_is_final() {
        let allowed = [
            (Queued, Running),
            (Queued, Cancelled),
            (Queued, Failed),
            (Running, Succeeded),
            (Running, Failed),
            (Running, Cancelled),
        ];
        for from in RunStatus::ALL {
            for to in RunStatus::ALL {
                assert_eq!(
                    from.can_become(to),
                    allowed.contains(&(from, to)),
                    "{from} -> {to}"
                );
            }
            if from.is_terminal() {
                assert!(RunStatus::ALL.iter().all(|&to| !from.can_become(to)));
            }
        }
        assert!(!Queued.is_terminal() && !Running.is_terminal());
    }

    #[test]
    fn names_match_serde() {
        for s in RunStatus::ALL {
            assert_eq!(serde_json::to_value(s).unwrap(), s.as_str());
            assert_eq!(s.as_str().parse::<RunStatus>().unwrap(), s);
        }
        for k in RunKind::ALL {
            assert_eq!(serde_json::to_value(k).unwrap(), k.as_str());
            assert_eq!(k.as_str().parse::<RunKind>().unwrap(), k);
        }
        assert!("done".parse::<RunStatus>().is_err());
    }

    #[test]
    fn status_changes_and_their_events_agree() {
        use crate::run_event::EventKind;
        for k in EventKind::ALL {
            // A terminal event seals a run with the status of the same word, and only those do.
            let sealed = RunStatus::sealed_by(k);
            assert_eq!(sealed.is_some(), k.is_terminal(), "{k}");
            if let Some(s) = sealed {
                assert_eq!((s.as_str(), s.event_kind()), (k.as_str(), k));
            }
        }
        let by_status: Vec<EventKind> = RunStatus::ALL.map(RunStatus::event_kind).to_vec();
        assert_eq!(by_status.len(), 5);
        assert!(RunStatus::writes(EventKind::Started) && !RunStatus::writes(EventKind::Progress));
    }

    #[test]
    fn dataset_sources_keep_their_wire_form() {
        let id: RunId = "exp-20260101t000000-aaaaaa".parse().unwrap();
        for (text, source) in [
            ("upload", DatasetSource::Upload),
            (
                "experiment:exp-20260101t000000-aaaaaa",
                DatasetSource::Experiment(id),
            ),
            (
                "import:elsewhere",
                DatasetSource::Other("import:elsewhere".into()),
            ),
        ] {
            assert_eq!(serde_json::to_value(&source).unwrap(), text);
            assert_eq!(
                serde_json::from_value::<DatasetSource>(text.into()).unwrap(),
                source
            );
        }
    }

    #[test]
    fn times_sort_as_text() {
        let a = now_rfc3339();
        std::thread::sleep(std::time::Duration::from_millis(2));
        let b = now_rfc3339();
        assert!(a < b, "{a} {b}");
        assert!(humantime::parse_rfc3339(&a).is_ok());
    }
}
