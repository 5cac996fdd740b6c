//! The measured motion against the commanded one: a rigid move's bias (measured mean − expected)
//! with the 95 % interval of its random part, and the scatter about it — the two numbers an
//! experimentalist reads off a translation test ("how accurate is my camera?").

use super::{
    valid_fields, BlockBootstrap, CorrelationLengths, DicResult, Stats,
    BLOCK_PER_CORRELATION_LENGTH,
};
use serde::Serialize;

/// One displacement component against its expected value, px.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Bias {
    pub expected_px: f64,
    pub mean_px: f64,
    /// `mean_px − expected_px`.
    pub bias_px: f64,
    /// 95 % interval of the bias's random part (the field mean's, by a block bootstrap over the
    /// grid; ≈ 25 % too narrow, as the std's: `bootstrap.rs`); NaN on a grid too small for it.
    pub bias_ci95_px: [f64; 2],
    pub std_px: f64,
    pub valid_points: usize,
}

/// u and v of `result` against the expected rigid move `(u, v)`, px.
pub fn bias_against(result: &DicResult, expected_px: (f64, f64)) -> [Bias; 2] {
    let fields = valid_fields(&result.points);
    let (nx, ny) = (result.grid.nx(), result.grid.ny());
    let lengths = CorrelationLengths::of(&result.settings);
    let intervals = BlockBootstrap::new(
        nx,
        ny,
        BLOCK_PER_CORRELATION_LENGTH * lengths.displacement_points,
    )
    .filter(|_| nx * ny == result.points.len())
    .map_or([[f64::NAN; 2]; 2], |plan| {
        let ci = plan.mean_intervals(&[&fields[0], &fields[1]]);
        [ci[0], ci[1]]
    });
    let component = |stats: Stats, expected: f64, [lo, hi]: [f64; 2]| Bias {
        expected_px: expected,
        mean_px: stats.mean,
        bias_px: stats.mean - expected,
        bias_ci95_px: [lo - expected, hi - expected],
        std_px: stats.std,
        valid_points: stats.count,
    };
    [
        component(result.summary.u, expected_px.0, intervals[0]),
        component(result.summary.v, expected_px.1, intervals[1]),
    ]
}
