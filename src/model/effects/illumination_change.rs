use serde::{Deserialize, Serialize};

/// Brightness and contrast change of a moved frame: I' = gain·I + offset (DN).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IlluminationChange {
    pub gain: f64,
    pub offset: f64,
}
