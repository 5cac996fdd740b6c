//! `ffdic analyze --card NAME|FILE`: the displacements of a pair with what a camera card explains
//! (its lens distortion and the target's tilt) taken off, beside the raw ones
//! (`ffdic::model::GeometryCorrection`).

use super::compare::load_analysis_model;
use anyhow::{bail, Result};
use ffdic::dic::{DicResult, Stats};
use ffdic::model::GeometryCorrection;
use serde_json::json;
use std::path::Path;

/// A card's correction, and the card's name.
pub struct CardCorrection {
    pub name: String,
    correction: Option<GeometryCorrection>,
}

impl CardCorrection {
    /// The card named `given` (a stored model or a TOML file, as `--model` finds it in `data`)
    /// for frames `width` x `height`; a card with a tilt needs the images' scale.
    pub fn load(
        given: &str,
        data: &Path,
        (width, height): (usize, usize),
        scale_px_per_mm: Option<f64>,
    ) -> Result<Self> {
        let model = load_analysis_model(&Some(given.to_string()), data)?;
        if model.effects.target_tilt.is_some() && scale_px_per_mm.is_none() {
            bail!(
                "--card {given} holds a target tilt: give the images' scale (--scale PX_PER_MM) to take it off"
            );
        }
        Ok(Self {
            name: model.name.clone(),
            correction: GeometryCorrection::of(
                &model.effects,
                width,
                height,
                scale_px_per_mm.unwrap_or(1.0),
            ),
        })
    }

    /// Each point's corrected (u, v), NaN where the point is not valid.
    pub fn corrected(&self, result: &DicResult) -> Vec<(f64, f64)> {
        result
            .points
            .iter()
            .map(|p| {
                if !p.status.is_valid() {
                    return (f64::NAN, f64::NAN);
                }
                match &self.correction {
                    Some(c) => c.corrected((p.x, p.y), (p.u, p.v)),
                    None => (p.u, p.v),
                }
            })
            .collect()
    }

    /// The corrected fields' statistics (u, v).
    pub fn stats(&self, result: &DicResult) -> (Stats, Stats) {
        let uv = self.corrected(result);
        (
            Stats::of(uv.iter().map(|p| p.0)),
            Stats::of(uv.iter().map(|p| p.1)),
        )
    }

    /// The summary's lines: the corrected u and v, and how far each departs from a rigid move
    /// (its std) against the raw one's.
    pub fn text(&self, result: &DicResult) -> String {
        let (u, v) = self.stats(result);
        let raw = &result.summary;
        format!(
            "card {}: corrected u mean {:.5} std {:.5} px (raw std {:.5}); v mean {:.5} std {:.5} px (raw std {:.5})\n",
            self.name, u.mean, u.std, raw.u.std, v.mean, v.std, raw.v.std
        )
    }

    pub fn json(&self, result: &DicResult) -> serde_json::Value {
        let (u, v) = self.stats(result);
        json!({ "model": self.name, "u": u, "v": v })
    }
}
