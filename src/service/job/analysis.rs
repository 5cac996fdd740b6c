//! `POST /datasets/{id}/analyses`: the fill-factor study of a stored dataset (its pairs
//! reduced by every scheme and correlated), on the compute lane; given a camera card, each row
//! also with the card's geometry taken off.

use super::Job;
use crate::dataset::Manifest;
use crate::dic::DicSettings;
use crate::experiment::{
    check_dic, check_schemes, ExperimentRequest, FieldError, RunSink, SchemeSpec,
};
use crate::model::GeometryCorrection;
use crate::reduce::Scheme;
use crate::report::study_files;
use crate::run_event::EventKind;
use crate::service::jobs::{JobContext, JobError, JobOutput, JobResult, Lane};
use crate::service::{Service, SubmitError};
use crate::store::{DatasetId, RunKind};
use crate::study::{analyze_dataset_with, CardCorrection, StudyError};
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
    /// A camera card (`POST /calibrations`; a stored or embedded model's name): each row also
    /// holds its displacement with the card's lens distortion and target tilt taken off
    /// (`card`: the corrected u and v and their bias against the commanded move).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub card: Option<String>,
}

impl Default for AnalysisRequest {
    fn default() -> Self {
        let r = ExperimentRequest::default();
        Self {
            schemes: r.schemes,
            dic: r.dic,
            card: None,
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

/// An analysis of a stored dataset, checked: the dataset exists and the work is within
/// `jobs.max_analysis_subset_pixels`.
pub struct AnalysisJob {
    service: Service,
    dataset: DatasetId,
    request: AnalysisRequest,
    plan: AnalysisPlan,
    card: Option<CardCorrection>,
}

impl AnalysisJob {
    pub fn plan(
        service: &Service,
        dataset: &DatasetId,
        request: AnalysisRequest,
    ) -> Result<Self, SubmitError> {
        let plan = request.plan()?;
        let record = service.store.get_dataset(dataset)?;
        plan.check_work(
            (record.width, record.height),
            record.runs,
            service.config.jobs.max_analysis_subset_pixels,
        )?;
        let card = match &request.card {
            None => None,
            Some(name) => {
                let model = service.model_named_by(name, "card")?;
                // The manifest's scale places a tilt's plane (a card fitted on this bench).
                let manifest =
                    Manifest::read(&service.store.dataset_dir(dataset)).map_err(|e| {
                        SubmitError::Field(FieldError {
                            field: "card".into(),
                            reason: format!("the dataset's manifest: {e}"),
                        })
                    })?;
                Some(CardCorrection {
                    model: model.name.clone(),
                    correction: GeometryCorrection::of(
                        &model.effects,
                        record.width,
                        record.height,
                        manifest.scale_px_per_mm,
                    ),
                })
            }
        };
        Ok(Self {
            service: service.clone(),
            dataset: dataset.clone(),
            request,
            plan,
            card,
        })
    }
}

impl Job for AnalysisJob {
    const KIND: RunKind = RunKind::Analysis;
    const LANE: Lane = Lane::Compute;

    type Request = AnalysisRequest;

    fn request(&self) -> &AnalysisRequest {
        &self.request
    }

    fn dataset(&self) -> Option<&DatasetId> {
        Some(&self.dataset)
    }

    fn run(self, ctx: &JobContext) -> Result<JobOutput, JobError> {
        let (service, dataset, plan) = (self.service, self.dataset, self.plan);
        let dir = service.store.dataset_dir(&dataset);
        let manifest = Manifest::read(&dir).map_err(JobError::failed)?;
        let rows = analyze_dataset_with(
            &dir,
            &manifest,
            (&plan.schemes, &plan.dic, self.card.as_ref()),
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
            &|_, _, _| {},
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
    }
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
