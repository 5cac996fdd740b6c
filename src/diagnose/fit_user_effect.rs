//! A user effect as a candidate (`[effects.user.NAME]` with a parameter still without a value):
//! its displacement field fitted on the field differences of the model's comparison, as the
//! catalogue's geometric effects are ([`super::fit_geometric`]), by Gauss–Newton on the
//! expressions' derivatives (central differences; one step is exact for a field linear in its
//! parameters), each parameter held within its stated range.
//!
//! "No effect" is every parameter at zero (the criteria ask a parameter to lie more than two
//! standard errors from it): a user writes the effect so that zero is none.

use super::fit_geometric::FieldSample;
use super::gauss_newton::gauss_newton;
use super::results::{GeometricTerms, ImageFit};
use crate::model::{CandidateId, Effects};
use std::collections::BTreeMap;

/// Fits user effect `name` of `model` on the field differences; None when it is not a proposed
/// user effect of the model, or when these runs cannot identify its parameters (a singular
/// fit, or a field that is not finite where the points are).
pub fn fit_user_effect(samples: &[FieldSample], model: &Effects, name: &str) -> Option<ImageFit> {
    let effect = model.user.get(name)?;
    let field = effect.field().ok()?;
    let ranges: Vec<(f64, f64)> = effect.params.values().map(|p| (p.min, p.max)).collect();
    // From zero (no effect) where the range holds it, else its middle.
    let at: Vec<f64> = ranges
        .iter()
        .map(|&(lo, hi)| {
            if lo <= 0.0 && 0.0 <= hi {
                0.0
            } else {
                0.5 * (lo + hi)
            }
        })
        .collect();
    let step: Vec<f64> = ranges.iter().map(|&(lo, hi)| 1e-6 * (hi - lo)).collect();
    let (at, fit) = gauss_newton(
        samples,
        &|p, t, values: &[f64]| field.displacement(p, t, values),
        at,
        &ranges,
        &step,
    )?;
    let names = field.param_names();
    let beyond_null = at.iter().zip(&fit.stderr).any(|(v, se)| v.abs() > 2.0 * se);
    let mut effects = model.clone();
    effects
        .user
        .insert(name.to_string(), effect.with_values(&at));
    let units: Vec<String> = effect
        .params
        .iter()
        .filter(|(_, p)| !p.unit.is_empty())
        .map(|(n, p)| format!("{n} in {}", p.unit))
        .collect();
    let notes = if units.is_empty() {
        Vec::new()
    } else {
        vec![units.join(", ")]
    };
    Some(ImageFit {
        effect: CandidateId::User(name.to_string()),
        params: names.iter().cloned().zip(at.iter().copied()).collect(),
        stderr: names
            .iter()
            .cloned()
            .zip(fit.stderr.iter().copied())
            .collect::<BTreeMap<_, _>>(),
        effects,
        k: names.len(),
        beyond_null,
        geometric: GeometricTerms {
            field: Vec::new(),
            derived: BTreeMap::new(),
            notes,
        },
    })
}
