//! What each kind of job does once its lane picks it up.

use super::jobs::{JobContext, JobError, JobOutput, Work};
use super::Service;
use crate::dataset::Manifest;
use crate::dic::DicSettings;
use crate::experiment::{
    analyze_dataset, figure_svgs, rows_json, run_experiment, study_csv, ExperimentPlan,
    ExperimentRequest, FieldError, RunSink, RunnerError, SchemeSpec, StudyError,
};
use crate::reduce::Scheme;
use crate::store::DatasetId;
use serde::{Deserialize, Serialize};
use serde_json::json;

/// `POST /datasets/{id}/analyses`: the reductions and DIC to run on a stored dataset; every field
/// defaults to the paper's study.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields, default)]
pub struct AnalysisRequest {
    #[schema(value_type = Vec<Object>)]
    pub schemes: Vec<SchemeSpec>,
    #[schema(value_type = Object)]
    pub dic: DicSettings,
}

impl Default for AnalysisRequest {
    fn default() -> Self {
        let r = ExperimentRequest::default();
        Self {
            schemes: r.schemes,
            dic: r.dic,
        }
    }
}

pub struct AnalysisPlan {
    schemes: Vec<Scheme>,
    dic: DicSettings,
}

impl AnalysisRequest {
    pub fn plan(&self) -> Result<AnalysisPlan, FieldError> {
        // The experiment's checks of schemes and DIC settings are the ones that apply.
        let p = ExperimentRequest {
            schemes: self.schemes.clone(),
            dic: self.dic.clone(),
            ..ExperimentRequest::default()
        }
        .plan(true)?;
        Ok(AnalysisPlan {
            schemes: p.schemes,
            dic: p.dic,
        })
    }
}

fn fail(e: impl std::fmt::Display) -> JobError {
    JobError::Failed(e.to_string())
}

pub fn experiment(service: Service, plan: ExperimentPlan) -> Work {
    Box::new(move |ctx: &JobContext| {
        let lease = service.bench.hold(ctx.run_id.as_str()).map_err(fail)?;
        let outcome = run_experiment(
            &plan,
            &service.bench,
            &lease,
            service.config.bench.scale_px_per_mm,
            service.timeouts(),
            ctx,
        )
        .map_err(|e| match e {
            RunnerError::Cancelled => JobError::Cancelled,
            other => fail(other),
        })?;
        drop(lease);
        // The frames are also a dataset of their own, so compare and diagnose read captured and
        // imported measurements alike.
        let dataset = ctx
            .store()
            .import_dataset_dir(
                &outcome.frames_dir,
                &plan.name,
                &format!("experiment:{}", ctx.run_id),
            )
            .map_err(fail)?;
        ctx.event(
            "dataset_registered",
            1.0,
            &format!("frames registered as dataset {}", dataset.id),
            json!({ "dataset_id": dataset.id }),
        );
        Ok(JobOutput {
            message: format!(
                "{} runs x {} schemes analysed; frames are dataset {}",
                outcome.manifest.runs.len(),
                plan.schemes.len(),
                dataset.id
            ),
        })
    })
}

pub fn analysis(service: Service, dataset: DatasetId, plan: AnalysisPlan) -> Work {
    Box::new(move |ctx: &JobContext| {
        let dir = service.store.dataset_dir(&dataset);
        let manifest = Manifest::read(&dir).map_err(fail)?;
        let rows = analyze_dataset(&dir, &manifest, &plan.schemes, &plan.dic, &|done, total| {
            ctx.event(
                "pair_analyzed",
                done as f64 / total.max(1) as f64,
                &format!("{done} of {total} reduced pairs correlated"),
                json!({ "done": done, "total": total }),
            );
            !ctx.cancelled()
        })
        .map_err(|e| match e {
            StudyError::Cancelled => JobError::Cancelled,
            other => fail(other),
        })?;
        let text = serde_json::to_string_pretty(&rows_json(&rows)).expect("rows serialise");
        ctx.write("results/study.json", text.as_bytes())
            .map_err(fail)?;
        ctx.write("results/study.csv", study_csv(&rows).as_bytes())
            .map_err(fail)?;
        for (file, svg) in figure_svgs(&rows) {
            ctx.write(&format!("plots/{file}"), svg.as_bytes())
                .map_err(fail)?;
        }
        Ok(JobOutput {
            message: format!("{} rows from dataset {dataset}", rows.len()),
        })
    })
}
