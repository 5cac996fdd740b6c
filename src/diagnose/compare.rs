//! `compare`: DIC on the measured frames and the same DIC on the frames the model renders for the
//! same nominal experiment, per run and scheme, with image statistics beside it.
//!
//! [`load_measurement`] reads a dataset and analyses the measured side once; [`compare_prepared`]
//! renders and analyses the model's side against it (diagnose calls it once per candidate).

use super::bic::chi2;
use super::capture_mode::{
    compare_hardware, measure_hardware, model_hardware, HardwareMeasurement, HardwareModelSide,
};
use super::discrepancy::{run_discrepancy, RunDiscrepancy};
use super::image_stats::{centre_crop, frame_stats, FrameStats, STATS_CROP_PX};
use super::nominal::{
    check_sizes, pattern_for, pattern_indices, pooled_noise_variance, white_level_guess, Nominal,
    Scene,
};
use super::optimise::golden;
use super::print::{
    placement_band_edge, spectral_shape_bins, spectral_shape_chi2, spectral_shape_chi2_below,
    PrintCalibration, PrintKnowledge,
};
use super::residuals::residual_map;
use super::results::{
    Accuracy, Chi2, Comparison, DiscrepancyParts, ImageComparison, ModelInfo, RunComparison, Side,
};
use super::stage::{fit_stage, StageObservation};
use super::{CompareOptions, DiagnoseError, Progress};
use crate::dataset::check_stated_move;
use crate::dataset::{Manifest, Run};
use crate::dic::{DicError, DicResult, PreparedReference, Watch};
use crate::image::{read_image, Image};
use crate::model::{DotProfile, ModelConfig, Placement, SpecklePattern};
use crate::pairs::{correlate_pairs, PairVisitor, RunPair};
use crate::reduce::{reduce, Scheme};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// The measured side of a dataset, analysed once.
pub struct Measurement {
    pub dir: PathBuf,
    pub manifest: Manifest,
    pub options: CompareOptions,
    /// Distinct pattern labels and each run's index into them.
    pub labels: Vec<String>,
    pub pattern_of_run: Vec<usize>,
    pub width: usize,
    pub height: usize,
    pub bit_depth: u8,
    /// Centred crops (≤ 512 px) of each pattern's reference and static repeat, of each moved frame.
    pub reference_crops: Vec<Image>,
    pub repeat_crops: Vec<Option<Image>>,
    pub moved_crops: Vec<Image>,
    pub reference_stats: Vec<FrameStats>,
    pub moved_stats: Vec<FrameStats>,
    /// DIC of every run (outer) and scheme (inner).
    pub dic: Vec<Vec<DicResult>>,
    /// Speckle, white levels and noise floor; the stage is fitted per comparison.
    pub nominal: Nominal,
    /// Runs of the dataset read out in a hardware scheme ([`super::capture_mode`]).
    pub hardware: Vec<HardwareMeasurement>,
    /// Such runs without a full-resolution twin in the dataset: not compared.
    pub hardware_runs_set_aside: usize,
}

/// A short, stable hash of the model's content (FNV-1a 64 of its canonical TOML).
pub fn model_version(model: &ModelConfig) -> String {
    super::history::short_hash(&model.effects_toml())
}

trait EffectsToml {
    fn effects_toml(&self) -> String;
}

impl EffectsToml for ModelConfig {
    /// Only the effects: renaming a model does not make it another version.
    fn effects_toml(&self) -> String {
        toml::to_string(&self.effects).unwrap_or_default()
    }
}

fn dic_error(run: &str, scheme: &Scheme, source: crate::dic::DicError) -> DiagnoseError {
    DiagnoseError::Dic {
        run: run.to_string(),
        scheme: scheme.name.clone(),
        source,
    }
}

/// Reads a dataset and analyses the measured frames. `progress` counts run × scheme analyses.
pub fn load_measurement(
    dir: &Path,
    options: &CompareOptions,
    progress: Progress,
) -> Result<Measurement, DiagnoseError> {
    // Frames the sensor binned or decimated itself are compared beside the fit, in their mode
    // (`capture_mode`); the fit holds the full-resolution runs.
    let (manifest, hardware_runs) = Manifest::read(dir)?.full_resolution();
    if manifest.runs.is_empty() {
        return Err(DiagnoseError::Frames {
            run: "-".into(),
            message: format!(
                "all {} runs were read out in a hardware scheme; the model is fitted to \
                 full-resolution runs (each hardware run is compared beside its twin)",
                hardware_runs.len()
            ),
        });
    }
    options.dic.validate().map_err(|e| DiagnoseError::Dic {
        run: "-".into(),
        scheme: "-".into(),
        source: e,
    })?;
    let (labels, pattern_of_run) = pattern_indices(&manifest);
    let mut measured = MeasuredPairs {
        dir,
        scale_px_per_mm: manifest.scale_px_per_mm,
        pattern_of_run: &pattern_of_run,
        total: manifest.runs.len() * options.schemes.len(),
        done: 0,
        progress,
        dic: Vec::with_capacity(manifest.runs.len()),
        moved_crops: Vec::new(),
        moved_stats: Vec::new(),
        references: ReferenceStats::new(labels.len()),
        size: None,
        bit_depth: 16,
    };
    correlate_pairs(
        dir,
        &manifest.runs,
        &options.schemes,
        &options.dic,
        &mut measured,
    )?;
    let MeasuredPairs {
        dic,
        moved_crops,
        moved_stats,
        references,
        size,
        bit_depth,
        ..
    } = measured;
    let (width, height) = size.expect("a manifest has runs");
    let nominal = references.nominal(&manifest, &pattern_of_run, (width, height), bit_depth);
    let (hardware, hardware_runs_set_aside) =
        measure_hardware(dir, hardware_runs, &manifest, options)?;
    Ok(Measurement {
        dir: dir.to_owned(),
        manifest,
        options: options.clone(),
        labels,
        pattern_of_run,
        width,
        height,
        bit_depth,
        reference_crops: references
            .crops
            .into_iter()
            .map(|c| c.expect("every pattern has a run"))
            .collect(),
        repeat_crops: references.repeats,
        moved_crops,
        reference_stats: references
            .stats
            .into_iter()
            .map(|s| s.expect("filled"))
            .collect(),
        moved_stats,
        dic,
        nominal,
        hardware,
        hardware_runs_set_aside,
    })
}

/// The measured side of the pair loop: each run's checks, image statistics and analyses.
struct MeasuredPairs<'a> {
    dir: &'a Path,
    scale_px_per_mm: f64,
    pattern_of_run: &'a [usize],
    total: usize,
    done: usize,
    progress: Progress<'a>,
    dic: Vec<Vec<DicResult>>,
    moved_crops: Vec<Image>,
    moved_stats: Vec<FrameStats>,
    references: ReferenceStats,
    size: Option<(usize, usize)>,
    bit_depth: u8,
}

impl PairVisitor for MeasuredPairs<'_> {
    type Error = DiagnoseError;

    fn frames(&mut self, pair: &RunPair<'_>) -> Result<(), DiagnoseError> {
        let (run, reference, deformed) = (pair.run, pair.reference, pair.deformed);
        check_sizes(run, reference, deformed)?;
        // A move stated an order of magnitude off would send the fit chasing a travel scale of
        // hundreds: say so with the measured figure instead.
        check_stated_move(
            reference,
            deformed,
            (run.stage.dx_mm, run.stage.dy_mm),
            self.scale_px_per_mm,
        )
        .map_err(|e| DiagnoseError::Frames {
            run: run.id.clone(),
            message: e.to_string(),
        })?;
        same_size_as_first(run, reference, &mut self.size)?;
        self.bit_depth = pair.bit_depth;
        self.references
            .observe(self.pattern_of_run[pair.index], self.dir, run, reference)?;
        let crop = centre_crop(deformed, STATS_CROP_PX);
        self.moved_stats
            .push(frame_stats(Some(deformed), &crop, None));
        self.moved_crops.push(crop);
        self.dic.push(Vec::new());
        Ok(())
    }

    /// Asked before every point: the counts so far again (see [`Progress`]).
    fn cancelled(&self) -> bool {
        !(self.progress)(self.done, self.total)
    }

    fn result(
        &mut self,
        _pair: &RunPair<'_>,
        _scheme: &Scheme,
        result: DicResult,
    ) -> Result<(), DiagnoseError> {
        self.dic.last_mut().expect("frames came first").push(result);
        self.done += 1;
        if (self.progress)(self.done, self.total) {
            Ok(())
        } else {
            Err(DiagnoseError::Cancelled)
        }
    }
}

/// Every run's frames have the size of the dataset's first run.
fn same_size_as_first(
    run: &Run,
    reference: &Image,
    first: &mut Option<(usize, usize)>,
) -> Result<(), DiagnoseError> {
    let here = (reference.width(), reference.height());
    match *first {
        None => *first = Some(here),
        Some(s) if s != here => {
            return Err(DiagnoseError::Frames {
                run: run.id.clone(),
                message: format!(
                    "frames are {}x{}, the dataset's first run has {}x{}",
                    here.0, here.1, s.0, s.1
                ),
            })
        }
        Some(_) => {}
    }
    Ok(())
}

/// Per pattern, from the reference (and its first repeat) of the pattern's first run: the centre
/// crops, their statistics, and the white level and noise variance guessed from them.
struct ReferenceStats {
    crops: Vec<Option<Image>>,
    repeats: Vec<Option<Image>>,
    stats: Vec<Option<FrameStats>>,
    /// (white level guess [DN], pooled noise variance [DN²])
    levels: Vec<(f64, f64)>,
}

impl ReferenceStats {
    fn new(patterns: usize) -> ReferenceStats {
        ReferenceStats {
            crops: vec![None; patterns],
            repeats: vec![None; patterns],
            stats: vec![None; patterns],
            levels: vec![(0.0, 0.0); patterns],
        }
    }

    /// Takes pattern `pi`'s figures from `run` unless an earlier run gave them.
    fn observe(
        &mut self,
        pi: usize,
        dir: &Path,
        run: &Run,
        reference: &Image,
    ) -> Result<(), DiagnoseError> {
        if self.stats[pi].is_some() {
            return Ok(());
        }
        let crop = centre_crop(reference, STATS_CROP_PX);
        let repeat = match run.repeat.first() {
            Some(name) => {
                let (r, _) = read_image(&dir.join(name))?;
                check_sizes(run, reference, &r)?;
                Some(centre_crop(&r, STATS_CROP_PX))
            }
            None => None,
        };
        self.stats[pi] = Some(frame_stats(Some(reference), &crop, repeat.as_ref()));
        self.levels[pi] = (
            white_level_guess(&crop),
            pooled_noise_variance(&crop, repeat.as_ref()),
        );
        self.crops[pi] = Some(crop);
        self.repeats[pi] = repeat;
        Ok(())
    }

    /// The measurement's nominal experiment: the frames as read, a noise floor from the pooled
    /// variance, each pattern's print from its crop, the stage as commanded.
    fn nominal(
        &self,
        manifest: &Manifest,
        pattern_of_run: &[usize],
        (width, height): (usize, usize),
        bit_depth: u8,
    ) -> Nominal {
        let noise_var = self.levels.iter().map(|r| r.1).sum::<f64>() / self.levels.len() as f64;
        let patterns = (0..self.crops.len())
            .map(|pi| {
                let run =
                    &manifest.runs[pattern_of_run.iter().position(|&p| p == pi).expect("used")];
                pattern_for(
                    run,
                    self.crops[pi].as_ref().expect("every pattern has a run"),
                    self.levels[pi].0,
                    self.levels[pi].1,
                    manifest.scale_px_per_mm,
                )
            })
            .collect();
        Nominal {
            width,
            height,
            bit_depth,
            scale_px_per_mm: manifest.scale_px_per_mm,
            noise_floor_dn: noise_var.max(0.0).sqrt(),
            misalignment_rad: 0.0,
            travel_scale: 1.0,
            stage: Default::default(),
            patterns,
        }
    }
}

/// The nominal experiment of `model` for this measurement: the stage fitted, the white levels
/// matched (one centred crop render per pattern), the model's speckle and noise drawn from
/// `seed`; `scene_from` hands over
/// the white levels and prints of another comparison of the same image chain (they depend on
/// the optics and the sensor, not on the geometry or the seed's realisation).
fn calibrate_seeded(
    meas: &Measurement,
    model: &ModelConfig,
    seed: u64,
    scene_from: SceneFrom<'_>,
    go_on: &dyn Fn() -> bool,
) -> Result<Nominal, DiagnoseError> {
    let mut nominal = meas.nominal.clone();
    let obs: Vec<StageObservation> = meas
        .manifest
        .runs
        .iter()
        .enumerate()
        .flat_map(|(ri, run)| {
            meas.options
                .schemes
                .iter()
                .zip(&meas.dic[ri])
                .map(move |(s, r)| StageObservation {
                    run: ri,
                    commanded: (run.stage.dx_mm, run.stage.dy_mm),
                    scheme: s,
                    result: r,
                })
        })
        .collect();
    fit_stage(
        &mut nominal,
        &model.effects,
        &obs,
        meas.manifest.runs.len(),
        meas.manifest.stage_repeatability_um,
        super::bic::inflation(&meas.options.dic),
    );
    // Each step renders crops (the print's calibration some thirty): asked before each.
    let check = || go_on().then_some(()).ok_or(DiagnoseError::Cancelled);
    for pi in 0..nominal.patterns.len() {
        let stated = nominal.patterns[pi].pattern.clone();
        // Whether an earlier calibration decided the placement and the dots' profile.
        let decided = match scene_from {
            SceneFrom::Reuse(other) => {
                nominal.patterns[pi].clone_from(&other.patterns[pi]);
                continue;
            }
            SceneFrom::Refit(other) => {
                let decided = &other.patterns[pi];
                let p = &mut nominal.patterns[pi];
                p.pattern.placement = decided.pattern.placement;
                p.pattern.profile = decided.pattern.profile;
                p.placement_chi2 = decided.placement_chi2;
                p.profile_chi2 = decided.profile_chi2;
                true
            }
            SceneFrom::Calibrate => false,
        };
        check()?;
        match_white(meas, &mut nominal, model, pi, seed)?;
        if !decided && !nominal.patterns[pi].placement_stated {
            check()?;
            choose_placement(meas, &mut nominal, model, pi, seed)?;
        }
        let profile = if nominal.patterns[pi].profile_stated {
            ProfileKnown::Stated
        } else if decided {
            ProfileKnown::Decided
        } else {
            ProfileKnown::No
        };
        if nominal.patterns[pi].print == PrintKnowledge::Calibrated {
            check()?;
            calibrate_print(meas, &mut nominal, model, pi, seed, profile, go_on)?;
            record_calibration(meas, &mut nominal, model, pi, seed, &stated)?;
            check()?;
            match_white(meas, &mut nominal, model, pi, seed)?;
        }
    }
    Ok(nominal)
}

/// Where a comparison's white levels and prints come from.
#[derive(Clone, Copy)]
pub enum SceneFrom<'a> {
    /// Calibrated against the measured references from what the manifest states: the placement
    /// chosen, the dots' profile decided, the print fitted.
    Calibrate,
    /// Calibrated again as [`SceneFrom::Calibrate`] does, from the same statement, but with the
    /// placement and the dots' profile a calibrated scene decided: a model whose image chain
    /// differs (a blur, an aperture, a noise) sees the same kind of print, with other dot sizes
    /// and contrast. The fit repeats the steps that decided the print (not more: a print fitted
    /// further than the scene it is judged against would credit the candidate with the better
    /// fit — on the DIC Challenge's Sample 3 two more rounds from the calibrated print alone
    /// took 90 % of the discrepancy). Cuts a disk print's calibration from some 180 renderings
    /// of its crop to some 90.
    Refit(&'a Nominal),
    /// Taken as they are: a model with the same image chain.
    Reuse(&'a Nominal),
}

/// The model's centred reference crop of pattern `pi`.
fn reference_crop(
    meas: &Measurement,
    nominal: &Nominal,
    model: &ModelConfig,
    pi: usize,
    seed: u64,
) -> Result<Image, DiagnoseError> {
    let scene = Scene::of_patterns(nominal, &model.effects, &meas.manifest, seed, &|i| i == pi)?;
    Ok(scene.render(pi, (0.0, 0.0), false, 0, Some(STATS_CROP_PX)))
}

/// Scales pattern `pi`'s white level so the model's reference crop has the measured mean.
fn match_white(
    meas: &Measurement,
    nominal: &mut Nominal,
    model: &ModelConfig,
    pi: usize,
    seed: u64,
) -> Result<(), DiagnoseError> {
    let (m_model, _) = reference_crop(meas, nominal, model, pi, seed)?.mean_std();
    let (m_meas, _) = meas.reference_crops[pi].mean_std();
    if m_model > 0.0 && m_meas > 0.0 {
        nominal.patterns[pi].white_level_dn *= m_meas / m_model;
    }
    Ok(())
}

/// Chooses pattern `pi`'s dot placement ([`crate::model::Placement`]) whose spectrum below half
/// the dot-spacing frequency has the measured shape: there the spectrum is the placement's (a
/// grid suppresses it towards zero frequency, independent positions leave it flat) and the dot
/// profile changes it little — over the whole band below the spacing frequency an unmodelled
/// blur of 1 px made a grid print read as Poisson. On the independent generator's Poisson prints
/// the jittered grid left the model's random error under subsampling at a third of the measured
/// one (ff50 0.00091 against 0.00283 px). Dots that never touch (the hard core) keep the
/// spectrum suppressed like a grid but without its order.
fn choose_placement(
    meas: &Measurement,
    nominal: &mut Nominal,
    model: &ModelConfig,
    pi: usize,
    seed: u64,
) -> Result<(), DiagnoseError> {
    let f_max = placement_band_edge(&nominal.patterns[pi].pattern, nominal.scale_px_per_mm);
    let mut chi2 = [0.0; 3];
    for (k, placement) in PLACEMENTS.into_iter().enumerate() {
        let mut n = nominal.clone();
        n.patterns[pi].pattern.placement = placement;
        let crop = reference_crop(meas, &n, model, pi, seed)?;
        chi2[k] = spectral_shape_chi2_below(&meas.reference_stats[pi], &crop, f_max);
    }
    let best = (0..3).fold(0, |b, k| if chi2[k] < chi2[b] { k } else { b });
    let p = &mut nominal.patterns[pi];
    p.pattern.placement = PLACEMENTS[best];
    p.placement_chi2 = Some(chi2);
    Ok(())
}

/// The placements [`choose_placement`] tries, in the order of `placement_chi2`.
const PLACEMENTS: [Placement; 3] = [
    Placement::JitteredGrid,
    Placement::Poisson,
    Placement::HardCore,
];

/// What [`calibrate_print`] knows of a print's dots.
#[derive(Clone, Copy)]
enum ProfileKnown {
    /// Nothing: Gaussian dots are fitted and, where rejected, disks under each placement.
    No,
    /// The manifest states the profile.
    Stated,
    /// An earlier calibration decided it ([`SceneFrom::Refit`]).
    Decided,
}

/// Calibrates pattern `pi`'s print to the measured reference (see [`super::print`]): with the
/// dots' profile when it is known, else with Gaussian dots and, where their spectral shape is
/// rejected, disks.
fn calibrate_print(
    meas: &Measurement,
    nominal: &mut Nominal,
    model: &ModelConfig,
    pi: usize,
    seed: u64,
    profile: ProfileKnown,
    go_on: &dyn Fn() -> bool,
) -> Result<(), DiagnoseError> {
    match (profile, nominal.patterns[pi].pattern.profile) {
        (ProfileKnown::Stated, _) | (ProfileKnown::Decided, DotProfile::Gaussian) => {
            fit_print(meas, nominal, model, pi, seed, 2, go_on)?;
            return Ok(());
        }
        (ProfileKnown::Decided, DotProfile::Disk) => {
            // The steps that decided it: a screening round, two more.
            fit_print(meas, nominal, model, pi, seed, 1, go_on)?;
            fit_print(meas, nominal, model, pi, seed, 2, go_on)?;
            return Ok(());
        }
        (ProfileKnown::No, _) => {}
    }
    // Gaussian dots first; disks only when the Gaussian's spectral shape is rejected (χ²
    // beyond its degrees of freedom by three standard deviations): the simpler print is
    // kept when it fits, and a disk's fit costs twice a Gaussian's.
    nominal.patterns[pi].pattern.profile = DotProfile::Gaussian;
    let mut gaussian = nominal.clone();
    let chi2_gaussian = fit_print(meas, &mut gaussian, model, pi, seed, 2, go_on)?;
    let dof = spectral_shape_bins(&meas.reference_stats[pi]).saturating_sub(2) as f64;
    let mut chi2 = [Some(chi2_gaussian), None];
    let mut best = gaussian.patterns[pi].pattern.clone();
    if chi2_gaussian > dof + 3.0 * (2.0 * dof).sqrt() {
        // The placement was chosen under Gaussian dots, whose spectrum is not the measured
        // one; below half the spacing frequency a grid and a hard core differ little. Each
        // placement is fitted with disks instead, and the whole band decides (on paper print
        // b, hard disks placed without touching: χ² 37 with the hard core, 404 on the grid).
        let placements = if nominal.patterns[pi].placement_stated {
            vec![nominal.patterns[pi].pattern.placement]
        } else {
            PLACEMENTS.to_vec()
        };
        // One round under each placement, two more for the best.
        let mut screened: Option<(f64, Nominal)> = None;
        for placement in placements {
            let mut disk = nominal.clone();
            disk.patterns[pi].pattern.profile = DotProfile::Disk;
            disk.patterns[pi].pattern.placement = placement;
            let chi2_disk = fit_print(meas, &mut disk, model, pi, seed, 1, go_on)?;
            if screened.as_ref().is_none_or(|(c, _)| chi2_disk < *c) {
                screened = Some((chi2_disk, disk));
            }
        }
        if let Some((_, mut disk)) = screened {
            let chi2_disk = fit_print(meas, &mut disk, model, pi, seed, 2, go_on)?;
            chi2[1] = Some(chi2_disk);
            if chi2_disk < chi2_gaussian {
                best = disk.patterns[pi].pattern.clone();
            }
        }
    }
    nominal.patterns[pi].pattern = best;
    nominal.patterns[pi].profile_chi2 = Some(chi2);
    Ok(())
}

/// Records pattern `pi`'s calibration from the `stated` print to the fitted one.
fn record_calibration(
    meas: &Measurement,
    nominal: &mut Nominal,
    model: &ModelConfig,
    pi: usize,
    seed: u64,
    stated: &SpecklePattern,
) -> Result<(), DiagnoseError> {
    let crop = reference_crop(meas, nominal, model, pi, seed)?;
    let p = &nominal.patterns[pi].pattern;
    nominal.patterns[pi].calibration = Some(PrintCalibration {
        start_sigma_mm: stated.sigma_mm(),
        sigma_mm: p.sigma_mm(),
        start_contrast: stated.contrast,
        contrast: p.contrast,
        measured_contrast: meas.reference_stats[pi].contrast,
        model_contrast: contrast_of(&crop),
        profile: p.profile,
        dot_diameter_mm: p.dot_diameter_mm,
        edge_softness_mm: p.edge_softness_mm,
    });
    Ok(())
}

/// A crop's contrast: std/mean.
fn contrast_of(img: &Image) -> f64 {
    let (m, s) = img.mean_std();
    s / m.max(1e-12)
}

/// Fits pattern `pi`'s print with its profile: `rounds` rounds of contrast, then size — a
/// Gaussian's σ, or a disk's diameter and then its edge softness — by golden section on the
/// spectral shape's χ², which it returns for the fitted print.
#[allow(clippy::too_many_arguments)]
fn fit_print(
    meas: &Measurement,
    nominal: &mut Nominal,
    model: &ModelConfig,
    pi: usize,
    seed: u64,
    rounds: usize,
    go_on: &dyn Fn() -> bool,
) -> Result<f64, DiagnoseError> {
    let measured = &meas.reference_stats[pi];
    let chi2_of = |n: &Nominal| -> f64 {
        if !go_on() {
            return f64::INFINITY;
        }
        match reference_crop(meas, n, model, pi, seed) {
            Ok(img) => spectral_shape_chi2(measured, &img),
            Err(_) => f64::INFINITY,
        }
    };
    // One size of the print along the search's coordinate, from `current`: golden section
    // assumes one minimum, and the χ² of a softness need not have one (on a hard print the
    // second round's search ran to its bound at 3,500 times the χ² it started from), so the
    // search's end is kept only where it is better than where it started.
    let search = |nominal: &mut Nominal,
                  set: &dyn Fn(&mut SpecklePattern, f64),
                  (lo, hi): (f64, f64),
                  current: f64,
                  iters: usize| {
        let trial = |x: f64| {
            let mut n = nominal.clone();
            set(&mut n.patterns[pi].pattern, x);
            chi2_of(&n)
        };
        let (best, chi2_best) = golden(&trial, lo, hi, iters);
        if chi2_best <= trial(current) {
            set(&mut nominal.patterns[pi].pattern, best);
        } else {
            set(&mut nominal.patterns[pi].pattern, current);
        }
    };
    for _ in 0..rounds {
        match_contrast(meas, nominal, model, pi, seed)?;
        let p = nominal.patterns[pi].pattern.clone();
        // Keep the print physical: the dots' mean darkening — 2πσ²ρc for Gaussian dots
        // (Campbell's theorem), the covered fraction πR²ρ times c for disks — below 60 %, beyond
        // which dots pile up into black.
        let rho_per_mm2 = 1.0 / p.dot_spacing_mm.powi(2);
        match p.profile {
            DotProfile::Gaussian => {
                let sigma0 = p.sigma_mm();
                let sigma_max =
                    (0.6 / (2.0 * std::f64::consts::PI * rho_per_mm2 * p.contrast)).sqrt();
                let hi = (sigma_max / sigma0).clamp(0.3, 4.0).ln();
                let set =
                    |q: &mut SpecklePattern, ln_factor: f64| set_sigma(q, sigma0 * ln_factor.exp());
                search(nominal, &set, ((0.25f64).ln(), hi), 0.0, 12);
            }
            DotProfile::Disk => {
                let d0 = p.dot_diameter_mm;
                let d_max = 2.0 * (0.6 / (std::f64::consts::PI * rho_per_mm2 * p.contrast)).sqrt();
                let hi = (d_max / d0).clamp(0.3, 4.0).ln();
                let set = |q: &mut SpecklePattern, ln_factor: f64| {
                    q.dot_diameter_mm = d0 * ln_factor.exp();
                };
                search(nominal, &set, ((0.25f64).ln(), hi), 0.0, 12);
                let q = &nominal.patterns[pi].pattern;
                let (d, fraction) = (q.dot_diameter_mm, q.edge_softness_mm / q.dot_diameter_mm);
                let set = |q: &mut SpecklePattern, fraction: f64| {
                    q.edge_softness_mm = d * fraction;
                };
                search(nominal, &set, (0.0, 0.5), fraction, 10);
            }
        }
        if !go_on() {
            return Err(DiagnoseError::Cancelled);
        }
    }
    // The size's last search moves the contrast of the crop: matched once more.
    match_contrast(meas, nominal, model, pi, seed)?;
    Ok(chi2_of(nominal))
}

/// Scales pattern `pi`'s dot depth so the model's reference crop has the measured contrast
/// (std/mean; both sides carry the same noise, so the raw ratio is compared), within [0.02, 1].
fn match_contrast(
    meas: &Measurement,
    nominal: &mut Nominal,
    model: &ModelConfig,
    pi: usize,
    seed: u64,
) -> Result<(), DiagnoseError> {
    let crop = reference_crop(meas, nominal, model, pi, seed)?;
    let ratio = meas.reference_stats[pi].contrast / contrast_of(&crop).max(1e-9);
    if ratio.is_finite() {
        let p = &mut nominal.patterns[pi].pattern;
        p.contrast = (p.contrast * ratio).clamp(0.02, 1.0);
    }
    Ok(())
}

/// A Gaussian dot of σ `sigma_mm` (the FWHM carries all of it; no separate softness).
fn set_sigma(p: &mut SpecklePattern, sigma_mm: f64) {
    p.dot_diameter_mm = sigma_mm * 2.354_820_045_030_949;
    p.edge_softness_mm = 0.0;
}

/// The landing offsets against the model's own DIC rather than its geometry: the first fit
/// compares the measured mean displacement with the ideal geometric one, so the model's own
/// sub-pixel bias would stay in every run as a rigid residual. The remaining mean difference of
/// each run (over its schemes and valid points, full-resolution px) is added to the run's
/// offset, within the stage's envelope, and to the model's displacements — a shift of a few
/// thousandths of a pixel moves a DIC result by the same amount (its bias changes at second
/// order), so no second rendering is needed.
fn refine_landings(meas: &Measurement, nominal: &mut Nominal, model_dic: &mut [Vec<DicResult>]) {
    let envelope = nominal.stage.envelope_px(nominal.scale_px_per_mm);
    for (ri, model_results) in model_dic.iter_mut().enumerate() {
        let (mut sum, mut k) = ([0.0, 0.0], 0.0);
        for (si, scheme) in meas.options.schemes.iter().enumerate() {
            let (m, o) = (&meas.dic[ri][si], &model_results[si]);
            let (mut du, mut dv, mut n) = (0.0, 0.0, 0.0);
            for (a, b) in m.points.iter().zip(&o.points) {
                if a.status.is_valid() && b.status.is_valid() {
                    du += a.u - b.u;
                    dv += a.v - b.v;
                    n += 1.0;
                }
            }
            if n > 0.0 {
                sum[0] += du / n * scheme.x.block as f64;
                sum[1] += dv / n * scheme.y.block as f64;
                k += 1.0;
            }
        }
        if k == 0.0 {
            continue;
        }
        let old = nominal.stage.applied_offset_px(ri);
        let mut shift = [0.0; 2];
        for c in 0..2 {
            let applied = (old[c] + sum[c] / k).clamp(-envelope, envelope);
            shift[c] = applied - old[c];
        }
        // What the data say: the offset the model was rendered at plus what its own analysis
        // still leaves over.
        if let Some(l) = nominal.stage.landing_px.get_mut(ri) {
            *l = [old[0] + sum[0] / k, old[1] + sum[1] / k];
        }
        if let Some(o) = nominal.stage.offsets_px.get_mut(ri) {
            *o = [old[0] + shift[0], old[1] + shift[1]];
        }
        for (si, scheme) in meas.options.schemes.iter().enumerate() {
            let (bx, by) = (scheme.x.block as f64, scheme.y.block as f64);
            for p in model_results[si].points.iter_mut() {
                p.u += shift[0] / bx;
                p.v += shift[1] / by;
            }
        }
    }
}

/// Renders and analyses the model's side and compares. `progress` counts run × scheme analyses.
pub fn compare_prepared(
    meas: &Measurement,
    model: &ModelConfig,
    progress: Progress,
) -> Result<Comparison, DiagnoseError> {
    compare_with_scene(
        meas,
        model,
        meas.options.seed,
        SceneFrom::Calibrate,
        progress,
    )
}

/// [`compare_prepared`] with the model's speckle and noise drawn from `seed` (`diagnose` renders
/// with the next seeds for the realisation scatter), and its white levels and prints from
/// `scene_from`.
pub fn compare_with_scene(
    meas: &Measurement,
    model: &ModelConfig,
    seed: u64,
    scene_from: SceneFrom<'_>,
    progress: Progress,
) -> Result<Comparison, DiagnoseError> {
    let opts = &meas.options;
    let runs = &meas.manifest.runs;
    let total = runs.len() * opts.schemes.len();
    let done = AtomicUsize::new(0);
    let go_on = || progress(done.load(Ordering::Relaxed), total);
    let nominal = calibrate_seeded(meas, model, seed, scene_from, &go_on)?;
    let scene = Scene::new(&nominal, &model.effects, &meas.manifest, seed)?;
    let cancelled = || !go_on();
    let mut model_dic: Vec<Option<Vec<DicResult>>> = vec![None; runs.len()];
    let mut images = Vec::new();
    let mut moved_images: Vec<Option<ImageComparison>> = vec![None; runs.len()];
    for pi in 0..meas.labels.len() {
        if !go_on() {
            return Err(DiagnoseError::Cancelled);
        }
        let reference = scene.render(pi, (0.0, 0.0), false, 0, None);
        let crop = centre_crop(&reference, STATS_CROP_PX);
        let repeat = meas.repeat_crops[pi]
            .as_ref()
            .map(|_| scene.render(pi, (0.0, 0.0), false, 1, Some(STATS_CROP_PX)));
        images.push(ImageComparison {
            frame: "reference".into(),
            pattern: meas.labels[pi].clone(),
            run: None,
            measured: meas.reference_stats[pi].clone(),
            model: frame_stats(Some(&reference), &crop, repeat.as_ref()),
        });
        let mut prepared = Vec::new();
        for s in &opts.schemes {
            let r = reduce(&reference, s)?;
            prepared
                .push(PreparedReference::new(&r, &opts.dic).map_err(|e| dic_error("model", s, e))?);
        }
        for (ri, run) in runs
            .iter()
            .enumerate()
            .filter(|(ri, _)| meas.pattern_of_run[*ri] == pi)
        {
            if !go_on() {
                return Err(DiagnoseError::Cancelled);
            }
            let moved = scene.render(
                pi,
                nominal.landed_command(ri, (run.stage.dx_mm, run.stage.dy_mm)),
                true,
                2 + ri as u64,
                None,
            );
            let mcrop = centre_crop(&moved, STATS_CROP_PX);
            moved_images[ri] = Some(ImageComparison {
                frame: "moved".into(),
                pattern: meas.labels[pi].clone(),
                run: Some(run.id.clone()),
                measured: meas.moved_stats[ri].clone(),
                model: frame_stats(Some(&moved), &mcrop, None),
            });
            let mut per_scheme = Vec::new();
            for (s, prep) in opts.schemes.iter().zip(&prepared) {
                let d = reduce(&moved, s)?;
                let watch = Watch {
                    progress: None,
                    cancelled: Some(&cancelled),
                };
                per_scheme.push(prep.correlate_watched(&d, watch).map_err(|e| match e {
                    DicError::Cancelled => DiagnoseError::Cancelled,
                    other => dic_error(&run.id, s, other),
                })?);
                let n = done.fetch_add(1, Ordering::Relaxed) + 1;
                if !progress(n, total) {
                    return Err(DiagnoseError::Cancelled);
                }
            }
            model_dic[ri] = Some(per_scheme);
        }
    }
    images.extend(moved_images.into_iter().flatten());
    let model_dic: Vec<Vec<DicResult>> = model_dic
        .into_iter()
        .map(|r| r.expect("every run rendered"))
        .collect();
    let hardware = model_hardware(&meas.hardware, &scene, &nominal, &meas.pattern_of_run, opts)?;
    Ok(assemble(meas, model, nominal, model_dic, images, hardware))
}

/// The comparison from the model's analyses: the landings refined against them
/// ([`refine_landings`]), every run's discrepancy, the totals and the χ²; the capture-mode runs
/// beside it when `hardware_model` holds their model side (empty for a prediction).
pub(super) fn assemble(
    meas: &Measurement,
    model: &ModelConfig,
    nominal: Nominal,
    mut model_dic: Vec<Vec<DicResult>>,
    images: Vec<ImageComparison>,
    hardware_model: Vec<HardwareModelSide>,
) -> Comparison {
    let opts = &meas.options;
    let runs = &meas.manifest.runs;
    let mut nominal = nominal;
    let rendered_at: Vec<[f64; 2]> = (0..runs.len())
        .map(|ri| nominal.stage.applied_offset_px(ri))
        .collect();
    refine_landings(meas, &mut nominal, &mut model_dic);
    let landing_shift_px: Vec<[f64; 2]> = rendered_at
        .iter()
        .enumerate()
        .map(|(ri, old)| {
            let new = nominal.stage.applied_offset_px(ri);
            [new[0] - old[0], new[1] - old[1]]
        })
        .collect();
    let hardware = compare_hardware(
        &meas.hardware,
        hardware_model,
        &meas.labels,
        &meas.pattern_of_run,
        &landing_shift_px,
        opts,
    );
    let out_runs = run_comparisons(meas, &nominal, &model_dic);
    let rms = |f: fn(&RunComparison) -> f64| {
        let v: Vec<f64> = out_runs.iter().map(f).filter(|x| x.is_finite()).collect();
        (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
    };
    let mut cmp = Comparison {
        dataset: meas.manifest.name.clone(),
        manifest_version: super::history::short_hash(
            &serde_json::to_string(&meas.manifest).expect("a manifest always serialises"),
        ),
        manifest_runs: meas.manifest.runs.len(),
        model: ModelInfo {
            name: model.name.clone(),
            version: model_version(model),
            effects: model.effects.clone(),
            nominal,
        },
        discrepancy_px: rms(|r| r.discrepancy_px),
        discrepancy_se_px: discrepancy_se(&out_runs),
        parts: DiscrepancyParts {
            rigid_px: rms(|r| r.rigid_px),
            field_px: rms(|r| r.field_px),
            std_px: rms(|r| r.std_px),
        },
        parts_se: DiscrepancyParts {
            rigid_px: rms_se(&out_runs, |d| (d.rigid_px, d.rigid_sq_var)),
            field_px: rms_se(&out_runs, |d| (d.field_px, d.field_sq_var)),
            std_px: rms_se(&out_runs, |d| (d.std_px, d.std_sq_var)),
        },
        runs: out_runs,
        images,
        chi2: Chi2::default(),
        hardware,
        hardware_runs_set_aside: meas.hardware_runs_set_aside,
        model_dic: Vec::new(),
    };
    cmp.chi2 = chi2(&cmp, None, &opts.dic);
    cmp.model_dic = model_dic;
    cmp
}

/// Every run and scheme of a comparison: the measured analysis against the model's.
fn run_comparisons(
    meas: &Measurement,
    nominal: &Nominal,
    model_dic: &[Vec<DicResult>],
) -> Vec<RunComparison> {
    let opts = &meas.options;
    let mut out_runs = Vec::new();
    for (ri, run) in meas.manifest.runs.iter().enumerate() {
        let model_results = &model_dic[ri];
        let move_px = nominal.actual_move_px(ri, (run.stage.dx_mm, run.stage.dy_mm));
        let um = |p: [f64; 2]| p.map(|x| x * 1000.0 / nominal.scale_px_per_mm);
        for (si, scheme) in opts.schemes.iter().enumerate() {
            let m = &meas.dic[ri][si];
            let o = &model_results[si];
            let d = run_discrepancy(m, o, super::bic::inflation(&opts.dic));
            let frac = |x: f64| x - x.floor();
            out_runs.push(RunComparison {
                id: run.id.clone(),
                pattern: meas.labels[meas.pattern_of_run[ri]].clone(),
                scheme: scheme.name.clone(),
                discrepancy_px: d.discrepancy_px,
                rigid_px: d.rigid_px,
                field_px: d.field_px,
                stage_offset_um: um(nominal.stage.applied_offset_px(ri)),
                stage_landing_um: um(nominal
                    .stage
                    .landing_px
                    .get(ri)
                    .copied()
                    .unwrap_or_default()),
                std_px: d.std_px,
                se: d.errors(),
                measured: Side {
                    summary: m.summary,
                    random_px: [d.measured_random_px.0, d.measured_random_px.1],
                },
                model: Side {
                    summary: o.summary,
                    random_px: [d.model_random_px.0, d.model_random_px.1],
                },
                mean_diff_px: [d.mean_diff_px.0, d.mean_diff_px.1],
                subpixel_fraction: [frac(m.summary.u.mean), frac(m.summary.v.mean)],
                move_px,
                accuracy: accuracy(run, meas.manifest.scale_px_per_mm, scheme, m, &opts.dic),
                residual: residual_map(m, &d),
                detail: d,
            });
        }
    }
    out_runs
}

/// The measured analysis `m` of `run` in `scheme` against the run's commanded move.
fn accuracy(
    run: &crate::dataset::Run,
    scale_px_per_mm: f64,
    scheme: &Scheme,
    m: &DicResult,
    dic: &crate::dic::DicSettings,
) -> Accuracy {
    let px_per_mm = run.frame_px_per_mm(scale_px_per_mm);
    let blocks = [scheme.x.block as f64, scheme.y.block as f64];
    let commanded = [
        run.stage.dx_mm * px_per_mm / blocks[0],
        run.stage.dy_mm * px_per_mm / blocks[1],
    ];
    let s = &m.summary;
    let n_eff = (s.valid as f64 / super::bic::inflation(dic)).max(1.0);
    let bias = [s.u.mean - commanded[0], s.v.mean - commanded[1]];
    let std = [s.u.std, s.v.std];
    let se = std.map(|x| x / n_eff.sqrt());
    let um = |p: [f64; 2]| [0, 1].map(|i| p[i] * blocks[i] * 1000.0 / px_per_mm);
    Accuracy {
        commanded_px: commanded,
        bias_px: bias,
        bias_se_px: se,
        std_px: std,
        bias_um: um(bias),
        bias_se_um: um(se),
        std_um: um(std),
    }
}

/// Standard error of the total discrepancy D = √(mean D_r²) from the noise of each analysis,
/// propagated (var D² = Σ var D_r² / N², scaled by N/N_eff for the frames the analyses share).
/// It does not hold the model's speckle realisation: `diagnose` adds the scatter over model
/// seeds.
pub fn discrepancy_se(runs: &[RunComparison]) -> f64 {
    rms_se(runs, |d| (d.discrepancy_px, d.discrepancy_sq_var))
}

/// The standard error of an RMS over runs of one length (the discrepancy or one of its parts),
/// `part` giving each run's length and the sampling variance of its square, propagated as
/// [`discrepancy_se`] says.
fn rms_se(runs: &[RunComparison], part: fn(&RunDiscrepancy) -> (f64, f64)) -> f64 {
    let valid: Vec<(f64, f64)> = runs
        .iter()
        .map(|r| part(&r.detail))
        .filter(|(d, _)| d.is_finite())
        .collect();
    let n = valid.len();
    if n == 0 {
        return f64::NAN;
    }
    let nf = n as f64;
    let d2 = valid.iter().map(|(d, _)| d.powi(2)).sum::<f64>() / nf;
    let shared = super::bic::shared_fraction(runs).max(1e-9);
    let var_d2 = valid
        .iter()
        .map(|(_, v)| *v)
        .filter(|v| v.is_finite())
        .sum::<f64>()
        / (nf * nf)
        / shared;
    super::discrepancy::se_of_length(d2.sqrt(), var_d2)
}

/// Reads the dataset in `dir` and compares it with `model`. `progress` counts every analysis
/// (measured and model side).
pub fn compare(
    dir: &Path,
    model: &ModelConfig,
    options: &CompareOptions,
    progress: Progress,
) -> Result<Comparison, DiagnoseError> {
    let manifest_runs = Manifest::read(dir)?.full_resolution().0.runs.len() * options.schemes.len();
    let total = 2 * manifest_runs;
    let meas = load_measurement(dir, options, &|d, _| progress(d, total))?;
    compare_prepared(&meas, model, &|d, _| progress(manifest_runs + d, total))
}
