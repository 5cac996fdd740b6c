//! A user effect as a candidate (`[effects.user.NAME]` with a parameter still without a value):
//! its displacement field fitted on the field differences of the model's comparison, as the
//! catalogue's geometric effects are ([`super::fit_geometric`]), by Gauss–Newton on the
//! expressions' derivatives (central differences; one step is exact for a field linear in its
//! parameters), each parameter held within its stated range.
//!
//! "No effect" is every parameter at zero (the criteria ask a parameter to lie more than two
//! standard errors from it): a user writes the effect so that zero is none.

use super::basis::geometric_basis;
use super::fit_geometric::{FieldSample, GeometricFit};
use super::fit_geometric_effect::{
    held_again, re_estimated_note, with_increments, GeometricSetting,
};
use super::gauss_newton::gauss_newton;
use super::results::{GeometricTerms, ImageFit};
use crate::model::{CandidateId, EffectId, Effects};
use std::collections::BTreeMap;

/// The step of a re-estimated term's central difference: its field is linear in it, so any step
/// is exact, and this one keeps the rounding far below the fields' precision.
const REFIT_STEP: f64 = 1e-3;

/// Fits user effect `name` of `model` on the field differences; None when it is not a proposed
/// user effect of the model, or when these runs cannot identify its parameters (a singular
/// fit, or a field that is not finite where the points are).
///
/// `refit`: the geometric effects `model` holds from earlier rounds, whose terms are fitted again
/// beside the user's, as increments on their values (as beside a geometric candidate, see
/// [`super::fit_geometric_effect::fit_geometric_effect`]): a catalogue effect named first keeps
/// what it absorbed of the user's field otherwise (measured: a radial distortion named before a
/// bow took part of it, and the bow fitted alone on what was left explained 71 % of it and was
/// withheld). The evidence is the user's parameters'; the field predicted and the model written
/// carry the increments too.
pub fn fit_user_effect(
    samples: &[FieldSample],
    setting: &GeometricSetting,
    model: &Effects,
    (name, refit): (&str, &[EffectId]),
) -> Option<ImageFit> {
    let effect = model.user.get(name)?;
    let field = effect.field().ok()?;
    let again = held_again(model, refit, setting.r0, None);
    let n = effect.params.len();
    let mut ranges: Vec<(f64, f64)> = effect.params.values().map(|p| (p.min, p.max)).collect();
    // From zero (no effect) where the range holds it, else its middle.
    let mut at: Vec<f64> = ranges
        .iter()
        .map(|&(lo, hi)| {
            if lo <= 0.0 && 0.0 <= hi {
                0.0
            } else {
                0.5 * (lo + hi)
            }
        })
        .collect();
    let mut step: Vec<f64> = ranges.iter().map(|&(lo, hi)| 1e-6 * (hi - lo)).collect();
    ranges.extend(again.iter().map(|_| (f64::NEG_INFINITY, f64::INFINITY)));
    at.extend(again.iter().map(|_| 0.0));
    step.extend(again.iter().map(|_| REFIT_STEP));
    let r0 = setting.r0;
    let (at, fit) = gauss_newton(
        samples,
        &|p, t, values: &[f64]| {
            let (mut u, mut v) = field.displacement(p, t, &values[..n]);
            for (&term, &dv) in again.iter().zip(&values[n..]) {
                let (bu, bv) = geometric_basis(term, p, t, r0);
                u += dv * bu;
                v += dv * bv;
            }
            (u, v)
        },
        at,
        &ranges,
        &step,
    )?;
    let names = field.param_names();
    let (own, own_se) = (&at[..n], &fit.stderr[..n]);
    let beyond_null = own.iter().zip(own_se).any(|(v, se)| v.abs() > 2.0 * se);
    let increments = GeometricFit {
        params: again.clone(),
        values: at[n..].to_vec(),
        stderr: fit.stderr[n..].to_vec(),
        chi2_drop: f64::NAN,
    };
    let mut effects = with_increments(model, &increments, setting.scale_px_per_mm);
    effects
        .user
        .insert(name.to_string(), effect.with_values(own));
    let units: Vec<String> = effect
        .params
        .iter()
        .filter(|(_, p)| !p.unit.is_empty())
        .map(|(n, p)| format!("{n} in {}", p.unit))
        .collect();
    let mut notes = Vec::new();
    if !units.is_empty() {
        notes.push(units.join(", "));
    }
    if !again.is_empty() {
        notes.push(re_estimated_note(&increments));
    }
    Some(ImageFit {
        effect: CandidateId::User(name.to_string()),
        params: names.iter().cloned().zip(own.iter().copied()).collect(),
        stderr: names
            .iter()
            .cloned()
            .zip(own_se.iter().copied())
            .collect::<BTreeMap<_, _>>(),
        effects,
        k: names.len(),
        beyond_null,
        geometric: GeometricTerms {
            // The increments' field: the user's own is added from its expressions.
            field: again.into_iter().zip(increments.values).collect(),
            derived: BTreeMap::new(),
            notes,
        },
    })
}
