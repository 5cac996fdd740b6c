//! `ffdic diagnose DATASET --on-bench`: what the diagnosis left open (pairs its design
//! confounds, effects it cannot reveal) resolved on the bench. The runs that separate them
//! (`ffdic::diagnose::runs_to_separate`) become a calibration-style plan on the dataset's target
//! and move size, captured through the same service a lab's clients use, appended to the
//! dataset as new runs (a new stored dataset: the original is left as it was) and diagnosed
//! again.

use super::reproduce::wait;
use anyhow::{bail, Context, Result};
use ffdic::dataset::{merge_datasets, Manifest};
use ffdic::diagnose::{diagnose_rounds, runs_to_separate, CompareOptions, Rounds, SeparatingRuns};
use ffdic::experiment::{CalibrationPlan, PatternSpec};
use ffdic::model::ModelConfig;
use ffdic::service::job::ExperimentJob;
use ffdic::service::{open_bench, DaemonConfig, Service};
use ffdic::store::{DatasetSource, RunId};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// What `--on-bench` did: the runs it asked for, the plan that captured them, the experiment,
/// the merged dataset and its diagnosis.
#[derive(serde::Serialize)]
pub struct OnBench {
    pub runs: Vec<SeparatingRuns>,
    pub plan: CalibrationPlan,
    pub experiment: RunId,
    pub dataset: String,
    pub folder: PathBuf,
    #[serde(skip)]
    pub after: Rounds,
}

/// The dataset in `dir`, whose diagnosis was `before`, completed on `config`'s bench and
/// diagnosed again with the same model, options and rounds.
pub fn on_bench(
    dir: &Path,
    before: &Rounds,
    (model, options, rounds): (&ModelConfig, &CompareOptions, usize),
    config: DaemonConfig,
    show: bool,
) -> Result<OnBench> {
    let last = before
        .diagnoses
        .last()
        .context("the diagnosis ran no round")?;
    let runs = runs_to_separate(last);
    if runs.is_empty() {
        bail!(
            "the diagnosis left nothing a bench's moves can separate (no pair confounded by the dataset's design, no effect a move, a step series or static frames would reveal)"
        );
    }
    let manifest = Manifest::read(dir)?;
    let plan = plan_for(&manifest, &runs, options)?;
    let hardware = open_bench(&config)?;
    let (service, _) = Service::start(config, hardware)?;
    let result = capture(&service, &plan, show).and_then(|experiment| {
        let id = service
            .store
            .get(&experiment)?
            .dataset_id
            .with_context(|| format!("experiment {experiment} registered no dataset"))?;
        let staging = service.store.stage_dataset()?;
        merge_datasets(
            dir,
            &service.store.dataset_dir(&id),
            "bench-",
            staging.path(),
        )?;
        let source = DatasetSource::Other(format!(
            "diagnose --on-bench: {} with experiment {experiment}",
            manifest.name
        ));
        let name = format!("{} on the bench", manifest.name);
        Ok((
            experiment,
            service.store.commit_dataset(staging, &name, source)?,
        ))
    });
    service.stop(Duration::from_secs(5));
    let (experiment, record) = result?;
    let folder = service.store.dataset_dir(&record.id);
    let bar = super::ProgressBar::new(show, "diagnosing with the bench's runs");
    let after = diagnose_rounds(&folder, model, options, rounds, &|done, total| {
        bar.update(done, total);
        true
    })?;
    bar.finish();
    Ok(OnBench {
        runs,
        plan,
        experiment,
        dataset: record.id.to_string(),
        folder,
        after,
    })
}

/// The plan that captures `runs` on the dataset's target (its first run's pattern, one the mock
/// bench and a lab both know by its preset name) at the dataset's own move size: ±x and ±y at
/// the largest move and a quarter of it where sizes or directions are asked for, a phase scan
/// of four steps for a step series, two static frames for repeats.
fn plan_for(
    manifest: &Manifest,
    runs: &[SeparatingRuns],
    options: &CompareOptions,
) -> Result<CalibrationPlan> {
    let label = manifest
        .runs
        .iter()
        .find_map(|r| r.pattern.as_ref().map(|p| p.label.clone()))
        .context("the dataset names no pattern: the bench must know which target to mount")?;
    let largest_mm = manifest
        .runs
        .iter()
        .map(|r| r.stage.dx_mm.hypot(r.stage.dy_mm))
        .fold(0.0, f64::max);
    let wants = |k: SeparatingRuns| runs.contains(&k);
    let move_sizes_mm = match (
        largest_mm > 0.0,
        wants(SeparatingRuns::SeveralMoveSizes) || wants(SeparatingRuns::BothAxes),
    ) {
        (false, _) => Vec::new(),
        (true, true) => vec![0.25 * largest_mm, largest_mm],
        (true, false) => vec![largest_mm],
    };
    Ok(CalibrationPlan {
        name: "on-bench".into(),
        pattern: PatternSpec::Preset(label),
        move_sizes_mm,
        phase_scan_count: if wants(SeparatingRuns::StepSeries) {
            4
        } else {
            0
        },
        static_frames: if wants(SeparatingRuns::StaticRepeats) {
            2
        } else {
            0
        },
        rounds: 1,
        dic: options.dic.clone(),
        ..CalibrationPlan::default()
    })
}

/// Captures `plan`'s runs as an experiment (its frames become a stored dataset).
fn capture(service: &Service, plan: &CalibrationPlan, show: bool) -> Result<RunId> {
    let request = plan.experiment(&service.limits, service.sensor_px)?;
    let (record, _) = service.submit(ExperimentJob::plan(service, request)?, None)?;
    wait(service, &record.id, "capturing the separating runs", show)?;
    Ok(record.id)
}
