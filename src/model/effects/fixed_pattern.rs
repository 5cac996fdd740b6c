use serde::{Deserialize, Serialize};

/// Fixed-pattern noise: photo-response non-uniformity (relative gain spread `prnu`) and dark-
/// signal non-uniformity (`dsnu`, DN), identical in every frame of the same sensor.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FixedPattern {
    pub prnu: f64,
    pub dsnu: f64,
}
