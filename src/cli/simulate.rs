//! `ffdic simulate`: the frames a camera on the bench would deliver, as a dataset.

use super::ProgressBar;
use anyhow::{bail, Context, Result};
use clap::Args;
use ffdic::experiment::{simulate_dataset, ExperimentSpec};
use ffdic::model::ModelConfig;
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// Experiment file (default: the embedded paper study).
    #[arg(long)]
    pub experiment: Option<PathBuf>,
    /// Model of the bench (default: config/models/paper-bench.toml, embedded).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Output folder for dataset.json and the TIFF frames.
    #[arg(long)]
    pub out: PathBuf,
    /// Noise and pattern seed (default: the experiment's).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Write into `--out` even if it already holds files (they may be overwritten).
    #[arg(long)]
    pub force: bool,
}

/// The paper's bench, embedded so the default needs no file.
pub use ffdic::service::PAPER_BENCH_TOML;

pub fn load_experiment(path: &Option<PathBuf>) -> Result<ExperimentSpec> {
    Ok(match path {
        Some(p) => ExperimentSpec::load(p)?,
        None => ExperimentSpec::paper(),
    })
}

pub fn load_model(
    path: &Option<PathBuf>,
    embedded: &str,
    embedded_name: &str,
) -> Result<ModelConfig> {
    Ok(match path {
        Some(p) => ModelConfig::load(p)?,
        None => ModelConfig::from_toml(embedded, std::path::Path::new(embedded_name))?,
    })
}

pub fn run(args: &SimulateArgs) -> Result<()> {
    if !args.force && args.out.is_dir() {
        let mut entries = std::fs::read_dir(&args.out)
            .with_context(|| format!("reading {}", args.out.display()))?;
        if entries.next().is_some() {
            bail!(
                "{} is not empty: simulate writes a whole dataset there (dataset.json and frames); \
                 choose an empty or new folder, or pass --force to write over it",
                args.out.display()
            );
        }
    }
    let spec = load_experiment(&args.experiment)?;
    let model = load_model(
        &args.model,
        PAPER_BENCH_TOML,
        "config/models/paper-bench.toml",
    )?;
    let seed = args.seed.unwrap_or(spec.seed);
    let bar = ProgressBar::new(true, "rendering");
    let manifest = simulate_dataset(&spec, &model, seed, &args.out, &|d, t| bar.update(d, t))?;
    bar.finish();
    println!(
        "wrote {} runs of {}x{} frames to {} (model {}, seed {seed})",
        manifest.runs.len(),
        spec.camera.width,
        spec.camera.height,
        args.out.display(),
        model.name
    );
    Ok(())
}
