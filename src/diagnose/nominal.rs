//! The nominal experiment of a dataset and the model's frames for it.
//!
//! Speckle: the manifest's pattern fields (`dot_diameter_mm`, `dot_spacing_mm`, and the optional
//! `contrast`, `edge_softness_mm`) when present; otherwise estimated from the measured reference
//! as a field of Gaussian dots (a shot-noise process): the autocorrelation along x and y gives the
//! imaged dot σ (ρ(k) ∝ exp(−k²/4σ²) for k ≥ 1, which skips the noise at lag 0), and the mean
//! deficit m = 2πσ²ρc and the noise-free variance v = πσ²ρc² give the depth c = 2v/m and the
//! density ρ. An estimated dot size contains the lens blur and the pixel aperture, which is why
//! `psf_blur` needs a manifest dot size to be identifiable. The white level is then matched so the
//! model's mean equals the measured mean.
//!
//! Stage: the commanded move, turned by the misalignment angle, scaled by the travel scale and
//! shifted by the run's landing offset, all fitted to the measured mean displacements
//! ([`super::stage`]).

use super::image_stats::{centred_crop, noise_variance, percentile};
use super::print::{
    characterised, stated_placement, stated_profile, PrintCalibration, PrintKnowledge,
};
use super::stage_landing::StageLanding;
use crate::dataset::{Manifest, Run};
use crate::image::Image;
use crate::model::effects::{Quantization, StageMisalignment};
use crate::model::{Camera, DotProfile, Effects, Placement, SpecklePattern};
use serde::{Deserialize, Serialize};

/// FWHM = 2·sqrt(2 ln 2)·σ.
const FWHM_PER_SIGMA: f64 = 2.354_820_045_030_949;

/// `config/models/baseline.toml`: what the paper assumes.
pub const BASELINE_TOML: &str = include_str!("../../config/models/baseline.toml");

/// The speckle of one pattern label and where its numbers came from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PatternEstimate {
    pub pattern: SpecklePattern,
    /// White (background) level of this pattern's frames in DN, matched to the measured mean.
    pub white_level_dn: f64,
    /// "manifest", "estimated" or "manifest+estimated": where the starting print came from.
    pub source: String,
    /// Whether the print is rendered as the manifest characterises it or calibrated to the
    /// measured reference ([`super::print`]).
    #[serde(default)]
    pub print: PrintKnowledge,
    /// The calibration, when there was one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration: Option<PrintCalibration>,
    /// Whether the manifest states the dots' placement (`"placement"` in the pattern);
    /// otherwise it is chosen from the measured spectrum below the dot-spacing frequency.
    #[serde(default)]
    pub placement_stated: bool,
    /// That choice's evidence: the spectral-shape χ² there of the jittered grid, of Poisson
    /// placement and of the hard core (Poisson is kept unless another is lower by more than the
    /// χ²'s own scatter).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub placement_chi2: Option<[f64; 3]>,
    /// Whether the manifest states the dots' profile; otherwise the print is calibrated with
    /// each and the better kept ([`super::print`]).
    #[serde(default)]
    pub profile_stated: bool,
    /// That choice's evidence: the calibrated print's spectral-shape χ² with Gaussian dots and
    /// with disks, the best of the placements each fitted with disks (None: not tried, the
    /// Gaussian fitted). A disk print's placement is its best fit's, not `placement_chi2`'s
    /// choice (made below half the spacing frequency under Gaussian dots).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub profile_chi2: Option<[Option<f64>; 2]>,
}

impl PatternEstimate {
    /// A print from `source` (`manifest`, `estimated`, …), not yet calibrated to the frames and
    /// its placement not yet chosen.
    fn new(
        pattern: SpecklePattern,
        source: &str,
        white_level_dn: f64,
        print: PrintKnowledge,
    ) -> Self {
        PatternEstimate {
            pattern,
            source: source.into(),
            white_level_dn,
            print,
            calibration: None,
            placement_stated: false,
            placement_chi2: None,
            profile_stated: false,
            profile_chi2: None,
        }
    }
}

/// Everything the model needs beyond its effects to render the dataset's experiment.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Nominal {
    pub width: usize,
    pub height: usize,
    pub bit_depth: u8,
    pub scale_px_per_mm: f64,
    /// σ of the signal-independent noise used when the model has no `sensor_noise`, DN.
    pub noise_floor_dn: f64,
    /// Fitted stage misalignment (rad) and travel scale (actual / commanded).
    pub misalignment_rad: f64,
    pub travel_scale: f64,
    /// Where each run's stage landed, fitted (see [`super::stage`]).
    #[serde(default)]
    pub stage: StageLanding,
    /// One per distinct pattern label, in order of first appearance.
    pub patterns: Vec<PatternEstimate>,
}

impl Nominal {
    pub fn full_scale_dn(&self) -> f64 {
        Quantization {
            bits: self.bit_depth.into(),
        }
        .max_dn()
    }

    /// The effects the renderer gets: the model's, with the fitted misalignment and the dataset's
    /// ADC unless the model names its own.
    pub fn render_effects(&self, model: &Effects) -> Effects {
        let mut e = model.clone();
        e.stage_misalignment = Some(StageMisalignment {
            angle_rad: self.misalignment_rad,
        });
        if e.quantization.is_none() {
            e.quantization = Some(Quantization {
                bits: self.bit_depth as u32,
            });
        }
        e
    }

    /// The full-frame camera for pattern `pattern` (its white level sets the exposure).
    pub fn camera(&self, pattern: usize) -> Camera {
        let white = self
            .patterns
            .get(pattern)
            .map_or(0.5 * self.full_scale_dn(), |p| p.white_level_dn);
        Camera {
            width: self.width,
            height: self.height,
            scale_px_per_mm: self.scale_px_per_mm,
            exposure_level: white / self.full_scale_dn(),
            principal_dx_px: 0.0,
            principal_dy_px: 0.0,
        }
    }

    /// [`Nominal::camera`] reading only the centred window of `side` px that [`centred_crop`]
    /// cuts (its optical axis at the window's centre, as the full frame's is).
    pub fn crop_camera(&self, pattern: usize, side: usize) -> Camera {
        let (_, _, width, height) = centred_crop(self.width, self.height, side);
        Camera {
            width,
            height,
            ..self.camera(pattern)
        }
    }

    /// The actual stage move for a commanded one, mm, before the misalignment turns it.
    pub fn scaled_move(&self, dx_mm: f64, dy_mm: f64) -> (f64, f64) {
        (dx_mm * self.travel_scale, dy_mm * self.travel_scale)
    }

    /// The command that, through the travel scale and the misalignment, lands run `run` where the
    /// fit says it landed: the commanded move plus the run's rigid offset turned back into stage
    /// axes.
    pub fn landed_command(&self, run: usize, (dx_mm, dy_mm): (f64, f64)) -> (f64, f64) {
        let [ox, oy] = self.stage.applied_offset_px(run);
        if ox == 0.0 && oy == 0.0 {
            return (dx_mm, dy_mm);
        }
        let (s, c) = self.misalignment_rad.sin_cos();
        let k = self.scale_px_per_mm * self.travel_scale;
        (
            dx_mm + (c * ox + s * oy) / k,
            dy_mm + (-s * ox + c * oy) / k,
        )
    }

    /// The actual move of run `run` in full-resolution px (travel, misalignment and offset).
    pub fn actual_move_px(&self, run: usize, (dx_mm, dy_mm): (f64, f64)) -> [f64; 2] {
        let (sx, sy) = self.scaled_move(dx_mm, dy_mm);
        let (s, c) = self.misalignment_rad.sin_cos();
        let k = self.scale_px_per_mm;
        let [ox, oy] = self.stage.applied_offset_px(run);
        [k * (c * sx - s * sy) + ox, k * (s * sx + c * sy) + oy]
    }
}

/// The speckle of a run's pattern from its manifest fields, with whatever is missing estimated
/// from the measured reference `crop` (white level `white_dn`, pooled noise variance `noise_var`).
pub fn pattern_for(
    run: &Run,
    crop: &Image,
    white_dn: f64,
    noise_var: f64,
    scale_px_per_mm: f64,
) -> PatternEstimate {
    let mut estimate = pattern_guess(run, crop, white_dn, noise_var, scale_px_per_mm);
    if let Some(placement) = stated_placement(run) {
        estimate.pattern.placement = placement;
        estimate.placement_stated = true;
    }
    estimate.profile_stated = stated_profile(run).is_some();
    estimate
}

fn pattern_guess(
    run: &Run,
    crop: &Image,
    white_dn: f64,
    noise_var: f64,
    scale_px_per_mm: f64,
) -> PatternEstimate {
    let info = run.pattern.as_ref();
    let label = info.map_or_else(|| run.reference.clone(), |p| p.label.clone());
    let diameter = info.and_then(|p| p.dot_diameter_mm);
    let spacing = info.and_then(|p| p.dot_spacing_mm);
    let contrast = info.and_then(|p| p.contrast);
    let softness = info.and_then(|p| p.edge_softness_mm).unwrap_or(0.0);
    if let Some(pattern) = characterised(run) {
        return PatternEstimate::new(
            SpecklePattern { label, ..pattern },
            "manifest",
            white_dn,
            PrintKnowledge::Characterised,
        );
    }
    let profile = stated_profile(run).unwrap_or_default();
    if let (Some(d), Some(s), Some(c)) = (diameter, spacing, contrast) {
        return PatternEstimate::new(
            SpecklePattern {
                label,
                dot_diameter_mm: d,
                dot_spacing_mm: s,
                contrast: c,
                edge_softness_mm: softness,
                placement: Placement::default(),
                profile,
                min_gap_mm: 0.0,
            },
            "manifest",
            white_dn,
            PrintKnowledge::Calibrated,
        );
    }
    let est = estimate_speckle(crop, white_dn, noise_var);
    let fwhm = FWHM_PER_SIGMA;
    // Imaged σ (px) → mm; with a manifest diameter, keep it.
    let sigma_mm = match diameter {
        Some(d) => ((d / fwhm).powi(2) + softness.powi(2)).sqrt(),
        None => est.sigma_px / scale_px_per_mm,
    };
    let sigma_px = sigma_mm * scale_px_per_mm;
    let (c, rho) = match (contrast, spacing) {
        (Some(c), Some(s)) => (c, 1.0 / (s * scale_px_per_mm).powi(2)),
        (None, Some(s)) => {
            let rho = 1.0 / (s * scale_px_per_mm).powi(2);
            (
                (est.deficit / (2.0 * std::f64::consts::PI * sigma_px * sigma_px * rho))
                    .clamp(0.02, 1.0),
                rho,
            )
        }
        (c, None) => {
            let c =
                c.unwrap_or_else(|| (2.0 * est.variance / est.deficit.max(1e-6)).clamp(0.02, 1.0));
            let rho = est.deficit / (2.0 * std::f64::consts::PI * sigma_px * sigma_px * c);
            (c, rho.max(1e-6))
        }
    };
    let spacing_mm = spacing.unwrap_or(1.0 / (rho.sqrt() * scale_px_per_mm));
    let (dot_diameter_mm, edge_softness_mm) = match (diameter, profile) {
        (Some(d), _) => (d, softness),
        (None, DotProfile::Gaussian) => (sigma_mm * fwhm, 0.0),
        // A disk of radius R has the second moment of a Gaussian of σ R/2.
        (None, DotProfile::Disk) => (4.0 * sigma_mm, 0.0),
    };
    let all_missing = diameter.is_none() && spacing.is_none() && contrast.is_none();
    PatternEstimate::new(
        SpecklePattern {
            label,
            dot_diameter_mm,
            dot_spacing_mm: spacing_mm,
            contrast: c,
            edge_softness_mm,
            placement: Placement::default(),
            profile,
            min_gap_mm: 0.0,
        },
        if all_missing {
            "estimated"
        } else {
            "manifest+estimated"
        },
        white_dn,
        PrintKnowledge::Calibrated,
    )
}

/// Moments of a speckle frame relative to its white level.
struct SpeckleMoments {
    /// Imaged dot σ, px.
    sigma_px: f64,
    /// 1 − mean/white.
    deficit: f64,
    /// Noise-free variance / white².
    variance: f64,
}

fn estimate_speckle(img: &Image, white: f64, noise_var: f64) -> SpeckleMoments {
    let (w, h) = (img.width(), img.height());
    let (mean, std) = img.mean_std();
    let var = (std * std - noise_var).max(1e-12);
    // Normalised autocovariance along x and y at lags 1..=8.
    let lag_cov = |k: usize, along_x: bool| -> f64 {
        let mut acc = 0.0;
        let mut n = 0usize;
        for r in 0..h - if along_x { 0 } else { k } {
            for c in 0..w - if along_x { k } else { 0 } {
                let a = img.get(c, r) as f64 - mean;
                let b = if along_x {
                    img.get(c + k, r)
                } else {
                    img.get(c, r + k)
                } as f64
                    - mean;
                acc += a * b;
                n += 1;
            }
        }
        acc / n.max(1) as f64
    };
    // ln ρ(k) = const − k²/(4σ²): least squares over lags with ρ above 10 % of var.
    let mut fits = Vec::new();
    for along_x in [true, false] {
        let (mut sx, mut sy, mut sxx, mut sxy, mut n) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for k in 1..=12usize {
            let c = lag_cov(k, along_x) / var;
            if !(c > 0.1) {
                break;
            }
            let (x, y) = ((k * k) as f64, c.ln());
            sx += x;
            sy += y;
            sxx += x * x;
            sxy += x * y;
            n += 1.0;
        }
        if n >= 2.0 {
            let slope = (n * sxy - sx * sy) / (n * sxx - sx * sx);
            if slope < 0.0 {
                fits.push((-1.0 / (4.0 * slope)).sqrt());
            }
        } else if n == 1.0 {
            // Only lag 1 above threshold: a small dot.
            fits.push((-1.0 / (4.0 * (sy - 0.0))).abs().sqrt().min(1.0));
        }
    }
    let sigma_px = if fits.is_empty() {
        1.0
    } else {
        fits.iter().sum::<f64>() / fits.len() as f64
    };
    SpeckleMoments {
        sigma_px: sigma_px.clamp(0.3, 50.0),
        deficit: (1.0 - mean / white).max(1e-4),
        variance: var / (white * white),
    }
}

/// First guess of the white level: a high percentile of the 3x3-smoothed frame.
pub fn white_level_guess(img: &Image) -> f64 {
    let (w, h) = (img.width(), img.height());
    let mut smooth = Vec::with_capacity(w * h);
    for r in 1..h.saturating_sub(1) {
        for c in 1..w.saturating_sub(1) {
            let mut s = 0.0;
            for dr in 0..3 {
                for dc in 0..3 {
                    s += img.get(c + dc - 1, r + dr - 1) as f64;
                }
            }
            smooth.push(s / 9.0);
        }
    }
    percentile(&mut smooth, 0.995).max(1.0)
}

/// Pooled noise variance of a measured reference (its static repeat when given), over the
/// pixels clipped in neither frame of a `bit_depth`-bit range.
pub fn pooled_noise_variance(reference: &Image, repeat: Option<&Image>, bit_depth: u8) -> f64 {
    let adc = Quantization {
        bits: bit_depth.into(),
    };
    noise_variance(reference, repeat, adc.max_dn())
}

/// The validated pattern index of every run (pattern labels in order of first appearance).
pub fn pattern_indices(manifest: &Manifest) -> (Vec<String>, Vec<usize>) {
    let mut labels: Vec<String> = Vec::new();
    let idx = manifest
        .runs
        .iter()
        .map(|r| {
            let label = r
                .pattern
                .as_ref()
                .map_or_else(|| r.reference.clone(), |p| p.label.clone());
            match labels.iter().position(|l| *l == label) {
                Some(i) => i,
                None => {
                    labels.push(label);
                    labels.len() - 1
                }
            }
        })
        .collect();
    (labels, idx)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::test_fields::{manifest, PrintStated};

    #[test]
    fn patterns_are_numbered_in_order_of_first_appearance() {
        let m = manifest(
            &[(1.0, 0.0); 5],
            &["c", "a", "c", "b"],
            PrintStated::Nothing,
        );
        let (labels, of_run) = pattern_indices(&m);
        assert_eq!(labels, ["c", "a", "b"]);
        assert_eq!(of_run, [0, 1, 0, 2, 0]);
    }

    #[test]
    fn the_white_level_is_the_bright_end_of_the_smoothed_frame() {
        // A dark speckle on a 1000 DN white, with single hot pixels a 3x3 mean dilutes.
        let (w, h) = (64, 64);
        let mut img = Image::filled(w, h, 1000.0);
        for r in (0..h).step_by(4) {
            for c in (0..w).step_by(4) {
                img.set(c, r, 200.0);
            }
        }
        img.set(30, 31, 60_000.0);
        let white = white_level_guess(&img);
        assert!((900.0..=1000.0).contains(&white), "{white}");
        // A black frame still has a white level to divide by.
        assert_eq!(white_level_guess(&Image::filled(8, 8, 0.0)), 1.0);
    }
}
