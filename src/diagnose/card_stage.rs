//! The camera card's stage map: the least-squares linear map from the commanded moves (mm) to
//! each run's measured rigid move (px), with the card's fitted fields' mean over the run's points
//! taken off — scale per axis, the angle of the stage's x axis to the sensor's rows and the
//! non-orthogonality of its axes (the affine stage-to-camera map of Micro-Manager's pixel
//! calibrator; see [`super::card`]).

use super::card_distortion::CardGeometry;
use super::fit_geometric::FieldSample;
use super::measurement::Measurement;
use serde::{Deserialize, Serialize};

/// The stage against the sensor, from the runs' measured rigid moves.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StageMap {
    /// The scale the dataset states, px/mm.
    pub nominal_scale_px_per_mm: f64,
    /// Image px per mm of the stage's x travel, and its standard error.
    pub scale_x_px_per_mm: f64,
    pub scale_x_se_px_per_mm: f64,
    pub scale_y_px_per_mm: f64,
    pub scale_y_se_px_per_mm: f64,
    /// The stage's x axis against the sensor's rows, rad (positive: a +x move goes towards +y
    /// in the image).
    pub angle_rad: f64,
    pub angle_se_rad: f64,
    /// The stage's y axis's departure from perpendicular to its x axis, rad.
    pub skew_rad: f64,
    pub skew_se_rad: f64,
    /// RMS of the runs' moves about the map, px: the stage's landing scatter.
    pub residual_px: f64,
    pub runs: usize,
    /// Which of `scale_x`, `scale_y` (against the nominal scale), `angle`, `skew` (against 0)
    /// differ significantly.
    pub significant: Vec<String>,
}

/// The least-squares linear map from commanded moves (mm) to the runs' rigid moves (px), the
/// fitted fields' mean over each run's points taken off; None with fewer than three runs or moves
/// along one axis only.
pub(super) fn stage_map(
    meas: &Measurement,
    samples: &[FieldSample],
    geometry: &CardGeometry,
    nominal_scale_px_per_mm: f64,
    z: f64,
) -> Option<StageMap> {
    let mut seen = std::collections::BTreeSet::new();
    let rows: Vec<([f64; 2], [f64; 2])> = samples
        .iter()
        .filter(|s| seen.insert(s.run))
        .map(|s| {
            let stage = &meas.manifest.runs[s.run].stage;
            let (fu, fv) = mean_field(s, geometry);
            (
                [stage.dx_mm, stage.dy_mm],
                [s.move_px.0 - fu, s.move_px.1 - fv],
            )
        })
        .collect();
    let n = rows.len();
    let (mut xx, mut xy, mut yy) = (0.0, 0.0, 0.0);
    for ([dx, dy], _) in &rows {
        xx += dx * dx;
        xy += dx * dy;
        yy += dy * dy;
    }
    let det = xx * yy - xy * xy;
    if n < 3 || !(det > 1e-12 * (xx * yy).max(1e-300)) {
        return None;
    }
    let inv = [yy / det, -xy / det, xx / det];
    let solve = |k: usize| {
        let (mut sx, mut sy) = (0.0, 0.0);
        for ([dx, dy], m) in &rows {
            sx += dx * m[k];
            sy += dy * m[k];
        }
        [inv[0] * sx + inv[1] * sy, inv[1] * sx + inv[2] * sy]
    };
    let (row_u, row_v) = (solve(0), solve(1));
    let ss: f64 = rows
        .iter()
        .map(|([dx, dy], m)| {
            (m[0] - row_u[0] * dx - row_u[1] * dy).powi(2)
                + (m[1] - row_v[0] * dx - row_v[1] * dy).powi(2)
        })
        .sum();
    let dof = (2 * n - 4).max(1) as f64;
    let s = (ss / dof).sqrt();
    let (a11, a12, a21, a22) = (row_u[0], row_u[1], row_v[0], row_v[1]);
    let scale_x = a11.hypot(a21);
    let scale_y = a12.hypot(a22);
    let (se_x, se_y) = (s * inv[0].sqrt(), s * inv[2].sqrt());
    let angle = a21.atan2(a11);
    let angle_se = se_x / scale_x;
    let y_angle = (-a12).atan2(a22);
    let skew = y_angle - angle;
    let skew_se = angle_se.hypot(se_y / scale_y);
    let tests = [
        ("scale_x", scale_x - nominal_scale_px_per_mm, se_x),
        ("scale_y", scale_y - nominal_scale_px_per_mm, se_y),
        ("angle", angle, angle_se),
        ("skew", skew, skew_se),
    ];
    Some(StageMap {
        nominal_scale_px_per_mm,
        scale_x_px_per_mm: scale_x,
        scale_x_se_px_per_mm: se_x,
        scale_y_px_per_mm: scale_y,
        scale_y_se_px_per_mm: se_y,
        angle_rad: angle,
        angle_se_rad: angle_se,
        skew_rad: skew,
        skew_se_rad: skew_se,
        residual_px: (ss / n as f64).sqrt(),
        runs: n,
        significant: tests
            .iter()
            .filter(|(_, d, se)| d.abs() > z * se)
            .map(|(name, _, _)| name.to_string())
            .collect(),
    })
}

/// The mean over a run's points of the card's fitted fields, full-resolution px.
fn mean_field(s: &FieldSample, geometry: &CardGeometry) -> (f64, f64) {
    if s.points.is_empty() {
        return (0.0, 0.0);
    }
    let (mut su, mut sv) = (0.0, 0.0);
    for p in s.points {
        let (fx, fy) = s.scheme.to_full(p.x, p.y);
        let (u, v) = geometry.displacement((fx - s.centre.0, fy - s.centre.1), s.move_px);
        su += u;
        sv += v;
    }
    let n = s.points.len() as f64;
    (su / n, sv / n)
}
