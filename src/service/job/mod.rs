//! Every kind of job, one file each: its request, how it is checked and planned (a bad request
//! queues nothing), its run kind and lane, and what it does once its lane picks it up. The lanes
//! themselves (queues, workers, cancellation, events) are `service/jobs.rs`; they know no kind.
//!
//! A new kind is: its file here (a type implementing [`Job`] and a `plan` that builds it), a
//! `mod` line below, a `RunKind` variant (`store/record.rs`: the compiler then walks through
//! every match on the kinds), and its HTTP handler and route (`api/routes/…`,
//! `api/openapi.rs`), which call [`Service::submit`].

mod analysis;
mod calibration;
mod comparison;
mod diagnosis;
mod experiment;
mod on_bench;
mod perpendicularity;
mod sweep;

pub use analysis::{AnalysisJob, AnalysisRequest};
pub use calibration::{calibration_options, card_prefix, CalibrationJob};
pub use comparison::{CompareRequest, ComparisonJob};
pub use diagnosis::DiagnosisJob;
pub use experiment::ExperimentJob;
pub use on_bench::{OnBenchCapture, OnBenchJob};
pub use perpendicularity::PerpendicularityJob;
pub use sweep::{plan_sweep, SweepJob, MAX_DAEMON_SENSOR_SIDE_PX, MAX_DAEMON_SWEEP_TASKS};

use super::jobs::{JobContext, JobError, JobOutput, Lane};
use super::{Service, SubmitError};
use crate::diagnose::DiagnoseError;
use crate::experiment::RunSink;
use crate::run_event::EventKind;
use crate::store::{DatasetId, RunKind, RunRecord};
use serde_json::json;

/// One kind of job, checked and planned: what [`Service::submit`] queues.
pub trait Job: Send + 'static {
    /// What the run store records the run as.
    const KIND: RunKind;
    /// Where it waits: `Bench` (one at a time, it holds the hardware) or `Compute`.
    const LANE: Lane;
    /// What a client sends.
    type Request: serde::Serialize;
    /// The request as the run records it (`GET /jobs/{id}`'s `request`, and what an
    /// `Idempotency-Key` is matched against).
    fn request(&self) -> &Self::Request;
    /// The stored dataset the job reads, if any: the dataset's page lists the job, and the
    /// dataset cannot be deleted while the job waits or runs.
    fn dataset(&self) -> Option<&DatasetId>;
    /// The work, on the lane's worker; events and files go through `ctx`.
    fn run(self, ctx: &JobContext) -> Result<JobOutput, JobError>;
}

impl Service {
    /// Queues `job` on its lane: `(record, true)`, or `(the run made before, false)` when
    /// `idempotency_key` was used already; `QueueFull` when its lane has
    /// `jobs.max_queued_per_lane` jobs waiting.
    pub fn submit<J: Job>(
        &self,
        job: J,
        idempotency_key: Option<&str>,
    ) -> Result<(RunRecord, bool), SubmitError> {
        let request = serde_json::to_value(job.request()).expect("a request serialises");
        let dataset = job.dataset().cloned();
        Ok(self.jobs.submit(
            J::KIND,
            J::LANE,
            request,
            idempotency_key,
            dataset,
            Box::new(move |ctx: &JobContext| job.run(ctx)),
        )?)
    }
}

/// How a dataset's page (`GET /datasets/{id}/jobs`) shows the runs of a kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DatasetPageRow {
    /// Not listed: the kind does not work on a stored dataset (an experiment or a calibration
    /// makes one, a sweep reads none).
    NotListed,
    /// Listed, without a results document (an analysis: its study is files).
    Listed,
    /// Listed, with the headline figures of this results document.
    Headline(&'static str),
}

/// How a dataset's page shows the runs of `kind`: a new kind is placed here, or the compiler
/// says so.
pub fn dataset_page_row(kind: RunKind) -> DatasetPageRow {
    match kind {
        RunKind::Comparison => DatasetPageRow::Headline("results/comparison.json"),
        // An on-bench diagnosis's `results/diagnosis.json` is the listed dataset's own.
        RunKind::Diagnosis | RunKind::OnBench => DatasetPageRow::Headline("results/diagnosis.json"),
        RunKind::Analysis => DatasetPageRow::Listed,
        RunKind::Experiment | RunKind::Sweep | RunKind::Calibration | RunKind::Perpendicularity => {
            DatasetPageRow::NotListed
        }
    }
}

/// Reports progress as events, at most about a hundred per job (each event is a synced append).
fn progress_reporter<'a>(
    ctx: &'a dyn RunSink,
    what: &'a str,
) -> impl Fn(usize, usize) -> bool + Sync + 'a {
    let last = std::sync::Mutex::new(-1.0f64);
    move |done: usize, total: usize| {
        let p = done as f64 / total.max(1) as f64;
        let mut last = last.lock().expect("progress lock");
        // Counts already reported come again (a comparison asks before every point): only
        // what moved on is an event.
        if p - *last >= 0.01 || (done == total && p > *last) {
            *last = p;
            ctx.event(
                EventKind::Progress,
                p.min(1.0),
                &format!("{what}: {done} of {total}"),
                json!({ "done": done, "total": total }),
            );
        }
        !ctx.cancelled()
    }
}

fn diagnose_failure(e: DiagnoseError) -> JobError {
    match e {
        DiagnoseError::Cancelled => JobError::Cancelled,
        other => JobError::failed(other),
    }
}
