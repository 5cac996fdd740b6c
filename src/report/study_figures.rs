//! The paper's Figures 5 and 6 from a study: terminal tables, CSV, JSON and SVG bar charts.
//! Shared by `ffdic reproduce`, the experiment runner and the API (through
//! `experiment::study_files`), so all show the same numbers.

use super::{csv, text_table, BarChart, Series};
use crate::dic::{BLOCK_PER_CORRELATION_LENGTH, MIN_BLOCKS};
use crate::study::{Increase, IncreaseInterval, StudyRow};
use serde_json::json;

/// `{"rows":[{"pattern","scheme","u":{"mean","std"},...}]}` as the issue specifies.
pub fn rows_json(rows: &[StudyRow]) -> serde_json::Value {
    let ms = |s: &crate::dic::Stats| json!({"mean": s.mean, "std": s.std, "ci95": s.std_ci95});
    json!({
        "rows": rows.iter().map(|r| (r, json!({
            "run": r.run,
            "pattern": r.pattern,
            "scheme": r.scheme,
            "fill_factor": [r.fill_factor.0, r.fill_factor.1],
            "valid": r.summary.valid,
            "points": r.summary.points,
            "u": ms(&r.summary.u), "v": ms(&r.summary.v),
            "exx": ms(&r.summary.exx), "eyy": ms(&r.summary.eyy), "exy": ms(&r.summary.exy),
            "increase_pct": r.increase_pct,
            "increase_ci95": r.increase_ci95,
            "repeats": r.repeats,
            "expected_px": r.expected_px,
            "bias_px": r.bias_px(),
        }))).map(|(r, mut row)| {
            // Only a study given a camera card has the corrected displacement.
            if let Some(c) = &r.card {
                row["card"] = json!({
                    "model": c.model, "u": ms(&c.u), "v": ms(&c.v), "bias_px": r.card_bias_px(),
                });
            }
            row
        }).collect::<Vec<_>>()
    })
}

/// `results/study.json`: the rows (pooled over captures), and with repeats every capture's own
/// rows under `"captures"`.
pub fn study_json(rows: &[StudyRow], captures: &[StudyRow]) -> serde_json::Value {
    let mut doc = rows_json(rows);
    if rows.iter().any(|r| r.repeats > 1) {
        doc["captures"] = rows_json(captures)["rows"].take();
    }
    doc
}

/// One reported statistic: its label with units, how to read it, and its % increase.
struct Metric {
    label: &'static str,
    value: fn(&StudyRow) -> f64,
    /// The 95 % interval of `value`.
    ci: fn(&StudyRow) -> [f64; 2],
    scale: f64,
    increase: fn(&Increase) -> f64,
    increase_ci: fn(&IncreaseInterval) -> [f64; 2],
}

impl Metric {
    /// The 95 % interval of the increase of row `r`, when it has a finite one.
    fn increase_interval(&self, r: &StudyRow) -> Option<[f64; 2]> {
        r.increase_ci95
            .map(|c| (self.increase_ci)(&c))
            .filter(|[lo, hi]| lo.is_finite() && hi.is_finite())
    }

    /// "+16.9 % [+8.1, +25.3]", with "n.s." when the interval holds 0 (no significant change).
    fn increase_text(&self, r: &StudyRow) -> Option<String> {
        let i = r.increase_pct?;
        let mut text = format!("{:+.1} %", (self.increase)(&i));
        if let Some([lo, hi]) = self.increase_interval(r) {
            text += &format!(" [{lo:+.1}, {hi:+.1}]{}", not_significant_mark([lo, hi]));
        }
        Some(text)
    }

    /// The bar label: the increase, and "n.s." when its interval holds 0.
    fn bar_label(&self, r: &StudyRow) -> Option<String> {
        let i = r.increase_pct?;
        let mark = self.increase_interval(r).map_or("", not_significant_mark);
        Some(format!("{:+.1} %{mark}", (self.increase)(&i)))
    }
}

/// " n.s." when an interval of an increase holds 0: no significant change.
fn not_significant_mark([lo, hi]: [f64; 2]) -> &'static str {
    if lo <= 0.0 && hi >= 0.0 {
        " n.s."
    } else {
        ""
    }
}

const STD_U: Metric = Metric {
    label: "std(u) [px]",
    value: |r| r.summary.u.std,
    ci: |r| r.summary.u.std_ci95,
    scale: 1.0,
    increase: |i| i.u,
    increase_ci: |c| c.u,
};
const STD_V: Metric = Metric {
    label: "std(v) [px]",
    value: |r| r.summary.v.std,
    ci: |r| r.summary.v.std_ci95,
    scale: 1.0,
    increase: |i| i.v,
    increase_ci: |c| c.v,
};
const STD_EXX: Metric = Metric {
    label: "std(exx) [µε]",
    value: |r| r.summary.exx.std,
    ci: |r| r.summary.exx.std_ci95,
    scale: 1e6,
    increase: |i| i.exx,
    increase_ci: |c| c.exx,
};
const STD_EYY: Metric = Metric {
    label: "std(eyy) [µε]",
    value: |r| r.summary.eyy.std,
    ci: |r| r.summary.eyy.std_ci95,
    scale: 1e6,
    increase: |i| i.eyy,
    increase_ci: |c| c.eyy,
};
const STD_EXY: Metric = Metric {
    label: "std(exy) [µε]",
    value: |r| r.summary.exy.std,
    ci: |r| r.summary.exy.std_ci95,
    scale: 1e6,
    increase: |i| i.exy,
    increase_ci: |c| c.exy,
};

/// Figures 5 and 6 (and the shear) as terminal tables.
pub fn figures_text(rows: &[StudyRow]) -> String {
    let table = |title: &str, metrics: &[&Metric]| {
        let mut headers = vec!["pattern", "scheme"];
        for m in metrics {
            headers.push(m.label);
            headers.push("Δ vs 100 %");
        }
        let body: Vec<Vec<String>> = rows
            .iter()
            .map(|r| {
                let mut row = vec![r.pattern.clone(), r.scheme.clone()];
                for m in metrics {
                    let v = (m.value)(r) * m.scale;
                    row.push(if m.scale == 1.0 {
                        format!("{v:.5}")
                    } else {
                        format!("{v:.1}")
                    });
                    row.push(m.increase_text(r).unwrap_or_else(|| "—".into()));
                }
                row
            })
            .collect();
        format!("\n{title}\n{}", text_table(&headers, &body))
    };
    let mean_u = rows.iter().map(|r| r.summary.u.mean).sum::<f64>() / rows.len().max(1) as f64;
    let mean_v = rows.iter().map(|r| r.summary.v.mean).sum::<f64>() / rows.len().max(1) as f64;
    table("Figure 5 — error of the x translation (std over the ROI)", &[&STD_U, &STD_EXX])
        + &table("Figure 6 — error of the small y component (std over the ROI)", &[&STD_V, &STD_EYY])
        + &table("Shear", &[&STD_EXY])
        + &format!("\nmean motion over all rows: u = {mean_u:.4} px, v = {mean_v:.4} px (reduced images)\n")
        + &interval_footnote(rows)
}

/// What the brackets of the tables mean: over captures when the rows pool repeats, else the
/// block bootstrap of one capture.
fn interval_footnote(rows: &[StudyRow]) -> String {
    let captures = rows.iter().map(|r| r.repeats).min().unwrap_or(1);
    if captures > 1 {
        format!(
            "each row: the mean over {captures} independent captures; […]: its 95 % interval (Student t over the\n\
             captures; the increases paired per capture); n.s.: the interval holds 0, no significant change.\n"
        )
    } else {
        format!(
            "[…]: 95 % interval of the increase, a paired block bootstrap over the grid (one frame pair;\n\
             it runs ≈ 25 % narrow, docs/study.md); n.s.: the interval holds 0, no significant change. No\n\
             interval: the grid holds fewer than {MIN_BLOCKS} blocks of {BLOCK_PER_CORRELATION_LENGTH}x the field's correlation\n\
             length (strains: the virtual strain gauge). `--repeats N` gives intervals over captures.\n"
        )
    }
}

/// The study as CSV, one row per run and scheme.
pub fn study_csv(rows: &[StudyRow]) -> String {
    let headers = [
        "run",
        "pattern",
        "scheme",
        "fill_x",
        "fill_y",
        "valid",
        "points",
        "u_mean",
        "u_std",
        "v_mean",
        "v_std",
        "exx_mean",
        "exx_std",
        "eyy_mean",
        "eyy_std",
        "exy_mean",
        "exy_std",
        "u_std_lo",
        "u_std_hi",
        "v_std_lo",
        "v_std_hi",
        "exx_std_lo",
        "exx_std_hi",
        "eyy_std_lo",
        "eyy_std_hi",
        "exy_std_lo",
        "exy_std_hi",
        "repeats",
        "u_expected",
        "v_expected",
        "u_bias",
        "v_bias",
    ];
    let with_card = rows.iter().any(|r| r.card.is_some());
    let body: Vec<Vec<String>> = rows
        .iter()
        .map(|r| {
            let s = &r.summary;
            vec![
                r.run.clone(),
                r.pattern.clone(),
                r.scheme.clone(),
                r.fill_factor.0.to_string(),
                r.fill_factor.1.to_string(),
                s.valid.to_string(),
                s.points.to_string(),
                s.u.mean.to_string(),
                s.u.std.to_string(),
                s.v.mean.to_string(),
                s.v.std.to_string(),
                s.exx.mean.to_string(),
                s.exx.std.to_string(),
                s.eyy.mean.to_string(),
                s.eyy.std.to_string(),
                s.exy.mean.to_string(),
                s.exy.std.to_string(),
            ]
            .into_iter()
            .chain(
                [s.u, s.v, s.exx, s.eyy, s.exy]
                    .iter()
                    .flat_map(|st| st.std_ci95.map(|v| v.to_string())),
            )
            .chain([r.repeats.to_string()])
            .chain(expected_and_bias(r))
            .chain(with_card.then(|| card_columns(r)).into_iter().flatten())
            .collect()
        })
        .collect();
    let headers: Vec<&str> = headers
        .into_iter()
        .chain(with_card.then_some(CARD_HEADERS).into_iter().flatten())
        .collect();
    csv(&headers, &body)
}

/// The columns of a study analysed with a camera card: the corrected u and v, and their bias
/// against the commanded move.
const CARD_HEADERS: [&str; 7] = [
    "card",
    "u_card_mean",
    "u_card_std",
    "v_card_mean",
    "v_card_std",
    "u_card_bias",
    "v_card_bias",
];

fn card_columns(r: &StudyRow) -> [String; 7] {
    let Some(c) = &r.card else {
        return Default::default();
    };
    let [bu, bv] = r
        .card_bias_px()
        .map_or([String::new(), String::new()], |b| b.map(|x| x.to_string()));
    [
        c.model.clone(),
        c.u.mean.to_string(),
        c.u.std.to_string(),
        c.v.mean.to_string(),
        c.v.std.to_string(),
        bu,
        bv,
    ]
}

/// `u_expected`, `v_expected`, `u_bias`, `v_bias` of a row (px of its scheme); empty where the
/// row has no commanded move recorded.
fn expected_and_bias(r: &StudyRow) -> [String; 4] {
    match (r.expected_px, r.bias_px()) {
        (Some([u, v]), Some([bu, bv])) => [u, v, bu, bv].map(|x| x.to_string()),
        _ => Default::default(),
    }
}

/// Figures 5 and 6 as SVG bar charts: `(file name, svg)`, the % increase over 100 % above
/// every bar as in the paper.
pub fn figure_svgs(rows: &[StudyRow]) -> Vec<(&'static str, String)> {
    let charts = [
        (
            "figure5_u.svg",
            "Figure 5a — displacement error, x move",
            &STD_U,
        ),
        (
            "figure5_exx.svg",
            "Figure 5b — strain error, x move",
            &STD_EXX,
        ),
        (
            "figure6_v.svg",
            "Figure 6a — displacement error, y component",
            &STD_V,
        ),
        (
            "figure6_eyy.svg",
            "Figure 6b — strain error, y component",
            &STD_EYY,
        ),
    ];
    let mut groups: Vec<String> = Vec::new();
    let mut schemes: Vec<String> = Vec::new();
    for r in rows {
        if !groups.contains(&r.pattern) {
            groups.push(r.pattern.clone());
        }
        if !schemes.contains(&r.scheme) {
            schemes.push(r.scheme.clone());
        }
    }
    let mut out = Vec::new();
    for (file, title, metric) in charts {
        let series = schemes
            .iter()
            .map(|scheme| {
                let pick =
                    |g: &String| rows.iter().find(|r| &r.pattern == g && &r.scheme == scheme);
                Series {
                    name: scheme_label(scheme),
                    values: groups
                        .iter()
                        .map(|g| pick(g).map_or(f64::NAN, |r| (metric.value)(r) * metric.scale))
                        .collect(),
                    labels: groups
                        .iter()
                        .map(|g| pick(g).and_then(|r| metric.bar_label(r)))
                        .collect(),
                    errors: groups
                        .iter()
                        .map(|g| pick(g).map(|r| (metric.ci)(r).map(|v| v * metric.scale)))
                        .collect(),
                }
            })
            .collect();
        let chart = BarChart {
            title: title.to_string(),
            y_label: metric.label.to_string(),
            groups: groups.iter().map(|g| format!("pattern {g}")).collect(),
            series,
        };
        out.push((file, chart.to_svg(720, 420)));
    }
    out
}

fn scheme_label(name: &str) -> String {
    match name {
        "ff100" => "100 % (2x2 binned)".into(),
        "ff50" => "50 % (rows binned, columns subsampled)".into(),
        "ff25" => "25 % (subsampled)".into(),
        other => other.into(),
    }
}
