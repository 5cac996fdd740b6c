use serde::{Deserialize, Serialize};

/// In-plane rotation of the target between the reference and a moved frame (stage yaw), about
/// the optical axis, positive from +x towards +y (clockwise on screen, y down).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rotation {
    /// Yaw per mm of stage travel would be more physical for a worn guide; a fixed angle per moved
    /// frame is what a single translation can reveal.
    pub angle_rad: f64,
}

impl Rotation {
    /// Rotates a target-plane point (relative to the optical axis).
    pub fn apply(&self, x: f64, y: f64) -> (f64, f64) {
        let (s, c) = self.angle_rad.sin_cos();
        (c * x - s * y, s * x + c * y)
    }
}
