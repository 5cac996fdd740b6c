//! What a dataset can reveal. Some effects leave no trace without the right runs, and some pairs
//! explain the same residual unless the dataset holds the runs that separate them:
//!
//! - `lens_distortion` needs a translation of at least 2 % of the frame width (its field is
//!   k1·[g(p+T) − g(p)] ∝ T); with translations of one size only, its field on a centred ROI is
//!   partly a magnification change, so it is confounded with `scale` until translations of
//!   several sizes (ratio ≥ 1.5) are measured: distortion grows with the move, a scale change
//!   does not.
//! - `psf_blur` needs the printed dot size in the manifest: an imaged dot's σ² is the printed σ²
//!   plus the PSF's (a speckle estimated from the frame already contains the blur).
//! - `psf_blur` and `fill_factor` need a characterised print (its profile, contrast, spacing and
//!   size stated, [`super::print::characterised`]): a print calibrated from the frames absorbs
//!   whatever blur one magnification cannot attribute, so neither could be named however well
//!   its fit did, and no stage move supplies what is missing. With a characterised print they
//!   are confounded with each other (both low-pass the image) unless sub-pixel step series in x
//!   and in y are measured: the aperture's bias against the sub-pixel fraction differs per axis.
//! - `sensor_noise` needs static repeat frames: noise against mean from a single speckle frame is
//!   entangled with the speckle itself.
//! - `rotation`, `scale`, `target_tilt`, `illumination_change`, `motion_blur` need a moved run.
//! - `fixed_pattern` needs flat-field and dark frames, which `ffdic-dataset/1` has no run for.

use crate::dataset::Manifest;
use crate::model::{CandidateId, EffectId};
use serde::{Deserialize, Serialize};

/// The runs of a dataset as the identifiability rules see them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DatasetDesign {
    pub moved_runs: usize,
    /// Distinct translation sizes, full-resolution px (commanded × scale).
    pub move_sizes_px: Vec<f64>,
    /// Largest translation / frame width.
    pub largest_move_fraction: f64,
    /// Distinct sub-pixel (< 2 px) moves along x only and along y only.
    pub subpixel_steps_x: usize,
    pub subpixel_steps_y: usize,
    pub has_repeats: bool,
    /// The dataset states its stage's repeatability (`stage_repeatability_um`).
    pub repeatability_stated: bool,
    pub dot_size_known: bool,
    /// Every run's print is characterised in the manifest ([`super::print::characterised`]), not
    /// calibrated from the frames.
    #[serde(default)]
    pub print_characterised: bool,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NotIdentifiable {
    pub effect: EffectId,
    pub reason: String,
    pub runs_to_add: String,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Confounded {
    /// Two effect ids, or an effect and what it is confounded with outside the vocabulary
    /// (`print`, `illumination`).
    pub effects: [String; 2],
    /// The run that would separate them.
    pub separate_with: String,
    /// "design" (the dataset lacks the separating runs) or "data" (both fits explain the same
    /// residual).
    pub evidence: String,
}

fn distinct(mut v: Vec<f64>, rel: f64) -> Vec<f64> {
    v.sort_by(|a, b| a.total_cmp(b));
    let mut out: Vec<f64> = Vec::new();
    for x in v {
        if out
            .last()
            .is_none_or(|l| (x - l).abs() > rel * x.abs().max(1e-9))
        {
            out.push(x);
        }
    }
    out
}

pub fn design_of(manifest: &Manifest, width: usize) -> DatasetDesign {
    let k = manifest.scale_px_per_mm;
    let moves: Vec<(f64, f64)> = manifest
        .runs
        .iter()
        .map(|r| (r.stage.dx_mm * k, r.stage.dy_mm * k))
        .collect();
    let sizes: Vec<f64> = moves
        .iter()
        .map(|m| m.0.hypot(m.1))
        .filter(|s| *s > 1e-9)
        .collect();
    let largest = sizes.iter().copied().fold(0.0, f64::max);
    let steps = |along_x: bool| {
        distinct(
            moves
                .iter()
                .filter(|m| {
                    let (a, b) = if along_x { (m.0, m.1) } else { (m.1, m.0) };
                    b.abs() < 1e-12 && a.abs() > 1e-9 && a.abs() < 2.0
                })
                .map(|m| if along_x { m.0.abs() } else { m.1.abs() })
                .collect(),
            0.05,
        )
        .len()
    };
    DatasetDesign {
        moved_runs: sizes.len(),
        move_sizes_px: distinct(sizes, 0.05),
        largest_move_fraction: largest / width.max(1) as f64,
        subpixel_steps_x: steps(true),
        subpixel_steps_y: steps(false),
        has_repeats: manifest.runs.iter().any(|r| !r.repeat.is_empty()),
        repeatability_stated: manifest.stage_repeatability_um.is_some(),
        dot_size_known: manifest.runs.iter().all(|r| {
            r.pattern
                .as_ref()
                .is_some_and(|p| p.dot_diameter_mm.is_some())
        }),
        print_characterised: manifest
            .runs
            .iter()
            .all(|r| super::print::characterised(r).is_some()),
    }
}

pub const SEVERAL_SIZES: &str =
    "translations of several sizes (e.g. 1/4, 1/2 and all of the largest move): distortion grows with the move, a scale change does not";
/// The sub-pixel steps along each axis a step series needs before the aperture and the blur count
/// as separable by the design ([`DatasetDesign::confounded`]); a bench's separating plan captures
/// exactly this many.
pub const STEP_SERIES_MIN_STEPS: usize = 3;

/// What separates lens blur and pixel aperture from the print's own profile.
pub const PRINT_SEPARATION: &str = "a characterised print (the dataset.json pattern's dot_spacing_mm and contrast, with profile \"gaussian\" and its dot_diameter_mm or a measured mtf, or profile \"disk\" and its dot_diameter_mm and edge_softness_mm), a second magnification, a through-focus pair, or a slanted-edge frame measured as in ISO 12233: the print's calibration to the frames absorbs whatever blur one magnification cannot attribute";

pub const STEP_SERIES: &str =
    "a sub-pixel step series in x and in y (at least 3 moves below 2 px along each axis, e.g. step_series with dx_step_mm, dy_step_mm)";

impl DatasetDesign {
    /// Why `effect` cannot be revealed by this dataset, if it cannot.
    pub fn not_identifiable(&self, effect: EffectId) -> Option<NotIdentifiable> {
        use EffectId::*;
        let no = |reason: &str, runs: &str| {
            Some(NotIdentifiable {
                effect,
                reason: reason.into(),
                runs_to_add: runs.into(),
            })
        };
        let moved = "a translation of the target (any run with a stage move)";
        match effect {
            Rotation | Scale | TargetTilt | IlluminationChange | MotionBlur
                if self.moved_runs == 0 =>
            {
                no("no run moves the target", moved)
            }
            LensDistortion if self.largest_move_fraction < 0.02 => no(
                "the largest translation is below 2 % of the frame width: distortion's field grows with the move and stays below the noise",
                "a translation of at least 5 % of the field of view, and translations of several sizes",
            ),
            PsfBlur if !self.dot_size_known => no(
                "the printed dot size is not in the manifest: a speckle estimated from the frames already contains the blur",
                "the printed dot diameter (pattern.dot_diameter_mm) of every run, or a run of a pattern with a known dot size",
            ),
            PsfBlur | FillFactor if !self.print_characterised => no(
                "the print is calibrated from the frames, not characterised: its calibration absorbs whatever blur one magnification cannot attribute",
                PRINT_SEPARATION,
            ),
            SensorNoise if !self.has_repeats => no(
                "no static repeat frames: noise against mean from one speckle frame is entangled with the speckle",
                "static repeat frames of the reference position (run.repeat), one or more per pattern",
            ),
            StageError if !self.repeatability_stated => no(
                "the stage's repeatability is not stated: every run's landing offset is fitted freely, so there is nothing to hold them against",
                "the stage's stated repeatability (dataset.json stage_repeatability_um, 1σ per axis in µm)",
            ),
            FixedPattern => no(
                "PRNU/DSNU need uniform illumination; speckle frames cannot tell a pixel's gain from the pattern",
                "flat-field frames of a uniform white target at several exposures and dark frames (lens capped)",
            ),
            Rotation | Scale | TargetTilt | IlluminationChange | MotionBlur | LensDistortion
            | PsfBlur | SensorNoise | StageError | StageMisalignment | FillFactor | Quantization
            | Vignetting => None,
        }
    }

    /// Pairs among `candidates` this design cannot separate, with the run that would.
    pub fn confounded(&self, candidates: &[EffectId]) -> Vec<Confounded> {
        let has = |e: EffectId| candidates.contains(&e);
        let mut out = Vec::new();
        let sizes_ok = self.move_sizes_px.len() >= 2
            && self.move_sizes_px.last().copied().unwrap_or(0.0)
                >= 1.5
                    * self
                        .move_sizes_px
                        .iter()
                        .copied()
                        .find(|s| *s > 2.0)
                        .unwrap_or(f64::INFINITY);
        if has(EffectId::LensDistortion) && has(EffectId::Scale) && !sizes_ok {
            out.push(Confounded {
                effects: pair(&EffectId::LensDistortion.into(), &EffectId::Scale.into()),
                separate_with: SEVERAL_SIZES.into(),
                evidence: "design".into(),
            });
        }
        if has(EffectId::FillFactor)
            && has(EffectId::PsfBlur)
            && (self.subpixel_steps_x < STEP_SERIES_MIN_STEPS
                || self.subpixel_steps_y < STEP_SERIES_MIN_STEPS)
        {
            out.push(Confounded {
                effects: pair(&EffectId::FillFactor.into(), &EffectId::PsfBlur.into()),
                separate_with: STEP_SERIES.into(),
                evidence: "design".into(),
            });
        }
        out
    }
}

/// What separates a tilt from the other affine fields that grow with the move.
pub const TILT_SEPARATION: &str = "translations along both x and y, of two sizes each: a tilt's strain is twice as large along the move as across it (εxx ≈ 2 εyy for an x move), decentring distortion's three times, and a scale change does not grow with the move";

/// Two effects as a confounded pair's names.
pub fn pair(a: &CandidateId, b: &CandidateId) -> [String; 2] {
    [a.to_string(), b.to_string()]
}

/// The run that separates two candidates, for pairs the data show explaining the same residual.
pub fn separating_run(a: &CandidateId, b: &CandidateId) -> String {
    match (a.catalogue(), b.catalogue()) {
        (Some(a), Some(b)) => separating_catalogue_run(a, b),
        _ => "runs for which the two fields differ: other move sizes and directions (a user effect's field is what its expressions say it is)".into(),
    }
}

fn separating_catalogue_run(a: EffectId, b: EffectId) -> String {
    use EffectId::*;
    let pair = |x: EffectId, y: EffectId| (a == x && b == y) || (a == y && b == x);
    if pair(LensDistortion, Scale) {
        SEVERAL_SIZES.into()
    } else if pair(FillFactor, PsfBlur) {
        STEP_SERIES.into()
    } else if pair(Rotation, LensDistortion) || pair(Rotation, Scale) {
        "translations along x and along y".into()
    } else if pair(TargetTilt, LensDistortion)
        || pair(TargetTilt, Scale)
        || pair(TargetTilt, Rotation)
    {
        TILT_SEPARATION.into()
    } else {
        "runs that change one of the two effects alone (see the effects' signatures in ARCHITECTURE.md)"
            .into()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::test_fields::{manifest, PrintStated};

    #[test]
    fn the_papers_one_move_design_cannot_tell_distortion_from_scale() {
        // One 5 mm move (130 px of a 2560 px frame): distortion is identifiable (5 % of the
        // field), but not apart from a scale change, which needs a second move size.
        let d = design_of(&manifest(&[(5.0, 0.0)], &["a"], PrintStated::Nothing), 2560);
        assert_eq!(d.moved_runs, 1);
        assert_eq!(d.move_sizes_px, vec![130.0]);
        assert!((d.largest_move_fraction - 130.0 / 2560.0).abs() < 1e-12);
        assert!(d.not_identifiable(EffectId::LensDistortion).is_none());
        assert!(
            d.not_identifiable(EffectId::PsfBlur).is_some(),
            "no dot size stated"
        );
        assert!(
            d.not_identifiable(EffectId::SensorNoise).is_some(),
            "no repeats"
        );
        assert!(
            d.not_identifiable(EffectId::StageError).is_some(),
            "no repeatability"
        );
        let c = d.confounded(&[EffectId::LensDistortion, EffectId::Scale]);
        assert_eq!(c.len(), 1);
        assert_eq!(c[0].separate_with, SEVERAL_SIZES);
    }

    /// Moves of three sizes along x, and three sub-pixel steps along each axis (0.2, 0.4, 0.6 px
    /// at 26 px/mm), mm.
    fn sizes_and_step_series() -> Vec<(f64, f64)> {
        let mut moves = vec![(1.25, 0.0), (2.5, 0.0), (5.0, 0.0)];
        for k in 1..=3 {
            let mm = 0.2 * k as f64 / 26.0;
            moves.push((mm, 0.0));
            moves.push((0.0, mm));
        }
        moves
    }

    #[test]
    fn moves_of_several_sizes_and_a_step_series_separate_what_one_move_cannot() {
        let moves = sizes_and_step_series();
        let d = design_of(&manifest(&moves, &["a"], PrintStated::Characterised), 2560);
        assert_eq!((d.subpixel_steps_x, d.subpixel_steps_y), (3, 3));
        assert_eq!(d.move_sizes_px.len(), 6, "{:?}", d.move_sizes_px);
        assert!(d.not_identifiable(EffectId::PsfBlur).is_none());
        let all = [
            EffectId::LensDistortion,
            EffectId::Scale,
            EffectId::FillFactor,
            EffectId::PsfBlur,
        ];
        assert!(d.confounded(&all).is_empty(), "{:?}", d.confounded(&all));
        // Two steps along y are not a series: aperture and blur stay confounded.
        let fewer: Vec<_> = moves.iter().copied().take(moves.len() - 1).collect();
        let c =
            design_of(&manifest(&fewer, &["a"], PrintStated::Characterised), 2560).confounded(&all);
        assert_eq!(c.len(), 1);
        assert_eq!(c[0].separate_with, STEP_SERIES);
    }

    #[test]
    fn a_print_calibrated_from_the_frames_leaves_blur_and_aperture_unfitted() {
        // The dots' size and spacing stated, their profile and contrast not: the print is
        // calibrated, and absorbs whatever blurs it, whatever the runs.
        let moves = sizes_and_step_series();
        let calibrated = design_of(&manifest(&moves, &["a"], PrintStated::DotSize), 2560);
        assert!(calibrated.dot_size_known && !calibrated.print_characterised);
        for effect in [EffectId::PsfBlur, EffectId::FillFactor] {
            let n = calibrated
                .not_identifiable(effect)
                .expect("not identifiable");
            assert_eq!(n.runs_to_add, PRINT_SEPARATION, "{effect}");
        }
        // Without the dot size the blur says what it lacks first.
        let bare = design_of(&manifest(&moves, &["a"], PrintStated::Nothing), 2560);
        assert!(bare
            .not_identifiable(EffectId::PsfBlur)
            .unwrap()
            .reason
            .contains("dot size"));
        assert_eq!(
            bare.not_identifiable(EffectId::FillFactor)
                .unwrap()
                .runs_to_add,
            PRINT_SEPARATION
        );
        // Characterised: both fitted.
        let stated = design_of(&manifest(&moves, &["a"], PrintStated::Characterised), 2560);
        assert!(stated.print_characterised);
        assert!(stated.not_identifiable(EffectId::PsfBlur).is_none());
        assert!(stated.not_identifiable(EffectId::FillFactor).is_none());
    }

    #[test]
    fn a_static_dataset_reveals_no_motion_effect() {
        let d = design_of(
            &manifest(
                &[(0.0, 0.0), (0.0, 0.0)],
                &["a"],
                PrintStated::Characterised,
            ),
            2560,
        );
        assert_eq!(d.moved_runs, 0);
        for effect in [
            EffectId::Rotation,
            EffectId::Scale,
            EffectId::TargetTilt,
            EffectId::MotionBlur,
            EffectId::LensDistortion,
        ] {
            assert!(d.not_identifiable(effect).is_some(), "{effect}");
        }
        assert!(d.not_identifiable(EffectId::Vignetting).is_none());
    }
}
