//! `diagnose`: for every catalogue effect the model lacks, fit its parameters, recompute the
//! discrepancy with it added, and rank the candidates by ΔBIC and by the drop of the
//! discrepancy. Geometric effects are fitted by weighted linear least squares on displacement
//! basis fields stacked over every run and scheme ([`super::fit_geometric`]); image-level ones by
//! simulation fits with fixed seeds or closed forms on image statistics ([`super::fit_image`]).
//!
//! A candidate is significant when its ΔBIC is below −10 and a fitted parameter lies more than two
//! standard errors from "no effect". The verdict is the significant candidate with the most
//! negative ΔBIC (Schwarz's criterion decides; the drop of the discrepancy is reported beside it,
//! because an image-level effect can be certain from the image statistics while the displacement
//! discrepancy stays at its floor), `none` when no candidate is significant — or when the winner
//! explains under 90 % of the model's unexplained low-order field and no other geometric effect
//! explains the rest (`withheld`: the nearest catalogue name for something outside it).
//!
//! A candidate whose parameter is within two standard errors of no effect is not re-rendered:
//! adding nothing changes nothing, so its discrepancy is the model's and its ΔBIC the bare
//! parameter penalty k·ln n (`recomputed` false); nor is one the criteria that do not read its
//! comparison already exclude (at its range's bound, or confounded with the light by the
//! design: `Method::Excluded`). Effects the dataset cannot reveal (blur and aperture against a
//! print calibrated from the frames among them) are listed with what would reveal them, not
//! fitted; pairs that explain the same residual are named with the run that would separate them.

use super::calibrate_scene::SceneFrom;
use super::candidates::{
    candidates_to_fit, field_samples, fit_one_candidate, geometric_candidate, in_lanes,
    judge_candidates, predict, render_winner, FittedModels, UnjudgedFit,
};
use super::compare::{compare_prepared, compare_with_scene};
use super::fit_user_effect::fit_user_effect;
pub use super::identifiability::Confounded;
use super::identifiability::{design_of, separating_run, DatasetDesign};
use super::measurement::{load_measurement, Measurement};
use super::results::Comparison;
use super::unexplained::{model_scatter, unexplained, ModelScatter, Unexplained};
use super::verdict::{
    Candidate, DesignRules, Diagnosis, Judge, Withheld, ILLUMINATION_SEPARATION,
    MIN_EXPLAINED_FRACTION,
};
use super::{CompareOptions, DiagnoseError, Progress};
use crate::model::{CandidateId, EffectId, ModelConfig};
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Reads the dataset in `dir` and diagnoses `model` against it.
pub fn diagnose(
    dir: &Path,
    model: &ModelConfig,
    options: &CompareOptions,
    progress: Progress,
) -> Result<Diagnosis, DiagnoseError> {
    let meas = load_measurement(dir, options, &|_, _| progress(0, 1))?;
    diagnose_prepared(&meas, model, None, &[], progress)
}

/// Renderings of the model (the comparison's seed and the next ones) whose scatter of the
/// discrepancy is part of its standard error: a model disagrees with one realisation of its own
/// speckle and noise by chance, and differently with the next.
pub const MODEL_SEEDS: u64 = 2;

/// Diagnoses `model` against an analysed measurement; `before` is the model's comparison when
/// already made; `refit`, the geometric effects of `model` re-estimated beside each geometric
/// candidate (the earlier rounds' verdicts; see `fit_geometric_effect`). `progress` counts
/// candidates.
pub fn diagnose_prepared(
    meas: &Measurement,
    model: &ModelConfig,
    before: Option<Comparison>,
    refit: &[EffectId],
    progress: Progress,
) -> Result<Diagnosis, DiagnoseError> {
    let _span = tracing::debug_span!("round", model = %model.name).entered();
    let before = match before {
        Some(b) => b,
        None => compare_prepared(meas, model, &|_, _| progress(0, 1))?,
    };
    let design = design_of(&meas.manifest, meas.width);
    let (fit_ids, not_identifiable) = candidates_to_fit(model, &design);
    let total = fit_ids.len() + MODEL_SEEDS as usize - 1;
    let done = AtomicUsize::new(0);
    let tick = || {
        let n = done.fetch_add(1, Ordering::Relaxed) + 1;
        if progress(n, total) {
            Ok(())
        } else {
            Err(DiagnoseError::Cancelled)
        }
    };
    // Asks, without a step done, whether to go on: inside each comparison, before every point.
    let ask = |_: usize, _: usize| progress(done.load(Ordering::Relaxed), total);
    let rules = DesignRules::of(&design);
    let (by_seed, scatter, fitted) = seeds_and_candidates(
        meas,
        (model, refit),
        (&before, rules),
        &fit_ids,
        (&tick, &ask),
    )?;
    let seed_sd = {
        let n = by_seed.len() as f64;
        let m = by_seed.iter().sum::<f64>() / n;
        (by_seed.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
    };
    let se_before = before.discrepancy_se_px.max(seed_sd);
    let judge = Judge {
        before: &before,
        se_before,
        seed_sd,
        rules,
        dic: &meas.options.dic,
    };
    let (mut candidates, mut models) = judge_candidates(&judge, fitted);
    candidates.sort_by(|a, b| a.delta_bic.total_cmp(&b.delta_bic));
    let winner = render_winner(meas, &judge, &mut candidates, &mut models, &ask)?;
    candidates.sort_by(|a, b| a.delta_bic.total_cmp(&b.delta_bic));
    let mut by_drop: Vec<&Candidate> = candidates.iter().collect();
    by_drop.sort_by(|a, b| b.drop_px.total_cmp(&a.drop_px));
    let ranking_by_drop = by_drop.iter().map(|c| c.effect.clone()).collect();
    let settling = tracing::debug_span!("settle").entered();
    let left = settle(
        meas,
        winner,
        &mut models,
        &before,
        &scatter,
        (se_before, seed_sd),
    );
    if let Some(w) = &left.withheld {
        for c in candidates.iter_mut().filter(|c| c.effect == w.effect) {
            c.criteria.explains_its_signature = false;
            c.significant = false;
        }
    }
    drop(settling);
    let confounded = confounded_pairs(&design, &candidates, left.winner.clone(), rules);
    Ok(Diagnosis {
        model: before.model.clone(),
        discrepancy_px: before.discrepancy_px,
        discrepancy_se_px: se_before,
        discrepancy_by_seed_px: by_seed,
        candidates,
        ranking_by_drop,
        verdict: left.winner,
        confounded,
        not_identifiable,
        partial: left
            .after
            .as_ref()
            .is_some_and(Unexplained::field_significant),
        explained_fraction: left.explained_fraction,
        unexplained: left.before,
        unexplained_after: left.after,
        withheld: left.withheld,
        winner_model: left.winner_model,
        before: Some(before),
        after: left.after_comparison,
    })
}

/// The verdict held against what it leaves (module doc of `unexplained`).
struct Settled {
    winner: Option<CandidateId>,
    winner_model: Option<ModelConfig>,
    after_comparison: Option<Comparison>,
    before: Unexplained,
    after: Option<Unexplained>,
    explained_fraction: Option<f64>,
    withheld: Option<Withheld>,
}

/// What the model and the model with the winner leave unexplained; the winner withheld when it
/// explains less than [`MIN_EXPLAINED_FRACTION`] of a significant residual and no other
/// catalogue effect explains the rest. `se` is the model's discrepancy SE and the seed scatter.
fn settle(
    meas: &Measurement,
    winner: Option<CandidateId>,
    models: &mut FittedModels,
    before: &Comparison,
    scatter: &ModelScatter,
    (se_before, seed_sd): (f64, f64),
) -> Settled {
    let infl = super::bic::inflation(&meas.options.dic);
    let schemes = &meas.options.schemes;
    let w0 = scatter.field_w;
    let left_before = unexplained(before, schemes, scatter, se_before, infl);
    let (winner_model, after) = match winner.as_ref().and_then(|w| models.remove(w)) {
        Some((_, m, a)) => (Some(m), a),
        None => (None, None),
    };
    let left_after = after.as_ref().map(|a| {
        let se = a.discrepancy_se_px.max(seed_sd);
        unexplained(a, schemes, scatter, se, infl)
    });
    let explained_fraction = left_after.as_ref().and_then(|a| explained(&left_before, a));
    let settled = Settled {
        winner,
        winner_model,
        after_comparison: after,
        before: left_before,
        after: left_after,
        explained_fraction,
        withheld: None,
    };
    let (Some(w), Some(left), Some(fraction), Some(after), Some(with)) = (
        settled.winner.clone(),
        &settled.after,
        explained_fraction,
        &settled.after_comparison,
        &settled.winner_model,
    ) else {
        return settled;
    };
    // Only the field test speaks to the verdict's signature: a rigid part or the stage's
    // plausibility is another finding.
    if !(left.field_significant()
        && fraction < MIN_EXPLAINED_FRACTION
        && !rest_has_a_name(meas, after, with, w0, infl))
    {
        return settled;
    }
    Settled {
        winner: None,
        winner_model: None,
        after_comparison: None,
        after: None,
        explained_fraction: None,
        withheld: Some(Withheld {
            reason: format!(
                "{w} explains {:.0} % of the low-order field the model leaves, and no geometric catalogue effect or proposed user effect explains the rest: its signature is not what the data show (see unexplained)",
                100.0 * fraction
            ),
            effect: w,
            explained_fraction: fraction,
        }),
        ..settled
    }
}

/// The share of the model's excess low-order field (F above 1) that is gone after the verdict.
fn explained(before: &Unexplained, after: &Unexplained) -> Option<f64> {
    let (fb, fa) = (before.field_f?, after.field_f?);
    (fb > 1.0).then(|| ((fb - fa) / (fb - 1.0)).clamp(0.0, 1.0))
}

/// Whether another geometric catalogue effect or one of the model's proposed user effects,
/// fitted on what the winner leaves (`after`, the comparison of `with`, the model with the
/// winner), explains at least half of it: then the winner is one of several effects (the next
/// round finds the next), not the nearest name for something outside the catalogue. A user's
/// effect counts as a catalogue's does: it is what the user said may be there.
fn rest_has_a_name(
    meas: &Measurement,
    after: &Comparison,
    with: &ModelConfig,
    w0: Option<f64>,
    infl: f64,
) -> bool {
    let floor = w0.unwrap_or(0.0);
    let excess = super::unexplained::field_w(after, infl) - floor;
    if !(excess > 0.0) {
        // Nothing beyond the model's own scatter is left for another effect to explain.
        return true;
    }
    let catalogue = EffectId::ALL
        .into_iter()
        .filter(|id| !with.effects.has(*id))
        .filter_map(|id| geometric_candidate(meas, after, &with.effects, id, &[]));
    let proposed: Vec<&String> = with.effects.proposed_user().collect();
    let fields = (!proposed.is_empty()).then(|| field_samples(meas, after));
    let user = proposed.into_iter().filter_map(|name| {
        let (samples, setting) = fields.as_ref()?;
        fit_user_effect(samples, setting, &with.effects, (name, &[]))
    });
    catalogue
        .chain(user)
        .filter(|fit| fit.beyond_null)
        .any(|fit| {
            let next = ModelConfig {
                effects: fit.effects.clone(),
                ..with.clone()
            };
            predict(meas, after, &next, &fit)
                .is_some_and(|c| super::unexplained::field_w(&c, infl) - floor < 0.5 * excess)
        })
}

/// The model's discrepancy under each of its seeds (the first is `before`'s), its own scatter
/// between the first two, and the candidates' fits, not yet judged. The comparisons under the
/// other seeds and the fits are independent: they share the lanes, the seeds first (each a
/// whole comparison; the candidates' fits and renderings then fill both lanes), and the
/// candidates are judged once the seeds' scatter is known. Before, the seeds ran alone first
/// (on a paper-size round ≈ 2.8 s at a core and a half).
fn seeds_and_candidates(
    meas: &Measurement,
    (model, refit): (&ModelConfig, &[EffectId]),
    (before, rules): (&Comparison, DesignRules),
    fit_ids: &[CandidateId],
    (tick, ask): (&(dyn Fn() -> Result<(), DiagnoseError> + Sync), Progress),
) -> Result<(Vec<f64>, ModelScatter, Vec<UnjudgedFit>), DiagnoseError> {
    let jobs: Vec<RoundJob> = (1..MODEL_SEEDS)
        .map(RoundJob::Seed)
        .chain(fit_ids.iter().map(RoundJob::Candidate))
        .collect();
    let run = |job: &RoundJob| match *job {
        RoundJob::Seed(k) => {
            seed_discrepancy(meas, model, before, k, ask).map(|(d, s)| RoundDone::Seed(d, s))
        }
        RoundJob::Candidate(id) => {
            fit_one_candidate(meas, (model, refit), (before, rules), id, ask)
                .map(|f| RoundDone::Candidate(f.map(Box::new)))
        }
    };
    let mut by_seed = vec![before.discrepancy_px];
    let mut scatter = ModelScatter::default();
    let mut fitted = Vec::new();
    for done in in_lanes(&jobs, &run, tick)? {
        match done {
            RoundDone::Seed(d, s) => {
                by_seed.push(d);
                scatter = s.unwrap_or(scatter);
            }
            RoundDone::Candidate(f) => fitted.extend(f.map(|f| *f)),
        }
    }
    Ok((by_seed, scatter, fitted))
}

/// One job of a round's lanes: the model's comparison under model seed `k` (of
/// [`MODEL_SEEDS`]; the first is `before`'s), or a candidate's fit.
enum RoundJob<'a> {
    Seed(u64),
    Candidate(&'a CandidateId),
}

/// What a [`RoundJob`] gives.
enum RoundDone {
    /// The discrepancy under the seed, and for the second seed the model's own scatter.
    Seed(f64, Option<ModelScatter>),
    /// Boxed: a fit and its comparison are some 2 kB against the seed's 40 bytes.
    Candidate(Option<Box<UnjudgedFit>>),
}

/// The discrepancy with model seed `k` (≥ 1; the first is `before`'s): the seeds' scatter is
/// part of the discrepancy's standard error. For `k` = 1 also the model's own scatter of the
/// low-order field and light change between the first two renderings ([`model_scatter`]).
fn seed_discrepancy(
    meas: &Measurement,
    model: &ModelConfig,
    before: &Comparison,
    k: u64,
    ask: Progress,
) -> Result<(f64, Option<ModelScatter>), DiagnoseError> {
    let c = compare_with_scene(
        meas,
        model,
        meas.options.seed.wrapping_add(k),
        SceneFrom::Reuse(&before.model.nominal),
        ask,
    )?;
    let infl = super::bic::inflation(&meas.options.dic);
    let scatter = (k == 1).then(|| model_scatter(before, &c, infl));
    Ok((c.discrepancy_px, scatter))
}

/// Effects the fits cannot tell apart: by the dataset's design (vignetting against
/// illumination on small moves, blur against aperture without a step series), and by the data
/// (a second significant candidate explaining nearly as much as the winner).
fn confounded_pairs(
    design: &DatasetDesign,
    candidates: &[Candidate],
    winner: Option<CandidateId>,
    rules: DesignRules,
) -> Vec<Confounded> {
    let fitted: Vec<EffectId> = candidates
        .iter()
        .filter_map(|c| c.effect.catalogue())
        .collect();
    let mut confounded = design.confounded(&fitted);
    if fitted.contains(&EffectId::Vignetting) && rules.small_moves {
        confounded.push(Confounded {
            effects: [EffectId::Vignetting.as_str().into(), "illumination".into()],
            separate_with: ILLUMINATION_SEPARATION.into(),
            evidence: "design".into(),
        });
    }
    let Some(w) = winner else {
        return confounded;
    };
    let top = candidates
        .iter()
        .find(|c| c.effect == w)
        .expect("winner is a candidate");
    for c in candidates.iter().filter(|c| c.significant && c.effect != w) {
        let names = super::identifiability::pair(&w, &c.effect);
        let already = confounded
            .iter()
            .any(|p| p.effects.contains(&names[0]) && p.effects.contains(&names[1]));
        if !already && top.drop_px > 0.0 && c.drop_px >= 0.8 * top.drop_px {
            confounded.push(Confounded {
                effects: names,
                separate_with: separating_run(&w, &c.effect),
                evidence: "data".into(),
            });
        }
    }
    confounded
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::identifiability::{SEVERAL_SIZES, STEP_SERIES};
    use crate::diagnose::test_fields::{candidate, finding, manifest, PrintStated};

    #[test]
    fn the_share_explained_is_of_the_field_beyond_the_noise() {
        // F = 5 before, 2 after: of the excess 5 − 1, 5 − 2 is gone, 0.75.
        let share = |b, a| explained(&finding(0.01, b), &finding(0.01, a));
        assert!((share(Some(5.0), Some(2.0)).unwrap() - 0.75).abs() < 1e-12);
        // Down to the noise or below: all of it; worse: none.
        assert_eq!(share(Some(5.0), Some(0.5)), Some(1.0));
        assert_eq!(share(Some(5.0), Some(7.0)), Some(0.0));
        // Nothing beyond the noise before, or a side without the field test: no share.
        assert_eq!(share(Some(0.9), Some(0.5)), None);
        assert_eq!(share(None, Some(0.5)), None);
        assert_eq!(share(Some(5.0), None), None);
    }

    proptest::proptest! {
        /// The share lies in [0, 1] and falls as more is left after.
        #[test]
        fn the_share_falls_with_what_is_left(
            before in 1.01f64..100.0,
            a in 0.0f64..120.0,
            b in 0.0f64..120.0,
        ) {
            let share = |after: f64| {
                explained(&finding(0.01, Some(before)), &finding(0.01, Some(after))).unwrap()
            };
            let (less, more) = (a.min(b), a.max(b));
            proptest::prop_assert!((0.0..=1.0).contains(&share(less)));
            proptest::prop_assert!(share(less) >= share(more));
        }
    }

    /// The pairs' names.
    fn names(pairs: &[Confounded]) -> Vec<[&str; 2]> {
        pairs
            .iter()
            .map(|c| [c.effects[0].as_str(), c.effects[1].as_str()])
            .collect()
    }

    #[test]
    fn small_moves_and_one_move_size_confound_by_design() {
        // One 1 mm move: 26 px of a 2560 px frame, 1 % of the field (vignetting needs 5 %);
        // no step series (blur against aperture); the print characterised.
        let design = design_of(
            &manifest(&[(1.0, 0.0)], &["a"], PrintStated::Characterised),
            2560,
        );
        let candidates = vec![
            candidate(EffectId::Vignetting, &[("strength", 0.3, 0.02)], -20.0, 0.0),
            candidate(EffectId::PsfBlur, &[("sigma_px", 0.8, 0.05)], -15.0, 0.0),
            candidate(EffectId::FillFactor, &[("fx", 0.5, 0.05)], -12.0, 0.0),
        ];
        let rules = DesignRules::of(&design);
        assert!(rules.small_moves);
        let pairs = confounded_pairs(&design, &candidates, None, rules);
        assert_eq!(
            names(&pairs),
            vec![["fill_factor", "psf_blur"], ["vignetting", "illumination"]]
        );
        let separations: Vec<&str> = pairs.iter().map(|p| p.separate_with.as_str()).collect();
        assert_eq!(separations, vec![STEP_SERIES, ILLUMINATION_SEPARATION]);
        assert!(pairs.iter().all(|p| p.evidence == "design"));
        // A 130 px move (5.1 %) leaves the design's blur and aperture.
        let wide = design_of(
            &manifest(&[(5.0, 0.0)], &["a"], PrintStated::Characterised),
            2560,
        );
        let rules = DesignRules::of(&wide);
        assert!(!rules.small_moves);
        let pairs = confounded_pairs(&wide, &candidates, None, rules);
        assert_eq!(names(&pairs), vec![["fill_factor", "psf_blur"]]);
    }

    #[test]
    fn a_significant_candidate_dropping_four_fifths_of_the_winners_is_named_beside_it() {
        // Moves of two sizes along x and y: nothing confounded by design. The winner, rotation,
        // dropped 0.010 px; scale (significant) 0.009 ≥ 0.8·0.010: named, with the runs that
        // separate them; tilt (significant) 0.007: not; distortion 0.0095 but not significant
        // (ΔBIC +3): not.
        let moves = [(5.0, 0.0), (2.5, 0.0), (0.0, 5.0), (0.0, 2.5)];
        let design = design_of(&manifest(&moves, &["a"], PrintStated::Characterised), 2560);
        let candidates = vec![
            candidate(
                EffectId::Rotation,
                &[("angle_rad", 1e-4, 1e-6)],
                -80.0,
                0.010,
            ),
            candidate(EffectId::Scale, &[("ds", 1e-4, 1e-6)], -60.0, 0.009),
            candidate(
                EffectId::TargetTilt,
                &[("angle_about_y_rad", 0.01, 1e-3)],
                -40.0,
                0.007,
            ),
            candidate(EffectId::LensDistortion, &[("k1", 1e-4, 1e-4)], 3.0, 0.0095),
        ];
        let winner = Some(EffectId::Rotation.into());
        let pairs = confounded_pairs(&design, &candidates, winner, DesignRules::of(&design));
        assert_eq!(names(&pairs), vec![["rotation", "scale"]]);
        assert_eq!(pairs[0].evidence, "data");
        assert_eq!(pairs[0].separate_with, "translations along x and along y");
        // Without a verdict, the data name no pair.
        assert!(confounded_pairs(&design, &candidates, None, DesignRules::of(&design)).is_empty());
    }

    #[test]
    fn a_pair_the_design_confounds_is_not_named_again_from_the_data() {
        // One move size: distortion and scale confounded by design; the data say so too.
        let design = design_of(
            &manifest(&[(5.0, 0.0)], &["a"], PrintStated::Characterised),
            2560,
        );
        let candidates = vec![
            candidate(
                EffectId::LensDistortion,
                &[("k1", 2e-3, 1e-5)],
                -90.0,
                0.010,
            ),
            candidate(EffectId::Scale, &[("ds", 1e-4, 1e-6)], -85.0, 0.0099),
        ];
        let winner = Some(EffectId::LensDistortion.into());
        let pairs = confounded_pairs(&design, &candidates, winner, DesignRules::of(&design));
        assert_eq!(names(&pairs), vec![["lens_distortion", "scale"]]);
        assert_eq!(
            (pairs[0].evidence.as_str(), pairs[0].separate_with.as_str()),
            ("design", SEVERAL_SIZES)
        );
    }
}
