//! `ffdic diagnose DATASET --on-bench`: the daemon's on-bench job
//! (`ffdic::service::job::OnBenchJob`, `POST /datasets/{id}/on-bench`) run in the process on the
//! configured bench, with the command line's model and options. A folder outside the data
//! folder's store is imported into it first (hard links where the filesystem allows).

use super::reproduce::wait;
use anyhow::{Context, Result};
use ffdic::diagnose::{CompareOptions, Rounds};
use ffdic::model::ModelConfig;
use ffdic::service::job::{OnBenchCapture, OnBenchJob};
use ffdic::service::{open_bench, DaemonConfig, JobResult, Service};
use ffdic::store::{DatasetId, DatasetSource, RunStore};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// What `--on-bench` did after the first diagnosis: what the bench captured, the merged
/// dataset's folder and its diagnosis (none when nothing was left for a bench).
pub struct OnBench {
    pub bench: OnBenchCapture,
    pub folder: Option<PathBuf>,
    pub after: Option<Rounds>,
    /// The job's closing message (what it captured, or why nothing).
    pub message: String,
}

/// The dataset in `dir` diagnosed with `model`, `options` and `rounds`, completed on `config`'s
/// bench and diagnosed again: the first diagnosis and what followed.
pub fn on_bench(
    dir: &Path,
    (model, options, rounds): (&ModelConfig, &CompareOptions, usize),
    config: DaemonConfig,
    show: bool,
) -> Result<(Rounds, OnBench)> {
    let hardware = open_bench(&config)?;
    let (service, _) = Service::start(config, hardware)?;
    service.jobs.keep_results();
    let result = (|| {
        let dataset = stored_dataset(&service.store, dir)?;
        let job =
            OnBenchJob::for_model(&service, &dataset, model.clone(), options.clone(), rounds)?;
        let (record, _) = service.submit(job, None)?;
        let record = wait(
            &service,
            &record.id,
            "diagnosing, capturing, diagnosing again",
            show,
        )?;
        let Some(JobResult::OnBench {
            before,
            bench,
            after,
        }) = service.jobs.take_result(&record.id)
        else {
            anyhow::bail!("run {} kept no on-bench result", record.id);
        };
        Ok((
            *before,
            OnBench {
                folder: bench
                    .dataset
                    .as_ref()
                    .map(|id| service.store.dataset_dir(id)),
                bench: *bench,
                after: after.map(|a| *a),
                message: record.message,
            },
        ))
    })();
    service.stop(Duration::from_secs(5));
    result
}

/// The stored dataset whose folder `dir` is, or `dir` imported into `store`.
fn stored_dataset(store: &RunStore, dir: &Path) -> Result<DatasetId> {
    let canonical = |p: &Path| p.canonicalize().ok();
    let own = dir
        .file_name()
        .and_then(|n| n.to_str())
        .and_then(|n| n.parse::<DatasetId>().ok())
        .filter(|id| {
            store.get_dataset(id).is_ok() && canonical(&store.dataset_dir(id)) == canonical(dir)
        });
    if let Some(id) = own {
        return Ok(id);
    }
    let name = ffdic::dataset::Manifest::read(dir)?.name;
    let record = store
        .import_dataset_dir(
            dir,
            &name,
            DatasetSource::Other(format!("diagnose --on-bench {}", dir.display())),
        )
        .with_context(|| format!("importing {} into the data folder", dir.display()))?;
    Ok(record.id)
}
