//! `POST /experiments` and `ffdic reproduce`: a study captured on the bench (moves, frames,
//! reductions, DIC), its frames registered as a dataset of their own.

use super::Job;
use crate::bench::BenchLease;
use crate::dataset::Manifest;
use crate::experiment::{
    capture_experiment, run_experiment, BenchGeometry, BenchTimeouts, ExperimentOutcome,
    ExperimentPlan, ExperimentRequest, RunSink, RunnerError,
};
use crate::run_event::EventKind;
use crate::service::jobs::{JobContext, JobError, JobOutput, JobResult, Lane};
use crate::service::{Service, SubmitError};
use crate::store::{DatasetId, DatasetRecord, DatasetSource, RunKind};
use serde_json::json;
use std::path::PathBuf;

/// An experiment, checked against the bench's limits and the runs' quota.
pub struct ExperimentJob {
    service: Service,
    request: ExperimentRequest,
    plan: ExperimentPlan,
}

impl ExperimentJob {
    /// Checks `request` against what the bench can do, and that its frames (every one at full
    /// resolution: an upper bound) fit the runs' quota: refused before the bench moves.
    pub fn plan(service: &Service, request: ExperimentRequest) -> Result<Self, SubmitError> {
        let plan = bench_plan(service, &request)?;
        Ok(Self {
            service: service.clone(),
            request,
            plan,
        })
    }
}

impl Job for ExperimentJob {
    const KIND: RunKind = RunKind::Experiment;
    const LANE: Lane = Lane::Bench;

    type Request = ExperimentRequest;

    fn request(&self) -> &ExperimentRequest {
        &self.request
    }

    fn dataset(&self) -> Option<&DatasetId> {
        None
    }

    fn run(self, ctx: &JobContext) -> Result<JobOutput, JobError> {
        let (outcome, dataset) = capture_dataset(&self.service, &self.plan, ctx, ctx)?;
        let hardware_runs = outcome
            .manifest
            .runs
            .iter()
            .filter(|r| r.capture.is_some())
            .count();
        let full_resolution_runs = outcome.manifest.runs.len() - hardware_runs;
        let hardware = if hardware_runs > 0 {
            format!(" and {hardware_runs} runs in the camera's own schemes")
        } else {
            String::new()
        };
        Ok(JobOutput {
            message: format!(
                "{full_resolution_runs} runs x {} schemes{hardware} analysed; frames are dataset {}",
                self.plan.schemes.len(),
                dataset.id
            ),
            result: JobResult::Study {
                rows: outcome.rows,
                captures: outcome.captures,
            },
        })
    }
}

/// `request` planned against what the bench can do, with a stage to move, and its frames (every
/// one at full resolution: an upper bound) within the runs' quota: refused before the bench
/// moves.
pub(super) fn bench_plan(
    service: &Service,
    request: &ExperimentRequest,
) -> Result<ExperimentPlan, SubmitError> {
    let plan = request.plan(&service.limits)?;
    if !service.limits.has_stage() {
        return Err(SubmitError::NoStage);
    }
    service
        .store
        .check_runs_room(plan.frame_count() as u64 * service.frame_bytes)?;
    Ok(plan)
}

/// Captures `plan` on the bench (events through `sink`) and registers its frames as a dataset
/// of their own, so compare and diagnose read captured and imported measurements alike; the
/// run's record names it as the dataset the run made.
pub(super) fn capture_dataset(
    service: &Service,
    plan: &ExperimentPlan,
    ctx: &JobContext,
    sink: &dyn RunSink,
) -> Result<(ExperimentOutcome, DatasetRecord), JobError> {
    let (outcome, dataset) = capture_frames(service, plan, ctx, sink)?;
    ctx.store()
        .set_dataset(&ctx.run_id, &dataset.id)
        .map_err(JobError::failed)?;
    registered(sink, &dataset, "frames registered as dataset");
    Ok((outcome, dataset))
}

/// The event that says `dataset` is stored, `what` before its id.
pub(super) fn registered(sink: &dyn RunSink, dataset: &DatasetRecord, what: &str) {
    sink.event(
        EventKind::DatasetRegistered,
        1.0,
        &format!("{what} {}", dataset.id),
        json!({ "dataset_id": dataset.id }),
    );
}

/// [`capture_dataset`] without naming the dataset in the run's record, nor an event: for a run
/// whose record names the dataset it reads (an on-bench diagnosis).
pub(super) fn capture_frames(
    service: &Service,
    plan: &ExperimentPlan,
    ctx: &JobContext,
    sink: &dyn RunSink,
) -> Result<(ExperimentOutcome, DatasetRecord), JobError> {
    let outcome = on_bench(service, ctx, |lease, geometry, timeouts| {
        run_experiment(plan, &service.bench, lease, geometry, timeouts, sink)
    })?;
    service
        .check_datasets_room(&outcome.frames_dir)
        .map_err(JobError::failed)?;
    let dataset = ctx
        .store()
        .import_dataset_dir(
            &outcome.frames_dir,
            &plan.name,
            DatasetSource::Experiment(ctx.run_id.clone()),
        )
        .map_err(JobError::failed)?;
    Ok((outcome, dataset))
}

/// Captures `plan` on the bench for the run `ctx` (events through `sink`), without the study:
/// the manifest and the folder of the exported frames, registered as nothing (a
/// perpendicularity check reads them and deletes them).
pub(super) fn capture_only(
    service: &Service,
    plan: &ExperimentPlan,
    ctx: &JobContext,
    sink: &dyn RunSink,
) -> Result<(Manifest, PathBuf), JobError> {
    on_bench(service, ctx, |lease, geometry, timeouts| {
        capture_experiment(plan, &service.bench, lease, geometry, timeouts, sink)
    })
}

/// `step` on the bench held for the run `ctx`, told the bench's geometry and timeouts.
fn on_bench<T>(
    service: &Service,
    ctx: &JobContext,
    step: impl FnOnce(&BenchLease, BenchGeometry, BenchTimeouts) -> Result<T, RunnerError>,
) -> Result<T, JobError> {
    let lease = service
        .bench
        .hold(ctx.run_id.as_str())
        .map_err(JobError::failed)?;
    let geometry = BenchGeometry {
        scale_px_per_mm: service.config.bench.scale_px_per_mm,
        working_distance_mm: service.config.bench.working_distance_mm,
    };
    step(&lease, geometry, service.timeouts()).map_err(|e| match e {
        RunnerError::Cancelled => JobError::Cancelled,
        other => JobError::failed(other),
    })
}
