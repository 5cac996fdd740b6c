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
use super::compare::DiscrepancyParts;
use super::discrepancy::run_discrepancy;
use super::image_stats::{centre_crop, frame_stats, FrameStats, STATS_CROP_PX};
use super::nominal::{check_sizes, Nominal, Scene};
use super::{CompareOptions, DiagnoseError};
use crate::dataset::{sensor_readout, Manifest, Run};
use crate::dic::{DicResult, PreparedReference};
use crate::image::Image;
use crate::model::{BinnedValue, SensorReadout};
use crate::pairs::{correlate_pairs, PairVisitor, RunPair};
use crate::reduce::Scheme;
use ffdic_hw::HardwareScheme;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
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

/// One capture-mode run compared.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HardwareRunComparison {
    pub id: String,
    /// The full-resolution run of the same pattern and move.
    pub twin: String,
    pub pattern: String,
    /// The capture mode's name (`hw:bin2x2-average`, …).
    pub scheme: String,
    /// In px of the captured (reduced) frames, as the synthesised schemes' are in theirs.
    pub discrepancy_px: f64,
    /// Its standard error from the noise of both analyses.
    pub discrepancy_se_px: f64,
    #[serde(flatten)]
    pub parts: DiscrepancyParts,
    /// Points valid in both analyses.
    pub points: usize,
    /// Random error of each side (std of u and v about their own quadratic surface), px.
    pub measured_random_px: [f64; 2],
    pub model_random_px: [f64; 2],
    pub mean_diff_px: [f64; 2],
    /// Image statistics of the captured reference and moved frames and the model's.
    pub reference: [FrameStats; 2],
    pub moved: [FrameStats; 2],
}

/// Every capture-mode run of a comparison.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HardwareComparison {
    /// RMS of the runs' discrepancies, px of their frames.
    pub discrepancy_px: f64,
    pub runs: Vec<HardwareRunComparison>,
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
        check_sizes(pair.run, pair.reference, pair.deformed)?;
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
            let reference = scene.render_read_out(pattern, (0.0, 0.0), false, seed, &readout);
            let at = nominal.landed_command(h.twin, (h.run.stage.dx_mm, h.run.stage.dy_mm));
            let moved = scene.render_read_out(pattern, at, true, seed + 1, &readout);
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
                discrepancy_se_px: d.discrepancy_se_px(),
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

/// Reads `irradiance` (a noise-free full-resolution frame, DN) out as `readout` combines the
/// sensor's pixels, each sensor pixel with its own signal-independent noise of σ `sigma_dn`
/// (module doc: the digital case), then the ADC's rounding to `0..=full_dn`. Output rows in
/// parallel, each with its own noise stream from (`seed`, row).
pub fn read_out_with_floor(
    irradiance: &Image,
    readout: &SensorReadout,
    sigma_dn: f64,
    full_dn: f64,
    seed: u64,
) -> Image {
    let (w, h) = (irradiance.width(), irradiance.height());
    let (ow, oh) = readout.output_size((w, h));
    let (bx, by) = readout.block();
    let (ax, ay) = (readout.binning.0.max(1), readout.binning.1.max(1));
    let n = (ax * ay) as f64;
    let data = irradiance.data();
    let mut out = vec![0.0f32; ow * oh];
    out.par_chunks_mut(ow.max(1))
        .enumerate()
        .for_each(|(orow, line)| {
            let mut rng = ChaCha8Rng::seed_from_u64(
                seed ^ (orow as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15),
            );
            let normal = Normal::new(0.0, sigma_dn.max(0.0)).expect("finite sigma");
            for (ocol, px) in line.iter_mut().enumerate() {
                let mut sum = 0.0;
                for dy in 0..ay {
                    let row = &data[(orow * by + dy) * w..][..w];
                    for &v in &row[ocol * bx..][..ax] {
                        sum += v as f64 + normal.sample(&mut rng);
                    }
                }
                let value = match readout.value {
                    BinnedValue::Average => sum / n,
                    BinnedValue::Sum => sum,
                };
                *px = value.round().clamp(0.0, full_dn) as f32;
            }
        });
    Image::from_vec(ow, oh, out).expect("sized")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Averaging n pixels of independent noise divides its σ by √n; decimation keeps it; the
    /// mean of a flat frame is kept by an average and multiplied by n by a sum.
    #[test]
    fn the_noise_floor_reads_out_as_digital_binning() {
        let flat = Image::from_vec(256, 256, vec![1000.0; 256 * 256]).unwrap();
        let sigma = 8.0;
        let mode = |binning, decimation, value| SensorReadout {
            binning,
            decimation,
            value,
            ..SensorReadout::default()
        };
        for (readout, mean, std) in [
            (
                mode((2, 2), (1, 1), BinnedValue::Average),
                1000.0,
                sigma / 2.0,
            ),
            (mode((1, 1), (2, 2), BinnedValue::Average), 1000.0, sigma),
            (mode((2, 2), (1, 1), BinnedValue::Sum), 4000.0, sigma * 2.0),
        ] {
            let img = read_out_with_floor(&flat, &readout, sigma, 65535.0, 7);
            assert_eq!((img.width(), img.height()), (128, 128));
            let (m, s) = img.mean_std();
            // Standard errors over 16,384 pixels: σ/128 for the mean, σ/181 for the std (plus
            // the rounding's 1/√12 DN in quadrature).
            let s_expected = (std * std + 1.0 / 12.0f64).sqrt();
            assert!(
                (m - mean).abs() < 4.0 * std / 128.0,
                "{readout:?}: mean {m}"
            );
            assert!(
                (s - s_expected).abs() < 4.0 * s_expected / 181.0,
                "{readout:?}: std {s} vs {s_expected}"
            );
        }
    }
}
