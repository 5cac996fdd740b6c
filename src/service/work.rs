//! What each kind of job does once its lane picks it up.

use super::jobs::{JobContext, JobError, JobOutput, JobResult, Work};
use super::Service;
use crate::dataset::Manifest;
use crate::diagnose::{
    append_history, compare, diagnose_rounds, CompareOptions, Comparison, DiagnoseError,
    HistoryEntry, MAX_ROUNDS,
};
use crate::dic::DicSettings;
use crate::experiment::{
    analyze_dataset, check_dic, check_schemes, run_experiment, study_files, BenchGeometry,
    ExperimentOutcome, ExperimentPlan, ExperimentRequest, FieldError, RunSink, RunnerError,
    SchemeSpec, StudyError,
};
use crate::model::ModelConfig;
use crate::reduce::Scheme;
use crate::report::comparison_svgs;
use crate::run_event::EventKind;
use crate::store::{DatasetId, DatasetRecord, DatasetSource};
use serde::{Deserialize, Serialize};
use serde_json::json;

/// `POST /datasets/{id}/analyses`: the reductions and DIC to run on a stored dataset; every field
/// defaults to the paper's study.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields, default)]
pub struct AnalysisRequest {
    #[schema(value_type = Vec<Object>, min_items = 1)]
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
        Ok(AnalysisPlan {
            schemes: check_schemes(&self.schemes)?,
            dic: check_dic(&self.dic)?,
        })
    }
}

impl AnalysisPlan {
    /// Subset pixels one IC-GN iteration visits over `runs` runs of `(width, height)` frames:
    /// Σ over schemes of points × subset² (a capture-mode run, analysed in its own scheme only,
    /// is counted as a full-resolution one: an upper bound).
    pub fn subset_pixels(&self, (width, height): (usize, usize), runs: usize) -> u64 {
        let side = self.dic.subset_px as u64;
        let per_run: u64 = self
            .schemes
            .iter()
            .filter_map(|scheme| {
                let (w, h) = scheme.output_size(width, height).ok()?;
                let grid = crate::dic::PoiGrid::new(&self.dic, w, h).ok()?;
                Some((grid.nx() * grid.ny()) as u64 * side * side)
            })
            .sum();
        per_run.saturating_mul(runs as u64)
    }

    /// Refuses, naming `dic.step_px`, an analysis that asks for more than `max_subset_pixels`.
    pub fn check_work(
        &self,
        size: (usize, usize),
        runs: usize,
        max_subset_pixels: u64,
    ) -> Result<(), FieldError> {
        let work = self.subset_pixels(size, runs);
        if work <= max_subset_pixels {
            return Ok(());
        }
        Err(FieldError {
            field: "dic.step_px".into(),
            reason: format!(
                "{runs} runs x {} schemes at subset {} px and step {} px visit {work:.3e} subset pixels per IC-GN iteration; this daemon takes at most {max_subset_pixels:.3e} (jobs.max_analysis_subset_pixels): a larger step, a smaller subset or a roi",
                self.schemes.len(),
                self.dic.subset_px,
                self.dic.step_px
            ),
        })
    }
}

/// Captures `plan` on the bench (events through `sink`) and registers its frames as a dataset
/// of their own, so compare and diagnose read captured and imported measurements alike.
pub(super) fn capture_dataset(
    service: &Service,
    plan: &ExperimentPlan,
    ctx: &JobContext,
    sink: &dyn RunSink,
) -> Result<(ExperimentOutcome, DatasetRecord), JobError> {
    let lease = service
        .bench
        .hold(ctx.run_id.as_str())
        .map_err(JobError::failed)?;
    let outcome = run_experiment(
        plan,
        &service.bench,
        &lease,
        BenchGeometry {
            scale_px_per_mm: service.config.bench.scale_px_per_mm,
            working_distance_mm: service.config.bench.working_distance_mm,
        },
        service.timeouts(),
        sink,
    )
    .map_err(|e| match e {
        RunnerError::Cancelled => JobError::Cancelled,
        other => JobError::failed(other),
    })?;
    drop(lease);
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
    ctx.store()
        .set_dataset(&ctx.run_id, &dataset.id)
        .map_err(JobError::failed)?;
    sink.event(
        EventKind::DatasetRegistered,
        1.0,
        &format!("frames registered as dataset {}", dataset.id),
        json!({ "dataset_id": dataset.id }),
    );
    Ok((outcome, dataset))
}

pub fn experiment(service: Service, plan: ExperimentPlan) -> Work {
    Box::new(move |ctx: &JobContext| {
        let (outcome, dataset) = capture_dataset(&service, &plan, ctx, ctx)?;
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
                plan.schemes.len(),
                dataset.id
            ),
            result: JobResult::Study {
                rows: outcome.rows,
                captures: outcome.captures,
            },
        })
    })
}

pub fn analysis(service: Service, dataset: DatasetId, plan: AnalysisPlan) -> Work {
    Box::new(move |ctx: &JobContext| {
        let dir = service.store.dataset_dir(&dataset);
        let manifest = Manifest::read(&dir).map_err(JobError::failed)?;
        let rows = analyze_dataset(
            &dir,
            &manifest,
            &plan.schemes,
            &plan.dic,
            &|done, total| {
                ctx.event(
                    EventKind::PairAnalyzed,
                    done as f64 / total.max(1) as f64,
                    &format!("{done} of {total} reduced pairs correlated"),
                    json!({ "done": done, "total": total }),
                );
                !ctx.cancelled()
            },
            &|| ctx.cancelled(),
        )
        .map_err(|e| match e {
            StudyError::Cancelled => JobError::Cancelled,
            other => JobError::failed(other),
        })?;
        let (rows, files) = study_files(&manifest, &rows);
        for (rel, bytes) in files {
            ctx.write(&rel, &bytes).map_err(JobError::failed)?;
        }
        Ok(JobOutput {
            message: format!("{} rows from dataset {dataset}", rows.len()),
            result: JobResult::Study {
                rows,
                captures: Vec::new(),
            },
        })
    })
}

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

/// Reports progress as events, at most about a hundred per job (each event is a synced append).
pub(super) fn progress_reporter<'a>(
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

pub(super) fn diagnose_failure(e: DiagnoseError) -> JobError {
    match e {
        DiagnoseError::Cancelled => JobError::Cancelled,
        other => JobError::failed(other),
    }
}

/// Writes a comparison's JSON and plots into the job's folder and records it in the dataset's
/// history.
fn keep_comparison(
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

pub fn comparison(
    service: Service,
    dataset: DatasetId,
    model: ModelConfig,
    options: CompareOptions,
) -> Work {
    Box::new(move |ctx: &JobContext| {
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
    })
}

pub fn diagnosis(
    service: Service,
    dataset: DatasetId,
    model: ModelConfig,
    options: CompareOptions,
    rounds: usize,
) -> Work {
    Box::new(move |ctx: &JobContext| {
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
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 36's dense analysis: subset 101 px at every pixel of the whole 1280x1080
    /// reductions, three schemes.
    fn dense() -> AnalysisRequest {
        serde_json::from_value(json!({"dic": {"subset_px": 101, "step_px": 1,
            "roi": {"x": 0, "y": 0, "width": 1280, "height": 1080}}}))
        .unwrap()
    }

    #[test]
    fn the_work_of_a_dense_analysis_is_its_points_times_its_subset_area() {
        let plan = dense().plan().unwrap();
        let one = plan.subset_pixels((2560, 2160), 1);
        // Subset centres from 50 to 1229 in x and to 1029 in y, at every pixel, in each of the
        // three 1280x1080 reductions.
        assert_eq!(one, 3 * 1180 * 980 * 101 * 101);
        assert_eq!(plan.subset_pixels((2560, 2160), 3), 3 * one);
        assert!(plan.check_work((2560, 2160), 1, one).is_ok());
        let e = plan.check_work((2560, 2160), 3, 2 * one).unwrap_err();
        assert_eq!(e.field, "dic.step_px");
    }
}
