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
use super::DiagnoseError;
use crate::dataset::{Manifest, Run};
use crate::image::Image;
use crate::model::derive_seed;
use crate::model::effects::user::{rendered_fields, UserField};
use crate::model::effects::{Quantization, StageMisalignment};
use crate::model::{
    project_prepared, render_frame, render_frame_read_out, Camera, DotProfile, Effects, FrameSpec,
    Placement, SensorReadout, SpecklePattern, TargetDot, TooManyDots,
};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;
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
    /// placement and of the hard core.
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
        2f64.powi(self.bit_depth as i32) - 1.0
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

/// The model's frames for a dataset: the nominal experiment, the model's effects, the dots of
/// every pattern (fixed seed).
pub struct Scene {
    pub nominal: Nominal,
    pub effects: Effects,
    /// The model's user effects bound once ([`rendered_fields`]): a geometric displacement
    /// projects each point several times.
    user: Vec<(UserField, Vec<f64>)>,
    dots: Vec<Vec<TargetDot>>,
    seed: u64,
}

impl Scene {
    /// Errs when the target the runs need (field of view plus the largest move) would hold more
    /// dots than a layout may: a manifest's moves are input, and size this allocation.
    pub fn new(
        nominal: &Nominal,
        model: &Effects,
        manifest: &Manifest,
        seed: u64,
    ) -> Result<Self, TooManyDots> {
        Self::of_patterns(nominal, model, manifest, seed, &|_| true)
    }

    /// [`Scene::new`] holding the dots of the patterns `wanted` names only: a print's
    /// calibration renders one pattern some fifty times, and laying out the others each time
    /// was a fifth of a comparison.
    pub fn of_patterns(
        nominal: &Nominal,
        model: &Effects,
        manifest: &Manifest,
        seed: u64,
        wanted: &dyn Fn(usize) -> bool,
    ) -> Result<Self, TooManyDots> {
        let travel = manifest
            .runs
            .iter()
            .map(|r| r.stage.dx_mm.abs().max(r.stage.dy_mm.abs()))
            .fold(0.0, f64::max)
            * nominal.travel_scale.abs().max(1.0);
        let camera = nominal.camera(0);
        let dots = nominal
            .patterns
            .iter()
            .enumerate()
            .map(|(i, p)| {
                if !wanted(i) {
                    return Ok(Vec::new());
                }
                p.pattern.dots(
                    camera.field_mm(travel + 2.0),
                    derive_seed(seed, i as u64, 0xD075),
                )
            })
            .collect::<Result<_, _>>()?;
        Ok(Self {
            nominal: nominal.clone(),
            effects: nominal.render_effects(model),
            user: rendered_fields(&model.user),
            dots,
            seed,
        })
    }

    /// A scene for geometry only (no dots: [`Scene::geometric_displacement`], not rendering).
    pub fn geometry_only(nominal: &Nominal, model: &Effects) -> Self {
        Self {
            nominal: nominal.clone(),
            effects: nominal.render_effects(model),
            user: rendered_fields(&model.user),
            dots: Vec::new(),
            seed: 0,
        }
    }

    /// Renders pattern `pattern` at a commanded stage position; `frame` numbers the exposure (its
    /// noise seed); `crop` renders only the centred window of that size.
    pub fn render(
        &self,
        pattern: usize,
        at_mm: (f64, f64),
        moved: bool,
        frame: u64,
        crop: Option<usize>,
    ) -> Image {
        self.render_in(pattern, at_mm, moved, frame, crop, None)
    }

    /// [`Scene::render`] of the whole frame as the camera reads it out in `readout` (its own
    /// binning or decimation; see [`super::floor_read_out`] for where the noise goes).
    pub fn render_read_out(
        &self,
        pattern: usize,
        at_mm: (f64, f64),
        moved: bool,
        frame: u64,
        readout: &SensorReadout,
    ) -> Image {
        self.render_in(pattern, at_mm, moved, frame, None, Some(readout))
    }

    fn render_in(
        &self,
        pattern: usize,
        (dx_mm, dy_mm): (f64, f64),
        moved: bool,
        frame: u64,
        crop: Option<usize>,
        readout: Option<&SensorReadout>,
    ) -> Image {
        let n = &self.nominal;
        let mut camera = n.camera(pattern);
        let mut effects = self.effects.clone();
        if let Some(side) = crop {
            let (_, _, w, h) = centred_crop(n.width, n.height, side);
            let full_r0 = camera.half_diagonal_px();
            camera.width = w;
            camera.height = h;
            let crop_r0 = camera.half_diagonal_px();
            if let Some(d) = effects.lens_distortion.as_mut() {
                if d.norm_radius_px <= 0.0 {
                    d.norm_radius_px = full_r0;
                }
            }
            if let Some(v) = effects.vignetting.as_mut() {
                v.v *= (crop_r0 / full_r0).powi(2);
            }
        }
        let (sx, sy) = n.scaled_move(dx_mm, dy_mm);
        let seed = derive_seed(self.seed, 0xF7A3 + pattern as u64, frame);
        let spec = FrameSpec {
            stage_dx_mm: sx,
            stage_dy_mm: sy,
            moved,
            seed,
        };
        let all = &self.dots[pattern];
        // A crop sees a small part of the target: hand the renderer only the dots near it (in mm,
        // with room for the move, the dots' reach and a generous allowance for distortion).
        let near: Vec<TargetDot>;
        let dots: &[TargetDot] = if crop.is_some() {
            let reach = all.iter().map(|d| d.shape.reach_mm()).fold(0.0, f64::max);
            let (x0, y0, x1, y1) = camera.field_mm(2.0 + reach);
            let (pad_x, pad_y) = (0.05 * (x1 - x0), 0.05 * (y1 - y0));
            let (mx, my) = (sx, sy);
            near = all
                .iter()
                .filter(|d| {
                    let (x, y) = (d.x_mm + mx, d.y_mm + my);
                    x > x0 - pad_x && x < x1 + pad_x && y > y0 - pad_y && y < y1 + pad_y
                })
                .copied()
                .collect();
            &near
        } else {
            all
        };
        let readout = readout.filter(|r| !r.is_full_resolution());
        if effects.sensor_noise.is_some() || n.noise_floor_dn <= 0.0 {
            return match readout {
                Some(r) => render_frame_read_out(&camera, &effects, dots, &spec, r),
                None => render_frame(&camera, &effects, dots, &spec),
            };
        }
        // The dataset's own sensor: signal-independent noise, then the ADC.
        let bits = effects.quantization.take().map_or(16, |q| q.bits);
        let full = 2f64.powi(bits as i32) - 1.0;
        camera.exposure_level *= n.full_scale_dn() / 65535.0;
        let mut img = render_frame(&camera, &effects, dots, &spec);
        let sigma = n.noise_floor_dn;
        if let Some(r) = readout {
            return super::floor_read_out::read_out_with_floor(&img, r, sigma, full, seed);
        }
        let w = img.width();
        img.data_mut()
            .par_chunks_mut(w)
            .enumerate()
            .for_each(|(row, line)| {
                let mut rng = ChaCha8Rng::seed_from_u64(
                    seed ^ (row as u64 + 1).wrapping_mul(0xA24B_AED4_963E_E407),
                );
                let normal = Normal::new(0.0, sigma).expect("finite sigma");
                for v in line.iter_mut() {
                    let x = *v as f64 + normal.sample(&mut rng);
                    *v = x.round().clamp(0.0, full) as f32;
                }
            });
        img
    }

    /// The model's geometric displacement (full-resolution px) at a reference-image position for
    /// a commanded move: the target point seen at `p` in the reference, projected in the moved
    /// frame. Exact for every geometric effect of the model (no rendering, no DIC).
    pub fn geometric_displacement(&self, (dx_mm, dy_mm): (f64, f64), p: (f64, f64)) -> (f64, f64) {
        let camera = self.nominal.camera(0);
        let (sx, sy) = self.nominal.scaled_move(dx_mm, dy_mm);
        let reference = FrameSpec {
            stage_dx_mm: 0.0,
            stage_dy_mm: 0.0,
            moved: false,
            seed: 0,
        };
        let moved = FrameSpec {
            stage_dx_mm: sx,
            stage_dy_mm: sy,
            moved: true,
            seed: 0,
        };
        let (cx, cy) = camera.centre();
        let s = camera.scale_px_per_mm;
        // Invert the reference projection by fixed-point iteration (distortion is small).
        let (mut x, mut y) = ((p.0 - cx) / s, (p.1 - cy) / s);
        for _ in 0..6 {
            let (qx, qy, _) =
                project_prepared(&camera, &self.effects, &self.user, &reference, x, y);
            x += (p.0 - qx) / s;
            y += (p.1 - qy) / s;
        }
        let (qx, qy, _) = project_prepared(&camera, &self.effects, &self.user, &moved, x, y);
        (qx - p.0, qy - p.1)
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

/// Pooled noise variance of a measured reference (its static repeat when given).
pub fn pooled_noise_variance(reference: &Image, repeat: Option<&Image>) -> f64 {
    noise_variance(reference, repeat)
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

/// Checks that a frame pair can be compared.
pub fn check_sizes(run: &Run, a: &Image, b: &Image) -> Result<(), DiagnoseError> {
    if (a.width(), a.height()) != (b.width(), b.height()) {
        return Err(DiagnoseError::Frames {
            run: run.id.clone(),
            message: format!(
                "reference is {}x{}, deformed {}x{}",
                a.width(),
                a.height(),
                b.width(),
                b.height()
            ),
        });
    }
    if a.width() < crate::dic::MIN_FRAME_SIDE_PX || a.height() < crate::dic::MIN_FRAME_SIDE_PX {
        return Err(DiagnoseError::Frames {
            run: run.id.clone(),
            message: format!(
                "frames of {}x{} px are too small to compare",
                a.width(),
                a.height()
            ),
        });
    }
    Ok(())
}
