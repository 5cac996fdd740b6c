//! Geometric candidates by weighted linear least squares: the difference of the displacement
//! fields (measured − model) of every run and scheme, stacked, against the candidate's basis fields,
//! with a constant offset per run and scheme as nuisance (it absorbs the stage's travel scale and
//! misalignment, which the comparison refits anyway, and each run's sub-pixel bias). Weights are the inverse noise variance of each run's field difference; standard errors
//! come from the inverse normal matrix, inflated by the correlation of neighbouring points whose
//! subsets overlap (n_eff ≈ n·(step/subset)², so the covariance grows by (subset/step)²).

use super::basis::{geometric_basis, GeometricParam};
use super::discrepancy::CommonPoint;
use crate::reduce::Scheme;

/// The field difference of one run and scheme, ready to fit.
pub struct FieldSample<'a> {
    pub scheme: &'a Scheme,
    /// Actual move, full-resolution px.
    pub move_px: (f64, f64),
    /// Image centre, full-resolution px.
    pub centre: (f64, f64),
    /// Distortion normalising radius, full-resolution px.
    pub r0: f64,
    pub points: &'a [CommonPoint],
    /// Noise variance of the difference, (u, v), px² of the analysed image.
    pub var: (f64, f64),
    /// Covariance inflation for correlated points, ≥ 1.
    pub inflation: f64,
    /// Index of the run's reference frame (pattern) and of the run: analyses sharing a frame
    /// share its noise and speckle, so their errors are correlated.
    pub pattern: usize,
    pub run: usize,
}

#[derive(Clone, Debug, PartialEq)]
pub struct GeometricFit {
    pub params: Vec<GeometricParam>,
    pub values: Vec<f64>,
    pub stderr: Vec<f64>,
    /// Wald statistic βᵀ C⁻¹ β: the χ² the candidate explains beyond the nuisances.
    pub chi2_drop: f64,
}

impl GeometricFit {
    /// The fitted value of `p` and its standard error, when the fit holds `p`.
    pub fn value(&self, p: GeometricParam) -> Option<(f64, f64)> {
        let i = self.params.iter().position(|q| *q == p)?;
        Some((self.values[i], self.stderr[i]))
    }

    /// The fitted fields' sum at `p` (px from the image centre) for the move `t`, px.
    pub fn field_at(&self, p: (f64, f64), t: (f64, f64), r0: f64) -> (f64, f64) {
        self.params
            .iter()
            .zip(&self.values)
            .fold((0.0, 0.0), |(u, v), (&q, &b)| {
                let (bu, bv) = geometric_basis(q, p, t, r0);
                (u + b * bu, v + b * bv)
            })
    }
}

/// The weighted normal matrix N (k×k) and right-hand side r of one run and scheme, each basis
/// column and the data centred on their own means (the per-run constant offsets are nuisances:
/// sub-pixel bias, travel, misalignment).
struct Sums {
    n: Vec<f64>,
    r: Vec<f64>,
    inflation: f64,
    pattern: usize,
    run: usize,
}

/// The basis fields of a fit, in full-resolution px at `p` (px from the image centre) for the
/// actual move `t` (px): `k` columns, and a field already known that is taken from the data
/// first (zero for the catalogue's fields, which are linear in their parameters).
pub trait Basis: Sync {
    fn len(&self) -> usize;
    /// Column j's (u, v) into `u[j]`, `v[j]`; returns the known field there.
    fn at(&self, p: (f64, f64), t: (f64, f64), u: &mut [f64], v: &mut [f64]) -> (f64, f64);
}

/// [`GeometricParam`]s with the distortion's normalising radius (the same for every sample: one
/// camera).
struct Catalogue<'a> {
    params: &'a [GeometricParam],
    r0: f64,
}

impl Basis for Catalogue<'_> {
    fn len(&self) -> usize {
        self.params.len()
    }

    fn at(&self, p: (f64, f64), t: (f64, f64), u: &mut [f64], v: &mut [f64]) -> (f64, f64) {
        for (j, &q) in self.params.iter().enumerate() {
            (u[j], v[j]) = geometric_basis(q, p, t, self.r0);
        }
        (0.0, 0.0)
    }
}

fn centred_sums(s: &FieldSample, basis: &dyn Basis) -> Option<Sums> {
    if !(s.var.0 > 0.0 && s.var.1 > 0.0) || s.points.len() < 3 {
        return None;
    }
    let k = basis.len();
    let (bx, by) = (s.scheme.x.block as f64, s.scheme.y.block as f64);
    // Per point: k basis values in u, k in v, then du, dv less the known field.
    let rows: Vec<(Vec<f64>, Vec<f64>, f64, f64)> = s
        .points
        .iter()
        .map(|p| {
            let (fx, fy) = s.scheme.to_full(p.x, p.y);
            let rel = (fx - s.centre.0, fy - s.centre.1);
            let (mut bu, mut bv) = (vec![0.0; k], vec![0.0; k]);
            let (ku, kv) = basis.at(rel, s.move_px, &mut bu, &mut bv);
            bu.iter_mut().for_each(|x| *x /= bx);
            bv.iter_mut().for_each(|x| *x /= by);
            (bu, bv, p.du - ku / bx, p.dv - kv / by)
        })
        .collect();
    let count = rows.len() as f64;
    let mut mean_u = vec![0.0; k];
    let mut mean_v = vec![0.0; k];
    let (mut mdu, mut mdv) = (0.0, 0.0);
    for (bu, bv, du, dv) in &rows {
        for j in 0..k {
            mean_u[j] += bu[j] / count;
            mean_v[j] += bv[j] / count;
        }
        mdu += du / count;
        mdv += dv / count;
    }
    let mut n = vec![0.0; k * k];
    let mut r = vec![0.0; k];
    for (bu, bv, du, dv) in &rows {
        let (du, dv) = (du - mdu, dv - mdv);
        for i in 0..k {
            let (ui, vi) = (bu[i] - mean_u[i], bv[i] - mean_v[i]);
            r[i] += ui * du / s.var.0 + vi * dv / s.var.1;
            for j in 0..k {
                let (uj, vj) = (bu[j] - mean_u[j], bv[j] - mean_v[j]);
                n[i * k + j] += ui * uj / s.var.0 + vi * vj / s.var.1;
            }
        }
    }
    (0..k).all(|j| n[j * k + j] > 0.0).then_some(Sums {
        n,
        r,
        inflation: s.inflation.max(1.0),
        pattern: s.pattern,
        run: s.run,
    })
}

/// The inverse of a small symmetric positive-definite matrix, None when singular.
fn invert(n: &[f64], k: usize) -> Option<Vec<f64>> {
    let m = nalgebra::DMatrix::from_row_slice(k, k, n);
    // Scale rows and columns to unit diagonal first: the parameters differ by many decades.
    let d: Vec<f64> = (0..k).map(|i| m[(i, i)].sqrt()).collect();
    if d.iter().any(|x| !(*x > 0.0)) {
        return None;
    }
    let unit = nalgebra::DMatrix::from_fn(k, k, |i, j| m[(i, j)] / (d[i] * d[j]));
    let chol = unit.cholesky()?;
    let l = chol.l_dirty();
    if !(0..k).all(|i| l[(i, i)] * l[(i, i)] > 1e-12) {
        return None;
    }
    let inv = chol.inverse();
    Some(
        (0..k * k)
            .map(|x| inv[(x / k, x % k)] / (d[x / k] * d[x % k]))
            .collect(),
    )
}

/// Fits candidate parameters jointly on the field differences with every run's and scheme's
/// constant offsets removed (Frisch–Waugh: equivalent to fitting them as nuisances). Each
/// parameter's variance is the least-squares one (inflated for correlated points), raised by
/// the factor that counting the frames the analyses share gives and, with three or more runs and
/// schemes, by the scatter of the per-run estimates about the joint value: a real effect is the
/// same in every run, a speckle realisation's systematic error is not. None when the basis
/// fields cannot be told apart by these runs (a singular normal matrix).
pub fn fit_geometric(samples: &[FieldSample], params: &[GeometricParam]) -> Option<GeometricFit> {
    fit_geometric_testing(samples, params, &[]).map(|(fit, _)| fit)
}

/// [`fit_geometric`], with the Wald statistic of the parameters at the indices `tested` alone
/// (βₜᵀ Cₜₜ⁻¹ βₜ, their marginal covariance; 0 when none): whether terms added to a fit are
/// asked for by the data. The difference of two fits' `chi2_drop` is not that statistic when the
/// per-run scatter inflates each fit's covariance by its own factors (three or more runs): a
/// centred lens then admitted decentring terms within one standard error of zero.
pub fn fit_geometric_testing(
    samples: &[FieldSample],
    params: &[GeometricParam],
    tested: &[usize],
) -> Option<(GeometricFit, f64)> {
    let r0 = samples.first().map_or(1.0, |s| s.r0);
    let fit = fit_fields(samples, &Catalogue { params, r0 })?;
    let wald = fit.wald_of(tested)?;
    Some((
        GeometricFit {
            params: params.to_vec(),
            values: fit.values,
            stderr: fit.stderr,
            chi2_drop: fit.chi2_drop,
        },
        wald,
    ))
}

/// A fit of any [`Basis`]: the values, their standard errors and the Wald χ² (as
/// [`GeometricFit`]).
pub struct FieldFit {
    pub values: Vec<f64>,
    pub stderr: Vec<f64>,
    pub chi2_drop: f64,
    /// The values' covariance C, k×k by rows (`stderr` is the root of its diagonal;
    /// `chi2_drop` = βᵀ C⁻¹ β).
    pub covariance: Vec<f64>,
}

impl FieldFit {
    /// The Wald statistic of the values at the indices `which` alone: βᵀ C⁻¹ β over their
    /// marginal covariance (the block of C, the others free). 0 for none; None when the block
    /// is singular.
    pub fn wald_of(&self, which: &[usize]) -> Option<f64> {
        let k = self.values.len();
        let m = which.len();
        if m == 0 {
            return Some(0.0);
        }
        let block: Vec<f64> = (0..m * m)
            .map(|x| self.covariance[which[x / m] * k + which[x % m]])
            .collect();
        let inv = invert(&block, m)?;
        Some(
            (0..m * m)
                .map(|x| self.values[which[x / m]] * inv[x] * self.values[which[x % m]])
                .sum(),
        )
    }
}

/// [`fit_geometric`] on any basis.
pub fn fit_fields(samples: &[FieldSample], basis: &dyn Basis) -> Option<FieldFit> {
    let k = basis.len();
    let sums: Vec<Sums> = samples
        .iter()
        .filter_map(|s| centred_sums(s, basis))
        .collect();
    if sums.is_empty() {
        return None;
    }
    let mut n = vec![0.0; k * k];
    let mut r = vec![0.0; k];
    for s in &sums {
        n.iter_mut().zip(&s.n).for_each(|(a, b)| *a += b);
        r.iter_mut().zip(&s.r).for_each(|(a, b)| *a += b);
    }
    let inv = invert(&n, k)?;
    let values: Vec<f64> = (0..k)
        .map(|i| (0..k).map(|j| inv[i * k + j] * r[j]).sum())
        .collect();
    let inflation = sums.iter().map(|s| s.inflation).fold(1.0, f64::max);
    let factors: Vec<f64> = (0..k)
        .map(|j| variance_factor(&sums, &values, j, k, inflation))
        .collect();
    let var: Vec<f64> = (0..k)
        .map(|j| inflation * inv[j * k + j] * factors[j])
        .collect();

    // βᵀ C⁻¹ β with C = inflation·N⁻¹ scaled per parameter by its factor.
    let scaled: Vec<f64> = (0..k).map(|j| values[j] / factors[j].sqrt()).collect();
    let chi2_drop = (0..k)
        .map(|i| {
            (0..k)
                .map(|j| scaled[i] * n[i * k + j] * scaled[j])
                .sum::<f64>()
        })
        .sum::<f64>()
        / inflation;
    let covariance = (0..k * k)
        .map(|x| {
            let (i, j) = (x / k, x % k);
            inflation * inv[x] * (factors[i] * factors[j]).sqrt()
        })
        .collect();
    Some(FieldFit {
        values,
        stderr: var.iter().map(|v| v.sqrt()).collect(),
        chi2_drop,
        covariance,
    })
}

/// The factor (≥ 1) by which parameter j's least-squares variance grows: half of a field
/// difference's noise comes from the reference frames (shared by every run of a pattern), half
/// from the moved frames (shared by every scheme of a run), which for similar basis fields gives
/// ½·c·[Σ_runs(Σ√N_jj)² + Σ_patterns(Σ√N_jj)²]/(ΣN_jj)²; and the scatter of the per-run
/// estimates (the others held at their joint values) about the joint value.
fn variance_factor(sums: &[Sums], values: &[f64], j: usize, k: usize, inflation: f64) -> f64 {
    let njj: f64 = sums.iter().map(|s| s.n[j * k + j]).sum();
    let grouped = |key: &dyn Fn(&Sums) -> usize| -> f64 {
        let mut acc: std::collections::BTreeMap<usize, f64> = Default::default();
        for s in sums {
            *acc.entry(key(s)).or_default() += s.n[j * k + j].sqrt();
        }
        acc.values().map(|x| x * x).sum()
    };
    let shared = 0.5 * (grouped(&|s| s.run) + grouped(&|s| s.pattern)) / njj;
    let mut factor = shared.max(1.0);
    if sums.len() >= 3 {
        let chi: f64 = sums
            .iter()
            .map(|s| {
                let others: f64 = (0..k)
                    .filter(|&l| l != j)
                    .map(|l| s.n[j * k + l] * values[l])
                    .sum();
                let own = (s.r[j] - others) / s.n[j * k + j];
                s.n[j * k + j] * (own - values[j]).powi(2)
            })
            .sum();
        factor = factor.max(chi / ((sums.len() - 1) as f64 * inflation));
    }
    factor
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::test_fields::{field_points, field_runs, field_sample, run_samples};

    #[test]
    fn a_scale_and_a_rotation_are_recovered_from_their_physics() {
        // The moved frame is imaged at magnification 1 + s and turned by θ: a reference point p
        // lands at R(θ)(1 + s)(p + t), so the field the model lacks is that minus p + t — written
        // here from the geometry, not from the fit's basis.
        let (s, theta): (f64, f64) = (2e-5, -3e-5);
        let physics = |p: (f64, f64), t: (f64, f64)| {
            let (x, y) = ((1.0 + s) * (p.0 + t.0), (1.0 + s) * (p.1 + t.1));
            let (sin, cos) = theta.sin_cos();
            (cos * x - sin * y - p.0 - t.0, sin * x + cos * y - p.1 - t.1)
        };
        let native = Scheme::parse("native").unwrap();
        let moves = [(130.0, 0.0), (0.0, 65.0), (-130.0, 13.0)];
        let points = field_runs(&moves, physics, 0.01, 0);
        let samples = run_samples(&native, &moves, &points, 1e-4);
        let params = [GeometricParam::Scale, GeometricParam::Rotation];
        let fit = fit_geometric(&samples, &params).unwrap();
        for (i, truth) in [s, theta].into_iter().enumerate() {
            let (v, se) = (fit.values[i], fit.stderr[i]);
            assert!(
                (v - truth).abs() < 3.0 * se,
                "{:?}: {v} ± {se} against {truth}",
                params[i]
            );
            assert!(se < 0.05 * truth.abs(), "{se}");
        }
        assert!(fit.chi2_drop > 100.0, "{}", fit.chi2_drop);
        // Noise alone: nothing beyond the null.
        let quiet = field_runs(&moves, |_, _| (0.0, 0.0), 0.01, 10);
        let samples = run_samples(&native, &moves, &quiet, 1e-4);
        let fit = fit_geometric(&samples, &params).unwrap();
        assert!(fit
            .values
            .iter()
            .zip(&fit.stderr)
            .all(|(v, se)| v.abs() < 4.0 * se));
    }

    /// The tested terms' Wald statistic is over their marginal covariance: all of them give
    /// `chi2_drop`, one alone (βⱼ/σⱼ)², none 0; a term the field does not hold stays near its
    /// one degree of freedom beside one it holds. (Where the two differ, a centred lens's
    /// decentring terms: `fit_geometric_effect`'s test.)
    #[test]
    fn a_terms_own_wald_statistic_is_over_its_marginal_covariance() {
        let s = 2e-5;
        let physics = |p: (f64, f64), t: (f64, f64)| (s * (p.0 + t.0), s * (p.1 + t.1));
        let native = Scheme::parse("native").unwrap();
        let moves = [(130.0, 0.0), (0.0, 65.0), (-130.0, 13.0)];
        let points = field_runs(&moves, physics, 0.01, 3);
        let samples = run_samples(&native, &moves, &points, 1e-4);
        let params = [GeometricParam::Scale, GeometricParam::Rotation];
        let (fit, both) = fit_geometric_testing(&samples, &params, &[0, 1]).unwrap();
        assert!(
            (both - fit.chi2_drop).abs() < 1e-9 * fit.chi2_drop,
            "{both} {fit:?}"
        );
        let (_, none) = fit_geometric_testing(&samples, &params, &[]).unwrap();
        assert_eq!(none, 0.0);
        let (_, rotation) = fit_geometric_testing(&samples, &params, &[1]).unwrap();
        let z = fit.values[1] / fit.stderr[1];
        assert!(
            (rotation - z * z).abs() < 1e-9 * rotation.max(1.0),
            "{rotation} {z}"
        );
        assert!(rotation < 16.0, "no rotation in the field: {rotation}");
        let alone = fit_geometric(&samples, &params[..1]).unwrap();
        assert!(alone.chi2_drop > 100.0, "{}", alone.chi2_drop);
    }

    #[test]
    fn fields_one_move_cannot_tell_apart_make_no_fit() {
        // Without a move the travel scale has no field at all: a singular normal matrix.
        let native = Scheme::parse("native").unwrap();
        let points = field_points((0.0, 0.0), |_, _| (0.0, 0.0), 0.01, 1);
        let samples = [field_sample(&native, &points, (0.0, 0.0), 1e-4, 0)];
        assert!(fit_geometric(&samples, &[GeometricParam::TravelScale]).is_none());
    }
}
