//! Geometric candidates by weighted linear least squares: the difference of the displacement
//! fields (measured − model) of every run and scheme, stacked, against the candidate's basis field,
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
    pub param: GeometricParam,
    pub value: f64,
    pub stderr: f64,
    /// Wald statistic (value/stderr)²: the χ² the candidate explains beyond the nuisances.
    pub chi2_drop: f64,
}

/// Weighted sums of one run and scheme, centred on its own means (the per-run constant offsets
/// are nuisances: sub-pixel bias, travel, misalignment).
fn centred_sums(s: &FieldSample, param: GeometricParam) -> Option<(f64, f64)> {
    if !(s.var.0 > 0.0 && s.var.1 > 0.0) || s.points.len() < 3 {
        return None;
    }
    let (bx, by) = (s.scheme.x.block as f64, s.scheme.y.block as f64);
    let rows: Vec<((f64, f64), (f64, f64))> = s
        .points
        .iter()
        .map(|p| {
            let (fx, fy) = s.scheme.to_full(p.x, p.y);
            let (u, v) =
                geometric_basis(param, (fx - s.centre.0, fy - s.centre.1), s.move_px, s.r0);
            ((u / bx, v / by), (p.du, p.dv))
        })
        .collect();
    let n = rows.len() as f64;
    type Row = ((f64, f64), (f64, f64));
    let mean = |f: &dyn Fn(&Row) -> f64| rows.iter().map(f).sum::<f64>() / n;
    let (mbu, mbv, mdu, mdv) = (
        mean(&|r| r.0 .0),
        mean(&|r| r.0 .1),
        mean(&|r| r.1 .0),
        mean(&|r| r.1 .1),
    );
    let (mut bb, mut bd) = (0.0, 0.0);
    for ((bu, bv), (du, dv)) in &rows {
        let (bu, bv, du, dv) = (bu - mbu, bv - mbv, du - mdu, dv - mdv);
        bb += bu * bu / s.var.0 + bv * bv / s.var.1;
        bd += bu * du / s.var.0 + bv * dv / s.var.1;
    }
    (bb > 0.0).then_some((bb, bd))
}

/// Fits one candidate parameter on the field differences with every run's and scheme's constant
/// offsets removed (Frisch–Waugh: equivalent to fitting them as nuisances). The standard error is
/// the largest of the least-squares one (inflated for correlated points), the one that counts the
/// frames the analyses share, and, with three or more runs and schemes, the scatter of the
/// per-run estimates about their weighted mean: a real effect is the same in every run, a speckle
/// realisation's systematic error is not.
pub fn fit_geometric(samples: &[FieldSample], param: GeometricParam) -> Option<GeometricFit> {
    let sums: Vec<(f64, f64, f64, usize, usize)> = samples
        .iter()
        .filter_map(|s| {
            centred_sums(s, param).map(|(bb, bd)| (bb, bd, s.inflation.max(1.0), s.pattern, s.run))
        })
        .collect();
    let bb: f64 = sums.iter().map(|s| s.0).sum();
    let bd: f64 = sums.iter().map(|s| s.1).sum();
    if !(bb > 0.0) {
        return None;
    }
    let inflation = sums.iter().map(|s| s.2).fold(1.0, f64::max);
    let value = bd / bb;
    // Half of a field difference's noise comes from the reference frames (shared by every run of
    // a pattern), half from the moved frames (shared by every scheme of a run): for similar basis
    // fields the variance of the estimate is ½·c·[Σ_runs(Σ√bb)² + Σ_patterns(Σ√bb)²]/(Σbb)².
    type Sums = (f64, f64, f64, usize, usize);
    let grouped = |key: &dyn Fn(&Sums) -> usize| -> f64 {
        let mut acc: std::collections::BTreeMap<usize, f64> = Default::default();
        for s in &sums {
            *acc.entry(key(s)).or_default() += s.0.sqrt();
        }
        acc.values().map(|x| x * x).sum()
    };
    let shared = 0.5 * inflation * (grouped(&|s| s.4) + grouped(&|s| s.3)) / (bb * bb);
    let mut var = (inflation / bb).max(shared);
    if sums.len() >= 3 {
        // Per-run estimates β_r = bd_r/bb_r with weights bb_r.
        let chi: f64 = sums.iter().map(|s| s.0 * (s.1 / s.0 - value).powi(2)).sum();
        let between = chi / ((sums.len() - 1) as f64 * bb);
        var = var.max(between);
    }
    Some(GeometricFit {
        param,
        value,
        stderr: var.sqrt(),
        chi2_drop: value * value / var,
    })
}
