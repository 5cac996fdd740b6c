//! Speckle-pattern quality of one frame, the figures a DIC user checks before an experiment:
//!
//! - **mean intensity gradient** (MIG, Pan, Xie, Wang, Qian & Lu, "Mean intensity gradient: an
//!   effective global parameter for quality assessment of the speckle patterns used in digital
//!   image correlation", Opt. Lasers Eng. 48 (2010) 469): the mean of |∇f| over the image.
//!   Derivatives are central differences, (f(x+1) − f(x−1)) / 2; on a pattern that varies along
//!   one axis the normalised Sobel kernel the paper uses gives the same. The larger, the smaller
//!   the random error of every subset (Pan et al. 2010, eq. 9: σ_u ∝ σ_noise / MIG).
//! - **mean speckle size**: the full width at half maximum of the normalised autocorrelation of
//!   the mean-free image, along x and along y (the definition used by e.g. Sutton, Orteu &
//!   Schreier, *Image Correlation for Shape, Motion and Deformation Measurements*, 2009, §7.2).
//!   Speckles of about 3 to 5 px are what subpixel interpolation resolves without aliasing.
//! - **SSSIG** (Pan, Xie, Wang, Qian & Wang, "Study on subset size selection in digital image
//!   correlation for speckle patterns", Opt. Express 16 (2008) 7037; also Opt. Lasers Eng. 46
//!   (2008) 460): the sum of squared subset intensity gradients, Σ f_x² and Σ f_y² over one
//!   subset. The standard deviation of the displacement a subset measures is, to first order,
//!   σ_u ≈ √2 · σ_noise / √SSSIG_x (and v with SSSIG_y), with σ_noise the image noise in DN.
//!
//! Pure numerics: an image in, numbers out; nothing here knows of files or HTTP.

use super::Image;
use crate::stats::median;
use serde::Serialize;

/// Longest autocorrelation lag looked at, px: a pattern whose autocorrelation is still above
/// one half there has no speckle size a DIC subset could use.
pub const MAX_SPECKLE_LAG_PX: usize = 64;

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SpeckleQualityError {
    #[error(
        "a {width}x{height} px image holds no {subset_px} px subset (with a one-pixel border for the gradients)"
    )]
    TooSmall {
        width: usize,
        height: usize,
        subset_px: usize,
    },
    #[error("the subset must be at least 3 px, got {0}")]
    Subset(usize),
}

/// The figures of [`speckle_quality`]. Intensities are in the image's own digital numbers (DN).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SpeckleQuality {
    /// Mean |∇f| over the image, DN/px (Pan et al. 2010).
    pub mean_gradient_dn_per_px: f64,
    /// Full width at half maximum of the autocorrelation along x and along y, px; `None` when
    /// it stays above one half up to [`MAX_SPECKLE_LAG_PX`] (no usable speckle along that axis).
    pub speckle_size_x_px: Option<f64>,
    pub speckle_size_y_px: Option<f64>,
    /// The mean of the two sizes (`None` unless both exist).
    pub speckle_size_px: Option<f64>,
    /// Subset side the SSSIG is summed over, px.
    pub subset_px: usize,
    /// Non-overlapping subsets tiling the image, whose SSSIG the figures below summarise.
    pub subsets: usize,
    /// Median over the subsets of Σ f_x² and Σ f_y², DN².
    pub sssig_x_median_dn2: f64,
    pub sssig_y_median_dn2: f64,
    /// The smallest subset's Σ f_x² and Σ f_y², DN² (the worst place in the image).
    pub sssig_x_min_dn2: f64,
    pub sssig_y_min_dn2: f64,
    /// σ_u and σ_v a median subset would show per DN of image noise, px/DN:
    /// √2 / √SSSIG (Pan et al. 2008). Multiply by the noise σ in DN.
    pub std_u_px_per_noise_dn: f64,
    pub std_v_px_per_noise_dn: f64,
}

/// Central-difference gradients (f_x, f_y) at interior pixel (c, r).
fn gradient(img: &Image, c: usize, r: usize) -> (f64, f64) {
    let fx = 0.5 * (img.get(c + 1, r) as f64 - img.get(c - 1, r) as f64);
    let fy = 0.5 * (img.get(c, r + 1) as f64 - img.get(c, r - 1) as f64);
    (fx, fy)
}

/// Mean |∇f| over the interior pixels, DN/px.
pub fn mean_intensity_gradient(img: &Image) -> f64 {
    let (w, h) = (img.width(), img.height());
    if w < 3 || h < 3 {
        return f64::NAN;
    }
    let mut sum = 0.0;
    for r in 1..h - 1 {
        for c in 1..w - 1 {
            let (fx, fy) = gradient(img, c, r);
            sum += fx.hypot(fy);
        }
    }
    sum / ((w - 2) * (h - 2)) as f64
}

/// Σ f_x² and Σ f_y² over the `side` x `side` subset with top-left pixel (c0, r0), all of whose
/// pixels must be interior.
pub fn sssig(img: &Image, c0: usize, r0: usize, side: usize) -> (f64, f64) {
    let (mut sx, mut sy) = (0.0, 0.0);
    for r in r0..r0 + side {
        for c in c0..c0 + side {
            let (fx, fy) = gradient(img, c, r);
            sx += fx * fx;
            sy += fy * fy;
        }
    }
    (sx, sy)
}

/// Normalised autocorrelation of the mean-free image at lag `lag` along x (or y), over the
/// pairs that overlap: ⟨g(p) g(p + lag)⟩ / ⟨g²⟩.
fn autocorrelation(img: &Image, mean: f64, variance: f64, lag: usize, along_x: bool) -> f64 {
    let (w, h) = (img.width(), img.height());
    let (cols, rows) = if along_x { (w - lag, h) } else { (w, h - lag) };
    let mut sum = 0.0;
    for r in 0..rows {
        for c in 0..cols {
            let (c2, r2) = if along_x { (c + lag, r) } else { (c, r + lag) };
            sum += (img.get(c, r) as f64 - mean) * (img.get(c2, r2) as f64 - mean);
        }
    }
    sum / (cols * rows) as f64 / variance
}

/// Full width at half maximum of the autocorrelation along one axis: twice the lag where it
/// first falls to one half, linearly interpolated between integer lags.
pub fn speckle_size(img: &Image, along_x: bool) -> Option<f64> {
    let (mean, std) = img.mean_std();
    let variance = std * std;
    let extent = if along_x { img.width() } else { img.height() };
    if !(variance > 0.0) || extent < 4 {
        return None;
    }
    let max_lag = MAX_SPECKLE_LAG_PX.min(extent / 2);
    let mut previous = 1.0;
    for lag in 1..=max_lag {
        let rho = autocorrelation(img, mean, variance, lag, along_x);
        if rho <= 0.5 {
            let half = (lag - 1) as f64 + (previous - 0.5) / (previous - rho);
            return Some(2.0 * half);
        }
        previous = rho;
    }
    None
}

/// Every figure of the module for `img` and subsets of `subset_px`.
pub fn speckle_quality(
    img: &Image,
    subset_px: usize,
) -> Result<SpeckleQuality, SpeckleQualityError> {
    if subset_px < 3 {
        return Err(SpeckleQualityError::Subset(subset_px));
    }
    let (w, h) = (img.width(), img.height());
    // Subsets tile the interior (one-pixel border for the central differences).
    let (nx, ny) = (
        w.saturating_sub(2) / subset_px,
        h.saturating_sub(2) / subset_px,
    );
    if nx == 0 || ny == 0 {
        return Err(SpeckleQualityError::TooSmall {
            width: w,
            height: h,
            subset_px,
        });
    }
    let (mut xs, mut ys) = (Vec::with_capacity(nx * ny), Vec::with_capacity(nx * ny));
    for j in 0..ny {
        for i in 0..nx {
            let (sx, sy) = sssig(img, 1 + i * subset_px, 1 + j * subset_px, subset_px);
            xs.push(sx);
            ys.push(sy);
        }
    }
    let sx_median = median(&mut xs);
    let sy_median = median(&mut ys);
    let (size_x, size_y) = (speckle_size(img, true), speckle_size(img, false));
    Ok(SpeckleQuality {
        mean_gradient_dn_per_px: mean_intensity_gradient(img),
        speckle_size_x_px: size_x,
        speckle_size_y_px: size_y,
        speckle_size_px: size_x.zip(size_y).map(|(a, b)| 0.5 * (a + b)),
        subset_px,
        subsets: xs.len(),
        sssig_x_median_dn2: sx_median,
        sssig_y_median_dn2: sy_median,
        sssig_x_min_dn2: xs[0],
        sssig_y_min_dn2: ys[0],
        std_u_px_per_noise_dn: std::f64::consts::SQRT_2 / sx_median.sqrt(),
        std_v_px_per_noise_dn: std::f64::consts::SQRT_2 / sy_median.sqrt(),
    })
}

/// Sorts `v` (ascending) and returns its median.
#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// f = A sin(2πx/P) sin(2πy/P) + B: a checkerboard of speckles P/2 wide.
    fn checkerboard(w: usize, h: usize, period: f64, a: f64, b: f64) -> Image {
        Image::from_fn(w, h, |c, r| {
            (a * (2.0 * PI * c as f64 / period).sin() * (2.0 * PI * r as f64 / period).sin() + b)
                as f32
        })
    }

    #[test]
    fn gradient_of_a_ramp_is_its_slope() {
        // f = 3x − 4y + 1000: |∇f| = 5 everywhere, exactly, with central differences.
        let img = Image::from_fn(50, 40, |c, r| {
            (3.0 * c as f64 - 4.0 * r as f64 + 1000.0) as f32
        });
        assert!((mean_intensity_gradient(&img) - 5.0).abs() < 1e-4);
    }

    #[test]
    fn sssig_of_a_sinusoid_is_its_integrated_squared_derivative() {
        // f = A sin(2πx/P): the central difference is A sin(2π/P) cos(2πx/P), and Σ cos² over
        // whole periods is half the number of samples (for P ≥ 3). Over a subset of side n that
        // spans whole periods along x: Σ f_x² = n² A² sin²(2π/P) / 2, Σ f_y² = 0.
        let (a, p, n) = (100.0_f64, 8.0_f64, 24);
        let img = Image::from_fn(40, 40, |c, _| {
            (a * (2.0 * PI * c as f64 / p).sin() + 500.0) as f32
        });
        let (sx, sy) = sssig(&img, 1, 1, n);
        let want = (n * n) as f64 * a * a * (2.0 * PI / p).sin().powi(2) / 2.0;
        assert!((sx / want - 1.0).abs() < 1e-5, "{sx} vs {want}");
        assert!(sy.abs() < 1e-6, "{sy}");
        let q = speckle_quality(&img, n).unwrap();
        assert_eq!(q.subsets, 1);
        assert!((q.std_u_px_per_noise_dn - (2.0 / want).sqrt()).abs() < 1e-9);
        assert!(q.std_v_px_per_noise_dn.is_infinite());
        // Mean |f_x| over whole periods: A sin(2π/P) · mean |cos|, and over the 8 samples of a
        // period mean |cos(2πk/8)| = (1 + √2) / 4.
        let mig_want = a * (2.0 * PI / p).sin() * (1.0 + 2f64.sqrt()) / 4.0;
        let mig = mean_intensity_gradient(&Image::from_fn(8 * 5 + 2, 10, |c, _| {
            (a * (2.0 * PI * (c as f64 - 1.0) / p).sin()) as f32
        }));
        assert!((mig / mig_want - 1.0).abs() < 1e-5, "{mig} vs {mig_want}");
    }

    #[test]
    fn speckle_size_of_a_checkerboard_is_a_third_of_its_period() {
        // The autocorrelation of sin(2πx/P) sin(2πy/P) along x is cos(2πτ/P): one half at
        // τ = P/6, so the full width at half maximum is P/3 on both axes. Over a finite window the
        // overlapping pairs do not span whole periods: the estimate is off by O(P / side), about
        // 0.03 px for a 960 px side (0.11 px for 240 px).
        let p = 24.0;
        let img = checkerboard(960, 960, p, 1000.0, 2000.0);
        let q = speckle_quality(&img, 21).unwrap();
        for s in [q.speckle_size_x_px, q.speckle_size_y_px, q.speckle_size_px] {
            let s = s.unwrap();
            assert!((s - p / 3.0).abs() < 0.1, "{s}");
        }
        // A larger pattern has larger speckles and a smaller gradient.
        let coarse = speckle_quality(&checkerboard(960, 960, 2.0 * p, 1000.0, 2000.0), 21).unwrap();
        assert!((coarse.speckle_size_px.unwrap() - 2.0 * p / 3.0).abs() < 0.2);
        assert!(coarse.mean_gradient_dn_per_px < q.mean_gradient_dn_per_px);
    }

    #[test]
    fn flat_and_tiny_images() {
        let flat = Image::filled(64, 64, 100.0);
        let q = speckle_quality(&flat, 21).unwrap();
        assert_eq!(q.mean_gradient_dn_per_px, 0.0);
        assert_eq!(q.speckle_size_px, None);
        assert!(q.std_u_px_per_noise_dn.is_infinite());
        assert_eq!(
            speckle_quality(&flat, 63),
            Err(SpeckleQualityError::TooSmall {
                width: 64,
                height: 64,
                subset_px: 63
            })
        );
        assert_eq!(
            speckle_quality(&flat, 2),
            Err(SpeckleQualityError::Subset(2))
        );
    }
}
