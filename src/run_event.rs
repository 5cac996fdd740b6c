//! The vocabulary of run events: the name of each line of a run's `events.jsonl` and of each
//! server-sent event. One enum, so the emitters (the experiment runner, the jobs), the store, the
//! SSE stream and the dashboard — which reads the list from the OpenAPI document's `EventKind`
//! schema instead of keeping its own — cannot drift apart. The wire form is the snake_case word.
//! Which kinds a status change writes is the store's (`RunStatus::event_kind`).

use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum EventKind {
    /// The run was accepted (written by the store when the run is created).
    Queued,
    /// A worker took the run up.
    Started,
    /// Progress of an analysis, comparison or diagnosis (`data` says which step).
    Progress,
    /// An experiment homes its stage.
    Homing,
    /// An experiment set the camera's exposure and gain (read back in `data`).
    CameraSet,
    /// The mock bench mounted a speckle pattern (a real bench asks the operator).
    TargetMounted,
    /// The stage reached a commanded position (read back in `data`).
    StageMoved,
    /// A frame was captured and written.
    FrameCaptured,
    /// The experiment's frames and manifest were written.
    DatasetWritten,
    /// One reference/moved pair was correlated (experiments and analyses).
    PairAnalyzed,
    /// The experiment's frames became a dataset in the store (`data.dataset_id`).
    DatasetRegistered,
    /// A sweep expanded its spec into tasks and shards.
    Planned,
    /// A sweep finished some of its shards.
    ShardsRun,
    /// A sweep merged its tasks into the map.
    Merged,
    /// Terminal: the run succeeded.
    Succeeded,
    /// Terminal: the run failed (`message` says why).
    Failed,
    /// Terminal: the run was cancelled.
    Cancelled,
}

impl EventKind {
    pub const ALL: [EventKind; 17] = [
        EventKind::Queued,
        EventKind::Started,
        EventKind::Progress,
        EventKind::Homing,
        EventKind::CameraSet,
        EventKind::TargetMounted,
        EventKind::StageMoved,
        EventKind::FrameCaptured,
        EventKind::DatasetWritten,
        EventKind::PairAnalyzed,
        EventKind::DatasetRegistered,
        EventKind::Planned,
        EventKind::ShardsRun,
        EventKind::Merged,
        EventKind::Succeeded,
        EventKind::Failed,
        EventKind::Cancelled,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            EventKind::Queued => "queued",
            EventKind::Started => "started",
            EventKind::Progress => "progress",
            EventKind::Homing => "homing",
            EventKind::CameraSet => "camera_set",
            EventKind::TargetMounted => "target_mounted",
            EventKind::StageMoved => "stage_moved",
            EventKind::FrameCaptured => "frame_captured",
            EventKind::DatasetWritten => "dataset_written",
            EventKind::PairAnalyzed => "pair_analyzed",
            EventKind::DatasetRegistered => "dataset_registered",
            EventKind::Planned => "planned",
            EventKind::ShardsRun => "shards_run",
            EventKind::Merged => "merged",
            EventKind::Succeeded => "succeeded",
            EventKind::Failed => "failed",
            EventKind::Cancelled => "cancelled",
        }
    }

    /// Whether the event ends its run (its status is the event's word). Written only by the
    /// store's status change, and always the run's last.
    pub fn is_terminal(self) -> bool {
        matches!(
            self,
            EventKind::Succeeded | EventKind::Failed | EventKind::Cancelled
        )
    }
}

crate::text_enum::text_enum!(EventKind, "event kind");

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_wire_form_is_the_serde_word_and_parses_back() {
        for k in EventKind::ALL {
            assert_eq!(serde_json::to_value(k).unwrap(), k.as_str());
            assert_eq!(k.as_str().parse::<EventKind>().unwrap(), k);
        }
        assert!("server_shutdown".parse::<EventKind>().is_err());
    }
}
