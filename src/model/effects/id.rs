//! The effect vocabulary as a type: every effect a model can hold, its name on the wire (the
//! model TOML's table names, the JSON of comparisons and diagnoses) and its place in the imaging
//! chain. Adding an effect means adding it here; the compiler then finds every `match` that must
//! learn it.

use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// Where in the imaging chain an effect acts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    Geometry,
    Optics,
    Sensor,
    Radiometry,
}

/// One effect of the vocabulary; serialised as its snake_case name (`psf_blur`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EffectId {
    StageMisalignment,
    StageError,
    Rotation,
    Scale,
    LensDistortion,
    TargetTilt,
    PsfBlur,
    FillFactor,
    SensorNoise,
    FixedPattern,
    Quantization,
    Vignetting,
    IlluminationChange,
    MotionBlur,
}

impl EffectId {
    /// Every effect, in vocabulary order (the order of `Effects`' fields).
    pub const ALL: [EffectId; 14] = [
        EffectId::StageMisalignment,
        EffectId::StageError,
        EffectId::Rotation,
        EffectId::Scale,
        EffectId::LensDistortion,
        EffectId::TargetTilt,
        EffectId::PsfBlur,
        EffectId::FillFactor,
        EffectId::SensorNoise,
        EffectId::FixedPattern,
        EffectId::Quantization,
        EffectId::Vignetting,
        EffectId::IlluminationChange,
        EffectId::MotionBlur,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            EffectId::StageMisalignment => "stage_misalignment",
            EffectId::StageError => "stage_error",
            EffectId::Rotation => "rotation",
            EffectId::Scale => "scale",
            EffectId::LensDistortion => "lens_distortion",
            EffectId::TargetTilt => "target_tilt",
            EffectId::PsfBlur => "psf_blur",
            EffectId::FillFactor => "fill_factor",
            EffectId::SensorNoise => "sensor_noise",
            EffectId::FixedPattern => "fixed_pattern",
            EffectId::Quantization => "quantization",
            EffectId::Vignetting => "vignetting",
            EffectId::IlluminationChange => "illumination_change",
            EffectId::MotionBlur => "motion_blur",
        }
    }

    /// The chain position.
    pub fn stage(self) -> Stage {
        use EffectId::*;
        match self {
            StageMisalignment | StageError | Rotation | Scale | LensDistortion | TargetTilt => {
                Stage::Geometry
            }
            PsfBlur | MotionBlur => Stage::Optics,
            FillFactor | SensorNoise | FixedPattern | Quantization => Stage::Sensor,
            Vignetting | IlluminationChange => Stage::Radiometry,
        }
    }
}

impl fmt::Display for EffectId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for EffectId {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        EffectId::ALL
            .into_iter()
            .find(|e| e.as_str() == s)
            .ok_or_else(|| format!("unknown effect '{s}'"))
    }
}

/// A verdict's name: the effect's, or `none`.
pub fn verdict_name(verdict: Option<EffectId>) -> &'static str {
    verdict.map_or(verdict_serde::NONE, EffectId::as_str)
}

/// Effect names joined with `separator` (`rotation, scale`).
pub fn join(effects: &[EffectId], separator: &str) -> String {
    effects
        .iter()
        .map(|e| e.as_str())
        .collect::<Vec<_>>()
        .join(separator)
}

/// A diagnosis' verdict on the wire: the effect's name, or `"none"`.
pub mod verdict_serde {
    use super::EffectId;
    use serde::{Deserialize, Deserializer, Serializer};

    pub const NONE: &str = "none";

    pub fn serialize<S: Serializer>(v: &Option<EffectId>, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(v.map_or(NONE, EffectId::as_str))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<EffectId>, D::Error> {
        let text = String::deserialize(d)?;
        if text == NONE {
            Ok(None)
        } else {
            text.parse().map(Some).map_err(serde::de::Error::custom)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_match_serde() {
        for e in EffectId::ALL {
            assert_eq!(e.as_str().parse::<EffectId>(), Ok(e));
            assert_eq!(
                serde_json::to_value(e).unwrap(),
                serde_json::json!(e.as_str())
            );
        }
        assert!("none".parse::<EffectId>().is_err());
    }
}
