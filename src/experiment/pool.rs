//! Independent captures of one run pooled into one study row: the mean of each statistic over
//! the captures and its 95 % Student-t interval — the spread a lab would see by repeating the
//! experiment (new noise each time; with new layouts, a new print too), which the block bootstrap
//! of a single capture (`dic::bootstrap`) can only estimate from within one image pair.
//!
//! The % increases are paired per capture (each capture's reduced schemes share its frames), so
//! a row's increase is the mean of the per-capture increases and its interval the t interval of
//! that mean (a paired t analysis, e.g. Montgomery & Runger, *Applied Statistics and Probability
//! for Engineers*, § 10-4).

use super::study::{Increase, IncreaseInterval, StudyRow};
use crate::dataset::Manifest;
use crate::dic::{Stats, Summary};
use std::collections::HashMap;

/// The 0.975 quantile of Student's t with `df` degrees of freedom, 1 ≤ df ≤ 31 tabulated (to
/// 4 decimals, e.g. NIST/SEMATECH e-Handbook of Statistical Methods, table 1.4.2.7.2); beyond,
/// the Cornish–Fisher expansion about the normal quantile (error < 1e-3 there).
pub fn t_975(df: usize) -> f64 {
    const TABLE: [f64; 31] = [
        12.7062, 4.3027, 3.1824, 2.7764, 2.5706, 2.4469, 2.3646, 2.3060, 2.2622, 2.2281, 2.2010,
        2.1788, 2.1604, 2.1448, 2.1314, 2.1199, 2.1098, 2.1009, 2.0930, 2.0860, 2.0796, 2.0739,
        2.0687, 2.0639, 2.0595, 2.0555, 2.0518, 2.0484, 2.0452, 2.0423, 2.0395,
    ];
    match df {
        0 => f64::NAN,
        1..=31 => TABLE[df - 1],
        _ => {
            let z = 1.959_964f64;
            let n = df as f64;
            z + (z.powi(3) + z) / (4.0 * n)
                + (5.0 * z.powi(5) + 16.0 * z.powi(3) + 3.0 * z) / (96.0 * n * n)
        }
    }
}

/// Mean of `xs` and its 95 % t interval; NaN where any value is NaN, the interval NaN for one
/// value.
pub fn mean_interval(xs: &[f64]) -> (f64, [f64; 2]) {
    let n = xs.len();
    if n == 0 || xs.iter().any(|x| !x.is_finite()) {
        return (f64::NAN, [f64::NAN; 2]);
    }
    let (mean, var_of_mean) = mean_and_variance_of_mean(xs);
    if n < 2 {
        return (mean, [f64::NAN; 2]);
    }
    let half = t_975(n - 1) * var_of_mean.sqrt();
    (mean, [mean - half, mean + half])
}

/// Mean of `xs` and the variance of that mean (sample variance / n; NaN for fewer than two).
pub(super) fn mean_and_variance_of_mean(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    let mean = xs.iter().sum::<f64>() / n;
    let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, if xs.len() < 2 { f64::NAN } else { var / n })
}

/// The study's rows with the captures of every repeated run pooled (runs whose manifest entry
/// names `repeat_of`), in the order of first appearance; rows of other runs pass unchanged.
pub fn pool_captures(manifest: &Manifest, rows: &[StudyRow]) -> Vec<StudyRow> {
    let repeat_of: HashMap<&str, &str> = manifest
        .runs
        .iter()
        .filter_map(|r| Some((r.id.as_str(), r.repeat_of.as_deref()?)))
        .collect();
    // One slot per output row: a row passed through (no pooled id), or the captures of one
    // (pooled run, scheme), at the place of its first capture.
    let mut slots: Vec<(Option<&str>, Vec<&StudyRow>)> = Vec::new();
    let mut slot_of: HashMap<(&str, &str), usize> = HashMap::new();
    for row in rows {
        match repeat_of.get(row.run.as_str()) {
            None => slots.push((None, vec![row])),
            Some(&id) => {
                let k = *slot_of.entry((id, row.scheme.as_str())).or_insert_with(|| {
                    slots.push((Some(id), Vec::new()));
                    slots.len() - 1
                });
                slots[k].1.push(row);
            }
        }
    }
    slots
        .into_iter()
        .map(|(id, members)| match id {
            None => members[0].clone(),
            Some(id) => pool(id, &members),
        })
        .collect()
}

fn pool(id: &str, members: &[&StudyRow]) -> StudyRow {
    let first = members[0];
    let stats = |f: fn(&Summary) -> &Stats| {
        let all: Vec<&Stats> = members.iter().map(|r| f(&r.summary)).collect();
        let (std, std_ci95) = mean_interval(&all.iter().map(|s| s.std).collect::<Vec<_>>());
        Stats {
            mean: mean_interval(&all.iter().map(|s| s.mean).collect::<Vec<_>>()).0,
            std,
            std_ci95,
            min: all.iter().map(|s| s.min).fold(f64::INFINITY, f64::min),
            max: all.iter().map(|s| s.max).fold(f64::NEG_INFINITY, f64::max),
            count: all.iter().map(|s| s.count).sum(),
        }
    };
    let increases: Option<Vec<Increase>> = members.iter().map(|r| r.increase_pct).collect();
    let (increase_pct, increase_ci95) = match increases {
        None => (None, None),
        Some(inc) => {
            let field =
                |f: fn(&Increase) -> f64| mean_interval(&inc.iter().map(f).collect::<Vec<_>>());
            let (u, v, exx, eyy, exy) = (
                field(|i| i.u),
                field(|i| i.v),
                field(|i| i.exx),
                field(|i| i.eyy),
                field(|i| i.exy),
            );
            (
                Some(Increase {
                    u: u.0,
                    v: v.0,
                    exx: exx.0,
                    eyy: eyy.0,
                    exy: exy.0,
                }),
                Some(IncreaseInterval {
                    u: u.1,
                    v: v.1,
                    exx: exx.1,
                    eyy: eyy.1,
                    exy: exy.1,
                }),
            )
        }
    };
    StudyRow {
        run: id.to_string(),
        pattern: first.pattern.clone(),
        scheme: first.scheme.clone(),
        fill_factor: first.fill_factor,
        summary: Summary {
            points: members.iter().map(|r| r.summary.points).sum(),
            valid: members.iter().map(|r| r.summary.valid).sum(),
            u: stats(|s| &s.u),
            v: stats(|s| &s.v),
            exx: stats(|s| &s.exx),
            eyy: stats(|s| &s.eyy),
            exy: stats(|s| &s.exy),
        },
        increase_pct,
        increase_ci95,
        repeats: members.len(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

    /// The interval's coverage on normal samples, counted by simulation (not from the table):
    /// a wrong quantile (the normal 1.96 at n = 5 covers ≈ 88 %) fails.
    #[test]
    fn t_intervals_cover_95_percent_of_normal_means() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        for n in [2usize, 3, 5, 10, 32, 40] {
            let trials = 20_000;
            let mut covered = 0;
            for _ in 0..trials {
                let xs: Vec<f64> = (0..n)
                    .map(|_| {
                        let z: f64 = StandardNormal.sample(&mut rng);
                        3.0 + 0.5 * z
                    })
                    .collect();
                let (_, [lo, hi]) = mean_interval(&xs);
                covered += usize::from(lo <= 3.0 && 3.0 <= hi);
            }
            let coverage = covered as f64 / trials as f64;
            // Binomial standard error at 95 %: 0.0015; 4 of them either side.
            assert!((coverage - 0.95).abs() < 0.006, "n = {n}: {coverage}");
        }
    }

    #[test]
    fn one_value_has_no_interval_and_nan_spreads() {
        assert!(mean_interval(&[1.0]).1[0].is_nan());
        assert!(mean_interval(&[1.0, f64::NAN]).0.is_nan());
    }
}
