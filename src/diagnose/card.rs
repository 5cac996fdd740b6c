//! The camera card (issue 33): what a calibration's runs identify about the camera, its lens, the
//! target's mount and the stage, each number with its standard error, and the model that holds it.
//!
//! The rounds of a diagnosis add one effect at a time, and a later effect's terms can take up part
//! of an earlier one's field: decentring terms absorb much of a tilt when distortion is named
//! first (measured on a bench with both: the rounds' tilt fell from 0.0122 to 0.0013 rad). The card
//! therefore fits every geometric term the runs identify *jointly* on the baseline comparison's
//! field differences — rotation, scale, target tilt, k1, p1, p2, and k2 when it pays its BIC price
//! (ln n) — by the same weighted least squares as a candidate ([`super::fit_geometric`]); a term
//! the runs cannot tell from those before it is listed, not fitted. Where that fit finds k1, the
//! distortion is refitted about a centre of its own ([`super::card_distortion`]). A number is significant
//! beyond z = Φ⁻¹(1 − α/2m) standard errors, α = 1 % family-wise over the card's m tested numbers
//! (Bonferroni): a card of a bench with nothing hidden is empty but at that rate.
//!
//! The stage's map — scale per axis, the angle of its x axis to the sensor's rows, the
//! non-orthogonality of its axes — is the least-squares linear map from the commanded moves (mm)
//! to each run's measured rigid move (px), with the card's fitted fields' mean over the run's
//! points taken off: the magnification at the image centre. It is the affine stage-to-camera map
//! of Micro-Manager's pixel calibrator; the stage is the length standard, so its travel error and
//! the camera's scale are one number. The imaging chain (blur, pixel aperture, gain, read noise)
//! comes from the candidate fit of the round that named it (the card's model holds that fit, and
//! later rounds do not offer it again), else from the last round's, each marked identifiable or
//! not as that round's design says.

use super::calibrate_scene::SceneFrom;
use super::candidates::field_samples;
use super::card_distortion::{card_geometry, CentredDistortion};
use super::card_joint_fit::joint_fit;
use super::card_stage::{stage_map, StageMap};
use super::compare::{compare_prepared, compare_with_scene};
use super::geometric::Geometric;
use super::measurement::Measurement;
use super::results::Comparison;
use super::rounds::Rounds;
use super::unexplained::{model_scatter, unexplained, Unexplained};
use super::write_geometric::write_joint;
use super::{DiagnoseError, Progress};
use crate::model::effects::{LensDistortion, StageMisalignment};
use crate::model::{EffectId, Effects, ModelConfig};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The family-wise false-alarm rate of a card's significance marks.
pub const CARD_FALSE_ALARM_RATE: f64 = 0.01;

/// The stage map's numbers tested for significance (scale x, scale y, angle, skew).
const STAGE_NUMBERS: usize = 4;

/// One geometric effect of the card, as the model writes it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CardEffect {
    pub effect: EffectId,
    pub params: BTreeMap<String, f64>,
    pub stderr: BTreeMap<String, f64>,
    /// What follows from the parameters (a tilt's working distance, a distortion centre).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub derived: BTreeMap<String, f64>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
    /// A parameter lies more than the card's z standard errors from zero: the effect is in the
    /// card's model.
    pub significant: bool,
}

/// An image-level effect of the card (blur, pixel aperture, sensor noise), from the round that
/// named it, or else the last round.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImagingEntry {
    pub effect: EffectId,
    /// Empty when the runs and the print could not reveal the effect (not fitted).
    pub params: BTreeMap<String, f64>,
    pub stderr: BTreeMap<String, f64>,
    /// The runs reveal it and separate it from what it is confounded with.
    pub identifiable: bool,
    /// The round's candidate met every criterion of a verdict; false: its fit is what the
    /// data allow, not a measured effect (a value at its range's bound, within its errors of
    /// none, or no better than the model without it).
    #[serde(default)]
    pub significant: bool,
    /// When not: the runs (or the print's characterisation) that would.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub separate_with: Option<String>,
}

/// What a calibration identified, with the discrepancy of the baseline and of the card's model on
/// the calibration's own runs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraCard {
    /// The significance threshold in standard errors, and the false-alarm rate it keeps.
    pub z_significant: f64,
    pub false_alarm_rate: f64,
    pub geometry: Vec<CardEffect>,
    /// Geometric terms these runs cannot tell apart from the others (not fitted).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub not_identifiable: Vec<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stage: Option<StageMap>,
    pub imaging: Vec<ImagingEntry>,
    /// The model diagnosed, and its discrepancy with its standard error, px.
    pub baseline_model: String,
    pub baseline_px: f64,
    pub baseline_se_px: f64,
    /// The card's model (the rounds' non-geometric verdicts, the significant geometry and the
    /// stage's angle when significant).
    pub card_px: f64,
    pub card_se_px: f64,
    /// What the card's model leaves unexplained.
    pub unexplained: Unexplained,
    #[serde(skip)]
    pub model: ModelConfig,
}

impl CameraCard {
    /// The names of the card's significant findings (geometry, then the stage's numbers).
    pub fn found(&self) -> Vec<String> {
        let geometry = self
            .geometry
            .iter()
            .filter(|g| g.significant)
            .map(|g| g.effect.to_string());
        let stage = self
            .stage
            .iter()
            .flat_map(|s| s.significant.iter().map(|n| format!("stage {n}")));
        geometry.chain(stage).collect()
    }
}

/// Reads the dataset in `dir`, diagnoses `model` against it in up to `rounds` rounds and writes
/// the card (its model named `name` and its hash).
pub fn calibrate(
    dir: &std::path::Path,
    model: &ModelConfig,
    options: &super::CompareOptions,
    rounds: usize,
    name: &str,
    progress: Progress,
) -> Result<(Rounds, CameraCard), DiagnoseError> {
    let meas = super::load_measurement(dir, options, &|_, _| progress(0, 1))?;
    let r = super::diagnose_rounds_prepared(&meas, model, rounds, progress)?;
    let card = camera_card(&meas, &r, name, progress)?;
    Ok((r, card))
}

/// The card of an analysed measurement: the joint geometric fit on the first round's baseline
/// comparison, the stage map, the imaging fits (the naming round's, else the last round's), and
/// the card's model compared with the measurement (twice, for the model's own scatter). The
/// card's model is named `name`, a dash and its content's hash.
pub fn camera_card(
    meas: &Measurement,
    rounds: &Rounds,
    name: &str,
    progress: Progress,
) -> Result<CameraCard, DiagnoseError> {
    let first = rounds.diagnoses.first();
    let before = match first.and_then(|d| d.before.as_ref()) {
        Some(b) => b.clone(),
        None => compare_prepared(meas, &rounds.final_model, progress)?,
    };
    let (samples, setting) = field_samples(meas, &before);
    let (fit, not_identifiable) = joint_fit(&samples, setting.observations);
    let geometry_fit = fit.map(|f| card_geometry(&samples, f, setting.r0, setting.observations));
    let tested = geometry_fit.as_ref().map_or(0, |g| {
        g.linear.params.len()
            + g.centred
                .as_ref()
                .map_or(0, |c| 3 + usize::from(c.k2.is_some()))
    }) + STAGE_NUMBERS;
    let z = crate::stats::normal_upper_quantile(CARD_FALSE_ALARM_RATE / (2.0 * tested as f64));

    let mut effects = rounds.final_model.effects.clone();
    for g in Geometric::ALL {
        take_geometric(&mut effects, &Effects::default(), g);
    }
    let base_effects = effects.clone();
    let mut geometry = Vec::new();
    if let Some(fit) = &geometry_fit {
        for written in write_joint(&fit.linear, &setting, &base_effects) {
            let significant = written
                .params
                .iter()
                .any(|(k, v)| written.stderr.get(k).is_some_and(|se| v.abs() > z * se));
            let id = written.effect.catalogue().expect("a geometric effect");
            if significant {
                let g = Geometric::of(id).expect("a geometric effect");
                take_geometric(&mut effects, &written.effects, g);
            }
            geometry.push(CardEffect {
                effect: id,
                params: written.params,
                stderr: written.stderr,
                derived: written.geometric.derived,
                notes: written.geometric.notes,
                significant,
            });
        }
        if let Some(c) = &fit.centred {
            let entry = centred_entry(c, z);
            if entry.significant {
                effects.lens_distortion = Some(LensDistortion {
                    k1: c.k1.0,
                    k2: c.k2.map_or(0.0, |k| k.0),
                    centre_dx_px: c.centre_px[0].0,
                    centre_dy_px: c.centre_px[1].0,
                    ..LensDistortion::radial(0.0)
                });
            }
            geometry.push(entry);
            geometry.sort_by_key(|g| g.effect);
        }
    }
    let stage = geometry_fit
        .as_ref()
        .and_then(|g| stage_map(meas, &samples, g, setting.scale_px_per_mm, z));
    state_stage_angle(&mut effects, stage.as_ref());
    let mut model = ModelConfig {
        name: String::new(),
        description: format!(
            "camera card: {} diagnosed on {}",
            rounds
                .diagnoses
                .first()
                .map_or("the baseline", |d| d.model.name.as_str()),
            meas.manifest.name
        ),
        effects,
    };
    // Names are versions: the card's carries its content's hash, so a new card is a new name.
    model.name = format!("{name}-{}", super::model_version(&model));
    let scene = SceneFrom::Refit(&before.model.nominal);
    let (card_cmp, card_se, left) = judge_card(meas, &model, scene, progress)?;
    let baseline_se_px = first.map_or(before.discrepancy_se_px, |d| d.discrepancy_se_px);
    Ok(CameraCard {
        z_significant: z,
        false_alarm_rate: CARD_FALSE_ALARM_RATE,
        geometry,
        not_identifiable,
        stage,
        imaging: imaging_entries(rounds),
        baseline_model: before.model.name.clone(),
        baseline_px: before.discrepancy_px,
        baseline_se_px,
        card_px: card_cmp.discrepancy_px,
        card_se_px: card_se,
        unexplained: left,
        model,
    })
}

/// Sets `to`'s geometric effect `g` to `from`'s.
fn take_geometric(to: &mut Effects, from: &Effects, g: Geometric) {
    match g {
        Geometric::Rotation => to.rotation = from.rotation,
        Geometric::Scale => to.scale = from.scale,
        Geometric::LensDistortion => to.lens_distortion = from.lens_distortion,
        Geometric::TargetTilt => to.target_tilt = from.target_tilt,
    }
}

/// The distortion about its own centre as a card entry.
fn centred_entry(c: &CentredDistortion, z: f64) -> CardEffect {
    let mut params = BTreeMap::from([
        ("k1".to_string(), c.k1.0),
        ("centre_dx_px".to_string(), c.centre_px[0].0),
        ("centre_dy_px".to_string(), c.centre_px[1].0),
    ]);
    let mut stderr = BTreeMap::from([
        ("k1".to_string(), c.k1.1),
        ("centre_dx_px".to_string(), c.centre_px[0].1),
        ("centre_dy_px".to_string(), c.centre_px[1].1),
    ]);
    if let Some((k2, se)) = c.k2 {
        params.insert("k2".into(), k2);
        stderr.insert("k2".into(), se);
    }
    let significant = [Some(c.k1), c.k2]
        .into_iter()
        .flatten()
        .any(|(v, se)| v.abs() > z * se);
    CardEffect {
        effect: EffectId::LensDistortion,
        params,
        stderr,
        derived: BTreeMap::new(),
        notes: vec!["radial distortion about its own centre (the principal point), fitted by Gauss–Newton; decentring (tangential) distortion about the image centre leaves the same field to first order, which translations alone cannot tell apart".into()],
        significant,
    }
}

/// Blur, pixel aperture and sensor noise: as the round that named one fitted it (the card's model
/// holds that fit, and later rounds no longer offer it as a candidate); otherwise as the last
/// round fitted it, or, where its runs and print could not reveal one, that one without
/// parameters and with what would.
fn imaging_entries(rounds: &Rounds) -> Vec<ImagingEntry> {
    let Some(last) = rounds.diagnoses.last() else {
        return Vec::new();
    };
    [
        EffectId::PsfBlur,
        EffectId::FillFactor,
        EffectId::SensorNoise,
    ]
    .into_iter()
    .filter_map(|effect| {
        let named_in = rounds.diagnoses.iter().rev().find(|d| {
            d.verdict
                .as_ref()
                .is_some_and(|v| v.catalogue() == Some(effect))
        });
        let round = named_in.unwrap_or(last);
        let Some(c) = round
            .candidates
            .iter()
            .find(|c| c.effect.catalogue() == Some(effect))
        else {
            let n = round.not_identifiable.iter().find(|n| n.effect == effect)?;
            return Some(ImagingEntry {
                effect,
                params: BTreeMap::new(),
                stderr: BTreeMap::new(),
                identifiable: false,
                significant: false,
                separate_with: Some(n.runs_to_add.clone()),
            });
        };
        let name = effect.to_string();
        let confounded = round
            .confounded
            .iter()
            .find(|k| k.effects.contains(&name))
            .map(|k| k.separate_with.clone());
        Some(ImagingEntry {
            effect,
            params: c.params.clone(),
            stderr: c.stderr.clone(),
            identifiable: confounded.is_none(),
            significant: c.significant,
            separate_with: confounded,
        })
    })
    .collect()
}

/// The stage's angle, when significant, as the card's model states it: a comparison fits its own
/// stage (`Nominal::render_effects`), but a bench rendered from the card's model (the mock bench
/// of `reproduce --bench-model`, a sweep) moves its target as this stage did.
fn state_stage_angle(effects: &mut Effects, stage: Option<&StageMap>) {
    if let Some(map) = stage.filter(|m| m.significant.iter().any(|k| k == "angle")) {
        effects.stage_misalignment = Some(StageMisalignment {
            angle_rad: map.angle_rad,
        });
    }
}

/// The card's model against the measurement: its comparison (the print calibrated again from
/// `scene`, the baseline's), the discrepancy's standard error (with the scatter of a second
/// rendering) and what it leaves unexplained.
fn judge_card(
    meas: &Measurement,
    model: &ModelConfig,
    scene: SceneFrom<'_>,
    progress: Progress,
) -> Result<(Comparison, f64, Unexplained), DiagnoseError> {
    let seed = meas.options.seed;
    let first = compare_with_scene(meas, model, seed, scene, progress)?;
    let second = compare_with_scene(
        meas,
        model,
        seed.wrapping_add(1),
        SceneFrom::Reuse(&first.model.nominal),
        progress,
    )?;
    let infl = super::bic::inflation(&meas.options.dic);
    let scatter = model_scatter(&first, &second, infl);
    let seed_sd = (first.discrepancy_px - second.discrepancy_px).abs() / std::f64::consts::SQRT_2;
    let se = first.discrepancy_se_px.max(seed_sd);
    let left = unexplained(&first, &meas.options.schemes, &scatter, se, infl);
    Ok((first, se, left))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::test_fields::{candidate, comparison, diagnosis, finding};
    use crate::diagnose::verdict::{Confounded, NotIdentifiable};

    #[test]
    fn a_centred_distortion_is_significant_when_k1_or_k2_passes_z_errors() {
        let centred = |k1: (f64, f64), k2: Option<(f64, f64)>| CentredDistortion {
            k1,
            k2,
            centre_px: [(60.0, 2.0), (-45.0, 2.0)],
        };
        // z = 3: k1 at 5 errors is significant, at 2 is not, unless k2 is (at 4).
        let clear = centred_entry(&centred((1e-3, 2e-4), None), 3.0);
        assert!(clear.significant);
        assert_eq!(clear.effect, EffectId::LensDistortion);
        assert_eq!(
            clear.params,
            BTreeMap::from([
                ("k1".to_string(), 1e-3),
                ("centre_dx_px".to_string(), 60.0),
                ("centre_dy_px".to_string(), -45.0)
            ])
        );
        assert_eq!(clear.stderr["centre_dy_px"], 2.0);
        assert!(!centred_entry(&centred((1e-3, 5e-4), None), 3.0).significant);
        let with_k2 = centred_entry(&centred((1e-3, 5e-4), Some((-4e-4, 1e-4))), 3.0);
        assert!(with_k2.significant);
        assert_eq!((with_k2.params["k2"], with_k2.stderr["k2"]), (-4e-4, 1e-4));
    }

    #[test]
    fn the_imaging_entries_are_the_naming_rounds_else_the_last_with_what_confounds_them() {
        let before = comparison(Vec::new());
        // Round 1 names the noise; the model then holds it, and round 2 no longer offers it.
        let first = diagnosis(
            &before,
            vec![
                candidate(EffectId::SensorNoise, &[("gain", 2.0, 0.1)], -30.0, 0.001),
                candidate(EffectId::PsfBlur, &[("sigma_px", 1.5, 0.1)], -12.0, 0.0),
            ],
            Some(EffectId::SensorNoise.into()),
        );
        let mut last = diagnosis(
            &before,
            vec![
                candidate(
                    EffectId::Rotation,
                    &[("angle_rad", 1e-4, 1e-6)],
                    -50.0,
                    0.01,
                ),
                candidate(EffectId::PsfBlur, &[("sigma_px", 0.8, 0.05)], -20.0, 0.001),
            ],
            None,
        );
        last.confounded.push(Confounded {
            effects: ["psf_blur".into(), "fill_factor".into()],
            separate_with: "a step series".into(),
            evidence: "design".into(),
        });
        last.not_identifiable.push(NotIdentifiable {
            effect: EffectId::FillFactor,
            reason: "the print is calibrated".into(),
            runs_to_add: "a characterised print".into(),
        });
        let rounds = Rounds {
            rounds: Vec::new(),
            verdicts: vec![EffectId::SensorNoise.into()],
            final_discrepancy_px: 0.0,
            final_unexplained: finding(0.0, None),
            runs_to_separate: Vec::new(),
            final_model: ModelConfig::default(),
            diagnoses: vec![first, last],
        };
        let entries = imaging_entries(&rounds);
        let summary: Vec<(EffectId, Option<f64>, bool, Option<&str>)> = entries
            .iter()
            .map(|e| {
                let value = e.params.values().next().copied();
                (e.effect, value, e.identifiable, e.separate_with.as_deref())
            })
            .collect();
        // The blur as fitted, confounded; the aperture not fitted, with what would reveal it.
        assert_eq!(
            summary,
            vec![
                (EffectId::PsfBlur, Some(0.8), false, Some("a step series")),
                (
                    EffectId::FillFactor,
                    None,
                    false,
                    Some("a characterised print")
                ),
                (EffectId::SensorNoise, Some(2.0), true, None),
            ]
        );
        assert_eq!(entries[0].stderr["sigma_px"], 0.05);
        // The blur's significance as the last round judged it; the noise as the round that named it.
        let significant: Vec<bool> = entries.iter().map(|e| e.significant).collect();
        assert_eq!(significant, [true, false, true]);
        let none = Rounds {
            diagnoses: Vec::new(),
            ..rounds
        };
        assert!(imaging_entries(&none).is_empty());
    }

    #[test]
    fn the_card_finds_its_significant_geometry_then_the_stages_numbers() {
        let effect = |effect: EffectId, significant: bool| CardEffect {
            effect,
            params: BTreeMap::new(),
            stderr: BTreeMap::new(),
            derived: BTreeMap::new(),
            notes: Vec::new(),
            significant,
        };
        let stage = StageMap {
            nominal_scale_px_per_mm: 26.0,
            scale_x_px_per_mm: 26.5,
            scale_x_se_px_per_mm: 0.01,
            scale_y_px_per_mm: 26.0,
            scale_y_se_px_per_mm: 0.01,
            angle_rad: 5e-3,
            angle_se_rad: 1e-4,
            skew_rad: 0.0,
            skew_se_rad: 1e-4,
            residual_px: 0.05,
            runs: 6,
            significant: vec!["scale_x".into(), "angle".into()],
        };
        let card = CameraCard {
            z_significant: 3.0,
            false_alarm_rate: CARD_FALSE_ALARM_RATE,
            geometry: vec![
                effect(EffectId::Rotation, false),
                effect(EffectId::Scale, true),
                effect(EffectId::LensDistortion, true),
            ],
            not_identifiable: Vec::new(),
            stage: Some(stage),
            imaging: Vec::new(),
            baseline_model: "baseline".into(),
            baseline_px: 0.01,
            baseline_se_px: 0.001,
            card_px: 0.001,
            card_se_px: 0.001,
            unexplained: finding(0.001, None),
            model: ModelConfig::default(),
        };
        assert_eq!(
            card.found(),
            vec!["scale", "lens_distortion", "stage scale_x", "stage angle"]
        );
        // Taking one geometric effect over changes that one alone.
        let mut to = Effects::default();
        let from = Effects {
            rotation: Some(crate::model::effects::Rotation { angle_rad: 1e-4 }),
            scale: Some(crate::model::effects::Scale { ds: 2e-4 }),
            ..Effects::default()
        };
        take_geometric(&mut to, &from, Geometric::Scale);
        assert_eq!((to.scale, to.rotation), (from.scale, None));
    }
}
