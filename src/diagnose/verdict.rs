//! The verdict's criteria: what a candidate is, the evidence it shows in, and how it is judged
//! against the model's comparison (ΔBIC, the drop against its standard error, the catalogue's
//! range, what the dataset can separate). The module doc of [`super`] states the criteria.

use super::bic::{chi2, delta_bic, image_change, SIGNIFICANT_DELTA_BIC};
use super::identifiability::DatasetDesign;
pub use super::identifiability::{Confounded, NotIdentifiable};
use super::results::{Comparison, ImageFit, ModelInfo};
use super::unexplained::Unexplained;
use crate::model::effects::UserKind;
use crate::model::{CandidateId, EffectId, Effects, ModelConfig};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

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
    /// A user effect shows where it acts ([`UserKind`]): a displacement field in the
    /// displacements, an intensity field in the image statistics. `effects` holds it (one
    /// that does not, or does not bind, is read as a displacement: it has no fit either way).
    pub fn of_candidate(candidate: &CandidateId, effects: &Effects) -> Self {
        match candidate {
            CandidateId::Catalogue(e) => Self::of(*e),
            CandidateId::User(name) => {
                let field = effects.user.get(name).and_then(|e| e.field().ok());
                match field.map(|f| f.kind()) {
                    Some(UserKind::Intensity) => Evidence::Image,
                    Some(UserKind::Displacement) | None => Evidence::Displacement,
                }
            }
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
    /// The design tells the effect from the print's and the light's own non-uniformity (false
    /// for vignetting under moves below [`VIGNETTING_MOVE_FRACTION`] of the field: see
    /// `Confounded`). Blur and aperture against a print calibrated from the frames are not
    /// candidates at all (`DatasetDesign::not_identifiable`).
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

/// The most a parameter of a fitted effect can be in a camera, where a fit is not bounded by the
/// catalogue's range and the data can ask for what no camera has. The sensor's noise is fitted
/// in closed form from the photon transfer curve: a curve that is flat within its errors gives
/// any gain, and on a control with nothing hidden a slope of zero by chance was named
/// `sensor_noise` with a full well of 8.4e7 e and a read noise of 25,500 e. The largest full
/// wells of scientific sensors (large-pixel CCDs, binned) are some 1e6 e, the worst read noises
/// some 100 e (EMVA 1288 data sheets): twice and ten times those bound what a fit may
/// name.
fn physical_max(effect: EffectId, param: &str) -> Option<f64> {
    use EffectId::*;
    match effect {
        SensorNoise => match param {
            "full_well_e" => Some(2e6),
            "read_noise_e" => Some(1e3),
            _ => None,
        },
        PsfBlur | FillFactor | MotionBlur | StageMisalignment | StageError | Rotation | Scale
        | LensDistortion | TargetTilt | FixedPattern | Quantization | Vignetting
        | IlluminationChange => None,
    }
}

/// The parameters of `fit` beyond what a camera has ([`physical_max`]).
fn beyond_physics(fit: &ImageFit) -> Vec<String> {
    let Some(effect) = fit.effect.catalogue() else {
        return Vec::new();
    };
    fit.params
        .iter()
        .filter_map(|(k, &v)| {
            let max = physical_max(effect, k)?;
            (!(v <= max)).then(|| format!("{k} = {v:.3e} (a camera's at most {max:e})"))
        })
        .collect()
}

pub(super) fn outside_range(fit: &ImageFit) -> Option<String> {
    let beyond = beyond_physics(fit);
    if !beyond.is_empty() {
        return Some(format!(
            "the fit asks for what no camera has: {}; the data do not describe this effect",
            beyond.join(", ")
        ));
    }
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
    /// Beyond its null, but excluded from the verdict whatever its comparison would show (at its
    /// range's bound, or confounded with the light by the design:
    /// [`DesignRules::may_be_named`]): not rendered, its discrepancy the model's and its ΔBIC the
    /// bare parameter penalty, as for `Unchanged`.
    Excluded,
    /// A geometric effect: the model's analyses shifted by the fitted field (first order, no
    /// rendering); the winner is always rendered.
    Predicted,
    /// Rendered and analysed.
    Rendered,
}

/// Everything the criteria of a candidate are judged against.
pub(super) struct Judge<'a> {
    pub(super) before: &'a Comparison,
    pub(super) se_before: f64,
    pub(super) seed_sd: f64,
    pub(super) rules: DesignRules,
    pub(super) dic: &'a crate::dic::DicSettings,
}

/// What the dataset's design leaves unseparable, known before any candidate is compared:
/// vignetting against the print's and the light's own non-uniformity under small moves. (The
/// lens blur and the aperture against a print calibrated from the frames are not fitted at all:
/// [`DatasetDesign::not_identifiable`].)
#[derive(Clone, Copy, Debug)]
pub(super) struct DesignRules {
    /// No translation reaches [`VIGNETTING_MOVE_FRACTION`] of the field.
    pub(super) small_moves: bool,
}

impl DesignRules {
    /// The rules for a dataset of `design`.
    pub(super) fn of(design: &DatasetDesign) -> Self {
        DesignRules {
            small_moves: design.largest_move_fraction < VIGNETTING_MOVE_FRACTION,
        }
    }

    /// Whether the design separates `effect` from the print's (or the light's) own properties.
    pub(super) fn separable(&self, effect: &CandidateId) -> bool {
        !(effect.catalogue() == Some(EffectId::Vignetting) && self.small_moves)
    }

    /// Whether a comparison of the model with `fit` could make it significant: not when its
    /// parameters are within their null, at its range's bound, or confounded by the design (the
    /// criteria that do not read the comparison). A rendered comparison costs seconds at paper
    /// size (the reproduce run's aperture on its calibrated print: 2.3 s of a lane that set the
    /// round's end), and for such a candidate it could only fill in a ΔBIC no verdict reads.
    pub(super) fn may_be_named(&self, fit: &ImageFit) -> bool {
        fit.beyond_null && outside_range(fit).is_none() && self.separable(&fit.effect)
    }
}

/// The smallest translation, as a fraction of the frame width, that tells vignetting (fixed on
/// the sensor) from a non-uniform print or light (moving with the target): below it, both give
/// the same mean-intensity map in every frame.
pub const VIGNETTING_MOVE_FRACTION: f64 = 0.05;

/// What separates vignetting from the print's or the light's own non-uniformity.
pub const ILLUMINATION_SEPARATION: &str = "a flat-field frame of a uniform white target, or a translation of at least 5 % of the field: a sensor-fixed falloff stays where it is while the print's and the light's non-uniformity move with the target";

impl Judge<'_> {
    pub(super) fn candidate(
        &self,
        fit: &ImageFit,
        after: Option<&(Comparison, Method)>,
    ) -> Candidate {
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
                if fit.beyond_null {
                    Method::Excluded
                } else {
                    Method::Unchanged
                },
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
        let evidence = Evidence::of_candidate(&fit.effect, &fit.effects);
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
        let separable_from_print = self.rules.separable(&fit.effect);
        let compared = matches!(method, Method::Predicted | Method::Rendered);
        let criteria = Criteria {
            delta_bic_ok: compared && delta < SIGNIFICANT_DELTA_BIC,
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
            recomputed: compared,
            method,
            criteria,
            derived: fit.geometric.derived.clone(),
            notes: fit.geometric.notes.clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::results::GeometricTerms;

    fn fit(effect: EffectId, params: &[(&str, f64)]) -> ImageFit {
        ImageFit {
            effect: effect.into(),
            params: params.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
            stderr: BTreeMap::new(),
            effects: Effects::default(),
            k: params.len(),
            beyond_null: true,
            geometric: GeometricTerms::default(),
        }
    }

    #[test]
    fn a_candidate_the_design_excludes_is_not_worth_a_rendering() {
        let rules = |small_moves| DesignRules { small_moves };
        let blur = fit(EffectId::PsfBlur, &[("sigma_px", 0.8)]);
        let aperture = fit(EffectId::FillFactor, &[("fx", 0.5), ("fy", 0.8)]);
        let falloff = fit(EffectId::Vignetting, &[("v", 0.1)]);
        // A wide move leaves all three a chance.
        for f in [&blur, &aperture, &falloff] {
            assert!(rules(false).may_be_named(f), "{}", f.effect);
        }
        // Small moves leave the falloff the light's or the print's.
        assert!(!rules(true).may_be_named(&falloff));
        assert!(rules(true).may_be_named(&blur));
        assert!(rules(true).may_be_named(&aperture));
        // Within its null, or at its range's bound: no chance whatever the design.
        let null = ImageFit {
            beyond_null: false,
            ..blur.clone()
        };
        assert!(!rules(false).may_be_named(&null));
        let bound = fit(EffectId::FillFactor, &[("fx", 0.05), ("fy", 0.8)]);
        assert!(!rules(false).may_be_named(&bound));
        // Geometric effects are never the light's.
        assert!(rules(true).may_be_named(&fit(EffectId::Scale, &[("ds", 1e-4)])));
    }

    #[test]
    fn a_fit_at_the_catalogues_bound_is_reported_outside_its_range() {
        // Blur's σ runs to 3 px, the aperture's fill factors down to 0.05.
        assert!(outside_range(&fit(EffectId::PsfBlur, &[("sigma_px", 2.999)])).is_some());
        assert!(outside_range(&fit(EffectId::PsfBlur, &[("sigma_px", 1.2)])).is_none());
        let aperture = fit(EffectId::FillFactor, &[("fx", 0.5), ("fy", 0.05)]);
        let text = outside_range(&aperture).unwrap();
        assert!(text.contains("fy") && !text.contains("fx"), "{text}");
        // An unbounded parameter is never at a bound.
        assert!(outside_range(&fit(EffectId::Scale, &[("ds", 1e9)])).is_none());
    }

    #[test]
    fn a_sensor_no_camera_has_is_outside_the_range() {
        // Control 23 of the 30: gain 1,281 e/DN at 16 bits, read noise 25,500 e.
        let control = [
            ("gain", 1281.0),
            ("read_noise_e", 25_500.0),
            ("full_well_e", 8.4e7),
        ];
        let text = outside_range(&fit(EffectId::SensorNoise, &control)).unwrap();
        assert!(
            text.contains("full_well_e") && text.contains("read_noise_e"),
            "{text}"
        );
        assert!(!text.contains("gain ="), "{text}");
        // An sCMOS camera (gain 0.46 e/DN, 16 bits, read noise 1.5 e) and a large-pixel CCD.
        let scmos = [
            ("gain", 0.46),
            ("read_noise_e", 1.5),
            ("full_well_e", 30_000.0),
        ];
        assert!(outside_range(&fit(EffectId::SensorNoise, &scmos)).is_none());
        let ccd = [
            ("gain", 15.0),
            ("read_noise_e", 12.0),
            ("full_well_e", 9.8e5),
        ];
        assert!(outside_range(&fit(EffectId::SensorNoise, &ccd)).is_none());
    }

    #[test]
    fn every_effect_shows_in_displacements_images_or_either() {
        for e in EffectId::ALL {
            let evidence = Evidence::of(e);
            assert_eq!(
                Evidence::of_candidate(&e.into(), &Effects::default()),
                evidence
            );
        }
        assert_eq!(Evidence::of(EffectId::Vignetting), Evidence::Image);
        assert_eq!(Evidence::of(EffectId::PsfBlur), Evidence::Either);
        assert_eq!(Evidence::of(EffectId::TargetTilt), Evidence::Displacement);
        let mut effects = Effects::default();
        let mut user = |name: &str, text: &str| {
            let effect = toml::from_str(text).expect("a user effect");
            effects.user.insert(name.into(), effect);
        };
        user(
            "wobble",
            "u = \"a * x\"\n[params.a]\nmin = -1.0\nmax = 1.0\n",
        );
        user(
            "lamp",
            "intensity = \"g * x\"\n[params.g]\nmin = -1.0\nmax = 1.0\n",
        );
        let of = |name: &str| Evidence::of_candidate(&CandidateId::User(name.into()), &effects);
        assert_eq!(of("wobble"), Evidence::Displacement);
        assert_eq!(of("lamp"), Evidence::Image);
    }
}
