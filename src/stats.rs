//! Small statistics every floor uses: the median, Student's t 0.975 quantile and the mean of
//! independent realisations with its 95 % t interval. No crate imports.

/// The median of `values` (sorted in place; NaN-free input assumed, the mean of the two middle
/// values for an even count).
pub fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n % 2 == 1 {
        values[n / 2]
    } else {
        0.5 * (values[n / 2 - 1] + values[n / 2])
    }
}

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

/// The z with P(Z > z) = `p` for a standard normal Z (0 < p < 1), by bisection on the
/// complementary error function: exact to 1e-12, for the few thresholds a report needs.
pub fn normal_upper_quantile(p: f64) -> f64 {
    let upper = |z: f64| 0.5 * libm::erfc(z / std::f64::consts::SQRT_2);
    let (mut lo, mut hi) = (-40.0f64, 40.0f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if upper(mid) > p {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
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
pub fn mean_and_variance_of_mean(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    let mean = xs.iter().sum::<f64>() / n;
    let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, if xs.len() < 2 { f64::NAN } else { var / n })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_quantiles_are_the_tabulated_ones() {
        // Abramowitz & Stegun table 26.5: 1.959964 (2.5 %), 2.575829 (0.5 %), 3.290527 (0.05 %).
        assert!((normal_upper_quantile(0.025) - 1.959_964).abs() < 1e-6);
        assert!((normal_upper_quantile(0.005) - 2.575_829).abs() < 1e-6);
        assert!((normal_upper_quantile(0.0005) - 3.290_527).abs() < 1e-6);
        assert!((normal_upper_quantile(0.5)).abs() < 1e-9);
    }
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
