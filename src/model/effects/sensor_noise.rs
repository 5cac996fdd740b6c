use serde::{Deserialize, Serialize};

/// Photon shot noise and read noise (photon transfer, EMVA 1288). `gain` is the conversion gain in
/// electrons per DN, so the variance of a pixel in DN² is mean/gain + (read_noise_e/gain)².
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorNoise {
    pub full_well_e: f64,
    pub read_noise_e: f64,
    /// Electrons per DN.
    pub gain: f64,
}
