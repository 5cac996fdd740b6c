//! What an analysis produces: one record per point of interest, the strain gauge, statistics.

use super::{DicSettings, PoiGrid, Summary};
use serde::{Deserialize, Serialize};

/// The outcome of one point of interest. Only `Converged` points are valid and carry
/// displacements: converged, correlated above `min_zncc`, a plausible shape, a texture that
/// determines the position, and in agreement with the neighbours.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PoiStatus {
    Converged,
    /// IC-GN hit the iteration limit.
    NotConverged,
    /// Converged, but the final ZNCC is below the threshold.
    LowCorrelation,
    /// The warped subset left the deformed image.
    LeftImage,
    /// The reference subset has no usable intensity variation (flat, or gradients in one
    /// direction only, which makes the Gauss-Newton Hessian singular).
    NoContrast,
    /// The subset's gradients do not pin its position down against the fit residual: the
    /// predicted standard deviation of u or v exceeds `max_displacement_std_px` (a blank or
    /// nearly blank region whose noise or shading the correlation can lock onto anywhere).
    NoTexture,
    /// Converged to a shape no real deformation of a subset has (a displacement gradient
    /// beyond [`MAX_PLAUSIBLE_GRADIENT`](crate::dic::MAX_PLAUSIBLE_GRADIENT)).
    Implausible,
    /// Disagrees with its neighbours by the normalised median test (Westerweel & Scarano,
    /// "Universal outlier detection for PIV data", Exp. Fluids 39 (2005)).
    Outlier,
    /// The subset centre lies outside the analysis mask.
    Masked,
}

impl PoiStatus {
    /// Every status, in declaration order (the codes the Python bindings give them).
    pub const ALL: [PoiStatus; 9] = [
        PoiStatus::Converged,
        PoiStatus::NotConverged,
        PoiStatus::LowCorrelation,
        PoiStatus::LeftImage,
        PoiStatus::NoContrast,
        PoiStatus::NoTexture,
        PoiStatus::Implausible,
        PoiStatus::Outlier,
        PoiStatus::Masked,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            PoiStatus::Converged => "converged",
            PoiStatus::NotConverged => "not_converged",
            PoiStatus::LowCorrelation => "low_correlation",
            PoiStatus::LeftImage => "left_image",
            PoiStatus::NoContrast => "no_contrast",
            PoiStatus::NoTexture => "no_texture",
            PoiStatus::Implausible => "implausible",
            PoiStatus::Outlier => "outlier",
            PoiStatus::Masked => "masked",
        }
    }

    pub fn is_valid(self) -> bool {
        self == PoiStatus::Converged
    }
}

/// One point of interest. Displacements and strains are NaN unless the point is valid.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoiResult {
    /// Subset centre in the reference image, px.
    pub x: f64,
    pub y: f64,
    /// Displacement of the subset centre, px.
    pub u: f64,
    pub v: f64,
    /// Displacement gradients of the first-order shape function.
    pub du_dx: f64,
    pub du_dy: f64,
    pub dv_dx: f64,
    pub dv_dy: f64,
    /// Small strains from the strain window (not the subset's own gradients).
    pub exx: f64,
    pub eyy: f64,
    pub exy: f64,
    /// Zero-normalised cross-correlation at the solution (NaN when never evaluated).
    pub zncc: f64,
    /// Standard deviation of u and v predicted from the fit residual and the subset's own
    /// gradients (the Gauss-Newton covariance σ̂²·H⁻¹), px; NaN when never evaluated.
    #[serde(default = "nan")]
    pub u_std_px: f64,
    #[serde(default = "nan")]
    pub v_std_px: f64,
    pub iterations: u32,
    pub status: PoiStatus,
}

impl PoiResult {
    pub fn invalid(x: f64, y: f64, status: PoiStatus, zncc: f64, iterations: u32) -> Self {
        Self {
            x,
            y,
            u: f64::NAN,
            v: f64::NAN,
            du_dx: f64::NAN,
            du_dy: f64::NAN,
            dv_dx: f64::NAN,
            dv_dy: f64::NAN,
            exx: f64::NAN,
            eyy: f64::NAN,
            exy: f64::NAN,
            zncc,
            u_std_px: f64::NAN,
            v_std_px: f64::NAN,
            iterations,
            status,
        }
    }
}

impl PoiResult {
    /// This point refused with `status`: displacements and strains cleared to NaN, its
    /// correlation evidence (ZNCC, predicted std, iterations) kept to show why.
    pub fn rejected(self, status: PoiStatus) -> Self {
        Self {
            u_std_px: self.u_std_px,
            v_std_px: self.v_std_px,
            ..Self::invalid(self.x, self.y, status, self.zncc, self.iterations)
        }
    }
}

fn nan() -> f64 {
    f64::NAN
}

/// Everything one analysis produced, with every setting that produced it.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct DicResult {
    pub settings: DicSettings,
    pub grid: PoiGrid,
    /// Row-major over the grid.
    pub points: Vec<PoiResult>,
    /// Integer rigid offset found by the global FFT cross-correlation, px.
    pub global_offset_px: (i64, i64),
    /// Size of the virtual strain gauge, px.
    pub strain_gauge_px: usize,
    pub summary: Summary,
}

impl DicResult {
    pub fn valid_count(&self) -> usize {
        self.points.iter().filter(|p| p.status.is_valid()).count()
    }

    /// How many points got each status, in the order of the statuses' names.
    pub fn status_counts(&self) -> Vec<(PoiStatus, usize)> {
        let mut counts: Vec<(PoiStatus, usize)> = Vec::new();
        for p in &self.points {
            match counts.iter_mut().find(|(s, _)| *s == p.status) {
                Some((_, n)) => *n += 1,
                None => counts.push((p.status, 1)),
            }
        }
        counts.sort_by_key(|(s, _)| s.as_str());
        counts
    }
}
