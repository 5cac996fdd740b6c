//! The measured side of a comparison: a dataset read, its frames checked, every run analysed
//! once in every scheme, and each pattern's reference statistics (white level, noise, the
//! centred crops the print is calibrated to) from which the nominal experiment starts.

use super::capture_mode::{measure_hardware, HardwareMeasurement};
use super::image_stats::{centre_crop, frame_stats, moved_frame_stats, FrameStats, STATS_CROP_PX};
use super::nominal::{
    pattern_for, pattern_indices, pooled_noise_variance, white_level_guess, Nominal,
};
use super::{CompareOptions, DiagnoseError, Progress};
use crate::dataset::{check_pair, check_stated_move};
use crate::dataset::{Manifest, Run};
use crate::dic::DicResult;
use crate::image::{read_image, Image};
use crate::pairs::{correlate_pairs, PairVisitor, RunPair};
use crate::reduce::Scheme;
use std::path::{Path, PathBuf};

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
    /// Runs of the dataset read out in a hardware scheme ([`super::capture_mode`]).
    pub hardware: Vec<HardwareMeasurement>,
    /// Such runs without a full-resolution twin in the dataset: not compared.
    pub hardware_runs_set_aside: usize,
}
/// Reads a dataset and analyses the measured frames. `progress` counts run × scheme analyses.
pub fn load_measurement(
    dir: &Path,
    options: &CompareOptions,
    progress: Progress,
) -> Result<Measurement, DiagnoseError> {
    // Frames the sensor binned or decimated itself are compared beside the fit, in their mode
    // (`capture_mode`); the fit holds the full-resolution runs.
    let _span = tracing::debug_span!("measured_side").entered();
    let (manifest, hardware_runs) = Manifest::read(dir)?.full_resolution();
    if manifest.runs.is_empty() {
        return Err(DiagnoseError::Frames {
            run: "-".into(),
            message: format!(
                "all {} runs were read out in a hardware scheme; the model is fitted to \
                 full-resolution runs (each hardware run is compared beside its twin)",
                hardware_runs.len()
            ),
        });
    }
    options.dic.validate().map_err(|e| DiagnoseError::Dic {
        run: "-".into(),
        scheme: "-".into(),
        source: e,
    })?;
    let (labels, pattern_of_run) = pattern_indices(&manifest);
    let mut measured = MeasuredPairs {
        dir,
        scale_px_per_mm: manifest.scale_px_per_mm,
        pattern_of_run: &pattern_of_run,
        total: manifest.runs.len() * options.schemes.len(),
        done: 0,
        progress,
        dic: Vec::with_capacity(manifest.runs.len()),
        moved_crops: Vec::new(),
        moved_stats: Vec::new(),
        references: ReferenceStats::new(labels.len()),
        size: None,
        bit_depth: 16,
    };
    correlate_pairs(
        dir,
        &manifest.runs,
        &options.schemes,
        &options.dic,
        &mut measured,
    )?;
    let MeasuredPairs {
        dic,
        moved_crops,
        moved_stats,
        references,
        size,
        bit_depth,
        ..
    } = measured;
    let (width, height) = size.expect("a manifest has runs");
    let nominal = references.nominal(&manifest, &pattern_of_run, (width, height), bit_depth);
    let (hardware, hardware_runs_set_aside) =
        measure_hardware(dir, hardware_runs, &manifest, options)?;
    Ok(Measurement {
        dir: dir.to_owned(),
        manifest,
        options: options.clone(),
        labels,
        pattern_of_run,
        width,
        height,
        bit_depth,
        reference_crops: references
            .crops
            .into_iter()
            .map(|c| c.expect("every pattern has a run"))
            .collect(),
        repeat_crops: references.repeats,
        moved_crops,
        reference_stats: references
            .stats
            .into_iter()
            .map(|s| s.expect("filled"))
            .collect(),
        moved_stats,
        dic,
        nominal,
        hardware,
        hardware_runs_set_aside,
    })
}

/// The measured side of the pair loop: each run's checks, image statistics and analyses.
struct MeasuredPairs<'a> {
    dir: &'a Path,
    scale_px_per_mm: f64,
    pattern_of_run: &'a [usize],
    total: usize,
    done: usize,
    progress: Progress<'a>,
    dic: Vec<Vec<DicResult>>,
    moved_crops: Vec<Image>,
    moved_stats: Vec<FrameStats>,
    references: ReferenceStats,
    size: Option<(usize, usize)>,
    bit_depth: u8,
}

impl PairVisitor for MeasuredPairs<'_> {
    type Error = DiagnoseError;

    fn frames(&mut self, pair: &RunPair<'_>) -> Result<(), DiagnoseError> {
        let (run, reference, deformed) = (pair.run, pair.reference, pair.deformed);
        // A move stated an order of magnitude off would send the fit chasing a travel scale of
        // hundreds: say so with the measured figure instead. (The pair loop checked the sizes.)
        // The scale of the run's own frames, as the upload's check takes it.
        let px_per_mm = run.frame_px_per_mm(self.scale_px_per_mm);
        let measured = check_stated_move(
            reference,
            deformed,
            (run.stage.dx_mm, run.stage.dy_mm),
            px_per_mm,
        )
        .map_err(|e| DiagnoseError::Frames {
            run: run.id.clone(),
            message: e.to_string(),
        })?;
        // The light map's whole-pixel shift: the frames' own move where it was measured.
        let shift_px = measured.map_or(
            (run.stage.dx_mm * px_per_mm, run.stage.dy_mm * px_per_mm),
            |m| m.measured_px,
        );
        same_size_as_first(run, reference, &mut self.size)?;
        self.bit_depth = pair.bit_depth;
        self.references.observe(
            self.pattern_of_run[pair.index],
            self.dir,
            run,
            reference,
            pair.bit_depth,
        )?;
        let crop = centre_crop(deformed, STATS_CROP_PX);
        self.moved_stats
            .push(moved_frame_stats(reference, deformed, &crop, shift_px));
        self.moved_crops.push(crop);
        self.dic.push(Vec::new());
        Ok(())
    }

    /// Asked before every point: the counts so far again (see [`Progress`]).
    fn cancelled(&self) -> bool {
        !(self.progress)(self.done, self.total)
    }

    fn result(
        &mut self,
        _pair: &RunPair<'_>,
        _scheme: &Scheme,
        result: DicResult,
    ) -> Result<(), DiagnoseError> {
        self.dic.last_mut().expect("frames came first").push(result);
        self.done += 1;
        if (self.progress)(self.done, self.total) {
            Ok(())
        } else {
            Err(DiagnoseError::Cancelled)
        }
    }
}

/// Every run's frames have the size of the dataset's first run.
fn same_size_as_first(
    run: &Run,
    reference: &Image,
    first: &mut Option<(usize, usize)>,
) -> Result<(), DiagnoseError> {
    let here = (reference.width(), reference.height());
    match *first {
        None => *first = Some(here),
        Some(s) if s != here => {
            return Err(DiagnoseError::Frames {
                run: run.id.clone(),
                message: format!(
                    "frames are {}x{}, the dataset's first run has {}x{}",
                    here.0, here.1, s.0, s.1
                ),
            })
        }
        Some(_) => {}
    }
    Ok(())
}

/// Per pattern, from the reference (and its first repeat) of the pattern's first run: the centre
/// crops, their statistics, and the white level and noise variance guessed from them.
struct ReferenceStats {
    crops: Vec<Option<Image>>,
    repeats: Vec<Option<Image>>,
    stats: Vec<Option<FrameStats>>,
    /// (white level guess [DN], pooled noise variance [DN²])
    levels: Vec<(f64, f64)>,
}

impl ReferenceStats {
    fn new(patterns: usize) -> ReferenceStats {
        ReferenceStats {
            crops: vec![None; patterns],
            repeats: vec![None; patterns],
            stats: vec![None; patterns],
            levels: vec![(0.0, 0.0); patterns],
        }
    }

    /// Takes pattern `pi`'s figures from `run` unless an earlier run gave them.
    fn observe(
        &mut self,
        pi: usize,
        dir: &Path,
        run: &Run,
        reference: &Image,
        bit_depth: u8,
    ) -> Result<(), DiagnoseError> {
        if self.stats[pi].is_some() {
            return Ok(());
        }
        let crop = centre_crop(reference, STATS_CROP_PX);
        let repeat = match run.repeat.first() {
            Some(name) => {
                let (r, _) = read_image(&dir.join(name))?;
                check_pair(reference, &r).map_err(|e| DiagnoseError::Frames {
                    run: run.id.clone(),
                    message: e.to_string(),
                })?;
                Some(centre_crop(&r, STATS_CROP_PX))
            }
            None => None,
        };
        self.stats[pi] = Some(frame_stats(Some(reference), &crop, repeat.as_ref()));
        self.levels[pi] = (
            white_level_guess(&crop),
            pooled_noise_variance(&crop, repeat.as_ref(), bit_depth),
        );
        self.crops[pi] = Some(crop);
        self.repeats[pi] = repeat;
        Ok(())
    }

    /// The measurement's nominal experiment: the frames as read, a noise floor from the pooled
    /// variance, each pattern's print from its crop, the stage as commanded.
    fn nominal(
        &self,
        manifest: &Manifest,
        pattern_of_run: &[usize],
        (width, height): (usize, usize),
        bit_depth: u8,
    ) -> Nominal {
        let noise_var = self.levels.iter().map(|r| r.1).sum::<f64>() / self.levels.len() as f64;
        let patterns = (0..self.crops.len())
            .map(|pi| {
                let run =
                    &manifest.runs[pattern_of_run.iter().position(|&p| p == pi).expect("used")];
                pattern_for(
                    run,
                    self.crops[pi].as_ref().expect("every pattern has a run"),
                    self.levels[pi].0,
                    self.levels[pi].1,
                    manifest.scale_px_per_mm,
                )
            })
            .collect();
        Nominal {
            width,
            height,
            bit_depth,
            scale_px_per_mm: manifest.scale_px_per_mm,
            noise_floor_dn: noise_var.max(0.0).sqrt(),
            misalignment_rad: 0.0,
            travel_scale: 1.0,
            stage: Default::default(),
            patterns,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::test_fields::{manifest, PrintStated};

    #[test]
    fn every_run_must_have_the_first_runs_size() {
        let m = manifest(&[(1.0, 0.0), (2.0, 0.0)], &["a"], PrintStated::Nothing);
        let mut first = None;
        same_size_as_first(&m.runs[0], &Image::filled(64, 48, 0.0), &mut first).unwrap();
        assert_eq!(first, Some((64, 48)));
        same_size_as_first(&m.runs[1], &Image::filled(64, 48, 0.0), &mut first).unwrap();
        let e = same_size_as_first(&m.runs[1], &Image::filled(48, 64, 0.0), &mut first);
        match e {
            Err(DiagnoseError::Frames { run, message }) => {
                assert_eq!(run, "r1");
                assert!(
                    message.contains("48x64") && message.contains("64x48"),
                    "{message}"
                );
            }
            other => panic!("{other:?}"),
        }
    }
}
