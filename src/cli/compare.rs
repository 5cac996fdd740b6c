//! `ffdic compare DATASET`: DIC on the measured frames against the same DIC on the frames the
//! model renders for the same nominal experiment; the discrepancy per run, scheme and in total;
//! residual maps and image statistics as SVG with `--out`; every comparison kept in the dataset's
//! history.

use super::ProgressBar;
use anyhow::{Context, Result};
use clap::Args;
use ffdic::diagnose::{
    append_history, compare, history_dir_for, CompareOptions, Comparison, HistoryEntry,
};
use ffdic::dic::DicSettings;
use ffdic::model::ModelConfig;
use ffdic::report::comparison_svgs;
use std::path::PathBuf;

/// How the comparison analyses both sides (shared by compare and diagnose).
#[derive(Debug, Args)]
pub struct AnalysisArgs {
    /// Reduction schemes, comma-separated: the paper's ff100, ff50, ff25; native (every pixel,
    /// the camera's own resolution); or BLOCKxBLOCK/APERTURE (e.g. 2x2/1x2: 2x2 blocks whose
    /// centred 1x2 pixels are light-sensitive, as `ffdic reduce --block --aperture`).
    #[arg(long, default_value = "ff100,ff50,ff25", value_delimiter = ',')]
    pub schemes: Vec<String>,
    /// DIC subset size, px (odd).
    #[arg(long, default_value_t = DicSettings::default().subset_px)]
    pub subset: usize,
    /// DIC step, px.
    #[arg(long, default_value_t = DicSettings::default().step_px)]
    pub step: usize,
    /// Gaussian pre-filter σ, px (0 = off).
    #[arg(long, default_value_t = DicSettings::default().prefilter_sigma_px)]
    pub prefilter_sigma: f64,
    /// Seed of the model's speckle layouts and noise.
    #[arg(long, default_value_t = CompareOptions::default().seed)]
    pub seed: u64,
    /// Data folder of the daemon, whose models/ holds the model versions `--model NAME` finds.
    #[arg(long, default_value = "data")]
    pub data: PathBuf,
}

impl AnalysisArgs {
    pub fn options(&self) -> Result<CompareOptions> {
        let dic = DicSettings {
            subset_px: self.subset,
            step_px: self.step,
            prefilter_sigma_px: self.prefilter_sigma,
            ..DicSettings::default()
        };
        Ok(CompareOptions::from_scheme_specs(
            &self.schemes,
            dic,
            self.seed,
        )?)
    }
}

#[derive(Debug, Args)]
pub struct CompareArgs {
    /// Dataset folder (format ffdic-dataset/1), or its dataset.json.
    #[arg(value_parser = super::dataset_folder)]
    pub dataset: PathBuf,
    /// Analysis model: a TOML file, or a model name — embedded (baseline, paper-bench,
    /// paper-bench-distortion) or stored by the daemon in DATA/models (default: baseline).
    #[arg(long, value_name = "FILE|NAME")]
    pub model: Option<String>,
    /// Print one JSON document and nothing else.
    #[arg(long)]
    pub json: bool,
    /// Write comparison.json and the plots (SVG) into this folder.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Do not record the comparison in the dataset's history.
    #[arg(long)]
    pub no_history: bool,
    /// Where the dataset's history goes (default: DATA/history/NAME-HASH, one folder per
    /// dataset; nothing is written into the measurement folder unless named here).
    #[arg(long, value_name = "DIR")]
    pub history_dir: Option<PathBuf>,
    #[command(flatten)]
    pub analysis: AnalysisArgs,
}

/// The analysis model `--model` names (see `ffdic::service::find_analysis_model`).
pub fn load_analysis_model(given: &Option<String>, data: &std::path::Path) -> Result<ModelConfig> {
    use ffdic::service::ModelLookupError;
    ffdic::service::find_analysis_model(given.as_deref(), data).map_err(|e| match e {
        ModelLookupError::NotFound { .. } => anyhow::anyhow!("--model {e}"),
        other => other.into(),
    })
}

/// Appends the comparison to the dataset's history in `history_dir`.
pub fn record(history_dir: &std::path::Path, cmp: &Comparison) -> Result<()> {
    append_history(history_dir, &HistoryEntry::of(cmp))?;
    Ok(())
}

/// Writes comparison.json and every plot into `out`.
pub fn write_outputs(out: &std::path::Path, cmp: &Comparison) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    std::fs::write(out.join("comparison.json"), serde_json::to_vec_pretty(cmp)?)?;
    for (name, svg) in comparison_svgs(cmp) {
        std::fs::write(out.join(&name), svg).with_context(|| format!("cannot write {name}"))?;
    }
    Ok(())
}

/// The runs read out in the camera's own binning or decimation, compared in that mode.
fn hardware_text(hw: &ffdic::diagnose::HardwareComparison) -> String {
    use ffdic::report::{length_pm, significant};
    let f = |x: f64| significant(x, 3);
    let rows: Vec<Vec<String>> = hw
        .runs
        .iter()
        .map(|r| {
            vec![
                r.id.clone(),
                r.twin.clone(),
                r.scheme.clone(),
                length_pm(r.discrepancy_px, r.se.discrepancy_se_px),
                length_pm(r.parts.rigid_px, r.se.rigid_se_px),
                length_pm(r.parts.field_px, r.se.field_se_px),
                length_pm(r.parts.std_px, r.se.std_se_px),
                f(r.measured_random_px[0]),
                f(r.model_random_px[0]),
                f(r.measured_random_px[1]),
                f(r.model_random_px[1]),
            ]
        })
        .collect();
    let mut s = format!(
        "\nIn the camera's own read-out (rendered in that mode, beside the fit; px of the \
         captured frames): D {:.5} px\n",
        hw.discrepancy_px
    );
    s.push_str(&ffdic::report::text_table(
        &[
            "run",
            "twin",
            "capture",
            "D [px]",
            "rigid",
            "field",
            "std",
            "random u meas",
            "random u model",
            "random v meas",
            "random v model",
        ],
        &rows,
    ));
    s
}

/// The comparison as a table for people.
pub fn comparison_text(cmp: &Comparison) -> String {
    use ffdic::report::{length_pm, plus_minus, significant};
    let f = |x: f64| significant(x, 3);
    let rows: Vec<Vec<String>> = cmp
        .runs
        .iter()
        .map(|r| {
            vec![
                r.id.clone(),
                r.scheme.clone(),
                length_pm(r.discrepancy_px, r.se.discrepancy_se_px),
                length_pm(r.rigid_px, r.se.rigid_se_px),
                length_pm(r.field_px, r.se.field_se_px),
                length_pm(r.std_px, r.se.std_se_px),
                plus_minus(r.mean_diff_px[0], r.se.mean_diff_se_px[0]),
                plus_minus(r.mean_diff_px[1], r.se.mean_diff_se_px[1]),
                f(r.measured.summary.u.std),
                f(r.model.summary.u.std),
                f(r.measured.summary.v.std),
                f(r.model.summary.v.std),
            ]
        })
        .collect();
    let mut s = ffdic::report::text_table(
        &[
            "run",
            "scheme",
            "D [px]",
            "rigid",
            "field",
            "std",
            "Δu mean",
            "Δv mean",
            "std u meas",
            "std u model",
            "std v meas",
            "std v model",
        ],
        &rows,
    );
    s += LENGTHS_LEGEND;
    s += "\n";
    s += &accuracy_text(cmp);
    if let Some(hw) = &cmp.hardware {
        s.push_str(&hardware_text(hw));
    }
    if cmp.hardware_runs_set_aside > 0 {
        s.push_str(&format!(
            "{} runs read out in the camera's own binning or decimation have no full-resolution \
             twin in the dataset and were set aside\n",
            cmp.hardware_runs_set_aside
        ));
    }
    s += "\n";
    s += &images_text(cmp);
    s += &format!(
        "\nmodel {} ({}), dataset {}: discrepancy {} px (rigid {}, field {}, std {}); stage misalignment {:.6} rad, travel scale {:.6}{}\n",
        cmp.model.name,
        cmp.model.version,
        cmp.dataset,
        length_pm(cmp.discrepancy_px, cmp.discrepancy_se_px),
        length_pm(cmp.parts.rigid_px, cmp.parts_se.rigid_px),
        length_pm(cmp.parts.field_px, cmp.parts_se.field_px),
        length_pm(cmp.parts.std_px, cmp.parts_se.std_px),
        cmp.model.nominal.misalignment_rad,
        cmp.model.nominal.travel_scale,
        stage_text(cmp)
    );
    s
}

/// What the discrepancy table's "±" and "<" say.
const LENGTHS_LEGEND: &str = "D and its parts (rigid, field, std) debiased for noise, px, ± their \
standard error from the noise of both analyses; < x: below its noise (debiased to zero), x twice \
its standard error; Δ mean: measured − model; std: 3 significant digits\n";

/// The measured side against the commanded move, per run and scheme: the bias with its standard
/// error and the std, px of the analysed image and µm on the target.
fn accuracy_text(cmp: &Comparison) -> String {
    use ffdic::report::{rounded_to_error, significant};
    let pm = ffdic::report::plus_minus;
    let rows: Vec<Vec<String>> = cmp
        .runs
        .iter()
        .map(|r| {
            let a = &r.accuracy;
            vec![
                r.id.clone(),
                r.scheme.clone(),
                format!("{:.4}, {:.4}", a.commanded_px[0], a.commanded_px[1]),
                pm(a.bias_px[0], a.bias_se_px[0]),
                pm(a.bias_px[1], a.bias_se_px[1]),
                significant(a.std_px[0], 3),
                significant(a.std_px[1], 3),
                format!(
                    "{}, {}",
                    rounded_to_error(a.bias_um[0], a.bias_se_um[0]),
                    rounded_to_error(a.bias_um[1], a.bias_se_um[1])
                ),
                format!(
                    "{}, {}",
                    significant(a.std_um[0], 3),
                    significant(a.std_um[1], 3)
                ),
            ]
        })
        .collect();
    let stated = match cmp.model.nominal.stage.repeatability_um {
        Some(r) => format!(
            "; the stage's repeatability {r:.2} µm, 1σ per axis, from the {} = {:.5} full-resolution px",
            format!("{:?}", cmp.model.nominal.stage.source).to_lowercase(),
            r * cmp.model.nominal.scale_px_per_mm / 1000.0
        ),
        None => String::new(),
    };
    let mut s =
        format!("accuracy against the commanded move (the stage's own error included{stated})\n");
    s += &ffdic::report::text_table(
        &[
            "run",
            "scheme",
            "commanded [px]",
            "bias u [px]",
            "bias v [px]",
            "std u [px]",
            "std v [px]",
            "bias [µm]",
            "std [µm]",
        ],
        &rows,
    );
    s
}

/// The image statistics of each frame, measured beside the model's.
fn images_text(cmp: &Comparison) -> String {
    let images: Vec<Vec<String>> = cmp
        .images
        .iter()
        .map(|im| {
            let slope = |p: &[ffdic::diagnose::PtcPoint]| match (p.first(), p.last()) {
                (Some(a), Some(b)) if b.mean_dn > a.mean_dn => ffdic::report::significant(
                    (b.variance_dn2 - a.variance_dn2) / (b.mean_dn - a.mean_dn),
                    3,
                ),
                _ => "—".into(),
            };
            vec![
                im.run
                    .clone()
                    .unwrap_or_else(|| format!("{} (reference)", im.pattern)),
                format!("{:.1}", im.measured.mean_dn),
                format!("{:.1}", im.model.mean_dn),
                format!("{:.4}", im.measured.contrast),
                format!("{:.4}", im.model.contrast),
                slope(&im.measured.ptc),
                slope(&im.model.ptc),
            ]
        })
        .collect();
    ffdic::report::text_table(
        &[
            "frame",
            "mean meas",
            "mean model",
            "contrast meas",
            "contrast model",
            "noise slope meas",
            "noise slope model",
        ],
        &images,
    )
}

/// The stage landing in words: the offsets' RMS against the repeatability that bounded them.
fn stage_text(cmp: &Comparison) -> String {
    let stage = &cmp.model.nominal.stage;
    let k = cmp.model.nominal.scale_px_per_mm;
    let observed = stage
        .observed_repeatability_um(k)
        .map_or(String::new(), |(s, se)| {
            format!("; stage landings {s:.2} ± {se:.2} µm RMS")
        });
    let bound = match stage.repeatability_um {
        Some(r) => format!(
            " (repeatability {r:.2} µm from the {:?}, envelope ±3σ)",
            stage.source
        )
        .to_lowercase(),
        None => " (no repeatability stated: offsets free)".into(),
    };
    if observed.is_empty() {
        observed
    } else {
        observed + &bound
    }
}

pub fn run(args: &CompareArgs) -> Result<()> {
    let model = load_analysis_model(&args.model, &args.analysis.data)?;
    let options = args.analysis.options()?;
    let bar = ProgressBar::new(!args.json, "comparing");
    let cmp = compare(&args.dataset, &model, &options, &|d, t| {
        bar.update(d, t);
        true
    })?;
    bar.finish();
    if !args.no_history {
        let dir = args
            .history_dir
            .clone()
            .unwrap_or_else(|| history_dir_for(&args.analysis.data, &args.dataset));
        record(&dir, &cmp)?;
    }
    if let Some(out) = &args.out {
        write_outputs(out, &cmp)?;
    }
    if args.json {
        println!("{}", serde_json::to_string(&cmp)?);
    } else {
        print!("{}", comparison_text(&cmp));
        if let Some(out) = &args.out {
            println!("comparison.json and plots in {}", out.display());
        }
    }
    Ok(())
}
