//! `ffdic history DATASET`: every comparison of the dataset with its model version and
//! discrepancy, oldest first, and the fall drawn as SVG.

use anyhow::{bail, Context, Result};
use clap::Args;
use ffdic::diagnose::{history_dir_for, read_history};
use ffdic::report::history_chart;
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct HistoryArgs {
    /// Dataset folder, or its dataset.json.
    #[arg(value_parser = super::dataset_folder)]
    pub dataset: PathBuf,
    /// Where to draw the chart (default: ffdic-history.svg in the history folder).
    #[arg(long)]
    pub svg: Option<PathBuf>,
    /// The dataset's history folder, as `compare --history-dir` named it (default:
    /// DATA/history/NAME-HASH).
    #[arg(long, value_name = "DIR")]
    pub history_dir: Option<PathBuf>,
    /// The data folder whose history/ holds the dataset's history.
    #[arg(long, default_value = "data")]
    pub data: PathBuf,
    /// Print the entries as one JSON array and nothing else.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &HistoryArgs) -> Result<()> {
    let dir = args
        .history_dir
        .clone()
        .unwrap_or_else(|| history_dir_for(&args.data, &args.dataset));
    let entries = read_history(&dir)?;
    if entries.is_empty() {
        bail!(
            "no comparison recorded for {} in {} yet (run ffdic compare first; --history-dir names another history folder)",
            args.dataset.display(),
            dir.display()
        );
    }
    let svg_path = args
        .svg
        .clone()
        .unwrap_or_else(|| dir.join("ffdic-history.svg"));
    std::fs::write(&svg_path, history_chart(&entries))
        .with_context(|| format!("cannot write {}", svg_path.display()))?;
    if args.json {
        println!("{}", serde_json::to_string(&entries)?);
        return Ok(());
    }
    let first = entries[0].discrepancy_px;
    let rows: Vec<Vec<String>> = entries
        .iter()
        .map(|e| {
            vec![
                e.time.clone(),
                e.model.clone(),
                e.version.clone(),
                match e.manifest_version.is_empty() {
                    true => "—".into(),
                    false => format!("{} ({} runs)", e.manifest_version, e.manifest_runs),
                },
                ffdic::report::length_pm(e.discrepancy_px, e.discrepancy_se_px),
                format!("{:+.1} %", 100.0 * (e.discrepancy_px / first - 1.0)),
            ]
        })
        .collect();
    print!(
        "{}",
        ffdic::report::text_table(
            &[
                "time",
                "model",
                "version",
                "manifest",
                "discrepancy [px]",
                "vs first"
            ],
            &rows
        )
    );
    println!("chart: {}", svg_path.display());
    Ok(())
}
