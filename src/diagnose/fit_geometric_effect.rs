//! A geometric candidate fitted (rotation, scale, lens distortion, target tilt; their terms in
//! [`super::geometric`]): the joint fit of its basis fields ([`super::fit_geometric`]) on the
//! field differences of the model's comparison, beside the terms an earlier round named, and
//! written as the model writes it ([`super::write_geometric`]).
//!
//! Lens distortion starts from k1 and adds the decentring terms p1, p2, then k2, each only when
//! the runs identify it and its own Wald χ² in the wider fit (over its marginal covariance) pays
//! the BIC's price (ln n per parameter): a term the data do not ask for would only spend the
//! candidate's evidence. A distortion centre off the image centre shows as p1, p2 (see
//! `basis`): both are reported, the centre as derived.

use super::basis::GeometricParam;
use super::fit_geometric::{fit_geometric, fit_geometric_testing, FieldSample, GeometricFit};
use super::geometric::{Geometric, GeometricSetting, Terms};
use super::results::ImageFit;
use super::write_geometric::{re_estimated_note, with_increments, write_fit};
use crate::model::{EffectId, Effects};

/// Fits a geometric effect; None for other effects or when the runs identify none of its terms.
///
/// `refit`: geometric effects `model` already holds (an earlier round's verdicts) whose terms are
/// fitted again beside the candidate's, as increments on their values: stepwise regression with
/// re-estimation. Without it a sequence of rounds is greedy: an earlier verdict keeps what it
/// absorbed of a later effect's field (measured: lens distortion's p2 took up most of a tilt
/// about the vertical axis, and the tilt fitted alone on what was left explained 12 % of it and
/// was withheld). The candidate's evidence is its own terms' (`k`); the field it predicts, and
/// the model it writes, carry the re-estimated terms too.
pub fn fit_geometric_effect(
    samples: &[FieldSample],
    setting: &GeometricSetting,
    model: &Effects,
    effect: EffectId,
    refit: &[EffectId],
) -> Option<ImageFit> {
    let geometric = Geometric::of(effect)?;
    let again = held_again(model, refit, setting.r0, Some(geometric));
    let (fit, left_out) = match geometric.terms() {
        Terms::Joint(params) => (
            fit_geometric(samples, &[params, &again[..]].concat())?,
            Vec::new(),
        ),
        Terms::Nested(groups) => fit_nested(samples, setting, groups, &again)?,
    };
    let own_part = fit.part(|g| g == geometric);
    let again_part = fit.part(|g| g != geometric);
    let base = with_increments(model, &again_part, setting.scale_px_per_mm);
    let mut written = write_fit(&own_part, setting, &base, (effect, geometric), &left_out);
    if !again_part.params.is_empty() {
        written.geometric.notes.push(re_estimated_note(&again_part));
        // The field the candidate predicts: its own terms and the others' increments.
        written.geometric.field = fit.params.iter().copied().zip(fit.values.clone()).collect();
    }
    Some(written)
}

/// The basis terms of the geometric effects in `refit` that `model` holds, but `except`'s: what
/// a re-estimation beside a candidate frees (see [`fit_geometric_effect`]).
pub fn held_again(
    model: &Effects,
    refit: &[EffectId],
    r0: f64,
    except: Option<Geometric>,
) -> Vec<GeometricParam> {
    refit
        .iter()
        .filter_map(|e| Geometric::of(*e))
        .filter(|g| Some(*g) != except)
        .flat_map(|g| g.held_terms(model, r0))
        .collect()
}

/// The first group, then each further one kept when identifiable and worth its price; `again`
/// (terms re-estimated beside them) is in every fit.
fn fit_nested(
    samples: &[FieldSample],
    setting: &GeometricSetting,
    groups: &[&[GeometricParam]],
    again: &[GeometricParam],
) -> Option<(GeometricFit, Vec<String>)> {
    let price = (setting.observations.max(2) as f64).ln();
    let mut fit = fit_geometric(samples, &[groups.first()?, again].concat())?;
    let mut left_out = Vec::new();
    for extra in &groups[1..] {
        let mut params = fit.params.clone();
        params.extend_from_slice(extra);
        let names = extra
            .iter()
            .map(|p| p.effect_and_name().1)
            .collect::<Vec<_>>()
            .join(", ");
        // The added terms' own Wald statistic in the wider fit, against their price.
        let added: Vec<usize> = (fit.params.len()..params.len()).collect();
        match fit_geometric_testing(samples, &params, &added) {
            Some((wider, wald)) if wald > price * extra.len() as f64 => {
                fit = wider;
            }
            Some(_) => left_out.push(format!("{names}: not needed by the data")),
            None => left_out.push(format!(
                "{names}: not identifiable apart from the other terms with these runs (translations of several sizes and along both axes separate them)"
            )),
        }
    }
    Some((fit, left_out))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::test_fields::{field_runs, run_samples};
    use crate::reduce::Scheme;

    #[test]
    fn radial_distortion_written_from_browns_model_is_found_as_k1() {
        // Brown (1966): a point seen at q from the centre is displaced by k1·q·|q|²/r0². A run
        // moved by t shows, where the model has none, D(p + t) − D(p) — written here from the
        // lens, not from the fit's basis. Two moves along x and y, noise 0.01 px per point.
        let r0 = 1280f64.hypot(1080.0);
        let k1 = 2e-3;
        let brown = |q: (f64, f64)| {
            let r2 = (q.0 * q.0 + q.1 * q.1) / (r0 * r0);
            (k1 * q.0 * r2, k1 * q.1 * r2)
        };
        let lens = |p: (f64, f64), t: (f64, f64)| {
            let (a, b) = (brown((p.0 + t.0, p.1 + t.1)), brown(p));
            (a.0 - b.0, a.1 - b.1)
        };
        let native = Scheme::parse("native").unwrap();
        let moves = [(130.0, 0.0), (0.0, 130.0), (65.0, 0.0)];
        let points = field_runs(&moves, lens, 0.01, 0);
        let samples = run_samples(&native, &moves, &points, 1e-4);
        let setting = GeometricSetting {
            scale_px_per_mm: 26.0,
            working_distance_mm: None,
            r0,
            observations: points.iter().map(Vec::len).sum::<usize>() * 2,
        };
        let fit = fit_geometric_effect(
            &samples,
            &setting,
            &Effects::default(),
            EffectId::LensDistortion,
            &[],
        )
        .unwrap();
        let (v, se) = (fit.params["k1"], fit.stderr["k1"]);
        assert!((v - k1).abs() < 3.0 * se, "k1 = {v} ± {se} against {k1}");
        assert!(fit.beyond_null);
        assert_eq!(fit.effects.lens_distortion.map(|d| d.k1), Some(v));
        // A centred lens has no decentring: the nested fit leaves p1, p2 out. (With three runs
        // the difference of two fits' Wald χ², whose covariances the per-run scatter inflates
        // differently, was 36,800 against a price of 2 ln n ≈ 18 while p1, p2 were within one
        // standard error of zero: the added terms' own statistic decides now.)
        for p in ["p1", "p2"] {
            assert!(
                !fit.params.contains_key(p),
                "{p} admitted: {:?}",
                fit.params
            );
        }
    }
}
