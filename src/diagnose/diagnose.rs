//! `diagnose`: for every catalogue effect the model lacks, fit its parameters, recompute the
//! discrepancy with it added, and rank the candidates by ΔBIC and by the drop of the
//! discrepancy. Geometric effects are fitted by weighted linear least squares on displacement
//! basis fields stacked over every run and scheme ([`super::fit_geometric`]); image-level ones by
//! simulation fits with fixed seeds or closed forms on image statistics ([`super::fit_image`]).
//!
//! A candidate is significant when its ΔBIC is below −10 and a fitted parameter lies more than two
//! standard errors from "no effect". The verdict is the significant candidate with the most
//! negative ΔBIC (Schwarz's criterion decides; the drop of the discrepancy is reported beside it,
//! because an image-level effect can be certain from the image statistics while the displacement
//! discrepancy stays at its floor), `none` when no candidate is significant — or when the winner
//! explains under 90 % of the model's unexplained low-order field and no other geometric effect
//! explains the rest (`withheld`: the nearest catalogue name for something outside it). A candidate whose parameter is within two
//! standard errors of no effect is not re-rendered: adding nothing changes nothing, so its
//! discrepancy is the model's and its ΔBIC the bare parameter penalty k·ln n (`recomputed`
//! false). Effects the dataset cannot reveal are listed with the runs to add, not fitted; pairs
//! that explain the same residual are named with the run that would separate them.

use super::basis::geometric_basis;
use super::bic::{chi2, delta_bic, image_change, SIGNIFICANT_DELTA_BIC};
use super::compare::{
    compare_prepared, compare_with_scene, load_measurement, Measurement, SceneFrom,
};
use super::fit_geometric::FieldSample;
use super::fit_geometric_effect::{fit_geometric_effect, GeometricSetting};
use super::fit_image::{
    fit_fill_factor, fit_illumination_change, fit_motion_blur, fit_psf_blur, fit_sensor_noise,
    fit_vignetting,
};
use super::fit_user_effect::fit_user_effect;
use super::identifiability::{design_of, separating_run, DatasetDesign};
pub use super::identifiability::{Confounded, NotIdentifiable};
use super::print::PrintKnowledge;
use super::results::{Comparison, ImageFit, ModelInfo};
use super::unexplained::{model_scatter, unexplained, Unexplained};
use super::{CompareOptions, DiagnoseError, Progress};
use crate::model::{CandidateId, EffectId, Effects, ModelConfig};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Candidate {
    pub effect: CandidateId,
    pub params: BTreeMap<String, f64>,
    /// Standard errors of the fitted parameters (parameters set rather than fitted have none).
    pub stderr: BTreeMap<String, f64>,
    /// The discrepancy with the candidate added, px.
    pub discrepancy_px: f64,
    pub delta_bic: f64,
    pub significant: bool,
    /// Discrepancy of the model − with the candidate, px.
    pub drop_px: f64,
    /// Whether the discrepancy was recomputed (see the module doc), and how.
    pub recomputed: bool,
    pub method: Method,
    /// Each criterion a verdict needs, and whether this candidate meets it.
    pub criteria: Criteria,
    /// Quantities that follow from the parameters (a tilt's working distance, a distortion's
    /// equivalent centre).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub derived: BTreeMap<String, f64>,
    /// What the fit left out and why, and how to read the parameters.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

/// What a candidate's effect shows in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Evidence {
    /// The displacement fields: the discrepancy must drop.
    Displacement,
    /// The image statistics (mean map, noise, contrast): their χ² must drop.
    Image,
    /// Either: the discrepancy or the image statistics must drop.
    Either,
}

impl Evidence {
    /// A user effect is a displacement field.
    pub fn of_candidate(candidate: &CandidateId) -> Self {
        match candidate {
            CandidateId::Catalogue(e) => Self::of(*e),
            CandidateId::User(_) => Evidence::Displacement,
        }
    }

    pub fn of(effect: EffectId) -> Self {
        use EffectId::*;
        match effect {
            Vignetting | IlluminationChange | SensorNoise | FixedPattern => Evidence::Image,
            PsfBlur | FillFactor | MotionBlur => Evidence::Either,
            StageMisalignment | StageError | Rotation | Scale | LensDistortion | TargetTilt
            | Quantization => Evidence::Displacement,
        }
    }
}

/// The criteria of a verdict (module doc); `significant` is their conjunction.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Criteria {
    /// ΔBIC below −10.
    pub delta_bic_ok: bool,
    /// A fitted parameter more than two standard errors from "no effect".
    pub beyond_null: bool,
    pub evidence: Evidence,
    /// The drop of the discrepancy and its standard error, px.
    pub drop_px: f64,
    pub drop_se_px: f64,
    /// The drop of the image statistics' χ² and its standard error.
    pub image_chi2_drop: f64,
    pub image_chi2_se: f64,
    /// The drop the evidence needs is larger than two of its standard errors.
    pub drop_ok: bool,
    /// No fitted parameter sits at the bound of the catalogue's range; when one does, the value
    /// is reported as outside the range, not as a verdict.
    pub within_range: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub outside_range: Option<String>,
    /// The effect can be told from the print (false for blur and aperture when the print is
    /// calibrated to the frames: see `Confounded`).
    pub separable_from_print: bool,
    /// False when the verdict was withheld: the effect explains under
    /// [`MIN_EXPLAINED_FRACTION`] of the low-order field and no geometric catalogue effect
    /// explains the rest (the next significant candidate is not tried: it explains less).
    #[serde(default = "yes")]
    pub explains_its_signature: bool,
}

fn yes() -> bool {
    true
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Diagnosis {
    pub model: ModelInfo,
    pub discrepancy_px: f64,
    /// Standard error of the discrepancy: the noise of both analyses propagated, or the scatter
    /// over [`MODEL_SEEDS`] renderings of the model with different seeds, the larger.
    pub discrepancy_se_px: f64,
    /// The discrepancy for each model seed.
    pub discrepancy_by_seed_px: Vec<f64>,
    /// Ranked by ΔBIC, most negative first.
    pub candidates: Vec<Candidate>,
    /// Candidate ids ranked by the drop of the discrepancy, largest first.
    pub ranking_by_drop: Vec<CandidateId>,
    /// The winner, `"none"` on the wire when there is none.
    #[serde(with = "crate::model::effects::verdict_serde")]
    pub verdict: Option<CandidateId>,
    pub confounded: Vec<Confounded>,
    pub not_identifiable: Vec<NotIdentifiable>,
    /// What the model as given leaves unexplained.
    pub unexplained: Unexplained,
    /// What is left with the verdict added (none when the verdict is `none`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unexplained_after: Option<Unexplained>,
    /// The share of the model's unexplained low-order field that the verdict explains (from the
    /// field test's F: (F before − F after)/(F before − 1)), when both were measured.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub explained_fraction: Option<f64>,
    /// The verdict explains only part of what the model lacks: something significant is left.
    pub partial: bool,
    /// The nearest catalogue effect when it explains too little of the structure to be named: no
    /// verdict, and this says what it would have explained.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub withheld: Option<Withheld>,
    /// The model with the winner added (none when the verdict is `none`).
    #[serde(skip)]
    pub winner_model: Option<ModelConfig>,
    /// The comparison of the model as given.
    #[serde(skip)]
    pub before: Option<Comparison>,
    /// The comparison with the winner added.
    #[serde(skip)]
    pub after: Option<Comparison>,
}

/// A significant candidate not named because the structure it explains is a small part of what
/// remains, and no other catalogue effect explains the rest: the signature is not its own.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Withheld {
    pub effect: CandidateId,
    pub explained_fraction: f64,
    pub reason: String,
}

/// The least share of the unexplained field a verdict must explain when nothing in the catalogue
/// explains the rest.
pub const MIN_EXPLAINED_FRACTION: f64 = 0.9;

/// Reads the dataset in `dir` and diagnoses `model` against it.
pub fn diagnose(
    dir: &Path,
    model: &ModelConfig,
    options: &CompareOptions,
    progress: Progress,
) -> Result<Diagnosis, DiagnoseError> {
    let meas = load_measurement(dir, options, &|_, _| progress(0, 1))?;
    diagnose_prepared(&meas, model, None, &[], progress)
}

/// The field differences of the model's comparison, per run and scheme, as the geometric fits
/// read them, with what else they need.
pub(super) fn field_samples<'a>(
    meas: &'a Measurement,
    before: &'a Comparison,
) -> (Vec<FieldSample<'a>>, GeometricSetting) {
    let camera = before.model.nominal.camera(0);
    let centre = camera.centre();
    let r0 = camera.half_diagonal_px();
    let infl = super::bic::inflation(&meas.options.dic);
    let samples: Vec<FieldSample> = before
        .runs
        .iter()
        .filter_map(|r| {
            let scheme = meas.options.schemes.iter().find(|s| s.name == r.scheme)?;
            let run = meas.manifest.runs.iter().position(|x| x.id == r.id)?;
            Some(FieldSample {
                scheme,
                move_px: (r.move_px[0], r.move_px[1]),
                centre,
                r0,
                points: &r.detail.common,
                var: r.detail.residual_var_px2,
                inflation: infl,
                pattern: meas.pattern_of_run[run],
                run,
            })
        })
        .collect();
    let setting = GeometricSetting {
        scale_px_per_mm: camera.scale_px_per_mm,
        working_distance_mm: meas.manifest.working_distance_mm,
        r0,
        observations: before.chi2.observations,
    };
    (samples, setting)
}

/// A geometric catalogue effect fitted on the field differences of the model's comparison, the
/// model's `refit` effects re-estimated beside it.
fn geometric_candidate(
    meas: &Measurement,
    before: &Comparison,
    model: &Effects,
    id: EffectId,
    refit: &[EffectId],
) -> Option<ImageFit> {
    let (samples, setting) = field_samples(meas, before);
    fit_geometric_effect(&samples, &setting, model, id, refit)
}

fn fit_candidate(
    meas: &Measurement,
    before: &Comparison,
    model: &Effects,
    (id, refit): (&CandidateId, &[EffectId]),
    stop: &dyn Fn() -> bool,
) -> Option<ImageFit> {
    use EffectId::*;
    let id = match id {
        CandidateId::Catalogue(e) => *e,
        CandidateId::User(name) => {
            let (samples, setting) = field_samples(meas, before);
            return fit_user_effect(&samples, &setting, model, (name, refit));
        }
    };
    match id {
        Rotation | Scale | LensDistortion | TargetTilt => {
            geometric_candidate(meas, before, model, id, refit)
        }
        PsfBlur => Some(fit_psf_blur(meas, before, model, stop)),
        FillFactor => Some(fit_fill_factor(meas, before, model, stop)),
        SensorNoise => fit_sensor_noise(meas, before, model),
        Vignetting => fit_vignetting(meas, before, model),
        IlluminationChange => fit_illumination_change(before, model),
        MotionBlur => fit_motion_blur(meas, before, model, stop),
        StageError => super::stage::fit_stage_error(before, model),
        // Always part of the nominal experiment (fitted) or known (the frames' ADC), or not
        // identifiable from speckle frames: never a candidate.
        StageMisalignment | Quantization | FixedPattern => None,
    }
}

/// Renderings of the model (the comparison's seed and the next ones) whose scatter of the
/// discrepancy is part of its standard error: a model disagrees with one realisation of its own
/// speckle and noise by chance, and differently with the next.
pub const MODEL_SEEDS: u64 = 2;

/// The non-null bound of every bounded parameter of the image-level fits: a fit that ends there
/// has not found the effect's value, only that the catalogue's range does not hold it.
fn bound_of(effect: EffectId, param: &str) -> Option<(f64, f64)> {
    // (bound, range width)
    use EffectId::*;
    match effect {
        PsfBlur => (param == "sigma_px").then_some((3.0, 3.0)),
        FillFactor => matches!(param, "fx" | "fy").then_some((0.05, 0.95)),
        MotionBlur => (param == "length_px").then_some((4.0, 4.0)),
        StageMisalignment | StageError | Rotation | Scale | LensDistortion | TargetTilt
        | SensorNoise | FixedPattern | Quantization | Vignetting | IlluminationChange => None,
    }
}

/// The end of a user effect's stated range nearer `value`, and the range's width.
fn user_bound_of(effects: &Effects, name: &str, param: &str, value: f64) -> Option<(f64, f64)> {
    let p = effects.user.get(name)?.params.get(param)?;
    let nearer = if (value - p.min).abs() <= (value - p.max).abs() {
        p.min
    } else {
        p.max
    };
    Some((nearer, p.max - p.min))
}

fn outside_range(fit: &ImageFit) -> Option<String> {
    let at: Vec<String> = fit
        .params
        .iter()
        .filter_map(|(k, v)| {
            let (bound, width) = match &fit.effect {
                CandidateId::Catalogue(e) => bound_of(*e, k)?,
                CandidateId::User(name) => user_bound_of(&fit.effects, name, k, *v)?,
            };
            ((v - bound).abs() <= 0.01 * width).then(|| format!("{k} = {v:.4e} (bound {bound:e})"))
        })
        .collect();
    (!at.is_empty()).then(|| {
        format!(
            "the fit ended at the edge of the catalogue's range: {}; the data want a value beyond it, which this effect does not describe",
            at.join(", ")
        )
    })
}

/// How a candidate's comparison was made.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// The parameter is within two standard errors of no effect: adding nothing changes nothing.
    Unchanged,
    /// A geometric effect: the model's analyses shifted by the fitted field (first order, no
    /// rendering); the winner is always rendered.
    Predicted,
    /// Rendered and analysed.
    Rendered,
}

/// Everything the criteria of a candidate are judged against.
struct Judge<'a> {
    before: &'a Comparison,
    se_before: f64,
    seed_sd: f64,
    print_calibrated: bool,
    /// No translation reaches [`VIGNETTING_MOVE_FRACTION`] of the field.
    small_moves: bool,
    dic: &'a crate::dic::DicSettings,
}

/// The smallest translation, as a fraction of the frame width, that tells vignetting (fixed on
/// the sensor) from a non-uniform print or light (moving with the target): below it, both give
/// the same mean-intensity map in every frame.
pub const VIGNETTING_MOVE_FRACTION: f64 = 0.05;

/// What separates vignetting from the print's or the light's own non-uniformity.
pub const ILLUMINATION_SEPARATION: &str = "a flat-field frame of a uniform white target, or a translation of at least 5 % of the field: a sensor-fixed falloff stays where it is while the print's and the light's non-uniformity move with the target";

impl Judge<'_> {
    fn candidate(&self, fit: &ImageFit, after: Option<&(Comparison, Method)>) -> Candidate {
        let before = self.before;
        let n_obs = before.chi2.observations;
        let (discrepancy_px, delta, method, image_chi2_drop) = match after {
            Some((a, m)) => {
                let c = chi2(a, Some(before), self.dic);
                (
                    a.discrepancy_px,
                    delta_bic(&before.chi2, &c, fit.k),
                    *m,
                    -image_change(&before.chi2, &c),
                )
            }
            None => (
                before.discrepancy_px,
                fit.k as f64 * (n_obs.max(1) as f64).ln(),
                Method::Unchanged,
                0.0,
            ),
        };
        let drop_px = before.discrepancy_px - discrepancy_px;
        // The after side shares the measured analyses and the seed: its own noise, plus the
        // same realisation scatter (conservative: the two are treated as independent).
        let se_after = after.map_or(self.se_before, |(a, _)| {
            a.discrepancy_se_px.max(self.seed_sd)
        });
        let drop_se_px = self.se_before.hypot(se_after);
        let evidence = Evidence::of_candidate(&fit.effect);
        let displacement_ok = drop_px > 2.0 * drop_se_px;
        // The image drop is scaled for overdispersion; with no effect a k-parameter drop is
        // χ²_k, whose standard deviation is √(2k).
        let image_se = (2.0 * fit.k as f64).sqrt();
        let image_ok = image_chi2_drop > 2.0 * image_se;
        // Whatever its evidence, an effect may not make the displacements clearly worse.
        let no_worse = drop_px > -2.0 * drop_se_px;
        let drop_ok = no_worse
            && match evidence {
                Evidence::Displacement => displacement_ok,
                Evidence::Image => image_ok,
                Evidence::Either => displacement_ok || image_ok,
            };
        let range = outside_range(fit);
        let catalogue = fit.effect.catalogue();
        let separable_from_print = !(self.print_calibrated
            && matches!(catalogue, Some(EffectId::PsfBlur | EffectId::FillFactor))
            || catalogue == Some(EffectId::Vignetting) && self.small_moves);
        let criteria = Criteria {
            delta_bic_ok: method != Method::Unchanged && delta < SIGNIFICANT_DELTA_BIC,
            beyond_null: fit.beyond_null,
            evidence,
            drop_px,
            drop_se_px,
            image_chi2_drop,
            image_chi2_se: image_se,
            drop_ok,
            within_range: range.is_none(),
            outside_range: range,
            separable_from_print,
            explains_its_signature: true,
        };
        Candidate {
            effect: fit.effect.clone(),
            params: fit.params.clone(),
            // A parameter whose error could not be estimated has no entry (JSON has no NaN).
            stderr: fit
                .stderr
                .iter()
                .filter(|(_, se)| se.is_finite())
                .map(|(k, se)| (k.clone(), *se))
                .collect(),
            discrepancy_px,
            delta_bic: delta,
            significant: criteria.delta_bic_ok
                && criteria.beyond_null
                && criteria.drop_ok
                && criteria.within_range
                && criteria.separable_from_print,
            drop_px,
            recomputed: method != Method::Unchanged,
            method,
            criteria,
            derived: fit.geometric.derived.clone(),
            notes: fit.geometric.notes.clone(),
        }
    }
}

/// The comparison with a geometric candidate added, predicted from the model's analyses: each
/// valid point's displacement moves by the candidate's displacement field (exact to first order:
/// a DIC result follows a smooth change of the motion), the landings are refined again, the image
/// statistics stay. `stage_error` widens the envelope the landings are refined in. None for the
/// other effects, which change the images.
fn predict(
    meas: &Measurement,
    before: &Comparison,
    with: &ModelConfig,
    fit: &ImageFit,
) -> Option<Comparison> {
    if before.model_dic.is_empty() {
        return None;
    }
    let mut nominal = before.model.nominal.clone();
    let mut dic = before.model_dic.clone();
    let r0 = nominal.camera(0).half_diagonal_px();
    let user = match &fit.effect {
        CandidateId::User(name) => {
            let e = with.effects.user.get(name)?;
            Some((e.field().ok()?, e.values()?))
        }
        CandidateId::Catalogue(_) => None,
    };
    // The candidate's field at p (px from the centre) for the move t, full-resolution px.
    // A user effect's own field from its expressions, beside the basis terms (a geometric
    // candidate's, or the increments of the verdicts re-estimated beside a user effect).
    let field = |p: (f64, f64), t: (f64, f64)| -> (f64, f64) {
        let own = user
            .as_ref()
            .map_or((0.0, 0.0), |(f, values)| f.displacement(p, t, values));
        fit.geometric
            .field
            .iter()
            .fold(own, |(u, v), &(param, value)| {
                let (bu, bv) = geometric_basis(param, p, t, r0);
                (u + value * bu, v + value * bv)
            })
    };
    if fit.effect == EffectId::StageError {
        let e = with.effects.stage_error?;
        nominal.stage.repeatability_um = Some(e.repeatability_um);
        nominal.stage.source = super::stage_landing::RepeatabilitySource::Model;
    } else if user.is_some() || !fit.geometric.field.is_empty() {
        let (cx, cy) = nominal.camera(0).centre();
        for (ri, run) in meas.manifest.runs.iter().enumerate() {
            let t = nominal.actual_move_px(ri, (run.stage.dx_mm, run.stage.dy_mm));
            for (si, scheme) in meas.options.schemes.iter().enumerate() {
                let (bx, by) = (scheme.x.block as f64, scheme.y.block as f64);
                for p in dic[ri][si].points.iter_mut() {
                    let (fx, fy) = scheme.to_full(p.x, p.y);
                    let (u, v) = field((fx - cx, fy - cy), (t[0], t[1]));
                    p.u += u / bx;
                    p.v += v / by;
                }
            }
        }
    } else {
        return None;
    }
    Some(super::compare::assemble(
        meas,
        with,
        nominal,
        dic,
        before.images.clone(),
        Vec::new(),
    ))
}

/// Diagnoses `model` against an analysed measurement; `before` is the model's comparison when
/// already made; `refit`, the geometric effects of `model` re-estimated beside each geometric
/// candidate (the earlier rounds' verdicts; see `fit_geometric_effect`). `progress` counts
/// candidates.
pub fn diagnose_prepared(
    meas: &Measurement,
    model: &ModelConfig,
    before: Option<Comparison>,
    refit: &[EffectId],
    progress: Progress,
) -> Result<Diagnosis, DiagnoseError> {
    let before = match before {
        Some(b) => b,
        None => compare_prepared(meas, model, &|_, _| progress(0, 1))?,
    };
    let design = design_of(&meas.manifest, meas.width);
    let (fit_ids, not_identifiable) = candidates_to_fit(model, &design);
    let total = fit_ids.len() + MODEL_SEEDS as usize - 1;
    let done = AtomicUsize::new(0);
    let tick = || {
        let n = done.fetch_add(1, Ordering::Relaxed) + 1;
        if progress(n, total) {
            Ok(())
        } else {
            Err(DiagnoseError::Cancelled)
        }
    };
    // Asks, without a step done, whether to go on: inside each comparison, before every point.
    let ask = |_: usize, _: usize| progress(done.load(Ordering::Relaxed), total);
    let (by_seed, w0) = discrepancy_by_seed(meas, model, &before, &tick, &ask)?;
    let seed_sd = {
        let n = by_seed.len() as f64;
        let m = by_seed.iter().sum::<f64>() / n;
        (by_seed.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
    };
    let se_before = before.discrepancy_se_px.max(seed_sd);
    let print_calibrated = before
        .model
        .nominal
        .patterns
        .iter()
        .any(|p| p.print == PrintKnowledge::Calibrated);
    let judge = Judge {
        before: &before,
        se_before,
        seed_sd,
        print_calibrated,
        small_moves: design.largest_move_fraction < VIGNETTING_MOVE_FRACTION,
        dic: &meas.options.dic,
    };
    let (mut candidates, mut models) =
        fit_candidates(meas, (model, refit), &judge, &fit_ids, &tick, &ask)?;
    candidates.sort_by(|a, b| a.delta_bic.total_cmp(&b.delta_bic));
    let winner = render_winner(meas, &judge, &mut candidates, &mut models, &ask)?;
    candidates.sort_by(|a, b| a.delta_bic.total_cmp(&b.delta_bic));
    let mut by_drop: Vec<&Candidate> = candidates.iter().collect();
    by_drop.sort_by(|a, b| b.drop_px.total_cmp(&a.drop_px));
    let ranking_by_drop = by_drop.iter().map(|c| c.effect.clone()).collect();
    let left = settle(meas, winner, &mut models, &before, w0, (se_before, seed_sd));
    if let Some(w) = &left.withheld {
        for c in candidates.iter_mut().filter(|c| c.effect == w.effect) {
            c.criteria.explains_its_signature = false;
            c.significant = false;
        }
    }
    let confounded = confounded_pairs(&design, &candidates, left.winner.clone(), print_calibrated);
    Ok(Diagnosis {
        model: before.model.clone(),
        discrepancy_px: before.discrepancy_px,
        discrepancy_se_px: se_before,
        discrepancy_by_seed_px: by_seed,
        candidates,
        ranking_by_drop,
        verdict: left.winner,
        confounded,
        not_identifiable,
        partial: left
            .after
            .as_ref()
            .is_some_and(Unexplained::field_significant),
        explained_fraction: left.explained_fraction,
        unexplained: left.before,
        unexplained_after: left.after,
        withheld: left.withheld,
        winner_model: left.winner_model,
        before: Some(before),
        after: left.after_comparison,
    })
}

/// The verdict held against what it leaves (module doc of `unexplained`).
struct Settled {
    winner: Option<CandidateId>,
    winner_model: Option<ModelConfig>,
    after_comparison: Option<Comparison>,
    before: Unexplained,
    after: Option<Unexplained>,
    explained_fraction: Option<f64>,
    withheld: Option<Withheld>,
}

/// What the model and the model with the winner leave unexplained; the winner withheld when it
/// explains less than [`MIN_EXPLAINED_FRACTION`] of a significant residual and no other
/// catalogue effect explains the rest. `se` is the model's discrepancy SE and the seed scatter.
fn settle(
    meas: &Measurement,
    winner: Option<CandidateId>,
    models: &mut FittedModels,
    before: &Comparison,
    w0: Option<f64>,
    (se_before, seed_sd): (f64, f64),
) -> Settled {
    let infl = super::bic::inflation(&meas.options.dic);
    let schemes = &meas.options.schemes;
    let left_before = unexplained(before, schemes, w0, se_before, infl);
    let (winner_model, after) = match winner.as_ref().and_then(|w| models.remove(w)) {
        Some((_, m, a)) => (Some(m), a),
        None => (None, None),
    };
    let left_after = after.as_ref().map(|a| {
        let se = a.discrepancy_se_px.max(seed_sd);
        unexplained(a, schemes, w0, se, infl)
    });
    let explained_fraction = left_after.as_ref().and_then(|a| explained(&left_before, a));
    let settled = Settled {
        winner,
        winner_model,
        after_comparison: after,
        before: left_before,
        after: left_after,
        explained_fraction,
        withheld: None,
    };
    let (Some(w), Some(left), Some(fraction), Some(after), Some(with)) = (
        settled.winner.clone(),
        &settled.after,
        explained_fraction,
        &settled.after_comparison,
        &settled.winner_model,
    ) else {
        return settled;
    };
    // Only the field test speaks to the verdict's signature: a rigid part or the stage's
    // plausibility is another finding.
    if !(left.field_significant()
        && fraction < MIN_EXPLAINED_FRACTION
        && !rest_has_a_name(meas, after, with, w0, infl))
    {
        return settled;
    }
    Settled {
        winner: None,
        winner_model: None,
        after_comparison: None,
        after: None,
        explained_fraction: None,
        withheld: Some(Withheld {
            reason: format!(
                "{w} explains {:.0} % of the low-order field the model leaves, and no geometric catalogue effect or proposed user effect explains the rest: its signature is not what the data show (see unexplained)",
                100.0 * fraction
            ),
            effect: w,
            explained_fraction: fraction,
        }),
        ..settled
    }
}

/// The share of the model's excess low-order field (F above 1) that is gone after the verdict.
fn explained(before: &Unexplained, after: &Unexplained) -> Option<f64> {
    let (fb, fa) = (before.field_f?, after.field_f?);
    (fb > 1.0).then(|| ((fb - fa) / (fb - 1.0)).clamp(0.0, 1.0))
}

/// Whether another geometric catalogue effect or one of the model's proposed user effects,
/// fitted on what the winner leaves (`after`, the comparison of `with`, the model with the
/// winner), explains at least half of it: then the winner is one of several effects (the next
/// round finds the next), not the nearest name for something outside the catalogue. A user's
/// effect counts as a catalogue's does: it is what the user said may be there.
fn rest_has_a_name(
    meas: &Measurement,
    after: &Comparison,
    with: &ModelConfig,
    w0: Option<f64>,
    infl: f64,
) -> bool {
    let floor = w0.unwrap_or(0.0);
    let excess = super::unexplained::field_w(after, infl) - floor;
    if !(excess > 0.0) {
        // Nothing beyond the model's own scatter is left for another effect to explain.
        return true;
    }
    let catalogue = EffectId::ALL
        .into_iter()
        .filter(|id| !with.effects.has(*id))
        .filter_map(|id| geometric_candidate(meas, after, &with.effects, id, &[]));
    let proposed: Vec<&String> = with.effects.proposed_user().collect();
    let fields = (!proposed.is_empty()).then(|| field_samples(meas, after));
    let user = proposed.into_iter().filter_map(|name| {
        let (samples, setting) = fields.as_ref()?;
        fit_user_effect(samples, setting, &with.effects, (name, &[]))
    });
    catalogue
        .chain(user)
        .filter(|fit| fit.beyond_null)
        .any(|fit| {
            let next = ModelConfig {
                effects: fit.effects.clone(),
                ..with.clone()
            };
            predict(meas, after, &next, &fit)
                .is_some_and(|c| super::unexplained::field_w(&c, infl) - floor < 0.5 * excess)
        })
}

/// A candidate's fit, the model with it, and that model's comparison (none when the fit stayed
/// within the null).
type FittedModel = (ImageFit, ModelConfig, Option<Comparison>);
/// Per fitted candidate, its [`FittedModel`].
type FittedModels = BTreeMap<CandidateId, FittedModel>;

/// The effects the model lacks, split into those this dataset can reveal (to be fitted) and
/// those it cannot (with the runs that would), then the model's proposed user effects. The stage
/// is always part of the nominal fit and the ADC is the TIFFs'.
fn candidates_to_fit(
    model: &ModelConfig,
    design: &DatasetDesign,
) -> (Vec<CandidateId>, Vec<NotIdentifiable>) {
    let present = model.effects.enabled();
    let mut not_identifiable = Vec::new();
    let mut fit_ids = Vec::new();
    for id in EffectId::ALL.into_iter().filter(|id| {
        !present.contains(id) && !matches!(id, EffectId::StageMisalignment | EffectId::Quantization)
    }) {
        match design.not_identifiable(id) {
            Some(n) => not_identifiable.push(n),
            None => fit_ids.push(id.into()),
        }
    }
    fit_ids.extend(
        model
            .effects
            .proposed_user()
            .map(|name| CandidateId::User(name.clone())),
    );
    (fit_ids, not_identifiable)
}

/// The discrepancy with each of the `MODEL_SEEDS` model seeds (the first is `before`'s): its
/// scatter is part of the discrepancy's standard error. Also the model's own scatter of the
/// low-order field between the first two renderings ([`model_scatter`]).
fn discrepancy_by_seed(
    meas: &Measurement,
    model: &ModelConfig,
    before: &Comparison,
    tick: &dyn Fn() -> Result<(), DiagnoseError>,
    ask: Progress,
) -> Result<(Vec<f64>, Option<f64>), DiagnoseError> {
    let mut by_seed = vec![before.discrepancy_px];
    let mut w0 = None;
    let infl = super::bic::inflation(&meas.options.dic);
    for k in 1..MODEL_SEEDS {
        let c = compare_with_scene(
            meas,
            model,
            meas.options.seed.wrapping_add(k),
            SceneFrom::Reuse(&before.model.nominal),
            ask,
        )?;
        by_seed.push(c.discrepancy_px);
        if k == 1 {
            w0 = model_scatter(before, &c, infl);
        }
        tick()?;
    }
    Ok((by_seed, w0))
}

/// Candidates fitted at once by [`fit_candidates`]: the second fills the core a fit's optimiser
/// leaves idle (its steps render small crops; one round used ≈ 1.45 of 2 cores with one candidate
/// at a time); more would multiply the memory (≈ 190 MB per candidate's rendered comparison at
/// 2560x2160) for little, since each candidate's rendering and DIC are parallel inside.
const CANDIDATES_AT_ONCE: usize = 2;

/// Fits each candidate, predicts (or, failing that, renders) the comparison of the model with
/// it, and judges it. Candidates are independent (each its own fit, seeds and rendering):
/// [`CANDIDATES_AT_ONCE`] lanes take them from one queue. The results keep `fit_ids`' order.
fn fit_candidates(
    meas: &Measurement,
    (model, refit): (&ModelConfig, &[EffectId]),
    judge: &Judge<'_>,
    fit_ids: &[CandidateId],
    tick: &(dyn Fn() -> Result<(), DiagnoseError> + Sync),
    ask: Progress,
) -> Result<(Vec<Candidate>, FittedModels), DiagnoseError> {
    let next = AtomicUsize::new(0);
    let slots: Vec<Mutex<Option<(Candidate, FittedModel)>>> =
        fit_ids.iter().map(|_| Mutex::new(None)).collect();
    (0..CANDIDATES_AT_ONCE.min(fit_ids.len()))
        .into_par_iter()
        .try_for_each(|_| -> Result<(), DiagnoseError> {
            loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(id) = fit_ids.get(i) else {
                    return Ok(());
                };
                let fitted = fit_one_candidate(meas, (model, refit), judge, id, ask)?;
                tick()?;
                *slots[i].lock().expect("a lane never panics holding it") = fitted;
            }
        })?;
    let mut candidates = Vec::new();
    let mut models = FittedModels::new();
    for slot in slots {
        let fitted = slot.into_inner().expect("a lane never panics holding it");
        if let Some((candidate, (fit, with, after))) = fitted {
            candidates.push(candidate);
            models.insert(fit.effect.clone(), (fit, with, after));
        }
    }
    Ok((candidates, models))
}

/// One candidate of [`fit_candidates`]: None when the effect has no fit on this dataset.
fn fit_one_candidate(
    meas: &Measurement,
    (model, refit): (&ModelConfig, &[EffectId]),
    judge: &Judge<'_>,
    id: &CandidateId,
    ask: Progress,
) -> Result<Option<(Candidate, FittedModel)>, DiagnoseError> {
    let before = judge.before;
    // A cancelled job's fit ends early; the tick after it reports the cancel.
    let stop = || !ask(0, 0);
    let Some(fit) = fit_candidate(meas, before, &model.effects, (id, refit), &stop) else {
        return Ok(None);
    };
    let with = ModelConfig {
        name: format!("{}+{}", model.name, fit.effect),
        description: format!(
            "{} with {} added, fitted by ffdic diagnose on dataset {}{}",
            model.name,
            fit.effect,
            meas.manifest.name,
            if fit.geometric.notes.is_empty() {
                String::new()
            } else {
                format!(" ({})", fit.geometric.notes.join("; "))
            }
        ),
        effects: fit.effects.clone(),
    };
    let after = if !fit.beyond_null {
        None
    } else if let Some(predicted) = predict(meas, before, &with, &fit) {
        Some((predicted, Method::Predicted))
    } else {
        let scene = SceneFrom::Refit(&before.model.nominal);
        let rendered = compare_with_scene(meas, &with, meas.options.seed, scene, ask)?;
        Some((rendered, Method::Rendered))
    };
    let candidate = judge.candidate(&fit, after.as_ref());
    Ok(Some((candidate, (fit, with, after.map(|a| a.0)))))
}

/// The winner is rendered: a predicted comparison is first order in the effect. When the
/// rendering no longer meets the criteria, the next significant candidate (in `candidates`'
/// order) is tried. The winner, if any.
fn render_winner(
    meas: &Measurement,
    judge: &Judge<'_>,
    candidates: &mut [Candidate],
    models: &mut FittedModels,
    ask: Progress,
) -> Result<Option<CandidateId>, DiagnoseError> {
    while let Some(pos) = candidates.iter().position(|c| c.significant) {
        let effect = candidates[pos].effect.clone();
        if candidates[pos].method == Method::Rendered {
            return Ok(Some(effect));
        }
        let (fit, with, after) = models.get_mut(&effect).expect("fitted");
        let rendered = (
            compare_with_scene(
                meas,
                with,
                meas.options.seed,
                SceneFrom::Reuse(&judge.before.model.nominal),
                ask,
            )?,
            Method::Rendered,
        );
        let judged = judge.candidate(fit, Some(&rendered));
        let ok = judged.significant;
        candidates[pos] = judged;
        *after = Some(rendered.0);
        if ok {
            return Ok(Some(effect));
        }
    }
    Ok(None)
}

/// Effects the fits cannot tell apart: by the dataset's design (vignetting against
/// illumination on small moves, blur and aperture against a calibrated print), and by the data
/// (a second significant candidate explaining nearly as much as the winner).
fn confounded_pairs(
    design: &DatasetDesign,
    candidates: &[Candidate],
    winner: Option<CandidateId>,
    print_calibrated: bool,
) -> Vec<Confounded> {
    let fitted: Vec<EffectId> = candidates
        .iter()
        .filter_map(|c| c.effect.catalogue())
        .collect();
    let mut confounded = design.confounded(&fitted);
    if fitted.contains(&EffectId::Vignetting)
        && design.largest_move_fraction < VIGNETTING_MOVE_FRACTION
    {
        confounded.push(Confounded {
            effects: [EffectId::Vignetting.as_str().into(), "illumination".into()],
            separate_with: ILLUMINATION_SEPARATION.into(),
            evidence: "design".into(),
        });
    }
    if print_calibrated {
        for effect in [EffectId::PsfBlur, EffectId::FillFactor] {
            if fitted.contains(&effect) {
                confounded.push(Confounded {
                    effects: [effect.as_str().into(), "print".into()],
                    separate_with: PRINT_SEPARATION.into(),
                    evidence: "design".into(),
                });
            }
        }
    }
    let Some(w) = winner else {
        return confounded;
    };
    let top = candidates
        .iter()
        .find(|c| c.effect == w)
        .expect("winner is a candidate");
    for c in candidates.iter().filter(|c| c.significant && c.effect != w) {
        let names = super::identifiability::pair(&w, &c.effect);
        let already = confounded
            .iter()
            .any(|p| p.effects.contains(&names[0]) && p.effects.contains(&names[1]));
        if !already && top.drop_px > 0.0 && c.drop_px >= 0.8 * top.drop_px {
            confounded.push(Confounded {
                effects: names,
                separate_with: separating_run(&w, &c.effect),
                evidence: "data".into(),
            });
        }
    }
    confounded
}

/// What separates lens blur and pixel aperture from the print's own profile.
pub const PRINT_SEPARATION: &str = "a characterised print (the dataset.json pattern's dot_spacing_mm and contrast, with profile \"gaussian\" and its dot_diameter_mm or a measured mtf, or profile \"disk\" and its dot_diameter_mm and edge_softness_mm), a second magnification, a through-focus pair, or a slanted-edge frame measured as in ISO 12233: the print's calibration to the frames absorbs whatever blur one magnification cannot attribute";
