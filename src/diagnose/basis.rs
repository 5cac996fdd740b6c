//! Displacement basis fields of the geometric effects: the change of a translation's displacement
//! at a reference position per unit of each parameter, to first order. Positions and moves in
//! full-resolution px, relative to the image centre (the optical axis and distortion centre of the
//! model); T is the actual move.
//!
//! - travel scale (ln): T; stage misalignment: R90·T = (−Ty, Tx) — constant fields;
//! - rotation θ of the moved frame about the optical axis: (−(y+Ty), x+Tx);
//! - scale ds of the moved frame: (x+Tx, y+Ty);
//! - radial distortion k1 (Brown, Photogramm. Eng. 32 (1966)), D(q) = q + k1·q|q|²/r0²: a point
//!   seen at p in the reference is seen at D(D⁻¹(p) + T) after the move, so the field changes by
//!   k1·[g(p+T) − g(p)], g(q) = q|q|²/r0² — quadratic in p for a translation, and proportional to
//!   T, which is what tells it from a scale change when translations of several sizes are measured.
//!   k2, p1, p2 the same way with g(q) = q|q|⁴/r0⁴, (2qx·qy, |q|² + 2qy²)/r0 and
//!   (|q|² + 2qx², 2qx·qy)/r0. A distortion centre off the image centre by c adds, to first order,
//!   −k1·c·∇ of the k1 field: exactly the p2 (cx) and p1 (cy) fields, so translations identify
//!   the decentring terms, not where the centre is;
//! - target tilt (slopes a, b = tan θ / (Z·scale), see `model::effects::TargetTilt`):
//!   −(2x·Tx + Tx², x·Ty + y·Tx + Tx·Ty) and −(x·Ty + y·Tx + Tx·Ty, 2y·Ty + Ty²): an affine field
//!   that grows with the move (Hijazi et al., Exp. Mech. 2020).

use crate::model::EffectId;
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GeometricParam {
    TravelScale,
    Misalignment,
    Rotation,
    Scale,
    DistortionK1,
    DistortionK2,
    DistortionP1,
    DistortionP2,
    /// tan θy / (Z·scale), 1/px.
    TiltSlopeY,
    /// tan θx / (Z·scale), 1/px.
    TiltSlopeX,
}

impl GeometricParam {
    /// The effect id and parameter name of DESIGN.md.
    pub fn effect_and_name(self) -> (EffectId, &'static str) {
        match self {
            GeometricParam::TravelScale => (EffectId::StageMisalignment, "travel_scale"),
            GeometricParam::Misalignment => (EffectId::StageMisalignment, "angle_rad"),
            GeometricParam::Rotation => (EffectId::Rotation, "angle_rad"),
            GeometricParam::Scale => (EffectId::Scale, "ds"),
            GeometricParam::DistortionK1 => (EffectId::LensDistortion, "k1"),
            GeometricParam::DistortionK2 => (EffectId::LensDistortion, "k2"),
            GeometricParam::DistortionP1 => (EffectId::LensDistortion, "p1"),
            GeometricParam::DistortionP2 => (EffectId::LensDistortion, "p2"),
            GeometricParam::TiltSlopeY => (EffectId::TargetTilt, "tilt_slope_y"),
            GeometricParam::TiltSlopeX => (EffectId::TargetTilt, "tilt_slope_x"),
        }
    }
}

/// The basis field at `p` (px from the image centre) for the actual move `t` (px); `r0` is the
/// distortion's normalising radius (the half diagonal by default).
pub fn geometric_basis(param: GeometricParam, p: (f64, f64), t: (f64, f64), r0: f64) -> (f64, f64) {
    let (x, y) = p;
    match param {
        GeometricParam::TravelScale => t,
        GeometricParam::Misalignment => (-t.1, t.0),
        GeometricParam::Rotation => (-(y + t.1), x + t.0),
        GeometricParam::Scale => (x + t.0, y + t.1),
        GeometricParam::DistortionK1
        | GeometricParam::DistortionK2
        | GeometricParam::DistortionP1
        | GeometricParam::DistortionP2 => {
            let g = |qx: f64, qy: f64| distortion_term(param, qx, qy, r0);
            let (a, b) = (g(x + t.0, y + t.1), g(x, y));
            (a.0 - b.0, a.1 - b.1)
        }
        GeometricParam::TiltSlopeY => (
            -(2.0 * x * t.0 + t.0 * t.0),
            -(x * t.1 + y * t.0 + t.0 * t.1),
        ),
        GeometricParam::TiltSlopeX => (
            -(x * t.1 + y * t.0 + t.0 * t.1),
            -(2.0 * y * t.1 + t.1 * t.1),
        ),
    }
}

/// The displacement per unit coefficient of one Brown–Conrady term at q (px from the centre).
fn distortion_term(param: GeometricParam, qx: f64, qy: f64, r0: f64) -> (f64, f64) {
    let r2 = (qx * qx + qy * qy) / (r0 * r0);
    match param {
        GeometricParam::DistortionK2 => (qx * r2 * r2, qy * r2 * r2),
        GeometricParam::DistortionP1 => {
            (2.0 * qx * qy / r0, (qx * qx + qy * qy + 2.0 * qy * qy) / r0)
        }
        GeometricParam::DistortionP2 => {
            ((qx * qx + qy * qy + 2.0 * qx * qx) / r0, 2.0 * qx * qy / r0)
        }
        GeometricParam::DistortionK1
        | GeometricParam::TravelScale
        | GeometricParam::Misalignment
        | GeometricParam::Rotation
        | GeometricParam::Scale
        | GeometricParam::TiltSlopeY
        | GeometricParam::TiltSlopeX => (qx * r2, qy * r2),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::effects::{LensDistortion, Rotation, Scale, TargetTilt};
    use crate::model::{project, Camera, Effects, FrameSpec};

    fn camera() -> Camera {
        Camera {
            width: 800,
            height: 600,
            scale_px_per_mm: 20.0,
            exposure_level: 0.5,
            principal_dx_px: 0.0,
            principal_dy_px: 0.0,
        }
    }

    /// The displacement at reference position p (px) of a 3 mm, 1 mm move under `e`: the
    /// reference projection inverted, the moved frame projected.
    fn displacement(e: &Effects, p: (f64, f64)) -> (f64, f64) {
        let camera = camera();
        let (cx, cy) = camera.centre();
        let frame = |moved: bool| FrameSpec {
            stage_dx_mm: if moved { 3.0 } else { 0.0 },
            stage_dy_mm: if moved { 1.0 } else { 0.0 },
            moved,
            seed: 0,
        };
        let (mut x, mut y) = ((p.0 - cx) / 20.0, (p.1 - cy) / 20.0);
        for _ in 0..20 {
            let q = project(&camera, e, &frame(false), x, y);
            x += (p.0 - q.0) / 20.0;
            y += (p.1 - q.1) / 20.0;
        }
        let q = project(&camera, e, &frame(true), x, y);
        (q.0 - p.0, q.1 - p.1)
    }

    /// Each basis field with the small step of its parameter and the model holding that step.
    fn cases() -> Vec<(GeometricParam, f64, Effects)> {
        let eps = 1e-5;
        let distortion = |d: LensDistortion| Effects {
            lens_distortion: Some(d),
            ..Default::default()
        };
        let none = LensDistortion::radial(0.0);
        // A tilt's slope is ~1e-6/px: its own small step keeps the difference first order.
        let slope = 1e-9;
        let tilt = |a: f64, b: f64| Effects {
            target_tilt: Some(TargetTilt::from_slopes(a, b, 300.0, 20.0)),
            ..Default::default()
        };
        vec![
            (
                GeometricParam::Rotation,
                eps,
                Effects {
                    rotation: Some(Rotation { angle_rad: eps }),
                    ..Default::default()
                },
            ),
            (
                GeometricParam::Scale,
                eps,
                Effects {
                    scale: Some(Scale { ds: eps }),
                    ..Default::default()
                },
            ),
            (
                GeometricParam::DistortionK1,
                eps,
                distortion(LensDistortion::radial(eps)),
            ),
            (
                GeometricParam::DistortionK2,
                eps,
                distortion(LensDistortion { k2: eps, ..none }),
            ),
            (
                GeometricParam::DistortionP1,
                eps,
                distortion(LensDistortion { p1: eps, ..none }),
            ),
            (
                GeometricParam::DistortionP2,
                eps,
                distortion(LensDistortion { p2: eps, ..none }),
            ),
            (GeometricParam::TiltSlopeY, slope, tilt(slope, 0.0)),
            (GeometricParam::TiltSlopeX, slope, tilt(0.0, slope)),
        ]
    }

    /// The closed forms against the model's own projection, by finite differences.
    #[test]
    fn basis_matches_the_model_projection() {
        let camera = camera();
        let (cx, cy) = camera.centre();
        let r0 = camera.half_diagonal_px();
        let t = (60.0, 20.0);
        for (param, eps, effects) in cases() {
            for p in [(100.0, 80.0), (650.0, 500.0), (400.0, 300.0)] {
                let a = displacement(&effects, p);
                let b = displacement(&Effects::default(), p);
                let fd = ((a.0 - b.0) / eps, (a.1 - b.1) / eps);
                let cf = geometric_basis(param, (p.0 - cx, p.1 - cy), t, r0);
                let tol = 1e-3 * (cf.0.abs() + cf.1.abs() + 1.0);
                assert!(
                    (fd.0 - cf.0).abs() < tol && (fd.1 - cf.1).abs() < tol,
                    "{param:?} {p:?}: {fd:?} vs {cf:?}"
                );
            }
        }
    }
}
