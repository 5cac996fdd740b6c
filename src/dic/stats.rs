//! Summary statistics over valid points. In a rigid-translation test every point should move
//! alike and every strain be zero, so the standard deviations are the measurement error (the
//! paper's error measure, after Hijazi et al. [12]).

use super::bootstrap::{BlockBootstrap, BLOCK_PER_CORRELATION_LENGTH};
use super::{DicSettings, PoiResult};
use serde::{Deserialize, Serialize};

/// Mean, sample standard deviation (n-1), min and max of the finite values of one field.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Stats {
    #[serde(deserialize_with = "f64_or_nan")]
    pub mean: f64,
    #[serde(deserialize_with = "f64_or_nan")]
    pub std: f64,
    /// 95 % interval of `std` by a block bootstrap over the grid (`bootstrap.rs`); null when
    /// not computed or when the grid holds too few independent blocks.
    #[serde(default = "no_interval", deserialize_with = "interval_or_nan")]
    pub std_ci95: [f64; 2],
    #[serde(deserialize_with = "f64_or_nan")]
    pub min: f64,
    #[serde(deserialize_with = "f64_or_nan")]
    pub max: f64,
    pub count: usize,
}

/// A number, or null read back as NaN (what serde_json writes for NaN).
pub fn f64_or_nan<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

fn no_interval() -> [f64; 2] {
    [f64::NAN, f64::NAN]
}

/// JSON has no NaN: serde_json writes it as null, and this reads null back as NaN.
pub fn interval_or_nan<'de, D: serde::Deserializer<'de>>(d: D) -> Result<[f64; 2], D::Error> {
    let pair = <[Option<f64>; 2]>::deserialize(d)?;
    Ok(pair.map(|v| v.unwrap_or(f64::NAN)))
}

/// Correlation lengths of a grid's fields, in points: neighbouring displacements share their
/// subsets' pixels, neighbouring strains their windows' points.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CorrelationLengths {
    pub displacement_points: usize,
    pub strain_points: usize,
}

impl CorrelationLengths {
    /// Subset side / step and virtual strain gauge / step, rounded up.
    pub fn of(settings: &DicSettings) -> Self {
        let step = settings.step_px.max(1);
        Self {
            displacement_points: settings.subset_px.div_ceil(step),
            strain_points: settings.strain_gauge_px().div_ceil(step),
        }
    }

    /// The bootstrap plans for displacements and strains on an `nx` x `ny` grid.
    pub fn plans(&self, nx: usize, ny: usize) -> (Option<BlockBootstrap>, Option<BlockBootstrap>) {
        let plan = |c: usize| BlockBootstrap::new(nx, ny, BLOCK_PER_CORRELATION_LENGTH * c);
        (plan(self.displacement_points), plan(self.strain_points))
    }
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
                std_ci95: no_interval(),
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
            std_ci95: no_interval(),
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

/// The five fields of valid points, row-major over the grid, NaN elsewhere: what the
/// bootstrap resamples.
pub fn valid_fields(points: &[PoiResult]) -> [Vec<f64>; 5] {
    let field = |f: fn(&PoiResult) -> f64| -> Vec<f64> {
        points
            .iter()
            .map(|p| if p.status.is_valid() { f(p) } else { f64::NAN })
            .collect()
    };
    [
        field(|p| p.u),
        field(|p| p.v),
        field(|p| p.exx),
        field(|p| p.eyy),
        field(|p| p.exy),
    ]
}

impl Summary {
    /// [`Summary::of`] with the 95 % interval of every std, from a block bootstrap over the
    /// `nx` x `ny` grid the points fill row-major.
    pub fn with_intervals(
        points: &[PoiResult],
        nx: usize,
        ny: usize,
        lengths: CorrelationLengths,
    ) -> Self {
        let fields = valid_fields(points);
        let mut summary = Self::from_fields(points, &fields);
        if nx * ny != points.len() {
            return summary;
        }
        let (disp, strain) = lengths.plans(nx, ny);
        if let Some(plan) = disp {
            let ci = plan.std_intervals(&[&fields[0], &fields[1]]);
            summary.u.std_ci95 = ci[0];
            summary.v.std_ci95 = ci[1];
        }
        if let Some(plan) = strain {
            let ci = plan.std_intervals(&[&fields[2], &fields[3], &fields[4]]);
            summary.exx.std_ci95 = ci[0];
            summary.eyy.std_ci95 = ci[1];
            summary.exy.std_ci95 = ci[2];
        }
        summary
    }

    pub fn of(points: &[PoiResult]) -> Self {
        Self::from_fields(points, &valid_fields(points))
    }

    /// The statistics of `points`' [`valid_fields`] (NaN marks a point that is not valid;
    /// `Stats::of` skips it).
    fn from_fields(points: &[PoiResult], fields: &[Vec<f64>; 5]) -> Self {
        let [u, v, exx, eyy, exy] = fields.each_ref().map(|f| Stats::of(f.iter().copied()));
        Self {
            points: points.len(),
            valid: points.iter().filter(|p| p.status.is_valid()).count(),
            u,
            v,
            exx,
            eyy,
            exy,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stats_with_nan_survive_json() {
        let s = Stats::of([f64::NAN]);
        let back: Stats = serde_json::from_str(&serde_json::to_string(&s).unwrap()).unwrap();
        assert!(back.mean.is_nan() && back.std_ci95[1].is_nan() && back.count == 0);
        let old = r#"{"mean":1.0,"std":2.0,"min":0.0,"max":3.0,"count":4}"#;
        assert!(serde_json::from_str::<Stats>(old).unwrap().std_ci95[0].is_nan());
    }

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
