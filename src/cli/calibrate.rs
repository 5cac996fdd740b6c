//! `ffdic calibrate`: a calibration plan run on the bench through the same service a lab's clients
//! use (`POST /calibrations`), then the camera card; or, with `--dataset`, the card of runs
//! already captured. The card's model is stored in DATA/models (`card-NAME-HASH`), where
//! `compare --model` and the daemon find it.

use super::compare::load_analysis_model;
use super::ProgressBar;
use anyhow::{bail, Context, Result};
use clap::Args;
use ffdic::diagnose::{calibrate, CameraCard, Rounds};
use ffdic::experiment::CalibrationPlan;
use ffdic::report::camera_card_text;
use ffdic::service::job::{calibration_options, card_prefix, CalibrationJob};
use ffdic::service::{open_bench, DaemonConfig, JobResult, Service};
use ffdic::store::ModelFolder;
use std::path::PathBuf;
use std::time::Duration;

#[derive(Debug, Args)]
pub struct CalibrateArgs {
    /// Daemon config naming the bench (default: the embedded config/ffdic.toml, the mock bench).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Calibration plan, TOML (default: moves of 10 % of the field and a fifth of that along ±x
    /// and ±y, a nominal print and so no phase scan (`print_characterised = true`: a 0.25 px
    /// scan of 4 steps along each axis), 2 static frames, 4 rounds; docs/calibration.md).
    #[arg(long)]
    pub plan: Option<PathBuf>,
    /// Data folder (default: the config's): the run, its dataset and the card's model go there.
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// The card of a dataset already captured (format ffdic-dataset/1) instead of running the
    /// plan on a bench: the plan's rounds, DIC settings, model and name apply.
    #[arg(long, value_parser = super::dataset_folder)]
    pub dataset: Option<PathBuf>,
    /// Print one JSON document (the card, the rounds, the plan) and nothing else.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &CalibrateArgs) -> Result<()> {
    let plan = match &args.plan {
        Some(p) => CalibrationPlan::load(p)?,
        None => CalibrationPlan::default(),
    };
    let mut config = match &args.config {
        Some(p) => DaemonConfig::load(p)?,
        None => DaemonConfig::embedded(),
    };
    if let Some(d) = &args.data {
        config.data_dir = d.clone();
    }
    let (rounds, card, where_) = match &args.dataset {
        Some(dir) => {
            let (rounds, card) = card_of_dataset(dir, &plan, &config, !args.json)?;
            (rounds, card, format!("dataset {}", dir.display()))
        }
        None => on_bench(&plan, config.clone(), !args.json)?,
    };
    // On the bench the plan is reported as run (its record's): the phase scan's count stated.
    let plan = match &args.dataset {
        Some(_) => plan,
        None => plan.with_phase_scan_stated(),
    };
    if args.json {
        let doc = serde_json::json!({
            "card": card,
            "model": card.model.name,
            "rounds": rounds.to_json(),
            "plan": plan,
        });
        println!("{doc}");
    } else {
        print!("{}", camera_card_text(&card));
        println!(
            "card model {} stored in {} ({where_})",
            card.model.name,
            ModelFolder::in_data_dir(&config.data_dir).dir().display()
        );
    }
    Ok(())
}

/// The plan on the config's bench, as the daemon runs it.
fn on_bench(
    plan: &CalibrationPlan,
    config: DaemonConfig,
    show: bool,
) -> Result<(Rounds, CameraCard, String)> {
    let hardware = open_bench(&config)?;
    let (service, _) = Service::start(config, hardware)?;
    service.jobs.keep_results();
    let (record, _) = service.submit(CalibrationJob::plan(&service, plan.clone())?, None)?;
    let record = super::reproduce::wait(&service, &record.id, "capturing, then diagnosing", show);
    service.stop(Duration::from_secs(5));
    let record = record?;
    let folder = service.store.run_dir(&record.id);
    let Some(JobResult::Calibration { rounds, card, .. }) = service.jobs.take_result(&record.id)
    else {
        bail!("calibration {} succeeded without a card", record.id)
    };
    Ok((
        *rounds,
        *card,
        format!("run {} in {}", record.id, folder.display()),
    ))
}

/// The frames' size: the manifest's camera, else the first reference frame's.
fn frame_size(dir: &std::path::Path) -> Result<(u32, u32)> {
    let manifest = ffdic::dataset::Manifest::read(dir)?;
    let (width, height) = match (&manifest.camera, manifest.runs.first()) {
        (Some(c), _) => (c.width, c.height),
        (None, Some(run)) => {
            let (image, _) = ffdic::image::read_image(&dir.join(&run.reference))?;
            (image.width(), image.height())
        }
        (None, None) => bail!("{}: the dataset has no runs", dir.display()),
    };
    Ok((u32::try_from(width)?, u32::try_from(height)?))
}

/// The card of runs already captured; the card's model stored as the daemon would.
fn card_of_dataset(
    dir: &std::path::Path,
    plan: &CalibrationPlan,
    config: &DaemonConfig,
    show: bool,
) -> Result<(Rounds, CameraCard)> {
    let model = load_analysis_model(&Some(plan.model.clone()), &config.data_dir)?;
    let size = frame_size(dir)?;
    let options = calibration_options(plan, size)?;
    let bar = ProgressBar::new(show, "calibration fits");
    let (rounds, card) = calibrate(
        dir,
        &model,
        &options,
        plan.rounds,
        &card_prefix(&plan.name),
        &|done, total| {
            bar.update(done, total);
            true
        },
    )?;
    bar.finish();
    ModelFolder::in_data_dir(&config.data_dir)
        .save(&card.model.name, &card.model.to_toml())
        .with_context(|| format!("cannot store the card's model {}", card.model.name))?;
    Ok((rounds, card))
}
