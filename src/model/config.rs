//! A model file (`config/models/*.toml`): a name and the enabled effects with their parameters.
//! Unknown keys are refused with the key named, so a typo never silently disables an effect.

use super::effects::Effects;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelConfig {
    pub name: String,
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub description: String,
    #[serde(default)]
    pub effects: Effects,
}

#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    #[error("cannot read model {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("model {path}: {message}")]
    Parse { path: PathBuf, message: String },
    #[error("model {name}: {message}")]
    Invalid { name: String, message: String },
}

impl ModelConfig {
    pub fn from_toml(text: &str, origin: &Path) -> Result<Self, ModelError> {
        let model: ModelConfig = toml::from_str(text).map_err(|e| ModelError::Parse {
            path: origin.to_owned(),
            message: e.message().to_string(),
        })?;
        model.validate()?;
        Ok(model)
    }

    pub fn load(path: &Path) -> Result<Self, ModelError> {
        let text = std::fs::read_to_string(path).map_err(|source| ModelError::Read {
            path: path.to_owned(),
            source,
        })?;
        Self::from_toml(&text, path)
    }

    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).expect("a model always serialises")
    }

    /// Checks parameter bounds that TOML types cannot express.
    pub fn validate(&self) -> Result<(), ModelError> {
        let bad = |message: String| {
            Err(ModelError::Invalid {
                name: self.name.clone(),
                message,
            })
        };
        let e = &self.effects;
        // Every parameter finite (TOML can write `nan` and `inf`): one walk over all of them, so
        // an effect added later is covered too.
        if let Some(path) = toml::Value::try_from(e)
            .ok()
            .and_then(|v| non_finite_at(&v, "effects"))
        {
            return bad(format!("{path} must be a finite number"));
        }
        if let Some(s) = e.stage_error {
            if !(s.repeatability_um >= 0.0) {
                return bad("stage_error repeatability_um must be >= 0".into());
            }
        }
        if let Some(f) = e.fill_factor {
            if !(f.fx > 0.0 && f.fx <= 1.0 && f.fy > 0.0 && f.fy <= 1.0) {
                return bad(format!(
                    "fill_factor fx, fy must lie in (0, 1], got {}, {}",
                    f.fx, f.fy
                ));
            }
        }
        if let Some(n) = e.sensor_noise {
            if !(n.gain > 0.0 && n.full_well_e > 0.0 && n.read_noise_e >= 0.0) {
                return bad(
                    "sensor_noise needs gain > 0, full_well_e > 0, read_noise_e >= 0".into(),
                );
            }
        }
        if let Some(q) = e.quantization {
            if !(1..=16).contains(&q.bits) {
                return bad(format!(
                    "quantization bits must lie in 1..=16, got {}",
                    q.bits
                ));
            }
        }
        if let Some(p) = e.psf_blur {
            if !(p.sigma_px >= 0.0) {
                return bad("psf_blur sigma_px must be >= 0".into());
            }
        }
        if let Some(t) = e.target_tilt {
            let max = super::effects::MAX_TILT_RAD;
            if !(t.angle_about_x_rad.abs() <= max && t.angle_about_y_rad.abs() <= max) {
                return bad(format!(
                    "target_tilt angles must lie within ±{max} rad, got {}, {}",
                    t.angle_about_y_rad, t.angle_about_x_rad
                ));
            }
            if !(t.working_distance_mm >= 1.0) {
                return bad("target_tilt working_distance_mm must be >= 1".into());
            }
        }
        for (name, user) in &e.user {
            if !super::effects::user::is_identifier(name) {
                return bad(format!(
                    "user effect '{name}': a name of letters, digits and '_' that starts with a letter"
                ));
            }
            if let Err(message) = user.field() {
                return bad(format!("user effect '{name}' {message}"));
            }
        }
        if let Some(m) = e.motion_blur {
            if !(m.length_px >= 0.0 && m.length_px <= 50.0) {
                return bad("motion_blur length_px must lie in [0, 50]".into());
            }
        }
        Ok(())
    }
}

/// The dotted path of the first non-finite float under `v`.
fn non_finite_at(v: &toml::Value, path: &str) -> Option<String> {
    match v {
        toml::Value::Float(x) if !x.is_finite() => Some(path.to_string()),
        toml::Value::Table(t) => t
            .iter()
            .find_map(|(k, v)| non_finite_at(v, &format!("{path}.{k}"))),
        toml::Value::Array(a) => a
            .iter()
            .enumerate()
            .find_map(|(i, v)| non_finite_at(v, &format!("{path}[{i}]"))),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn non_finite_parameters_are_refused_naming_them() {
        for (table, key, value) in [
            ("rotation", "angle_rad", "nan"),
            ("psf_blur", "sigma_px", "inf"),
            ("illumination_change", "gain", "-inf"),
        ] {
            let text = format!("name = \"m\"\n[effects.{table}]\n{key} = {value}\n");
            let text = if table == "illumination_change" {
                text + "offset = 0.0\n"
            } else {
                text
            };
            let err = ModelConfig::from_toml(&text, Path::new("m.toml"))
                .unwrap_err()
                .to_string();
            assert!(
                err.contains(&format!("effects.{table}.{key}")) && err.contains("finite"),
                "{err}"
            );
        }
        let err = ModelConfig::from_toml(
            "name = \"m\"\n[effects.stage_error]\nrepeatability_um = -1.0\n",
            Path::new("m.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("repeatability_um"), "{err}");
    }

    #[test]
    fn parses_effects_and_refuses_unknown_keys() {
        let m = ModelConfig::from_toml(
            "name = \"m\"\n[effects.psf_blur]\nsigma_px = 0.8\n[effects.stage_misalignment]\nangle_rad = 0.006\n",
            Path::new("m.toml"),
        )
        .unwrap();
        assert_eq!(
            m.effects.enabled(),
            vec![
                crate::model::EffectId::StageMisalignment,
                crate::model::EffectId::PsfBlur
            ]
        );
        let err = ModelConfig::from_toml(
            "name = \"m\"\n[effects.psf_blurr]\nsigma_px = 1\n",
            Path::new("m.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("psf_blurr"), "{err}");
        let err = ModelConfig::from_toml(
            "name = \"m\"\n[effects.psf_blur]\nsigma = 1\n",
            Path::new("m.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("sigma"), "{err}");
    }

    #[test]
    fn round_trips_through_toml() {
        let m = ModelConfig::from_toml(
            "name = \"m\"\n[effects.lens_distortion]\nk1 = -0.01\n[effects.sensor_noise]\nfull_well_e = 30000\nread_noise_e = 1.5\ngain = 0.5\n",
            Path::new("m.toml"),
        )
        .unwrap();
        let back = ModelConfig::from_toml(&m.to_toml(), Path::new("x")).unwrap();
        assert_eq!(m, back);
    }
}
