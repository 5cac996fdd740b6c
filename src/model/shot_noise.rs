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
//!
//! A sensor pixel reads its count plus a normal read noise, and [`count_plus_read_noise`] draws
//! that sum. Where the mean is large and the read noise hides the count's integer steps, the sum
//! is drawn from one standard normal through the Cornish–Fisher expansion to the sum's own third
//! and fourth cumulants: PTRS and its exact test (a fifth of the draws take three logarithms and
//! a log-gamma) were most of a model frame's noise.

use super::normal_draws::NormalDraws;
use rand::{Rng, RngCore};

/// Below this mean, inversion; at and above it, PTRS (whose constants Hörmann fitted for ≥ 10).
const PTRS_MIN_MEAN: f64 = 10.0;

/// From this mean on, [`count_plus_read_noise`] draws the sum through the Cornish–Fisher
/// expansion. At 100 e⁻ the sum's skewness is ≤ 0.1 and its excess kurtosis ≤ 0.01, and the
/// expanded CDF is within 2.5e-6 of the exact law's (4.8e-5 with the γ₁ term alone, 6.6e-3 for a
/// plain normal: at 100 e⁻ and σ = 1 e⁻, the worst case; docs/performance.md has the table). The
/// unit test below holds a million draws to the exact law's CDF.
const EXPANSION_MIN_MEAN: f64 = 100.0;

/// The least read noise for the expansion, e⁻: a normal of σ ≥ 1 smooths the count's unit steps
/// to a ripple of exp(−2π²σ²) ≈ 3e-9 of the density; with less the steps show and the sum is
/// drawn exactly.
const EXPANSION_MIN_READ_E: f64 = 1.0;

/// A Poisson count of mean `mean` plus a normal read noise of σ `read_sigma` (both e⁻), as a
/// float. Exact ([`poisson_count`] plus a normal draw) below [`EXPANSION_MIN_MEAN`] or
/// [`EXPANSION_MIN_READ_E`]; above both, one standard normal z mapped by the Cornish–Fisher
/// expansion (E. A. Cornish and R. A. Fisher, "Moments and cumulants in the specification of
/// distributions", *Revue de l'Institut International de Statistique* 5 (1938) 307–320; the
/// terms as in Abramowitz and Stegun 26.2.49) to the sum's cumulants κ₁ = λ, κ₂ = λ + σ²,
/// κ₃ = κ₄ = λ: x = κ₁ + √κ₂·(z + γ₁(z² − 1)/6 + γ₂(z³ − 3z)/24 − γ₁²(2z³ − 5z)/36), with
/// skewness γ₁ = κ₃/κ₂^{3/2} and excess kurtosis γ₂ = κ₄/κ₂².
/// The standard normals come from `draws` (a tabulated quantile function, within 7.6e-6 of Φ:
/// `normal_draws`), the small means' counts from its stream.
#[inline(always)]
pub fn count_plus_read_noise<R: RngCore>(
    mean: f64,
    read_sigma: f64,
    draws: &mut NormalDraws<R>,
) -> f64 {
    if !(mean >= EXPANSION_MIN_MEAN && read_sigma >= EXPANSION_MIN_READ_E && mean.is_finite()) {
        let count = poisson_count(mean, draws.rng());
        return count + read_sigma * draws.standard();
    }
    let variance = mean + read_sigma * read_sigma;
    let sd = variance.sqrt();
    let skewness = mean / (variance * sd);
    let kurtosis = mean / (variance * variance);
    let z = draws.standard();
    let z2 = z * z;
    let x = z + skewness * (z2 - 1.0) / 6.0 + kurtosis * z * (z2 - 3.0) / 24.0
        - skewness * skewness * z * (2.0 * z2 - 5.0) / 36.0;
    mean + sd * x
}

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
    use rand_distr::Distribution;

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

    /// The CDF of a Poisson count of mean `mean` plus a normal of σ `sigma` at `x`, from the
    /// law's formula: Σₖ P(k)·Φ((x − k)/σ), with libm's erfc (not from the sampler).
    fn sum_cdf(x: f64, mean: f64, sigma: f64) -> f64 {
        let reach = 12.0 * mean.sqrt() + 30.0;
        let (lo, hi) = ((mean - reach).max(0.0) as u64, (mean + reach) as u64);
        (lo..=hi)
            .map(|k| {
                let z = (x - k as f64) / sigma;
                probability(mean, k) * 0.5 * libm::erfc(-z / std::f64::consts::SQRT_2)
            })
            .sum()
    }

    /// The largest gap between the empirical CDF of `draws` and the exact law's, over 601 points
    /// across ±6 standard deviations.
    fn cdf_gap(mut draws: Vec<f64>, mean: f64, sigma: f64) -> f64 {
        draws.sort_by(f64::total_cmp);
        let sd = (mean + sigma * sigma).sqrt();
        (0..=600)
            .map(|i| {
                let x = mean - 6.0 * sd + 12.0 * sd * i as f64 / 600.0;
                let empirical = draws.partition_point(|&d| d <= x) as f64 / draws.len() as f64;
                (empirical - sum_cdf(x, mean, sigma)).abs()
            })
            .fold(0.0, f64::max)
    }

    /// A million draws of count plus read noise against the exact law, where the expansion
    /// draws them (at its threshold, the worst case, and at a sensor's well depths) and where the
    /// draw is exact (read noise below 1 e⁻): the empirical CDF stays within the
    /// Dvoretzky–Kiefer–Wolfowitz bound ε = √(ln(2/α)/2n), α = 1e-6 (0.0027). A plain normal of
    /// the same mean and variance, which leaves out the skewness, is off by 0.0066 at 100 e⁻ and
    /// σ = 1 e⁻, and the test tells it apart there.
    #[test]
    fn count_plus_read_noise_follows_the_exact_law() {
        let n = 1_000_000;
        let bound = ((2.0f64 / 1e-6).ln() / (2.0 * n as f64)).sqrt();
        for (i, (mean, sigma)) in [
            (100.0, 1.0),
            (100.0, 11.0),
            (1_000.0, 1.0),
            (4_000.0, 3.0),
            (30_000.0, 11.0),
            (150.0, 0.5),
        ]
        .into_iter()
        .enumerate()
        {
            let mut normals = NormalDraws::new(ChaCha8Rng::seed_from_u64(20 + i as u64));
            let draws: Vec<f64> = (0..n)
                .map(|_| count_plus_read_noise(mean, sigma, &mut normals))
                .collect();
            let gap = cdf_gap(draws, mean, sigma);
            println!("mean {mean} e, σ {sigma} e: CDF gap {gap:.5} (bound {bound:.5})");
            assert!(
                gap < bound,
                "mean {mean}, σ {sigma}: CDF gap {gap:.5}, bound {bound:.5}"
            );
        }
        let mut rng = ChaCha8Rng::seed_from_u64(19);
        let sd = 101.0f64.sqrt();
        let plain: Vec<f64> = (0..n)
            .map(|_| {
                let z: f64 = rand_distr::StandardNormal.sample(&mut rng);
                100.0 + sd * z
            })
            .collect();
        let gap = cdf_gap(plain, 100.0, 1.0);
        println!("a plain normal at 100 e, σ 1 e: CDF gap {gap:.5}");
        assert!(
            gap > bound,
            "a plain normal's CDF gap {gap:.5} is within {bound:.5}"
        );
    }

    #[test]
    fn no_mean_gives_no_count() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for mean in [0.0, -3.0, f64::NAN, f64::INFINITY] {
            assert_eq!(poisson_count(mean, &mut rng), 0.0);
        }
    }
}
