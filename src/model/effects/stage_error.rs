use serde::{Deserialize, Serialize};

/// The stage does not land exactly where it is told: every run's actual position is off by a
/// rigid offset drawn from the stage's repeatability (1σ per axis). The model does not render a
/// realisation of it: a comparison fits each run's offset from the measured mean displacement
/// (the nominal fit, `diagnose::nominal`) and accepts offsets up to [`StageError::ENVELOPE_SIGMAS`]
/// times this repeatability; larger ones stay in the discrepancy as its rigid part. Without this
/// effect the repeatability the dataset states (`stage_repeatability_um`) bounds the offsets; a
/// dataset stating none leaves them free.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StageError {
    pub repeatability_um: f64,
}

impl StageError {
    /// Offsets within ±3σ per axis are the stage behaving as specified (99.7 % of landings).
    pub const ENVELOPE_SIGMAS: f64 = 3.0;
}
