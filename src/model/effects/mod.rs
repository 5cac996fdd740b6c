//! The effect vocabulary of DESIGN.md: one physical mechanism per file, with named parameters
//! (units in the names) and the physics that applies it. Ids are fixed: they are the TOML table
//! names, the API's and the CLI's words.

mod fill_factor;
mod fixed_pattern;
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

use serde::{Deserialize, Serialize};

/// Where in the imaging chain an effect acts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    Geometry,
    Optics,
    Sensor,
    Radiometry,
}

/// Every effect id, in the order of DESIGN.md's table.
pub const EFFECT_IDS: [&str; 13] = [
    "stage_misalignment",
    "stage_error",
    "rotation",
    "scale",
    "lens_distortion",
    "psf_blur",
    "fill_factor",
    "sensor_noise",
    "fixed_pattern",
    "quantization",
    "vignetting",
    "illumination_change",
    "motion_blur",
];

/// The chain position of an effect id.
pub fn stage_of(id: &str) -> Option<Stage> {
    Some(match id {
        "stage_misalignment" | "stage_error" | "rotation" | "scale" | "lens_distortion" => {
            Stage::Geometry
        }
        "psf_blur" | "motion_blur" => Stage::Optics,
        "fill_factor" | "sensor_noise" | "fixed_pattern" | "quantization" => Stage::Sensor,
        "vignetting" | "illumination_change" => Stage::Radiometry,
        _ => return None,
    })
}

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
    /// Ids of the enabled effects, in vocabulary order.
    pub fn enabled(&self) -> Vec<&'static str> {
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
        EFFECT_IDS
            .iter()
            .zip(on)
            .filter_map(|(id, on)| on.then_some(*id))
            .collect()
    }
}
