//! `compare`: DIC on the measured frames and the same DIC on the frames the model renders for the
//! same nominal experiment, per run and scheme, with image statistics beside it.
//!
//! [`load_measurement`] reads a dataset and analyses the measured side once; [`compare_prepared`]
//! renders and analyses the model's side against it (diagnose calls it once per candidate).

use super::bic::{chi2, Chi2};
use super::discrepancy::{run_discrepancy, RunDiscrepancy};
use super::image_stats::{centre_crop, frame_stats, FrameStats, STATS_CROP_PX};
use super::nominal::{
    check_sizes, fit_stage, pattern_for, pattern_indices, pooled_noise_variance, white_level_guess,
    Nominal, Scene, StageObservation,
};
use super::residuals::{residual_map, ResidualMap};
use super::{CompareOptions, DiagnoseError, Progress};
use crate::dataset::Manifest;
use crate::dic::{DicResult, PreparedReference, Summary};
use crate::image::{read_tiff, Image};
use crate::model::{Effects, ModelConfig};
use crate::reduce::{reduce, Scheme};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// The measured side of a dataset, analysed once.
pub struct Measurement {
    pub dir: PathBuf,
    pub manifest: Manifest,
    pub options: CompareOptions,
    /// Distinct pattern labels and each run's index into them.
    pub labels: Vec<String>,
    pub pattern_of_run: Vec<usize>,
    pub width: usize,
    pub height: usize,
    pub bit_depth: u8,
    /// Centred crops (≤ 512 px) of each pattern's reference and static repeat, of each moved frame.
    pub reference_crops: Vec<Image>,
    pub repeat_crops: Vec<Option<Image>>,
    pub moved_crops: Vec<Image>,
    pub reference_stats: Vec<FrameStats>,
    pub moved_stats: Vec<FrameStats>,
    /// DIC of every run (outer) and scheme (inner).
    pub dic: Vec<Vec<DicResult>>,
    /// Speckle, white levels and noise floor; the stage is fitted per comparison.
    pub nominal: Nominal,
}

/// The model a comparison used: its file's name, a version hash, its effects, and the nominal
/// experiment calibrated for this dataset.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelInfo {
    pub name: String,
    pub version: String,
    pub effects: Effects,
    pub nominal: Nominal,
}

/// One side of a run's comparison: the paper's statistics and the random error.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Side {
    pub summary: Summary,
    /// Std of u and v about their own quadratic surface, px.
    pub random_px: [f64; 2],
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunComparison {
    pub id: String,
    /// The run's pattern label (the reference frame it shares with other runs).
    pub pattern: String,
    pub scheme: String,
    pub discrepancy_px: f64,
    pub field_px: f64,
    pub std_px: f64,
    pub measured: Side,
    pub model: Side,
    /// Mean of measured − model, px (u, v).
    pub mean_diff_px: [f64; 2],
    /// Sub-pixel fraction of the measured mean displacement (u, v), in [0, 1).
    pub subpixel_fraction: [f64; 2],
    /// Actual move of the nominal experiment, full-resolution px.
    pub move_px: [f64; 2],
    pub residual: ResidualMap,
    #[serde(skip)]
    pub detail: RunDiscrepancy,
}

/// Image statistics of one measured frame and the model's frame of it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImageComparison {
    /// "reference" (per pattern) or "moved" (per run).
    pub frame: String,
    pub pattern: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub run: Option<String>,
    pub measured: FrameStats,
    pub model: FrameStats,
}

/// Totals by part, px.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DiscrepancyParts {
    pub field_px: f64,
    pub std_px: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Comparison {
    pub dataset: String,
    pub model: ModelInfo,
    /// RMS over every run and scheme of the per-run discrepancy, px.
    pub discrepancy_px: f64,
    pub parts: DiscrepancyParts,
    pub runs: Vec<RunComparison>,
    pub images: Vec<ImageComparison>,
    pub chi2: Chi2,
}

/// A short, stable hash of the model's content (FNV-1a 64 of its canonical TOML).
pub fn model_version(model: &ModelConfig) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in model.effects_toml().bytes() {
        h ^= b as u64;
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    format!("{:012x}", h & 0xffff_ffff_ffff)
}

trait EffectsToml {
    fn effects_toml(&self) -> String;
}

impl EffectsToml for ModelConfig {
    /// Only the effects: renaming a model does not make it another version.
    fn effects_toml(&self) -> String {
        toml::to_string(&self.effects).unwrap_or_default()
    }
}

fn dic_error(run: &str, scheme: &Scheme, source: crate::dic::DicError) -> DiagnoseError {
    DiagnoseError::Dic {
        run: run.to_string(),
        scheme: scheme.name.clone(),
        source,
    }
}

/// Reads a dataset and analyses the measured frames. `progress` counts run × scheme analyses.
pub fn load_measurement(
    dir: &Path,
    options: &CompareOptions,
    progress: Progress,
) -> Result<Measurement, DiagnoseError> {
    let manifest = Manifest::read(dir)?;
    options.dic.validate().map_err(|e| DiagnoseError::Dic {
        run: "-".into(),
        scheme: "-".into(),
        source: e,
    })?;
    let (labels, pattern_of_run) = pattern_indices(&manifest);
    let total = manifest.runs.len() * options.schemes.len();
    let mut done = 0;
    let mut dic = Vec::with_capacity(manifest.runs.len());
    let mut moved_crops = Vec::new();
    let mut moved_stats = Vec::new();
    let mut reference_crops: Vec<Option<Image>> = vec![None; labels.len()];
    let mut repeat_crops: Vec<Option<Image>> = vec![None; labels.len()];
    let mut reference_stats: Vec<Option<FrameStats>> = vec![None; labels.len()];
    let mut ref_info: Vec<(f64, f64)> = vec![(0.0, 0.0); labels.len()];
    let mut size = None;
    let mut bit_depth = 16u8;
    // The prepared references of the last reference file (runs sharing it reuse them).
    let mut cached: Option<(String, Image, Vec<PreparedReference>)> = None;
    for (ri, run) in manifest.runs.iter().enumerate() {
        if cached.as_ref().map(|c| &c.0) != Some(&run.reference) {
            let (img, info) = read_tiff(&dir.join(&run.reference))?;
            bit_depth = info.bit_depth.min(16);
            let mut prepared = Vec::new();
            for s in &options.schemes {
                let r = reduce(&img, s)?;
                prepared.push(
                    PreparedReference::new(&r, &options.dic)
                        .map_err(|e| dic_error(&run.id, s, e))?,
                );
            }
            cached = Some((run.reference.clone(), img, prepared));
        }
        let (_, reference, prepared) = cached.as_ref().expect("just filled");
        let (deformed, _) = read_tiff(&dir.join(&run.deformed))?;
        check_sizes(run, reference, &deformed)?;
        match size {
            None => size = Some((reference.width(), reference.height())),
            Some(s) if s != (reference.width(), reference.height()) => {
                return Err(DiagnoseError::Frames {
                    run: run.id.clone(),
                    message: format!(
                        "frames are {}x{}, the dataset's first run has {}x{}",
                        reference.width(),
                        reference.height(),
                        s.0,
                        s.1
                    ),
                })
            }
            Some(_) => {}
        }
        let pi = pattern_of_run[ri];
        if reference_stats[pi].is_none() {
            let crop = centre_crop(reference, STATS_CROP_PX);
            let repeat = match run.repeat.first() {
                Some(name) => {
                    let (r, _) = read_tiff(&dir.join(name))?;
                    check_sizes(run, reference, &r)?;
                    Some(centre_crop(&r, STATS_CROP_PX))
                }
                None => None,
            };
            reference_stats[pi] = Some(frame_stats(Some(reference), &crop, repeat.as_ref()));
            ref_info[pi] = (
                white_level_guess(&crop),
                pooled_noise_variance(&crop, repeat.as_ref()),
            );
            reference_crops[pi] = Some(crop);
            repeat_crops[pi] = repeat;
        }
        let crop = centre_crop(&deformed, STATS_CROP_PX);
        moved_stats.push(frame_stats(Some(&deformed), &crop, None));
        moved_crops.push(crop);
        let mut per_scheme = Vec::with_capacity(options.schemes.len());
        for (s, prep) in options.schemes.iter().zip(prepared) {
            let d = reduce(&deformed, s)?;
            per_scheme.push(
                prep.correlate(&d, None)
                    .map_err(|e| dic_error(&run.id, s, e))?,
            );
            done += 1;
            if !progress(done, total) {
                return Err(DiagnoseError::Cancelled);
            }
        }
        dic.push(per_scheme);
    }
    let (width, height) = size.expect("a manifest has runs");
    let reference_crops: Vec<Image> = reference_crops
        .into_iter()
        .map(|c| c.expect("every pattern has a run"))
        .collect();
    let noise_var = ref_info.iter().map(|r| r.1).sum::<f64>() / ref_info.len() as f64;
    let patterns = labels
        .iter()
        .enumerate()
        .map(|(pi, _)| {
            let run = &manifest.runs[pattern_of_run.iter().position(|&p| p == pi).expect("used")];
            pattern_for(
                run,
                &reference_crops[pi],
                ref_info[pi].0,
                ref_info[pi].1,
                manifest.scale_px_per_mm,
            )
        })
        .collect();
    let nominal = Nominal {
        width,
        height,
        bit_depth,
        scale_px_per_mm: manifest.scale_px_per_mm,
        noise_floor_dn: noise_var.max(0.0).sqrt(),
        misalignment_rad: 0.0,
        travel_scale: 1.0,
        patterns,
    };
    Ok(Measurement {
        dir: dir.to_owned(),
        manifest,
        options: options.clone(),
        labels,
        pattern_of_run,
        width,
        height,
        bit_depth,
        reference_crops,
        repeat_crops,
        moved_crops,
        reference_stats: reference_stats
            .into_iter()
            .map(|s| s.expect("filled"))
            .collect(),
        moved_stats,
        dic,
        nominal,
    })
}

/// The nominal experiment of `model` for this measurement: the stage fitted, the white levels
/// matched (one centred crop render per pattern).
pub fn calibrate(meas: &Measurement, model: &ModelConfig) -> Result<Nominal, DiagnoseError> {
    let mut nominal = meas.nominal.clone();
    let obs: Vec<StageObservation> = meas
        .manifest
        .runs
        .iter()
        .enumerate()
        .flat_map(|(ri, run)| {
            meas.options
                .schemes
                .iter()
                .zip(&meas.dic[ri])
                .map(move |(s, r)| StageObservation {
                    pattern: meas.pattern_of_run[ri],
                    commanded: (run.stage.dx_mm, run.stage.dy_mm),
                    scheme: s,
                    result: r,
                })
        })
        .collect();
    fit_stage(&mut nominal, &model.effects, &meas.manifest, &obs);
    let scene = Scene::new(&nominal, &model.effects, &meas.manifest, meas.options.seed)?;
    for (pi, crop) in meas.reference_crops.iter().enumerate() {
        let img = scene.render(pi, (0.0, 0.0), false, 0, Some(STATS_CROP_PX));
        let (m_model, _) = img.mean_std();
        let (m_meas, _) = crop.mean_std();
        if m_model > 0.0 && m_meas > 0.0 {
            nominal.patterns[pi].white_level_dn *= m_meas / m_model;
        }
    }
    Ok(nominal)
}

/// Renders and analyses the model's side and compares. `progress` counts run × scheme analyses.
pub fn compare_prepared(
    meas: &Measurement,
    model: &ModelConfig,
    progress: Progress,
) -> Result<Comparison, DiagnoseError> {
    let opts = &meas.options;
    let nominal = calibrate(meas, model)?;
    let scene = Scene::new(&nominal, &model.effects, &meas.manifest, opts.seed)?;
    let runs = &meas.manifest.runs;
    let total = runs.len() * opts.schemes.len();
    let done = AtomicUsize::new(0);
    let mut model_dic: Vec<Option<Vec<DicResult>>> = vec![None; runs.len()];
    let mut images = Vec::new();
    let mut moved_images: Vec<Option<ImageComparison>> = vec![None; runs.len()];
    for pi in 0..meas.labels.len() {
        let reference = scene.render(pi, (0.0, 0.0), false, 0, None);
        let crop = centre_crop(&reference, STATS_CROP_PX);
        let repeat = meas.repeat_crops[pi]
            .as_ref()
            .map(|_| scene.render(pi, (0.0, 0.0), false, 1, Some(STATS_CROP_PX)));
        images.push(ImageComparison {
            frame: "reference".into(),
            pattern: meas.labels[pi].clone(),
            run: None,
            measured: meas.reference_stats[pi].clone(),
            model: frame_stats(Some(&reference), &crop, repeat.as_ref()),
        });
        let mut prepared = Vec::new();
        for s in &opts.schemes {
            let r = reduce(&reference, s)?;
            prepared
                .push(PreparedReference::new(&r, &opts.dic).map_err(|e| dic_error("model", s, e))?);
        }
        for (ri, run) in runs
            .iter()
            .enumerate()
            .filter(|(ri, _)| meas.pattern_of_run[*ri] == pi)
        {
            let moved = scene.render(
                pi,
                (run.stage.dx_mm, run.stage.dy_mm),
                true,
                2 + ri as u64,
                None,
            );
            let mcrop = centre_crop(&moved, STATS_CROP_PX);
            moved_images[ri] = Some(ImageComparison {
                frame: "moved".into(),
                pattern: meas.labels[pi].clone(),
                run: Some(run.id.clone()),
                measured: meas.moved_stats[ri].clone(),
                model: frame_stats(Some(&moved), &mcrop, None),
            });
            let mut per_scheme = Vec::new();
            for (s, prep) in opts.schemes.iter().zip(&prepared) {
                let d = reduce(&moved, s)?;
                per_scheme.push(
                    prep.correlate(&d, None)
                        .map_err(|e| dic_error(&run.id, s, e))?,
                );
                let n = done.fetch_add(1, Ordering::Relaxed) + 1;
                if !progress(n, total) {
                    return Err(DiagnoseError::Cancelled);
                }
            }
            model_dic[ri] = Some(per_scheme);
        }
    }
    images.extend(moved_images.into_iter().flatten());
    let mut out_runs = Vec::new();
    for (ri, run) in runs.iter().enumerate() {
        let model_results = model_dic[ri].as_ref().expect("every run rendered");
        let (sx, sy) = nominal.scaled_move(run.stage.dx_mm, run.stage.dy_mm);
        let (s, c) = nominal.misalignment_rad.sin_cos();
        let k = nominal.scale_px_per_mm;
        let move_px = [k * (c * sx - s * sy), k * (s * sx + c * sy)];
        for (si, scheme) in opts.schemes.iter().enumerate() {
            let m = &meas.dic[ri][si];
            let o = &model_results[si];
            let d = run_discrepancy(m, o, super::bic::inflation(&opts.dic));
            let frac = |x: f64| x - x.floor();
            out_runs.push(RunComparison {
                id: run.id.clone(),
                pattern: meas.labels[meas.pattern_of_run[ri]].clone(),
                scheme: scheme.name.clone(),
                discrepancy_px: d.discrepancy_px,
                field_px: d.field_px,
                std_px: d.std_px,
                measured: Side {
                    summary: m.summary,
                    random_px: [d.measured_random_px.0, d.measured_random_px.1],
                },
                model: Side {
                    summary: o.summary,
                    random_px: [d.model_random_px.0, d.model_random_px.1],
                },
                mean_diff_px: [d.mean_diff_px.0, d.mean_diff_px.1],
                subpixel_fraction: [frac(m.summary.u.mean), frac(m.summary.v.mean)],
                move_px,
                residual: residual_map(m, &d),
                detail: d,
            });
        }
    }
    let rms = |f: fn(&RunComparison) -> f64| {
        let v: Vec<f64> = out_runs.iter().map(f).filter(|x| x.is_finite()).collect();
        (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
    };
    let mut cmp = Comparison {
        dataset: meas.manifest.name.clone(),
        model: ModelInfo {
            name: model.name.clone(),
            version: model_version(model),
            effects: model.effects.clone(),
            nominal,
        },
        discrepancy_px: rms(|r| r.discrepancy_px),
        parts: DiscrepancyParts {
            field_px: rms(|r| r.field_px),
            std_px: rms(|r| r.std_px),
        },
        runs: out_runs,
        images,
        chi2: Chi2::default(),
    };
    cmp.chi2 = chi2(&cmp, None, &opts.dic);
    Ok(cmp)
}

/// Reads the dataset in `dir` and compares it with `model`. `progress` counts every analysis
/// (measured and model side).
pub fn compare(
    dir: &Path,
    model: &ModelConfig,
    options: &CompareOptions,
    progress: Progress,
) -> Result<Comparison, DiagnoseError> {
    let manifest_runs = Manifest::read(dir)?.runs.len() * options.schemes.len();
    let total = 2 * manifest_runs;
    let meas = load_measurement(dir, options, &|d, _| progress(d, total))?;
    compare_prepared(&meas, model, &|d, _| progress(manifest_runs + d, total))
}
