use serde::{Deserialize, Serialize};

/// Magnification change of a moved frame relative to the reference, 1 + ds: the target came
/// closer or went further (out-of-plane motion, a stage not perpendicular to the optical axis).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scale {
    pub ds: f64,
}
