//! The nominal scene calibrated to the measurement for one model: the stage fitted to the
//! measured mean displacements, then per pattern the white level, the dots' placement and
//! profile, and the print's contrast and size, each matched to the measured reference crop
//! (see [`super::print`] for why a print is calibrated and what its spectral shape is).

use super::measurement::Measurement;
use super::nominal::Nominal;
use super::nominal::PatternEstimate;
use super::optimise::{brent, golden_tolerance, GOLDEN_STEP};
use super::print::{
    placement_band_edge, spectral_shape_bins, spectral_shape_chi2, spectral_shape_chi2_below,
    PrintCalibration, PrintKnowledge,
};
use super::stage::{fit_stage, StageObservation};
use super::DiagnoseError;
use crate::image::Image;
use crate::model::{DotProfile, ModelConfig, Placement, SpecklePattern};
use rayon::prelude::*;
use std::sync::Arc;

/// Asked before each step whether to go on (a cancelled job says no); shared by the patterns'
/// and the placements' calibrations running side by side.
type GoOn<'a> = &'a (dyn Fn() -> bool + Sync);

/// The nominal experiment of `model` for this measurement: the stage fitted, the white levels
/// matched (one centred crop render per pattern), the model's speckle and noise drawn from
/// `seed`; `scene_from` hands over
/// the white levels and prints of another comparison of the same image chain (they depend on
/// the optics and the sensor, not on the geometry or the seed's realisation).
pub(super) fn calibrate_seeded(
    meas: &Measurement,
    model: &ModelConfig,
    seed: u64,
    scene_from: SceneFrom<'_>,
    go_on: GoOn<'_>,
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
    // The patterns side by side: a pattern's calibration reads and writes its own estimate
    // only (its white level and print; its renders take its dots alone), so each on its own
    // copy of the scene gives what it gave when they ran in turn.
    let calibrated: Vec<PatternEstimate> = (0..nominal.patterns.len())
        .into_par_iter()
        .map(|pi| {
            let mut own = nominal.clone();
            calibrate_pattern(meas, &mut own, model, (pi, seed), scene_from, go_on)?;
            Ok(own.patterns.swap_remove(pi))
        })
        .collect::<Result<_, DiagnoseError>>()?;
    nominal.patterns = calibrated;
    Ok(nominal)
}

/// Pattern `pi`'s white level and print in `nominal`, calibrated as `scene_from` says
/// ([`calibrate_seeded`]).
fn calibrate_pattern(
    meas: &Measurement,
    nominal: &mut Nominal,
    model: &ModelConfig,
    (pi, seed): (usize, u64),
    scene_from: SceneFrom<'_>,
    go_on: GoOn<'_>,
) -> Result<(), DiagnoseError> {
    // Each step renders crops (the print's calibration some thirty): asked before each.
    let check = || go_on().then_some(()).ok_or(DiagnoseError::Cancelled);
    let stated = nominal.patterns[pi].pattern.clone();
    // Whether an earlier calibration decided the placement and the dots' profile.
    let decided = match scene_from {
        SceneFrom::Reuse(other) => {
            nominal.patterns[pi].clone_from(&other.patterns[pi]);
            return Ok(());
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
        SceneFrom::Rematch(other) => {
            nominal.patterns[pi].clone_from(&other.patterns[pi]);
            return rematch_levels(meas, nominal, model, (pi, seed), &stated);
        }
        SceneFrom::Calibrate => false,
    };
    check()?;
    match_white(meas, nominal, model, pi, seed)?;
    if !decided && !nominal.patterns[pi].placement_stated {
        check()?;
        choose_placement(meas, nominal, model, pi, seed)?;
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
        calibrate_print(meas, nominal, model, pi, seed, profile, go_on)?;
        record_calibration(meas, nominal, model, pi, seed, &stated)?;
        check()?;
        match_white(meas, nominal, model, pi, seed)?;
    }
    Ok(())
}

/// Pattern `pi`'s white level and, for a calibrated print, its contrast matched again to the
/// measured reference under `model`, the print's placement, profile and sizes kept
/// ([`SceneFrom::Rematch`]): the contrast matched moves the crop's mean, so the white level is
/// matched on both sides of it.
fn rematch_levels(
    meas: &Measurement,
    nominal: &mut Nominal,
    model: &ModelConfig,
    (pi, seed): (usize, u64),
    stated: &SpecklePattern,
) -> Result<(), DiagnoseError> {
    match_white(meas, nominal, model, pi, seed)?;
    if nominal.patterns[pi].print == PrintKnowledge::Calibrated {
        match_contrast(meas, nominal, model, pi, seed)?;
        record_calibration(meas, nominal, model, pi, seed, stated)?;
        match_white(meas, nominal, model, pi, seed)?;
        if tracing::enabled!(tracing::Level::DEBUG) {
            // How the kept print's spectral shape fits under this model (the refit's searches
            // log theirs): one more spectrum of a remembered crop.
            let crop = reference_crop(meas, nominal, model, pi, seed)?;
            let chi2 = spectral_shape_chi2(&meas.reference_stats[pi], &crop);
            tracing::debug!(pattern = pi, chi2, "a print kept, its levels matched again");
        }
    }
    Ok(())
}

/// Where a comparison's white levels and prints come from.
#[derive(Clone, Copy)]
pub enum SceneFrom<'a> {
    /// Calibrated against the measured references from what the manifest states: the placement
    /// chosen, the dots' profile decided, the print fitted.
    Calibrate,
    /// Calibrated again as [`SceneFrom::Calibrate`] does, from the same statement, but with the
    /// placement and the dots' profile a calibrated scene decided: a model whose image chain
    /// differs (a blur, an aperture) sees the same kind of print, with other dot sizes
    /// and contrast. The fit repeats the steps that decided the print (not more: a print fitted
    /// further than the scene it is judged against would credit the candidate with the better
    /// fit — on the DIC Challenge's Sample 3 two more rounds from the calibrated print alone
    /// took 90 % of the discrepancy). Cuts a disk print's calibration from some 180 renderings
    /// of its crop to some 90.
    Refit(&'a Nominal),
    /// The prints of a calibrated scene taken as they are (placement, profile, sizes), the white
    /// levels and contrasts matched again: a model whose reference frame differs from that
    /// scene's only in the noise the sensor adds or a smooth shading
    /// ([`crate::model::Effects::print_image`]). The noise changes the crop's variance, not the
    /// print: refitted, the print's sizes moved only by the refit's own path, and the refit was
    /// most of a noise candidate's time (on the paper-size example 5.5 s of a 25 s round).
    Rematch(&'a Nominal),
    /// Taken as they are: a model with the same image chain, or one that renders the same
    /// reference frame ([`crate::model::Effects::reference_part`]).
    Reuse(&'a Nominal),
}

impl SceneFrom<'_> {
    /// The variant's name, for the logs.
    pub fn kind(&self) -> &'static str {
        match self {
            SceneFrom::Calibrate => "calibrate",
            SceneFrom::Refit(_) => "refit",
            SceneFrom::Rematch(_) => "rematch",
            SceneFrom::Reuse(_) => "reuse",
        }
    }
}

/// The model's centred reference crop of pattern `pi`.
fn reference_crop(
    meas: &Measurement,
    nominal: &Nominal,
    model: &ModelConfig,
    pi: usize,
    seed: u64,
) -> Result<Arc<Image>, DiagnoseError> {
    Ok(super::scene::reference_crop(
        nominal,
        &model.effects,
        &meas.manifest,
        seed,
        pi,
    )?)
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
/// spectrum suppressed like a grid but without its order. Independent positions (Poisson), the
/// placement without structure, are kept unless another fits better by more than the χ²'s own
/// scatter, √(2ν) over ν + 1 bins: a closer χ² is the crop's noise, not a finding. On a control
/// of the independent generator's test bench (Gaussian dots placed independently, 640x540) the
/// hard core read 10.5 against Poisson's 12.7 over some 12 bins, and under it the Gaussian
/// dots' whole band fitted at χ² 5,024: the print went to the disks' screening (three more
/// fits) and ended as soft disks.
fn choose_placement(
    meas: &Measurement,
    nominal: &mut Nominal,
    model: &ModelConfig,
    pi: usize,
    seed: u64,
) -> Result<(), DiagnoseError> {
    let f_max = placement_band_edge(&nominal.patterns[pi].pattern, nominal.scale_px_per_mm);
    let (mut chi2, mut bins) = ([0.0; 3], [0usize; 3]);
    for (k, placement) in PLACEMENTS.into_iter().enumerate() {
        let mut n = nominal.clone();
        n.patterns[pi].pattern.placement = placement;
        let crop = reference_crop(meas, &n, model, pi, seed)?;
        (chi2[k], bins[k]) = spectral_shape_chi2_below(&meas.reference_stats[pi], &crop, f_max);
    }
    let best = (0..3).fold(0, |b, k| if chi2[k] < chi2[b] { k } else { b });
    let poisson = PLACEMENTS
        .iter()
        .position(|p| *p == Placement::Poisson)
        .expect("Poisson is a placement tried");
    let scatter = (2.0 * bins[poisson].saturating_sub(1) as f64).sqrt();
    let chosen = if chi2[poisson] - chi2[best] <= scatter {
        poisson
    } else {
        best
    };
    let p = &mut nominal.patterns[pi];
    p.pattern.placement = PLACEMENTS[chosen];
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
    go_on: GoOn<'_>,
) -> Result<(), DiagnoseError> {
    match (profile, nominal.patterns[pi].pattern.profile) {
        (ProfileKnown::Stated, _) | (ProfileKnown::Decided, DotProfile::Gaussian) => {
            fit_print(meas, nominal, model, pi, seed, (2, Gap::Fitted), go_on)?;
            return Ok(());
        }
        (ProfileKnown::Decided, DotProfile::Disk) => {
            // The steps that decided it: a screening round, two more.
            fit_print(meas, nominal, model, pi, seed, (1, Gap::Kept), go_on)?;
            fit_print(meas, nominal, model, pi, seed, (2, Gap::Fitted), go_on)?;
            return Ok(());
        }
        (ProfileKnown::No, _) => {}
    }
    // Gaussian dots first; disks only when the Gaussian's spectral shape is rejected (χ²
    // beyond its degrees of freedom by three standard deviations): the simpler print is
    // kept when it fits, and a disk's fit costs twice a Gaussian's.
    nominal.patterns[pi].pattern.profile = DotProfile::Gaussian;
    let mut gaussian = nominal.clone();
    let chi2_gaussian = fit_print(meas, &mut gaussian, model, pi, seed, (2, Gap::Kept), go_on)?;
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
        // One round under each placement (side by side: independent fits), two more for the
        // best; of equal χ², the first in the list.
        let screened = placements
            .into_par_iter()
            .map(|placement| {
                let mut disk = nominal.clone();
                disk.patterns[pi].pattern.profile = DotProfile::Disk;
                disk.patterns[pi].pattern.placement = placement;
                let chi2_disk = fit_print(meas, &mut disk, model, pi, seed, (1, Gap::Kept), go_on)?;
                Ok((chi2_disk, disk))
            })
            .collect::<Result<Vec<_>, DiagnoseError>>()?
            .into_iter()
            .reduce(|best, next| if next.0 < best.0 { next } else { best });
        if let Some((_, mut disk)) = screened {
            let chi2_disk = fit_print(meas, &mut disk, model, pi, seed, (2, Gap::Fitted), go_on)?;
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
        min_gap_mm: p.min_gap_mm,
    });
    Ok(())
}

/// A crop's contrast: std/mean.
fn contrast_of(img: &Image) -> f64 {
    let (m, s) = img.mean_std();
    s / m.max(1e-12)
}

/// Fits pattern `pi`'s print with its profile: up to `rounds` rounds of contrast, then size — a
/// Gaussian's σ, or a disk's gap under a hard core (where `gap` says), its diameter and then
/// its edge softness — by Brent's method on the spectral shape's χ², which it returns for the
/// fitted print. The rounds are a coordinate
/// descent: one whose searches all keep their starting size has converged (the next would search
/// the same sizes again under a contrast matched again to the same print), and the rest are left
/// out — on a disk print they cost 7–11 renderings per search and found nothing.
#[allow(clippy::too_many_arguments)]
fn fit_print(
    meas: &Measurement,
    nominal: &mut Nominal,
    model: &ModelConfig,
    pi: usize,
    seed: u64,
    (rounds, gap): (usize, Gap),
    go_on: GoOn<'_>,
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
    let search = |nominal: &mut Nominal,
                  set: &dyn Fn(&mut SpecklePattern, f64),
                  bracket: (f64, f64),
                  current: f64,
                  steps: usize| {
        search_size(nominal, pi, &chi2_of, set, (bracket, current), steps)
    };
    for _ in 0..rounds {
        match_contrast(meas, nominal, model, pi, seed)?;
        let p = nominal.patterns[pi].pattern.clone();
        // Keep the print physical: the dots' mean darkening — 2πσ²ρc for Gaussian dots
        // (Campbell's theorem), the covered fraction πR²ρ times c for disks — below 60 %, beyond
        // which dots pile up into black.
        let rho_per_mm2 = 1.0 / p.dot_spacing_mm.powi(2);
        let moved = match p.profile {
            DotProfile::Gaussian => {
                let sigma0 = p.sigma_mm();
                let sigma_max =
                    (0.6 / (2.0 * std::f64::consts::PI * rho_per_mm2 * p.contrast)).sqrt();
                let hi = (sigma_max / sigma0).clamp(0.3, 4.0).ln();
                let set =
                    |q: &mut SpecklePattern, ln_factor: f64| set_sigma(q, sigma0 * ln_factor.exp());
                search(nominal, &set, ((0.25f64).ln(), hi), 0.0, 12)
            }
            DotProfile::Disk => {
                // The gap first: a diameter fitted without it is too large (the two trade in
                // the spectrum near the spacing frequency), and searched after it the gap found
                // that diameter's valley floor at none on five of sixteen draws.
                let gap_moved = match gap {
                    Gap::Fitted => fit_gap(nominal, pi, &chi2_of, &search),
                    Gap::Kept => false,
                };
                let p = nominal.patterns[pi].pattern.clone();
                let d0 = p.dot_diameter_mm;
                let d_max = 2.0 * (0.6 / (std::f64::consts::PI * rho_per_mm2 * p.contrast)).sqrt();
                let hi = (d_max / d0).clamp(0.3, 4.0).ln();
                let set = |q: &mut SpecklePattern, ln_factor: f64| {
                    q.dot_diameter_mm = d0 * ln_factor.exp();
                };
                let diameter_moved = search(nominal, &set, ((0.25f64).ln(), hi), 0.0, 12);
                let q = &nominal.patterns[pi].pattern;
                let (d, fraction) = (q.dot_diameter_mm, q.edge_softness_mm / q.dot_diameter_mm);
                let set = |q: &mut SpecklePattern, fraction: f64| {
                    q.edge_softness_mm = d * fraction;
                };
                let softness_moved = search(nominal, &set, (0.0, 0.5), fraction, 10);
                gap_moved || diameter_moved || softness_moved
            }
        };
        if !go_on() {
            return Err(DiagnoseError::Cancelled);
        }
        if !moved {
            break;
        }
    }
    // The size's last search moves the contrast of the crop: matched once more.
    match_contrast(meas, nominal, model, pi, seed)?;
    Ok(chi2_of(nominal))
}

/// [`fit_print`]'s search of one size: the scene, how the size is set, its bracket, where it
/// starts and the golden-section steps of precision; whether the size moved.
type SizeSearch<'a> =
    &'a dyn Fn(&mut Nominal, &dyn Fn(&mut SpecklePattern, f64), (f64, f64), f64, usize) -> bool;

/// Whether [`fit_print`] fits a hard-core disk print's gap ([`fit_gap`]) or keeps it: a
/// screening round, which only ranks the placements, keeps it (each gap searched there cost
/// some ten renderings of the crop).
#[derive(Clone, Copy)]
enum Gap {
    Fitted,
    Kept,
}

/// The least gap between a hard-core disk print's dots, as a fraction of their diameter, by the
/// same spectral shape as its size: the gap sets how close the nearest dots come, so the
/// placement's structure near the spacing frequency, where a disk's own transform still
/// carries power. On eight draws of the independent generator's print b (0.24 mm disks with a
/// gap of 5 % of their diameter), a model kept at no gap fitted the disk's spectral shape at χ²
/// 35–72 over its 24 bins and one with the gap fitted at 9.5–48.5, lower in all 16
/// comparisons; and the one without it overstated the random error of v under ff50 by 19 %
/// (`docs/model-and-diagnosis.md`). The gap found is an effective one (the generator's
/// 0.012 mm read 0.001–0.032 mm): the model's adsorption is not the generator's dart throwing.
/// Up to the distance the hard core can keep (0.8 spacing). Whether the gap moved; none for
/// another placement.
fn fit_gap(
    nominal: &mut Nominal,
    pi: usize,
    chi2_of: &dyn Fn(&Nominal) -> f64,
    search: SizeSearch<'_>,
) -> bool {
    let q = &nominal.patterns[pi].pattern;
    if q.placement != Placement::HardCore {
        return false;
    }
    let d = q.dot_diameter_mm;
    let most = (0.8 * q.dot_spacing_mm / d - 1.0).min(0.5);
    if !(most > 0.0) {
        return false;
    }
    let set = |q: &mut SpecklePattern, fraction: f64| {
        q.min_gap_mm = d * fraction;
    };
    let current = (q.min_gap_mm / d).min(most);
    // From no gap, Brent's first steps hug the bound; started inside where that is better.
    let start = if current == 0.0 {
        let inside = GOLDEN_STEP * most;
        let at = |fraction: f64| {
            let mut n = nominal.clone();
            set(&mut n.patterns[pi].pattern, fraction);
            chi2_of(&n)
        };
        if at(inside) < at(0.0) {
            inside
        } else {
            0.0
        }
    } else {
        current
    };
    set(&mut nominal.patterns[pi].pattern, start);
    search(nominal, &set, (0.0, most), start, 8) || start != current
}

/// One size of pattern `pi`'s print along a search's coordinate, in `bracket` from `current`:
/// the search assumes one minimum, and the χ² of a softness need not have one (on a hard print
/// the second round's search ran to its bound at 3,500 times the χ² it started from), so the
/// search's end is kept only where it is better than where it started. Brent's method, started
/// where the print is (the χ² the guard needs anyway), to the precision `steps` golden-section
/// steps on the bracket had. Whether the size moved.
fn search_size(
    nominal: &mut Nominal,
    pi: usize,
    chi2_of: &dyn Fn(&Nominal) -> f64,
    set: &dyn Fn(&mut SpecklePattern, f64),
    ((lo, hi), current): ((f64, f64), f64),
    steps: usize,
) -> bool {
    // Each trial renders a crop: counted for the log, where a round's time goes.
    let renders = std::cell::Cell::new(0usize);
    let trial = |x: f64| {
        renders.set(renders.get() + 1);
        let mut n = nominal.clone();
        set(&mut n.patterns[pi].pattern, x);
        chi2_of(&n)
    };
    let chi2_current = trial(current);
    let start = if (lo..=hi).contains(&current) {
        (current, chi2_current)
    } else {
        // A print outside the bracket: started where a golden section starts.
        let x = lo + GOLDEN_STEP * (hi - lo);
        (x, trial(x))
    };
    let tolerance = golden_tolerance(hi - lo, steps);
    let (best, chi2_best) = brent(&trial, (lo, hi), start, tolerance, steps + 2);
    tracing::debug!(
        pattern = pi,
        renders = renders.get(),
        chi2_start = chi2_current,
        chi2_end = chi2_best,
        "a print size searched"
    );
    // Strictly better: where the χ² is flat (a disk's softness below what its rendering
    // resolves, `model::disk`) a tie is no reason to move, nor to run another round.
    let size = if chi2_best < chi2_current {
        best
    } else {
        current
    };
    set(&mut nominal.patterns[pi].pattern, size);
    size != current
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_gaussian_dots_sigma_is_carried_by_its_fwhm_alone() {
        let mut p = SpecklePattern {
            profile: DotProfile::Gaussian,
            edge_softness_mm: 0.05,
            ..SpecklePattern::preset("a").unwrap()
        };
        set_sigma(&mut p, 0.2);
        assert_eq!(p.edge_softness_mm, 0.0);
        assert!((p.sigma_mm() - 0.2).abs() < 1e-12, "{}", p.sigma_mm());
    }

    #[test]
    fn contrast_is_std_over_mean() {
        // Half the pixels at 100, half at 300: mean 200, std 100.
        let data: Vec<f32> = (0..64)
            .map(|i| if i % 2 == 0 { 100.0 } else { 300.0 })
            .collect();
        let img = Image::from_vec(8, 8, data).unwrap();
        assert!((contrast_of(&img) - 0.5).abs() < 1e-6);
        // A black crop has no contrast to match, and no division by zero.
        assert_eq!(contrast_of(&Image::filled(4, 4, 0.0)), 0.0);
    }
}
