//! The study's files: the rows pooled over captures and every view of them, one writer for the
//! experiment runner and the dataset analysis job.

use crate::report::{figure_svgs, study_csv, study_json};

use crate::study::StudyRow;

/// The study's files from every capture's rows, beside the pooled rows they show:
/// `results/study.json`, `results/study.csv` and the figures under `plots/` — one writer for the
/// experiment runner and the dataset analysis job.
pub fn study_files(
    manifest: &crate::dataset::Manifest,
    captures: &[StudyRow],
) -> (Vec<StudyRow>, Vec<(String, Vec<u8>)>) {
    let rows = crate::study::pool_captures(manifest, captures);
    let json = serde_json::to_string_pretty(&study_json(&rows, captures)).expect("rows serialise");
    let mut files = vec![
        ("results/study.json".to_string(), json.into_bytes()),
        (
            "results/study.csv".to_string(),
            study_csv(&rows).into_bytes(),
        ),
    ];
    files.extend(
        figure_svgs(&rows)
            .into_iter()
            .map(|(name, svg)| (format!("plots/{name}"), svg.into_bytes())),
    );
    (rows, files)
}
