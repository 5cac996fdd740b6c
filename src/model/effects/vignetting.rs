use serde::{Deserialize, Serialize};

/// Radial fall-off of irradiance, 1 - v·r² with r normalised by the half diagonal (the first term
/// of the cos⁴ law's expansion).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Vignetting {
    pub v: f64,
}
