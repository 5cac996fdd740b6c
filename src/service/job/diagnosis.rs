//! `POST /datasets/{id}/diagnoses`: a stored dataset held against a model, the candidate
//! effects fitted and ranked, in rounds (the winner added, diagnosed again), on the compute lane.

use super::comparison::ModelAgainstDataset;
use super::CompareRequest;
use super::{diagnose_failure, progress_reporter, Job};
use crate::diagnose::{append_history, diagnose_rounds, HistoryEntry};
use crate::experiment::RunSink;
use crate::report::comparison_svgs;
use crate::service::jobs::{JobContext, JobError, JobOutput, JobResult, Lane};
use crate::service::{Service, SubmitError};
use crate::store::{DatasetId, RunKind};

/// A diagnosis, checked as a comparison is, with its rounds.
pub struct DiagnosisJob(ModelAgainstDataset);

impl DiagnosisJob {
    pub fn plan(
        service: &Service,
        dataset: &DatasetId,
        request: CompareRequest,
    ) -> Result<Self, SubmitError> {
        ModelAgainstDataset::plan(service, dataset, request).map(Self)
    }
}

impl Job for DiagnosisJob {
    const KIND: RunKind = RunKind::Diagnosis;
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
            request,
            model,
            options,
        } = self.0;
        let rounds = request.rounds;
        let dir = service.store.dataset_dir(&dataset);
        let report = progress_reporter(ctx, "candidate fits");
        let r =
            diagnose_rounds(&dir, &model, &options, rounds, &report).map_err(diagnose_failure)?;
        let text = serde_json::to_vec_pretty(&r.to_json()).map_err(JobError::failed)?;
        ctx.write("results/diagnosis.json", &text)
            .map_err(JobError::failed)?;
        if !r.verdicts.is_empty() {
            ctx.write(
                "results/winner-model.toml",
                r.final_model.to_toml().as_bytes(),
            )
            .map_err(JobError::failed)?;
        }
        let first = r
            .diagnoses
            .first()
            .ok_or_else(|| JobError::failed("no round ran"))?;
        if let Some(before) = &first.before {
            for (name, svg) in comparison_svgs(before) {
                ctx.write(&format!("plots/{name}"), svg.as_bytes())
                    .map_err(JobError::failed)?;
            }
        }
        // Several rounds: every step of the fall joins the history.
        if rounds > 1 {
            let steps = r
                .diagnoses
                .iter()
                .filter_map(|d| d.before.as_ref())
                .chain(r.diagnoses.last().and_then(|d| d.after.as_ref()));
            for cmp in steps {
                append_history(&dir, &HistoryEntry::of(cmp)).map_err(JobError::failed)?;
            }
        }
        let fall: Vec<String> = r
            .rounds
            .iter()
            .map(|x| format!("{:.5}", x.discrepancy_px))
            .chain(std::iter::once(format!("{:.5}", r.final_discrepancy_px)))
            .collect();
        let message = if r.verdicts.is_empty() {
            format!(
                "verdict none: no candidate explains the discrepancy of {:.5} ± {:.5} px",
                first.discrepancy_px, first.discrepancy_se_px
            )
        } else {
            format!(
                "verdict {}: discrepancy {} px",
                crate::model::effects::join_effects(&r.verdicts, ", "),
                fall.join(" → ")
            )
        };
        Ok(JobOutput {
            message,
            result: JobResult::Diagnosis(Box::new(r)),
        })
    }
}
