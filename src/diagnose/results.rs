//! What a comparison and a candidate fit produce: the types `comparison.json` and the
//! diagnosis are made of. They sit apart from the steps that compute them (`compare`, `bic`,
//! `capture_mode`, `fit_image`, `stage`) so those steps import them without importing each other.

use super::discrepancy::{DiscrepancyErrors, RunDiscrepancy};
use super::image_stats::FrameStats;
use super::nominal::Nominal;
use super::residuals::ResidualMap;
use crate::dic::{DicResult, Summary};
use crate::model::{CandidateId, Effects};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The model a comparison used: its file's name, a version hash, its effects, and the nominal
/// experiment calibrated for this dataset.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelInfo {
    pub name: String,
    pub version: String,
    pub effects: Effects,
    pub nominal: Nominal,
}

/// One side of a run's comparison: the paper's statistics and the random error.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Side {
    pub summary: Summary,
    /// Std of u and v about their own quadratic surface, px.
    pub random_px: [f64; 2],
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunComparison {
    pub id: String,
    /// The run's pattern label (the reference frame it shares with other runs).
    pub pattern: String,
    pub scheme: String,
    pub discrepancy_px: f64,
    /// The three parts of the discrepancy (module doc of `diagnose`): rigid, field, std.
    pub rigid_px: f64,
    pub field_px: f64,
    pub std_px: f64,
    /// The standard errors of the discrepancy, its parts and `mean_diff_px`.
    #[serde(flatten)]
    pub se: DiscrepancyErrors,
    /// The stage landing offset the model rendered for this run, µm (x, y), and what the data
    /// said before the stage's envelope clipped it.
    pub stage_offset_um: [f64; 2],
    pub stage_landing_um: [f64; 2],
    pub measured: Side,
    pub model: Side,
    /// Mean of measured − model, px (u, v).
    pub mean_diff_px: [f64; 2],
    /// Sub-pixel fraction of the measured mean displacement (u, v), in [0, 1).
    pub subpixel_fraction: [f64; 2],
    /// Actual move of the nominal experiment, full-resolution px.
    pub move_px: [f64; 2],
    /// The measured side against the commanded move.
    #[serde(default)]
    pub accuracy: Accuracy,
    pub residual: ResidualMap,
    #[serde(skip)]
    pub detail: RunDiscrepancy,
}

/// "How accurate is my camera?": the measured mean displacement of a run against the move the
/// stage was commanded to make (its travel error included), and the scatter about it, in the
/// analysed image's px and in µm on the target.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Accuracy {
    /// The commanded move in this scheme's px (stage mm × the frames' px/mm ÷ the block).
    pub commanded_px: [f64; 2],
    /// Measured mean − commanded, px, and its standard error: the std over √(valid points / c),
    /// c = (subset/step)² the overlap of neighbouring subsets.
    pub bias_px: [f64; 2],
    pub bias_se_px: [f64; 2],
    /// The measured displacements' standard deviation over the grid, px.
    pub std_px: [f64; 2],
    pub bias_um: [f64; 2],
    pub bias_se_um: [f64; 2],
    pub std_um: [f64; 2],
}

/// Image statistics of one measured frame and the model's frame of it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImageComparison {
    /// "reference" (per pattern) or "moved" (per run).
    pub frame: String,
    pub pattern: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub run: Option<String>,
    pub measured: FrameStats,
    pub model: FrameStats,
}

/// Totals by part, px.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DiscrepancyParts {
    #[serde(default)]
    pub rigid_px: f64,
    pub field_px: f64,
    pub std_px: f64,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Comparison {
    pub dataset: String,
    /// The manifest compared, by content (a short hash of its JSON), and its number of runs:
    /// what the history keys a comparison on besides the model's version.
    #[serde(default)]
    pub manifest_version: String,
    #[serde(default)]
    pub manifest_runs: usize,
    pub model: ModelInfo,
    /// RMS over every run and scheme of the per-run discrepancy, px.
    pub discrepancy_px: f64,
    /// Its standard error from the noise of both sides' analyses, px ([`super::compare::discrepancy_se`]).
    #[serde(default)]
    pub discrepancy_se_px: f64,
    pub parts: DiscrepancyParts,
    /// The parts' standard errors, propagated as the total's.
    #[serde(default)]
    pub parts_se: DiscrepancyParts,
    pub runs: Vec<RunComparison>,
    pub images: Vec<ImageComparison>,
    pub chi2: Chi2,
    /// The runs the camera read out in its own binning or decimation, compared in that mode
    /// beside the fit ([`super::capture_mode`]); absent without such runs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hardware: Option<HardwareComparison>,
    /// Such runs without a full-resolution twin in the dataset: not compared.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub hardware_runs_set_aside: usize,
    /// The model's analyses, per run and scheme (diagnose predicts geometric candidates from
    /// them without rendering).
    #[serde(skip)]
    pub model_dic: Vec<Vec<DicResult>>,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// The image statistics' kinds: spectra, photon transfer, mean map, contrast.
pub const IMAGE_KINDS: usize = 5;

#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Chi2 {
    pub field: f64,
    pub std: f64,
    pub image: f64,
    pub total: f64,
    /// Number of observations (for k·ln n).
    pub observations: usize,
    /// Of which image statistics.
    #[serde(default)]
    pub image_observations: usize,
    /// The image χ² and observations per kind (spectra, photon transfer, mean map, contrast,
    /// the moved frames' light change).
    #[serde(default)]
    pub image_parts: [(f64, usize); IMAGE_KINDS],
}

/// One capture-mode run compared.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HardwareRunComparison {
    pub id: String,
    /// The full-resolution run of the same pattern and move.
    pub twin: String,
    pub pattern: String,
    /// The capture mode's name (`hw:bin2x2-average`, …).
    pub scheme: String,
    /// In px of the captured (reduced) frames, as the synthesised schemes' are in theirs.
    pub discrepancy_px: f64,
    /// Its standard errors (and its parts') from the noise of both analyses.
    #[serde(flatten)]
    pub se: DiscrepancyErrors,
    #[serde(flatten)]
    pub parts: DiscrepancyParts,
    /// Points valid in both analyses.
    pub points: usize,
    /// Random error of each side (std of u and v about their own quadratic surface), px.
    pub measured_random_px: [f64; 2],
    pub model_random_px: [f64; 2],
    pub mean_diff_px: [f64; 2],
    /// Image statistics of the captured reference and moved frames and the model's.
    pub reference: [FrameStats; 2],
    pub moved: [FrameStats; 2],
}

/// Every capture-mode run of a comparison.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HardwareComparison {
    /// RMS of the runs' discrepancies, px of their frames.
    pub discrepancy_px: f64,
    pub runs: Vec<HardwareRunComparison>,
}

/// A fitted candidate: its parameters, their standard errors (fitted ones only), the effects with
/// it added, and whether any parameter differs from its null value by more than two standard
/// errors.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageFit {
    pub effect: CandidateId,
    pub params: BTreeMap<String, f64>,
    pub stderr: BTreeMap<String, f64>,
    pub effects: Effects,
    pub k: usize,
    pub beyond_null: bool,
    /// For a geometric effect, its basis terms and what follows from them.
    pub geometric: GeometricTerms,
}

/// A geometric candidate's fitted basis terms (to predict its comparison without rendering),
/// quantities derived from them, and notes on the terms left out.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GeometricTerms {
    pub field: Vec<(super::basis::GeometricParam, f64)>,
    pub derived: BTreeMap<String, f64>,
    pub notes: Vec<String>,
}
