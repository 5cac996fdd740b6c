//! Every setting of one DIC analysis. Defaults follow the paper's study (Hijazi, Rawashdeh &
//! Kähler): subset 41x41, step 20, ROI 800x800 centred, strain window 7x7 points.

use super::{DicError, Interpolation, PolygonMask};
use crate::image::Roi;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DicSettings {
    /// Subset side in px; odd.
    pub subset_px: usize,
    /// Distance between neighbouring points of interest in px.
    pub step_px: usize,
    /// Rectangle holding the POI centres; `None` is the centred 800x800, clipped to the image.
    pub roi: Option<Roi>,
    /// Strain window side in POIs; odd.
    pub strain_window: usize,
    pub interpolation: Interpolation,
    /// Subset shape function: first-order (affine, the default) or second-order.
    pub shape: ShapeFunction,
    /// Gaussian pre-filter applied to both images, σ in px (0 turns it off).
    pub prefilter_sigma_px: f64,
    /// IC-GN stops when the largest displacement the update causes in the subset is below this.
    pub convergence_px: f64,
    pub max_iterations: u32,
    /// Points whose final ZNCC is below this get the `low_correlation` status.
    pub min_zncc: f64,
    /// Points whose ZNSSD (= 2·(1 − ZNCC)) exceeds this many times the median ZNSSD of the
    /// field's valid points get the `low_correlation` status, unless their ZNCC is at least
    /// [`RELATIVE_ZNCC_FLOOR`](crate::dic::RELATIVE_ZNCC_FLOOR): a subset that straddles a
    /// discontinuity or a region the deformed image does not show matches only in part;
    /// `None` turns the test off.
    pub max_znssd_ratio: Option<f64>,
    /// Points whose predicted displacement standard deviation (fit residual against the
    /// subset's own gradients) exceeds this get the `no_texture` status, px.
    pub max_displacement_std_px: f64,
    /// Threshold of the normalised median test against the 3x3 neighbours (Westerweel &
    /// Scarano 2005 recommend 2); `None` turns the test off.
    pub outlier_threshold: Option<f64>,
    /// Polygons bounding the analysed region; points outside get the `masked` status.
    pub mask: Option<PolygonMask>,
    /// Largest rigid motion the global FFT cross-correlation looks for, in px.
    pub max_motion_px: usize,
    /// Integer search radius around the global offset where no converged neighbour helps, in px.
    pub search_radius_px: usize,
}

/// The subset shape function of IC-GN.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum ShapeFunction {
    /// First order: displacement and its four gradients (6 parameters).
    #[default]
    Affine,
    /// Second order: also the six second derivatives (12 parameters; Lu & Cary 2000), for
    /// displacement gradients that change across a subset. Slower; the first-order part is
    /// reported.
    Quadratic,
}

impl ShapeFunction {
    pub fn as_str(self) -> &'static str {
        match self {
            ShapeFunction::Affine => "affine",
            ShapeFunction::Quadratic => "quadratic",
        }
    }
}

impl std::str::FromStr for ShapeFunction {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "affine" => Ok(Self::Affine),
            "quadratic" => Ok(Self::Quadratic),
            other => Err(format!(
                "unknown shape function '{other}' (expected affine or quadratic)"
            )),
        }
    }
}

/// Side of the default ROI (the paper's 800x800 centred region).
pub const DEFAULT_ROI_SIDE_PX: usize = 800;

/// The smallest frame side an experiment captures or a comparison takes: room for one subset of
/// the default 41 px with its margins and a few points beside it.
pub const MIN_FRAME_SIDE_PX: usize = 64;

/// Upper bounds of the settings that size memory or work. Each is far beyond any useful analysis
/// and far below what would exhaust a lab PC: a request cannot ask for a 16k x 16k FFT
/// (`max_motion_px`), a subset larger than a camera, or millions of iterations per point.
pub const MAX_SUBSET_PX: usize = 1001;
pub const MAX_STEP_PX: usize = 10_000;
pub const MAX_STRAIN_WINDOW: usize = 101;
pub const MAX_ITERATIONS: u32 = 1_000;
pub const MAX_MOTION_PX: usize = 4_096;
pub const MAX_SEARCH_RADIUS_PX: usize = 256;
/// The largest ROI corner or side: a million pixels, beyond any sensor, and small enough that
/// no sum of two overflows.
pub const MAX_ROI_COORDINATE_PX: usize = 1 << 20;

impl Default for DicSettings {
    fn default() -> Self {
        Self {
            subset_px: 41,
            step_px: 20,
            roi: None,
            strain_window: 7,
            interpolation: Interpolation::Bspline3,
            shape: ShapeFunction::Affine,
            prefilter_sigma_px: 0.7,
            convergence_px: 1e-3,
            max_iterations: 50,
            min_zncc: 0.6,
            max_znssd_ratio: Some(10.0),
            max_displacement_std_px: 0.1,
            outlier_threshold: Some(2.0),
            mask: None,
            max_motion_px: 160,
            search_radius_px: 3,
        }
    }
}

impl DicSettings {
    /// Checks everything that does not depend on the images.
    pub fn validate(&self) -> Result<(), DicError> {
        let bad = |field: &'static str, reason: String| Err(DicError::Setting { field, reason });
        if self.subset_px < 5 || self.subset_px.is_multiple_of(2) || self.subset_px > MAX_SUBSET_PX
        {
            return bad(
                "subset",
                format!(
                    "subset size must be odd, 5 to {MAX_SUBSET_PX}, got {}",
                    self.subset_px
                ),
            );
        }
        if !(1..=MAX_STEP_PX).contains(&self.step_px) {
            return bad("step", format!("step must be 1 to {MAX_STEP_PX} px"));
        }
        if self.strain_window < 3
            || self.strain_window.is_multiple_of(2)
            || self.strain_window > MAX_STRAIN_WINDOW
        {
            return bad(
                "strain_window",
                format!(
                    "strain window must be odd, 3 to {MAX_STRAIN_WINDOW}, got {}",
                    self.strain_window
                ),
            );
        }
        if !(0.0..=5.0).contains(&self.prefilter_sigma_px) {
            return bad("prefilter_sigma_px", "must lie in [0, 5] px".into());
        }
        if !(self.convergence_px > 0.0 && self.convergence_px <= 1.0) {
            return bad("convergence_px", "must lie in (0, 1] px".into());
        }
        if !(1..=MAX_ITERATIONS).contains(&self.max_iterations) {
            return bad("max_iterations", format!("must be 1 to {MAX_ITERATIONS}"));
        }
        if !(-1.0..=1.0).contains(&self.min_zncc) {
            return bad("min_zncc", "must lie in [-1, 1]".into());
        }
        if !(self.max_displacement_std_px > 0.0 && self.max_displacement_std_px <= 100.0) {
            return bad("max_displacement_std_px", "must lie in (0, 100] px".into());
        }
        if let Some(r) = self.max_znssd_ratio {
            if !(1.0..=1e6).contains(&r) {
                return bad("max_znssd_ratio", "must lie in [1, 1e6]".into());
            }
        }
        if let Some(t) = self.outlier_threshold {
            if !(t > 0.0 && t <= 100.0) {
                return bad("outlier_threshold", "must lie in (0, 100]".into());
            }
        }
        if let Some(mask) = &self.mask {
            mask.validate()?;
        }
        if self.max_motion_px > MAX_MOTION_PX {
            return bad("max_motion_px", format!("at most {MAX_MOTION_PX} px"));
        }
        if self.search_radius_px > MAX_SEARCH_RADIUS_PX {
            return bad(
                "search_radius_px",
                format!("at most {MAX_SEARCH_RADIUS_PX} px"),
            );
        }
        if let Some(roi) = self.roi {
            if roi.width == 0 || roi.height == 0 {
                return bad("roi", "width and height must be at least 1 px".into());
            }
            if [roi.x, roi.y, roi.width, roi.height]
                .iter()
                .any(|&v| v > MAX_ROI_COORDINATE_PX)
            {
                return bad(
                    "roi",
                    format!("x, y, width and height at most {MAX_ROI_COORDINATE_PX} px"),
                );
            }
        }
        Ok(())
    }

    /// Half the subset side: the subset spans centre-half ..= centre+half.
    pub fn half_subset(&self) -> usize {
        self.subset_px / 2
    }

    /// Size of the virtual strain gauge in px: the span of the strain window plus one subset.
    pub fn strain_gauge_px(&self) -> usize {
        (self.strain_window - 1) * self.step_px + self.subset_px
    }

    /// The ROI used for an image of the given size.
    pub fn roi_for(&self, width: usize, height: usize) -> Result<Roi, DicError> {
        match self.roi {
            None => Ok(Roi::centred(
                width,
                height,
                DEFAULT_ROI_SIDE_PX,
                DEFAULT_ROI_SIDE_PX,
            )),
            Some(roi) => roi
                .clip(width, height)
                .ok_or(DicError::RoiOutside { roi, width, height }),
        }
    }
}
