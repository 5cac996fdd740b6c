//! Lack of fit as a finding of its own: what a comparison leaves unexplained, whether it exceeds
//! what the noise and the model's own scatter predict, and what it looks like.
//!
//! **The field test.** Per run and scheme the field difference d = measured − model is fitted
//! with a quadratic surface per component (1, x, y, x², xy, y²); the ten non-constant terms'
//! Wald statistic W = (RSS about the mean − RSS about the surface)/(σ²·c) (σ² the residual
//! variance, c the covariance inflation of overlapping subsets) is what the model leaves in the
//! low orders. Under a right model that is noise plus the DIC's systematic error on one speckle
//! realisation — the same on the model's side as on the measured one. So the reference is the
//! same statistic of the difference between two renderings of the model with different seeds
//! (W₀, on the same points): both have the variance of twice one side's noise and realisation
//! error. F = W/W₀ is compared with F(K, K) (K = 10 per run and scheme, times the share of
//! independent analyses when runs share frames, `bic::shared_fraction`) at the stated false-alarm
//! rate through Paulson's normal approximation (Paulson, Ann. Math. Stat. 13 (1942)); W and W₀
//! share the model's first rendering, which narrows their ratio's scatter, so the test errs on the
//! quiet side.
//!
//! **The rigid test.** The debiased rigid part of the discrepancy (landings beyond the stage's
//! envelope, a bias the model lacks; RMS over runs) against z·SE at the same rate: a right model
//! scatters about zero. The field part is the field test's (its debiasing counts the noise, not
//! the model's own scatter, which the field test does); both are reported as `systematic_px`.
//! The random part (the difference of the two sides' random errors) is reported as a ratio
//! beside the tests and not judged: it is the print's and the noise's, which a model with a nominal print only
//! approximates (see `random_error_ratio`). W₀ is scaled to the measured side's error level for
//! the same reason (`side_ratio`).
//!
//! **The light test.** What the light did between a reference and its moved frames: per block
//! of the moved frame, its light against the reference's on the same part of the print
//! (`image_stats::light_map`), measured over the model's (`image_stats::light_change`), its χ²
//! about the frame's own constant, against the same between two renderings of the model, F
//! against F(K, K) at the same rate, K reduced for the blocks' estimated errors (`light_test`).
//! A lamp that drifted, a shadow, light that changed across the field leave it, and so does a
//! vignetting the model lacks (the print moved across it: a ramp along the move); the print's
//! texture divides out, and it sees no displacement.
//!
//! **The shape** ([`super::residual_shape`]): what the residual looks like, per run.

use super::discrepancy::CommonPoint;
use super::residual_shape::{shape_of, surface, Shape};
use super::results::{Comparison, RunComparison};
use super::unexplained_words::Finding;
use crate::reduce::Scheme;
use serde::{Deserialize, Serialize};

/// The false-alarm rate of both tests.
pub const FALSE_ALARM_RATE: f64 = 0.01;
/// The one-sided normal quantile of [`FALSE_ALARM_RATE`].
const Z_FALSE_ALARM: f64 = 2.326;
/// Non-constant terms of the quadratic surfaces of one run and scheme (5 per component).
const TERMS_PER_SAMPLE: f64 = 10.0;

/// What a comparison leaves unexplained.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Unexplained {
    /// A test (the low-order field, the rigid part, the light change) exceeds its threshold at
    /// [`FALSE_ALARM_RATE`].
    pub significant: bool,
    pub false_alarm_rate: f64,
    /// The comparison's discrepancy, px.
    pub discrepancy_px: f64,
    /// Its systematic parts (rigid and field, RMS over runs and schemes), px: what the test
    /// judges.
    pub systematic_px: f64,
    /// What a right model's rigid part stays below at the false-alarm rate: z·SE (the SE of the
    /// whole discrepancy, which errs on the quiet side), px.
    pub expected_px: f64,
    /// The rigid part over what a right model stays below (the rigid test fires above 1); 0
    /// when nothing is expected and nothing is there.
    pub ratio: f64,
    /// The measured random error over the model's (RMS over runs and both components): the
    /// print and the noise as the model draws them. Reported beside the tests, not judged by
    /// them: a print the model only approximates (hard disks against its Gaussian dots) gives
    /// a ratio far from 1 with nothing missing from the geometry. Absent when no run was
    /// measured on both sides.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub random_error_ratio: Option<f64>,
    /// The field test: F = W/W₀ and its threshold; absent without a second rendering.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub field_f: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub field_f_threshold: Option<f64>,
    /// The light test: the χ² of the moved frames' light change against the model over the same
    /// between two renderings of the model, and its threshold; absent without a second rendering
    /// or moved frames.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub light_f: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub light_f_threshold: Option<f64>,
    pub shape: Shape,
    /// Fitted stage nuisances no stage produces (a travel scale beyond ±[`MAX_TRAVEL_ERROR`], a
    /// misalignment beyond [`MAX_MISALIGNMENT_RAD`]): each makes the finding significant, since
    /// the comparison absorbed something else into them.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub implausible_stage: Vec<String>,
    /// The finding in words.
    pub summary: String,
}

/// The largest travel-scale error a stage shows (a lead screw or encoder off by this much is
/// broken, or the dataset's scale is wrong).
pub const MAX_TRAVEL_ERROR: f64 = 0.1;
/// The largest angle between the stage's axes and the sensor's a mount leaves unnoticed, rad (6°).
pub const MAX_MISALIGNMENT_RAD: f64 = 0.1;

/// What the fitted stage says that no stage does.
fn implausible_stage(cmp: &Comparison) -> Vec<String> {
    let n = &cmp.model.nominal;
    let mut out = Vec::new();
    if !((n.travel_scale - 1.0).abs() <= MAX_TRAVEL_ERROR) {
        out.push(format!(
            "the fitted travel scale is {:.4}: the stage moved {:.1} % {} than the manifest states, more than a stage errs (check the dataset's scale_px_per_mm and the runs' units)",
            n.travel_scale,
            100.0 * (n.travel_scale - 1.0).abs(),
            if n.travel_scale > 1.0 { "further" } else { "less far" }
        ));
    }
    if !(n.misalignment_rad.abs() <= MAX_MISALIGNMENT_RAD) {
        out.push(format!(
            "the fitted stage misalignment is {:.4} rad ({:.1}°): the moves point elsewhere than the manifest states (check the runs' axes and signs)",
            n.misalignment_rad,
            n.misalignment_rad.to_degrees()
        ));
    }
    out
}

/// The field statistic of one run and scheme's points (d per component given by `value`).
struct FieldStat {
    /// Σ W over the samples.
    w: f64,
    samples: usize,
    /// Share of independent analyses among those that contributed.
    shared_fraction: f64,
}

/// W of one run and scheme for the differences `d` at `points` (analysed px).
fn sample_w(
    points: &[(f64, f64)],
    du: &[f64],
    dv: &[f64],
    var: (f64, f64),
    infl: f64,
) -> Option<f64> {
    if !(var.0 > 0.0 && var.1 > 0.0) {
        return None;
    }
    let (_, ru) = surface(points, du)?;
    let (_, rv) = surface(points, dv)?;
    Some((ru / var.0 + rv / var.1) / infl)
}

impl Unexplained {
    /// The low-order field test alone fired: what a verdict's signature is judged by.
    pub fn field_significant(&self) -> bool {
        fires(self.field_f.zip(self.field_f_threshold))
    }
}

/// Whether the field test's F exceeds its threshold.
fn fires(field: Option<(f64, f64)>) -> bool {
    field.is_some_and(|(f, t)| f > t)
}

/// The field statistic W of a comparison (summed over its runs and schemes).
pub fn field_w(cmp: &Comparison, infl: f64) -> f64 {
    field_stat(cmp, infl).w
}

fn field_stat(cmp: &Comparison, infl: f64) -> FieldStat {
    let mut stat = FieldStat {
        w: 0.0,
        samples: 0,
        shared_fraction: 1.0,
    };
    let mut used: Vec<(&str, &str)> = Vec::new();
    for r in &cmp.runs {
        let pts: Vec<(f64, f64)> = r.detail.common.iter().map(|p| (p.x, p.y)).collect();
        let du: Vec<f64> = r.detail.common.iter().map(|p| p.du).collect();
        let dv: Vec<f64> = r.detail.common.iter().map(|p| p.dv).collect();
        if let Some(w) = sample_w(&pts, &du, &dv, r.detail.residual_var_px2, infl) {
            stat.w += w;
            stat.samples += 1;
            used.push((r.id.as_str(), r.pattern.as_str()));
        }
    }
    stat.shared_fraction = super::bic::shared_fraction_of(used.into_iter());
    stat
}

/// What a right model leaves, from two renderings of it with different seeds: the reference
/// statistics of the field test and of the light test.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ModelScatter {
    /// W₀ ([`field_scatter`]).
    pub field_w: Option<f64>,
    /// χ² of the moved frames' light change between the two renderings
    /// ([`super::bic::light_change_between`]).
    pub light_chi2: Option<f64>,
}

/// The model's own scatter between renderings `first` and `second` of it.
pub fn model_scatter(first: &Comparison, second: &Comparison, infl: f64) -> ModelScatter {
    ModelScatter {
        field_w: field_scatter(first, second, infl),
        light_chi2: super::bic::light_change_between(first, second),
    }
}

/// The reference statistic W₀: the difference between two renderings of the model (their field
/// differences against the same measurement, subtracted at the points both hold).
fn field_scatter(first: &Comparison, second: &Comparison, infl: f64) -> Option<f64> {
    let mut w0 = 0.0;
    let mut samples = 0;
    for (a, b) in first.runs.iter().zip(&second.runs) {
        if a.id != b.id || a.scheme != b.scheme {
            continue;
        }
        let by_index: std::collections::HashMap<usize, &CommonPoint> =
            b.detail.common.iter().map(|p| (p.index, p)).collect();
        let (mut pts, mut du, mut dv) = (Vec::new(), Vec::new(), Vec::new());
        for p in &a.detail.common {
            if let Some(q) = by_index.get(&p.index) {
                pts.push((p.x, p.y));
                du.push(p.du - q.du);
                dv.push(p.dv - q.dv);
            }
        }
        if let Some(w) = sample_w(&pts, &du, &dv, a.detail.residual_var_px2, infl) {
            w0 += w * side_ratio(a);
            samples += 1;
        }
    }
    (samples > 0 && w0 > 0.0).then_some(w0)
}

/// (σm² + σo²)/(2σo²) of a run: the measured side's errors against the model's. W holds one of
/// each side, W₀ two of the model's; where the measured print gives larger errors than the
/// model's (a print the model only approximates), W₀ is scaled up to the measured side's level
/// so that the test asks about the low-order field, not about the random error, which
/// `random_error_ratio` reports.
fn side_ratio(r: &RunComparison) -> f64 {
    let m = r.measured.random_px[0].powi(2) + r.measured.random_px[1].powi(2);
    let o = r.model.random_px[0].powi(2) + r.model.random_px[1].powi(2);
    if o > 0.0 && m.is_finite() {
        ((m + o) / (2.0 * o)).max(0.5)
    } else {
        1.0
    }
}

/// The upper quantile of F(d1, d2) at [`FALSE_ALARM_RATE`], by Paulson's approximation solved
/// for F (bisection on the monotone z(F)).
fn f_threshold(d1: f64, d2: f64) -> f64 {
    let z = |f: f64| {
        let (a, b) = (2.0 / (9.0 * d1), 2.0 / (9.0 * d2));
        let c = f.cbrt();
        ((1.0 - b) * c - (1.0 - a)) / (a + c * c * b).sqrt()
    };
    let (mut lo, mut hi) = (1.0, 100.0);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if z(mid) < Z_FALSE_ALARM {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// What `cmp` leaves unexplained; `scatter` is the model's own ([`model_scatter`], the default
/// when only one rendering was made), `se_px` the discrepancy's standard error.
pub fn unexplained(
    cmp: &Comparison,
    schemes: &[Scheme],
    scatter: &ModelScatter,
    se_px: f64,
    infl: f64,
) -> Unexplained {
    let w0 = scatter.field_w;
    let stat = field_stat(cmp, infl);
    // The analyses share frames (every run of a pattern its reference): their low-order fields
    // are correlated, and the statistic holds N_eff/N of the independent terms it sums.
    let k = (TERMS_PER_SAMPLE * stat.samples as f64 * stat.shared_fraction).max(TERMS_PER_SAMPLE);
    let (field_f, field_f_threshold) = match w0 {
        Some(w0) if stat.samples > 0 => (Some(stat.w / w0), Some(f_threshold(k, k))),
        _ => (None, None),
    };
    let expected_px = Z_FALSE_ALARM * se_px;
    let field = field_f.zip(field_f_threshold);
    let field_significant = fires(field);
    let light = light_test(cmp, scatter);
    let light_significant = fires(light);
    let systematic_px = systematic(cmp);
    let rigid_px = rigid(cmp);
    let discrepancy_significant = rigid_px > expected_px;
    let random_error_ratio = random_ratio(cmp);
    let shape = shape_of(cmp, schemes, infl);
    let implausible_stage = implausible_stage(cmp);
    let significant = field_significant
        || discrepancy_significant
        || light_significant
        || !implausible_stage.is_empty();
    let summary = super::unexplained_words::summary(&Finding {
        significant,
        false_alarm_rate: FALSE_ALARM_RATE,
        field,
        field_fired: field_significant,
        light,
        light_fired: light_significant,
        rigid_px,
        rigid_fired: discrepancy_significant,
        expected_px,
        random_error_ratio,
        implausible_stage: &implausible_stage,
        shape: &shape,
    });
    Unexplained {
        significant,
        false_alarm_rate: FALSE_ALARM_RATE,
        discrepancy_px: cmp.discrepancy_px,
        systematic_px,
        expected_px,
        ratio: if expected_px > 0.0 {
            rigid_px / expected_px
        } else {
            0.0
        },
        random_error_ratio,
        field_f,
        field_f_threshold,
        light_f: light.map(|l| l.0),
        light_f_threshold: light.map(|l| l.1),
        shape,
        summary,
        implausible_stage,
    }
}

/// Degrees of freedom of a light-change block's standard error: each side's from the scatter of
/// its four quarter-blocks (3), two sides (Welch–Satterthwaite, for comparable errors: 6).
const LIGHT_SE_DOF: f64 = 6.0;

/// The light test: the moved frames' light change against the model ([`super::bic`]'s
/// `light_change_of`, in the comparison's χ²) over the same between two renderings of the model,
/// against F(K, K) at the false-alarm rate. K is its observations (each moved frame weighed
/// 1/moved frames of its pattern: the frames share their reference, so the test errs on the
/// quiet side) times (ν − 4)/(ν − 1), ν = [`LIGHT_SE_DOF`]: each term is a Student t² with ν
/// degrees of freedom, whose relative variance 2(ν − 1)/(ν − 4) is that of a χ² of
/// (ν − 4)/(ν − 1) degrees of freedom per term (5/2 times χ²₁'s at ν = 6). Measured on 30
/// controls with nothing hidden: ln F scattered by 0.36 about 0.0, where F(63, 63) scatters by
/// 0.25 and F(25, 25) by 0.40; at K = 63 one of 30 fired (F 1.92 against 1.81).
/// None without a second rendering or without moved frames.
fn light_test(cmp: &Comparison, scatter: &ModelScatter) -> Option<(f64, f64)> {
    let (chi2, n) = cmp.chi2.image_parts[super::bic::LIGHT_CHANGE];
    let reference = scatter.light_chi2?;
    let k = n as f64 * (LIGHT_SE_DOF - 4.0) / (LIGHT_SE_DOF - 1.0);
    (n > 0 && reference > 0.0).then(|| (chi2 / reference, f_threshold(k.max(1.0), k.max(1.0))))
}

/// The systematic parts of the discrepancy: √(rigid² + field²), RMS over runs and schemes.
fn systematic(cmp: &Comparison) -> f64 {
    rms(cmp.runs.iter().map(|r| r.rigid_px.hypot(r.field_px)))
}

/// RMS of the finite values (an unmeasurable run's parts are NaN); 0 with none.
fn rms(values: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = values
        .filter(|v| v.is_finite())
        .fold((0.0, 0usize), |(s, n), v| (s + v * v, n + 1));
    if n == 0 {
        0.0
    } else {
        (sum / n as f64).sqrt()
    }
}

/// The rigid part (RMS over runs and schemes): landings and biases the field test does not see.
fn rigid(cmp: &Comparison) -> f64 {
    rms(cmp.runs.iter().map(|r| r.rigid_px))
}

/// RMS of the measured random error over RMS of the model's.
fn random_ratio(cmp: &Comparison) -> Option<f64> {
    let both: Vec<(f64, f64)> = cmp
        .runs
        .iter()
        .map(|r| {
            let sq = |x: [f64; 2]| x[0] * x[0] + x[1] * x[1];
            (sq(r.measured.random_px), sq(r.model.random_px))
        })
        .filter(|(m, o)| m.is_finite() && o.is_finite())
        .collect();
    let (m, o) = both
        .iter()
        .fold((0.0, 0.0), |(a, b), (m, o)| (a + m, b + o));
    (o > 0.0).then(|| (m / o).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_f_threshold_matches_tabulated_quantiles() {
        // F(0.99; 10, 10) = 4.85, F(0.99; 60, 60) = 1.84, F(0.99; 120, 120) = 1.53 (tables).
        for (d, q) in [(10.0, 4.85), (60.0, 1.84), (120.0, 1.53)] {
            let t = f_threshold(d, d);
            assert!((t - q).abs() < 0.05 * q, "F({d}, {d}) = {t}, table {q}");
        }
    }
}
