//! Radial distortion about a centre of its own, for the camera card. The linear fit reads an
//! off-centre distortion centre c as the decentring terms p1, p2 (to first order in c: p2 =
//! −k1·cx/r0, p1 = −k1·cy/r0, `basis`); the second-order terms it leaves then pose as a k2 and
//! bias the stage's scale (measured with c = (40, −30) px on a 640x540 sensor: a k2 of
//! −1.2e-4 ± 0.4e-4 marked significant where the truth has none, the scale low by 0.03 %). Where
//! the linear fit finds k1, the card fits the centre itself — Brown's radial model about the
//! principal point (Brown, Photogramm. Eng. 37 (1971)) — by Gauss–Newton on the same field
//! differences ([`super::gauss_newton`]), with the other geometric terms beside it, and k2 only
//! when it pays the BIC's price. A lens with true decentring (tangential) distortion about the
//! image centre fits such a centre to first order as well: translations alone cannot tell them
//! apart, which the card says.

use super::basis::{geometric_basis, GeometricParam};
use super::fit_geometric::{FieldSample, GeometricFit};
use super::gauss_newton::gauss_newton;

/// The distortion about a fitted centre: each value with its standard error.
#[derive(Clone, Debug, PartialEq)]
pub struct CentredDistortion {
    pub k1: (f64, f64),
    pub k2: Option<(f64, f64)>,
    /// The centre, px from the image centre (x, y).
    pub centre_px: [(f64, f64); 2],
}

/// The card's geometry: linear terms, and the distortion about its own centre when fitted.
#[derive(Clone, Debug, PartialEq)]
pub struct CardGeometry {
    pub linear: GeometricFit,
    pub centred: Option<CentredDistortion>,
    /// The distortion's normalising radius, px.
    pub r0: f64,
}

impl CardGeometry {
    /// The fitted field at `p` (px from the image centre) for the move `t`, px.
    pub fn displacement(&self, p: (f64, f64), t: (f64, f64)) -> (f64, f64) {
        let (mut u, mut v) = self.linear.field_at(p, t, self.r0);
        if let Some(c) = &self.centred {
            let k2 = c.k2.map_or(0.0, |k| k.0);
            let (du, dv) = radial_difference(
                p,
                t,
                (c.centre_px[0].0, c.centre_px[1].0),
                (c.k1.0, k2),
                self.r0,
            );
            u += du;
            v += dv;
        }
        (u, v)
    }
}

/// The displacement of radial distortion (k1, k2) about `centre`, at q (px from the image
/// centre).
fn radial(q: (f64, f64), centre: (f64, f64), (k1, k2): (f64, f64), r0: f64) -> (f64, f64) {
    let (x, y) = (q.0 - centre.0, q.1 - centre.1);
    let r2 = (x * x + y * y) / (r0 * r0);
    let f = k1 * r2 + k2 * r2 * r2;
    (x * f, y * f)
}

/// What a move `t` changes of it at the reference position `p`. The DIC measures at image
/// (distorted) positions, the distortion acts on ideal ones: `p` is taken back to the ideal
/// position first (two fixed-point steps: the error is of order k1³). Evaluated at the image
/// position instead, the field is off by terms of order k1² r⁵ that a fit reads as a k2 (measured:
/// −1.2e-4 ± 0.2e-4 for k1 = −0.01 and no k2).
fn radial_difference(
    p: (f64, f64),
    t: (f64, f64),
    centre: (f64, f64),
    k: (f64, f64),
    r0: f64,
) -> (f64, f64) {
    let mut ideal = p;
    for _ in 0..2 {
        let d = radial(ideal, centre, k, r0);
        ideal = (p.0 - d.0, p.1 - d.1);
    }
    let a = radial((ideal.0 + t.0, ideal.1 + t.1), centre, k, r0);
    let b = radial(ideal, centre, k, r0);
    (a.0 - b.0, a.1 - b.1)
}

fn is_distortion(p: GeometricParam) -> bool {
    matches!(
        p,
        GeometricParam::DistortionK1
            | GeometricParam::DistortionK2
            | GeometricParam::DistortionP1
            | GeometricParam::DistortionP2
    )
}

/// The card's geometry from the linear joint fit: the distortion refitted about its own centre
/// when the fit holds k1 (beyond two standard errors) and p1, p2, else the linear fit as it is.
pub fn card_geometry(
    samples: &[FieldSample],
    linear: GeometricFit,
    r0: f64,
    observations: usize,
) -> CardGeometry {
    let as_is = |linear: GeometricFit| CardGeometry {
        linear,
        centred: None,
        r0,
    };
    let (Some((k1, k1_se)), Some((p1, _)), Some((p2, _))) = (
        linear.value(GeometricParam::DistortionK1),
        linear.value(GeometricParam::DistortionP1),
        linear.value(GeometricParam::DistortionP2),
    ) else {
        return as_is(linear);
    };
    if k1.abs() <= 2.0 * k1_se {
        return as_is(linear);
    }
    let others: Vec<usize> = (0..linear.params.len())
        .filter(|&i| !is_distortion(linear.params[i]))
        .collect();
    let params: Vec<GeometricParam> = others.iter().map(|&i| linear.params[i]).collect();
    let n = params.len();
    let fit = |with_k2: bool| {
        let field = |p: (f64, f64), t: (f64, f64), values: &[f64]| {
            let (mut u, mut v) = radial_difference(
                p,
                t,
                (values[n + 1], values[n + 2]),
                (values[n], if with_k2 { values[n + 3] } else { 0.0 }),
                r0,
            );
            for (q, value) in params.iter().zip(values) {
                let (bu, bv) = geometric_basis(*q, p, t, r0);
                u += value * bu;
                v += value * bv;
            }
            (u, v)
        };
        let mut start: Vec<f64> = others.iter().map(|&i| linear.values[i]).collect();
        start.extend([k1, -p2 * r0 / k1, -p1 * r0 / k1]);
        let mut ranges = vec![(f64::NEG_INFINITY, f64::INFINITY); n];
        ranges.extend([(-1.0, 1.0), (-r0, r0), (-r0, r0)]);
        // Central differences are exact for the linear terms at any step; the centre's, in px.
        let mut step: Vec<f64> = others
            .iter()
            .map(|&i| linear.stderr[i].max(1e-12))
            .collect();
        step.extend([k1_se.max(1e-9), 1e-2, 1e-2]);
        if with_k2 {
            start.push(0.0);
            ranges.push((-1.0, 1.0));
            step.push(k1_se.max(1e-9));
        }
        gauss_newton(samples, &field, start, &ranges, &step)
    };
    let Some((values, without)) = fit(false) else {
        return as_is(linear);
    };
    let (values, stderr, k2) = match fit(true) {
        Some((wider, w))
            if (wider[n + 3] / w.stderr[n + 3]).powi(2) > (observations.max(2) as f64).ln() =>
        {
            let k2 = Some((wider[n + 3], w.stderr[n + 3]));
            (wider, w.stderr, k2)
        }
        _ => (values, without.stderr, None),
    };
    CardGeometry {
        linear: GeometricFit {
            params,
            values: values[..n].to_vec(),
            stderr: stderr[..n].to_vec(),
            chi2_drop: f64::NAN,
        },
        centred: Some(CentredDistortion {
            k1: (values[n], stderr[n]),
            k2,
            centre_px: [
                (values[n + 1], stderr[n + 1]),
                (values[n + 2], stderr[n + 2]),
            ],
        }),
        r0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::fit_geometric::fit_geometric;
    use crate::diagnose::test_fields::{field_runs, half_diagonal, lens_field, run_samples};
    use crate::reduce::Scheme;
    use GeometricParam as P;

    #[test]
    fn the_field_is_taken_at_the_ideal_position_of_each_image_point() {
        // k1 = −0.01 about (40, −30) px moves the frame's corners by some 16 px. Two fixed-point
        // steps leave an error of order (3k1)²·16 px ≈ 0.015 px in the ideal position, which the
        // field's gradient (≈ 6·k1·r·t/r0² ≈ 0.005) makes 1e-4 px; the field taken at the image
        // position instead is off by 16 px times that gradient, some 0.08 px.
        let (c, k, r0) = ((40.0, -30.0), (-0.01, 0.0), half_diagonal());
        let mut worst_naive = 0.0f64;
        for p in [
            (1250.0, 1050.0),
            (-1250.0, 1050.0),
            (-900.0, -1000.0),
            (300.0, -200.0),
        ] {
            for t in [(130.0, 0.0), (0.0, 130.0), (-65.0, 40.0)] {
                let truth = lens_field(p, t, c, k);
                let got = radial_difference(p, t, c, k, r0);
                let err = (got.0 - truth.0).hypot(got.1 - truth.1);
                assert!(err < 2e-4, "at {p:?} for {t:?}: {got:?} against {truth:?}");
                let (a, b) = (
                    radial((p.0 + t.0, p.1 + t.1), c, k, r0),
                    radial(p, c, k, r0),
                );
                worst_naive = worst_naive.max((a.0 - b.0 - truth.0).hypot(a.1 - b.1 - truth.1));
            }
        }
        assert!(worst_naive > 0.02, "{worst_naive}");
    }

    #[test]
    fn a_distortion_centre_off_the_image_centre_is_found_by_its_own_fit() {
        // k1 = 4e-3 about (60, −45) px, no k2; moves of two sizes along x and y, noise 0.01 px.
        // The linear fit reads the centre as p1, p2; the card fits it.
        let (c, k1) = ((60.0, -45.0), 4e-3);
        let native = Scheme::parse("native").unwrap();
        let moves = [(130.0, 0.0), (0.0, 130.0), (65.0, 0.0), (0.0, 65.0)];
        let points = field_runs(&moves, |p, t| lens_field(p, t, c, (k1, 0.0)), 0.01, 0);
        let samples = run_samples(&native, &moves, &points, 1e-4);
        let linear = fit_geometric(
            &samples,
            &[P::DistortionK1, P::DistortionP1, P::DistortionP2],
        )
        .unwrap();
        let observations = 2 * points.iter().map(Vec::len).sum::<usize>();
        let g = card_geometry(&samples, linear, half_diagonal(), observations);
        let centred = g.centred.as_ref().expect("k1 is far beyond its error");
        assert!(g.linear.params.is_empty(), "no other term was fitted");
        for (name, (v, se), truth) in [
            ("k1", centred.k1, k1),
            ("cx", centred.centre_px[0], c.0),
            ("cy", centred.centre_px[1], c.1),
        ] {
            assert!(
                (v - truth).abs() < 3.0 * se,
                "{name} = {v} ± {se} against {truth}"
            );
            assert!(se < 0.02 * truth.abs(), "{name}: ± {se}");
        }
        assert_eq!(centred.k2, None, "no k2 in the lens, none paid its price");
        // The card's field is the lens's, wherever the frame reaches.
        for p in [(1200.0, 1000.0), (-1200.0, -1000.0), (0.0, 0.0)] {
            let (got, truth) = (
                g.displacement(p, (130.0, 0.0)),
                lens_field(p, (130.0, 0.0), c, (k1, 0.0)),
            );
            assert!(
                (got.0 - truth.0).hypot(got.1 - truth.1) < 2e-3,
                "{got:?} against {truth:?}"
            );
        }
    }

    fn linear(params: Vec<GeometricParam>, values: Vec<f64>, stderr: Vec<f64>) -> GeometricFit {
        GeometricFit {
            params,
            values,
            stderr,
            chi2_drop: 0.0,
        }
    }

    #[test]
    fn without_k1_beyond_two_errors_and_both_decentring_terms_the_linear_fit_stands() {
        let r0 = half_diagonal();
        // k1 alone (no p1, p2): no centre to fit.
        let k1_only = linear(vec![P::DistortionK1], vec![4e-3], vec![1e-5]);
        let g = card_geometry(&[], k1_only.clone(), r0, 1000);
        assert_eq!((g.linear, g.centred), (k1_only, None));
        // k1 at 1.9 standard errors: nothing to refit.
        let weak = linear(
            vec![
                P::Rotation,
                P::DistortionK1,
                P::DistortionP1,
                P::DistortionP2,
            ],
            vec![1e-4, 1.9e-5, 1e-6, -1e-6],
            vec![1e-6, 1e-5, 1e-5, 1e-5],
        );
        let g = card_geometry(&[], weak.clone(), r0, 1000);
        assert_eq!((g.linear, g.centred), (weak, None));
        // A clear k1 with no field difference to fit it on: the linear fit, as it is.
        let clear = linear(
            vec![P::DistortionK1, P::DistortionP1, P::DistortionP2],
            vec![4e-3, 1e-4, -1e-4],
            vec![1e-5; 3],
        );
        assert_eq!(card_geometry(&[], clear, r0, 1000).centred, None);
    }

    #[test]
    fn the_linear_terms_give_the_first_order_field_of_their_physics() {
        // The moved frame turned by θ and magnified by 1 + s: p + t lands at R(θ)(1 + s)(p + t),
        // so the field is that less p + t; first order in θ and s, the error of order θ·s·|p|.
        let (theta, s): (f64, f64) = (1e-4, 2e-4);
        let g = CardGeometry {
            linear: linear(vec![P::Rotation, P::Scale], vec![theta, s], vec![1e-6; 2]),
            centred: None,
            r0: half_diagonal(),
        };
        for (p, t) in [
            ((1200.0, -1000.0), (130.0, 0.0)),
            ((-500.0, 800.0), (0.0, -65.0)),
        ] {
            let (x, y) = ((1.0 + s) * (p.0 + t.0), (1.0 + s) * (p.1 + t.1));
            let (sin, cos) = theta.sin_cos();
            let truth = (cos * x - sin * y - p.0 - t.0, sin * x + cos * y - p.1 - t.1);
            let got = g.displacement(p, t);
            assert!(
                (got.0 - truth.0).hypot(got.1 - truth.1) < 1e-4,
                "{got:?} against {truth:?}"
            );
        }
    }
}
