//! Tables and SVG plots for people. Plain data in, text out (the DIC summary reads a `DicResult`;
//! nothing here knows HTTP, files or cameras). SVG is written by hand: the charts need no font metrics (text width is estimated),
//! so nothing depends on system fonts and every asset ships in the binary.

mod bar_chart;
mod dic_summary;
mod heatmap;
mod history_chart;
mod png;
mod svg;
mod table;
mod xy_plot;

pub use bar_chart::{BarChart, Series};
pub use dic_summary::{dic_settings_json, dic_summary_json};
pub use heatmap::{Heatmap, HeatmapMarker};
pub use history_chart::{history_svg, HistoryPoint};
pub use png::png_quicklook;
pub use table::{csv, text_table};
pub use xy_plot::{Mark, XyPlot, XySeries};
