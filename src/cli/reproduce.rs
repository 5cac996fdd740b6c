//! `ffdic reproduce`: the paper's study end to end through the same service a lab's clients use —
//! the experiment runner and the bench actor on the mock bench (the model renders what the sensor
//! sees at the mock stage's position), the frames reduced to 100 / 50 / 25 % fill factor, DIC at
//! the paper's settings — then Figures 5 and 6. The run lands in the data folder like any other,
//! so `ffdic serve` shows it.

use super::simulate::load_experiment;
use super::ProgressBar;
use anyhow::{bail, Context, Result};
use clap::Args;
use ffdic::diagnose::Diagnosis;
use ffdic::experiment::{ExperimentRequest, SchemeSpec};
use ffdic::model::ModelConfig;
use ffdic::report::findings_text;
use ffdic::report::{figures_text, paper_figures_text, study_json};
use ffdic::service::job::{CompareRequest, DiagnosisJob, ExperimentJob};
use ffdic::service::{
    find_analysis_model, mock_bench, CameraConfig, DaemonConfig, JobResult, MockBinning,
    MockReduction, ModelStoreError, NewModel, Service,
};
use ffdic::store::{RunId, RunRecord, RunStatus, StoreError};
use ffdic::study::{paper_findings, StudyRow};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Duration;

#[derive(Debug, Args)]
pub struct ReproduceArgs {
    /// Experiment file (default: the embedded paper study, config/experiments/paper.toml).
    #[arg(long)]
    pub experiment: Option<PathBuf>,
    /// Model of the mock bench's truth: a TOML file, or a model name — embedded or stored in
    /// DATA/models, e.g. a camera card's (`ffdic calibrate`) — (default: the embedded
    /// paper-bench-distortion, the paper's bench with a mild lens distortion the baseline
    /// analysis model lacks).
    #[arg(long, value_name = "FILE|NAME")]
    pub bench_model: Option<String>,
    /// Data folder the run is stored in (as `ffdic serve` would).
    #[arg(long, default_value = "data")]
    pub data: PathBuf,
    /// Seed of the speckle layouts (default: the experiment's).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Independent captures of every pair (default: the experiment's, 1): the study then reports
    /// the mean over captures with a 95 % interval.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=32))]
    pub repeats: Option<u64>,
    /// A new speckle layout for every capture (with --repeats).
    #[arg(long)]
    pub new_layouts: bool,
    /// Print the table as one JSON document and nothing else (with --repeats, every capture's
    /// rows under "captures").
    #[arg(long)]
    pub json: bool,
    /// Stop after the study: no comparison with the baseline model, no diagnosis.
    #[arg(long)]
    pub no_model: bool,
    /// Where the mock sensor's own 2x2 binning combines pixels (the experiment's `hw:` schemes):
    /// digital (read every pixel, average) or charge (sum the electrons, read once).
    #[arg(long, value_enum, default_value_t = SensorBinning::Digital)]
    pub hardware_binning: SensorBinning,
}

/// `--hardware-binning`: the mock sensor's binning domain.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum SensorBinning {
    None,
    Digital,
    Charge,
}

impl From<SensorBinning> for MockBinning {
    fn from(b: SensorBinning) -> Self {
        match b {
            SensorBinning::None => MockBinning::None,
            SensorBinning::Digital => MockBinning::Digital,
            SensorBinning::Charge => MockBinning::Charge,
        }
    }
}

pub fn run(args: &ReproduceArgs) -> Result<()> {
    let spec = load_experiment(&args.experiment)?;
    let truth = find_analysis_model(
        Some(
            args.bench_model
                .as_deref()
                .unwrap_or("paper-bench-distortion"),
        ),
        &args.data,
    )?;
    let truth_effects = bench_effects(&truth);
    let mut config = DaemonConfig::embedded();
    config.data_dir = args.data.clone();
    config.bench.scale_px_per_mm = spec.camera.scale_px_per_mm;
    let reduction = MockReduction {
        binning: args.hardware_binning.into(),
        ..MockReduction::default()
    };
    config.camera = CameraConfig::Mock {
        width: spec.camera.width,
        height: spec.camera.height,
        exposure_level: spec.camera.exposure_level,
        bench_model: truth.name.clone(),
        hardware_binning: reduction.binning,
        hardware_decimation_max: reduction.decimation_max,
    };
    // A fast mock stage: travel time is not what this study measures.
    let hardware = mock_bench(
        spec.camera.clone(),
        truth,
        reduction,
        200.0,
        Duration::from_millis(5),
    )?;
    let (service, _) = Service::start(config, hardware)?;
    // This process waits for its own jobs: their typed results, not their files read back.
    service.jobs.keep_results();
    let request = ExperimentRequest {
        name: spec.name.clone(),
        patterns: spec.patterns.clone(),
        moves: spec.moves.clone(),
        step_series: spec.step_series.clone(),
        static_frames: spec.static_frames,
        repeats: args.repeats.map_or(spec.repeats, |n| n as usize),
        new_layout_per_repeat: args.new_layouts || spec.new_layout_per_repeat,
        settle_ms: 0,
        schemes: spec
            .schemes
            .iter()
            .cloned()
            .map(SchemeSpec::Preset)
            .collect(),
        dic: spec.dic.clone(),
        seed: args.seed.unwrap_or(spec.seed),
        ..ExperimentRequest::default()
    };
    let (record, _) = service.submit(ExperimentJob::plan(&service, request)?, None)?;
    let record = wait(
        &service,
        &record.id,
        "capturing and correlating",
        !args.json,
    )?;
    let story = if args.no_model {
        None
    } else {
        Some(model_story(
            &service,
            &record.id,
            &spec,
            &truth_effects,
            !args.json,
        )?)
    };
    service.stop(Duration::from_secs(5));
    let run_dir = service.store.run_dir(&record.id);
    let Some(JobResult::Study { rows, captures }) = service.jobs.take_result(&record.id) else {
        bail!("experiment {} succeeded without a study", record.id)
    };
    let outcome = Outcome {
        run: record.id.to_string(),
        folder: run_dir.display().to_string(),
        rows,
        captures,
        story,
    };
    match args.json {
        true => println!("{}", outcome.json()?),
        false => print!("{}", outcome.text()),
    }
    Ok(())
}

/// What `reproduce` found: the study (pooled rows and every capture's), where it lies, and the
/// model's story.
struct Outcome {
    run: String,
    folder: String,
    rows: Vec<StudyRow>,
    captures: Vec<StudyRow>,
    story: Option<ModelStory>,
}

impl Outcome {
    fn json(&self) -> Result<serde_json::Value> {
        let mut doc = study_json(&self.rows, &self.captures);
        if !self.captures.is_empty() {
            doc["findings"] = serde_json::to_value(paper_findings(&self.captures))?;
        }
        doc["run"] = serde_json::json!(self.run);
        doc["folder"] = serde_json::json!(self.folder);
        if let Some(story) = &self.story {
            doc["model"] = serde_json::to_value(story)?;
        }
        Ok(doc)
    }

    fn text(&self) -> String {
        let mut t = figures_text(&self.rows);
        t += &paper_figures_text(&self.rows);
        t += &findings_text(&paper_findings(&self.captures));
        t += &format!(
            "\nrun {} in {} (frames/ as ffdic-dataset/1, results/study.csv, study.json, plots/figure5_*.svg, figure6_*.svg)\n",
            self.run, self.folder
        );
        if let Some(story) = &self.story {
            t += &story_text(story);
        }
        t
    }
}

/// Waits for run `id` with a progress bar; an error unless it succeeded.
pub(super) fn wait(
    service: &Service,
    id: &RunId,
    what: &'static str,
    show: bool,
) -> Result<RunRecord> {
    let bar = ProgressBar::fraction(show, what);
    let record = loop {
        let r = service.store.get(id)?;
        bar.update_fraction(r.progress);
        if r.status.is_terminal() {
            break r;
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    bar.finish();
    if record.status != RunStatus::Succeeded {
        bail!(
            "{what}: run {} {:?}: {}",
            record.id,
            record.status,
            record.message
        );
    }
    Ok(record)
}

/// The model against the measurement, as a user would do it on the dashboard: diagnose the
/// captured frames against the baseline model (the diagnosis compares the baseline with them and
/// renders the model with the winner added: its run holds the baseline's residual maps), then
/// store the model with the winner so the next comparison can take it.
#[derive(Debug, serde::Serialize)]
struct ModelStory {
    dataset: String,
    /// The discrepancy against the baseline model and its standard error, px.
    baseline_px: f64,
    baseline_se_px: f64,
    #[serde(with = "ffdic::model::effects::verdict_serde")]
    verdict: Option<ffdic::model::CandidateId>,
    /// The winner's fitted parameters and standard errors.
    params: BTreeMap<String, f64>,
    stderr: BTreeMap<String, f64>,
    /// The mock bench's truth: every effect of its model with its numeric parameters, what the
    /// diagnosis is held against (a lab's bench has no such line).
    bench_truth: BenchEffects,
    delta_bic: Option<f64>,
    /// The model with the winner added, and the discrepancy against it.
    model: Option<String>,
    after_px: Option<f64>,
    after_se_px: Option<f64>,
    /// Jobs: the diagnosis (its baseline comparison and the winner's are part of it).
    jobs: Vec<String>,
}

/// Effect name → its numeric parameters, as the model's TOML states them.
type BenchEffects = BTreeMap<String, BTreeMap<String, f64>>;

/// The effects of the bench's model with their numeric parameters, read from its TOML (the
/// model's own serialisation: every effect, present and future, without a list here).
fn bench_effects(truth: &ffdic::model::ModelConfig) -> BenchEffects {
    let doc: toml::Table = toml::from_str(&truth.to_toml()).unwrap_or_default();
    let Some(toml::Value::Table(effects)) = doc.get("effects") else {
        return BenchEffects::new();
    };
    effects
        .iter()
        .filter_map(|(name, params)| {
            let params = params.as_table()?;
            let numbers = params
                .iter()
                .filter_map(|(k, v)| {
                    let x = v.as_float().or_else(|| v.as_integer().map(|i| i as f64))?;
                    Some((k.clone(), x))
                })
                .collect();
            Some((name.clone(), numbers))
        })
        .collect()
}

fn model_story(
    service: &Service,
    experiment: &RunId,
    spec: &ffdic::experiment::ExperimentSpec,
    bench_truth: &BenchEffects,
    show: bool,
) -> Result<ModelStory> {
    let dataset_id = service
        .store
        .get(experiment)?
        .dataset_id
        .with_context(|| format!("experiment {experiment} registered no dataset"))?;
    let dataset = service.store.get_dataset(&dataset_id)?;
    let request = CompareRequest {
        // The model is compared with the full-resolution runs: the camera's own schemes
        // (`hw:`) are the study's, not the comparison's.
        schemes: spec
            .schemes
            .iter()
            .filter(|s| !ffdic::experiment::is_hardware_scheme_name(s))
            .cloned()
            .map(SchemeSpec::Preset)
            .collect(),
        dic: spec.dic.clone(),
        ..CompareRequest::default()
    };
    let (job, _) = service.submit(DiagnosisJob::plan(service, &dataset.id, request)?, None)?;
    wait(service, &job.id, "diagnosing", show)?;
    let Some(JobResult::Diagnosis(rounds)) = service.jobs.take_result(&job.id) else {
        bail!("diagnosis {} succeeded without a diagnosis", job.id);
    };
    let diagnosis: Diagnosis = rounds
        .diagnoses
        .first()
        .cloned()
        .with_context(|| format!("diagnosis {} ran no round", job.id))?;
    let baseline = diagnosis
        .before
        .as_ref()
        .with_context(|| format!("diagnosis {} kept no baseline comparison", job.id))?;
    let (baseline_px, baseline_se_px) = (baseline.discrepancy_px, baseline.discrepancy_se_px);
    let winner = diagnosis
        .candidates
        .iter()
        .find(|c| Some(&c.effect) == diagnosis.verdict.as_ref())
        .cloned();
    // The winner's comparison is the diagnosis's own rendering of the model with it added (the
    // baseline's print, the same seed); the model is stored for the dashboard's next comparison.
    let (model, after) = match (&winner, &diagnosis.after) {
        (Some(_), Some(after)) => {
            let added = store_winner(service, rounds.final_model.clone(), dataset.id.as_ref())?;
            (
                Some(added),
                Some((after.discrepancy_px, after.discrepancy_se_px)),
            )
        }
        (None, _) | (Some(_), None) => (None, None),
    };
    let jobs = vec![job.id.to_string()];
    Ok(ModelStory {
        dataset: dataset.id.to_string(),
        baseline_px,
        baseline_se_px,
        verdict: diagnosis.verdict,
        params: winner
            .as_ref()
            .map(|c| c.params.clone())
            .unwrap_or_default(),
        stderr: winner
            .as_ref()
            .map(|c| c.stderr.clone())
            .unwrap_or_default(),
        bench_truth: bench_truth.clone(),
        delta_bic: winner.as_ref().map(|c| c.delta_bic),
        model,
        after_px: after.map(|a| a.0),
        after_se_px: after.map(|a| a.1),
        jobs,
    })
}

fn story_text(s: &ModelStory) -> String {
    let mut t = format!(
        "\nmodel against measurement (dataset {}):\n  baseline model: discrepancy {} px\n",
        s.dataset,
        ffdic::report::length_pm(s.baseline_px, s.baseline_se_px)
    );
    let effect = ffdic::model::effects::verdict_name(&s.verdict);
    let truth = s.bench_truth.get(&effect);
    match (&s.model, s.after_px) {
        (Some(model), Some(after)) => {
            let params: Vec<String> = s
                .params
                .iter()
                .map(|(k, v)| {
                    let se = s.stderr.get(k).copied().unwrap_or(f64::NAN);
                    let fitted = format!("{k} = {}", ffdic::report::value_pm(*v, se));
                    match (truth.and_then(|t| t.get(k)), s.stderr.get(k)) {
                        (Some(t), Some(se)) if *se > 0.0 => {
                            format!("{fitted} (bench truth {t:.4e}: {:+.1} SE)", (v - t) / se)
                        }
                        (Some(t), _) => format!("{fitted} (bench truth {t:.4e})"),
                        (None, _) => fitted,
                    }
                })
                .collect();
            t += &format!(
                "  diagnosis: missing effect {} ({}; ΔBIC {:.1})\n  with it added ({model}): discrepancy {} px\n",
                ffdic::model::effects::verdict_name(&s.verdict),
                params.join(", "),
                s.delta_bic.unwrap_or(f64::NAN),
                ffdic::report::length_pm(after, s.after_se_px.unwrap_or(f64::NAN))
            );
        }
        _ => t += "  diagnosis: no significant missing effect (verdict none)\n",
    }
    if s.model.is_some() && truth.is_none() {
        t += &format!("  the mock bench's truth has no {effect}: a false alarm\n");
    }
    let truth_line: Vec<String> = s
        .bench_truth
        .iter()
        .map(|(name, params)| {
            // Zero is an absent term (k2, p1, p2 of a radial distortion): left out.
            let p: Vec<String> = params
                .iter()
                .filter(|(_, v)| **v != 0.0)
                .map(|(k, v)| format!("{k} {v}"))
                .collect();
            match p.is_empty() {
                true => name.clone(),
                false => format!("{name} ({})", p.join(", ")),
            }
        })
        .collect();
    t += &format!("  the mock bench's truth: {}\n", truth_line.join("; "));
    t += &format!("  jobs: {}\n", s.jobs.join(", "));
    t
}

/// Fresh names tried after the winner's own when the names hold other models.
const FRESH_NAMES: usize = 5;

/// Stores the winner's `model` in the data folder and returns the name it is stored under: its
/// own, or, when that name holds another model (a winner fitted on another dataset: a model name
/// is a version for good), the name with the dataset's id, then `.2`, `.3`…, as the dashboard's
/// `addWinner` does. The same text under a name is the model already there.
fn store_winner(service: &Service, mut model: ModelConfig, dataset_id: &str) -> Result<String> {
    let wanted = model.name.clone();
    let names: Vec<String> = std::iter::once(wanted.clone())
        .chain(std::iter::once(format!("{wanted}.{dataset_id}")))
        .chain((2..=FRESH_NAMES).map(|k| format!("{wanted}.{dataset_id}.{k}")))
        .collect();
    for name in &names {
        model.name = name.clone();
        match service.add_model(&NewModel {
            toml: model.to_toml(),
        }) {
            Ok((added, _)) => return Ok(added.summary.name),
            Err(ModelStoreError::Store(StoreError::Conflict(_))) => continue,
            Err(e) => return Err(e.into()),
        }
    }
    bail!(
        "the names {} all hold other models: the winner was not stored",
        names.join(", ")
    )
}
