//! A camera card as a person reads it: one row per number with its standard error and whether it
//! is significant, the stage's map, the imaging chain, and the discrepancy the card leaves.

use super::{length_pm, parameters_text, text_table, value_pm};
use crate::diagnose::{CameraCard, StageMap};

/// The card as text (the CLI's `calibrate` and the job's `results/card.txt`).
pub fn camera_card_text(card: &CameraCard) -> String {
    let z = card.z_significant;
    let mark = |v: f64, se: f64| if v.abs() > z * se { "yes" } else { "no" };
    let mut rows: Vec<Vec<String>> = Vec::new();
    for g in &card.geometry {
        for (name, v) in &g.params {
            let se = g.stderr.get(name).copied().unwrap_or(f64::NAN);
            rows.push(vec![
                g.effect.to_string(),
                name.clone(),
                value_pm(*v, se),
                mark(*v, se).into(),
            ]);
        }
    }
    if let Some(s) = &card.stage {
        rows.extend(stage_rows(s));
    }
    let mut out = format!(
        "camera card {} (significant: beyond {z:.2} SE, {:.0} % family-wise false alarms)\n",
        card.model.name,
        100.0 * card.false_alarm_rate
    );
    out += &text_table(&["effect", "parameter", "value ± SE", "significant"], &rows);
    if let Some(s) = &card.stage {
        out += &format!(
            "stage: against the nominal {:.4} px/mm; {} runs scatter {:.4} px about the map (the stage is the length standard: its travel error and the camera's scale are one number)\n",
            s.nominal_scale_px_per_mm, s.runs, s.residual_px
        );
    } else {
        out += "stage: not mapped (moves along both axes, at least three runs, are needed)\n";
    }
    for g in &card.geometry {
        for (name, v) in &g.derived {
            out += &format!("{}: {name} = {v:.4}\n", g.effect);
        }
        for note in &g.notes {
            out += &format!("{}: {note}\n", g.effect);
        }
    }
    for n in &card.not_identifiable {
        out += &format!("not fitted: {n}\n");
    }
    for i in &card.imaging {
        let mut params = parameters_text(&i.params, &i.stderr);
        if !i.significant && !i.params.is_empty() {
            params += " (not significant)";
        }
        match &i.separate_with {
            None => out += &format!("{}: {params}\n", i.effect),
            Some(how) if i.params.is_empty() => {
                out += &format!(
                    "{}: not identifiable with these runs and this print, not fitted; add {how}\n",
                    i.effect
                )
            }
            Some(how) => {
                out += &format!(
                    "{}: not identifiable with these runs ({params}); separate it with {how}\n",
                    i.effect
                )
            }
        }
    }
    let found = card.found();
    out += &format!(
        "found: {}\ndiscrepancy: baseline {} {} px → card {} px\nleft unexplained: {}\n",
        if found.is_empty() {
            "nothing significant".to_string()
        } else {
            found.join(", ")
        },
        card.baseline_model,
        length_pm(card.baseline_px, card.baseline_se_px),
        length_pm(card.card_px, card.card_se_px),
        card.unexplained.summary
    );
    out
}

/// The stage map's rows; which numbers are significant is the map's own finding
/// (`StageMap::significant`).
fn stage_rows(s: &StageMap) -> Vec<Vec<String>> {
    [
        (
            "scale_x_px_per_mm",
            "scale_x",
            s.scale_x_px_per_mm,
            s.scale_x_se_px_per_mm,
        ),
        (
            "scale_y_px_per_mm",
            "scale_y",
            s.scale_y_px_per_mm,
            s.scale_y_se_px_per_mm,
        ),
        ("angle_rad", "angle", s.angle_rad, s.angle_se_rad),
        ("skew_rad", "skew", s.skew_rad, s.skew_se_rad),
    ]
    .into_iter()
    .map(|(name, test, v, se)| {
        let significant = s.significant.iter().any(|n| n == test);
        vec![
            "stage".into(),
            name.into(),
            value_pm(v, se),
            if significant { "yes" } else { "no" }.into(),
        ]
    })
    .collect()
}
