//! The model held against a measurement (DESIGN.md, "The model and its effects").
//!
//! `compare` runs the same DIC on the measured frames of a dataset and on frames the model renders
//! for the same nominal experiment, and reports where and by how much they disagree; `diagnose`
//! fits every catalogue effect the model lacks, recomputes the discrepancy with it, and ranks the
//! candidates by ΔBIC and by the drop; `history` keeps the fall of the discrepancy.
//!
//! # The nominal experiment
//!
//! What the dataset says plus what any comparison must calibrate: the frames' size and bit depth,
//! `scale_px_per_mm`, each run's commanded move, the print, the white level, the stage and the
//! sensor.
//!
//! - **The print** ([`print`]) is calibrated to the measured reference frame (contrast, then the
//!   dot size that gives the measured spectral shape) unless the manifest characterises it
//!   (`"profile": "gaussian"` with contrast and size or MTF): a nominal print never is the print
//!   the camera sees. Blur that one magnification cannot attribute to the print or to the lens is
//!   therefore not fitted against such a print (blur and aperture are reported as not
//!   identifiable, with what would reveal them).
//! - **The stage** ([`stage`]): travel scale and misalignment fitted to the mean displacements, and
//!   each run's rigid landing offset, within ±3σ of the stated repeatability (the model's
//!   `stage_error`, else the dataset's `stage_repeatability_um`; free when neither states one).
//!   The offsets are refined against the model's own DIC, so its sub-pixel bias is not read as a
//!   landing. Offsets beyond the envelope stay in the discrepancy's rigid part, where `diagnose`
//!   finds `stage_error`.
//! - **The sensor**: the ADC at the TIFFs' bit depth and — when the model has no `sensor_noise` —
//!   a signal-independent noise whose σ is the pooled noise of the measured frames (from the
//!   static repeat frames when present, over the pixels clipped in neither). A hidden
//!   photon-transfer (shot) noise therefore shows as the wrong slope of noise against mean
//!   (EMVA 1288).
//!
//! `quantization` is thus always known and `stage_misalignment` always fitted; neither is a
//! diagnose candidate.
//!
//! # The discrepancy (px)
//!
//! For one run and one reduction scheme, with d_i = (u, v)_measured − (u, v)_model at every point
//! of interest valid in both analyses (DIC output against DIC output, never against the true
//! motion), in px of the analysed (reduced) image, three parts, each debiased for noise (squares
//! clipped at zero, so a model that is right scatters about zero instead of sitting on the noise
//! floor):
//!
//! - `rigid_px`: the length of the mean of d, less its noise σ²·c/n per component (c = (subset/
//!   step)² ≥ 1, the variance inflation of averages over points whose subsets overlap): a landing
//!   beyond the stage's envelope, or a sub-pixel bias one scheme has and the model lacks;
//! - `field_px`: the RMS about its mean of the least-squares quadratic surface fitted to d, per
//!   component, less (p−1)·σ²·c/n (p = 6 terms, σ² the residual variance about the surface): linear
//!   fields (rotation, scale), quadratic ones (radial distortion for a translation is exactly
//!   quadratic in position);
//! - `std_px`: √(Δσu² + Δσv²), Δσ the difference of the random errors — the standard deviation of
//!   each analysis' displacement about its own quadratic surface (the paper's std statistic with
//!   the systematic field removed) — less the sampling error of two stds ((σm² + σo²)/(2 n_eff),
//!   n_eff = n/c). This is where image-level effects (blur, aperture, noise) show in DIC.
//!
//! `discrepancy_px` = √(rigid² + field² + std²) per run and scheme; in total the RMS over all
//! runs and schemes. Its standard error (`discrepancy_se_px`): the sampling variance of each
//! square (a noncentral χ²) propagated over the analyses, the frames they share counted
//! (`compare::discrepancy_se`); `diagnose` takes the larger of that and the scatter of the
//! discrepancy over `MODEL_SEEDS` renderings of the model with different seeds.
//!
//! The same comparison keeps the paper's raw std statistics of both sides, the strain std, and
//! image statistics (mean-intensity map, contrast, noise against mean, power spectra along x and
//! y) that DIC's zero-normalised criterion does not see (vignetting, illumination change).
//!
//! # A verdict
//!
//! A candidate is the verdict when it meets every criterion ([`Criteria`], in the JSON): ΔBIC
//! below −10 (the χ² counts coefficients and bins, not points, each scaled for overlapping
//! subsets and shared frames, so n in k·ln n is an effective sample size); a fitted parameter more
//! than two standard errors from "no effect"; a drop larger than two standard errors — of the
//! discrepancy for effects DIC sees, of the image statistics' χ² (SE √(2n + 4λ)) for those it
//! does not (vignetting, illumination change, shot noise), either for blur, aperture and motion
//! blur; a value not at the bound of the catalogue's range (reported as outside it instead); and
//! for blur and aperture, a print the dataset characterises. Among the candidates meeting all,
//! the most negative ΔBIC wins. `--rounds N` adds the winner and diagnoses again ([`rounds`]).
//!
//! References: Schreier, Braasch & Sutton, Opt. Eng. 39 (2000) (interpolation bias, sub-pixel
//! errors); Pan, Xie & Wang, Appl. Opt. 49 (2010) and Pan, Meas. Sci. Technol. 29 (2018)
//! (noise-induced DIC errors, σu ≈ √2 σ / √Σ f_x²); Reu, Exp. Tech. (2012–2015) "Hidden
//! components of DIC" series (speckle, noise, calibration); Brown, Photogramm. Eng. 32 (1966)
//! (radial distortion); EMVA 1288 (photon transfer); Schwarz, Ann. Stat. 6 (1978) (BIC); Kass &
//! Raftery, JASA 90 (1995) (ΔBIC < −10: very strong evidence).

mod basis;
mod bic;
mod calibrate_scene;
mod candidates;
mod capture_mode;
mod card;
mod card_distortion;
mod card_joint_fit;
mod card_stage;
mod compare;
// The brief names the file after its job; the module is the entry point of the folder's job.
#[allow(clippy::module_inception)]
mod diagnose;
mod discrepancy;
mod fit_geometric;
mod fit_geometric_effect;
mod fit_image;
mod fit_image_stats;
mod fit_user_effect;
mod fit_user_intensity;
mod floor_read_out;
mod gauss_newton;
mod geometric;
mod history;
mod identifiability;
mod image_stats;
mod measurement;
mod move_design;
mod nominal;
mod optimise;
mod print;
mod residual_shape;
mod residuals;
mod results;
mod rounds;
mod scene;
mod separating_runs;
mod stage;
mod stage_landing;
#[cfg(test)]
mod test_fields;
mod tilt_readout;
mod unexplained;
mod unexplained_words;
mod verdict;
mod write_geometric;

// The public surface: what `service`, `report`, `cli`, the Python bindings and the tests call,
// then the types of the documents those calls return (ARCHITECTURE.md lists both).
pub use card::calibrate;
pub use compare::{compare, compare_prepared, model_version};
pub use diagnose::{diagnose, diagnose_prepared};
pub use history::{append_history, history_dir_for, read_history};
pub use image_stats::noise_variance;
pub use measurement::{load_measurement, Measurement};
pub use nominal::BASELINE_TOML;
pub use rounds::{diagnose_rounds, diagnose_rounds_prepared, MAX_ROUNDS};
pub use tilt_readout::{
    read_perpendicularity, PerpendicularityReading, ReadoutError, ReadoutRun, ReadoutSetting,
};

pub use basis::GeometricParam;
pub use card::{CameraCard, CardEffect, ImagingEntry};
pub use card_stage::StageMap;
pub use discrepancy::{DiscrepancyErrors, RunDiscrepancy};
pub use history::HistoryEntry;
pub use identifiability::{Confounded, NotIdentifiable, STEP_SERIES_MIN_STEPS};
pub use image_stats::{FrameStats, MeanMap, PsdBin, PtcPoint};
pub use move_design::{design_for, DesignedPair, MoveDesign, MAX_VARIANCE_INFLATION};
pub use nominal::{Nominal, PatternEstimate};
pub use print::{PrintCalibration, PrintKnowledge};
pub use residual_shape::{ImageMismatch, RunShape, Shape};
pub use residuals::ResidualMap;
pub use results::{
    Accuracy, Chi2, Comparison, DiscrepancyParts, HardwareComparison, HardwareRunComparison,
    ImageComparison, ModelInfo, RunComparison, Side,
};
pub use rounds::{Round, Rounds};
pub use separating_runs::{open_questions, runs_to_separate, SeparatingRuns};
pub use stage_landing::{RepeatabilitySource, StageLanding};
pub use unexplained::Unexplained;
pub use verdict::{Candidate, Criteria, Diagnosis, Evidence, Method, Withheld};

use crate::dataset::DatasetError;
use crate::dic::{DicError, DicSettings};
use crate::image::ImageError;
use crate::model::ModelError;
use crate::reduce::{ReduceError, Scheme};

/// Progress callback: (steps done, steps in all) -> go on? Returning false cancels the job. It
/// is also called again with counts it was given before, from any thread (before every DIC
/// point of a comparison, so a cancel is seen within a point): such a call only asks, and a
/// reporter reports only what changed.
pub type Progress<'a> = &'a (dyn Fn(usize, usize) -> bool + Sync);

#[derive(Debug, thiserror::Error)]
pub enum DiagnoseError {
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    #[error(transparent)]
    Image(#[from] ImageError),
    #[error(transparent)]
    Model(#[from] ModelError),
    /// The runs' moves (or the fitted travel) need a target larger than a layout may hold.
    #[error("the model cannot render this dataset: {0}")]
    Target(#[from] crate::model::TooManyDots),
    #[error(transparent)]
    Reduce(#[from] ReduceError),
    #[error("run {run}, scheme {scheme}: {source}")]
    Dic {
        run: String,
        scheme: String,
        source: DicError,
    },
    #[error("run {run}: {message}")]
    Frames { run: String, message: String },
    #[error("history {path}: {message}")]
    History {
        path: std::path::PathBuf,
        message: String,
    },
    #[error("cancelled")]
    Cancelled,
}

impl From<crate::pairs::PairError> for DiagnoseError {
    fn from(e: crate::pairs::PairError) -> Self {
        use crate::pairs::PairError;
        match e {
            PairError::Cancelled => DiagnoseError::Cancelled,
            PairError::Image(e) => DiagnoseError::Image(e),
            PairError::Frames { run, source } => DiagnoseError::Frames {
                run,
                message: source.to_string(),
            },
            PairError::Reduce { source, .. } => DiagnoseError::Reduce(source),
            PairError::Dic {
                run,
                scheme,
                source,
            } => DiagnoseError::Dic {
                run,
                scheme,
                source,
            },
        }
    }
}

/// How a comparison is made: the DIC settings, the reduction schemes and the seed of the model's
/// speckle layouts and noise (fixed, so a comparison is reproducible).
#[derive(Clone, Debug, PartialEq)]
pub struct CompareOptions {
    pub dic: DicSettings,
    pub schemes: Vec<Scheme>,
    pub seed: u64,
}

/// Options a caller spelled wrong.
#[derive(Debug, thiserror::Error)]
pub enum CompareOptionsError {
    #[error(transparent)]
    Scheme(#[from] ReduceError),
    #[error("at least one scheme")]
    NoScheme,
    #[error(transparent)]
    Dic(#[from] DicError),
}

impl CompareOptions {
    /// Options from schemes as a person writes them (`ff100`, `ff50`, `ff25`, `native` in any
    /// case, or `BXxBY/AXxAY`; see [`Scheme::parse`]) and the DIC settings both sides are
    /// analysed with: what `ffdic compare` and the Python bindings take.
    pub fn from_scheme_specs(
        schemes: &[String],
        dic: DicSettings,
        seed: u64,
    ) -> Result<Self, CompareOptionsError> {
        let schemes = schemes
            .iter()
            .map(|s| Scheme::parse(s))
            .collect::<Result<Vec<_>, _>>()?;
        if schemes.is_empty() {
            return Err(CompareOptionsError::NoScheme);
        }
        dic.validate()?;
        Ok(Self { dic, schemes, seed })
    }
}

impl Default for CompareOptions {
    fn default() -> Self {
        Self {
            dic: DicSettings::default(),
            schemes: Scheme::presets(),
            seed: 0x0FFD_1C5E,
        }
    }
}
