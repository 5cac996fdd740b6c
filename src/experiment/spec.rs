//! An experiment file (`config/experiments/*.toml`): what to capture and how to analyse it.
//! Unknown keys are refused with the key named.

use crate::dic::DicSettings;
use crate::model::{Camera, SpecklePattern};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExperimentSpec {
    pub name: String,
    #[serde(default)]
    pub seed: u64,
    pub camera: Camera,
    pub patterns: Vec<PatternSpec>,
    #[serde(default)]
    pub moves: Vec<MoveSpec>,
    /// Sub-pixel step series: `count` moves of k·step for k = 1..=count.
    #[serde(default)]
    pub step_series: Vec<StepSeries>,
    /// Static frames of the reference position per pattern and capture (noise floor).
    #[serde(default)]
    pub static_frames: usize,
    /// Independent captures of every reference/deformed pair (see `ExperimentRequest::repeats`).
    #[serde(default = "one")]
    pub repeats: usize,
    /// A new speckle layout for every capture (mock bench and simulation).
    #[serde(default)]
    pub new_layout_per_repeat: bool,
    /// Reduction schemes by name (`ff100`, `native`, `2x2/1x2`, …; see `Scheme::parse`).
    #[serde(default = "default_schemes")]
    pub schemes: Vec<String>,
    #[serde(default)]
    pub dic: DicSettings,
}

fn one() -> usize {
    1
}

fn default_schemes() -> Vec<String> {
    vec!["ff100".into(), "ff50".into(), "ff25".into()]
}

/// A paper preset by label, or a full pattern description.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum PatternSpec {
    Preset(String),
    Custom(SpecklePattern),
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MoveSpec {
    pub id: String,
    pub dx_mm: f64,
    #[serde(default)]
    pub dy_mm: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StepSeries {
    pub id: String,
    #[serde(default)]
    pub dx_step_mm: f64,
    #[serde(default)]
    pub dy_step_mm: f64,
    pub count: usize,
}

#[derive(Debug, thiserror::Error)]
pub enum SpecError {
    #[error("cannot read experiment {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("experiment {path}: {message}")]
    Parse { path: PathBuf, message: String },
}

/// The paper's study, embedded so `reproduce` needs no file.
pub const PAPER_TOML: &str = include_str!("../../config/experiments/paper.toml");

impl ExperimentSpec {
    pub fn from_toml(text: &str, origin: &Path) -> Result<Self, SpecError> {
        let parse = |message: String| SpecError::Parse {
            path: origin.to_owned(),
            message,
        };
        let spec: ExperimentSpec =
            toml::from_str(text).map_err(|e| parse(e.message().to_string()))?;
        spec.dic.validate().map_err(|e| parse(e.to_string()))?;
        for p in &spec.patterns {
            if let PatternSpec::Preset(label) = p {
                if SpecklePattern::preset(label).is_none() {
                    return Err(parse(format!(
                        "unknown pattern preset '{label}' (a, b or c)"
                    )));
                }
            }
        }
        if !(1..=32).contains(&spec.repeats) {
            return Err(parse(format!(
                "repeats must be 1 to 32 captures, got {}",
                spec.repeats
            )));
        }
        let min = crate::dic::MIN_FRAME_SIDE_PX;
        if spec.camera.width < min
            || spec.camera.height < min
            || !(spec.camera.scale_px_per_mm > 0.0)
        {
            return Err(parse(format!(
                "camera must be at least {min}x{min} px with a positive scale"
            )));
        }
        Ok(spec)
    }

    pub fn load(path: &Path) -> Result<Self, SpecError> {
        let text = std::fs::read_to_string(path).map_err(|source| SpecError::Read {
            path: path.to_owned(),
            source,
        })?;
        Self::from_toml(&text, path)
    }

    /// The embedded paper study.
    pub fn paper() -> Self {
        Self::from_toml(PAPER_TOML, Path::new("config/experiments/paper.toml"))
            .expect("embedded spec is valid")
    }

    pub fn patterns(&self) -> Vec<SpecklePattern> {
        self.patterns
            .iter()
            .map(|p| match p {
                PatternSpec::Preset(label) => SpecklePattern::preset(label).expect("validated"),
                PatternSpec::Custom(p) => p.clone(),
            })
            .collect()
    }

    /// Every move: the listed ones, then each step series expanded.
    pub fn all_moves(&self) -> Vec<MoveSpec> {
        let mut moves = self.moves.clone();
        for s in &self.step_series {
            for k in 1..=s.count {
                moves.push(MoveSpec {
                    id: format!("{}{k:02}", s.id),
                    dx_mm: s.dx_step_mm * k as f64,
                    dy_mm: s.dy_step_mm * k as f64,
                });
            }
        }
        moves
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embedded_paper_spec_is_the_paper() {
        let s = ExperimentSpec::paper();
        assert_eq!((s.camera.width, s.camera.height), (2560, 2160));
        assert_eq!(s.camera.scale_px_per_mm, 26.0);
        assert_eq!(s.patterns().len(), 3);
        assert_eq!(s.all_moves()[0].dx_mm, 5.0);
        assert_eq!(s.schemes, vec!["ff100", "ff50", "ff25"]);
        assert_eq!(
            (s.dic.subset_px, s.dic.step_px, s.dic.strain_window),
            (41, 20, 7)
        );
    }

    #[test]
    fn unknown_keys_are_named() {
        let text = PAPER_TOML.replace("static_frames", "static_framez");
        let err = ExperimentSpec::from_toml(&text, Path::new("x.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("static_framez"), "{err}");
    }

    #[test]
    fn step_series_expand() {
        let text =
            format!("{PAPER_TOML}\n[[step_series]]\nid = \"xs\"\ndx_step_mm = 0.002\ncount = 3\n");
        let s = ExperimentSpec::from_toml(&text, Path::new("x.toml")).unwrap();
        let m = s.all_moves();
        assert_eq!(m.len(), 4);
        assert_eq!(m[3].id, "xs03");
        assert!((m[3].dx_mm - 0.006).abs() < 1e-12);
    }
}
