use serde::{Deserialize, Serialize};

/// The lens point-spread function as a Gaussian of `sigma_px`. A Gaussian dot convolved with a
/// Gaussian PSF stays Gaussian (variances add), so rendering stays exact.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PsfBlur {
    pub sigma_px: f64,
}
