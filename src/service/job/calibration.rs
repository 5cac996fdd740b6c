//! `POST /calibrations` and `ffdic calibrate`: a calibration plan captured on the bench (the
//! first half of the job's progress), the frames registered as a dataset, diagnosed in rounds at
//! the camera's own resolution and written as a camera card (the second half). The card's model
//! joins the stored models (`card-NAME-HASH`); the run's folder gets `results/card.json` (the
//! card, the rounds, the plan and the experiment it became), `results/card.txt` and
//! `results/diagnosis.json`.

use super::experiment::{bench_plan, capture_dataset};
use super::{diagnose_failure, progress_reporter, Job};
use crate::diagnose::{calibrate, CompareOptions};
use crate::experiment::{
    check_dic, check_schemes, CalibrationPlan, ExperimentPlan, ExperimentRequest, FieldError,
    RunSink, SchemeSpec,
};
use crate::model::ModelConfig;
use crate::report::camera_card_text;
use crate::service::jobs::{JobContext, JobError, JobOutput, JobResult, Lane};
use crate::service::scaled_sink::ScaledSink;
use crate::service::{NewModel, Service, SubmitError};
use crate::store::{DatasetId, RunKind};
use serde_json::json;

/// The share of a calibration's progress its capture takes.
const CAPTURE_SHARE: f64 = 0.5;

/// A calibration, checked: its rounds, its experiment against the bench, the runs' quota, its
/// model and its DIC.
pub struct CalibrationJob {
    service: Service,
    plan: ExperimentPlan,
    request: ExperimentRequest,
    calibration: CalibrationPlan,
    model: ModelConfig,
    options: CompareOptions,
}

impl CalibrationJob {
    pub fn plan(service: &Service, calibration: CalibrationPlan) -> Result<Self, SubmitError> {
        // The record keeps the plan as run: its phase scan's count stated.
        let calibration = calibration.with_phase_scan_stated();
        if !(1..=crate::diagnose::MAX_ROUNDS).contains(&calibration.rounds) {
            return Err(SubmitError::Field(crate::experiment::FieldError {
                field: "rounds".into(),
                reason: format!(
                    "must lie in [1, {}], got {}",
                    crate::diagnose::MAX_ROUNDS,
                    calibration.rounds
                ),
            }));
        }
        let request = calibration.experiment(&service.limits, service.sensor_px)?;
        let plan = bench_plan(service, &request)?;
        let model = service.requested_model(&calibration.model)?;
        let options = calibration_options(&calibration, service.sensor_px)?;
        Ok(Self {
            service: service.clone(),
            plan,
            request,
            calibration,
            model,
            options,
        })
    }
}

/// How a calibration's runs are analysed on a sensor of `size` px: at its own resolution
/// (`native`), with the plan's DIC over the whole frame unless it names a ROI, and its seed.
pub fn calibration_options(
    plan: &CalibrationPlan,
    size: (u32, u32),
) -> Result<CompareOptions, FieldError> {
    Ok(CompareOptions {
        dic: check_dic(&plan.dic_for(size))?,
        schemes: check_schemes(&[SchemeSpec::Preset("native".into())])?,
        seed: plan.seed,
    })
}

/// The card model's name prefix: `card-` and the plan's name in model-name characters.
pub fn card_prefix(name: &str) -> String {
    let clean: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.') {
                c
            } else {
                '-'
            }
        })
        .take(64)
        .collect();
    format!("card-{}", clean.trim_start_matches(['-', '.']))
}

impl Job for CalibrationJob {
    const KIND: RunKind = RunKind::Calibration;
    const LANE: Lane = Lane::Bench;

    type Request = CalibrationPlan;

    fn request(&self) -> &CalibrationPlan {
        &self.calibration
    }

    fn dataset(&self) -> Option<&DatasetId> {
        None
    }

    fn run(self, ctx: &JobContext) -> Result<JobOutput, JobError> {
        let service = &self.service;
        let capture = ScaledSink {
            inner: ctx,
            from: 0.0,
            span: CAPTURE_SHARE,
        };
        let (_, dataset) = capture_dataset(service, &self.plan, ctx, &capture)?;
        let diagnosis = ScaledSink {
            inner: ctx,
            from: CAPTURE_SHARE,
            span: 1.0 - CAPTURE_SHARE,
        };
        let report = progress_reporter(&diagnosis, "calibration fits");
        let dir = service.store.dataset_dir(&dataset.id);
        let (rounds, card) = calibrate(
            &dir,
            &self.model,
            &self.options,
            self.calibration.rounds,
            &card_prefix(&self.calibration.name),
            &report,
        )
        .map_err(diagnose_failure)?;
        service
            .add_model(&NewModel {
                toml: card.model.to_toml(),
            })
            .map_err(JobError::failed)?;
        let document = json!({
            "card": card,
            "model": card.model.name,
            "dataset_id": dataset.id,
            "rounds": rounds.to_json(),
            "plan": self.calibration,
            "experiment": self.request,
        });
        let write = |rel: &str, bytes: &[u8]| ctx.write(rel, bytes).map_err(JobError::failed);
        write(
            "results/card.json",
            &serde_json::to_vec_pretty(&document).map_err(JobError::failed)?,
        )?;
        write("results/card.txt", camera_card_text(&card).as_bytes())?;
        write(
            "results/diagnosis.json",
            &serde_json::to_vec_pretty(&rounds.to_json()).map_err(JobError::failed)?,
        )?;
        write("results/card-model.toml", card.model.to_toml().as_bytes())?;
        let found = card.found();
        Ok(JobOutput {
            message: format!(
                "card {}: {}; discrepancy {:.5} → {:.5} px",
                card.model.name,
                if found.is_empty() {
                    "nothing significant".to_string()
                } else {
                    found.join(", ")
                },
                card.baseline_px,
                card.card_px
            ),
            result: JobResult::Calibration {
                rounds: Box::new(rounds),
                card: Box::new(card),
                dataset: dataset.id,
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_card_is_named_in_model_name_characters() {
        assert_eq!(card_prefix("camera-card"), "card-camera-card");
        assert_eq!(card_prefix("lab 3 / lens #2"), "card-lab-3---lens--2");
        assert!(crate::store::is_model_name(&format!(
            "{}-0123456789ab",
            card_prefix(&"x".repeat(200))
        )));
    }
}
