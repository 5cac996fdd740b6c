//! Runs the camera read out in its own binning or decimation (a dataset run with `capture`, the
//! `hw:` schemes of an experiment), compared in that mode.
//!
//! The measured frames are analysed as they are (no synthesised reduction on top); the model
//! renders the same pattern at the landing of the run's full-resolution twin (the same pattern and
//! move, captured at the same stage position) and reads it out as the camera did
//! ([`crate::model::SensorReadout`]): binned pixels average or sum the sensor's pixels, decimation
//! keeps one of each block. A model with `sensor_noise` puts its read noise where the binning
//! domain says (once per binned pixel for charge binning, per sensor pixel for digital binning,
//! Janesick, *Photon Transfer*, 2007, §7); without it the dataset's noise floor (signal-independent,
//! measured at full resolution) cannot tell shot from read noise and is applied per sensor pixel —
//! the digital case.
//!
//! These runs are reported beside the comparison — their discrepancy, its parts and image
//! statistics in the capture mode — and are not part of the fit: their stage landings are their
//! twins' (already fitted), and a second read-out of the same scene at the same position would
//! count the geometric evidence twice in the BIC.

use super::bic::inflation;
use super::discrepancy::run_discrepancy;
use super::image_stats::{centre_crop, frame_stats, FrameStats, STATS_CROP_PX};
use super::nominal::Nominal;
use super::results::{DiscrepancyParts, HardwareComparison, HardwareRunComparison};
use super::scene::{Scene, Shot};
use super::{CompareOptions, DiagnoseError};
use crate::dataset::{sensor_readout, Manifest, Run};
use crate::dic::{DicResult, PreparedReference};
use crate::image::Image;
use crate::pairs::{correlate_pairs, PairVisitor, RunPair};
use crate::reduce::Scheme;
use ffdic_hw::HardwareScheme;
use std::path::Path;

/// The noise seeds of the model's capture-mode frames start here (full-resolution frames use
/// 0, 1 and 2 + run index).
const FRAME_SEED_BASE: u64 = 1 << 32;

/// The measured side of one run read out in a hardware scheme.
pub struct HardwareMeasurement {
    pub run: Run,
    pub capture: HardwareScheme,
    /// Index of its full-resolution twin in the measurement's runs.
    pub twin: usize,
    pub dic: DicResult,
    pub reference_stats: FrameStats,
    pub moved_stats: FrameStats,
}

/// The model's side of one such run: its analysis and its frames' statistics.
pub struct HardwareModelSide {
    pub dic: DicResult,
    pub reference_stats: FrameStats,
    pub moved_stats: FrameStats,
}

/// Analyses the runs of `hardware` (a dataset's capture-mode runs) whose twin is a run of
/// `manifest`; returns them and how many had no twin there (set aside).
pub fn measure_hardware(
    dir: &Path,
    hardware: Vec<Run>,
    manifest: &Manifest,
    options: &CompareOptions,
) -> Result<(Vec<HardwareMeasurement>, usize), DiagnoseError> {
    let twin_of = |run: &Run| {
        run.twin_of
            .as_ref()
            .and_then(|t| manifest.runs.iter().position(|r| &r.id == t))
    };
    let total = hardware.len();
    let (runs, twins): (Vec<Run>, Vec<usize>) = hardware
        .into_iter()
        .filter(|r| r.capture.is_some())
        .filter_map(|r| twin_of(&r).map(|t| (r, t)))
        .unzip();
    let mut measured = MeasuredCaptures {
        twins: &twins,
        reference_stats: None,
        out: Vec::with_capacity(runs.len()),
    };
    correlate_pairs(dir, &runs, &[], &options.dic, &mut measured)?;
    Ok((measured.out, total - runs.len()))
}

/// The capture-mode side of the pair loop: each run's analysis and image statistics.
struct MeasuredCaptures<'a> {
    /// Each run's twin (an index into the manifest's runs).
    twins: &'a [usize],
    /// The last reference's file and statistics (runs of one pattern and mode share it).
    reference_stats: Option<(String, FrameStats)>,
    out: Vec<HardwareMeasurement>,
}

impl PairVisitor for MeasuredCaptures<'_> {
    type Error = DiagnoseError;

    fn frames(&mut self, pair: &RunPair<'_>) -> Result<(), DiagnoseError> {
        if self.reference_stats.as_ref().map(|r| &r.0) != Some(&pair.run.reference) {
            self.reference_stats = Some((pair.run.reference.clone(), stats_of(pair.reference)));
        }
        Ok(())
    }

    fn result(
        &mut self,
        pair: &RunPair<'_>,
        _scheme: &Scheme,
        dic: DicResult,
    ) -> Result<(), DiagnoseError> {
        let run = pair.run.clone();
        self.out.push(HardwareMeasurement {
            twin: self.twins[pair.index],
            reference_stats: self
                .reference_stats
                .as_ref()
                .expect("frames came first")
                .1
                .clone(),
            moved_stats: stats_of(pair.deformed),
            dic,
            capture: run.capture.clone().expect("a capture-mode run"),
            run,
        });
        Ok(())
    }
}

fn stats_of(frame: &Image) -> FrameStats {
    frame_stats(Some(frame), &centre_crop(frame, STATS_CROP_PX), None)
}

/// Renders and analyses the model's side of every capture-mode run of `measured` (landings as
/// `nominal` has them for the twins).
pub fn model_hardware(
    measured: &[HardwareMeasurement],
    scene: &Scene,
    nominal: &Nominal,
    pattern_of_run: &[usize],
    options: &CompareOptions,
) -> Result<Vec<HardwareModelSide>, DiagnoseError> {
    measured
        .iter()
        .enumerate()
        .map(|(k, h)| {
            let readout = sensor_readout(&h.capture);
            let pattern = pattern_of_run[h.twin];
            let seed = FRAME_SEED_BASE + 2 * k as u64;
            let reference = scene.render_read_out(pattern, Shot::still(seed), &readout);
            let at = nominal.landed_command(h.twin, (h.run.stage.dx_mm, h.run.stage.dy_mm));
            let moved = scene.render_read_out(pattern, Shot::moved(at, seed + 1), &readout);
            let dic_error = |source| DiagnoseError::Dic {
                run: h.run.id.clone(),
                scheme: h.capture.name.clone(),
                source,
            };
            let dic = PreparedReference::new(&reference, &options.dic)
                .map_err(dic_error)?
                .correlate(&moved, None)
                .map_err(dic_error)?;
            Ok(HardwareModelSide {
                dic,
                reference_stats: stats_of(&reference),
                moved_stats: stats_of(&moved),
            })
        })
        .collect()
}

/// The capture-mode runs compared; `shift_px` is each full-resolution run's landing change since
/// the model's frames were rendered (`compare::refine_landings`), moved onto the model's
/// displacements in the captured frames' px as for the synthesised schemes. `None` without
/// capture-mode runs or without their model side (a comparison predicted without rendering).
pub fn compare_hardware(
    measured: &[HardwareMeasurement],
    model: Vec<HardwareModelSide>,
    labels: &[String],
    pattern_of_run: &[usize],
    shift_px: &[[f64; 2]],
    options: &CompareOptions,
) -> Option<HardwareComparison> {
    if measured.is_empty() || model.len() != measured.len() {
        return None;
    }
    let runs: Vec<HardwareRunComparison> = measured
        .iter()
        .zip(model)
        .map(|(h, mut o)| {
            let shift = shift_px.get(h.twin).copied().unwrap_or_default();
            let (bx, by) = (h.capture.x.factor() as f64, h.capture.y.factor() as f64);
            for p in o.dic.points.iter_mut() {
                p.u += shift[0] / bx;
                p.v += shift[1] / by;
            }
            let d = run_discrepancy(&h.dic, &o.dic, inflation(&options.dic));
            HardwareRunComparison {
                id: h.run.id.clone(),
                twin: h.run.twin_of.clone().unwrap_or_default(),
                pattern: labels[pattern_of_run[h.twin]].clone(),
                scheme: h.capture.name.clone(),
                discrepancy_px: d.discrepancy_px,
                se: d.errors(),
                parts: DiscrepancyParts {
                    rigid_px: d.rigid_px,
                    field_px: d.field_px,
                    std_px: d.std_px,
                },
                points: d.points,
                measured_random_px: [d.measured_random_px.0, d.measured_random_px.1],
                model_random_px: [d.model_random_px.0, d.model_random_px.1],
                mean_diff_px: [d.mean_diff_px.0, d.mean_diff_px.1],
                reference: [h.reference_stats.clone(), o.reference_stats],
                moved: [h.moved_stats.clone(), o.moved_stats],
            }
        })
        .collect();
    let finite: Vec<f64> = runs
        .iter()
        .map(|r| r.discrepancy_px)
        .filter(|d| d.is_finite())
        .collect();
    let discrepancy_px =
        (finite.iter().map(|d| d * d).sum::<f64>() / finite.len().max(1) as f64).sqrt();
    Some(HardwareComparison {
        discrepancy_px,
        runs,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::test_fields::{frame_stats, manifest, synthetic_result, PrintStated};
    use crate::dic::{DicSettings, PoiStatus};
    use ffdic_hw::{AxisReduction, BinningDomain, BinningMode};

    /// The camera's 2x2 averaging binning, or its 2x2 decimation.
    fn two_by_two(binned: bool) -> HardwareScheme {
        let (axis, name, preset, fill) = if binned {
            let mode = BinningMode::Average;
            (
                AxisReduction::Bin { factor: 2, mode },
                "hw:bin2x2-average",
                "ff100",
                1.0,
            )
        } else {
            (
                AxisReduction::Decimate { factor: 2 },
                "hw:dec2x2",
                "ff25",
                0.25,
            )
        };
        HardwareScheme {
            name: name.into(),
            x: axis,
            y: axis,
            binning_domain: binned.then_some(BinningDomain::Charge),
            equivalent_preset: Some(preset.into()),
            fill_factor: fill,
        }
    }

    fn settings() -> DicSettings {
        DicSettings {
            subset_px: 21,
            step_px: 20,
            ..DicSettings::default()
        }
    }

    /// A 640x540 captured frame pair's analysis: every point moved by `(u, v)`, noise 0.002 px.
    fn analysis((u, v): (f64, f64), seed: u64) -> DicResult {
        synthetic_result((640, 540), &settings(), |_, _| (u, v), 0.002, seed)
    }

    /// The run `twin` of `manifest` read out in `capture`, its frames analysed as `dic`.
    fn captured(
        manifest: &Manifest,
        twin: usize,
        capture: HardwareScheme,
        dic: DicResult,
    ) -> HardwareMeasurement {
        let mut run = manifest.runs[twin].clone();
        run.twin_of = Some(run.id.clone());
        run.id = format!("{}-{}", run.id, capture.name);
        run.capture = Some(capture.clone());
        HardwareMeasurement {
            run,
            capture,
            twin,
            dic,
            reference_stats: frame_stats(1000.0),
            moved_stats: frame_stats(990.0),
        }
    }

    fn model_side(dic: DicResult) -> HardwareModelSide {
        HardwareModelSide {
            dic,
            reference_stats: frame_stats(1010.0),
            moved_stats: frame_stats(1005.0),
        }
    }

    #[test]
    fn a_capture_mode_run_is_compared_after_its_twins_landing_moved() {
        // Run r0's landing moved by (0.4, −0.2) full-resolution px since the model rendered its
        // binned twin: (0.2, −0.1) px of the 2x2 frames. The measured frames show that and
        // (0.03, 0.04) px more: a rigid part of 0.05 px. Run r1's decimated frames show exactly
        // its twin's change, (−0.6, 0.2)/2: nothing.
        let m = manifest(&[(5.0, 0.0), (0.0, 5.0)], &["a", "b"], PrintStated::Nothing);
        let measured = vec![
            captured(&m, 0, two_by_two(true), analysis((1.23, 0.44), 1)),
            captured(&m, 1, two_by_two(false), analysis((0.4, 0.2), 2)),
        ];
        let model = vec![
            model_side(analysis((1.0, 0.5), 3)),
            model_side(analysis((0.7, 0.1), 4)),
        ];
        let options = CompareOptions {
            dic: settings(),
            ..CompareOptions::default()
        };
        let labels = ["a".to_string(), "b".to_string()];
        let shift = [[0.4, -0.2], [-0.6, 0.2]];
        let h = compare_hardware(&measured, model, &labels, &[0, 1], &shift, &options).unwrap();
        let [r0, r1] = &h.runs[..] else {
            panic!("two runs: {:?}", h.runs.len())
        };
        assert_eq!(
            (r0.id.as_str(), r0.twin.as_str(), r0.pattern.as_str()),
            ("r0-hw:bin2x2-average", "r0", "a")
        );
        assert_eq!(
            (r1.scheme.as_str(), r1.pattern.as_str()),
            ("hw:dec2x2", "b")
        );
        assert_eq!(r0.points, measured[0].dic.points.len());
        for (k, truth) in [0.03, 0.04].into_iter().enumerate() {
            let (got, se) = (r0.mean_diff_px[k], r0.se.mean_diff_se_px[k]);
            assert!(
                (got - truth).abs() < 3.0 * se,
                "{got} ± {se} against {truth}"
            );
        }
        let (d, se) = (r0.parts.rigid_px, r0.se.rigid_se_px);
        assert!((d - 0.05).abs() < 3.0 * se, "{d} ± {se}");
        assert!(r0.parts.field_px < 3.0 * r0.se.field_se_px);
        assert!(r1.discrepancy_px < 3.0 * r1.se.discrepancy_se_px, "{r1:?}");
        // Both sides' noise is 0.002 px per component.
        for side in [r0.measured_random_px, r0.model_random_px] {
            assert!(
                side.iter().all(|s| (s / 0.002 - 1.0).abs() < 0.1),
                "{side:?}"
            );
        }
        // Statistics of each frame, measured first.
        assert_eq!(
            (r0.reference[0].mean_dn, r0.reference[1].mean_dn),
            (1000.0, 1010.0)
        );
        assert_eq!((r0.moved[0].mean_dn, r0.moved[1].mean_dn), (990.0, 1005.0));
        // The total is the RMS over the runs: √(0.05²/2).
        let total = (0.05f64.powi(2) / 2.0).sqrt();
        let se = r0.se.discrepancy_se_px + r1.se.discrepancy_se_px;
        assert!(
            (h.discrepancy_px - total).abs() < 3.0 * se,
            "{} ± {se}",
            h.discrepancy_px
        );
    }

    #[test]
    fn an_unmeasurable_run_is_reported_and_left_out_of_the_total() {
        // The model's analysis of the second run has no valid point: its discrepancy is NaN and
        // the total is the first run's alone.
        let m = manifest(&[(5.0, 0.0), (0.0, 5.0)], &["a"], PrintStated::Nothing);
        let mut lost = analysis((0.0, 0.0), 8);
        lost.points
            .iter_mut()
            .for_each(|p| p.status = PoiStatus::LowCorrelation);
        let measured = vec![
            captured(&m, 0, two_by_two(true), analysis((0.13, 0.0), 5)),
            captured(&m, 1, two_by_two(true), analysis((0.0, 0.0), 6)),
        ];
        let model = vec![model_side(analysis((0.0, 0.0), 7)), model_side(lost)];
        let options = CompareOptions {
            dic: settings(),
            ..CompareOptions::default()
        };
        let labels = ["a".to_string()];
        let h = compare_hardware(&measured, model, &labels, &[0, 0], &[], &options).unwrap();
        assert!(h.runs[1].discrepancy_px.is_nan());
        assert_eq!(h.runs[1].points, 0);
        // No landing change known (no shifts given): the first run's 0.13 px is all rigid.
        let (d, se) = (h.runs[0].discrepancy_px, h.runs[0].se.discrepancy_se_px);
        assert!((d - 0.13).abs() < 3.0 * se, "{d} ± {se}");
        assert!((h.discrepancy_px - d).abs() < 1e-15);
    }

    #[test]
    fn without_capture_mode_runs_or_their_model_side_there_is_no_comparison() {
        let m = manifest(&[(5.0, 0.0)], &["a"], PrintStated::Nothing);
        let options = CompareOptions::default();
        let labels = ["a".to_string()];
        assert!(compare_hardware(&[], Vec::new(), &labels, &[0], &[], &options).is_none());
        // A comparison predicted without rendering has no model side.
        let measured = [captured(&m, 0, two_by_two(false), analysis((0.0, 0.0), 9))];
        assert!(compare_hardware(&measured, Vec::new(), &labels, &[0], &[], &options).is_none());
    }
}
