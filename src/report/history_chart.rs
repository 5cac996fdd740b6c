//! The fall of a discrepancy over model versions: one column per model version in the order
//! each was first compared (a re-run of the baseline lands on the baseline's column, not at the
//! end as if the error had risen back), one line per manifest (the dataset as it was compared: a
//! manifest that grew from 1 to 11 runs is another line) through each version's latest
//! comparison.

use super::distinct;
use super::xy_plot::{Mark, XyPlot, XySeries};
use crate::diagnose::HistoryEntry;

/// The history drawn, 760x460 px.
pub fn history_chart(entries: &[HistoryEntry]) -> String {
    let title = match entries.first() {
        Some(e) => format!("Discrepancy of {} over model versions", e.dataset),
        None => "No comparison yet".to_string(),
    };
    let mut plot = XyPlot::new(&title, "model version", "discrepancy [px]");
    let versions = distinct(entries.iter().map(version_key));
    let manifests = distinct(entries.iter().map(|e| e.manifest_version.clone()));
    for manifest in &manifests {
        let of_manifest: Vec<&HistoryEntry> = entries
            .iter()
            .filter(|e| &e.manifest_version == manifest)
            .collect();
        let points: Vec<(f64, f64)> = versions
            .iter()
            .enumerate()
            .filter_map(|(k, v)| {
                let latest = of_manifest.iter().rev().find(|e| &version_key(e) == v)?;
                Some(((k + 1) as f64, latest.discrepancy_px))
            })
            .collect();
        let runs = of_manifest.last().map_or(0, |e| e.manifest_runs);
        plot.series.push(XySeries {
            name: match (manifests.len(), manifest.is_empty()) {
                (1, _) => "discrepancy (each version's latest comparison)".into(),
                (_, true) => "comparisons recorded before manifests were".into(),
                (_, false) => format!("{runs} runs (manifest {})", short(manifest)),
            },
            points,
            mark: Mark::LinePoints,
            y_err: Vec::new(),
        });
    }
    plot.x_tick_labels = versions
        .iter()
        .enumerate()
        .map(|(k, (model, version))| ((k + 1) as f64, format!("{model} {}", short(version))))
        .collect();
    plot.to_svg(760, 460)
}

fn version_key(e: &HistoryEntry) -> (String, String) {
    (e.model.clone(), e.version.clone())
}

fn short(hash: &str) -> &str {
    &hash[..hash.len().min(6)]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(model: &str, version: &str, d: f64, manifest: &str, runs: usize) -> HistoryEntry {
        HistoryEntry {
            manifest_version: manifest.into(),
            manifest_runs: runs,
            ..HistoryEntry::now("ds", model, version, d, vec![])
        }
    }

    #[test]
    fn a_rerun_lands_on_its_version_and_a_grown_manifest_is_its_own_line() {
        let svg = history_chart(&[
            entry("baseline", "aaaaaa11", 0.05, "m1", 1),
            entry("baseline+lens", "bbbbbb22", 0.01, "m1", 1),
            entry("baseline", "aaaaaa11", 0.049, "m1", 1),
            entry("baseline", "aaaaaa11", 0.04, "m2", 11),
        ]);
        // Two versions (two columns), two manifests (two lines); the re-run replaced the
        // baseline's point of its manifest instead of adding a third column.
        assert_eq!(svg.matches(r#"class="line""#).count(), 1, "{svg}");
        assert_eq!(svg.matches(r#"class="point""#).count(), 3, "{svg}");
        assert!(svg.contains("baseline aaaaaa") && svg.contains("baseline+lens bbbbbb"));
        assert!(svg.contains("11 runs (manifest m2)") && svg.contains("1 runs (manifest m1)"));
        assert_eq!(svg.matches(">baseline aaaaaa<").count(), 1, "{svg}");
    }
}
