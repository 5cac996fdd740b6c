//! The `ffdic` command line: one file per subcommand.

pub mod analyze;
mod progress;

pub use progress::ProgressBar;
