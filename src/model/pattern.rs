//! Printed random speckle targets, defined in mm on the target plane.
//!
//! A dot is a Gaussian darkening whose full width at half maximum is the dot diameter, softened
//! by `edge_softness_mm` (a Gaussian blur of the print, variances add). Smooth dots can be
//! integrated exactly over any pixel aperture (see `speckle.rs`); the price is that "diameter" is
//! the FWHM of a soft dot rather than the edge of a hard disc.

use serde::{Deserialize, Serialize};

/// FWHM = 2·sqrt(2 ln 2)·σ.
const FWHM_PER_SIGMA: f64 = 2.354_820_045_030_949;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpecklePattern {
    pub label: String,
    pub dot_diameter_mm: f64,
    /// Mean distance between dot centres: one dot per spacing² of target.
    pub dot_spacing_mm: f64,
    /// Darkening at a dot centre as a fraction of the white background (1 = black dots).
    pub contrast: f64,
    /// Standard deviation of the print's blur, mm.
    #[serde(default)]
    pub edge_softness_mm: f64,
    /// Where the dots sit: [`Placement`] (absent: the jittered grid).
    #[serde(default, skip_serializing_if = "Placement::is_jittered_grid")]
    pub placement: Placement,
}

/// How a print's dots are placed. The placement sets the print's spectrum below the
/// dot-spacing frequency (a grid suppresses it, independent positions leave it flat) and how
/// much sparse and crowded patches a subset sees — which is what sets DIC's error under
/// subsampling (the paper's ff50 and ff25), beside the dot profile and contrast.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Placement {
    /// One dot per cell of the spacing grid, anywhere in it (ffdic's targets).
    #[default]
    JitteredGrid,
    /// Every dot anywhere in the field, independently (a Poisson process of the same density).
    Poisson,
}

impl Placement {
    pub fn is_jittered_grid(&self) -> bool {
        *self == Placement::JitteredGrid
    }
}

/// The most dots one target layout may hold (32 bytes each: 128 MiB). Every layout is sized
/// from input — a request's pattern, a dataset's moves — so the cap is what keeps one request
/// from allocating the machine away.
pub const MAX_TARGET_DOTS: usize = 4_000_000;

/// A layout larger than [`MAX_TARGET_DOTS`] (or with a spacing that is not a positive number).
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[error(
    "the target would need {dots:.3e} dots (at most {MAX_TARGET_DOTS}): dot_spacing_mm must be at \
     least {min_spacing_mm:.4} mm over this field, or the field (image and moves) smaller"
)]
pub struct TooManyDots {
    pub dots: f64,
    pub min_spacing_mm: f64,
}

/// One dot on the target plane, mm, relative to the optical axis at the reference position.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TargetDot {
    pub x_mm: f64,
    pub y_mm: f64,
    pub sigma_mm: f64,
    /// Fraction of the background removed at the centre.
    pub depth: f64,
}

impl SpecklePattern {
    /// The paper's patterns (Hijazi et al., Fig. 3): `a` 0.5 mm dots at 0.75 mm, `b` 0.24 mm dots
    /// at 0.36 mm, both black on white; `c` a defocused, low-contrast print of `a`.
    pub fn preset(label: &str) -> Option<Self> {
        let p = |d: f64, s: f64, c: f64, soft: f64| SpecklePattern {
            label: label.to_string(),
            dot_diameter_mm: d,
            dot_spacing_mm: s,
            contrast: c,
            edge_softness_mm: soft,
            placement: Placement::JitteredGrid,
        };
        match label {
            "a" => Some(p(0.5, 0.75, 0.85, 0.02)),
            "b" => Some(p(0.24, 0.36, 0.85, 0.02)),
            "c" => Some(p(0.5, 0.75, 0.35, 0.2)),
            _ => None,
        }
    }

    /// σ of one dot's Gaussian profile, mm.
    pub fn sigma_mm(&self) -> f64 {
        ((self.dot_diameter_mm / FWHM_PER_SIGMA).powi(2) + self.edge_softness_mm.powi(2)).sqrt()
    }

    /// How many dots cover the rectangle [x0, x1] x [y0, y1] mm: one per lattice cell. Refuses
    /// (never allocates) a layout above [`MAX_TARGET_DOTS`], a non-finite field or spacing.
    pub fn dot_count(&self, (x0, y0, x1, y1): (f64, f64, f64, f64)) -> Result<usize, TooManyDots> {
        let s = self.dot_spacing_mm;
        let nx = ((x1 - x0) / s).ceil();
        let ny = ((y1 - y0) / s).ceil();
        let n = nx * ny;
        // NaN fails every comparison, so `!(n <= MAX)` also refuses NaN and infinities.
        if !(s > 0.0 && nx >= 0.0 && ny >= 0.0 && n <= MAX_TARGET_DOTS as f64) {
            let area_mm2 = (x1 - x0) * (y1 - y0);
            return Err(TooManyDots {
                dots: n,
                min_spacing_mm: (area_mm2 / MAX_TARGET_DOTS as f64).sqrt(),
            });
        }
        Ok(n as usize)
    }

    /// Dots covering the rectangle [x0, x1] x [y0, y1] mm on a jittered lattice (one dot per
    /// cell, uniformly placed within it, depth ±15 %), reproducible from `seed`.
    pub fn dots(
        &self,
        field: (f64, f64, f64, f64),
        seed: u64,
    ) -> Result<Vec<TargetDot>, TooManyDots> {
        use rand::{Rng, SeedableRng};
        self.dot_count(field)?;
        let (x0, y0, x1, y1) = field;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let s = self.dot_spacing_mm;
        let nx = ((x1 - x0) / s).ceil() as usize;
        let ny = ((y1 - y0) / s).ceil() as usize;
        let sigma = self.sigma_mm();
        let mut dots = Vec::with_capacity(nx * ny);
        for j in 0..ny {
            for i in 0..nx {
                // The jittered grid keeps the cell; Poisson draws the cell too (the same count
                // and the same stream of draws, so the two layouts differ only in placement).
                let (ci, cj) = match self.placement {
                    Placement::JitteredGrid => (i as f64, j as f64),
                    Placement::Poisson => (
                        (rng.gen::<f64>() * nx as f64).floor(),
                        (rng.gen::<f64>() * ny as f64).floor(),
                    ),
                };
                dots.push(TargetDot {
                    x_mm: x0 + (ci + rng.gen::<f64>()) * s,
                    y_mm: y0 + (cj + rng.gen::<f64>()) * s,
                    sigma_mm: sigma,
                    depth: self.contrast * (1.0 + 0.15 * (2.0 * rng.gen::<f64>() - 1.0)),
                });
            }
        }
        Ok(dots)
    }
}
