//! Standard normal draws for the model's pixel noise, by inversion of a tabulated quantile
//! function: each draw is the table's entry at 16 random bits, four draws to one 64-bit word of
//! the row's stream.
//!
//! The table holds Φ⁻¹ at the midpoints (i + ½)/2¹⁶ of 2¹⁶ equal slices of probability, so a
//! draw follows a discrete law whose CDF is within 1/2¹⁷ ≈ 7.6e-6 of Φ everywhere (inversion,
//! L. Devroye, *Non-Uniform Random Variate Generation*, Springer 1986, §II.2, of a quantile
//! function tabulated at equal steps of probability); its extreme entries are ±4.325, so a frame
//! of 5.5 Mpx misses some 80 pixels that a continuous normal puts beyond 4.325 σ, and its
//! variance is 0.99998. A model frame's noise (the dataset's floor, a sensor's count and read noise) was
//! one ziggurat draw per pixel from ChaCha8 (`rand_distr::Normal`): some 9 % of a paper-size
//! diagnosis round's CPU; a table read is a fraction of it and the stream is read a quarter as
//! often. The unit tests hold the table to Φ⁻¹ computed apart (bisection on `erfc`) and a million
//! draws to Φ within the DKW bound.

use rand::RngCore;
use std::sync::OnceLock;

/// Bits of the stream per draw.
const INDEX_BITS: u32 = 16;
/// Entries of the quantile table.
pub const TABLE_LEN: usize = 1 << INDEX_BITS;

/// Standard normal draws from the random stream `R` (module doc). Deterministic: the same stream
/// gives the same draws.
pub struct NormalDraws<R> {
    rng: R,
    /// Stream bits not yet used, lowest first.
    bits: u64,
    /// Draws left in `bits`.
    left: u32,
    table: &'static [f32; TABLE_LEN],
}

impl<R: RngCore> NormalDraws<R> {
    pub fn new(rng: R) -> Self {
        Self {
            rng,
            bits: 0,
            left: 0,
            table: quantile_table(),
        }
    }

    /// One standard normal draw.
    #[inline(always)]
    pub fn standard(&mut self) -> f64 {
        if self.left == 0 {
            self.bits = self.rng.next_u64();
            self.left = u64::BITS / INDEX_BITS;
        }
        let index = (self.bits as usize) & (TABLE_LEN - 1);
        self.bits >>= INDEX_BITS;
        self.left -= 1;
        f64::from(self.table[index])
    }

    /// The stream itself, for the draws that are not normal (a small mean's Poisson count).
    #[inline(always)]
    pub fn rng(&mut self) -> &mut R {
        &mut self.rng
    }
}

/// Φ⁻¹((i + ½)/2¹⁶), i = 0..2¹⁶: the lower half by Newton's method on the lower tail (libm's
/// erfc, exact to a few ulps there) from Abramowitz and Stegun's 26.2.23 (|error| < 4.5e-4),
/// whose error four steps take below f32's resolution; the upper half by symmetry.
fn quantile_table() -> &'static [f32; TABLE_LEN] {
    static TABLE: OnceLock<Box<[f32; TABLE_LEN]>> = OnceLock::new();
    TABLE.get_or_init(|| {
        let mut table = Box::new([0.0f32; TABLE_LEN]);
        for i in 0..TABLE_LEN / 2 {
            let z = lower_quantile((i as f64 + 0.5) / TABLE_LEN as f64);
            table[i] = z as f32;
            table[TABLE_LEN - 1 - i] = -z as f32;
        }
        table
    })
}

/// Φ⁻¹(p) for 0 < p ≤ ½.
fn lower_quantile(p: f64) -> f64 {
    let t = (-2.0 * p.ln()).sqrt();
    let mut z = -(t
        - (2.515_517 + 0.802_853 * t + 0.010_328 * t * t)
            / (1.0 + 1.432_788 * t + 0.189_269 * t * t + 0.001_308 * t * t * t));
    for _ in 0..4 {
        let cdf = 0.5 * libm::erfc(-z / std::f64::consts::SQRT_2);
        let density = (-0.5 * z * z).exp() / (2.0 * std::f64::consts::PI).sqrt();
        z -= (cdf - p) / density;
    }
    z
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// Φ(z) from libm's erfc, apart from the table's construction.
    fn phi(z: f64) -> f64 {
        0.5 * libm::erfc(-z / std::f64::consts::SQRT_2)
    }

    #[test]
    fn the_table_holds_the_normal_quantiles() {
        let table = quantile_table();
        // Each entry against Φ⁻¹ by bisection on erfc (200 halvings).
        let quantile = |p: f64| {
            let (mut lo, mut hi) = (-40.0f64, 40.0f64);
            for _ in 0..200 {
                let mid = 0.5 * (lo + hi);
                if phi(mid) < p {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            0.5 * (lo + hi)
        };
        for i in (0..TABLE_LEN)
            .step_by(97)
            .chain([0, 1, TABLE_LEN / 2, TABLE_LEN - 1])
        {
            let p = (i as f64 + 0.5) / TABLE_LEN as f64;
            let z = quantile(p);
            let tolerance = 2.0 * f64::from(f32::EPSILON) * z.abs().max(1e-4);
            assert!(
                (f64::from(table[i]) - z).abs() <= tolerance,
                "entry {i}: {} against {z}",
                table[i]
            );
        }
        // The extreme entry Φ⁻¹(1 − 2⁻¹⁷) as Python's statistics.NormalDist().inv_cdf gives it
        // (Wichura's AS 241), and the entries in order.
        assert!((f64::from(table[TABLE_LEN - 1]) - 4.324_919).abs() < 1e-5);
        assert!(table.windows(2).all(|w| w[0] < w[1]));
    }

    #[test]
    fn a_million_draws_follow_the_normal_law() {
        let mut draws = NormalDraws::new(ChaCha8Rng::seed_from_u64(17));
        let n = 1_000_000;
        let mut xs: Vec<f64> = (0..n).map(|_| draws.standard()).collect();
        xs.sort_by(f64::total_cmp);
        // Kolmogorov–Smirnov distance to Φ against the Dvoretzky–Kiefer–Wolfowitz bound at
        // α = 1e-6: sqrt(ln(2/α) / 2n) = 0.0027.
        let gap = xs
            .iter()
            .enumerate()
            .map(|(k, &x)| {
                let f = phi(x);
                (f - k as f64 / n as f64)
                    .abs()
                    .max((f - (k + 1) as f64 / n as f64).abs())
            })
            .fold(0.0f64, f64::max);
        assert!(gap < 0.0027, "KS distance {gap}");
        let mean = xs.iter().sum::<f64>() / n as f64;
        let variance = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
        // The mean's SE is 0.001, the variance's 0.0014 (√(2/n)).
        assert!(mean.abs() < 0.005, "mean {mean}");
        assert!((variance - 1.0).abs() < 0.007, "variance {variance}");
    }

    #[test]
    fn the_same_stream_gives_the_same_draws_and_uses_a_word_per_four() {
        let mut a = NormalDraws::new(ChaCha8Rng::seed_from_u64(3));
        let mut b = NormalDraws::new(ChaCha8Rng::seed_from_u64(3));
        let xs: Vec<f64> = (0..9).map(|_| a.standard()).collect();
        let ys: Vec<f64> = (0..9).map(|_| b.standard()).collect();
        assert_eq!(xs, ys);
        // Nine draws took three words: the streams are in step with one three words on.
        let mut c = ChaCha8Rng::seed_from_u64(3);
        for _ in 0..3 {
            c.next_u64();
        }
        assert_eq!(a.rng().next_u64(), c.next_u64());
    }
}
