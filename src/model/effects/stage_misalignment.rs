use serde::{Deserialize, Serialize};

/// The stage axis is not parallel to the sensor rows: a commanded move (dx, dy) happens along
/// axes turned by `angle_rad`. The paper's 5 mm x move showed ≈0.4 px of y motion in the reduced
/// images for this reason (Hijazi et al., Results).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StageMisalignment {
    pub angle_rad: f64,
}

impl StageMisalignment {
    /// The move that really happens for a commanded (dx, dy), same units.
    pub fn actual_move(&self, dx: f64, dy: f64) -> (f64, f64) {
        let (s, c) = self.angle_rad.sin_cos();
        (c * dx - s * dy, s * dx + c * dy)
    }
}
