//! `ffdic store rebuild`: recreates the SQLite index from the run folders, which are the truth.

use anyhow::Result;
use clap::{Args, Subcommand};
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct StoreArgs {
    #[command(subcommand)]
    pub command: StoreCommand,
}

#[derive(Debug, Subcommand)]
pub enum StoreCommand {
    /// Delete and recreate the index from data/runs and data/datasets.
    Rebuild {
        /// Data folder.
        #[arg(long, default_value = "data")]
        data: PathBuf,
    },
}

pub fn run(args: &StoreArgs) -> Result<()> {
    match &args.command {
        StoreCommand::Rebuild { data } => {
            let report = ffdic::store::rebuild_index(data)?;
            println!(
                "index rebuilt from {}: {} runs, {} datasets",
                data.display(),
                report.runs,
                report.datasets
            );
        }
    }
    Ok(())
}
