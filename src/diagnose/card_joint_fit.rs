//! The card's joint fit of every geometric term (issue 33): rotation, scale, target tilt, k1,
//! p1, p2 admitted in that order, each only when the runs tell it from those already in, then k2
//! when its Wald χ² pays the BIC's price (ln n); a term left out is named, not fitted.

use super::basis::GeometricParam;
use super::fit_geometric::{fit_geometric, FieldSample, GeometricFit};

/// The joint fit's terms in the order they are admitted: each stays when the runs tell it from
/// those already in.
pub const JOINT_ORDER: [GeometricParam; 7] = [
    GeometricParam::Rotation,
    GeometricParam::Scale,
    GeometricParam::TiltSlopeY,
    GeometricParam::TiltSlopeX,
    GeometricParam::DistortionK1,
    GeometricParam::DistortionP1,
    GeometricParam::DistortionP2,
];

/// Every term of [`JOINT_ORDER`] the runs tell from those before it, then k2 when its Wald χ²
/// pays ln n; the terms left out, named.
pub fn joint_fit(
    samples: &[FieldSample],
    observations: usize,
) -> (Option<GeometricFit>, Vec<String>) {
    let mut kept: Vec<GeometricParam> = Vec::new();
    let mut left_out = Vec::new();
    let named = |p: GeometricParam| {
        let (effect, name) = p.effect_and_name();
        format!("{effect}.{name}: not identifiable apart from the other terms with these runs")
    };
    for p in JOINT_ORDER {
        let mut trial = kept.clone();
        trial.push(p);
        if fit_geometric(samples, &trial).is_some() {
            kept = trial;
        } else {
            left_out.push(named(p));
        }
    }
    let Some(mut fit) = fit_geometric(samples, &kept) else {
        return (None, left_out);
    };
    let mut wider = kept.clone();
    wider.push(GeometricParam::DistortionK2);
    match fit_geometric(samples, &wider) {
        Some(w) => {
            let (k2, se) = (w.values[kept.len()], w.stderr[kept.len()]);
            if (k2 / se).powi(2) > (observations.max(2) as f64).ln() {
                fit = w;
            }
        }
        None => left_out.push(named(GeometricParam::DistortionK2)),
    }
    (Some(fit), left_out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::test_fields::{field_runs, lens_field, run_samples};
    use crate::reduce::Scheme;
    use GeometricParam as P;

    /// The moved frame turned by θ and magnified by 1 + s (p + t lands at R(θ)(1 + s)(p + t)),
    /// seen through a lens of radial distortion k1 about the image centre: the field the baseline
    /// lacks at p for the move t.
    fn camera(theta: f64, s: f64, k1: f64) -> impl Fn((f64, f64), (f64, f64)) -> (f64, f64) + Copy {
        move |p, t| {
            let (x, y) = ((1.0 + s) * (p.0 + t.0), (1.0 + s) * (p.1 + t.1));
            let (sin, cos) = theta.sin_cos();
            let lens = lens_field(p, t, (0.0, 0.0), (k1, 0.0));
            (
                cos * x - sin * y - p.0 - t.0 + lens.0,
                sin * x + cos * y - p.1 - t.1 + lens.1,
            )
        }
    }

    #[test]
    fn the_joint_fit_finds_each_term_of_the_camera_beside_the_others() {
        // Rotation −3e-5, scale 2e-5 and k1 2e-3 at once; moves of two sizes along x and y
        // identify every term, and the ones the camera lacks (tilt, decentring) stay within
        // three errors of zero.
        let (theta, s, k1) = (-3e-5, 2e-5, 2e-3);
        let moves = [(130.0, 0.0), (0.0, 130.0), (65.0, 0.0), (0.0, -65.0)];
        let points = field_runs(&moves, camera(theta, s, k1), 0.01, 20);
        let native = Scheme::parse("native").unwrap();
        let samples = run_samples(&native, &moves, &points, 1e-4);
        let observations = 2 * points.iter().map(Vec::len).sum::<usize>();
        let (fit, left_out) = joint_fit(&samples, observations);
        let fit = fit.unwrap();
        assert!(left_out.is_empty(), "{left_out:?}");
        assert_eq!(&fit.params[..JOINT_ORDER.len()], &JOINT_ORDER[..]);
        for &p in &fit.params {
            let truth = match p {
                P::Rotation => theta,
                P::Scale => s,
                P::DistortionK1 => k1,
                _ => 0.0,
            };
            within_3_errors(&fit, p, truth);
        }
    }

    /// The fit's value of `p` lies within three of its standard errors of `truth`.
    fn within_3_errors(fit: &GeometricFit, p: GeometricParam, truth: f64) {
        let (v, se) = fit.value(p).unwrap();
        assert!(
            (v - truth).abs() < 3.0 * se,
            "{p:?} = {v} ± {se} against {truth}"
        );
    }

    #[test]
    fn one_move_along_x_cannot_tell_decentring_from_rotation_tilt_and_scale() {
        // For t = (tx, 0) the decentring fields are affine: p1 gives (2y, 2x)·tx/r0, a shear,
        // which rotation (−y, x) and the tilt's (−y·tx, 0) make up; p2 gives (6x, 2y)·tx/r0,
        // which scale (x, y) and the tilt's (−2x·tx, −y·tx) make up. Both are named, not fitted.
        let (theta, s) = (-3e-5, 2e-5);
        let moves = [(130.0, 0.0), (130.0, 0.0)];
        let points = field_runs(&moves, camera(theta, s, 0.0), 0.01, 20);
        let native = Scheme::parse("native").unwrap();
        let samples = run_samples(&native, &moves, &points, 1e-4);
        let (fit, left_out) = joint_fit(&samples, 2 * 2 * points[0].len());
        let named = |term: &str| {
            format!("lens_distortion.{term}: not identifiable apart from the other terms with these runs")
        };
        assert_eq!(left_out, vec![named("p1"), named("p2")]);
        let fit = fit.unwrap();
        assert!(!fit.params.contains(&P::DistortionP1) && !fit.params.contains(&P::DistortionP2));
        within_3_errors(&fit, P::Rotation, theta);
        within_3_errors(&fit, P::Scale, s);
    }
}
