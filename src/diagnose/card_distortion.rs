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
        let (mut u, mut v) = (0.0, 0.0);
        for (q, value) in self.linear.params.iter().zip(&self.linear.values) {
            let (bu, bv) = geometric_basis(*q, p, t, self.r0);
            u += value * bu;
            v += value * bv;
        }
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

fn value_of(fit: &GeometricFit, p: GeometricParam) -> Option<(f64, f64)> {
    let i = fit.params.iter().position(|q| *q == p)?;
    Some((fit.values[i], fit.stderr[i]))
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
        value_of(&linear, GeometricParam::DistortionK1),
        value_of(&linear, GeometricParam::DistortionP1),
        value_of(&linear, GeometricParam::DistortionP2),
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
