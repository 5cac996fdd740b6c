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

    /// Whether the effect acts only between the reference and a moved frame — the stage's
    /// move and landing, the print turning or magnified with the move, the light changing, the
    /// exposure smeared by a stage still moving — and so leaves the reference frame as the model
    /// without it renders it ([`super::Effects::reference_part`]).
    pub fn leaves_the_reference(self) -> bool {
        use EffectId::*;
        match self {
            StageMisalignment | StageError | Rotation | Scale | IlluminationChange | MotionBlur => {
                true
            }
            LensDistortion | TargetTilt | PsfBlur | FillFactor | SensorNoise | FixedPattern
            | Quantization | Vignetting => false,
        }
    }

    /// Whether the effect leaves the print's image at the scale of its dots as it was, so that a
    /// print calibrated without it holds with it, its white level and contrast matched again
    /// ([`super::Effects::print_image`]): noise the sensor adds to what it reads out (the shot
    /// and read noise, a fixed pattern, the ADC's steps), or a shading smooth over the field
    /// (vignetting: a fall from the centre to the corners, under which each dot's neighbourhood
    /// is lit evenly; checked up to a fall of 30 %, docs/performance.md). A print's sizes are
    /// read from the spectral shape of its reference crop (`diagnose::print`: each line's
    /// spectrum with its own mean removed, against the crop's level), which a smooth shading
    /// leaves but for its lowest frequencies.
    pub fn keeps_the_print(self) -> bool {
        use EffectId::*;
        match self {
            SensorNoise | FixedPattern | Quantization | Vignetting => true,
            StageMisalignment | StageError | Rotation | Scale | LensDistortion | TargetTilt
            | PsfBlur | FillFactor | IlluminationChange | MotionBlur => false,
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

crate::text_enum::text_enum!(EffectId, "effect");

/// What a diagnosis fits and may name: a catalogue effect, or a user effect of the model
/// (`[effects.user.NAME]`) by its name. On the wire, the effect's name or `user.NAME`.
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum CandidateId {
    Catalogue(EffectId),
    User(String),
}

/// The prefix of a user effect's candidate name.
pub const USER_PREFIX: &str = "user.";

impl CandidateId {
    /// The catalogue effect, when it is one.
    pub fn catalogue(&self) -> Option<EffectId> {
        match self {
            CandidateId::Catalogue(e) => Some(*e),
            CandidateId::User(_) => None,
        }
    }
}

impl From<EffectId> for CandidateId {
    fn from(e: EffectId) -> Self {
        CandidateId::Catalogue(e)
    }
}

impl PartialEq<EffectId> for CandidateId {
    fn eq(&self, other: &EffectId) -> bool {
        self.catalogue() == Some(*other)
    }
}

impl fmt::Display for CandidateId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CandidateId::Catalogue(e) => f.write_str(e.as_str()),
            CandidateId::User(name) => write!(f, "{USER_PREFIX}{name}"),
        }
    }
}

impl FromStr for CandidateId {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.strip_prefix(USER_PREFIX) {
            Some(name) if super::user::is_identifier(name) => Ok(CandidateId::User(name.into())),
            Some(_) => Err(format!(
                "'{s}': a user effect's name is letters, digits and '_'"
            )),
            None => s.parse().map(CandidateId::Catalogue),
        }
    }
}

impl Serialize for CandidateId {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for CandidateId {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        String::deserialize(d)?
            .parse()
            .map_err(serde::de::Error::custom)
    }
}

/// A verdict's name: the effect's, or `none`.
pub fn verdict_name(verdict: &Option<CandidateId>) -> String {
    verdict
        .as_ref()
        .map_or_else(|| verdict_serde::NONE.to_string(), ToString::to_string)
}

/// Names joined with `separator` (`rotation, scale`, `scale, user.bow`).
pub fn join<T: fmt::Display>(effects: &[T], separator: &str) -> String {
    effects
        .iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join(separator)
}

/// A diagnosis' verdict on the wire: the effect's name, or `"none"`.
pub mod verdict_serde {
    use super::CandidateId;
    use serde::{Deserialize, Deserializer, Serializer};

    pub const NONE: &str = "none";

    pub fn serialize<S: Serializer>(v: &Option<CandidateId>, s: S) -> Result<S::Ok, S::Error> {
        match v {
            Some(c) => s.collect_str(c),
            None => s.serialize_str(NONE),
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<CandidateId>, D::Error> {
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

    #[test]
    fn candidates_are_catalogue_names_or_user_dot_name() {
        for c in [
            CandidateId::Catalogue(EffectId::TargetTilt),
            CandidateId::User("bow".into()),
        ] {
            let text = serde_json::to_string(&c).unwrap();
            assert_eq!(serde_json::from_str::<CandidateId>(&text).unwrap(), c);
        }
        assert_eq!(CandidateId::User("bow".into()).to_string(), "user.bow");
        assert!("user.".parse::<CandidateId>().is_err());
        assert!("user.2x".parse::<CandidateId>().is_err());
        assert!(CandidateId::Catalogue(EffectId::Scale) == EffectId::Scale);
        assert!(CandidateId::User("scale".into()) != EffectId::Scale);
    }
}
