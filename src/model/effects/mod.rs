//! The effect vocabulary of DESIGN.md: one physical mechanism per file, with named parameters
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
pub use vignetting::Vignetting;

pub use id::{join as join_effects, verdict_name, verdict_serde, EffectId, Stage};
use serde::{Deserialize, Serialize};

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
}

impl Effects {
    /// The enabled effects, in vocabulary order.
    pub fn enabled(&self) -> Vec<EffectId> {
        let on = [
            self.stage_misalignment.is_some(),
            self.stage_error.is_some(),
            self.rotation.is_some(),
            self.scale.is_some(),
            self.lens_distortion.is_some(),
            self.psf_blur.is_some(),
            self.fill_factor.is_some(),
            self.sensor_noise.is_some(),
            self.fixed_pattern.is_some(),
            self.quantization.is_some(),
            self.vignetting.is_some(),
            self.illumination_change.is_some(),
            self.motion_blur.is_some(),
        ];
        EffectId::ALL
            .into_iter()
            .zip(on)
            .filter_map(|(id, on)| on.then_some(id))
            .collect()
    }
}
