//! `POST /datasets/{id}/comparisons` and `ffdic compare`'s daemon twin: a stored dataset held
//! against a model (both sides analysed alike), on the compute lane; the comparison joins the
//! dataset's history.

use super::AnalysisRequest;
use super::{diagnose_failure, progress_reporter, Job};
use crate::diagnose::{
    append_history, compare, CompareOptions, Comparison, HistoryEntry, MAX_ROUNDS,
};
use crate::dic::DicSettings;
use crate::experiment::{check_dic, check_schemes, FieldError, RunSink, SchemeSpec};
use crate::model::ModelConfig;
use crate::report::comparison_svgs;
use crate::service::jobs::{JobContext, JobError, JobOutput, JobResult, Lane};
use crate::service::{Service, SubmitError};
use crate::store::{DatasetId, RunKind};
use serde::{Deserialize, Serialize};

/// `POST /datasets/{id}/comparisons` and `/diagnoses`: which model, and how both sides are
/// analysed; every field has a default (the baseline model, the paper's schemes and DIC).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields, default)]
pub struct CompareRequest {
    /// A name from `GET /models`.
    pub model: String,
    #[schema(value_type = Vec<Object>, min_items = 1)]
    pub schemes: Vec<SchemeSpec>,
    #[schema(value_type = Object)]
    pub dic: DicSettings,
    /// Seed of the model's speckle layouts and noise (fixed: a comparison is reproducible).
    pub seed: u64,
    /// Diagnoses only: add the winner and diagnose again, up to this many rounds (1–8; stops at
    /// verdict `none`). Each round's comparison joins the dataset's history.
    #[schema(minimum = 1, maximum = 8)]
    pub rounds: usize,
}

impl Default for CompareRequest {
    fn default() -> Self {
        let a = AnalysisRequest::default();
        Self {
            model: "baseline".into(),
            schemes: a.schemes,
            dic: a.dic,
            seed: CompareOptions::default().seed,
            rounds: 1,
        }
    }
}

impl CompareRequest {
    pub fn options(&self) -> Result<CompareOptions, FieldError> {
        if !(1..=MAX_ROUNDS).contains(&self.rounds) {
            return Err(FieldError {
                field: "rounds".into(),
                reason: format!("must lie in [1, {MAX_ROUNDS}], got {}", self.rounds),
            });
        }
        Ok(CompareOptions {
            dic: check_dic(&self.dic)?,
            schemes: check_schemes(&self.schemes)?,
            seed: self.seed,
        })
    }
}

/// What a comparison and a diagnosis are planned into: the request's options checked, its model
/// found, its dataset stored.
pub(super) struct ModelAgainstDataset {
    pub(super) service: Service,
    pub(super) dataset: DatasetId,
    pub(super) request: CompareRequest,
    pub(super) model: ModelConfig,
    pub(super) options: CompareOptions,
}

impl ModelAgainstDataset {
    pub(super) fn plan(
        service: &Service,
        dataset: &DatasetId,
        request: CompareRequest,
    ) -> Result<Self, SubmitError> {
        let options = request.options()?;
        let model = service.requested_model(&request.model)?;
        service.store.get_dataset(dataset)?;
        Ok(Self {
            service: service.clone(),
            dataset: dataset.clone(),
            request,
            model,
            options,
        })
    }
}

/// A comparison, checked.
pub struct ComparisonJob(ModelAgainstDataset);

impl ComparisonJob {
    pub fn plan(
        service: &Service,
        dataset: &DatasetId,
        request: CompareRequest,
    ) -> Result<Self, SubmitError> {
        ModelAgainstDataset::plan(service, dataset, request).map(Self)
    }
}

impl Job for ComparisonJob {
    const KIND: RunKind = RunKind::Comparison;
    const LANE: Lane = Lane::Compute;
    type Request = CompareRequest;

    fn request(&self) -> &CompareRequest {
        &self.0.request
    }

    fn dataset(&self) -> Option<&DatasetId> {
        Some(&self.0.dataset)
    }

    fn run(self, ctx: &JobContext) -> Result<JobOutput, JobError> {
        let ModelAgainstDataset {
            service,
            dataset,
            model,
            options,
            ..
        } = self.0;
        let dir = service.store.dataset_dir(&dataset);
        let report = progress_reporter(ctx, "analyses (measured and model)");
        let cmp = compare(&dir, &model, &options, &report).map_err(diagnose_failure)?;
        keep_comparison(ctx, &dir, &cmp)?;
        Ok(JobOutput {
            message: format!(
                "discrepancy {:.5} px against model {} ({})",
                cmp.discrepancy_px, cmp.model.name, cmp.model.version
            ),
            result: JobResult::Comparison(Box::new(cmp)),
        })
    }
}

/// Writes a comparison's JSON and plots into the job's folder and records it in the dataset's
/// history.
pub(super) fn keep_comparison(
    ctx: &JobContext,
    dataset_dir: &std::path::Path,
    cmp: &Comparison,
) -> Result<(), JobError> {
    let text = serde_json::to_vec_pretty(cmp).map_err(JobError::failed)?;
    ctx.write("results/comparison.json", &text)
        .map_err(JobError::failed)?;
    for (name, svg) in comparison_svgs(cmp) {
        ctx.write(&format!("plots/{name}"), svg.as_bytes())
            .map_err(JobError::failed)?;
    }
    append_history(dataset_dir, &HistoryEntry::of(cmp)).map_err(JobError::failed)
}
