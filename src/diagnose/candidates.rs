//! The candidates of a diagnosis: the effects the model lacks that the dataset can reveal,
//! each fitted (geometric effects on the field differences, image-level ones by simulation or
//! closed forms), its comparison predicted to first order where the effect is geometric and
//! rendered otherwise, and the winner always rendered.

use super::basis::geometric_basis;
use super::calibrate_scene::SceneFrom;
use super::compare::compare_with_scene;
use super::fit_geometric::FieldSample;
use super::fit_geometric_effect::fit_geometric_effect;
use super::fit_image::{fit_fill_factor, fit_motion_blur, fit_psf_blur};
use super::fit_image_stats::{fit_illumination_change, fit_sensor_noise, fit_vignetting};
use super::fit_user_effect::fit_user_effect;
use super::fit_user_intensity::fit_user_intensity;
use super::geometric::GeometricSetting;
use super::identifiability::DatasetDesign;
pub use super::identifiability::NotIdentifiable;
use super::measurement::Measurement;
use super::results::{Comparison, ImageFit};
use super::verdict::{Candidate, DesignRules, Judge, Method};
use super::{DiagnoseError, Progress};
use crate::model::effects::UserKind;
use crate::model::{CandidateId, EffectId, Effects, ModelConfig};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

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
pub(super) fn geometric_candidate(
    meas: &Measurement,
    before: &Comparison,
    model: &Effects,
    id: EffectId,
    refit: &[EffectId],
) -> Option<ImageFit> {
    let (samples, setting) = field_samples(meas, before);
    fit_geometric_effect(&samples, &setting, model, id, refit)
}

pub(super) fn fit_candidate(
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
            let kind = model.user.get(name)?.field().ok()?.kind();
            return match kind {
                UserKind::Displacement => {
                    let (samples, setting) = field_samples(meas, before);
                    fit_user_effect(&samples, &setting, model, (name, refit))
                }
                UserKind::Intensity => fit_user_intensity(meas, before, model, name),
            };
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

/// The comparison with a geometric candidate added, predicted from the model's analyses: each
/// valid point's displacement moves by the candidate's displacement field (exact to first order:
/// a DIC result follows a smooth change of the motion), the landings are refined again, the image
/// statistics stay. `stage_error` widens the envelope the landings are refined in. None for the
/// other effects, which change the images.
pub(super) fn predict(
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
            let field = e.field().ok()?;
            // An intensity changes the images: rendered, as the catalogue's image effects are.
            if field.kind() == UserKind::Intensity {
                return None;
            }
            Some((field, e.values()?))
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

/// A candidate's fit, the model with it, and that model's comparison (none when the fit stayed
/// within the null).
pub(super) type FittedModel = (ImageFit, ModelConfig, Option<Comparison>);
/// Per fitted candidate, its [`FittedModel`].
pub(super) type FittedModels = BTreeMap<CandidateId, FittedModel>;
/// A candidate's fit, the model with it, and that model's comparison with how it was made, not
/// yet judged ([`judge_candidates`]).
pub(super) type UnjudgedFit = (ImageFit, ModelConfig, Option<(Comparison, Method)>);

/// The effects the model lacks, split into those this dataset can reveal (to be fitted) and
/// those it cannot (with the runs that would), then the model's proposed user effects. The stage
/// is always part of the nominal fit and the ADC is the TIFFs'.
pub(super) fn candidates_to_fit(
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

/// Jobs run at once by [`in_lanes`]: the second fills the core a fit's optimiser leaves idle
/// (its steps render small crops; one round used ≈ 1.45 of 2 cores with one candidate at a
/// time); more would multiply the memory (≈ 190 MB per rendered comparison at 2560x2160) for
/// little, since each rendering and DIC are parallel inside.
pub(super) const CANDIDATES_AT_ONCE: usize = 2;

/// Runs independent `jobs` in [`CANDIDATES_AT_ONCE`] lanes that take them from one queue, in
/// order, calling `tick` after each; the results keep `jobs`' order. The first error ends the
/// lanes (each stops at its next job).
pub(super) fn in_lanes<J: Sync, R: Send>(
    jobs: &[J],
    run: &(dyn Fn(&J) -> Result<R, DiagnoseError> + Sync),
    tick: &(dyn Fn() -> Result<(), DiagnoseError> + Sync),
) -> Result<Vec<R>, DiagnoseError> {
    let next = AtomicUsize::new(0);
    let slots: Vec<Mutex<Option<R>>> = jobs.iter().map(|_| Mutex::new(None)).collect();
    (0..CANDIDATES_AT_ONCE.min(jobs.len()))
        .into_par_iter()
        .try_for_each(|_| -> Result<(), DiagnoseError> {
            loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(job) = jobs.get(i) else {
                    return Ok(());
                };
                let done = run(job)?;
                tick()?;
                *slots[i].lock().expect("a lane never panics holding it") = Some(done);
            }
        })?;
    Ok(slots
        .into_iter()
        .map(|slot| {
            slot.into_inner()
                .expect("a lane never panics holding it")
                .expect("every job ran: an error would have returned above")
        })
        .collect())
}

/// Judges each fitted candidate against `judge`, in the order given; the candidates, and per
/// candidate its fit, model and comparison.
pub(super) fn judge_candidates(
    judge: &Judge<'_>,
    fitted: impl IntoIterator<Item = UnjudgedFit>,
) -> (Vec<Candidate>, FittedModels) {
    let mut candidates = Vec::new();
    let mut models = FittedModels::new();
    for (fit, with, after) in fitted {
        candidates.push(judge.candidate(&fit, after.as_ref()));
        models.insert(fit.effect.clone(), (fit, with, after.map(|a| a.0)));
    }
    (candidates, models)
}

/// Fits candidate `id` against the model's comparison `before` and predicts (or, failing that,
/// renders) the comparison of the model with it: None when the effect has no fit on this
/// dataset. Candidates are independent (each its own fit, seeds and rendering).
pub(super) fn fit_one_candidate(
    meas: &Measurement,
    (model, refit): (&ModelConfig, &[EffectId]),
    (before, rules): (&Comparison, DesignRules),
    id: &CandidateId,
    ask: Progress,
) -> Result<Option<UnjudgedFit>, DiagnoseError> {
    let _span = tracing::debug_span!("candidate", %id).entered();
    // A cancelled job's fit ends early; the tick after it reports the cancel.
    let stop = || !ask(0, 0);
    let fitting = tracing::debug_span!("fit");
    let fitted =
        fitting.in_scope(|| fit_candidate(meas, before, &model.effects, (id, refit), &stop));
    let Some(fit) = fitted else {
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
    } else if !rules.may_be_named(&fit) {
        // Excluded whatever its rendering shows (`Method::Excluded`).
        None
    } else {
        // A candidate that leaves the reference frame as it was (a motion blur, an illumination
        // change) keeps the print calibrated against it: refitted, the print would differ only
        // by the refit's own path, and it cost most of such a candidate's time (a disk print:
        // some 90 renderings of its crop).
        // A noise candidate (shot and read noise, a fixed pattern) or a vignetting leaves the
        // print's image as it was (`EffectId::keeps_the_print`): the print is kept, its levels
        // matched again.
        let scene = if with.effects.reference_part() == model.effects.reference_part() {
            SceneFrom::Reuse(&before.model.nominal)
        } else if with.effects.print_image() == model.effects.print_image() {
            SceneFrom::Rematch(&before.model.nominal)
        } else {
            SceneFrom::Refit(&before.model.nominal)
        };
        let rendered = compare_with_scene(meas, &with, meas.options.seed, scene, ask)?;
        Some((rendered, Method::Rendered))
    };
    Ok(Some((fit, with, after)))
}

/// The winner is rendered: a predicted comparison is first order in the effect. When the
/// rendering no longer meets the criteria, the next significant candidate (in `candidates`'
/// order) is tried. The winner, if any.
pub(super) fn render_winner(
    meas: &Measurement,
    judge: &Judge<'_>,
    candidates: &mut [Candidate],
    models: &mut FittedModels,
    ask: Progress,
) -> Result<Option<CandidateId>, DiagnoseError> {
    while let Some(pos) = candidates.iter().position(|c| c.significant) {
        let effect = candidates[pos].effect.clone();
        let _span = tracing::debug_span!("winner", %effect).entered();
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::identifiability::design_of;
    use crate::diagnose::test_fields::{manifest, PrintStated};
    use std::path::Path;

    #[test]
    fn candidates_are_the_absent_effects_the_design_can_reveal() {
        let baseline =
            ModelConfig::from_toml(crate::diagnose::BASELINE_TOML, Path::new("b")).unwrap();
        // The paper's design: one 5 mm move, no dot size, no repeats, no stated repeatability.
        let design = design_of(&manifest(&[(5.0, 0.0)], &["a"], PrintStated::Nothing), 2560);
        let (fit, not) = candidates_to_fit(&baseline, &design);
        let fit: Vec<EffectId> = fit.iter().filter_map(|c| c.catalogue()).collect();
        let not: Vec<EffectId> = not.iter().map(|n| n.effect).collect();
        for e in [
            EffectId::PsfBlur,
            EffectId::SensorNoise,
            EffectId::StageError,
        ] {
            assert!(not.contains(&e) && !fit.contains(&e), "{e}");
        }
        for e in [
            EffectId::Rotation,
            EffectId::Scale,
            EffectId::LensDistortion,
        ] {
            assert!(fit.contains(&e), "{e}");
        }
        // Always in the nominal experiment, never a candidate; nor what the model has.
        for e in [EffectId::StageMisalignment, EffectId::Quantization] {
            assert!(!fit.contains(&e) && !not.contains(&e), "{e}");
        }
        for e in baseline.effects.enabled() {
            assert!(!fit.contains(&e), "{e}");
        }
    }
}
