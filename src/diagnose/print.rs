//! The print the model renders, taken from the measurement unless the dataset characterises it.
//!
//! A nominal print (the dot size and spacing the lab asked the printer for) is never the print
//! the camera sees: toner spreads, dots vary, edges are soft. A model that renders the nominal
//! print reads every difference between it and the real one as lens blur or pixel aperture. So
//! unless a pattern is *characterised* in the manifest, the comparison calibrates it, the same way
//! it matches the white level and the noise:
//!
//! - the dot's contrast, so the model's reference crop has the measured contrast (std/mean; both
//!   sides carry the same noise, so the raw ratio is compared), and
//! - the dot's imaged size, so the *shape* of the model's power spectra along x and y matches the
//!   measured one (χ² of ln(measured/model) per bin about its weighted mean: the level is the
//!   contrast's business), by Brent's method on σ;
//! - for hard disks that never touch, the least gap between them, by the same shape
//!   (`calibrate_scene::fit_gap`): how close the nearest disks come sets DIC's error under
//!   subsampling.
//!
//! Before either, the dots' **placement** ([`crate::model::Placement`]): below the dot-spacing
//! frequency a print's spectrum is its placement statistics — a jittered grid (one dot per cell,
//! ffdic's own targets) suppresses it, independent (Poisson) positions leave it flat — and the
//! placement also sets how sparse and crowded the patches a subset sees are, which is what sets
//! DIC's error under subsampling. The comparison renders the reference crop with both and keeps
//! the one whose spectral shape below half the spacing frequency is the measured one
//! (`placement_chi2` in the JSON), unless
//! the manifest states `"placement": "poisson"` or `"jittered_grid"`. On the independent
//! generator's Poisson prints the grid had made the calibrated σ 21 % too large and the model's
//! error under ff50 a third of the measured.
//!
//! Both go through the model's own optics and sensor, so the print absorbs exactly what the model
//! does not explain of the spectrum — which is why `psf_blur` (and the spectral side of
//! `fill_factor`) cannot be told from the print on such a dataset: `diagnose` reports them as not
//! identifiable, naming what would reveal them, instead of fitting them.
//!
//! A pattern is characterised when its manifest entry states the dots' `profile` and gives their
//! `contrast` and size: for `"gaussian"` as `dot_diameter_mm` (FWHM) or as a measured `mtf` —
//! pairs `[cycles_per_mm, modulation]` of the print alone, fitted to exp(−2π²σ²f²) (a Gaussian
//! dot's transfer function) — with `edge_softness_mm` in quadrature to the diameter's σ (a
//! measured MTF already holds it); for `"disk"` (hard-edged dots) as `dot_diameter_mm`, the
//! edge blurred by `edge_softness_mm`. The model renders it as stated.
//!
//! Otherwise the dots' **profile** is calibrated too: the print is fitted with Gaussian dots and,
//! when their spectral shape is rejected (χ² more than three standard deviations above its
//! degrees of freedom), with disks (diameter, then edge softness) under each placement; the
//! better is kept (`profile_chi2` in the JSON: Gaussian, disk or null when not tried). The
//! profile is what a Gaussian cannot imitate: a hard edge's gradient energy, which sets DIC's
//! random error. On the independent
//! generator's hard-disk print b (0.24 mm at 26 px/mm) the Gaussian fit had collapsed to 0.03 mm
//! dots at full contrast and put the model's random error at 2.6–3.7x the measured.

use super::image_stats::{psd, FrameStats, PsdBin};
use crate::dataset::Run;
use crate::image::Image;
use crate::model::{DotProfile, Placement, SpecklePattern};
use serde::{Deserialize, Serialize};

/// FWHM = 2·sqrt(2 ln 2)·σ.
const FWHM_PER_SIGMA: f64 = 2.354_820_045_030_949;

/// What the comparison knows of a pattern's print.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PrintKnowledge {
    /// Stated by the manifest (profile, size or MTF, contrast): rendered as stated.
    Characterised,
    /// Calibrated to the measured reference frame (module doc).
    #[default]
    Calibrated,
}

/// The calibration of one pattern: the starting print and the one the model renders.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PrintCalibration {
    /// σ of a dot before and after, mm.
    pub start_sigma_mm: f64,
    pub sigma_mm: f64,
    pub start_contrast: f64,
    pub contrast: f64,
    /// The reference crops' contrast (std/mean): measured, and the model's once calibrated.
    pub measured_contrast: f64,
    pub model_contrast: f64,
    /// The profile the model renders, with its diameter (a Gaussian's FWHM, a disk's edge) and
    /// edge softness, mm.
    #[serde(default)]
    pub profile: DotProfile,
    #[serde(default)]
    pub dot_diameter_mm: f64,
    #[serde(default)]
    pub edge_softness_mm: f64,
    /// The least gap between the dots of a hard-core print, mm (0: they may touch).
    #[serde(default)]
    pub min_gap_mm: f64,
}

/// Where a print's spectrum stops being its placement's and becomes its dots' profile, cycles/px:
/// half the dot-spacing frequency. The placement is chosen below it
/// (`compare::choose_placement`), a blur fitted above it (`fit_image`).
pub fn placement_band_edge(pattern: &SpecklePattern, scale_px_per_mm: f64) -> f64 {
    0.5 / (pattern.dot_spacing_mm * scale_px_per_mm)
}

/// The dots' placement the manifest states for `run`'s pattern.
pub fn stated_placement(run: &Run) -> Option<Placement> {
    run.pattern.as_ref()?.placement
}

/// The print of `run`'s pattern as the manifest characterises it — its profile, dot size,
/// softness, contrast and spacing — or None when it is not characterised (module doc). A
/// Gaussian print is rendered with its σ in the diameter (a measured MTF holds the softness
/// too); a disk print keeps its diameter and softness apart.
pub fn characterised(run: &Run) -> Option<SpecklePattern> {
    let p = run.pattern.as_ref()?;
    let contrast = p.contrast?;
    let softness = p.edge_softness_mm.unwrap_or(0.0);
    let (dot_diameter_mm, edge_softness_mm) = match p.profile? {
        DotProfile::Gaussian => {
            let from_mtf = p.mtf.as_deref().and_then(sigma_from_mtf);
            // A measured MTF is the whole print's, its softness included; a nominal diameter is
            // the dot's before the print's own blur.
            let sigma = from_mtf.or(p
                .dot_diameter_mm
                .map(|d| (d / FWHM_PER_SIGMA).hypot(softness)))?;
            (sigma * FWHM_PER_SIGMA, 0.0)
        }
        DotProfile::Disk => (p.dot_diameter_mm?, softness),
    };
    Some(SpecklePattern {
        label: p.label.clone(),
        dot_diameter_mm,
        dot_spacing_mm: p.dot_spacing_mm?,
        contrast,
        edge_softness_mm,
        placement: Placement::default(),
        profile: p.profile?,
        min_gap_mm: 0.0,
    })
}

/// The dots' profile the manifest states for `run`'s pattern.
pub fn stated_profile(run: &Run) -> Option<DotProfile> {
    run.pattern.as_ref()?.profile
}

/// σ (mm) of the Gaussian whose transfer function exp(−2π²σ²f²) fits the MTF pairs
/// (cycles/mm, modulation) best in ln M against f², through the origin; points with M outside
/// (0.02, 0.995) carry no usable information and are skipped.
pub fn sigma_from_mtf(pairs: &[[f64; 2]]) -> Option<f64> {
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for &[f, m] in pairs {
        if f > 0.0 && m > 0.02 && m < 0.995 {
            let x = f * f;
            sxy += x * m.ln();
            sxx += x * x;
        }
    }
    if !(sxx > 0.0) {
        return None;
    }
    let slope = sxy / sxx;
    (slope < 0.0).then(|| (-slope / (2.0 * std::f64::consts::PI.powi(2))).sqrt())
}

/// χ² of the spectral shape: ln(measured/model) per bin about its weighted mean.
pub fn spectral_shape_chi2(measured: &FrameStats, model: &Image) -> f64 {
    spectral_shape_chi2_below(measured, model, f64::INFINITY).0
}

/// How many spectral bins [`spectral_shape_chi2`] can compare for this measured frame.
pub fn spectral_shape_bins(measured: &FrameStats) -> usize {
    let used = |bins: &[PsdBin]| bins.iter().filter(|b| b.value > 0.0 && b.se > 0.0).count();
    used(&measured.psd_x) + used(&measured.psd_y)
}

/// [`spectral_shape_chi2`] over the bins below `f_max` cycles/px, and how many bins it compared.
pub fn spectral_shape_chi2_below(measured: &FrameStats, model: &Image, f_max: f64) -> (f64, usize) {
    let pairs = |m: &[PsdBin], o: Vec<PsdBin>| -> Vec<(f64, f64)> {
        m.iter()
            .zip(o)
            .filter(|(a, b)| a.value > 0.0 && b.value > 0.0 && a.f < f_max)
            .map(|(a, b)| {
                let se = ((a.se / a.value).powi(2) + (b.se / b.value).powi(2)).sqrt();
                ((a.value / b.value).ln(), se)
            })
            .filter(|(r, se)| r.is_finite() && *se > 0.0)
            .collect()
    };
    let mut all = pairs(&measured.psd_x, psd(model, true));
    all.extend(pairs(&measured.psd_y, psd(model, false)));
    let w: f64 = all.iter().map(|(_, se)| 1.0 / (se * se)).sum();
    if !(w > 0.0) {
        return (0.0, 0);
    }
    let mean = all.iter().map(|(r, se)| r / (se * se)).sum::<f64>() / w;
    let chi2 = all.iter().map(|(r, se)| ((r - mean) / se).powi(2)).sum();
    (chi2, all.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_gaussian_mtf_gives_back_its_sigma() {
        let sigma = 0.08;
        let pairs: Vec<[f64; 2]> = (0..15)
            .map(|k| {
                let f = k as f64 * 0.5;
                [f, (-2.0 * (std::f64::consts::PI * sigma * f).powi(2)).exp()]
            })
            .collect();
        let s = sigma_from_mtf(&pairs).unwrap();
        assert!((s / sigma - 1.0).abs() < 1e-9, "{s}");
        assert_eq!(sigma_from_mtf(&[[1.0, 1.0]]), None);
    }
}
