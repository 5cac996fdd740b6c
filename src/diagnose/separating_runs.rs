//! What a bench can capture to resolve what a diagnosis left open (issue 33, "resolve confounds
//! on the bench"): each pair the design confounds and each effect the dataset cannot reveal,
//! mapped to the kind of runs that separate it. `identifiability.rs` says why in words; this is
//! the same knowledge as a vocabulary a bench's plan is built from. What no stage move can
//! supply (a characterised print, a stated repeatability, flat fields) maps to nothing.

use super::geometric::Geometric;
use super::identifiability::{Confounded, NotIdentifiable};
use super::Diagnosis;
use crate::model::EffectId;
use serde::{Deserialize, Serialize};

/// A kind of run a bench captures to separate effects.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SeparatingRuns {
    /// Translations of several sizes: distortion's field grows with the move, a scale change's
    /// does not.
    SeveralMoveSizes,
    /// Translations along x and along y: a rotation's and a tilt's fields differ from the
    /// others' by direction.
    BothAxes,
    /// A sub-pixel step series along each axis: the pixel aperture and the lens blur change the
    /// random error differently with the sub-pixel phase.
    StepSeries,
    /// Static repeat frames of the reference position: the sensor's noise against the mean.
    StaticRepeats,
}

impl SeparatingRuns {
    /// The runs in words.
    pub fn describe(self) -> &'static str {
        match self {
            SeparatingRuns::SeveralMoveSizes => "moves of several sizes",
            SeparatingRuns::BothAxes => "moves along x and along y",
            SeparatingRuns::StepSeries => "a sub-pixel step series",
            SeparatingRuns::StaticRepeats => "static repeat frames",
        }
    }
}

/// The runs that would resolve the design confounds of `rounds` (a diagnosis's rounds) and the
/// effects they could not reveal, each kind once, in the enum's order.
pub fn runs_to_separate(rounds: &[Diagnosis]) -> Vec<SeparatingRuns> {
    let (confounded, not_identifiable) = open_questions(rounds);
    runs_for(&confounded, &not_identifiable)
}

/// What `rounds` left open, each once in the order first met: the confounded pairs and the
/// effects the dataset cannot reveal. A later round's model holds an earlier verdict, so its
/// candidates no longer show that verdict's confounds: every round's are kept.
pub fn open_questions(rounds: &[Diagnosis]) -> (Vec<Confounded>, Vec<NotIdentifiable>) {
    let mut confounded: Vec<Confounded> = Vec::new();
    let mut not_identifiable: Vec<NotIdentifiable> = Vec::new();
    for d in rounds {
        for c in &d.confounded {
            if !confounded.contains(c) {
                confounded.push(c.clone());
            }
        }
        for n in &d.not_identifiable {
            if !not_identifiable.iter().any(|m| m.effect == n.effect) {
                not_identifiable.push(n.clone());
            }
        }
    }
    (confounded, not_identifiable)
}

/// [`runs_to_separate`] of a diagnosis's confounded pairs and not-identifiable effects.
fn runs_for(
    confounded: &[Confounded],
    not_identifiable: &[NotIdentifiable],
) -> Vec<SeparatingRuns> {
    let mut runs: Vec<SeparatingRuns> = confounded
        .iter()
        // Two geometric fields the data could not tell apart: other moves make them differ
        // (`move_design.rs` chooses them).
        .filter(|c| c.evidence == "design" || Geometric::pair_of(c).is_some())
        .flat_map(for_confounded)
        .chain(not_identifiable.iter().flat_map(for_not_identifiable))
        .collect();
    runs.sort();
    runs.dedup();
    runs
}

/// The runs that separate a confounded pair (empty when one side is not a catalogue effect a
/// move can tell apart: the print, the illumination).
fn for_confounded(c: &Confounded) -> Vec<SeparatingRuns> {
    let [Ok(a), Ok(b)] = c.effects.each_ref().map(|e| e.parse::<EffectId>()) else {
        return Vec::new();
    };
    let mut runs = Vec::new();
    for e in [a, b] {
        runs.extend(for_effect(e));
    }
    runs
}

/// The runs that reveal an effect the dataset could not (none for what needs more than moves).
fn for_not_identifiable(n: &NotIdentifiable) -> Vec<SeparatingRuns> {
    use EffectId::*;
    match n.effect {
        // What the blur and the aperture lack is knowledge of the print (its dot size, or the
        // print characterised: `identifiability.rs`), which no run of the same print supplies:
        // a step series separates them from each other, not from a print calibrated to the
        // frames.
        PsfBlur | FillFactor => Vec::new(),
        LensDistortion | Scale | Rotation | TargetTilt | SensorNoise | IlluminationChange
        | MotionBlur | StageError | StageMisalignment | FixedPattern | Quantization
        | Vignetting => for_effect(n.effect),
    }
}

/// The runs whose variation an effect's signature needs.
fn for_effect(effect: EffectId) -> Vec<SeparatingRuns> {
    use EffectId::*;
    use SeparatingRuns::*;
    match effect {
        LensDistortion | Scale => vec![SeveralMoveSizes],
        Rotation | TargetTilt => vec![BothAxes, SeveralMoveSizes],
        PsfBlur | FillFactor => vec![StepSeries],
        SensorNoise => vec![StaticRepeats],
        IlluminationChange | MotionBlur => vec![SeveralMoveSizes],
        // A stated repeatability, flat fields, the ADC, a vignetting against an illumination
        // change (large moves of a uniform target): nothing a speckle run adds.
        StageError | StageMisalignment | FixedPattern | Quantization | Vignetting => Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::identifiability::design_of;
    use crate::diagnose::test_fields::{manifest, PrintStated};

    fn confounded(a: &str, b: &str, evidence: &str) -> Confounded {
        Confounded {
            effects: [a.into(), b.into()],
            separate_with: String::new(),
            evidence: evidence.into(),
        }
    }

    /// The paper's design (one 5 mm move, no repeats, no step series): the bench adds moves of
    /// several sizes for distortion against scale, a step series for the aperture against the
    /// blur, static frames for the noise; a print the dataset does not characterise adds
    /// nothing, and a data confound is the bench's only between two geometric fields.
    #[test]
    fn each_open_question_asks_for_its_runs() {
        let design = design_of(&manifest(&[(5.0, 0.0)], &["a"], PrintStated::Nothing), 2560);
        let mut pairs = design.confounded(&[
            EffectId::LensDistortion,
            EffectId::Scale,
            EffectId::FillFactor,
            EffectId::PsfBlur,
        ]);
        pairs.push(confounded("psf_blur", "print", "design"));
        pairs.push(confounded("fill_factor", "vignetting", "data"));
        let not_identifiable: Vec<NotIdentifiable> = [
            EffectId::SensorNoise,
            EffectId::StageError,
            EffectId::PsfBlur,
            EffectId::FillFactor,
        ]
        .into_iter()
        .filter_map(|e| design.not_identifiable(e))
        .collect();
        assert_eq!(not_identifiable.len(), 4);
        // The print not characterised: neither blur nor aperture asks for a step series.
        assert!(runs_for(&[], &not_identifiable[2..]).is_empty());
        assert_eq!(
            runs_for(&pairs, &not_identifiable),
            vec![
                SeparatingRuns::SeveralMoveSizes,
                SeparatingRuns::StepSeries,
                SeparatingRuns::StaticRepeats
            ]
        );
        // Nothing open: nothing for the bench.
        assert!(runs_for(&[], &[]).is_empty());
        // Two geometric fields the data could not tell apart: other moves can.
        assert_eq!(
            runs_for(&[confounded("rotation", "target_tilt", "data")], &[]),
            vec![SeparatingRuns::SeveralMoveSizes, SeparatingRuns::BothAxes]
        );
    }
}
