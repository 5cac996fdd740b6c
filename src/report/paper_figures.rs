//! What the paper states in numbers, beside a study's own: the terminal table `ffdic reproduce`
//! prints under Figures 5 and 6.
//!
//! Hijazi, Rawashdeh & Kähler, *Effect of camera's focal plane array fill factor on digital
//! image correlation measurement accuracy*, § 4. The heights of its bars are in its figures, not
//! its text; the text gives the translation, its y component and pattern (b)'s increase, and
//! those are all that can be set beside a run without reading values off a picture.

use super::text_table;
use crate::study::{Increase, StudyRow};

/// The translation in the paper's reduced images: "about 64 pixels", px.
const PAPER_U_PX: f64 = 64.0;
/// Its vertical component from the stage's misalignment: "about 0.4 pixels", px.
const PAPER_V_PX: f64 = 0.4;
/// Pattern (b)'s "percentage increase of 13.2 % and 19.8 % in the displacement and strain
/// errors" (Figure 5: std of u and of exx against the 100 % fill factor). The text does not say
/// at which fill factor; Figure 5's largest bars are at 25 %.
const PAPER_B_INCREASE_U_PCT: f64 = 13.2;
const PAPER_B_INCREASE_EXX_PCT: f64 = 19.8;

/// The table, or nothing when the study holds neither the paper's reference scheme nor
/// pattern (b) (a study of one's own design).
pub fn paper_figures_text(rows: &[StudyRow]) -> String {
    let reference: Vec<&StudyRow> = rows.iter().filter(|r| r.scheme == "ff100").collect();
    let mut body: Vec<Vec<String>> = Vec::new();
    if !reference.is_empty() {
        let n = reference.len() as f64;
        let mean_u = reference.iter().map(|r| r.summary.u.mean).sum::<f64>() / n;
        let mean_v = reference.iter().map(|r| r.summary.v.mean).sum::<f64>() / n;
        body.push(vec![
            "the x translation, reduced images (ff100)".into(),
            format!("≈ {PAPER_U_PX:.0} px"),
            format!("{mean_u:.2} px (mean u over patterns)"),
        ]);
        body.push(vec![
            "its y component (the stage's misalignment)".into(),
            format!("≈ {PAPER_V_PX:.1} px"),
            format!("{mean_v:.3} px (mean v)"),
        ]);
    }
    for (what, paper, increase) in [
        (
            "pattern b: increase of std u",
            PAPER_B_INCREASE_U_PCT,
            (|i: &Increase| i.u) as fn(&Increase) -> f64,
        ),
        (
            "pattern b: increase of std exx",
            PAPER_B_INCREASE_EXX_PCT,
            |i: &Increase| i.exx,
        ),
    ] {
        let ours: Vec<String> = ["ff50", "ff25"]
            .iter()
            .filter_map(|scheme| {
                let row = rows
                    .iter()
                    .find(|r| r.pattern == "b" && r.scheme == *scheme)?;
                let pct = increase(row.increase_pct.as_ref()?);
                Some(format!("{scheme} {pct:+.1} %"))
            })
            .collect();
        if !ours.is_empty() {
            body.push(vec![
                what.into(),
                format!("{paper:+.1} % (fill factor not stated)"),
                ours.join(", "),
            ]);
        }
    }
    if body.is_empty() {
        return String::new();
    }
    format!(
        "\nThe paper's stated figures beside this run (its bar heights are pictures, not text; intervals above):\n{}",
        text_table(&["the paper (§ 4)", "paper", "this run"], &body)
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dic::{Stats, Summary};

    fn row(pattern: &str, scheme: &str, u_mean: f64, increase_u: Option<f64>) -> StudyRow {
        let one = |v: f64| Stats::of([v]);
        StudyRow {
            run: format!("{pattern}-x5mm"),
            pattern: pattern.into(),
            scheme: scheme.into(),
            fill_factor: (1.0, 1.0),
            summary: Summary {
                points: 1,
                valid: 1,
                u: one(u_mean),
                v: one(0.38),
                exx: one(0.0),
                eyy: one(0.0),
                exy: one(0.0),
            },
            increase_pct: increase_u.map(|u| Increase {
                u,
                v: 0.0,
                exx: 2.0 * u,
                eyy: 0.0,
                exy: 0.0,
            }),
            increase_ci95: None,
            repeats: 1,
            expected_px: None,
            card: None,
        }
    }

    #[test]
    fn the_paper_beside_the_run() {
        let rows = [
            row("a", "ff100", 64.9, None),
            row("b", "ff100", 65.1, None),
            row("b", "ff50", 65.1, Some(3.0)),
            row("b", "ff25", 65.1, Some(10.5)),
        ];
        let text = paper_figures_text(&rows);
        assert!(
            text.contains("≈ 64 px") && text.contains("65.00 px"),
            "{text}"
        );
        assert!(text.contains("0.380 px"), "{text}");
        assert!(
            text.contains("+13.2 %") && text.contains("ff50 +3.0 %, ff25 +10.5 %"),
            "{text}"
        );
        assert!(
            text.contains("+19.8 %") && text.contains("ff25 +21.0 %"),
            "{text}"
        );
    }

    #[test]
    fn a_study_of_other_schemes_and_prints_gets_no_table() {
        assert_eq!(paper_figures_text(&[row("x", "native", 3.0, None)]), "");
    }
}
