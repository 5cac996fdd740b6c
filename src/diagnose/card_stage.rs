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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::basis::GeometricParam;
    use crate::diagnose::discrepancy::CommonPoint;
    use crate::diagnose::fit_geometric::GeometricFit;
    use crate::diagnose::test_fields::{
        field_points, field_sample, half_diagonal, manifest, measurement, PrintStated, CENTRE,
    };
    use crate::reduce::Scheme;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// A stage seen by the camera: its x axis at `angle` to the sensor's rows, `sx` px per mm,
    /// its y axis `skew` off the perpendicular to that, `sy` px per mm. A move (dx, dy) mm is
    /// imaged as dx·sx·(cos a, sin a) + dy·sy·(−sin(a + skew), cos(a + skew)).
    struct Stage {
        sx: f64,
        sy: f64,
        angle: f64,
        skew: f64,
    }

    impl Stage {
        fn imaged(&self, (dx, dy): (f64, f64)) -> (f64, f64) {
            let (s, c) = self.angle.sin_cos();
            let (sy_, cy_) = (self.angle + self.skew).sin_cos();
            (
                dx * self.sx * c - dy * self.sy * sy_,
                dx * self.sx * s + dy * self.sy * cy_,
            )
        }
    }

    /// The card's geometry with these linear terms only.
    fn geometry(terms: &[(GeometricParam, f64)]) -> CardGeometry {
        CardGeometry {
            linear: GeometricFit {
                params: terms.iter().map(|t| t.0).collect(),
                values: terms.iter().map(|t| t.1).collect(),
                stderr: vec![1e-9; terms.len()],
                chi2_drop: 0.0,
            },
            centred: None,
            r0: half_diagonal(),
        }
    }

    const MOVES_MM: [(f64, f64); 6] = [
        (5.0, 0.0),
        (0.0, 5.0),
        (2.5, 0.0),
        (0.0, -2.5),
        (3.0, 3.0),
        (-4.0, 1.0),
    ];

    #[test]
    fn a_turned_and_skewed_stage_is_read_back_from_the_runs_moves() {
        // No scatter: the map is exact. Run 0 is analysed in two schemes and counts once.
        let stage = Stage {
            sx: 26.13,
            sy: 25.95,
            angle: 4e-3,
            skew: -2e-3,
        };
        let meas = measurement(
            manifest(&MOVES_MM, &["a"], PrintStated::Nothing),
            &["native"],
        );
        let native = Scheme::parse("native").unwrap();
        let mut samples: Vec<FieldSample> = MOVES_MM
            .iter()
            .enumerate()
            .map(|(k, &mm)| field_sample(&native, &[], stage.imaged(mm), 1e-4, k))
            .collect();
        samples.push(field_sample(
            &native,
            &[],
            stage.imaged(MOVES_MM[0]),
            1e-4,
            0,
        ));
        let map = stage_map(&meas, &samples, &geometry(&[]), 26.0, 3.0).unwrap();
        assert_eq!(map.runs, MOVES_MM.len());
        for (got, truth) in [
            (map.scale_x_px_per_mm, stage.sx),
            (map.scale_y_px_per_mm, stage.sy),
            (map.angle_rad, stage.angle),
            (map.skew_rad, stage.skew),
        ] {
            assert!((got - truth).abs() < 1e-9, "{got} against {truth}");
        }
        assert!(map.residual_px < 1e-9, "{}", map.residual_px);
        assert_eq!(map.nominal_scale_px_per_mm, 26.0);
    }

    #[test]
    fn the_cards_fields_mean_over_each_runs_points_is_taken_off_its_move() {
        // A magnification 1 + s of the moved frame shifts each point by s·(p + t) (p from the
        // centre): a run's mean displacement holds s·(p̄ + t), which is the camera's, not the
        // stage's. Left in, the scale would read (1 + s)·26 = 26.0078 px/mm.
        let (stage, s) = (
            Stage {
                sx: 26.0,
                sy: 26.0,
                angle: 0.0,
                skew: 0.0,
            },
            3e-4,
        );
        let meas = measurement(
            manifest(&MOVES_MM, &["a"], PrintStated::Nothing),
            &["native"],
        );
        let native = Scheme::parse("native").unwrap();
        let points: Vec<Vec<CommonPoint>> = (0..MOVES_MM.len())
            .map(|k| field_points((0.0, 0.0), |_, _| (0.0, 0.0), 0.01, k as u64))
            .collect();
        let samples: Vec<FieldSample> = MOVES_MM
            .iter()
            .zip(&points)
            .enumerate()
            .map(|(k, (&mm, pts))| {
                let t = stage.imaged(mm);
                let n = pts.len() as f64;
                let mean = |f: &dyn Fn(&CommonPoint) -> f64| pts.iter().map(f).sum::<f64>() / n;
                let fu = mean(&|p| s * (p.x - CENTRE.0 + t.0));
                let fv = mean(&|p| s * (p.y - CENTRE.1 + t.1));
                field_sample(&native, pts, (t.0 + fu, t.1 + fv), 1e-4, k)
            })
            .collect();
        let g = geometry(&[(GeometricParam::Scale, s)]);
        let map = stage_map(&meas, &samples, &g, 26.0, 3.0).unwrap();
        // The field is taken at the sample's move, which holds its own mean: what is left is of
        // order s²·|t|, some 1e-5 px in 130 px, 2e-6 px/mm.
        assert!((map.scale_x_px_per_mm - 26.0).abs() < 1e-5, "{map:?}");
        assert!((map.scale_y_px_per_mm - 26.0).abs() < 1e-5, "{map:?}");
        assert!(map.angle_rad.abs() < 1e-8 && map.skew_rad.abs() < 1e-8);
    }

    #[test]
    fn landing_scatter_sets_the_errors_and_only_real_departures_are_significant() {
        // The stage's x travel 0.5 px/mm long and turned by 5 mrad; its y axis as stated and
        // square. Landings scatter by σ = 0.05 px per axis: a scale's error is about
        // σ/√Σdx² (Σdx² = 56.25 mm² here), and the LS residual's RMS over the runs about
        // σ·√((2n − 4)/n), n = 6 runs.
        let stage = Stage {
            sx: 26.5,
            sy: 26.0,
            angle: 5e-3,
            skew: 0.0,
        };
        let meas = measurement(
            manifest(&MOVES_MM, &["a"], PrintStated::Nothing),
            &["native"],
        );
        let native = Scheme::parse("native").unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let scatter = Normal::new(0.0, 0.05).unwrap();
        let samples: Vec<FieldSample> = MOVES_MM
            .iter()
            .enumerate()
            .map(|(k, &mm)| {
                let (u, v) = stage.imaged(mm);
                let landed = (u + scatter.sample(&mut rng), v + scatter.sample(&mut rng));
                field_sample(&native, &[], landed, 1e-4, k)
            })
            .collect();
        let map = stage_map(&meas, &samples, &geometry(&[]), 26.0, 3.0).unwrap();
        let sum_dx2: f64 = MOVES_MM.iter().map(|m| m.0 * m.0).sum();
        let rough_se = 0.05 / sum_dx2.sqrt();
        let ratio = map.scale_x_se_px_per_mm / rough_se;
        assert!((0.5..2.0).contains(&ratio), "{ratio}");
        let n = MOVES_MM.len() as f64;
        let residual = 0.05 * ((2.0 * n - 4.0) / n).sqrt();
        assert!(
            (map.residual_px / residual - 1.0).abs() < 0.5,
            "{}",
            map.residual_px
        );
        for (got, se, truth) in [
            (map.scale_x_px_per_mm, map.scale_x_se_px_per_mm, stage.sx),
            (map.scale_y_px_per_mm, map.scale_y_se_px_per_mm, stage.sy),
            (map.angle_rad, map.angle_se_rad, stage.angle),
            (map.skew_rad, map.skew_se_rad, stage.skew),
        ] {
            assert!(
                (got - truth).abs() < 3.0 * se,
                "{got} ± {se} against {truth}"
            );
        }
        assert_eq!(map.significant, vec!["scale_x", "angle"]);
    }

    #[test]
    fn two_runs_or_moves_along_one_axis_make_no_map() {
        let native = Scheme::parse("native").unwrap();
        let map_of = |moves: &[(f64, f64)]| {
            let meas = measurement(manifest(moves, &["a"], PrintStated::Nothing), &["native"]);
            let samples: Vec<FieldSample> = moves
                .iter()
                .enumerate()
                .map(|(k, &(dx, dy))| field_sample(&native, &[], (26.0 * dx, 26.0 * dy), 1e-4, k))
                .collect();
            stage_map(&meas, &samples, &geometry(&[]), 26.0, 3.0)
        };
        assert!(map_of(&MOVES_MM[..2]).is_none(), "two runs");
        assert!(
            map_of(&[(5.0, 0.0), (2.5, 0.0), (-1.0, 0.0)]).is_none(),
            "x only"
        );
        assert!(map_of(&MOVES_MM[..3]).is_some());
    }
}
