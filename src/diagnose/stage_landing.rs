//! Where each run's stage landed, as fitted (`stage::fit_stage`): part of the nominal experiment
//! the model renders.

use crate::model::effects::StageError;
use serde::{Deserialize, Serialize};

/// Where the repeatability that bounds the landing offsets came from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RepeatabilitySource {
    /// The model's `stage_error` effect.
    Model,
    /// The dataset's `stage_repeatability_um`.
    Dataset,
    /// Neither: offsets are free.
    #[default]
    Unstated,
}

/// The fitted landing of every run (indexed as the manifest's runs).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StageLanding {
    /// The repeatability (1σ per axis, µm) that bounds the offsets, and its source.
    pub repeatability_um: Option<f64>,
    pub source: RepeatabilitySource,
    /// What the data say each run's stage did beyond travel and misalignment, px (x, y).
    pub landing_px: Vec<[f64; 2]>,
    /// Standard error of each landing (per axis), px.
    pub landing_se_px: Vec<f64>,
    /// The offset the model renders, px: the landing clipped to the envelope.
    pub offsets_px: Vec<[f64; 2]>,
}

impl StageLanding {
    pub fn applied_offset_px(&self, run: usize) -> [f64; 2] {
        self.offsets_px.get(run).copied().unwrap_or([0.0, 0.0])
    }

    /// The envelope half-width per axis, px (infinite when no repeatability is known).
    pub fn envelope_px(&self, scale_px_per_mm: f64) -> f64 {
        self.repeatability_um.map_or(f64::INFINITY, |r| {
            StageError::ENVELOPE_SIGMAS * r * scale_px_per_mm / 1000.0
        })
    }

    /// The repeatability the landings show, 1σ per axis, µm, with its standard error: the RMS of
    /// the landings over 2·runs − 2 degrees of freedom (travel and misalignment took two), the
    /// landings' own measurement noise removed.
    pub fn observed_repeatability_um(&self, scale_px_per_mm: f64) -> Option<(f64, f64)> {
        let n = self.landing_px.len();
        if n < 2 {
            return None;
        }
        let dof = (2 * n - 2) as f64;
        let ss: f64 = self
            .landing_px
            .iter()
            .zip(&self.landing_se_px)
            .map(|(l, se)| l[0] * l[0] + l[1] * l[1] - 2.0 * se * se)
            .sum();
        let sigma_px = (ss / dof).max(0.0).sqrt();
        let to_um = 1000.0 / scale_px_per_mm;
        // A χ² with `dof` degrees of freedom: SE(σ) ≈ σ/√(2·dof), never below the landings' noise.
        let noise = self.landing_se_px.iter().copied().fold(0.0, f64::max);
        let se_px = (sigma_px / (2.0 * dof).sqrt()).max(noise);
        Some((sigma_px * to_um, se_px * to_um))
    }
}
