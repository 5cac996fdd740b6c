//! The `ffdic` command line: one file per subcommand.

pub mod analyze;
mod progress;
pub mod reduce;
pub mod reproduce;
pub mod simulate;

pub use progress::ProgressBar;
