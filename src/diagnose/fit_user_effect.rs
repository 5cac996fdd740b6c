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
use super::fit_geometric_effect::held_again;
use super::gauss_newton::gauss_newton;
use super::geometric::GeometricSetting;
use super::results::{GeometricTerms, ImageFit};
use super::write_geometric::{re_estimated_note, with_increments};
use crate::model::effects::{UserEffect, UserKind};
use crate::model::{CandidateId, EffectId, Effects};
use std::collections::BTreeMap;

/// The step of a re-estimated term's central difference: its field is linear in it, so any step
/// is exact, and this one keeps the rounding far below the fields' precision.
const REFIT_STEP: f64 = 1e-3;

/// Fits user effect `name` of `model` on the field differences; None when it is not a proposed
/// displacement effect of the model, or when these runs cannot identify its parameters (a singular
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
    if field.kind() != UserKind::Displacement {
        return None;
    }
    let again = held_again(model, refit, setting.r0, None);
    let n = effect.params.len();
    let mut ranges: Vec<(f64, f64)> = effect.params.values().map(|p| (p.min, p.max)).collect();
    let mut at = null_start(&ranges);
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
    let (own, own_se) = (&at[..n], &fit.stderr[..n]);
    let increments = GeometricFit {
        params: again.clone(),
        values: at[n..].to_vec(),
        stderr: fit.stderr[n..].to_vec(),
        chi2_drop: f64::NAN,
    };
    let effects = with_increments(model, &increments, setting.scale_px_per_mm);
    let notes = if again.is_empty() {
        Vec::new()
    } else {
        vec![re_estimated_note(&increments)]
    };
    let terms = GeometricTerms {
        // The increments' field: the user's own is added from its expressions.
        field: again.into_iter().zip(increments.values).collect(),
        derived: BTreeMap::new(),
        notes,
    };
    Some(user_fit((name, effect), (own, own_se), effects, terms))
}

/// Where a user effect's fit starts: each parameter at zero (no effect) where its range holds
/// it, else at the range's middle.
pub(super) fn null_start(ranges: &[(f64, f64)]) -> Vec<f64> {
    ranges
        .iter()
        .map(|&(lo, hi)| {
            if lo <= 0.0 && 0.0 <= hi {
                0.0
            } else {
                0.5 * (lo + hi)
            }
        })
        .collect()
}

/// The fit of user effect `name` at `values` ± `stderr` (its parameters' order): `effects`
/// with the effect valued, the parameters' units noted before `terms`' notes, "no effect" every
/// parameter within two standard errors of zero.
pub(super) fn user_fit(
    (name, effect): (&str, &UserEffect),
    (values, stderr): (&[f64], &[f64]),
    mut effects: Effects,
    mut terms: GeometricTerms,
) -> ImageFit {
    effects
        .user
        .insert(name.to_string(), effect.with_values(values));
    let units: Vec<String> = effect
        .params
        .iter()
        .filter(|(_, p)| !p.unit.is_empty())
        .map(|(n, p)| format!("{n} in {}", p.unit))
        .collect();
    if !units.is_empty() {
        terms.notes.insert(0, units.join(", "));
    }
    let names: Vec<String> = effect.params.keys().cloned().collect();
    ImageFit {
        effect: CandidateId::User(name.to_string()),
        params: names.iter().cloned().zip(values.iter().copied()).collect(),
        stderr: names.iter().cloned().zip(stderr.iter().copied()).collect(),
        effects,
        k: names.len(),
        beyond_null: values.iter().zip(stderr).any(|(v, se)| v.abs() > 2.0 * se),
        geometric: terms,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::basis::GeometricParam;
    use crate::diagnose::discrepancy::CommonPoint;
    use crate::diagnose::test_fields::{field_runs, half_diagonal, run_samples};
    use crate::model::effects::{Rotation, UserEffect};
    use crate::reduce::Scheme;

    const MOVES: [(f64, f64); 3] = [(130.0, 0.0), (0.0, 130.0), (65.0, 0.0)];

    /// The moved frame turned by θ about the optical axis: p + t lands at R(θ)(p + t).
    fn turned(theta: f64) -> impl Fn((f64, f64), (f64, f64)) -> (f64, f64) + Copy {
        move |p, t| {
            let (x, y) = (p.0 + t.0, p.1 + t.1);
            let (sin, cos) = theta.sin_cos();
            (cos * x - sin * y - x, sin * x + cos * y - y)
        }
    }

    /// The field differences of [`MOVES`], noise 0.01 px per component.
    fn runs(field: impl Fn((f64, f64), (f64, f64)) -> (f64, f64) + Copy) -> Vec<Vec<CommonPoint>> {
        field_runs(&MOVES, field, 0.01, 40)
    }

    fn setting(points: &[Vec<CommonPoint>]) -> GeometricSetting {
        GeometricSetting {
            scale_px_per_mm: 26.0,
            working_distance_mm: None,
            r0: half_diagonal(),
            observations: 2 * points.iter().map(Vec::len).sum::<usize>(),
        }
    }

    /// A model whose only effect is the user's `name`, written in TOML as a lab would.
    fn model(name: &str, toml_text: &str) -> Effects {
        let effect: UserEffect = toml::from_str(toml_text).unwrap();
        Effects {
            user: BTreeMap::from([(name.to_string(), effect)]),
            ..Effects::default()
        }
    }

    /// A rotation as a user writes it, to first order, within `[min, max]` rad.
    fn turn(min: f64, max: f64) -> Effects {
        model(
            "turn",
            &format!(
                "u = \"-a * (y + ty)\"\nv = \"a * (x + tx)\"\n[params.a]\nunit = \"rad\"\nmin = {min:e}\nmax = {max:e}\n"
            ),
        )
    }

    fn fit(
        points: &[Vec<CommonPoint>],
        effects: &Effects,
        name: &str,
        refit: &[EffectId],
    ) -> Option<ImageFit> {
        let native = Scheme::parse("native").unwrap();
        let samples = run_samples(&native, &MOVES, points, 1e-4);
        fit_user_effect(&samples, &setting(points), effects, (name, refit))
    }

    #[test]
    fn a_users_rotation_is_fitted_to_the_turn_of_the_moved_frame() {
        // The frames turned by 4e-5 rad exactly (sine and cosine), the user's field first order.
        let theta = 4e-5;
        let points = runs(turned(theta));
        let f = fit(&points, &turn(-1e-2, 1e-2), "turn", &[]).unwrap();
        let (a, se) = (f.params["a"], f.stderr["a"]);
        assert!(
            (a - theta).abs() < 3.0 * se,
            "a = {a} ± {se} against {theta}"
        );
        assert!(se < 0.01 * theta, "± {se}");
        assert!(f.beyond_null);
        assert_eq!(
            (f.effect.clone(), f.k),
            (CandidateId::User("turn".into()), 1)
        );
        assert_eq!(f.effects.user["turn"].params["a"].value, Some(a));
        assert_eq!(f.geometric.notes, vec!["a in rad".to_string()]);
        assert!(f.geometric.field.is_empty());
        // Noise alone: a within three errors of zero, and beyond the null only past two.
        let quiet = runs(turned(0.0));
        let f = fit(&quiet, &turn(-1e-2, 1e-2), "turn", &[]).unwrap();
        let (a, se) = (f.params["a"], f.stderr["a"]);
        assert!(a.abs() < 3.0 * se, "a = {a} ± {se}");
        assert_eq!(f.beyond_null, a.abs() > 2.0 * se);
    }

    #[test]
    fn a_value_beyond_the_stated_range_stops_at_its_end() {
        // The turn is 4e-5 rad; the user allowed [0, 1e-5].
        let points = runs(turned(4e-5));
        let f = fit(&points, &turn(0.0, 1e-5), "turn", &[]).unwrap();
        assert_eq!(f.params["a"], 1e-5);
    }

    #[test]
    fn an_unknown_or_empty_effect_is_not_fitted() {
        let points = runs(turned(4e-5));
        assert!(fit(&points, &turn(-1e-2, 1e-2), "bow", &[]).is_none());
        let nothing = model("none", "[params.a]\nmin = -1.0\nmax = 1.0\n");
        assert!(fit(&points, &nothing, "none", &[]).is_none());
    }

    #[test]
    fn an_earlier_rounds_rotation_is_re_estimated_beside_a_bow() {
        // A bowed print of curvature κ = −2e-4 /mm at Z = 500 mm, 26 px/mm: a move t changes the
        // displacement at p by −t·κ|p|²/(2·Z·s²) (model::effects::user's doc), which the user
        // writes c·|p|²·t, so c = −κ/(2·Z·s²) = 2.96e-10 /px². The model already holds a
        // rotation of 1e-4 rad from an earlier round; the frames turned 2e-5 rad further.
        let (kappa, z, s) = (-2e-4, 500.0, 26.0);
        let c = -kappa / (2.0 * z * s * s);
        let delta = 2e-5;
        let rest = turned(delta);
        let points = runs(move |p, t| {
            let bend = -kappa * (p.0 * p.0 + p.1 * p.1) / (2.0 * z * s * s);
            let r = rest(p, t);
            (r.0 + bend * t.0, r.1 + bend * t.1)
        });
        let mut effects = model(
            "bow",
            "u = \"c * (x^2 + y^2) * tx\"\nv = \"c * (x^2 + y^2) * ty\"\n[params.c]\nunit = \"1/px^2\"\nmin = -1e-7\nmax = 1e-7\n",
        );
        effects.rotation = Some(Rotation { angle_rad: 1e-4 });
        let f = fit(&points, &effects, "bow", &[EffectId::Rotation]).unwrap();
        let (v, se) = (f.params["c"], f.stderr["c"]);
        assert!((v - c).abs() < 3.0 * se, "c = {v} ± {se} against {c}");
        assert_eq!(f.k, 1, "the evidence is the bow's alone");
        // The increment: its error is about 0.01 px over √Σ|p|² of 4,000 points, some 2e-7.
        let [(term, increment)] = f.geometric.field[..] else {
            panic!("{:?}", f.geometric.field)
        };
        assert_eq!(term, GeometricParam::Rotation);
        assert!(
            (increment - delta).abs() < 1e-6,
            "{increment} against {delta}"
        );
        let angle = f.effects.rotation.unwrap().angle_rad;
        assert!((angle - (1e-4 + increment)).abs() < 1e-15);
        assert!(
            f.geometric.notes[1].starts_with("re-estimated beside it: rotation.angle_rad"),
            "{:?}",
            f.geometric.notes
        );
    }
}
