//! 2D subset digital image correlation: B-spline interpolation, initial guesses from a global
//! FFT offset (translation) or a Fourier-Mellin similarity (rotation and scale) at seed points,
//! reliability-guided propagation over the grid, IC-GN with the first-order shape function and
//! the ZNSSD criterion, validation (ZNCC, shape, texture, normalised median test, masks),
//! strain by pointwise least squares, and summary statistics.
//!
//! Nothing here knows about files, cameras or HTTP: images in, [`DicResult`] out.

mod bias;
mod bootstrap;
mod bspline;
mod engine;
mod error;
mod fft_guess;
mod grid;
mod icgn;
mod icgn_sums;
mod integer_search;
mod mask;
mod prefilter;
mod propagate;
mod quadratic;
mod reference_sums;
mod result;
mod sequence;
mod settings;
mod similarity;
mod stats;
mod strain;
mod validate;
mod warp;

pub use bias::{bias_against, Bias};
pub use bootstrap::{
    BlockBootstrap, BLOCK_PER_CORRELATION_LENGTH, BOOTSTRAP_REPLICATES, MIN_BLOCKS,
};
pub use bspline::{BSplineImage, Interpolation};
pub use engine::{analyze, PreparedReference, Progress, Watch};
pub use error::DicError;
pub use fft_guess::global_offset;
pub use grid::PoiGrid;
pub use mask::{Polygon, PolygonMask, RasterMask, MAX_MASK_VERTICES};
pub use prefilter::gaussian_blur;
pub use result::{DicResult, PoiResult, PoiStatus};
pub use sequence::{analyze_sequence, SequenceFrame, REFERENCE_UPDATE_FRACTION};
pub use settings::{
    DicSettings, ShapeFunction, DEFAULT_ROI_SIDE_PX, MAX_ITERATIONS, MAX_MOTION_PX,
    MAX_ROI_COORDINATE_PX, MAX_SEARCH_RADIUS_PX, MAX_STEP_PX, MAX_STRAIN_WINDOW, MAX_SUBSET_PX,
    MIN_FRAME_SIDE_PX,
};
pub use similarity::{estimate_similarity, Similarity};
pub use stats::{f64_or_nan, interval_or_nan, valid_fields, CorrelationLengths, Stats, Summary};
pub use validate::{MAX_PLAUSIBLE_GRADIENT, RELATIVE_ZNCC_FLOOR};
pub use warp::Warp;
