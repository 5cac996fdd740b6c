use serde::{Deserialize, Serialize};

/// The target plane not parallel to the sensor (the camera not perpendicular to the target),
/// seen through a pinhole: a target point at in-plane position q (mm from where the optical
/// axis meets the target) lies at W = Ry(θy)·Rx(θx)·(qx, qy, 0) + (0, 0, Z) and images at
/// Z·(Wx, Wy)/Wz mm (times the scale in px/mm). Rx turns the target's +y side away from the
/// camera for θx > 0, Ry its +x side for θy > 0. The stage moves the target within its own plane.
///
/// One translation reveals the angle only through tan θ / Z (Hijazi et al., "A novel approach
/// for the determination of surface tilt angles in 2D-DIC experiments", Exp. Mech. 2020): to
/// first order a move t (px) changes the displacement at p (px from the axis) by
/// −a·(2 px tx + tx², px ty + py tx + tx ty) − b·(px ty + py tx + tx ty, 2 py ty + ty²) with
/// a = tan θy / (Z·scale), b = tan θx / (Z·scale). Without a stated working distance the angles
/// are those at the `working_distance_mm` written here.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TargetTilt {
    /// Rotation of the target about the image's vertical axis (its +x side farther), rad.
    pub angle_about_y_rad: f64,
    /// Rotation of the target about the image's horizontal axis (its +y side farther), rad.
    #[serde(default)]
    pub angle_about_x_rad: f64,
    /// Distance from the lens's entrance pupil to the target along the optical axis, mm.
    pub working_distance_mm: f64,
}

/// The largest tilt the model renders: beyond it a flat-target DIC study is not what is
/// measured.
pub const MAX_TILT_RAD: f64 = 0.35;

impl TargetTilt {
    /// The pinhole image (mm, at the axis's magnification) of the in-plane point (x, y) mm, and
    /// the local linear magnification there relative to the axis (Z/Wz, the dots' shrinking
    /// with depth).
    pub fn apply(&self, x_mm: f64, y_mm: f64) -> (f64, f64, f64) {
        let (sx, cx) = self.angle_about_x_rad.sin_cos();
        let (sy, cy) = self.angle_about_y_rad.sin_cos();
        // Rx·(x, y, 0) = (x, y cx, y sx); then Ry.
        let (wx0, wy, wz0) = (x_mm, y_mm * cx, y_mm * sx);
        let wx = cy * wx0 - sy * wz0;
        let wz = sy * wx0 + cy * wz0 + self.working_distance_mm;
        let depth = self.working_distance_mm / wz;
        (wx * depth, wy * depth, depth)
    }

    /// The first-order coefficients (a, b) of the module doc, 1/px, for `scale_px_per_mm`.
    pub fn slopes_per_px(&self, scale_px_per_mm: f64) -> (f64, f64) {
        let k = self.working_distance_mm * scale_px_per_mm;
        (
            self.angle_about_y_rad.tan() / k,
            self.angle_about_x_rad.tan() / k,
        )
    }

    /// The tilt whose first-order slopes are (a, b) 1/px at `working_distance_mm`.
    pub fn from_slopes(a: f64, b: f64, working_distance_mm: f64, scale_px_per_mm: f64) -> Self {
        let k = working_distance_mm * scale_px_per_mm;
        TargetTilt {
            angle_about_y_rad: (a * k).atan(),
            angle_about_x_rad: (b * k).atan(),
            working_distance_mm,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_tilt_is_the_identity_and_depth_follows_the_angle() {
        let flat = TargetTilt {
            angle_about_y_rad: 0.0,
            angle_about_x_rad: 0.0,
            working_distance_mm: 300.0,
        };
        assert_eq!(flat.apply(3.0, -2.0), (3.0, -2.0, 1.0));
        let t = TargetTilt {
            angle_about_y_rad: 0.01,
            ..flat
        };
        // The +x side is farther: it images smaller, the −x side larger.
        let (xr, _, mr) = t.apply(10.0, 0.0);
        let (xl, _, ml) = t.apply(-10.0, 0.0);
        assert!(mr < 1.0 && ml > 1.0 && xr < 10.0 && xl < -10.0, "{xr} {xl}");
    }

    /// The first-order field of the doc against the exact projection, by differences.
    #[test]
    fn a_translation_changes_the_field_as_the_first_order_formula_says() {
        let scale = 13.0;
        for (ay, ax) in [(0.012, 0.0), (0.0, -0.009), (0.006, 0.004)] {
            let t = TargetTilt {
                angle_about_y_rad: ay,
                angle_about_x_rad: ax,
                working_distance_mm: 300.0,
            };
            let (a, b) = t.slopes_per_px(scale);
            let img = |q: (f64, f64)| {
                let (x, y, _) = t.apply(q.0 / scale, q.1 / scale);
                (x * scale, y * scale)
            };
            let move_px = (65.0, 20.0);
            for p in [(200.0, -150.0), (-250.0, 100.0), (30.0, 40.0)] {
                // The point seen at p in the reference: invert by fixed point.
                let mut q = p;
                for _ in 0..50 {
                    let r = img(q);
                    q = (q.0 + p.0 - r.0, q.1 + p.1 - r.1);
                }
                let moved = img((q.0 + move_px.0, q.1 + move_px.1));
                let exact = (moved.0 - p.0 - move_px.0, moved.1 - p.1 - move_px.1);
                let (tx, ty) = move_px;
                let (px, py) = p;
                let cross = px * ty + py * tx + tx * ty;
                let first = (
                    -a * (2.0 * px * tx + tx * tx) - b * cross,
                    -a * cross - b * (2.0 * py * ty + ty * ty),
                );
                let size = first.0.abs() + first.1.abs();
                // Second order: the in-plane foreshortening cos θ of the move itself.
                let tol = 0.05 * size + (ay * ay + ax * ax) * tx.hypot(ty) + 1e-4;
                assert!(
                    (exact.0 - first.0).abs() < tol && (exact.1 - first.1).abs() < tol,
                    "{ay} {ax} at {p:?}: exact {exact:?}, first order {first:?}"
                );
            }
        }
    }
}
