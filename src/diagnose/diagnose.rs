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
//! discrepancy stays at its floor), `none` when no candidate is significant. A candidate whose parameter is within two
//! standard errors of no effect is not re-rendered: adding nothing changes nothing, so its
//! discrepancy is the model's and its ΔBIC the bare parameter penalty k·ln n (`recomputed`
//! false). Effects the dataset cannot reveal are listed with the runs to add, not fitted; pairs
//! that explain the same residual are named with the run that would separate them.

use super::basis::GeometricParam;
use super::bic::{chi2, delta_bic, SIGNIFICANT_DELTA_BIC};
use super::compare::{compare_prepared, load_measurement, Comparison, Measurement, ModelInfo};
use super::fit_geometric::{fit_geometric, FieldSample};
use super::fit_image::{
    fit_fill_factor, fit_illumination_change, fit_motion_blur, fit_psf_blur, fit_sensor_noise,
    fit_vignetting, ImageFit,
};
use super::identifiability::{design_of, separating_run};
pub use super::identifiability::{Confounded, NotIdentifiable};
use super::{CompareOptions, DiagnoseError, Progress};
use crate::model::effects::{LensDistortion, Rotation, Scale};
use crate::model::{Effects, ModelConfig, EFFECT_IDS};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Candidate {
    pub effect: String,
    pub params: BTreeMap<String, f64>,
    /// Standard errors of the fitted parameters (parameters set rather than fitted have none).
    pub stderr: BTreeMap<String, f64>,
    /// The discrepancy with the candidate added, px.
    pub discrepancy_px: f64,
    pub delta_bic: f64,
    pub significant: bool,
    /// Discrepancy of the model − with the candidate, px.
    pub drop_px: f64,
    /// Whether the discrepancy was recomputed by rendering (see the module doc).
    pub recomputed: bool,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Diagnosis {
    pub model: ModelInfo,
    pub discrepancy_px: f64,
    /// Ranked by ΔBIC, most negative first.
    pub candidates: Vec<Candidate>,
    /// Candidate ids ranked by the drop of the discrepancy, largest first.
    pub ranking_by_drop: Vec<String>,
    pub verdict: String,
    pub confounded: Vec<Confounded>,
    pub not_identifiable: Vec<NotIdentifiable>,
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

/// Reads the dataset in `dir` and diagnoses `model` against it.
pub fn diagnose(
    dir: &Path,
    model: &ModelConfig,
    options: &CompareOptions,
    progress: Progress,
) -> Result<Diagnosis, DiagnoseError> {
    let meas = load_measurement(dir, options, &|_, _| progress(0, 1))?;
    diagnose_prepared(&meas, model, None, progress)
}

fn geometric_fit_effects(model: &Effects, param: GeometricParam, value: f64) -> Effects {
    let mut e = model.clone();
    match param {
        GeometricParam::Rotation => e.rotation = Some(Rotation { angle_rad: value }),
        GeometricParam::Scale => e.scale = Some(Scale { ds: value }),
        GeometricParam::DistortionK1 => {
            e.lens_distortion = Some(LensDistortion {
                k1: value,
                k2: 0.0,
                p1: 0.0,
                p2: 0.0,
                centre_dx_px: 0.0,
                centre_dy_px: 0.0,
                norm_radius_px: 0.0,
            })
        }
        GeometricParam::TravelScale | GeometricParam::Misalignment => {}
    }
    e
}

fn geometric_candidate(
    meas: &Measurement,
    before: &Comparison,
    model: &Effects,
    id: &str,
) -> Option<ImageFit> {
    let param = match id {
        "rotation" => GeometricParam::Rotation,
        "scale" => GeometricParam::Scale,
        "lens_distortion" => GeometricParam::DistortionK1,
        _ => return None,
    };
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
    let fit = fit_geometric(&samples, param)?;
    let (_, name) = param.effect_and_name();
    Some(ImageFit {
        effect: match param {
            GeometricParam::Rotation => "rotation",
            GeometricParam::Scale => "scale",
            _ => "lens_distortion",
        },
        params: [(name.to_string(), fit.value)].into_iter().collect(),
        stderr: [(name.to_string(), fit.stderr)]
            .into_iter()
            .filter(|(_, se)| se.is_finite())
            .collect(),
        effects: geometric_fit_effects(model, param, fit.value),
        k: 1,
        beyond_null: fit.value.abs() > 2.0 * fit.stderr,
    })
}

fn fit_candidate(
    meas: &Measurement,
    before: &Comparison,
    model: &Effects,
    id: &str,
) -> Option<ImageFit> {
    match id {
        "rotation" | "scale" | "lens_distortion" => geometric_candidate(meas, before, model, id),
        "psf_blur" => Some(fit_psf_blur(meas, before, model)),
        "fill_factor" => Some(fit_fill_factor(meas, before, model)),
        "sensor_noise" => fit_sensor_noise(meas, before, model),
        "vignetting" => fit_vignetting(meas, before, model),
        "illumination_change" => fit_illumination_change(meas, before, model),
        "motion_blur" => fit_motion_blur(meas, before, model),
        _ => None,
    }
}

/// Diagnoses `model` against an analysed measurement; `before` is the model's comparison when
/// already made. `progress` counts candidates.
pub fn diagnose_prepared(
    meas: &Measurement,
    model: &ModelConfig,
    before: Option<Comparison>,
    progress: Progress,
) -> Result<Diagnosis, DiagnoseError> {
    let before = match before {
        Some(b) => b,
        None => compare_prepared(meas, model, &|_, _| true)?,
    };
    let design = design_of(&meas.manifest, meas.width);
    let present = model.effects.enabled();
    // Always part of the nominal experiment: the stage is fitted, the ADC is the TIFFs'.
    let absent: Vec<&str> = EFFECT_IDS
        .iter()
        .copied()
        .filter(|id| !present.contains(id) && *id != "stage_misalignment" && *id != "quantization")
        .collect();
    let mut not_identifiable = Vec::new();
    let mut fit_ids = Vec::new();
    for id in absent {
        match design.not_identifiable(id) {
            Some(n) => not_identifiable.push(n),
            None => fit_ids.push(id),
        }
    }
    let total = fit_ids.len();
    let done = AtomicUsize::new(0);
    let n_obs = before.chi2.observations;
    let mut candidates = Vec::new();
    let mut models: BTreeMap<String, (ModelConfig, Option<Comparison>)> = BTreeMap::new();
    for id in &fit_ids {
        let Some(fit) = fit_candidate(meas, &before, &model.effects, id) else {
            continue;
        };
        let with = ModelConfig {
            name: format!("{}+{}", model.name, fit.effect),
            description: format!(
                "{} with {} added, fitted by ffdic diagnose on dataset {}",
                model.name, fit.effect, meas.manifest.name
            ),
            effects: fit.effects.clone(),
        };
        let (discrepancy_px, delta, recomputed, after) = if fit.beyond_null {
            let after = compare_prepared(meas, &with, &|_, _| true)?;
            let c = chi2(&after, Some(&before), &meas.options.dic);
            (
                after.discrepancy_px,
                delta_bic(&before.chi2, &c, fit.k),
                true,
                Some(after),
            )
        } else {
            (
                before.discrepancy_px,
                fit.k as f64 * (n_obs.max(1) as f64).ln(),
                false,
                None,
            )
        };
        candidates.push(Candidate {
            effect: fit.effect.to_string(),
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
            significant: recomputed && fit.beyond_null && delta < SIGNIFICANT_DELTA_BIC,
            drop_px: before.discrepancy_px - discrepancy_px,
            recomputed,
        });
        models.insert(fit.effect.to_string(), (with, after));
        let n = done.fetch_add(1, Ordering::Relaxed) + 1;
        if !progress(n, total) {
            return Err(DiagnoseError::Cancelled);
        }
    }
    candidates.sort_by(|a, b| a.delta_bic.total_cmp(&b.delta_bic));
    let mut by_drop: Vec<&Candidate> = candidates.iter().collect();
    by_drop.sort_by(|a, b| b.drop_px.total_cmp(&a.drop_px));
    let ranking_by_drop = by_drop.iter().map(|c| c.effect.clone()).collect();
    let significant: Vec<&Candidate> = candidates.iter().filter(|c| c.significant).collect();
    let winner = significant.first().map(|c| c.effect.clone());
    let fitted: Vec<&str> = candidates.iter().map(|c| c.effect.as_str()).collect();
    let mut confounded = design.confounded(&fitted);
    // Data: a second significant candidate explaining nearly as much as the winner.
    if let Some(w) = &winner {
        let top = candidates
            .iter()
            .find(|c| &c.effect == w)
            .expect("winner is a candidate");
        for c in significant.iter().filter(|c| &c.effect != w) {
            let already = confounded
                .iter()
                .any(|p| p.effects.contains(&c.effect) && p.effects.contains(w));
            if !already && top.drop_px > 0.0 && c.drop_px >= 0.8 * top.drop_px {
                confounded.push(Confounded {
                    effects: [w.clone(), c.effect.clone()],
                    separate_with: separating_run(w, &c.effect),
                    evidence: "data".into(),
                });
            }
        }
    }
    let (winner_model, after) = match &winner {
        Some(w) => {
            let (m, a) = models.remove(w).expect("fitted");
            (Some(m), a)
        }
        None => (None, None),
    };
    Ok(Diagnosis {
        model: before.model.clone(),
        discrepancy_px: before.discrepancy_px,
        candidates,
        ranking_by_drop,
        verdict: winner.unwrap_or_else(|| "none".into()),
        confounded,
        not_identifiable,
        winner_model,
        before: Some(before),
        after,
    })
}
