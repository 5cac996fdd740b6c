//! Printed random speckle targets, defined in mm on the target plane.
//!
//! A dot is either a Gaussian darkening whose full width at half maximum is the dot diameter, or
//! a disk of that diameter with a hard edge (toner, a laser print, a stencil); either is softened
//! by `edge_softness_mm` (a Gaussian blur of the print). Both are integrated exactly over any pixel
//! aperture (see `speckle.rs`). The profile matters to DIC beyond the spectrum's width: a hard
//! edge carries gradient energy that no Gaussian of the same contrast has, and that energy sets
//! the random error (Pan et al., "Study on subset size selection in digital image correlation for
//! speckle patterns", Opt. Express 16 (2008): σ_u ∝ σ_noise / √(Σ|∇I|²)).

use super::hard_core::hard_core_centres_remembered;
use super::lattice::lattice_remembered;
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
    /// The dots' profile (absent: Gaussian).
    #[serde(default, skip_serializing_if = "DotProfile::is_gaussian")]
    pub profile: DotProfile,
    /// The least gap between two dots' edges under [`Placement::HardCore`], mm (absent: 0, dots
    /// may touch): a speckle generator that places disks "without touching" keeps one, and how
    /// close the nearest dots come sets DIC's error under subsampling — on the independent
    /// generator's disks with a gap of 5 % of their diameter, a model without it overstated
    /// the random error of v under ff50 by 19 % (`docs/model-and-diagnosis.md`).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub min_gap_mm: f64,
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

/// A printed dot's profile.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DotProfile {
    /// Deficit c·exp(−ρ²/2σ²) per dot, the diameter its FWHM.
    #[default]
    Gaussian,
    /// A hard-edged disk of the diameter, depth c.
    Disk,
}

impl DotProfile {
    pub fn is_gaussian(&self) -> bool {
        *self == DotProfile::Gaussian
    }
}

/// One dot's shape on the target plane, mm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DotShape {
    /// A Gaussian of standard deviation `sigma_mm` (the print's softness included).
    Gaussian { sigma_mm: f64 },
    /// A disk of radius `radius_mm`, blurred by a Gaussian of σ `blur_mm` (the print's softness).
    Disk { radius_mm: f64, blur_mm: f64 },
}

impl DotShape {
    /// How far the dot darkens the print from its centre, mm (six standard deviations of blur
    /// beyond its edge: exp(−18) of its depth).
    pub fn reach_mm(&self) -> f64 {
        match *self {
            DotShape::Gaussian { sigma_mm } => 6.0 * sigma_mm,
            DotShape::Disk { radius_mm, blur_mm } => radius_mm + 6.0 * blur_mm,
        }
    }
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
    /// Dots anywhere but never closer than their diameter and the pattern's `min_gap_mm` (at
    /// most 0.8 spacing; random sequential adsorption): a print whose dots do not touch, as a
    /// stencil or a laser
    /// printer's speckle generator makes them. Dense prints of hard dots differ most: overlaps
    /// merge dots and remove edges.
    HardCore,
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
    pub shape: DotShape,
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
            profile: DotProfile::Gaussian,
            min_gap_mm: 0.0,
        };
        match label {
            "a" => Some(p(0.5, 0.75, 0.85, 0.02)),
            "b" => Some(p(0.24, 0.36, 0.85, 0.02)),
            "c" => Some(p(0.5, 0.75, 0.35, 0.2)),
            _ => None,
        }
    }

    /// σ of one dot's profile, mm: a Gaussian's own, a disk's that of the Gaussian with its
    /// second moment (R²/4 per axis), each with the print's softness in quadrature.
    pub fn sigma_mm(&self) -> f64 {
        let own = match self.profile {
            DotProfile::Gaussian => self.dot_diameter_mm / FWHM_PER_SIGMA,
            DotProfile::Disk => self.dot_diameter_mm / 4.0,
        };
        own.hypot(self.edge_softness_mm)
    }

    /// One dot's shape as printed.
    pub fn shape(&self) -> DotShape {
        match self.profile {
            DotProfile::Gaussian => DotShape::Gaussian {
                sigma_mm: self.sigma_mm(),
            },
            DotProfile::Disk => DotShape::Disk {
                radius_mm: 0.5 * self.dot_diameter_mm,
                blur_mm: self.edge_softness_mm,
            },
        }
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
        let shape = self.shape();
        // A dot's depth from its uniform draw u: ±15 % about the contrast.
        let depth = |u: f64| self.contrast * (1.0 + 0.15 * (2.0 * u - 1.0));
        if self.placement == Placement::HardCore {
            // Dots of their diameter and gap cannot all keep it beyond the jamming limit (54.7 %
            // of the plane): the distance is held to 0.8 spacing (50 %).
            let distance = (self.dot_diameter_mm + self.min_gap_mm).min(0.8 * s);
            let centres = hard_core_centres_remembered(&mut rng, field, nx * ny, distance);
            return Ok(centres
                .iter()
                .map(|&(x_mm, y_mm)| TargetDot {
                    x_mm,
                    y_mm,
                    shape,
                    depth: depth(rng.gen::<f64>()),
                })
                .collect());
        }
        Ok(lattice_remembered(self.placement, field, s, seed)
            .iter()
            .map(|&(x_mm, y_mm, u)| TargetDot {
                x_mm,
                y_mm,
                shape,
                depth: depth(u),
            })
            .collect())
    }
}
