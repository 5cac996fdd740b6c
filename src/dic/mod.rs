//! 2D subset digital image correlation: B-spline interpolation, a global FFT initial guess with
//! per-point integer refinement, IC-GN with the first-order shape function and the ZNSSD
//! criterion, strain by pointwise least squares, and summary statistics.
//!
//! Nothing here knows about files, cameras or HTTP: images in, [`DicResult`] out.

mod bspline;
mod engine;
mod error;
mod fft_guess;
mod grid;
mod icgn;
mod integer_search;
mod prefilter;
mod result;
mod settings;
mod stats;
mod strain;
mod warp;

pub use bspline::{BSplineImage, Interpolation};
pub use engine::{analyze, PreparedReference, Progress};
pub use error::DicError;
pub use fft_guess::global_offset;
pub use grid::PoiGrid;
pub use prefilter::gaussian_blur;
pub use result::{DicResult, PoiResult, PoiStatus};
pub use settings::{DicSettings, DEFAULT_ROI_SIDE_PX};
pub use stats::{Stats, Summary};
pub use warp::Warp;
