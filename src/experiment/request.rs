//! An experiment as a client asks for it (`POST /experiments`, `ffdic reproduce`): every field
//! defaults to the paper's study, so `{}` runs it. Validation names the offending field, so the
//! API can answer 422 with it.

use super::spec::{ExperimentSpec, MoveSpec, PatternSpec, StepSeries};
use crate::dic::DicSettings;
use crate::model::SpecklePattern;
use crate::reduce::Scheme;
use serde::{Deserialize, Serialize};

/// A reduction scheme by preset name (`ff100`, `ff50`, `ff25`) or spelled out per axis.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum SchemeSpec {
    Preset(String),
    Custom(Scheme),
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields, default)]
pub struct ExperimentRequest {
    pub name: String,
    /// Speckle targets: presets `a`, `b`, `c` or full descriptions. A bench without a target
    /// changer (real hardware) takes exactly one: the target mounted by hand.
    #[schema(value_type = Vec<Object>)]
    pub patterns: Vec<PatternSpec>,
    /// Stage moves from the reference position, mm.
    #[schema(value_type = Vec<Object>)]
    pub moves: Vec<MoveSpec>,
    /// Sub-pixel step series: `count` moves of k·step for k = 1..=count.
    #[schema(value_type = Vec<Object>)]
    pub step_series: Vec<StepSeries>,
    /// Static frames of the reference position per pattern (noise floor).
    pub repeats: usize,
    /// Frames averaged into each stored frame.
    pub frames_averaged: usize,
    /// Extra wait after the stage reports settled, ms.
    pub settle_ms: u64,
    /// Camera exposure for the experiment, µs (`None`: keep the camera's).
    pub exposure_us: Option<f64>,
    #[schema(value_type = Vec<Object>)]
    pub schemes: Vec<SchemeSpec>,
    #[schema(value_type = Object)]
    pub dic: DicSettings,
    /// Seed of the mock bench's speckle layouts.
    pub seed: u64,
}

impl Default for ExperimentRequest {
    fn default() -> Self {
        let paper = ExperimentSpec::paper();
        Self {
            name: paper.name,
            patterns: paper.patterns,
            moves: paper.moves,
            step_series: paper.step_series,
            repeats: paper.repeats,
            frames_averaged: 1,
            settle_ms: 50,
            exposure_us: None,
            schemes: paper.schemes.into_iter().map(SchemeSpec::Preset).collect(),
            dic: paper.dic,
            seed: paper.seed,
        }
    }
}

/// A request that cannot run, with the field to blame.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field}: {reason}")]
pub struct FieldError {
    pub field: String,
    pub reason: String,
}

fn field_error(field: impl Into<String>, reason: impl Into<String>) -> FieldError {
    FieldError {
        field: field.into(),
        reason: reason.into(),
    }
}

/// A checked request: what the runner executes.
#[derive(Clone, Debug)]
pub struct ExperimentPlan {
    pub name: String,
    pub patterns: Vec<SpecklePattern>,
    pub moves: Vec<MoveSpec>,
    pub repeats: usize,
    pub frames_averaged: usize,
    pub settle_ms: u64,
    pub exposure_us: Option<f64>,
    pub schemes: Vec<Scheme>,
    pub dic: DicSettings,
    pub seed: u64,
}

/// Limits that keep one request from occupying the bench for days.
const MAX_MOVES: usize = 200;
const MAX_FRAMES_AVERAGED: usize = 64;
const MAX_REPEATS: usize = 32;

impl ExperimentRequest {
    /// Checks everything that does not need the hardware; `has_target_mount` is whether the
    /// bench can change targets itself.
    pub fn plan(&self, has_target_mount: bool) -> Result<ExperimentPlan, FieldError> {
        if self.name.trim().is_empty() || self.name.len() > 128 {
            return Err(field_error("name", "must be 1 to 128 characters"));
        }
        if self.patterns.is_empty() {
            return Err(field_error("patterns", "at least one pattern"));
        }
        if !has_target_mount && self.patterns.len() != 1 {
            return Err(field_error(
                "patterns",
                "this bench has no target changer: name exactly one pattern, the mounted target",
            ));
        }
        let mut patterns = Vec::new();
        for (i, p) in self.patterns.iter().enumerate() {
            patterns.push(match p {
                PatternSpec::Preset(label) => SpecklePattern::preset(label).ok_or_else(|| {
                    field_error(
                        format!("patterns[{i}]"),
                        format!("unknown preset '{label}' (a, b or c)"),
                    )
                })?,
                PatternSpec::Custom(c) => {
                    if !(c.dot_diameter_mm > 0.0 && c.dot_spacing_mm > 0.0) {
                        return Err(field_error(
                            format!("patterns[{i}]"),
                            "dot_diameter_mm and dot_spacing_mm must be positive",
                        ));
                    }
                    c.clone()
                }
            });
        }
        for (i, p) in patterns.iter().enumerate() {
            if patterns[..i].iter().any(|q| q.label == p.label) {
                return Err(field_error(
                    format!("patterns[{i}]"),
                    format!("label '{}' appears twice", p.label),
                ));
            }
        }
        let spec_moves = ExperimentSpec {
            moves: self.moves.clone(),
            step_series: self.step_series.clone(),
            ..ExperimentSpec::paper()
        }
        .all_moves();
        if spec_moves.is_empty() {
            return Err(field_error("moves", "at least one move or step series"));
        }
        if spec_moves.len() > MAX_MOVES {
            return Err(field_error(
                "moves",
                format!("at most {MAX_MOVES} moves in all"),
            ));
        }
        for (i, m) in spec_moves.iter().enumerate() {
            if !(m.dx_mm.is_finite() && m.dy_mm.is_finite()) {
                return Err(field_error(
                    format!("moves[{i}]"),
                    "dx_mm, dy_mm must be finite",
                ));
            }
            if !is_plain_id(&m.id) {
                return Err(field_error(
                    format!("moves[{i}].id"),
                    "letters, digits, '-' and '_' only, at most 64",
                ));
            }
            if spec_moves[..i].iter().any(|o| o.id == m.id) {
                return Err(field_error(
                    format!("moves[{i}].id"),
                    format!("'{}' appears twice", m.id),
                ));
            }
        }
        for (i, p) in patterns.iter().enumerate() {
            if !is_plain_id(&p.label) {
                return Err(field_error(
                    format!("patterns[{i}].label"),
                    "letters, digits, '-' and '_' only, at most 64",
                ));
            }
        }
        if !(1..=MAX_FRAMES_AVERAGED).contains(&self.frames_averaged) {
            return Err(field_error(
                "frames_averaged",
                format!("1 to {MAX_FRAMES_AVERAGED}"),
            ));
        }
        if self.repeats > MAX_REPEATS {
            return Err(field_error("repeats", format!("at most {MAX_REPEATS}")));
        }
        if self.settle_ms > 60_000 {
            return Err(field_error("settle_ms", "at most 60000"));
        }
        if let Some(e) = self.exposure_us {
            if !(e > 0.0 && e.is_finite()) {
                return Err(field_error("exposure_us", "must be positive"));
            }
        }
        if self.schemes.is_empty() {
            return Err(field_error("schemes", "at least one scheme"));
        }
        let mut schemes = Vec::new();
        for (i, s) in self.schemes.iter().enumerate() {
            let scheme = match s {
                SchemeSpec::Preset(name) => Scheme::preset(name),
                SchemeSpec::Custom(c) => Scheme::new(&c.name, c.x, c.y),
            }
            .map_err(|e| field_error(format!("schemes[{i}]"), e.to_string()))?;
            schemes.push(scheme);
        }
        self.dic.validate().map_err(|e| match e {
            crate::dic::DicError::Setting { field, reason } => {
                field_error(format!("dic.{field}"), reason)
            }
            other => field_error("dic", other.to_string()),
        })?;
        Ok(ExperimentPlan {
            name: self.name.clone(),
            patterns,
            moves: spec_moves,
            repeats: self.repeats,
            frames_averaged: self.frames_averaged,
            settle_ms: self.settle_ms,
            exposure_us: self.exposure_us,
            schemes,
            dic: self.dic.clone(),
            seed: self.seed,
        })
    }
}

/// Ids and labels become file names: keep them plain.
fn is_plain_id(s: &str) -> bool {
    !s.is_empty()
        && s.len() <= 64
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_request_is_the_paper() {
        let r: ExperimentRequest = serde_json::from_str("{}").unwrap();
        let p = r.plan(true).unwrap();
        assert_eq!(p.patterns.len(), 3);
        assert_eq!(p.moves.len(), 1);
        assert_eq!(p.moves[0].dx_mm, 5.0);
        assert_eq!(p.schemes.len(), 3);
    }

    #[test]
    fn problems_name_their_field() {
        let bad = |json: &str| {
            serde_json::from_str::<ExperimentRequest>(json)
                .unwrap()
                .plan(true)
                .unwrap_err()
                .field
        };
        assert_eq!(bad(r#"{"patterns":["z"]}"#), "patterns[0]");
        assert_eq!(bad(r#"{"frames_averaged":0}"#), "frames_averaged");
        assert_eq!(bad(r#"{"schemes":["ff7"]}"#), "schemes[0]");
        assert_eq!(bad(r#"{"dic":{"subset_px":40}}"#), "dic.subset");
        assert_eq!(bad(r#"{"moves":[{"id":"../x","dx_mm":1}]}"#), "moves[0].id");
        let one_target = serde_json::from_str::<ExperimentRequest>("{}")
            .unwrap()
            .plan(false)
            .unwrap_err();
        assert_eq!(one_target.field, "patterns");
    }
}
