//! The paper's findings tested on a study (`study::paper_findings`) as a terminal table.

use super::text_table;
use crate::study::{Finding, Verdict};

/// The findings as a terminal table.
pub fn findings_text(findings: &[Finding]) -> String {
    if findings.is_empty() {
        return String::new();
    }
    let headers = [
        "paper's finding",
        "tested",
        "mean [95 % interval]",
        "verdict",
    ];
    let body: Vec<Vec<String>> = findings
        .iter()
        .map(|f| {
            vec![
                f.claim.clone(),
                f.measure.clone(),
                format!("{:+.1} [{:+.1}, {:+.1}]", f.mean, f.ci95[0], f.ci95[1]),
                match f.verdict {
                    Verdict::Holds => "holds",
                    Verdict::Contradicted => "contradicted",
                    Verdict::NotResolved => "not resolved",
                }
                .to_string(),
            ]
        })
        .collect();
    format!(
        "\nThe paper's findings on this bench ({} captures per row; 95 % t intervals; between patterns Welch's t):\n{}",
        findings[0].captures,
        text_table(&headers, &body)
    )
}
