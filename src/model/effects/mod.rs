//! The effect vocabulary: one physical mechanism per file, with named parameters
//! (units in the names) and the physics that applies it. Ids are fixed: they are the TOML table
//! names, the API's and the CLI's words.

mod fill_factor;
mod fixed_pattern;
mod id;
mod illumination_change;
mod lens_distortion;
mod motion_blur;
mod psf_blur;
mod quantization;
mod rotation;
mod scale;
mod sensor_noise;
mod stage_error;
mod stage_misalignment;
mod target_tilt;
pub mod user;
mod vignetting;

pub use fill_factor::FillFactor;
pub use fixed_pattern::FixedPattern;
pub use illumination_change::IlluminationChange;
pub use lens_distortion::LensDistortion;
pub use motion_blur::MotionBlur;
pub use psf_blur::PsfBlur;
pub use quantization::Quantization;
pub use rotation::Rotation;
pub use scale::Scale;
pub use sensor_noise::SensorNoise;
pub use stage_error::StageError;
pub use stage_misalignment::StageMisalignment;
pub use target_tilt::{TargetTilt, MAX_TILT_RAD};
pub use user::{UserEffect, UserKind, UserParam};
pub use vignetting::Vignetting;

pub use id::{join as join_effects, verdict_name, verdict_serde, CandidateId, EffectId, Stage};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The enabled effects of a model; an absent table is an absent effect.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Effects {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stage_misalignment: Option<StageMisalignment>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stage_error: Option<StageError>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rotation: Option<Rotation>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scale: Option<Scale>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lens_distortion: Option<LensDistortion>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub target_tilt: Option<TargetTilt>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub psf_blur: Option<PsfBlur>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fill_factor: Option<FillFactor>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sensor_noise: Option<SensorNoise>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fixed_pattern: Option<FixedPattern>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub quantization: Option<Quantization>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vignetting: Option<Vignetting>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub illumination_change: Option<IlluminationChange>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub motion_blur: Option<MotionBlur>,
    /// Effects the catalogue lacks, written down by the user (`[effects.user.NAME]`), by name.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub user: BTreeMap<String, UserEffect>,
}

impl Effects {
    /// Whether the model holds `effect`: one arm per effect, so a new one cannot be forgotten.
    pub fn has(&self, effect: EffectId) -> bool {
        match effect {
            EffectId::StageMisalignment => self.stage_misalignment.is_some(),
            EffectId::StageError => self.stage_error.is_some(),
            EffectId::Rotation => self.rotation.is_some(),
            EffectId::Scale => self.scale.is_some(),
            EffectId::LensDistortion => self.lens_distortion.is_some(),
            EffectId::TargetTilt => self.target_tilt.is_some(),
            EffectId::PsfBlur => self.psf_blur.is_some(),
            EffectId::FillFactor => self.fill_factor.is_some(),
            EffectId::SensorNoise => self.sensor_noise.is_some(),
            EffectId::FixedPattern => self.fixed_pattern.is_some(),
            EffectId::Quantization => self.quantization.is_some(),
            EffectId::Vignetting => self.vignetting.is_some(),
            EffectId::IlluminationChange => self.illumination_change.is_some(),
            EffectId::MotionBlur => self.motion_blur.is_some(),
        }
    }

    /// The names of what the model holds, as the API and the history list them: the catalogue
    /// effects in vocabulary order, then each user effect as `user.NAME` (`user.NAME (proposed)`
    /// while a parameter has no value).
    pub fn names(&self) -> Vec<String> {
        let catalogue = self.enabled().into_iter().map(|e| e.to_string());
        let user = self.user.iter().map(|(name, e)| {
            let id = CandidateId::User(name.clone());
            if e.is_proposed() {
                format!("{id} (proposed)")
            } else {
                id.to_string()
            }
        });
        catalogue.chain(user).collect()
    }

    /// The user effects with a parameter still without a value: a diagnosis fits them.
    pub fn proposed_user(&self) -> impl Iterator<Item = &String> {
        self.user
            .iter()
            .filter(|(_, e)| e.is_proposed())
            .map(|(name, _)| name)
    }

    /// The enabled effects, in vocabulary order.
    pub fn enabled(&self) -> Vec<EffectId> {
        EffectId::ALL
            .into_iter()
            .filter(|id| self.has(*id))
            .collect()
    }

    /// The effects that act on the reference frame: those acting between the reference and a
    /// moved frame ([`EffectId::leaves_the_reference`]) left out. Two models with the same
    /// reference part render the same reference frame, pixel for pixel, so a print calibrated
    /// against the measured reference under one holds for the other. User effects are left out
    /// too: the renderer applies both kinds (a displacement, an intensity) to moved frames only.
    pub fn reference_part(&self) -> Effects {
        self.part(|id| !id.leaves_the_reference())
    }

    /// The reference part ([`Effects::reference_part`]) without the effects that keep the print
    /// ([`EffectId::keeps_the_print`]): two models with the same print image see the print
    /// alike and differ at most in the noise, the shading and the level the sensor reads out.
    pub fn print_image(&self) -> Effects {
        self.part(|id| !id.leaves_the_reference() && !id.keeps_the_print())
    }

    /// The catalogue effects `keep` names, user effects left out.
    fn part(&self, keep: impl Fn(EffectId) -> bool) -> Effects {
        // Every field named: a new effect's field is a compile error here until it is sorted.
        let Effects {
            stage_misalignment,
            stage_error,
            rotation,
            scale,
            lens_distortion,
            target_tilt,
            psf_blur,
            fill_factor,
            sensor_noise,
            fixed_pattern,
            quantization,
            vignetting,
            illumination_change,
            motion_blur,
            user: _,
        } = self.clone();
        Effects {
            stage_misalignment: stage_misalignment.filter(|_| keep(EffectId::StageMisalignment)),
            stage_error: stage_error.filter(|_| keep(EffectId::StageError)),
            rotation: rotation.filter(|_| keep(EffectId::Rotation)),
            scale: scale.filter(|_| keep(EffectId::Scale)),
            lens_distortion: lens_distortion.filter(|_| keep(EffectId::LensDistortion)),
            target_tilt: target_tilt.filter(|_| keep(EffectId::TargetTilt)),
            psf_blur: psf_blur.filter(|_| keep(EffectId::PsfBlur)),
            fill_factor: fill_factor.filter(|_| keep(EffectId::FillFactor)),
            sensor_noise: sensor_noise.filter(|_| keep(EffectId::SensorNoise)),
            fixed_pattern: fixed_pattern.filter(|_| keep(EffectId::FixedPattern)),
            quantization: quantization.filter(|_| keep(EffectId::Quantization)),
            vignetting: vignetting.filter(|_| keep(EffectId::Vignetting)),
            illumination_change: illumination_change.filter(|_| keep(EffectId::IlluminationChange)),
            motion_blur: motion_blur.filter(|_| keep(EffectId::MotionBlur)),
            user: BTreeMap::new(),
        }
    }
}
