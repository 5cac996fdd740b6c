//! A user effect as a candidate (`[effects.user.NAME]` with a parameter still without a value):
//! its displacement field fitted on the field differences of the model's comparison, as the
//! catalogue's geometric effects are ([`super::fit_geometric`]), by Gauss–Newton on the
//! expressions' derivatives (central differences; one step is exact for a field linear in its
//! parameters), each parameter held within its stated range.
//!
//! "No effect" is every parameter at zero (the criteria ask a parameter to lie more than two
//! standard errors from it): a user writes the effect so that zero is none.

use super::fit_geometric::{fit_fields, Basis, FieldFit, FieldSample};
use super::results::{GeometricTerms, ImageFit};
use crate::model::effects::user::UserField;
use crate::model::{CandidateId, Effects};
use std::collections::BTreeMap;

/// The most Gauss–Newton steps; a field linear in its parameters needs one.
const MAX_STEPS: usize = 12;

/// The expressions linearised about `at`: columns ∂d/∂θⱼ, and the known part d(at) − J·at, so
/// the fit's values are the parameters themselves (not a step), and its Wald χ² is that of
/// "every parameter zero".
struct Linearised<'a> {
    field: &'a UserField,
    at: Vec<f64>,
    step: Vec<f64>,
}

impl Linearised<'_> {
    fn column(&self, j: usize, p: (f64, f64), t: (f64, f64)) -> (f64, f64) {
        let h = self.step[j];
        let mut hi = self.at.clone();
        let mut lo = self.at.clone();
        hi[j] += h;
        lo[j] -= h;
        let a = self.field.displacement(p, t, &hi);
        let b = self.field.displacement(p, t, &lo);
        ((a.0 - b.0) / (2.0 * h), (a.1 - b.1) / (2.0 * h))
    }
}

impl Basis for Linearised<'_> {
    fn len(&self) -> usize {
        self.at.len()
    }

    /// The columns, and the known part d(at) − J·at from the same columns.
    fn at(&self, p: (f64, f64), t: (f64, f64), u: &mut [f64], v: &mut [f64]) -> (f64, f64) {
        let (mut ku, mut kv) = self.field.displacement(p, t, &self.at);
        for (j, a) in self.at.iter().enumerate() {
            (u[j], v[j]) = self.column(j, p, t);
            ku -= u[j] * a;
            kv -= v[j] * a;
        }
        (ku, kv)
    }
}

/// Fits user effect `name` of `model` on the field differences; None when it is not a proposed
/// user effect of the model, or when these runs cannot identify its parameters (a singular
/// fit, or a field that is not finite where the points are).
pub fn fit_user_effect(samples: &[FieldSample], model: &Effects, name: &str) -> Option<ImageFit> {
    let effect = model.user.get(name)?;
    let field = effect.field().ok()?;
    let ranges: Vec<(f64, f64)> = effect.params.values().map(|p| (p.min, p.max)).collect();
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
    let step: Vec<f64> = ranges.iter().map(|&(lo, hi)| 1e-6 * (hi - lo)).collect();
    let mut fit: Option<FieldFit> = None;
    for _ in 0..MAX_STEPS {
        let basis = Linearised {
            field: &field,
            at: at.clone(),
            step: step.clone(),
        };
        let next = fit_fields(samples, &basis)?;
        if !next.values.iter().all(|v| v.is_finite()) {
            return None;
        }
        let clamped: Vec<f64> = next
            .values
            .iter()
            .zip(&ranges)
            .map(|(v, &(lo, hi))| v.clamp(lo, hi))
            .collect();
        let settled = clamped
            .iter()
            .zip(&at)
            .zip(&next.stderr)
            .all(|((v, a), se)| (v - a).abs() <= 1e-3 * se);
        at = clamped;
        fit = Some(next);
        if settled {
            break;
        }
    }
    let fit = fit?;
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
