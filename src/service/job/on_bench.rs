//! `POST /datasets/{id}/on-bench` and `ffdic diagnose --on-bench` (issue 33, "resolve confounds
//! on the bench"): a stored dataset diagnosed; the runs that separate what the diagnosis left
//! open ([`crate::diagnose::runs_to_separate`]: the pairs its design confounds, the effects it
//! cannot reveal) become a calibration-style plan on the dataset's target and move size, which
//! the bench captures; the frames are appended to the dataset's runs as a new stored dataset (the
//! original is left as it was) and diagnosed again with the same model and options. On the bench
//! lane: the before and the after belong to one request, and the capture between them needs the
//! hardware.

use super::comparison::ModelAgainstDataset;
use super::experiment::{capture_frames, registered};
use super::{diagnose_failure, progress_reporter, CompareRequest, Job};
use crate::bench::BenchLimits;
use crate::dataset::{merge_datasets, Manifest};
use crate::diagnose::{
    design_for, diagnose_rounds, open_questions, CompareOptions, Confounded, MoveDesign, Rounds,
    SeparatingRuns, STEP_SERIES_MIN_STEPS,
};
use crate::experiment::{
    field_error, CalibrationPlan, ExperimentRequest, FieldError, MoveSpec, PatternSpec, RunSink,
    SchemeSpec,
};
use crate::model::{ModelConfig, SpecklePattern};
use crate::service::jobs::{JobContext, JobError, JobOutput, JobResult, Lane};
use crate::service::scaled_sink::ScaledSink;
use crate::service::{Service, SubmitError};
use crate::store::{DatasetId, DatasetRecord, DatasetSource, RunKind, RunStore};
use serde::Serialize;
use serde_json::json;
use std::path::Path;

/// The shares of the job's progress: the first diagnosis, the capture, the second diagnosis.
const FIRST_SHARE: f64 = 0.4;
const CAPTURE_SHARE: f64 = 0.2;

/// The prefix of the bench's run ids, frame files and pattern labels in the merged dataset.
const BENCH_PREFIX: &str = "bench-";

/// An on-bench diagnosis, checked: a diagnosis's request, a stage, a dataset that names the
/// target the bench is to mount.
pub struct OnBenchJob(ModelAgainstDataset);

/// What the bench added to a dataset.
#[derive(Clone, Debug, Default, Serialize)]
pub struct OnBenchCapture {
    /// The kinds of runs the first diagnosis asked for (empty: nothing a bench resolves).
    pub runs: Vec<SeparatingRuns>,
    /// The experiment that captured them.
    pub plan: Option<ExperimentRequest>,
    /// How its moves were chosen: the geometric pairs' signature correlations before and after.
    pub design: Option<MoveDesign>,
    /// The bench's frames alone, as a stored dataset.
    pub captured: Option<DatasetId>,
    /// The dataset's runs and the bench's (ids `bench-…`), diagnosed again.
    pub dataset: Option<DatasetId>,
}

impl OnBenchJob {
    /// A client's request (`POST /datasets/{id}/on-bench`): its model from the stored models.
    pub fn plan(
        service: &Service,
        dataset: &DatasetId,
        request: CompareRequest,
    ) -> Result<Self, SubmitError> {
        Self::checked(ModelAgainstDataset::plan(service, dataset, request)?)
    }

    /// `ffdic diagnose --on-bench`'s job: a model of the command line's (a file or a name), its
    /// options and rounds.
    pub fn for_model(
        service: &Service,
        dataset: &DatasetId,
        model: ModelConfig,
        options: CompareOptions,
        rounds: usize,
    ) -> Result<Self, SubmitError> {
        service.store.get_dataset(dataset)?;
        let request = CompareRequest {
            model: model.name.clone(),
            schemes: options
                .schemes
                .iter()
                .cloned()
                .map(SchemeSpec::Custom)
                .collect(),
            dic: options.dic.clone(),
            seed: options.seed,
            rounds,
        };
        Self::checked(ModelAgainstDataset {
            service: service.clone(),
            dataset: dataset.clone(),
            request,
            model,
            options,
        })
    }

    fn checked(job: ModelAgainstDataset) -> Result<Self, SubmitError> {
        if !job.service.limits.has_stage() {
            return Err(SubmitError::NoStage);
        }
        let manifest = Manifest::read(&job.service.store.dataset_dir(&job.dataset))
            .map_err(|e| field_error("dataset", e.to_string()))?;
        target_pattern(&manifest)?;
        Ok(Self(job))
    }
}

/// The target the bench mounts: the dataset's first named pattern. A preset's name is that preset
/// (what the mock bench renders); another label is the print the dataset states (its dot
/// diameter, spacing and contrast; softness, placement and profile where stated), which a lab's
/// own target needs to be mounted by name. An exec camera is told the label either way.
fn target_pattern(manifest: &Manifest) -> Result<PatternSpec, FieldError> {
    let info = manifest
        .runs
        .iter()
        .find_map(|r| r.pattern.as_ref())
        .ok_or_else(|| {
            field_error(
                "dataset",
                "the dataset names no pattern: the bench must know which target to mount",
            )
        })?;
    if SpecklePattern::preset(&info.label).is_some() {
        return Ok(PatternSpec::Preset(info.label.clone()));
    }
    let (Some(dot_diameter_mm), Some(dot_spacing_mm), Some(contrast)) =
        (info.dot_diameter_mm, info.dot_spacing_mm, info.contrast)
    else {
        return Err(field_error(
            "dataset",
            format!(
                "the dataset's pattern '{}' is not a preset the bench knows (a, b, c) and does not state its dot_diameter_mm, dot_spacing_mm and contrast: the bench cannot mount it",
                info.label
            ),
        ));
    };
    Ok(PatternSpec::Custom(SpecklePattern {
        label: info.label.clone(),
        dot_diameter_mm,
        dot_spacing_mm,
        contrast,
        edge_softness_mm: info.edge_softness_mm.unwrap_or(0.0),
        placement: info.placement.unwrap_or_default(),
        profile: info.profile.unwrap_or_default(),
        min_gap_mm: 0.0,
    }))
}

/// The experiment that captures `runs` on the dataset's target (`open`: the pairs the
/// diagnosis left confounded), with the design of its moves: chosen from ±x and ±y at a quarter,
/// a half and all of the dataset's largest move (the calibration's default size when it has no
/// move) to meet the identifiability rules `runs` names and make the geometric pairs' fields
/// differ, fewest first ([`crate::diagnose::design_for`]); a phase scan of the rule's
/// [`STEP_SERIES_MIN_STEPS`] steps along each axis for a step series, two static frames for repeats.
fn separating_plan(
    manifest: &Manifest,
    (open, runs): (&[Confounded], &[SeparatingRuns]),
    limits: &BenchLimits,
    sensor_px: (u32, u32),
) -> Result<(ExperimentRequest, MoveDesign), FieldError> {
    let scale = manifest.scale_px_per_mm;
    let existing_px: Vec<(f64, f64)> = manifest
        .runs
        .iter()
        .map(|r| (r.stage.dx_mm * scale, r.stage.dy_mm * scale))
        .collect();
    let largest_mm = manifest
        .runs
        .iter()
        .map(|r| r.stage.dx_mm.hypot(r.stage.dy_mm))
        .fold(0.0, f64::max);
    let wants = |k: SeparatingRuns| runs.contains(&k);
    let calibration = CalibrationPlan {
        name: "on-bench".into(),
        pattern: target_pattern(manifest)?,
        // The fewest steps the identifiability rule takes as a series, along each axis: six
        // runs (issue 33: at most six for a confound).
        phase_scan_count: Some(if wants(SeparatingRuns::StepSeries) {
            STEP_SERIES_MIN_STEPS
        } else {
            0
        }),
        static_frames: if wants(SeparatingRuns::StaticRepeats) {
            2
        } else {
            0
        },
        rounds: 1,
        ..CalibrationPlan::default()
    };
    let largest_mm = match largest_mm > 0.0 {
        true => largest_mm,
        false => calibration
            .sizes_mm(limits, sensor_px.0)
            .into_iter()
            .fold(0.0, f64::max),
    };
    let menu_mm: Vec<(f64, f64)> = [0.25, 0.5, 1.0]
        .iter()
        .flat_map(|s| {
            let d = s * largest_mm;
            [(d, 0.0), (-d, 0.0), (0.0, d), (0.0, -d)]
        })
        .collect();
    let menu_px: Vec<(f64, f64)> = menu_mm.iter().map(|m| (m.0 * scale, m.1 * scale)).collect();
    let frame = (f64::from(sensor_px.0), f64::from(sensor_px.1));
    let design = design_for(open, runs, &existing_px, &menu_px, frame);
    let mut moves: Vec<MoveSpec> = design
        .moves_px
        .iter()
        .enumerate()
        .map(|(k, m)| MoveSpec {
            id: format!("m{}", k + 1),
            dx_mm: m.0 / scale,
            dy_mm: m.1 / scale,
        })
        .collect();
    if moves.is_empty() && !wants(SeparatingRuns::StepSeries) {
        // Static frames alone: an experiment has a move; the smallest of the menu.
        moves.push(MoveSpec {
            id: "m1".into(),
            dx_mm: menu_mm[0].0,
            dy_mm: 0.0,
        });
    }
    let request = calibration.experiment_with_moves(limits, sensor_px, moves)?;
    Ok((request, design))
}

/// The dataset in `base_dir` with the runs of the stored dataset `added` appended (ids, frame
/// files and pattern labels prefixed [`BENCH_PREFIX`]), committed to `store` as a new dataset.
fn merge_into_store(
    store: &RunStore,
    base_dir: &Path,
    added: &DatasetId,
    name: &str,
    source: DatasetSource,
) -> Result<DatasetRecord, String> {
    let staging = store.stage_dataset().map_err(|e| e.to_string())?;
    merge_datasets(
        base_dir,
        &store.dataset_dir(added),
        BENCH_PREFIX,
        staging.path(),
    )
    .map_err(|e| e.to_string())?;
    store
        .commit_dataset(staging, name, source)
        .map_err(|e| e.to_string())
}

/// What a diagnosis's rounds left open, as the on-bench document shows it before and after.
fn open_document(r: Option<&Rounds>) -> serde_json::Value {
    r.map_or(serde_json::Value::Null, |r| {
        let (confounded, not_identifiable) = open_questions(&r.diagnoses);
        json!({ "confounded": confounded, "not_identifiable": not_identifiable })
    })
}

/// The confounded pairs the rounds' design left, as `a/b` words.
fn design_confounds(r: &Rounds) -> Vec<String> {
    open_questions(&r.diagnoses)
        .0
        .iter()
        .filter(|c| c.evidence == "design")
        .map(|c| c.effects.join("/"))
        .collect()
}

/// Captures `bench.runs` on the bench (the job's progress from the first diagnosis's share on)
/// and stores the dataset `dataset` with them appended; fills in `bench`'s plan and datasets.
fn capture_and_merge(
    service: &Service,
    dataset: &DatasetId,
    open: &[Confounded],
    bench: &mut OnBenchCapture,
    ctx: &JobContext,
) -> Result<DatasetRecord, JobError> {
    let dir = service.store.dataset_dir(dataset);
    let manifest = Manifest::read(&dir).map_err(JobError::failed)?;
    let (request, design) = separating_plan(
        &manifest,
        (open, &bench.runs),
        &service.limits,
        service.sensor_px,
    )
    .map_err(JobError::failed)?;
    let experiment = request.plan(&service.limits).map_err(JobError::failed)?;
    service
        .store
        .check_runs_room(experiment.frame_count() as u64 * service.frame_bytes)
        .map_err(JobError::failed)?;
    bench.plan = Some(request);
    bench.design = Some(design);
    let capture = ScaledSink {
        inner: ctx,
        from: FIRST_SHARE,
        span: CAPTURE_SHARE,
    };
    let (_, captured) = capture_frames(service, &experiment, ctx, &capture)?;
    bench.captured = Some(captured.id.clone());
    let merged = merge_into_store(
        &service.store,
        &dir,
        &captured.id,
        &format!("{} on the bench", manifest.name),
        DatasetSource::Other(format!(
            "on-bench {}: {dataset} and {}",
            ctx.run_id, captured.id
        )),
    )
    .map_err(JobError::failed)?;
    registered(ctx, &merged, "the dataset with the bench's runs:");
    bench.dataset = Some(merged.id.clone());
    Ok(merged)
}

impl Job for OnBenchJob {
    const KIND: RunKind = RunKind::OnBench;
    const LANE: Lane = Lane::Bench;
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
        let part = |from: f64, span: f64| ScaledSink {
            inner: ctx,
            from,
            span,
        };
        let dir = service.store.dataset_dir(&dataset);
        let first = part(0.0, FIRST_SHARE);
        let before = diagnose_rounds(
            &dir,
            &model,
            &options,
            request.rounds,
            &progress_reporter(&first, "diagnosis of the dataset"),
        )
        .map_err(diagnose_failure)?;
        let write_json = |rel: &str, value: &serde_json::Value| {
            let bytes = serde_json::to_vec_pretty(value).map_err(JobError::failed)?;
            ctx.write(rel, &bytes).map_err(JobError::failed)
        };
        write_json("results/diagnosis.json", &before.to_json())?;
        let mut bench = OnBenchCapture {
            runs: before.runs_to_separate.clone(),
            ..OnBenchCapture::default()
        };
        let document = |bench: &OnBenchCapture, after: Option<&Rounds>| {
            json!({
                "before": before.to_json(),
                "open_before": open_document(Some(&before)),
                "bench": bench,
                "after": after.map(Rounds::to_json),
                "open_after": open_document(after),
            })
        };
        if bench.runs.is_empty() {
            write_json("results/on-bench.json", &document(&bench, None))?;
            return Ok(JobOutput {
                message: "nothing to capture: the diagnosis left no pair confounded by the dataset's design and no effect a move, a step series or static frames would reveal".into(),
                result: JobResult::OnBench {
                    before: Box::new(before),
                    bench: Box::new(bench),
                    after: None,
                },
            });
        }
        let (open, _) = open_questions(&before.diagnoses);
        let merged = capture_and_merge(&service, &dataset, &open, &mut bench, ctx)?;
        let second = part(
            FIRST_SHARE + CAPTURE_SHARE,
            1.0 - FIRST_SHARE - CAPTURE_SHARE,
        );
        let after = diagnose_rounds(
            &service.store.dataset_dir(&merged.id),
            &model,
            &options,
            request.rounds,
            &progress_reporter(&second, "diagnosis with the bench's runs"),
        )
        .map_err(diagnose_failure)?;
        write_json("results/on-bench.json", &document(&bench, Some(&after)))?;
        let words = |pairs: Vec<String>| match pairs.is_empty() {
            true => "none".to_string(),
            false => pairs.join(", "),
        };
        Ok(JobOutput {
            message: format!(
                "confounded by the design: {} → {} with the bench's runs (dataset {})",
                words(design_confounds(&before)),
                words(design_confounds(&after)),
                merged.id
            ),
            result: JobResult::OnBench {
                before: Box::new(before),
                bench: Box::new(bench),
                after: Some(Box::new(after)),
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with_pattern(pattern: serde_json::Value) -> Manifest {
        serde_json::from_value(json!({"format": crate::dataset::FORMAT, "name": "lab",
            "scale_px_per_mm": 26.0, "runs": [{"id": "x5", "pattern": pattern,
            "reference": "ref.tif", "deformed": "x5.tif", "stage": {"dx_mm": 5.0, "dy_mm": 0.0}}]}))
        .unwrap()
    }

    /// A preset's name mounts the preset; a lab's own label mounts the print its dataset states;
    /// a label with nothing stated is refused, naming what is missing.
    #[test]
    fn the_bench_mounts_a_preset_or_the_print_the_dataset_states() {
        assert_eq!(
            target_pattern(&with_pattern(json!({"label": "b", "dot_diameter_mm": 0.3}))).unwrap(),
            PatternSpec::Preset("b".into())
        );
        let own = with_pattern(json!({"label": "lab-print-7", "dot_diameter_mm": 0.18,
            "dot_spacing_mm": 0.27, "contrast": 0.6, "placement": "hard_core"}));
        let PatternSpec::Custom(p) = target_pattern(&own).unwrap() else {
            panic!("the stated print");
        };
        assert_eq!(
            (
                p.label.as_str(),
                p.dot_diameter_mm,
                p.dot_spacing_mm,
                p.contrast
            ),
            ("lab-print-7", 0.18, 0.27, 0.6)
        );
        assert_eq!(p.placement, crate::model::Placement::HardCore);
        let unstated = with_pattern(json!({"label": "lab-print-7", "dot_diameter_mm": 0.18}));
        let e = target_pattern(&unstated).unwrap_err().to_string();
        assert!(e.contains("lab-print-7") && e.contains("contrast"), "{e}");
    }
}
