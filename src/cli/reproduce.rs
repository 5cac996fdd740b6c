//! `ffdic reproduce`: the paper's study end to end through the same service a lab's clients use —
//! the experiment runner and the bench actor on the mock bench (the model renders what the sensor
//! sees at the mock stage's position), the frames reduced to 100 / 50 / 25 % fill factor, DIC at
//! the paper's settings — then Figures 5 and 6. The run lands in the data folder like any other,
//! so `ffdic serve` shows it.

use super::simulate::{load_experiment, load_model};
use super::ProgressBar;
use anyhow::{bail, Context, Result};
use clap::Args;
use ffdic::experiment::{figures_text, rows_json, ExperimentRequest, SchemeSpec, StudyRow};
use ffdic::service::{mock_bench, CameraConfig, DaemonConfig, Service, PAPER_BENCH_TOML};
use ffdic::store::RunStatus;
use std::path::PathBuf;
use std::time::Duration;

#[derive(Debug, Args)]
pub struct ReproduceArgs {
    /// Experiment file (default: the embedded paper study, config/experiments/paper.toml).
    #[arg(long)]
    pub experiment: Option<PathBuf>,
    /// Model of the mock bench's truth (default: config/models/paper-bench.toml).
    #[arg(long)]
    pub bench_model: Option<PathBuf>,
    /// Data folder the run is stored in (as `ffdic serve` would).
    #[arg(long, default_value = "data")]
    pub data: PathBuf,
    /// Seed of the speckle layouts (default: the experiment's).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Print the table as one JSON document and nothing else.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &ReproduceArgs) -> Result<()> {
    let spec = load_experiment(&args.experiment)?;
    let truth = load_model(
        &args.bench_model,
        PAPER_BENCH_TOML,
        "config/models/paper-bench.toml",
    )?;
    let mut config = DaemonConfig::embedded();
    config.data_dir = args.data.clone();
    config.bench.scale_px_per_mm = spec.camera.scale_px_per_mm;
    config.camera = CameraConfig::Mock {
        width: spec.camera.width,
        height: spec.camera.height,
        exposure_level: spec.camera.exposure_level,
        bench_model: truth.name.clone(),
    };
    // A fast mock stage: travel time is not what this study measures.
    let hardware = mock_bench(spec.camera.clone(), truth, 200.0, Duration::from_millis(5));
    let (service, _) = Service::start(config, hardware)?;
    let request = ExperimentRequest {
        name: spec.name.clone(),
        patterns: spec.patterns.clone(),
        moves: spec.moves.clone(),
        step_series: spec.step_series.clone(),
        repeats: spec.repeats,
        settle_ms: 0,
        schemes: spec
            .schemes
            .iter()
            .cloned()
            .map(SchemeSpec::Preset)
            .collect(),
        dic: spec.dic.clone(),
        seed: args.seed.unwrap_or(spec.seed),
        ..ExperimentRequest::default()
    };
    let (record, _) = service.submit_experiment(&request, None)?;
    let bar = ProgressBar::new(!args.json, "capturing and correlating");
    let record = loop {
        let r = service.store.get(&record.id)?;
        bar.update((r.progress * 1000.0) as usize, 1000);
        if r.status.is_terminal() {
            break r;
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    bar.finish();
    service.stop(Duration::from_secs(5));
    if record.status != RunStatus::Succeeded {
        bail!(
            "experiment {} {:?}: {}",
            record.id,
            record.status,
            record.message
        );
    }
    let run_dir = service.store.run_dir(&record.id);
    let rows_path = run_dir.join("results/rows.json");
    let rows: Vec<StudyRow> = serde_json::from_slice(
        &std::fs::read(&rows_path)
            .with_context(|| format!("cannot read {}", rows_path.display()))?,
    )?;
    if args.json {
        let mut doc = rows_json(&rows);
        doc["run"] = serde_json::json!(record.id.to_string());
        doc["folder"] = serde_json::json!(run_dir.display().to_string());
        println!("{doc}");
    } else {
        print!("{}", figures_text(&rows));
        println!(
            "\nrun {} in {} (frames/ as ffdic-dataset/1, results/study.csv, study.json, plots/figure5_*.svg, figure6_*.svg)",
            record.id,
            run_dir.display()
        );
    }
    Ok(())
}
