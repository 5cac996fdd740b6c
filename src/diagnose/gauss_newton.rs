//! Fields nonlinear in their parameters fitted on the field differences of a comparison, as the
//! catalogue's linear ones are ([`super::fit_geometric`]): Gauss–Newton on central-difference
//! derivatives, each step a weighted least-squares fit of the linearised field with every run's
//! constant offset as a nuisance, each value held within its range. One step is exact for a
//! field linear in its parameters. Used by a user's own effects and by the camera card's
//! distortion about a centre of its own.

use super::fit_geometric::{fit_fields, Basis, FieldFit, FieldSample};

/// The most Gauss–Newton steps; a field linear in its parameters needs one.
const MAX_STEPS: usize = 12;

/// A displacement field: at `p` (px from the image centre) for the actual move `t` (px), with
/// parameter values `values`, full-resolution px.
pub type Field<'a> = &'a (dyn Fn((f64, f64), (f64, f64), &[f64]) -> (f64, f64) + Sync);

/// The field linearised about `at`: columns ∂d/∂θⱼ, and the known part d(at) − J·at, so the
/// fit's values are the parameters themselves (not a step), and its Wald χ² is that of "every
/// parameter zero".
struct Linearised<'a> {
    field: Field<'a>,
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
        let a = (self.field)(p, t, &hi);
        let b = (self.field)(p, t, &lo);
        ((a.0 - b.0) / (2.0 * h), (a.1 - b.1) / (2.0 * h))
    }
}

impl Basis for Linearised<'_> {
    fn len(&self) -> usize {
        self.at.len()
    }

    /// The columns, and the known part d(at) − J·at from the same columns.
    fn at(&self, p: (f64, f64), t: (f64, f64), u: &mut [f64], v: &mut [f64]) -> (f64, f64) {
        let (mut ku, mut kv) = (self.field)(p, t, &self.at);
        for (j, a) in self.at.iter().enumerate() {
            (u[j], v[j]) = self.column(j, p, t);
            ku -= u[j] * a;
            kv -= v[j] * a;
        }
        (ku, kv)
    }
}

/// Fits `field` from `start`, each value clamped to its range after every step, until the values
/// move by less than 1e-3 of their standard errors; the values and the last step's fit. None
/// when these runs cannot identify the parameters (a singular fit) or a value is not finite.
pub fn gauss_newton(
    samples: &[FieldSample],
    field: Field,
    start: Vec<f64>,
    ranges: &[(f64, f64)],
    step: &[f64],
) -> Option<(Vec<f64>, FieldFit)> {
    let mut at = start;
    let mut fit: Option<FieldFit> = None;
    for _ in 0..MAX_STEPS {
        let basis = Linearised {
            field,
            at: at.clone(),
            step: step.to_vec(),
        };
        let next = fit_fields(samples, &basis)?;
        if !next.values.iter().all(|v| v.is_finite()) {
            return None;
        }
        let clamped: Vec<f64> = next
            .values
            .iter()
            .zip(ranges)
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
    Some((at, fit?))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::test_fields::{field_points, field_sample};
    use crate::reduce::Scheme;

    #[test]
    fn a_field_nonlinear_in_its_parameter_is_found_from_afar() {
        // u = a·sin(x/w), v = 0 with a = 0.02 px, w = 500 px: nonlinear in w. Gauss–Newton from
        // w = 400 finds both within three standard errors.
        let (a, w) = (0.02, 500.0);
        let field = |p: (f64, f64), _: (f64, f64), v: &[f64]| (v[0] * (p.0 / v[1]).sin(), 0.0);
        let points = field_points((130.0, 0.0), |p, t| field(p, t, &[a, w]), 0.005, 3);
        let native = Scheme::parse("native").unwrap();
        let samples = [field_sample(&native, &points, (130.0, 0.0), 2.5e-5, 0)];
        let (values, fit) = gauss_newton(
            &samples,
            &field,
            vec![0.01, 400.0],
            &[(-1.0, 1.0), (100.0, 2000.0)],
            &[1e-4, 1.0],
        )
        .unwrap();
        for (i, truth) in [a, w].into_iter().enumerate() {
            let se = fit.stderr[i];
            assert!(
                (values[i] - truth).abs() < 3.0 * se,
                "{}: {} ± {se}",
                i,
                values[i]
            );
        }
    }
}
