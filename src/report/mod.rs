//! Tables and SVG plots for people. Plain data in, text out: nothing here knows DIC, HTTP or
//! cameras. SVG is written by hand: the charts need no font metrics (text width is estimated),
//! so nothing depends on system fonts and every asset ships in the binary.

mod bar_chart;
mod svg;
mod table;

pub use bar_chart::{BarChart, Series};
pub use table::{csv, text_table};
