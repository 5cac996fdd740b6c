//! Shot noise: one Poisson count per pixel and frame, for a mean that changes from pixel to pixel.
//!
//! A model frame draws millions of counts, each with its own mean, so the sampler's per-mean setup
//! is paid per pixel. `rand_distr::Poisson` sets up (a square root, a logarithm, a log-gamma) and
//! then rejects with a Lorentzian envelope (a tangent, a logarithm and an exponential per trial);
//! with it the sensor noise was ≈ 30 % of a diagnosis round's profile, and replacing it cut the
//! round's CPU by a quarter (docs/performance.md). Here:
//!
//! - mean ≥ 10: PTRS, the transformed rejection of W. Hörmann, "The transformed rejection method
//!   for generating Poisson random variables", *Insurance: Mathematics and Economics* 12 (1993)
//!   39–45, as numpy draws them: its setup is a square root and two divisions, and about 9 of 10
//!   draws are accepted by the squeeze `us ≥ 0.07 ∧ v ≤ v_r` with two uniforms and no
//!   transcendental function; the rest take the exact test against the log-probability.
//! - mean < 10: inversion by sequential search from zero (Devroye, *Non-Uniform Random Variate
//!   Generation*, 1986, §X.3.2), about mean + 1 steps.
//!
//! Both are exact: the counts follow the Poisson law, not an approximation of it.

use rand::Rng;

/// Below this mean, inversion; at and above it, PTRS (whose constants Hörmann fitted for ≥ 10).
const PTRS_MIN_MEAN: f64 = 10.0;

/// One Poisson count of mean `mean` (≥ 0; a non-finite or non-positive mean gives 0), as a float.
#[inline(always)]
pub fn poisson_count<R: Rng + ?Sized>(mean: f64, rng: &mut R) -> f64 {
    if !(mean > 0.0) || !mean.is_finite() {
        0.0
    } else if mean < PTRS_MIN_MEAN {
        by_inversion(mean, rng)
    } else {
        by_transformed_rejection(mean, rng)
    }
}

#[inline]
fn by_inversion<R: Rng + ?Sized>(mean: f64, rng: &mut R) -> f64 {
    let u: f64 = rng.gen();
    let mut k = 0.0;
    let mut p = (-mean).exp();
    let mut cumulative = p;
    // The tail beyond 40 + 10 means is below 1e-16 for a mean under 10 (and rounding can leave
    // `cumulative` a hair under 1): stop there.
    while u > cumulative && k < 40.0 + 10.0 * mean {
        k += 1.0;
        p *= mean / k;
        cumulative += p;
    }
    k
}

#[inline(always)]
fn by_transformed_rejection<R: Rng + ?Sized>(mean: f64, rng: &mut R) -> f64 {
    // Hörmann (1993), algorithm PTRS, with his constants.
    let sqrt_mean = mean.sqrt();
    let b = 0.931 + 2.53 * sqrt_mean;
    let a = -0.059 + 0.02483 * b;
    let inv_alpha = 1.1239 + 1.1328 / (b - 3.4);
    let v_r = 0.9277 - 3.6224 / (b - 2.0);
    loop {
        let u = rng.gen::<f64>() - 0.5;
        let v: f64 = rng.gen();
        let us = 0.5 - u.abs();
        let k = ((2.0 * a / us + b) * u + mean + 0.43).floor();
        if us >= 0.07 && v <= v_r {
            return k;
        }
        if k < 0.0 || (us < 0.013 && v > us) {
            continue;
        }
        let log_envelope = v.ln() + inv_alpha.ln() - (a / (us * us) + b).ln();
        let log_probability = -mean + k * mean.ln() - libm::lgamma(k + 1.0);
        if log_envelope <= log_probability {
            return k;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// The Poisson probability of `k`, from its formula (not from the sampler's algorithm).
    fn probability(mean: f64, k: u64) -> f64 {
        (-mean + k as f64 * mean.ln() - libm::lgamma(k as f64 + 1.0)).exp()
    }

    /// Pearson's χ² of `n` draws against the Poisson law, the classes merged until each expects at
    /// least 20 draws; returns (χ², degrees of freedom).
    fn chi_squared(mean: f64, n: usize, seed: u64) -> (f64, usize) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let top = (mean + 12.0 * mean.sqrt() + 30.0) as usize;
        let mut counts = vec![0usize; top + 1];
        for _ in 0..n {
            let k = poisson_count(mean, &mut rng);
            assert!(k >= 0.0 && k.fract() == 0.0, "a count: {k}");
            counts[(k as usize).min(top)] += 1;
        }
        let expected: Vec<f64> = (0..=top)
            .map(|k| n as f64 * probability(mean, k as u64))
            .collect();
        // Classes from the lower tail upwards, merged until each expects ≥ 20; the last class
        // takes the upper tail (everything the classes before it do not expect).
        let (mut chi2, mut classes) = (0.0, 0);
        let (mut observed_class, mut expected_class, mut expected_sofar) = (0.0, 0.0, 0.0);
        for k in 0..=top {
            observed_class += counts[k] as f64;
            expected_class += expected[k];
            let tail_left = n as f64 - expected_sofar - expected_class;
            if expected_class >= 20.0 && tail_left >= 20.0 {
                chi2 += (observed_class - expected_class).powi(2) / expected_class;
                classes += 1;
                expected_sofar += expected_class;
                observed_class = 0.0;
                expected_class = 0.0;
            }
        }
        let expected_last = n as f64 - expected_sofar;
        chi2 += (observed_class - expected_last).powi(2) / expected_last;
        (chi2, classes)
    }

    /// 2,000,000 draws at means either side of the switch between the two methods, inside PTRS's
    /// squeeze region and in its tails, and at a sensor's well depths: Pearson's χ² against the
    /// Poisson probabilities stays below its 1e-5 quantile bound (mean + 6·sd of χ² with ν
    /// degrees of freedom, ν + 6√(2ν)). A sampler off by a few per mille in any class of a
    /// few thousand expected draws fails it.
    #[test]
    fn the_counts_follow_the_poisson_law() {
        for (i, mean) in [0.3, 2.5, 9.99, 10.0, 17.0, 160.0, 4_000.0, 30_000.0]
            .into_iter()
            .enumerate()
        {
            let (chi2, dof) = chi_squared(mean, 2_000_000, 7 + i as u64);
            let bound = dof as f64 + 6.0 * (2.0 * dof as f64).sqrt();
            assert!(
                chi2 < bound,
                "mean {mean}: χ² {chi2:.1} on {dof} dof, bound {bound:.1}"
            );
        }
    }

    /// The sampler's mean and variance equal the Poisson mean to within their standard errors
    /// (5 SE; the variance's SE is mean·√(2/n) for a large mean).
    #[test]
    fn mean_and_variance_equal_the_mean() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let n = 200_000;
        for mean in [4.0, 55.5, 12_345.6] {
            let draws: Vec<f64> = (0..n).map(|_| poisson_count(mean, &mut rng)).collect();
            let m = draws.iter().sum::<f64>() / n as f64;
            let var = draws.iter().map(|d| (d - m).powi(2)).sum::<f64>() / (n - 1) as f64;
            let se_mean = (mean / n as f64).sqrt();
            let se_var = mean * (2.0 / n as f64).sqrt() + (mean / n as f64).sqrt();
            assert!((m - mean).abs() < 5.0 * se_mean, "mean {mean}: {m}");
            assert!((var - mean).abs() < 5.0 * se_var, "mean {mean}: var {var}");
        }
    }

    #[test]
    fn no_mean_gives_no_count() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for mean in [0.0, -3.0, f64::NAN, f64::INFINITY] {
            assert_eq!(poisson_count(mean, &mut rng), 0.0);
        }
    }
}
