use serde::{Deserialize, Serialize};

/// The stage still moving during the exposure of a moved frame: the image is the mean over a
/// straight path of `length_px` at `angle_rad` from +x, centred on the final position.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotionBlur {
    pub length_px: f64,
    #[serde(default)]
    pub angle_rad: f64,
}
