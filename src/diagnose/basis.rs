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
        GeometricParam::DistortionK1 => {
            let g = |qx: f64, qy: f64| {
                let r2 = (qx * qx + qy * qy) / (r0 * r0);
                (qx * r2, qy * r2)
            };
            let (a, b) = (g(x + t.0, y + t.1), g(x, y));
            (a.0 - b.0, a.1 - b.1)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::effects::{LensDistortion, Rotation, Scale};
    use crate::model::{project, Camera, Effects, FrameSpec};

    /// The closed forms against the model's own projection, by finite differences.
    #[test]
    fn basis_matches_the_model_projection() {
        let camera = Camera {
            width: 800,
            height: 600,
            scale_px_per_mm: 20.0,
            exposure_level: 0.5,
            principal_dx_px: 0.0,
            principal_dy_px: 0.0,
        };
        let (cx, cy) = camera.centre();
        let r0 = camera.half_diagonal_px();
        let moved = FrameSpec {
            stage_dx_mm: 3.0,
            stage_dy_mm: 1.0,
            moved: true,
            seed: 0,
        };
        let t = (60.0, 20.0);
        let disp = |e: &Effects, p: (f64, f64)| {
            // Invert the reference projection, project the moved frame.
            let reference = FrameSpec {
                moved: false,
                stage_dx_mm: 0.0,
                stage_dy_mm: 0.0,
                seed: 0,
            };
            let (mut x, mut y) = ((p.0 - cx) / 20.0, (p.1 - cy) / 20.0);
            for _ in 0..20 {
                let q = project(&camera, e, &reference, x, y);
                x += (p.0 - q.0) / 20.0;
                y += (p.1 - q.1) / 20.0;
            }
            let q = project(&camera, e, &moved, x, y);
            (q.0 - p.0, q.1 - p.1)
        };
        let eps = 1e-5;
        let cases: Vec<(GeometricParam, Effects)> = vec![
            (
                GeometricParam::Rotation,
                Effects {
                    rotation: Some(Rotation { angle_rad: eps }),
                    ..Default::default()
                },
            ),
            (
                GeometricParam::Scale,
                Effects {
                    scale: Some(Scale { ds: eps }),
                    ..Default::default()
                },
            ),
            (
                GeometricParam::DistortionK1,
                Effects {
                    lens_distortion: Some(LensDistortion::radial(eps)),
                    ..Default::default()
                },
            ),
        ];
        for (param, effects) in cases {
            for p in [(100.0, 80.0), (650.0, 500.0), (400.0, 300.0)] {
                let a = disp(&effects, p);
                let b = disp(&Effects::default(), p);
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
