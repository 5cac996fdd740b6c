//! A model's static geometry undone on measured displacements (`ffdic analyze --card`): lens
//! distortion and the target's tilt map a point of the target to the image through the chain the
//! renderer draws (`render::project_prepared`: tilt, then the scale, then distortion). A measured
//! displacement d at image point p is corrected by taking p and p + d back through that chain to
//! the target plane (in px at the nominal scale): d' = T⁻¹(p + d) − T⁻¹(p). A rigid move of the
//! target is then uniform, whatever the lens and the mount did to it. The inverses are solved by
//! fixed-point steps: both maps are within a few per mille of the identity.

use super::effects::{LensDistortion, TargetTilt};
use super::Effects;

/// Fixed-point steps of each inverse (each step gains the map's departure from the identity,
/// ≲ 1e-2: eight steps leave < 1e-12 px).
const INVERSE_STEPS: usize = 8;

/// The correction for frames `width` x `height` px at `scale_px_per_mm`.
#[derive(Clone, Debug, PartialEq)]
pub struct GeometryCorrection {
    distortion: Option<LensDistortion>,
    tilt: Option<TargetTilt>,
    centre: (f64, f64),
    half_diagonal_px: f64,
    scale_px_per_mm: f64,
}

impl GeometryCorrection {
    /// None when the model has neither distortion nor tilt: nothing to undo.
    pub fn of(
        effects: &Effects,
        width: usize,
        height: usize,
        scale_px_per_mm: f64,
    ) -> Option<Self> {
        if effects.lens_distortion.is_none() && effects.target_tilt.is_none() {
            return None;
        }
        // As `Camera::centre` and `Camera::half_diagonal_px`.
        let centre = ((width as f64 - 1.0) / 2.0, (height as f64 - 1.0) / 2.0);
        Some(Self {
            distortion: effects.lens_distortion,
            tilt: effects.target_tilt,
            centre,
            half_diagonal_px: 0.5 * (width as f64).hypot(height as f64),
            scale_px_per_mm,
        })
    }

    /// Where image point `q` (px) lies on the target plane, px at the nominal scale from the
    /// image's origin.
    pub fn to_plane(&self, q: (f64, f64)) -> (f64, f64) {
        let (cx, cy) = self.centre;
        let mut ideal = q;
        if let Some(d) = &self.distortion {
            for _ in 0..INVERSE_STEPS {
                let (x, y) = d.distort(ideal.0, ideal.1, self.centre, self.half_diagonal_px);
                ideal = (ideal.0 + q.0 - x, ideal.1 + q.1 - y);
            }
        }
        let Some(t) = &self.tilt else {
            return ideal;
        };
        let k = self.scale_px_per_mm;
        let seen = ((ideal.0 - cx) / k, (ideal.1 - cy) / k);
        let mut plane = seen;
        for _ in 0..INVERSE_STEPS {
            let (x, y, _) = t.apply(plane.0, plane.1);
            plane = (plane.0 + seen.0 - x, plane.1 + seen.1 - y);
        }
        (cx + k * plane.0, cy + k * plane.1)
    }

    /// The displacement `d` measured at image point `p`, on the target plane (px).
    pub fn corrected(&self, p: (f64, f64), d: (f64, f64)) -> (f64, f64) {
        let a = self.to_plane(p);
        let b = self.to_plane((p.0 + d.0, p.1 + d.1));
        (b.0 - a.0, b.1 - a.1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::render::project;
    use crate::model::{Camera, FrameSpec};

    fn effects() -> Effects {
        Effects {
            lens_distortion: Some(LensDistortion {
                centre_dx_px: 40.0,
                centre_dy_px: -30.0,
                ..LensDistortion::radial(-0.01)
            }),
            target_tilt: Some(TargetTilt {
                angle_about_y_rad: 0.0105,
                angle_about_x_rad: -0.004,
                working_distance_mm: 300.0,
            }),
            ..Effects::default()
        }
    }

    /// The renderer's own chain, taken back: a target point rendered at the stage's origin and
    /// after a move lands, corrected, where the move puts it on the plane (the renderer is the
    /// model's forward map, so this checks the inverse, not the physics).
    #[test]
    fn a_rigid_move_is_uniform_once_corrected() {
        let camera = Camera {
            width: 640,
            height: 540,
            scale_px_per_mm: 13.0,
            exposure_level: 0.5,
            principal_dx_px: 0.0,
            principal_dy_px: 0.0,
        };
        let fx = effects();
        let c = GeometryCorrection::of(&fx, 640, 540, 13.0).unwrap();
        let frame = |dx: f64, dy: f64| FrameSpec {
            stage_dx_mm: dx,
            stage_dy_mm: dy,
            moved: true,
            seed: 0,
        };
        let (moved, still) = (frame(2.0, -1.5), frame(0.0, 0.0));
        for (x_mm, y_mm) in [(0.0, 0.0), (-20.0, 15.0), (22.0, -18.0), (10.0, 19.0)] {
            let (ax, ay) = project(&camera, &fx, &still, x_mm, y_mm);
            let (bx, by) = project(&camera, &fx, &moved, x_mm, y_mm);
            let raw = (bx - ax, by - ay);
            let (u, v) = c.corrected((ax, ay), raw);
            assert!(
                (u - 26.0).abs() < 1e-9 && (v + 19.5).abs() < 1e-9,
                "{raw:?} -> {u}, {v}"
            );
        }
    }
}
