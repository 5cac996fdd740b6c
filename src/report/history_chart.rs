//! The fall of a discrepancy over model versions: one point per comparison, in the order they
//! were made, labelled with the model's name and version.

use super::xy_plot::{Mark, XyPlot, XySeries};
use crate::diagnose::HistoryEntry;

/// One comparison: its label (model name and version) and its discrepancy in px.
#[derive(Clone, Debug, PartialEq)]
pub struct HistoryPoint {
    pub label: String,
    pub discrepancy_px: f64,
}

/// A line chart of the discrepancy against the comparison's index.
pub fn history_svg(title: &str, points: &[HistoryPoint], width_px: u32, height_px: u32) -> String {
    let mut plot = XyPlot::new(title, "comparison (model version)", "discrepancy [px]");
    plot.series.push(XySeries {
        name: "discrepancy".into(),
        points: points
            .iter()
            .enumerate()
            .map(|(i, p)| ((i + 1) as f64, p.discrepancy_px))
            .collect(),
        mark: Mark::LinePoints,
        y_err: Vec::new(),
    });
    plot.x_tick_labels = points
        .iter()
        .enumerate()
        .map(|(i, p)| ((i + 1) as f64, p.label.clone()))
        .collect();
    plot.to_svg(width_px, height_px)
}

/// The history drawn: the discrepancy of each comparison in the order made, labelled with the
/// model's name and the start of its version.
pub fn history_chart(entries: &[HistoryEntry]) -> String {
    let points: Vec<HistoryPoint> = entries
        .iter()
        .map(|e| HistoryPoint {
            label: format!("{} {}", e.model, &e.version[..e.version.len().min(6)]),
            discrepancy_px: e.discrepancy_px,
        })
        .collect();
    let title = match entries.first() {
        Some(e) => format!("Discrepancy of {} over model versions", e.dataset),
        None => "No comparison yet".to_string(),
    };
    history_svg(&title, &points, 760, 460)
}
