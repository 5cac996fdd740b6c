//! Several effects at once: diagnose, add the winner, diagnose again, until the verdict is `none`
//! or the rounds run out; what the final model leaves unexplained is reported either way. Each
//! round starts from the comparison the previous one made with its
//! winner added, so the fall of the discrepancy is a chain of comparisons on the same
//! measurement. The earlier rounds' geometric verdicts are fitted again beside each later
//! geometric candidate (`fit_geometric_effect`): the rounds are stepwise regression with
//! re-estimation, not a greedy sequence that keeps what its first verdict absorbed.

use super::compare::compare_prepared;
use super::diagnose::diagnose_prepared;
use super::measurement::{load_measurement, Measurement};
use super::separating_runs::{runs_to_separate, SeparatingRuns};
use super::unexplained::Unexplained;
use super::verdict::Diagnosis;
use super::{CompareOptions, DiagnoseError, Progress};
use crate::model::ModelConfig;
use crate::model::{CandidateId, EffectId};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// The most rounds one diagnosis may run (each is a full diagnosis).
pub const MAX_ROUNDS: usize = 8;

/// One round: the verdict, its fitted parameters, and the discrepancy of the model entering the
/// round (with its standard error) and with the verdict added.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Round {
    /// `"none"` on the wire when the round found nothing.
    #[serde(with = "crate::model::effects::verdict_serde")]
    pub verdict: Option<CandidateId>,
    pub params: BTreeMap<String, f64>,
    pub stderr: BTreeMap<String, f64>,
    /// What follows from the parameters and how to read them (a tilt's working distance,
    /// stated or assumed).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub derived: BTreeMap<String, f64>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
    /// The model this round diagnosed.
    pub model: String,
    pub discrepancy_px: f64,
    pub discrepancy_se_px: f64,
    /// With the verdict added (none when the verdict is `none`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub after_px: Option<f64>,
    /// The model entering the round leaves something significant unexplained.
    pub unexplained: bool,
    /// The verdict explains only part of it.
    pub partial: bool,
    /// The nearest catalogue effect, not named (see `Diagnosis::withheld`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub withheld: Option<CandidateId>,
}

/// Every round; `diagnoses[k]` is round k's full diagnosis.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Rounds {
    pub rounds: Vec<Round>,
    /// The verdicts other than `none`, in the order found.
    pub verdicts: Vec<CandidateId>,
    /// The discrepancy of the final model (every verdict added), px.
    pub final_discrepancy_px: f64,
    /// What the final model leaves unexplained: never `none` silently over a significant
    /// residual.
    pub final_unexplained: Unexplained,
    /// What a bench's runs would resolve of what the rounds left open (their design's
    /// confounds, the effects the dataset cannot reveal; every round's: a verdict chosen under a
    /// confound is itself in question): `ffdic diagnose --on-bench` and
    /// `POST /datasets/{id}/on-bench` capture them.
    #[serde(default)]
    pub runs_to_separate: Vec<SeparatingRuns>,
    /// The model with every verdict added.
    #[serde(skip)]
    pub final_model: ModelConfig,
    #[serde(skip)]
    pub diagnoses: Vec<Diagnosis>,
}

impl Rounds {
    /// The first round's diagnosis as JSON (the fields a one-round diagnosis has always had) with
    /// `rounds`, `verdicts` and `final_discrepancy_px` beside them.
    pub fn to_json(&self) -> serde_json::Value {
        let mut v = self.diagnoses.first().map_or(serde_json::Value::Null, |d| {
            serde_json::to_value(d).unwrap_or_default()
        });
        if let (Some(obj), Ok(serde_json::Value::Object(extra))) =
            (v.as_object_mut(), serde_json::to_value(self))
        {
            obj.extend(extra);
        }
        v
    }
}

/// Reads the dataset in `dir` and runs up to `rounds` rounds on it.
pub fn diagnose_rounds(
    dir: &Path,
    model: &ModelConfig,
    options: &CompareOptions,
    rounds: usize,
    progress: Progress,
) -> Result<Rounds, DiagnoseError> {
    let meas = load_measurement(dir, options, &|_, _| progress(0, 1))?;
    diagnose_rounds_prepared(&meas, model, rounds, progress)
}

/// Up to `rounds` (1..=[`MAX_ROUNDS`]) rounds on an analysed measurement. `progress` counts the
/// candidate fits of the current round.
pub fn diagnose_rounds_prepared(
    meas: &Measurement,
    model: &ModelConfig,
    rounds: usize,
    progress: Progress,
) -> Result<Rounds, DiagnoseError> {
    let rounds = rounds.clamp(1, MAX_ROUNDS);
    let mut current = model.clone();
    let mut before = Some(compare_prepared(meas, &current, &|_, _| progress(0, 1))?);
    let mut out = Vec::new();
    let mut verdicts = Vec::new();
    let mut diagnoses: Vec<Diagnosis> = Vec::new();
    for _ in 0..rounds {
        // The earlier rounds' geometric verdicts are re-estimated beside each geometric
        // candidate: a verdict gives back what a later effect explains better.
        let refit: Vec<EffectId> = verdicts.iter().filter_map(CandidateId::catalogue).collect();
        let d = diagnose_prepared(meas, &current, before.take(), &refit, progress)?;
        let winner = d
            .candidates
            .iter()
            .find(|c| Some(&c.effect) == d.verdict.as_ref());
        out.push(Round {
            verdict: d.verdict.clone(),
            params: winner.map(|c| c.params.clone()).unwrap_or_default(),
            stderr: winner.map(|c| c.stderr.clone()).unwrap_or_default(),
            derived: winner.map(|c| c.derived.clone()).unwrap_or_default(),
            notes: winner.map(|c| c.notes.clone()).unwrap_or_default(),
            model: current.name.clone(),
            discrepancy_px: d.discrepancy_px,
            discrepancy_se_px: d.discrepancy_se_px,
            after_px: d.after.as_ref().map(|a| a.discrepancy_px),
            unexplained: d.unexplained.significant,
            partial: d.partial,
            withheld: d.withheld.as_ref().map(|w| w.effect.clone()),
        });
        let next = d.winner_model.clone();
        before = d.after.clone();
        diagnoses.push(d);
        match (next, out.last().and_then(|r| r.verdict.clone())) {
            (Some(m), Some(verdict)) => {
                verdicts.push(verdict);
                current = m;
            }
            _ => break,
        }
    }
    let last = diagnoses.last().expect("at least one round");
    let final_discrepancy_px = out
        .last()
        .and_then(|r| r.after_px)
        .unwrap_or(last.discrepancy_px);
    // `unexplained_after` exists exactly when the last round named a verdict.
    let final_unexplained = last
        .unexplained_after
        .clone()
        .unwrap_or_else(|| last.unexplained.clone());
    Ok(Rounds {
        rounds: out,
        verdicts,
        final_discrepancy_px,
        final_unexplained,
        runs_to_separate: runs_to_separate(&diagnoses),
        final_model: current,
        diagnoses,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::test_fields::{candidate, comparison, diagnosis, finding};

    /// A round with `verdict` on a model at `discrepancy_px`, `after_px` with it.
    fn round(verdict: Option<EffectId>, discrepancy_px: f64, after_px: Option<f64>) -> Round {
        Round {
            verdict: verdict.map(CandidateId::from),
            params: BTreeMap::new(),
            stderr: BTreeMap::new(),
            derived: BTreeMap::new(),
            notes: Vec::new(),
            model: "baseline".into(),
            discrepancy_px,
            discrepancy_se_px: 0.0002,
            after_px,
            unexplained: true,
            partial: false,
            withheld: None,
        }
    }

    #[test]
    fn the_json_is_the_first_rounds_diagnosis_with_the_rounds_beside_it() {
        // Round 1 names rotation (0.02 → 0.005 px), round 2 nothing.
        let mut before = comparison(Vec::new());
        before.discrepancy_px = 0.02;
        let rotation = candidate(
            EffectId::Rotation,
            &[("angle_rad", 1e-4, 1e-6)],
            -80.0,
            0.015,
        );
        let first = diagnosis(&before, vec![rotation], Some(EffectId::Rotation.into()));
        before.discrepancy_px = 0.005;
        let second = diagnosis(&before, Vec::new(), None);
        let rounds = Rounds {
            rounds: vec![
                round(Some(EffectId::Rotation), 0.02, Some(0.005)),
                round(None, 0.005, None),
            ],
            verdicts: vec![EffectId::Rotation.into()],
            final_discrepancy_px: 0.005,
            final_unexplained: finding(0.005, Some(1.2)),
            runs_to_separate: Vec::new(),
            final_model: ModelConfig::default(),
            diagnoses: vec![first, second],
        };
        let j = rounds.to_json();
        // The first round's diagnosis…
        assert_eq!(j["verdict"], "rotation");
        assert_eq!(j["discrepancy_px"], 0.02);
        assert_eq!(j["candidates"][0]["effect"], "rotation");
        // …and the rounds.
        assert_eq!(j["verdicts"], serde_json::json!(["rotation"]));
        assert_eq!(j["final_discrepancy_px"], 0.005);
        assert_eq!(j["final_unexplained"]["field_f"], 1.2);
        assert_eq!(j["rounds"].as_array().map(Vec::len), Some(2));
        assert_eq!(j["rounds"][0]["after_px"], 0.005);
        assert_eq!(j["rounds"][1]["verdict"], "none");
        assert!(j["rounds"][1].get("after_px").is_none());
        // A round reads back as it was written, `none` as no verdict.
        let back: Round = serde_json::from_value(j["rounds"][1].clone()).unwrap();
        assert_eq!(back, rounds.rounds[1]);
    }
}
