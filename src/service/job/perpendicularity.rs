//! `POST /perpendicularity-checks` and the dashboard's perpendicularity check: the target moved
//! along +x and −x from the reference position (the first 80 % of the job's progress), the two
//! pairs correlated at the camera's own resolution and the tilt and the stage's angle read from
//! their fields (`diagnose::read_perpendicularity`). A setup aid pressed again and again while the
//! mount is adjusted, so it keeps nothing heavy: the frames are deleted once read, no dataset and
//! no model are stored; the run's folder keeps `results/perpendicularity.json`.

use super::experiment::{bench_plan, capture_only};
use super::Job;
use crate::dataset::Manifest;
use crate::diagnose::{read_perpendicularity, PerpendicularityReading, ReadoutRun, ReadoutSetting};
use crate::dic::{DicError, PreparedReference, Watch};
use crate::experiment::{ExperimentPlan, PerpendicularityCheck, RunSink};
use crate::image::read_image;
use crate::run_event::EventKind;
use crate::service::jobs::{JobContext, JobError, JobOutput, JobResult, Lane};
use crate::service::scaled_sink::ScaledSink;
use crate::service::{Service, SubmitError};
use crate::store::{DatasetId, RunKind};
use serde_json::json;
use std::path::Path;

/// The share of a check's progress its capture takes.
const CAPTURE_SHARE: f64 = 0.8;

/// A perpendicularity check, planned against the bench.
pub struct PerpendicularityJob {
    service: Service,
    check: PerpendicularityCheck,
    plan: ExperimentPlan,
}

impl PerpendicularityJob {
    pub fn plan(service: &Service, check: PerpendicularityCheck) -> Result<Self, SubmitError> {
        let request = check.experiment(&service.limits, service.sensor_px)?;
        let plan = bench_plan(service, &request)?;
        Ok(Self {
            service: service.clone(),
            check,
            plan,
        })
    }
}

impl Job for PerpendicularityJob {
    const KIND: RunKind = RunKind::Perpendicularity;
    const LANE: Lane = Lane::Bench;

    type Request = PerpendicularityCheck;

    fn request(&self) -> &PerpendicularityCheck {
        &self.check
    }

    fn dataset(&self) -> Option<&DatasetId> {
        None
    }

    fn run(self, ctx: &JobContext) -> Result<JobOutput, JobError> {
        // The capture reports up to half of an experiment's progress: here it is the first
        // `CAPTURE_SHARE` of the check's.
        let capture = ScaledSink {
            inner: ctx,
            from: 0.0,
            span: 2.0 * CAPTURE_SHARE,
        };
        let read = capture_only(&self.service, &self.plan, ctx, &capture).and_then(
            |(manifest, frames_dir)| {
                read_frames(&self.service, &self.plan, &manifest, &frames_dir, ctx)
            },
        );
        // The frames were for this reading only, whatever it gave: a failed or cancelled
        // capture's too.
        let _ = std::fs::remove_dir_all(ctx.store().run_dir(&ctx.run_id).join("frames"));
        let reading = read?;
        ctx.write(
            "results/perpendicularity.json",
            &serde_json::to_vec_pretty(&reading).map_err(JobError::failed)?,
        )
        .map_err(JobError::failed)?;
        ctx.event(
            EventKind::Progress,
            1.0,
            "tilt read",
            json!({ "significant": reading.significant }),
        );
        Ok(JobOutput {
            message: format!(
                "tilt about y {:.5} ± {:.5} rad, about x {:.5} ± {:.5} rad at {:.0} mm{}; stage angle {:.6} ± {:.6} rad",
                reading.tilt_about_y_rad,
                reading.tilt_about_y_se_rad,
                reading.tilt_about_x_rad,
                reading.tilt_about_x_se_rad,
                reading.working_distance_mm,
                if reading.working_distance_stated { "" } else { " (assumed)" },
                reading.stage_angle_rad,
                reading.stage_angle_se_rad,
            ),
            result: JobResult::Perpendicularity(Box::new(reading)),
        })
    }
}

/// The reference against each moved frame, then the reading; a cancel of `ctx` ends a
/// correlation within a point.
fn read_frames(
    service: &Service,
    plan: &ExperimentPlan,
    manifest: &Manifest,
    frames_dir: &Path,
    ctx: &JobContext,
) -> Result<PerpendicularityReading, JobError> {
    let runs = &manifest.runs;
    let first = runs
        .first()
        .ok_or_else(|| JobError::Failed("the check captured no runs".into()))?;
    let image = |name: &str| {
        read_image(&frames_dir.join(name))
            .map(|(image, _)| image)
            .map_err(JobError::failed)
    };
    let reference = image(&first.reference)?;
    let (width, height) = (reference.width(), reference.height());
    let prepared = PreparedReference::new(&reference, &plan.dic).map_err(JobError::failed)?;
    let cancelled = || ctx.cancelled();
    let fields = runs
        .iter()
        .map(|run| {
            let watch = Watch {
                progress: None,
                cancelled: Some(&cancelled),
            };
            prepared
                .correlate_watched(&image(&run.deformed)?, watch)
                .map_err(|e| match e {
                    DicError::Cancelled => JobError::Cancelled,
                    e => JobError::failed(e),
                })
        })
        .collect::<Result<Vec<_>, JobError>>()?;
    let readout: Vec<ReadoutRun> = runs
        .iter()
        .zip(&fields)
        .map(|(run, dic)| ReadoutRun {
            commanded_mm: (run.stage.dx_mm, run.stage.dy_mm),
            dic,
        })
        .collect();
    let setting = ReadoutSetting {
        width_px: width,
        height_px: height,
        scale_px_per_mm: service.config.bench.scale_px_per_mm,
        working_distance_mm: service.config.bench.working_distance_mm,
    };
    read_perpendicularity(&readout, &setting).map_err(JobError::failed)
}
