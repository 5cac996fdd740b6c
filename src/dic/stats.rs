//! Summary statistics over valid points. In a rigid-translation test every point should move
//! alike and every strain be zero, so the standard deviations are the measurement error (the
//! paper's error measure, after Hijazi et al. [12]).

use super::PoiResult;
use serde::{Deserialize, Serialize};

/// Mean, sample standard deviation (n-1), min and max of the finite values of one field.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Stats {
    pub mean: f64,
    pub std: f64,
    pub min: f64,
    pub max: f64,
    pub count: usize,
}

impl Stats {
    /// Statistics of the finite values; all NaN (count 0) when there are none.
    pub fn of(values: impl IntoIterator<Item = f64>) -> Self {
        let v: Vec<f64> = values.into_iter().filter(|x| x.is_finite()).collect();
        let n = v.len();
        if n == 0 {
            return Self {
                mean: f64::NAN,
                std: f64::NAN,
                min: f64::NAN,
                max: f64::NAN,
                count: 0,
            };
        }
        let mean = v.iter().sum::<f64>() / n as f64;
        let ss: f64 = v.iter().map(|x| (x - mean).powi(2)).sum();
        let std = if n > 1 {
            (ss / (n - 1) as f64).sqrt()
        } else {
            0.0
        };
        let min = v.iter().copied().fold(f64::INFINITY, f64::min);
        let max = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        Self {
            mean,
            std,
            min,
            max,
            count: n,
        }
    }
}

/// Statistics of every field over the valid points of one analysis.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    pub points: usize,
    pub valid: usize,
    pub u: Stats,
    pub v: Stats,
    pub exx: Stats,
    pub eyy: Stats,
    pub exy: Stats,
}

impl Summary {
    pub fn of(points: &[PoiResult]) -> Self {
        let valid: Vec<&PoiResult> = points.iter().filter(|p| p.status.is_valid()).collect();
        let field = |f: fn(&PoiResult) -> f64| Stats::of(valid.iter().map(|p| f(p)));
        Self {
            points: points.len(),
            valid: valid.len(),
            u: field(|p| p.u),
            v: field(|p| p.v),
            exx: field(|p| p.exx),
            eyy: field(|p| p.eyy),
            exy: field(|p| p.exy),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sample_std_and_nan_skipping() {
        let s = Stats::of([1.0, 2.0, 3.0, f64::NAN, 4.0]);
        assert_eq!(s.count, 4);
        assert!((s.mean - 2.5).abs() < 1e-12);
        assert!((s.std - (5.0f64 / 3.0).sqrt()).abs() < 1e-12);
        assert_eq!((s.min, s.max), (1.0, 4.0));
        assert!(Stats::of([f64::NAN]).mean.is_nan());
    }
}
