//! `POST /sweeps`: a design map run by the daemon as a job on the compute lane. The sweep's
//! folder (`plan.json`, one result per task) lives inside the run's folder as `sweep/`, so a
//! daemon restarted mid-sweep keeps every finished task; the merged map goes where every run's
//! outputs go: `results/map.csv`, `results/map.json`, `results/recommendations.txt` and
//! `plots/*.svg`.

use super::Job;
use crate::experiment::{FieldError, RunSink};
use crate::model::ModelConfig;
use crate::run_event::EventKind;
use crate::service::jobs::{JobContext, JobError, JobOutput, JobResult, Lane};
use crate::service::{Service, SubmitError, SweepLimits};
use crate::store::{DatasetId, RunKind};
use crate::sweep::{
    map_files, merge, plan, read_results, run_shards, write_plan, Plan, SweepError, SweepSpec,
};
use serde_json::json;

/// The largest sweep any daemon runs (larger ones belong to `ffdic sweep` on a cluster: the
/// daemon shares its cores with the bench and every other job); `[sweeps] max_tasks` may lower it.
pub const MAX_DAEMON_SWEEP_TASKS: usize = 10_000;
/// The largest sensor side a daemon sweep renders, px; `[sweeps] max_sensor_side_px` may lower it.
pub const MAX_DAEMON_SENSOR_SIDE_PX: usize = 4096;
/// At most this many progress events per sweep (one per shard would flood a long sweep's log).
const PROGRESS_EVENTS: usize = 200;

/// Checks `spec` against the sweep's own rules and this daemon's `limits`, and plans it with
/// `model` (the model `spec.model` names, already looked up).
pub fn plan_sweep(
    spec: &SweepSpec,
    model: Option<&ModelConfig>,
    limits: &SweepLimits,
) -> Result<Plan, FieldError> {
    spec.validate()?;
    let c = &spec.camera;
    let side = limits.max_sensor_side_px;
    if c.width > side || c.height > side {
        return Err(FieldError {
            field: "camera".into(),
            reason: format!(
                "width and height at most {side} px on this daemon (`ffdic sweep` takes larger sensors)"
            ),
        });
    }
    let (tasks, max) = (spec.task_count(), limits.max_tasks);
    if tasks > max {
        return Err(FieldError {
            field: "axes".into(),
            reason: format!(
                "{tasks} tasks; this daemon runs at most {max} (`ffdic sweep slurm` runs larger sweeps on a cluster)"
            ),
        });
    }
    plan(spec, model).map_err(|e| FieldError {
        field: "axes".into(),
        reason: e.to_string(),
    })
}

/// A design map, checked against the sweep's rules and this daemon's `[sweeps]` limits, and
/// planned.
pub struct SweepJob {
    spec: SweepSpec,
    plan: Plan,
}

impl SweepJob {
    pub fn plan(service: &Service, spec: SweepSpec) -> Result<Self, SubmitError> {
        let model = spec
            .model
            .as_deref()
            .map(|name| service.requested_model(name))
            .transpose()?;
        let plan = plan_sweep(&spec, model.as_ref(), &service.config.sweeps)?;
        Ok(Self { spec, plan })
    }
}

impl Job for SweepJob {
    const KIND: RunKind = RunKind::Sweep;
    const LANE: Lane = Lane::Compute;

    type Request = SweepSpec;

    fn request(&self) -> &SweepSpec {
        &self.spec
    }

    fn dataset(&self) -> Option<&DatasetId> {
        None
    }

    fn run(self, ctx: &JobContext) -> Result<JobOutput, JobError> {
        let plan = self.plan;
        let dir = ctx.store().run_dir(&ctx.run_id).join("sweep");
        write_plan(&dir, &plan).map_err(JobError::failed)?;
        let (tasks, shards) = (plan.task_count(), plan.shards.len());
        ctx.event(
            EventKind::Planned,
            0.0,
            &format!("{tasks} tasks in {shards} shards"),
            json!({ "tasks": tasks, "shards": shards }),
        );
        let every = shards.div_ceil(PROGRESS_EVENTS).max(1);
        // A shard asks again, before every point, with the count already reported: one event
        // per count reached.
        let reported = std::sync::atomic::AtomicUsize::new(0);
        let counts = run_shards(&dir, &plan, &|_| true, &|done, total| {
            let new = reported.fetch_max(done, std::sync::atomic::Ordering::Relaxed) < done;
            if new && (done % every == 0 || done == total) {
                ctx.event(
                    EventKind::ShardsRun,
                    0.95 * done as f64 / total.max(1) as f64,
                    &format!("{done} of {total} shards run"),
                    json!({ "done": done, "total": total }),
                );
            }
            !ctx.cancelled()
        })
        .map_err(|e| match e {
            SweepError::Cancelled => JobError::Cancelled,
            other => JobError::failed(other),
        })?;
        let merged = merge(&plan, &read_results(&dir, &plan));
        for file in map_files(&plan, &merged) {
            let folder = if file.figure { "plots" } else { "results" };
            ctx.write(&format!("{folder}/{}", file.name), &file.bytes)
                .map_err(JobError::Failed)?;
        }
        ctx.event(
            EventKind::Merged,
            1.0,
            &format!("{} cells merged", merged.cells.len()),
            json!({ "cells": merged.cells.len(), "missing_tasks": merged.missing.len() }),
        );
        Ok(JobOutput {
            message: format!(
                "{} cells from {tasks} tasks ({} run now, {} shards found done)",
                merged.cells.len(),
                counts.tasks_run,
                counts.shards_skipped
            ),
            result: JobResult::Files,
        })
    }
}
