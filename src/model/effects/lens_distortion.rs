use serde::{Deserialize, Serialize};

/// Brown–Conrady distortion (Brown, "Decentering distortion of lenses", Photogramm. Eng. 32
/// (1966)) in image coordinates normalised by `norm_radius_px` (default: the half diagonal), about
/// a centre given in px from the image centre.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LensDistortion {
    pub k1: f64,
    #[serde(default)]
    pub k2: f64,
    #[serde(default)]
    pub p1: f64,
    #[serde(default)]
    pub p2: f64,
    /// Distortion centre relative to the image centre, px.
    #[serde(default)]
    pub centre_dx_px: f64,
    #[serde(default)]
    pub centre_dy_px: f64,
    /// Radius that normalises coordinates; 0 means the image's half diagonal.
    #[serde(default)]
    pub norm_radius_px: f64,
}

impl LensDistortion {
    /// The first radial term alone (k1, normalised by the half diagonal, about the image
    /// centre): what `diagnose` fits.
    pub fn radial(k1: f64) -> Self {
        LensDistortion {
            k1,
            k2: 0.0,
            p1: 0.0,
            p2: 0.0,
            centre_dx_px: 0.0,
            centre_dy_px: 0.0,
            norm_radius_px: 0.0,
        }
    }

    /// Distorted position of an ideal image point, all in px; `centre` is the image centre and
    /// `half_diagonal_px` the default normalisation.
    pub fn distort(&self, x: f64, y: f64, centre: (f64, f64), half_diagonal_px: f64) -> (f64, f64) {
        let r0 = if self.norm_radius_px > 0.0 {
            self.norm_radius_px
        } else {
            half_diagonal_px
        };
        let (cx, cy) = (centre.0 + self.centre_dx_px, centre.1 + self.centre_dy_px);
        let (xn, yn) = ((x - cx) / r0, (y - cy) / r0);
        let r2 = xn * xn + yn * yn;
        let radial = self.k1 * r2 + self.k2 * r2 * r2;
        let dx = xn * radial + 2.0 * self.p1 * xn * yn + self.p2 * (r2 + 2.0 * xn * xn);
        let dy = yn * radial + self.p1 * (r2 + 2.0 * yn * yn) + 2.0 * self.p2 * xn * yn;
        (x + dx * r0, y + dy * r0)
    }
}
