//! The `ffdic` command line: one file per subcommand.

pub mod analyze;
mod analyze_card;
pub mod calibrate;
pub mod compare;
pub mod dataset;
mod dataset_arg;
pub mod diagnose;
mod diagnose_on_bench;
mod error_line;
pub mod history;
pub mod logging;
mod number_pair;
mod progress;
pub mod reduce;
pub mod reproduce;
pub mod serve;
pub mod simulate;
pub mod store;
pub mod sweep;

pub use dataset_arg::dataset_folder;
pub use error_line::error_line;
pub use number_pair::number_pair;
pub use progress::ProgressBar;
