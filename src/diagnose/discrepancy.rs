//! The discrepancy of one run and scheme (definition in the module doc of [`super`]): the
//! systematic part from a quadratic surface fitted to the difference of the two displacement
//! fields, the random part from the difference of the two analyses' random errors.

use crate::dic::DicResult;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// Terms of the quadratic surface: 1, x, y, x², xy, y² in coordinates centred and scaled to the
/// points' span (conditioning).
pub const QUADRATIC_TERMS: usize = 6;

/// A least-squares quadratic surface through (x, y, value) samples.
#[derive(Clone, Debug, PartialEq)]
pub struct QuadraticFit {
    /// The fitted value at every sample.
    pub fitted: Vec<f64>,
    /// Residual variance, RSS / (n − 6).
    pub residual_var: f64,
    /// The coefficients of 1, a, b, a², ab, b² with (a, b) = ((x − cx)/s, (y − cy)/s).
    pub coefficients: [f64; QUADRATIC_TERMS],
    /// (cx, cy, s): the points' centroid and their largest distance from it along either axis.
    pub norm: (f64, f64, f64),
    /// False when the layout was degenerate (one row or column of points) and a plane or a
    /// constant was fitted instead.
    pub full: bool,
}

fn terms(x: f64, y: f64, (cx, cy, s): (f64, f64, f64)) -> [f64; QUADRATIC_TERMS] {
    let (a, b) = ((x - cx) / s, (y - cy) / s);
    [1.0, a, b, a * a, a * b, b * b]
}

/// Solves the symmetric positive-definite system `a x = b` (n ≤ 8) by Cholesky (nalgebra); None
/// when `a` is singular to working precision: a pivot below 1e-13 of the largest diagonal entry,
/// as a degenerate layout of points (one row or column) gives.
pub fn solve_spd(a: &[Vec<f64>], b: &[f64]) -> Option<Vec<f64>> {
    let n = a.len();
    let scale = (0..n)
        .map(|i| a[i][i].abs())
        .fold(0.0, f64::max)
        .max(1e-300);
    let chol = DMatrix::from_fn(n, n, |i, j| a[i][j]).cholesky()?;
    let l = chol.l_dirty();
    if !(0..n).all(|i| l[(i, i)] * l[(i, i)] > 1e-13 * scale) {
        return None;
    }
    Some(
        chol.solve(&DVector::from_column_slice(b))
            .as_slice()
            .to_vec(),
    )
}

/// Fits a quadratic surface to `values` at `xy`; None with fewer than 8 samples.
pub fn quadratic_fit(xy: &[(f64, f64)], values: &[f64]) -> Option<QuadraticFit> {
    let n = xy.len();
    if n < QUADRATIC_TERMS + 2 {
        return None;
    }
    let cx = xy.iter().map(|p| p.0).sum::<f64>() / n as f64;
    let cy = xy.iter().map(|p| p.1).sum::<f64>() / n as f64;
    let s = xy
        .iter()
        .map(|p| (p.0 - cx).abs().max((p.1 - cy).abs()))
        .fold(1e-9, f64::max);
    let norm = (cx, cy, s);
    let mut ata = vec![vec![0.0; QUADRATIC_TERMS]; QUADRATIC_TERMS];
    let mut atb = vec![0.0; QUADRATIC_TERMS];
    for (p, v) in xy.iter().zip(values) {
        let t = terms(p.0, p.1, norm);
        for i in 0..QUADRATIC_TERMS {
            atb[i] += t[i] * v;
            for j in 0..QUADRATIC_TERMS {
                ata[i][j] += t[i] * t[j];
            }
        }
    }
    // A degenerate layout (one row or column of points) falls back to a plane or a constant.
    let full = solve_spd(&ata, &atb);
    let is_full = full.is_some();
    let coef = full.or_else(|| {
        let k = 3;
        let a: Vec<Vec<f64>> = ata[..k].iter().map(|r| r[..k].to_vec()).collect();
        solve_spd(&a, &atb[..k]).map(|mut c| {
            c.resize(QUADRATIC_TERMS, 0.0);
            c
        })
    })?;
    let fitted: Vec<f64> = xy
        .iter()
        .map(|p| {
            terms(p.0, p.1, norm)
                .iter()
                .zip(&coef)
                .map(|(a, b)| a * b)
                .sum()
        })
        .collect();
    let rss: f64 = fitted
        .iter()
        .zip(values)
        .map(|(f, v)| (v - f).powi(2))
        .sum();
    let mut coefficients = [0.0; QUADRATIC_TERMS];
    coefficients.copy_from_slice(&coef);
    Some(QuadraticFit {
        fitted,
        residual_var: rss / (n - QUADRATIC_TERMS) as f64,
        coefficients,
        norm,
        full: is_full,
    })
}

/// The discrepancy of one run and scheme, and the numbers behind it.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RunDiscrepancy {
    /// Points valid in both analyses.
    pub points: usize,
    /// √(rigid² + field² + std²), px.
    pub discrepancy_px: f64,
    /// Sampling variance of discrepancy² from the noise of both analyses, px⁴: the sum of the
    /// three parts' below.
    pub discrepancy_sq_var: f64,
    /// Sampling variances of rigid², field² and std², px⁴.
    #[serde(default)]
    pub rigid_sq_var: f64,
    #[serde(default)]
    pub field_sq_var: f64,
    #[serde(default)]
    pub std_sq_var: f64,
    /// Rigid part: the length of the mean of the field difference, debiased for its noise, px —
    /// a stage landing the fit could not explain, or a sub-pixel bias the model lacks.
    pub rigid_px: f64,
    /// Systematic field part: RMS of the quadratic surface of the field difference about its
    /// mean, debiased for the noise the surface absorbs, px.
    pub field_px: f64,
    /// Random part: √(Δσu² + Δσv²) debiased for the sampling error of the two stds, px.
    pub std_px: f64,
    /// Mean of the difference, px (u, v), and its standard error.
    pub mean_diff_px: (f64, f64),
    #[serde(default)]
    pub mean_diff_se_px: (f64, f64),
    /// Random error (std about the own quadratic surface) of each side, px (u, v).
    pub measured_random_px: (f64, f64),
    pub model_random_px: (f64, f64),
    /// Residual variance of the difference about its surface, px² (u, v): the noise level of the
    /// field difference.
    pub residual_var_px2: (f64, f64),
    /// The fitted surface of the difference at every common point (u, v), and the raw
    /// difference: the residual map.
    #[serde(skip)]
    pub common: Vec<CommonPoint>,
}

/// Standard errors of a run's discrepancy, its parts and its mean difference from the noise
/// of both analyses, px ([`se_of_length`]: at a part debiased to zero, the noise level below
/// which it cannot be told from zero).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DiscrepancyErrors {
    #[serde(default, deserialize_with = "crate::dic::f64_or_nan")]
    pub discrepancy_se_px: f64,
    #[serde(default, deserialize_with = "crate::dic::f64_or_nan")]
    pub rigid_se_px: f64,
    #[serde(default, deserialize_with = "crate::dic::f64_or_nan")]
    pub field_se_px: f64,
    #[serde(default, deserialize_with = "crate::dic::f64_or_nan")]
    pub std_se_px: f64,
    /// Of the mean difference (u, v).
    #[serde(default = "nan_pair", deserialize_with = "crate::dic::interval_or_nan")]
    pub mean_diff_se_px: [f64; 2],
}

fn nan_pair() -> [f64; 2] {
    [f64::NAN, f64::NAN]
}

/// A point valid in both analyses.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CommonPoint {
    pub index: usize,
    pub x: f64,
    pub y: f64,
    pub du: f64,
    pub dv: f64,
    pub fit_du: f64,
    pub fit_dv: f64,
}

/// Standard error of a length D from the variance of its square: √(D² + SE(D²)) − D, which is
/// SE(D²)/(2D) for a clear signal and √SE(D²) at zero.
pub fn se_of_length(d: f64, sq_var: f64) -> f64 {
    let se_sq = sq_var.max(0.0).sqrt();
    (d * d + se_sq).sqrt() - d
}

fn random_error(xy: &[(f64, f64)], v: &[f64]) -> f64 {
    quadratic_fit(xy, v).map_or(f64::NAN, |f| f.residual_var.sqrt())
}

impl RunDiscrepancy {
    /// The standard error of `discrepancy_px` from the noise of both analyses.
    pub fn discrepancy_se_px(&self) -> f64 {
        se_of_length(self.discrepancy_px, self.discrepancy_sq_var)
    }

    /// The standard errors of the discrepancy, its parts and the mean difference.
    pub fn errors(&self) -> DiscrepancyErrors {
        DiscrepancyErrors {
            discrepancy_se_px: self.discrepancy_se_px(),
            rigid_se_px: se_of_length(self.rigid_px, self.rigid_sq_var),
            field_se_px: se_of_length(self.field_px, self.field_sq_var),
            std_se_px: se_of_length(self.std_px, self.std_sq_var),
            mean_diff_se_px: [self.mean_diff_se_px.0, self.mean_diff_se_px.1],
        }
    }

    /// Too few points valid in both analyses to fit the difference: every figure NaN.
    fn unmeasurable(points: usize) -> RunDiscrepancy {
        let nan2 = (f64::NAN, f64::NAN);
        RunDiscrepancy {
            points,
            discrepancy_px: f64::NAN,
            discrepancy_sq_var: f64::NAN,
            rigid_sq_var: f64::NAN,
            field_sq_var: f64::NAN,
            std_sq_var: f64::NAN,
            rigid_px: f64::NAN,
            field_px: f64::NAN,
            std_px: f64::NAN,
            mean_diff_px: nan2,
            mean_diff_se_px: nan2,
            measured_random_px: nan2,
            model_random_px: nan2,
            residual_var_px2: nan2,
            common: Vec::new(),
        }
    }
}

/// Compares two analyses of the same grid (same image size and settings). `inflation` is the
/// variance inflation of averages over correlated neighbouring points ((subset/step)², ≥ 1).
pub fn run_discrepancy(measured: &DicResult, model: &DicResult, inflation: f64) -> RunDiscrepancy {
    /// (grid index, x, y, measured u, v, model u, v) of a point valid in both.
    type Pair = (usize, f64, f64, f64, f64, f64, f64);
    let common: Vec<Pair> = measured
        .points
        .iter()
        .zip(&model.points)
        .enumerate()
        .filter(|(_, (a, b))| a.status.is_valid() && b.status.is_valid())
        .map(|(i, (a, b))| (i, a.x, a.y, a.u, a.v, b.u, b.v))
        .collect();
    let xy: Vec<(f64, f64)> = common.iter().map(|c| (c.1, c.2)).collect();
    let col = |f: fn(&Pair) -> f64| -> Vec<f64> { common.iter().map(f).collect() };
    let (mu, mv, ou, ov) = (col(|c| c.3), col(|c| c.4), col(|c| c.5), col(|c| c.6));
    let du: Vec<f64> = mu.iter().zip(&ou).map(|(a, b)| a - b).collect();
    let dv: Vec<f64> = mv.iter().zip(&ov).map(|(a, b)| a - b).collect();
    let n = common.len();
    let (Some(fu), Some(fv)) = (quadratic_fit(&xy, &du), quadratic_fit(&xy, &dv)) else {
        return RunDiscrepancy::unmeasurable(n);
    };
    let nf = n as f64;
    let p = QUADRATIC_TERMS as f64;
    let infl = inflation.max(1.0);
    let mean = |v: &[f64]| v.iter().sum::<f64>() / nf;
    let (mean_du, mean_dv) = (mean(&du), mean(&dv));
    // The surface's mean is the mean of the difference (it has a constant term): the rigid part.
    // E[mean²] of correlated noise is σ²·inflation/n per component, E[mean fitted²] is p times
    // that: remove both.
    let noise = |f: &QuadraticFit| f.residual_var * infl / nf;
    let rigid_sq = mean_du * mean_du + mean_dv * mean_dv - noise(&fu) - noise(&fv);
    let shape = |f: &QuadraticFit, m: f64| {
        f.fitted.iter().map(|x| (x - m).powi(2)).sum::<f64>() / nf - (p - 1.0) * noise(f)
    };
    let field_sq = shape(&fu, mean_du) + shape(&fv, mean_dv);
    let rigid_px = rigid_sq.max(0.0).sqrt();
    let field_px = field_sq.max(0.0).sqrt();
    // Sampling variance of the squares (a noncentral χ²: var = 4·signal·s² + 2·k·s⁴ per
    // component, s² the noise variance of one coefficient, k the coefficients).
    let square_var = |signal: f64, s2: f64, k: f64| 4.0 * signal.max(0.0) * s2 + 2.0 * k * s2 * s2;
    let shape_u = shape(&fu, mean_du).max(0.0);
    let shape_v = shape(&fv, mean_dv).max(0.0);
    let rigid_sq_var = square_var(mean_du * mean_du, noise(&fu), 1.0)
        + square_var(mean_dv * mean_dv, noise(&fv), 1.0);
    let field_sq_var =
        square_var(shape_u, noise(&fu), p - 1.0) + square_var(shape_v, noise(&fv), p - 1.0);
    let measured_random_px = (random_error(&xy, &mu), random_error(&xy, &mv));
    let model_random_px = (random_error(&xy, &ou), random_error(&xy, &ov));
    // A sample std over n_eff independent points has variance σ²/(2 n_eff): remove the
    // expected square of the difference of two such estimates.
    let n_eff = (nf / infl).max(1.0);
    let sq = |a: f64, b: f64| (a - b).powi(2) - (a * a + b * b) / (2.0 * n_eff);
    let std_px = (sq(measured_random_px.0, model_random_px.0)
        + sq(measured_random_px.1, model_random_px.1))
    .max(0.0)
    .sqrt();
    let mut std_sq_var = 0.0;
    for (a, b) in [
        (measured_random_px.0, model_random_px.0),
        (measured_random_px.1, model_random_px.1),
    ] {
        let se2 = (a * a + b * b) / (2.0 * n_eff);
        if se2.is_finite() {
            std_sq_var += square_var((a - b).powi(2), se2, 1.0);
        }
    }
    RunDiscrepancy {
        points: n,
        discrepancy_px: (rigid_px * rigid_px + field_px * field_px + std_px * std_px).sqrt(),
        discrepancy_sq_var: rigid_sq_var + field_sq_var + std_sq_var,
        rigid_sq_var,
        field_sq_var,
        std_sq_var,
        rigid_px,
        field_px,
        std_px,
        mean_diff_px: (mean_du, mean_dv),
        mean_diff_se_px: (noise(&fu).sqrt(), noise(&fv).sqrt()),
        measured_random_px,
        model_random_px,
        residual_var_px2: (fu.residual_var, fv.residual_var),
        common: common
            .iter()
            .enumerate()
            .map(|(k, c)| CommonPoint {
                index: c.0,
                x: c.1,
                y: c.2,
                du: du[k],
                dv: dv[k],
                fit_du: fu.fitted[k],
                fit_dv: fv.fitted[k],
            })
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quadratic_surface_is_recovered_exactly() {
        let xy: Vec<(f64, f64)> = (0..100)
            .map(|k| ((k % 10) as f64 * 7.0, (k / 10) as f64 * 5.0))
            .collect();
        let v: Vec<f64> = xy
            .iter()
            .map(|(x, y)| 0.3 + 0.01 * x - 0.02 * y + 1e-4 * x * y - 3e-4 * y * y)
            .collect();
        let f = quadratic_fit(&xy, &v).unwrap();
        for (a, b) in f.fitted.iter().zip(&v) {
            assert!((a - b).abs() < 1e-9);
        }
        assert!(f.residual_var < 1e-18 && f.full);
        // The coefficients in the normalised coordinates give the surface anywhere.
        let (cx, cy, s) = f.norm;
        let (x, y) = (12.0, 31.0);
        let t = terms(x, y, (cx, cy, s));
        let at: f64 = t.iter().zip(&f.coefficients).map(|(a, b)| a * b).sum();
        let truth = 0.3 + 0.01 * x - 0.02 * y + 1e-4 * x * y - 3e-4 * y * y;
        assert!((at - truth).abs() < 1e-9, "{at} against {truth}");
    }

    use crate::diagnose::test_fields::synthetic_result;
    use crate::dic::DicSettings;

    /// A 640x480 frame analysed at the paper's grid (subset 29, step 10): 2,600 points or so.
    fn analysis(field: impl Fn(f64, f64) -> (f64, f64), noise_px: f64, seed: u64) -> DicResult {
        let settings = DicSettings {
            subset_px: 29,
            step_px: 10,
            ..DicSettings::default()
        };
        synthetic_result((640, 480), &settings, field, noise_px, seed)
    }

    #[test]
    fn a_rigid_offset_is_the_rigid_part_and_nothing_else() {
        // The measured side landed (0.03, 0.04) px away from the model's: 0.05 px rigid, both
        // sides with the same noise (0.01 px), no field, no change of the random error.
        let measured = analysis(|_, _| (0.53, 0.04), 0.01, 1);
        let model = analysis(|_, _| (0.50, 0.0), 0.01, 2);
        let d = run_discrepancy(&measured, &model, 1.0);
        let e = d.errors();
        assert!(
            (d.rigid_px - 0.05).abs() < 3.0 * e.rigid_se_px.max(1e-4),
            "{d:?}"
        );
        assert!(
            d.field_px < 3.0 * e.field_se_px,
            "{} ± {}",
            d.field_px,
            e.field_se_px
        );
        assert!(
            d.std_px < 3.0 * e.std_se_px,
            "{} ± {}",
            d.std_px,
            e.std_se_px
        );
        // The noise of each side is read back about its surface.
        assert!((d.measured_random_px.0 / 0.01 - 1.0).abs() < 0.1);
        assert!((d.model_random_px.1 / 0.01 - 1.0).abs() < 0.1);
    }

    #[test]
    fn a_scale_change_is_the_field_part_at_its_rms() {
        // u = s·(x − 320), v = s·(y − 240) with s = 1e-4: a linear field whose RMS about its mean
        // over the grid is s·√(var x + var y).
        let s = 1e-4;
        let measured = analysis(|x, y| (s * (x - 320.0), s * (y - 240.0)), 0.005, 3);
        let model = analysis(|_, _| (0.0, 0.0), 0.005, 4);
        let d = run_discrepancy(&measured, &model, 1.0);
        let var = |v: Vec<f64>| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64
        };
        let xs: Vec<f64> = measured.points.iter().map(|p| p.x).collect();
        let ys: Vec<f64> = measured.points.iter().map(|p| p.y).collect();
        let truth = s * (var(xs) + var(ys)).sqrt();
        let se = d.errors().field_se_px;
        assert!(
            (d.field_px - truth).abs() < 3.0 * se,
            "{} ± {se} against {truth}",
            d.field_px
        );
        assert!(d.rigid_px < 3.0 * d.errors().rigid_se_px.max(1e-5));
    }

    #[test]
    fn a_larger_random_error_is_the_std_part() {
        // The measured side is twice as noisy: Δσ = 0.01 px per component, √2 · 0.01 in all.
        let measured = analysis(|_, _| (0.2, 0.1), 0.02, 5);
        let model = analysis(|_, _| (0.2, 0.1), 0.01, 6);
        let d = run_discrepancy(&measured, &model, 1.0);
        let truth = 0.01 * 2f64.sqrt();
        let se = d.errors().std_se_px;
        assert!(
            (d.std_px - truth).abs() < 3.0 * se,
            "{} ± {se} against {truth}",
            d.std_px
        );
    }

    proptest::proptest! {
        /// The SE of a length from its square's variance: SE(D²)/(2D) for a clear signal, √SE(D²)
        /// at zero, and never negative.
        #[test]
        fn the_length_error_follows_its_square(d in 0.0f64..1.0, se_sq in 1e-12f64..1e-2) {
            let se = se_of_length(d, se_sq * se_sq);
            proptest::prop_assert!(se >= 0.0);
            proptest::prop_assert!(se <= se_sq.sqrt() + 1e-15);
            if d * d > 100.0 * se_sq {
                proptest::prop_assert!((se / (se_sq / (2.0 * d)) - 1.0).abs() < 0.03);
            }
        }
    }
}
