//! Where the model fails: the residual map of each run and scheme (measured − model displacement
//! at every point of interest) and its profiles against position, as data (`comparison.json`);
//! drawn by `report::comparison_svgs`.

use super::discrepancy::RunDiscrepancy;
use crate::dic::DicResult;
use serde::{Deserialize, Serialize};

/// The residual field of one run and scheme on the DIC grid, px of the analysed image.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ResidualMap {
    /// Grid positions (px of the analysed image).
    pub xs: Vec<f64>,
    pub ys: Vec<f64>,
    /// Row-major over the grid; NaN (null in JSON) where either analysis has no valid point.
    pub du: Vec<f64>,
    pub dv: Vec<f64>,
    /// Mean residual per grid column: (x, Δu, Δv); per grid row: (y, Δu, Δv).
    pub profile_x: Vec<[f64; 3]>,
    pub profile_y: Vec<[f64; 3]>,
}

pub fn residual_map(measured: &DicResult, d: &RunDiscrepancy) -> ResidualMap {
    let xs: Vec<f64> = measured.grid.xs.iter().map(|&x| x as f64).collect();
    let ys: Vec<f64> = measured.grid.ys.iter().map(|&y| y as f64).collect();
    let n = xs.len() * ys.len();
    let mut du = vec![f64::NAN; n];
    let mut dv = vec![f64::NAN; n];
    for p in &d.common {
        if p.index < n {
            du[p.index] = p.du;
            dv[p.index] = p.dv;
        }
    }
    let profile = |along_x: bool| -> Vec<[f64; 3]> {
        let (outer, inner) = if along_x {
            (xs.len(), ys.len())
        } else {
            (ys.len(), xs.len())
        };
        (0..outer)
            .filter_map(|a| {
                let (mut su, mut sv, mut k) = (0.0, 0.0, 0.0);
                for b in 0..inner {
                    let idx = if along_x {
                        b * xs.len() + a
                    } else {
                        a * xs.len() + b
                    };
                    if du[idx].is_finite() {
                        su += du[idx];
                        sv += dv[idx];
                        k += 1.0;
                    }
                }
                (k > 0.0).then(|| [if along_x { xs[a] } else { ys[a] }, su / k, sv / k])
            })
            .collect()
    };
    ResidualMap {
        profile_x: profile(true),
        profile_y: profile(false),
        xs,
        ys,
        du,
        dv,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::discrepancy::run_discrepancy;
    use crate::diagnose::test_fields::synthetic_result;
    use crate::dic::{DicSettings, PoiStatus};

    #[test]
    fn the_map_holds_each_points_difference_and_its_profiles_the_means() {
        // u differs by 1e-4·(x − 320) px, v by nothing; one point is invalid in the model.
        let settings = DicSettings {
            subset_px: 21,
            step_px: 40,
            ..DicSettings::default()
        };
        let measured = synthetic_result(
            (640, 480),
            &settings,
            |x, _| (1e-4 * (x - 320.0), 0.0),
            0.0,
            1,
        );
        let mut model = synthetic_result((640, 480), &settings, |_, _| (0.0, 0.0), 0.0, 2);
        model.points[5].status = PoiStatus::LowCorrelation;
        let d = run_discrepancy(&measured, &model, 1.0);
        let map = residual_map(&measured, &d);
        assert_eq!(map.du.len(), map.xs.len() * map.ys.len());
        assert!(map.du[5].is_nan() && map.dv[5].is_nan());
        let (k, p) = (6, &measured.points[6]);
        assert!((map.du[k] - 1e-4 * (p.x - 320.0)).abs() < 1e-12);
        // Every column's mean is its x's difference; every row's mean the grid's mean of it.
        for [x, du, dv] in &map.profile_x {
            assert!((du - 1e-4 * (x - 320.0)).abs() < 1e-12 && dv.abs() < 1e-12);
        }
        assert_eq!(map.profile_y.len(), map.ys.len());
    }
}
