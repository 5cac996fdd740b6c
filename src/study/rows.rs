//! The rows of the fill-factor study (one per run and scheme, or per pooled captures): what its
//! tables, CSV, JSON and figures show.

use crate::dic::{f64_or_nan, interval_or_nan, Summary};
use serde::{Deserialize, Serialize};

/// Percent increase of each standard deviation over the same run's first (100 %) scheme — for a
/// hardware scheme's run, over its twin's first scheme.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Increase {
    #[serde(deserialize_with = "f64_or_nan")]
    pub u: f64,
    #[serde(deserialize_with = "f64_or_nan")]
    pub v: f64,
    #[serde(deserialize_with = "f64_or_nan")]
    pub exx: f64,
    #[serde(deserialize_with = "f64_or_nan")]
    pub eyy: f64,
    #[serde(deserialize_with = "f64_or_nan")]
    pub exy: f64,
}

/// 95 % intervals of the [`Increase`] percentages: a block bootstrap resampling the same
/// grid blocks in the baseline and this scheme (`dic::bootstrap`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct IncreaseInterval {
    #[serde(deserialize_with = "interval_or_nan")]
    pub u: [f64; 2],
    #[serde(deserialize_with = "interval_or_nan")]
    pub v: [f64; 2],
    #[serde(deserialize_with = "interval_or_nan")]
    pub exx: [f64; 2],
    #[serde(deserialize_with = "interval_or_nan")]
    pub eyy: [f64; 2],
    #[serde(deserialize_with = "interval_or_nan")]
    pub exy: [f64; 2],
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StudyRow {
    pub run: String,
    pub pattern: String,
    pub scheme: String,
    /// Linear fill factors (x, y) of the scheme.
    pub fill_factor: (f64, f64),
    pub summary: Summary,
    /// None for the baseline scheme itself.
    pub increase_pct: Option<Increase>,
    /// None for the baseline, and where the two grids differ in shape or hold too few blocks.
    #[serde(default)]
    pub increase_ci95: Option<IncreaseInterval>,
    /// Independent captures pooled into this row (`pool::pool_captures`); 1 for a single capture,
    /// whose intervals are the block bootstrap's.
    #[serde(default = "one_capture")]
    pub repeats: usize,
    /// The commanded move in this row's pixels (u, v): the stage's move × the dataset's scale,
    /// over the camera's own read-out factor and the scheme's block per axis. The bias is
    /// `summary.u.mean − expected_px[0]`. Absent in rows written before it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub expected_px: Option<[f64; 2]>,
    /// The displacement with a camera card's geometry taken off (an analysis given a card).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub card: Option<super::CardStats>,
}

impl StudyRow {
    /// The measured mean minus the commanded move (u, v), px of the row's scheme; `None` where
    /// no commanded move is recorded.
    pub fn bias_px(&self) -> Option<[f64; 2]> {
        self.expected_px
            .map(|[u, v]| [self.summary.u.mean - u, self.summary.v.mean - v])
    }

    /// The card-corrected mean minus the commanded move (u, v), px of the row's scheme.
    pub fn card_bias_px(&self) -> Option<[f64; 2]> {
        let (card, [u, v]) = (self.card.as_ref()?, self.expected_px?);
        Some([card.u.mean - u, card.v.mean - v])
    }
}

fn one_capture() -> usize {
    1
}
