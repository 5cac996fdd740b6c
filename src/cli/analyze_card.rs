//! `ffdic analyze --card NAME|FILE`: the displacements of a pair with what a camera card explains
//! (its lens distortion and the target's tilt) taken off, beside the raw ones
//! ([`ffdic::study::CardCorrection`], which the API's analyses use too).

use super::compare::load_analysis_model;
use anyhow::{bail, Result};
use ffdic::dic::DicResult;
use ffdic::model::GeometryCorrection;
use ffdic::study::CardCorrection;
use serde_json::json;
use std::path::Path;

/// The card named `given` (a stored model or a TOML file, as `--model` finds it in `data`) for
/// frames `width` x `height`; a card with a tilt needs the images' scale.
pub fn load_card(
    given: &str,
    data: &Path,
    (width, height): (usize, usize),
    scale_px_per_mm: Option<f64>,
) -> Result<CardCorrection> {
    let model = load_analysis_model(&Some(given.to_string()), data)?;
    if model.effects.target_tilt.is_some() && scale_px_per_mm.is_none() {
        bail!(
            "--card {given} holds a target tilt: give the images' scale (--scale PX_PER_MM) to take it off"
        );
    }
    Ok(CardCorrection {
        model: model.name.clone(),
        correction: GeometryCorrection::of(
            &model.effects,
            width,
            height,
            scale_px_per_mm.unwrap_or(1.0),
        ),
    })
}

/// The summary's lines: the corrected u and v, and how far each departs from a rigid move (its
/// std) against the raw one's.
pub fn card_text(card: &CardCorrection, result: &DicResult) -> String {
    let c = card.stats(None, &result.points);
    let raw = &result.summary;
    format!(
        "card {}: corrected u mean {:.5} std {:.5} px (raw std {:.5}); v mean {:.5} std {:.5} px (raw std {:.5})\n",
        c.model, c.u.mean, c.u.std, raw.u.std, c.v.mean, c.v.std, raw.v.std
    )
}

pub fn card_json(card: &CardCorrection, result: &DicResult) -> serde_json::Value {
    let c = card.stats(None, &result.points);
    json!({ "model": c.model, "u": c.u, "v": c.v })
}
