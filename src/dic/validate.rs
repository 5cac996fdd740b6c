//! Whether a correlated point can be trusted: its own evidence (ZNCC, a plausible shape, a
//! texture that pins its position down) and its neighbours' (the normalised median test).

use super::{DicSettings, PoiResult, PoiStatus};
use crate::stats::median;

/// Largest displacement gradient a subset may converge to. Beyond ±0.5 (a 50 % strain, or a
/// 30° rotation between neighbouring images) a first-order subset match is not a measurement
/// but IC-GN sliding to a degenerate shape.
pub const MAX_PLAUSIBLE_GRADIENT: f64 = 0.5;

/// Minimum normalisation level ε of the median test, px: the acceptable fluctuation of a valid
/// point (Westerweel & Scarano 2005 use 0.1 px).
pub const MEDIAN_TEST_EPSILON_PX: f64 = 0.1;

/// Points correlating at least this well are never judged against the field's median ZNSSD:
/// on noise-free images the median is tiny and ordinary interpolation misfit would exceed any
/// multiple of it.
pub const RELATIVE_ZNCC_FLOOR: f64 = 0.9;

/// Indices of valid points whose ZNSSD exceeds `ratio` times the median ZNSSD of all valid
/// points (and whose ZNCC is below [`RELATIVE_ZNCC_FLOOR`]). With noise alone the ZNSSD of a
/// subset is ≈ 2σ²/σ_f², much alike over a speckle pattern; a subset that holds two motions,
/// or material the deformed image hides, matches in part and leaves a residual an order of
/// magnitude larger — while its ZNCC can still pass an absolute threshold.
pub fn relative_correlation_failures(points: &[PoiResult], ratio: f64) -> Vec<usize> {
    let mut znssd: Vec<f64> = points
        .iter()
        .filter(|p| p.status.is_valid())
        .map(|p| 2.0 * (1.0 - p.zncc))
        .collect();
    if znssd.is_empty() {
        return Vec::new();
    }
    let limit = ratio * median(&mut znssd);
    points
        .iter()
        .enumerate()
        .filter(|(_, p)| {
            p.status.is_valid() && p.zncc < RELATIVE_ZNCC_FLOOR && 2.0 * (1.0 - p.zncc) > limit
        })
        .map(|(k, _)| k)
        .collect()
}

/// A subset whose grey-level standard deviation is below this many times the image noise holds
/// no texture a correlation could follow: noise alone gives a ratio of ≈ 1, and a match on it
/// is a match of noise.
pub const MIN_TEXTURE_TO_NOISE: f64 = 3.0;

/// The noise standard deviation of one (pre-filtered) image, from the valid points' fit
/// residuals: the ZNSSD residual Σ r² = ZNSSD·Σ(f − f̄)² holds the noise of both images, so
/// its per-pixel variance is ≈ 2σ². The median over points makes it robust to the few that
/// misfit. None without valid points.
pub fn noise_std(points: &[PoiResult], subset_std: &[f64], subset_pixels: usize) -> Option<f64> {
    let n = subset_pixels as f64;
    let mut var: Vec<f64> = points
        .iter()
        .zip(subset_std)
        .filter(|(p, _)| p.status.is_valid())
        .map(|(p, sd)| 2.0 * (1.0 - p.zncc) * sd * sd * n / (n - 6.0).max(1.0) / 2.0)
        .collect();
    if var.is_empty() {
        return None;
    }
    Some(median(&mut var).max(0.0).sqrt())
}

/// The status a converged point earns from its own evidence alone.
pub fn own_status(p: &PoiResult, settings: &DicSettings) -> PoiStatus {
    if p.status != PoiStatus::Converged {
        return p.status;
    }
    if !(p.zncc >= settings.min_zncc) {
        return PoiStatus::LowCorrelation;
    }
    if !(p.u_std_px <= settings.max_displacement_std_px
        && p.v_std_px <= settings.max_displacement_std_px)
    {
        return PoiStatus::NoTexture;
    }
    let gradients = [p.du_dx, p.du_dy, p.dv_dx, p.dv_dy];
    if !gradients.iter().all(|g| g.abs() <= MAX_PLAUSIBLE_GRADIENT) {
        return PoiStatus::Implausible;
    }
    PoiStatus::Converged
}

/// The normalised median test of Westerweel & Scarano, "Universal outlier detection for PIV
/// data", Exp. Fluids 39 (2005), on the 3x3 neighbourhood. Each valid neighbour predicts the
/// centre's displacement through its own first-order shape (so a uniform strain or rotation
/// gives identical predictions, not a spread); the residual of the centre against their
/// median, normalised by the median residual of the predictions plus ε, must stay below
/// `threshold` for u and for v. A point with fewer than two valid neighbours where the grid
/// offers three or more cannot be confirmed and fails too.
///
/// Returns the indices (row-major over an `nx` x `ny` grid) that fail; the field is judged as
/// a whole, so one outlier does not condemn its neighbours in turn.
pub fn median_test_failures(
    points: &[PoiResult],
    nx: usize,
    ny: usize,
    threshold: f64,
) -> Vec<usize> {
    let mut failures = Vec::new();
    let mut pu = Vec::with_capacity(8);
    let mut pv = Vec::with_capacity(8);
    for j in 0..ny {
        for i in 0..nx {
            let k = j * nx + i;
            let centre = &points[k];
            if !centre.status.is_valid() {
                continue;
            }
            pu.clear();
            pv.clear();
            let mut neighbours_in_grid = 0;
            for jj in j.saturating_sub(1)..=(j + 1).min(ny - 1) {
                for ii in i.saturating_sub(1)..=(i + 1).min(nx - 1) {
                    if (ii, jj) == (i, j) {
                        continue;
                    }
                    neighbours_in_grid += 1;
                    let n = &points[jj * nx + ii];
                    if !n.status.is_valid() {
                        continue;
                    }
                    let (dx, dy) = (centre.x - n.x, centre.y - n.y);
                    pu.push(n.u + n.du_dx * dx + n.du_dy * dy);
                    pv.push(n.v + n.dv_dx * dx + n.dv_dy * dy);
                }
            }
            if pu.len() < 2 {
                if neighbours_in_grid >= 3 {
                    failures.push(k);
                }
                continue;
            }
            let fails = |predictions: &mut Vec<f64>, value: f64| {
                let m = median(predictions);
                let mut residuals: Vec<f64> = predictions.iter().map(|p| (p - m).abs()).collect();
                let rm = median(&mut residuals);
                (value - m).abs() / (rm + MEDIAN_TEST_EPSILON_PX) > threshold
            };
            if fails(&mut pu, centre.u) || fails(&mut pv, centre.v) {
                failures.push(k);
            }
        }
    }
    failures
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field(nx: usize, ny: usize, u: impl Fn(f64, f64) -> f64) -> Vec<PoiResult> {
        let mut out = Vec::new();
        for j in 0..ny {
            for i in 0..nx {
                let (x, y) = (10.0 * i as f64, 10.0 * j as f64);
                let mut p = PoiResult::invalid(x, y, PoiStatus::Converged, 0.99, 3);
                p.u = u(x, y);
                p.v = 0.0;
                // The gradients of a linear field, as IC-GN would report them.
                p.du_dx = (u(x + 1.0, y) - u(x - 1.0, y)) / 2.0;
                p.du_dy = (u(x, y + 1.0) - u(x, y - 1.0)) / 2.0;
                p.dv_dx = 0.0;
                p.dv_dy = 0.0;
                out.push(p);
            }
        }
        out
    }

    #[test]
    fn a_strong_linear_field_has_no_outliers_and_a_wrong_point_is_found() {
        let mut pts = field(7, 7, |x, y| 0.1 * x - 0.05 * y + 3.0);
        assert!(median_test_failures(&pts, 7, 7, 2.0).is_empty());
        pts[3 * 7 + 3].u += 0.5;
        assert_eq!(median_test_failures(&pts, 7, 7, 2.0), vec![3 * 7 + 3]);
    }

    #[test]
    fn an_isolated_point_cannot_be_confirmed() {
        let mut pts = field(3, 3, |_, _| 1.0);
        for (k, p) in pts.iter_mut().enumerate() {
            if k != 4 {
                p.status = PoiStatus::LowCorrelation;
            }
        }
        assert_eq!(median_test_failures(&pts, 3, 3, 2.0), vec![4]);
    }

    #[test]
    fn a_partial_match_is_judged_against_the_field() {
        let mut pts = field(5, 5, |_, _| 0.0);
        for p in pts.iter_mut() {
            p.zncc = 0.99;
        }
        pts[7].zncc = 0.7;
        pts[8].zncc = 0.95;
        assert_eq!(relative_correlation_failures(&pts, 10.0), vec![7]);
    }

    #[test]
    fn own_evidence() {
        let s = DicSettings::default();
        let mut p = PoiResult::invalid(0.0, 0.0, PoiStatus::Converged, 0.99, 3);
        (p.u_std_px, p.v_std_px) = (0.01, 0.01);
        (p.du_dx, p.du_dy, p.dv_dx, p.dv_dy) = (0.0, 0.0, 0.0, 0.0);
        assert_eq!(own_status(&p, &s), PoiStatus::Converged);
        p.du_dy = 0.7;
        assert_eq!(own_status(&p, &s), PoiStatus::Implausible);
        p.du_dy = 0.0;
        p.v_std_px = 0.5;
        assert_eq!(own_status(&p, &s), PoiStatus::NoTexture);
        p.zncc = 0.3;
        assert_eq!(own_status(&p, &s), PoiStatus::LowCorrelation);
    }
}
