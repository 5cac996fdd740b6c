//! Tables and SVG plots for people. Plain data in, text out (the DIC summary reads a `DicResult`;
//! nothing here knows HTTP, files or cameras). SVG is written by hand: the charts need no font metrics (text width is estimated),
//! so nothing depends on system fonts and every asset ships in the binary.

mod bar_chart;
mod camera_card;
mod comparison_figures;
mod dic_summary;
mod field_maps;
mod findings_text;
mod heatmap;
mod history_chart;
mod paper_figures;
mod png;
mod study_figures;
mod study_files;
mod svg;
mod table;
mod xy_plot;

pub use bar_chart::{small_multiples, BarChart, Series};
pub use camera_card::camera_card_text;
pub use comparison_figures::comparison_svgs;
pub use dic_summary::{dic_settings_json, dic_summary_json};
pub use field_maps::{field_map_svgs, map_file_name};
pub use findings_text::findings_text;
pub use heatmap::{Heatmap, HeatmapMarker};
pub use history_chart::history_chart;
pub use paper_figures::paper_figures_text;
pub use png::png_quicklook;
pub use study_figures::{figure_svgs, figures_text, rows_json, study_csv, study_json};
pub use study_files::study_files;
pub use table::{
    csv, length_pm, parameters_text, plus_minus, rounded_to_error, significant, text_table,
    value_pm,
};
pub use xy_plot::{Mark, XyPlot, XySeries};

/// Distinct values in first-seen order (a plot's runs, schemes, versions).
pub fn distinct<T: PartialEq>(items: impl Iterator<Item = T>) -> Vec<T> {
    let mut out: Vec<T> = Vec::new();
    for item in items {
        if !out.contains(&item) {
            out.push(item);
        }
    }
    out
}
