//! `compare`: DIC on the measured frames and the same DIC on the frames the model renders for the
//! same nominal experiment, per run and scheme, with image statistics beside it.
//!
//! [`load_measurement`] reads a dataset and analyses the measured side once; [`compare_prepared`]
//! renders and analyses the model's side against it (diagnose calls it once per candidate).

use super::bic::chi2;
use super::calibrate_scene::{calibrate_seeded, SceneFrom};
use super::capture_mode::{compare_hardware, model_hardware, HardwareModelSide};
use super::discrepancy::{run_discrepancy, RunDiscrepancy};
use super::image_stats::{centre_crop, frame_stats, moved_frame_stats, STATS_CROP_PX};
use super::measurement::{load_measurement, Measurement};
use super::nominal::Nominal;
use super::residuals::residual_map;
use super::results::{
    Accuracy, Chi2, Comparison, DiscrepancyParts, ImageComparison, ModelInfo, RunComparison, Side,
};
use super::scene::{Scene, Shot};
use super::{CompareOptions, DiagnoseError, Progress};
use crate::dataset::Manifest;
use crate::dic::{DicError, DicResult, PreparedReference, Watch};
use crate::model::ModelConfig;
use crate::reduce::{reduce, Scheme};
use rayon::prelude::*;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

/// A short, stable hash of the model's content (FNV-1a 64 of its canonical TOML).
pub fn model_version(model: &ModelConfig) -> String {
    super::history::short_hash(&model.effects_toml())
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

pub(super) fn dic_error(run: &str, scheme: &Scheme, source: crate::dic::DicError) -> DiagnoseError {
    DiagnoseError::Dic {
        run: run.to_string(),
        scheme: scheme.name.clone(),
        source,
    }
}

/// The landing offsets against the model's own DIC rather than its geometry: the first fit
/// compares the measured mean displacement with the ideal geometric one, so the model's own
/// sub-pixel bias would stay in every run as a rigid residual. The remaining mean difference of
/// each run (over its schemes and valid points, full-resolution px) is added to the run's
/// offset, within the stage's envelope, and to the model's displacements — a shift of a few
/// thousandths of a pixel moves a DIC result by the same amount (its bias changes at second
/// order), so no second rendering is needed.
fn refine_landings(meas: &Measurement, nominal: &mut Nominal, model_dic: &mut [Vec<DicResult>]) {
    let envelope = nominal.stage.envelope_px(nominal.scale_px_per_mm);
    for (ri, model_results) in model_dic.iter_mut().enumerate() {
        let (mut sum, mut k) = ([0.0, 0.0], 0.0);
        for (si, scheme) in meas.options.schemes.iter().enumerate() {
            let (m, o) = (&meas.dic[ri][si], &model_results[si]);
            let (mut du, mut dv, mut n) = (0.0, 0.0, 0.0);
            for (a, b) in m.points.iter().zip(&o.points) {
                if a.status.is_valid() && b.status.is_valid() {
                    du += a.u - b.u;
                    dv += a.v - b.v;
                    n += 1.0;
                }
            }
            if n > 0.0 {
                sum[0] += du / n * scheme.x.block as f64;
                sum[1] += dv / n * scheme.y.block as f64;
                k += 1.0;
            }
        }
        if k == 0.0 {
            continue;
        }
        let old = nominal.stage.applied_offset_px(ri);
        let mut shift = [0.0; 2];
        for c in 0..2 {
            let applied = (old[c] + sum[c] / k).clamp(-envelope, envelope);
            shift[c] = applied - old[c];
        }
        // What the data say: the offset the model was rendered at plus what its own analysis
        // still leaves over.
        if let Some(l) = nominal.stage.landing_px.get_mut(ri) {
            *l = [old[0] + sum[0] / k, old[1] + sum[1] / k];
        }
        if let Some(o) = nominal.stage.offsets_px.get_mut(ri) {
            *o = [old[0] + shift[0], old[1] + shift[1]];
        }
        for (si, scheme) in meas.options.schemes.iter().enumerate() {
            let (bx, by) = (scheme.x.block as f64, scheme.y.block as f64);
            for p in model_results[si].points.iter_mut() {
                p.u += shift[0] / bx;
                p.v += shift[1] / by;
            }
        }
    }
}

/// Renders and analyses the model's side and compares. `progress` counts run × scheme analyses.
pub fn compare_prepared(
    meas: &Measurement,
    model: &ModelConfig,
    progress: Progress,
) -> Result<Comparison, DiagnoseError> {
    compare_with_scene(
        meas,
        model,
        meas.options.seed,
        SceneFrom::Calibrate,
        progress,
    )
}

/// [`compare_prepared`] with the model's speckle and noise drawn from `seed` (`diagnose` renders
/// with the next seeds for the realisation scatter), and its white levels and prints from
/// `scene_from`.
pub fn compare_with_scene(
    meas: &Measurement,
    model: &ModelConfig,
    seed: u64,
    scene_from: SceneFrom<'_>,
    progress: Progress,
) -> Result<Comparison, DiagnoseError> {
    let opts = &meas.options;
    let runs = &meas.manifest.runs;
    let total = runs.len() * opts.schemes.len();
    let done = AtomicUsize::new(0);
    let go_on = || progress(done.load(Ordering::Relaxed), total);
    let span =
        tracing::debug_span!("comparison", model = %model.name, seed, scene = scene_from.kind());
    let _entered = span.enter();
    let nominal = tracing::debug_span!("calibrate")
        .in_scope(|| calibrate_seeded(meas, model, seed, scene_from, &go_on))?;
    let scene = Scene::new(&nominal, &model.effects, &meas.manifest, seed)?;
    // The prints side by side: each renders, prepares and correlates its own runs from its own
    // seeds, so the results do not depend on the order; one print at a time left a core idle
    // through its statistics and reductions (a comparison outside the candidates' lanes kept
    // 1.6–1.8 of the 2 cores busy).
    let sides: Vec<PrintSide> = (0..meas.labels.len())
        .into_par_iter()
        .map(|pi| {
            // A print's spans inside the comparison's, on whichever thread takes it.
            let _in_comparison = span.enter();
            compare_print(meas, (&scene, &nominal), pi, (&done, total), progress)
        })
        .collect::<Result<_, _>>()?;
    let mut images = Vec::new();
    let mut moved_images: Vec<Option<ImageComparison>> = vec![None; runs.len()];
    let mut model_dic: Vec<Option<Vec<DicResult>>> = vec![None; runs.len()];
    for side in sides {
        images.push(side.reference);
        for (ri, image, results) in side.runs {
            moved_images[ri] = Some(image);
            model_dic[ri] = Some(results);
        }
    }
    images.extend(moved_images.into_iter().flatten());
    let model_dic: Vec<Vec<DicResult>> = model_dic
        .into_iter()
        .map(|r| r.expect("every run rendered"))
        .collect();
    let hardware = model_hardware(&meas.hardware, &scene, &nominal, &meas.pattern_of_run, opts)?;
    Ok(assemble(meas, model, nominal, model_dic, images, hardware))
}

/// One print's model side: its reference frame's statistics, and per run of the print its moved
/// frame's statistics and its analyses under each scheme.
struct PrintSide {
    reference: ImageComparison,
    runs: Vec<(usize, ImageComparison, Vec<DicResult>)>,
}

/// Renders print `pi`'s frames from `scene` (landed as `nominal` says), prepares its reference
/// under each scheme and correlates each of its runs; `done` of `total` counts the analyses for
/// `progress`, which is asked before every frame and point.
fn compare_print(
    meas: &Measurement,
    (scene, nominal): (&Scene, &Nominal),
    pi: usize,
    (done, total): (&AtomicUsize, usize),
    progress: Progress,
) -> Result<PrintSide, DiagnoseError> {
    let opts = &meas.options;
    let go_on = || progress(done.load(Ordering::Relaxed), total);
    let cancelled = || !go_on();
    if !go_on() {
        return Err(DiagnoseError::Cancelled);
    }
    let rendering = tracing::debug_span!("render");
    let reference = rendering.in_scope(|| scene.render(pi, Shot::REFERENCE, None));
    let crop = centre_crop(&reference, STATS_CROP_PX);
    let repeat = rendering.in_scope(|| {
        meas.repeat_crops[pi]
            .as_ref()
            .map(|_| scene.render(pi, Shot::REPEAT, Some(STATS_CROP_PX)))
    });
    let reference_image = ImageComparison {
        frame: "reference".into(),
        pattern: meas.labels[pi].clone(),
        run: None,
        measured: meas.reference_stats[pi].clone(),
        model: frame_stats(Some(&reference), &crop, repeat.as_ref()),
    };
    let mut prepared = Vec::new();
    let preparing = tracing::debug_span!("prepare").entered();
    for s in &opts.schemes {
        let r = reduce(&reference, s)?;
        prepared.push(PreparedReference::new(&r, &opts.dic).map_err(|e| dic_error("model", s, e))?);
    }
    drop(preparing);
    let mut runs = Vec::new();
    for (ri, run) in meas
        .manifest
        .runs
        .iter()
        .enumerate()
        .filter(|(ri, _)| meas.pattern_of_run[*ri] == pi)
    {
        if !go_on() {
            return Err(DiagnoseError::Cancelled);
        }
        let at = nominal.landed_command(ri, (run.stage.dx_mm, run.stage.dy_mm));
        let moved = rendering.in_scope(|| scene.render(pi, Shot::of_run(ri, at), None));
        let mcrop = centre_crop(&moved, STATS_CROP_PX);
        let [sx, sy] = nominal.actual_move_px(ri, (run.stage.dx_mm, run.stage.dy_mm));
        let image = ImageComparison {
            frame: "moved".into(),
            pattern: meas.labels[pi].clone(),
            run: Some(run.id.clone()),
            measured: meas.moved_stats[ri].clone(),
            model: moved_frame_stats(&reference, &moved, &mcrop, (sx, sy)),
        };
        let mut per_scheme = Vec::new();
        let _correlating = tracing::debug_span!("dic").entered();
        for (s, prep) in opts.schemes.iter().zip(&prepared) {
            let d = reduce(&moved, s)?;
            let watch = Watch {
                progress: None,
                cancelled: Some(&cancelled),
            };
            per_scheme.push(prep.correlate_watched(&d, watch).map_err(|e| match e {
                DicError::Cancelled => DiagnoseError::Cancelled,
                other => dic_error(&run.id, s, other),
            })?);
            let n = done.fetch_add(1, Ordering::Relaxed) + 1;
            if !progress(n, total) {
                return Err(DiagnoseError::Cancelled);
            }
        }
        runs.push((ri, image, per_scheme));
    }
    Ok(PrintSide {
        reference: reference_image,
        runs,
    })
}

/// The comparison from the model's analyses: the landings refined against them
/// ([`refine_landings`]), every run's discrepancy, the totals and the χ²; the capture-mode runs
/// beside it when `hardware_model` holds their model side (empty for a prediction).
pub(super) fn assemble(
    meas: &Measurement,
    model: &ModelConfig,
    nominal: Nominal,
    mut model_dic: Vec<Vec<DicResult>>,
    images: Vec<ImageComparison>,
    hardware_model: Vec<HardwareModelSide>,
) -> Comparison {
    let opts = &meas.options;
    let runs = &meas.manifest.runs;
    let mut nominal = nominal;
    let rendered_at: Vec<[f64; 2]> = (0..runs.len())
        .map(|ri| nominal.stage.applied_offset_px(ri))
        .collect();
    refine_landings(meas, &mut nominal, &mut model_dic);
    let landing_shift_px: Vec<[f64; 2]> = rendered_at
        .iter()
        .enumerate()
        .map(|(ri, old)| {
            let new = nominal.stage.applied_offset_px(ri);
            [new[0] - old[0], new[1] - old[1]]
        })
        .collect();
    let hardware = compare_hardware(
        &meas.hardware,
        hardware_model,
        &meas.labels,
        &meas.pattern_of_run,
        &landing_shift_px,
        opts,
    );
    let out_runs = run_comparisons(meas, &nominal, &model_dic);
    let rms = |f: fn(&RunComparison) -> f64| {
        let v: Vec<f64> = out_runs.iter().map(f).filter(|x| x.is_finite()).collect();
        (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
    };
    let mut cmp = Comparison {
        dataset: meas.manifest.name.clone(),
        manifest_version: super::history::short_hash(
            &serde_json::to_string(&meas.manifest).expect("a manifest always serialises"),
        ),
        manifest_runs: meas.manifest.runs.len(),
        model: ModelInfo {
            name: model.name.clone(),
            version: model_version(model),
            effects: model.effects.clone(),
            nominal,
        },
        discrepancy_px: rms(|r| r.discrepancy_px),
        discrepancy_se_px: discrepancy_se(&out_runs),
        parts: DiscrepancyParts {
            rigid_px: rms(|r| r.rigid_px),
            field_px: rms(|r| r.field_px),
            std_px: rms(|r| r.std_px),
        },
        parts_se: DiscrepancyParts {
            rigid_px: rms_se(&out_runs, |d| (d.rigid_px, d.rigid_sq_var)),
            field_px: rms_se(&out_runs, |d| (d.field_px, d.field_sq_var)),
            std_px: rms_se(&out_runs, |d| (d.std_px, d.std_sq_var)),
        },
        runs: out_runs,
        images,
        chi2: Chi2::default(),
        hardware,
        hardware_runs_set_aside: meas.hardware_runs_set_aside,
        model_dic: Vec::new(),
    };
    cmp.chi2 = chi2(&cmp, None, &opts.dic);
    cmp.model_dic = model_dic;
    cmp
}

/// Every run and scheme of a comparison: the measured analysis against the model's.
fn run_comparisons(
    meas: &Measurement,
    nominal: &Nominal,
    model_dic: &[Vec<DicResult>],
) -> Vec<RunComparison> {
    let opts = &meas.options;
    let mut out_runs = Vec::new();
    for (ri, run) in meas.manifest.runs.iter().enumerate() {
        let model_results = &model_dic[ri];
        let move_px = nominal.actual_move_px(ri, (run.stage.dx_mm, run.stage.dy_mm));
        let um = |p: [f64; 2]| p.map(|x| x * 1000.0 / nominal.scale_px_per_mm);
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
                rigid_px: d.rigid_px,
                field_px: d.field_px,
                stage_offset_um: um(nominal.stage.applied_offset_px(ri)),
                stage_landing_um: um(nominal
                    .stage
                    .landing_px
                    .get(ri)
                    .copied()
                    .unwrap_or_default()),
                std_px: d.std_px,
                se: d.errors(),
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
                accuracy: accuracy(run, meas.manifest.scale_px_per_mm, scheme, m, &opts.dic),
                residual: residual_map(m, &d),
                detail: d,
            });
        }
    }
    out_runs
}

/// The measured analysis `m` of `run` in `scheme` against the run's commanded move.
fn accuracy(
    run: &crate::dataset::Run,
    scale_px_per_mm: f64,
    scheme: &Scheme,
    m: &DicResult,
    dic: &crate::dic::DicSettings,
) -> Accuracy {
    let px_per_mm = run.frame_px_per_mm(scale_px_per_mm);
    let blocks = [scheme.x.block as f64, scheme.y.block as f64];
    let commanded = [
        run.stage.dx_mm * px_per_mm / blocks[0],
        run.stage.dy_mm * px_per_mm / blocks[1],
    ];
    let s = &m.summary;
    let n_eff = (s.valid as f64 / super::bic::inflation(dic)).max(1.0);
    let bias = [s.u.mean - commanded[0], s.v.mean - commanded[1]];
    let std = [s.u.std, s.v.std];
    let se = std.map(|x| x / n_eff.sqrt());
    let um = |p: [f64; 2]| [0, 1].map(|i| p[i] * blocks[i] * 1000.0 / px_per_mm);
    Accuracy {
        commanded_px: commanded,
        bias_px: bias,
        bias_se_px: se,
        std_px: std,
        bias_um: um(bias),
        bias_se_um: um(se),
        std_um: um(std),
    }
}

/// Standard error of the total discrepancy D = √(mean D_r²) from the noise of each analysis,
/// propagated (var D² = Σ var D_r² / N², scaled by N/N_eff for the frames the analyses share).
/// It does not hold the model's speckle realisation: `diagnose` adds the scatter over model
/// seeds.
pub fn discrepancy_se(runs: &[RunComparison]) -> f64 {
    rms_se(runs, |d| (d.discrepancy_px, d.discrepancy_sq_var))
}

/// The standard error of an RMS over runs of one length (the discrepancy or one of its parts),
/// `part` giving each run's length and the sampling variance of its square, propagated as
/// [`discrepancy_se`] says.
fn rms_se(runs: &[RunComparison], part: fn(&RunDiscrepancy) -> (f64, f64)) -> f64 {
    let valid: Vec<(f64, f64)> = runs
        .iter()
        .map(|r| part(&r.detail))
        .filter(|(d, _)| d.is_finite())
        .collect();
    let n = valid.len();
    if n == 0 {
        return f64::NAN;
    }
    let nf = n as f64;
    let d2 = valid.iter().map(|(d, _)| d.powi(2)).sum::<f64>() / nf;
    let shared = super::bic::shared_fraction(runs).max(1e-9);
    let var_d2 = valid
        .iter()
        .map(|(_, v)| *v)
        .filter(|v| v.is_finite())
        .sum::<f64>()
        / (nf * nf)
        / shared;
    super::discrepancy::se_of_length(d2.sqrt(), var_d2)
}

/// Reads the dataset in `dir` and compares it with `model`. `progress` counts every analysis
/// (measured and model side).
pub fn compare(
    dir: &Path,
    model: &ModelConfig,
    options: &CompareOptions,
    progress: Progress,
) -> Result<Comparison, DiagnoseError> {
    let manifest_runs = Manifest::read(dir)?.full_resolution().0.runs.len() * options.schemes.len();
    let total = 2 * manifest_runs;
    let meas = load_measurement(dir, options, &|d, _| progress(d, total))?;
    compare_prepared(&meas, model, &|d, _| progress(manifest_runs + d, total))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::test_fields::{manifest, synthetic_result, PrintStated};
    use crate::dic::DicSettings;

    #[test]
    fn accuracy_is_the_measured_mean_against_the_commanded_move() {
        // A 0.1 mm move at 26 px/mm (2.6 px) measured as 2.65 px in x, −0.02 in y, with 0.01 px
        // of noise; in a 2x2 binned scheme the move is 1.3 px of the reduced frame.
        let run = &manifest(&[(0.1, 0.0)], &["a"], PrintStated::Nothing).runs[0];
        let dic = DicSettings {
            subset_px: 21,
            step_px: 21,
            ..DicSettings::default()
        };
        let m = synthetic_result((400, 300), &dic, |_, _| (1.325, -0.01), 0.01, 9);
        let scheme = Scheme::parse("ff100").unwrap();
        let a = accuracy(run, 26.0, &scheme, &m, &dic);
        assert!((a.commanded_px[0] - 1.3).abs() < 1e-12 && a.commanded_px[1] == 0.0);
        for k in 0..2 {
            let truth = [0.025, -0.01][k];
            assert!(
                (a.bias_px[k] - truth).abs() < 3.0 * a.bias_se_px[k],
                "{a:?}"
            );
            // µm of the full-resolution frame: px × block × 1000 / scale.
            let um = a.bias_px[k] * 2.0 * 1000.0 / 26.0;
            assert!((a.bias_um[k] - um).abs() < 1e-9);
        }
        // Points a step apart with a subset no larger are independent: SE = std/√n.
        let se = a.std_px[0] / (m.summary.valid as f64).sqrt();
        assert!((a.bias_se_px[0] - se).abs() < 1e-12);
    }

    #[test]
    fn a_models_version_is_its_effects_not_its_name() {
        let base = ModelConfig::from_toml(super::super::BASELINE_TOML, Path::new("b")).unwrap();
        let renamed = ModelConfig {
            name: "another name".into(),
            description: "another text".into(),
            ..base.clone()
        };
        assert_eq!(model_version(&base), model_version(&renamed));
        let mut changed = base.clone();
        changed.effects.rotation = Some(crate::model::effects::Rotation { angle_rad: 1e-4 });
        assert_ne!(model_version(&base), model_version(&changed));
    }
}
