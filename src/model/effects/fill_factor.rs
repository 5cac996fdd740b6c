use serde::{Deserialize, Serialize};

/// Linear fill factor per axis: each pixel integrates light over a centred aperture of fx x fy of
/// its pitch (1 = 100 %). A real aperture, not a signal scale: the collected signal is the mean
/// irradiance over the aperture, so contrast and MTF change while the mean level does not.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FillFactor {
    pub fx: f64,
    pub fy: f64,
}
